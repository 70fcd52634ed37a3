"""Gap-dependent magnetic factors of the iron-cored PMLSM: lam(y), Carter's Kc(y), the PM field B(y).

Each function takes a CasADi expression (SX/MX) or a number and returns the same kind, so the
stage model differentiates through them exactly. Formulas: paper 002, Section 3; SPEC 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.model.parameters import MU0, StageParameters

__all__ = [
    "FIELD_FIT_DEGREE",
    "FIELD_FIT_RANGE",
    "FieldPolynomial",
    "carter_coefficient",
    "field_closed_form",
    "fit_field_polynomial",
    "slot_factor",
]

FIELD_FIT_RANGE = (5e-3, 35e-3)
"""Gap range [m] over which the papers' 12th-degree polynomial field fit is valid."""
FIELD_FIT_DEGREE = 12


def slot_factor(p: StageParameters, y):
    """lam~(y) = 1 - b0^2 / (4 t1 (y + b0/2 + h_m/mu_rec)) (000, eq. (1)); dimensionless."""
    b0, t1 = p.slot_width, p.slot_pitch
    return 1 - b0**2 / (4 * t1 * (y + b0 / 2 + p.magnet_height / p.recoil_permeability))


def carter_coefficient(p: StageParameters, y):
    """Carter's coefficient Kc(y) = t1 / (t1 - y gamma1(y)) (002, Section 3); dimensionless, > 1.

    gamma1 = (4/pi) [r atan(r) - ln sqrt(1 + r^2)] with r = b0 / (2 y).
    """
    r = p.slot_width / (2 * y)
    gamma1 = (4 / math.pi) * (r * ca.atan(r) - 0.5 * ca.log(1 + r**2))
    return p.slot_pitch / (p.slot_pitch - y * gamma1)


def field_closed_form(p: StageParameters, y):
    """Fundamental of the PMs' normal field B(y) [T] from the magnetic-charge model (SPEC 1).

    B = (4 mu0 sigma_m / pi) sin(pi tau_p / (2 tau)) sinh(a h_m) / sinh(a (h_m + y)), a = pi/tau.
    """
    a = math.pi / p.pole_pitch
    amplitude = 4 * MU0 * p.surface_charge / math.pi * math.sin(math.pi * p.magnet_width / (2 * p.pole_pitch))
    return amplitude * math.sinh(a * p.magnet_height) / ca.sinh(a * (p.magnet_height + y))


@dataclass(frozen=True)
class FieldPolynomial:
    """The papers' 12th-degree polynomial approximation of B(y), refitted to the closed form.

    The polynomial is in the scaled gap s = (y - center) / half_width in [-1, 1] (the raw power
    basis in metres is hopelessly ill-conditioned at degree 12). ``max_error`` [T] and
    ``max_relative_error`` are measured on a dense grid over ``fit_range``.
    """

    coefficients: tuple[float, ...]  # lowest power first, in the scaled variable
    center: float  # [m]
    half_width: float  # [m]
    fit_range: tuple[float, float]  # [m]
    max_error: float  # [T]
    max_relative_error: float  # [-]

    def __call__(self, y):
        s = (y - self.center) / self.half_width
        out = self.coefficients[-1]
        for c in reversed(self.coefficients[:-1]):
            out = out * s + c
        return out


def fit_field_polynomial(
    p: StageParameters,
    degree: int = FIELD_FIT_DEGREE,
    fit_range: tuple[float, float] = FIELD_FIT_RANGE,
) -> FieldPolynomial:
    """Least-squares fit of B(y) on Chebyshev nodes over ``fit_range`` (papers: 12th degree, 5-35 mm)."""
    lo, hi = fit_range
    if not 0 < lo < hi:
        raise InputError(f"fit_range must satisfy 0 < lo < hi, got {fit_range!r}")
    center, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    y_sym = ca.SX.sym("y")
    closed = ca.Function("B", [y_sym], [field_closed_form(p, y_sym)])
    nodes = np.cos(np.pi * (np.arange(4 * degree) + 0.5) / (4 * degree))
    y_nodes = center + half * nodes
    b_nodes = np.asarray(closed.map(len(y_nodes))(y_nodes)).ravel()
    coefficients = np.polynomial.polynomial.polyfit(nodes, b_nodes, degree)
    fit = FieldPolynomial(tuple(float(c) for c in coefficients), center, half, (lo, hi), 0.0, 0.0)
    y_dense = np.linspace(lo, hi, 3001)
    b_dense = np.asarray(closed.map(len(y_dense))(y_dense)).ravel()
    err = np.abs(np.asarray(fit(y_dense)) - b_dense)
    return FieldPolynomial(
        fit.coefficients, center, half, (lo, hi), float(err.max()), float((err / b_dense).max())
    )
