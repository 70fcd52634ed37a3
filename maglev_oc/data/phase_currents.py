"""The d-q transform between the stator's phase currents and the inputs u = (i_q, i_d) of a log.

Eq. (2) of paper 001 (002 Sec. 3) at the mover position x3, with theta = pi x3 / tau.
"""

from __future__ import annotations

import numpy as np

from maglev_oc.errors import InputError

__all__ = ["inputs_to_phase_currents", "phase_currents_to_inputs"]


def phase_currents_to_inputs(
    ia: np.ndarray, ib: np.ndarray, ic: np.ndarray, x3: np.ndarray, pole_pitch: float
) -> np.ndarray:
    """Inputs ``u = (i_q, i_d)`` [A], shape (2, n), from the phase currents at mover position x3.

    Eq. (2) of paper 001 (002 Sec. 3), with theta = pi x3 / tau:

        i_d =  2/3 [cos(theta) ia + cos(theta - 2 pi/3) ib + cos(theta + 2 pi/3) ic]
        i_q = -2/3 [sin(theta) ia + sin(theta - 2 pi/3) ib + sin(theta + 2 pi/3) ic]

    Parameters
    ----------
    ia, ib, ic : (n,) arrays
        Phase currents [A].
    x3 : (n,) array
        Horizontal mover position [m].
    pole_pitch : float
        tau [m] (``StageParameters().pole_pitch`` = 57.15 mm).

    Returns
    -------
    (2, n) array
        (i_q, i_d) [A].
    """
    theta = np.pi * np.asarray(x3, dtype=float) / pole_pitch
    shifts = (0.0, -2 * np.pi / 3, 2 * np.pi / 3)
    phases = (np.asarray(ia, dtype=float), np.asarray(ib, dtype=float), np.asarray(ic, dtype=float))
    i_d = 2 / 3 * sum(np.cos(theta + s) * i for s, i in zip(shifts, phases, strict=True))
    i_q = -2 / 3 * sum(np.sin(theta + s) * i for s, i in zip(shifts, phases, strict=True))
    return np.vstack([i_q, i_d])


def inputs_to_phase_currents(u: np.ndarray, x3: np.ndarray, pole_pitch: float) -> np.ndarray:
    """Balanced phase currents ``(ia, ib, ic)`` [A], shape (3, n), that give ``u = (i_q, i_d)``.

    The inverse of :func:`phase_currents_to_inputs` for currents that sum to zero (the star-
    connected stator): i_k = cos(theta_k) i_d - sin(theta_k) i_q with theta_k = pi x3 / tau,
    theta - 2 pi/3, theta + 2 pi/3. This is what the controller sends to the amplifiers (002 Fig. 8).

    Parameters
    ----------
    u : (2, n) array
        (i_q, i_d) [A].
    x3 : (n,) array
        Horizontal mover position [m].
    pole_pitch : float
        tau [m].

    Returns
    -------
    (3, n) array
        (ia, ib, ic) [A].
    """
    u = np.asarray(u, dtype=float)
    if u.ndim != 2 or u.shape[0] != 2:
        raise InputError(f"u: expected shape (2, n) = (i_q, i_d), got {u.shape}")
    theta = np.pi * np.asarray(x3, dtype=float) / pole_pitch
    i_q, i_d = u
    shifts = (0.0, -2 * np.pi / 3, 2 * np.pi / 3)
    return np.vstack([np.cos(theta + s) * i_d - np.sin(theta + s) * i_q for s in shifts])
