"""Properties of the least-squares fits and their covariances (``maglev_oc.regression.solve`` and
``covariance``), each checked against numpy's or scipy's own computation:

- the plain covariance is s^2 (X'X)^-1, and the fit's chi-square is the weighted residual sum of
  squares with the errors-in-variables part removed;
- an overlarge errors-in-variables part is removed up to the largest share that keeps the normal
  equations positive definite (scipy's generalized eigenvalues);
- the periodogram of a long series is its definition, and the long-run covariance is the sandwich
  of the (compensated, or for ordinary least squares plain) scores, recomputed with numpy's FFT;
- a common factor on the axis weights changes nothing, and Gauss-Newton stopped by its budget
  says so with its documented status.
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest
from scipy.linalg import eigh

from maglev_oc.regression import solve
from maglev_oc.regression.base import GAP_OFFSET
from maglev_oc.regression.covariance import DIRECT_DFT_SIZE, periodogram_long_run
from maglev_oc.regression.data import prepare
from maglev_oc.regression.design import build_design
from maglev_oc.regression.solve import fit_nonlinear, fit_subset
from tests.test_regression_covariance import _direct_periodogram, _series
from tests.test_statistics_properties import _rows


# --- the regression layer's solve and covariance -------------------------------------------------------
def test_the_plain_covariance_is_the_residual_variance_times_the_inverse_normal_matrix(cogged):
    # ordinary least squares on the weighted rows the fit sees (numpy's lstsq): s^2 (X'X)^-1 with
    # s^2 the residual sum of squares over rows minus parameters. Two solvers on the same rows:
    # rtol 1e-7 (the normal equations square the columns' condition number, about 1e3 here)
    design, _ = cogged
    fit = fit_subset(design, ["base", "cogging_horizontal_19mm"], compensate=False)
    x, y = _rows(design, fit.index, design.fit)
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    s2 = float(np.sum((y - x @ coef) ** 2)) / (x.shape[0] - x.shape[1])
    np.testing.assert_allclose(fit.coef, coef, rtol=1e-7)
    assert fit.chi_square == pytest.approx(s2 * (x.shape[0] - x.shape[1]), rel=1e-7)
    np.testing.assert_allclose(fit.naive, s2 * np.linalg.inv(x.T @ x), rtol=1e-7)


@pytest.mark.parametrize("excess", [1.5, 4.0])
def test_an_overlarge_errors_in_variables_part_is_removed_up_to_the_largest_share_that_keeps_a_solution(
    cogged, excess
):
    # an errors-in-variables estimate N larger than the signal (here N = excess / 4 x M D M', D the
    # diagonal of X'X and M a random mixing near the identity) leaves X'X - N indefinite; the fit
    # removes the largest share s of N for which X'X - s N is still positive definite: s* = 1 /
    # lambda_max of the pencil (N, X'X) (scipy's generalized symmetric eigensolver). The bisection's
    # 30 halvings reach s* to 1e-9 from below: rel 1e-6
    design, _ = cogged
    idx = design.indices(["base", "cogging_horizontal_19mm"])
    rng = np.random.default_rng(5)
    mix = np.eye(design.n_parameters) + 0.3 * rng.normal(size=(design.n_parameters,) * 2)
    noise = np.stack([excess * mix @ np.diag(np.diag(g)) @ mix.T / 4 for g in design.gram])
    noisy = dataclasses.replace(design, noise=noise)
    fit = fit_subset(noisy, ["base", "cogging_horizontal_19mm"])
    g, n = (a[:, idx][:, :, idx].sum(axis=0) for a in (design.gram, noise))
    critical = 1.0 / float(eigh(n, g, eigvals_only=True)[-1])
    assert 0.0 < critical < 1.0  # the whole N cannot be removed
    assert fit.compensation == pytest.approx(critical, rel=1e-6)
    assert fit.compensation <= critical and "could be removed" in fit.message


def test_the_long_run_covariance_of_a_long_series_is_its_definition():
    # a series long enough (n m beyond DIRECT_DFT_SIZE) that the periodogram takes the FFT path: the
    # mean over j = 1..m of Re(D_j D_j^*), the zero frequency left out (at the least-squares solution
    # the influence sums to zero, and any mean must not count), against the explicit sum; FFT
    # round-off over 70 000 samples: rtol 1e-9
    n, m = 70_000, 17
    assert n * m > DIRECT_DFT_SIZE
    d = _series(n, seed=3) + np.array([[0.3], [-0.2]])  # a mean the zero frequency would pick up
    np.testing.assert_allclose(periodogram_long_run(d, m), _direct_periodogram(d, m), rtol=1e-9)


def test_the_long_run_covariance_is_the_sandwich_of_the_compensated_scores(model, twin_log):
    # the twin's log (its logged currents carry amplifier noise, so the fit removes an
    # errors-in-variables part N): per sample the score sum_a w_a^2 x_a r_a plus the block's N_b theta
    # spread evenly over its m_b samples; per log the mean over j = 1..m of Re(D_j D_j^*) of their
    # DFT (numpy's FFT, m = max(4, floor(0.25 Hz x duration))); the covariance H^-1 S H^-1 with
    # H = sum_b (X_b'X_b - N_b). An FFT against the code's tabulated DFT: rtol 1e-7
    data = prepare([twin_log], bandwidth=10.0)
    fit_mask, hold = data.masks(0.25)
    design = build_design(data, model, fit=fit_mask, holdout=hold)
    fit = fit_subset(design, ["base"])
    assert fit.compensation == 1.0 and np.any(design.noise != 0)
    idx = fit.index
    x = design.columns[idx][:, :, design.fit]
    r = design.target[:, design.fit] - np.einsum("p,pan->an", fit.coef, x)
    scores = np.einsum("pan,an->pn", x, r * design.weights[:, None] ** 2)
    blocks = design.block_of[design.fit]
    noise = design.noise[:, idx][:, :, idx]
    for b in range(design.gram.shape[0]):
        scores[:, blocks == b] += (noise[b] @ fit.coef / np.sum(blocks == b))[:, None]
    n = scores.shape[1]
    m = max(4, math.floor(0.25 * n * data.sample_time))
    f = np.fft.fft(scores, axis=1)[:, 1 : m + 1]
    meat = (f @ f.conj().T).real / m
    h = design.gram[:, idx][:, :, idx].sum(axis=0) - noise.sum(axis=0)
    hinv = np.linalg.inv(h)
    np.testing.assert_allclose(fit.covariance, hinv @ meat @ hinv, rtol=1e-7, atol=0)


# --- the regression layer -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def twin_design(model, twin_log):
    """The twin's log (its logged currents carry amplifier noise) with C1..C4, a quarter held out."""
    data = prepare([twin_log], bandwidth=10.0)
    fit_mask, hold = data.masks(0.25)
    return build_design(data, model, fit=fit_mask, holdout=hold)


def test_the_fits_chi_square_is_the_weighted_residual_sum_of_squares_with_compensation(twin_design):
    """On the twin's log (noisy logged currents: the fit removes an errors-in-variables part, so its
    coefficients are not the plain least-squares ones) the fit's chi-square is the weighted residual
    sum of squares of its fitted rows, recomputed with numpy from the columns and the coefficients,
    and the plain covariance is chi^2 / (rows - parameters) times the compensated normal matrix's
    inverse (rtol 1e-9: sums of 10^4 squares in another order)."""
    design = twin_design
    fit = fit_subset(design, ["base"])
    assert fit.compensation == 1.0 and np.any(design.noise != 0)
    x, y = _rows(design, fit.index, design.fit)
    rss = float(np.sum((y - x @ fit.coef) ** 2))
    assert fit.chi_square == pytest.approx(rss, rel=1e-9)
    idx = fit.index
    h = design.gram[:, idx][:, :, idx].sum(axis=0) - design.noise[:, idx][:, :, idx].sum(axis=0)
    np.testing.assert_allclose(fit.naive, rss / (y.size - idx.size) * np.linalg.inv(h), rtol=1e-9)


def test_an_ordinary_least_squares_fits_long_run_covariance_has_no_errors_in_variables_part(twin_design):
    """compensate=False on the same log: the sandwich H^-1 S H^-1 of the plain scores, H = X'X and the
    scores sum_a w_a^2 x_a r_a with no errors-in-variables correction (nothing was removed), S the
    mean over j = 1..m of Re(D_j D_j^*) of their DFT (numpy's FFT, m = max(4, floor(0.25 Hz x
    duration))); rtol 1e-7, an FFT against the code's tabulated DFT (as in the second round's test
    of the compensated fit)."""
    design = twin_design
    fit = fit_subset(design, ["base"], compensate=False)
    assert fit.compensation == 0.0
    idx = fit.index
    x = design.columns[idx][:, :, design.fit]
    r = design.target[:, design.fit] - np.einsum("p,pan->an", fit.coef, x)
    scores = np.einsum("pan,an->pn", x, r * design.weights[:, None] ** 2)
    m = max(4, math.floor(0.25 * scores.shape[1] * design.prepared.sample_time))
    f = np.fft.fft(scores, axis=1)[:, 1 : m + 1]
    meat = (f @ f.conj().T).real / m
    hinv = np.linalg.inv(design.gram[:, idx][:, :, idx].sum(axis=0))
    np.testing.assert_allclose(fit.covariance, hinv @ meat @ hinv, rtol=1e-7, atol=0)


# --- least squares ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def prepared(twin_log):
    return prepare([twin_log], bandwidth=10.0)


@pytest.mark.parametrize("factor", [1e-7, 1e7])
def test_a_common_factor_on_the_axis_weights_changes_nothing(model, prepared, factor):
    """Weighted least squares minimises sum w_a^2 r_a^2: a common factor c on both weights multiplies
    the cost by c^2 and moves no minimum, and the covariance (the normal matrix's inverse times the
    weighted residuals' long-run covariance) is unchanged too. The Gram's diagonal goes from about 1e8
    to 1e-6 or 1e22 (its entries span four decades among C1..C4). Tolerances: the coefficients to 1e-9
    relative (measured 1e-11: round-off of sums over 6000 samples), the covariance to 1e-6 (measured
    3e-9: the long-run estimate sums products of residuals)."""
    design = build_design(prepared, model)
    scaled = build_design(prepared, model, weights=factor * design.weights)
    assert np.diag(scaled.gram.sum(axis=0)).max() == pytest.approx(
        factor**2 * np.diag(design.gram.sum(axis=0)).max(), rel=1e-9
    )
    ref, fit = (fit_subset(d, list(d.groups)) for d in (design, scaled))
    assert np.all(ref.coef > 0)  # the constants, not zeros
    np.testing.assert_allclose(fit.coef, ref.coef, rtol=1e-9)
    np.testing.assert_allclose(fit.covariance, ref.covariance, rtol=1e-6)


def test_gauss_newton_stopped_by_its_budget_says_so(truth_model, twin_log):
    """fit_nonlinear's docstring: status "converged", "iteration_limit" or "no_decrease". The gap offset
    enters nonlinearly; a log whose gap reading is 0.3 mm above the true gap needs a few Gauss-Newton
    iterations from 0: with a budget of one or two it stops with "iteration_limit" after that many;
    with the default budget it converges to -0.3 mm (gap_offset = true - reading), to 1 % (the
    offset's standard error on this log is about 0.3 um)."""
    words = set(re.findall(r'"([a-z_]+)"', solve.fit_nonlinear.__doc__))
    x = np.array(twin_log.x)
    x[0] += 3e-4
    data = prepare([dataclasses.replace(twin_log, x=x)], bandwidth=10.0)
    first = build_design(data, truth_model, estimate=(GAP_OFFSET,))

    def build(at):
        return build_design(data, truth_model, estimate=(GAP_OFFSET,), at=at, weights=first.weights)

    bounds = (np.array([-5e-3]), np.array([5e-3]), np.array([1e-3]))
    for budget in (1, 2):
        _, _, status, message, iterations = fit_nonlinear(build, np.zeros(1), *bounds, max_iterations=budget)
        assert status == "iteration_limit" and status in words
        assert iterations == budget and str(budget) in message
    _, fit, status, _, iterations = fit_nonlinear(build, np.zeros(1), *bounds)
    assert status == "converged" and status in words and 2 < iterations < 30
    assert fit.coef[0] == pytest.approx(-3e-4, rel=0.01)
