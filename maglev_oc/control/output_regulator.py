"""Pieces shared by the output regulators: internal models, velocity observers and tracking errors.

The papers' regulator (001 eqs. (5)-(7), 002 eqs. (21)-(24)) feeds the tracking errors
e = (x1 - r_v, x3 - r_h) into two copies of the internal model xi' = phi xi + N e and feeds back
z = (e, e', xi) per axis. On the rig, e' comes from high-gain observers (002 Sec. 4). Sampled at
the controller period with a zero-order hold, the internal model is discretized exactly.

Controller state layout (10): (p_v, q_v, p_h, q_h, xi_v (3), xi_h (3)) with (p, q) the observer's
position and velocity estimates per axis.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
from scipy.linalg import expm

from maglev_oc.control.gains import OMEGA0, internal_model
from maglev_oc.estimation.high_gain import DEFAULT_EPSILON, HighGainObserver

__all__ = ["N_REGULATOR_STATE", "RegulatorCore", "RegulatorSignals", "discrete_internal_model"]

N_REGULATOR_STATE = 10
"""Entries of the regulator state (module docstring)."""


def discrete_internal_model(omega0: float, sample_time: float) -> tuple[np.ndarray, np.ndarray]:
    """The internal model sampled with a zero-order hold (exact).

    Parameters
    ----------
    omega0 : float
        [rad/s].
    sample_time : float
        [s].

    Returns
    -------
    Phi_d : (3, 3) array
    Gamma_d : (3, 1) array
        xi[k+1] = Phi_d xi[k] + Gamma_d e[k].
    """
    phi, n, _ = internal_model(omega0)
    m = np.zeros((4, 4))
    m[:3, :3] = phi
    m[:3, 3:] = n
    e = expm(m * sample_time)
    return e[:3, :3], e[:3, 3:4]


@dataclass(frozen=True)
class RegulatorSignals:
    """Symbolic quantities of one regulator update (CasADi SX).

    Attributes
    ----------
    z_v : SX (5,)
        (e1, e1', xi_v): vertical error [m], its rate [m/s], internal model.
    z_h : SX (5,)
        (e2, e2', xi_h): horizontal error [m], its rate [m/s], internal model.
    gap : SX
        Measured gap y1 [m].
    """

    z_v: ca.SX
    z_h: ca.SX
    gap: ca.SX


class RegulatorCore:
    """Builds the observer and internal-model updates for an output regulator.

    Parameters
    ----------
    sample_time : float
        Controller period [s].
    omega0 : float
        Internal-model frequency [rad/s].
    observer_epsilon : float
        High-gain observer time constant [s].
    """

    def __init__(
        self,
        sample_time: float,
        omega0: float = OMEGA0,
        observer_epsilon: float = DEFAULT_EPSILON,
    ) -> None:
        self.sample_time = float(sample_time)
        self.omega0 = float(omega0)
        self.observer = HighGainObserver(self.sample_time, observer_epsilon)
        self.phi_d, self.gamma_d = discrete_internal_model(self.omega0, self.sample_time)

    def signals(self, c: ca.SX, y: ca.SX, r: ca.SX) -> RegulatorSignals:
        """The fed-back vectors z_v, z_h and the measured gap, from the state c (10), the
        reading y (2) [m] and the reference r (6)."""
        e1 = y[0] - r[0]
        e2 = y[1] - r[3]
        e1d = c[1] - r[1]
        e2d = c[3] - r[4]
        z_v = ca.vertcat(e1, e1d, c[4:7])
        z_h = ca.vertcat(e2, e2d, c[7:10])
        return RegulatorSignals(z_v, z_h, y[0])

    def next_state(self, c: ca.SX, y: ca.SX, r: ca.SX, acc_v, acc_h) -> ca.SX:
        """Observer update with the accelerations the controller expects (acc_v, acc_h) and the
        internal-model update with the current errors."""
        obs = self.observer
        pv = obs.step(c[0:2], y[0], acc_v)
        ph = obs.step(c[2:4], y[1], acc_h)
        xi_v = ca.mtimes(ca.DM(self.phi_d), c[4:7]) + ca.DM(self.gamma_d) * (y[0] - r[0])
        xi_h = ca.mtimes(ca.DM(self.phi_d), c[7:10]) + ca.DM(self.gamma_d) * (y[1] - r[3])
        return ca.vertcat(pv, ph, xi_v, xi_h)

    @staticmethod
    def initial_state(y0, r0) -> np.ndarray:
        """Observer at the first reading at rest, internal models empty (xi = 0)."""
        y0 = np.asarray(y0, dtype=float).ravel()
        return np.array([y0[0], 0.0, y0[1], 0.0, 0, 0, 0, 0, 0, 0], dtype=float)
