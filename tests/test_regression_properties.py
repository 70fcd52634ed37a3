"""The shared regression layer's data preparation and small helpers, against independent checks.

* The prepared states: the gap rate and the position rate are the derivatives of the gap and the
  position (checked against central differences of the prepared positions themselves, which
  are smooth: the SG estimates of a 1 kHz log agree with them to a small fraction of the speed);
* logs of different rates are refused (a 2x mismatch is not a rounding of the time stamps);
* the settings record the band asked for; sample masks given as 0/1 integers mean what booleans
  mean; a term acts on its own axis only; a zero sine/cosine pair has no phase, not an error.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_oc.data.log import Log
from maglev_oc.errors import InputError
from maglev_oc.regression.data import prepare
from maglev_oc.regression.terms import amplitude_phase, viscous_friction


@pytest.fixture(scope="module")
def prepared(twin_log):
    return prepare([twin_log], bandwidth=10.0)


def test_the_prepared_rates_are_the_derivatives_of_the_prepared_positions(prepared):
    d = prepared
    v = d.valid
    for pos, rate in ((0, 1), (2, 3)):
        diff = np.gradient(d.x[pos], d.sample_time)
        scale = np.std(d.x[rate][v])
        assert scale > 0
        # the SG rate and the difference of the SG position: the same signal within 5 % of its spread
        assert np.sqrt(np.mean((d.x[rate][v] - diff[v]) ** 2)) < 0.05 * scale, (pos, rate)


def test_logs_of_different_rates_are_refused(twin_log):
    # every second sample: the same run at 500 Hz beside the 1 kHz one
    half = Log(twin_log.t[::2], twin_log.x[:, ::2], twin_log.u[:, ::2], source="half.csv")
    with pytest.raises(InputError, match=r"half\.csv"):
        prepare([twin_log, half], bandwidth=10.0)


def test_the_settings_record_the_band_and_masks_take_integers(prepared):
    assert prepared.settings["bandwidth_hz"] == 10.0
    n = prepared.n
    keep = np.zeros(n, dtype=int)
    keep[: n // 2] = 1
    as_int = prepared.masks(0.25, samples=[keep])
    as_bool = prepared.masks(0.25, samples=[keep.astype(bool)])
    for a, b in zip(as_int, as_bool, strict=True):
        np.testing.assert_array_equal(a, b)
    assert not np.any(as_int[0][n // 2 :])  # nothing past the mask is fitted


@pytest.mark.parametrize(("axis", "row", "rate"), [("vertical", 0, 1), ("horizontal", 1, 3)])
def test_a_term_acts_on_its_own_axis_only(axis, row, rate):
    term = viscous_friction(axis)
    x = np.array([0.02, 0.1, 0.0, -0.2])
    acc = np.asarray(term.function(x, [0, 0], [0, 0], [3.0])).ravel()
    assert acc[row] == pytest.approx(-3.0 * x[rate]) and acc[1 - row] == 0


def test_a_zero_sine_cosine_pair_has_no_phase():
    out = amplitude_phase("N")(np.zeros(2), np.eye(2), {})
    assert out["amplitude"].value == 0 and math.isnan(out["amplitude"].stderr)
    assert math.isnan(out["phase"].stderr)


def test_the_long_run_covariance_of_several_logs_adds_each_logs_own():
    """covariance.per_log_long_run (the meat of every equation-error fit and of the diagnosis's
    halves rule): over samples labelled by log, the sum of each log's averaged periodogram at its
    own number of frequencies, the same as long_run_covariance over the logs as a list; the logs'
    order in the series does not matter (each log's samples are taken in their order)."""
    from maglev_oc.regression.covariance import (
        frequencies_for,
        long_run_covariance,
        per_log_long_run,
        periodogram_long_run,
    )

    rng = np.random.default_rng(3)
    # 60 s and 20 s at 1 kHz: 15 and 5 frequencies each (20 over the two taken as one)
    parts = [rng.normal(size=(3, n)).cumsum(axis=1) * 1e-3 for n in (60_000, 20_000)]
    series = np.concatenate(parts, axis=1)
    labels = np.repeat([5, 2], [60_000, 20_000])
    meat, m = per_log_long_run(series, labels, 1e-3)
    by_hand = sum(periodogram_long_run(p, frequencies_for(p.shape[1], 1e-3)) for p in parts)
    assert m == frequencies_for(60_000, 1e-3) + frequencies_for(20_000, 1e-3) == 20
    np.testing.assert_allclose(meat, 0.5 * (by_hand + by_hand.T), rtol=1e-12)
    listed = long_run_covariance(parts, np.eye(3), 1e-3).covariance
    np.testing.assert_allclose(meat, listed, rtol=1e-12)
    swapped, _ = per_log_long_run(np.concatenate(parts[::-1], axis=1), labels[::-1], 1e-3)
    np.testing.assert_allclose(swapped, meat, rtol=1e-12)
