"""The papers' 2-DOF force model, written out from the formulas (SPEC 1, 000 Sec. III-IV, 002 Sec. 3-5).

Everything is in SI units. With gap ``y`` [m] and ``a = pi / tau``:

.. math::

    K_c(y) = t_1 / (t_1 - y \\gamma_1(y)),\\quad
    \\gamma_1 = (4/\\pi) [r \\arctan r - \\ln\\sqrt{1 + r^2}],\\quad r = b_0 / (2 y)

    \\tilde\\lambda(y) = 1 - b_0^2 / (4 t_1 (y + b_0/2 + h_m/\\mu_{rec}))

    B(y) = (4 \\mu_0 \\sigma_m / \\pi) \\sin(\\pi \\tau_p / (2 \\tau)) \\sinh(a h_m) / \\sinh(a (h_m + y))

    L_1 = C_1 \\tilde\\lambda / (K_c \\sinh(a(h_m+y))),\\quad L_2 = C_2 \\tilde\\lambda B^2

    L_3 = -C_3 \\tilde\\lambda B \\coth(a(h_m+y)) / K_c

    L_4 = C_4 \\tilde\\lambda \\coth^2(a(h_m+y)) / K_c^2

and the model ``x2' = G - L4 (u1^2 + u2^2) - L3 u2 - L2``, ``x4' = -L1 u1`` with ``u = (i_q, i_d)``.
The magnet field is the fundamental of the magnetic-charge model with the surface charge
``sigma_m = H_c``; the C1..C4 absorb the rest. The C simulation core evaluates the same
formulas; :func:`model_functions` here is the numpy reference it is checked against.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

G = 9.81
"""[m/s^2] Gravitational acceleration (SPEC 1)."""

MU0 = 4e-7 * math.pi
"""[N/A^2] Permeability of free space."""


@dataclass(frozen=True)
class StageGeometry:
    """Table I of papers 000/002: the geometry and magnets of the Quanser 2-DOF stage.

    Attributes
    ----------
    b0 : float
        Stator slot width (slot opening) [m].
    t1 : float
        Stator slot pitch [m].
    hm : float
        Permanent-magnet height [m].
    tau : float
        Pole pitch [m].
    tau_p : float
        Permanent-magnet width (pole arc) [m].
    Hc : float
        Coercivity of the N35 magnets [A/m]; used as the magnetic surface charge sigma_m.
    mu_rec : float
        Relative recoil permeability of the magnets [-].
    M_h : float
        Mass moving horizontally [kg].
    M_v : float
        Mass moving vertically [kg].
    stator_length : float
        Length of the slotted stator, z1 t1 = 18 x 19.05 mm [m] (used to place the end effects).
    """

    b0: float = 12.7e-3
    t1: float = 19.05e-3
    hm: float = 5.0e-3
    tau: float = 57.15e-3
    tau_p: float = 28.58e-3
    Hc: float = 875400.0
    mu_rec: float = 1.1
    M_h: float = 1.594
    M_v: float = 4.350
    stator_length: float = 18 * 19.05e-3

    def as_dict(self) -> dict[str, float]:
        """The geometry as a plain dict (for the truth file)."""
        return asdict(self)


PAPERS_CONSTANTS = (14.20, 796.99, 31.04, 0.07)
"""(C1, C2, C3, C4): Table III of 000 at eps = 0.01, the constants the papers' controller uses."""

GEOMETRY = StageGeometry()


def field_prefactor(geo: StageGeometry = GEOMETRY) -> float:
    """``(4 mu0 sigma_m / pi) sin(pi tau_p / (2 tau)) sinh(a hm)`` [T m^0]: B(y) times sinh(a (hm + y))."""
    a = math.pi / geo.tau
    return (
        4.0 * MU0 * geo.Hc / math.pi * math.sin(math.pi * geo.tau_p / (2.0 * geo.tau)) * math.sinh(a * geo.hm)
    )


def carter(y: np.ndarray | float, geo: StageGeometry = GEOMETRY) -> np.ndarray:
    """Carter's coefficient K_c(y) [-] for slot opening b0 and slot pitch t1 at gap ``y`` [m]."""
    y = np.asarray(y, dtype=float)
    r = geo.b0 / (2.0 * y)
    gamma1 = 4.0 / math.pi * (r * np.arctan(r) - 0.5 * np.log1p(r * r))
    return geo.t1 / (geo.t1 - y * gamma1)


def lambda_tilde(y: np.ndarray | float, geo: StageGeometry = GEOMETRY) -> np.ndarray:
    """The slotting factor lambda~(y) [-] of 000 Sec. III."""
    y = np.asarray(y, dtype=float)
    return 1.0 - geo.b0**2 / (4.0 * geo.t1 * (y + geo.b0 / 2.0 + geo.hm / geo.mu_rec))


def magnet_field(y: np.ndarray | float, geo: StageGeometry = GEOMETRY) -> np.ndarray:
    """Closed-form fundamental of the magnets' normal field B(y) [T] at gap ``y`` [m]."""
    y = np.asarray(y, dtype=float)
    a = math.pi / geo.tau
    return field_prefactor(geo) / np.sinh(a * (geo.hm + y))


def model_functions(
    y: np.ndarray | float,
    constants: tuple[float, float, float, float] = PAPERS_CONSTANTS,
    geo: StageGeometry = GEOMETRY,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """L1..L4 of the model at gap ``y`` [m] for lumped constants ``(C1, C2, C3, C4)``.

    Returns
    -------
    L1 : [m/s^2/A] horizontal acceleration per ampere of i_q.
    L2 : [m/s^2] magnets' attraction per unit vertical mass.
    L3 : [m/s^2/A] (negative) coefficient of i_d in the vertical equation.
    L4 : [m/s^2/A^2] coefficient of i_d^2 + i_q^2.
    """
    C1, C2, C3, C4 = constants
    y = np.asarray(y, dtype=float)
    a = math.pi / geo.tau
    s = np.sinh(a * (geo.hm + y))
    coth = np.cosh(a * (geo.hm + y)) / s
    kc = carter(y, geo)
    lam = lambda_tilde(y, geo)
    b = field_prefactor(geo) / s
    L1 = C1 * lam / (kc * s)
    L2 = C2 * lam * b * b
    L3 = -C3 * lam * b * coth / kc
    L4 = C4 * lam * coth * coth / (kc * kc)
    return L1, L2, L3, L4


def equilibrium_current(
    y: np.ndarray | float,
    constants: tuple[float, float, float, float] = PAPERS_CONSTANTS,
    geo: StageGeometry = GEOMETRY,
) -> np.ndarray:
    """The i_d [A] that holds gap ``y`` [m] at rest with i_q = 0 (002 eq. (12)).

    The small-magnitude root of ``L4 u2^2 + L3 u2 + L2 - G = 0``,
    ``u2 = (-L3 - sqrt(L3^2 - 4 L4 (L2 - G))) / (2 L4)``, which is continuous through zero current.
    """
    _, L2, L3, L4 = model_functions(y, constants, geo)
    return (-L3 - np.sqrt(L3 * L3 - 4.0 * L4 * (L2 - G))) / (2.0 * L4)
