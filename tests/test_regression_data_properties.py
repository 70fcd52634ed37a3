"""The data preparation shared by identify and diagnose (``maglev_oc.regression.data``) against
its defining properties: the matching filter F makes the Savitzky-Golay acceleration of the
positions equal to F applied to the true acceleration; rate reduction is block means; the
estimated floor of the logged currents' error is the variance of a planted white noise times
the share of it that did not reach the plant. About 1 s of CPU."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.data.logs import Log
from maglev_oc.estimation.differentiate import SavitzkyGolay
from maglev_oc.regression.data import logging_error_share, matching_kernel, prepare, reduce_rate
from tests.test_regression import _synthetic


def test_the_matching_filter_turns_the_true_acceleration_into_the_sg_estimate():
    """Positions a sum of sines at 1 kHz: the SG acceleration (10 Hz band) equals the true
    acceleration filtered by F away from the edges, to 1e-6 of its size (measured 3e-8: F is
    exact for signals quadratic between samples, and the sines' higher derivatives between
    samples at 2-9 Hz are of order (w T)^2 / 12 ~ 3e-6 relative, mostly cancelling); F is
    symmetric with unit DC gain."""
    ts = 1e-3
    sg = SavitzkyGolay(ts, bandwidth=10.0)
    t = np.arange(6000) * ts
    w = 2 * math.pi * np.array([2.0, 5.0, 9.0])
    phase = np.array([[0.3], [1.1], [2.0]])
    y = np.sum(np.sin(np.outer(w, t) + phase), axis=0) * 1e-3
    acc = -np.sum((w**2)[:, None] * np.sin(np.outer(w, t) + phase), axis=0) * 1e-3
    kernel = matching_kernel(sg)
    assert kernel.sum() == pytest.approx(1.0, rel=1e-12)
    # symmetric up to the polynomial division's round-off, which grows along its recurrence over
    # the 53 taps (measured 1e-13 of the largest tap on one machine, 2e-11 on an AMD EPYC whose
    # libraries round otherwise); a tap out of place would be off by a share of the largest tap
    assert_allclose(kernel, kernel[::-1], rtol=0, atol=1e-9 * np.max(np.abs(kernel)))
    est = np.ravel(sg(y).acceleration)
    filtered = np.convolve(acc, kernel, mode="same")
    edge = max(sg.acceleration_window, kernel.size)
    inner = slice(edge, -edge)
    assert np.max(np.abs(est[inner] - filtered[inner])) < 1e-6 * np.max(np.abs(acc))
    # and F is not the identity: at 9 Hz it attenuates measurably (0.5 % here)
    assert np.max(np.abs(filtered[inner] - acc[inner])) > 1e-3 * np.max(np.abs(acc))


def test_rate_reduction_is_block_means():
    rng = np.random.default_rng(0)
    n = 5003  # not a multiple of the block: the tail is dropped
    t = np.arange(n) / 5000.0
    x = rng.standard_normal((4, n))
    u = rng.standard_normal((2, n))
    log = Log(t, x, u, source="r")
    reduced, q = reduce_rate(log, 1000.0)
    assert q == 5 and reduced.n == n // 5
    assert_allclose(reduced.x, x[:, :5000].reshape(4, 1000, 5).mean(axis=2), rtol=1e-12)
    assert_allclose(reduced.u, u[:, :5000].reshape(2, 1000, 5).mean(axis=2), rtol=1e-12)
    assert reduced.sample_time == pytest.approx(1e-3, rel=1e-9)
    same, q1 = reduce_rate(log, 5000.0)
    assert q1 == 1 and same is log


@pytest.mark.parametrize(
    "measured, control_rate, share",
    [
        (True, None, 1.0),  # sensor noise is all error
        (False, None, 0.8),  # the rig's 5 kHz commands logged at 1 kHz: 1 - 1/5 of the floor
        (False, 2000.0, 0.5),  # a 2 kHz loop: 1 - 1/2
        (False, 1000.0, 0.0),  # logged at the control rate: every value was applied
    ],
)
def test_the_current_error_floor_is_the_planted_noise_times_its_share(model, measured, control_rate, share):
    """White noise of 0.01 A RMS added to the logged currents of a smooth sweep: the prepared
    current_noise is 1e-4 A^2 times the share that did not reach the plant (within 6 %: the
    floor is the median of a Welch spectrum over 15 % of the band, whose chi-square scatter
    biases a median by about 2 % low and whose spread over some 500 bins averages the rest)."""
    log = _synthetic(model, seconds=30.0, seed=4)
    rng = np.random.default_rng(7)
    noisy = dataclasses.replace(
        log, u=log.u + 0.01 * rng.standard_normal(log.u.shape), currents_measured=measured
    )
    assert logging_error_share(noisy, control_rate) == pytest.approx(share, abs=1e-9)
    data = prepare([noisy], bandwidth=10.0, control_rate=control_rate)
    assert_allclose(data.current_noise, share * 1e-4, rtol=0.06, atol=1e-12)
    off = prepare([noisy], bandwidth=10.0, control_rate=control_rate, logging_error=False)
    assert np.all(off.current_noise == 0.0)
