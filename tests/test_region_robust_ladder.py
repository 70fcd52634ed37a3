"""The robust certificate's ladder (``RobustCertifier._ladder``) with its branch and bound replaced
by a scripted one whose answer is known: every level up to a threshold is certified, every level
above it refuted (or undecided). The ladder stops at the first certified rung and bisects between
it and the rung above (``REFINE_STEPS`` halvings), so the level it returns lies within
(rung above - rung certified) / 2^REFINE_STEPS below the threshold and never above it; the upper
bound it reports is the least refuted level tried; and every search it runs is handed the one
geometry of P it was given (the real search reads its Cholesky factor and constraint images from
it). The quick tests' plant sets never reach this bisection (bench/README, mutation seed 53)."""

from __future__ import annotations

import math

import pytest

from maglev_oc.region.robust_certificate import REFINE_STEPS, RobustCertifier, RobustSearch


def _scripted(ladder, threshold, above="refuted"):
    """A certifier whose search certifies levels <= ``threshold`` and gives ``above`` elsewhere,
    recording (level, geometry) of every call."""
    cert = object.__new__(RobustCertifier)  # the ladder needs no loop: only `ladder` and `_search`
    cert.ladder = ladder
    calls = []

    def search(reference, P, level, plants, geo, t0):
        calls.append((level, geo))
        status = "certified" if level <= threshold else above
        return RobustSearch(status == "certified", status, status, level, 1, None, 0.0, None, math.nan)

    cert._search = search
    return cert, calls


@pytest.mark.parametrize("threshold", [0.31, 0.55, 0.69])
def test_the_ladder_bisects_to_the_boundary_between_certified_and_refuted_levels(threshold):
    ladder, c_nom, geo = (1.0, 0.7, 0.5, 0.3, 0.1), 2.0, object()
    cert, calls = _scripted(ladder, threshold * c_nom)
    level, upper, witness, attempts = cert._ladder(None, None, c_nom, None, geo)
    first = next(f for f in ladder if f <= threshold)  # the first rung certified
    above = ladder[ladder.index(first) - 1]
    width = (above - first) * c_nom / 2**REFINE_STEPS
    assert threshold * c_nom - width <= level <= threshold * c_nom
    assert upper > threshold * c_nom and upper == min(lv for lv, _ in calls if lv > threshold * c_nom)
    assert witness is not None and witness.level == upper
    assert len(attempts) == len(calls) == ladder.index(first) + 1 + REFINE_STEPS
    assert all(g is geo for _, g in calls)


def test_undecided_levels_above_leave_no_upper_bound_and_nothing_certified_means_zero():
    """Undecided rungs above a certified one: bisected the same, but nothing was refuted, so the
    upper bound is infinite. A ladder with no certified rung returns 0 and the least refuted level."""
    cert, _ = _scripted((1.0, 0.5, 0.25), 0.6, above="undecided")
    level, upper, witness, _ = cert._ladder(None, None, 1.0, None, object())
    assert 0.5 <= level <= 0.6 and upper == math.inf and witness is None
    cert, calls = _scripted((1.0, 0.5, 0.25), 0.1)
    level, upper, witness, attempts = cert._ladder(None, None, 1.0, None, object())
    assert level == 0.0 and upper == 0.25 and len(attempts) == 3 and len(calls) == 3
