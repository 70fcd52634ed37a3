"""Long-run covariance: closed-form processes, the Bartlett cross-check, and coverage on twin logs."""

from __future__ import annotations

import numpy as np
import pytest

from maglev_oc.regression.covariance import (
    bartlett_long_run,
    correlation_from,
    frequencies_for,
    long_run_covariance,
    periodogram_long_run,
)


def _ar1(n: int, rho: float, rng) -> np.ndarray:
    e = rng.standard_normal(n)
    x = np.empty(n)
    x[0] = e[0] / np.sqrt(1 - rho**2)
    for k in range(1, n):
        x[k] = rho * x[k - 1] + e[k]
    return x


def test_periodogram_at_zero_matches_the_ar1_long_run_variance():
    # For an AR(1) with unit innovations, Var(sum x) / n -> 1 / (1 - rho)^2; the averaged
    # periodogram over the lowest frequencies estimates n times that. 40 replications: the mean
    # is within 10 % (each estimate has 2m = 30 degrees of freedom, mean error ~ 4 %).
    rng = np.random.default_rng(0)
    n, rho = 20_000, 0.8
    est = [periodogram_long_run(_ar1(n, rho, rng)[None, :], 15)[0, 0] / n for _ in range(40)]
    assert np.mean(est) == pytest.approx(1 / (1 - rho) ** 2, rel=0.1)


def test_over_differenced_noise_has_a_small_long_run_variance():
    # The second difference of white noise (what a differentiator leaves of quantization noise)
    # sums to almost nothing: its long-run variance is ~0 while its variance is 6; the plain
    # formula would overstate the uncertainty of a mean by orders of magnitude.
    rng = np.random.default_rng(1)
    w = rng.standard_normal(40_001)
    d = np.diff(w, 2)[None, :]
    lr = long_run_covariance([d - d.mean()], np.array([[np.var(d) * d.size]]), 1e-3)
    assert lr.covariance[0, 0] < 1e-3 * np.var(d) * d.size
    assert lr.variance_inflation[0] < 1e-3


def test_bartlett_with_long_lags_agrees_with_the_periodogram():
    rng = np.random.default_rng(2)
    x = np.vstack([_ar1(30_000, 0.9, rng), _ar1(30_000, 0.5, rng)])
    x -= x.mean(axis=1, keepdims=True)
    per = long_run_covariance([x], np.eye(2), 1e-3, band=2.0).covariance  # 60 frequencies
    bart = bartlett_long_run([x], 600)
    assert np.diag(bart) == pytest.approx(np.diag(per), rel=0.25)
    assert np.diag(per) == pytest.approx(30_000 / (1 - np.array([0.9, 0.5])) ** 2, rel=0.3)


def test_frequency_count_and_correlation_helpers():
    assert frequencies_for(60_000, 1e-3) == 15  # 0.25 Hz x 60 s
    assert frequencies_for(5_000, 1e-3) == 4  # floor of 4
    assert frequencies_for(8, 1e-3) == 3  # never beyond n // 2 - 1
    c = correlation_from(np.array([[4.0, 2.0], [2.0, 9.0]]))
    assert c[0, 1] == pytest.approx(2 / 6)
    with pytest.raises(ValueError, match="band"):
        long_run_covariance([np.zeros((1, 100))], np.eye(1), 1e-3, band=0.0)


@pytest.mark.slow
def test_equation_error_standard_errors_cover_the_truth_over_seeds(model):
    # Eight 20 s twin runs: |z| <= 2 in most runs for every constant and std(z) near 1 (the
    # estimate of the long-run variance has ~10 degrees of freedom: std(z) ~ 1.1 expected).
    from maglev_oc.identification.equation_error import fit_equation_error
    from maglev_oc.identification.experiments import TWIN_TRUTH, excitation_log

    truth = dict(zip(("C1", "C2", "C3", "C4"), TWIN_TRUTH.as_array(), strict=True))
    tm = model.with_constants(TWIN_TRUTH)
    z = []
    for seed in range(8):
        log = excitation_log(tm, duration=20.0, seed=300 + seed, controller_model=model)
        fit = fit_equation_error(log, model)
        z.append([fit.z_scores(truth)[k] for k in truth])
    z = np.array(z)
    assert np.all(np.mean(np.abs(z) <= 2, axis=0) >= 0.75)
    assert np.all(np.std(z, axis=0) < 1.8)
    assert np.all(np.abs(z) < 4)
