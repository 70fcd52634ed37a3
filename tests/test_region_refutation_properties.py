"""Refutations and IPOPT's boundary points in ``maglev_oc.region``, as properties.

The region tests let two kinds of hand-injected bug through (bench/README.md, "Hand-injected
bugs"): a refutation that searches one sign or one side only, and a weakened or inverted check of
what IPOPT (or a sampled point of the branch and bound) returns. Each property below is what a
user of a certificate relies on, checked against numbers computed independently of the code
under test: V as z' P z, F through the loop's physical state and :meth:`FeasibleSet.evaluate`
(not the certifier's graphs), the microstepper's constraints through the controller's own
transformation. Mirror images and off-centre set-points put the binding side on each side in turn.

A level is refuted just above the certified one whichever side binds:

* the least V on the current boundary is the same for a P and its left-right mirror image (the
  six coordinate rays of the search meet the lower minimum from opposite sides);
* each stopper's witness lies on that stopper (below and above, left and right) at the phase of
  the orbit closest to it, and a hair beyond it the stopper is passed;
* the linear regulators' region of attraction is capped by the nearer stopper, on either side;
* the microstepper's travel level is set by the nearer limit of each axis, on either side, and
  its witness reaches that limit;
* the microstepper's branch and bound refutes a level 10 % above IPOPT's least violation, with
  the violation where the gap closes and where it opens.

IPOPT's boundary points, the branch and bound's samples, and the bounds they give:

* a start IPOPT reports as failed is not counted, whatever point it returns; when every start
  fails, Procedure 2 still certifies, its upper bound then from branch-and-bound refutations;
* a point IPOPT calls converged but where R >= 0 holds (half-way back to the set-point) is not
  counted on R >= 0's boundary;
* a point on the current boundary where R < 0 (no physical root: no transformation) is not
  counted;
* the point IPOPT reports on a boundary is on it: a hair further out its constraint fails;
* a sampled point with a negative constraint refutes the level, however shallow the violation;
  likewise a robust level is refuted by a plant of Theta that leaves it, however slowly;
* Procedure 2's upper bound is the least V of the infeasible points it met and its witness is
  one of them; refutations alone bring the certificate to the ladder's first rung;
* the microstepper's refutation does not count a state where its constraint holds, however close
  to the boundary.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from scipy.optimize import brentq

from maglev_oc.control.linear_regulator import paper_linear_regulator
from maglev_oc.model.feedback import FeedbackTransformation
from maglev_oc.model.hardware import MICROSTEPPER_STOPPER_GAP, STOPPER_POSITION
from maglev_oc.region.boundary import BoundaryMinimizer
from maglev_oc.region.branch_and_bound import LevelCertifier
from maglev_oc.region.closed_loop import DE1, DE2, E1, E2, N_ERROR, Reference, RegulatorLoop
from maglev_oc.region.feasibility import NONLINEAR, FeasibleSet
from maglev_oc.region.microstepper import MICROSTEPPER_CONSTRAINTS, MicrostepperRegion
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.region.roa import certify_roa
from maglev_oc.region.robust import assumed_covariance
from maglev_oc.region.robust_certificate import RobustCertifier
from maglev_oc.region.sweep import PlantSet
from tests.test_microstepper_region import PLATFORM, TRANSFORM, _violations


@pytest.fixture(scope="module")
def loop():
    return RegulatorLoop()


def _physical(feasible: FeasibleSet, loop: RegulatorLoop, reference: Reference, z, phase=0.0):
    """(gap [m], position [m], margin [m/s^2], headroom [A^2]), each (n,), at error states z (10,)
    or (10, n) and ``phase``: the physical state of :meth:`RegulatorLoop.physical_state`, the
    accelerations v = (K_h z_h, K_v z_v) with z = z~ + z_ss (002 (23)-(24)) and F pointwise."""
    zt = np.asarray(z, dtype=float).reshape(N_ERROR, -1)
    x, _ = loop.physical_state(zt, reference, phase)
    full = zt + loop.steady_state(reference, phase)
    v1, v2 = loop.K_h @ full[5:], loop.K_v @ full[:5]
    margin, headroom = feasible.evaluate(x[0], v1, v2, x2=x[1], x3=x[2], x4=x[3])
    return x[0], x[2], margin, headroom


def _image_factor(loop: RegulatorLoop, P) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M, S, C): l = (e1, v1, v2) = M z~, S = M P^-1 M' and C C' = S. The state of least V with
    image l is P^-1 M' S^-1 l, and its V is l' S^-1 l."""
    M = loop.rows(("x1", "v1", "v2"))
    S = M @ np.linalg.solve(P, M.T)
    S = 0.5 * (S + S.T)
    return M, S, np.linalg.cholesky(S)


class _Ipopt:
    """IPOPT as :class:`BoundaryMinimizer` calls it (``solver(x0=..., p=..., bounds)``, then
    ``solver.stats()``), with its verdict or its answer replaced: ``success`` overrides the
    status it reports; ``answer(x, ng)`` turns the point it found (z~ (10), phase) into another
    one and returns (x, f, g) computed honestly there (what a run that stopped somewhere else
    would return)."""

    def __init__(self, solver, *, success=None, answer=None):
        self.solver, self.success, self.answer = solver, success, answer

    def __call__(self, **kwargs):
        sol = self.solver(**kwargs)
        if self.answer is None:
            return sol
        ng = np.asarray(sol["g"]).size
        x, f, g = self.answer(np.asarray(sol["x"]).ravel(), ng)
        return {"x": ca.DM(x), "f": ca.DM(f), "g": ca.DM(g)}

    def stats(self):
        stats = dict(self.solver.stats())
        if self.success is not None:
            stats["success"] = self.success
        return stats


def _honest(feasible, loop, reference, P, constraint: str, z, phase: float, ng: int):
    """(x, f, g) of the boundary NLP of ``constraint`` at (z, phase): f = V and g = (h_j, gap and,
    on the current boundary, R / (4 L4)), the rows the solver has (``ng``)."""
    gap, _, margin, headroom = _physical(feasible, loop, reference, z, phase)
    rows = {"margin": [margin[0], gap[0]], "headroom": [headroom[0], gap[0], margin[0]]}[constraint]
    return np.append(z, phase), float(z @ P @ z), np.array(rows[:ng])


# --- refuted on either side -------------------------------------------------------------------------
def _coupled_p(loop: RegulatorLoop, rho: float) -> np.ndarray:
    """The Lyapunov equation's P for Q = diag(1 / scale^2) with the gap and position errors (and
    their rates) correlated by ``rho`` (|rho| < 1: Q > 0): {V <= c} is tilted between e1 and v1."""
    s = 1.0 / loop.state_scale()
    Q = np.diag(s**2)
    for i, j in ((E1, E2), (DE1, DE2)):
        Q[i, j] = Q[j, i] = rho * s[i] * s[j]
    return loop.lyapunov_matrix(Q)


def test_the_least_v_on_the_current_boundary_is_found_from_either_side(model, loop):
    """F depends on the horizontal states only through v1^2 (u1 = -v1 / L1 enters squared), so the
    left-right mirror z~_h -> -z~_h, P -> D P D (D = diag(1 x 5, -1 x 5), exact sign flips; still a
    Lyapunov matrix: A_cl is block diagonal) maps the boundary search onto itself, and its six
    coordinate rays of zeta (``starts=6``: +-e_i) onto themselves (+e2 <-> -e2): the least V found
    must be the same (1e-9: IPOPT stops at a scaled KKT error of 1e-10; measured equal to the
    last digit). With e1 and e2 coupled in P (rho = 0.5) at 26 mm the six rays end in two local
    minima (measured: V = 10.35 and 46.39), and for the mirror only the rays on the minus side
    reach 10.35: a search along +e1, +e2, +e3 alone reports 46.39 for it and 10.35 for P."""
    feasible = FeasibleSet(model)
    minimizer = BoundaryMinimizer(feasible, loop)
    ref = Reference.setpoint(0.026)
    P = _coupled_p(loop, 0.5)
    D = np.diag([1.0] * 5 + [-1.0] * 5)
    levels = []
    for p in (P, D @ P @ D):
        assert loop.is_lyapunov(p)
        res = minimizer.minimize(ref, p, "headroom", starts=6)
        assert res.success, res.message
        assert res.state @ p @ res.state == pytest.approx(res.level, rel=1e-9)
        levels.append(res.level)
    assert levels[0] == pytest.approx(levels[1], rel=1e-9)


STOPPER_CASES = [
    # (FeasibleSet options, a sinusoid off-centre towards one stopper, that stopper)
    ({}, Reference(0.012, -0.02, 0.003, 0.03, 0.4, 1.1), "gap_low"),
    ({"current_limit": None}, Reference(0.02, -0.02, 0.003, 0.03, 0.4, 1.1), "gap_high"),
    ({"current_limit": None}, Reference(0.02, -0.05, 0.003, 0.008, 0.4, 1.1), "position_low"),
    ({"current_limit": None}, Reference(0.02, 0.05, 0.003, 0.008, 0.4, 1.1), "position_high"),
]


@pytest.mark.parametrize(
    ("options", "reference", "stopper"), STOPPER_CASES, ids=[c[2] for c in STOPPER_CASES]
)
def test_a_stoppers_witness_lies_on_that_stopper(model, loop, options, reference, stopper):
    """When a stopper binds, Procedure 2's witness is the state of the certified set's closure
    (V = level_upper) that reaches the stopper: at the witness phase the gap (position) is the
    stopper, for the lower and the upper stopper of each axis, and 1e-6 further out along the
    same state it passes it. The references are sinusoids (amplitudes 3 and 8-30 mm), so the
    phase matters: the orbit is at the stopper's side only near one phase. Equalities: V to
    1e-9 (P's rounding), the coordinate to 1e-12 m (rounding of 1e-2 m values); 1e-6 of a 1-5 mm
    reach is 1e-9 m past the stopper, far above that rounding."""
    feasible = FeasibleSet(model, **options)
    res = Procedure2(feasible, loop, starts=2).run(reference)
    assert res.success and res.binding == stopper, res.message
    assert res.level <= res.level_upper
    z, phase = res.witness, res.witness_phase
    assert z @ res.P @ z == pytest.approx(res.level_upper, rel=1e-9)
    row = 0 if stopper.startswith("gap") else 1
    lo, hi = feasible.gap_range if row == 0 else feasible.position_range
    low = stopper.endswith("low")
    at = _physical(feasible, loop, reference, z, phase)[row][0]
    assert at == pytest.approx(lo if low else hi, abs=1e-12)
    beyond = _physical(feasible, loop, reference, (1 + 1e-6) * z, phase)[row][0]
    assert (beyond < lo) if low else (beyond > hi)


@pytest.mark.parametrize("side", ["below-left", "above-right"])
def test_the_region_of_attraction_is_capped_by_the_nearer_stopper_on_either_side(model, side):
    """The linear regulator's certified level is capped where {V <= c} first touches a stopper:
    the farthest reach of e1 (e2) over the set is sqrt(c (P^-1)_kk), so the cap is
    min_k room_k^2 / (P^-1)_kk with room_k the distance to the *nearer* stopper of axis k. With
    stoppers 0.1 mm and 0.2 mm from the set-point (14, 30) mm below and left of it, or above and
    right of it (the far ones 6-90 mm away), the cap is the same closed form, to rounding (1e-9),
    and it is the certified level (the stability level is 4x larger, measured)."""
    ref = Reference.setpoint(0.014, 0.030)
    room = {E1: 1e-4, E2: 2e-4}
    if side == "below-left":
        feasible = FeasibleSet(
            model, gap_range=(ref.gap - room[E1], 0.03), position_range=(ref.position - room[E2], 0.06)
        )
    else:
        feasible = FeasibleSet(
            model, gap_range=(0.008, ref.gap + room[E1]), position_range=(-0.06, ref.position + room[E2])
        )
    res = certify_roa(model, paper_linear_regulator(model), ref, feasible=feasible)
    Pinv = np.linalg.inv(res.P)
    cap = min(room[k] ** 2 / Pinv[k, k] for k in room)
    assert res.level_travel == pytest.approx(cap, rel=1e-9)
    assert res.level == res.level_travel < res.level_stability


@pytest.fixture(scope="module")
def stepper():
    return MicrostepperRegion(PLATFORM)


MICROSTEPPER_TRAVEL = [
    # (set-point (x, y, gap) [m], the axis whose nearer limit binds, -1: the lower limit, +1: the upper)
    ((-0.058, 0.0, 0.025), "x", -1),
    ((0.0, 0.058, 0.025), "y", 1),
    ((0.0, 0.0, 0.0095), "gap", -1),
    ((0.0, 0.0, 0.034), "gap", 1),
]


@pytest.mark.parametrize(("setpoint", "axis", "side"), MICROSTEPPER_TRAVEL)
def test_the_microstepper_travel_binds_at_the_nearer_limit_on_either_side(stepper, setpoint, axis, side):
    """1-2 mm from one limit of an axis (travel +-60 mm, gap stoppers 8 and 35 mm), that limit
    binds: the witness is a state of V = refuted level whose axis error reaches the limit exactly
    (1e-12 m: rounding of 1e-2 m values), on the lower and the upper side, and the certified set's
    half-width along the axis fits the room to the nearer limit (1e-9: rounding). A 5 % bracket
    and 100 000 boxes a pass keep it to a fraction of a second (the travel level is exact)."""
    res = stepper.largest_level(setpoint, rel_tol=0.05, max_boxes=100_000)
    assert res.success and res.binding == axis, res.message
    j = ("x", "y", "gap").index(axis)
    lo, hi = (STOPPER_POSITION, STOPPER_POSITION, MICROSTEPPER_STOPPER_GAP)[j]
    z = res.witness
    assert z @ stepper.P @ z == pytest.approx(res.refuted_level, rel=1e-9)
    assert setpoint[j] + z[5 * j] == pytest.approx(lo if side < 0 else hi, abs=1e-12)
    assert res.half_widths[axis] <= min(setpoint[j] - lo, hi - setpoint[j]) * (1 + 1e-9)


@pytest.fixture(scope="module")
def free_stepper():
    """The microstepper with its current limit and without stoppers or travel limits."""
    return MicrostepperRegion(PLATFORM, stoppers=False)


@pytest.mark.parametrize(("gap", "closing"), [(0.012, True), (0.015, False)])
def test_the_microstepper_refutes_above_a_violation_where_the_gap_closes_or_opens(free_stepper, gap, closing):
    """IPOPT's least violation at 12 mm is a pair's current limit with the gap closing (e_gap < 0,
    measured zeta = (-1, 0, 0, 0.09)), at 15 mm with it opening (zeta = (0.38, 0, 0.91, 0.18)).
    {V <= 1.1 x that level} holds that infeasible point and its neighbourhood, so the branch and
    bound, covering the whole ball of zeta, must refute it (measured: 0.2 s, 121 520 and 34 928
    boxes), with a state inside the level set (1e-9: rounding) at which the constraint it names
    fails, judged by the controller's transformation."""
    region = free_stepper
    setpoint = (0.0, 0.0, gap)
    found, why, ell = region.refute(setpoint, starts=4)
    assert math.isfinite(found) and why.startswith("headroom")
    assert (ell[0] < 0) == closing
    level = 1.1 * found
    status, _, binding, state = region.certify(setpoint, level, max_boxes=200_000)
    assert status == "refuted"
    assert state @ region.P @ state <= level * (1 + 1e-9)
    assert _violations(region, setpoint, state[:, None])[binding] == 1


# --- IPOPT's boundary points and the branch and bound ------------------------------------------------
def test_a_start_ipopt_reports_as_failed_is_not_counted(model, loop, monkeypatch):
    """A start counts only if IPOPT converged (``BoundaryMinimum``: "no start ... converged" is
    ``not_found``). With every run reported as failed, at points IPOPT did find on the
    boundaries, no start is counted: nothing found, no state, an infinite level. Procedure 2
    then has no IPOPT bound and still certifies through the branch and bound (measured at 20 mm:
    the stoppers' level 11.45 refuted by a witness at V = 11.44, 0.98 of that certified): its
    upper bound is the least V of the refutations' witnesses, and its witness has that V (1e-9:
    rounding) and fails the constraint it names, evaluated independently."""
    feasible = FeasibleSet(model)
    proc = Procedure2(feasible, loop, starts=2)
    for name, (solver, ng) in list(proc.minimizer._solvers.items()):
        monkeypatch.setitem(proc.minimizer._solvers, name, (_Ipopt(solver, success=False), ng))
    ref = Reference.setpoint(0.02)
    P = loop.lyapunov_matrix()
    for name in proc.minimizer.constraints:
        res = proc.minimizer.minimize(ref, P, name, starts=6)
        assert not res.success and res.status == "not_found" and "no start" in res.message
        assert res.converged == 0 and res.level == math.inf and res.state is None
    out = proc.run(ref)
    assert all(m.status == "not_found" for m in out.minima)
    assert out.success and 0 < out.level <= out.level_upper
    refuted = [a.witness_level for a in out.attempts if a.status == "refuted"]
    assert refuted and out.level_upper <= min(refuted)
    z = out.witness
    assert z @ out.P @ z == pytest.approx(out.level_upper, rel=1e-9)
    h = dict(zip(NONLINEAR, _physical(feasible, loop, ref, z, out.witness_phase)[2:], strict=True))
    assert h[out.binding][0] < 0


@pytest.mark.parametrize("constraint", ["margin", "headroom"])
def test_a_converged_point_where_the_constraint_holds_is_not_counted_on_its_boundary(
    model, loop, monkeypatch, constraint
):
    """What bounds c* from above is a point where the constraint fails or is zero. If IPOPT says it
    converged at a point where the constraint holds with room (each start's answer moved half-way
    back to the set-point: V a quarter of the boundary's; there R / (4 L4) = 27 m/s^2, or the
    current limit's headroom 63-80 A^2 of its 81, checked), the start is not counted and nothing is
    found. The boundary check's tolerance is 1e-7 of the constraint's size at the set-point. It was
    1e-7 of the largest |h| met along the start's ray, which reaches 1e9 A^2 for the headroom: any
    point where the limit held passed, and Procedure 2 reported such a point as its witness, with a
    level bracket 4x too low (found by injecting bugs, issue 21)."""
    feasible = FeasibleSet(model)
    minimizer = BoundaryMinimizer(feasible, loop)
    ref = Reference.setpoint(0.02)
    P = loop.lyapunov_matrix()
    seen = []

    def halfway(x, ng):
        out = _honest(feasible, loop, ref, P, constraint, 0.5 * x[:N_ERROR], x[N_ERROR], ng)
        seen.append(out[2][0])
        return out

    solver, ng = minimizer._solvers[constraint]
    monkeypatch.setitem(minimizer._solvers, constraint, (_Ipopt(solver, answer=halfway), ng))
    res = minimizer.minimize(ref, P, constraint, starts=6)
    assert seen and min(seen) > 1.0  # [m/s^2 or A^2]: every answer is well inside the constraint
    assert not res.success and res.converged == 0 and res.level == math.inf


def test_a_current_boundary_point_without_the_transformation_is_not_counted(model, loop, monkeypatch):
    """On the current boundary |u| = I the transformation must exist (R >= 0: the physical root):
    where R < 0 the loop has no current to command, and "the current limit binds there" is not
    true. With a 50 A limit at 20 mm, R = 0 needs i_d = -L3 / (2 L4) = 31 A < 50 A, so along
    v2 (e1 = v1 = 0) R turns negative before |u| (with sqrt(max(R, 0)) = 0) reaches 50 A: a
    point with headroom = 0 and R < 0 exists (found by root finding, checked). If IPOPT says it
    converged there, no start is counted."""
    feasible = FeasibleSet(model, current_limit=50.0)
    minimizer = BoundaryMinimizer(feasible, loop)
    ref = Reference.setpoint(0.02)
    P = loop.lyapunov_matrix()
    M, S, _ = _image_factor(loop, P)

    def state(a):  # the least-V state with e1 = v1 = 0, v2 = a [m/s^2]
        return np.linalg.solve(P, M.T @ np.linalg.solve(S, [0.0, 0.0, a]))

    def h(a, k):
        return _physical(feasible, loop, ref, state(a))[k][0]

    a_r = brentq(h, 0.0, 1e4, args=(2,), xtol=1e-12)
    a_u = brentq(h, a_r, 1e5, args=(3,), xtol=1e-12)
    z = state(a_u)
    assert h(a_u, 2) < -1.0 and abs(h(a_u, 3)) < 1e-6  # R / (4 L4) [m/s^2] < 0, |u|^2 = I^2 [A^2]

    def there(x, ng):
        return _honest(feasible, loop, ref, P, "headroom", z, 0.0, ng)

    solver, ng = minimizer._solvers["headroom"]
    monkeypatch.setitem(minimizer._solvers, "headroom", (_Ipopt(solver, answer=there), ng))
    res = minimizer.minimize(ref, P, "headroom", starts=6)
    assert not res.success and res.converged == 0 and res.level == math.inf


@pytest.mark.parametrize(("gap", "constraint"), [(0.012, "margin"), (0.02, "headroom"), (0.026, "headroom")])
def test_the_point_found_on_a_boundary_fails_its_constraint_a_hair_beyond(model, loop, gap, constraint):
    """IPOPT's least V on a boundary bounds c* from above only if its point is infeasible or on the
    boundary: a point short of it, where the constraint still holds, has a V below c*. IPOPT
    stops at a scaled KKT error of 1e-10, which puts the point on the boundary to ~1e-12 (A^2 or
    m/s^2), ~1e-14 of its distance from the set-point; 1e-9 further out along the same state the
    constraint has fallen by 1e-9 |dh/ds| (|dh/ds| = 77 m/s^2 for the margin at 12 mm, 250 and 350
    A^2 for the headroom at 20 and 26 mm: finite differences), far above rounding (~1e-14 of terms
    of ~100): it must be negative there (and V of the state is the level reported, 1e-9: rounding)."""
    feasible = FeasibleSet(model)
    minimizer = BoundaryMinimizer(feasible, loop)
    ref = Reference.setpoint(gap)
    P = loop.lyapunov_matrix()
    res = minimizer.minimize(ref, P, constraint, starts=6)
    assert res.success, res.message
    assert res.state @ P @ res.state == pytest.approx(res.level, rel=1e-9)
    k = 2 + NONLINEAR.index(constraint)
    assert _physical(feasible, loop, ref, (1 + 1e-9) * res.state, res.phase)[k][0] < 0


def test_a_shallow_violation_refutes_the_level(model, loop):
    """A sampled point at which a constraint is negative refutes the level, however small the
    violation. With a 3 A limit at 20 mm the headroom falls by only 8.9 A^2 per unit of radial
    scale at IPOPT's least-V point (finite differences), so on {V <= (1 + 1e-4) c*} (scale <=
    1 + 5e-5) it is never below about -4.5e-4 A^2: a threshold below zero would leave the level
    undecided. The branch and bound refutes it (measured: 116 280 boxes, 0.4 s) with a witness
    inside the level set at which the headroom, evaluated independently, is negative but above
    -1e-3 A^2."""
    feasible = FeasibleSet(model, current_limit=3.0)
    ref = Reference.setpoint(0.02)
    P = loop.lyapunov_matrix()
    least = BoundaryMinimizer(feasible, loop).minimize(ref, P, "headroom", starts=6)
    assert least.success, least.message
    level = (1 + 1e-4) * least.level
    cert = LevelCertifier(feasible, loop, max_boxes=200_000)
    res = cert.certify(ref, P, level)
    assert res.status == "refuted" and res.binding == "headroom", res.message
    z = cert.zeta_to_state(P, level, res.witness[:-1])
    assert z @ P @ z == pytest.approx(res.witness_level, rel=1e-9)
    assert res.witness_level <= level * (1 + 1e-12)
    headroom = _physical(feasible, loop, ref, z, res.witness[-1])[3][0]
    assert -1e-3 < headroom < 0


def test_a_robust_level_is_refuted_by_a_plant_that_leaves_it_however_slowly(model, loop):
    """The robust certificate refutes a level when, at a state on V = c, some plant of Theta has
    dV/dt > 0: that plant leaves the set, however slowly. With the Lyapunov equation's P at 20 mm
    and the 0.01 confidence set of the assumed covariance, 5 % of the nominal level is refuted
    (measured: dV/dt = 0.082 at the witness, 3 730 boxes). The witness is on V = c (1e-9:
    rounding), its plant is in Theta, and its dV/dt, recomputed from the model's f_theta and the
    transformation's currents (not the certifier's graph), is positive and the one reported (1e-9
    relative: the same doubles in another order)."""
    feasible = FeasibleSet(model)
    nominal = Procedure2(feasible, loop, starts=4).run(Reference.setpoint(0.02))
    constants = np.asarray(model.constants.as_array(), dtype=float)
    plants = PlantSet.confidence(constants, assumed_covariance(model.constants), 0.01)
    level = 0.05 * nominal.level
    out = RobustCertifier(feasible, loop, max_boxes=20_000).certify(
        nominal.reference, nominal.P, level, plants
    )
    assert out.status == "refuted", out.message
    z, C, P, ref = out.witness, out.witness_plant, nominal.P, nominal.reference
    assert z @ P @ z == pytest.approx(level, rel=1e-9)
    assert plants.contains(C[:, None])[0]
    x, _ = loop.physical_state(z, ref, out.witness_phase)
    off = loop.offsets(ref, out.witness_phase)[:, 0]
    v = np.array([off[2] + loop.K_h @ z[5:], off[3] + loop.K_v @ z[:5]])
    u = np.asarray(FeedbackTransformation(model).currents(x[0, 0], v)).ravel()
    delta = np.asarray(model.f_theta(x[:, 0], u, C) - model.f_theta(x[:, 0], u, constants)).ravel()
    rate = 2 * z @ P @ (loop.A @ z + loop.B_v * delta[1] + loop.B_h * delta[3])
    assert rate > 0
    assert rate == pytest.approx(out.witness_rate, rel=1e-9)


@pytest.fixture(scope="module")
def ladder(model, loop):
    """Procedure 2 at 26 mm without gap stoppers and with one IPOPT start (the +e1 ray of zeta),
    which reaches the R >= 0 boundary but fails on the current one (measured): the bound for the
    current limit comes from branch-and-bound refutations alone (measured: 5 in a row, then the
    first rung certified; 0.5 s)."""
    feasible = FeasibleSet(model, gap_range=None)
    proc = Procedure2(feasible, loop, starts=1, max_boxes=100_000)
    return feasible, proc.run(Reference.setpoint(0.026))


def test_procedure2s_upper_bound_is_the_least_v_of_the_infeasible_points_it_met(ladder, loop):
    """c* lies in [level, level_upper]: level_upper is the least V over every infeasible point
    Procedure 2 met (IPOPT's boundary points and the refutations' witnesses; equal, they are the
    same numbers), the binding constraint is the one that fails there, and the witness is that
    point: V = level_upper (1e-9: rounding) and the constraint, evaluated independently, < 0."""
    feasible, res = ladder
    refuted = [a for a in res.attempts if a.status == "refuted"]
    assert res.success and refuted and res.minima[1].status == "not_found"
    met = [a.witness_level for a in refuted] + [m.level for m in res.minima]
    assert res.level <= res.level_upper == min(met)
    assert res.binding == min(refuted, key=lambda a: a.witness_level).binding == "headroom"
    z = res.witness
    assert z @ res.P @ z == pytest.approx(res.level_upper, rel=1e-9)
    h = dict(zip(NONLINEAR, _physical(feasible, loop, res.reference, z, res.witness_phase)[2:], strict=True))
    assert h[res.binding][0] < 0


def test_refutations_bring_the_certificate_to_the_ladders_first_rung(ladder, loop):
    """A refutation hands back the infeasible sampled point of least V, and the ladder retries
    0.995 of it: once a witness lies within 0.5 % of c* the first rung is certified, at >= 0.995
    c*; the next rung down is 0.98. Without IPOPT's bound for the current limit the refutations
    alone get there (measured: level 0.9952 c*, upper bound 1.0002 c*, c* from 12 IPOPT starts).
    So the certificate is at least 0.99 c* and the upper bound at most c* / 0.995."""
    feasible, res = ladder
    c_star = BoundaryMinimizer(feasible, loop).minimize(res.reference, res.P, "headroom", starts=12).level
    assert 0.99 * c_star <= res.level <= c_star
    assert c_star * (1 - 1e-9) <= res.level_upper <= c_star / 0.995


class _Inside:
    """The microstepper's IPOPT (``solver(x0=..., p=gap0, bounds)``) answering, instead of its own
    point l*, the point s l* (0 < s <= 1) on the segment back to the set-point where constraint j
    is +1e-4, judged by the controller's transformation (the point itself when it is feasible by
    more already)."""

    def __init__(self, solver, j: int, limit: float):
        self.solver, self.j, self.limit = solver, j, limit
        self.values: list[float] = []

    def h(self, ell, gap0: float) -> float:
        u, R = (np.asarray(a).ravel() for a in TRANSFORM(gap0 + ell[0], ell[1:4]))
        return [R[0], self.limit**2 - u[0] ** 2 - u[1] ** 2, self.limit**2 - u[2] ** 2 - u[3] ** 2][self.j]

    def __call__(self, **kwargs):
        sol = self.solver(**kwargs)
        gap0 = float(kwargs["p"])
        ell = np.asarray(sol["x"]).ravel()
        if self.h(ell, gap0) < 1e-4:
            s = brentq(lambda s: self.h(s * ell, gap0) - 1e-4, 0.0, 1.0, xtol=1e-15)
            ell = s * ell
        self.values.append(self.h(ell, gap0))
        return {"x": ca.DM(ell)}


def test_the_microstepper_refutation_needs_its_constraint_to_fail(free_stepper, monkeypatch):
    """The microstepper's IPOPT refutation (least V at which a constraint fails) counts a state only
    where its constraint is <= 0 (to rounding: 1e-9 of its size), judged by the transformation,
    not by IPOPT's status. With every answer moved to a hair inside F (constraint +1e-4: A^2 for
    a pair's current, 5.6 uA below 9 A; checked) nothing is refuted: no level, no constraint."""
    region = free_stepper
    stubs = [_Inside(solver, j, region.current_limit) for j, solver in enumerate(region._refuters)]
    monkeypatch.setattr(region, "_refuters", stubs)
    found, why, ell = region.refute((0.0, 0.0, 0.025), starts=4)
    values = np.concatenate([s.values for s in stubs])
    assert values.size == 4 * len(MICROSTEPPER_CONSTRAINTS) and np.all(values >= 1e-4 * (1 - 1e-6))
    assert found == math.inf and why == "" and ell is None
