"""The long-run (HAC) covariances of ``maglev_oc.regression.covariance`` against computations
written here from their definitions (explicit sums, no FFT) and against the variance of a sum of
an autocorrelated series whose value is known in closed form. Numpy only, about 1 s of CPU."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.signal import lfilter

from maglev_oc.errors import InputError
from maglev_oc.regression.covariance import (
    MIN_FREQUENCIES,
    bartlett_long_run,
    correlation_from,
    frequencies_for,
    long_run_covariance,
    periodogram_long_run,
)


def _series(n, p=2, seed=0, phi=0.6):
    """(p, n) AR(1) rows with unit innovations, mixed so that the rows are correlated."""
    rng = np.random.default_rng(seed)
    x = lfilter([1.0], [1.0, -phi], rng.standard_normal((p, n)), axis=1)  # x_t = phi x_t-1 + e_t
    mix = np.array([[1.0, 0.0], [0.7, 0.5]])[:p, :p]
    return mix @ x


def _direct_periodogram(d, m):
    """mean_{j=1..m} Re(D_j D_j^*), D_j = sum_k d_k exp(-2 pi i j k / n), as written."""
    n = d.shape[1]
    k = np.arange(n)
    out = np.zeros((d.shape[0], d.shape[0]))
    for j in range(1, m + 1):
        dj = d @ np.exp(-2j * math.pi * j * k / n)
        out += np.real(np.outer(dj, np.conj(dj)))
    return out / m


def _direct_bartlett(logs, lags):
    """sum over logs of sum_{|l| <= L} (1 - |l| / (L + 1)) Gamma_l, Gamma_l = sum_t d_{t+l} d_t'."""
    p = logs[0].shape[0]
    out = np.zeros((p, p))
    for d in logs:
        n = d.shape[1]
        big_l = min(lags, n - 1)
        for lag in range(-big_l, big_l + 1):
            w = 1 - abs(lag) / (big_l + 1)
            if lag >= 0:
                g = d[:, lag:] @ d[:, : n - lag].T
            else:
                g = d[:, : n + lag] @ d[:, -lag:].T
            out += w * g
    return 0.5 * (out + out.T)


def test_periodogram_is_its_definition():
    d = _series(500, seed=1)
    for m in (1, 4, 17):
        # an FFT against the explicit sum over 500 samples: round-off only
        assert_allclose(periodogram_long_run(d, m), _direct_periodogram(d, m), rtol=1e-9)


def test_bartlett_is_its_definition_summed_over_logs():
    logs = [_series(300, seed=2), _series(120, seed=3)]
    for lags in (0, 1, 7, 150):  # 150 > the second log's length - 1: capped there
        assert_allclose(bartlett_long_run(logs, lags), _direct_bartlett(logs, lags), rtol=1e-9, atol=1e-9)


def test_the_periodogram_estimates_the_variance_of_the_sum():
    """For an AR(1) series with coefficient phi and unit innovations the variance of the sum of n
    samples is n / (1 - phi)^2 to within O(1/n); the estimator's mean over 400 seeds is within
    8 % of it (each estimate averages m = 4 frequencies, 8 degrees of freedom: the mean of 400
    has a relative standard error of 1/sqrt(1600) = 2.5 %; 8 % is 3 of them, plus the spectrum's
    curvature between zero and the fourth frequency, 0.1 % here). The plain variance n s^2 would
    be (1 - phi)^2 / (1 - phi^2) = 0.25 of it: the estimator is not that."""
    n, phi = 4000, 0.6
    m = frequencies_for(n, 1e-3)
    assert m == MIN_FREQUENCIES
    est = [periodogram_long_run(_series(n, p=1, seed=s, phi=phi), m)[0, 0] for s in range(400)]
    truth = n / (1 - phi) ** 2
    assert np.mean(est) == pytest.approx(truth, rel=0.08)


def test_frequencies_follow_the_band_with_a_floor_and_a_ceiling():
    assert frequencies_for(60_000, 1e-3, 0.25) == 15  # floor(0.25 Hz x 60 s)
    assert frequencies_for(60_000, 1e-3, 0.5) == 30
    assert frequencies_for(1000, 1e-3, 0.25) == MIN_FREQUENCIES  # 0.25 x 1 s is below the floor
    assert frequencies_for(8, 1.0, 10.0) == 3  # n // 2 - 1: only that many positive frequencies
    assert frequencies_for(3, 1.0, 10.0) == 1


def test_long_run_covariance_adds_logs_and_reports_the_inflation():
    logs = [_series(2000, seed=4), _series(1000, seed=5)]
    naive = np.array([[2.0, 0.1], [0.1, 3.0]])
    out = long_run_covariance(logs, naive, 1e-3, band=2.0)
    ms = [frequencies_for(d.shape[1], 1e-3, 2.0) for d in logs]
    assert ms == [4, MIN_FREQUENCIES]  # floor(2 Hz x 2 s) = 4 and the floor
    expected = sum(_direct_periodogram(d, m) for d, m in zip(logs, ms, strict=True))
    assert_allclose(out.covariance, 0.5 * (expected + expected.T), rtol=1e-9)
    assert out.frequencies == sum(ms)
    assert_allclose(out.variance_inflation, np.diag(out.covariance) / np.diag(naive), rtol=1e-12)
    assert_allclose(out.naive, naive)
    wider = long_run_covariance(logs, naive, 1e-3, band=8.0)
    assert wider.frequencies == sum(frequencies_for(d.shape[1], 1e-3, 8.0) for d in logs) > out.frequencies
    for bad in (0.0, -1.0, math.inf, math.nan):
        with pytest.raises(InputError, match="band"):
            long_run_covariance(logs, naive, 1e-3, band=bad)


def test_correlation_from_a_covariance():
    cov = np.array([[4.0, 1.0, 0.0], [1.0, 9.0, 0.0], [0.0, 0.0, 0.0]])
    corr = correlation_from(cov)
    assert_allclose(corr[:2, :2], [[1.0, 1 / 6], [1 / 6, 1.0]], rtol=1e-12)
    assert corr[2, 2] == 1.0 and np.all(corr[2, :2] == 0.0) and np.all(corr[:2, 2] == 0.0)


def test_the_frequency_count_does_not_turn_on_the_last_bit_of_the_sample_time():
    """At a whole band * n * T (8 Hz on a 1 s log at 1 kHz) logs cut from one record, whose sample
    times differ in the last bits (0.001 against 0.0010000000000000009 or 0.0009999999999999998),
    average the same 8 frequencies; away from a whole number the count is the floor of band n T
    (at least 4, below n / 2)."""
    for T in (0.001, np.nextafter(0.001, 1.0), np.nextafter(0.001, 0.0), 0.0010000000000000009):
        assert frequencies_for(1000, T, 8.0) == 8
    assert frequencies_for(1000, 0.001, 8.4) == 8 and frequencies_for(1000, 0.001, 7.9) == 7
    assert frequencies_for(1000, 0.001, 1.0) == 4 and frequencies_for(10, 0.001, 1000.0) == 4
