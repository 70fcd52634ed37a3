"""The microstepper's feedback transformation: four currents for three forces.

For the platform of :func:`~maglev_oc.model.platform.microstepper` (coordinates (x, y, gap), inputs
(i_qA, i_dA, i_qB, i_dB)), the accelerations v = (v_x, v_y, v_gap) the regulator asks for fix the
thrusts and the total normal force, as in 002 eq. (13) for one motor:

    i_qA = -m_x v_x / (2 K1 l1(y)),    i_qB = -m_y v_y / (2 K1 l1(y))
    2 N(y, i_qA, i_dA) + 2 N(y, i_qB, i_dB) = m_gap (G - v_gap)

with N(y, i_q, i_d) = K2 l2 + K3 l3 i_d + K4 l4 (i_q^2 + i_d^2) per motor. The last equation leaves
one degree of freedom between i_dA and i_dB: the input redundancy. Two ways to resolve it:

* **minimum current norm** (closed form, the default): minimising i_dA^2 + i_dB^2 on the
  constraint gives i_dA = i_dB (Lagrange: i / (K3 l3 + 2 K4 l4 i) must be equal for both pairs, and
  it is monotonic in i), so the quadratic of 002 eq. (13) returns with averaged coefficients:

      K4 l4 i_d^2 + K3 l3 i_d + K2 l2 + K4 l4 (i_qA^2 + i_qB^2) / 2 - m_gap (G - v_gap) / 4 = 0,
      i_d = (-K3 l3 - sqrt(R)) / (2 K4 l4),
      R = (K3 l3)^2 - 4 K4 l4 (K2 l2 + K4 l4 (i_qA^2 + i_qB^2) / 2 - m_gap (G - v_gap) / 4),

  defined where R >= 0 (the microstepper's feasibility set, as (15) of 001 for the 2-DOF stage);
* **maximum feasibility margin** (numerical): the split of the normal load that keeps the larger
  pair current magnitude sqrt(i_q^2 + i_d^2) smallest, so that a pair accelerating hard leaves the
  levitation to the other pair before it reaches the amplifiers' 9 A. Equal to the minimum norm
  when i_qA^2 = i_qB^2 (at rest, in every equilibrium).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
from scipy.optimize import minimize_scalar

from maglev_oc.errors import InputError
from maglev_oc.model.magnetics import field_closed_form
from maglev_oc.model.platform import Platform
from maglev_oc.model.stage import _shape_expressions

__all__ = ["ALLOCATIONS", "Allocation", "MicrostepperTransformation"]

ALLOCATIONS = ("minimum_norm", "maximum_margin")


@dataclass(frozen=True)
class Allocation:
    """Currents for one request.

    Attributes
    ----------
    currents : (4,) array  (i_qA, i_dA, i_qB, i_dB) [A]
    discriminant : float   R of the minimum-norm solution [N^2/A^2 scale]; < 0: not defined
    peak : float           the larger pair magnitude sqrt(i_q^2 + i_d^2) [A]
    method : str
    """

    currents: np.ndarray
    discriminant: float
    peak: float
    method: str

    @property
    def defined(self) -> bool:
        return self.discriminant >= 0


class MicrostepperTransformation:
    """The feedback transformation (v, gap) -> currents of the 3-DOF microstepper, built once.

    ``function`` is the CasADi Function (gap, v (3)) -> (currents (4), R) of the minimum-norm
    allocation, for use inside a controller; :meth:`allocate` also gives the maximum-margin one.
    ``coefficients`` is gap -> (k1, k2, k3, k4) of one motor: thrust -k1 i_q [N], normal force
    k2 + k3 i_d + k4 (i_q^2 + i_d^2) [N] (K_i l_i(gap)).
    """

    def __init__(self, platform: Platform) -> None:
        if platform.coordinates != ("x", "y", "gap") or platform.n_inputs != 4:
            raise InputError(
                f"{platform.name}: the microstepper transformation needs coordinates (x, y, gap) and "
                "inputs (i_qA, i_dA, i_qB, i_dB)"
            )
        self.platform = platform
        p = platform.params
        K = platform.force_constants()
        self.masses = np.asarray(platform.masses, dtype=float)
        self.gravity = float(platform.gravity[2])
        y, v = ca.SX.sym("y"), ca.SX.sym("v", 3)
        l = _shape_expressions(p, y, lambda g: field_closed_form(p, g))
        k1, k2, k3, k4 = (float(K[i]) * l[i] for i in range(4))
        iqa = -self.masses[0] * v[0] / (2 * k1)
        iqb = -self.masses[1] * v[1] / (2 * k1)
        load = self.masses[2] * (self.gravity - v[2])
        R = k3**2 - 4 * k4 * (k2 + k4 * (iqa**2 + iqb**2) / 2 - load / 4)
        # a floor above 0 keeps the derivative finite (0, not 0 * inf) where R < 0
        i_d = (-k3 - ca.sqrt(ca.fmax(R, 1e-300))) / (2 * k4)
        self.function = ca.Function(
            "microstepper_fl", [y, v], [ca.vertcat(iqa, i_d, iqb, i_d), R], ["gap", "v"], ["u", "R"]
        )
        self.coefficients = ca.Function("k", [y], [ca.vertcat(k1, k2, k3, k4)], ["gap"], ["k"])

    def allocate(self, gap: float, v, method: str = "minimum_norm") -> Allocation:
        """The currents that give accelerations ``v`` (3) [m/s^2] at ``gap`` [m]."""
        if method not in ALLOCATIONS:
            raise InputError(f"allocation must be one of {ALLOCATIONS}, got {method!r}")
        u, R = self.function(gap, np.asarray(v, dtype=float))
        u, R = np.asarray(u).ravel(), float(R)
        if method == "maximum_margin" and R >= 0:
            u = self._maximum_margin(gap, u, v)
        peak = float(max(np.hypot(u[0], u[1]), np.hypot(u[2], u[3])))
        return Allocation(u, R, peak, method)

    def _maximum_margin(self, gap: float, u: np.ndarray, v) -> np.ndarray:
        """Split the normal load between the pairs so that the larger pair magnitude is smallest."""
        _, k2, k3, k4 = np.asarray(self.coefficients(gap)).ravel()
        iqa, iqb = u[0], u[2]
        load = self.masses[2] * (self.gravity - float(v[2]))
        # per pair: 2 N(i_q, i_d) = 2 (k2 + k3 i_d + k4 (i_q^2 + i_d^2)); given i_dA, i_dB solves
        # k4 i^2 + k3 i + (k2 + k4 i_qB^2 - (load / 2 - N_A)) = 0 (the small root, as (13))

        def other(ida: float) -> float:
            n_a = k2 + k3 * ida + k4 * (iqa**2 + ida**2)
            c = k2 + k4 * iqb**2 - (load / 2 - n_a)
            disc = k3**2 - 4 * k4 * c
            return np.nan if disc < 0 else (-k3 - np.sqrt(disc)) / (2 * k4)

        def worst(ida: float) -> float:
            idb = other(ida)
            return np.inf if np.isnan(idb) else max(iqa**2 + ida**2, iqb**2 + idb**2)

        span = 4 * max(abs(u[1]), 1.0)
        best = minimize_scalar(worst, bounds=(u[1] - span, u[1] + span), method="bounded")
        ida = float(best.x) if worst(best.x) <= worst(u[1]) else u[1]
        return np.array([iqa, ida, iqb, other(ida)])
