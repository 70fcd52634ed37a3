"""Procedure 2 of Maggiore & Becerril (2004), adapted to the output regulator of 001/002, certified.

The papers (001 Sec. V, 002 Sec. 6) ask for "the largest set of feasible initial conditions x(0)
guaranteeing that (x(t), v(t)) in A for all t >= 0" and leave the adaptation of Procedure 2 to
their v undone. Procedure 2 as adapted here:

1. In error coordinates z~ (:mod:`maglev_oc.region.closed_loop`) the closed loop is z~' = A_cl z~
   *as long as* (x, v) stays in the feasible set F (:mod:`maglev_oc.region.feasibility`).
2. Take V = z~' P z~ with A_cl' P + P A_cl <= 0 (Lyapunov equation, or the SDP of
   :mod:`maglev_oc.region.sdp`). Every level set Omega_c = {V <= c} is invariant for the linear loop.
3. If Omega_c x {exosystem orbit} lies inside F, a solution starting in Omega_c stays in Omega_c
   (while it is in F it is a solution of the linear loop, whose V does not increase; it cannot
   reach the boundary of F without first leaving Omega_c), so the transformation exists and the
   currents fit for all t >= 0. The largest such c is c* = min V over the complement of F.

**Certificate.** F depends on z~ only through four linear functions (e1, e2, v1, v2) and the phase.
On Omega_c each linear function m'z~ ranges exactly over |m'z~| <= sqrt(c m' P^-1 m'), and the
triple l = (e1, v1, v2) ranges exactly over the 3-D ellipsoid {l' S^-1 l <= c}, S = M P^-1 M'
(the image of an ellipsoid under a linear map). So:

* the stopper constraints (linear in e1, e2) give their level in closed form;
* the nonlinear constraints (R >= 0, |u| <= I) are checked on l = sqrt(c) chol(S) zeta + l_ss(phi),
  |zeta| <= 1, phi in [0, 2 pi), by branch and bound with interval arithmetic on the CasADi graph
  (:mod:`maglev_oc.region.interval`): a box is accepted when the enclosure of every constraint is
  >= 0, refined otherwise. "Certified" means every box covering the ball was accepted: a sound
  lower bound on c*, up to floating-point rounding (handled by outward padding).

**Tightness.** Multistart IPOPT with exact derivatives minimises V on each constraint's boundary
(10-D, plus the phase): any point it returns is infeasible (or on the boundary) and bounds c* from
above. A branch-and-bound refutation also returns such a point. The report gives both bounds.

Assumptions of the certificate: the nominal plant equals the controller's model; the loop is the
continuous-time FL loop with exact velocities and an ideal amplifier (commands applied exactly
while within the limit); the reference is an exosystem trajectory (constant, or a pure sinusoid
at the exosystem's frequency, no ramp-in). The 5 kHz sampling, the high-gain observer and the
encoder quantisation are not covered; :mod:`maglev_oc.region.montecarlo` checks the sampled loop.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.region.closed_loop import DE1, DE2, E1, E2, N_ERROR, Reference, RegulatorLoop
from maglev_oc.region.feasibility import CONSTRAINT_NAMES, FeasibleSet, transformation_constraints
from maglev_oc.region.interval import IntervalFunction
from maglev_oc.results import PerAxis, Result

__all__ = [
    "GAP_DOMAIN",
    "LADDER",
    "MAX_ATTEMPTS",
    "NONLINEAR",
    "BoundaryMinimizer",
    "BoundaryMinimum",
    "BoxSearch",
    "EllipsoidImage",
    "InitialConditionSet",
    "LevelCertifier",
    "Procedure2",
    "Procedure2Result",
    "ellipsoid_image",
    "initial_condition_set",
    "max_rectangle",
    "travel_levels",
]

NONLINEAR = ("margin", "headroom")
"""The constraints of F that are not linear in z~ (checked by branch and bound)."""
LADDER = (0.995, 0.98, 0.95, 0.9, 0.8, 0.65, 0.5, 0.3, 0.15, 0.05, 0.01)
"""Fractions of the best upper bound at which a certificate is attempted, in this order."""
GAP_DOMAIN = (2e-3, 80e-3)
"""Gaps [m] the boundary search stays within (the model's formulas hold for any positive gap)."""
MAX_ATTEMPTS = 24
"""Branch-and-bound runs per reference and P before giving up."""


# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class EllipsoidImage:
    """What Omega_c = {z~' P z~ <= c} looks like through the functions F depends on.

    S (3, 3) = M P^-1 M' for l = (e1, v1, v2); chol (3, 3) lower factor of S; ``spread`` (4,) =
    sqrt(m' P^-1 m) for m = rows (e1, e2, v1, v2): on Omega_c each ranges over +- sqrt(c) spread.
    """

    S: np.ndarray
    chol: np.ndarray
    spread: np.ndarray
    Pinv_Mt: np.ndarray  # (10, 3) P^-1 M'


def ellipsoid_image(loop: RegulatorLoop, P: np.ndarray) -> EllipsoidImage:
    """What {V <= c} looks like through (e1, v1, v2) and the four linear functions F depends on.

    Parameters
    ----------
    loop : RegulatorLoop
    P : (10, 10) array
        Symmetric positive definite.

    Returns
    -------
    EllipsoidImage
    """
    P = _check_p(P)
    M = loop.output[[0, 2, 3]]
    pinv_mt = np.linalg.solve(P, M.T)
    S = M @ pinv_mt
    S = 0.5 * (S + S.T)
    spread = np.sqrt(np.einsum("ij,ji->i", loop.output, np.linalg.solve(P, loop.output.T)))
    return EllipsoidImage(S, np.linalg.cholesky(S), spread, pinv_mt)


def _check_p(P) -> np.ndarray:
    P = np.asarray(P, dtype=float)
    if P.shape != (N_ERROR, N_ERROR) or not np.all(np.isfinite(P)):
        raise ValueError(f"P must be a finite 10 x 10 matrix, got shape {P.shape}")
    if not np.allclose(P, P.T, rtol=1e-10, atol=0):
        raise ValueError("P must be symmetric")
    return 0.5 * (P + P.T)


def travel_levels(feasible: FeasibleSet, loop: RegulatorLoop, reference: Reference, P) -> dict[str, float]:
    """Exact min of V over each violated stopper half-space {x1 < g_lo}, ... (closed form).

    Parameters
    ----------
    feasible : FeasibleSet
        Supplies the stoppers [m] (a missing one gives an infinite level).
    loop : RegulatorLoop
    reference : Reference
    P : (10, 10) array

    Returns
    -------
    dict of str to float
        The level per stopper constraint (gap_low, gap_high, position_low, position_high).
    """
    img = ellipsoid_image(loop, P)
    F = loop.offset_coefficients(reference)
    out = {}
    for row, rng, names in (
        (0, feasible.gap_range, ("gap_low", "gap_high")),
        (1, feasible.position_range, ("position_low", "position_high")),
    ):
        if rng is None:
            out[names[0]] = out[names[1]] = math.inf
            continue
        amp = math.hypot(F[row, 1], F[row, 2])
        lo_room = F[row, 0] - amp - rng[0]
        hi_room = rng[1] - (F[row, 0] + amp)
        out[names[0]] = max(lo_room, 0.0) ** 2 / img.spread[row] ** 2
        out[names[1]] = max(hi_room, 0.0) ** 2 / img.spread[row] ** 2
    return out


# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BoxSearch(Result):
    """Outcome of one branch and bound on {V <= c}: ``status`` ``"certified"``, ``"refuted"``
    (an infeasible point was found: ``witness``) or ``"undecided"`` (box budget spent)."""

    success: bool
    status: str
    message: str
    level: float
    witness: np.ndarray | None  # (4,) zeta (3) and phase of an infeasible point, if refuted
    witness_level: float  # V at the witness (c |zeta|^2)
    binding: str  # constraint violated at the witness ('' otherwise)
    boxes: int  # boxes evaluated
    timings: Mapping[str, float] = field(default_factory=dict)  # [s] {"total": ...}

    @classmethod
    def of(
        cls,
        status: str,
        level: float,
        boxes: int,
        t0: float,
        *,
        witness: np.ndarray | None = None,
        witness_level: float = math.inf,
        binding: str = "",
    ) -> BoxSearch:
        """The outcome with its message; ``t0`` is the search's start (``time.perf_counter``)."""
        message = {
            "certified": f"every box of {{V <= {level:.4g}}} proved feasible ({boxes} boxes)",
            "refuted": f"{binding} < 0 at V = {witness_level:.4g} ({boxes} boxes)",
            "undecided": f"box budget spent after {boxes} boxes",
        }[status]
        timings = {"total": time.perf_counter() - t0}
        return cls(
            status == "certified", status, message, level, witness, witness_level, binding, boxes, timings
        )


class LevelCertifier:
    """Branch and bound over the image of Omega_c (module docstring), built once per
    (feasible set, loop) and reused for any P, c and reference.

    Parameters
    ----------
    feasible : FeasibleSet
    loop : RegulatorLoop
    max_boxes : int
        Budget of box evaluations per level before giving up ('undecided').
    """

    def __init__(self, feasible: FeasibleSet, loop: RegulatorLoop, *, max_boxes: int = 400_000) -> None:
        if max_boxes < 100:
            raise ValueError(f"max_boxes must be >= 100, got {max_boxes!r}")
        self.feasible = feasible
        self.loop = loop
        self.max_boxes = int(max_boxes)
        zeta = ca.SX.sym("zeta", 3)
        phi = ca.SX.sym("phi")
        lmat = ca.SX.sym("L", 3, 3)  # sqrt(c) chol(S)
        off = ca.SX.sym("F", 4, 3)
        basis = ca.vertcat(1, ca.sin(phi), ca.cos(phi))
        ell = ca.mtimes(lmat, zeta)
        offs = ca.mtimes(off, basis)
        x1 = offs[0] + ell[0]
        v = ca.vertcat(offs[2] + ell[1], offs[3] + ell[2])
        margin, headroom = transformation_constraints(feasible.model, x1, v, feasible.current_limit)
        h = ca.vertcat(margin, headroom)
        self._fn = ca.Function("h_zeta", [zeta, phi, ca.vec(lmat), ca.vec(off)], [h])
        self._ifn = IntervalFunction(self._fn)

    def certify(self, reference: Reference, P, level: float, *, phase_cells: int = 24) -> BoxSearch:
        """Branch and bound for the nonlinear constraints on {V <= level}.

        Parameters
        ----------
        reference : Reference
        P : (10, 10) array
        level : float
            c, positive and finite.
        phase_cells : int
            Initial cells over the phase [0, 2 pi) for a sinusoid.

        Returns
        -------
        BoxSearch
        """
        t0 = time.perf_counter()
        if not (level > 0 and math.isfinite(level)):
            raise ValueError(f"level must be positive and finite, got {level!r}")
        img = ellipsoid_image(self.loop, P)
        lmat = math.sqrt(level) * img.chol
        par_l = lmat.ravel(order="F")[:, None]
        par_f = self.loop.offset_coefficients(reference).ravel(order="F")[:, None]
        periodic = not reference.is_setpoint
        lo, hi = _initial_boxes(periodic, phase_cells)
        scale = np.array([1.0, 1.0, 1.0, 1.0 / math.pi])  # phase widths count per pi
        boxes = 0
        while lo.shape[1] > 0:
            # boxes outside the unit ball hold no point of the ellipsoid's image
            near = np.clip(0.0, lo[:3], hi[:3])
            keep = np.sum(near**2, axis=0) <= 1.0
            lo, hi, near = lo[:, keep], hi[:, keep], near[:, keep]
            n = lo.shape[1]
            if n == 0:
                break
            boxes += n
            hlo, _ = self._ifn([lo[:3], lo[3:4], par_l, par_f], [hi[:3], hi[3:4], par_l, par_f])
            ok = np.all(hlo[0] >= 0, axis=0)
            lo, hi, near = lo[:, ~ok], hi[:, ~ok], near[:, ~ok]
            if lo.shape[1] == 0:
                break
            # a point of each undecided box inside the ball: refute if infeasible there
            phase_mid = 0.5 * (lo[3] + hi[3])
            vals = np.asarray(self._fn.map(lo.shape[1])(near, phase_mid[None, :], par_l, par_f))
            bad = np.any(vals < 0, axis=0)
            if np.any(bad):
                r2 = np.where(bad, np.sum(near**2, axis=0), np.inf)
                k = int(np.argmin(r2))
                j = int(np.argmin(vals[:, k]))
                witness = np.concatenate([near[:, k], [phase_mid[k]]])
                return BoxSearch.of(
                    "refuted",
                    level,
                    boxes,
                    t0,
                    witness=witness,
                    witness_level=level * float(r2[k]),
                    binding=NONLINEAR[j],
                )
            if boxes > self.max_boxes:
                return BoxSearch.of("undecided", level, boxes, t0)
            lo, hi = _bisect_boxes(lo, hi, scale, periodic)
        return BoxSearch.of("certified", level, boxes, t0)

    def zeta_to_state(self, P, level: float, zeta) -> np.ndarray:
        """The z~ of least V whose l equals sqrt(level) chol(S) zeta (V there = level |zeta|^2)."""
        img = ellipsoid_image(self.loop, P)
        ell = math.sqrt(level) * img.chol @ np.asarray(zeta, dtype=float)
        return img.Pinv_Mt @ np.linalg.solve(img.S, ell)


def _initial_boxes(periodic: bool, phase_cells: int) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) (4, k): a 4 x 4 x 4 grid over the cube [-1, 1]^3 of zeta, times ``phase_cells``
    cells over [0, 2 pi) for a sinusoid (the phase pinned at 0 for a set-point)."""
    n0 = 4
    edges = np.linspace(-1, 1, n0 + 1)
    g = np.array(np.meshgrid(range(n0), range(n0), range(n0), indexing="ij")).reshape(3, -1)
    lo = edges[g]
    hi = edges[g + 1]
    if periodic:
        pe = np.linspace(0, 2 * math.pi, phase_cells + 1)
        k = np.arange(phase_cells)
        lo = np.vstack([np.repeat(lo, phase_cells, axis=1), np.tile(pe[k], lo.shape[1])])
        hi = np.vstack([np.repeat(hi, phase_cells, axis=1), np.tile(pe[k + 1], hi.shape[1])])
    else:
        lo = np.vstack([lo, np.zeros(lo.shape[1])])
        hi = np.vstack([hi, np.zeros(hi.shape[1])])
    return lo, hi


def _bisect_boxes(lo: np.ndarray, hi: np.ndarray, scale: np.ndarray, periodic: bool):
    """Every box halved along its widest (scaled) side; the phase only for a sinusoid."""
    width = (hi - lo) * scale[:, None]
    if not periodic:
        width[3] = 0
    dim = np.argmax(width, axis=0)
    cols = np.arange(lo.shape[1])
    mid = 0.5 * (lo[dim, cols] + hi[dim, cols])
    lo2, hi2 = lo.copy(), hi.copy()
    hi[dim, cols] = mid
    lo2[dim, cols] = mid
    return np.hstack([lo, lo2]), np.hstack([hi, hi2])


# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BoundaryMinimum(Result):
    """min V on the boundary of one constraint by multistart IPOPT (an upper bound on c*).

    ``success``: at least one start converged onto the boundary (``status`` ``"found"``, else
    ``"not_found"``: no boundary point was met along the start rays, or none converged).
    """

    success: bool
    status: str
    message: str
    constraint: str
    level: float  # best V found (inf if no start converged)
    state: np.ndarray | None  # z~ (10,)
    phase: float
    starts: int
    converged: int
    levels: np.ndarray  # V of every converged start
    timings: Mapping[str, float] = field(default_factory=dict)  # [s] {"total": ...}


class BoundaryMinimizer:
    """min z~' P z~  s.t. h_j(z~, phi) = 0 (and the other nonlinear constraint >= 0), IPOPT with
    exact Hessians; built once per (feasible set, loop), parameters P and the reference."""

    def __init__(self, feasible: FeasibleSet, loop: RegulatorLoop) -> None:
        self.feasible = feasible
        self.loop = loop
        z = ca.SX.sym("z", N_ERROR)
        phi = ca.SX.sym("phi")
        pvec = ca.SX.sym("P", N_ERROR * N_ERROR)
        off = ca.SX.sym("F", 4, 3)
        h = feasible.loop_expressions(loop, z, phi, off)
        P = ca.reshape(pvec, N_ERROR, N_ERROR)
        obj = ca.bilin(P, z, z)
        basis = ca.vertcat(1, ca.sin(phi), ca.cos(phi))
        gap = ca.dot(off[0, :].T, basis) + z[0]
        self._h = ca.Function("h", [z, phi, ca.vec(off)], [ca.vertcat(h[0], h[1], gap)])
        self._solvers = {}
        names = NONLINEAR if feasible.current_limit is not None else NONLINEAR[:1]
        for j, name in enumerate(names):
            g = [h[j], gap]  # the gap is kept inside the model's domain GAP_DOMAIN
            if name == "headroom":
                g.append(h[0])  # R >= 0 on the current boundary (physical root defined)
            nlp = {"x": ca.vertcat(z, phi), "p": ca.vertcat(pvec, ca.vec(off)), "f": obj, "g": ca.vertcat(*g)}
            opts = {
                "ipopt.print_level": 0,
                "print_time": False,
                "ipopt.tol": 1e-10,
                "ipopt.max_iter": 200,
                "ipopt.sb": "yes",
                # multistart points may leave the model's domain (NaN): that start fails and
                # is reported in the result; no warning on stderr for each
                "show_eval_warnings": False,
                "calc_lam_p": False,
            }
            self._solvers[name] = (ca.nlpsol(f"min_V_{name}", "ipopt", nlp, opts), len(g))

    @property
    def constraints(self) -> tuple[str, ...]:
        """The constraints with a solver: margin, and headroom when F has a current limit."""
        return tuple(self._solvers)

    def minimize(
        self, reference: Reference, P, constraint: str, *, starts: int = 12, seed: int = 0
    ) -> BoundaryMinimum:
        """min V on the boundary of ``constraint`` from ``starts`` rays (multistart IPOPT).

        Parameters
        ----------
        reference : Reference
        P : (10, 10) array
        constraint : str
            One of :attr:`constraints`.
        starts : int
            Rays: the six coordinate directions of zeta, then random ones.
        seed : int
            Seed of the random rays and phases.

        Returns
        -------
        BoundaryMinimum
        """
        t0 = time.perf_counter()
        if constraint not in self._solvers:
            raise ValueError(f"constraint must be one of {list(self._solvers)}, got {constraint!r}")
        P = _check_p(P)
        solver, ng = self._solvers[constraint]
        F = self.loop.offset_coefficients(reference)
        par = np.concatenate([P.ravel(order="F"), F.ravel(order="F")])
        img = ellipsoid_image(self.loop, P)
        rng = np.random.default_rng(seed)
        j = NONLINEAR.index(constraint)
        dirs = np.vstack([np.eye(3), -np.eye(3), rng.standard_normal((max(starts - 6, 0), 3))])[:starts]
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        periodic = not reference.is_setpoint
        lbx = -np.inf * np.ones(N_ERROR + 1)
        ubx = np.inf * np.ones(N_ERROR + 1)
        if not periodic:
            lbx[-1] = ubx[-1] = 0.0
        lbg = np.zeros(ng)
        ubg = np.zeros(ng)
        lbg[1], ubg[1] = GAP_DOMAIN
        if ng == 3:
            ubg[2] = np.inf
        best_level, best_z, best_phi = math.inf, None, 0.0
        levels = []
        # along each ray zeta = t d, the first sign change of h_j gives a start on the boundary
        ts = np.geomspace(1e-3, 1e3, 241)
        for d in dirs:
            phi0 = rng.uniform(0, 2 * math.pi) if periodic else 0.0
            zs = np.outer(img.Pinv_Mt @ np.linalg.solve(img.S, img.chol @ d), ts)
            hv_all = np.asarray(self._h.map(ts.size)(zs, phi0, F.ravel(order="F")))
            hv = hv_all[j]
            inside = (hv_all[2] > GAP_DOMAIN[0]) & (hv_all[2] < GAP_DOMAIN[1])
            neg = np.nonzero((hv < 0) & inside)[0]
            if neg.size == 0:
                continue
            x0 = np.concatenate([zs[:, neg[0]], [phi0]])
            sol = solver(x0=x0, p=par, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
            stats = solver.stats()
            if not stats["success"]:
                continue
            x = np.asarray(sol["x"]).ravel()
            gval = np.asarray(sol["g"]).ravel()
            if abs(gval[0]) > 1e-7 * max(1.0, abs(hv[inside]).max()) or (ng == 3 and gval[2] < -1e-9):
                continue
            lev = float(sol["f"])
            levels.append(lev)
            if lev < best_level:
                best_level, best_z, best_phi = lev, x[:N_ERROR], float(x[-1]) % (2 * math.pi)
        found = bool(levels)
        message = (
            f"least V on {constraint} = 0: {best_level:.4g} ({len(levels)} of {len(dirs)} starts converged)"
            if found
            else f"no start reached the boundary of {constraint} ({len(dirs)} starts)"
        )
        return BoundaryMinimum(
            found,
            "found" if found else "not_found",
            message,
            constraint,
            best_level,
            best_z,
            best_phi,
            len(dirs),
            len(levels),
            np.array(levels),
            {"total": time.perf_counter() - t0},
        )


# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class InitialConditionSet:
    """The certified set {z~' P z~ <= c} seen through the initial conditions users set.

    Semi-axes: the largest deviation of each of e1 [m], e1' [m/s], e2 [m], e2' [m/s] from the
    reference's steady state with every other state at its steady-state value (for a
    set-point: at rest, internal models empty). ``rectangle`` (a1, a2) [m]: the largest-area
    box |e1| <= a1, |e2| <= a2 (rates and internal models at steady state) inside the set.
    """

    semi_axes: dict[str, float]  # e1, e1_rate, e2, e2_rate
    rectangle: PerAxis  # (a1 on e1, vertical; a2 on e2, horizontal)


def initial_condition_set(P, level: float) -> InitialConditionSet:
    """The set {z~' P z~ <= level} seen through the initial conditions users set.

    Parameters
    ----------
    P : (10, 10) array
    level : float
        c (0 gives the empty set's zero sizes).

    Returns
    -------
    InitialConditionSet
    """
    P = _check_p(P)
    semi = {
        name: math.sqrt(level / P[i, i])
        for name, i in (("e1", E1), ("e1_rate", DE1), ("e2", E2), ("e2_rate", DE2))
    }
    return InitialConditionSet(semi, PerAxis.of(max_rectangle(P[np.ix_([E1, E2], [E1, E2])], level)))


def max_rectangle(P2, level: float) -> tuple[float, float]:
    """Half-sides (a, b) of the largest-area axis-aligned box centred at 0 inside the ellipse
    {y' P2 y <= level} (2 x 2): corners (a, +-b) must satisfy a^2 p11 + b^2 p22 + 2|a b p12| <= level.

    Parameters
    ----------
    P2 : (2, 2) array
        Symmetric positive definite.
    level : float

    Returns
    -------
    (float, float)
        a, b in the units of y.
    """
    p11, p22, p12 = P2[0, 0], P2[1, 1], abs(P2[0, 1])
    # with a = r cos t / sqrt(p11), b = r sin t / sqrt(p22): r^2 (1 + k sin 2t) = level,
    # k = p12 / sqrt(p11 p22); area ~ sin 2t / (1 + k sin 2t) is largest at t = pi/4.
    k = p12 / math.sqrt(p11 * p22)
    r = math.sqrt(level / (1 + k))
    return r / math.sqrt(2 * p11), r / math.sqrt(2 * p22)


@dataclass(frozen=True)
class Procedure2Result(Result):
    """The adapted Procedure 2 for one reference and one P (module docstring).

    ``level`` is the certified c (0 if nothing could be certified); c* lies in
    [level, level_upper]; ``tightness`` = level / level_upper. ``levels`` lists, per
    constraint of F, (certified lower bound, best upper bound) on min V over its violation.
    """

    success: bool
    status: str
    message: str
    reference: Reference
    P: np.ndarray
    level: float
    level_upper: float
    tightness: float
    binding: str
    witness: np.ndarray | None  # z~ (10,) of the best upper bound
    witness_phase: float
    levels: dict[str, tuple[float, float]]
    initial_conditions: InitialConditionSet
    attempts: tuple[BoxSearch, ...]
    minima: tuple[BoundaryMinimum, ...]
    timings: Mapping[str, float] = field(default_factory=dict)  # [s] nlp, certify, total


@dataclass
class _UpperBounds:
    """The best infeasible points known per nonlinear constraint, improved by refutations."""

    upper: dict[str, float]  # constraint -> least V found on its violation
    witness: dict[str, tuple[np.ndarray | None, float]]  # constraint -> (z~, phase) there
    best: float  # least of them (or a stand-in when IPOPT found no boundary point)

    @classmethod
    def of(cls, minima: tuple[BoundaryMinimum, ...], travel: dict[str, float]) -> _UpperBounds:
        upper = {m.constraint: m.level for m in minima}
        witness = {m.constraint: (m.state, m.phase) for m in minima}
        best = min(upper.values())
        if not math.isfinite(best):
            # no boundary point found by IPOPT: bound the search by the stoppers' level
            best = min(v for v in travel.values()) * 4 if math.isfinite(min(travel.values())) else 1.0
        return cls(upper, witness, best)

    def refuted(self, name: str, level: float, state: np.ndarray, phase: float) -> None:
        """A branch-and-bound refutation found an infeasible point of ``name`` at V = level."""
        self.best = level
        self.witness[name] = (state, phase)
        self.upper[name] = min(self.upper.get(name, math.inf), level)


class Procedure2:
    """The adapted Procedure 2 (module docstring). Build once; call :meth:`run` for each
    reference and P. Its solvers (IPOPT, interval graph) are built here, once.

    Parameters
    ----------
    feasible : FeasibleSet
    loop : RegulatorLoop
    starts : int
        IPOPT starts per constraint.
    max_boxes : int
        Branch-and-bound budget per attempted level.
    """

    def __init__(
        self, feasible: FeasibleSet, loop: RegulatorLoop, *, starts: int = 12, max_boxes: int = 400_000
    ) -> None:
        if starts < 1:
            raise ValueError(f"starts must be >= 1, got {starts!r}")
        self.feasible = feasible
        self.loop = loop
        self.starts = int(starts)
        self.certifier = LevelCertifier(feasible, loop, max_boxes=max_boxes)
        self.minimizer = BoundaryMinimizer(feasible, loop)

    def run(self, reference: Reference, P=None, *, seed: int = 0) -> Procedure2Result:
        """Certify the largest level set of V = z~' P z~ inside F for ``reference`` (module docstring).

        Parameters
        ----------
        reference : Reference
        P : (10, 10) array, optional
            A Lyapunov matrix of the loop (default: the Lyapunov equation's,
            :meth:`RegulatorLoop.lyapunov_matrix`).
        seed : int
            Seed of the multistart rays.

        Returns
        -------
        Procedure2Result
            ``status`` ``"certified"`` or ``"not_certified"`` (nothing within the branch-and-bound
            budget).
        """
        t0 = time.perf_counter()
        P = self.loop.lyapunov_matrix() if P is None else _check_p(P)
        if not self.loop.is_lyapunov(P):
            raise ValueError("P is not a Lyapunov matrix of the loop (A' P + P A must be <= 0, P > 0)")
        timings: dict[str, float] = {}
        travel = travel_levels(self.feasible, self.loop, reference, P)  # exact, closed form
        t1 = time.perf_counter()
        minima = tuple(
            self.minimizer.minimize(reference, P, name, starts=self.starts, seed=seed)
            for name in self.minimizer.constraints
        )
        timings["nlp"] = time.perf_counter() - t1
        bounds = _UpperBounds.of(minima, travel)
        t1 = time.perf_counter()
        certified_nl, attempts = self._ladder(reference, P, min(travel.values()), bounds)
        timings["certify"] = time.perf_counter() - t1
        result = self._result(reference, P, travel, bounds, certified_nl, attempts, minima)
        timings["total"] = time.perf_counter() - t0
        return dataclasses.replace(result, timings=timings)

    def _ladder(
        self, reference: Reference, P: np.ndarray, cap: float, bounds: _UpperBounds
    ) -> tuple[float, tuple[BoxSearch, ...]]:
        """Certify the nonlinear constraints on a ladder of levels below the best upper bound, but
        no higher than the stoppers allow (``cap``: the certified set is their minimum anyway).
        A refutation lowers the bound and the same rung is tried again below it."""
        attempts = []
        target = min(bounds.best, cap / LADDER[0]) if math.isfinite(cap) else bounds.best
        k = 0
        while k < len(LADDER) and len(attempts) < MAX_ATTEMPTS:
            lev = LADDER[k] * target
            res = self.certifier.certify(reference, P, lev)
            attempts.append(res)
            if res.status == "certified":
                return lev, tuple(attempts)
            if res.status == "refuted" and res.witness_level < bounds.best:
                zt = self.certifier.zeta_to_state(P, lev, res.witness[:3])
                bounds.refuted(res.binding, res.witness_level, zt, float(res.witness[3]))
                target = res.witness_level  # retry the same fraction of the better bound
                continue
            k += 1
        return 0.0, tuple(attempts)

    def _result(self, reference, P, travel, bounds, certified_nl, attempts, minima) -> Procedure2Result:
        """The certified level, the bounds per constraint, the binding one and its witness."""
        cap = min(travel.values())
        level = min(certified_nl, cap)
        levels: dict[str, tuple[float, float]] = {}
        for name in CONSTRAINT_NAMES:
            if name in travel:
                levels[name] = (travel[name], travel[name])
            elif name in bounds.upper or name in NONLINEAR:
                levels[name] = (certified_nl, bounds.upper.get(name, math.inf))
        all_upper = {k: v[1] for k, v in levels.items()}
        binding = min(all_upper, key=all_upper.get)
        level_upper = all_upper[binding]
        wz, wphi = bounds.witness.get(binding, (None, 0.0))
        if binding in travel and wz is None:
            wz, wphi = self._travel_witness(reference, P, binding, level_upper)
        success = bool(level > 0)
        if success and level >= cap and certified_nl >= cap:
            message = f"certified up to the stoppers' exact level ({binding})"
        elif success:
            message = (
                f"certified c = {level:.4g}; the best infeasible point found has V = {level_upper:.4g} "
                f"({binding})"
            )
        else:
            message = "no level could be certified within the branch-and-bound budget"
        return Procedure2Result(
            success,
            "certified" if success else "not_certified",
            message,
            reference,
            P,
            level,
            level_upper,
            level / level_upper if level_upper > 0 else 0.0,
            binding,
            wz,
            wphi,
            levels,
            initial_condition_set(P, level) if success else initial_condition_set(P, 0.0),
            attempts,
            minima,
        )

    def _travel_witness(self, reference: Reference, P, name: str, level: float):
        """The z~ on the stopper's half-space with the least V (closed form)."""
        row = 0 if name.startswith("gap") else 1
        m = self.loop.output[row]
        pinv_m = np.linalg.solve(P, m)
        sign = -1.0 if name.endswith("low") else 1.0
        F = self.loop.offset_coefficients(reference)
        phase = math.atan2(F[row, 1], F[row, 2]) if sign > 0 else math.atan2(-F[row, 1], -F[row, 2])
        return sign * math.sqrt(level) * pinv_m / math.sqrt(m @ pinv_m), phase % (2 * math.pi)
