"""Properties of ``maglev_oc.control`` and ``maglev_oc.diagnosis`` behind the survivors of the seed-48
mutation-testing run: each test states what a user computes or reads, not the mutated token.

* Without a C compiler, compiling the generated code raises a SolverError that says so.
* ``read_outputs`` reads back a file in the documented instance layout (several outputs of
  different widths), built here byte by byte.
* The RTI step's reported cost is the OCP's cost of the applied plan, 0.5 e' H e / cost_scale with
  e = (z - z_ref) / z_scale recomputed here (zero when the plan is the reference).
* The converged NMPC's fallback current (a failed solve) lies in the current limit's octagon, in
  the direction of the plan's, and is the plan's own when already inside.
* Each round of the shares the guides hold while sticking is a share in [0, 1]: estimates above 1
  (plausible up to 1.5) are all "every force held", so they compare equal from round to round.
* ``converged_references`` gives the same constants whether it is handed the first round's library
  or builds it, and its later rounds rebuild the library from the refitted constants.
* (In tests/test_diagnose_synthetic.py, beside its diagnosis of a friction log: a diagnosis that
  found an effect carries the validation of the model with it, in the result and in its JSON.)
* The compensation study's "after" regulator compensates the found effect: on a twin with it,
  its closed loop differs from the base regulator's and tracks better.

About 5 s of CPU (two 1 s closed loops, a few
joint refits of a synthetic log, one NMPC transcription).
"""

from __future__ import annotations

import dataclasses
import math
import struct
from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest

import maglev_oc.diagnosis.refit as refit
from maglev_oc.control import codegen
from maglev_oc.control.nmpc import NonlinearMPC
from maglev_oc.control.nmpc.converged import ConvergedSolver
from maglev_oc.control.nmpc.layout import MemoryLayout
from maglev_oc.control.nmpc.rti import rti_parts
from maglev_oc.control.nmpc.status import DIAG_NAMES
from maglev_oc.diagnosis.feedback import compensation_study
from maglev_oc.diagnosis.library import candidate_library
from maglev_oc.diagnosis.magnetics import EndProfile
from maglev_oc.diagnosis.pipeline import _holding_shares
from maglev_oc.errors import SolverError
from maglev_oc.model.parameters import LumpedConstants
from maglev_oc.regression.data import prepare
from maglev_oc.results import Estimate
from maglev_oc.sim.scenarios import paper_scenarios
from tests.test_diagnosis_seed39_properties import _force_found
from tests.test_statistics_properties import RATE_FRICTION, _log


# --- the C compiler --------------------------------------------------------------------------------------
def test_compiling_without_a_c_compiler_says_there_is_none(monkeypatch, tmp_path):
    """No compiler found: both the shared library and the harness refuse with a SolverError whose
    message names the missing C compiler and how to provide one ($CC)."""
    monkeypatch.setattr(codegen, "c_compiler", lambda: None)
    code = SimpleNamespace(source=tmp_path / "x.c", include_dirs=(), link_flags=())
    for build in (codegen.compile_shared, codegen.build_harness):
        with pytest.raises(SolverError) as info:
            build(code)
        text = str(info.value)
        assert "no C compiler found" in text and "$CC" in text, text


# --- the harness's output file ---------------------------------------------------------------------------
def test_read_outputs_reads_the_documented_layout(tmp_path):
    """A file written here in the module docstring's layout (magic, n, n_in, n_out, nnz_in, nnz_out,
    then float64 rows): three outputs of widths 2, 4 and 1 over three rows come back as three arrays
    of those widths with the rows' values, bit for bit (the header's two input widths, which the
    outputs do not need, are skipped)."""
    n, nnz_in, nnz_out = 3, (5, 7), (2, 4, 1)
    rows = np.arange(n * sum(nnz_out), dtype=float).reshape(n, -1) * 0.5 - 3.25
    path = tmp_path / "out.bin"
    path.write_bytes(
        b"NMPCREC1"
        + struct.pack("<3i", n, len(nnz_in), len(nnz_out))
        + struct.pack("<2i", *nnz_in)
        + struct.pack("<3i", *nnz_out)
        + rows.astype("<f8").tobytes()
    )
    got = codegen.read_outputs(path)
    assert [g.shape for g in got] == [(3, 2), (3, 4), (3, 1)]
    np.testing.assert_array_equal(np.concatenate(got, axis=1), rows)


# --- the RTI step's reported cost ------------------------------------------------------------------------
@pytest.fixture(scope="module")
def rti(model):
    nmpc = NonlinearMPC(model)
    return nmpc, rti_parts(nmpc._ocp, nmpc._observer, nmpc.shift).post


def _post_call(nmpc, post, dz, z_bar, z_ref, hess):
    """The post-processing of an accepted QP step ``dz`` (no constraint, data finite): its diag
    (DIAG_NAMES without qp_status) as an array."""
    ocp = nmpc._ocp
    nz, na = ocp.nz, ocp.na
    big = 1e8
    args = {
        "z_bar": z_bar,
        "dz": dz,
        "lam_x": np.zeros(nz),
        "lam_a": np.zeros(na),
        "A": ca.DM(post.sparsity_in("A"), 0.0),
        "lba": -big * np.ones(na),
        "uba": big * np.ones(na),
        "lbx": -big * np.ones(nz),
        "ubx": big * np.ones(nz),
        "data_ok": 1.0,
        "H": hess,
        "z_ref": z_ref,
        "obs": np.zeros(4),
        "d": np.zeros(2),
        "y": np.zeros(2),
        "dz_lq": np.zeros(nz),
    }
    out = post(**{k: args[k] for k in post.name_in()})
    return np.asarray(out["diag"]).ravel(), np.asarray(out["plan"]).ravel()


def test_the_rti_steps_cost_is_the_ocps_cost_of_the_applied_plan(rti):
    """An accepted step: the reported cost is 0.5 e' H e / cost_scale with e the applied plan's
    deviation from the reference plan in the QP's scaled variables, (z - z_ref) / z_scale; zero when
    the plan is the reference."""
    nmpc, post = rti
    ocp = nmpc._ocp
    rng = np.random.default_rng(48)
    sp = post.sparsity_in("H")
    hess = ca.DM(sp, rng.uniform(0.5, 2.0, sp.nnz()))
    scale = np.asarray(ocp.z_scale, dtype=float)
    z_bar = rng.normal(size=ocp.nz) * scale
    z_ref = z_bar + rng.normal(size=ocp.nz) * scale
    dz = 0.1 * rng.normal(size=ocp.nz)
    diag, plan = _post_call(nmpc, post, dz, z_bar, z_ref, hess)
    names = [n for n in DIAG_NAMES if n != "qp_status"]
    assert diag[names.index("solver_ok")] == 1.0
    z = z_bar + dz * scale
    np.testing.assert_allclose(plan, z, rtol=1e-12)
    e = (z - z_ref) / scale
    expected = 0.5 * e @ np.asarray(hess.full()) @ e / ocp.cost_scale
    # the same sums in another order: rounding only
    assert diag[names.index("cost")] == pytest.approx(expected, rel=1e-10)
    assert expected > 0
    # the plan on the reference: no cost
    diag, _ = _post_call(nmpc, post, dz, z_bar, z_bar + dz * scale, hess)
    assert abs(diag[names.index("cost")]) < 1e-20  # a difference of equal doubles: exactly 0


# --- the converged NMPC's fallback -----------------------------------------------------------------------
def _octagon_excess(u, r):
    """Largest of the octagon's rows over the radius (<= 1 inside)."""
    return max(abs(u[0]), abs(u[1]), abs(u[0] + u[1]) / math.sqrt(2), abs(u[0] - u[1]) / math.sqrt(2)) / r


def test_the_converged_fallback_current_lies_in_the_octagon(model):
    """A solve that cannot start (the encoder reading is not finite) applies the plan's first
    current: scaled back onto the octagon along its own direction when outside (on its boundary),
    the plan's own when inside."""
    nmpc = NonlinearMPC(model, mode="converged")
    ocp = nmpc._ocp
    solver = ConvergedSolver(ocp, nmpc._observer, nmpc.shift)
    lay = MemoryLayout(ocp.nz)
    r = ocp.radius
    ref = np.zeros((6, nmpc.grid.horizon + 1))
    y = np.array([np.nan, np.nan])
    for u_plan, inside in (((3.0 * r, r), False), ((0.9 * r, -0.9 * r), False), ((0.3 * r, -0.2 * r), True)):
        memory = np.zeros(lay.size)
        memory[lay.plan.start : lay.plan.start + 2] = u_plan
        u, _, diag = solver.step(memory, y, ref)
        assert diag[DIAG_NAMES.index("solver_ok")] == 0.0
        u_plan = np.asarray(u_plan)
        if inside:
            np.testing.assert_array_equal(u, u_plan)
        else:
            # one division: rounding only
            assert _octagon_excess(u, r) == pytest.approx(1.0, rel=1e-12)
            assert u[0] * u_plan[1] - u[1] * u_plan[0] == pytest.approx(0.0, abs=1e-12 * r * r)
            assert u @ u_plan > 0


# --- the shares the guides hold --------------------------------------------------------------------------
def _selection_with_holding(value):
    step = SimpleNamespace(
        chosen="guide_friction_horizontal",
        judgements={
            "guide_friction_horizontal": SimpleNamespace(physical={"holding": Estimate(value, 0.1, "1")})
        },
    )
    return SimpleNamespace(steps=[step])


def test_the_share_held_by_sticking_guides_is_a_share(model):
    """A friction's holding estimate above 1 (its plausible range reaches 1.5) means the guides hold
    every force: the share is 1, so two rounds with 1.2 and 1.3 hold the same (the selection's test
    that the held shares stopped changing); below 0 it is 0, inside [0, 1] the estimate."""
    data = prepare([_log(model, friction=0.0)], bandwidth=10.0)
    library = [c for c in candidate_library(model, data) if c.name == "guide_friction_horizontal"]
    assert library and library[0].family == "friction"
    shares = {v: _holding_shares(_selection_with_holding(v), library) for v in (1.2, 1.3, -0.2, 0.4)}
    assert shares[1.2] == shares[1.3] == {"horizontal": 1.0}
    assert shares[-0.2] == {"horizontal": 0.0}
    assert shares[0.4] == {"horizontal": 0.4}


# --- the references iterated to convergence --------------------------------------------------------------
def test_converged_references_rebuilds_the_library_from_each_refit(model, monkeypatch):
    """Guide friction on the synthetic horizontal log, started from a C1 10 % low (so that several
    rounds run): handed the library of the starting model, the result is the one it gets building
    that library itself, and every library it builds is of a refitted model (none of the starting
    one, one per round after the first)."""
    data = prepare([_log(model, friction=RATE_FRICTION)], bandwidth=10.0)
    train, hold = data.masks(0.25)
    c = model.constants
    start = model.with_constants(LumpedConstants(0.9 * c.C1, c.C2, c.C3, c.C4, source="start"))
    first = candidate_library(start, data, None)
    built_for = []
    widths = []

    def spy(fitted, data, held=None, *, end_profile):
        built_for.append(fitted.constants.C1)
        widths.append(end_profile)
        return candidate_library(fitted, data, held, end_profile=end_profile)

    monkeypatch.setattr(refit, "candidate_library", spy)
    args = (model, start, data, ["guide_friction_horizontal"], train, hold, np.array([0.0, 1.0]))
    built = refit.converged_references(*args)
    rounds = len(built_for)
    assert rounds >= 2 and built_for[0] == start.constants.C1
    built_for.clear()
    handed = refit.converged_references(*args, library=first)
    assert len(built_for) == rounds - 1
    assert start.constants.C1 not in built_for
    # the same fits of the same columns: rounding only
    np.testing.assert_allclose(handed.constants.as_array(), built.constants.as_array(), rtol=1e-12)
    # each rebuilt library has the end effects' fall-off handed in (the scanned one), not the default
    widths.clear()
    scanned = EndProfile(0.02, "rounded")
    refit.converged_references(*args, end_profile=scanned)
    assert widths and set(widths) == {scanned}


# --- the compensation study ------------------------------------------------------------------------------
def test_the_compensation_studys_after_regulator_compensates_the_found_force(model):
    """A found constant horizontal force, the papers' constants before and after, 1 s of the
    sinusoid on the default twin (which carries the force): the regulator with the force compensated
    runs a different closed loop from the base one and tracks the horizontal axis better over its
    second half."""
    scenario = dataclasses.replace(paper_scenarios()["sinusoid"], duration=1.0)
    study = compensation_study(_force_found(model), model, scenario=scenario)
    assert not np.array_equal(study.result_before.u, study.result_after.u)
    # the horizontal tracking error over the second half (the papers' metrics start at 8 s)
    errors = [
        np.sqrt(np.mean((res.x[2] - res.reference[3])[res.t >= 0.5] ** 2))
        for res in (study.result_before, study.result_after)
    ]
    assert errors[1] < errors[0]
