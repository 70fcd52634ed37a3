"""Upper bounds on the largest certifiable level: min V on the boundary of each nonlinear
constraint of F by multistart IPOPT with exact Hessians (the tightness check of
:mod:`maglev_oc.region.procedure2`): any point found is infeasible or on the boundary.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.region.closed_loop import LOOP_VARIABLES, N_ERROR, Reference, RegulatorLoop
from maglev_oc.region.ellipsoid import checked_p, ellipsoid_image
from maglev_oc.region.feasibility import NONLINEAR, FeasibleSet
from maglev_oc.results import Result

__all__ = ["GAP_DOMAIN", "BoundaryMinimizer", "BoundaryMinimum"]

GAP_DOMAIN = (2e-3, 80e-3)
"""Gaps [m] the boundary search stays within (the model's formulas hold for any positive gap)."""


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
        off = ca.SX.sym("F", len(LOOP_VARIABLES), 3)
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
            raise InputError(f"constraint must be one of {list(self._solvers)}, got {constraint!r}")
        P = checked_p(P)
        solver, ng = self._solvers[constraint]
        F = self.loop.offset_coefficients(reference)
        par = np.concatenate([P.ravel(order="F"), F.ravel(order="F")])
        img = ellipsoid_image(self.loop, P)
        rng = np.random.default_rng(seed)
        j = NONLINEAR.index(constraint)
        dirs = np.vstack([np.eye(3), -np.eye(3), rng.standard_normal((max(starts - 6, 0), 3))])[:starts]
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        periodic = not reference.is_setpoint
        bounds = _bounds(ng, periodic)
        best_level, best_z, best_phi = math.inf, None, 0.0
        levels = []
        for d in dirs:
            phi0 = rng.uniform(0, 2 * math.pi) if periodic else 0.0
            start = self._ray_start(img, F, d, phi0, j)
            if start is None:
                continue
            x0, h_scale = start
            sol = solver(x0=x0, p=par, **bounds)
            if not solver.stats()["success"]:
                continue
            x = np.asarray(sol["x"]).ravel()
            gval = np.asarray(sol["g"]).ravel()
            if abs(gval[0]) > 1e-7 * h_scale or (ng == 3 and gval[2] < -1e-9):
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

    def _ray_start(self, img, F: np.ndarray, d: np.ndarray, phi0: float, j: int):
        """(start (11,), constraint scale) on the boundary of constraint j along the ray zeta = t d
        (the first sign change of h_j inside the gap domain), or None if the ray never crosses it. The
        scale is |h_j| at the ray's first point, next to the set-point (at least 1)."""
        ts = np.geomspace(1e-3, 1e3, 241)
        zs = np.outer(img.Pinv_Mt @ np.linalg.solve(img.S, img.chol @ d), ts)
        hv_all = np.asarray(self._h.map(ts.size)(zs, phi0, F.ravel(order="F")))
        hv = hv_all[j]
        inside = (hv_all[2] > GAP_DOMAIN[0]) & (hv_all[2] < GAP_DOMAIN[1])
        neg = np.nonzero((hv < 0) & inside)[0]
        if neg.size == 0:
            return None
        # the constraint's own size: its value at the set-point end of the ray (the current headroom
        # there is I^2 - |u|^2 <= 81 A^2), not the largest met along it: far out on a ray |h| reaches
        # 1e9 A^2, and 1e-7 of that would count a point where the limit holds as on its boundary
        return np.concatenate([zs[:, neg[0]], [phi0]]), max(1.0, abs(hv[0]))


def _bounds(ng: int, periodic: bool) -> dict[str, np.ndarray]:
    """IPOPT's bounds: the phase pinned at 0 for a set-point; g = (h_j = 0, gap in GAP_DOMAIN,
    and R >= 0 when there is a third row)."""
    lbx = -np.inf * np.ones(N_ERROR + 1)
    ubx = np.inf * np.ones(N_ERROR + 1)
    if not periodic:
        lbx[-1] = ubx[-1] = 0.0
    lbg = np.zeros(ng)
    ubg = np.zeros(ng)
    lbg[1], ubg[1] = GAP_DOMAIN
    if ng == 3:
        ubg[2] = np.inf
    return {"lbx": lbx, "ubx": ubx, "lbg": lbg, "ubg": ubg}
