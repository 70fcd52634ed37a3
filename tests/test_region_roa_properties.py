"""Soundness of the linear regulators' region-of-attraction certificate (maglev_oc.region.roa) as
properties checked against independent computations, not remembered numbers.

The certificate {z^' P z^ <= c} rests on three things, each checked here:

* the Jacobian box encloses dg/dl at every point of the certified set (sampled in the 10-D
  ellipsoid and mapped through l = M z^, not through the Cholesky factor the box is built on),
  and g(l) = Delta l with Delta in the box (the mean-value step);
* the decrease test: (A + B Delta M)' P + P (A + B Delta M) is negative definite at every vertex
  of the box at the certified level (recomputed unscaled), and fails at a vertex 1 % above it;
* the stoppers' and the current limit's levels are exact: a start of the set reaches the
  stopper (or |u| = I) at the level, none passes it below, one does above; and a stopper that
  is nearer than the stability level caps the certified level.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from maglev_oc.control.linear_regulator import paper_linear_regulator
from maglev_oc.region.closed_loop import DE1, DE2, E1, E2, Reference
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.roa import LinearizedLoop, RoaCertifier, certify_roa

# off-centre in both coordinates, so the nearer stopper is a different one per axis
TARGET = Reference.setpoint(0.014, 0.030)


@pytest.fixture(scope="module")
def linear(model):
    return paper_linear_regulator(model)


@pytest.fixture(scope="module")
def loop(model, linear):
    return LinearizedLoop(model, linear, TARGET)


@pytest.fixture(scope="module")
def roa(model, linear):
    return certify_roa(model, linear, TARGET)


def _ellipsoid_points(P, level, n, rng, shell=(0.0, 1.0)):
    """n points of {z' P z <= level}, directions uniform, V / level uniform in ``shell``."""
    g = rng.standard_normal((P.shape[0], n))
    g /= np.linalg.norm(g, axis=0)
    g *= np.sqrt(rng.uniform(*shell, n))
    return math.sqrt(level) * np.linalg.solve(np.linalg.cholesky(P).T, g)


def _lyapunov_at(loop, P, delta):
    """(A + B Delta M)' P + P (A + B Delta M) for Delta (2, 3): rows (vertical, horizontal)."""
    A = loop.A + np.outer(np.eye(10)[DE1], delta[0] @ loop.output)
    A = A + np.outer(np.eye(10)[DE2], delta[1] @ loop.output)
    return A.T @ P + P @ A


def test_the_jacobian_box_encloses_the_jacobian_on_the_certified_set(loop, roa):
    """dg/dl at 4000 points of {V <= c} (half of them on the outer 10 % of V) lies in the box."""
    cert = RoaCertifier(loop)
    lo, hi = cert.jacobian_box(roa.P, roa.level_stability)
    rng = np.random.default_rng(11)
    z = np.hstack(
        [
            _ellipsoid_points(roa.P, roa.level_stability, 2000, rng),
            _ellipsoid_points(roa.P, roa.level_stability, 2000, rng, shell=(0.9, 1.0)),
        ]
    )
    ell = loop.output @ z
    jac = np.asarray(loop.remainder_jacobian.map(z.shape[1])(ell)).reshape(2, 3, -1, order="F")
    # the enclosure is rigorous up to a few ulps of outward padding; 1e-9 relative is far above
    tol = 1e-9 * (1.0 + np.abs(jac))
    assert np.all(jac >= lo[:, :, None] - tol) and np.all(jac <= hi[:, :, None] + tol)
    # and the box is not vacuous: every entry with a nonzero range is within 10x the sampled range
    spread = jac.max(axis=2) - jac.min(axis=2)
    live = spread > 1e-12
    assert np.all((hi - lo)[live] <= 10 * spread[live])


def test_the_remainder_is_a_box_matrix_times_l(loop, roa):
    """The mean-value step: g_ax(l) lies in the interval product [Delta_ax] . l at sampled l."""
    cert = RoaCertifier(loop)
    lo, hi = cert.jacobian_box(roa.P, roa.level_stability)
    rng = np.random.default_rng(12)
    ell = loop.output @ _ellipsoid_points(roa.P, roa.level_stability, 3000, rng)
    g = np.asarray(loop.remainder.map(ell.shape[1])(ell))
    for ax in range(2):
        a, b = lo[ax][:, None] * ell, hi[ax][:, None] * ell
        low, high = np.minimum(a, b).sum(axis=0), np.maximum(a, b).sum(axis=0)
        # rounding of g (sums of terms of size |a21 e1| ~ 1e-2 m/s^2): 1e-12 absolute is far above it
        assert np.all(g[ax] >= low - 1e-12) and np.all(g[ax] <= high + 1e-12)


def test_every_vertex_decreases_at_the_certified_level_and_one_does_not_above(loop, roa):
    """The decrease test recomputed without the diagonal scaling: negative definite at all 2^k
    vertices of the certified level's box (and at random interior points), and a vertex with a
    nonnegative eigenvalue in the box 1 % above the level (the bisection stops within 1 %)."""
    cert = RoaCertifier(loop)

    def vertices(box):
        lo, hi = box
        return [
            np.array(c).reshape(2, 3) for c in itertools.product(*zip(lo.ravel(), hi.ravel(), strict=True))
        ]

    box = cert.jacobian_box(roa.P, roa.level_stability)
    worst = max(np.linalg.eigvalsh(_lyapunov_at(loop, roa.P, d)).max() for d in vertices(box))
    assert worst < 0 and cert.decrease_margin(roa.P, box) < 0
    rng = np.random.default_rng(13)
    for _ in range(50):
        d = box[0] + (box[1] - box[0]) * rng.uniform(size=(2, 3))
        assert np.linalg.eigvalsh(_lyapunov_at(loop, roa.P, d)).max() < 0
    assert roa.level_stability < 4 * roa.level_travel  # the bisection, not the cap, ended the search
    above = cert.jacobian_box(roa.P, 1.01 * roa.level_stability)
    assert max(np.linalg.eigvalsh(_lyapunov_at(loop, roa.P, d)).max() for d in vertices(above)) >= 0
    assert cert.decrease_margin(roa.P, above) >= 0


def _reach(P, level, k):
    """The point of {z' P z <= level} farthest along coordinate k: sqrt(level) P^-1 e_k / sqrt(e_k' P^-1 e_k)
    (Cauchy-Schwarz), and its coordinate k."""
    e = np.eye(P.shape[0])[k]
    w = np.linalg.solve(P, e)
    z = math.sqrt(level) * w / math.sqrt(e @ w)
    return z, z[k]


def test_the_stoppers_level_is_where_the_set_first_touches_a_stopper(model, linear):
    """With stoppers 0.1 mm above the gap set-point and 0.2 mm right of the position (nearer than
    the stability level), the certified level is the stoppers': the farthest start reaches the
    nearer stopper exactly, sampled starts below it stay inside, and 1 % above it a start passes."""
    ref = TARGET
    feasible = FeasibleSet(
        model, gap_range=(0.008, ref.gap + 1e-4), position_range=(-0.06, ref.position + 2e-4)
    )
    res = certify_roa(model, linear, ref, feasible=feasible)
    assert res.success and res.level == res.level_travel < res.level_stability
    rooms = {E1: 1e-4, E2: 2e-4}
    reach = {k: _reach(res.P, res.level, k)[1] for k in rooms}
    binding = min(rooms, key=lambda k: rooms[k] - reach[k])
    # exact closed form against the level's own: equal to rounding
    assert reach[binding] == pytest.approx(rooms[binding], rel=1e-9)
    assert all(reach[k] <= rooms[k] * (1 + 1e-9) for k in rooms)
    z = _ellipsoid_points(res.P, res.level, 5000, np.random.default_rng(14), shell=(0.95, 1.0))
    assert np.all(z[E1] <= rooms[E1] * (1 + 1e-9)) and np.all(z[E2] <= rooms[E2] * (1 + 1e-9))
    assert _reach(res.P, 1.01 * res.level, binding)[1] > rooms[binding]
    # the other sides' stoppers are far: moving them changes nothing
    far = FeasibleSet(model, gap_range=(0.002, ref.gap + 1e-4), position_range=(-0.2, ref.position + 2e-4))
    assert certify_roa(model, linear, ref, feasible=far).level_travel == pytest.approx(res.level, rel=1e-12)


def test_without_stoppers_there_is_no_travel_cap(model, linear, roa):
    res = certify_roa(model, linear, TARGET, feasible=FeasibleSet(model, gap_range=None, position_range=None))
    assert res.level_travel == math.inf and res.level == res.level_stability
    # the search grew from 1 and bisected to the same largest level within its 1 %
    assert res.level == pytest.approx(roa.level_stability, rel=0.02)


def test_the_current_level_is_where_the_commanded_current_can_reach_the_limit(loop, roa):
    """|u_eq + du| <= I at sampled starts of the current level's set (du = (K_h z_h, K_v z_v)), and
    the start of that set with the largest |du| (top singular direction, computed separately) has
    |du| = I - |u_eq|: the bound is attained, so the level is the largest the bound allows."""
    limit = 9.0  # FeasibleSet's default (the amplifiers' peak)
    c = roa.level_current
    assert math.isfinite(c) and c > 0
    Mu = loop.output[1:3]
    z = _ellipsoid_points(roa.P, c, 5000, np.random.default_rng(15), shell=(0.9, 1.0))
    u = loop.u_eq[:, None] + Mu @ z
    assert np.all(np.hypot(*u) <= limit * (1 + 1e-9))
    Lc = np.linalg.cholesky(roa.P)  # z = L'^-1 y, |y| <= sqrt(c)
    W = np.linalg.solve(Lc, Mu.T).T  # du = W y
    vt = np.linalg.svd(W)[2]
    zstar = math.sqrt(c) * np.linalg.solve(Lc.T, vt[0])
    assert zstar @ roa.P @ zstar == pytest.approx(c, rel=1e-9)
    assert np.linalg.norm(Mu @ zstar) == pytest.approx(limit - np.linalg.norm(loop.u_eq), rel=1e-9)
    assert (
        certify_roa(
            loop.model, loop.controller, TARGET, feasible=FeasibleSet(loop.model, current_limit=None)
        ).level_current
        == math.inf
    )


def test_a_setpoint_on_a_stopper_certifies_nothing(model, linear):
    """No room to the stopper: the level is 0, and the result says that nothing is certified."""
    res = certify_roa(model, linear, TARGET, feasible=FeasibleSet(model, gap_range=(0.008, TARGET.gap)))
    assert res.level_travel == 0.0 and res.level == 0.0
    assert not res.success and res.status == "not_certified"
    assert res.value(np.zeros(10)) == math.inf  # no start is inside an empty certificate


def test_a_given_p_is_the_certificates_own_symmetrised(model, linear, roa):
    """{z' (k P) z <= k c} is {z' P z <= c}: handed 3 P0 (P0 the default, the Lyapunov equation's)
    plus a skew-symmetric part, which adds nothing to a quadratic form, the certificate keeps the
    symmetric part of the matrix it was given and its exact levels (the stoppers', the current
    limit's) are 3 times the default's (1e-9 relative: two Cholesky solves of the same set), and so
    is the bisected stability level (its trial levels scale with P; measured 3 to 1e-15, asserted
    to 1e-6)."""
    P0 = roa.P
    skew = 1e-3 * np.abs(P0).max() * np.triu(np.ones_like(P0), 1)
    res = certify_roa(model, linear, TARGET, P=3.0 * P0 + skew - skew.T)
    np.testing.assert_allclose(res.P, 3.0 * P0, rtol=0, atol=1e-12 * np.abs(P0).max())
    assert res.level_travel == pytest.approx(3.0 * roa.level_travel, rel=1e-9)
    assert res.level_current == pytest.approx(3.0 * roa.level_current, rel=1e-9)
    assert res.level_stability == pytest.approx(3.0 * roa.level_stability, rel=1e-6)
