"""One branch and bound of the FL regulator's certificate (``LevelCertifier.certify``) reports
what it found and nothing else: a refutation names the nonlinear constraint that fails and a
witness, the state of least V on the ellipsoid image's point it sampled, at which the loop's own
constraint Function (not the interval code) is negative and whose V is the reported level, within
{V <= level}; a certification or a spent budget names no constraint and no witness. Verdicts are
ordered along the level. A budget of 100 boxes keeps it to about a second."""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_oc.region.branch_and_bound import LevelCertifier, meets_unit_ball
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.ellipsoid import ellipsoid_image
from maglev_oc.region.feasibility import CONSTRAINT_NAMES, NONLINEAR, FeasibleSet

ORDER = {"certified": 0, "undecided": 1, "refuted": 2}


@pytest.fixture(scope="module")
def certifier(model):
    loop = RegulatorLoop()
    feasible = FeasibleSet(model)
    return feasible, loop, loop.lyapunov_matrix(), LevelCertifier(feasible, loop, max_boxes=100)


def test_a_search_names_a_failing_constraint_only_when_it_refutes(certifier):
    feasible, loop, P, cert = certifier
    ref = Reference.setpoint(0.02)
    fn = feasible.loop_function(loop, ref)
    img = ellipsoid_image(loop, P, cert.rows)
    seen = []
    for level in np.geomspace(1.0, 1e4, 13):  # measured: certified to ~3, refuted from ~30
        b = cert.certify(ref, P, level)
        seen.append(b.status)
        assert b.success == (b.status == "certified")
        if b.status != "refuted":
            assert b.binding == "" and b.witness is None and b.witness_level == math.inf, (level, b.status)
            continue
        assert b.binding in NONLINEAR
        zeta, phase = b.witness[:-1], b.witness[-1]
        z = math.sqrt(level) * img.Pinv_Mt @ np.linalg.solve(img.S, img.chol @ zeta)
        # V of the witness state is the reported level (1e-9: rounding of the solves), inside
        assert z @ P @ z == pytest.approx(b.witness_level, rel=1e-9)
        assert b.witness_level <= level * (1 + 1e-12)
        h = np.asarray(fn(z, phase)).ravel()
        assert h[CONSTRAINT_NAMES.index(b.binding)] < 0, (level, b.binding, h)
    assert set(seen) == set(ORDER)
    ranks = [ORDER[s] for s in seen]
    assert ranks == sorted(ranks), seen


@pytest.mark.parametrize("dims", [3, 4])
def test_a_box_is_kept_exactly_when_it_meets_the_unit_ball(dims):
    """The cover of the unit ball every branch and bound (and the RoA's Jacobian cover) starts
    from: a box is kept if and only if it holds a point of the closed ball. Checked on 3000 random
    boxes, many of them touching the ball only near a corner, against two independent witnesses:
    a sampled point of the box inside the ball (so the box must be kept: a cover with holes would
    leave part of {V <= c} unchecked), and, for a dropped box, the least |x| over it found by
    scipy's bounded minimizer above 1 (1e-9: its tolerance on a convex quadratic)."""
    from scipy.optimize import minimize

    rng = np.random.default_rng(dims)
    n = 3000
    centre = rng.normal(size=(dims, n))
    centre *= rng.uniform(0.6, 1.6, n) / np.linalg.norm(centre, axis=0)
    half = rng.uniform(0.01, 0.4, (dims, n))
    lo, hi = centre - half, centre + half
    keep, near = meets_unit_ball(lo, hi)
    assert 0.2 < keep.mean() < 0.95  # both kinds of box are there
    assert np.all((near >= lo) & (near <= hi))
    pts = lo[:, :, None] + (hi - lo)[:, :, None] * rng.uniform(0, 1, (dims, n, 64))
    inside = np.any(np.sum(pts**2, axis=0) <= 1.0, axis=1)
    assert np.all(keep[inside])
    for k in np.flatnonzero(~keep)[:40]:
        best = minimize(lambda x: x @ x, centre[:, k], bounds=list(zip(lo[:, k], hi[:, k], strict=True)))
        assert best.fun > 1.0 - 1e-9
    for k in np.flatnonzero(keep)[:40]:
        assert near[:, k] @ near[:, k] <= 1.0
