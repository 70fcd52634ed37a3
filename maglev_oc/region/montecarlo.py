"""Monte Carlo on the sampled twin: many closed-loop runs at once, reduced to what a region needs.

The engine's fused closed-loop step (:attr:`maglev_oc.sim.engine.ClosedLoop.step_function`, twin
and controller at 5 kHz) is wrapped into one CasADi Function that runs a whole horizon
(``mapaccum``) while carrying the running extremes a feasibility check needs, and that Function
is ``map``-ped over thousands of initial conditions (threads, optionally JIT-compiled). Nothing
per sample or per trajectory happens in Python.

Per trajectory it returns the least feasibility margin R/(4 L4) the controller saw (NaN for
controllers without one), the largest current-vector magnitude commanded, whether a stopper was
hit, the extreme gaps and positions, and the final twin and controller states.

A *violation* of the FL regulator's feasible set is a sample with R < 0 (the transformation
had to clip), a commanded |u| above the limit, or a stopper hit.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.twin import RigTwin

N_EXTREMA = 6
EXTREMA_NAMES = ("min_margin", "max_current_sq", "stopper_hit", "min_gap", "max_gap", "max_abs_position")


@dataclass(frozen=True)
class BatchOutcome:
    """Outcomes of n runs (arrays of shape (n,), states (n_state, n))."""

    min_margin: np.ndarray  # [m/s^2], NaN without a margin diagnostic
    max_current: np.ndarray  # [A] largest |u| commanded
    stopper_hit: np.ndarray  # bool
    min_gap: np.ndarray  # [m]
    max_gap: np.ndarray
    max_abs_position: np.ndarray  # [m]
    final_twin: np.ndarray  # (n_twin, n)
    final_controller: np.ndarray  # (n_ctrl, n)
    finite: np.ndarray  # bool
    wall_time: float

    @property
    def n(self) -> int:
        return self.min_margin.size

    def violations(self, current_limit: float | None) -> np.ndarray:
        """Runs that left the feasible set F (R < 0, |u| > limit, stopper) or diverged."""
        bad = ~self.finite | self.stopper_hit
        with np.errstate(invalid="ignore"):
            bad |= self.min_margin < 0
            if current_limit is not None:
                bad |= self.max_current > current_limit * (1 + 1e-9)
        return bad


class BatchSimulator:
    """Runs a controller on a twin from many initial states over a fixed horizon.

    Parameters
    ----------
    twin : RigTwin
    controller : ExpressionController
    duration : float
        Horizon [s].
    threads : int
        Parallel evaluations of the mapped Function.
    compile : bool
        JIT-compile the horizon Function with the system C compiler (falls back to CasADi's
        virtual machine if compilation fails; ``compiled`` tells which).
    """

    def __init__(self, twin: RigTwin, controller, *, duration: float, threads: int = 2, compile: bool = True):
        if not (duration > 0 and math.isfinite(duration)):
            raise ValueError(f"duration must be positive [s], got {duration!r}")
        if threads < 1:
            raise ValueError(f"threads must be >= 1, got {threads!r}")
        t0 = time.perf_counter()
        self.twin = twin
        self.controller = controller
        self.loop = ClosedLoop(twin, controller)
        self.n_steps = round(duration / twin.sample_time)
        self.threads = int(threads)
        step = self.loop.step_function
        ns, nc = twin.n_state, controller.n_state
        nz = ns + nc
        nd = len(controller.diag_names)
        z = ca.SX.sym("z", nz + N_EXTREMA)
        r = ca.SX.sym("r", 6)
        w = ca.SX.sym("w", 2)
        z_next, out = step(z[:nz], r, w)
        u = out[2:4]
        margin = (
            out[4 + controller.diag_names.index("margin")] if "margin" in controller.diag_names else ca.inf
        )
        flags = out[4 + nd : 7 + nd]
        ext = z[nz:]
        x1, x3 = z_next[0], z_next[2]
        ext_next = ca.vertcat(
            ca.fmin(ext[0], margin),
            ca.fmax(ext[1], ca.sumsqr(u)),
            ca.fmax(ext[2], flags[1]),
            ca.fmin(ext[3], x1),
            ca.fmax(ext[4], x1),
            ca.fmax(ext[5], ca.fabs(x3)),
        )
        acc = ca.Function("acc_step", [z, r, w], [ca.vertcat(z_next, ext_next)])
        horizon = acc.mapaccum("horizon", self.n_steps)
        z0 = ca.MX.sym("z0", nz + N_EXTREMA)
        ref = ca.MX.sym("r", 6, self.n_steps)
        noise = ca.MX.sym("w", 2, self.n_steps)
        zs = horizon(z0, ref, noise)
        self.compiled = False
        fn = None
        if compile:
            try:
                fn = ca.Function(
                    "horizon_jit",
                    [z0, ref, noise],
                    [zs[:, -1]],
                    {"jit": True, "compiler": "shell", "jit_options": {"flags": ["-O3"]}},
                )
                self.compiled = True
            except RuntimeError:
                fn = None
        if fn is None:
            fn = ca.Function("horizon", [z0, ref, noise], [zs[:, -1]])
        self._fn = fn
        self._nz = nz
        self._maps: dict[int, ca.Function] = {}
        self.build_time = time.perf_counter() - t0

    def run(self, x0, c0, reference, noise=None) -> BatchOutcome:
        """Simulate from mechanical states ``x0`` (4, n) and controller states ``c0`` (n_ctrl, n)
        with the sampled ``reference`` (6, n_steps) shared by all runs (or (6,) constant) and the
        encoder noise ``noise`` (2, n_steps) in standard deviations, shared by all runs (default
        zero; only twins with an encoder use it)."""
        t0 = time.perf_counter()
        x0 = np.asarray(x0, dtype=float)
        c0 = np.asarray(c0, dtype=float)
        if x0.ndim != 2 or x0.shape[0] != 4:
            raise ValueError(f"x0 must have shape (4, n), got {x0.shape}")
        n = x0.shape[1]
        if c0.shape != (self.controller.n_state, n):
            raise ValueError(f"c0 must have shape ({self.controller.n_state}, {n}), got {c0.shape}")
        ref = np.asarray(reference, dtype=float)
        if ref.ndim == 1:
            ref = np.repeat(ref.reshape(6, 1), self.n_steps, axis=1)
        if ref.shape != (6, self.n_steps):
            raise ValueError(f"reference must have shape (6, {self.n_steps}) or (6,), got {ref.shape}")
        s0 = np.column_stack([self.twin.initial_state(x0[:, k]) for k in range(n)])
        ext0 = np.tile(np.array([[np.inf], [0.0], [0.0], [np.inf], [-np.inf], [0.0]]), (1, n))
        z0 = np.vstack([s0, c0, ext0])
        fmap = self._maps.get(n)
        if fmap is None:
            fmap = self._fn.map(n, "thread", self.threads) if self.threads > 1 else self._fn.map(n)
            self._maps = {n: fmap}
        w = np.zeros((2, self.n_steps)) if noise is None else np.asarray(noise, dtype=float)
        if w.shape != (2, self.n_steps):
            raise ValueError(f"noise must have shape (2, {self.n_steps}), got {w.shape}")
        zf = np.asarray(fmap(z0, ref, w))
        ns = self.twin.n_state
        ext = zf[self._nz :]
        has_margin = "margin" in self.controller.diag_names
        return BatchOutcome(
            min_margin=ext[0] if has_margin else np.full(n, np.nan),
            max_current=np.sqrt(ext[1]),
            stopper_hit=ext[2] > 0.5,
            min_gap=ext[3],
            max_gap=ext[4],
            max_abs_position=ext[5],
            final_twin=zf[:ns],
            final_controller=zf[ns : self._nz],
            finite=np.all(np.isfinite(zf[: self._nz]), axis=0),
            wall_time=time.perf_counter() - t0,
        )


def concat_outcomes(outcomes: list[BatchOutcome]) -> BatchOutcome:
    """One BatchOutcome holding the runs of several (in order)."""
    cat = np.concatenate
    return BatchOutcome(
        min_margin=cat([o.min_margin for o in outcomes]),
        max_current=cat([o.max_current for o in outcomes]),
        stopper_hit=cat([o.stopper_hit for o in outcomes]),
        min_gap=cat([o.min_gap for o in outcomes]),
        max_gap=cat([o.max_gap for o in outcomes]),
        max_abs_position=cat([o.max_abs_position for o in outcomes]),
        final_twin=np.hstack([o.final_twin for o in outcomes]),
        final_controller=np.hstack([o.final_controller for o in outcomes]),
        finite=cat([o.finite for o in outcomes]),
        wall_time=sum(o.wall_time for o in outcomes),
    )


# ----------------------------------------------------------------------------------------------
def uniform_in_ellipsoid(P, level: float, n: int, rng: np.random.Generator, dims=None) -> np.ndarray:
    """n points (10, n) uniform in {z' P z <= level} restricted to the coordinates ``dims``
    (others zero): uniform in that slice's ellipse/ellipsoid."""
    P = np.asarray(P, dtype=float)
    dims = list(range(P.shape[0])) if dims is None else list(dims)
    Ps = P[np.ix_(dims, dims)]
    k = len(dims)
    g = rng.standard_normal((k, n))
    g /= np.linalg.norm(g, axis=0, keepdims=True)
    radius = rng.uniform(0, 1, n) ** (1.0 / k)
    L = np.linalg.cholesky(Ps)  # Ps = L L'; z = sqrt(level) L'^-1 u
    pts = math.sqrt(level) * np.linalg.solve(L.T, g * radius)
    out = np.zeros((P.shape[0], n))
    out[dims] = pts
    return out


# ----------------------------------------------------------------------------------------------
def regulator_state(x, xi) -> np.ndarray:
    """Controller state of the output regulators (10, n) for runs started at mechanical state x
    (4, n) with internal-model states xi (6, n): observers at the true position and velocity
    (the certificate assumes exact velocities), internal models at xi."""
    x = np.asarray(x, dtype=float).reshape(4, -1)
    xi = np.asarray(xi, dtype=float).reshape(6, -1)
    return np.vstack([x[0], x[1], x[2], x[3], xi])


def reference_samples(reference: Reference, phase: float, n_steps: int, sample_time: float) -> np.ndarray:
    """The reference (6, n_steps) on the sample grid, starting at phase phi (exosystem, no ramp)."""
    phases = phase + reference.omega * sample_time * np.arange(n_steps)
    return reference.signals(phases)


@dataclass(frozen=True)
class CertificateCheck:
    """Runs of the sampled twin started inside (or outside) a certified set {z~' P z~ <= level}.

    ``violations`` counts runs that left F (R < 0, |u| above the limit, a stopper); for runs
    started inside, it must be zero. ``final_ratio`` = V(end)/level per run: below 1 means the
    run is back inside the certified set when the horizon ends.
    """

    reference: Reference
    level: float
    n: int
    violations: int
    violating: np.ndarray  # bool (n,)
    start_ratio: np.ndarray  # V(start)/level (n,)
    final_ratio: np.ndarray  # V(end)/level (n,)
    min_margin: float  # [m/s^2] over all runs
    max_current: float  # [A] over all runs
    outcome: BatchOutcome
    wall_time: float


def check_error_states(
    sim: BatchSimulator,
    loop: RegulatorLoop,
    reference: Reference,
    P,
    level: float,
    ztilde,
    *,
    phase: float = 0.0,
    current_limit: float | None = 9.0,
) -> CertificateCheck:
    """Run the FL loop from error states z~ (10, n) at reference phase phi (module docstring)."""
    t0 = time.perf_counter()
    P = np.asarray(P, dtype=float)
    zt = np.asarray(ztilde, dtype=float).reshape(10, -1)
    x, xi = loop.physical_state(zt, reference, phase)
    ref = reference_samples(reference, phase, sim.n_steps, sim.twin.sample_time)
    out = sim.run(x, regulator_state(x, xi), ref)
    bad = out.violations(current_limit)
    end_phase = phase + reference.omega * sim.twin.sample_time * sim.n_steps
    z_end = loop.error_state(out.final_twin[:4], out.final_controller[4:10], reference, end_phase)
    v_start = np.einsum("in,ij,jn->n", zt, P, zt) / level
    v_end = np.einsum("in,ij,jn->n", z_end, P, z_end) / level
    return CertificateCheck(
        reference,
        level,
        zt.shape[1],
        int(bad.sum()),
        bad,
        v_start,
        np.where(out.finite, v_end, np.inf),
        float(np.nanmin(out.min_margin)) if np.any(np.isfinite(out.min_margin)) else math.nan,
        float(np.nanmax(out.max_current)),
        out,
        time.perf_counter() - t0,
    )


@dataclass(frozen=True)
class SliceCheck:
    """A 2-D grid of starts on a slice, each labelled safe (empirically) and certified.

    For the FL regulator *safe* means the run never left F; for a linear regulator it means
    the run converged (|e| below ``tolerance`` at the end) without hitting a stopper. The
    *conservativeness* figure is the share of the safe starts that the certificate covers,
    |certified and safe| / |safe|; ``unsafe_certified`` (certified but not safe) must be 0.
    """

    controller: str
    reference: Reference
    axes: tuple[str, str]
    x: np.ndarray  # (nx,) slice coordinate [SI]
    y: np.ndarray  # (ny,)
    safe: np.ndarray  # (ny, nx) bool
    certified: np.ndarray  # (ny, nx) bool
    unsafe_certified: int
    coverage: float  # |certified & safe| / |safe|
    min_gap: np.ndarray  # (ny, nx) [m]
    max_current: np.ndarray  # (ny, nx) [A]
    starts: np.ndarray  # (10, ny * nx) error states of the grid (z~ or z - z_eq before offsets)
    wall_time: float

    @property
    def n(self) -> int:
        return self.safe.size

    def with_certificate(self, P, level: float, offset=None) -> SliceCheck:
        """The same runs judged against another certified set {(z - offset)' P (z - offset) <= level}."""
        z = self.starts - (0.0 if offset is None else np.asarray(offset, dtype=float)[:, None])
        cert = (np.einsum("in,ij,jn->n", z, np.asarray(P, float), z) <= level).reshape(self.safe.shape)
        return dataclasses.replace(
            self,
            certified=cert,
            unsafe_certified=int(np.sum(cert & ~self.safe)),
            coverage=float(np.sum(cert & self.safe) / max(np.sum(self.safe), 1)),
        )


_SLICE_INDEX = {"e1": 0, "e1_rate": 1, "e2": 5, "e2_rate": 6}


def _grid(axes, x_range, y_range, n):
    for a in axes:
        if a not in _SLICE_INDEX:
            raise ValueError(f"slice axes must be among {list(_SLICE_INDEX)}, got {a!r}")
    xs = np.linspace(*x_range, n)
    ys = np.linspace(*y_range, n)
    X, Y = np.meshgrid(xs, ys)
    z = np.zeros((10, X.size))
    z[_SLICE_INDEX[axes[0]]] = X.ravel()
    z[_SLICE_INDEX[axes[1]]] = Y.ravel()
    return xs, ys, z


def fl_slice(
    sim: BatchSimulator,
    loop: RegulatorLoop,
    reference: Reference,
    P,
    level: float,
    axes: tuple[str, str],
    x_range,
    y_range,
    *,
    n: int = 41,
    current_limit: float | None = 9.0,
) -> SliceCheck:
    """FL regulator on a slice of error states (deviations from the steady state at phase 0)."""
    t0 = time.perf_counter()
    xs, ys, z = _grid(axes, x_range, y_range, n)
    chk = check_error_states(sim, loop, reference, P, level, z, current_limit=current_limit)
    shape = (ys.size, xs.size)
    safe = ~chk.violating.reshape(shape)
    cert = (chk.start_ratio <= 1.0).reshape(shape)
    return SliceCheck(
        sim.controller.name,
        reference,
        tuple(axes),
        xs,
        ys,
        safe,
        cert,
        int(np.sum(cert & ~safe)),
        float(np.sum(cert & safe) / max(np.sum(safe), 1)),
        chk.outcome.min_gap.reshape(shape),
        chk.outcome.max_current.reshape(shape),
        z,
        time.perf_counter() - t0,
    )


def linear_slice(
    sim: BatchSimulator,
    reference: Reference,
    axes: tuple[str, str],
    x_range,
    y_range,
    *,
    n: int = 41,
    roa=None,
    z_eq=None,
    tolerance: float = 1e-4,
) -> SliceCheck:
    """A linear regulator (or any output regulator) started at rest with empty internal models
    on a slice of initial errors; safe = converged without a stopper hit (a *sampled estimate*
    of the region of attraction). ``roa`` (a RoaResult) marks the certified starts."""
    t0 = time.perf_counter()
    if not reference.is_setpoint:
        raise ValueError("linear_slice needs a set-point reference")
    xs, ys, z = _grid(axes, x_range, y_range, n)
    x0 = np.vstack([reference.gap + z[0], z[1], reference.position + z[5], z[6]])
    ref = np.array([reference.gap, 0, 0, reference.position, 0, 0])
    out = sim.run(x0, regulator_state(x0, np.zeros((6, x0.shape[1]))), ref)
    e1 = out.final_twin[0] - reference.gap
    e2 = out.final_twin[2] - reference.position
    with np.errstate(invalid="ignore"):
        conv = out.finite & ~out.stopper_hit & (np.abs(e1) < tolerance) & (np.abs(e2) < tolerance)
    shape = (ys.size, xs.size)
    safe = conv.reshape(shape)
    if roa is not None:
        zh = z - (roa.z_eq if z_eq is None else np.asarray(z_eq))[:, None]
        cert = (np.einsum("in,ij,jn->n", zh, roa.P, zh) <= roa.level).reshape(shape)
    else:
        cert = np.zeros(shape, dtype=bool)
    return SliceCheck(
        sim.controller.name,
        reference,
        tuple(axes),
        xs,
        ys,
        safe,
        cert,
        int(np.sum(cert & ~safe)),
        float(np.sum(cert & safe) / max(np.sum(safe), 1)),
        out.min_gap.reshape(shape),
        out.max_current.reshape(shape),
        z,
        time.perf_counter() - t0,
    )
