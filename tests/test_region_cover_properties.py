"""The grids every branch and bound of the certificates starts from cover what they must.

A certificate examines {V <= c} through boxes in the coordinates zeta of its image, where the set
is the unit ball: the 2-DOF level certifier (:func:`initial_boxes`), the microstepper's (a 4-D
grid) and the region-of-attraction's Jacobian enclosure (:class:`RoaCertifier`). A grid that left
part of the cube out would leave that part of the set unexamined and the certificate unsound: the
seed-42 mutation sample found the microstepper's grid cut at 6 edges for 4 cells (the positive side
above 0.6 never looked at), which certified 1.01x a refuted level. All three now start from
:func:`cube_grid`; these are its properties and the covers built on it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_oc.control.linear_regulator import paper_linear_regulator
from maglev_oc.errors import InputError
from maglev_oc.region.branch_and_bound import bisect_widest, cube_grid, initial_boxes, meets_unit_ball
from maglev_oc.region.closed_loop import Reference
from maglev_oc.region.roa import LinearizedLoop, RoaCertifier


def _holders(lo: np.ndarray, hi: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(n,) how many boxes (lo, hi) (d, k) hold each of ``points`` (d, n) (closed boxes)."""
    inside = (lo[:, :, None] <= points[:, None, :]) & (points[:, None, :] <= hi[:, :, None])
    return np.sum(np.all(inside, axis=0), axis=0)


@pytest.mark.parametrize(("cells", "dims"), [(4, 3), (4, 4), (14, 3), (1, 2), (3, 1)])
def test_the_grid_tiles_the_cube(cells, dims):
    """cells^dims boxes of width 2 / cells inside [-1, 1]^dims, of total volume 2^dims (exact in
    binary for these widths up to rounding, 1e-12); every random point of the cube lies in exactly
    one (a shared face has probability zero), and the corners +-1 lie in one each."""
    lo, hi = cube_grid(cells, dims)
    assert lo.shape == hi.shape == (dims, cells**dims)
    assert np.all(lo >= -1.0) and np.all(hi <= 1.0)
    np.testing.assert_allclose(hi - lo, 2.0 / cells, rtol=1e-12)
    assert np.prod(hi - lo, axis=0).sum() == pytest.approx(2.0**dims, rel=1e-12)
    points = np.random.default_rng(42).uniform(-1, 1, (dims, 2000))
    assert np.all(_holders(lo, hi, points) == 1)
    corners = np.array([np.full(dims, 1.0), np.full(dims, -1.0)]).T
    assert np.all(_holders(lo, hi, corners) == 1)


@pytest.mark.parametrize(("cells", "dims"), [(0, 3), (4, 0), (-1, 2)])
def test_an_empty_grid_is_refused(cells, dims):
    with pytest.raises(InputError, match="cube_grid"):
        cube_grid(cells, dims)


@pytest.mark.parametrize("periodic", [False, True])
def test_the_level_certifiers_first_boxes_cover_the_cube_and_one_period(periodic):
    """4^3 boxes of the cube times 6 phase cells over [0, 2 pi) for a sinusoid, each (zeta, phase)
    in one box; for a set-point the phase is pinned at 0."""
    lo, hi = initial_boxes(periodic, 6)
    rng = np.random.default_rng(7)
    zeta = rng.uniform(-1, 1, (3, 1000))
    phase = rng.uniform(0, 2 * math.pi, (1, 1000)) if periodic else np.zeros((1, 1000))
    assert np.all(_holders(lo, hi, np.vstack([zeta, phase])) == 1)
    assert lo.shape[1] == 64 * (6 if periodic else 1)
    if not periodic:
        assert np.all(lo[3] == 0) and np.all(hi[3] == 0)


def test_the_roa_certifiers_cover_holds_every_point_of_the_unit_ball(model):
    """The Jacobian enclosure of :class:`RoaCertifier` is taken over the grid's boxes that meet the
    unit ball (14^3 cells by default): every point of the ball, random and on its surface, lies in a
    kept box, and exactly the boxes that meet the ball are kept."""
    loop = LinearizedLoop(model, paper_linear_regulator(model), Reference.setpoint(0.02))
    cert = RoaCertifier(loop)
    rng = np.random.default_rng(3)
    d = rng.standard_normal((3, 2000))
    d /= np.linalg.norm(d, axis=0)
    points = np.hstack([d * rng.uniform(0, 1, 2000) ** (1 / 3), d])  # inside and on the sphere
    assert np.all(_holders(cert._lo, cert._hi, points) >= 1)
    lo, hi = cube_grid(cert.cover, 3)
    keep, _ = meets_unit_ball(lo, hi)
    assert cert._lo.shape[1] == int(keep.sum()) < lo.shape[1]


def test_without_a_current_limit_the_headroom_is_one_everywhere():
    """constraints_from_coefficients (the SDP's numpy twin of the constraints): with no current
    limit the headroom is documented as 1, an array of the margin's shape and of floats (the SDP's
    bisection compares it elementwise with 0 beside the margin)."""
    from maglev_oc.model.stage import StageModel
    from maglev_oc.region.feasibility import constraints_from_coefficients

    model = StageModel()
    coef = model.coefficients(np.linspace(0.012, 0.026, 5))[:, None, :]  # (4, 1, 5)
    v1, v2 = np.zeros((3, 5)), np.linspace(-5.0, 5.0, 15).reshape(3, 5)
    margin, headroom = constraints_from_coefficients(coef, v1, v2, 9.81, None)
    assert margin.shape == headroom.shape == (3, 5)
    assert headroom.dtype == np.float64 and np.all(headroom == 1.0)
    _, limited = constraints_from_coefficients(coef, v1, v2, 9.81, 9.0)
    assert limited.shape == (3, 5) and np.all(limited <= 81.0)  # 9 A^2 less what the currents use


@pytest.mark.parametrize("seed", range(6))
def test_bisection_halves_each_box_along_its_widest_scaled_side_and_the_halves_tile_it(seed):
    """Every box of a branch and bound is replaced by its two halves: together they hold every
    point of it exactly once (a shared face has probability zero) and have its volume; the cut is
    at the midpoint of the side that is widest after scaling, and a side of zero scale is never
    cut. A half that went missing would leave part of the set unexamined (an unsound
    certificate). The boxes handed in are left as they were."""
    rng = np.random.default_rng(seed)
    d, k = 4, 7
    lo = rng.uniform(-1, 0, (d, k))
    hi = lo + rng.uniform(0.05, 1.0, (d, k))
    scale = np.array([1.0, 3.0, 0.0, 0.5]) if seed % 2 else None
    before = lo.copy(), hi.copy()
    lo2, hi2 = bisect_widest(lo, hi, scale)
    np.testing.assert_array_equal(lo, before[0])
    np.testing.assert_array_equal(hi, before[1])
    assert lo2.shape == hi2.shape == (d, 2 * k) and np.all(lo2 < hi2)
    weights = np.ones(d) if scale is None else scale
    for j in range(k):
        halves = [j, j + k]
        volume = np.prod(hi2[:, halves] - lo2[:, halves], axis=0)
        assert volume.sum() == pytest.approx(np.prod(hi[:, j] - lo[:, j]), rel=1e-12)
        axis = int(np.argmax((hi[:, j] - lo[:, j]) * weights))
        assert weights[axis] > 0
        cut = np.flatnonzero(
            np.any(lo2[:, halves] != lo[:, [j, j]], axis=1) | np.any(hi2[:, halves] != hi[:, [j, j]], axis=1)
        )
        assert cut.tolist() == [axis]
        assert hi2[axis, j] == lo2[axis, j + k] == pytest.approx(0.5 * (lo[axis, j] + hi[axis, j]), rel=1e-15)
        points = lo[:, [j]] + (hi[:, [j]] - lo[:, [j]]) * rng.uniform(size=(d, 500))
        np.testing.assert_array_equal(_holders(lo2[:, halves], hi2[:, halves], points), 1)
