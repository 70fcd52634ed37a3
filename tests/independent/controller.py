"""The papers' feedback-linearizing output regulator (002 eqs. (13)-(16), (21)-(24)), discretized.

Continuous design (per axis, with ``e`` the tracking error):

* feedback transformation with the controller's constants (SPEC 1 item 5, physical root):
  ``u1 = -v1 / L1(y1)``, ``R = L3^2 - 4 L4 (L4 u1^2 + L2 - G + v2)``,
  ``u2 = (-L3 - sqrt(max(R, 0))) / (2 L4)``;
* internal model ``xi' = phi xi + N e`` with ``phi = [[0,1,0],[0,0,1],[0,-omega0^2,0]]``,
  ``N = (0, 0, 1)``, ``omega0 = 1.5 pi`` (a step and a sinusoid at omega0 are rejected);
* ``v = K (e, e', xi1, xi2, xi3)`` with the printed gains K_h, K_v (SPEC 4);
* the velocities from a high-gain observer on each encoder reading ``y``:
  ``p' = q + 2 w_o (y - p)``, ``q' = v + w_o^2 (y - p)`` (both poles at ``-w_o``; ``v`` the
  pseudo-acceleration the loop asks for), so ``e' = q - r'``.

Discrete implementation at the control period ``T`` (5 kHz): the internal model and the
observer are integrated exactly over one period with their inputs held (zero-order hold),
``z_{k+1} = A_d z_k + B_d w_k``; the velocity used at sample k is the observer's prediction
from sample k-1 (one period of computation delay, as a real-time loop has).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import expm
from scipy.signal import place_poles

from .physics import PAPERS_CONSTANTS, G, equilibrium_current, model_functions

OMEGA0 = 1.5 * math.pi
"""[rad/s] Frequency of the internal model (002 Sec. 7.2)."""

K_H = (-1182.0, -55.0, -154440.0, -45128.0, -11924.0)
"""Printed horizontal gains (002 Sec. 7.1), acting on (e2, e2', xi_h)."""

K_V = (-1662.0, -65.0, -360360.0, -103350.0, -20332.0)
"""Printed vertical gains (002 Sec. 7.1), acting on (e1, e1', xi_v)."""

OBSERVER_BANDWIDTH = 1000.0
"""[rad/s] Double pole of the high-gain observers (epsilon = 1 ms): about 60x the regulator poles
and 1/30 of the 5 kHz sampling rate (the papers do not print theirs). The encoder quantization
then shows in the commanded currents as a few mA of sample-to-sample jitter."""


def augmented_matrices(omega0: float = OMEGA0) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis augmented system (e, e', xi1, xi2, xi3) of 002 eq. (25) with e'' = v: (A, B)."""
    A = np.zeros((5, 5))
    A[0, 1] = 1.0
    A[2, 3] = 1.0
    A[3, 4] = 1.0
    A[4, 0] = 1.0
    A[4, 3] = -(omega0**2)
    B = np.zeros((5, 1))
    B[1, 0] = 1.0
    return A, B


def closed_loop_poles(K: tuple[float, ...], omega0: float = OMEGA0) -> np.ndarray:
    """Eigenvalues of A + B K for the augmented system: where the printed gains put the poles."""
    A, B = augmented_matrices(omega0)
    return np.sort_complex(np.linalg.eigvals(A + B @ np.asarray(K, dtype=float)[None, :]))


def _zoh(A: np.ndarray, B: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray]:
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = A
    M[:n, n:] = B
    E = expm(M * T)
    return E[:n, :n], E[:n, n:]


def internal_model_matrices(T: float, omega0: float = OMEGA0) -> tuple[np.ndarray, np.ndarray]:
    """Exact ZOH discretization of ``xi' = phi xi + N e`` over ``T`` [s]: (A_i (3,3), B_i (3,))."""
    phi = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, -(omega0**2), 0.0]])
    N = np.array([[0.0], [0.0], [1.0]])
    Ad, Bd = _zoh(phi, N, T)
    return Ad, Bd[:, 0]


def observer_matrices(T: float, bandwidth: float = OBSERVER_BANDWIDTH) -> tuple[np.ndarray, np.ndarray]:
    """Exact ZOH discretization of the high-gain observer over ``T`` [s].

    State (p, q) = (position, velocity estimate), inputs (y, v): returns (A_o (2,2), B_o (2,2)).
    """
    h1, h2 = 2.0 * bandwidth, bandwidth**2
    A = np.array([[-h1, 1.0], [-h2, 0.0]])
    B = np.array([[h1, 0.0], [h2, 1.0]])
    return _zoh(A, B, T)


def feedback_transformation(
    y1: np.ndarray | float,
    v1: np.ndarray | float,
    v2: np.ndarray | float,
    constants: tuple[float, float, float, float] = PAPERS_CONSTANTS,
) -> tuple[np.ndarray, np.ndarray]:
    """(u1, u2) = (i_q, i_d) [A] that give accelerations (v1, v2) on the model with ``constants``.

    Uses the gap reading ``y1`` [m]. ``R`` is clipped at 0 (the nearest current the model allows)
    when the requested v2 is infeasible.
    """
    L1, L2, L3, L4 = model_functions(y1, constants)
    u1 = -np.asarray(v1) / L1
    R = np.maximum(L3 * L3 - 4.0 * L4 * (L4 * u1 * u1 + L2 - G + np.asarray(v2)), 0.0)
    return u1, (-L3 - np.sqrt(R)) / (2.0 * L4)


def scaled_gains(K: tuple[float, ...], scale: float, omega0: float = OMEGA0) -> tuple[float, ...]:
    """Gains on (e, e', xi1, xi2, xi3) that put every closed-loop pole of ``K`` at ``scale`` times
    its place (a softer loop for ``scale`` < 1, a stiffer one above)."""
    A, B = augmented_matrices(omega0)
    poles = closed_loop_poles(K, omega0) * scale
    # place_poles places the eigenvalues of A - B G; here the loop is A + B K
    return tuple(float(g) for g in -place_poles(A, B, poles).gain_matrix[0])


PID_POLES = (25.0, 10.0)
"""[rad/s] The PID loops' triple closed-loop pole, vertical and horizontal, on the linearization at
the operating gap. Vertically the magnets' negative stiffness a = d x1''/d x1 is 1140-2450 /s^2
over gaps of 24.5-14.5 mm (1600 at 19.5 mm): at 15 rad/s (kp = a + 675) the loop lost the stage at
the smallest gaps of the references, at 25 it holds all eleven logs of the ``eleven`` set with RMS
errors of 0.24-0.63 mm vertically and 0.25-1.5 mm horizontally (the papers' PID runs: about 0.9
and 0.19 mm, 001 Sec. 6)."""


def pid_design(
    gap: float, poles: tuple[float, float] = PID_POLES, constants: tuple[float, ...] = PAPERS_CONSTANTS
) -> dict[str, tuple[float, ...] | float]:
    """The two independent PID regulators of the papers' identification runs (000 Sec. III, 002 Sec.
    5: "two PID regulators ... for the control inputs i_d and i_q to independently make the
    horizontal and vertical dynamics track"), designed on the model with ``constants`` linearized
    at ``gap`` [m] and zero i_q.

    Vertically x1'' = G - L2 - L3 i_d - L4 i_d^2 gives, about the equilibrium current i_eq,
    e'' = a e + b di_d (a = d x1''/d x1, b = d x1''/d i_d); horizontally x3'' = -L1 i_q, a = 0,
    b = -L1. With di = -(kp e + kd e' + ki int e) / b the error obeys
    s^3 + kd s^2 + (kp - a) s + ki = 0, here (s + p)^3: kd = 3 p, kp = a + 3 p^2, ki = p^3.
    Returns the gains (kp, kd, ki) per axis, the two b and i_eq."""
    i_eq = float(equilibrium_current(gap, constants))

    def vertical(y: float, i: float) -> float:
        _, L2, L3, L4 = (float(v) for v in model_functions(y, constants))
        return G - L2 - L3 * i - L4 * i * i

    h_y, h_i = 1e-7, 1e-5
    a_v = (vertical(gap + h_y, i_eq) - vertical(gap - h_y, i_eq)) / (2 * h_y)
    b_v = (vertical(gap, i_eq + h_i) - vertical(gap, i_eq - h_i)) / (2 * h_i)
    b_h = -float(model_functions(gap, constants)[0])

    def gains(p: float, a: float) -> tuple[float, float, float]:
        return (a + 3 * p * p, 3 * p, p**3)

    return {
        "vertical": gains(poles[0], a_v),
        "horizontal": gains(poles[1], 0.0),
        "b_v": b_v,
        "b_h": b_h,
        "i_eq": i_eq,
    }
