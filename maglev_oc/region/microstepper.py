"""The certified operating region of the 3-DOF microstepper's FL loop (Procedure 2, adapted).

The same argument as :mod:`maglev_oc.region.procedure2` for the 2-DOF stage, on three axes. After
the feedback transformation of :mod:`maglev_oc.model.allocation` each axis a in (x, y, gap) is
e_a'' = v_a with v_a = K_a z_a, z_a = (e_a, e_a', xi_a) and the internal model xi_a' = phi xi_a +
N e_a, so in error coordinates z~ = (z_x, z_y, z_gap) (15 states, the steady state of a set-point
is zero) the loop is z~' = A_cl z~, A_cl = blkdiag(A + B K_h, A + B K_h, A + B K_v), *as long as*
the transformation is defined and the currents fit:

* R(gap, v) >= 0 (the minimum-norm allocation's discriminant),
* each pair's current magnitude sqrt(i_q^2 + i_d^2) <= the amplifier limit (9 A),
* the gap between the stoppers and x, y within the travel; without the stoppers the gap still
  stays at :data:`PHYSICAL_GAP` or more, where the field model is defined (a closed gap is not).

V = z~' P z~ with A_cl' P + P A_cl = -Q (Q the acceleration-scaled identity, as for the 2-DOF
loop) makes every {V <= c} invariant for the linear loop; the largest c for which {V <= c} lies
inside the constraints is certified. The constraints depend on z~ only through l = (e_gap, v_x,
v_y, v_gap) = M z~, which on {V <= c} ranges over the 4-D ellipsoid {l' S^-1 l <= c},
S = M P^-1 M': the travel and stopper constraints (linear) give their level in closed form, the
nonlinear ones are checked by branch and bound with interval arithmetic
(:class:`~maglev_oc.region.interval.IntervalFunction`, and the tighter
:class:`~maglev_oc.region.interval.CenteredForm` where that one spends its budget) over
l = sqrt(c) chol(S) zeta, |zeta| <= 1. A box is accepted when every constraint's enclosure is
>= 0; a sampled point of an undecided box that violates a constraint refutes the level.
Bisection on c between a certified and a refuted level brackets c*.

Assumptions (as for the 2-DOF certificate): the plant is the controller's model (the platform of
:func:`~maglev_oc.model.platform.microstepper`), the loop is continuous with exact velocities and
ideal amplifiers while within the limit, the reference a constant set-point. Sampling, observers,
quantisation, friction and cogging are not covered: the twin's simulations check those.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
from scipy.linalg import block_diag, cholesky, solve_continuous_lyapunov

from maglev_oc.control.gains import OMEGA0, PAPER_K_H, PAPER_K_V, augmented_axis, checked_gains
from maglev_oc.errors import InputError
from maglev_oc.model.allocation import MicrostepperTransformation
from maglev_oc.model.hardware import MICROSTEPPER_STOPPER_GAP, PEAK_CURRENT_LIMIT, STOPPER_POSITION
from maglev_oc.model.platform import Platform, microstepper
from maglev_oc.numerics import ColumnMap
from maglev_oc.region.branch_and_bound import bisect_widest, cube_grid, meets_unit_ball
from maglev_oc.region.interval import CenteredForm, IntervalFunction
from maglev_oc.results import Result

__all__ = ["MICROSTEPPER_CONSTRAINTS", "PHYSICAL_GAP", "MicrostepperRegion", "MicrostepperRegionResult"]

MICROSTEPPER_CONSTRAINTS = ("margin", "headroom_A", "headroom_B")
"""The nonlinear constraints, in order: R >= 0 and each pair's current headroom [A^2]."""

AXES = ("x", "y", "gap")

CENTRED_AFTER = 0.5
"""The share of a level's box budget the natural interval extension spends alone before the
centred form joins it on the boxes it leaves undecided: easy levels stay as quick as before, hard
ones (near c*, or near the stator where the field's exponentials make the natural extension loose)
get the tighter enclosure (measured, default budget, the report's three set-points: 49 s instead
of 27 s, the 21 mm bracket closed from 3 % to 0.8 %; 15 mm, 300 000 boxes: 5.61 certified instead
of 2.76; 8 mm without stoppers: 1.40 instead of 0.21)."""

PHYSICAL_GAP = 1e-3
"""The least gap [m] the certificate and its refutations consider with the stoppers off: the field
model (exp(-a (h_m + y)) terms, Carter's coefficient) is not a model of a closed gap."""


@dataclass(frozen=True)
class MicrostepperRegionResult(Result):
    """The certified level at one set-point.

    ``level`` is certified (every box proved feasible); ``refuted_level`` is the V of ``witness``,
    a state at which ``binding`` fails (a nonlinear constraint or an axis's travel/stopper); c*
    lies between them. ``half_widths`` [m]: the largest error of each axis inside {V <= level}.
    """

    success: bool
    status: str
    message: str
    setpoint: tuple[float, float, float]
    level: float
    refuted_level: float
    binding: str
    linear_levels: dict[str, float]
    half_widths: dict[str, float]
    boxes: int
    witness: np.ndarray | None  # (15,) z~ at which ``binding`` fails, V there = refuted_level
    timings: dict[str, float] = field(default_factory=dict)


class MicrostepperRegion:
    """Procedure 2 for the 3-DOF loop (module docstring), built once and reused for any set-point.

    Parameters
    ----------
    platform : Platform
        The microstepper (default :func:`~maglev_oc.model.platform.microstepper`).
    K_h, K_v : array (5,)
        Gains of the x and y axes and of the gap (default: the papers' printed gains).
    omega0 : float
        Internal-model frequency [rad/s].
    current_limit : float or None
        Pair current magnitude limit [A] (None: only R >= 0).
    stoppers : bool
        Whether the gap stoppers and the x, y travel limits are constraints.
    """

    def __init__(
        self,
        platform: Platform | None = None,
        K_h=PAPER_K_H,
        K_v=PAPER_K_V,
        omega0: float = OMEGA0,
        *,
        current_limit: float | None = PEAK_CURRENT_LIMIT,
        stoppers: bool = True,
    ) -> None:
        self.platform = platform or microstepper()
        k_h, k_v = checked_gains(K_h, "K_h"), checked_gains(K_v, "K_v")
        if current_limit is not None and not current_limit > 0:
            raise InputError(f"current_limit must be positive [A], got {current_limit!r}")
        self.current_limit = current_limit
        self.stoppers = stoppers
        a, b = augmented_axis(omega0)
        gains = (k_h, k_h, k_v)
        self.A = block_diag(*(a + b @ k[None, :] for k in gains))
        if np.max(np.linalg.eigvals(self.A).real) >= 0:
            raise InputError("the gains do not stabilise the augmented axes (A_cl is not Hurwitz)")
        scale = 1.0 / np.abs(np.concatenate(gains))
        P = solve_continuous_lyapunov(self.A.T, -np.diag(1.0 / scale**2))
        self.P = 0.5 * (P + P.T)
        # l = (e_gap, v_x, v_y, v_gap) = M z~; errors of each axis for the linear constraints
        M = np.zeros((4, 15))
        M[0, 10] = 1.0
        for j, k in enumerate(gains):
            M[1 + j, 5 * j : 5 * j + 5] = k
        self.M = M
        self.errors = np.zeros((3, 15))
        for j in range(3):
            self.errors[j, 5 * j] = 1.0
        p_inv = np.linalg.inv(self.P)
        self.S = M @ p_inv @ M.T
        self.chol = cholesky(self.S, lower=True)
        self._spread = np.sqrt(np.einsum("ij,jk,ik->i", self.errors, p_inv, self.errors))
        self._fn, self._ifn = self._constraint_functions()
        self._columns = ColumnMap(self._fn)  # the constraints at many points, one map built once

    def _constraint_functions(self) -> tuple[ca.Function, IntervalFunction]:
        ell, gap0 = ca.SX.sym("l", 4), ca.SX.sym("gap0")
        transform = MicrostepperTransformation(self.platform).function
        u, R = transform(gap0 + ell[0], ell[1:4])
        limit2 = (self.current_limit or 1e3) ** 2
        h = ca.vertcat(R, limit2 - u[0] ** 2 - u[1] ** 2, limit2 - u[2] ** 2 - u[3] ** 2)
        if self.current_limit is None:
            h = h[0]
        self._h_of_l = ca.Function("h_l", [ell, gap0], [h]).expand()
        zeta, lmat = ca.SX.sym("zeta", 4), ca.SX.sym("L", 4, 4)
        fn = ca.Function("h_zeta", [zeta, ca.vec(lmat), gap0], [self._h_of_l(ca.mtimes(lmat, zeta), gap0)])
        fn = fn.expand()
        self._centred = CenteredForm(fn, boxed=1)  # tighter where the natural extension is undecided
        # the least V at which constraint j fails: min l' S^-1 l s.t. h_j(l) <= 0 (4-D, IPOPT)
        s_inv = ca.DM(np.linalg.inv(self.S))
        opts = {"ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False, "ipopt.max_iter": 300}
        self._refuters = [
            ca.nlpsol(
                f"refute_{j}", "ipopt", {"x": ell, "p": gap0, "f": ca.bilin(s_inv, ell, ell), "g": h[j]}, opts
            )
            for j in range(h.numel())
        ]
        return fn, IntervalFunction(fn)

    def refute(self, setpoint, *, starts: int = 12, seed: int = 0) -> tuple[float, str, np.ndarray | None]:
        """The least V found at which a nonlinear constraint fails, by multistart IPOPT:
        (level, constraint, l) — an upper bound on c* (inf when no violation is found)."""
        rng = np.random.default_rng(seed)
        gap0 = float(setpoint[2])
        best = (math.inf, "", None)
        s_inv = np.linalg.inv(self.S)
        for j, solver in enumerate(self._refuters):
            for _ in range(starts):
                x0 = self.chol @ rng.normal(size=4) * 3.0
                # the gap stays physical: the field model is not defined at a closed gap
                bounds = {
                    "lbx": [PHYSICAL_GAP - gap0, -ca.inf, -ca.inf, -ca.inf],
                    "ubx": [0.1, ca.inf, ca.inf, ca.inf],
                }
                sol = solver(x0=x0, p=gap0, ubg=0.0, lbg=-ca.inf, **bounds)
                ell = np.asarray(sol["x"]).ravel()
                h = np.asarray(self._h_of_l(ell, gap0)).ravel()
                if h[j] <= 1e-9 * max(1.0, abs(h[j])):  # on or beyond the boundary
                    value = float(ell @ s_inv @ ell)
                    if value < best[0]:
                        best = (value, MICROSTEPPER_CONSTRAINTS[j], ell)
        return best

    # ------------------------------------------------------------------------------------------
    def _limits(self) -> dict[str, tuple[float, float]]:
        """Each linearly limited axis's (low, high) [m]: the travel and the stoppers, or, with the
        stoppers off, the gap's physical floor alone."""
        if not self.stoppers:
            return {"gap": (PHYSICAL_GAP, math.inf)}
        return dict(zip(AXES, (STOPPER_POSITION, STOPPER_POSITION, MICROSTEPPER_STOPPER_GAP), strict=True))

    def linear_levels(self, setpoint) -> dict[str, float]:
        """Largest c keeping each axis within its travel (or the gap within the stoppers, or above
        :data:`PHYSICAL_GAP` without them)."""
        out = {}
        for axis, (lo, hi) in self._limits().items():
            j = AXES.index(axis)
            room = min(setpoint[j] - lo, hi - setpoint[j])
            if room <= 0:
                where = f"[{lo * 1e3:g}, {hi * 1e3:g}] mm"
                raise InputError(f"set-point {axis} = {setpoint[j] * 1e3:.1f} mm is outside {where}")
            out[axis] = (room / self._spread[j]) ** 2
        return out

    def certify(
        self, setpoint, level: float, *, max_boxes: int = 1_000_000
    ) -> tuple[str, int, str, np.ndarray | None]:
        """Branch and bound of the nonlinear constraints on {V <= level}: (status, boxes, binding,
        the state z~ at which ``binding`` fails when refuted). Boxes are decided by the natural
        interval extension, and after :data:`CENTRED_AFTER` of the budget also by the centred form."""
        par_l = (math.sqrt(level) * self.chol).ravel(order="F")[:, None]
        gap0 = np.array([[float(setpoint[2])]])
        lo, hi = cube_grid(4, 4)
        boxes = 0
        while lo.shape[1]:
            keep, near = meets_unit_ball(lo, hi)
            lo, hi, near = lo[:, keep], hi[:, keep], near[:, keep]
            if not lo.shape[1]:
                break
            boxes += lo.shape[1]
            (hlo,), _ = self._ifn([lo, par_l, gap0], [hi, par_l, gap0])  # parameters broadcast over boxes
            ok = np.all(hlo >= 0, axis=0)  # every constraint's lower bound, per box
            lo, hi, near, hlo = lo[:, ~ok], hi[:, ~ok], near[:, ~ok], hlo[:, ~ok]
            if boxes > CENTRED_AFTER * max_boxes and lo.shape[1]:
                mv_lo, _ = self._centred.mean_value([lo, par_l, gap0], [hi, par_l, gap0])
                ok = np.all(np.fmax(hlo, mv_lo) >= 0, axis=0)
                lo, hi, near = lo[:, ~ok], hi[:, ~ok], near[:, ~ok]
            if not lo.shape[1]:
                break
            vals = self._columns(near, par_l, gap0)[0]
            bad = np.any(vals < 0, axis=0)
            if np.any(bad):
                k = int(np.argmax(bad))
                state = self.state_of(math.sqrt(level) * self.chol @ near[:, k])
                return "refuted", boxes, MICROSTEPPER_CONSTRAINTS[int(np.argmin(vals[:, k]))], state
            if boxes > max_boxes:
                return "undecided", boxes, "", None
            lo, hi = bisect_widest(lo, hi)
        return "certified", boxes, "", None

    def state_of(self, ell) -> np.ndarray:
        """The z~ of least V with M z~ = ``ell`` (4,); V there is ell' S^-1 ell."""
        ell = np.asarray(ell, dtype=float)
        return np.linalg.solve(self.P, self.M.T @ np.linalg.solve(self.S, ell))

    def _linear_witness(self, setpoint, axis: str, level: float) -> np.ndarray:
        """The point of {V <= level} farthest along ``axis``'s error towards its nearer limit."""
        j = AXES.index(axis)
        lo, hi = self._limits()[axis]
        sign = 1.0 if hi - setpoint[j] <= setpoint[j] - lo else -1.0
        m = self.errors[j]
        p_inv_m = np.linalg.solve(self.P, m)
        return sign * math.sqrt(level) * p_inv_m / math.sqrt(m @ p_inv_m)

    def largest_level(
        self, setpoint, *, rel_tol: float = 0.01, max_boxes: int = 1_000_000
    ) -> MicrostepperRegionResult:
        """c*: the least level at which a constraint fails (the linear ones in closed form, the
        nonlinear ones by :meth:`refute`), certified by branch and bound, or bisected down to a
        certified level when the search cannot prove it (``rel_tol`` apart, box budget allowing).

        Parameters
        ----------
        setpoint : (3,) [m]
            (x, y, gap).
        """
        t0 = time.perf_counter()
        setpoint = tuple(float(s) for s in setpoint)
        if len(setpoint) != 3:
            raise InputError(f"set-point needs (x, y, gap) [m], got {setpoint!r}")
        linear = self.linear_levels(setpoint)
        status, total, binding, _ = self.certify(setpoint, 1e-12)
        if status != "certified":
            return MicrostepperRegionResult(
                False, "infeasible_setpoint", f"the set-point itself violates {binding}",
                setpoint, 0.0, 0.0, binding, linear, {}, total, None, {"total": time.perf_counter() - t0},
            )  # fmt: skip
        found, why, ell = self.refute(setpoint)
        axis = min(linear, key=linear.get)  # the gap's floor at least: always a finite bound
        if linear[axis] <= found:
            hi, binding = linear[axis], axis
            witness = self._linear_witness(setpoint, axis, hi)
        else:
            hi, binding, witness = found, why, self.state_of(ell)
        # bisection between lo (certified) and top (not proved: refuted, or the box budget spent)
        lo, top, note = 0.0, hi, ""
        status, boxes, why, _ = self.certify(setpoint, hi * (1 - 1e-9), max_boxes=max_boxes)
        total += boxes
        if status == "certified":
            lo = hi * (1 - 1e-9)
        for _ in range(60):
            if lo > 0 and top - lo <= rel_tol * top:
                break
            mid = 0.5 * (lo + top) if lo > 0 else 0.5 * top
            status, boxes, why, state = self.certify(setpoint, mid, max_boxes=max_boxes)
            total += boxes
            if status == "certified":
                lo = mid
            else:
                top = mid
                if status == "refuted":  # a sampled point of {V <= mid}: its own V bounds c*
                    hi, binding, witness = float(state @ self.P @ state), why, state
        if lo > 0 and top < hi * (1 - 1e-9):
            note = f" (not proved above {top:.4g}: box budget spent)"
        half = {a: float(math.sqrt(lo) * self._spread[j]) for j, a in enumerate(AXES)}
        message = f"certified V <= {lo:.4g}; {binding} fails at V = {hi:.4g}{note}"
        return MicrostepperRegionResult(
            bool(lo > 0), "certified" if lo > 0 else "undecided", message, setpoint, lo, hi, binding, linear,
            half, total, witness, {"total": time.perf_counter() - t0},
        )  # fmt: skip
