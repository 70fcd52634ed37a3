"""Properties of ``maglev_oc.identification`` from the survivors of the seed-39 mutation run:

* a twin check whose run fails (here: a reference that starts inside the lower stopper, 5 mm
  against the stopper's 8 mm, so the first sample hits it) is a result of the convention
  (``maglev_oc.results.check_result``) that says so: success False, status ``"failed"``, the
  simulator's message, and the seeds it was asked for;
* a feasibility violation names the bounds it was checked against: the "outside LO..HI mm" of
  every message (set-points and simulated run) are the FeasibleSet's bounds in mm, for bounds
  drawn at random (seeded). Tolerance: relative 1e-5, the six significant digits of ``:g``; the
  run's own range is printed with ``.2f`` (0.005 mm);
* with acceleration terms in a parameter layout, the layout's accelerations are the model's own
  (``StageModel.dynamics`` with the estimated constants put in) plus each term's function
  evaluated with *its* slice of theta: two terms with different parameter counts (guide friction
  with 2, a constant force with 1), and the reading's accelerations are those at the gap reading
  plus the offset. Tolerance: 1e-9 relative + 1e-12 absolute, the round-off of two CasADi
  evaluations of the same formulas (the accelerations are of order 1-100 m/s^2);
* a written design's MATLAB file holds the design's metadata under ``metadata``: the same as the
  CSV's ``# key: value`` header, and its kind, targets, description and sample rate are the
  design JSON's (read back with ``scipy.io.loadmat``, compared as strings: exact).
"""

from __future__ import annotations

import json
import re
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.io

from maglev_oc.identification.design import (
    REFERENCE_RATE_HZ,
    CurrentBudget,
    ExperimentDesign,
    FeasibleSet,
    Prediction,
    SampledReference,
    check_on_twin,
    write_design,
)
from maglev_oc.identification.layout import ParameterLayout
from maglev_oc.model.hardware import STOPPER_GAP
from maglev_oc.regression.base import CONSTANT_NAMES
from maglev_oc.regression.terms import constant_force, guide_friction
from maglev_oc.results import check_result


def _reference(gap: float, n: int = 200, name: str = "reference", description: str = "") -> SampledReference:
    """A constant set-point (gap [m], position 0) sampled at the reference rate."""
    values = np.zeros((6, n))
    values[0] = gap
    return SampledReference(np.arange(n) / REFERENCE_RATE_HZ, values, name, description)


def _prediction(model, violations=()) -> Prediction:
    """A prediction for C1..C4 with 10 % standard errors (only its names and stderr are read)."""
    nominal = np.array(model.constants.as_array())
    return Prediction(
        CONSTANT_NAMES,
        nominal,
        np.diag((0.1 * nominal) ** 2),
        1.0,
        np.array([1.0, 2.0]),
        1.5,
        np.array([15e-3, 25e-3]),
        np.array([-40e-3, 40e-3]),
        tuple(violations),
    )


# --- a failed twin check -------------------------------------------------------------------
def test_a_twin_check_whose_run_fails_says_so_with_its_seeds(model):
    assert 5e-3 < STOPPER_GAP[0]  # the reference starts inside the lower stopper
    seeds = (3, 5)
    check = check_on_twin(_reference(5e-3, name="into_stopper"), _prediction(model), model=model, seeds=seeds)
    check_result(check)
    assert check.success is False
    assert check.status == "failed"
    assert "stopper" in check.message
    assert check.seeds == seeds
    assert check.reference == "into_stopper"
    assert check.to_dict()["seeds"] == list(seeds)


# --- violation messages name the bounds ----------------------------------------------------
_OUTSIDE = re.compile(
    r"^(simulated )?(\S+(?: set-point)?) (-?[\d.]+)\.\.(-?[\d.]+) mm outside (\S+)\.\.(\S+) mm$"
)


@pytest.mark.parametrize("seed", range(4))
def test_violation_messages_give_the_feasible_sets_bounds_in_mm(seed):
    rng = np.random.default_rng(seed)
    fs = FeasibleSet(
        gap=(rng.uniform(11e-3, 14e-3), rng.uniform(20e-3, 24e-3)),
        position=(rng.uniform(-44e-3, -30e-3), rng.uniform(30e-3, 44e-3)),
        true_gap=(rng.uniform(8.5e-3, 10e-3), rng.uniform(26e-3, 29e-3)),
        true_position=(rng.uniform(-49e-3, -45e-3), rng.uniform(45e-3, 49e-3)),
    )
    n = 50
    values = np.zeros((6, n))
    values[0] = np.linspace(fs.gap[0] - 1e-3, fs.gap[1] + 1e-3, n)
    values[3] = np.linspace(fs.position[0] - 2e-3, fs.position[1] + 2e-3, n)
    ref = SampledReference(np.arange(n) / REFERENCE_RATE_HZ, values)
    x = np.zeros((4, n))
    x[0] = np.linspace(fs.true_gap[0] - 0.5e-3, fs.true_gap[1] + 0.5e-3, n)
    x[2] = np.linspace(fs.true_position[0] - 1e-3, fs.true_position[1] + 1e-3, n)
    run = SimpleNamespace(success=True, message="", x=x, u=np.zeros((2, n)))
    out = fs.violations(ref, run)
    expected = {
        ("gap set-point", False): (values[0], fs.gap),
        ("position set-point", False): (values[3], fs.position),
        ("gap", True): (x[0], fs.true_gap),
        ("position", True): (x[2], fs.true_position),
    }
    seen = set()
    for message in out:
        m = _OUTSIDE.match(message)
        assert m, message
        key = (m.group(2), m.group(1) is not None)
        signal, (lo, hi) = expected[key]
        seen.add(key)
        assert float(m.group(3)) == pytest.approx(signal.min() * 1e3, abs=0.005 + 1e-9), message
        assert float(m.group(4)) == pytest.approx(signal.max() * 1e3, abs=0.005 + 1e-9), message
        assert float(m.group(5)) == pytest.approx(lo * 1e3, rel=1e-5), message
        assert float(m.group(6)) == pytest.approx(hi * 1e3, rel=1e-5), message
    assert seen == set(expected)


# --- the layout's accelerations with terms ---------------------------------------------------
def test_layout_accelerations_are_the_models_plus_each_term_on_its_own_parameters(model):
    friction = guide_friction(model.params, "horizontal")
    force = constant_force(model.params, "vertical")
    assert (friction.n_parameters, force.n_parameters) == (2, 1)
    layout = ParameterLayout(model, ("C2", "C3", "gap_offset"), (friction, force))
    assert layout.names[:3] == ("C2", "C3", "gap_offset")
    rng = np.random.default_rng(39)
    for _ in range(5):
        c2, c3 = model.constants.C2 * rng.uniform(0.8, 1.2), model.constants.C3 * rng.uniform(0.8, 1.2)
        offset = rng.uniform(-1e-3, 1e-3)
        p_friction = rng.uniform([1.0, 5.0], [5.0, 50.0])
        p_force = rng.uniform(-3.0, 3.0, 1)
        theta = np.concatenate([[c2, c3, offset], p_friction, p_force])
        x = np.array([rng.uniform(12e-3, 22e-3), rng.uniform(-0.05, 0.05), rng.uniform(-0.03, 0.03), 0.0])
        x[3] = rng.uniform(0.002, 0.1) * rng.choice([-1.0, 1.0])
        u = rng.uniform(-3.0, 3.0, 2)
        fitted = model.with_constants(model.constants.replace(C2=c2, C3=c3))

        def expected(x_true, fitted=fitted, u=u, p_friction=p_friction, p_force=p_force):
            base = fitted.dynamics(x_true, u)[[1, 3], 0]
            du = np.zeros(2)
            extra = (
                np.asarray(friction.function(x_true, u, du, p_friction)).ravel()
                + np.asarray(force.function(x_true, u, du, p_force)).ravel()
            )
            return base + extra

        got_true = np.asarray(layout.acceleration_true(x, u, theta)).ravel()
        np.testing.assert_allclose(got_true, expected(x), rtol=1e-9, atol=1e-12)
        shifted = x.copy()
        shifted[0] += offset
        got_reading = np.asarray(layout.acceleration_reading(x, u, theta)).ravel()
        np.testing.assert_allclose(got_reading, expected(shifted), rtol=1e-9, atol=1e-12)


# --- the MATLAB file's metadata ----------------------------------------------------------------
def test_the_mat_file_holds_the_designs_metadata(model, tmp_path):
    n = 120
    values = np.zeros((6, n))
    values[0] = 20e-3 + 1e-3 * np.sin(np.arange(n) / 10)
    values[3] = 5e-3 * np.cos(np.arange(n) / 15)
    ref = SampledReference(np.arange(n) / REFERENCE_RATE_HZ, values, "hand_made", "a hand-made reference")
    design = ExperimentDesign(
        kind="multisine",
        reference=ref,
        targets=("C1", "C2"),
        purpose="the metadata test",
        prediction=_prediction(model),
        budget=CurrentBudget(),
        baseline=None,
        settings={"seed": 39},
    )
    paths = write_design(tmp_path / "out", design)
    mat = scipy.io.loadmat(paths["mat"], squeeze_me=True, struct_as_record=False, chars_as_strings=True)
    assert "metadata" in mat
    meta = {k: str(getattr(mat["metadata"], k)) for k in mat["metadata"]._fieldnames}
    header = {}
    for line in paths["csv"].read_text(encoding="utf-8").splitlines():
        if line.startswith("# "):
            key, _, value = line[2:].partition(": ")
            header[key.replace(" ", "_")] = value
    assert meta == header
    js = json.loads(paths["json"].read_text(encoding="utf-8"))
    assert meta["design"] == js["kind"] == "multisine"
    assert meta["targets"].split() == js["targets"] == ["C1", "C2"]
    assert meta["description"] == js["reference"]["description"] == "a hand-made reference"
    assert float(meta["sample_rate_hz"]) == js["reference"]["sample_rate_hz"] == REFERENCE_RATE_HZ
