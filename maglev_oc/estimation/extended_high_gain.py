"""Extended high-gain observer: position, velocity and a constant disturbance per axis.

No velocity is measured on the rig. Each axis has the papers' high-gain observer
(:class:`~maglev_oc.estimation.high_gain.HighGainObserver`, poles at -1/eps), driven by the model
acceleration at the commanded current plus the disturbance estimate, and the disturbance is a
third, slow observer state integrating the position innovation:

    (p, q)[k+1] = Ad (p, q)[k] + By y[k] + Ba (a_model(y, u[k]) + d[k])
    d[k+1]      = d[k] + w_d (alpha2 / eps^2) int_{sample} (y[k] - p(t)) dt

(the integral of the innovation over the sample, exact for the held reading). At steady state
the innovation is d_err eps^2 / alpha2, so d converges with rate w_d (time-scale separation:
w_d << 1/eps). d is clipped to +-``limit`` (anti-windup).

The disturbance is an acceleration d = (d_v, d_h) [m/s^2] added to the model's x2' and x4'
(SPEC 1; 001 Sec. V models the friction and misalignment the same way, as constant Delta_1,
Delta_2 on x4', x2'). The NMPC (:mod:`maglev_oc.control.nmpc`) uses the estimate for offset-free
tracking: at a steady state of the closed loop d is constant, so y = p and the model with d is
at rest at the measured position (Pannocchia & Rawlings' offset-free argument).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
from scipy.linalg import expm

from maglev_oc.errors import InputError
from maglev_oc.estimation.high_gain import DEFAULT_EPSILON, HighGainObserver
from maglev_oc.model.stage import StageModel

__all__ = [
    "DEFAULT_DISTURBANCE_BANDWIDTH",
    "DEFAULT_DISTURBANCE_LIMIT",
    "N_DISTURBANCE",
    "N_OBSERVER_STATE",
    "ExtendedHighGainObserver",
]

N_OBSERVER_STATE = 4
"""Observer state (p_v, q_v, p_h, q_h): position [m] and velocity [m/s] estimates per axis."""
N_DISTURBANCE = 2
"""Disturbance estimate (d_v, d_h) [m/s^2]."""
DEFAULT_DISTURBANCE_BANDWIDTH = 30.0
"""w_d [rad/s]: disturbance estimate time constant 33 ms, comparable to the NMPC's closed loop."""
DEFAULT_DISTURBANCE_LIMIT = 5.0
"""|d| clip [m/s^2]: 8x the largest friction of the rig twin (1.5 N / 4.35 kg = 0.34 m/s^2
vertically, 1 N / 1.594 kg = 0.63 m/s^2 horizontally), half of gravity."""


class ExtendedHighGainObserver:
    """Per-axis high-gain observer (position, velocity) plus a disturbance state (module doc).

    The (p, q) update is :class:`HighGainObserver`'s exact ZOH discretization. The disturbance
    integrates the observer's innovation over the sample, exactly (an augmented matrix
    exponential), not the innovation at the sample instant: the observer sees the encoder
    reading held over the sample, so at the sampling instants its position estimate lags a
    moving stage by v Ts / 2 (14 um at the ellipse's 0.14 m/s), and a rectangle-rule integral
    of that lag would read as a disturbance of (v Ts / 2) alpha2 / eps^2 = 3.5 m/s^2. The
    exact integral of the innovation over a sample is zero for a ramp in steady state.

    Parameters
    ----------
    model : StageModel
        The model whose acceleration drives the observer.
    sample_time : float
        Sample period [s].
    epsilon : float
        High-gain observer time constant [s] (poles at -1/eps).
    bandwidth : float
        w_d [rad/s] of the disturbance estimate; 0 switches it off (d stays at its start).
    limit : float
        |d| clip [m/s^2].
    effects : casadi.Function, optional
        (x (4), i (2)) -> (x2', x4') [m/s^2] added to the model's accelerations (found effects
        that the model carries, so that the disturbance estimate is only what remains).

    Attributes
    ----------
    observer : HighGainObserver
        The (p, q) observer of each axis.
    gain : float
        w_d alpha2 / eps^2 [1/s^3]: continuous d' = gain (y - p).
    """

    def __init__(
        self,
        model: StageModel,
        sample_time: float,
        epsilon: float = DEFAULT_EPSILON,
        bandwidth: float = DEFAULT_DISTURBANCE_BANDWIDTH,
        limit: float = DEFAULT_DISTURBANCE_LIMIT,
        effects: ca.Function | None = None,
    ) -> None:
        if not (bandwidth >= 0 and math.isfinite(bandwidth)):
            raise InputError(f"bandwidth must be >= 0 [rad/s], got {bandwidth!r}")
        if not (limit > 0 and math.isfinite(limit)):
            raise InputError(f"limit must be positive [m/s^2], got {limit!r}")
        self.observer = HighGainObserver(sample_time, epsilon)
        self.model = model
        self.effects = effects
        self.limit = limit
        a1, a2 = self.observer.alpha
        self.gain = bandwidth * a2 / epsilon**2
        # [p, q, I]' with I' = y - p, inputs (y, a) held over the sample
        m = np.zeros((5, 5))
        m[0:2, 0:2] = [[-a1 / epsilon, 1.0], [-a2 / epsilon**2, 0.0]]
        m[0:2, 3:5] = [[a1 / epsilon, 0.0], [a2 / epsilon**2, 1.0]]
        m[2, 0] = -1.0
        m[2, 3] = 1.0
        e = expm(m * sample_time)
        if not (
            np.allclose(e[0:2, 0:2], self.observer.Ad)
            and np.allclose(e[0:2, 3:5], np.hstack([self.observer.By, self.observer.Ba]))
        ):
            raise RuntimeError("HighGainObserver's discretization is not the one assumed here")
        self._integral_state = e[2, 0:2]  # I(Ts) = F_x (p, q) + F_y y + F_a a
        self._integral_y = float(e[2, 3])
        self._integral_a = float(e[2, 4])

    @staticmethod
    def state_estimate(obs, y):
        """The state estimate x^ = (y_1, q_v, y_2, q_h): encoder positions, observer velocities.

        Parameters
        ----------
        obs : (4,) CasADi or array
            Observer state (p_v, q_v, p_h, q_h) [m, m/s].
        y : (2,) CasADi or array
            Encoder reading (gap, horizontal position) [m].

        Returns
        -------
        CasADi column (4,)
            (x1, x2, x3, x4) [m, m/s, m, m/s].
        """
        return ca.vertcat(y[0], obs[1], y[1], obs[3])

    def _innovation_integral(self, xhat, y, acc):
        return ca.dot(ca.DM(self._integral_state), xhat) + self._integral_y * y + self._integral_a * acc

    def update(self, obs, d, y, u):
        """One sample of the observer, symbolically.

        Parameters
        ----------
        obs : (4,) CasADi
            Observer state (p_v, q_v, p_h, q_h) [m, m/s].
        d : (2,) CasADi
            Disturbance estimate (d_v, d_h) [m/s^2].
        y : (2,) CasADi
            Encoder reading (gap, horizontal position) [m] at this sample.
        u : (2,) CasADi
            Current (i_q, i_d) [A] applied over the sample.

        Returns
        -------
        obs_next : CasADi column (4,)
            Observer state at the next sample.
        d_next : CasADi column (2,)
            Disturbance estimate at the next sample, clipped to +-``limit``.
        """
        x_hat = self.state_estimate(obs, y)
        acc = self.model.f(x_hat, u)
        if self.effects is not None:
            e = self.effects(x_hat, u)
            acc = acc + ca.vertcat(0, e[0], 0, e[1])
        a_v = acc[1] + d[0]
        a_h = acc[3] + d[1]
        pv = self.observer.step(obs[0:2], y[0], a_v)
        ph = self.observer.step(obs[2:4], y[1], a_h)
        d_next = d + self.gain * ca.vertcat(
            self._innovation_integral(obs[0:2], y[0], a_v), self._innovation_integral(obs[2:4], y[1], a_h)
        )
        d_next = ca.fmin(ca.fmax(d_next, -self.limit), self.limit)
        return ca.vertcat(pv, ph), d_next

    def error_dynamics(self) -> np.ndarray:
        """Transition matrix of one axis's estimator with the plant held still at 0.

        Returns
        -------
        (3, 3) array
            On (p^, q^, d^); its eigenvalues are the estimator's poles, the observer pair near
            exp(-Ts / eps) and the disturbance pole near exp(-w_d Ts).
        """
        o = self.observer
        m = np.zeros((3, 3))
        m[0:2, 0:2] = o.Ad
        m[0:2, 2] = o.Ba[:, 0]
        m[2, 0:2] = self.gain * self._integral_state
        m[2, 2] = 1.0 + self.gain * self._integral_a
        return m
