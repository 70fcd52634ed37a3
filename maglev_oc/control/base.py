"""What every controller offers the simulation engine.

Two kinds, both sampled at ``sample_time`` with a zero-order hold on their output:

* :class:`ExpressionController` — the whole update is one CasADi Function
  ``step(c, y, r) -> (u, c_next, diag)``; the engine fuses it with the twin and runs the
  closed loop inside CasADi (``mapaccum``), no Python per sample.
* :class:`OnlineController` — a Python object that solves something each sample (NMPC); the
  engine loops in Python and calls ``control(k, y, reference)``.

Signals (fixed layouts, column vectors):

* ``y`` (2): measured (gap [m], horizontal position [m]) — encoder readings.
* ``r`` (6): reference (r_v, r_v', r_v'', r_h, r_h', r_h'') [m, m/s, m/s^2]; r_v is the gap
  reference, r_h the horizontal one (001 eq. (5)).
* ``u`` (2): current commands (i_q, i_d) [A].
* ``diag``: controller diagnostics, named by ``diag_names``; by convention ``margin`` is the
  feasibility margin R/(4 L4) [m/s^2] where a controller has one and ``clipped`` is 1 on
  samples where the controller had to clip (e.g. R < 0).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import casadi as ca
import numpy as np

__all__ = ["N_MEASUREMENTS", "N_REFERENCE", "ExpressionController", "OnlineController"]

N_MEASUREMENTS = 2
"""Entries of ``y``: (gap, horizontal position) [m]."""
N_REFERENCE = 6
"""Rows of ``r``: (r_v, r_v', r_v'', r_h, r_h', r_h'') [m, m/s, m/s^2]."""


@runtime_checkable
class ExpressionController(Protocol):
    """A controller whose whole update is one CasADi Function.

    Attributes
    ----------
    name : str
    sample_time : float
        [s].
    n_state : int
        Entries of the controller state c.
    diag_names : tuple of str
        Rows of ``diag``.
    step : casadi.Function
        (c, y (2), r (6)) -> (u (2) [A], c_next, diag).
    """

    name: str
    sample_time: float
    n_state: int
    diag_names: tuple[str, ...]
    step: ca.Function  # (c, y, r) -> (u, c_next, diag)

    def initial_state(self, y0: np.ndarray, r0: np.ndarray, u0: np.ndarray) -> np.ndarray:
        """Controller state at start.

        Parameters
        ----------
        y0 : (2,) array
            First measurement [m].
        r0 : (6,) array
            First reference sample.
        u0 : (2,) array
            The current already flowing [A] (for a bumpless start).

        Returns
        -------
        (n_state,) array
        """
        ...


@runtime_checkable
class OnlineController(Protocol):
    """A controller that solves something each sample, stepped from Python.

    Attributes
    ----------
    name : str
    sample_time : float
        [s].
    diag_names : tuple of str
        Entries of the diagnostics :meth:`control` returns.
    """

    name: str
    sample_time: float
    diag_names: tuple[str, ...]

    def reset(self, y0: np.ndarray, r0: np.ndarray, u0: np.ndarray) -> None:
        """Prepare for a new run (observer, warm start).

        Parameters
        ----------
        y0 : (2,) array
            First measurement [m].
        r0 : (6,) array
            First reference sample.
        u0 : (2,) array
            The current already flowing [A].
        """
        ...

    def control(self, k: int, y: np.ndarray, reference: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One update.

        Parameters
        ----------
        k : int
            Sample index.
        y : (2,) array
            Measurement [m].
        reference : (6, n) array
            The whole sampled reference (for preview).

        Returns
        -------
        u : (2,) array
            Current command [A].
        diag : (len(diag_names),) array
        """
        ...
