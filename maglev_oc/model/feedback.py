"""The feedback transformation (13)-(16) of paper 002 with the physical root (SPEC 1, reading 5).

Given the desired accelerations v = (v1, v2) of the linearized plant x4' = v1, x2' = v2:

    u1 = -v1 / L1(x1)                                                  (13)
    u2 = (-L3(x1) - sqrt(R)) / (2 L4(x1))                              (14), corrected root
    R(x1, v1, v2) = L3^2 - 4 L4 (L4 U + L2 - G + v2)                   (15)
    U(x1, v1) = (v1 / L1)^2                                            (16)

The printed (14), (L3 + sqrt R) / (2 L4), is this root with its sign flipped. The
transformation is defined on A = {R >= 0, L1 != 0, L4 != 0} (001, 002).

``feasibility_margin`` is R / (4 L4) [m/s^2]: how much further v2 could increase (the gap be
pushed open faster) before the transformation ceases to exist. It is positive inside A, zero on
its boundary, and its units make it comparable to the accelerations v.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.model.stage import StageModel

__all__ = ["FeedbackTransformation", "transformation_expressions"]


@dataclass(frozen=True, eq=False)
class FeedbackTransformation:
    """CasADi Functions of the transformation for one model, built once.

    Attributes
    ----------
    R : (x1, v) -> R                      discriminant (15) [(m/s^2/A)^2]
    margin : (x1, v) -> R / (4 L4)        feasibility margin [m/s^2]
    currents : (x1, v) -> u (2,)          (13), (14); NaN where R < 0
    currents_clipped : (x1, v) -> (u, R)  u with sqrt(max(R, 0)): the closest realisable input
    """

    model: StageModel
    R: ca.Function = field(init=False, repr=False)
    margin: ca.Function = field(init=False, repr=False)
    currents: ca.Function = field(init=False, repr=False)
    currents_clipped: ca.Function = field(init=False, repr=False)

    def __post_init__(self) -> None:
        x1 = ca.SX.sym("x1")
        v = ca.SX.sym("v", 2)
        r, u, u_clip = transformation_expressions(self.model, x1, v)
        L4 = self.model.L(x1)[3]
        set_ = object.__setattr__
        set_(self, "R", ca.Function("R", [x1, v], [r], ["x1", "v"], ["R"]))
        set_(self, "margin", ca.Function("margin", [x1, v], [r / (4 * L4)], ["x1", "v"], ["margin"]))
        set_(self, "currents", ca.Function("currents", [x1, v], [u], ["x1", "v"], ["u"]))
        set_(
            self,
            "currents_clipped",
            ca.Function("currents_clipped", [x1, v], [u_clip, r], ["x1", "v"], ["u", "R"]),
        )

    def feasibility_margin(self, x1, v1, v2) -> np.ndarray:
        """R / (4 L4) [m/s^2] for arrays of x1 [m], v1, v2 [m/s^2] (broadcast together)."""
        x1, v1, v2 = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (x1, v1, v2)))
        n = x1.size
        out = self.margin.map(n)(x1.reshape(1, n), np.vstack([v1.ravel(), v2.ravel()]))
        return np.asarray(out).reshape(x1.shape)

    def discriminant(self, x1, v1, v2) -> np.ndarray:
        """R(x1, v1, v2) of (15) for arrays (broadcast together)."""
        x1, v1, v2 = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (x1, v1, v2)))
        n = x1.size
        out = self.R.map(n)(x1.reshape(1, n), np.vstack([v1.ravel(), v2.ravel()]))
        return np.asarray(out).reshape(x1.shape)


def transformation_expressions(model: StageModel, x1, v):
    """Symbolic R, u and u with R clipped at zero, for use inside larger CasADi graphs."""
    L1, L2, L3, L4 = model.L(x1)
    G = model.params.gravity
    u1 = -v[0] / L1
    r = L3**2 - 4 * L4 * (L4 * u1**2 + L2 - G + v[1])
    u2 = (-L3 - ca.sqrt(r)) / (2 * L4)
    u2_clip = (-L3 - ca.sqrt(ca.fmax(r, 0))) / (2 * L4)
    return r, ca.vertcat(u1, u2), ca.vertcat(u1, u2_clip)
