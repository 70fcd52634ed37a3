"""The output-error fit's covariance rests on ``constrained_inverse_rows``: the variable block of
the inverse KKT matrix of min |J_r w|^2 s.t. J_c w = 0. Against the null-space form computed
independently: with Z a basis of null(J_c), that block is Z (Z' J_r' J_r Z)^-1 Z' (the covariance,
per unit residual variance, of a least-squares estimate constrained to the null space; Nocedal &
Wright, 2nd ed., Sec. 16.2). Random sparse-structured problems, 1e-9 relative to the block's
largest entry (two factorizations of well-conditioned matrices)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import null_space

from maglev_oc.identification.constrained_gn import constrained_inverse_rows


@given(st.integers(0, 10_000), st.integers(3, 9), st.integers(1, 3))
@settings(max_examples=40, deadline=None)
def test_the_inverse_rows_are_the_null_space_covariance(seed, n, p):
    rng = np.random.default_rng(seed)
    p = min(p, n - 1)
    Jr = rng.normal(size=(3 * n, n))
    Jc = rng.normal(size=(p, n))
    q = int(rng.integers(1, n + 1))
    rows = constrained_inverse_rows(sp.csr_matrix(Jr), sp.csr_matrix(Jc), q)
    Z = null_space(Jc)
    full = Z @ np.linalg.solve(Z.T @ Jr.T @ Jr @ Z, Z.T)
    assert rows.shape == (q, n)
    np.testing.assert_allclose(rows, full[:q], rtol=0, atol=1e-9 * np.abs(full).max())
    # a covariance: symmetric, positive semi-definite, and zero along the constraints' normals
    np.testing.assert_allclose(full[:q, :q], full[:q, :q].T, atol=1e-12 * np.abs(full).max())
    np.testing.assert_allclose(Jc @ rows.T, 0.0, atol=1e-9 * np.abs(full).max() * np.abs(Jc).max())


def test_without_constraints_the_rows_are_the_inverse_gram():
    rng = np.random.default_rng(1)
    Jr = rng.normal(size=(20, 4))
    rows = constrained_inverse_rows(sp.csr_matrix(Jr), sp.csr_matrix((0, 4)), 4)
    np.testing.assert_allclose(rows, np.linalg.inv(Jr.T @ Jr), rtol=1e-10)


def test_a_singular_kkt_matrix_raises():
    Jr = np.zeros((5, 3))
    Jr[:, 0] = 1.0  # two variables no residual sees and no constraint fixes
    with pytest.raises(RuntimeError):
        constrained_inverse_rows(sp.csr_matrix(Jr), sp.csr_matrix(np.array([[0.0, 1.0, 0.0]])), 1)
