"""Properties that catch wrong answers in ``maglev_oc.region`` which the other region tests let
through (issue 21: "Tests that would catch a wrong answer: certificate soundness and the
statistics"). Each property was found by injecting a small plausible bug (a wrong sign, index,
comparison, factor, a dropped validation or an ignored option) into the region package, one at a
time, and running the quick region tests: these are the bugs nothing caught, each turned into a
property that holds for the right code whatever its implementation, with the origin of every
tolerance written beside it.

* F's set-point check: the stoppers are strict (a set-point on a stopper is refused, one just
  inside is accepted), and stoppers at a gap <= 0 are refused when a FeasibleSet is made.
* F on the closed loop (``loop_function``) is F evaluated pointwise at the physical state the loop
  is in: the same numbers from :meth:`RegulatorLoop.physical_state`, the accelerations v = K z and
  :meth:`FeasibleSet.evaluate`, for a compensation that depends on every state.
* Every boundary point of a feasibility map satisfies the other constraints of F.
* The largest (e1, e2) rectangle lies inside its ellipse and no densely sampled one is larger.
* Each stopper's level touches that stopper over the whole reference orbit (numpy, dense phases).
* A sinusoid's level 1 % above IPOPT's least infeasible V is never certified, whichever half of
  the orbit binds (the branch and bound covers every phase).
* A refutation's state has the searched image and the least V; a level that is not positive and
  finite is refused.
* The SDP's inner polygon proves a vertex only if every constraint holds on all its cells (a
  vertex infeasible on a thin sliver of the gap range is not proved); the reach along a direction
  ends exactly on the certified set's boundary.
* The robust certificate's worst plant lies in Theta and attains the sup of dV/dt, which no
  sampled plant exceeds.
* Plants are uniform in a confidence ellipsoid of any rank (share within half the radius 0.5^k).
* A sweep flags a planted current-limit violation against its own ``current_limit``.
* The microstepper never certifies a level 5 % above IPOPT's least violation.
* The study predicts a stopper hit for a step exactly when the linear response (integrated
  independently) reaches either stopper.
"""

from __future__ import annotations

import dataclasses
import math

import casadi as ca
import numpy as np
import pytest
from scipy.linalg import expm

from maglev_oc.errors import InputError
from maglev_oc.model.equilibrium import equilibrium_currents
from maglev_oc.model.platform import microstepper
from maglev_oc.region.boundary import BoundaryMinimizer
from maglev_oc.region.branch_and_bound import LevelCertifier
from maglev_oc.region.closed_loop import N_ERROR, Reference, RegulatorLoop
from maglev_oc.region.ellipsoid import max_rectangle
from maglev_oc.region.feasibility import (
    CONSTRAINT_NAMES,
    FeasibleSet,
    constraints_from_coefficients,
    feasibility_map,
)
from maglev_oc.region.microstepper import MicrostepperRegion
from maglev_oc.region.procedure2 import Procedure2, _travel_levels
from maglev_oc.region.robust_certificate import RobustCertifier
from maglev_oc.region.sdp import PolygonBuilder, enlarge
from maglev_oc.region.study import _predicted_stoppers, step_extremes
from maglev_oc.region.sweep import PlantSet, SweepSpec, run_sweep


# --- the feasible set F -------------------------------------------------------------------------
def test_a_setpoint_on_a_stopper_is_refused_and_one_just_inside_is_held(model):
    """The stoppers bound F strictly (``check_setpoint``: "strictly between the stoppers"). Without
    a current limit only R >= 0 and the stoppers remain, and R > 0 at rest over 8-30 mm: at a
    stopper the set-point is refused by the stopper check alone; 0.1 mm inside it is held."""
    feasible = FeasibleSet(model, current_limit=None)
    (g_lo, g_hi), (p_lo, p_hi) = feasible.gap_range, feasible.position_range
    for gap, position in ((g_lo, 0.0), (g_hi, 0.0), (0.02, p_lo), (0.02, p_hi)):
        with pytest.raises(InputError, match="strictly between the stoppers"):
            feasible.check_setpoint(gap, position)
    for gap, position in ((g_lo + 1e-4, 0.0), (g_hi - 1e-4, 0.0), (0.02, p_lo + 1e-4), (0.02, p_hi - 1e-4)):
        feasible.check_setpoint(gap, position)


@pytest.mark.parametrize("low", [0.0, -1e-3])
def test_stoppers_at_a_gap_of_zero_or_below_are_refused(model, low):
    """A gap is positive (the field model is not defined at a closed gap): a lower stopper at or
    below 0 m is an input error, not a feasible set."""
    with pytest.raises(InputError, match="gap_range"):
        FeasibleSet(model, gap_range=(low, 0.03))


def _every_state_compensation() -> ca.Function:
    """A smooth effect x (4) -> (x2', x4') [m/s^2] that depends on every state, the way friction
    (velocities) and cogging or a cable carrier (position) do; coefficients of the size of the
    rig's effects (a few m/s^2 over the states' ranges)."""
    x = ca.SX.sym("x", 4)
    d_vertical = -20.0 * x[1] + 30.0 * x[2] - 2.0 * ca.tanh(x[3] / 0.01)
    d_horizontal = -15.0 * x[3] + 40.0 * x[2] + 100.0 * (x[0] - 0.02)
    return ca.Function("effect", [x], [ca.vertcat(d_vertical, d_horizontal)])


def test_the_loops_constraints_are_F_at_the_loops_physical_state(model):
    """The closed loop's constraints at (z~, phi) are F at the physical state of that z~: gap and
    position from :meth:`RegulatorLoop.physical_state`, v = (K_h z_h, K_v z_v) with z = z~ + z_ss
    (002 (23)-(24)), and the compensation at (x1, x2, x3, x4). Computed independently with
    numpy and :meth:`FeasibleSet.evaluate`; the two differ by rounding only (relative 1e-9 covers
    the few hundred operations of each side, ~1e-13 each, with room)."""
    loop = RegulatorLoop()
    ref = Reference.paper_sinusoid()
    feasible = FeasibleSet(model, compensation=_every_state_compensation())
    fn = feasible.loop_function(loop, ref)
    rng = np.random.default_rng(7)
    scale = np.array([2e-3, 0.05, 1e-4, 1e-3, 1e-3, 5e-3, 0.1, 1e-4, 1e-3, 1e-3])
    for phase in (0.3, 2.0, 4.5):
        zt = rng.uniform(-1, 1, (N_ERROR, 40)) * scale[:, None]
        x, _ = loop.physical_state(zt, ref, phase)
        z = zt + loop.steady_state(ref, phase)
        v1, v2 = loop.K_h @ z[5:], loop.K_v @ z[:5]
        want = feasible.evaluate(x[0], v1, v2, x2=x[1], x3=x[2], x4=x[3])
        got = np.asarray(fn.map(zt.shape[1])(zt, np.full((1, zt.shape[1]), phase)))
        np.testing.assert_allclose(got[:2], want, rtol=1e-9, atol=1e-9)
        (g_lo, g_hi), (p_lo, p_hi) = feasible.gap_range, feasible.position_range
        stoppers = np.vstack([x[0] - g_lo, g_hi - x[0], x[2] - p_lo, p_hi - x[2]])
        np.testing.assert_allclose(got[2:], stoppers, rtol=0, atol=1e-15)


def test_every_boundary_point_of_a_map_satisfies_the_other_constraints(model):
    """``FeasibilityMap.boundary[name]`` holds the points where ``name`` is zero *and every other
    constraint holds* (its docstring): the boundary of F, not of each constraint alone. On a slice
    through 20 mm where the stoppers' lines (e1 = -12 and +10 mm) cross the current boundary,
    every kept point has the other constraints >= 0 (to the 1e-9 relative tolerance the map
    itself uses) and lies on its own constraint's zero: Newton stops once its step is below 1e-12
    (CasADi's default step tolerance), and the headroom's slope along the line reaches 1.5e7 A^2
    per unit of xi_v3 on this slice (finite differences), so a root is exact to 1.5e-5 A^2 at
    worst (measured: 1.2e-8); 2e-5 is 2.5e-7 of the constraint's scale (81 A^2)."""
    feasible = FeasibleSet(model)
    loop = RegulatorLoop()
    ref = Reference.setpoint(0.02)
    fm = feasibility_map(feasible, loop, ref, ("e1", "xi_v3"), (-0.014, 0.012), (-0.1, 0.1), n=41)
    fn = feasible.loop_function(loop, ref)
    kept = 0
    for j, name in enumerate(CONSTRAINT_NAMES):
        pts = fm.boundary[name]
        if pts.shape[1] == 0:
            continue
        z = np.zeros((N_ERROR, pts.shape[1]))
        z[0], z[4] = pts
        h = np.asarray(fn.map(pts.shape[1])(z, np.zeros((1, pts.shape[1]))))
        others = np.delete(h, j, axis=0)
        assert np.all(others >= -1e-9 * np.maximum(1, np.abs(others))), name
        np.testing.assert_allclose(h[j], 0.0, atol=2e-5)
        kept += pts.shape[1]
    # the stoppers' lines do cross infeasible parts of the slice: the filter has work to do
    assert not fm.feasible[:, 0].all() or not fm.feasible[:, -1].all()
    assert kept > 20


# --- ellipsoid geometry ---------------------------------------------------------------------------
@pytest.mark.parametrize("p12", [-1.5, -0.4, 0.0, 0.9, 1.9])
def test_the_largest_rectangle_fits_the_ellipse_and_no_sampled_one_is_larger(p12):
    """``max_rectangle``: its corners (+-a, +-b) lie in {y' P2 y <= c} (one on the boundary, to
    rounding: 1e-12 relative), and no box of another aspect ratio scaled onto the ellipse has a
    larger area. The others are sampled densely: 20001 angles; the area is flat at the optimum, so
    the grid's best is within (pi/20000)^2 ~ 2.5e-8 relative of the true maximum (1e-7 allowed)."""
    P2 = np.array([[4.0, p12], [p12, 1.0]])  # positive definite: p12^2 < 4
    level = 0.7
    a, b = max_rectangle(P2, level)
    corners = np.array([[a, b], [a, -b], [-a, b], [-a, -b]])
    values = np.einsum("ki,ij,kj->k", corners, P2, corners)
    assert values.max() == pytest.approx(level, rel=1e-12)
    t = np.linspace(0, math.pi / 2, 20001)
    c, s = np.cos(t), np.sin(t)
    size = np.sqrt(level / (c**2 * P2[0, 0] + s**2 * P2[1, 1] + 2 * np.abs(c * s * P2[0, 1])))
    assert a * b >= (size**2 * c * s).max() * (1 - 1e-7)


# --- Procedure 2 -----------------------------------------------------------------------------------
def test_each_stoppers_level_touches_that_stopper_over_the_whole_orbit(model):
    """The stoppers' levels of Procedure 2 are exact (closed form): on {V <= c} the gap ranges over
    x1_ss(phi) +- sqrt(c e1' P^-1 e1), so at c = level(gap_low) the least gap over all phases is the
    lower stopper, and likewise for the upper stopper and the position's. Checked against numpy on
    a sinusoid near the lower stopper (12 +- 3 mm) and beside the left one, where every stopper is
    at a different distance; phases sampled at 100001 points (the orbit's extreme is then found
    to amp (dphi)^2 / 2 ~ 6e-14 m); equality to 1e-12 m (rounding of ~1e-2 m values, with room)."""
    loop = RegulatorLoop()
    ref = Reference(0.012, -0.02, 0.003, 0.03, 0.4, 1.1)
    P = loop.lyapunov_matrix()
    feasible = FeasibleSet(model)
    levels = _travel_levels(feasible, loop, ref, P)
    phase = np.linspace(0, 2 * math.pi, 100001)
    off = loop.offsets(ref, phase)
    Pinv = np.linalg.inv(P)
    for row, k, (lo, hi) in ((0, 0, feasible.gap_range), (1, 5, feasible.position_range)):
        spread = math.sqrt(Pinv[k, k])
        names = ("gap_low", "gap_high") if row == 0 else ("position_low", "position_high")
        least = off[row].min() - math.sqrt(levels[names[0]]) * spread
        largest = off[row].max() + math.sqrt(levels[names[1]]) * spread
        assert least == pytest.approx(lo, abs=1e-12)
        assert largest == pytest.approx(hi, abs=1e-12)


@pytest.mark.parametrize("shift", [math.pi / 2, 3 * math.pi / 2])
def test_a_sinusoids_level_is_refuted_just_above_whichever_half_orbit_binds(model, shift):
    """The branch and bound covers the whole orbit phi in [0, 2 pi): IPOPT's least infeasible V
    on the current boundary for the papers' sinusoid bounds c* from above, so the level 1 % above
    it must not be certified, for the orbit shifted by a quarter period and by three quarters
    (IPOPT finds the binding phase at 3 pi / 2 and at pi / 2: one in each half of [0, 2 pi),
    neither at a cell edge). 1 % above c* the
    violating part of the ellipsoid is thin and the search may spend its budget without meeting it
    ("undecided"); it must never prove the level."""
    base = Reference.paper_sinusoid()
    ref = Reference(
        base.gap, base.position, base.gap_amplitude, base.position_amplitude,
        base.gap_phase + shift, base.position_phase + shift, base.omega,
    )  # fmt: skip
    loop = RegulatorLoop()
    feasible = FeasibleSet(model)
    P = loop.lyapunov_matrix()
    found = BoundaryMinimizer(feasible, loop).minimize(ref, P, "headroom", starts=8)
    assert found.success
    res = LevelCertifier(feasible, loop, max_boxes=200_000).certify(ref, P, 1.01 * found.level)
    assert res.status != "certified"  # refuted, or undecided where the violation is too thin
    assert res.status == "refuted" or res.boxes > 200_000


def test_a_refutations_state_has_the_searched_image_and_the_least_v(model):
    """``LevelCertifier.zeta_to_state``: the z~ of least V whose image l = (e1, v1~, v2~) is
    sqrt(c) chol(S) zeta. Its image is that l, and V there is c |zeta|^2 (the least V over
    {M z~ = l} is l' S^-1 l); equalities to 1e-6 relative (solves with P, whose condition number
    is 2.3e9, lose up to 2.3e9 x 1.1e-16 ~ 2.5e-7 relative)."""
    _check_zeta_to_state(FeasibleSet(model), ("x1", "v1", "v2"), draws=5, seed=3)


def _check_zeta_to_state(feasible: FeasibleSet, rows: tuple[str, ...], *, draws: int, seed: int) -> None:
    """zeta_to_state's state has the image sqrt(c) chol(S) zeta over ``rows`` and V = c |zeta|^2, for
    random zeta in the unit cube and levels of the order of the certified ones (tolerances: the
    test above)."""
    loop = RegulatorLoop()
    P = loop.lyapunov_matrix()
    cert = LevelCertifier(feasible, loop)
    M = loop.rows(rows)
    S = M @ np.linalg.solve(P, M.T)
    chol = np.linalg.cholesky(0.5 * (S + S.T))
    rng = np.random.default_rng(seed)
    for _ in range(draws):
        zeta = rng.uniform(-0.6, 0.6, len(rows))
        level = float(rng.uniform(0.5, 2.0)) * 1e-5
        z = cert.zeta_to_state(P, level, zeta)
        np.testing.assert_allclose(M @ z, math.sqrt(level) * chol @ zeta, rtol=1e-6, atol=0)
        assert z @ P @ z == pytest.approx(level * zeta @ zeta, rel=1e-6)


def test_with_a_compensation_along_the_travel_the_state_has_the_image_over_its_four_rows(model):
    """A compensated force that depends on the position (a normal cogging force) adds x3 to the
    variables F depends on, so the certifier searches a 4-D image: ``zeta_to_state`` maps a 4-D zeta
    to the z~ whose image over those four rows is sqrt(c) chol(S) zeta, with V = c |zeta|^2 (the
    same tolerances as the 3-D case above)."""
    import casadi as ca

    x = ca.SX.sym("x", 4)
    tau = model.params.pole_pitch
    cogging = ca.Function("d", [x], [ca.vertcat(0.3 * ca.sin(2 * math.pi * x[2] / tau), 0)])
    feasible = FeasibleSet(model, compensation=cogging)
    rows = tuple(feasible.loop_variables)
    assert len(rows) == 4 and "x3" in rows
    _check_zeta_to_state(feasible, rows, draws=3, seed=4)


@pytest.mark.parametrize("level", [math.inf, math.nan, 0.0, -1e-6])
def test_a_level_that_is_not_positive_and_finite_is_refused(model, level):
    """A certificate is for a level c in (0, inf): an infinite level is no set that can be checked
    box by box (its image is unbounded), and must be refused rather than searched."""
    loop = RegulatorLoop()
    cert = LevelCertifier(FeasibleSet(model), loop)
    with pytest.raises(InputError, match="level"):
        cert.certify(Reference.setpoint(0.02), loop.lyapunov_matrix(), level)


# --- the SDP enlargement ------------------------------------------------------------------------
def test_a_polygon_vertex_is_proved_only_if_every_constraint_holds_on_its_cells(model):
    """The inner polygon's proof accepts a cell of (e1, phase) only when *every* constraint's
    enclosure is >= 0 there. At 20 mm with |e1| <= 2 mm, dv = (0, -45.2) m/s^2 keeps R > 0 (R / (4
    L4) > 50 m/s^2) and fits the 9 A limit except in a sliver near e1 = +2 mm (the headroom falls
    with the gap and is zero at 21.9 mm for v2 = -45.16, numpy below): it must not be proved,
    however thin the sliver. dv = (0, -10) m/s^2 (headroom > 0 on the whole range) must be."""
    loop = RegulatorLoop()
    ref = Reference.setpoint(0.02)
    builder = PolygonBuilder(FeasibleSet(model), loop)
    verts = np.array([[0.0, 0.0], [-10.0, -45.2]])
    gaps = 0.02 + np.linspace(-2e-3, 2e-3, 401)
    coef = model.coefficients(gaps)[:, :, None]
    h = constraints_from_coefficients(coef, 0.0, verts[1][None, :], model.params.gravity, 9.0)
    assert np.all(h[0] > 50) and np.all(h[1][:, 0] > 0)
    assert h[1][-1, 1] < 0 and np.mean(h[1][:, 1] < 0) < 0.05  # infeasible on under 5 % of the range
    fpar = loop.offset_coefficients(ref).ravel(order="F")[:, None]
    proved, _ = builder._prove_vertices(verts, 2e-3, False, fpar, 20_000)
    assert proved.tolist() == [True, False]


def test_the_reach_along_a_direction_is_where_the_certified_set_ends(model):
    """``enlarge(direction=d)``: ``best.reach`` is the largest t with t d in the certified set
    {V <= c}, i.e. (t d)' P (t d) = c exactly (to rounding, 1e-9 relative); for the papers' large
    step 26 -> (18, 20) mm it is above 1 (the start is covered)."""
    loop = RegulatorLoop()
    feasible = FeasibleSet(model)
    proc = Procedure2(feasible, loop, starts=4)
    ref = Reference.setpoint(0.018, 0.020)
    z0 = loop.error_state([0.026, 0, 0, 0], np.zeros(6), ref)[:, 0]
    res = enlarge(proc, ref, fractions=(0.75,), builder=PolygonBuilder(feasible, loop), direction=z0)
    best = res.best
    t = best.reach
    assert t > 1
    assert (t * z0) @ best.P @ (t * z0) == pytest.approx(best.certified.level, rel=1e-9)


# --- the robust certificate ---------------------------------------------------------------------
def test_the_worst_plant_is_in_the_set_and_attains_the_sup_of_dv_dt(model):
    """``RobustCertifier.rate`` returns sup over Theta of dV/dt and the plant attaining it. The
    plant is a member of Theta, its own dV/dt (the rate for the one-point set {C}) equals the
    sup, and no plant sampled from Theta has a larger dV/dt. Box of +-5 % around the nominal
    constants; 20 sampled plants per state; dV/dt is linear in C, so the sup is attained at
    a vertex and equalities hold to rounding (1e-9 relative of the terms, ~1e2-1e4)."""
    loop = RegulatorLoop()
    feasible = FeasibleSet(model)
    cert = RobustCertifier(feasible, loop, max_boxes=1000)
    c = np.asarray(model.constants.as_array(), dtype=float)
    box = PlantSet.box(0.95 * c, 1.05 * c)
    P = loop.lyapunov_matrix()
    ref = Reference.paper_sinusoid()
    rng = np.random.default_rng(5)
    scale = np.array([2e-3, 0.05, 1e-4, 1e-3, 1e-3, 5e-3, 0.1, 1e-4, 1e-3, 1e-3])
    zt = rng.uniform(-1, 1, (N_ERROR, 6)) * scale[:, None]
    phase = rng.uniform(0, 2 * math.pi, 6)
    sup, worst = cert.rate(P, ref, box, zt, phase)
    # in the box: |C - C0| <= half-width, to the rounding of C0 +- half-width (1e-12 relative)
    assert np.all(np.abs(worst - c[:, None]) <= 0.05 * c[:, None] * (1 + 1e-9))
    plants = box.sample(20, rng)
    for k in range(zt.shape[1]):
        own, _ = cert.rate(P, ref, PlantSet.point(worst[:, k]), zt[:, k], phase[k])
        assert own[0] == pytest.approx(sup[k], rel=1e-9, abs=1e-9 * abs(sup[k]) + 1e-12)
        sampled = [cert.rate(P, ref, PlantSet.point(p), zt[:, k], phase[k])[0][0] for p in plants.T]
        assert max(sampled) <= sup[k] + 1e-9 * abs(sup[k])


# --- sampled plants -------------------------------------------------------------------------------
@pytest.mark.parametrize("rank", [1, 2, 3, 4])
def test_plants_are_uniform_in_an_ellipsoid_of_any_rank(model, rank):
    """``PlantSet.sample`` is uniform in the ellipsoid, which has the covariance's rank k as its
    dimension (the other constants held at the centre): the share of plants within half the
    radius is 0.5^k. 4000 draws: the binomial standard deviation is at most 0.008, 5 of them
    (0.04) allowed."""
    c = np.asarray(model.constants.as_array(), dtype=float)
    rel = np.array([0.02, 0.03, 0.01, 0.1])
    rel[rank:] = 0.0  # constants held fixed
    plants = PlantSet.confidence(c, np.diag((rel * c) ** 2), 0.9)
    C = plants.sample(4000, np.random.default_rng(11))
    d = (C - c[:, None]) / c[:, None]
    s = np.asarray(plants.shape) / np.outer(c, c)
    r2 = np.einsum("in,ij,jn->n", d, np.linalg.pinv(s), d)
    assert r2.max() <= 1 + 1e-9
    assert np.mean(r2 <= 0.25) == pytest.approx(0.5**rank, abs=0.04)


def test_a_sweep_judges_its_runs_against_its_own_current_limit(model):
    """A sweep's violations use the spec's ``current_limit``: from rest at the 20 mm set-point on
    the nominal plant the FL regulator commands the equilibrium current |u_eq| and nothing more
    (zero error, zero v; 000 eq. (7)), so every run violates a limit 0.05 A below |u_eq| and none
    violates one 0.05 A above it, or no limit at all. 0.05 A is far above the loop's rounding
    (the commanded current is exact to ~1e-12 A at rest) and the amplifier is ideal."""
    C = model.constants.as_array()
    u_eq = abs(float(equilibrium_currents(model, [0.02]).current[0]))
    spec = SweepSpec(PlantSet.point(C), Reference.setpoint(0.02), start=(0.02, 0.0, 0.0, 0.0), duration=0.02)
    for limit, violations in ((u_eq - 0.05, 3), (u_eq + 0.05, 0), (None, 0)):
        res = run_sweep(dataclasses.replace(spec, current_limit=limit), 3, progress=False)
        assert res.violations == violations, limit
        np.testing.assert_allclose(res.max_current, u_eq, rtol=1e-6)


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


# --- the study -------------------------------------------------------------------------------------
def test_a_step_is_predicted_to_hit_a_stopper_when_its_linear_response_reaches_either_one(model):
    """Where F holds the FL loop is linear in the errors, so a step from rest reaches a stopper
    exactly when the linear response target + e(t) does, on either side. Checked on a grid of
    start and target gaps against the response integrated independently (scipy expm, 1 ms steps
    over 10 s, the same horizon), away from the few pairs within 10 um of a stopper (where the
    two discretisations may disagree: the response moves < 1 um per 1 ms step near its extreme)."""
    loop = RegulatorLoop()
    feasible = FeasibleSet(model)
    starts = np.linspace(0.009, 0.029, 21)
    targets = np.linspace(0.009, 0.029, 21)
    predicted = _predicted_stoppers(feasible, step_extremes(loop), starts, targets)
    step = expm(loop.A * 1e-3)
    z, e1 = np.zeros(N_ERROR), [1.0]
    z[0] = 1.0
    for _ in range(10_000):
        z = step @ z
        e1.append(z[0])
    e1 = np.array(e1)
    g_lo, g_hi = feasible.gap_range
    assert predicted.any()  # some steps do reach a stopper on this grid
    for i, target in enumerate(targets):
        for j, start in enumerate(starts):
            gap = target + (start - target) * e1
            distance = min(gap.min() - g_lo, g_hi - gap.max())
            if abs(distance) > 1e-5:
                assert predicted[i, j] == (distance < 0), (start, target)
