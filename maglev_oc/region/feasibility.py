"""The feasible set of the FL regulator: where the feedback transformation exists and the currents fit.

The transformation (002 (13)-(16), physical root of SPEC 1 reading 5) is defined on
A = {R(x1, v1, v2) >= 0} (L1, L4 > 0 on every gap considered). With the amplifiers' limit on the
current-vector magnitude |u| = sqrt(i_q^2 + i_d^2) <= I (9 A peak, 002 Sec. 4) and the stoppers,
the feasible set is

    F = { margin(x1, v) = R / (4 L4) = L3^2/(4 L4) + G - L2 - L4 (v1/L1)^2 - v2 >= 0     [m/s^2]
          headroom(x1, v) = I^2 - u1^2 - u2^2 >= 0                                      [A^2]
          g_lo <= x1 <= g_hi,  p_lo <= x3 <= p_hi }                                     [m]

with u1 = -v1/L1 and the physical root written without cancellation,

    u2 = (-L3 - sqrt R) / (2 L4) = 2 (L4 u1^2 + L2 - G + v2) / (sqrt R - L3)      (L3 < 0),

which is the same number (multiply by (sqrt R - L3)/(sqrt R - L3)) but evaluates to tight
intervals. In the closed loop, v = K z, so F is a set of states (x, xi) and reference phases;
:func:`feasibility_map` draws it on two-dimensional slices and locates its boundary by Newton's
method (CasADi ``rootfinder``) on every grid line where a constraint changes sign.

Over 8-30 mm the root at R = 0 needs i_d = -L3/(2 L4) >= 18 A, twice the peak limit, so with the
9 A limit the current constraint always binds before R = 0: A is larger than F.

**Compensated effects.** When the regulator feeds an identified acceleration d(x) forward (a
stage file's state-dependent effects, ``FeedbackLinearizingRegulator(compensation=d)``), it asks
the transformation for v - d(x) (vertical d_1 from v2, horizontal d_2 from v1). On the plant that
has exactly that effect the loop in error coordinates is unchanged (the effect is cancelled), but
the transformation and the currents are evaluated at v - d(x): F depends on the states d depends
on (the velocities for friction, the position for cogging or a cable carrier) as well as on
(x1, v1, v2). ``FeasibleSet(compensation=d)`` is that set; :attr:`FeasibleSet.loop_variables`
names what it depends on.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.model.hardware import PEAK_CURRENT_LIMIT, STOPPER_GAP, STOPPER_POSITION
from maglev_oc.model.stage import StageModel
from maglev_oc.region.closed_loop import N_ERROR, Reference, RegulatorLoop
from maglev_oc.region.interval import IntervalFunction
from maglev_oc.results import Result
from maglev_oc.units import M_TO_MM

__all__ = [
    "CONSTRAINT_LABELS",
    "CONSTRAINT_NAMES",
    "CONSTRAINT_UNITS",
    "GAP_TRAVEL",
    "NONLINEAR",
    "POSITION_TRAVEL",
    "SLICE_VARIABLES",
    "FeasibilityMap",
    "FeasibleSet",
    "compensated_constraints",
    "constraints_from_coefficients",
    "feasibility_map",
    "transformation_constraints",
]

GAP_TRAVEL = STOPPER_GAP
"""Gap between the stoppers [m] (:data:`maglev_oc.model.hardware.STOPPER_GAP`; 002 Fig. 5)."""
POSITION_TRAVEL = STOPPER_POSITION
"""Horizontal position between the stoppers [m] (:data:`maglev_oc.model.hardware.STOPPER_POSITION`)."""

CONSTRAINT_NAMES = ("margin", "headroom", "gap_low", "gap_high", "position_low", "position_high")
NONLINEAR = CONSTRAINT_NAMES[:2]
"""The constraints of F that are not linear in the loop's error state (R >= 0 and |u| <= I)."""
CONSTRAINT_LABELS = (
    "R >= 0 (transformation exists)",
    "|u| <= current limit",
    "gap >= lower stopper",
    "gap <= upper stopper",
    "position >= left stopper",
    "position <= right stopper",
)
CONSTRAINT_UNITS = ("m/s^2", "A^2", "m", "m", "m", "m")


def transformation_constraints(model: StageModel, x1, v, current_limit: float | None):
    """Symbolic (margin [m/s^2], headroom [A^2]) at gap x1 and accelerations v (CasADi).

    ``headroom`` uses sqrt(max(R, 0)); it is meaningful where margin >= 0. With
    ``current_limit=None`` headroom is returned as the constant 1 (no current constraint).

    Parameters
    ----------
    model : StageModel
        Supplies L1..L4 and gravity.
    x1 : CasADi scalar
        Gap [m].
    v : CasADi (2,)
        Accelerations (v1, v2) [m/s^2].
    current_limit : float or None
        |u| limit [A].

    Returns
    -------
    (margin, headroom)
        CasADi expressions [m/s^2], [A^2].
    """
    L1, L2, L3, L4 = model.L(x1)
    G = model.params.gravity
    u1 = -v[0] / L1
    margin = L3**2 / (4 * L4) + G - L2 - L4 * u1**2 - v[1]
    if current_limit is None:
        return margin, ca.SX(1.0) if isinstance(x1, ca.SX) else 1.0
    sqrt_r = 2 * ca.sqrt(L4 * ca.fmax(margin, 0))
    u2 = 2 * (L4 * u1**2 + L2 - G + v[1]) / (sqrt_r - L3)
    headroom = current_limit**2 - u1**2 - u2**2
    return margin, headroom


def compensated_constraints(
    model: StageModel, x, v, current_limit: float | None, compensation: ca.Function | None
):
    """(margin, headroom) of :func:`transformation_constraints` at the state ``x`` (4: x1..x4) when
    the regulator compensates ``compensation`` (x (4) -> (x2', x4') [m/s^2]): the transformation
    is asked for (v1 - d_2(x), v2 - d_1(x)), as in :class:`FeedbackLinearizingRegulator`. Without
    a compensation, the constraints at v (x2..x4 unused)."""
    if compensation is None:
        return transformation_constraints(model, x[0], v, current_limit)
    d = compensation(x)
    return transformation_constraints(model, x[0], ca.vertcat(v[0] - d[1], v[1] - d[0]), current_limit)


def constraints_from_coefficients(coefficients, v1, v2, gravity: float, current_limit: float | None):
    """numpy twin of :func:`transformation_constraints` given L1..L4 (4, ...) at the gaps.

    Parameters
    ----------
    coefficients : (4, ...) array
        L1..L4 at the gaps (``StageModel.coefficients``).
    v1, v2 : arrays
        Accelerations [m/s^2], broadcast with the trailing shape.
    gravity : float
        [m/s^2].
    current_limit : float or None
        |u| limit [A] (None: headroom is 1).

    Returns
    -------
    (margin, headroom)
        Arrays [m/s^2], [A^2].
    """
    L1, L2, L3, L4 = coefficients
    u1 = -v1 / L1
    margin = L3**2 / (4 * L4) + gravity - L2 - L4 * u1**2 - v2
    if current_limit is None:
        return margin, np.ones_like(margin)
    sqrt_r = 2 * np.sqrt(L4 * np.maximum(margin, 0))
    u2 = 2 * (L4 * u1**2 + L2 - gravity + v2) / (sqrt_r - L3)
    return margin, current_limit**2 - u1**2 - u2**2


@dataclass(frozen=True, eq=False)
class FeasibleSet:
    """The feasible set F (module docstring) for one model and one set of limits.

    Parameters
    ----------
    model : StageModel
        The controller's model (assumed equal to the plant).
    current_limit : float or None
        Limit on |u| [A] (default 9 A, the amplifiers' peak); None drops the current
        constraint and leaves A = {R >= 0} with the stoppers.
    gap_range, position_range : (float, float) or None
        Stoppers [m]; None drops the constraint.
    compensation : casadi.Function, optional
        The acceleration the regulator feeds forward, x (4) -> (x2', x4') [m/s^2] (module
        docstring); its operations must have an interval extension
        (:class:`~maglev_oc.region.interval.IntervalFunction`).
    compensated : tuple of str
        Names of the compensated effects, for labels.

    Attributes
    ----------
    pointwise : casadi.Function
        (x (4), v (2)) -> (margin, headroom): x2..x4 matter only through the compensation.
    pointwise_interval : IntervalFunction of ``pointwise``
    loop_variables : tuple of str
        The :data:`~maglev_oc.region.closed_loop.LOOP_VARIABLES` the nonlinear constraints depend
        on: (x1, v1, v2), then x2, x3, x4 where the compensation depends on them.
    """

    model: StageModel
    current_limit: float | None = PEAK_CURRENT_LIMIT
    gap_range: tuple[float, float] | None = GAP_TRAVEL
    position_range: tuple[float, float] | None = POSITION_TRAVEL
    compensation: ca.Function | None = None
    compensated: tuple[str, ...] = ()
    pointwise: ca.Function = field(init=False, repr=False)
    pointwise_interval: IntervalFunction = field(init=False, repr=False)
    loop_variables: tuple[str, ...] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.model, StageModel):
            raise TypeError(f"model must be a StageModel, got {type(self.model).__name__}")
        if self.current_limit is not None and not (0 < self.current_limit < 100):
            raise InputError(f"current_limit must be in (0, 100) A or None, got {self.current_limit!r}")
        for name in ("gap_range", "position_range"):
            rng = getattr(self, name)
            if rng is None:
                continue
            lo, hi = (float(v) for v in rng)
            if not (lo < hi) or max(abs(lo), abs(hi)) > 0.5:
                raise InputError(f"{name} must be (low, high) in metres, got {rng!r}")
            object.__setattr__(self, name, (lo, hi))
        if self.gap_range is not None and self.gap_range[0] <= 0:
            raise InputError(f"gap_range must be positive [m], got {self.gap_range!r}")
        comp = self.compensation
        if comp is not None:
            if not isinstance(comp, ca.Function) or comp.n_in() != 1 or comp.n_out() != 1:
                raise InputError("compensation must be a casadi.Function x (4) -> (x2', x4') (2)")
            if comp.size1_in(0) != 4 or comp.size1_out(0) != 2:
                raise InputError("compensation must map x (4) -> (x2', x4') (2)")
        x = ca.SX.sym("x", 4)
        v = ca.SX.sym("v", 2)
        margin, headroom = compensated_constraints(self.model, x, v, self.current_limit, comp)
        fn = ca.Function("feasible", [x, v], [ca.vertcat(margin, headroom)], ["x", "v"], ["h"])
        object.__setattr__(self, "pointwise", fn)
        try:
            object.__setattr__(self, "pointwise_interval", IntervalFunction(fn))
        except NotImplementedError as exc:
            raise InputError(f"compensation: {exc}; no certificate can be computed with it") from None
        extra = ()
        if comp is not None:
            jac = ca.jacobian(comp(x), x).sparsity()
            used = {jac.get_col()[k] for k in range(jac.nnz())}  # columns that hold a nonzero
            extra = tuple(name for name, k in (("x2", 1), ("x3", 2), ("x4", 3)) if k in used)
        object.__setattr__(self, "loop_variables", ("x1", "v1", "v2", *extra))
        object.__setattr__(self, "compensated", tuple(self.compensated))

    @property
    def label(self) -> str:
        cur = "no current limit" if self.current_limit is None else f"|u| <= {self.current_limit:g} A"
        gap = (
            "no gap stoppers"
            if self.gap_range is None
            else f"gap in [{self.gap_range[0] * 1e3:g}, {self.gap_range[1] * 1e3:g}] mm"
        )
        comp = ""
        if self.compensation is not None:
            comp = f", {', '.join(self.compensated) or 'an effect'} compensated"
        return f"R >= 0, {cur}, {gap}{comp}"

    def check_setpoint(self, gap: float, position: float = 0.0) -> None:
        """Raise :class:`InputError` unless the stage at rest at (``gap``, ``position``) [m] lies
        strictly inside F; the message says which constraint fails and the range allowed."""
        mm = M_TO_MM
        where = f"set-point {gap * mm:g} mm gap, {position * mm:g} mm position"
        for name, value, rng in (("gap", gap, self.gap_range), ("position", position, self.position_range)):
            if rng is not None and not (rng[0] < value < rng[1]):
                raise InputError(
                    f"{where}: the {name} must lie strictly between the stoppers at "
                    f"{rng[0] * mm:g} and {rng[1] * mm:g} mm"
                )
        margin, headroom = self.evaluate(gap, 0.0, 0.0, x3=position)
        if margin > 0 and headroom > 0:
            return
        lo, hi = self.gap_range or (1e-3, 40e-3)
        grid = np.linspace(lo, hi, 401)[1:-1]
        h = self.evaluate(grid, 0.0, 0.0, x3=position)
        ok = grid[(h[0] > 0) & (h[1] > 0)]
        allowed = f"({ok.min() * mm:.1f}, {ok.max() * mm:.1f}) mm" if ok.size else "none"
        why = (
            "no equilibrium (R < 0)"
            if margin <= 0
            else f"its equilibrium needs |u| > {self.current_limit:g} A"
        )
        raise InputError(f"{where}: {why}; gaps held at rest within the limits: {allowed}")

    def evaluate(self, x1, v1, v2, *, x2=0.0, x3=0.0, x4=0.0) -> np.ndarray:
        """The constraints of F at given gaps and accelerations.

        Parameters
        ----------
        x1 : array
            Gap [m].
        v1, v2 : arrays
            Accelerations [m/s^2], broadcast with x1.
        x2, x3, x4 : arrays
            Vertical velocity [m/s], position [m], horizontal velocity [m/s]: they matter only
            through a compensation (default at rest at position 0).

        Returns
        -------
        (2, ...) array
            (margin [m/s^2], headroom [A^2]).
        """
        arrays = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (x1, v1, v2, x2, x3, x4)))
        x1, v1, v2, x2, x3, x4 = arrays
        n = x1.size
        x = np.vstack([a.ravel() for a in (x1, x2, x3, x4)])
        out = np.asarray(self.pointwise.map(n)(x, np.vstack([v1.ravel(), v2.ravel()])))
        return out.reshape((2, *x1.shape))

    # ------------------------------------------------------------------------------------
    def loop_expressions(self, loop: RegulatorLoop, ztilde, phase, offsets) -> list:
        """Symbolic constraint values (CONSTRAINT_NAMES order) of the closed loop at z~ and phase
        phi, with ``offsets`` the (6, 3) matrix of :meth:`RegulatorLoop.offset_coefficients`
        (a CasADi matrix or numbers)."""
        basis = ca.vertcat(1, ca.sin(phase), ca.cos(phase))
        off = ca.mtimes(offsets, basis)
        x1 = off[0] + ztilde[0]
        x3 = off[1] + ztilde[5]
        v1 = off[2] + ca.dot(ca.DM(loop.K_h), ztilde[5:10])
        v2 = off[3] + ca.dot(ca.DM(loop.K_v), ztilde[0:5])
        x = ca.vertcat(x1, off[4] + ztilde[1], x3, off[5] + ztilde[6])
        margin, headroom = compensated_constraints(
            self.model, x, ca.vertcat(v1, v2), self.current_limit, self.compensation
        )
        g_lo, g_hi = self.gap_range if self.gap_range is not None else (-np.inf, np.inf)
        p_lo, p_hi = self.position_range if self.position_range is not None else (-np.inf, np.inf)
        big = 1.0  # a constant "satisfied" value for constraints that are switched off
        return [
            margin,
            headroom,
            x1 - g_lo if np.isfinite(g_lo) else ca.SX(big),
            g_hi - x1 if np.isfinite(g_hi) else ca.SX(big),
            x3 - p_lo if np.isfinite(p_lo) else ca.SX(big),
            p_hi - x3 if np.isfinite(p_hi) else ca.SX(big),
        ]

    def loop_function(self, loop: RegulatorLoop, reference: Reference) -> ca.Function:
        """(z~ (10), phi) -> h (6): every constraint of F on the closed loop of ``reference``."""
        z = ca.SX.sym("z", N_ERROR)
        phi = ca.SX.sym("phi")
        h = self.loop_expressions(loop, z, phi, ca.DM(loop.offset_coefficients(reference)))
        return ca.Function("loop_constraints", [z, phi], [ca.vertcat(*h)], ["z", "phi"], ["h"])


# ----------------------------------------------------------------------------------------------
SLICE_VARIABLES = {
    "e1": 0,
    "e1_rate": 1,
    "xi_v1": 2,
    "xi_v2": 3,
    "xi_v3": 4,
    "e2": 5,
    "e2_rate": 6,
    "xi_h1": 7,
    "xi_h2": 8,
    "xi_h3": 9,
    "phase": 10,
}
"""Slice coordinates: deviations z~ from the reference's steady state (m, m/s, ...), or phase [rad]."""


@dataclass(frozen=True)
class FeasibilityMap(Result):
    """The constraints of F on a 2-D slice through the steady state of a reference.

    ``values`` has shape (6, ny, nx) (CONSTRAINT_NAMES order) on the grid ``x`` (nx) x ``y`` (ny)
    of slice coordinates (SLICE_VARIABLES; SI units). ``boundary[name]`` is a (2, k) array of
    points (x, y) where that constraint is exactly zero, found by Newton's method on the grid
    lines (columns: y varies; rows: x varies) that bracket a sign change, and kept only where
    every other constraint holds; ``newton_failures`` counts brackets where Newton left the
    bracket and bisection was used instead (the point is exact either way: ``status``
    ``"mapped"``).
    """

    success: bool
    status: str
    message: str
    reference: Reference
    axes: tuple[str, str]
    x: np.ndarray
    y: np.ndarray
    values: np.ndarray
    feasible: np.ndarray  # (ny, nx) bool
    boundary: dict[str, np.ndarray]
    newton_failures: int
    base: np.ndarray  # (11,) z~ and phase of the slice's origin
    timings: Mapping[str, float] = field(default_factory=dict)  # [s] {"total": ...}


def feasibility_map(
    feasible: FeasibleSet,
    loop: RegulatorLoop,
    reference: Reference,
    axes: tuple[str, str],
    x_range: tuple[float, float],
    y_range: tuple[float, float],
    *,
    n: int = 121,
    phase: float = 0.0,
) -> FeasibilityMap:
    """Constraints of F on the slice spanned by ``axes`` through z~ = 0 at ``phase``.

    Parameters
    ----------
    feasible : FeasibleSet
    loop : RegulatorLoop
    reference : Reference
    axes : (str, str)
        Two different keys of :data:`SLICE_VARIABLES`.
    x_range, y_range : (float, float)
        In the slice coordinates' SI units (e.g. (-0.01, 0.01) m for e1).
    n : int
        Grid points per axis (>= 3).
    phase : float
        Reference phase of the slice [rad].

    Returns
    -------
    FeasibilityMap
    """
    t0 = time.perf_counter()
    for a in axes:
        if a not in SLICE_VARIABLES:
            raise InputError(f"unknown slice variable {a!r}; known: {', '.join(SLICE_VARIABLES)}")
    if axes[0] == axes[1]:
        raise InputError(f"the two slice axes must differ, got {axes!r}")
    if n < 3:
        raise InputError(f"n must be >= 3, got {n!r}")
    fn = feasible.loop_function(loop, reference)
    base = np.zeros(N_ERROR + 1)
    base[N_ERROR] = phase
    ix, iy = SLICE_VARIABLES[axes[0]], SLICE_VARIABLES[axes[1]]
    xs = np.linspace(*x_range, n)
    ys = np.linspace(*y_range, n)
    X, Y = np.meshgrid(xs, ys)
    pts = np.repeat(base[:, None], X.size, axis=1)
    pts[ix] += X.ravel()
    pts[iy] += Y.ravel()
    vals = np.asarray(fn.map(X.size)(pts[:N_ERROR], pts[N_ERROR:]))
    values = vals.reshape(len(CONSTRAINT_NAMES), *X.shape)
    ok = np.all(values >= 0, axis=0)
    slicer = _Slice(fn, base, ix, iy, xs, ys)
    boundary, failures = slicer.boundary(values)
    points = sum(b.shape[1] for b in boundary.values())
    message = (
        f"{n} x {n} grid on ({axes[0]}, {axes[1]}): {ok.mean():.0%} feasible; {points} boundary points "
        f"({failures} by bisection where Newton left the bracket)"
    )
    return FeasibilityMap(
        True,
        "mapped",
        message,
        reference,
        tuple(axes),
        xs,
        ys,
        values,
        ok,
        boundary,
        failures,
        base,
        {"total": time.perf_counter() - t0},
    )


@dataclass(frozen=True)
class _Slice:
    """A slice of F: the loop's constraint Function, the origin (11,) and the grid."""

    fn: ca.Function
    base: np.ndarray
    ix: int
    iy: int
    xs: np.ndarray
    ys: np.ndarray

    def boundary(self, values: np.ndarray) -> tuple[dict[str, np.ndarray], int]:
        """Exact boundary points (2, k) per constraint: Newton on the grid lines that bracket a
        sign change; and the number of brackets where bisection replaced Newton."""
        s = ca.SX.sym("s")
        p0 = ca.SX.sym("p0", N_ERROR + 1)
        d = ca.SX.sym("d", N_ERROR + 1)
        point = p0 + s * d
        hs = self.fn(point[:N_ERROR], point[N_ERROR])
        boundary: dict[str, list] = {name: [] for name in CONSTRAINT_NAMES}
        failures = 0
        for j, name in enumerate(CONSTRAINT_NAMES):
            if not ca.depends_on(hs[j], s):
                # a constraint switched off (no stoppers, no travel limit) is a positive constant:
                # no boundary, and a rootfinder on it cannot be built (structurally singular)
                continue
            g = ca.Function("g", [s, ca.vertcat(p0, d)], [hs[j]])
            opts = {"abstol": 1e-12, "max_iter": 50, "error_on_fail": False}
            solver = ca.rootfinder("root", "newton", g, opts)
            for direction in (0, 1):  # 0: along y (columns), 1: along x (rows)
                failures += self._line_roots(j, values[j], direction, g, solver, boundary[name])
        bnd = {k: (np.array(v).T if v else np.zeros((2, 0))) for k, v in boundary.items()}
        return bnd, failures

    def _line_roots(self, j: int, vj: np.ndarray, direction: int, g, solver, found: list) -> int:
        """Roots of constraint j on every grid line of one direction that brackets a sign change,
        appended to ``found`` as slice coordinates where the other constraints hold; returns the
        number of brackets where Newton did not converge or left the bracket (bisection was used)."""
        lines = vj.T if direction == 0 else vj
        grid = self.ys if direction == 0 else self.xs
        other = self.xs if direction == 0 else self.ys
        sign = np.signbit(lines)
        idx_line, idx_k = np.nonzero(sign[:, :-1] != sign[:, 1:])
        failures = 0
        for li, k in zip(idx_line, idx_k, strict=True):
            a_val, b_val = lines[li, k], lines[li, k + 1]
            lo, hi = grid[k], grid[k + 1]
            start = lo + (hi - lo) * a_val / (a_val - b_val)
            p = self.base.copy()
            dvec = np.zeros(N_ERROR + 1)
            if direction == 0:
                p[self.ix] += other[li]
                dvec[self.iy] = 1.0
            else:
                p[self.iy] += other[li]
                dvec[self.ix] = 1.0
            par = np.concatenate([p, dvec])
            root = float(solver(start, par))
            converged = bool(solver.stats().get("success", True))  # error_on_fail off: it says so here
            if not (converged and np.isfinite(root) and lo - 1e-12 <= root <= hi + 1e-12):
                failures += 1
                root = _bisect(g, lo, hi, par)
            pt = p + root * dvec
            h_all = np.asarray(self.fn(pt[:N_ERROR], pt[N_ERROR])).ravel()
            others = np.delete(h_all, j)
            if np.all(others >= -1e-9 * np.maximum(1, np.abs(others))):
                found.append((pt[self.ix] - self.base[self.ix], pt[self.iy] - self.base[self.iy]))
        return failures


def _bisect(g: ca.Function, lo: float, hi: float, par: np.ndarray, iters: int = 60) -> float:
    f_lo = float(g(lo, par))
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        f_mid = float(g(mid, par))
        if np.signbit(f_mid) == np.signbit(f_lo):
            lo, f_lo = mid, f_mid
        else:
            hi = mid
    return 0.5 * (lo + hi)
