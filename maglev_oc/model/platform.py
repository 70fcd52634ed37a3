"""A stage built from motors: a rigid platform that translates on linear guides, moved by PMLSMs.

Each motor is the 2-DOF stage's PMLSM (eqs. (1)-(2) of 000, eq. (3) of 002) with its own
orientation, placement and wiring. A motor k with unit thrust direction ``t_k`` and unit normal
``n_k`` (from the mover towards its stator), driven by the inputs ``(i_q, i_d)`` its wiring names,
sees

    gap        y_k = gap_at_zero_k - n_k . q          (moving towards the stator closes the gap)
    position   s_k = position_at_zero_k + t_k . q     (along its stator)

for platform coordinates q, and pushes the platform with

    F_k = T_k t_k + N_k n_k,
    T_k = -K1 l1(y_k) i_q                                        (thrust)
    N_k =  K2 l2(y_k) + K3 l3(y_k) i_d + K4 l4(y_k) (i_q^2 + i_d^2)   (normal, towards the stator)

with the shape functions l1..l4 of :mod:`~maglev_oc.model.stage` and force constants
K1 = C1 M_h, K2..K4 = C_i M_v [N per unit of l_i]: the lumped constants of the 2-DOF rig
(which divide the forces by the mass each axis moves there) times those masses. The platform
has a diagonal mass matrix (stacked guides: coordinate j moves mass m_j) and gravity g_j along
each coordinate, so

    q_j'' = g_j + (sum_k F_k . e_j) / m_j.

State x = (q_1, q_1', q_2, q_2', ...), inputs u as the wiring numbers them. The 2-DOF stage is
the instance with coordinates (gap, position), one motor with n = -e_gap, t = e_position, masses
(M_v, M_h) and gravity +G on the gap: its dynamics are :class:`~maglev_oc.model.stage.StageModel`'s
to rounding (a test checks it). The 3-DOF microstepper of 002 Sec. 8 is
:func:`microstepper`; nothing here assumes two axes or one motor per input pair.

Rotations are left for later: the platform's guides hold it translational (002 Sec. 8), so a
motor's placement on the platform does not enter; a 6-DOF platform adds the attitude to q and the
placements to the forces' moments.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.model.magnetics import field_closed_form
from maglev_oc.model.parameters import DEFAULT_CONSTANTS, LumpedConstants, StageParameters
from maglev_oc.model.stage import _shape_expressions

__all__ = [
    "MICROSTEPPER_ASSUMPTIONS",
    "Motor",
    "Platform",
    "PlatformModel",
    "microstepper",
    "two_dof_platform",
]

_UNIT_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Motor:
    """One PMLSM on the platform.

    Attributes
    ----------
    name : str
    thrust : tuple of float  unit vector t (platform coordinates) along which its thrust acts
    normal : tuple of float  unit vector n from the mover towards its stator (attraction)
    inputs : (int, int)      indices of its (i_q, i_d) in the input vector (motors wired in
                             parallel share them)
    gap_at_zero : float      [m] its gap when q = 0
    position_at_zero : float [m] the mover's position along its stator when q = 0
    """

    name: str
    thrust: tuple[float, ...]
    normal: tuple[float, ...]
    inputs: tuple[int, int]
    gap_at_zero: float = 0.0
    position_at_zero: float = 0.0

    def __post_init__(self) -> None:
        t, n = np.asarray(self.thrust, float), np.asarray(self.normal, float)
        if t.shape != n.shape:
            raise InputError(f"motor {self.name}: thrust and normal need the same length")
        for label, v in (("thrust", t), ("normal", n)):
            if abs(np.linalg.norm(v) - 1) > _UNIT_TOLERANCE:
                raise InputError(f"motor {self.name}: {label} must be a unit vector, got {tuple(v)}")
        if abs(float(t @ n)) > _UNIT_TOLERANCE:
            raise InputError(f"motor {self.name}: thrust and normal must be orthogonal")
        if len(self.inputs) != 2 or self.inputs[0] == self.inputs[1]:
            raise InputError(f"motor {self.name}: inputs must be two distinct indices (i_q, i_d)")


@dataclass(frozen=True)
class Platform:
    """A rigid translational platform and its motors.

    Attributes
    ----------
    coordinates : tuple of str  names of the platform coordinates q (e.g. ("x", "y", "gap"))
    masses : tuple of float     [kg] the mass each coordinate moves (stacked guides)
    gravity : tuple of float    [m/s^2] gravity along each coordinate
    motors : tuple of Motor
    n_inputs : int
    params : StageParameters    the motors' geometry (Table I)
    constants : LumpedConstants C1..C4 of the 2-DOF rig, whose masses in ``params`` turn them
                                into the force constants K_i
    name : str
    assumptions : tuple of str  what the instance assumes where the papers are silent
    """

    coordinates: tuple[str, ...]
    masses: tuple[float, ...]
    gravity: tuple[float, ...]
    motors: tuple[Motor, ...]
    n_inputs: int
    params: StageParameters = field(default_factory=StageParameters)
    constants: LumpedConstants = DEFAULT_CONSTANTS
    name: str = "platform"
    assumptions: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        d = len(self.coordinates)
        if len(self.masses) != d or len(self.gravity) != d:
            raise InputError(f"{self.name}: one mass and one gravity component per coordinate ({d})")
        if any(not m > 0 for m in self.masses):
            raise InputError(f"{self.name}: masses must be positive, got {self.masses}")
        if not self.motors:
            raise InputError(f"{self.name}: a platform needs at least one motor")
        used = set()
        for m in self.motors:
            if len(m.thrust) != d:
                raise InputError(f"motor {m.name}: vectors need {d} components ({self.coordinates})")
            if max(m.inputs) >= self.n_inputs or min(m.inputs) < 0:
                raise InputError(f"motor {m.name}: inputs {m.inputs} outside 0..{self.n_inputs - 1}")
            used.update(m.inputs)
        if used != set(range(self.n_inputs)):
            raise InputError(f"{self.name}: inputs {sorted(set(range(self.n_inputs)) - used)} drive no motor")

    @property
    def n_states(self) -> int:
        return 2 * len(self.coordinates)

    def force_constants(self) -> np.ndarray:
        """K1..K4 of one motor: C1 M_h, C2 M_v, C3 M_v, C4 M_v of the 2-DOF rig."""
        c, p = self.constants.as_array(), self.params
        return np.array(
            [c[0] * p.mass_horizontal, c[1] * p.mass_vertical, c[2] * p.mass_vertical, c[3] * p.mass_vertical]
        )


@dataclass(frozen=True, eq=False)
class PlatformModel:
    """The platform's CasADi Functions, built once.

    Attributes
    ----------
    f : (x, u) -> x'                 state equation
    jacobian : (x, u) -> (A, B)      exact df/dx and df/du
    motor_forces : (x, u) -> (T, N, y, s)  per motor thrust [N], normal force [N], gap [m] and
                                          position along its stator [m]
    """

    platform: Platform
    f: ca.Function = field(init=False, repr=False)
    jacobian: ca.Function = field(init=False, repr=False)
    motor_forces: ca.Function = field(init=False, repr=False)

    def __post_init__(self) -> None:
        pf = self.platform
        d, nu = len(pf.coordinates), pf.n_inputs
        x, u = ca.SX.sym("x", 2 * d), ca.SX.sym("u", nu)
        q, qd = x[0::2], x[1::2]
        K = pf.force_constants()
        force = ca.SX.zeros(d)
        thrusts, normals, gaps, positions = [], [], [], []
        for m in pf.motors:
            t, n = ca.DM(m.thrust), ca.DM(m.normal)
            y = m.gap_at_zero - ca.dot(n, q)
            l = _shape_expressions(pf.params, y, lambda g: field_closed_form(pf.params, g))
            iq, id_ = u[m.inputs[0]], u[m.inputs[1]]
            thrust = -K[0] * l[0] * iq
            normal = K[1] * l[1] + K[2] * l[2] * id_ + K[3] * l[3] * (iq**2 + id_**2)
            force += thrust * t + normal * n
            thrusts.append(thrust)
            normals.append(normal)
            gaps.append(y)
            positions.append(m.position_at_zero + ca.dot(t, q))
        acc = ca.DM(pf.gravity) + force / ca.DM(pf.masses)
        xdot = ca.SX.zeros(2 * d)
        xdot[0::2] = qd
        xdot[1::2] = acc
        set_ = object.__setattr__
        set_(self, "f", ca.Function("f", [x, u], [xdot], ["x", "u"], ["xdot"]))
        set_(
            self,
            "jacobian",
            ca.Function(
                "jac_f", [x, u], [ca.jacobian(xdot, x), ca.jacobian(xdot, u)], ["x", "u"], ["A", "B"]
            ),
        )
        set_(
            self,
            "motor_forces",
            ca.Function(
                "motor_forces",
                [x, u],
                [ca.vertcat(*thrusts), ca.vertcat(*normals), ca.vertcat(*gaps), ca.vertcat(*positions)],
                ["x", "u"],
                ["T", "N", "y", "s"],
            ),
        )

    def dynamics(self, x, u) -> np.ndarray:
        """x' for column batches x (n_states, n) and u (n_inputs, n)."""
        pf = self.platform
        x = np.asarray(x, dtype=float).reshape(pf.n_states, -1)
        u = np.asarray(u, dtype=float).reshape(pf.n_inputs, -1)
        n = max(x.shape[1], u.shape[1])
        xb = np.broadcast_to(x, (pf.n_states, n))
        ub = np.broadcast_to(u, (pf.n_inputs, n))
        return np.asarray(self.f.map(n)(xb, ub))


def two_dof_platform(
    params: StageParameters | None = None, constants: LumpedConstants = DEFAULT_CONSTANTS
) -> Platform:
    """The 2-DOF stage (papers 000-002) as a platform: coordinates (gap, position), one motor."""
    p = params or StageParameters()
    return Platform(
        coordinates=("gap", "position"),
        masses=(p.mass_vertical, p.mass_horizontal),
        gravity=(p.gravity, 0.0),
        motors=(Motor("PMLSM", thrust=(0.0, 1.0), normal=(-1.0, 0.0), inputs=(0, 1)),),
        n_inputs=2,
        params=p,
        constants=constants,
        name="2-DOF stage",
    )


MICROSTEPPER_ASSUMPTIONS = (
    "Coordinates (x, y, gap): the platform translates in x and y and all four movers share one air "
    "gap (the linear guides keep it level; 002 Sec. 8: 'purely translational').",
    "Four motors identical to the 2-DOF rig's PMLSM (Table I geometry, the same C1..C4): pair A (two "
    "motors, thrust along x) is driven by inputs (i_qA, i_dA), pair B (thrust along y) by (i_qB, i_dB); "
    "the three phases of a pair are in parallel, so both motors of a pair carry the same currents and "
    "sit at the same electrical angle (their movers a whole number of pole pairs apart).",
    "A pair shares the normal load equally: its two motors have the same gap and currents, so each "
    "makes the same normal force.",
    "A mover displaced across its stator (pair A's movers when the platform moves in y, pair B's in x) "
    "keeps its force: the stators are wider than the movers by more than the +-50 mm travel, so the "
    "magnetic overlap does not change (end effects across the stator are neglected).",
    "Masses per axis (Table I gives the 2-DOF's only): the platform and the four movers, 4 M_h, move in "
    "x (the innermost guides); the y guides carry them plus one 2-DOF guide carriage (M_v - M_h); the "
    "vertical guides carry everything plus another (the masses are a parameter of the instance).",
    "Gravity opens the gap, as in the 2-DOF rig (the stators above the movers).",
    "Operating region 002 Sec. 8: x, y in [-50, 50] mm, gap in [20, 30] mm.",
)


def microstepper(
    params: StageParameters | None = None,
    constants: LumpedConstants = DEFAULT_CONSTANTS,
    *,
    masses: Sequence[float] | None = None,
) -> Platform:
    """The 3-DOF microstepper of 002 Sec. 8 (Fig. 14): four PMLSMs in two pairs, coordinates
    (x, y, gap), inputs (i_qA, i_dA, i_qB, i_dB). See :data:`MICROSTEPPER_ASSUMPTIONS`."""
    p = params or StageParameters()
    if masses is None:
        carriage = p.mass_vertical - p.mass_horizontal
        mx = 4 * p.mass_horizontal
        masses = (mx, mx + carriage, mx + 2 * carriage)
    if len(masses) != 3:
        raise InputError(f"microstepper: three masses (x, y, gap) needed, got {len(masses)}")
    along_x, along_y, towards_stator = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, -1.0)
    motors = [
        Motor(name, thrust=t, normal=towards_stator, inputs=inputs)
        for name, t, inputs in (
            ("A1", along_x, (0, 1)),
            ("A2", along_x, (0, 1)),
            ("B1", along_y, (2, 3)),
            ("B2", along_y, (2, 3)),
        )
    ]
    return Platform(
        coordinates=("x", "y", "gap"),
        masses=tuple(float(m) for m in masses),
        gravity=(0.0, 0.0, p.gravity),
        motors=tuple(motors),
        n_inputs=4,
        params=p,
        constants=constants,
        name="3-DOF microstepper",
        assumptions=MICROSTEPPER_ASSUMPTIONS,
    )
