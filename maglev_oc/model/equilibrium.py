"""Equilibria of the stage: the current that holds a gap, for any gap and horizontal position.

At an equilibrium x2 = x4 = 0, x4' = 0 forces u1 = 0 (L1 > 0), and x2' = 0 is the quadratic
(7) of paper 000 in u2:  L4 u2^2 + L3 u2 + (L2 - G) = 0.  Its physical root is the small one,
continuous through zero current (SPEC 1, reading 5; eq. (8) of 000, eq. (12) of 002):

    u2 = (-L3 - sqrt(R0)) / (2 L4),   R0 = L3^2 - 4 L4 (L2 - G).

The base model has no dependence on the horizontal position, so every x3 is an equilibrium
position with the same current.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.model.hardware import CONTINUOUS_CURRENT_LIMIT, PEAK_CURRENT_LIMIT
from maglev_oc.model.stage import StageModel

__all__ = [
    "EquilibriumCurve",
    "NoEquilibriumError",
    "OperatingPoint",
    "equilibrium",
    "equilibrium_currents",
    "gap_for_current",
]


class NoEquilibriumError(InputError):
    """No equilibrium exists at the requested gap, or it needs more current than allowed."""


@dataclass(frozen=True)
class OperatingPoint:
    """An equilibrium (x, u) of the stage: x = (gap, 0, position, 0), u = (0, i_d)."""

    x: np.ndarray  # (4,)
    u: np.ndarray  # (2,)

    @property
    def gap(self) -> float:
        return float(self.x[0])

    @property
    def position(self) -> float:
        return float(self.x[2])


@dataclass(frozen=True)
class EquilibriumCurve:
    """Equilibrium currents over a set of gaps, with where they exist and fit the amplifiers.

    All arrays have the shape of ``gap``. ``current`` is NaN where no equilibrium exists.
    """

    gap: np.ndarray  # [m]
    current: np.ndarray  # u2 = i_d [A]
    discriminant: np.ndarray  # R0 = L3^2 - 4 L4 (L2 - G) [(m/s^2/A)^2]; < 0: no equilibrium
    exists: np.ndarray  # bool
    within_continuous: np.ndarray  # bool, |u2| <= 7 A
    within_peak: np.ndarray  # bool, |u2| <= 9 A


def equilibrium_currents(model: StageModel, gaps) -> EquilibriumCurve:
    """Equilibrium current u2 [A] at each gap [m] (u1 = 0), vectorised; never raises for a gap.

    Parameters
    ----------
    model : StageModel
    gaps : array_like
        [m] Gaps, any shape.

    Returns
    -------
    EquilibriumCurve
        Current, discriminant, existence and the amplifier checks, each of the shape of ``gaps``
        (NaN current where no equilibrium exists)."""
    gaps = np.atleast_1d(np.asarray(gaps, dtype=float))
    bad = ~(np.isfinite(gaps) & (gaps > 0))
    if np.any(bad):
        shown = ", ".join(f"{g:g}" for g in gaps[bad][:3])
        raise InputError(f"gaps must be positive and finite [m], got {shown}")
    _, L2, L3, L4 = model.coefficients(gaps)
    disc = L3**2 - 4 * L4 * (L2 - model.params.gravity)
    exists = disc >= 0
    current = np.full_like(gaps, np.nan)
    current[exists] = (-L3[exists] - np.sqrt(disc[exists])) / (2 * L4[exists])
    with np.errstate(invalid="ignore"):
        within_cont = exists & (np.abs(current) <= CONTINUOUS_CURRENT_LIMIT)
        within_peak = exists & (np.abs(current) <= PEAK_CURRENT_LIMIT)
    return EquilibriumCurve(gaps, current, disc, exists, within_cont, within_peak)


def equilibrium(
    model: StageModel,
    gap: float,
    position: float = 0.0,
    *,
    current_limit: float = CONTINUOUS_CURRENT_LIMIT,
) -> OperatingPoint:
    """The equilibrium holding ``gap`` [m] at horizontal ``position`` [m].

    Parameters
    ----------
    model : StageModel
    gap : float
        [m] Air gap to hold (SPEC 1: x1, larger is further from the stator).
    position : float
        [m] Horizontal position; the papers' model does not depend on it (cogging aside).
    current_limit : float
        [A] Largest |i_d| accepted.

    Returns
    -------
    OperatingPoint
        x = (gap, 0, position, 0), u = (0, i_d) with i_d = (-L3 - sqrt(R0)) / (2 L4), the
        root the papers' feedback law uses.

    Raises
    ------
    NoEquilibriumError
        If the quadratic for u2 has no real root at this gap (the magnets' pull cannot be
        balanced), or if the current exceeds ``current_limit`` [A] (default: the amplifiers'
        7 A continuous rating, since an equilibrium is held indefinitely).

    Examples
    --------
    The current that holds a 20 mm gap (SPEC 1: about 1.5 A):

    >>> import maglev_oc as mo
    >>> op = mo.equilibrium(mo.StageModel(), 0.020)
    >>> print(f"{op.u[1]:.3f} A")
    1.497 A
    """
    gap = float(gap)
    position = float(position)
    if not np.isfinite(position):
        raise InputError(f"position must be finite [m], got {position!r}")
    if gap > 1.0:
        raise InputError(f"gap = {gap!r} looks like millimetres; the gap is in metres")
    curve = equilibrium_currents(model, [gap])
    if not curve.exists[0]:
        raise NoEquilibriumError(
            f"no equilibrium at gap {gap * 1e3:.2f} mm: L4 u2^2 + L3 u2 + L2 - G = 0 has no real "
            f"root (discriminant {curve.discriminant[0]:.3g} < 0)"
        )
    current = float(curve.current[0])
    if abs(current) > current_limit:
        raise NoEquilibriumError(
            f"equilibrium at gap {gap * 1e3:.2f} mm needs i_d = {current:.2f} A, beyond the "
            f"{current_limit:g} A limit (amplifiers: {CONTINUOUS_CURRENT_LIMIT:g} A continuous, "
            f"{PEAK_CURRENT_LIMIT:g} A peak)"
        )
    return OperatingPoint(np.array([gap, 0.0, position, 0.0]), np.array([0.0, current]))


def gap_for_current(model: StageModel, current: float, bracket=(5e-3, 35e-3)) -> float:
    """The gap [m] whose equilibrium current is ``current`` [A] (e.g. 0 A: where no power is needed).

    The equilibrium current decreases monotonically with the gap over the operating range; the
    root is found by Brent's method on ``bracket``.
    """
    from scipy.optimize import brentq

    def residual(g: float) -> float:
        return float(equilibrium_currents(model, [g]).current[0]) - current

    lo, hi = bracket
    if not (np.isfinite(residual(lo)) and np.isfinite(residual(hi))) or residual(lo) * residual(hi) > 0:
        raise NoEquilibriumError(
            f"no gap in [{lo * 1e3:g}, {hi * 1e3:g}] mm has equilibrium current {current:g} A"
        )
    return float(brentq(residual, lo, hi, xtol=1e-12))
