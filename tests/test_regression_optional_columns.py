"""A term's optional parameter (``AccelerationTerm.optional``, the share of the force the guides hold
while an axis sticks) is held at zero by a compensated fit when the logged currents' errors are at
least :data:`~maglev_oc.regression.solve.OPTIONAL_NOISE_SHARE` of its column. Synthetic columns;
milliseconds."""

from __future__ import annotations

from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from maglev_oc.errors import InputError
from maglev_oc.regression.solve import OPTIONAL_NOISE_SHARE, fit_subset
from maglev_oc.regression.terms import AccelerationTerm, term_function


def _design(x_seen: np.ndarray, y: np.ndarray, noise_var: np.ndarray, optional: np.ndarray, blocks: int = 4):
    """A one-axis design of the logged columns ``x_seen`` (n, p) and target ``y``, whose columns'
    errors have the variances ``noise_var`` (p,) per sample, as
    :class:`~maglev_oc.regression.design.Design` carries the block sums."""
    n, p = x_seen.shape
    parts = np.array_split(np.arange(n), blocks)
    gram = np.stack([x_seen[i].T @ x_seen[i] for i in parts])
    noise = np.stack([np.diag(noise_var) * i.size for i in parts])
    rhs = np.stack([x_seen[i].T @ y[i] for i in parts])
    yy = np.array([y[i] @ y[i] for i in parts])
    cols = {"base": np.array([0]), "term": np.arange(1, p)}
    return SimpleNamespace(
        gram=gram,
        noise=noise,
        rhs=rhs,
        yy=yy,
        fit=np.ones(n, dtype=bool),
        weights=np.array([1.0, 0.0]),
        names=tuple(f"c{j}" for j in range(p)),
        hold_n=0,
        optional=optional,
        indices=lambda names: np.concatenate([cols[g] for g in names]),
    )


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), share=st.floats(0.05, 0.95), flag=st.booleans())
def test_an_optional_column_mostly_made_of_the_currents_errors_is_held_at_zero(seed, share, flag):
    rng = np.random.default_rng(seed)
    n = 4000
    a = rng.standard_normal(n)  # a column without errors (a friction's Coulomb part)
    # the optional column: a signal of variance 1 - share seen through errors of variance share
    signal = np.sqrt(1.0 - share) * rng.standard_normal(n)
    seen = signal + np.sqrt(share) * rng.standard_normal(n)
    y = 2.0 * a + 0.5 * signal + 0.1 * rng.standard_normal(n)
    x = np.column_stack([a, seen])
    optional = np.array([False, flag])
    fit = fit_subset(_design(x, y, np.array([0.0, share]), optional), ["base", "term"], covariance=False)
    # the errors' estimated share of the column's variance, as the fit sees it (sampling: 1/sqrt(n))
    measured = share * n / float(seen @ seen)
    if flag and measured >= OPTIONAL_NOISE_SHARE:
        assert fit.coef[1] == 0.0
        assert fit.compensation == 1.0
        # a alone: its residual (0.5 signal and the noise, standard deviation at most 0.51) over
        # sqrt(n) is a standard error of 0.008; 0.1 is 12 of them
        assert fit.coef[0] == pytest.approx(2.0, abs=0.1)
    elif share <= 0.5:
        # kept and compensated: the coefficient of the signal, not its attenuated least-squares value
        # 0.5 (1 - share). Its standard error (s = 1 - share, the signal's variance): the residual
        # (at most sqrt(0.01 + 0.25 share)) over sqrt(n s), plus what moves the compensated
        # denominator x'x - N: the errors' sample variance (share sqrt(2 / n)) and their sample
        # covariance with the signal (2 sqrt(s share / n)), times 0.5 / s. Over 6000 draws the
        # largest error was 1.65 of it; 4 of them, while the uncompensated value is 6 away at a
        # share of 0.15
        s = 1.0 - share
        denominator = share * np.sqrt(2 / n) + 2 * np.sqrt(s * share / n)
        se = np.sqrt((0.01 + 0.25 * share) / (n * s)) + 0.5 * denominator / s
        assert fit.compensation == 1.0
        assert fit.coef[1] == pytest.approx(0.5, abs=4 * se)
    else:  # mostly errors and kept: fitted, not held (the ratio's tails make its size loose)
        assert fit.coef[1] != 0.0


def test_without_compensation_nothing_is_held():
    rng = np.random.default_rng(3)
    n = 2000
    x = np.column_stack([rng.standard_normal(n), rng.standard_normal(n)])
    y = x[:, 0] + 0.3 * x[:, 1]
    design = _design(x, y, np.array([0.0, 2.0]), np.array([False, True]))
    fit = fit_subset(design, ["base", "term"], covariance=False, compensate=False)
    assert fit.coef[1] == pytest.approx(0.3, abs=1e-9)  # the plain least squares of an exact target


def test_optional_names_its_own_parameters_only():
    with pytest.raises(InputError, match="optional"):
        AccelerationTerm(
            "t",
            "x",
            "vertical",
            ("a",),
            function=term_function("t", lambda x, u, du, q: ca.vertcat(q[0], 0), 1),
            optional=("b",),
        )
