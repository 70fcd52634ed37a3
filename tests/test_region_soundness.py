"""Soundness of the region certificates as properties, not as remembered numbers.

A certificate says: every start in {z~' P z~ <= c} keeps the closed loop in F. It is worth only
what these hold to:

* every interval enclosure the branch and bound relies on contains the values sampled in its box
  (the certifier's constraint function over (zeta, phase) boxes, the feasible set's pointwise
  constraints over state boxes);
* every certified level is refuted just above it (1.01 c: by the branch and bound for R >= 0 and
  |u| <= I, by the closed-form maximum of a coordinate over the ellipsoid for the stoppers) and
  holds under dense sampling just below it (0.9-0.999 c, every constraint of F);
* each constraint of F (headroom, margin, both gap stoppers, both position stoppers) is the
  binding one in some case below (off-centre set-points, limits switched off), so a bug in any
  of them changes a tested level;
* the Monte Carlo checks flag runs started outside, with and without the current limit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.ellipsoid import ellipsoid_image
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.montecarlo import BatchSimulator, check_error_states
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.sim.twin import RigTwin

# (set-point gap [m], position [m], FeasibleSet options, the constraint that binds): one case per
# constraint of F; the bindings were found by running Procedure 2 and are asserted below
CASES = [
    (0.020, 0.0, {}, "headroom"),
    (0.020, 0.0, {"gap_range": None, "current_limit": None}, "margin"),
    (0.012, 0.0, {}, "gap_low"),
    (0.020, 0.0, {"current_limit": None}, "gap_high"),
    (0.020, 0.055, {}, "position_high"),
    (0.020, -0.055, {"current_limit": None}, "position_low"),
]
STOPPER_ROW = {"gap_low": (0, -1), "gap_high": (0, 1), "position_low": (5, -1), "position_high": (5, 1)}
"""The error coordinate z~[k] a stopper limits, and on which side."""


@pytest.fixture(scope="module")
def loop():
    return RegulatorLoop()


@pytest.fixture(scope="module")
def certificates(model, loop):
    out = {}
    for gap, position, options, binding in CASES:
        proc = Procedure2(FeasibleSet(model, **options), loop)
        out[binding] = (proc, proc.run(Reference.setpoint(gap, position)))
    return out


def _ellipsoid_points(P, level, n, shell, rng):
    """n points of {z' P z <= level} with V / level uniform in ``shell`` (directions uniform)."""
    g = rng.standard_normal((P.shape[0], n))
    g /= np.linalg.norm(g, axis=0)
    g *= np.sqrt(rng.uniform(*shell, n))
    return math.sqrt(level) * np.linalg.solve(np.linalg.cholesky(P).T, g)


@pytest.mark.parametrize("binding", [c[3] for c in CASES])
def test_each_constraint_binds_somewhere(certificates, binding):
    _, res = certificates[binding]
    assert res.success and res.binding == binding
    assert 0 < res.level <= res.level_upper


@pytest.mark.parametrize("binding", [c[3] for c in CASES])
def test_holds_under_dense_sampling_just_below(certificates, binding):
    proc, res = certificates[binding]
    rng = np.random.default_rng(7)
    z = _ellipsoid_points(res.P, 0.999 * res.level, 20_000, (0.81, 1.0), rng)
    fn = proc.feasible.loop_function(proc.loop, res.reference)
    h = np.asarray(fn.map(z.shape[1])(z, np.zeros((1, z.shape[1]))))
    assert np.all(h >= 0), f"{np.sum(np.any(h < 0, axis=0))} of 20000 sampled starts outside F"


@pytest.mark.parametrize("binding", [c[3] for c in CASES])
def test_refuted_just_above(certificates, binding):
    proc, res = certificates[binding]
    above = 1.01 * res.level
    if binding in STOPPER_ROW:
        # independent closed form: max of z~[k] over {z' P z <= c} is sqrt(c (P^-1)_kk)
        k, side = STOPPER_ROW[binding]
        stoppers = proc.feasible.gap_range if k == 0 else proc.feasible.position_range
        centre = res.reference.gap if k == 0 else res.reference.position
        room = (stoppers[1] - centre) if side > 0 else (centre - stoppers[0])
        reach = math.sqrt(above * np.linalg.inv(res.P)[k, k])
        assert reach > room  # just above the level, a start reaches past the stopper
        assert math.sqrt(0.999 * res.level * np.linalg.inv(res.P)[k, k]) < room
    else:
        out = proc.certifier.certify(res.reference, res.P, above)
        assert out.status == "refuted" and out.binding == binding, out.message
        assert out.witness_level <= above


@st.composite
def _boxes(draw):
    """A box of (zeta (3) in the unit cube, phase in [0, 2 pi)): (lo (4,), hi (4,))."""
    lo, hi = [], []
    for _ in range(3):
        a = draw(st.floats(-1.0, 1.0))
        lo.append(a)
        hi.append(min(a + draw(st.floats(1e-3, 1.0)), 1.0))
    p = draw(st.floats(0.0, 2 * math.pi))
    lo.append(p)
    hi.append(min(p + draw(st.floats(0.0, 1.5)), 2 * math.pi))
    return np.array(lo), np.array(hi)


@settings(max_examples=60, deadline=None)
@given(box=_boxes(), which=st.sampled_from(["headroom", "margin"]), seed=st.integers(0, 2**16))
def test_certifier_enclosure_contains_sampled_values(certificates, loop, box, which, seed):
    """The interval enclosure of (margin, headroom) over a box of (zeta, phase) contains the
    function's values at points sampled in the box (with the sinusoid's offsets, so the phase
    matters)."""
    proc, res = certificates[which]
    cert = proc.certifier
    lo, hi = box
    img = ellipsoid_image(loop, res.P)
    par_l = (math.sqrt(res.level) * img.chol).ravel(order="F")[:, None]
    par_f = loop.offset_coefficients(Reference.paper_sinusoid()).ravel(order="F")[:, None]
    hlo, hhi = cert._ifn(
        [lo[:3, None], lo[3:4, None], par_l, par_f], [hi[:3, None], hi[3:4, None], par_l, par_f]
    )
    rng = np.random.default_rng(seed)
    pts = lo[:, None] + (hi - lo)[:, None] * rng.uniform(size=(4, 200))
    pts[:, :2] = np.column_stack([lo, hi])  # the corners of the diagonal too
    vals = np.asarray(cert._fn.map(pts.shape[1])(pts[:3], pts[3:4], par_l, par_f))
    tol = 1e-9 * (1.0 + np.abs(vals))
    assert np.all(vals >= hlo[0] - tol) and np.all(vals <= hhi[0] + tol)


@settings(max_examples=60, deadline=None)
@given(
    gap=st.floats(0.008, 0.030),
    width=st.floats(1e-5, 5e-3),
    v1=st.floats(-200.0, 200.0),
    v2=st.floats(-200.0, 200.0),
    vw=st.floats(1e-3, 50.0),
    limited=st.booleans(),
    seed=st.integers(0, 2**16),
)
def test_feasible_set_enclosure_contains_sampled_values(model, gap, width, v1, v2, vw, limited, seed):
    feasible = FeasibleSet(model, current_limit=9.0 if limited else None)
    lo = np.array([[gap], [v1], [v2]])
    hi = lo + np.array([[width], [vw], [vw]])
    rest = np.zeros((3, 1))  # x2, x3, x4: no compensation, they do not enter
    x_lo, x_hi = np.vstack([lo[:1], rest]), np.vstack([hi[:1], rest])
    hlo, hhi = feasible.pointwise_interval([x_lo, lo[1:]], [x_hi, hi[1:]])
    rng = np.random.default_rng(seed)
    pts = lo + (hi - lo) * rng.uniform(size=(3, 200))
    vals = feasible.evaluate(pts[0], pts[1], pts[2])
    tol = 1e-9 * (1.0 + np.abs(vals))
    assert np.all(vals >= hlo[0] - tol) and np.all(vals <= hhi[0] + tol)


@pytest.mark.parametrize("limit", [9.0, None], ids=["current-limit", "no-current-limit"])
def test_monte_carlo_flags_starts_outside(model, loop, limit):
    """Starts at 4x the certified level along the refuting witness leave F on the sampled twin
    (headroom with the limit, R < 0 without it); starts at half the level do not."""
    feasible = FeasibleSet(model, current_limit=limit, gap_range=None)
    res = Procedure2(feasible, loop).run(Reference.setpoint(0.02))
    sim = BatchSimulator(RigTwin(model), FeedbackLinearizingRegulator(model), duration=0.4, compile=False)
    w = res.witness / math.sqrt(res.witness @ res.P @ res.witness / res.level)
    z = np.column_stack([0.5 * w, 2.0 * w])
    chk = check_error_states(sim, loop, res.reference, res.P, res.level, z, current_limit=limit)
    assert list(chk.violating) == [False, True], chk.message
    assert not chk.success and chk.violations == 1
