"""Diagnosis properties from the survivors of the seed-34 mutation run at ef280fd (issue 21), each a
property of a result a user sees, not of one line:

* A refit adopts only positive, finite constants of a moving axis: a fitted zero, a negative or a
  non-finite value, or a locked axis's, keeps the model's constant.
* A diagnosis's ``to_dict`` (the JSON the CLI writes) follows the result convention: success,
  status and message with their values, and it survives a JSON round trip.
* A guide waviness the motor does not explain (a force periodic in the position at 45 mm) is found
  by the whole diagnosis, at its period, with about its size.
* The pooled z of the blocks' log-ratios equals its mean over the long-run standard error
  computed here independently (per log: the square of the summed deviations from the overall mean).
"""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.data.log import Log
from maglev_oc.diagnosis.pipeline import diagnose
from maglev_oc.diagnosis.refit import fitted_model
from maglev_oc.diagnosis.selection import _block_z
from maglev_oc.regression.base import CONSTANT_AXIS, CONSTANT_NAMES
from maglev_oc.results import AXES, check_result
from tests.diagnosis_support import stub_diagnosis
from tests.test_regression import GAP, _synthetic


def _fit(values: dict[str, float]) -> SimpleNamespace:
    return SimpleNamespace(value=lambda name: values[name])


@pytest.mark.parametrize("bad", [0.0, -0.0, -3.0, math.nan, math.inf])
def test_a_refit_keeps_the_models_constant_where_the_fit_is_not_positive(model, bad):
    """C2 fitted to ``bad`` keeps the model's C2 (a fitted 0 is what a column that vanishes on the
    fitted rows gives: no information, not a zero constant); every positive fit of a moving
    axis is adopted exactly, and a locked axis's constant is the model's whatever its fit."""
    c0 = dict(zip(CONSTANT_NAMES, model.constants.as_array(), strict=True))
    fitted = {name: 1.25 * c0[name] for name in CONSTANT_NAMES}
    fitted["C2"] = bad
    out = fitted_model(model, _fit(fitted), np.array([True, True]), "test")
    got = dict(zip(CONSTANT_NAMES, out.constants.as_array(), strict=True))
    assert got["C2"] == c0["C2"]
    for name in ("C1", "C3", "C4"):
        assert got[name] == fitted[name]
    locked = np.array([AXES[a] == "vertical" for a in range(2)])  # horizontal axis held
    out = fitted_model(model, _fit(fitted), locked, "test")
    got = dict(zip(CONSTANT_NAMES, out.constants.as_array(), strict=True))
    for name in CONSTANT_NAMES:
        moving = CONSTANT_AXIS[name] == "vertical" and name != "C2"
        assert got[name] == (fitted[name] if moving else c0[name]), name


@pytest.mark.parametrize(
    ("success", "status", "message"),
    [(True, "nothing_found", "no missing effect found"), (False, "unexplained_only", "a residual at 60 mm")],
)
def test_a_diagnosis_to_dict_carries_its_outcome_and_round_trips_through_json(success, status, message):
    """The dict the CLI writes has the convention's success, status and message with the
    diagnosis's values (both outcomes, so a constant cannot pass), and the logs, holdout sizes,
    settings and timings; it is plain JSON (dumped and loaded, it is equal)."""
    d = stub_diagnosis(success, status, message, sources=("a.csv", "b.csv"), ranking=[("cogging", 0.12)])
    check_result(d)
    out = d.to_dict()
    assert out["success"] is success and out["status"] == status and out["message"] == message
    assert out["logs"] == ["a.csv", "b.csv"]
    assert out["holdout"] == {"fraction": 0.25, "samples": 1, "fit_samples": 2}
    assert out["settings"] == {"holdout_fraction": 0.25} and out["timings"] == {"total": 1.5}
    assert out["error_before"] == {"vertical": 0.5, "horizontal": 0.25}
    assert out["candidate_ranking"] == [{"name": "cogging", "holdout_gain": 0.12}]
    assert json.loads(json.dumps(out)) == out


def _z_short_logs(ratios: np.ndarray, logs: np.ndarray) -> float:
    """Mean / standard error with, per log of fewer than 4 blocks, the long-run variance the square
    of its summed deviations from the overall mean (the periodogram at zero frequency)."""
    mean = ratios.mean()
    total = sum(np.sum(ratios[logs == s] - mean) ** 2 for s in np.unique(logs))
    return mean / (math.sqrt(total) / ratios.size)


def test_the_pooled_z_of_short_logs_is_the_mean_over_its_long_run_standard_error():
    """Logs of 2 and 3 blocks (too short for a periodogram): the z is the mean log-ratio over the
    standard error from the summed deviations per log, to round-off (1e-12 relative: a handful of
    sums). The deviations are from the overall mean: shifting every ratio by a constant moves
    the mean and keeps the standard error."""
    rng = np.random.default_rng(34)
    ratios = 0.3 + rng.standard_normal(8)
    logs = np.array([0, 0, 1, 1, 1, 2, 2, 2])
    z = _block_z(ratios, logs, 0.5)
    assert z == pytest.approx(_z_short_logs(ratios, logs), rel=1e-12)
    shifted = _block_z(ratios + 1.0, logs, 0.5)
    assert shifted / z == pytest.approx((ratios.mean() + 1.0) / ratios.mean(), rel=1e-12)


def test_a_guide_waviness_at_a_period_no_motor_explains_is_found_at_that_period(model):
    """The synthetic 20 s log of the regression tests (position sweeping +-35 mm) with a horizontal
    force periodic in the position, 0.05 m/s^2 sin(2 pi x3 / 45 mm), that the currents do not
    carry: the trace's unexplained peak is refined, a waviness candidate at it joins the library
    and is chosen. Its period within 1 % of 45 mm (about a fifth of the refinement's resolution
    over 1.5 periods of travel; measured 0.45 %), its horizontal contribution within 25 % of the
    force's RMS 0.05 / sqrt(2) m/s^2 (measured 12 %: the fit shares it with the constants)."""
    log = _synthetic(model, seconds=20.0, position_noise=2e-6, seed=3)
    l1 = float(model.coefficients(GAP)[0, 0])
    u = np.array(log.u)
    u[0] += 0.05 * np.sin(2 * np.pi * log.x[2] / 0.045) / l1
    d = diagnose([Log(log.t, log.x, u, metadata=log.metadata, source=log.source)], min_duration=5.0)
    assert d.status == "effects_found" and len(d.effects) == 1, d.report()
    effect = d.effects[0]
    assert effect.name.startswith("guide_waviness")
    assert effect.parameters["period"].value == pytest.approx(0.045, rel=0.01)
    assert effect.contribution_rms["horizontal"] == pytest.approx(0.05 / math.sqrt(2), rel=0.25)
