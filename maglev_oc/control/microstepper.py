"""The FL output regulator of the 3-DOF microstepper (002 Sec. 8), with anti-windup.

Three copies of the 2-DOF regulator of :mod:`~maglev_oc.control.fl_regulator`, one per platform
coordinate (x, y, gap) of :func:`~maglev_oc.model.platform.microstepper`:

    e_j = y_j - r_j,   e_j' = (observer velocity) - r_j'      per axis j
    xi_j' = phi xi_j + N e_j                                 (21)-(22) of 002, omega0 = 1.5 pi
    v_j = K_j (e_j, e_j', xi_j)                              (23)-(24): K_h on x and y, K_v on the gap
    u = (i_qA, i_dA, i_qB, i_dB) = T(gap, v)                 the microstepper's transformation

with the printed gains (negative entries: v = K z is negative feedback, as in the 2-DOF one), the
rates from high-gain observers (002 Sec. 4) and T the minimum-current-norm transformation of
:class:`~maglev_oc.model.allocation.MicrostepperTransformation` at the measured gap. Where its
discriminant R < 0, i_d uses sqrt(max(R, 0)) and the sample is flagged ``clipped``, as in the
2-DOF regulator. The maximum-margin allocation is not offered: it is a numerical minimisation
(:meth:`~maglev_oc.model.allocation.MicrostepperTransformation.allocate`), not a CasADi
expression.

Anti-windup (002 Sec. 8: "enhanced with an antiwindup mechanism"; the scheme is not given)
------------------------------------------------------------------------------------------
Each pair's amplifier limits its current magnitude sqrt(i_q^2 + i_d^2) to 9 A. The most thrust
a pair gives is 12-29 m/s^2 (pair B / pair A, 30 / 20 mm gap), while a step of e on x or y asks
for 1182 e m/s^2 at once: every step over about 1 cm saturates, and the internal models (an
integrator and the undamped omega0 oscillator each) wind up. Two parts, both in the virtual
input v, where the axes are decoupled double integrators:

1. **Levitation first** (``levitation_first``). The amplifiers scale a saturated pair's (i_q, i_d)
   as a vector, so a pair driven hard in thrust loses the i_d that holds the gap, and the i_q^2
   term of the normal force (K4 l4 i_q^2, 24 N per motor at 9 A and 25 mm, most of the 29 N
   weight share) pulls on the gap as well: on the twin the platform drops to the gap stopper
   within 50 ms of an 80 mm step, anti-windup or not. The gap is the open-loop unstable axis, so
   the controller limits its own currents: the gap's acceleration is realised exactly and each
   pair's thrust current is cut to what the limit leaves, sqrt(I^2 - i_d^2) (i_d equal in both
   pairs, as in the minimum-norm solution; :attr:`MicrostepperRegulator.limiter`).
   Below the limit this is the transformation T itself.
2. **Back-calculation (tracking) in observer form** (``anti_windup``; Åström & Wittenmark,
   *Computer-Controlled Systems*, Sec. 9.4, the state-space form of the PI controller's tracking
   anti-windup). The model being exact, the controller knows the accelerations it gets,

       v_ach = (PlatformModel.f at the measured gap and the currents the amplifiers will apply),

   equal to v to rounding when nothing is limited and R >= 0 (T is the model's exact inverse).
   Each axis's internal model is driven by the shortfall,

       xi_j' = phi xi_j + N e_j + L_j (v_ach,j - v_j),

   so that under saturation, with v_j = K_j z_j, its dynamics become phi - L_j k_xi,j (k_xi,j the
   gains on xi_j): a stable filter instead of an integrator and an undamped oscillator, and its
   contribution k_xi,j xi_j to v_j tracks what the plant can do. L_j places the eigenvalues of
   phi - L_j k_xi,j at -1/T_t (triple). The high-gain observers integrate v_ach instead of v (the
   acceleration actually realised; fed v, their velocity estimate runs away during saturation).
   Why this scheme: no tuning beyond T_t; exactly inactive when nothing saturates (the controller
   is then the 2-DOF one on three axes); the amplifier limit and the R < 0 clip are treated alike
   (both are "v not realised"); and each axis is corrected by its own shortfall although one
   pair's limit couples a thrust and the shared normal force.

Tracking time constant: T_t = 1 / |real part of the slowest closed-loop pole| of the axis,
0.130 s for the printed K_h (poles -7.7 +- 1.6j, ...) and 0.106 s for K_v (-9.4 +- 1.8j, ...):
the dominant closed-loop time constant. Much slower, the windup is undone only after the loop
has overshot (on the twin's 80 mm steps: 34 % overshoot at T_t = 0.13 s, 43 % at 0.25 s, 73 % at
1 s, 80 % without anti-windup). Faster helps down to about 0.06 s (9 %), but below 0.05 s the
internal models over-track: they cancel the proportional action mid-stroke and reverse the
motion (excursions of 130-190 mm at 0.035-0.04 s). The dominant time constant keeps a factor 2.6
from that failure at a moderate cost in overshoot, and ties T_t to the gains rather than to one
twin.

Controller state (15): (p_x, q_x, p_y, q_y, p_gap, q_gap, xi_x (3), xi_y (3), xi_gap (3)), (p, q)
the observer's position and velocity per axis. Signals: y (3) = encoder readings (x, y, gap) [m];
r (9) = (r_x, r_x', r_x'', r_y, r_y', r_y'', r_gap, r_gap', r_gap'') [m, m/s, m/s^2] (the 2-DOF
layout, one block of three per axis; r'' unused, as in the 2-DOF regulator); u (4) = (i_qA, i_dA,
i_qB, i_dB) [A] as commanded (within the limit when ``levitation_first``; otherwise the
amplifiers limit them).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import casadi as ca
import numpy as np
from scipy.linalg import expm

from maglev_oc.control.gains import OMEGA0, PAPER_K_H, PAPER_K_V, axis_poles, checked_gains, internal_model
from maglev_oc.control.output_regulator import discrete_internal_model
from maglev_oc.errors import InputError
from maglev_oc.estimation.high_gain import DEFAULT_EPSILON, HighGainObserver
from maglev_oc.model.allocation import MicrostepperTransformation
from maglev_oc.model.hardware import PEAK_CURRENT_LIMIT, RIG_SAMPLE_TIME
from maglev_oc.model.platform import Platform, PlatformModel

__all__ = [
    "AXES",
    "N_MEASUREMENTS",
    "N_REFERENCE",
    "N_STATE",
    "MicrostepperRegulator",
    "anti_windup_gain",
    "dominant_time_constant",
    "saturated_currents",
]

AXES = ("x", "y", "gap")
"""The regulated coordinates, in the order of y, of the blocks of r and of the controller state."""
N_MEASUREMENTS = 3
"""Entries of ``y``: encoder readings (x, y, gap) [m]."""
N_REFERENCE = 9
"""Rows of ``r``: (position, rate, acceleration) per axis [m, m/s, m/s^2], axes as :data:`AXES`."""
N_STATE = 15
"""Entries of the controller state (module docstring)."""
_LIMIT_SLACK = 1e-9
"""Relative margin of the levitation-first currents below the amplifiers' limit (rounding)."""


def dominant_time_constant(gains, omega0: float = OMEGA0) -> float:
    """1 / |real part of the slowest closed-loop pole| [s] of an axis under v = K z.

    Parameters
    ----------
    gains : array_like
        K (5,) on (e, e', xi1, xi2, xi3).
    omega0 : float
        Internal-model frequency [rad/s].

    Returns
    -------
    float
        [s]; 0.130 s for the printed K_h, 0.106 s for K_v (the printed integers move the
        slowest poles from the design's -9 and -11 to -7.7 and -9.4 1/s).
    """
    poles = axis_poles(gains, omega0)
    slowest = float(np.max(poles.real))
    if not slowest < 0:
        raise InputError(
            f"gains {np.asarray(gains).tolist()} do not stabilise the axis (pole at {slowest:g})"
        )
    return -1.0 / slowest


def anti_windup_gain(gains, time_constant: float, omega0: float = OMEGA0) -> np.ndarray:
    """Back-calculation gain L of one axis: eig(phi - L k_xi) = -1/time_constant (triple).

    The internal model with anti-windup is xi' = phi xi + N e + L (v_ach - v); while v is not
    realised, its own dynamics are phi - L k_xi with k_xi = gains[2:] (Ackermann's formula for
    the observer form, dual of :func:`~maglev_oc.control.gains.place_axis`).

    Parameters
    ----------
    gains : array_like
        K (5,) on (e, e', xi1, xi2, xi3) [1/s^2, 1/s, 1/s^5, 1/s^4, 1/s^3].
    time_constant : float
        Tracking time constant T_t [s], positive.
    omega0 : float
        Internal-model frequency [rad/s].

    Returns
    -------
    (3,) array
        L [units of xi per m/s^2 per s].
    """
    k = checked_gains(gains, "gains")[2:].reshape(1, 3)
    if not (np.isfinite(time_constant) and time_constant > 0):
        raise InputError(f"time_constant must be positive [s], got {time_constant!r}")
    phi, _, _ = internal_model(omega0)
    obs = np.vstack([k, k @ phi, k @ phi @ phi])
    if np.linalg.matrix_rank(obs) < 3:
        raise InputError(f"the internal model is not observable from the gains {k.ravel().tolist()}")
    coeffs = np.poly(np.full(3, -1.0 / time_constant))
    p_phi = sum(c * np.linalg.matrix_power(phi, 3 - j) for j, c in enumerate(coeffs))
    return (p_phi @ np.linalg.solve(obs, np.eye(3)[:, -1])).ravel()


def _discrete_tracking_input(omega0: float, sample_time: float, gain: np.ndarray) -> np.ndarray:
    """Lambda_d (3, 1): the ZOH-exact input matrix of (v_ach - v) into the sampled internal model."""
    phi, _, _ = internal_model(omega0)
    m = np.zeros((4, 4))
    m[:3, :3] = phi
    m[:3, 3] = gain
    return expm(m * sample_time)[:3, 3:4]


def saturated_currents(u, peak: float):
    """Each pair's current vector (i_q, i_d) scaled to magnitude ``peak`` [A] where it exceeds it,
    as the amplifiers do (direction kept); CasADi expressions in, expressions out.

    Parameters
    ----------
    u : casadi SX (4,)
        (i_qA, i_dA, i_qB, i_dB) [A].
    peak : float
        [A].

    Returns
    -------
    u_sat : SX (4,)
    over : SX (2,)
        1 where pair A / pair B exceeds ``peak``.
    """
    parts, over = [], []
    for pair in (u[0:2], u[2:4]):
        mag = ca.sqrt(pair[0] ** 2 + pair[1] ** 2 + 1e-30)
        parts.append(pair * ca.fmin(1.0, peak / mag))
        over.append(mag > peak)
    return ca.vertcat(*parts), ca.vertcat(*over)


@dataclass(frozen=True, eq=False)
class MicrostepperRegulator:
    """The microstepper's FL output regulator as one CasADi step Function (built once).

    Parameters
    ----------
    platform : Platform
        The controller's model (:func:`~maglev_oc.model.platform.microstepper`; its constants may
        differ from the twin's).
    K_h, K_v : array (5,)
        Gains on (e, e', xi1, xi2, xi3): K_h on x and y, K_v on the gap (default: printed, 002).
    sample_time : float
        [s], default 2e-4 (5 kHz).
    omega0 : float
        Internal-model frequency [rad/s] (default 1.5 pi).
    observer_epsilon : float
        High-gain observer time constant [s].
    anti_windup : bool
        Back-calculation of the module docstring (default on); off, the internal models and the
        observers are those of the 2-DOF regulator (observers fed v).
    levitation_first : bool
        Limit the currents in the controller, the gap's acceleration first (module docstring;
        default on); off, the unlimited minimum-norm currents are commanded and the amplifiers
        scale each pair's vector. Both off: the 2-DOF regulator on three axes.
    tracking_time_constant : float, optional
        T_t [s] for every axis; default per axis :func:`dominant_time_constant` of its gains.
    peak_current : float
        The amplifiers' limit on each pair's current magnitude [A] (default 9 A, 002 Sec. 4).
    name : str, optional
        Default "microstepper FL regulator", with what is switched off in brackets.

    Attributes
    ----------
    step : casadi.Function
        (c (15), y (3), r (9)) -> (u (4) [A], c_next (15), diag (10)); ``diag`` rows are
        :attr:`diag_names`: feasibility margin -R / (dR/dv_gap) [m/s^2] (how much further v_gap
        could rise before R = 0), clipped (R < 0), saturated_A / saturated_B (pair over the
        limit in the unlimited minimum-norm solution), v (3) asked and v_ach (3) realised
        [m/s^2].
    limiter : casadi.Function
        (gap [m], v (3) [m/s^2]) -> (u (4) [A], limited (3)): the levitation-first currents;
        ``limited`` = (pair A's thrust cut, pair B's thrust cut, the gap's request unreachable).
    tracking_gains : (3, 3) array
        L per axis (rows x, y, gap), zero rows without anti-windup.
    tracking_time_constants : (3,) array
        [s] per axis.
    """

    platform: Platform
    K_h: np.ndarray = field(default_factory=PAPER_K_H.copy)
    K_v: np.ndarray = field(default_factory=PAPER_K_V.copy)
    sample_time: float = RIG_SAMPLE_TIME
    omega0: float = OMEGA0
    observer_epsilon: float = DEFAULT_EPSILON
    anti_windup: bool = True
    levitation_first: bool = True
    tracking_time_constant: float | None = None
    peak_current: float = PEAK_CURRENT_LIMIT
    name: str | None = None

    n_state: ClassVar[int] = N_STATE
    diag_names: ClassVar[tuple[str, ...]] = (
        "margin",
        "clipped",
        "saturated_A",
        "saturated_B",
        "v_x",
        "v_y",
        "v_gap",
        "v_ach_x",
        "v_ach_y",
        "v_ach_gap",
    )

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        for label in ("K_h", "K_v"):
            set_(self, label, checked_gains(getattr(self, label), label))
        for label in ("anti_windup", "levitation_first"):
            if not isinstance(getattr(self, label), bool):
                raise InputError(f"{label} must be a bool, got {getattr(self, label)!r}")
        if not (np.isfinite(self.peak_current) and self.peak_current > 0):
            raise InputError(f"peak_current must be positive [A], got {self.peak_current!r}")
        if self.name is None:
            off = [
                label
                for label, on in (
                    ("anti-windup", self.anti_windup),
                    ("levitation first", self.levitation_first),
                )
                if not on
            ]
            set_(self, "name", "microstepper FL regulator" + (f" (no {', no '.join(off)})" if off else ""))
        gains = (self.K_h, self.K_h, self.K_v)
        if self.tracking_time_constant is None:
            taus = np.array([dominant_time_constant(k, self.omega0) for k in gains])
        else:
            taus = np.full(3, float(self.tracking_time_constant))
        set_(self, "tracking_time_constants", taus)
        if self.anti_windup:
            L = np.vstack([anti_windup_gain(k, t, self.omega0) for k, t in zip(gains, taus, strict=True)])
        else:
            L = np.zeros((3, 3))
        set_(self, "tracking_gains", L)
        set_(self, "transformation", MicrostepperTransformation(self.platform))
        set_(self, "model", PlatformModel(self.platform))
        set_(self, "limiter", self._limiter_function())
        set_(self, "step", self._step_function(gains))

    def _step_function(self, gains) -> ca.Function:
        observer = HighGainObserver(self.sample_time, self.observer_epsilon)
        phi_d, gamma_d = discrete_internal_model(self.omega0, self.sample_time)
        lambdas = [_discrete_tracking_input(self.omega0, self.sample_time, l) for l in self.tracking_gains]
        c = ca.SX.sym("c", N_STATE)
        y = ca.SX.sym("y", N_MEASUREMENTS)
        r = ca.SX.sym("r", N_REFERENCE)
        err = [y[j] - r[3 * j] for j in range(3)]
        rate = [c[2 * j + 1] - r[3 * j + 1] for j in range(3)]
        xi = [c[6 + 3 * j : 9 + 3 * j] for j in range(3)]
        v = ca.vertcat(*(ca.dot(ca.DM(gains[j]), ca.vertcat(err[j], rate[j], xi[j])) for j in range(3)))
        gap = y[2]
        u_fl, R = self.transformation.function(gap, v)
        _, over = saturated_currents(u_fl, self.peak_current)
        u = self.limiter(gap, v)[0] if self.levitation_first else u_fl
        u_applied, _ = saturated_currents(u, self.peak_current)
        x_hat = ca.vertcat(y[0], c[1], y[1], c[3], y[2], c[5])
        v_ach = self.model.f(x_hat, u_applied)[1::2]
        acc = v_ach if self.anti_windup else v
        nxt = [observer.step(c[2 * j : 2 * j + 2], y[j], acc[j]) for j in range(3)]
        for j in range(3):
            xi_next = ca.mtimes(ca.DM(phi_d), xi[j]) + ca.DM(gamma_d) * err[j]
            if self.anti_windup:
                xi_next += ca.DM(lambdas[j]) * (v_ach[j] - v[j])
            nxt.append(xi_next)
        margin = self._margin_function()(gap, v)
        diag = ca.vertcat(margin, R < 0, over, v, v_ach)
        return ca.Function(
            "microstepper_step",
            [c, y, r],
            [u, ca.vertcat(*nxt), diag],
            ["c", "y", "r"],
            ["u", "c_next", "diag"],
        )

    def _limiter_function(self) -> ca.Function:
        """(gap, v) -> (u (4), limited (3)): levitation-first current limiting (module docstring).

        With equal i_d in both pairs (the minimum-norm structure) and each pair's thrust current
        cut to sqrt(I^2 - i_d^2) where it would exceed the limit, the mean normal force per motor
        F(i_d) = k2 + k3 i_d + k4 (mean of min(i_q^2 + i_d^2, I^2)) decreases strictly on [-I, I]
        (k3 + I k4 < 0 for gaps up to 50 mm with the rig's constants), so
        F(i_d) = m_gap (G - v_gap) / 4 has one solution there or none. Which pairs are cut
        decides the piece of F: none (the minimum-norm quadratic), A or B (another quadratic),
        both (linear). Each piece is solved in closed form and the one consistent with its own
        assumption is taken; with none, the request for the gap is out of reach and i_d goes to
        the end of [-I, I] that comes closest.
        ``limited`` = (pair A's thrust cut, pair B's thrust cut, the gap's request unreachable).
        """
        # aim a hair inside the limit, so that rounding never leaves a command above it
        pf, peak2 = self.platform, (self.peak_current * (1 - _LIMIT_SLACK)) ** 2
        gap, v = ca.SX.sym("gap"), ca.SX.sym("v", 3)
        k1, k2, k3, k4 = self._force_coefficients(gap)
        iqa = -pf.masses[0] * v[0] / (2 * k1)
        iqb = -pf.masses[1] * v[1] / (2 * k1)
        target = pf.masses[2] * (pf.gravity[2] - v[2]) / 4  # mean normal force per motor [N]
        a2, b2 = iqa**2, iqb**2

        def smaller_root(half_b, c_):
            """The physical root of k4 i^2 + 2 half_b i + c_ = 0 and whether it is real."""
            disc = half_b**2 - k4 * c_
            return (-half_b - ca.sqrt(ca.fmax(disc, 0))) / k4, disc >= 0

        id0, ok0 = smaller_root(k3 / 2, k2 + k4 * (a2 + b2) / 2 - target)
        ida, oka = smaller_root(k3, 2 * k2 + k4 * (peak2 + b2) - 2 * target)
        idb, okb = smaller_root(k3, 2 * k2 + k4 * (peak2 + a2) - 2 * target)
        idab = (target - k2 - k4 * peak2) / k3
        fits = lambda q2, i: q2 + i**2 <= peak2  # noqa: E731
        valid0 = ok0 * fits(a2, id0) * fits(b2, id0)
        valida = oka * (1 - fits(a2, ida)) * fits(b2, ida) * (ida**2 <= peak2)
        validb = okb * fits(a2, idb) * (1 - fits(b2, idb)) * (idb**2 <= peak2)
        validab = (1 - fits(a2, idab)) * (1 - fits(b2, idab)) * (idab**2 <= peak2)
        fallback = ca.fmin(ca.fmax(idab, -ca.sqrt(peak2)), ca.sqrt(peak2))
        i_d = ca.if_else(
            valid0, id0, ca.if_else(valida, ida, ca.if_else(validb, idb, ca.if_else(validab, idab, fallback)))
        )
        room = ca.sqrt(ca.fmax(peak2 - i_d**2, 0))
        qa = ca.sign(iqa) * ca.fmin(ca.fabs(iqa), room)
        qb = ca.sign(iqb) * ca.fmin(ca.fabs(iqb), room)
        unreachable = 1 - (valid0 + valida + validb + validab > 0)
        limited = ca.vertcat(ca.fabs(iqa) > room, ca.fabs(iqb) > room, unreachable)
        return ca.Function(
            "limiter", [gap, v], [ca.vertcat(qa, i_d, qb, i_d), limited], ["gap", "v"], ["u", "limited"]
        )

    def _force_coefficients(self, gap):
        """(k1, k2, k3, k4) of one motor at ``gap`` (thrust -k1 i_q, normal k2 + k3 i_d +
        k4 (i_q^2 + i_d^2), every motor alike)."""
        k = self.transformation.coefficients(gap)
        return k[0], k[1], k[2], k[3]

    def _margin_function(self) -> ca.Function:
        """(gap, v) -> -R / (dR/dv_gap) [m/s^2]: R is affine in v_gap, so this is how much further
        v_gap could rise before R = 0 (the 2-DOF regulator's R / (4 L4))."""
        gap, v = ca.SX.sym("gap"), ca.SX.sym("v", 3)
        _, R = self.transformation.function(gap, v)
        return ca.Function("margin", [gap, v], [-R / ca.jacobian(R, v)[2]])

    def initial_state(self, y0, r0=None, u0=None) -> np.ndarray:
        """The controller state (15,) at start: observers at the first reading at rest, internal
        models empty.

        Parameters
        ----------
        y0 : (3,) array
            First reading (x, y, gap) [m].
        r0, u0 : ignored
            For the engine's interface (first reference, currents flowing).

        Returns
        -------
        (15,) array
        """
        y0 = np.asarray(y0, dtype=float).ravel()
        if y0.shape != (N_MEASUREMENTS,):
            raise InputError(f"y0 must be the three readings (x, y, gap), got shape {y0.shape}")
        c0 = np.zeros(N_STATE)
        c0[0:6:2] = y0
        return c0
