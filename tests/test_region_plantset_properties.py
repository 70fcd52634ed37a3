"""Uncertainty sets of the plant's constants (maglev_oc.region.sweep.PlantSet) checked against
independent computations: a confidence ellipsoid holds its level of the estimate's normal
distribution (with the chi-square quantile of ``scipy.stats`` at the covariance's rank), sampled
plants are members and points just outside are not, and levels that name no bounded set are
refused.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_oc.region.sweep import PlantSet

C = np.array([0.28, 760.0, 310.0, 2.2e-3])  # constants of the papers' size (C1..C4)


def _covariance(rank: int, rng) -> np.ndarray:
    """A covariance of (C1..C4) with relative errors of a few percent and the given rank (the
    constants beyond it held fixed: zero rows and columns)."""
    A = rng.normal(size=(4, 4)) * (0.03 * C)[:, None]
    A[rank:] = 0.0
    return A @ A.T


@pytest.mark.parametrize("rank", [4, 2])
@pytest.mark.parametrize("level", [0.5, 0.9])
def test_a_confidence_ellipsoid_holds_its_level_of_the_estimates_distribution(rank, level):
    """Of 20 000 draws from N(mean, covariance) a share ``level`` lies inside, within 5 binomial
    standard errors (the set is the chi-square quantile at the covariance's rank; with the full
    dimension instead the share would be off by 0.2-0.4 at rank 2)."""
    rng = np.random.default_rng(rank * 10 + int(level * 10))
    cov = _covariance(rank, rng)
    plants = PlantSet.confidence(C, cov, level)
    n = 20_000
    draws = rng.multivariate_normal(C, cov, size=n, method="eigh").T
    share = float(np.mean(plants.contains(draws)))
    assert abs(share - level) <= 5 * math.sqrt(level * (1 - level) / n), share


def test_sampled_plants_are_members_and_points_just_outside_are_not():
    rng = np.random.default_rng(3)
    for plants in (
        PlantSet.confidence(C, _covariance(4, rng), 0.9),
        PlantSet.confidence(C, _covariance(3, rng), 0.9),
        PlantSet.box(0.95 * C, 1.1 * C),
    ):
        s = plants.sample(2000, rng)
        assert np.all(plants.contains(s)), plants.label
        centre = np.asarray(plants.center)[:, None]
        # the farthest sampled plant pushed 2 % further from the centre leaves the set
        d = s - centre
        if plants.kind == "box":
            far = centre + 1.02 * (np.asarray(plants.upper) - np.asarray(plants.center))[:, None]
        else:
            pinv = np.linalg.pinv(np.asarray(plants.shape))
            v = np.einsum("in,ij,jn->n", d, pinv, d)
            far = centre + d[:, [int(np.argmax(v))]] * 1.02 / math.sqrt(v.max())
        assert not plants.contains(far)[0], plants.label
    # a plant off the span of a rank-deficient ellipsoid (a constant held fixed) is outside it
    flat = PlantSet.confidence(C, _covariance(2, rng), 0.99)
    moved = C.copy()
    moved[3] *= 1 + 1e-6
    assert flat.contains(C[:, None])[0] and not flat.contains(moved[:, None])[0]


@pytest.mark.parametrize("level", [0.0, 1.0, -0.1, 1.5, math.nan])
def test_a_confidence_level_outside_zero_one_is_refused(level):
    # level 1 would be the chi-square quantile inf: an unbounded "set"
    with pytest.raises(ValueError, match="confidence level"):
        PlantSet.confidence(C, np.diag((0.02 * C) ** 2), level)
