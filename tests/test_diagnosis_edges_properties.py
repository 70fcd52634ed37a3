"""Edges of the diagnosis that the scenario tests do not reach: what it says when it has nothing
to predict or only confounded candidates to show (issue 21: survivors of a mutation run at
31d4cd9, seed 33, each turned into a property)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from maglev_oc.diagnosis.pipeline import _outcome
from maglev_oc.diagnosis.prediction import output_error
from maglev_oc.diagnosis.trace import Trace, unexplained_periods
from maglev_oc.regression.data import prepare
from tests.test_regression import _synthetic


def test_with_no_window_in_the_held_out_block_the_output_error_is_undefined_on_both_axes(model):
    """No held-out sample, so no 50 ms window to simulate: both axes' output error are NaN (not
    a number for one axis and a crash for the other); with the held-out quarter, the moving
    (horizontal) axis gets a finite error and the held vertical axis stays NaN."""
    data = prepare([_synthetic(model, seconds=12.0, position_noise=2e-6)], bandwidth=10.0)
    none = output_error(data, np.zeros(data.n, dtype=bool), model)
    assert math.isnan(none["vertical"]) and math.isnan(none["horizontal"])
    _, hold = data.masks(0.25)
    some = output_error(data, hold, model)
    assert math.isnan(some["vertical"]) and math.isfinite(some["horizontal"])


def test_one_window_in_the_held_out_block_is_enough_for_an_output_error(model):
    """A held-out block holding exactly one 50 ms window: its error is the RMS over that window of
    the simulated position against the logged one, recomputed here from ``simulate_windows`` (the
    moving axis finite, the held one NaN); one window is data, not nothing."""
    from maglev_oc.validation import simulate_windows

    data = prepare([_synthetic(model, seconds=12.0, position_noise=2e-6)], bandwidth=10.0)
    h = round(0.05 / data.sample_time)
    _, hold = data.masks(0.25)
    first = int(np.flatnonzero(hold)[0])
    one = np.zeros(data.n, dtype=bool)
    one[first : first + h + 1] = True  # room for one window and no second start
    err = output_error(data, one, model)
    traj, meas = simulate_windows(data, np.array([first]), h, model)
    rms = np.sqrt(np.mean((traj[[0, 2]] - meas[[0, 2]]).reshape(2, -1) ** 2, axis=1))
    assert math.isnan(err["vertical"]) and err["horizontal"] == rms[1]
    assert math.isfinite(err["horizontal"])


def test_a_horizon_of_one_sample_simulates_one_step(model):
    """The output error's windows last ``horizon`` rounded to samples, at least one: a horizon of
    one sample (or less) is a one-step prediction, recomputed here from ``simulate_windows`` with
    h = 1 on the same window starts (seed 65: a floor of 2 samples went unseen)."""
    from maglev_oc.validation import simulate_windows, window_starts

    data = prepare([_synthetic(model, seconds=12.0, position_noise=2e-6)], bandwidth=10.0)
    _, hold = data.masks(0.25)
    ts = data.sample_time
    starts = window_starts(data, hold, 1, round(0.25 / ts))
    traj, meas = simulate_windows(data, starts, 1, model)
    rms = np.sqrt(np.mean((traj[[0, 2]] - meas[[0, 2]]).reshape(2, -1) ** 2, axis=1))
    for horizon in (ts, 0.4 * ts):
        assert output_error(data, hold, model, horizon=horizon)["horizontal"] == rms[1]


def test_a_diagnosis_with_only_confounded_candidates_says_none_was_separable():
    """Nothing claimed and nothing unexplained, but candidates that explain part of the residual
    and cannot be told from the constants: the outcome says no effect could be separated (not
    that the base model explains the log to its noise) and how many were not separable."""
    sel = SimpleNamespace(base=SimpleNamespace(compensated=True))
    data = SimpleNamespace(current_noise=np.zeros(2))
    status, success, message = _outcome([], ["a", "b"], [], sel, data)
    assert status == "nothing_found" and success
    assert message == (
        "no effect this log can separate from the constants found; 2 candidate(s) not separable on this log"
    )
    _, _, clean = _outcome([], [], [], sel, data)
    assert clean == "no missing effect found: the base model explains the log to its noise"
    # nothing found, but a refitted constant no stage of this design has (noisy pair 9922: C1 at
    # 0.25 for the true 14.7 beside an unclaimed commutation offset and cable carrier): the log is
    # not explained to its noise, and the outcome does not say it is
    _, _, warned = _outcome([], [], [], sel, data, ("C1 refitted beside the effects is 0.2529",))
    assert "explains the log to its noise" not in warned
    assert warned.startswith("no effect found, but a refitted constant is one no stage of this design has")


def test_the_strongest_unexplained_peak_of_an_axis_is_the_one_reported():
    """Periodogram peaks that match no motor period are waviness candidates, at most one per axis:
    the one explaining the largest share, whatever its period; a peak at a motor period (within
    1.5 %) is never one."""
    motor = {"slot_pitch": 0.012, "pole_pitch": 0.024}
    peaks = [
        ("horizontal", 0.0171, 0.04),
        ("horizontal", 0.0452, 0.21),  # the strongest unexplained
        ("horizontal", 0.0241, 0.5),  # the pole pitch, 0.4 % off: explained
        ("vertical", 0.061, 0.03),
    ]
    tr = Trace(np.zeros(0), np.zeros((2, 0)), motor, peaks, {}, np.zeros(0), np.zeros((2, 0)))
    assert unexplained_periods(tr) == [("horizontal", 0.0452), ("vertical", 0.061)]
