"""The optimal control problem transcribed by multiple shooting with one RK4 step per interval.

The OCP solved at every sample k, on the controller's own model with constant acceleration
disturbances d = (d_v, d_h):

    min   sum_{j<N} h_j [ |x_j - xr_j|_Q^2 + |u_j - ur_j|_R^2 ]  +  |x_N - xr_N|_P(r_v,N)^2
    s.t.  x_0 = x^(k)                           (observer estimate, initial-value embedding)
          x_{j+1} = RK4(x_j, u_j, d; h_j)        (one RK4 step per shooting interval)
          current polytope:  |u_1|, |u_2| <= r,  |u_1 +- u_2| <= sqrt(2) r,   r = I_max cos(pi/8)
          gap and horizontal bounds on x_j, j >= 2

with f(x, u, d) = f(x, u) + (0, d_v, 0, d_h). The input reference ur is the inverse dynamics
along the reference with the disturbance removed (the feedback transformation of SPEC 1 at
x1 = r_v, v = (r_h'' - d_h, r_v'' - d_v)); P is :mod:`.terminal`'s table.

:class:`Transcription` builds the symbolic pieces once; the RTI (:mod:`.rti`) and the converged
solver (:mod:`.converged`) share them. The decision vector's layout is :mod:`.layout`'s.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from maglev_oc.control.base import N_REFERENCE
from maglev_oc.control.nmpc.grid import ShootingGrid
from maglev_oc.control.nmpc.layout import NU, NX, STAGE_ROWS, STAGE_SIZE, u_index, x_index
from maglev_oc.control.nmpc.settings import NMPCWeights
from maglev_oc.control.nmpc.terminal import LocalLQR, TerminalCostTable, local_lqr, terminal_cost_table
from maglev_oc.estimation.extended_high_gain import N_DISTURBANCE
from maglev_oc.model.feedback import transformation_expressions
from maglev_oc.model.stage import StageModel
from maglev_oc.numerics import rk4_step

__all__ = ["OCTAGON", "Transcription"]

OCTAGON = np.array([[1.0, 1.0], [1.0, -1.0]])
"""D: the octagon's diagonal rows, |D u| <= sqrt(2) r (the axis rows are simple bounds on u)."""
_BIG = 1e8  # stands for an infinite bound in the QP data (HPIPM's own 'inf' default)
_POSITION_SCALE = 1e-3  # positions in mm in the QP (see Transcription.z_scale)


class Transcription:
    """Symbolic pieces shared by the RTI and the converged solver (built once).

    Parameters
    ----------
    model : StageModel
        The controller's model.
    grid : ShootingGrid
    weights : NMPCWeights
    current_limit : float
        Amplifier peak current [A]; the octagon's inscribed radius is ``current_limit cos(pi/8)``.
    gap_bounds, position_bounds : (float, float)
        Bounds [m] on x1 and x3 at nodes 2..N.

    Attributes
    ----------
    rk4 : casadi.Function
        (x, u, d, h) -> x_next: one RK4 step of the model with the disturbance.
    rk4_lin : casadi.Function
        (x, u, d, h) -> (x_next, A, B): the same step and its Jacobians.
    feedforward : casadi.Function
        (r, d) -> u: the current realising the reference sample r with the disturbance removed.
    terminal : TerminalCostTable
    nz, na : int
        Entries of z and rows of the constraint matrix (both 6 N, by :mod:`.layout`).
    cost_scale : float
        c [-]: the QP's cost is c times the OCP's (:meth:`qp_data_function`, Notes).
    radius : float
        Inscribed radius of the current octagon [A].
    """

    def __init__(
        self,
        model: StageModel,
        grid: ShootingGrid,
        weights: NMPCWeights,
        current_limit: float,
        gap_bounds: tuple[float, float],
        position_bounds: tuple[float, float],
        effects: ca.Function | None = None,
    ) -> None:
        self.model = model
        self.grid = grid
        self.weights = weights
        self.N = grid.horizon
        self.nz = STAGE_SIZE * self.N
        self.na = STAGE_ROWS * self.N
        self.radius = current_limit * math.cos(math.pi / 8)  # inscribed octagon
        self.gap_bounds = gap_bounds
        self.position_bounds = position_bounds
        # the QP's cost is multiplied by this so that the Hessian's smallest entry, the first
        # (one-sample) interval's input weight 2 h_0 min(R), is 1 (see qp_data_function)
        self.cost_scale = 1.0 / (
            2.0 * float(grid.intervals[0]) * float(np.min(np.diag(weights.input_weight)))
        )

        x = ca.SX.sym("x", NX)
        u = ca.SX.sym("u", NU)
        d = ca.SX.sym("d", N_DISTURBANCE)
        h = ca.SX.sym("h")
        e = effects(x, u) if effects is not None else ca.SX.zeros(2, 1)
        xdot = model.f(x, u) + ca.vertcat(0, d[0] + e[0], 0, d[1] + e[1])
        fd = ca.Function("f_d", [x, u, d], [xdot])
        x_next = rk4_step(fd, x, h, u, d)
        self.rk4 = ca.Function("rk4", [x, u, d, h], [x_next], ["x", "u", "d", "h"], ["x_next"])
        self.rk4_lin = ca.Function(
            "rk4_lin",
            [x, u, d, h],
            [x_next, ca.jacobian(x_next, x), ca.jacobian(x_next, u)],
            ["x", "u", "d", "h"],
            ["x_next", "A", "B"],
        )
        # feedforward current of the reference with the disturbance removed (SPEC 1, reading 5)
        r = ca.SX.sym("r", N_REFERENCE)
        _, _, u_ff = transformation_expressions(model, r[0], ca.vertcat(r[5] - d[1], r[2] - d[0]))
        if effects is not None:
            # the effects at the reference state, at the feedforward without them (one fixed-point
            # step: an effect that depends on the current is evaluated at the current it nearly is)
            e_r = effects(ca.vertcat(r[0], r[1], r[3], r[4]), u_ff)
            _, _, u_ff = transformation_expressions(
                model, r[0], ca.vertcat(r[5] - d[1] - e_r[1], r[2] - d[0] - e_r[0])
            )
        self.feedforward = ca.Function("feedforward", [r, d], [u_ff], ["r", "d"], ["u"])
        self.terminal: TerminalCostTable = terminal_cost_table(model, self.rk4_lin, weights, grid.interval)

    def local_lqr(self, gap: float, position: float = 0.0) -> LocalLQR:
        """The linear-quadratic law the NMPC reduces to near the equilibrium at ``gap`` [m]."""
        return local_lqr(self.model, self.rk4_lin, self.weights, self.grid, self.terminal, gap, position)

    # ------------------------------------------------------------------------------------
    def references(self, ref, d):
        """(z_ref, P) of the OCP for the node references ``ref`` (6, N + 1) and disturbance d."""
        n = self.N
        parts = []
        for j in range(n):
            rj = ref[:, j]
            if j > 0:
                parts.append(ca.vertcat(rj[0], rj[1], rj[3], rj[4]))
            parts.append(self.feedforward(rj, d))
        rn = ref[:, n]
        parts.append(ca.vertcat(rn[0], rn[1], rn[3], rn[4]))
        return ca.vertcat(*parts), self.terminal.expression(rn[0])

    def cost_weight(self, p):
        """W (6N, 6N) sparse: the cost is (z - z_ref)' W (z - z_ref)."""
        q = ca.DM(self.weights.state_weight)
        r = ca.DM(self.weights.input_weight)
        blocks = []
        for j, h in enumerate(self.grid.intervals):
            if j > 0:
                blocks.append(ca.SX(h * q))
            blocks.append(ca.SX(h * r))
        blocks.append(p)
        return ca.diagcat(*[ca.sparsify(b) for b in blocks])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Absolute simple bounds (lbz, ubz) of z (numpy, +-inf where unbounded)."""
        lb = np.full(self.nz, -np.inf)
        ub = np.full(self.nz, np.inf)
        for j in range(self.N):
            k = u_index(j)
            lb[k : k + NU] = -self.radius
            ub[k : k + NU] = self.radius
        for j in range(2, self.N + 1):
            k = x_index(j)
            lb[k], ub[k] = self.gap_bounds
            lb[k + 2], ub[k + 2] = self.position_bounds
        return lb, ub

    @property
    def z_scale(self) -> np.ndarray:
        """s (6N,): z = z_bar + s * dz_s in the QP; 1e-3 on positions (mm), 1 elsewhere."""
        x_scale = np.array([_POSITION_SCALE, 1.0, _POSITION_SCALE, 1.0])
        s = np.ones(self.nz)
        for j in range(1, self.N + 1):
            s[x_index(j) : x_index(j) + NX] = x_scale
        return s

    @property
    def row_scale(self) -> np.ndarray:
        """t (6N,): the QP's constraint rows are t * (rows in SI); 1/s on the dynamics rows, so
        that the -I blocks of x_{j+1} stay -I (HPIPM's structure)."""
        inv = 1 / _POSITION_SCALE
        return np.tile(np.r_[inv, 1.0, inv, 1.0, np.ones(STAGE_ROWS - NX)], self.N)

    def stage_states(self, z, x0):
        """([x_0, ..., x_N], [u_0, ..., u_{N-1}]) from z and the estimate x0."""
        xs = [x0] + [z[x_index(j) : x_index(j) + NX] for j in range(1, self.N + 1)]
        us = [z[u_index(j) : u_index(j) + NU] for j in range(self.N)]
        return xs, us

    # ------------------------------------------------------------------------------------
    def qp_data_function(self) -> ca.Function:
        """The Gauss-Newton QP at a plan, in the scaled step dz_s = (z - z_bar) / s.

        Returns
        -------
        casadi.Function
            (z_bar, x0, d, ref) -> (H, g, A, lba, uba, lbx, ubx, data_ok, z_ref), with bounds
            made finite where the data are not (``data_ok`` 0), and the reference plan z_ref
            (SI): the cost is (z - z_ref)' W (z - z_ref) = 1/2 e_s' H e_s / c with
            e_s = (z - z_ref) / s (see :attr:`z_scale`) and c = :attr:`cost_scale`.

        Notes
        -----
        Two scalings make HPIPM's absolute tolerances mean the same precision on every entry.
        Positions are in mm (variables and dynamics rows). The cost is multiplied by
        c = 1 / (2 h_0 min(R)) (2500 with the defaults), which makes the smallest Hessian entry,
        the first interval's input weight (h_0 = one sample, 0.2 ms), equal to 1: HPIPM in mode
        "speed_abs" stops when the duality measure mu (the mean of multiplier times slack) is
        below an absolute 1e-8, so the slack of a bound whose multiplier is small stays about
        1e-8 / multiplier away from zero; the first current's bound has the smallest multipliers
        and, unscaled, its value was up to 0.07 A off the exact solution on the large step
        (tests/test_export_qp.py). A scaling of the variables alone cannot help: the product
        multiplier times slack of a bound does not change with the variable's unit. The QP's
        solution does not depend on c; its multipliers are c times those of the unscaled cost.
        """
        n, nz = self.N, self.nz
        zb = ca.SX.sym("z_bar", nz)
        x0 = ca.SX.sym("x0", NX)
        d = ca.SX.sym("d", N_DISTURBANCE)
        ref = ca.SX.sym("ref", N_REFERENCE, n + 1)
        z_ref, p = self.references(ref, d)
        hess = 2 * self.cost_weight(p)
        grad = ca.mtimes(hess, zb - z_ref)
        a, lba, uba = self._linearized_constraints(zb, x0, d)
        # scaling (Notes): positions in mm in the QP (rows of the position dynamics likewise), so
        # that the Hessian's blocks are O(1e-3..10) instead of O(1e-3..1e7) in SI, and the cost
        # times c, so that they are O(1..3e4) with the smallest, the first input's, equal to 1
        sz, ta, c = self.z_scale, self.row_scale, self.cost_scale
        hess = c * ca.mtimes([ca.diag(ca.DM(sz)), hess, ca.diag(ca.DM(sz))])
        grad = c * grad * ca.DM(sz)
        a = ca.mtimes([ca.diag(ca.DM(ta)), a, ca.diag(ca.DM(sz))])
        lba = lba * ca.DM(ta)
        uba = uba * ca.DM(ta)
        lbz, ubz = self.bounds()
        lbx = ca.vertcat(*[-_BIG if not np.isfinite(v) else (v - zb[i]) / sz[i] for i, v in enumerate(lbz)])
        ubx = ca.vertcat(*[_BIG if not np.isfinite(v) else (v - zb[i]) / sz[i] for i, v in enumerate(ubz)])
        data_ok, lba, uba, lbx, ubx = self._harmless_if_not_finite(a, grad, lba, uba, lbx, ubx)
        return ca.Function(
            "nmpc_qp_data",
            [zb, x0, d, ref],
            [hess, grad, a, lba, uba, lbx, ubx, data_ok, z_ref],
            ["z_bar", "x0", "d", "ref"],
            ["H", "g", "A", "lba", "uba", "lbx", "ubx", "data_ok", "z_ref"],
            {"cse": True},  # common subexpressions of the 20 RK4 linearizations: -10 % operations
        )

    def _linearized_constraints(self, zb, x0, d):
        """(A, lba, uba) in SI for the step z - z_bar: per interval the linearized dynamics
        (rows equal to minus the defect) and the octagon's diagonal rows."""
        n = self.N
        xs, us = self.stage_states(zb, x0)
        a = ca.SX(self.na, self.nz)
        lba, uba = [], []
        dm = ca.DM(OCTAGON)
        lim = math.sqrt(2) * self.radius
        for j in range(n):
            row = STAGE_ROWS * j
            x_next, aj, bj = self.rk4_lin(xs[j], us[j], d, float(self.grid.intervals[j]))
            if j > 0:
                a[row : row + NX, x_index(j) : x_index(j) + NX] = aj
            a[row : row + NX, u_index(j) : u_index(j) + NU] = bj
            a[row : row + NX, x_index(j + 1) : x_index(j + 1) + NX] = -ca.SX.eye(NX)
            defect = x_next - xs[j + 1]
            lba.append(-defect)
            uba.append(-defect)
            a[row + NX : row + STAGE_ROWS, u_index(j) : u_index(j) + NU] = dm
            du = ca.mtimes(dm, us[j])
            lba.append(-lim - du)
            uba.append(lim - du)
        return a, ca.vertcat(*lba), ca.vertcat(*uba)

    def _harmless_if_not_finite(self, a, grad, lba, uba, lbx, ubx):
        """(data_ok, lba, uba, lbx, ubx): the bounds unchanged when all QP data are finite.

        Non-finite data (a NaN measurement, a plan that left the model's domain) would make the
        QP ill-posed, which CasADi refuses with an exception: then every bound is replaced by a
        harmless finite one (the step dz = 0 is feasible) and the solution check downstream
        flags the sample.
        """
        size = (
            ca.sum1(ca.fabs(lba))
            + ca.sum1(ca.fabs(lbx))
            + ca.sum1(ca.fabs(ubx))
            + ca.sum1(ca.fabs(grad))
            + ca.sum1(ca.fabs(ca.vertcat(*a.nonzeros())))
        )
        data_ok = size < 1e20
        is_dyn = np.tile(np.r_[np.ones(NX), np.zeros(STAGE_ROWS - NX)], self.N).astype(bool)
        lba = ca.if_else(data_ok, lba, ca.DM(np.where(is_dyn, 0.0, -_BIG)))
        uba = ca.if_else(data_ok, uba, ca.DM(np.where(is_dyn, 0.0, _BIG)))
        lbx = ca.if_else(data_ok, lbx, ca.DM.ones(self.nz) * -_BIG)
        ubx = ca.if_else(data_ok, ubx, ca.DM.ones(self.nz) * _BIG)
        return data_ok, lba, uba, lbx, ubx

    def objective_function(self) -> ca.Function:
        """(z, d, ref) -> the OCP's cost [-] of the plan z."""
        z = ca.SX.sym("z", self.nz)
        d = ca.SX.sym("d", N_DISTURBANCE)
        ref = ca.SX.sym("ref", N_REFERENCE, self.N + 1)
        z_ref, p = self.references(ref, d)
        e = z - z_ref
        return ca.Function("nmpc_cost", [z, d, ref], [ca.bilin(self.cost_weight(p), e, e)])

    def project_current(self, u):
        """u (CasADi, 2) scaled into the current octagon (unchanged inside it)."""
        m = ca.fmax(
            ca.fmax(ca.fabs(u[0]), ca.fabs(u[1])),
            ca.fmax(ca.fabs(u[0] + u[1]), ca.fabs(u[0] - u[1])) / math.sqrt(2),
        )
        return u / ca.fmax(1.0, m / self.radius)
