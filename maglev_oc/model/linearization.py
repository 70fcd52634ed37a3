"""Linearization of the stage at an operating point, from the exact CasADi Jacobians."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from maglev_oc.model.equilibrium import equilibrium_currents
from maglev_oc.model.stage import N_INPUTS, N_STATES, StageModel

__all__ = ["OUTPUT_MATRIX", "LinearModel", "OpenLoopPoles", "linearize", "open_loop_poles"]

OUTPUT_MATRIX = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
"""Outputs y = (x1, x3): air gap and horizontal position (eq. (4) of 002)."""


@dataclass(frozen=True)
class LinearModel:
    """dx' = A dx + B du, dy = C dx + D du about (x0, u0), with f(x0, u0) = ``drift``."""

    A: np.ndarray  # (4, 4)
    B: np.ndarray  # (4, 2)
    C: np.ndarray  # (2, 4)
    D: np.ndarray  # (2, 2)
    x0: np.ndarray  # (4,)
    u0: np.ndarray  # (2,)
    drift: np.ndarray  # (4,) f(x0, u0); zero at an equilibrium

    @property
    def poles(self) -> np.ndarray:
        """Eigenvalues of A [1/s], sorted by real part, largest first."""
        ev = np.linalg.eigvals(self.A)
        return ev[np.argsort(-ev.real, kind="stable")]


def linearize(model: StageModel, x, u) -> LinearModel:
    """A = df/dx, B = df/du at (x, u) (exact, by CasADi AD), C, D for the outputs (x1, x3).

    Any (x, u) is accepted; at a non-equilibrium point ``drift`` is nonzero.

    Parameters
    ----------
    model : StageModel
    x : array_like, (4,)
        State (gap [m], gap rate [m/s], position [m], velocity [m/s]).
    u : array_like, (2,)
        Currents (i_q, i_d) [A].

    Returns
    -------
    LinearModel
        A (4x4), B (4x2), C (2x4), D (2x2), the point and f(x, u) as ``drift``.

    Examples
    --------
    At 20 mm the vertical axis is open-loop unstable, the horizontal one a double integrator:

    >>> import numpy as np
    >>> import maglev_oc as mo
    >>> model = mo.StageModel()
    >>> op = mo.equilibrium(model, 0.020)
    >>> lin = mo.linearize(model, op.x, op.u)
    >>> np.sort(np.linalg.eigvals(lin.A).real).round(2)
    array([-39.25,   0.  ,   0.  ,  39.25])
    """
    x = np.asarray(x, dtype=float).reshape(N_STATES)
    u = np.asarray(u, dtype=float).reshape(N_INPUTS)
    a, b = model.jacobian(x, u)
    drift = np.asarray(model.f(x, u)).ravel()
    return LinearModel(
        np.asarray(a), np.asarray(b), OUTPUT_MATRIX.copy(), np.zeros((2, N_INPUTS)), x, u, drift
    )


@dataclass(frozen=True)
class OpenLoopPoles:
    """Open-loop poles at the equilibrium of each gap: the vertical pair +-sqrt(a21) and the
    horizontal double integrator (two poles at 0 at every equilibrium, since u1 = 0)."""

    gap: np.ndarray  # [m], (n,)
    vertical: np.ndarray  # (n, 2) complex [1/s]; NaN where no equilibrium exists
    horizontal: np.ndarray  # (n, 2) complex [1/s]
    stiffness: np.ndarray  # a21 = d x2'/d x1 at equilibrium [1/s^2]; > 0: unstable


def open_loop_poles(model: StageModel, gaps) -> OpenLoopPoles:
    """Open-loop poles of the linearization at the equilibrium of each gap, vectorised.

    Parameters
    ----------
    model : StageModel
    gaps : array_like
        [m] Gaps, one dimension.

    Returns
    -------
    OpenLoopPoles
        The vertical pair +-sqrt(a21) (NaN where no equilibrium exists), the horizontal double
        integrator and the stiffness a21 [1/s^2], per gap."""
    curve = equilibrium_currents(model, gaps)
    n = curve.gap.size
    x = np.zeros((N_STATES, n))
    x[0] = curve.gap
    u = np.zeros((N_INPUTS, n))
    u[1] = np.where(curve.exists, curve.current, 0.0)
    a_batch = np.asarray(model.jacobian.map(n)(x, u)[0])  # (4, 4n)
    a_batch = a_batch.reshape(N_STATES, n, N_STATES).transpose(1, 0, 2)  # (n, 4, 4)
    vertical = np.full((n, 2), np.nan + 0j)
    horizontal = np.full((n, 2), np.nan + 0j)
    for k in range(n):
        if not curve.exists[k]:
            continue
        ev_v = np.linalg.eigvals(a_batch[k][:2, :2])
        ev_h = np.linalg.eigvals(a_batch[k][2:, 2:])
        vertical[k] = ev_v[np.argsort(-ev_v.real)]
        horizontal[k] = ev_h
    stiffness = np.where(curve.exists, a_batch[:, 1, 0], np.nan)
    return OpenLoopPoles(curve.gap, vertical, horizontal, stiffness)
