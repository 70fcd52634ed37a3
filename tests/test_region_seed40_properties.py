"""Region properties from the survivors of the seed-40 mutation run, each a property of a result a
user sees, not of one line:

* a linear regulator's loop is built for a set-point anywhere on its schedule, both ends
  included: at the first and the last scheduled gap it has the poles the gains were placed at
  (relative 1e-6, as at any node: no interpolation there); a set-point a hair outside either end
  is refused, and the message names its gap;
* a Monte Carlo simulator whose compiled C batch cannot be built says so (``compiled`` is False)
  and still runs, in CasADi's virtual machine, with the compiled batch's results (to rounding:
  the same expression graph) and the engine's (the same step run sample by sample);
* the SDP's ellipsoid keeps the horizontal reference clear of the position stoppers: its reach in
  e2 plus the reference orbit's whole amplitude (orbits with their peak in the sin part, in the
  cos part and in both) stays inside the position range, which binds (without it the reach is
  larger);
* the papers' reference is r_v = 20 + 5 cos(w0 t) mm, r_h = 30 sin(w0 t) mm (001 Sec. VI-B, 002
  Sec. 7.2): its samples and their first two derivatives are those closed forms at every t;
* the quantisation Monte Carlo of the study starts its runs, for a reference that moves, at
  states inside the certified set about the reference at t = 0, where its samples start: the
  start states mapped to error coordinates at phase 0 satisfy z' P z <= level, and their ratio
  is the one the check reports;
* a refutation found by Procedure 2's branch and bound is recorded with its own phase: the
  witness state of the result, at the witness phase, violates the binding constraint (evaluated
  independently through the physical state), for a sinusoid whose violations lie near phase pi.
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest

import maglev_oc.region.montecarlo as montecarlo
import maglev_oc.region.study as study
from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.control.gains import OMEGA0, PAPER_GAINS, axis_poles
from maglev_oc.control.linear_regulator import paper_linear_regulator
from maglev_oc.errors import InputError, SolverError
from maglev_oc.numerics import c_compiler
from maglev_oc.region.closed_loop import E2, Reference, RegulatorLoop
from maglev_oc.region.feasibility import NONLINEAR, FeasibleSet
from maglev_oc.region.montecarlo import BatchSimulator, regulator_state
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.region.roa import LinearizedLoop
from maglev_oc.region.sdp import PolygonBuilder, solve_sdp
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.scenarios import paper_scenarios
from maglev_oc.sim.twin import RigTwin
from tests.test_region_refutation_properties import _Ipopt, _physical

MM = 1e-3


@pytest.fixture(scope="module")
def loop():
    return RegulatorLoop()


# --- the linear regulator's loop on the whole schedule -------------------------------------------
def test_a_linear_loop_is_built_at_either_end_of_the_schedule_and_refused_beyond(model):
    """Schedule 12, 16, 20 mm: at 12 and 20 mm the loop's poles are the printed gains' FL poles
    (the design of paper_linear_regulator; relative 1e-6 as in tests/test_region_roa.py, the
    eigenvalues of a 10 x 10 matrix with poles up to ~100 rad/s); 1e-9 m below 12 mm or above
    20 mm (far above the rounding of 1e-2 m, 2e-18 m) the set-point is refused by its gap."""
    gaps = (12 * MM, 16 * MM, 20 * MM)
    linear = paper_linear_regulator(model, gaps=gaps)
    expect = np.sort_complex(
        np.concatenate([axis_poles(PAPER_GAINS["K_v"].printed), axis_poles(PAPER_GAINS["K_h"].printed)])
    )
    for gap in (gaps[0], gaps[-1]):
        lp = LinearizedLoop(model, linear, Reference.setpoint(gap, 0.01))
        np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(lp.A)), expect, rtol=1e-6)
    for gap in (gaps[0] - 1e-9, gaps[-1] + 1e-9):
        with pytest.raises(InputError, match=rf"set-point gap {re.escape(repr(gap))} m outside"):
            LinearizedLoop(model, linear, Reference.setpoint(gap))


# --- the Monte Carlo simulator without its compiled batch -----------------------------------------
def test_a_simulator_whose_c_batch_fails_to_build_runs_in_casadi_with_the_same_results(model, monkeypatch):
    """NativeBatch raising SolverError (a compilation that failed), with a compiler on the PATH as
    far as the simulator can tell: ``compiled`` is False and the runs are those of the compiled
    batch (when this machine has a compiler; 1e-9 relative, 1e-12 absolute: the same graph in C and
    in the virtual machine, as in tests/test_region_montecarlo.py) and of the engine run sample by
    sample from the papers' large step (1e-12: identical arithmetic)."""
    ctrl, twin = FeedbackLinearizingRegulator(model), RigTwin(model)
    duration = 0.05
    sc = paper_scenarios()["large_step"]
    rng = np.random.default_rng(5)
    n = 5  # the large step first, then starts around 20 mm
    x0 = np.vstack([0.02 + rng.uniform(-0.004, 0.004, n), rng.uniform(-0.2, 0.2, n), np.zeros((2, n))])
    x0[:, 0] = sc.x0
    c0 = regulator_state(x0, np.zeros((6, n)))
    compiled = None
    if c_compiler() is not None:
        native = BatchSimulator(twin, ctrl, duration=duration, compile=True, threads=1)
        assert native.compiled is True
        compiled = native.run(x0, c0, sc.sample(twin.sample_time)[1][:, : native.n_steps])

    def fails(step, **kwargs):
        raise SolverError("compiling the closed loop failed: (planted)")

    monkeypatch.setattr(montecarlo, "NativeBatch", fails)
    monkeypatch.setattr(montecarlo, "c_compiler", lambda: "/usr/bin/cc")
    sim = BatchSimulator(twin, ctrl, duration=duration, compile=True, threads=1)
    assert sim.compiled is False
    ref = sc.sample(twin.sample_time)[1][:, : sim.n_steps]
    out = sim.run(x0, c0, ref)
    assert out.status == "completed"
    names = ("min_margin", "max_current", "min_gap", "max_gap", "max_abs_position", "final_twin")
    if compiled is not None:
        for name in names:
            np.testing.assert_allclose(
                getattr(out, name), getattr(compiled, name), rtol=1e-9, atol=1e-12, err_msg=name
            )
    # the engine records x[k] before step k: one sample longer to see x[n]
    k = sim.n_steps
    res = ClosedLoop(twin, ctrl).run(dataclasses.replace(sc, duration=(k + 1) * twin.sample_time))
    np.testing.assert_allclose(out.min_gap[0], res.x[0, 1 : k + 1].min(), rtol=1e-12)
    np.testing.assert_allclose(out.max_current[0], np.hypot(*res.u[:, :k]).max(), rtol=1e-12)
    np.testing.assert_allclose(out.final_twin[:4, 0], res.x[:, k], rtol=1e-9, atol=1e-15)


# --- the SDP's room to the position stoppers ------------------------------------------------------
@pytest.mark.parametrize(
    "position_phase",
    [0.0, math.pi / 2, 3 * math.pi / 4],
    ids=["sin-part", "cos-part", "both-parts"],
)
def test_the_sdps_ellipsoid_keeps_the_whole_horizontal_orbit_inside_the_position_range(
    model, loop, position_phase
):
    """r_h = -4 + 30 sin(w0 t + phase) mm (the papers' amplitude, r_v their 20 + 5 cos): at
    w0 the steady-state error is zero, so the position orbit is r_h itself, spanning -34 to 26 mm.
    With stoppers at -36 and 30 mm the room is 2 mm below and 4 mm above; the SDP's ellipsoid
    {z' Q^-1 z <= 1} reaches sqrt(Q_e2e2) in e2 and must fit: -4 mm - 30 mm - reach >= -36 mm and
    -4 + 30 + reach <= 30 mm, to 1e-6 relative of the room (Clarabel's feasibility tolerance,
    1e-8, on a constraint scaled to about 1, with margin). Without the stoppers the SDP reaches
    further in e2 (the range binds)."""
    ref = Reference(20 * MM, -4 * MM, 5 * MM, 30 * MM, math.pi / 2, position_phase, OMEGA0)
    limited = FeasibleSet(model, position_range=(-36 * MM, 30 * MM))
    free = FeasibleSet(model, position_range=None)
    poly = PolygonBuilder(limited, loop).build(ref, 2 * MM)
    assert poly.success, poly.message
    status, Q, _ = solve_sdp(loop, ref, poly, limited, 0.05, (1.0, 1.0))
    assert status == "optimal" and Q is not None, status
    reach = math.sqrt(Q[E2, E2])
    low = ref.position - ref.position_amplitude - reach
    high = ref.position + ref.position_amplitude + reach
    room = 2 * MM
    assert low >= -36 * MM - 1e-6 * room and high <= 30 * MM + 1e-6 * room
    _, Q_free, _ = solve_sdp(loop, ref, poly, free, 0.05, (1.0, 1.0))
    assert math.sqrt(Q_free[E2, E2]) > 1.1 * room


# --- the papers' reference -----------------------------------------------------------------------
def test_the_papers_sinusoid_is_its_closed_form_with_its_derivatives():
    """r_v = 20 + 5 cos(w0 t) mm and r_h = 30 sin(w0 t) mm with their first and second time
    derivatives, at quarter periods and at arbitrary times over three periods (1e-12 in SI units:
    values up to 0.7 m/s^2, rounding ~1e-16 of that)."""
    ref = Reference.paper_sinusoid()
    w = OMEGA0
    period = 2 * math.pi / w
    t = np.concatenate([np.arange(5) * period / 4, np.random.default_rng(2).uniform(0, 3 * period, 9)])
    got = ref.signals(w * t)
    want = np.vstack(
        [
            20 * MM + 5 * MM * np.cos(w * t),
            -5 * MM * w * np.sin(w * t),
            -5 * MM * w**2 * np.cos(w * t),
            30 * MM * np.sin(w * t),
            30 * MM * w * np.cos(w * t),
            -30 * MM * w**2 * np.sin(w * t),
        ]
    )
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


# --- the quantisation Monte Carlo's starts --------------------------------------------------------
def test_the_quantisation_runs_start_inside_the_certified_set_about_the_reference_at_t0(
    model, loop, monkeypatch
):
    """A study of the papers' sinusoid alone (its certificate by Procedure 2; no 20 mm set-point,
    so the quantisation runs use the sinusoid's): the simulator is handed reference samples that
    start at t = 0 (the closed form r(0): 25 mm, 0 mm, ...; 1e-12 in SI) and start states whose
    error coordinates about r(0), z = error_state(x, xi, r, phase 0), lie in the certified set:
    V / level <= 1 (+1e-9: the round-off of mapping mm-sized errors through cm-sized states) and
    equal to the start ratios the check reports (1e-9 absolute, the same round-off)."""
    ref = Reference.paper_sinusoid()
    feasible = FeasibleSet(model)
    cert = Procedure2(feasible, loop, starts=2).run(ref)
    assert cert.success, cert.message
    rs = study.ReferenceStudy(ref, cert, None, None, {}, {})
    config = study.StudyConfig(
        setpoints_mm=(15.0,), sdp=False, linear=False, quantization_samples=8, horizon=0.004, compile=False
    )
    run = study._Run(model, config, feasible, loop, np.random.default_rng(0), lambda _m: None, {})
    calls = []
    original = BatchSimulator.run

    def recording(self, x0, c0, reference, *args, **kwargs):
        calls.append((np.array(x0), np.array(c0), np.array(reference)))
        return original(self, x0, c0, reference, *args, **kwargs)

    monkeypatch.setattr(BatchSimulator, "run", recording)
    fl = FeedbackLinearizingRegulator(model, loop.K_h, loop.K_v, omega0=loop.omega0)
    check = study._quantization(run, fl, [rs])
    assert check is not None and len(calls) == 1
    x0, c0, samples = calls[0]
    w = OMEGA0
    r0 = [25 * MM, 0.0, -5 * MM * w**2, 0.0, 30 * MM * w, 0.0]
    np.testing.assert_allclose(samples[:, 0], r0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(c0[:4], x0, rtol=0, atol=0)  # observers at the true state
    z = loop.error_state(x0, c0[4:], ref, 0.0)
    ratio = np.einsum("in,ij,jn->n", z, cert.P, z) / cert.level
    assert np.all(ratio <= 1 + 1e-9), ratio
    np.testing.assert_allclose(ratio, check.start_ratio, rtol=0, atol=1e-9)


# --- the phase of a refutation -------------------------------------------------------------------
def test_a_refutations_witness_violates_its_constraint_at_its_recorded_phase(model, loop):
    """Procedure 2 without gap stoppers for the papers' ellipse started half a period later (its
    largest gap, where the current limit is first violated, near phase pi), IPOPT reporting every
    start as failed: the upper bound comes from branch-and-bound refutations alone (measured: 6 in
    a row, 1.1-1.8 s). The result's witness is a point of V = level_upper (1e-9: rounding of the
    quadratic form) whose binding constraint, evaluated at the recorded phase through the physical
    state and FeasibleSet.evaluate, is negative; the phase lies in [0, 2 pi)."""
    p = Reference.paper_sinusoid()
    ref = dataclasses.replace(p, gap_phase=p.gap_phase + math.pi, position_phase=p.position_phase + math.pi)
    feasible = FeasibleSet(model, gap_range=None)
    proc = Procedure2(feasible, loop, starts=1, max_boxes=100_000)
    for name, (solver, ng) in list(proc.minimizer._solvers.items()):
        proc.minimizer._solvers[name] = (_Ipopt(solver, success=False), ng)
    res = proc.run(ref)
    refuted = [a for a in res.attempts if a.status == "refuted"]
    assert res.success and refuted and all(m.status == "not_found" for m in res.minima), res.message
    assert res.binding in NONLINEAR
    z, phase = res.witness, res.witness_phase
    assert z @ res.P @ z == pytest.approx(res.level_upper, rel=1e-9)
    assert 0.0 <= phase < 2 * math.pi
    h = dict(zip(NONLINEAR, _physical(feasible, loop, ref, z, phase)[2:], strict=True))
    assert h[res.binding][0] < 0, (res.binding, phase, h)
