"""Linear output regulators on the Jacobian linearization, scheduled on the set-point gap.

The papers' comparison (001 Sec. VI-A, 002 Sec. 7.1): "the model is linearized about equilibria
corresponding to the desired setpoints. For each linear model, the gains K_h, K_v are chosen so
that the poles of the closed-loop system coincide with the poles induced by the nonlinear
controller in the feedback-linearized plant", and the same internal models (21)-(22) are used,
without the feedback transformation. At an equilibrium (u1 = 0) the linearization decouples:

    vertical:   e1'' = a21(g) e1 + b22(g) du2,   a21 = d x2'/d x1,  b22 = d x2'/d u2
    horizontal: e2'' = -L1(g) du1

and the regulator is u = (0, u2_eq(g)) + (K_h(g) z_h, K_v(g) z_v) with g the reference gap r_v.
Gains are designed on a grid of gaps and interpolated (a set-point step uses the design at the
new set-point, as in the papers; a moving reference gives a gain-scheduled regulator).

:func:`paper_linear_regulator` places the poles of the printed gains; :mod:`maglev_oc.control.lqr`
designs the gains by LQR on the same linearization.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import ClassVar

import casadi as ca
import numpy as np

from maglev_oc.control.base import N_MEASUREMENTS, N_REFERENCE
from maglev_oc.control.gains import OMEGA0, PAPER_K_H, PAPER_K_V, axis_poles, place_axis
from maglev_oc.control.output_regulator import N_REGULATOR_STATE, RegulatorCore
from maglev_oc.errors import InputError
from maglev_oc.estimation.high_gain import DEFAULT_EPSILON
from maglev_oc.model.equilibrium import equilibrium_currents
from maglev_oc.model.hardware import RIG_SAMPLE_TIME
from maglev_oc.model.stage import StageModel

__all__ = [
    "SCHEDULE_GAPS",
    "AxisLinearization",
    "GainDesign",
    "ScheduledLinearRegulator",
    "axis_linearizations",
    "paper_linear_regulator",
    "schedule_gains",
]

SCHEDULE_GAPS = np.linspace(8e-3, 32e-3, 49)
"""Gaps [m] at which scheduled gains are designed (0.5 mm apart; linear interpolation between)."""


@dataclass(frozen=True)
class AxisLinearization:
    """Per-axis linearization at the equilibria of ``gap`` (arrays over the schedule).

    Attributes
    ----------
    gap : (n,) array
        [m].
    u2_eq : (n,) array
        Current added to the regulator's output [A] (equilibrium, or zero).
    stiffness_v : (n,) array
        a21 = d x2'/d x1 [1/s^2].
    gain_v : (n,) array
        b22 = d x2'/d u2 [m/(s^2 A)].
    gain_h : (n,) array
        b41 = -L1 [m/(s^2 A)].
    """

    gap: np.ndarray
    u2_eq: np.ndarray
    stiffness_v: np.ndarray
    gain_v: np.ndarray
    gain_h: np.ndarray


def axis_linearizations(model: StageModel, gaps=SCHEDULE_GAPS) -> AxisLinearization:
    """The Jacobian linearization of each axis at the equilibria of ``gaps``.

    Parameters
    ----------
    model : StageModel
    gaps : array_like
        Gaps [m]; every one must have an equilibrium.

    Returns
    -------
    AxisLinearization

    Raises
    ------
    ValueError
        Naming the gaps [mm] without an equilibrium.
    """
    gaps = np.asarray(gaps, dtype=float)
    curve = equilibrium_currents(model, gaps)
    if not np.all(curve.exists):
        bad = gaps[~curve.exists]
        raise InputError(f"no equilibrium at gap(s) {bad * 1e3} mm; cannot schedule there")
    n = gaps.size
    x = np.zeros((4, n))
    x[0] = gaps
    u = np.zeros((2, n))
    u[1] = curve.current
    a, b = (np.asarray(m) for m in model.jacobian.map(n)(x, u))
    a = a.reshape(4, n, 4)
    b = b.reshape(4, n, 2)
    return AxisLinearization(gaps, curve.current, a[1, :, 0], b[1, :, 1], b[3, :, 0])


GainDesign = Callable[[float, float, float], np.ndarray]
"""(stiffness, input_gain, gap) -> K (5,) for one axis."""


@dataclass(frozen=True, eq=False)
class ScheduledLinearRegulator:
    """u = (0, u2_eq(r_v)) + (K_h(r_v) z_h, K_v(r_v) z_v): an ExpressionController.

    Built by :func:`paper_linear_regulator` or :func:`maglev_oc.control.lqr.lqr_regulator`.

    Parameters
    ----------
    model : StageModel
    schedule : AxisLinearization
        The linearizations the gains were designed on.
    gains_h, gains_v : (5, n_gaps) array
        Gain tables over ``schedule.gap``.
    name : str
    sample_time : float
        [s].
    omega0 : float
        Internal-model frequency [rad/s].
    observer_epsilon : float
        High-gain observer time constant [s].
    design : dict
        How the gains were designed (poles, weights), for the reports.

    Attributes
    ----------
    step : casadi.Function
        (c (10), y (2), r (6)) -> (u (2) [A], c_next (10), diag (3)); ``diag`` is
        (clipped, du1, du2 [A]).
    """

    model: StageModel
    schedule: AxisLinearization
    gains_h: np.ndarray
    gains_v: np.ndarray
    name: str
    sample_time: float = RIG_SAMPLE_TIME
    omega0: float = OMEGA0
    observer_epsilon: float = DEFAULT_EPSILON
    design: dict = field(default_factory=dict)

    n_state: ClassVar[int] = N_REGULATOR_STATE
    diag_names: ClassVar[tuple[str, ...]] = ("clipped", "du1", "du2")

    def __post_init__(self) -> None:
        n = self.schedule.gap.size
        for label in ("gains_h", "gains_v"):
            g = np.asarray(getattr(self, label), dtype=float)
            if g.shape != (5, n) or not np.all(np.isfinite(g)):
                raise InputError(f"{label} must be a finite (5, {n}) table, got shape {g.shape}")
        core = RegulatorCore(self.sample_time, self.omega0, self.observer_epsilon)
        grid = [self.schedule.gap.tolist()]
        table = np.vstack(
            [
                self.gains_h,
                self.gains_v,
                self.schedule.u2_eq[None, :],
                self.schedule.stiffness_v[None, :],
                self.schedule.gain_v[None, :],
                self.schedule.gain_h[None, :],
            ]
        )
        interp = ca.interpolant("schedule", "linear", grid, table.ravel(order="F"))
        c = ca.SX.sym("c", self.n_state)
        y = ca.SX.sym("y", N_MEASUREMENTS)
        r = ca.SX.sym("r", N_REFERENCE)
        sig = core.signals(c, y, r)
        g_ref = ca.fmin(ca.fmax(r[0], grid[0][0]), grid[0][-1])
        row = interp(g_ref)
        k_h, k_v = row[0:5], row[5:10]
        u2_eq, a21, b22, b41 = row[10], row[11], row[12], row[13]
        du1 = ca.dot(k_h, sig.z_h)
        du2 = ca.dot(k_v, sig.z_v)
        u = ca.vertcat(du1, u2_eq + du2)
        # accelerations this linear model predicts, fed to the velocity observers
        acc_v = a21 * (y[0] - r[0]) + b22 * du2
        acc_h = b41 * du1
        c_next = core.next_state(c, y, r, acc_v, acc_h)
        diag = ca.vertcat(0, du1, du2)
        step = ca.Function(
            "linear_step", [c, y, r], [u, c_next, diag], ["c", "y", "r"], ["u", "c_next", "diag"]
        )
        object.__setattr__(self, "step", step)

    def initial_state(self, y0, r0, u0=None) -> np.ndarray:
        """The regulator state (10,) at start: observers at the first reading ``y0`` [m] at rest,
        internal models empty."""
        return RegulatorCore.initial_state(y0, r0)

    def gains_at(self, gap: float) -> tuple[np.ndarray, np.ndarray]:
        """The gains at a gap, interpolated in the schedule.

        Parameters
        ----------
        gap : float
            [m].

        Returns
        -------
        K_h, K_v : (5,) arrays
        """
        g = self.schedule.gap
        kh = np.array([np.interp(gap, g, row) for row in self.gains_h])
        kv = np.array([np.interp(gap, g, row) for row in self.gains_v])
        return kh, kv


def schedule_gains(lin: AxisLinearization, design_h: GainDesign, design_v: GainDesign):
    """Gain tables per axis from a per-point design function.

    Parameters
    ----------
    lin : AxisLinearization
    design_h, design_v : GainDesign
        (stiffness, input_gain, gap) -> K (5,) for the horizontal and the vertical axis.

    Returns
    -------
    gains_h, gains_v : (5, n) arrays
    """
    kh = np.column_stack([design_h(0.0, b, g) for b, g in zip(lin.gain_h, lin.gap, strict=True)])
    kv = np.column_stack(
        [design_v(a, b, g) for a, b, g in zip(lin.stiffness_v, lin.gain_v, lin.gap, strict=True)]
    )
    return kh, kv


def paper_linear_regulator(
    model: StageModel,
    K_h=PAPER_K_H,
    K_v=PAPER_K_V,
    *,
    feedforward: bool = True,
    omega0: float = OMEGA0,
    sample_time: float = RIG_SAMPLE_TIME,
    gaps=SCHEDULE_GAPS,
) -> ScheduledLinearRegulator:
    """The papers' linear output regulator: at every set-point gap, the closed-loop poles of
    the linearized plant coincide with those ``K_h``, ``K_v`` give the feedback-linearized plant.

    With ``feedforward`` the equilibrium current of the set-point is added to the regulator's
    output; without it the internal model has to build that current up from zero, as a
    regulator "without the feedback transformation" in the papers' words may have done. The
    papers do not say which; the comparison report runs both.

    Parameters
    ----------
    model : StageModel
    K_h, K_v : array_like (5,)
        Gains whose feedback-linearized poles are placed (default: the printed gains of 002).
    feedforward : bool
        Add the set-point's equilibrium current.
    omega0 : float
        Internal-model frequency [rad/s].
    sample_time : float
        [s].
    gaps : array_like
        Schedule [m].

    Returns
    -------
    ScheduledLinearRegulator
    """
    poles_h = axis_poles(K_h, omega0)
    poles_v = axis_poles(K_v, omega0)
    lin = axis_linearizations(model, gaps)
    if not feedforward:
        lin = AxisLinearization(lin.gap, np.zeros_like(lin.u2_eq), lin.stiffness_v, lin.gain_v, lin.gain_h)
    kh, kv = schedule_gains(
        lin,
        lambda a, b, g: place_axis(poles_h, omega0, a, b),
        lambda a, b, g: place_axis(poles_v, omega0, a, b),
    )
    name = "linear regulator" if feedforward else "linear regulator (no feedforward)"
    return ScheduledLinearRegulator(
        model,
        lin,
        kh,
        kv,
        name,
        sample_time,
        omega0,
        design={"poles_h": poles_h, "poles_v": poles_v, "feedforward": feedforward},
    )
