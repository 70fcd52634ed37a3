"""Gauss-Newton with step halving (``regression.solve.fit_nonlinear``) as an algorithm: an accepted
iterate never raises the cost, and a step along which no fraction lowers it ends the fit as
"no_decrease" at the last point that was accepted.

The designs here are stand-ins on one parameter: ``build(at)`` records ``at``, the linear fit of
the design linearized there proposes ``at + gain (x* - at)`` (the Gauss-Newton point of a model
whose Jacobian is off by 1/gain), and the cost is (at - x*)^2. A gain of 1 is exact Gauss-Newton;
a large gain overshoots, so only a step of about 1/gain lowers the cost: the halving has to go that
far (1/32 for a gain of 40), and a search that gives up after a few halvings accepts a point worse
than the one it left.
"""

from __future__ import annotations

import itertools
from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.regression import solve

X_STAR = 1.0


@pytest.fixture
def stand_in(monkeypatch):
    """(build, accepted costs) of the stand-in problem with Gauss-Newton gain ``gain``."""

    def make(gain: float):
        def fit_subset(design, groups, compensate=True, covariance=True):
            return SimpleNamespace(coef=design.at + gain * (X_STAR - design.at))

        def cost_at(design, at):
            return float(np.sum((np.asarray(at) - X_STAR) ** 2))

        monkeypatch.setattr(solve, "fit_subset", fit_subset)
        monkeypatch.setattr(solve, "_cost_at", cost_at)
        return lambda at: SimpleNamespace(at=np.array(at, dtype=float), groups={"p": np.array([0])})

    return make


def _bounds():
    return np.array([-1e6]), np.array([1e6]), np.array([1.0])


# gains whose accepted fraction contracts the distance to x* by 4 or more per iteration (a gain
# of 2^k would land at the same cost on the other side and cycle; 1000 contracts by 0.95 only)
@pytest.mark.parametrize("gain", [1.0, 2.5, 5.0, 40.0, 700.0])
def test_an_overshooting_step_is_halved_until_the_cost_falls(stand_in, gain):
    # from 0 (cost 1) to x* = 1: every accepted point is at most as far from x* as the one before
    # (the cost never rises), and the fit converges there (the halving stops at the largest
    # 2^-k with |1 - 2^-k gain| < 1, a contraction)
    build = stand_in(gain)
    seen: list[float] = []

    def recording(at):
        design = build(at)
        seen.append(float(design.at[0]))
        return design

    lower, upper, scale = _bounds()
    design, _, status, _, iterations = solve.fit_nonlinear(recording, np.array([0.0]), lower, upper, scale)
    assert status == "converged", (status, iterations)
    assert design.at[0] == pytest.approx(X_STAR, abs=1e-6)
    # the points the fit moved to, in order: the trial of each iteration that was kept is the
    # first of its trials with a cost not above the last kept one
    kept = [0.0]
    for x in seen[1:]:
        if (x - X_STAR) ** 2 <= (kept[-1] - X_STAR) ** 2 * (1 + 1e-12):
            kept.append(x)
    assert kept[-1] == pytest.approx(design.at[0])
    costs = [(x - X_STAR) ** 2 for x in kept]
    assert all(b <= a * (1 + 1e-12) for a, b in itertools.pairwise(costs))


@pytest.mark.parametrize("gain", [-1.0, -40.0])
def test_a_step_that_only_raises_the_cost_ends_the_fit_where_it_was(stand_in, gain):
    # a proposal away from x*: no fraction of it lowers the cost; the fit stops at once, as
    # "no_decrease", with the design and point it started from (not the last trial)
    build = stand_in(gain)
    lower, upper, scale = _bounds()
    design, _, status, message, iterations = solve.fit_nonlinear(build, np.array([0.25]), lower, upper, scale)
    assert status == "no_decrease", (status, message)
    assert iterations == 1
    assert design.at[0] == 0.25
