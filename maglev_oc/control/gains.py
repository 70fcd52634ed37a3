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
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.results import Result

__all__ = [
    "OMEGA0",
    "PAPER_GAINS",
    "PAPER_K_H",
    "PAPER_K_V",
    "GainCheck",
    "PaperGains",
    "augmented_axis",
    "axis_poles",
    "check_paper_gains",
    "checked_gains",
    "internal_model",
    "place_axis",
]

OMEGA0 = 1.5 * math.pi
"""Exosystem frequency of the papers [rad/s] (001, 002: omega0 = 1.5 pi)."""


def internal_model(omega0: float = OMEGA0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The internal model of eqs. (21)-(22) of 002.

    Parameters
    ----------
    omega0 : float
        Exosystem frequency [rad/s].

    Returns
    -------
    phi : (3, 3) array
        xi' = phi xi + N e.
    N : (3, 1) array
    Gamma : (1, 3) array
    """
    phi = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, -(omega0**2), 0.0]])
    n = np.array([[0.0], [0.0], [1.0]])
    gamma = np.array([[1.0, 0.0, 0.0]])
    return phi, n, gamma


def checked_gains(value, label: str) -> np.ndarray:
    """``value`` as five finite gains.

    Parameters
    ----------
    value : array_like
        Gains on (e, e', xi1, xi2, xi3) [1/s^2, 1/s, 1/s^5, 1/s^4, 1/s^3].
    label : str
        Name used in the error message.

    Returns
    -------
    (5,) array

    Raises
    ------
    ValueError
        Naming ``label`` and the value, unless there are five finite gains.
    """
    k = np.asarray(value, dtype=float).ravel()
    if k.shape != (5,) or not np.all(np.isfinite(k)):
        raise InputError(f"{label} must be 5 finite gains, got {value!r}")
    return k


def augmented_axis(
    omega0: float = OMEGA0, stiffness: float = 0.0, input_gain: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """(A, B) of the per-axis augmented system in z = (e, e', xi1, xi2, xi3).

    The axis is e'' = stiffness * e + input_gain * w. After the feedback transformation
    stiffness = 0 and input_gain = 1 (w = v, the papers' design); for the linear regulator on
    the Jacobian linearization, stiffness = d x2'/d x1 and input_gain = d x2'/d u2 (vertical) or
    0 and -L1 (horizontal).

    Parameters
    ----------
    omega0 : float
        Internal-model frequency [rad/s].
    stiffness : float
        [1/s^2].
    input_gain : float
        [m/(s^2 A)], or 1 for w = v [m/s^2]; nonzero.

    Returns
    -------
    A : (5, 5) array
    B : (5, 1) array
    """
    if not (np.isfinite(input_gain) and input_gain != 0):
        raise InputError(f"input_gain must be finite and nonzero, got {input_gain!r}")
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
    """Gains K with eig(A + B K) = ``poles`` for the augmented axis (Ackermann's formula).

    Parameters
    ----------
    poles : array_like
        Five values [1/s] closed under complex conjugation, in the open left half plane.
    omega0, stiffness, input_gain : float
        The axis, as in :func:`augmented_axis`.

    Returns
    -------
    (5,) array
        K on (e, e', xi1, xi2, xi3), w = K z.
    """
    poles = np.asarray(poles, dtype=complex).ravel()
    if poles.size != 5:
        raise InputError(f"need 5 poles for the augmented axis, got {poles.size}")
    if np.any(poles.real >= 0):
        raise InputError(f"poles must lie in the open left half plane, got {poles}")
    coeffs = np.poly(poles)
    if np.max(np.abs(coeffs.imag)) > 1e-9 * np.max(np.abs(coeffs)):
        raise InputError(f"poles must be closed under complex conjugation, got {poles}")
    coeffs = coeffs.real
    a, b = augmented_axis(omega0, stiffness, input_gain)
    ctrb = np.hstack([np.linalg.matrix_power(a, k) @ b for k in range(5)])
    phi_a = sum(c * np.linalg.matrix_power(a, 5 - k) for k, c in enumerate(coeffs))
    last_row = np.linalg.solve(ctrb.T, np.eye(5)[:, -1])  # e_n^T ctrb^{-1}
    k_ackermann = last_row @ phi_a  # u = -k x places the poles
    return -k_ackermann


def axis_poles(gains, omega0: float = OMEGA0, stiffness: float = 0.0, input_gain: float = 1.0) -> np.ndarray:
    """Closed-loop poles of the augmented axis under w = K z.

    Parameters
    ----------
    gains : array_like
        K (5,).
    omega0, stiffness, input_gain : float
        The axis, as in :func:`augmented_axis`.

    Returns
    -------
    (5,) complex array
        Poles [1/s], sorted by real part (descending), then imaginary part.
    """
    a, b = augmented_axis(omega0, stiffness, input_gain)
    k = np.asarray(gains, dtype=float).reshape(1, 5)
    ev = np.linalg.eigvals(a + b @ k)
    return ev[np.lexsort((ev.imag, -ev.real))]


@dataclass(frozen=True)
class PaperGains:
    """A gain vector printed in the papers with the poles it was placed at.

    Attributes
    ----------
    name : str
    poles : tuple of complex
        Design poles [1/s].
    printed : tuple of float
        The printed gains on (e, e', xi1, xi2, xi3).
    source : str
        Paper and section.
    """

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
class GainCheck(Result):
    """Paper gains recomputed by pole placement, and the poles the printed integers give.

    Attributes
    ----------
    success : bool
        The printed gains give a stable augmented axis (every pole in the open left half plane).
    status : str
        "stable" or "unstable".
    message : str
        How far the printed gains and their poles are from the design.
    paper : PaperGains
    computed : (5,) array
        Gains placing ``paper.poles`` exactly.
    abs_difference : (5,) array
        |printed - computed|, per entry.
    rel_difference : (5,) array
        |printed - computed| / |computed|, per entry.
    printed_poles : (5,) complex array
        eig(A + B K_printed) [1/s], the k-th matched to the k-th design pole.
    omega0 : float
        [rad/s].
    timings : mapping
        Empty (nothing worth timing).
    """

    success: bool
    status: str
    message: str
    paper: PaperGains
    computed: np.ndarray
    abs_difference: np.ndarray
    rel_difference: np.ndarray
    printed_poles: np.ndarray
    omega0: float
    timings: Mapping[str, float] = field(default_factory=dict)


def check_paper_gains(omega0: float = OMEGA0) -> list[GainCheck]:
    """Recompute every gain vector of :data:`PAPER_GAINS` and locate the printed gains' poles.

    Parameters
    ----------
    omega0 : float
        Internal-model frequency [rad/s].

    Returns
    -------
    list of GainCheck
        In the order of :data:`PAPER_GAINS`.
    """
    checks = []
    for g in PAPER_GAINS.values():
        computed = place_axis(g.poles, omega0)
        printed = np.asarray(g.printed, dtype=float)
        diff = np.abs(printed - computed)
        design = np.asarray(g.poles, dtype=complex)
        moved = _match(design, axis_poles(printed, omega0))
        rel = diff / np.abs(computed)
        stable = bool(np.all(moved.real < 0))
        message = (
            f"{g.name}: printed gains within {np.max(rel):.2%} of the placed ones; their poles "
            f"lie up to {np.max(np.abs(moved - design)):.3g} 1/s from the design poles"
        )
        checks.append(
            GainCheck(
                success=stable,
                status="stable" if stable else "unstable",
                message=message,
                paper=g,
                computed=computed,
                abs_difference=diff,
                rel_difference=rel,
                printed_poles=moved,
                omega0=omega0,
            )
        )
    return checks


def _match(reference: np.ndarray, poles: np.ndarray) -> np.ndarray:
    """Reorder ``poles`` so that the k-th is the one assigned to ``reference[k]`` (min total distance)."""
    from scipy.optimize import linear_sum_assignment

    cost = np.abs(reference[:, None] - poles[None, :])
    _, cols = linear_sum_assignment(cost)
    return poles[cols]
