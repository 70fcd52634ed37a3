"""The feedback-linearizing output regulator of papers 001/002.

    v1 = K_h (e2, e2', xi_h),   v2 = K_v (e1, e1', xi_v)           (23), (24) of 002
    xi' = phi xi + N e (per axis)                                    (21), (22)
    u = feedback transformation (13)-(16) at the measured gap        (corrected root, SPEC 1)

Where R(x1, v1, v2) < 0 the transformation has no real solution; the controller then uses
sqrt(max(R, 0)) (the closest realisable i_d: the largest repulsive action it can command),
flags the sample (``clipped`` = 1) and never produces NaN. The engine counts these events.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import casadi as ca
import numpy as np

from maglev_oc.control.base import N_MEASUREMENTS, N_REFERENCE
from maglev_oc.control.gains import OMEGA0, PAPER_K_H, PAPER_K_V, checked_gains
from maglev_oc.control.output_regulator import N_REGULATOR_STATE, RegulatorCore
from maglev_oc.errors import InputError
from maglev_oc.estimation.high_gain import DEFAULT_EPSILON
from maglev_oc.model.feedback import transformation_expressions
from maglev_oc.model.hardware import RIG_SAMPLE_TIME
from maglev_oc.model.stage import StageModel

__all__ = ["FeedbackLinearizingRegulator"]


@dataclass(frozen=True, eq=False)
class FeedbackLinearizingRegulator:
    """The papers' nonlinear controller as one CasADi step Function (built once).

    Parameters
    ----------
    model : StageModel
        The controller's model (its constants may differ from the plant's).
    K_h, K_v : array (5,)
        Gains on (e, e', xi1, xi2, xi3) per axis (default: the printed gains of 002).
    sample_time : float
        [s], default 2e-4 (5 kHz).
    omega0 : float
        Internal-model frequency [rad/s] (default 1.5 pi).
    observer_epsilon : float
        High-gain observer time constant [s].
    compensation : casadi.Function, optional
        An identified extra acceleration d(x) (x (4) -> (x2', x4') [m/s^2]) the model lacks,
        e.g. from ``maglev-oc diagnose``; the transformation is then asked for v - d so that
        the plant with the effect still sees v. Evaluated at the measured positions and the
        observers' velocities.
    name : str

    Attributes
    ----------
    step : casadi.Function
        (c (10), y (2), r (6)) -> (u (2) [A], c_next (10), diag (4)); ``diag`` is
        (margin [m/s^2], clipped, v1, v2 [m/s^2]).
    """

    model: StageModel
    K_h: np.ndarray = field(default_factory=PAPER_K_H.copy)
    K_v: np.ndarray = field(default_factory=PAPER_K_V.copy)
    sample_time: float = RIG_SAMPLE_TIME
    omega0: float = OMEGA0
    observer_epsilon: float = DEFAULT_EPSILON
    compensation: ca.Function | None = None
    name: str = "FL regulator"

    n_state: ClassVar[int] = N_REGULATOR_STATE
    diag_names: ClassVar[tuple[str, ...]] = ("margin", "clipped", "v1", "v2")

    def __post_init__(self) -> None:
        for label in ("K_h", "K_v"):
            object.__setattr__(self, label, checked_gains(getattr(self, label), label))
        core = RegulatorCore(self.sample_time, self.omega0, self.observer_epsilon)
        object.__setattr__(self, "core", core)
        c = ca.SX.sym("c", self.n_state)
        y = ca.SX.sym("y", N_MEASUREMENTS)
        r = ca.SX.sym("r", N_REFERENCE)
        sig = core.signals(c, y, r)
        v1 = ca.dot(ca.DM(self.K_h), sig.z_h)
        v2 = ca.dot(ca.DM(self.K_v), sig.z_v)
        v = ca.vertcat(v1, v2)
        v_ask = v
        if self.compensation is not None:
            if self.compensation.size1_in(0) != 4 or self.compensation.size1_out(0) != 2:
                raise InputError("compensation must map x (4) -> (x2', x4') (2)")
            x_hat = ca.vertcat(y[0], c[1], y[1], c[3])
            d = self.compensation(x_hat)
            v_ask = ca.vertcat(v1 - d[1], v2 - d[0])
        R, _, u = transformation_expressions(self.model, sig.gap, v_ask)
        L4 = self.model.L(sig.gap)[3]
        margin = R / (4 * L4)
        clipped = R < 0
        c_next = core.next_state(c, y, r, v2, v1)
        diag = ca.vertcat(margin, clipped, v1, v2)
        step = ca.Function("fl_step", [c, y, r], [u, c_next, diag], ["c", "y", "r"], ["u", "c_next", "diag"])
        object.__setattr__(self, "step", step)

    def initial_state(self, y0, r0, u0=None) -> np.ndarray:
        """The regulator state (10,) at start: observers at the first reading ``y0`` [m] at rest,
        internal models empty (``r0`` and ``u0`` are not needed)."""
        return RegulatorCore.initial_state(y0, r0)
