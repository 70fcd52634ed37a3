"""Properties of ``maglev_oc.identification`` from the survivors of the seed-41 mutation run:

* the smoothed set-points of a PRBS design are the response of the critically damped second-order
  filter to the levels held constant over each sample (zero-order hold, as the rig's set-point
  generator holds each bit): checked against the filter's closed-form solution, stepped sample by
  sample with the level held, both on hand-made levels and on the PRBS reference itself (its
  levels read back from r''). Tolerance: 1e-12 of the level's scale, round-off of the two
  exact solutions (scipy's matrix exponential against the closed form) over a few thousand steps;
  a linearly interpolated input moves the rates by ~1e-4 m/s at a 4 mm step;
* when a shape played on both axes has a larger log det than the best vertical shape paired with
  the best horizontal one (the pairing, re-scaled to the budget, loses), the D-optimal design keeps
  that joint shape: its settings name it on both axes, its reference is that shape's multisine and
  its prediction is that shape's; when the pairing wins, the pairing is kept;
* the eps-trend study records its whole wall time under ``timings["total"]`` (from its start to
  the end of its explanation, spanning every step), and its report and JSON carry it.
"""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.identification import eps_trend
from maglev_oc.identification.design import (
    REFERENCE_RATE_HZ,
    CurrentBudget,
    MultisineShape,
    Prediction,
    _smoothed_levels,
    design_experiment,
    multisine_reference,
    prbs_reference,
)
from maglev_oc.identification.experiments import TWIN_TRUTH
from maglev_oc.identification.layout import CONSTANT_NAMES
from tests.test_identification_round2_properties import _trend


# --- the PRBS set-points: a zero-order hold through the smoothing filter -----------------------------
def _held_filter(levels: np.ndarray, t: np.ndarray, w: float) -> np.ndarray:
    """(r, r') of the critically damped filter r'' = w^2 (u - r) - 2 w r', started at rest at
    levels[0], with u = levels[k] held over [t_k, t_k+1): the closed form of each interval, with
    e = r - u: e(s) = (e0 + (v0 + w e0) s) exp(-w s), r'(s) = (v0 - w (v0 + w e0) s) exp(-w s)."""
    r = np.empty(levels.size)
    v = np.empty(levels.size)
    r[0], v[0] = levels[0], 0.0
    for k in range(levels.size - 1):
        h = t[k + 1] - t[k]
        e0 = r[k] - levels[k]
        b = v[k] + w * e0
        decay = math.exp(-w * h)
        r[k + 1] = levels[k] + (e0 + b * h) * decay
        v[k + 1] = (v[k] - w * b * h) * decay
    return np.vstack([r, v])


def test_smoothed_levels_hold_each_level_over_its_sample():
    """Levels that step (up, down, by different sizes) and change at every sample over a stretch:
    the smoothed (r, r') is the closed-form response to each level held over its sample, and r''
    is the filter's right-hand side at the held level. 1e-12 x the 5 mm level scale (and x w for the
    rates): round-off (measured 5e-16 m); the linear interpolation of the input instead of the hold
    moves r' by about w^2 x step x h / 2 = 1e-4 m/s at the 2.5 mm steps here."""
    w = 2 * math.pi * 1.5
    t = np.arange(1500) / REFERENCE_RATE_HZ
    levels = np.full(t.size, 20e-3)
    levels[100:400] = 22.5e-3
    levels[400:700] = 17e-3
    levels[700:1000] = 20e-3 + 2e-3 * np.sin(np.arange(300) / 7.0)  # a new level every sample
    levels[1000:] = 25e-3
    out = _smoothed_levels(levels, t, w)
    expected = _held_filter(levels, t, w)
    scale = 5e-3
    np.testing.assert_allclose(out[0], expected[0], rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(out[1], expected[1], rtol=0, atol=1e-12 * scale * w)
    acc = w**2 * (levels - expected[0]) - 2 * w * expected[1]
    np.testing.assert_allclose(out[2], acc, rtol=0, atol=1e-12 * scale * w**2)


def test_prbs_set_points_are_the_filter_driven_by_held_levels():
    """Each axis of a PRBS reference (the design's filter of 1.5 Hz, 2 pi x 1.5 rad/s): the level
    at each sample, read back from r'' = w^2 (u - r) - 2 w r', held over the sample, carries
    (r, r') to the next sample exactly as the closed-form filter does. The levels read back take
    the PRBS values offset +- amplitude x ramp (after the 2 s ramp: offset +- amplitude). Same
    tolerances as above (scale: the 2 and 30 mm amplitudes; measured 1e-17 m)."""
    w = 2 * math.pi * 1.5
    ref = prbs_reference(10.0)
    h = 1 / REFERENCE_RATE_HZ
    for row, offset, amp in ((0, 20e-3, 2e-3), (3, 0.0, 30e-3)):
        r, v, a = ref.values[row : row + 3]
        levels = r + (a + 2 * w * v) / w**2
        after_ramp = ref.t >= 2.0
        np.testing.assert_allclose(np.abs(levels[after_ramp] - offset), amp, rtol=0, atol=1e-9 * amp)
        decay = math.exp(-w * h)
        e0 = r[:-1] - levels[:-1]
        b = v[:-1] + w * e0
        np.testing.assert_allclose(r[1:], levels[:-1] + (e0 + b * h) * decay, rtol=0, atol=1e-12 * amp)
        np.testing.assert_allclose(v[1:], (v[:-1] - w * b * h) * decay, rtol=0, atol=1e-12 * amp * w)


# --- the D-optimal design: a joint shape that beats the pairing -----------------------------------------
JOINT = MultisineShape((0.1, 3.0), 6, 0.5)
"""Played on both axes, the best for C1 and the best overall."""
OTHER = MultisineShape((0.2, 2.0), 8, 1.0)
"""Played on both axes, the best for C2..C4, so the pairing is (vertical OTHER, horizontal JOINT)."""
DURATION = 10.0
V, H = 3e-3, 30e-3  # [m] the excursions the stub's fit_to_budget settles on


class _ShapeDesigner:
    """Stands for :class:`ExperimentDesigner`: recognises the shape of each axis of a reference
    (its rows against each shape's multisine) and predicts per axis: C1's variance from the
    horizontal shape (JOINT's 4x smaller), C2..C4's from the vertical one (OTHER's 4x smaller). The
    log det of each design is given: JOINT alone 5, OTHER alone 4, the pairing ``paired`` (a pairing
    re-scaled to the budget can lose information to a shape that fits it better on both axes)."""

    def __init__(self, paired: float):
        self.paired = paired
        self.calls: list[tuple[MultisineShape, MultisineShape]] = []
        self.rows = {
            s: multisine_reference(DURATION, vertical=s, horizontal=s, gap_amplitude=V, position_amplitude=H)
            for s in (JOINT, OTHER)
        }

    def _shape(self, values: np.ndarray, row: int) -> MultisineShape:
        (shape,) = [s for s, ref in self.rows.items() if np.array_equal(ref.values[row], values[row])]
        return shape

    @staticmethod
    def _prediction(log_det, var_h, var_v) -> Prediction:
        nominal = np.asarray(TWIN_TRUTH.as_array())
        rel = np.array([var_h, var_v, var_v, var_v])
        return Prediction(
            CONSTANT_NAMES,
            nominal,
            np.diag(rel * nominal**2),
            log_det,
            np.array([1.0, 3.0]),
            1.0,
            np.array([0.017, 0.023]),
            np.array([-0.03, 0.03]),
            (),
        )

    def papers_budget(self, duration, *, seed=0):
        return CurrentBudget(vertical=3.0, horizontal=1.0), self._prediction(-10.0, 1.0, 1.0)

    def predict(self, reference, *, effect=False, budget=None, run=None):
        return self._prediction(-10.0, 1.0, 1.0)  # the papers' excitation: far below every shape

    def fit_to_budget(self, make, budget, *, effect=False, iterations=4):
        ref = make(V, H)
        vertical, horizontal = self._shape(ref.values, 0), self._shape(ref.values, 3)
        self.calls.append((vertical, horizontal))
        var_h = 1e-4 if horizontal == JOINT else 4e-4
        var_v = 1e-4 if vertical == OTHER else 4e-4
        if vertical == horizontal:
            log_det = 5.0 if vertical == JOINT else 4.0
        else:
            log_det = self.paired
        return ref, self._prediction(log_det, var_h, var_v)


@pytest.mark.parametrize(
    ("paired", "vertical", "horizontal"),
    [(1.0, JOINT, JOINT), (9.0, OTHER, JOINT)],
    ids=["joint_shape_wins", "pairing_wins"],
)
def test_doptimal_keeps_the_larger_log_det_of_the_pairing_and_the_best_joint_shape(
    model, paired, vertical, horizontal
):
    """The pairing (vertical OTHER, horizontal JOINT) is tried; if its log det (1) is below JOINT's
    on both axes (5), the design is JOINT on both axes: settings, reference and prediction; if it
    is above (9), the pairing stays. Exact: the stub's numbers and the same multisine computation."""
    designer = _ShapeDesigner(paired)
    design = design_experiment("doptimal", DURATION, model=model, designer=designer, grid=(JOINT, OTHER))
    assert (OTHER, JOINT) in designer.calls  # the pairing was tried
    assert design.settings["vertical"] == vertical.to_dict()
    assert design.settings["horizontal"] == horizontal.to_dict()
    expected = multisine_reference(
        DURATION, vertical=vertical, horizontal=horizontal, gap_amplitude=V, position_amplitude=H
    )
    np.testing.assert_array_equal(design.reference.values, expected.values)
    assert design.prediction.log_det == max(paired, 5.0)
    # the candidates are JSON (the shape objects used in the search are not left in them)
    json.dumps(design.to_dict())
    assert [c["log_det"] for c in design.candidates[:2]] == [5.0, 4.0]


# --- the eps-trend study's wall time -------------------------------------------------------------------
def test_eps_trend_study_records_and_reports_its_total_wall_time(model, monkeypatch):
    """The study's timings hold its total under ``"total"``: from its start to its end, so at least
    the sum of its steps; the report prints it with ``.2f`` and the JSON carries it. The twin runs are
    replaced by trends (as in tests/test_identification_round2_properties.py) and the clock by one
    that advances by a power of two on each read, so every difference is exact."""
    t2 = ("C2", "C3", "C4")
    d3, d2 = _trend(CONSTANT_NAMES, (-0.04, 0.002, -0.02, -0.3)), _trend(t2, (0.002, -0.02, -0.3))
    f3, f2 = _trend(CONSTANT_NAMES, (0.06, 0.002, 0.03, 0.2)), _trend(t2, (0.002, 0.03, 0.2))
    log = SimpleNamespace(sample_time=1e-3)
    reads: list[float] = []

    def clock():
        reads.append(float(2 ** len(reads)) - 1.0)  # 0, 1, 3, 7, ...: each step takes a new time
        return reads[-1]

    def runs(model, friction, **kw):
        return (d3, d2, log, True) if friction == (None, None) else (f3, f2, log, True)

    monkeypatch.setattr(eps_trend, "_twin_trend", runs)
    monkeypatch.setattr(eps_trend, "_npfsi_trend", lambda *a, **k: (d3, True))
    monkeypatch.setattr(eps_trend, "_limit", lambda *a: d3)
    monkeypatch.setattr(eps_trend.time, "perf_counter", clock)
    study = eps_trend.eps_trend_study(model)
    monkeypatch.undo()
    total = study.timings["total"]
    assert total == reads[-1] - reads[0]  # the first read starts the study, the last ends it
    steps = [v for k, v in study.timings.items() if k != "total"]
    assert len(steps) == 4 and total >= sum(steps)
    assert f"total {total:.2f}" in study.report()
    assert study.to_dict()["timings"]["total"] == total


def test_eps_trend_study_status_is_one_of_its_documented_three(model, monkeypatch):
    """``EpsTrendStudy.status`` (its docstring): ``"reproduced"`` when with friction every constant
    moves the papers' way, ``"partly_reproduced"`` naming the rest otherwise, ``"failed"`` when a run
    did not complete; reports and the workflow compare it to these exact strings. The friction runs
    are replaced by the papers' own trends (every direction matches), then by the same with C4 of
    Table III reversed, then by a run that did not complete."""
    p3 = eps_trend._papers("table3", CONSTANT_NAMES)
    p2 = eps_trend._papers("table2", eps_trend.TABLE2_NAMES)
    d3 = _trend(CONSTANT_NAMES, (-0.04, 0.002, -0.02, -0.3))
    log = SimpleNamespace(sample_time=1e-3)
    reversed_c4 = p3.values.copy()
    reversed_c4[CONSTANT_NAMES.index("C4")] = reversed_c4[CONSTANT_NAMES.index("C4")][::-1]
    partly = eps_trend.EpsTrend("t", CONSTANT_NAMES, p3.eps, reversed_c4)
    cases = {
        "reproduced": ((p3, p2, log, True), None),
        "partly_reproduced": ((partly, p2, log, True), "C4"),
        "failed": ((p3, p2, log, False), None),
    }
    monkeypatch.setattr(eps_trend, "_npfsi_trend", lambda *a, **k: (d3, True))
    monkeypatch.setattr(eps_trend, "_limit", lambda *a: d3)
    for status, (friction_run, named) in cases.items():

        def runs(model, friction, run=friction_run, **kw):
            return (d3, p2, log, True) if friction == (None, None) else run

        monkeypatch.setattr(eps_trend, "_twin_trend", runs)
        study = eps_trend.eps_trend_study(model)
        assert study.status == status
        assert study.success == (status != "failed")
        assert named is None or f"Table III {named}" in study.message
