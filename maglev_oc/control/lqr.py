"""LQR with the internal model on the exact (Jacobian) linearization, scheduled on the set-point.

Per axis the design model is the augmented system of :func:`maglev_oc.control.gains.augmented_axis`
(e'' = a21 e + b w, xi' = phi xi + N e) at the equilibrium of the set-point gap; the internal
model gives integral action against constant disturbances (friction offsets, guide
misalignment, model mismatch) and rejects the omega0 sinusoid. The gain minimises

    J = int  (e/e_max)^2 + (e'/de_max)^2 + (xi1/xi_max)^2 + ... + (du/du_max)^2  dt

(Bryson's rule). The default maxima give a closed loop about as fast as the papers' regulators;
see :data:`DEFAULT_WEIGHTS`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_continuous_are

from maglev_oc.control.gains import OMEGA0, augmented_axis
from maglev_oc.control.linear_regulator import (
    SCHEDULE_GAPS,
    ScheduledLinearRegulator,
    axis_linearizations,
    schedule_gains,
)
from maglev_oc.errors import InputError
from maglev_oc.model.hardware import RIG_SAMPLE_TIME
from maglev_oc.model.stage import StageModel

__all__ = ["DEFAULT_WEIGHTS", "AxisWeights", "axis_lqr", "lqr_regulator"]


@dataclass(frozen=True)
class AxisWeights:
    """Bryson maxima for one axis.

    Parameters
    ----------
    error : float
        [m].
    error_rate : float
        [m/s].
    internal_model : (float, float, float)
        xi1 [m s^3], xi2 [m s^2], xi3 [m s].
    current : float
        [A].
    """

    error: float
    error_rate: float
    internal_model: tuple[float, float, float]
    current: float

    def __post_init__(self) -> None:
        if len(self.internal_model) != 3:
            raise InputError(f"internal_model must hold 3 maxima, got {self.internal_model!r}")
        for name in ("error", "error_rate", "internal_model", "current"):
            value = getattr(self, name)
            values = np.atleast_1d(np.asarray(value, dtype=float))
            if not np.all(np.isfinite(values) & (values > 0)):
                raise InputError(f"Bryson maxima must be positive and finite: {name} = {value!r}")

    def matrices(self) -> tuple[np.ndarray, np.ndarray]:
        """(Q (5, 5), R (1, 1)): the inverse squared maxima on the diagonals."""
        scales = np.array([self.error, self.error_rate, *self.internal_model], dtype=float)
        return np.diag(1.0 / scales**2), np.array([[1.0 / self.current**2]])


DEFAULT_WEIGHTS = {
    # Bryson maxima searched on a grid (bench-free: 1 ms per design) for the fastest 1 % step
    # settling of the linear closed loop at 20 mm with no more overshoot than the papers'
    # regulator (45 %) and no more current per metre of error than it spends (horizontal
    # 220 A/m; vertical 1100 A/m, the least that mirrors the +39 1/s open-loop pole with margin).
    # Result at 20 mm: vertical poles -4.5 +- 9.0j, -9.2, -35.9, -43.2 (38 % overshoot, 0.80 s);
    # horizontal -3.5, -9.1 +- 11.0j, -9.6, -32.3 (45 %, 0.91 s). The papers' regulator with the
    # printed gains: 45 % / 0.89 s vertical, 42 % / 1.08 s horizontal.
    "vertical": AxisWeights(2e-2, 0.5, (3e-6, 1e-4, 1e-3), 1.0),
    "horizontal": AxisWeights(2e-2, 0.2, (3e-5, 1e-4, 1e-3), 1.0),
}


def axis_lqr(weights: AxisWeights, stiffness: float, input_gain: float, omega0: float = OMEGA0) -> np.ndarray:
    """The LQR gain of one augmented axis (continuous-time ARE).

    Parameters
    ----------
    weights : AxisWeights
    stiffness, input_gain : float
        The axis, as in :func:`~maglev_oc.control.gains.augmented_axis`.
    omega0 : float
        Internal-model frequency [rad/s].

    Returns
    -------
    (5,) array
        K for w = K z minimising the axis cost.
    """
    a, b = augmented_axis(omega0, stiffness, input_gain)
    q, r = weights.matrices()
    p = solve_continuous_are(a, b, q, r)
    return -(np.linalg.solve(r, b.T @ p)).ravel()


def lqr_regulator(
    model: StageModel,
    weights: dict[str, AxisWeights] | None = None,
    *,
    omega0: float = OMEGA0,
    sample_time: float = RIG_SAMPLE_TIME,
    gaps=SCHEDULE_GAPS,
) -> ScheduledLinearRegulator:
    """LQR + internal model on the Jacobian linearization at each set-point gap.

    Parameters
    ----------
    model : StageModel
    weights : dict, optional
        {"horizontal": AxisWeights, "vertical": AxisWeights} (default :data:`DEFAULT_WEIGHTS`).
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
    w = dict(DEFAULT_WEIGHTS if weights is None else weights)
    unknown = set(w) - {"horizontal", "vertical"}
    if unknown:
        raise InputError(f"weights keys must be 'horizontal' and 'vertical', got {sorted(unknown)}")
    lin = axis_linearizations(model, gaps)
    kh, kv = schedule_gains(
        lin,
        lambda a, b, g: axis_lqr(w["horizontal"], a, b, omega0),
        lambda a, b, g: axis_lqr(w["vertical"], a, b, omega0),
    )
    return ScheduledLinearRegulator(model, lin, kh, kv, "LQR", sample_time, omega0, design={"weights": w})
