"""The regression design's bookkeeping (``maglev_oc.regression.design``) and the sandwich covariance of
``fit_subset`` against computations written here from their definitions, on two short synthetic logs
with both axes moving and noisy measured currents:

* the fitted samples are cut into blocks that partition them, never cross a log or a gap in the mask,
  and hold ``block_seconds`` of samples (a run's short tail joined to the block before it);
* each block's weighted Gram matrix, right-hand side and target energy are the sums over its samples
  and both axes of w_a^2 x x', w_a^2 x y and w_a^2 y^2; the held-out ones the unweighted sums per axis;
* the default axis weights are 1 / RMS of each axis's residual of an unweighted least-squares fit;
* the covariance is H^-1 S H^-1 with S the averaged periodogram (its lowest m Fourier frequencies, per
  log, summed) of the per-sample scores w^2 x (y - x' theta) plus, when the currents' errors are
  removed, each block's N_b theta spread evenly over its samples; ordinary least squares
  (``compensate=False``) has no such correction.
Sums here are np.add.at over ``block_of`` and explicit DFT sums, not the package's loops and FFTs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_oc.data.logs import Log
from maglev_oc.model.stage import StageModel
from maglev_oc.regression.covariance import frequencies_for
from maglev_oc.regression.data import prepare
from maglev_oc.regression.design import build_design
from maglev_oc.regression.solve import fit_subset

RATE = 1000.0


def _log(seed: int, seconds: float) -> Log:
    """Both axes moving (gap 19-21 mm, position +-10 mm), currents with a white error (measured)."""
    rng = np.random.default_rng(seed)
    t = np.arange(round(seconds * RATE)) / RATE
    f = rng.uniform(0.5, 4.0, 3)
    x1 = 0.02 + 1e-3 * np.sin(2 * math.pi * f[0] * t + seed)
    x3 = 0.01 * np.sin(2 * math.pi * f[1] * t) + 2e-3 * np.cos(2 * math.pi * f[2] * t)
    x = np.vstack([x1, np.zeros_like(t), x3, np.zeros_like(t)])
    x[[0, 2]] += 1e-6 * rng.standard_normal((2, t.size))
    u = np.vstack([np.sin(2 * math.pi * f[2] * t) - 0.3, 1.5 + 0.4 * np.cos(2 * math.pi * f[0] * t)])
    u += 0.05 * rng.standard_normal(u.shape)
    return Log(t, x, u, source=f"s46 {seed}", currents_measured=True)


@pytest.fixture(scope="module")
def setting():
    model = StageModel()
    data = prepare([_log(1, 3.0), _log(2, 2.2)], bandwidth=10.0)
    fit, hold = data.masks(0.25)
    fit[np.flatnonzero(fit)[100:137]] = False  # a gap inside the first log's fitted part
    design = build_design(data, model, fit=fit, holdout=hold, block_seconds=0.1)
    return model, data, fit, hold, design


def test_the_blocks_partition_the_fitted_samples_without_crossing_logs_or_gaps(setting):
    _, data, fit, _, design = setting
    size = round(0.1 * RATE)
    assert np.array_equal(design.block_of >= 0, fit)
    B = design.gram.shape[0]
    assert set(np.unique(design.block_of[fit])) == set(range(B))
    runs = np.split(np.flatnonzero(fit), np.flatnonzero(np.diff(np.flatnonzero(fit)) > 1) + 1)
    expected = []
    for run in runs:  # each run of consecutive fitted samples: whole blocks, the tail joined if short
        k, rest = divmod(run.size, size)
        lengths = [size] * k + ([rest] if rest else [])
        if len(lengths) > 1 and lengths[-1] < size // 2:
            tail = lengths.pop()
            lengths[-1] += tail
        expected += lengths
    got = [int(np.sum(design.block_of == b)) for b in range(B)]
    assert got == expected
    for b in range(B):
        at = np.flatnonzero(design.block_of == b)
        assert np.all(np.diff(at) == 1)  # consecutive samples
        assert np.unique(data.segment[at]).size == 1 and design.block_log[b] == data.segment[at[0]]
    assert design.block_seconds == pytest.approx(size / RATE, rel=1e-12)


def test_block_sums_are_the_weighted_sums_over_their_samples(setting):
    _, _, fit, hold, design = setting
    w = design.weights
    assert np.all(w > 0)
    B, P = design.gram.shape[:2]
    xw = design.columns * w[None, :, None]  # (P, 2, n)
    yw = design.target * w[:, None]
    gram, rhs, yy = np.zeros((B, P, P)), np.zeros((B, P)), np.zeros(B)
    at = np.flatnonzero(fit)
    blk = design.block_of[at]
    for a in range(2):
        np.add.at(gram, blk, np.einsum("pn,qn->npq", xw[:, a, at], xw[:, a, at]))
        np.add.at(rhs, blk, (xw[:, a, at] * yw[a, at]).T)
        np.add.at(yy, blk, yw[a, at] ** 2)
    # the same products summed in another order: round-off of a few hundred terms, relative to
    # each block's largest entry
    for b in range(B):
        np.testing.assert_allclose(design.gram[b], gram[b], rtol=0, atol=1e-11 * np.abs(gram[b]).max())
    np.testing.assert_allclose(design.rhs, rhs, rtol=1e-10, atol=1e-11 * np.abs(rhs).max())
    np.testing.assert_allclose(design.yy, yy, rtol=1e-10)
    # held out: unweighted, per axis
    assert design.hold_n == int(hold.sum()) > 0
    for a in range(2):
        x, y = design.columns[:, a, hold], design.target[a, hold]
        np.testing.assert_allclose(
            design.hold_gram[a], x @ x.T, rtol=1e-10, atol=1e-11 * np.abs(x @ x.T).max()
        )
        np.testing.assert_allclose(design.hold_rhs[a], x @ y, rtol=1e-10, atol=1e-11 * np.abs(x @ y).max())
        assert design.hold_yy[a] == pytest.approx(y @ y, rel=1e-10)


def test_default_weights_are_the_inverse_rms_of_each_axis_residual(setting):
    _, _, fit, _, design = setting
    P = design.columns.shape[0]
    X = design.columns[:, :, fit].reshape(P, -1).T
    y = design.target[:, fit].reshape(-1)
    coef = np.linalg.solve(X.T @ X, X.T @ y)  # normal equations instead of lstsq
    r = design.target[:, fit] - np.einsum("p,pan->an", coef, design.columns[:, :, fit])
    expected = 1.0 / np.sqrt(np.mean(r**2, axis=1))
    # normal equations against an orthogonal factorization: cond(X)^2 eps on the residual, ~1e-8 here
    np.testing.assert_allclose(design.weights, expected, rtol=1e-6)
    assert abs(math.log(expected[0] / expected[1])) > 0.1  # the two axes' weights differ: not a common factor


def _sandwich(design, sub, share):
    """H^-1 S H^-1 from the definition: per-sample scores, the N_b theta correction spread over each
    block, explicit DFT sums over the lowest m frequencies of each log."""
    fit, w = design.fit, design.weights
    idx, coef = sub.index, sub.coef
    x = design.columns[idx][:, :, fit]
    r = design.target[:, fit] - np.einsum("p,pan->an", coef, x)
    scores = np.einsum("pan,an->pn", x, r * (w**2)[:, None])
    blk = design.block_of[fit]
    sizes = np.bincount(blk)
    for b in range(design.gram.shape[0]):
        nb = design.noise[b][np.ix_(idx, idx)]
        scores[:, blk == b] += share * (nb @ coef)[:, None] / sizes[b]
    seg = design.prepared.segment[fit]
    S = np.zeros((idx.size, idx.size))
    for log in np.unique(seg):
        s = scores[:, seg == log]
        n = s.shape[1]
        m = frequencies_for(n, design.prepared.sample_time)
        k = np.arange(n)
        for j in range(1, m + 1):
            dj = s @ np.exp(-2j * math.pi * j * k / n)
            S += np.real(np.outer(dj, np.conj(dj))) / m
    g = design.gram.sum(axis=0)[np.ix_(idx, idx)] - share * design.noise.sum(axis=0)[np.ix_(idx, idx)]
    hinv = np.linalg.inv(g)
    return hinv @ (0.5 * (S + S.T)) @ hinv


@pytest.mark.parametrize("compensate", [True, False])
def test_the_covariance_is_the_sandwich_of_the_per_sample_scores(setting, compensate):
    _, _, _, _, design = setting
    sub = fit_subset(design, ["base"], compensate=compensate)
    share = 1.0 if compensate else 0.0
    assert sub.compensation == share
    expected = _sandwich(design, sub, share)
    # FFT and twiddle tables against explicit sums, and an inverse of a 4 x 4 matrix: round-off
    np.testing.assert_allclose(sub.covariance, expected, rtol=1e-7, atol=1e-9 * np.abs(expected).max())
    # the correction matters here: the other share's sandwich differs by more than the tolerance
    other = _sandwich(design, sub, 1.0 - share)
    assert np.abs(other - expected).max() > 1e-4 * np.abs(expected).max()
