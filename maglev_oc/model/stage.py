"""The symbolic 2-DOF stage model of SPEC 1 (eq. (1)-(2) of paper 000, eq. (3) of paper 002).

State x = (x1, x2, x3, x4) = (air gap [m], gap rate [m/s], horizontal position [m], its rate
[m/s]); input u = (u1, u2) = (i_q, i_d) [A]. Gravity opens the gap:

    x1' = x2
    x2' = G - L4(x1) (u1^2 + u2^2) - L3(x1) u2 - L2(x1)
    x3' = x4
    x4' = -L1(x1) u1

with L_i(y) = C_i * l_i(y), where the shape functions l_i depend only on the geometry (Table I)
and the lumped constants C1..C4 enter linearly (000, eq. (2)). l3 carries the minus sign of
K3 so that C3 > 0 (SPEC 1, reading 4).

Trajectories and batches are always column-major: shape ``(n_states, n_samples)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.model.magnetics import (
    FieldPolynomial,
    carter_coefficient,
    field_closed_form,
    fit_field_polynomial,
    slot_factor,
)
from maglev_oc.model.parameters import DEFAULT_CONSTANTS, LumpedConstants, StageParameters

__all__ = ["FIELD_MODELS", "N_INPUTS", "N_STATES", "StageModel"]

N_STATES = 4
N_INPUTS = 2
FIELD_MODELS = ("closed_form", "polynomial")


def _shape_expressions(params: StageParameters, y, field_fn) -> list:
    """The four shape functions l1..l4 of eqs. (5)-(8) of 002 at gap ``y`` (L_i = C_i l_i).

    l1 = lam / (Kc sinh(a (h_m + y)))           [1/1]   (L1 = C1 l1, m/(s^2 A))
    l2 = lam B^2                                 [T^2]
    l3 = -lam B coth(a (h_m + y)) / Kc           [T]
    l4 = lam coth(a (h_m + y))^2 / Kc^2          [1]
    """
    a = math.pi / params.pole_pitch
    lam = slot_factor(params, y)
    kc = carter_coefficient(params, y)
    b = field_fn(y)
    arg = a * (params.magnet_height + y)
    coth = ca.cosh(arg) / ca.sinh(arg)
    return [
        lam / (kc * ca.sinh(arg)),
        lam * b**2,
        -lam * b * coth / kc,
        lam * coth**2 / kc**2,
    ]


@dataclass(frozen=True, eq=False)
class StageModel:
    """The stage model with its CasADi Functions, built once when the object is made.

    Parameters
    ----------
    params : StageParameters
        Table I (SI units).
    constants : LumpedConstants
        C1..C4 (default: Table III, eps = 0.01).
    field_model : {"closed_form", "polynomial"}
        PM field B(y): the closed form of SPEC 1 (default) or the papers' 12th-degree polynomial
        fitted to it over 5-35 mm (outside that range the polynomial is extrapolated).

    Attributes (CasADi Functions; all accept column batches through ``.map``)
    ----------
    pm_field : y -> B                        PM field [T]
    shape : y -> l (4,)                      shape functions, L = C * l
    L : y -> (L1, L2, L3, L4)                with this model's constants
    f : (x, u) -> x'                         state equation
    f_theta : (x, u, C) -> x'                state equation with the constants as an input
    jacobian : (x, u) -> (A, B)              exact df/dx (4x4) and df/du (4x2)
    regressor : (x, u) -> (Phi, b)           accelerations (x2', x4') = Phi C + b
    """

    params: StageParameters = field(default_factory=StageParameters)
    constants: LumpedConstants = DEFAULT_CONSTANTS
    field_model: str = "closed_form"

    field_polynomial: FieldPolynomial | None = field(init=False, repr=False)
    pm_field: ca.Function = field(init=False, repr=False)
    shape: ca.Function = field(init=False, repr=False)
    L: ca.Function = field(init=False, repr=False)
    L_theta: ca.Function = field(init=False, repr=False)
    regressor: ca.Function = field(init=False, repr=False)
    f_theta: ca.Function = field(init=False, repr=False)
    f: ca.Function = field(init=False, repr=False)
    jacobian: ca.Function = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.params, StageParameters):
            raise TypeError(f"params must be StageParameters, got {type(self.params).__name__}")
        if not isinstance(self.constants, LumpedConstants):
            raise TypeError(f"constants must be LumpedConstants, got {type(self.constants).__name__}")
        if self.field_model not in FIELD_MODELS:
            raise InputError(f"field_model must be one of {FIELD_MODELS}, got {self.field_model!r}")
        self._build()

    # ------------------------------------------------------------------------------------
    def _build(self) -> None:
        p = self.params
        set_ = object.__setattr__
        field_poly: FieldPolynomial | None = None
        if self.field_model == "polynomial":
            field_poly = fit_field_polynomial(p)
            field_fn = field_poly
        else:

            def field_fn(y):
                return field_closed_form(p, y)

        set_(self, "field_polynomial", field_poly)

        y = ca.SX.sym("y")
        theta = ca.SX.sym("C", 4)
        shapes = ca.vertcat(*_shape_expressions(p, y, field_fn))
        set_(self, "pm_field", ca.Function("B", [y], [field_fn(y)], ["y"], ["B"]))
        set_(self, "shape", ca.Function("shape", [y], [shapes], ["y"], ["l"]))
        c_nom = ca.DM(self.constants.as_array())
        L_nom = c_nom * shapes
        set_(
            self,
            "L",
            ca.Function("L", [y], [L_nom[0], L_nom[1], L_nom[2], L_nom[3]], ["y"], ["L1", "L2", "L3", "L4"]),
        )
        set_(self, "L_theta", ca.Function("L_theta", [y, theta], [theta * shapes], ["y", "C"], ["L"]))

        x = ca.SX.sym("x", N_STATES)
        u = ca.SX.sym("u", N_INPUTS)
        l = ca.substitute(shapes, y, x[0])
        G = p.gravity
        # accelerations = Phi(x, u) C + b   (rows: x2', x4')
        phi = ca.SX.zeros(2, 4)
        phi[0, 1] = -l[1]
        phi[0, 2] = -l[2] * u[1]
        phi[0, 3] = -l[3] * (u[0] ** 2 + u[1] ** 2)
        phi[1, 0] = -l[0] * u[0]
        b = ca.vertcat(G, 0)
        set_(self, "regressor", ca.Function("regressor", [x, u], [phi, b], ["x", "u"], ["Phi", "b"]))
        acc = phi @ theta + b
        xdot = ca.vertcat(x[1], acc[0], x[3], acc[1])
        set_(self, "f_theta", ca.Function("f_theta", [x, u, theta], [xdot], ["x", "u", "C"], ["xdot"]))
        xdot_nom = ca.substitute(xdot, theta, c_nom)
        set_(self, "f", ca.Function("f", [x, u], [xdot_nom], ["x", "u"], ["xdot"]))
        set_(
            self,
            "jacobian",
            ca.Function(
                "jac_f",
                [x, u],
                [ca.jacobian(xdot_nom, x), ca.jacobian(xdot_nom, u)],
                ["x", "u"],
                ["A", "B"],
            ),
        )

    # ------------------------------------------------------------------------------------
    def with_constants(self, constants: LumpedConstants) -> StageModel:
        """The same geometry and field model with other lumped constants."""
        return StageModel(self.params, constants, self.field_model)

    def coefficients(self, gap) -> np.ndarray:
        """L1..L4 at each gap [m]; returns shape (4, n)."""
        gap = np.atleast_1d(np.asarray(gap, dtype=float))
        out = self.L_theta.map(gap.size)(gap[None, :], ca.DM(self.constants.as_array()))
        return np.asarray(out)

    def field_at(self, gap) -> np.ndarray:
        """B(y) [T] at each gap [m]; shape (n,)."""
        gap = np.atleast_1d(np.asarray(gap, dtype=float))
        return np.asarray(self.pm_field.map(gap.size)(gap[None, :])).ravel()

    def dynamics(self, x, u) -> np.ndarray:
        """x' for column batches x (4, n) and u (2, n); returns (4, n)."""
        x = np.asarray(x, dtype=float).reshape(N_STATES, -1)
        u = np.asarray(u, dtype=float).reshape(N_INPUTS, -1)
        n = max(x.shape[1], u.shape[1])
        return np.asarray(self.f.map(n)(np.broadcast_to(x, (N_STATES, n)), np.broadcast_to(u, (N_INPUTS, n))))
