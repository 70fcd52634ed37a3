"""The PID regulators the papers used to excite the rig for identification (000 Sec. IV, 002 Sec. 5).

Two independent PIDs, one per axis, on the encoder errors with derivatives from the high-gain
observers: i_d on the gap error, i_q on the horizontal error. They know nothing of the coupling
("because the horizontal and vertical dynamics of the system are not decoupled, PID control does
not yield good tracking performance", 000 footnote 2). The integrator of the vertical PID carries
the levitation current; it starts at the current already flowing (bumpless start).

Gains come from pole placement on the linearization at a design gap (default 20 mm):
e'' = a e + b du with du = -(Kp e + Kd e' + Ki int e) gives s^3 + b Kd s^2 + (b Kp - a) s + b Ki.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import casadi as ca
import numpy as np

from maglev_oc.control.base import N_MEASUREMENTS, N_REFERENCE
from maglev_oc.control.linear_regulator import axis_linearizations
from maglev_oc.errors import InputError
from maglev_oc.estimation.high_gain import DEFAULT_EPSILON, HighGainObserver
from maglev_oc.model.hardware import RIG_SAMPLE_TIME
from maglev_oc.model.stage import StageModel

__all__ = ["DEFAULT_POLES", "PidGains", "PidRegulator", "paper_pid", "place_pid"]

DEFAULT_POLES = {"vertical": (-30.0, -30.0, -30.0), "horizontal": (-20.0, -20.0, -20.0)}
"""Triple poles [1/s]. The PID has no internal model of the omega0 sinusoid: the closed loop
from reference to output at omega0 = 1.5 pi is 1.04/6 deg (vertical, at 20 mm) and 1.008/0.5
deg (horizontal), so on the ellipse it tracks with about 0.85 mm and 0.19 mm mean error, the
papers' PID figures (0.9 and 0.19 mm, 001 Sec. VI-B). Slower poles track much worse (a triple
pole at -25 doubles the vertical error; PID zeros on an unstable plant amplify the reference)."""


@dataclass(frozen=True)
class PidGains:
    """Gains of one PID, du = -(kp e + kd e' + ki int e).

    Parameters
    ----------
    kp : float
        [A/m].
    ki : float
        [A/(m s)].
    kd : float
        [A s/m].
    """

    kp: float
    ki: float
    kd: float


def place_pid(poles, stiffness: float, input_gain: float) -> PidGains:
    """PID gains placing the three closed-loop poles of e'' = a e + b du.

    Parameters
    ----------
    poles : array_like
        Three poles [1/s].
    stiffness : float
        a [1/s^2].
    input_gain : float
        b [m/(s^2 A)].

    Returns
    -------
    PidGains
    """
    c = np.real(np.poly(np.asarray(poles, dtype=complex)))
    if c.size != 4:
        raise InputError(f"need 3 poles, got {poles!r}")
    _, c2, c1, c0 = c
    b = input_gain
    return PidGains(kp=(c1 + stiffness) / b, ki=c0 / b, kd=c2 / b)


@dataclass(frozen=True, eq=False)
class PidRegulator:
    """Two PIDs (an ExpressionController). State: observers (4) and integrators (2).

    Parameters
    ----------
    model : StageModel
    vertical, horizontal : PidGains
        On the gap error (i_d) and the horizontal error (i_q).
    sample_time : float
        [s].
    observer_epsilon : float
        High-gain observer time constant [s].
    name : str
    design : dict
        How the gains were designed, for the reports.

    Attributes
    ----------
    step : casadi.Function
        (c (6), y (2), r (6)) -> (u (2) [A], c_next (6), diag (1)).
    """

    model: StageModel
    vertical: PidGains
    horizontal: PidGains
    sample_time: float = RIG_SAMPLE_TIME
    observer_epsilon: float = DEFAULT_EPSILON
    name: str = "PID"
    design: dict = field(default_factory=dict)

    n_state: ClassVar[int] = 6
    diag_names: ClassVar[tuple[str, ...]] = ("clipped",)

    def __post_init__(self) -> None:
        obs = HighGainObserver(self.sample_time, self.observer_epsilon)
        ts = self.sample_time
        c = ca.SX.sym("c", self.n_state)
        y = ca.SX.sym("y", N_MEASUREMENTS)
        r = ca.SX.sym("r", N_REFERENCE)
        e1, e2 = y[0] - r[0], y[1] - r[3]
        e1d, e2d = c[1] - r[1], c[3] - r[4]
        gv, gh = self.vertical, self.horizontal
        u2 = c[4] - gv.kp * e1 - gv.kd * e1d
        u1 = c[5] - gh.kp * e2 - gh.kd * e2d
        c_next = ca.vertcat(
            obs.step(c[0:2], y[0]),
            obs.step(c[2:4], y[1]),
            c[4] - ts * gv.ki * e1,
            c[5] - ts * gh.ki * e2,
        )
        step = ca.Function(
            "pid_step",
            [c, y, r],
            [ca.vertcat(u1, u2), c_next, ca.SX(0)],
            ["c", "y", "r"],
            ["u", "c_next", "diag"],
        )
        object.__setattr__(self, "step", step)

    def initial_state(self, y0, r0, u0=(0.0, 0.0)) -> np.ndarray:
        """The state (6,) at start: observers at the first reading ``y0`` [m] at rest, the
        integrators holding the current ``u0`` [A] already flowing (bumpless start)."""
        y0 = np.asarray(y0, dtype=float).ravel()
        u0 = np.asarray(u0, dtype=float).ravel()
        return np.array([y0[0], 0.0, y0[1], 0.0, u0[1], u0[0]])


def paper_pid(
    model: StageModel,
    poles: dict[str, tuple[float, ...]] | None = None,
    *,
    design_gap: float = 20e-3,
    sample_time: float = RIG_SAMPLE_TIME,
) -> PidRegulator:
    """PIDs placed at ``poles`` on the linearization at ``design_gap``.

    Parameters
    ----------
    model : StageModel
    poles : dict, optional
        {"vertical": 3 poles, "horizontal": 3 poles} [1/s] (default :data:`DEFAULT_POLES`).
    design_gap : float
        [m].
    sample_time : float
        [s].

    Returns
    -------
    PidRegulator
    """
    p = dict(DEFAULT_POLES if poles is None else poles)
    lin = axis_linearizations(model, [design_gap])
    vertical = place_pid(p["vertical"], float(lin.stiffness_v[0]), float(lin.gain_v[0]))
    horizontal = place_pid(p["horizontal"], 0.0, float(lin.gain_h[0]))
    return PidRegulator(
        model, vertical, horizontal, sample_time, design={"poles": p, "design_gap": design_gap}
    )
