"""Properties of the microstepper's certified level (``maglev_oc.region.microstepper``), checked
against IPOPT's least violations, sampling of the level sets and closed forms of its ellipsoid:

- a level above a known violation is never certified, also off-centre on the positive side, and
  no sampled violation lies below the refutation, which draws its starts from the seed given;
- the half-widths are reached inside the certified set; a level no pass could certify is
  undecided; the result reports its total wall time.
"""

from __future__ import annotations

import math
import time

import casadi as ca
import numpy as np
import pytest

from maglev_oc.model.allocation import MicrostepperTransformation
from maglev_oc.model.platform import microstepper
from maglev_oc.region.microstepper import AXES, MICROSTEPPER_CONSTRAINTS, MicrostepperRegion
from maglev_oc.results import check_result
from tests.test_microstepper_region import PLATFORM, _violations


# --- the microstepper -----------------------------------------------------------------------------
@pytest.mark.parametrize("setpoint", [(0.04, -0.04, 0.021), (0.0, 0.0, 0.025)])
def test_a_microstepper_level_above_a_known_violation_is_never_certified(setpoint):
    """The microstepper's branch and bound accepts a box only when every constraint holds on it:
    IPOPT's least V at which a pair's current exceeds 9 A (near the stator, and at 25 mm) is an
    infeasible point of {V <= 1.05 that level}, so that level must not be certified."""
    region = MicrostepperRegion(microstepper(), stoppers=False)
    found, why, _ = region.refute(setpoint, starts=4)
    assert math.isfinite(found) and why.startswith("headroom")
    status, *_ = region.certify(setpoint, 1.05 * found, max_boxes=200_000)
    assert status != "certified"


# --- the microstepper and the SDP ---------------------------------------------------------------
def test_the_microstepper_half_widths_are_reached_inside_its_certified_set():
    """``half_widths``: the largest error of each axis inside {V <= level}, sqrt(level (P^-1)_jj),
    reached at the point P^-1 e_j scaled to V = level (computed here from P's inverse). A cheap
    case: 20 A at 10 mm, no stoppers (its refutation is 45.4, seed37's test)."""
    region = MicrostepperRegion(current_limit=20.0, stoppers=False)
    # a loose bracket (any certified level has these half-widths) keeps the test to about a second
    res = region.largest_level((0.0, 0.0, 0.010), rel_tol=0.5, max_boxes=20_000)
    assert res.success
    p_inv = np.linalg.inv(region.P)
    for axis, j in (("x", 0), ("y", 5), ("gap", 10)):
        z = p_inv[:, j] * math.sqrt(res.level / p_inv[j, j])
        assert z @ region.P @ z == pytest.approx(res.level, rel=1e-9)
        assert res.half_widths[axis] == pytest.approx(z[j], rel=1e-9)


@pytest.mark.parametrize(
    ("limit", "setpoint", "status"),
    [
        # 3 mm below the 35 mm stopper: the stopper binds; a coarse bracket (rel_tol 0.5) and a
        # small box budget keep it to a fraction of a second (measured 0.25 s)
        (None, (0.0, 0.0, 0.032), "certified"),
        # 0.5 A cannot hold the mover at 25 mm (the equilibrium needs more): refused at once
        (0.5, (0.0, 0.0, 0.025), "infeasible_setpoint"),
    ],
    ids=["certified", "infeasible"],
)
def test_the_microstepper_level_reports_its_total_wall_time(limit, setpoint, status):
    """``timings == {"total": t}`` with 0 < t <= the wall time measured around the call (the
    result's clock starts after the call begins and stops before it returns)."""
    kwargs = {} if limit is None else {"current_limit": limit}
    region = MicrostepperRegion(PLATFORM, **kwargs)
    t0 = time.perf_counter()
    res = region.largest_level(setpoint, rel_tol=0.5, max_boxes=20_000)
    wall = time.perf_counter() - t0
    assert res.status == status, res.message
    assert set(res.timings) == {"total"}
    assert 0 < res.timings["total"] <= wall
    assert "timings [s]: total " in res.report()
    check_result(res)  # success a Python bool (it was numpy's np.True_ when certified), the rest
    if status == "infeasible_setpoint":
        # the set-point itself (V = 0) breaks a constraint: nothing is certified, and the least
        # refuted level is 0, a number a table can print (not a missing value)
        assert res.level == 0.0 and res.refuted_level == 0.0 and res.binding


MM = 1e-3


# --- the microstepper's refutation -----------------------------------------------------------------
@pytest.fixture(scope="module")
def stepper20():
    """The free microstepper (no stoppers) with a 20 A current limit: at a 10 mm gap the
    current of pair B (the pair that lifts against the gap) fails first, at V about 45; R >= 0
    and pair A's current fail further out (V about 53), so a search that misses pair B's
    boundary reports a bound about 16 % too high."""
    return MicrostepperRegion(microstepper(), stoppers=False, current_limit=20.0)


def _constraints(platform, limit: float) -> ca.Function:
    """(R, pair A's headroom, pair B's headroom) [A^2] at l = (e_gap, v_x, v_y, v_gap) and the
    set-point gap, from the model's transformation alone (not the region's functions)."""
    ell, gap0 = ca.SX.sym("l", 4), ca.SX.sym("gap0")
    u, R = MicrostepperTransformation(platform).function(gap0 + ell[0], ell[1:4])
    lim2 = limit**2
    return ca.Function(
        "h", [ell, gap0], [ca.vertcat(R, lim2 - u[0] ** 2 - u[1] ** 2, lim2 - u[2] ** 2 - u[3] ** 2)]
    )


def test_no_sampled_violation_lies_below_the_microstepper_refutation(stepper20):
    """A sampling of {V = t^2} along 2000 random rays l = t chol(S) zeta (|zeta| = 1, 120 steps
    of t up to V = 64, the gap kept >= 1 mm as the refutation keeps it) finds violating states;
    every one is an upper bound on c*, and the refutation, which minimises V on each boundary,
    must not be above the least of them (measured: refutation 45.38 on pair B's current, the
    sampling's least 46.3; a search missing that boundary gives 52.85). The refutation's state
    itself violates the constraint it names, with V = the level it reports."""
    region, gap = stepper20, 10 * MM
    h = _constraints(region.platform, region.current_limit)
    level, name, ell = region.refute((0.0, 0.0, gap))
    rng = np.random.default_rng(37)
    zeta = rng.standard_normal((4, 2000))
    zeta /= np.linalg.norm(zeta, axis=0)
    ts = np.linspace(0.1, 8.0, 120)
    ells = ((region.chol @ zeta)[:, :, None] * ts).reshape(4, -1)
    hv = np.asarray(h.map(ells.shape[1])(ells, gap))
    violating = np.any(hv <= 0, axis=0) & (gap + ells[0] >= 1 * MM)
    sampled = np.min(np.where(violating.reshape(2000, ts.size), ts**2, np.inf))
    assert np.isfinite(sampled) and sampled < 1.1 * level  # the sampling is fine enough to matter
    assert level <= sampled
    assert name == "headroom_B"
    assert float(ell @ np.linalg.solve(region.S, ell)) == pytest.approx(level, rel=1e-12)
    assert gap + ell[0] >= 1 * MM and float(h(ell, gap)[2]) <= 1e-9 * 400


# --- the microstepper's region when nothing can be certified -------------------------------------
def test_a_microstepper_level_that_no_pass_could_certify_is_undecided(monkeypatch):
    """Every branch-and-bound pass after the set-point's own check (level 1e-12) runs out of its
    budget (planted: "undecided" after one box): the bisection certifies nothing, and the result
    says so, success False and status "undecided", with level 0 and zero half-widths; the upper
    end of the bracket and its constraint are still those of the refutation."""
    region = MicrostepperRegion(PLATFORM)
    setpoint = (0.0, 0.0, 0.025)
    certify = region.certify
    levels = []

    def out_of_budget(sp, level, *, max_boxes=1_000_000):
        levels.append(level)
        if len(levels) == 1:  # the set-point's own check (at 1e-12), done for real
            return certify(sp, level, max_boxes=max_boxes)
        return "undecided", 1, "", None

    monkeypatch.setattr(region, "certify", out_of_budget)
    res = region.largest_level(setpoint)
    check_result(res)
    assert levels[0] == 1e-12 and len(levels) > 2  # the check, the refuted level, the bisection
    assert (res.success, res.status, res.level) == (False, "undecided", 0.0)
    assert res.half_widths == dict.fromkeys(AXES, 0.0)
    assert res.binding in (*MICROSTEPPER_CONSTRAINTS, *AXES) and res.refuted_level > 0
    assert res.message.startswith("certified V <= 0;") and res.binding in res.message


# --- the microstepper's branch and bound covers the whole box -----------------------------------------
def test_no_level_above_a_failing_point_on_the_positive_side_is_certified():
    """R >= 0 alone (no current limit, no stoppers) off-centre at (40, -40, 22) mm: IPOPT's least
    violation of R >= 0 (the "margin" case of tests/test_microstepper_region.py) lies where the gap
    error and the velocities are positive, in the upper corner of the box the search covers. The
    state is checked with the controller's own Function, not the interval code. It lies inside
    {V <= 1.01 V_there}, so that level must never come out certified. With 100 000 boxes the
    search goes deep enough to find it (refuted after about 110 000 boxes, measured). Running out
    of budget ("undecided") would also be sound; only "certified" is wrong."""
    region = MicrostepperRegion(PLATFORM, current_limit=None, stoppers=False)
    setpoint = (0.04, -0.04, 0.022)
    found, binding, ell = region.refute(setpoint)
    assert binding == "margin"
    z = region.state_of(ell)
    assert z @ region.P @ z == pytest.approx(found, rel=1e-9)  # rounding of the quadratic form
    assert _violations(region, setpoint, 1.0001 * z[:, None])["margin"] == 1
    status, _, _, _ = region.certify(setpoint, 1.01 * found, max_boxes=100_000)
    assert status != "certified"


def test_the_microstepper_refutation_draws_its_starts_from_the_seed_it_is_given(monkeypatch):
    from maglev_oc.region.microstepper import MicrostepperRegion

    seeds = []
    original = np.random.default_rng

    def recording(seed=None):
        seeds.append(seed)
        return original(seed)

    region = MicrostepperRegion(current_limit=20.0, stoppers=False)
    monkeypatch.setattr(np.random, "default_rng", recording)
    a = region.refute((0.0, 0.0, 0.010), starts=1, seed=7)
    b = region.refute((0.0, 0.0, 0.010), starts=1, seed=7)
    assert seeds == [7, 7]
    assert a[:2] == b[:2]
    assert (a[2] is None and b[2] is None) or np.array_equal(a[2], b[2])
