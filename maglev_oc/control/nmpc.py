"""Nonlinear model predictive control of the stage: multiple shooting, RK4, real-time iteration.

The optimal control problem (OCP) solved at every sample k, on the controller's own
:class:`~maglev_oc.model.stage.StageModel` with constant acceleration disturbances d = (d_v, d_h):

    min   sum_{j<N} h_j [ |x_j - xr_j|_Q^2 + |u_j - ur_j|_R^2 ]  +  |x_N - xr_N|_P(r_v,N)^2
    s.t.  x_0 = x^(k)                           (observer estimate, initial-value embedding)
          x_{j+1} = RK4(x_j, u_j, d; h_j)        (one RK4 step per shooting interval)
          current polytope:  |u_1|, |u_2| <= r,  |u_1 +- u_2| <= sqrt(2) r,   r = I_max cos(pi/8)
          gap and horizontal bounds on x_j, j >= 2

with f(x, u, d) = f(x, u) + (0, d_v, 0, d_h) (SPEC 1; 001 Sec. V models the friction and
misalignment the same way, as constant Delta_1, Delta_2 on x4', x2').

Shooting grid and the 5 kHz loop
    The controller runs every sample Ts = 200 us and re-solves every sample. The first shooting
    interval is exactly one sample (h_0 = Ts): u_0 is the current held by the zero-order hold
    until the next solve, so the plan's first piece is what the rig applies. The other N - 1
    intervals are uniform, h = 5 ms = 25 Ts by default. The open-loop unstable pole (30-64
    rad/s over 10-30 mm) and the closed loop of the default weights (poles of magnitude 55-110
    rad/s, damping 0.75-0.96, over 10-29 mm; the papers' regulators: 9-15 rad/s) give h |lambda|
    <= 0.55, where one RK4 step is accurate to (h lambda)^5 / 120 < 5e-4 and a time constant
    (9-18 ms) spans 2-4 intervals. N = 20 previews Ts + 95 ms (N = 40: 195 ms), five to ten
    closed-loop time constants and one sixth of the ellipse's period; beyond it the terminal
    cost is the infinite-horizon LQR value. Shorter intervals would cost more intervals for the
    same preview; longer ones would leave the unstable and closed-loop modes under-resolved.
    With a short first interval the first input is, near an equilibrium,
    u_0 = -(Ts R + B0' P B0)^-1 B0' P A0 dx: the LQR law of the sampled problem (checked in
    tests/test_nmpc.py), close to the continuous-time LQR of (Q, R). The stage cost is integrated
    (weighted by h_j), so the weights do not depend on the grid.

Reference preview
    The nodes read the reference array at their own times (``preview=True``, the default): the
    plan sees a set-point step up to Ts + (N - 1) h before it happens and leaves the old
    set-point early (by ~50 ms with the defaults), which metrics that time the settling from the
    step instant count against it. ``preview=False`` makes the controller causal like the
    papers' regulators: every node extrapolates the current reference sample with its velocity
    and acceleration (on the ellipse, which is smooth, the tracking errors are the same to
    within a few um).

Warm start by shifting
    After a sample the new grid starts at the old node 1 and every later node lies a fraction
    a = Ts / h into the old interval; the plan is shifted by linear interpolation between old
    nodes (the last node and input are held).

Real-time iteration (``mode="rti"``)
    ONE Gauss-Newton SQP step per sample (Diehl et al.'s RTI): the cost is a linear least
    squares in (x, u), so its Gauss-Newton Hessian is the exact, constant block-diagonal
    2 diag(h_0 R, h_1 Q, h_1 R, ..., P); the dynamics are linearized by CasADi AD at the shifted
    plan. The whole update -- observer, linearization and QP data (an SX Function), the sparse
    QP (a ``ca.conic`` call), the check of its solution, the fallback, the shift and the observer
    update (an SX Function) -- is ONE CasADi Function, :attr:`NonlinearMPC.rti_step`, called
    once per sample from Python and code-generated to C by :mod:`maglev_oc.control.codegen`.

QP solver and the unconstrained shortcut
    The QP variables are ordered (u_0, x_1, u_1, ..., x_N) and the constraints per stage
    (dynamics, current polytope): the OCP structure HPIPM's Riccati-based interior point
    method exploits (u_0 plays HPIPM's "x_0" since x_0 is not a variable). ``hpipm`` is the
    default (mode "speed_abs", iteration limit 30) because its cost on a constrained sample is
    bounded (4-10 interior point iterations of fixed cost) where QRQP's active-set iterations
    each refactorize the KKT matrix, so that QRQP's cost grows with the number of constraints
    that switch (the start of a large step). The QP is scaled (positions in mm) so that
    HPIPM's absolute tolerances are reachable (in SI units its Hessian spans 1e-3..1e7 and the
    first sample of a large step ran into the iteration limit). Measured by bench/nmpc_step.py
    with the QP solved every sample (N = 20, CasADi VM, per call, two runs): HPIPM 0.42-0.47
    ms, QRQP 0.42 ms, OSQP 0.75-0.83 ms (OSQP needs tight tolerances for the solution check,
    hence many ADMM iterations); in the generated C the p99 over a large step, set by the
    samples that need the QP, was 0.14 ms with HPIPM and 0.24 ms with QRQP. Most samples have no
    active inequality: the Riccati recursion of the equality-constrained QP (its exact minimizer
    without inequalities, ~10k flops) is computed first and, when it satisfies every bound and
    polytope row, it IS the QP's solution and the solver is not called (a CasADi Switch: only
    the selected branch runs, in Python and in the generated C). The QP solver runs on the other
    samples (0.1-1 % of the samples of the papers' scenarios); ``unconstrained_shortcut=False``
    solves the QP every sample.

A failed QP never raises: the solution is checked inside the Function (finite, dynamics
residual and constraint violation below tolerance); when it fails the controller applies the
shifted previous plan (or the feedforward current of the reference, projected on the current
polytope), keeps the previous plan as the next linearization point and reports
``solver_ok = 0``.

Converged solve (``mode="converged"``): the same NLP solved to convergence by IPOPT (exact
Hessian) every sample, warm-started by the same shift; a reference for the RTI, not real time.

State and disturbance estimate (offset-free tracking)
    No velocity is measured. Each axis has the papers' high-gain observer
    (:class:`~maglev_oc.estimation.high_gain.HighGainObserver`, poles at -1/eps), driven by the
    model acceleration at the commanded current plus the disturbance estimate, and the
    disturbance is a third, slow observer state integrating the position innovation:

        (p, q)[k+1] = Ad (p, q)[k] + By y[k] + Ba (a_model(y, u[k]) + d[k])
        d[k+1]      = d[k] + w_d (alpha2 / eps^2) int_{sample} (y[k] - p(t)) dt

    (the integral of the innovation over the sample, exact for the held reading). At steady
    state the innovation is d_err eps^2 / alpha2, so d converges with rate w_d (time-scale
    separation: w_d << 1/eps). The OCP uses x^ = (y_1, q_v, y_2, q_h) (positions
    straight from the encoders, like the papers' regulator) and d, and its input reference is
    the inverse dynamics along the reference with the disturbance removed (the feedback
    transformation of SPEC 1 at x1 = r_v, v = (r_h'' - d_h, r_v'' - d_v)). At a steady state of
    the closed loop d is constant, so y = p and the model with d is at rest at the measured
    position: the optimal plan then holds it only at the reference (Pannocchia & Rawlings'
    offset-free argument), whatever constant force the model misses. d is clipped to
    +-``disturbance_limit`` (anti-windup).

Weights (defaults, :class:`NMPCWeights`)
    Q = diag(1e6, 1e2, 1e6, 1e2), R = diag(1, 1) per second in SI units: 1 mm of position
    error costs as much as 1 A of current beyond the feedforward (position gains of the LQR
    ~1000-1500 A/m), 10 mm/s of velocity error as much as 0.1 mm of position. The LQR on the
    linearization then has its poles at magnitudes 55-110 rad/s (damping 0.75-0.96) over
    10-29 mm (the vertical pair can not be slower than the mirror of the unstable pole, 30-64
    rad/s): 4-7x faster than the papers' regulators, which matters against friction reversals
    (a 1.3 N Coulomb step on the 1.6 kg horizontal mover costs 0.8 m/s^2 / 6700 s^-2 = 0.1 mm
    of error before the disturbance estimate catches up), yet 5-10x below the observer (500
    rad/s) and 60x below the amplifier (6300 rad/s). Encoder quantization (10 um, and about
    5 mm/s of velocity noise through the observer) maps to ~0.01 A + 0.1 A of current noise.
    Large steps are shaped by the current polytope, not by the weights.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
from scipy.linalg import expm, solve_discrete_are

from maglev_oc.estimation.high_gain import DEFAULT_EPSILON, HighGainObserver
from maglev_oc.model.equilibrium import NoEquilibriumError, equilibrium
from maglev_oc.model.feedback import transformation_expressions
from maglev_oc.model.hardware import PEAK_CURRENT_LIMIT, RIG_SAMPLE_TIME
from maglev_oc.model.stage import N_INPUTS, N_STATES, StageModel

NX = N_STATES
NU = N_INPUTS
MODES = ("rti", "converged")
QP_SOLVERS = ("hpipm", "qrqp", "osqp")
DIAG_NAMES = ("solver_ok", "qp_iterations", "cost", "d_v", "d_h", "active_constraints", "qp_status")
"""Diagnostics per sample: ``solver_ok`` 1 if the solution passed the checks (else the fallback
was applied); ``qp_iterations`` of the QP solver (0: the unconstrained Riccati step was feasible
and no QP was solved; IPOPT's iterations in converged mode); ``cost`` of the applied plan [-];
``d_v``, ``d_h`` the disturbance estimates [m/s^2]; ``active_constraints`` the number of
inequalities active in the solution (-1 when it failed); ``qp_status`` -1 no QP solved, 0 the
solver reported success, 1 it reported a failure (iteration limit, infeasibility). The generated
C leaves qp_iterations at -1 and qp_status at NaN on QP samples (no solver statistics there)."""

DEFAULT_INTERVAL = 5e-3
"""Shooting interval after the first (one-sample) interval [s]; see the module docstring."""
DEFAULT_HORIZON = 20
DEFAULT_GAP_BOUNDS = (10e-3, 29e-3)
"""Gap bounds [m]: the 10 mm end is where the model's verified range ends (cogging > 1 N below
15 mm, 000 Sec. V-C) widened to the travel; the upper one keeps 1 mm from the 30 mm stopper."""
DEFAULT_POSITION_BOUNDS = (-55e-3, 55e-3)
"""Horizontal bounds [m]: the +-50 mm travel plus 5 mm, inside the +-60 mm stoppers."""
DEFAULT_DISTURBANCE_BANDWIDTH = 30.0
"""w_d [rad/s]: disturbance estimate time constant 33 ms, comparable to the closed loop."""
DEFAULT_DISTURBANCE_LIMIT = 5.0
"""|d| clip [m/s^2]: 8x the largest friction of the rig twin (1.5 N / 4.35 kg = 0.34 m/s^2
vertically, 1 N / 1.594 kg = 0.63 m/s^2 horizontally), half of gravity."""
TERMINAL_GAPS = np.linspace(10e-3, 30e-3, 21)
"""Gaps [m] at which the terminal weight P is tabulated (1 mm apart; linear in between)."""
SOLUTION_TOLERANCE = 1e-6
"""Largest dynamics residual and constraint violation accepted in a QP solution, in the QP's
scaled units (mm, m/s, A); the solvers reach 1e-8 or better on a good solve, a failed one is
far off."""
_BIG = 1e8  # stands for an infinite bound in the QP data (HPIPM's own 'inf' default)


@dataclass(frozen=True)
class NMPCWeights:
    """Weights of the integrated tracking cost (per second of horizon, SI units).

    The stage cost is ``gap (x1 - r_v)^2 + gap_rate (x2 - r_v')^2 + position (x3 - r_h)^2 +
    position_rate (x4 - r_h')^2 + i_q (u1 - ur1)^2 + i_d (u2 - ur2)^2`` where ur is the
    feedforward current of the reference. Units: [1/(m^2 s)], [s/m^2], [1/(m^2 s)], [s/m^2],
    [1/(A^2 s)], [1/(A^2 s)].
    """

    gap: float = 1e6
    gap_rate: float = 1e2
    position: float = 1e6
    position_rate: float = 1e2
    i_q: float = 1.0
    i_d: float = 1.0

    def __post_init__(self) -> None:
        for name in ("gap", "gap_rate", "position", "position_rate", "i_q", "i_d"):
            value = getattr(self, name)
            positive = name in ("i_q", "i_d")
            if (
                not (isinstance(value, (int, float)) and math.isfinite(value))
                or value < 0
                or (positive and value == 0)
            ):
                kind = "positive" if positive else "non-negative"
                raise ValueError(f"NMPCWeights.{name} must be {kind} and finite, got {value!r}")

    @property
    def state_weight(self) -> np.ndarray:
        """Q (4, 4)."""
        return np.diag([self.gap, self.gap_rate, self.position, self.position_rate]).astype(float)

    @property
    def input_weight(self) -> np.ndarray:
        """R (2, 2)."""
        return np.diag([self.i_q, self.i_d]).astype(float)


@dataclass(frozen=True)
class ShootingGrid:
    """The multiple-shooting grid: a first interval of one sample, then N - 1 of ``interval_samples``.

    Attributes
    ----------
    node_offsets : (N + 1,) int
        Node j lies ``node_offsets[j]`` samples after the current one (0, 1, 1 + m, 1 + 2m, ...);
        the reference preview is read there.
    intervals : (N,) float
        h_j [s].
    """

    sample_time: float
    interval_samples: int
    horizon: int
    node_offsets: np.ndarray = field(init=False, repr=False)
    intervals: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not (self.sample_time > 0 and math.isfinite(self.sample_time)):
            raise ValueError(f"sample_time must be positive [s], got {self.sample_time!r}")
        if not (isinstance(self.interval_samples, int) and self.interval_samples >= 1):
            raise ValueError(f"interval_samples must be a positive integer, got {self.interval_samples!r}")
        if not (isinstance(self.horizon, int) and self.horizon >= 2):
            raise ValueError(f"horizon must be an integer >= 2, got {self.horizon!r}")
        offsets = np.concatenate([[0], 1 + self.interval_samples * np.arange(self.horizon)])
        h = np.full(self.horizon, self.interval_samples * self.sample_time)
        h[0] = self.sample_time
        object.__setattr__(self, "node_offsets", offsets.astype(int))
        object.__setattr__(self, "intervals", h)

    @property
    def interval(self) -> float:
        """The regular interval h [s]."""
        return self.interval_samples * self.sample_time

    @property
    def preview(self) -> float:
        """Time covered by the horizon [s]."""
        return float(self.intervals.sum())

    def shift_fraction(self) -> float:
        """How far into an old interval a new node lies after one sample (Ts / h)."""
        return 1.0 / self.interval_samples


# ------------------------------------------------------------------------------------------
# Layout of the decision vector z = (u_0, x_1, u_1, ..., x_{N-1}, u_{N-1}, x_N): x_0 is not a
# variable (it is the estimate), so z has 6 N entries.
def _x_index(j: int) -> int:
    return NU + (j - 1) * (NX + NU)


def _u_index(j: int) -> int:
    return 0 if j == 0 else NU + (j - 1) * (NX + NU) + NX


def shift_matrix(grid: ShootingGrid) -> np.ndarray:
    """S (6N, 6N): the warm start z_next = S z after one sample (see the module docstring)."""
    n = grid.horizon
    nz = 6 * n
    a = grid.shift_fraction()
    s = np.zeros((nz, nz))
    eye_u, eye_x = np.eye(NU), np.eye(NX)
    # new u_0 (over [Ts, 2 Ts]) lies inside old interval 1
    s[0:NU, _u_index(1) : _u_index(1) + NU] = eye_u
    for j in range(1, n + 1):
        r = _x_index(j)
        if j < n:  # new node j sits a fraction a into old interval j
            s[r : r + NX, _x_index(j) : _x_index(j) + NX] += (1 - a) * eye_x
            s[r : r + NX, _x_index(j + 1) : _x_index(j + 1) + NX] += a * eye_x
        else:
            s[r : r + NX, r : r + NX] = eye_x
        if j < n:
            ru = _u_index(j)
            if j + 1 < n:
                s[ru : ru + NU, _u_index(j) : _u_index(j) + NU] += (1 - a) * eye_u
                s[ru : ru + NU, _u_index(j + 1) : _u_index(j + 1) + NU] += a * eye_u
            else:
                s[ru : ru + NU, ru : ru + NU] = eye_u
    return s


@dataclass(frozen=True)
class TerminalCostTable:
    """Terminal weights P(gap) (4, 4) from the DARE of the RK4-discretized linearization.

    At the equilibrium of each gap in ``gaps`` the shooting step over one regular interval h is
    linearized exactly (the same CasADi Function the OCP uses) and the DARE with stage weights
    (h Q, h R) is solved; with this P the cost-to-go beyond node N equals that of the
    infinite-horizon LQR of the sampled linearization.
    """

    gaps: np.ndarray  # (n,) [m]
    P: np.ndarray  # (n, 4, 4)
    gains: np.ndarray  # (n, 2, 4) LQR gains of the regular interval, u = -K dx

    def expression(self, gap):
        """P at ``gap`` (CasADi scalar), linear between the tabulated gaps, clamped outside."""
        g = ca.fmin(ca.fmax(gap, float(self.gaps[0])), float(self.gaps[-1]))
        entries = []
        for c in range(NX):
            for r in range(NX):
                if r < c:
                    continue
                vals = self.P[:, r, c]
                if np.all(vals == 0):
                    entries.append((r, c, None))
                else:
                    entries.append((r, c, ca.pw_lin(g, list(self.gaps), list(vals))))
        out = ca.SX.zeros(NX, NX) if isinstance(gap, ca.SX) else ca.MX.zeros(NX, NX)
        for r, c, e in entries:
            if e is None:
                continue
            out[r, c] = e
            if r != c:
                out[c, r] = e
        return out

    def at(self, gap: float) -> np.ndarray:
        """P at ``gap`` as a numpy array."""
        g = float(np.clip(gap, self.gaps[0], self.gaps[-1]))
        return np.array([[np.interp(g, self.gaps, self.P[:, r, c]) for c in range(NX)] for r in range(NX)])


@dataclass(frozen=True)
class LocalLQR:
    """The LQR of the sampled linearization at an equilibrium, as the NMPC sees it.

    ``gain_first`` is the law of the shortened first interval, u - u_eq = -K0 (x - x_eq), with
    K0 = (Ts R + B0' P B0)^-1 B0' P A0; ``gain`` the regular-interval DARE gain; ``P`` the
    terminal weight.
    """

    x_eq: np.ndarray
    u_eq: np.ndarray
    gain_first: np.ndarray  # (2, 4)
    gain: np.ndarray  # (2, 4)
    P: np.ndarray  # (4, 4)


class _Transcription:
    """Symbolic pieces shared by the RTI and the converged solver (built once)."""

    def __init__(
        self,
        model: StageModel,
        grid: ShootingGrid,
        weights: NMPCWeights,
        current_limit: float,
        gap_bounds,
        position_bounds,
    ) -> None:
        self.model = model
        self.grid = grid
        self.weights = weights
        self.N = grid.horizon
        self.nz = 6 * self.N
        self.na = 6 * self.N
        self.radius = current_limit * math.cos(math.pi / 8)  # inscribed octagon
        self.gap_bounds = gap_bounds
        self.position_bounds = position_bounds

        x = ca.SX.sym("x", NX)
        u = ca.SX.sym("u", NU)
        d = ca.SX.sym("d", 2)
        h = ca.SX.sym("h")
        xdot = model.f(x, u) + ca.vertcat(0, d[0], 0, d[1])
        fd = ca.Function("f_d", [x, u, d], [xdot])
        k1 = fd(x, u, d)
        k2 = fd(x + h / 2 * k1, u, d)
        k3 = fd(x + h / 2 * k2, u, d)
        k4 = fd(x + h * k3, u, d)
        x_next = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        self.rk4 = ca.Function("rk4", [x, u, d, h], [x_next], ["x", "u", "d", "h"], ["x_next"])
        self.rk4_lin = ca.Function(
            "rk4_lin",
            [x, u, d, h],
            [x_next, ca.jacobian(x_next, x), ca.jacobian(x_next, u)],
            ["x", "u", "d", "h"],
            ["x_next", "A", "B"],
        )
        # feedforward current of the reference with the disturbance removed (SPEC 1, reading 5)
        r = ca.SX.sym("r", 6)
        _, _, u_ff = transformation_expressions(model, r[0], ca.vertcat(r[5] - d[1], r[2] - d[0]))
        self.feedforward = ca.Function("feedforward", [r, d], [u_ff], ["r", "d"], ["u"])
        self.terminal = self._terminal_table()
        # octagon: D u in [-sqrt(2) r, sqrt(2) r]
        self.D = np.array([[1.0, 1.0], [1.0, -1.0]])

    # ------------------------------------------------------------------------------------
    def _terminal_table(self) -> TerminalCostTable:
        h = self.grid.interval
        q = self.weights.state_weight * h
        rr = self.weights.input_weight * h
        ps, ks = [], []
        for gap in TERMINAL_GAPS:
            op = equilibrium(self.model, float(gap), current_limit=math.inf)
            _, a, b = self.rk4_lin(op.x, op.u, [0, 0], h)
            a, b = np.asarray(a), np.asarray(b)
            p = solve_discrete_are(a, b, q, rr)
            p = 0.5 * (p + p.T)
            ps.append(p)
            ks.append(np.linalg.solve(rr + b.T @ p @ b, b.T @ p @ a))
        return TerminalCostTable(TERMINAL_GAPS.copy(), np.array(ps), np.array(ks))

    def local_lqr(self, gap: float, position: float = 0.0) -> LocalLQR:
        """The linear-quadratic law the NMPC reduces to near the equilibrium at ``gap`` [m]."""
        op = equilibrium(self.model, gap, position, current_limit=math.inf)
        p = self.terminal.at(gap)
        ts, h = self.grid.sample_time, self.grid.interval
        _, a0, b0 = (np.asarray(v) for v in self.rk4_lin(op.x, op.u, [0, 0], ts))
        _, a, b = (np.asarray(v) for v in self.rk4_lin(op.x, op.u, [0, 0], h))
        rr = self.weights.input_weight
        k0 = np.linalg.solve(ts * rr + b0.T @ p @ b0, b0.T @ p @ a0)
        k = np.linalg.solve(h * rr + b.T @ p @ b, b.T @ p @ a)
        return LocalLQR(op.x, op.u, k0, k, p)

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

    def bounds(self):
        """Absolute simple bounds (lbz, ubz) of z (numpy, +-inf where unbounded)."""
        lb = np.full(self.nz, -np.inf)
        ub = np.full(self.nz, np.inf)
        for j in range(self.N):
            k = _u_index(j)
            lb[k : k + NU] = -self.radius
            ub[k : k + NU] = self.radius
        for j in range(2, self.N + 1):
            k = _x_index(j)
            lb[k], ub[k] = self.gap_bounds
            lb[k + 2], ub[k + 2] = self.position_bounds
        return lb, ub

    @property
    def z_scale(self) -> np.ndarray:
        """s (6N,): z = z_bar + s * dz_s in the QP; 1e-3 on positions (mm), 1 elsewhere."""
        x_scale = np.array([1e-3, 1.0, 1e-3, 1.0])
        s = np.ones(self.nz)
        for j in range(1, self.N + 1):
            s[_x_index(j) : _x_index(j) + NX] = x_scale
        return s

    @property
    def row_scale(self) -> np.ndarray:
        """t (6N,): the QP's constraint rows are t * (rows in SI); 1/s on the dynamics rows, so
        that the -I blocks of x_{j+1} stay -I (HPIPM's structure)."""
        return np.tile(np.r_[1e3, 1.0, 1e3, 1.0, 1.0, 1.0], self.N)

    def stage_states(self, z, x0):
        xs = [x0] + [z[_x_index(j) : _x_index(j) + NX] for j in range(1, self.N + 1)]
        us = [z[_u_index(j) : _u_index(j) + NU] for j in range(self.N)]
        return xs, us

    # ------------------------------------------------------------------------------------
    def qp_data_function(self) -> ca.Function:
        """(z_bar, x0, d, ref) -> (H, g, A, lba, uba, lbx, ubx, data_ok, z_ref): the Gauss-Newton
        QP in the scaled step dz_s = (z - z_bar) / s (see :attr:`z_scale`), with bounds made
        finite where the data are not, and the reference plan z_ref (SI): the cost is
        (z - z_ref)' W (z - z_ref) = 1/2 e_s' H e_s with e_s = (z - z_ref) / s."""
        n, nz, na = self.N, self.nz, self.na
        zb = ca.SX.sym("z_bar", nz)
        x0 = ca.SX.sym("x0", NX)
        d = ca.SX.sym("d", 2)
        ref = ca.SX.sym("ref", 6, n + 1)
        xs, us = self.stage_states(zb, x0)
        z_ref, p = self.references(ref, d)
        w = self.cost_weight(p)
        hess = 2 * w
        grad = ca.mtimes(hess, zb - z_ref)

        a = ca.SX(na, nz)
        lba, uba = [], []
        dm = ca.DM(self.D)
        lim = math.sqrt(2) * self.radius
        for j in range(n):
            row = 6 * j
            x_next, aj, bj = self.rk4_lin(xs[j], us[j], d, float(self.grid.intervals[j]))
            if j > 0:
                a[row : row + NX, _x_index(j) : _x_index(j) + NX] = aj
            a[row : row + NX, _u_index(j) : _u_index(j) + NU] = bj
            a[row : row + NX, _x_index(j + 1) : _x_index(j + 1) + NX] = -ca.SX.eye(NX)
            defect = x_next - xs[j + 1]
            lba.append(-defect)
            uba.append(-defect)
            a[row + NX : row + 6, _u_index(j) : _u_index(j) + NU] = dm
            du = ca.mtimes(dm, us[j])
            lba.append(-lim - du)
            uba.append(lim - du)
        lba = ca.vertcat(*lba)
        uba = ca.vertcat(*uba)
        # scaling: positions in mm in the QP (rows of the position dynamics likewise), so that the
        # Hessian's blocks are O(1e-3..10) instead of O(1e-3..1e7) in SI; HPIPM's absolute
        # stationarity tolerance (1e-6) is then reachable on every sample
        sz, ta = self.z_scale, self.row_scale
        hess = ca.mtimes([ca.diag(ca.DM(sz)), hess, ca.diag(ca.DM(sz))])
        grad = grad * ca.DM(sz)
        a = ca.mtimes([ca.diag(ca.DM(ta)), a, ca.diag(ca.DM(sz))])
        lba = lba * ca.DM(ta)
        uba = uba * ca.DM(ta)
        lbz, ubz = self.bounds()
        lbx = ca.vertcat(*[-_BIG if not np.isfinite(v) else (v - zb[i]) / sz[i] for i, v in enumerate(lbz)])
        ubx = ca.vertcat(*[_BIG if not np.isfinite(v) else (v - zb[i]) / sz[i] for i, v in enumerate(ubz)])
        # Non-finite data (a NaN measurement, a plan that left the model's domain) would make the
        # QP ill-posed, which CasADi refuses with an exception: then every bound is replaced by a
        # harmless finite one (the step dz = 0 is feasible) and the solution check downstream
        # flags the sample.
        size = (
            ca.sum1(ca.fabs(lba))
            + ca.sum1(ca.fabs(lbx))
            + ca.sum1(ca.fabs(ubx))
            + ca.sum1(ca.fabs(grad))
            + ca.sum1(ca.fabs(ca.vertcat(*a.nonzeros())))
        )
        data_ok = size < 1e20
        is_dyn = np.tile(np.r_[np.ones(NX), np.zeros(2)], n).astype(bool)
        lba = ca.if_else(data_ok, lba, ca.DM(np.where(is_dyn, 0.0, -_BIG)))
        uba = ca.if_else(data_ok, uba, ca.DM(np.where(is_dyn, 0.0, _BIG)))
        lbx = ca.if_else(data_ok, lbx, ca.DM.ones(nz) * -_BIG)
        ubx = ca.if_else(data_ok, ubx, ca.DM.ones(nz) * _BIG)
        return ca.Function(
            "nmpc_qp_data",
            [zb, x0, d, ref],
            [hess, grad, a, lba, uba, lbx, ubx, data_ok, z_ref],
            ["z_bar", "x0", "d", "ref"],
            ["H", "g", "A", "lba", "uba", "lbx", "ubx", "data_ok", "z_ref"],
            {"cse": True},  # common subexpressions of the 20 RK4 linearizations: -10 % operations
        )

    def objective_function(self) -> ca.Function:
        """(z, d, ref) -> OCP cost."""
        z = ca.SX.sym("z", self.nz)
        d = ca.SX.sym("d", 2)
        ref = ca.SX.sym("ref", 6, self.N + 1)
        z_ref, p = self.references(ref, d)
        e = z - z_ref
        return ca.Function("nmpc_cost", [z, d, ref], [ca.bilin(self.cost_weight(p), e, e)])

    def project_current(self, u):
        """Scale u (SX) into the current octagon."""
        m = ca.fmax(
            ca.fmax(ca.fabs(u[0]), ca.fabs(u[1])),
            ca.fmax(ca.fabs(u[0] + u[1]), ca.fabs(u[0] - u[1])) / math.sqrt(2),
        )
        return u / ca.fmax(1.0, m / self.radius)


class _Estimator:
    """Per-axis high-gain observer (position, velocity) plus a disturbance state; see module doc.

    The (p, q) update is :class:`HighGainObserver`'s exact ZOH discretization. The disturbance
    integrates the observer's innovation over the sample, exactly (the augmented matrix
    exponential below), not the innovation at the sample instant: the observer sees the encoder
    reading held over the sample, so at the sampling instants its position estimate lags a
    moving stage by v Ts / 2 (14 um at the ellipse's 0.14 m/s), and a rectangle-rule integral
    of that lag would read as a disturbance of (v Ts / 2) alpha2 / eps^2 = 3.5 m/s^2. The
    exact integral of the innovation over a sample is zero for a ramp in steady state.
    """

    def __init__(
        self, model: StageModel, sample_time: float, epsilon: float, bandwidth: float, limit: float
    ) -> None:
        self.observer = HighGainObserver(sample_time, epsilon)
        self.model = model
        self.limit = limit
        a1, a2 = self.observer.alpha
        self.gain = bandwidth * a2 / epsilon**2  # continuous: d' = gain (y - p)
        # [p, q, I]' with I' = y - p, inputs (y, a) held over the sample
        m = np.zeros((5, 5))
        m[0:2, 0:2] = [[-a1 / epsilon, 1.0], [-a2 / epsilon**2, 0.0]]
        m[0:2, 3:5] = [[a1 / epsilon, 0.0], [a2 / epsilon**2, 1.0]]
        m[2, 0] = -1.0
        m[2, 3] = 1.0
        e = expm(m * sample_time)
        if not (
            np.allclose(e[0:2, 0:2], self.observer.Ad)
            and np.allclose(e[0:2, 3:5], np.hstack([self.observer.By, self.observer.Ba]))
        ):
            raise RuntimeError("HighGainObserver's discretization is not the one assumed here")
        self.integral_state = e[2, 0:2]  # I(Ts) = F_x (p, q) + F_y y + F_a a
        self.integral_y = float(e[2, 3])
        self.integral_a = float(e[2, 4])

    def state_estimate(self, obs, y):
        """x^ for the OCP: encoder positions, observer velocities."""
        return ca.vertcat(y[0], obs[1], y[1], obs[3])

    def _innovation_integral(self, xhat, y, acc):
        return ca.dot(ca.DM(self.integral_state), xhat) + self.integral_y * y + self.integral_a * acc

    def update(self, obs, d, y, u):
        """(obs_next (4), d_next (2)) after applying u at measurement y."""
        x_hat = self.state_estimate(obs, y)
        acc = self.model.f(x_hat, u)
        a_v = acc[1] + d[0]
        a_h = acc[3] + d[1]
        pv = self.observer.step(obs[0:2], y[0], a_v)
        ph = self.observer.step(obs[2:4], y[1], a_h)
        d_next = d + self.gain * ca.vertcat(
            self._innovation_integral(obs[0:2], y[0], a_v), self._innovation_integral(obs[2:4], y[1], a_h)
        )
        d_next = ca.fmin(ca.fmax(d_next, -self.limit), self.limit)
        return ca.vertcat(pv, ph), d_next

    def error_dynamics(self) -> np.ndarray:
        """(3, 3) transition matrix of one axis's estimator (p^, q^, d^) with the plant held
        still at 0: its eigenvalues are the estimator's poles, the observer pair near
        exp(-Ts / eps) and the disturbance pole near exp(-w_d Ts)."""
        o = self.observer
        m = np.zeros((3, 3))
        m[0:2, 0:2] = o.Ad
        m[0:2, 2] = o.Ba[:, 0]
        m[2, 0:2] = self.gain * self.integral_state
        m[2, 2] = 1.0 + self.gain * self.integral_a
        return m


@dataclass(frozen=True)
class NMPCStepResult:
    """One controller update, for analyses and tests (the engine uses :meth:`NonlinearMPC.control`)."""

    u: np.ndarray  # (2,)
    diag: np.ndarray  # (len(DIAG_NAMES),)
    plan: np.ndarray  # (6N,) applied plan z (before the shift)


class NonlinearMPC:
    """Nonlinear MPC of the stage (an :class:`~maglev_oc.control.base.OnlineController`).

    Parameters
    ----------
    model : StageModel
        The controller's model (its constants may differ from the plant's).
    horizon : int
        Number of shooting intervals N (default 20; 40 works too).
    interval : float
        Regular shooting interval [s] (default 5 ms); a multiple of ``sample_time``.
    sample_time : float
        Controller period [s] (default 2e-4, 5 kHz); also the first shooting interval.
    weights : NMPCWeights
        Tracking weights.
    mode : {"rti", "converged"}
        One Gauss-Newton SQP step per sample (real time) or IPOPT to convergence (reference).
    qp_solver : {"hpipm", "qrqp", "osqp"}
        Sparse QP solver of the RTI.
    current_limit : float
        Amplifier peak current [A]; the current vector is kept in the inscribed regular octagon
        (facets at 0.924 of the limit, vertices on the circle).
    gap_bounds, position_bounds : (float, float)
        State bounds [m] on x1 and x3 at nodes 2..N.
    observer_epsilon : float
        High-gain observer time constant [s].
    disturbance_bandwidth : float
        w_d [rad/s] of the disturbance estimate; 0 switches the disturbance estimate off.
    disturbance_limit : float
        |d| clip [m/s^2].
    qp_options : dict
        Options merged into the QP solver's (e.g. ``{"hpipm": {"mode": "robust"}}``).
    preview : bool
        Read the future reference from the reference array (default), or extrapolate the current
        sample (causal, like the papers' regulators: set-point steps are not anticipated).
    unconstrained_shortcut : bool
        Take the Riccati step when it is feasible (default) or solve the QP every sample.
    compile : bool
        JIT-compile the three SX parts of the RTI step with the system C compiler (CasADi
        ``jit``, -O1: 10-25 s once; then 2.5-3x faster calls, 0.13 ms instead of 0.31-0.36 ms
        at N = 20 on the 2-core test machine). Needs gcc/cc; the C export
        (:mod:`maglev_oc.control.codegen`) does not use it.
    name : str
        Default "NMPC" (the name the comparison plots know), "NMPC (converged, IPOPT)".
    """

    def __init__(
        self,
        model: StageModel,
        *,
        horizon: int = DEFAULT_HORIZON,
        interval: float = DEFAULT_INTERVAL,
        sample_time: float = RIG_SAMPLE_TIME,
        weights: NMPCWeights | None = None,
        mode: str = "rti",
        qp_solver: str = "hpipm",
        current_limit: float = PEAK_CURRENT_LIMIT,
        gap_bounds: tuple[float, float] = DEFAULT_GAP_BOUNDS,
        position_bounds: tuple[float, float] = DEFAULT_POSITION_BOUNDS,
        observer_epsilon: float = DEFAULT_EPSILON,
        disturbance_bandwidth: float = DEFAULT_DISTURBANCE_BANDWIDTH,
        disturbance_limit: float = DEFAULT_DISTURBANCE_LIMIT,
        qp_options: dict | None = None,
        preview: bool = True,
        unconstrained_shortcut: bool = True,
        compile: bool = False,
        name: str | None = None,
    ) -> None:
        if not isinstance(model, StageModel):
            raise TypeError(f"model must be a StageModel, got {type(model).__name__}")
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        if qp_solver not in QP_SOLVERS:
            raise ValueError(f"qp_solver must be one of {QP_SOLVERS}, got {qp_solver!r}")
        if not (sample_time > 0 and math.isfinite(sample_time)):
            raise ValueError(f"sample_time must be positive [s], got {sample_time!r}")
        ratio = interval / sample_time
        if not (math.isfinite(ratio) and ratio >= 1 and abs(ratio - round(ratio)) < 1e-9):
            raise ValueError(
                f"interval must be a positive multiple of sample_time {sample_time} s, got {interval!r}"
            )
        if not (math.isfinite(current_limit) and current_limit > 0):
            raise ValueError(f"current_limit must be positive [A], got {current_limit!r}")
        for label, b in (("gap_bounds", gap_bounds), ("position_bounds", position_bounds)):
            if len(b) != 2 or not (b[0] < b[1]) or not all(math.isfinite(v) for v in b):
                raise ValueError(f"{label} must be (lower, upper) with lower < upper [m], got {b!r}")
        if gap_bounds[1] > 0.1 or gap_bounds[0] <= 0:
            raise ValueError(f"gap_bounds must be positive and in metres, got {gap_bounds!r}")
        if not (disturbance_bandwidth >= 0 and math.isfinite(disturbance_bandwidth)):
            raise ValueError(f"disturbance_bandwidth must be >= 0 [rad/s], got {disturbance_bandwidth!r}")
        if not (disturbance_limit > 0 and math.isfinite(disturbance_limit)):
            raise ValueError(f"disturbance_limit must be positive [m/s^2], got {disturbance_limit!r}")
        if disturbance_bandwidth * observer_epsilon > 0.5:
            raise ValueError(
                f"disturbance_bandwidth {disturbance_bandwidth} rad/s is too close to the observer's "
                f"1/eps = {1 / observer_epsilon:g} rad/s (keep w_d eps <= 0.5)"
            )
        weights = NMPCWeights() if weights is None else weights
        if not isinstance(weights, NMPCWeights):
            raise TypeError(f"weights must be NMPCWeights, got {type(weights).__name__}")

        self.model = model
        self.sample_time = float(sample_time)
        self.grid = ShootingGrid(self.sample_time, round(ratio), int(horizon))
        self.weights = weights
        self.mode = mode
        self.qp_solver = qp_solver
        self.qp_options = dict(qp_options or {})
        self.unconstrained_shortcut = bool(unconstrained_shortcut)
        self.preview = bool(preview)
        self.current_limit = float(current_limit)
        self.compiled = bool(compile)
        self.name = name or ("NMPC" if mode == "rti" else "NMPC (converged, IPOPT)")
        self.diag_names = DIAG_NAMES
        self._ocp = _Transcription(
            model, self.grid, weights, current_limit, tuple(gap_bounds), tuple(position_bounds)
        )
        self._est = _Estimator(
            model, self.sample_time, observer_epsilon, disturbance_bandwidth, disturbance_limit
        )
        self.shift = shift_matrix(self.grid)
        self.nz = self._ocp.nz
        self.na = self._ocp.na
        self.n_memory = 6 + self.nz
        self._build_sx_parts()
        self.rti_step, self._rti_qp = self._build_rti_step(self._qp_data, self._riccati, self._post)
        # the controller's own copy (JIT-compiled parts if asked), with its own QP solver instance
        # so that the solver statistics read after each call are those of that call
        parts = (self._qp_data, self._riccati, self._post)
        if self.compiled:
            parts = tuple(_jit(f) for f in parts)
        step, self._step_qp = self._build_rti_step(*parts)
        self._step = self._python_entry(step)
        if mode == "converged":
            self._build_nlp()
        self._memory: np.ndarray | ca.DM | None = None
        self._u_last = np.zeros(NU)

    # ------------------------------------------------------------------------------------
    @property
    def terminal_cost(self) -> TerminalCostTable:
        return self._ocp.terminal

    @property
    def node_offsets(self) -> np.ndarray:
        return self.grid.node_offsets

    def local_lqr(self, gap: float, position: float = 0.0) -> LocalLQR:
        """The LQR the NMPC coincides with near the equilibrium at ``gap`` [m]."""
        return self._ocp.local_lqr(gap, position)

    # ------------------------------------------------------------------------------------
    def _build_sx_parts(self) -> None:
        ocp, est = self._ocp, self._est
        n, nz, na = self.grid.horizon, self.nz, self.na
        self._qp_data = ocp.qp_data_function()
        self._cost = ocp.objective_function()

        # post-processing: check, fallback, shift, observer
        zb = ca.SX.sym("z_bar", nz)
        dz = ca.SX.sym("dz", nz)
        lam_x = ca.SX.sym("lam_x", nz)
        lam_a = ca.SX.sym("lam_a", na)
        a = ca.SX.sym("A", self._qp_data.sparsity_out("A"))
        lba = ca.SX.sym("lba", na)
        uba = ca.SX.sym("uba", na)
        lbx = ca.SX.sym("lbx", nz)
        ubx = ca.SX.sym("ubx", nz)
        data_ok = ca.SX.sym("data_ok")
        obs = ca.SX.sym("obs", 4)
        d = ca.SX.sym("d", 2)
        y = ca.SX.sym("y", 2)
        hess = ca.SX.sym("H", self._qp_data.sparsity_out("H"))
        z_ref = ca.SX.sym("z_ref", nz)

        adz = ca.mtimes(a, dz)
        viol = ca.vertcat(lba - adz, adz - uba, lbx - dz, dz - ubx)
        worst = ca.mmax(viol)
        size = ca.sum1(ca.fabs(dz)) + ca.sum1(ca.fabs(lam_a))
        ok = ca.logic_and(ca.logic_and(data_ok, size < 1e20), worst <= SOLUTION_TOLERANCE)
        z_qp = zb + dz * ca.DM(ocp.z_scale)
        plan_finite = ca.sum1(ca.fabs(zb)) < 1e20
        ref_finite = ca.sum1(ca.fabs(z_ref)) < 1e20
        # fallback: the shifted previous plan, else the reference plan (its first input is the
        # feedforward current of the reference), else no current at all
        z_keep = ca.if_else(plan_finite, zb, ca.if_else(ref_finite, z_ref, ca.DM.zeros(nz)))
        z_new = ca.if_else(ok, z_qp, z_keep)
        u = ocp.project_current(z_new[0:NU])
        z_next = ca.mtimes(ca.DM(ca.sparsify(ca.DM(self.shift))), z_new)
        e = (z_new - z_ref) / ca.DM(ocp.z_scale)
        cost = 0.5 * ca.bilin(hess, e, e)
        obs_next, d_next = est.update(obs, d, y, u)
        memory_next = ca.vertcat(obs_next, d_next, z_next)
        # inequality rows of A (2 per stage) and bounds with a nonzero multiplier
        ineq = [lam_a[6 * j + NX + i] for j in range(n) for i in range(2)]
        active = ca.sum1(ca.fabs(ca.vertcat(*ineq, lam_x)) > 1e-9)
        diag = ca.vertcat(ok, 0, cost, d, ca.if_else(ok, active, -1))
        names = ["z_bar", "dz", "lam_x", "lam_a", "A", "lba", "uba", "lbx", "ubx", "data_ok", "H", "z_ref"]
        self._post = ca.Function(
            "nmpc_post",
            [zb, dz, lam_x, lam_a, a, lba, uba, lbx, ubx, data_ok, hess, z_ref, obs, d, y],
            [u, memory_next, diag, z_new],
            [*names, "obs", "d", "y"],
            ["u", "memory_next", "diag", "plan"],
        )
        self._riccati = self._riccati_function()
        # estimator alone (converged mode)
        u_s = ca.SX.sym("u", NU)
        o_n, d_n = est.update(obs, d, y, u_s)
        self._estimator = ca.Function("nmpc_estimator", [obs, d, y, u_s], [o_n, d_n])

    def _riccati_function(self) -> ca.Function:
        """(H, g, A, lba, uba, lbx, ubx) -> (dz, feasible): the minimizer of the QP without its
        inequalities, by the Riccati recursion of the equality-constrained (LQ) problem, and
        whether it satisfies every bound and polytope row (then it IS the QP's solution)."""
        n, nz, na = self.grid.horizon, self.nz, self.na
        hess = ca.SX.sym("H", self._qp_data.sparsity_out("H"))
        grad = ca.SX.sym("g", nz)
        a = ca.SX.sym("A", self._qp_data.sparsity_out("A"))
        lba = ca.SX.sym("lba", na)
        uba = ca.SX.sym("uba", na)
        lbx = ca.SX.sym("lbx", nz)
        ubx = ca.SX.sym("ubx", nz)

        def blk(m, r, c, nr, nc):
            return ca.densify(m[r : r + nr, c : c + nc])

        def inv2(m):
            det = m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]
            return ca.vertcat(ca.horzcat(m[1, 1], -m[0, 1]), ca.horzcat(-m[1, 0], m[0, 0])) / det

        bs, as_, cs, gains = [], [], [], []
        for j in range(n):
            row = 6 * j
            bs.append(blk(a, row, _u_index(j), NX, NU))
            as_.append(blk(a, row, _x_index(j), NX, NX) if j > 0 else None)
            cs.append(-lba[row : row + NX])
        xn = _x_index(n)
        p_mat = blk(hess, xn, xn, NX, NX)
        p_vec = grad[xn : xn + NX]
        for j in range(n - 1, -1, -1):
            iu = _u_index(j)
            b, c = bs[j], cs[j]
            pcp = ca.mtimes(p_mat, c) + p_vec
            quu = blk(hess, iu, iu, NU, NU) + ca.mtimes(b.T, ca.mtimes(p_mat, b))
            qu = grad[iu : iu + NU] + ca.mtimes(b.T, pcp)
            quu_inv = inv2(quu)
            if j == 0:
                gains.append((None, ca.mtimes(quu_inv, qu)))
                break
            am = as_[j]
            ix = _x_index(j)
            pa = ca.mtimes(p_mat, am)  # shared by B' P A and A' P A
            qux = ca.mtimes(b.T, pa)
            k_mat = ca.mtimes(quu_inv, qux)
            k_vec = ca.mtimes(quu_inv, qu)
            gains.append((k_mat, k_vec))
            p_new = blk(hess, ix, ix, NX, NX) + ca.mtimes(am.T, pa) - ca.mtimes(qux.T, k_mat)
            p_vec = grad[ix : ix + NX] + ca.mtimes(am.T, pcp) - ca.mtimes(qux.T, k_vec)
            p_mat = 0.5 * (p_new + p_new.T)
        gains = gains[::-1]
        parts = []
        du = -gains[0][1]
        dx = ca.mtimes(bs[0], du) + cs[0]
        parts += [du, dx]
        for j in range(1, n):
            k_mat, k_vec = gains[j]
            du = -ca.mtimes(k_mat, dx) - k_vec
            dx = ca.mtimes(as_[j], dx) + ca.mtimes(bs[j], du) + cs[j]
            parts += [du, dx]
        dz = ca.vertcat(*parts)
        adz = ca.mtimes(a, dz)
        rows = [6 * j + NX + i for j in range(n) for i in range(2)]
        slack = ca.vertcat(dz - lbx, ubx - dz, adz[rows] - lba[rows], uba[rows] - adz[rows])
        feasible = ca.mmin(slack) >= 0
        return ca.Function(
            "nmpc_riccati",
            [hess, grad, a, lba, uba, lbx, ubx],
            [dz, feasible],
            ["H", "g", "A", "lba", "uba", "lbx", "ubx"],
            ["dz", "feasible"],
        )

    def _qp_function(self) -> ca.Function:
        n = self.grid.horizon
        sp = {"h": self._qp_data.sparsity_out("H"), "a": self._qp_data.sparsity_out("A")}
        opts: dict = {"error_on_fail": False}
        if self.qp_solver == "hpipm":
            opts.update(
                N=n,
                nx=[NU] + [NX] * n,
                nu=[0] + [NU] * (n - 1) + [0],
                ng=[2] * n + [0],
                hpipm={"mode": "speed_abs", "iter_max": 30},
            )
        elif self.qp_solver == "qrqp":
            opts.update(print_iter=False, print_header=False, print_info=False, max_iter=200)
        else:
            opts.update(
                osqp={"verbose": False, "eps_abs": 1e-9, "eps_rel": 1e-9, "max_iter": 20000, "polish": True}
            )
        for key, value in self.qp_options.items():  # solver-specific overrides, one level deep
            if isinstance(value, dict) and isinstance(opts.get(key), dict):
                opts[key] = {**opts[key], **value}
            else:
                opts[key] = value
        return ca.conic("nmpc_qp", self.qp_solver, sp, opts)

    def _build_rti_step(
        self, qp_data: ca.Function, riccati: ca.Function, post: ca.Function
    ) -> tuple[ca.Function, ca.Function]:
        """The RTI step Function and the QP solver (conic) inside it."""
        n, nz, na = self.grid.horizon, self.nz, self.na
        mem = ca.MX.sym("memory", self.n_memory)
        y = ca.MX.sym("y", 2)
        ref = ca.MX.sym("ref", 6, n + 1)
        obs, d = mem[0:4], mem[4:6]
        zb = mem[6 : 6 + nz]
        x0 = self._est.state_estimate(obs, y)
        data = qp_data(zb, x0, d, ref)
        _, _, a, lba, uba, lbx, ubx, data_ok, _ = data
        qp_in = [
            ca.MX.sym(name, sp)
            for name, sp in zip(
                ("H", "g", "A", "lba", "uba", "lbx", "ubx", "dz_lq"),
                [qp_data.sparsity_out(i) for i in range(7)] + [ca.Sparsity.dense(nz, 1)],
                strict=True,
            )
        ]
        qp = self._qp_function()
        # Cold start: QRQP warm-started with the previous multipliers was seen to return a wrong
        # step (equality rows dropped from its initial active set) while reporting success, and
        # an interior point method has no use for them. All of the conic's outputs are used:
        # CasADi 3.8.2's HPIPM interface writes lam_a even when nobody asked for it (a NULL
        # pointer inside an MX graph: segfault).
        sol = qp(
            h=qp_in[0],
            g=qp_in[1],
            a=qp_in[2],
            lba=qp_in[3],
            uba=qp_in[4],
            lbx=qp_in[5],
            ubx=qp_in[6],
            x0=ca.DM.zeros(nz),
            lam_x0=ca.DM.zeros(nz),
            lam_a0=ca.DM.zeros(na),
        )
        solve_qp = ca.Function("nmpc_solve_qp", qp_in, [sol["x"], sol["lam_x"], sol["lam_a"]])
        if self.unconstrained_shortcut:
            take_lq = ca.Function("nmpc_take_lq", qp_in, [qp_in[7], ca.DM.zeros(nz), ca.DM.zeros(na)])
            # only the selected branch runs (a CasADi Switch, also in the generated C)
            step = ca.Function.if_else("nmpc_lq_or_qp", take_lq, solve_qp)
            dz_lq, feasible = riccati(*data[:7])
            dz, lam_x, lam_a = step(feasible, *data[:7], dz_lq)
        else:
            feasible = ca.MX(0)
            dz, lam_x, lam_a = solve_qp(*data[:7], ca.DM.zeros(nz))
        hess, z_ref = data[0], data[8]
        u, mem_next, diag, _ = post(
            zb, dz, lam_x, lam_a, a, lba, uba, lbx, ubx, data_ok, hess, z_ref, obs, d, y
        )
        # qp_iterations: 0 when the unconstrained step was taken, -1 (filled in from the solver's
        # statistics in Python) when the QP was solved
        diag = ca.vertcat(diag[0], ca.if_else(feasible, 0, -1), diag[2:], ca.if_else(feasible, -1, np.nan))
        step = ca.Function(
            "nmpc_rti_step",
            [mem, y, ref],
            [u, mem_next, diag],
            ["memory", "y", "ref"],
            ["u", "memory_next", "diag"],
        )
        return step, qp

    def _build_nlp(self) -> None:
        ocp = self._ocp
        n, nz = self.grid.horizon, self.nz
        z = ca.SX.sym("z", nz)
        x0 = ca.SX.sym("x0", NX)
        d = ca.SX.sym("d", 2)
        ref = ca.SX.sym("ref", 6, n + 1)
        xs, us = ocp.stage_states(z, x0)
        g = []
        for j in range(n):
            g.append(ocp.rk4(xs[j], us[j], d, float(self.grid.intervals[j])) - xs[j + 1])
            g.append(ca.mtimes(ca.DM(ocp.D), us[j]))
        p = ca.vertcat(x0, d, ca.vec(ref))
        nlp = {"x": z, "p": p, "f": self._cost(z, d, ref), "g": ca.vertcat(*g)}
        opts = {
            "print_time": False,
            "error_on_fail": False,
            "ipopt": {
                "print_level": 0,
                "sb": "yes",
                "tol": 1e-10,
                "acceptable_tol": 1e-8,
                "max_iter": 200,
                "warm_start_init_point": "yes",
                "mu_strategy": "adaptive",
            },
        }
        self._nlp = ca.nlpsol("nmpc_nlp", "ipopt", nlp, opts)
        lim = math.sqrt(2) * ocp.radius
        self._lbg = np.tile(np.r_[np.zeros(NX), -lim, -lim], n)
        self._ubg = np.tile(np.r_[np.zeros(NX), lim, lim], n)
        self._lbz, self._ubz = ocp.bounds()

    # ------------------------------------------------------------------------------------
    def initial_memory(self, y0, r0=None, u0=None) -> np.ndarray:
        """Controller memory at start: observer at the first reading at rest, no disturbance, the
        plan holding the current position with the current ``u0`` already flowing."""
        y0 = np.asarray(y0, dtype=float).reshape(2)
        u0 = np.zeros(NU) if u0 is None else np.asarray(u0, dtype=float).reshape(NU)
        z = np.zeros(self.nz)
        for j in range(self.grid.horizon):
            z[_u_index(j) : _u_index(j) + NU] = u0
        for j in range(1, self.grid.horizon + 1):
            z[_x_index(j) : _x_index(j) + NX] = [y0[0], 0.0, y0[1], 0.0]
        return np.concatenate([[y0[0], 0.0, y0[1], 0.0], [0.0, 0.0], z])

    def reset(self, y0, r0, u0) -> None:
        self._memory = self.initial_memory(y0, r0, u0)
        self._u_last = np.asarray(u0, dtype=float).reshape(NU).copy()
        self._lam_g = None
        self._lam_x = None

    def node_references(self, k: int, reference: np.ndarray) -> np.ndarray:
        """The reference (6, N + 1) at the shooting nodes from sample ``k`` on.

        With ``preview`` the nodes read the reference array at their own times; nodes beyond
        its last sample extrapolate it with its last velocity and acceleration (a set-point is
        held; a sinusoid ending mid-motion is continued instead of being seen to stop, which
        would make the plan brake before the run ends). Without ``preview`` every node
        extrapolates the current sample that way (a causal controller: a step is seen when it
        happens, a sinusoid is continued by its local Taylor expansion).
        """
        last = reference.shape[1] - 1
        if not self.preview:
            return _extrapolate(reference[:, min(k, last)], self.grid.node_offsets * self.sample_time)
        idx = k + self.grid.node_offsets
        if idx[-1] <= last:
            return reference[:, idx]
        out = reference[:, np.minimum(idx, last)].copy()
        beyond = idx > last
        out[:, beyond] = _extrapolate(reference[:, last], (idx[beyond] - last) * self.sample_time)
        return out

    def control(self, k: int, y, reference: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self._memory is None:
            raise RuntimeError("NonlinearMPC.control() called before reset()")
        ref = self.node_references(k, reference)
        if self.mode == "rti":
            return self._control_rti(y, ref)
        return self._control_converged(y, ref)

    def _python_entry(self, step: ca.Function) -> ca.Function:
        """(memory, [y; vec(ref)]) -> ([u; diag], memory_next): the RTI step with its inputs and
        outputs packed, because each numpy <-> CasADi conversion costs 10-25 us in Python while
        the memory can stay a DM from one call to the next."""
        n = self.grid.horizon
        mem = ca.MX.sym("memory", self.n_memory)
        yr = ca.MX.sym("y_ref", 2 + 6 * (n + 1))
        u, mem_next, diag = step(mem, yr[0:2], ca.reshape(yr[2:], 6, n + 1))
        return ca.Function("nmpc_control", [mem, yr], [ca.vertcat(u, diag), mem_next])

    def _control_rti(self, y, ref) -> tuple[np.ndarray, np.ndarray]:
        yr = np.concatenate([np.asarray(y, dtype=float).ravel(), ref.ravel(order="F")])
        try:
            out, mem = self._step(self._memory, yr)
        except RuntimeError as err:  # defensive: the Function is built not to raise
            warnings.warn(
                f"NMPC step raised ({err}); applying the previous current", RuntimeWarning, stacklevel=2
            )
            d = self.memory[4:6]
            return self._u_last.copy(), np.array([0.0, 0.0, np.nan, *d, -1.0, np.nan])
        self._memory = mem
        out = np.array(out.nonzeros())
        u, diag = out[0:NU], out[NU:]
        if diag[1] < 0:
            _fill_qp_stats(diag, self._step_qp)
        self._u_last = u
        return u, diag

    def step_rti(self, memory: np.ndarray, y, ref) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One evaluation of :attr:`rti_step` on explicit inputs (u, memory_next, diag), the
        controller's own memory untouched (for analyses and tests)."""
        u, mem, diag = self.rti_step(memory, y, ref)
        diag = diag.full().ravel()
        if diag[1] < 0:
            _fill_qp_stats(diag, self._rti_qp)
        return u.full().ravel(), mem.full().ravel(), diag

    def _control_converged(self, y, ref) -> tuple[np.ndarray, np.ndarray]:
        y = np.asarray(y, dtype=float).ravel()
        nz = self.nz
        mem = self._memory
        obs, d = mem[0:4], mem[4:6]
        zb = mem[6 : 6 + nz]
        x0 = np.array([y[0], obs[1], y[1], obs[3]])
        p = np.concatenate([x0, d, ref.ravel(order="F")])
        args = {"x0": zb, "p": p, "lbx": self._lbz, "ubx": self._ubz, "lbg": self._lbg, "ubg": self._ubg}
        if self._lam_g is not None:
            args["lam_g0"] = self._lam_g
            args["lam_x0"] = self._lam_x
        ok = False
        iters = 0
        if np.all(np.isfinite(p)):
            sol = self._nlp(**args)
            stats = self._nlp.stats()
            z = sol["x"].full().ravel()
            ok = bool(stats["success"]) and np.all(np.isfinite(z))
            iters = stats.get("iter_count", 0)
        if ok:
            self._lam_g = sol["lam_g"].full().ravel()
            self._lam_x = sol["lam_x"].full().ravel()
            u = z[0:NU].copy()
        else:
            z = zb
            self._lam_g = None
            u = np.asarray(self._ocp_fallback(zb, d, ref)).ravel()
        cost = float(self._cost(z, d, ref)) if np.all(np.isfinite(z)) else np.nan
        obs_n, d_n = self._estimator(obs, d, y, u)
        self._memory = np.concatenate([np.asarray(obs_n).ravel(), np.asarray(d_n).ravel(), self.shift @ z])
        self._u_last = u
        active = -1.0
        if ok:
            lam = np.concatenate([self._lam_x, self._lam_g.reshape(-1, 6)[:, NX:].ravel()])
            active = float(np.sum(np.abs(lam) > 1e-9))
        return u, np.array([float(ok), iters, cost, *d, active, 0.0 if ok else 1.0])

    def _ocp_fallback(self, zb, d, ref):
        u = (
            zb[0:NU]
            if np.all(np.isfinite(zb[0:NU]))
            else np.asarray(self._ocp.feedforward(ref[:, 0], d)).ravel()
        )
        r = self._ocp.radius
        m = max(abs(u[0]), abs(u[1]), abs(u[0] + u[1]) / math.sqrt(2), abs(u[0] - u[1]) / math.sqrt(2))
        return u / max(1.0, m / r)

    # ------------------------------------------------------------------------------------
    @property
    def memory(self) -> np.ndarray:
        """The controller memory: observer (p_v, q_v, p_h, q_h), disturbance (d_v, d_h), the
        shifted plan z (6N)."""
        if self._memory is None:
            raise RuntimeError("no memory before reset()")
        if isinstance(self._memory, ca.DM):
            return np.array(self._memory.nonzeros())
        return self._memory.copy()

    @property
    def disturbance(self) -> np.ndarray:
        """Current disturbance estimate (d_v, d_h) [m/s^2]."""
        return self.memory[4:6]

    def plan(self) -> tuple[np.ndarray, np.ndarray]:
        """The shifted plan as (states (4, N), inputs (2, N)) for nodes 1..N and 0..N-1."""
        z = self.memory[6 : 6 + self.nz]
        xs = np.array([z[_x_index(j) : _x_index(j) + NX] for j in range(1, self.grid.horizon + 1)]).T
        us = np.array([z[_u_index(j) : _u_index(j) + NU] for j in range(self.grid.horizon)]).T
        return xs, us


def _extrapolate(r: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """The reference sample r (6,) continued with constant acceleration over times dt: (6, n)."""
    out = np.empty((6, dt.size))
    for row in (0, 3):
        p, v, a = r[row], r[row + 1], r[row + 2]
        out[row] = p + v * dt + 0.5 * a * dt**2
        out[row + 1] = v + a * dt
        out[row + 2] = a
    return out


def _fill_qp_stats(diag: np.ndarray, qp: ca.Function) -> None:
    """Put the QP solver's iteration count and success into diag (in place).

    A conic called inside an MX Function (here behind a Switch) keeps its statistics in the
    memory the enclosing Function checked out for it, index 1 for a Function evaluated from one
    thread; the enclosing Function's own stats() does not forward them through the Switch.
    Diagnostics only: if they are not there, the entries stay -1 / NaN.
    """
    try:
        stats = qp.stats(1)
    except RuntimeError:
        return
    diag[1] = stats.get("iter_count", -1)
    diag[6] = 0.0 if stats.get("success", False) else 1.0


def _jit(fun: ca.Function) -> ca.Function:
    """A JIT-compiled copy of an SX Function (CasADi 'shell' compiler, -O3)."""
    ins = [ca.SX.sym(fun.name_in(i), fun.sparsity_in(i)) for i in range(fun.n_in())]
    return ca.Function(
        fun.name() + "_jit",
        ins,
        fun(*ins),
        fun.name_in(),
        fun.name_out(),
        {"jit": True, "compiler": "shell", "jit_options": {"flags": ["-O1"], "verbose": False}},
    )


def nominal_equilibrium_current(model: StageModel, gap: float) -> np.ndarray:
    """(0, i_d) holding ``gap`` [m] on ``model`` (NaN if none), for fallbacks and tests."""
    try:
        return equilibrium(model, gap, current_limit=math.inf).u
    except NoEquilibriumError:
        return np.array([0.0, np.nan])
