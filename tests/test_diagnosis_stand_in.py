"""The collinearity :func:`maglev_oc.diagnosis.selection._beside_a_stand_in` judges a candidate by
when its fit beside a stand-in for the constants runs off: ``_partial_inflation``, from the summed
block Grams of a design, against the same number computed another way, by regressing both
candidates' columns on the rest and correlating what is left (numpy's least squares on the samples
themselves). Synthetic columns; milliseconds."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from maglev_oc.diagnosis.selection import RIVAL_CONSTANT_Z, _partial_inflation, another_motor
from maglev_oc.identification.pipeline import PLAUSIBLE_CHANGE


def _design(x: np.ndarray, blocks: int, groups: dict[str, list[int]]):
    """A design of the columns ``x`` (n, p) in ``blocks`` blocks of samples: their Grams and the
    column groups, as :class:`maglev_oc.regression.design.Design` carries them."""
    parts = np.array_split(x, blocks)
    gram = np.stack([p.T @ p for p in parts])
    cols = {k: np.asarray(v, dtype=int) for k, v in groups.items()}
    return SimpleNamespace(
        gram=gram, groups=cols, indices=lambda names: np.concatenate([cols[g] for g in names])
    )


def _by_samples(x: np.ndarray, a: list[int], b: list[int], rest: list[int]) -> float:
    """1 / (1 - rho^2), rho the largest canonical correlation of the columns a and b once the
    columns ``rest`` are regressed out of both."""

    def left(cols):
        y = x[:, cols]
        if not rest:
            return y
        coef, *_ = np.linalg.lstsq(x[:, rest], y, rcond=None)
        return y - x[:, rest] @ coef

    qa, _ = np.linalg.qr(left(a))
    qb, _ = np.linalg.qr(left(b))
    rho = np.linalg.svd(qa.T @ qb, compute_uv=False).max()
    return 1.0 / (1.0 - rho**2)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    mix=st.floats(0.0, 0.98),
    n_rest=st.integers(0, 3),
    n_a=st.integers(1, 2),
)
def test_the_partial_inflation_is_that_of_the_columns_left_by_the_rest(seed, mix, n_rest, n_a):
    rng = np.random.default_rng(seed)
    n = 400
    rest = rng.standard_normal((n, n_rest))
    a = rng.standard_normal((n, n_a))
    # b leans on a's first column by ``mix`` and on the rest, which the projection removes
    b = mix * a[:, :1] + np.sqrt(1 - mix**2) * rng.standard_normal((n, 1))
    if n_rest:
        b = b + rest @ rng.standard_normal((n_rest, 1))
    x = np.hstack([rest, a, b])
    cols = list(range(x.shape[1]))
    groups = {"base": cols[:n_rest], "a": cols[n_rest : n_rest + n_a], "b": cols[-1:]}
    design = _design(x, 3, groups)
    names = ["base", "a", "b"]
    got = _partial_inflation(design, names, "a", "b")
    # the same quantity from the samples (rounding of normal equations against QR: 1e-7 relative)
    want = _by_samples(x, groups["a"], groups["b"], groups["base"])
    assert got == pytest.approx(want, rel=1e-7)
    # a b that is a's column plus the rest's: the two are one direction once the rest is gone
    y = np.hstack([rest, a, a[:, :1] + (rest.sum(axis=1, keepdims=True) if n_rest else 0.0)])
    assert _partial_inflation(_design(y, 3, groups), names, "a", "b") > 1e6


_REFERENCE = {"C1": 14.2, "C2": 796.99, "C3": 31.04, "C4": 0.07}  # the papers' (SPEC)


def _fit(values: dict[str, float], sd: dict[str, float]):
    """A candidate's fit as :func:`another_motor` reads it: the constants' values and standard errors."""
    names = tuple(values)
    return SimpleNamespace(
        names=names,
        value=lambda n: values[n],
        covariance=np.diag([sd[n] ** 2 for n in names]),
    )


OWN = _fit(
    {"C1": 14.33, "C2": 775.6, "C3": 30.74, "C4": 0.103}, {"C1": 0.035, "C2": 2.7, "C3": 0.57, "C4": 0.027}
)
"""The 19 mm cogging's fit of drawn pair 9030 (tests/test_diagnose_effects.py)."""


def test_a_stand_in_that_needs_another_motor_is_no_rival():
    # pair 9030: the constant vertical force's fit had C2 at 47.5, -94 % from the model's
    assert another_motor({"C2": 47.5, "C3": 1.94, "C4": 0.008}, OWN, "vertical", _REFERENCE)
    # a 3 N hanging cable's force moved C2 by 5.6 % (bench/README, the load change): a rival
    assert not another_motor({"C2": 752.0, "C3": 29.0, "C4": 0.07}, OWN, "vertical", _REFERENCE)
    # only the candidate's axes count: C1 far off does not make a vertical rival another motor
    assert not another_motor({"C1": 5.0, "C2": 770.0}, OWN, "vertical", _REFERENCE)
    assert another_motor({"C1": 5.0, "C2": 770.0}, OWN, "horizontal", _REFERENCE)


@settings(max_examples=60, deadline=None)
@given(change=st.floats(-0.9, 0.9), sd=st.floats(0.1, 400.0))
def test_another_motor_is_beyond_the_plausible_change_and_the_candidates_errors(change, sd):
    # at the bound itself the verdict is the rounding's (change 0.3: C2 / 797 - 1 is 0.30000000000000004)
    assume(abs(abs(change) - PLAUSIBLE_CHANGE) > 1e-9)
    own = _fit({"C2": 780.0}, {"C2": sd})
    c2 = _REFERENCE["C2"] * (1 + change)
    expected = abs(change) > PLAUSIBLE_CHANGE and abs(c2 - 780.0) > RIVAL_CONSTANT_Z * sd
    # a candidate's own fit beyond the plausible change (by more than 5 standard errors) is no such
    # stage either: then the rival counts (780 is within 2.2 % of the reference: never here)
    assert another_motor({"C2": c2}, own, "vertical", _REFERENCE) == expected


def test_a_candidate_whose_own_fit_is_no_such_stage_keeps_every_rival():
    beyond = _fit({"C2": 400.0}, {"C2": 2.0})  # -50 % at 200 standard errors
    assert not another_motor({"C2": 47.5}, beyond, "vertical", _REFERENCE)
    unknown = _fit({"C2": 780.0}, {"C2": float("nan")})
    assert not another_motor({"C2": 47.5}, unknown, "vertical", _REFERENCE)
