"""The NPFSI end point of ``eps_trend.stationary_point`` with several rows and parameters, against
its docstring's definition evaluated here sample by sample: theta solves sum_k w_k g_k(theta) = 0
with g_k(theta) = A_k' [(1 - phi) e_k + beta (s_k - A_k theta)], s = dy - b,
e_k = eps (1 - phi) sum_{j<k} phi^(k-1-j) (s_j - A_j theta), w_k = (k / n)^(1 / (gamma^2 - 1)),
phi = exp(-h / eps), beta = h - eps (1 - phi). The existing checks run one row and one parameter,
where a transposed or misplaced product cannot show."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from maglev_oc.identification.eps_trend import stationary_point


def _data(seed, n, m, p):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-3
    A = rng.normal(size=(n, m, p)) + np.sin(2 * np.pi * rng.uniform(1, 5, (1, m, p)) * t[:, None, None])
    b = rng.normal(size=(n, m))
    y = np.cumsum(rng.normal(size=(n, m)), axis=0) * 1e-3
    return A, b, y


def _g(theta, A, b, y, h, eps, gamma):
    """sum_k w_k g_k(theta), one sample at a time, as the docstring writes it."""
    n, m, p = A.shape
    phi = math.exp(-h / eps)
    beta = h - eps * (1 - phi)
    dy = np.zeros((n, m))
    dy[:-1] = (y[1:] - y[:-1]) / h
    total = np.zeros(p)
    e = np.zeros(m)  # e_0: the empty sum
    for k in range(n):
        s_k = dy[k] - b[k] - A[k] @ theta
        w = (k / n) ** (1.0 / (gamma**2 - 1.0))
        total += w * (A[k].T @ ((1 - phi) * e + beta * s_k))
        e = phi * e + eps * (1 - phi) * s_k  # e_{k+1} = sum over j <= k
    return total


@given(st.integers(0, 10_000), st.integers(1, 3), st.integers(2, 4), st.sampled_from([0.001, 0.01, 0.05]))
@settings(max_examples=15, deadline=None)
def test_the_end_point_zeroes_the_weighted_moment_it_is_defined_by(seed, m, p, eps):
    A, b, y = _data(seed, 200, m, p)
    h, gamma = 1e-3, 1.1 + (seed % 3) * 0.4
    theta = stationary_point(A, b, y, h, eps, gamma)
    assert theta.shape == (p,)
    # g is affine in theta: its value at theta against the size of its linear part; 1e-9 covers
    # the round-off of 200-sample sums and one p x p solve of a well-conditioned random system
    scale = max(
        np.abs(_g(np.eye(p)[j], A, b, y, h, eps, gamma) - _g(np.zeros(p), A, b, y, h, eps, gamma)).max()
        for j in range(p)
    )
    np.testing.assert_allclose(
        _g(theta, A, b, y, h, eps, gamma), 0.0, atol=1e-9 * scale * (1 + np.abs(theta).max())
    )


def test_an_exact_model_is_its_own_end_point_for_every_eps():
    # dy - b = A theta exactly at every sample: every g_k vanishes at the truth, whatever eps,
    # gamma and the weights (the last sample, which has no forward difference, carries no
    # regressor and no offset); 1e-10 relative is round-off of the sums
    rng = np.random.default_rng(3)
    n, h = 400, 1e-3
    A = rng.normal(size=(n, 2, 3))
    b = rng.normal(size=(n, 2))
    A[-1], b[-1] = 0.0, 0.0
    truth = np.array([1.5, -0.7, 2.2])
    acc = np.einsum("nij,j->ni", A, truth) + b
    y = np.vstack([np.zeros(2), np.cumsum(acc[:-1], axis=0) * h])
    for eps in (0.001, 0.01, 0.05):
        np.testing.assert_allclose(stationary_point(A, b, y, h, eps), truth, rtol=1e-10)
