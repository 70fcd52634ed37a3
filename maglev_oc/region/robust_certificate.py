"""A *certified* robust operating region: a level set of V = z~' P z~ that is forward invariant
inside the feasible set F for every plant whose constants lie in an uncertainty set Theta.

:mod:`~maglev_oc.region.procedure2` certifies {V <= c} for the plant that equals the controller's
model; :mod:`~maglev_oc.region.robust` only samples other plants. Here the FL regulator keeps the
nominal constants C_nom while the plant's C = (C1, C2, C3, C4) is anywhere in Theta (a box, or a
confidence ellipsoid {(C - C0)' S^+ (C - C0) <= 1}: :class:`~maglev_oc.region.sweep.PlantSet`).

**The loop with a mismatched plant.** The controller inverts its model, so the plant's
accelerations are the commanded v plus the mismatch

    Delta(x1, v; C) = f_C(x, u) - f_Cnom(x, u),   u = u(x1, v; C_nom)  (002 (13)-(16))

in rows x2' (vertical) and x4' (horizontal). In error coordinates (:mod:`closed_loop`)

    z~' = A_cl z~ + B_v Delta_v + B_h Delta_h                                        (*)

and z~ = 0 is no longer an equilibrium. Delta is built symbolically from
:attr:`StageModel.f_theta` with C as a CasADi symbol; it is *linear* in C (the model is
x'' = Phi(x, u) C + b, checked when the graph is built), Delta = J(x1, v) (C - C_nom), so

    dV/dt = -z~' Q z~ + g(z~, phi)' (C - C_nom),   Q = -(A_cl' P + P A_cl),   g = 2 J' B' P z~,

and the worst plant of Theta is found in closed form by the support function:
g'(C0 - C_nom) + sum_k r_k |g_k| for a box of half-widths r, g'(C0 - C_nom) + |chol(S)' g| for an
ellipsoid (exact, no bounding box). The worst plant itself is returned with a refutation.

**The certificate.** Omega_c = {V <= c} is forward invariant for every plant in Theta, and the
transformation exists with the currents within the limit for all t >= 0, if

  (a) Omega_c x {exosystem orbit} lies in F: it does for c <= c_nom, the level Procedure 2
      certifies for the same P and reference (F does not depend on the plant);
  (b) on the boundary V = c, sup_{C in Theta} dV/dt < 0 for every phase of the reference.

(While the state is in Omega_c it is in F, so (*) holds; V cannot cross c where dV/dt < 0.)
(b) depends on z~ only through five linear functions, w = N z~ = (e1, v1~, v2~, p_v, p_h) with
p = B'P z~, and through -z~'Q z~. For any alpha with H = Q - alpha P > 0 on null(N),

    -z~'Q z~ = -alpha V - z~'H z~ <= -alpha c + w' R_alpha w   on V = c,

R_alpha = -T'(H - H Z (Z'H Z)^-1 Z'H) T (T = P^-1 N'(N P^-1 N')^-1, Z a basis of null(N)): the
largest -z~'H z~ over the z~ with N z~ = w (an S-procedure bound; with alpha chosen per w it is
exact, by S-lemma duality). The image of the shell V = c under N is the whole ellipsoid
w = sqrt(c) chol(N P^-1 N') zeta, |zeta| <= 1. So (b) holds if, for every zeta in the unit ball
(and every phase), min over a grid of alphas of

    c zeta' R~_alpha zeta - alpha c + sup_{C in Theta} g(w, phi)'(C - C_nom)  <  0.

Interval branch and bound (:class:`~maglev_oc.region.interval.IntervalFunction` on the same
CasADi graph, boxes of :func:`~maglev_oc.region.branch_and_bound.bisect_widest`) proves it over
boxes of (zeta (5), phase): a box is accepted when the upper end of the enclosure of one alpha's
bound is < 0. For an undecided box, the box's midpoint is lifted to a z~ exactly on V = c (the
least-V preimage T w plus a null-space direction) and the exact sup dV/dt is evaluated there: a
positive value *refutes* the level (a real plant of Theta leaves Omega_c from that point).

Levels are tried from c_nom down a ladder of fractions; between the first certified rung and the
rung above it a few bisection steps tighten the level. The robust level is never above c_nom; it
equals c_nom when Theta is the nominal point (then sup dV/dt = -z~'Q z~ < 0). Small level sets
are not invariant for mismatched plants (the shifted equilibrium lies outside them), so the set
of certified levels is bounded below too: a ladder that reaches its last rung says so.

**Method choice.** The certificate is the interval method: the support function removes the
four parameters exactly, leaving 5 dimensions (6 with the phase), and the S-procedure bound on
-z~'Q z~ is exact per point for the best alpha. An SDP certificate with Delta as a norm-bounded
term would need a bound on Delta over Omega_c (itself an interval computation) and loses its
dependence on the gap and the phase; it is used only to *choose* P
(:func:`robust_lyapunov_matrix`), which the interval method then certifies. What each gives:
with the Lyapunov equation's P (:meth:`RegulatorLoop.lyapunov_matrix`, decay rate of V only
0.67 1/s) no level is invariant even for the 0.5 confidence set of
:func:`~maglev_oc.region.robust.assumed_covariance` at 15, 20 or 25 mm (every rung refuted by a
real plant: dV/dt > 0 on V = c); with the SDP's P at 25 mm the whole nominal level is certified
up to the 0.95 set (bench/region_robust_certificate.py).

Assumptions (besides those of Procedure 2: continuous-time FL loop, exact velocities, ideal
amplifier, exosystem reference): the plant is the SPEC 1 model with constant C in Theta (no
cogging, friction or other effects); the controller uses C_nom.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
from scipy.linalg import eigh, null_space

from maglev_oc.errors import InputError
from maglev_oc.numerics import ColumnMap
from maglev_oc.region.branch_and_bound import bisect_widest, initial_boxes, meets_unit_ball
from maglev_oc.region.closed_loop import LOOP_VARIABLES, N_ERROR, Reference, RegulatorLoop
from maglev_oc.region.ellipsoid import InitialConditionSet, checked_p, initial_condition_set
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.interval import IntervalFunction
from maglev_oc.region.procedure2 import Procedure2, Procedure2Result
from maglev_oc.region.sweep import PlantSet
from maglev_oc.results import Result

__all__ = [
    "ALPHA_FRACTIONS",
    "ROBUST_LADDER",
    "Coverage",
    "RobustCertificate",
    "RobustCertifier",
    "RobustSearch",
    "certificate_words",
    "certify_robust",
    "coverage",
    "mismatch_expressions",
    "robust_lyapunov_matrix",
]

ROBUST_LADDER = (1.0, 0.9, 0.8, 0.7, 0.6, 0.5, 0.4, 0.3, 0.2, 0.15, 0.1, 0.07, 0.05, 0.03, 0.02, 0.01)
"""Fractions of the nominal certified level at which the robust condition is tried, in order."""
REFINE_STEPS = 3
"""Bisection steps between the first certified rung and the rung above it."""
ALPHA_FRACTIONS = (-1.0, -0.25, 0.0, 0.25, 0.5, 0.7, 0.85, 0.95, 0.99)
"""alpha / alpha_max of the S-procedure bounds (alpha_max: H = Q - alpha P singular on null(N))."""
N_IMAGE = 5
"""Dimension of w = N z~ = (e1, v1~, v2~, p_v, p_h)."""


def _currents(model, x1, v):
    """The controller's currents u(x1, v) (002 (13)-(16), physical root), u2 written without
    cancellation as in :func:`~maglev_oc.region.feasibility.transformation_constraints` (equal to
    :attr:`FeedbackTransformation.currents` where R >= 0; tight interval enclosures)."""
    L1, L2, L3, L4 = model.L(x1)
    G = model.params.gravity
    u1 = -v[0] / L1
    margin = L3**2 / (4 * L4) + G - L2 - L4 * u1**2 - v[1]
    sqrt_r = 2 * ca.sqrt(L4 * ca.fmax(margin, 0))
    u2 = 2 * (L4 * u1**2 + L2 - G + v[1]) / (sqrt_r - L3)
    return ca.vertcat(u1, u2)


def mismatch_expressions(model, x1, v) -> tuple[ca.SX, ca.SX]:
    """The acceleration mismatch of a plant with constants C under the controller of ``model``.

    Parameters
    ----------
    model : StageModel
        The controller's model (C_nom).
    x1 : CasADi SX scalar
        Gap [m].
    v : CasADi SX (2,)
        Commanded accelerations (v1 horizontal, v2 vertical) [m/s^2].

    Returns
    -------
    (Delta, J)
        Delta (2,) = (vertical, horizontal) mismatch [m/s^2] as a function of a symbol C (4,)
        (returned second element's free symbol is not needed: J is dDelta/dC (2, 4), which does
        not depend on C; Delta = J (C - C_nom)). Raises NotImplementedError if the model's
        accelerations are not linear in C.
    """
    C = ca.SX.sym("C", 4)
    x = ca.vertcat(x1, ca.SX.zeros(3))
    u = _currents(model, x1, v)
    c_nom = ca.DM(model.constants.as_array())
    acc = model.f_theta(x, u, C) - model.f_theta(x, u, c_nom)
    delta = ca.vertcat(acc[1], acc[3])
    J = ca.jacobian(delta, C)
    if ca.depends_on(J, C):
        raise NotImplementedError("the plant's accelerations are not linear in C: no exact support function")
    return delta, J


# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Geometry:
    """What the condition (b) needs of (loop, P): the image map N, its ellipsoid, the bounds."""

    N: np.ndarray  # (5, 10) rows e1, v1~, v2~, p_v, p_h
    chol: np.ndarray  # (5, 5) lower factor of N P^-1 N'
    T: np.ndarray  # (10, 5) least-V preimage z~ = T w
    Z: np.ndarray  # (10, 5) basis of null(N)
    Q: np.ndarray  # (10, 10) -(A'P + PA)
    alphas: np.ndarray  # (k,) effective alphas (lowered for rounding, see _geometry)
    R: np.ndarray  # (k, 5, 5) chol' R_alpha chol (per unit level)
    lift: np.ndarray  # (k, 5, 10) eta = lift z0: the null-space part maximising -z'Hz
    spare: np.ndarray  # (10,) a null-space direction with V = 1 (when that part is zero)


def _geometry(loop: RegulatorLoop, P: np.ndarray) -> _Geometry:
    Q = -(loop.A.T @ P + P @ loop.A)
    Q = 0.5 * (Q + Q.T)
    N = np.vstack([loop.output[[0, 2, 3]], (P @ loop.B_v)[None, :], (P @ loop.B_h)[None, :]])
    Pinv_Nt = np.linalg.solve(P, N.T)
    S = N @ Pinv_Nt
    S = 0.5 * (S + S.T)
    chol = np.linalg.cholesky(S)
    T = Pinv_Nt @ np.linalg.inv(S)
    Z = null_space(N)
    Zq, Zp = Z.T @ Q @ Z, Z.T @ P @ Z
    lam, vec = eigh(0.5 * (Zq + Zq.T), 0.5 * (Zp + Zp.T))
    alpha_max = float(lam[0])
    spare = Z @ vec[:, 0]
    spare = spare / math.sqrt(spare @ P @ spare)
    alphas = alpha_max * np.asarray(ALPHA_FRACTIONS)
    R, lift, effective = [], [], []
    for a in alphas:
        H = Q - a * P
        ZH = Z.T @ H
        G = np.linalg.solve(ZH @ Z, ZH)  # (Z'HZ)^-1 Z'H
        Ra = -T.T @ (H - H @ Z @ G) @ T
        Ra = 0.5 * (Ra + Ra.T)
        # the bound needs H + N'R N >= 0 (PSD with a 5-D kernel by construction); rounding is
        # absorbed by lowering alpha by the pencil's most negative eigenvalue (plus a hair)
        M = H + N.T @ Ra @ N
        lowest = float(eigh(0.5 * (M + M.T), P, eigvals_only=True)[0])
        effective.append(a - max(0.0, -lowest) - 1e-12 * abs(alpha_max))
        Rt = chol.T @ Ra @ chol
        R.append(0.5 * (Rt + Rt.T))
        lift.append(-G)
    return _Geometry(N, chol, T, Z, Q, np.array(effective), np.array(R), np.array(lift), spare)


@dataclass(frozen=True)
class RobustSearch(Result):
    """Outcome of one branch and bound of condition (b) at one level: ``status``
    ``"certified"``, ``"refuted"`` (a point of V = level and a plant of Theta with dV/dt > 0:
    ``witness``, ``witness_phase``, ``witness_plant``) or ``"undecided"`` (box budget spent)."""

    success: bool
    status: str
    message: str
    level: float
    boxes: int
    witness: np.ndarray | None  # z~ (10,) on V = level
    witness_phase: float
    witness_plant: np.ndarray | None  # C (4,) of the worst plant there
    witness_rate: float  # dV/dt there [V units / s]
    timings: Mapping[str, float] = field(default_factory=dict)  # [s] {"total": ...}


@dataclass(frozen=True)
class RobustCertificate(Result):
    """The certified robust level for one reference, one P and one uncertainty set.

    ``level`` is the certified robust c (0 if none): {V <= level} is forward invariant inside F
    for every plant of ``plants`` (module docstring). ``nominal_level`` is Procedure 2's for the
    same P; ``ratio`` = level / nominal_level. ``level_upper``: the least level tried above
    ``level`` that was refuted (a plant of Theta leaves its set; inf if none was refuted).
    ``status``: ``"certified"``, ``"not_certified"`` (no level of the ladder certified, or the
    nominal certificate failed) or ``"failed"`` (a numerical failure; ``message`` says which).
    """

    success: bool
    status: str
    message: str
    reference: Reference
    plants: str
    P: np.ndarray
    nominal_level: float
    level: float
    ratio: float
    level_upper: float
    witness: np.ndarray | None
    witness_phase: float
    witness_plant: np.ndarray | None
    initial_conditions: InitialConditionSet
    attempts: tuple[RobustSearch, ...]
    nominal: Procedure2Result | None = field(default=None, repr=False)
    timings: Mapping[str, float] = field(default_factory=dict)  # [s] nominal, certify, total


class RobustCertifier:
    """Condition (b) of the module docstring by interval branch and bound. Build once per
    (feasible set, loop); :meth:`run` for any nominal certificate and uncertainty set.

    Parameters
    ----------
    feasible : FeasibleSet
        Its model is the controller's (C_nom).
    loop : RegulatorLoop
    max_boxes : int
        Box budget per level.
    phase_cells : int
        Initial cells over the phase for a sinusoid.
    ladder : sequence of float
        Fractions of the nominal level tried, decreasing, in (0, 1] (default :data:`ROBUST_LADDER`).
        The same ladder and budget for two sets Theta_1 in Theta_2 give level_2 <= level_1.
    """

    def __init__(
        self,
        feasible: FeasibleSet,
        loop: RegulatorLoop,
        *,
        max_boxes: int = 200_000,
        phase_cells: int = 12,
        ladder=ROBUST_LADDER,
    ) -> None:
        if max_boxes < 1000:
            raise InputError(f"max_boxes must be >= 1000, got {max_boxes!r}")
        ladder = tuple(float(f) for f in ladder)
        if (
            not ladder
            or any(not (0 < f <= 1) for f in ladder)
            or any(a <= b for a, b in itertools.pairwise(ladder))
        ):
            raise InputError(f"ladder must be decreasing fractions in (0, 1], got {ladder!r}")
        self.ladder = ladder
        if phase_cells < 1:
            raise InputError(f"phase_cells must be >= 1, got {phase_cells!r}")
        if feasible.compensation is not None:
            raise InputError(
                "the robust certificate bounds the constants' mismatch of the uncompensated loop; "
                "a compensated effect is not covered (certify it with Procedure 2)"
            )
        self.feasible = feasible
        self.loop = loop
        self.max_boxes = int(max_boxes)
        self.phase_cells = int(phase_cells)
        self.constants = np.asarray(feasible.model.constants.as_array(), dtype=float)
        k = len(ALPHA_FRACTIONS)
        # the sup of g'(C - C_nom) over Theta at (l, p, phase), Theta = C0 + box(r) + chol(S) ball
        ell = ca.SX.sym("l", 3)  # (e1, v1~, v2~)
        p = ca.SX.sym("p", 2)  # (p_v, p_h) = B'P z~
        phi = ca.SX.sym("phi")
        off = ca.SX.sym("F", len(LOOP_VARIABLES), 3)
        shift = ca.SX.sym("d0", 4)  # C0 - C_nom
        radius = ca.SX.sym("r", 4)  # box half-widths
        shape = ca.SX.sym("Ls", 4, 4)  # chol(S) of the ellipsoid (zero for a box)
        offs = ca.mtimes(off, ca.vertcat(1, ca.sin(phi), ca.cos(phi)))
        x1 = offs[0] + ell[0]
        v = ca.vertcat(offs[2] + ell[1], offs[3] + ell[2])
        _, J = mismatch_expressions(feasible.model, x1, v)
        g = 2 * ca.mtimes(J.T, p)  # (4,)
        sup = ca.dot(g, shift) + ca.dot(radius, ca.fabs(g)) + ca.norm_2(ca.mtimes(shape.T, g))
        theta = [shift, radius, ca.vec(shape)]
        self._sup = ca.Function("sup_rate", [ell, p, phi, ca.vec(off), *theta], [sup, g])
        self._sup_columns = ColumnMap(self._sup)  # at many error states, one map built once
        self._jac = ca.Function("mismatch_jacobian", [ell, phi, ca.vec(off)], [J])
        # the interval graph over (zeta, phase): k bounds c zeta'R zeta - alpha c + sup
        zeta = ca.SX.sym("zeta", N_IMAGE)
        lmat = ca.SX.sym("L", N_IMAGE, N_IMAGE)  # sqrt(c) chol(N P^-1 N')
        rq = ca.SX.sym("Rc", N_IMAGE * N_IMAGE, k)  # c R~_alpha, column-major per alpha
        ac = ca.SX.sym("ac", k)  # alpha c
        w = ca.mtimes(lmat, zeta)
        s = self._sup(w[0:3], w[3:5], phi, ca.vec(off), *theta)[0]
        bounds = []
        for j in range(k):
            R = ca.reshape(rq[:, j], N_IMAGE, N_IMAGE)
            quad = 0
            for a in range(N_IMAGE):
                quad += R[a, a] * zeta[a] ** 2
                for b in range(a + 1, N_IMAGE):
                    quad += 2 * R[a, b] * zeta[a] * zeta[b]
            bounds.append(quad - ac[j] + s)
        fn = ca.Function(
            "robust_rate",
            [zeta, phi, ca.vec(lmat), ca.vec(off), *theta, ca.vec(rq), ac],
            [ca.vertcat(*bounds)],
        )
        self._ifn = IntervalFunction(fn)

    # ------------------------------------------------------------------------------------
    def theta_parameters(self, plants: PlantSet) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(C0 - C_nom (4,), box half-widths (4,), chol of the ellipsoid's shape (4, 4))."""
        if not isinstance(plants, PlantSet):
            raise TypeError(f"plants must be a PlantSet, got {type(plants).__name__}")
        c0 = np.asarray(plants.center, dtype=float)
        if plants.kind == "box":
            lo, hi = np.asarray(plants.lower, dtype=float), np.asarray(plants.upper, dtype=float)
            return c0 - self.constants, 0.5 * (hi - lo), np.zeros((4, 4))
        s = np.asarray(plants.shape, dtype=float)
        eig, vec = np.linalg.eigh(0.5 * (s + s.T))
        factor = vec * np.sqrt(np.maximum(eig, 0.0))[None, :]  # S = factor factor'
        return c0 - self.constants, np.zeros(4), factor

    def rate(self, P, reference: Reference, plants: PlantSet, ztilde, phase) -> tuple[np.ndarray, np.ndarray]:
        """The exact sup over Theta of dV/dt at error states z~ (10, n) and phases (n,): (n,), and
        the worst plants' constants (4, n)."""
        P = checked_p(P)
        zt = np.asarray(ztilde, dtype=float).reshape(N_ERROR, -1)
        n = zt.shape[1]
        phase = np.broadcast_to(np.asarray(phase, dtype=float).ravel(), (n,))
        geo_n = np.vstack(
            [self.loop.output[[0, 2, 3]], (P @ self.loop.B_v)[None, :], (P @ self.loop.B_h)[None, :]]
        )
        w = geo_n @ zt
        d0, r, factor = self.theta_parameters(plants)
        par_f = self.loop.offset_coefficients(reference).ravel(order="F")[:, None]
        sup, g = self._sup_columns(w[0:3], w[3:5], phase[None, :], par_f, d0, r, factor.ravel(order="F"))
        sup = sup.ravel()
        Q = -(self.loop.A.T @ P + P @ self.loop.A)
        base = -np.einsum("in,ij,jn->n", zt, Q, zt)
        # the worst plant: C0 + r sign(g) + S g / |factor' g|
        fg = factor.T @ g
        norm = np.linalg.norm(fg, axis=0)
        ell = np.where(norm > 0, factor @ fg / np.where(norm > 0, norm, 1.0), 0.0)
        worst = (self.constants + d0)[:, None] + r[:, None] * np.sign(g) + ell
        return base + sup, worst

    def certify(self, reference: Reference, P, level: float, plants: PlantSet) -> RobustSearch:
        """Branch and bound of condition (b) on V = ``level`` (module docstring).

        Parameters
        ----------
        reference : Reference
        P : (10, 10) array
            A Lyapunov matrix of the loop.
        level : float
            c > 0.
        plants : PlantSet

        Returns
        -------
        RobustSearch
        """
        t0 = time.perf_counter()
        if not (level > 0 and math.isfinite(level)):
            raise InputError(f"level must be positive and finite, got {level!r}")
        P = checked_p(P)
        geo = _geometry(self.loop, P)
        return self._search(reference, P, level, plants, geo, t0)

    def _search(self, reference, P, level, plants, geo: _Geometry, t0: float) -> RobustSearch:
        k = geo.alphas.size
        par_l = (math.sqrt(level) * geo.chol).ravel(order="F")[:, None]
        par_f = self.loop.offset_coefficients(reference).ravel(order="F")[:, None]
        d0, r, factor = self.theta_parameters(plants)
        theta = [d0[:, None], r[:, None], factor.ravel(order="F")[:, None]]
        par_r = np.concatenate([(level * geo.R[j]).ravel(order="F") for j in range(k)])[:, None]
        par_a = (level * geo.alphas)[:, None]
        periodic = not reference.is_setpoint
        lo, hi = initial_boxes(periodic, self.phase_cells, N_IMAGE)
        scale = np.ones(N_IMAGE + 1)
        scale[-1] = 1.0 / math.pi if periodic else 0.0
        boxes = 0

        def outcome(status, witness=None, phase=0.0, plant=None, rate=math.nan):
            msg = {
                "certified": f"sup dV/dt < 0 on V = {level:.4g} for every plant ({boxes} boxes)",
                "refuted": f"a plant has dV/dt = {rate:.3g} > 0 on V = {level:.4g} ({boxes} boxes)",
                "undecided": f"box budget spent after {boxes} boxes at V = {level:.4g}",
            }[status]
            return RobustSearch(
                status == "certified",
                status,
                msg,
                level,
                boxes,
                witness,
                phase,
                plant,
                rate,
                {"total": time.perf_counter() - t0},
            )

        while lo.shape[1] > 0:
            keep, _ = meets_unit_ball(lo[:N_IMAGE], hi[:N_IMAGE])
            lo, hi = lo[:, keep], hi[:, keep]
            if lo.shape[1] == 0:
                break
            boxes += lo.shape[1]
            _, up = self._ifn(
                [lo[:N_IMAGE], lo[N_IMAGE:], par_l, par_f, *theta, par_r, par_a],
                [hi[:N_IMAGE], hi[N_IMAGE:], par_l, par_f, *theta, par_r, par_a],
            )
            best = np.min(up[0], axis=0)
            ok = best < 0
            which = np.argmin(up[0], axis=0)[~ok]
            lo, hi = lo[:, ~ok], hi[:, ~ok]
            if lo.shape[1] == 0:
                break
            bad = self._refute(reference, P, level, plants, geo, lo, hi, which)
            if bad is not None:
                return outcome("refuted", *bad)
            if boxes > self.max_boxes:
                return outcome("undecided")
            lo, hi = bisect_widest(lo, hi, scale)
        return outcome("certified")

    def _refute(self, reference, P, level, plants, geo: _Geometry, lo, hi, which):
        """Lift each undecided box's midpoint to z~ on V = level (both signs of the null-space
        part) and evaluate the exact sup dV/dt there: (z~, phase, plant, rate) of the worst
        positive one, or None."""
        mid = 0.5 * (lo + hi)
        zeta = mid[:N_IMAGE] / np.maximum(1.0, np.linalg.norm(mid[:N_IMAGE], axis=0))
        w = math.sqrt(level) * geo.chol @ zeta
        z0 = geo.T @ w
        v0 = level * np.sum(zeta**2, axis=0)
        eta = np.einsum("nij,jn->in", geo.lift[which], z0)
        d = geo.Z @ eta
        dp = np.sqrt(np.maximum(np.einsum("in,ij,jn->n", d, P, d), 0.0))
        small = dp <= 1e-12 * max(1.0, float(np.max(dp, initial=0.0)))
        d = np.where(small[None, :], geo.spare[:, None], d / np.where(small, 1.0, dp)[None, :])
        room = np.sqrt(np.maximum(level - v0, 0.0))
        phase = mid[N_IMAGE]
        pts = np.hstack([z0 + room * d, z0 - room * d])
        phs = np.concatenate([phase, phase])
        rate, worst = self.rate(P, reference, plants, pts, phs)
        if not np.any(rate > 0):
            return None
        j = int(np.argmax(rate))
        return pts[:, j], float(phs[j]), worst[:, j], float(rate[j])

    # ------------------------------------------------------------------------------------
    def run(self, nominal: Procedure2Result, plants: PlantSet) -> RobustCertificate:
        """The largest level of the ladder (refined by bisection) at which condition (b) is
        certified, capped at the nominal certified level (condition (a)).

        Parameters
        ----------
        nominal : Procedure2Result
            Procedure 2 for the reference and P (its level is c_nom).
        plants : PlantSet
            The uncertainty set Theta of the plant's constants.

        Returns
        -------
        RobustCertificate
            Never raises on a numerical failure: ``status`` ``"failed"`` says what failed.
        """
        t0 = time.perf_counter()
        if not isinstance(nominal, Procedure2Result):
            raise TypeError(f"nominal must be a Procedure2Result, got {type(nominal).__name__}")
        self.theta_parameters(plants)  # type check before any work
        P = checked_p(nominal.P)
        c_nom = float(nominal.level)
        timings = {"nominal": float(nominal.timings.get("total", 0.0))}
        base = dict(
            reference=nominal.reference, plants=plants.label, P=P, nominal_level=c_nom, nominal=nominal
        )
        if not (nominal.success and c_nom > 0):
            timings["total"] = time.perf_counter() - t0
            return _certificate(
                "not_certified",
                "the nominal certificate failed: " + nominal.message,
                base,
                0.0,
                math.inf,
                None,
                (),
                timings,
            )
        try:
            geo = _geometry(self.loop, P)
            level, upper, witness, attempts = self._ladder(nominal.reference, P, c_nom, plants, geo)
        except (np.linalg.LinAlgError, RuntimeError, FloatingPointError) as exc:
            timings["total"] = time.perf_counter() - t0
            return _certificate(
                "failed",
                f"numerical failure: {type(exc).__name__}: {exc}",
                base,
                0.0,
                math.inf,
                None,
                (),
                timings,
            )
        timings["certify"] = time.perf_counter() - t0
        timings["total"] = timings["certify"] + timings["nominal"]
        if level > 0:
            where = (
                "the nominal level (no shrinking needed)" if level >= c_nom else f"{level / c_nom:.3g} of it"
            )
            message = f"certified c = {level:.4g} for every plant of {plants.label}: {where}"
            status = "certified"
        else:
            last = attempts[-1] if attempts else None
            message = (
                f"no level down to {self.ladder[-1]:g} of the nominal one is invariant for every plant of "
                f"{plants.label}" + (f" (last: {last.message})" if last else "")
            )
            status = "not_certified"
        return _certificate(status, message, base, level, upper, witness, attempts, timings)

    def _ladder(self, reference, P, c_nom, plants, geo):
        attempts: list[RobustSearch] = []
        above = None  # the attempt just above the certified level
        lowest_refuted = None
        certified = 0.0
        for frac in self.ladder:
            res = self._search(reference, P, frac * c_nom, plants, geo, time.perf_counter())
            attempts.append(res)
            if res.status == "certified":
                certified = res.level
                break
            above = res
            if res.status == "refuted":
                lowest_refuted = res
        if certified > 0 and above is not None:
            lo_c, hi_c = certified, above.level
            for _ in range(REFINE_STEPS):
                mid = 0.5 * (lo_c + hi_c)
                res = self._search(reference, P, mid, plants, geo, time.perf_counter())
                attempts.append(res)
                if res.status == "certified":
                    lo_c = mid
                else:
                    hi_c = mid
                    if res.status == "refuted":
                        lowest_refuted = res
            certified = lo_c
        if lowest_refuted is None:
            return certified, math.inf, None, tuple(attempts)
        return certified, lowest_refuted.level, lowest_refuted, tuple(attempts)


def robust_lyapunov_matrix(
    certifier: RobustCertifier,
    nominal: Procedure2Result,
    plants: PlantSet,
    *,
    alphas=(0.5, 1.0, 2.0, 4.0, 8.0),
    budget: float = 0.7,
    margin: float = 0.9,
    samples: int = 4000,
    seed: int = 0,
    direction: np.ndarray | None = None,
) -> tuple[np.ndarray | None, str]:
    """A P chosen for robustness (a heuristic; the certificate is :meth:`RobustCertifier.run`).

    The mismatch is treated as a bounded disturbance |Delta_v| <= mu_v, |Delta_h| <= mu_h, mu
    the largest worst-case mismatch over ``samples`` points of the nominal set {V0 <= c_nom} (not
    a bound: P is only *chosen* here). With Y = P^-1, the level set {z~' P z~ <= 1} is invariant
    under such a disturbance if, for some alpha > 0 and beta >= 0 with beta' mu^2 <= alpha
    (S-procedure),  [[A Y + Y A' + alpha Y, B], [B', -diag(beta)]] <= 0. Subject to that and to
    the spreads of (e1, e2, v1~, v2~) over the set staying within those of the nominal set, the
    SDP (cvxpy + Clarabel, acceleration-scaled coordinates) maximises the (e1, e2) rectangle at
    rest, for each alpha of ``alphas`` [1/s]; the best is returned. With ``direction`` (a z~ (10,),
    e.g. one start's error state) it maximises instead how far along it the set {V <= 1} reaches
    (a P aimed at that start; pass the nominal certificate of a P aimed at it too, e.g.
    :func:`~maglev_oc.region.sdp.enlarge` with the same direction, since its spreads bound the set).

    Returns
    -------
    (P or None, message)
    """
    import warnings

    import cvxpy as cp

    from maglev_oc.region.montecarlo import uniform_in_ellipsoid

    loop = certifier.loop
    P0 = checked_p(nominal.P)
    c0 = float(nominal.level)
    if not c0 > 0:
        return None, "the nominal certificate has no level"
    z = uniform_in_ellipsoid(P0, c0, samples, np.random.default_rng(seed))
    ell = loop.output[[0, 2, 3]] @ z
    par_f = loop.offset_coefficients(nominal.reference).ravel(order="F")[:, None]
    J = np.asarray(certifier._jac.map(samples)(ell, np.zeros((1, samples)), par_f))  # (2, 4 n)
    J = J.reshape(2, samples, 4).transpose(0, 2, 1)  # (2, 4, n): the map puts the n (2, 4) side by side
    d0, r, factor = certifier.theta_parameters(plants)
    mu = np.zeros(2)
    for i in range(2):
        Ji = J[i]  # (4, n)
        worst = np.abs(d0 @ Ji) + r @ np.abs(Ji) + np.linalg.norm(factor.T @ Ji, axis=0)
        mu[i] = float(np.max(worst))
    if not np.any(mu > 0):
        return P0, "no mismatch: the nominal P is kept"
    d = loop.state_scale()
    Dm = np.diag(d)
    A = np.diag(1 / d) @ loop.A @ Dm
    B = np.diag(1 / d) @ np.column_stack([loop.B_v, loop.B_h])
    rows = loop.output @ Dm
    spreads = budget * c0 * np.einsum("ij,ji->i", loop.output, np.linalg.solve(P0, loop.output.T))
    corners = []
    for s in (1.0, -1.0):
        x = np.zeros((N_ERROR, 2))
        x[0, 0], x[5, 1] = 1 / d[0], s / d[5]
        corners.append(x)
    if direction is not None:
        direction = np.asarray(direction, dtype=float).reshape(N_ERROR)
        if not (np.all(np.isfinite(direction)) and np.any(direction != 0)):
            raise InputError("direction must be a finite, nonzero z~ (10,)")
        corners = [(direction / d)[:, None]]  # one column: the objective's a has one entry

    def solve(alpha: float, mu_s: np.ndarray, rectangle: bool):
        Y = cp.Variable((N_ERROR, N_ERROR), symmetric=True)
        beta = cp.Variable(2, nonneg=True)
        t = cp.Variable()
        cons = [
            cp.bmat([[A @ Y + Y @ A.T + alpha * Y, B], [B.T, -cp.diag(beta)]]) << 0,
            beta @ mu_s**2 <= alpha,
            Y >> 1e-9 * np.eye(N_ERROR),
        ]
        if rectangle:
            a = cp.Variable(corners[0].shape[1])
            cons += [rs @ Y @ rs <= b2 for rs, b2 in zip(rows, spreads, strict=True)]
            for x in corners:
                xa = cp.reshape(x @ a, (N_ERROR, 1), order="F")
                cons.append(cp.bmat([[np.ones((1, 1)), xa.T], [xa, Y]]) >> 0)
            prob = cp.Problem(cp.Maximize(cp.sum(cp.log(a))), cons)
        else:
            cons += [rs @ Y @ rs <= t * b2 for rs, b2 in zip(rows, spreads, strict=True)]
            prob = cp.Problem(cp.Minimize(t), cons)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)
                prob.solve(solver=cp.CLARABEL)
        except cp.error.SolverError as err:
            return f"solver error: {err}", None, np.inf
        ok = prob.status in ("optimal", "optimal_inaccurate") and Y.value is not None
        return str(prob.status), (Dm @ Y.value @ Dm if ok else None), (prob.value if ok else np.inf)

    # the least spread factor t each alpha needs for the full mu (t scales as mu^2)
    need = {alpha: solve(alpha, mu, False)[2] for alpha in alphas}
    alpha = min(need, key=need.get)
    if not np.isfinite(need[alpha]):
        return None, "the robust SDP found no P"
    shrink = min(1.0, margin / math.sqrt(need[alpha]))
    status, best, _ = solve(alpha, shrink * mu, True)
    if best is None:
        return None, f"the robust SDP found no P ({status})"
    P = np.linalg.inv(0.5 * (best + best.T))
    P = 0.5 * (P + P.T)
    if not loop.is_lyapunov(P):
        return None, "the SDP's P is not a Lyapunov matrix in floating point"
    return P, (
        f"P from the robust SDP (mismatch up to {mu[0]:.3g}, {mu[1]:.3g} m/s^2; designed for "
        f"{shrink:.3g} of it, alpha {alpha:g} 1/s)"
    )


@dataclass(frozen=True)
class Coverage(Result):
    """How much of the empirically safe region a certificate covers (computed from a sweep).

    The sweep's runs start uniformly in a probe set {V <= probe_level} (larger than the nominal
    set) with plants drawn from Theta; a start is *safe* when its run stays in F. ``nominal`` and
    ``robust`` are the shares of the safe starts with V <= the nominal / robust certified level;
    ``unsafe_in_nominal`` / ``unsafe_in_robust`` count starts inside each certified set whose run
    left F (the robust count must be 0: ``success``).
    """

    success: bool
    status: str
    message: str
    probe_level: float
    nominal_level: float
    robust_level: float
    runs: int
    safe: int
    nominal: float
    robust: float
    unsafe_in_nominal: int
    unsafe_in_robust: int
    timings: Mapping[str, float] = field(default_factory=dict)


def coverage(sweep, nominal_level: float, robust_level: float) -> Coverage:
    """The conservativeness of the nominal and robust certificates on one sweep (:class:`Coverage`).

    Parameters
    ----------
    sweep : SweepResult
        Runs started in {V <= sweep.spec.level} (the probe set) of the same P, plants from Theta.
    nominal_level, robust_level : float
        The certified levels c_nom and c_rob.

    Returns
    -------
    Coverage
    """
    if sweep.spec.P is None:
        raise InputError("coverage needs a sweep started in a level set {V <= level}, not a fixed start")
    v = np.asarray(sweep.start_ratio) * sweep.spec.level
    safe = ~np.asarray(sweep.violating)
    n_safe = int(safe.sum())
    in_nom, in_rob = v <= nominal_level, v <= robust_level
    share_nom = float(np.mean(in_nom[safe])) if n_safe else 0.0
    share_rob = float(np.mean(in_rob[safe])) if n_safe else 0.0
    bad_nom, bad_rob = int(np.sum(in_nom & ~safe)), int(np.sum(in_rob & ~safe))
    message = (
        f"of {n_safe} safe starts in {{V <= {sweep.spec.level:.4g}}}, the nominal set covers {share_nom:.1%} "
        f"({bad_nom} unsafe inside), the robust set {share_rob:.1%} ({bad_rob} unsafe inside)"
    )
    return Coverage(
        bad_rob == 0,
        "sound" if bad_rob == 0 else "violated",
        message,
        float(sweep.spec.level),
        float(nominal_level),
        float(robust_level),
        int(sweep.n),
        n_safe,
        share_nom,
        share_rob,
        bad_nom,
        bad_rob,
        {"sweep": float(sweep.timings.get("total", 0.0))},
    )


def certificate_words(certificate: RobustCertificate) -> str:
    """The outcome of :meth:`RobustCertifier.run` in plain words: "certified", "not certified:
    refuted by plant C=(...) at level c (share of the nominal level)", or "undecided within the
    budget" when no rung was certified and none refuted (every box budget spent)."""
    if certificate.status == "certified":
        return "certified"
    if certificate.status == "failed":
        return "failed: " + certificate.message
    if not certificate.nominal_level > 0:
        return "not certified: no nominal level"
    if certificate.witness_plant is None:
        return "undecided within the budget"
    plant = ", ".join(f"{c:.4g}" for c in certificate.witness_plant)
    upper = certificate.level_upper
    return (
        f"not certified: refuted by plant C=({plant}) at level {upper:.4g} "
        f"({upper / certificate.nominal_level:.2f} of the nominal one)"
    )


def _certificate(status, message, base, level, upper, witness, attempts, timings) -> RobustCertificate:
    c_nom = base["nominal_level"]
    return RobustCertificate(
        status == "certified",
        status,
        message,
        base["reference"],
        base["plants"],
        base["P"],
        c_nom,
        level,
        level / c_nom if c_nom > 0 else 0.0,
        upper,
        None if witness is None else witness.witness,
        0.0 if witness is None else witness.witness_phase,
        None if witness is None else witness.witness_plant,
        initial_condition_set(base["P"], level),
        tuple(attempts),
        base["nominal"],
        {k: float(v) for k, v in timings.items()},
    )


def certify_robust(
    feasible: FeasibleSet,
    loop: RegulatorLoop,
    reference: Reference,
    plants: PlantSet,
    P=None,
    **options,
) -> RobustCertificate:
    """One-off: Procedure 2 for (reference, P), then the robust level for ``plants``.

    Parameters
    ----------
    feasible : FeasibleSet
    loop : RegulatorLoop
    reference : Reference
    plants : PlantSet
    P : (10, 10) array, optional
        Default: the loop's Lyapunov-equation P (as Procedure 2).
    **options
        ``max_boxes``, ``phase_cells``, ``ladder`` of :class:`RobustCertifier`.

    Returns
    -------
    RobustCertificate
    """
    unknown = set(options) - {"max_boxes", "phase_cells", "ladder"}
    if unknown:
        raise TypeError(f"unknown option(s) {sorted(unknown)}")
    nominal = Procedure2(feasible, loop).run(reference, P)
    return RobustCertifier(feasible, loop, **options).run(nominal, plants)
