"""Pole placement for the per-axis augmented system of the output regulator (001 eq. (7); 002 (21)-(25)).

After the feedback transformation each axis is a double integrator e'' = v (plus a constant or
omega0-sinusoidal disturbance). The internal model (21)/(22) of paper 002,

    xi' = phi xi + N e,   phi = [[0, 1, 0], [0, 0, 1], [0, -omega0^2, 0]],   N = [0, 0, 1]^T,

contains the exosystem's modes (0, +-j omega0). The per-axis augmented state is
z = (e, e', xi1, xi2, xi3) and the regulator is v = K z with K = [k_e, k_de, k_xi1, k_xi2, k_xi3]
(the printed gains have five entries in this order: -k_de is the sum of the poles and -k_xi1
their product). The closed loop z' = (A + B K) z has characteristic polynomial

    (s^2 - k_de s - k_e)(s^3 + omega0^2 s) - (k_xi3 s^2 + k_xi2 s + k_xi1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

OMEGA0 = 1.5 * math.pi
"""Exosystem frequency of the papers [rad/s] (001, 002: omega0 = 1.5 pi)."""


def internal_model(omega0: float = OMEGA0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(phi, N, Gamma) of eqs. (21)-(22) of 002."""
    phi = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, -(omega0**2), 0.0]])
    n = np.array([[0.0], [0.0], [1.0]])
    gamma = np.array([[1.0, 0.0, 0.0]])
    return phi, n, gamma


def checked_gains(value, label: str) -> np.ndarray:
    """``value`` as five finite gains (5,), or ``ValueError`` naming ``label``."""
    k = np.asarray(value, dtype=float).ravel()
    if k.shape != (5,) or not np.all(np.isfinite(k)):
        raise ValueError(f"{label} must be 5 finite gains, got {value!r}")
    return k


def augmented_axis(
    omega0: float = OMEGA0, stiffness: float = 0.0, input_gain: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """(A, B) of the per-axis augmented system in z = (e, e', xi1, xi2, xi3).

    The axis is e'' = stiffness * e + input_gain * w. After the feedback transformation
    stiffness = 0 and input_gain = 1 (w = v, the papers' design); for the linear regulator on
    the Jacobian linearization, stiffness = d x2'/d x1 and input_gain = d x2'/d u2 (vertical) or
    0 and -L1 (horizontal).
    """
    if not (np.isfinite(input_gain) and input_gain != 0):
        raise ValueError(f"input_gain must be finite and nonzero, got {input_gain!r}")
    phi, n, _ = internal_model(omega0)
    a = np.zeros((5, 5))
    a[0, 1] = 1.0
    a[1, 0] = stiffness
    a[2:, 2:] = phi
    a[2:, 0:1] = n
    b = np.zeros((5, 1))
    b[1, 0] = input_gain
    return a, b


def place_axis(poles, omega0: float = OMEGA0, stiffness: float = 0.0, input_gain: float = 1.0) -> np.ndarray:
    """Gains K (5,) with eig(A + B K) = ``poles`` for the augmented axis (Ackermann's formula).

    ``poles`` must be five values closed under complex conjugation, in the open left half plane.
    ``stiffness`` and ``input_gain`` describe the axis as in :func:`augmented_axis`.
    """
    poles = np.asarray(poles, dtype=complex).ravel()
    if poles.size != 5:
        raise ValueError(f"need 5 poles for the augmented axis, got {poles.size}")
    if np.any(poles.real >= 0):
        raise ValueError(f"poles must lie in the open left half plane, got {poles}")
    coeffs = np.poly(poles)
    if np.max(np.abs(coeffs.imag)) > 1e-9 * np.max(np.abs(coeffs)):
        raise ValueError(f"poles must be closed under complex conjugation, got {poles}")
    coeffs = coeffs.real
    a, b = augmented_axis(omega0, stiffness, input_gain)
    ctrb = np.hstack([np.linalg.matrix_power(a, k) @ b for k in range(5)])
    phi_a = sum(c * np.linalg.matrix_power(a, 5 - k) for k, c in enumerate(coeffs))
    last_row = np.linalg.solve(ctrb.T, np.eye(5)[:, -1])  # e_n^T ctrb^{-1}
    k_ackermann = last_row @ phi_a  # u = -k x places the poles
    return -k_ackermann


def axis_poles(gains, omega0: float = OMEGA0, stiffness: float = 0.0, input_gain: float = 1.0) -> np.ndarray:
    """Closed-loop poles of the augmented axis under w = K z, sorted by real part, then imag."""
    a, b = augmented_axis(omega0, stiffness, input_gain)
    k = np.asarray(gains, dtype=float).reshape(1, 5)
    ev = np.linalg.eigvals(a + b @ k)
    return ev[np.lexsort((ev.imag, -ev.real))]


@dataclass(frozen=True)
class PaperGains:
    """A gain vector printed in the papers with the poles it was placed at."""

    name: str
    poles: tuple[complex, ...]
    printed: tuple[float, ...]
    source: str


PAPER_GAINS: dict[str, PaperGains] = {
    "K_h": PaperGains(
        "K_h",
        (-9, -10, -11, -12, -13),
        (-1182, -55, -154440, -45128, -11924),
        "002 Sec. 7.1 (also 001 Sec. VI-A): horizontal axis",
    ),
    "K_v": PaperGains(
        "K_v",
        (-11, -12, -13, -14, -15),
        (-1662, -65, -360360, -103350, -20332),
        "002 Sec. 7.1 (also 001 Sec. VI-A): vertical axis",
    ),
    "K_v_retuned": PaperGains(
        "K_v_retuned",
        (-57.9, -9.9 + 11.3j, -9.9 - 11.3j, -1.6 + 1.4j, -1.6 - 1.4j),
        (-1592, -81, -55736, -11573, -15825),
        "002 Sec. 7.1: vertical axis retuned for less overshoot (poles printed to 0.1)",
    ),
}
PAPER_K_H = np.array(PAPER_GAINS["K_h"].printed, dtype=float)
"""The printed horizontal gains K_h (002 Sec. 7.1), the regulators' default."""
PAPER_K_V = np.array(PAPER_GAINS["K_v"].printed, dtype=float)
"""The printed vertical gains K_v (002 Sec. 7.1), the regulators' default."""


@dataclass(frozen=True)
class GainCheck:
    """Paper gains recomputed by pole placement, and the poles the printed integers give."""

    paper: PaperGains
    computed: np.ndarray  # (5,) gains placing ``paper.poles`` exactly
    abs_difference: np.ndarray  # |printed - computed|, per entry
    rel_difference: np.ndarray  # |printed - computed| / |computed|, per entry
    printed_poles: np.ndarray  # (5,) eig(A + B K_printed), k-th matched to the k-th design pole
    omega0: float


def check_paper_gains(omega0: float = OMEGA0) -> list[GainCheck]:
    """Recompute every gain vector of :data:`PAPER_GAINS` and locate the printed gains' poles."""
    checks = []
    for g in PAPER_GAINS.values():
        computed = place_axis(g.poles, omega0)
        printed = np.asarray(g.printed, dtype=float)
        diff = np.abs(printed - computed)
        moved = _match(np.asarray(g.poles, dtype=complex), axis_poles(printed, omega0))
        checks.append(GainCheck(g, computed, diff, diff / np.abs(computed), moved, omega0))
    return checks


def _match(reference: np.ndarray, poles: np.ndarray) -> np.ndarray:
    """Reorder ``poles`` so that the k-th is the one assigned to ``reference[k]`` (min total distance)."""
    from scipy.optimize import linear_sum_assignment

    cost = np.abs(reference[:, None] - poles[None, :])
    _, cols = linear_sum_assignment(cost)
    return poles[cols]
