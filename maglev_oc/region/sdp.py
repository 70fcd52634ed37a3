"""Enlarging the certified set: P chosen by an SDP (cvxpy + Clarabel) over a sound inner polytope.

Procedure 2 with the Lyapunov equation's P certifies whatever ellipsoid that P happens to give.
Here P is chosen to make the certified set large where users care: the initial gap error e1 and
the initial horizontal error e2 (at rest, internal models empty). The feasible set F is
nonconvex in (x1, v); it is replaced by a polytope that is *proved* to lie inside it:

* **Inner polytope.** For a gap half-width E, the product [-E, E] x Poly of gap errors and
  acceleration deviations dv = v - v_ss(phi) such that (r_v(phi) + e1, v_ss(phi) + dv) is in F
  for every e1 in [-E, E] and every phase phi. For each gap x1, the slice of F in v is convex:
  R >= 0 is v2 <= m0(x1) - q(x1) v1^2 (q = L4/L1^2 > 0), and when the root at R = 0 needs more
  than the limit, -L3/(2 L4) >= I (checked by interval arithmetic on the whole gap range), the
  current constraint is exactly the ellipse (v1/L1)^2 + ((v2 - G + L2 + L4 I^2)/L3)^2 <= I^2
  (the image of the disk |u| <= I under the physical root). A polygon whose vertices lie in every
  slice therefore lies in every slice; each vertex is verified on all (e1, phi) by branch and
  bound with interval arithmetic.
* **SDP.** With Q = P^-1 (level 1), maximise log a1 + log a2 subject to
  A Q + Q A' + 2 decay Q <= 0 (invariance), n' M Q M' n <= b^2 for each face n' dv <= b of the
  polygon, e1 and e2 spreads within E and the stoppers, and [[1, x'], [x, Q]] >= 0 for the
  corners x = (+-a1, +-a2) of the initial-condition rectangle (Schur complement of x' Q^-1 x <= 1).
  Solved in acceleration-scaled coordinates (:meth:`RegulatorLoop.state_scale`) with Clarabel.
* **Re-check.** The solver's Q is checked in floating point (eigenvalues, face inequalities) and
  the level scaled down if needed; then :class:`~maglev_oc.region.procedure2.Procedure2`
  certifies the resulting P against the exact F, usually at a level above 1.

Several half-widths E are tried; the one with the largest certified rectangle is kept.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field

import casadi as ca
import cvxpy as cp
import numpy as np
from scipy.spatial import ConvexHull

from maglev_oc.errors import InputError
from maglev_oc.model.hardware import PEAK_CURRENT_LIMIT
from maglev_oc.region.closed_loop import E1, E2, LOOP_VARIABLES, N_ERROR, Reference, RegulatorLoop
from maglev_oc.region.ellipsoid import max_rectangle
from maglev_oc.region.feasibility import (
    FeasibleSet,
    constraints_from_coefficients,
    transformation_constraints,
)
from maglev_oc.region.interval import IntervalFunction
from maglev_oc.region.procedure2 import Procedure2, Procedure2Result
from maglev_oc.results import PerAxis, Result

__all__ = [
    "HALFWIDTH_FRACTIONS",
    "InnerPolygon",
    "PolygonBuilder",
    "SdpCandidate",
    "SdpResult",
    "construction_level",
    "enlarge",
    "solve_sdp",
]

HALFWIDTH_FRACTIONS = (0.35, 0.55, 0.75, 0.95)
"""Gap half-widths tried, as fractions of the room to the nearer stopper."""


@dataclass(frozen=True)
class InnerPolygon(Result):
    """A polygon Poly in dv = (v1 - v1_ss, v2 - v2_ss) [m/s^2] with [-E, E] x Poly inside F for
    every phase (proved: vertices by interval branch and bound, convexity of F's slices).

    Faces are n' dv <= b (``normals`` (k, 2), ``offsets`` (k,)). ``status`` ``"proved"``, or
    ``"not_proved"`` with the reason in ``message``.
    """

    success: bool
    status: str
    message: str
    halfwidth: float  # E [m]
    vertices: np.ndarray  # (2, k)
    normals: np.ndarray
    offsets: np.ndarray
    cells: int  # interval evaluations spent on the proof
    timings: Mapping[str, float] = field(default_factory=dict)  # [s] {"total": ...}


class PolygonBuilder:
    """Builds and proves inner polygons for one feasible set and loop (functions built once)."""

    def __init__(self, feasible: FeasibleSet, loop: RegulatorLoop) -> None:
        if feasible.compensation is not None:
            raise InputError(
                "the SDP enlargement's inner polygons are for the uncompensated feasible set; with a "
                "compensated effect use Procedure 2 with the Lyapunov P (or a P of your own)"
            )
        self.feasible = feasible
        self.loop = loop
        e1 = ca.SX.sym("e1")
        phi = ca.SX.sym("phi")
        dv = ca.SX.sym("dv", 2)
        off = ca.SX.sym("F", len(LOOP_VARIABLES), 3)
        basis = ca.vertcat(1, ca.sin(phi), ca.cos(phi))
        o = ca.mtimes(off, basis)
        x1 = o[0] + e1
        v = ca.vertcat(o[2] + dv[0], o[3] + dv[1])
        margin, headroom = transformation_constraints(feasible.model, x1, v, feasible.current_limit)
        self._fn = ca.Function("h_poly", [e1, phi, dv, ca.vec(off)], [ca.vertcat(margin, headroom)])
        self._ifn = IntervalFunction(self._fn)
        y = ca.SX.sym("y")
        L1, _, L3, L4 = feasible.model.L(y)
        # convexity premise: L1 > 0, L4 > 0, -L3 > 0 and (with a current limit) -L3/(2 L4) >= I
        limit = feasible.current_limit if feasible.current_limit is not None else 0.0
        premise = ca.vertcat(L1, L4, -L3, -L3 / (2 * L4) - limit)
        self._premise = IntervalFunction(ca.Function("premise", [y], [premise]))

    def convex_slices(self, gap_lo: float, gap_hi: float, cells: int = 512) -> bool:
        """Interval proof that F's v-slices are convex for every gap in [gap_lo, gap_hi]."""
        edges = np.linspace(gap_lo, gap_hi, cells + 1)
        lo, _ = self._premise([edges[None, :-1]], [edges[None, 1:]])
        return bool(np.all(lo[0] > 0))

    def build(
        self,
        reference: Reference,
        halfwidth: float,
        *,
        n_vertices: int = 24,
        shrink: float = 0.995,
        max_cells: int = 200_000,
    ) -> InnerPolygon:
        """An inner polygon for the gap half-width ``halfwidth`` (module docstring).

        Parameters
        ----------
        reference : Reference
        halfwidth : float
            E [m]: gap errors |e1| <= E around the reference's whole orbit.
        n_vertices : int
            Directions in dv, scaled so that each asks for about the same current.
        shrink : float
            Fraction of the sampled radius at which a vertex is first tried.
        max_cells : int
            Interval evaluations per vertex, pooled over the vertices proved together: a batch of k
            vertices stops after ``max_cells * k`` cells, and its vertices not yet proved count as not
            proved (so one hard vertex may use the others' share).

        Returns
        -------
        InnerPolygon
        """
        t0 = time.perf_counter()
        if not (halfwidth > 0):
            raise InputError(f"halfwidth must be positive [m], got {halfwidth!r}")
        F = self.loop.offset_coefficients(reference)
        amp = math.hypot(F[0, 1], F[0, 2])
        gap_lo, gap_hi = F[0, 0] - amp - halfwidth, F[0, 0] + amp + halfwidth
        if gap_lo <= 0:
            return self._fail(halfwidth, t0, f"gap range reaches {gap_lo * 1e3:.3g} mm <= 0")
        if not self.convex_slices(gap_lo, gap_hi):
            return self._fail(halfwidth, t0, "could not prove F's slices convex on the gap range")
        periodic = not reference.is_setpoint
        L1, _, L3, _ = self.feasible.model.coefficients([F[0, 0]])[:, 0]
        lim = self.feasible.current_limit or PEAK_CURRENT_LIMIT
        scale = np.array([L1 * lim, abs(L3) * lim])
        th = np.linspace(0, 2 * math.pi, n_vertices, endpoint=False)
        dirs = np.vstack([np.cos(th), np.sin(th)]) * scale[:, None]
        radius = self._sampled_radii(F, dirs, halfwidth, periodic) * shrink
        radii, cells_used, pending = self._proved_radii(F, dirs, radius, halfwidth, periodic, max_cells)
        if pending.size:
            message = f"vertices {pending.tolist()} could not be proved inside F"
            return self._fail(halfwidth, t0, message, cells_used)
        verts = dirs * radii[None, :]
        if np.any(radius <= 0):
            message = "the origin dv = 0 is not strictly inside F on this range"
            return self._fail(halfwidth, t0, message, cells_used)
        hull = ConvexHull(verts.T)
        return InnerPolygon(
            True,
            "proved",
            f"{hull.vertices.size} vertices proved on gap [{gap_lo * 1e3:.3f}, {gap_hi * 1e3:.3f}] mm",
            halfwidth,
            verts[:, hull.vertices],
            hull.equations[:, :2],
            -hull.equations[:, 2],
            cells_used,
            {"total": time.perf_counter() - t0},
        )

    def _sampled_radii(self, F: np.ndarray, dirs: np.ndarray, halfwidth: float, periodic: bool) -> np.ndarray:
        """Radius (k,) of the intersection of F's slices along each direction, on a sample of
        gap errors and phases (bisection on the numpy constraints over [0, 2]: a direction asks for
        the current limit at about 1, so the limit's ellipse, of diameter 2, bounds the radius;
        without a current limit F is unbounded towards weaker attraction and 2 is the cap)."""
        es = np.linspace(-halfwidth, halfwidth, 41)
        ps = np.linspace(0, 2 * math.pi, 73)[:-1] if periodic else np.zeros(1)
        E, PH = (a.ravel() for a in np.meshgrid(es, ps))
        nd = dirs.shape[1]
        offs = F @ np.vstack([np.ones_like(PH), np.sin(PH), np.cos(PH)])  # (4, ns)
        coef = self.feasible.model.coefficients(offs[0] + E)[:, None, :]  # (4, 1, ns)
        G = self.feasible.model.params.gravity
        lo_t = np.zeros((nd, E.size))
        hi_t = np.full((nd, E.size), 2.0)
        for _ in range(40):
            mid = 0.5 * (lo_t + hi_t)
            v1 = offs[2][None, :] + dirs[0][:, None] * mid
            v2 = offs[3][None, :] + dirs[1][:, None] * mid
            m_, h_ = constraints_from_coefficients(coef, v1, v2, G, self.feasible.current_limit)
            ok = (m_ >= 0) & (h_ >= 0)
            lo_t = np.where(ok, mid, lo_t)
            hi_t = np.where(ok, hi_t, mid)
        return lo_t.min(axis=1)

    def _proved_radii(self, F, dirs, radius, halfwidth, periodic, max_cells):
        """(radii (k,), cells spent, vertices still unproved): the vertices proved on all (e1, phi)
        cells by one batched branch and bound, any vertex that cannot be proved shrunk by 3 %
        and tried again (12 rounds)."""
        fpar = F.ravel(order="F")[:, None]
        cells_used = 0
        radii = radius.copy()
        pending = np.arange(dirs.shape[1])
        for _ in range(12):
            proved, used = self._prove_vertices(
                dirs[:, pending] * radii[pending], halfwidth, periodic, fpar, max_cells
            )
            cells_used += used
            pending = pending[~proved]
            if pending.size == 0:
                break
            radii[pending] *= 0.97
        return radii, cells_used, pending

    def _prove_vertices(self, verts, halfwidth, periodic, fpar, max_cells) -> tuple[np.ndarray, int]:
        """Interval branch and bound over (e1, phi) for every vertex (2, k) at once."""
        k = verts.shape[1]
        n_e = 16
        e_edges = np.linspace(-halfwidth, halfwidth, n_e + 1)
        if periodic:
            n_p = 24
            p_edges = np.linspace(0, 2 * math.pi, n_p + 1)
            ie, ip = (a.ravel() for a in np.meshgrid(range(n_e), range(n_p)))
            lo = np.vstack([e_edges[ie], p_edges[ip]])
            hi = np.vstack([e_edges[ie + 1], p_edges[ip + 1]])
        else:
            lo = np.vstack([e_edges[:-1], np.zeros(n_e)])
            hi = np.vstack([e_edges[1:], np.zeros(n_e)])
        owner = np.repeat(np.arange(k), lo.shape[1])
        lo, hi = np.tile(lo, k), np.tile(hi, k)
        failed = np.zeros(k, dtype=bool)
        used = 0
        scale = np.array([[halfwidth], [math.pi]])
        while lo.shape[1]:
            used += lo.shape[1]
            v = verts[:, owner]
            hlo, hhi = self._ifn([lo[0:1], lo[1:2], v, fpar], [hi[0:1], hi[1:2], v, fpar])
            failed[owner[np.any(hhi[0] < 0, axis=0)]] = True
            bad = ~np.all(hlo[0] >= 0, axis=0) & ~failed[owner]
            lo, hi, owner = lo[:, bad], hi[:, bad], owner[bad]
            if used > max_cells * k:
                failed[owner] = True
                break
            if lo.shape[1]:
                w = (hi - lo) / scale
                dim = np.argmax(w, axis=0) if periodic else np.zeros(lo.shape[1], dtype=int)
                cols = np.arange(lo.shape[1])
                mid = 0.5 * (lo[dim, cols] + hi[dim, cols])
                lo2, hi2 = lo.copy(), hi.copy()
                hi[dim, cols] = mid
                lo2[dim, cols] = mid
                lo, hi, owner = np.hstack([lo, lo2]), np.hstack([hi, hi2]), np.concatenate([owner, owner])
        return ~failed, used

    @staticmethod
    def _fail(halfwidth, t0, message, cells: int = 0) -> InnerPolygon:
        """Not proved, with the interval evaluations spent before it gave up."""
        z = np.zeros((2, 0))
        timings = {"total": time.perf_counter() - t0}
        return InnerPolygon(
            False, "not_proved", message, halfwidth, z, np.zeros((0, 2)), np.zeros(0), int(cells), timings
        )


# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SdpCandidate(Result):
    """One SDP solve for one gap half-width, with its re-certification by Procedure 2.

    ``status`` ``"certified"`` when Procedure 2 certified the SDP's P, else ``"not_certified"``;
    ``solver_status`` is what the SDP solver (or the step before it) said.
    """

    success: bool
    status: str
    message: str
    halfwidth: float  # E [m]
    polygon: InnerPolygon
    solver_status: str
    P: np.ndarray | None  # level 1 is inside the polytope (after the floating-point re-check)
    construction_level: float  # largest c <= 1 with {V <= c} inside the polytope, re-checked
    rectangle: PerAxis  # [m] half-sides (e1, e2) at the certified level
    certified: Procedure2Result | None
    reach: float = 0.0  # with a direction d: largest t with t d in the certified set
    timings: Mapping[str, float] = field(default_factory=dict)  # [s] {"sdp": solve time}

    @classmethod
    def of(
        cls,
        halfwidth: float,
        polygon: InnerPolygon,
        solver_status: str,
        *,
        P: np.ndarray | None = None,
        construction_level: float = 0.0,
        rectangle=(0.0, 0.0),
        certified: Procedure2Result | None = None,
        reach: float = 0.0,
        solve_time: float = 0.0,
    ) -> SdpCandidate:
        """The candidate with its verdict; ``solve_time`` [s] of the SDP."""
        ok = bool(certified is not None and certified.success)
        message = f"E = {halfwidth * 1e3:.3g} mm: SDP {solver_status}"
        if certified is not None:
            message += f"; Procedure 2: {certified.message}"
        return cls(
            ok,
            "certified" if ok else "not_certified",
            message,
            halfwidth,
            polygon,
            solver_status,
            P,
            construction_level,
            PerAxis.of(rectangle),
            certified,
            reach,
            {"sdp": solve_time},
        )

    @property
    def score(self) -> float:
        """What :func:`enlarge` maximises: ``reach`` with a direction, else the rectangle's area [m^2]."""
        return self.reach if self.reach > 0 else self.rectangle[0] * self.rectangle[1]


@dataclass(frozen=True)
class SdpResult(Result):
    """The SDP-enlarged certificate for one reference (module docstring).

    ``status`` ``"certified"`` (``best`` is the candidate with the largest score),
    ``"not_certified"`` (no candidate P could be certified) or ``"infeasible"`` (the reference
    reaches the stoppers).
    """

    success: bool
    status: str
    message: str
    reference: Reference
    best: SdpCandidate | None
    candidates: tuple[SdpCandidate, ...]
    decay: float
    timings: Mapping[str, float] = field(default_factory=dict)  # [s] polygon, sdp, certify, total

    @property
    def certified(self) -> Procedure2Result | None:
        """The best candidate's certificate (None without one)."""
        return None if self.best is None else self.best.certified


def solve_sdp(
    loop: RegulatorLoop,
    reference: Reference,
    polygon: InnerPolygon,
    feasible: FeasibleSet,
    decay: float,
    weights: tuple[float, float],
    direction: np.ndarray | None = None,
) -> tuple[str, np.ndarray | None, float]:
    """The SDP of the module docstring, in acceleration-scaled coordinates (cvxpy + Clarabel).

    Objective: the (e1, e2) rectangle, or with ``direction`` (10,) the largest t with
    +-t direction in the set.

    Parameters
    ----------
    loop : RegulatorLoop
    reference : Reference
    polygon : InnerPolygon
        The proved faces n' dv <= b the level set must respect.
    feasible : FeasibleSet
        Supplies the horizontal stoppers [m].
    decay : float
        Guaranteed decay rate of V [1/s].
    weights : (float, float)
        Weights of log a1, log a2.
    direction : (10,) array, optional

    Returns
    -------
    (str, array or None, float)
        The solver's status, Q = P^-1 in SI units (None if not solved) and the solve time [s].
    """
    d = loop.state_scale()
    Dm = np.diag(d)
    A = np.diag(1 / d) @ loop.A @ Dm
    Qh = cp.Variable((N_ERROR, N_ERROR), symmetric=True)
    a = cp.Variable(2)
    cons = [A @ Qh + Qh @ A.T + 2 * decay * Qh << 0, Qh >> 1e-9 * np.eye(N_ERROR)]
    Mv = loop.output[2:4] @ Dm  # (v1, v2) rows in scaled coordinates
    for n, b in zip(polygon.normals, polygon.offsets, strict=True):
        row = n @ Mv
        cons.append(row @ Qh @ row <= b**2)
    F = loop.offset_coefficients(reference)
    room = {0: polygon.halfwidth}
    if feasible.position_range is not None:
        amp = math.hypot(F[1, 1], F[1, 2])
        room[1] = min(F[1, 0] - amp - feasible.position_range[0], feasible.position_range[1] - F[1, 0] - amp)
    for row_idx, r in room.items():
        if r <= 0:
            return "infeasible (no room to the stoppers)", None, 0.0
        row = loop.output[row_idx] @ Dm
        cons.append(row @ Qh @ row <= r**2)
    if direction is None:
        u1 = np.zeros(N_ERROR)
        u1[E1] = 1 / d[E1]
        u2 = np.zeros(N_ERROR)
        u2[E2] = 1 / d[E2]
        for s in (1.0, -1.0):
            x = cp.reshape(a[0] * u1 + s * a[1] * u2, (N_ERROR, 1), order="F")
            cons.append(cp.bmat([[np.ones((1, 1)), x.T], [x, Qh]]) >> 0)
        obj = cp.Maximize(weights[0] * cp.log(a[0]) + weights[1] * cp.log(a[1]))
    else:
        x = cp.reshape(a[0] * (np.asarray(direction, float) / d), (N_ERROR, 1), order="F")
        cons.append(cp.bmat([[np.ones((1, 1)), x.T], [x, Qh]]) >> 0)
        obj = cp.Maximize(a[0])
    prob = cp.Problem(obj, cons)
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():  # "optimal_inaccurate" is kept in the status and re-checked
            warnings.simplefilter("ignore", UserWarning)
            prob.solve(solver=cp.CLARABEL)
    except cp.error.SolverError as err:
        return f"solver error: {err}", None, time.perf_counter() - t0
    dt = time.perf_counter() - t0
    if prob.status not in ("optimal", "optimal_inaccurate") or Qh.value is None:
        return str(prob.status), None, dt
    Q = Dm @ Qh.value @ Dm
    return str(prob.status), 0.5 * (Q + Q.T), dt


def construction_level(loop: RegulatorLoop, P: np.ndarray, polygon: InnerPolygon, room_e1: float) -> float:
    """Largest c <= 1 with {V <= c} inside [-E, E] x Poly, recomputed from P in floating point.

    Parameters
    ----------
    loop : RegulatorLoop
    P : (10, 10) array
    polygon : InnerPolygon
    room_e1 : float
        E [m].

    Returns
    -------
    float
    """
    Pinv = np.linalg.inv(P)
    Mv = loop.output[2:4]
    levels = [1.0]
    for n, b in zip(polygon.normals, polygon.offsets, strict=True):
        row = n @ Mv
        levels.append(b**2 / (row @ Pinv @ row))
    levels.append(room_e1**2 / Pinv[E1, E1])
    return float(min(levels))


def enlarge(
    procedure: Procedure2,
    reference: Reference,
    *,
    fractions=HALFWIDTH_FRACTIONS,
    decay: float = 0.1,
    weights: tuple[float, float] = (1.0, 1.0),
    direction=None,
    builder: PolygonBuilder | None = None,
) -> SdpResult:
    """Choose P by SDP to maximise the certified rectangle of (e1, e2) initial errors.

    Parameters
    ----------
    procedure : Procedure2
        Built once for the feasible set and loop; used to certify each candidate P.
    reference : Reference
    fractions : sequence of float
        Gap half-widths E to try, as fractions of the room to the nearer stopper.
    decay : float
        Guaranteed decay rate [1/s] of V in the SDP (A'P + PA + 2 decay P <= 0).
    weights : (float, float)
        Weights of log a1, log a2 in the objective.
    direction : array (10,) or None
        If given, maximise instead how far along this z~ (e.g. one start's initial error) the
        certified set reaches; ``best.reach`` >= 1 means that start is certified.
    builder : PolygonBuilder, optional
        Reused across calls (built here otherwise).

    Returns
    -------
    SdpResult
    """
    t0 = time.perf_counter()
    if decay < 0:
        raise InputError(f"decay must be >= 0 [1/s], got {decay!r}")
    feasible, loop = procedure.feasible, procedure.loop
    builder = builder or PolygonBuilder(feasible, loop)
    room = _gap_room(feasible, loop, reference)
    if room <= 0:
        timings = {"total": time.perf_counter() - t0}
        return SdpResult(
            False, "infeasible", "the reference reaches the stoppers", reference, None, (), decay, timings
        )
    clock = {"polygon": 0.0, "sdp": 0.0, "certify": 0.0}
    cands = tuple(
        _candidate(procedure, builder, reference, frac * room, decay, weights, direction, clock)
        for frac in fractions
    )
    good = [c for c in cands if c.success]
    timings = {**clock, "total": time.perf_counter() - t0}
    if not good:
        message = "no candidate P could be certified"
        return SdpResult(False, "not_certified", message, reference, None, cands, decay, timings)
    best = max(good, key=lambda c: c.score)
    return SdpResult(
        True, "certified", _best_message(best, direction), reference, best, cands, decay, timings
    )


def _gap_room(feasible: FeasibleSet, loop: RegulatorLoop, reference: Reference) -> float:
    """Room [m] from the reference's gap orbit to the nearer stopper (to 2 mm without stoppers)."""
    F = loop.offset_coefficients(reference)
    amp = math.hypot(F[0, 1], F[0, 2])
    if feasible.gap_range is not None:
        return min(F[0, 0] - amp - feasible.gap_range[0], feasible.gap_range[1] - F[0, 0] - amp)
    return F[0, 0] - amp - 2e-3


def _candidate(procedure, builder, reference, E, decay, weights, direction, clock) -> SdpCandidate:
    """Polygon, SDP, floating-point checks and Procedure 2 for one half-width E [m]; the time of
    each step is added to ``clock``."""
    loop = procedure.loop
    tp = time.perf_counter()
    poly = builder.build(reference, E)
    clock["polygon"] += time.perf_counter() - tp
    if not poly.success:
        return SdpCandidate.of(E, poly, "no polygon")
    status, Q, dt = solve_sdp(loop, reference, poly, procedure.feasible, decay, weights, direction)
    clock["sdp"] += dt
    if Q is None:
        return SdpCandidate.of(E, poly, status, solve_time=dt)
    P = np.linalg.inv(Q)
    P = 0.5 * (P + P.T)
    if not loop.is_lyapunov(P, decay * 0.5):
        return SdpCandidate.of(E, poly, status + " (Lyapunov check failed)", solve_time=dt)
    c_con = construction_level(loop, P, poly, E)
    tc = time.perf_counter()
    cert = procedure.run(reference, P)
    clock["certify"] += time.perf_counter() - tc
    level = max(cert.level, 0.0)
    rect = max_rectangle(P[np.ix_([E1, E2], [E1, E2])], level) if level > 0 else (0.0, 0.0)
    reach = 0.0
    if direction is not None and level > 0:
        dvec = np.asarray(direction, float)
        reach = math.sqrt(level / (dvec @ P @ dvec))
    return SdpCandidate.of(
        E,
        poly,
        status,
        P=P,
        construction_level=c_con,
        rectangle=rect,
        certified=cert,
        reach=reach,
        solve_time=dt,
    )


def _best_message(best: SdpCandidate, direction) -> str:
    msg = (
        f"best half-width E = {best.halfwidth * 1e3:.3g} mm: rectangle |e1| <= {best.rectangle[0] * 1e3:.3g} "
        "mm, "
        f"|e2| <= {best.rectangle[1] * 1e3:.3g} mm (certified level {best.certified.level:.4g}; "
        f"{best.construction_level:.4g} by construction)"
    )
    if direction is not None:
        msg += f"; reaches {best.reach:.3g} x the given direction"
    if direction is not None and best.reach < 1:
        # success refers to certifying something; whether the direction is covered is in reach
        msg += " (not covered)"
    return msg
