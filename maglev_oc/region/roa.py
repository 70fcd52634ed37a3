"""Regions of attraction of the linear regulators (papers' linear regulator, LQR) on the nonlinear plant.

A :class:`~maglev_oc.control.linear_regulator.ScheduledLinearRegulator` at a set-point r applies
u = (0, u2_ff(r)) + (K_h z_h, K_v z_v) with gains designed on the Jacobian linearization. On the
nonlinear plant (SPEC 1) the closed loop, in z^ = z - z_eq (z_eq: the internal-model state that
supplies whatever part of the equilibrium current the feedforward does not, zero with exact
feedforward), is

    z^' = A z^ + B_v g_v(l) + B_h g_h(l),     l = (e1, du1, du2) = (z^[0], K_h z^_h, K_v z^_v)

with A the exact linearization at (r, u_eq) closed by the gains, and the remainders

    g_v = x2'(r + e1, du1, u2_eq + du2) - a21 e1 - b22 du2,    g_h = -(L1(r + e1) - L1(r)) du1,

which vanish with their first derivatives at l = 0.

**Certificate (a Lyapunov level set with the nonlinearity bounded on it).** Take V = z^' P z^
with A' P + P A = -Q. On Omega_c = {V <= c}, l ranges over the ellipsoid {l' S^-1 l <= c},
S = M P^-1 M'. Interval arithmetic on the CasADi Jacobian of g over boxes covering that ellipsoid
encloses dg/dl there in a box [lo, hi] (2 x 3). By the mean-value theorem on the segment from 0
(inside the convex ellipsoid), g_ax(l) = Delta_ax . l with Delta in that box, so on Omega_c the loop
is z^' = (A + B_v Delta_v' M + B_h Delta_h' M) z^ for some Delta in the box. V' is affine in Delta,
hence V' < 0 on Omega_c \\ {0} if

    (A + B Delta M)' P + P (A + B Delta M) < 0     at every vertex of the box.

The largest c passing (bisection) is the certified level; Omega_c is then in the region of
attraction of the continuous-time loop with exact velocities and no current limit. The stoppers
(gap travel) cap c exactly; the amplifiers' limit |u| <= I gives a further cap
(|u| <= |u_eq| + sqrt(c lambda_max(S_du)) on Omega_c), reported separately because the ideal
twin does not limit the current.

**Sampled estimate.** The operating-region study (:mod:`maglev_oc.region.study`) runs the sampled
twin from a grid of starts and targets; that is labelled as an estimate, not a certificate.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
from scipy.linalg import block_diag, solve_continuous_lyapunov

from maglev_oc.control.gains import augmented_axis, axis_poles
from maglev_oc.control.linear_regulator import ScheduledLinearRegulator, axis_linearizations
from maglev_oc.errors import InputError
from maglev_oc.model.equilibrium import equilibrium
from maglev_oc.model.stage import StageModel
from maglev_oc.region.branch_and_bound import cube_grid, meets_unit_ball
from maglev_oc.region.closed_loop import DE1, DE2, E1, E2, N_ERROR, Reference
from maglev_oc.region.ellipsoid import InitialConditionSet, initial_condition_set
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.interval import IntervalFunction
from maglev_oc.results import Result

__all__ = ["LinearizedLoop", "RoaCertifier", "RoaResult", "certify_roa", "frozen_poles"]


@dataclass(frozen=True, eq=False)
class LinearizedLoop:
    """The loop of a scheduled linear regulator at a set-point, in z^ = z - z_eq (module docstring).

    Attributes
    ----------
    A : (10, 10)      exact linearization closed by the regulator's gains at r_v
    output : (3, 10)  rows l = (e1, du1, du2)
    z_eq : (10,)      internal-model offset of the equilibrium (nonzero without feedforward)
    u_eq : (2,)       equilibrium current [A]
    remainder : CasADi Function l (3) -> g (2) [m/s^2]
    remainder_jacobian : CasADi Function l (3) -> dg/dl (2, 3)
    """

    model: StageModel
    controller: ScheduledLinearRegulator
    reference: Reference
    A: np.ndarray = field(init=False, repr=False)
    output: np.ndarray = field(init=False, repr=False)
    z_eq: np.ndarray = field(init=False, repr=False)
    u_eq: np.ndarray = field(init=False, repr=False)
    K_h: np.ndarray = field(init=False, repr=False)
    K_v: np.ndarray = field(init=False, repr=False)
    remainder: ca.Function = field(init=False, repr=False)
    remainder_jacobian: ca.Function = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.controller, ScheduledLinearRegulator):
            raise TypeError(
                f"controller must be a ScheduledLinearRegulator, got {type(self.controller).__name__}"
            )
        if not self.reference.is_setpoint:
            raise InputError("the linear regulators' regions are computed for set-points")
        r = self.reference.gap
        sched = self.controller.schedule
        if not (sched.gap[0] <= r <= sched.gap[-1]):
            raise InputError(f"set-point gap {r!r} m outside the regulator's schedule")
        kh, kv = self.controller.gains_at(r)
        u2_ff = float(np.interp(r, sched.gap, sched.u2_eq))
        op = equilibrium(self.model, r, self.reference.position, current_limit=math.inf)
        u2 = float(op.u[1])
        jac_a, jac_b = (np.asarray(m) for m in self.model.jacobian(op.x, op.u))
        a21, b22, b41 = jac_a[1, 0], jac_b[1, 1], jac_b[3, 0]
        om = self.controller.omega0
        av, bv = augmented_axis(om, a21, b22)
        ah, bh = augmented_axis(om, 0.0, b41)
        A = block_diag(av + bv @ kv[None, :], ah + bh @ kh[None, :])
        z_eq = np.zeros(N_ERROR)
        z_eq[2] = (u2 - u2_ff) / kv[2]
        out = np.zeros((3, N_ERROR))
        out[0, E1] = 1.0
        out[1, 5:] = kh
        out[2, :5] = kv
        ell = ca.SX.sym("l", 3)
        x = ca.vertcat(r + ell[0], 0, self.reference.position, 0)
        u = ca.vertcat(ell[1], u2 + ell[2])
        acc = self.model.f(x, u)
        g = ca.vertcat(acc[1] - a21 * ell[0] - b22 * ell[2], acc[3] - b41 * ell[1])
        rem = ca.Function("remainder", [ell], [g])
        jac = ca.Function("remainder_jac", [ell], [ca.jacobian(g, ell)])
        for name, value in (
            ("A", A),
            ("output", out),
            ("z_eq", z_eq),
            ("u_eq", np.array([0.0, u2])),
            ("K_h", kh),
            ("K_v", kv),
        ):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "remainder", rem)
        object.__setattr__(self, "remainder_jacobian", jac)

    def state_scale(self) -> np.ndarray:
        """1 / |gain| per state: the size of each state that commands 1 A."""
        return 1.0 / np.abs(np.concatenate([self.K_v, self.K_h]))

    def lyapunov_matrix(self) -> np.ndarray:
        """P of A'P + PA = -diag(1/state_scale^2) (identity in current-scaled coordinates)."""
        Q = np.diag(1.0 / self.state_scale() ** 2)
        P = solve_continuous_lyapunov(self.A.T, -Q)
        return 0.5 * (P + P.T)

    def initial_error(self, x0) -> np.ndarray:
        """z^ (10,) of a start at rest at mechanical state x0 (4,) with empty internal models."""
        x0 = np.asarray(x0, dtype=float).ravel()
        z = np.zeros(N_ERROR)
        z[E1] = x0[0] - self.reference.gap
        z[DE1] = x0[1]
        z[E2] = x0[2] - self.reference.position
        z[DE2] = x0[3]
        return z - self.z_eq


@dataclass(frozen=True)
class RoaResult(Result):
    """Certified region of attraction {z^' P z^ <= level} of a linear regulator at a set-point.

    ``level`` = min(level_stability, level_travel); ``level_current`` is the largest level on
    which the commanded |u| stays within the current limit (inf if no limit was given).
    ``jacobian_box``: the enclosure of the remainder's Jacobian on the certified level set.
    ``status`` ``"certified"``, or ``"not_certified"`` when no level set could be certified.
    """

    success: bool
    status: str
    message: str
    controller: str
    reference: Reference
    P: np.ndarray
    z_eq: np.ndarray
    level: float
    level_stability: float
    level_travel: float
    level_current: float
    jacobian_box: tuple[np.ndarray, np.ndarray]  # (lo, hi) (2, 3) enclosure of dg/dl at level_stability
    initial_conditions: InitialConditionSet
    bisections: int
    timings: Mapping[str, float] = field(default_factory=dict)  # [s] stability, total

    def value(self, zhat) -> float:
        """V(z^) / level (<= 1 inside the certified set; inf when nothing was certified).

        Parameters
        ----------
        zhat : (10,) array
            z^ = z - z_eq (e.g. :meth:`LinearizedLoop.initial_error`).

        Returns
        -------
        float
        """
        z = np.asarray(zhat, dtype=float)
        return float(z @ self.P @ z / self.level) if self.level > 0 else math.inf


class RoaCertifier:
    """Certifies the level sets of one linearized loop (Jacobian graph built once)."""

    def __init__(self, loop: LinearizedLoop, *, cover: int = 14) -> None:
        if cover < 2:
            raise InputError(f"cover must be >= 2, got {cover!r}")
        self.loop = loop
        self.cover = int(cover)
        zeta = ca.SX.sym("zeta", 3)
        lmat = ca.SX.sym("L", 3, 3)
        jac = loop.remainder_jacobian(ca.mtimes(lmat, zeta))
        self._ijac = IntervalFunction(
            ca.Function("jac_zeta", [zeta, ca.vec(lmat)], [ca.vec(ca.densify(jac))])
        )
        lo, hi = cube_grid(self.cover, 3)
        keep, _ = meets_unit_ball(lo, hi)
        self._lo, self._hi = lo[:, keep], hi[:, keep]

    def jacobian_box(self, P, level: float) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi), each (2, 3): an enclosure of dg/dl on the image of {V <= level}."""
        M = self.loop.output
        S = M @ np.linalg.solve(P, M.T)
        L = math.sqrt(level) * np.linalg.cholesky(0.5 * (S + S.T))
        par = L.ravel(order="F")[:, None]
        lo, hi = self._ijac([self._lo, par], [self._hi, par])
        return lo[0].min(axis=1).reshape(2, 3, order="F"), hi[0].max(axis=1).reshape(2, 3, order="F")

    def decrease_margin(self, P, box: tuple[np.ndarray, np.ndarray]) -> float:
        """Largest eigenvalue (diagonally scaled) of (A + B Delta M)' P + P (A + B Delta M) over
        the vertices of the box of Delta; < 0 certifies V' < 0 on the level set.

        g_ax(l) = Delta_ax . l with Delta_ax the mean of dg_ax/dl on the segment [0, l], so Delta
        lies in the enclosure; V' is affine in Delta, so the vertices are the worst cases."""
        A, M = self.loop.A, self.loop.output
        lo, hi = box
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            return math.inf
        if np.any(np.diag(P) <= 0) or not np.all(np.isfinite(P)):
            return math.inf
        d = 1.0 / np.sqrt(np.diag(P))
        D = np.diag(d)
        base = D @ (A.T @ P + P @ A) @ D
        cols = [DE1, DE2]
        terms, choices = [], []
        for ax in range(2):
            pb = D @ P[:, cols[ax]]
            for i in range(3):
                dm = D @ M[i]
                t = np.outer(pb, dm)
                terms.append(t + t.T)
                choices.append((lo[ax, i], hi[ax, i]) if hi[ax, i] > lo[ax, i] else (lo[ax, i],))
        worst = -math.inf
        for combo in itertools.product(*choices):
            m = base + sum(c * t for c, t in zip(combo, terms, strict=True))
            worst = max(worst, float(np.linalg.eigvalsh(m).max()))
        return worst


def certify_roa(
    model: StageModel,
    controller: ScheduledLinearRegulator,
    reference: Reference,
    *,
    P=None,
    feasible: FeasibleSet | None = None,
    iterations: int = 40,
) -> RoaResult:
    """Largest certified level set of V = z^' P z^ in the region of attraction (module docstring).

    Parameters
    ----------
    model : StageModel
        The plant (equal to the regulator's design model here).
    controller : ScheduledLinearRegulator
    reference : Reference
        A set-point.
    P : (10, 10) array, optional
        Default: the Lyapunov equation's (:meth:`LinearizedLoop.lyapunov_matrix`).
    feasible : FeasibleSet, optional
        Supplies the stoppers [m] and the current limit [A] (default: FeasibleSet(model)).
    iterations : int
        Most levels tried by the bisection.

    Returns
    -------
    RoaResult
    """
    t0 = time.perf_counter()
    feasible = FeasibleSet(model) if feasible is None else feasible
    loop = LinearizedLoop(model, controller, reference)
    P = loop.lyapunov_matrix() if P is None else 0.5 * (np.asarray(P, float) + np.asarray(P, float).T)
    cert = RoaCertifier(loop)
    Pinv = np.linalg.inv(P)
    travel = _travel_level(feasible, reference, Pinv)
    current = _current_level(feasible, loop, Pinv)
    t1 = time.perf_counter()
    stable, best_box, n_iter = _stability_level(cert, P, travel, iterations)
    t_stab = time.perf_counter() - t1
    level = min(stable, travel)
    success = bool(level > 0)
    msg = (
        f"certified level {level:.4g} (stability {stable:.4g}, stoppers {travel:.4g}, current {current:.4g})"
        if success
        else "no level set could be certified"
    )
    return RoaResult(
        success,
        "certified" if success else "not_certified",
        msg,
        controller.name,
        reference,
        P,
        loop.z_eq.copy(),
        level,
        stable,
        travel,
        current,
        best_box,
        initial_condition_set(P, level),
        n_iter,
        {"stability": t_stab, "total": time.perf_counter() - t0},
    )


def _travel_level(feasible: FeasibleSet, reference: Reference, Pinv: np.ndarray) -> float:
    """The exact level at which {V <= c} touches a stopper (inf without stoppers)."""
    travel = math.inf
    for row, rng, centre in (
        (E1, feasible.gap_range, reference.gap),
        (E2, feasible.position_range, reference.position),
    ):
        if rng is None:
            continue
        room = min(centre - rng[0], rng[1] - centre)
        travel = min(travel, max(room, 0.0) ** 2 / Pinv[row, row])
    return travel


def _current_level(feasible: FeasibleSet, loop: LinearizedLoop, Pinv: np.ndarray) -> float:
    """The level up to which |u| <= |u_eq| + sqrt(c lambda_max(S_du)) <= I (inf without a limit)."""
    if feasible.current_limit is None:
        return math.inf
    Mu = loop.output[1:3]
    lam = float(np.linalg.eigvalsh(Mu @ Pinv @ Mu.T).max())
    room = feasible.current_limit - float(np.linalg.norm(loop.u_eq))
    return max(room, 0.0) ** 2 / lam


def _stability_level(cert: RoaCertifier, P: np.ndarray, travel: float, iterations: int):
    """(largest certified level, its Jacobian box, levels tried): bisection on a log scale between
    a certified and a failed level, starting at the stoppers' level (or 1) and growing 4x until a
    level fails or exceeds 4x the stoppers' level."""
    lo_c, hi_c = 0.0, None
    c = travel if math.isfinite(travel) else 1.0
    best_box = (np.zeros((2, 3)), np.zeros((2, 3)))
    n_iter = 0
    for n_iter in range(1, iterations + 1):  # noqa: B007
        box = cert.jacobian_box(P, c)
        ok = cert.decrease_margin(P, box) < 0
        if ok:
            lo_c, best_box = c, box
            if hi_c is None:
                if c >= 4 * travel:
                    break
                c *= 4
                continue
        else:
            hi_c = c
        if hi_c is not None:
            if lo_c > 0 and hi_c / lo_c < 1.01:
                break
            c = math.sqrt(lo_c * hi_c) if lo_c > 0 else hi_c / 4
    return lo_c, best_box, n_iter


def frozen_poles(
    model: StageModel, controller: ScheduledLinearRegulator, reference: Reference, gaps
) -> np.ndarray:
    """Vertical closed-loop poles (n, 5) when the gains designed for ``reference`` meet the plant's
    linearization at the equilibrium of each gap in ``gaps`` [m] (a frozen-time picture of what the
    linear regulator faces along a large step).

    Parameters
    ----------
    model : StageModel
    controller : ScheduledLinearRegulator
    reference : Reference
        The set-point whose gains are frozen.
    gaps : array-like (n,)
        Gaps [m] of the equilibria.

    Returns
    -------
    (n, 5) complex array
        The poles [1/s].
    """
    _, kv = controller.gains_at(reference.gap)
    lin = axis_linearizations(model, np.asarray(gaps, dtype=float))
    return np.array(
        [axis_poles(kv, controller.omega0, a, b) for a, b in zip(lin.stiffness_v, lin.gain_v, strict=True)]
    )
