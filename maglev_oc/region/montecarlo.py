"""Monte Carlo on the sampled twin: many closed-loop runs at once, reduced to what a region needs.

The engine's fused closed-loop step (:attr:`maglev_oc.sim.engine.ClosedLoop.step_function`, twin
and controller at 5 kHz) is extended with the running extremes a feasibility check needs, then
run over the horizon from thousands of initial conditions at once: generated as C with a C loop
over runs and samples (:class:`maglev_oc.sim.native.NativeBatch`, on threads) when a C compiler
is there, else as a CasADi Function that runs the horizon (``mapaccum``) ``map``-ped over the
starts in CasADi's virtual machine. Nothing per sample or per trajectory happens in Python.

Per trajectory it returns the least feasibility margin R/(4 L4) the controller saw (NaN for
controllers without one), the largest current-vector magnitude commanded, whether a stopper was
hit, the extreme gaps and positions, and the final twin and controller states.

A *violation* of the FL regulator's feasible set is a sample with R < 0 (the transformation
had to clip), a commanded |u| above the limit, or a stopper hit.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.errors import InputError, SolverError
from maglev_oc.model.hardware import PEAK_CURRENT_LIMIT
from maglev_oc.numerics import c_compiler
from maglev_oc.region.closed_loop import N_ERROR, Reference, RegulatorLoop
from maglev_oc.results import Result
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.native import NativeBatch
from maglev_oc.sim.twin import RigTwin

__all__ = [
    "EXTREMA_NAMES",
    "BatchOutcome",
    "BatchSimulator",
    "CertificateCheck",
    "SliceCheck",
    "check_error_states",
    "fl_batch_simulator",
    "fl_slice",
    "merge_checks",
    "reference_samples",
    "regulator_state",
    "uniform_in_ellipsoid",
]

EXTREMA_NAMES = ("min_margin", "max_current_sq", "stopper_hit", "min_gap", "max_gap", "max_abs_position")
"""The running extremes carried through a horizon, in the order of the state's extra rows."""
_N_EXTREMA = len(EXTREMA_NAMES)


@dataclass(frozen=True)
class BatchOutcome(Result):
    """Outcomes of n runs (arrays of shape (n,), states (n_state, n)).

    ``success``: every run stayed finite (``status`` ``"completed"``, else ``"diverged"``);
    stopper hits and margins are judged by :meth:`violations`, which needs the current limit.
    """

    success: bool
    status: str
    message: str
    min_margin: np.ndarray  # [m/s^2], NaN without a margin diagnostic
    max_current: np.ndarray  # [A] largest |u| commanded
    stopper_hit: np.ndarray  # bool
    min_gap: np.ndarray  # [m]
    max_gap: np.ndarray
    max_abs_position: np.ndarray  # [m]
    final_twin: np.ndarray  # (n_twin, n)
    final_controller: np.ndarray  # (n_ctrl, n)
    finite: np.ndarray  # bool
    timings: Mapping[str, float]  # [s] {"total": ...}

    @property
    def n(self) -> int:
        """Number of runs."""
        return self.min_margin.size

    @classmethod
    def of(cls, timings: Mapping[str, float], **arrays: np.ndarray) -> BatchOutcome:
        """The outcome of the runs in ``arrays`` (the fields), with its verdict."""
        finite, hit = arrays["finite"], arrays["stopper_hit"]
        n = int(finite.size)
        diverged = int(np.sum(~finite))
        message = f"{n} runs: {diverged} diverged, {int(np.sum(hit))} hit a stopper"
        status = "completed" if diverged == 0 else "diverged"
        return cls(diverged == 0, status, message, timings=dict(timings), **arrays)

    def violations(self, current_limit: float | None) -> np.ndarray:
        """Runs that left the feasible set F (R < 0, |u| > limit, stopper) or diverged.

        Parameters
        ----------
        current_limit : float or None
            |u| limit [A] (None: no current constraint).

        Returns
        -------
        (n,) bool array
        """
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
        Generate the step as C and run it in a C loop (falls back to CasADi's virtual machine
        when there is no C compiler or compilation fails; ``compiled`` tells which).
    """

    def __init__(self, twin: RigTwin, controller, *, duration: float, threads: int = 2, compile: bool = True):
        if not (duration > 0 and math.isfinite(duration)):
            raise InputError(f"duration must be positive [s], got {duration!r}")
        if threads < 1:
            raise InputError(f"threads must be >= 1, got {threads!r}")
        self.twin = twin
        self.controller = controller
        self.loop = ClosedLoop(twin, controller)
        self.n_steps = round(duration / twin.sample_time)
        self.threads = int(threads)
        self._nz = twin.n_state + controller.n_state
        self._step = self._accumulating_step()
        self._native = None
        if compile and c_compiler() is not None:
            try:
                self._native = NativeBatch(self._step)
            except SolverError:
                self._native = None
        self.compiled = self._native is not None
        self._fn: ca.Function | None = None
        self._maps: dict[int, ca.Function] = {}

    def with_duration(self, duration: float) -> BatchSimulator:
        """The same twin and controller over another horizon [s], sharing what was built."""
        if not (duration > 0 and math.isfinite(duration)):
            raise InputError(f"duration must be positive [s], got {duration!r}")
        other = copy.copy(self)
        other.n_steps = round(duration / self.twin.sample_time)
        other._fn, other._maps = None, {}
        return other

    def _horizon_map(self, n: int) -> ca.Function:
        """The virtual machine's horizon Function mapped over n starts (built on first use)."""
        if self._fn is None:
            horizon = self._step.mapaccum("horizon", self.n_steps)
            z0 = ca.MX.sym("z0", self._nz + _N_EXTREMA)
            ref = ca.MX.sym("r", 6, self.n_steps)
            noise = ca.MX.sym("w", 2, self.n_steps)
            self._fn = ca.Function("horizon", [z0, ref, noise], [horizon(z0, ref, noise)[:, -1]])
        fmap = self._maps.get(n)
        if fmap is None:
            fmap = self._fn.map(n, "thread", self.threads) if self.threads > 1 else self._fn.map(n)
            self._maps = {n: fmap}
        return fmap

    def _accumulating_step(self) -> ca.Function:
        """The engine's fused step with the running extremes (:data:`EXTREMA_NAMES`) appended
        to the state: (z + extremes, r, w) -> z_next + extremes_next."""
        controller, nz = self.controller, self._nz
        nd = len(controller.diag_names)
        z = ca.SX.sym("z", nz + _N_EXTREMA)
        r = ca.SX.sym("r", 6)
        w = ca.SX.sym("w", 2)
        z_next, out = self.loop.step_function(z[:nz], r, w)
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
        return ca.Function("acc_step", [z, r, w], [ca.vertcat(z_next, ext_next)])

    def run(self, x0, c0, reference, noise=None, twin_states=None) -> BatchOutcome:
        """Simulate n runs over the horizon at once.

        Parameters
        ----------
        x0 : (4, n) array
            Mechanical states [m, m/s, m, m/s].
        c0 : (n_ctrl, n) array
            Controller states (e.g. :func:`regulator_state`).
        reference : (6, n_steps) or (6,) array
            The sampled reference (control.base layout), shared by all runs; (6,) is constant.
        noise : (2, n_steps) array, optional
            Encoder noise in standard deviations, shared by all runs (default zero; only twins
            with an encoder use it).
        twin_states : (n_twin_state, n) array, optional
            The twin's whole starting states (default ``twin.initial_state`` of each ``x0``): for
            twins that carry more than the mechanics, e.g. each run's plant constants.

        Returns
        -------
        BatchOutcome
        """
        t0 = time.perf_counter()
        x0 = np.asarray(x0, dtype=float)
        c0 = np.asarray(c0, dtype=float)
        if x0.ndim != 2 or x0.shape[0] != 4:
            raise InputError(f"x0 must have shape (4, n), got {x0.shape}")
        n = x0.shape[1]
        if c0.shape != (self.controller.n_state, n):
            raise InputError(f"c0 must have shape ({self.controller.n_state}, {n}), got {c0.shape}")
        ref = np.asarray(reference, dtype=float)
        if ref.ndim == 1:
            ref = np.repeat(ref.reshape(6, 1), self.n_steps, axis=1)
        if ref.shape != (6, self.n_steps):
            raise InputError(f"reference must have shape (6, {self.n_steps}) or (6,), got {ref.shape}")
        if twin_states is None:
            s0 = np.column_stack([self.twin.initial_state(x0[:, k]) for k in range(n)])
        else:
            s0 = np.asarray(twin_states, dtype=float)
            if s0.shape != (self.twin.n_state, n):
                raise InputError(f"twin_states must have shape ({self.twin.n_state}, {n}), got {s0.shape}")
        ext0 = np.tile(np.array([[np.inf], [0.0], [0.0], [np.inf], [-np.inf], [0.0]]), (1, n))
        z0 = np.vstack([s0, c0, ext0])
        w = np.zeros((2, self.n_steps)) if noise is None else np.asarray(noise, dtype=float)
        if w.shape != (2, self.n_steps):
            raise InputError(f"noise must have shape (2, {self.n_steps}), got {w.shape}")
        if self._native is not None:
            zf = self._native(z0, ref, w, threads=self.threads)
        else:
            zf = np.asarray(self._horizon_map(n)(z0, ref, w))
        ns = self.twin.n_state
        ext = zf[self._nz :]
        has_margin = "margin" in self.controller.diag_names
        return BatchOutcome.of(
            {"total": time.perf_counter() - t0},
            min_margin=ext[0] if has_margin else np.full(n, np.nan),
            max_current=np.sqrt(ext[1]),
            stopper_hit=ext[2] > 0.5,
            min_gap=ext[3],
            max_gap=ext[4],
            max_abs_position=ext[5],
            final_twin=zf[:ns],
            final_controller=zf[ns : self._nz],
            finite=np.all(np.isfinite(zf[: self._nz]), axis=0),
        )


def _concat_outcomes(outcomes: list[BatchOutcome]) -> BatchOutcome:
    """One BatchOutcome holding the runs of several (in order)."""
    cat = np.concatenate
    return BatchOutcome.of(
        {"total": sum(o.timings["total"] for o in outcomes)},
        min_margin=cat([o.min_margin for o in outcomes]),
        max_current=cat([o.max_current for o in outcomes]),
        stopper_hit=cat([o.stopper_hit for o in outcomes]),
        min_gap=cat([o.min_gap for o in outcomes]),
        max_gap=cat([o.max_gap for o in outcomes]),
        max_abs_position=cat([o.max_abs_position for o in outcomes]),
        final_twin=np.hstack([o.final_twin for o in outcomes]),
        final_controller=np.hstack([o.final_controller for o in outcomes]),
        finite=cat([o.finite for o in outcomes]),
    )


# ----------------------------------------------------------------------------------------------
def uniform_in_ellipsoid(P, level: float, n: int, rng: np.random.Generator, dims=None) -> np.ndarray:
    """n points uniform in {z' P z <= level} restricted to the coordinates ``dims`` (others zero):
    uniform in that slice's ellipse/ellipsoid.

    Parameters
    ----------
    P : (m, m) array
        Symmetric positive definite.
    level : float
    n : int
        Number of points.
    rng : numpy.random.Generator
    dims : sequence of int, optional
        The coordinates that vary (default all).

    Returns
    -------
    (m, n) array
    """
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
    """Controller state of the output regulators for runs started at mechanical state x with
    internal-model states xi: observers at the true position and velocity (the certificate
    assumes exact velocities), internal models at xi.

    Parameters
    ----------
    x : (4, n) array
        [m, m/s, m, m/s].
    xi : (6, n) array
        (xi_v, xi_h) [m s^2, m s, m] per axis.

    Returns
    -------
    (10, n) array
    """
    x = np.asarray(x, dtype=float).reshape(4, -1)
    xi = np.asarray(xi, dtype=float).reshape(6, -1)
    return np.vstack([x[0], x[1], x[2], x[3], xi])


def reference_samples(reference: Reference, phase: float, n_steps: int, sample_time: float) -> np.ndarray:
    """The reference on the sample grid, starting at phase phi (exosystem, no ramp).

    Parameters
    ----------
    reference : Reference
    phase : float
        [rad] at the first sample.
    n_steps : int
    sample_time : float
        [s].

    Returns
    -------
    (6, n_steps) array
        (r_v, r_v', r_v'', r_h, r_h', r_h'') [m, m/s, m/s^2].
    """
    phases = phase + reference.omega * sample_time * np.arange(n_steps)
    return reference.signals(phases)


@dataclass(frozen=True)
class CertificateCheck(Result):
    """Runs of the sampled twin started inside (or outside) a certified set {z~' P z~ <= level}.

    ``violations`` counts runs that left F (R < 0, |u| above the limit, a stopper); for runs
    started inside, it must be zero: ``success`` is ``violations == 0`` (``status``
    ``"no_violations"``, else ``"violations"``). ``final_ratio`` = V(end)/level per run: below 1
    means the run is back inside the certified set when the horizon ends.
    """

    success: bool
    status: str
    message: str
    reference: Reference
    level: float
    n: int
    violations: int
    violating: np.ndarray  # bool (n,)
    start_ratio: np.ndarray  # V(start)/level (n,)
    final_ratio: np.ndarray  # V(end)/level (n,)
    min_margin: float  # [m/s^2] over all runs
    max_current: float  # [A] over all runs
    outcome: BatchOutcome = field(repr=False)
    timings: Mapping[str, float] = field(default_factory=dict)  # [s] {"total": ...}

    @classmethod
    def of(cls, timings: Mapping[str, float], **fields) -> CertificateCheck:
        """The check of the runs described by ``fields``, with its verdict."""
        n, bad = fields["n"], fields["violations"]
        message = (
            f"{n} runs at level {fields['level']:.4g}: {bad} left F; least margin "
            f"{fields['min_margin']:.4g} m/s^2, largest |u| {fields['max_current']:.4g} A"
        )
        status = "no_violations" if bad == 0 else "violations"
        return cls(bad == 0, status, message, timings=dict(timings), **fields)


def fl_batch_simulator(
    model, *, compensation: ca.Function | None = None, duration: float, compile: bool = True
) -> BatchSimulator:
    """The FL regulator on the twin of ``model`` whose plant is what a certificate assumes: the
    model itself, plus the effect ``compensation`` (x (4) -> (x2', x4') [m/s^2]) when the
    regulator compensates one (:class:`~maglev_oc.region.feasibility.FeasibleSet`'s premise).

    Parameters
    ----------
    model : StageModel
    compensation : casadi.Function, optional
    duration : float
        Horizon [s].
    compile : bool
        See :class:`BatchSimulator`.

    Returns
    -------
    BatchSimulator
    """
    from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
    from maglev_oc.sim.effects import TwinEffects

    twin = RigTwin(model)
    if compensation is not None:
        x, i = ca.SX.sym("x", 4), ca.SX.sym("i", 2)
        extra = ca.Function("effects", [x, i], [compensation(x)], ["x", "i"], ["acc"])
        twin = RigTwin(model, TwinEffects(extra=extra))
    controller = FeedbackLinearizingRegulator(model, compensation=compensation)
    return BatchSimulator(twin, controller, duration=duration, compile=compile)


def check_error_states(
    sim: BatchSimulator,
    loop: RegulatorLoop,
    reference: Reference,
    P,
    level: float,
    ztilde,
    *,
    phase: float = 0.0,
    current_limit: float | None = PEAK_CURRENT_LIMIT,
) -> CertificateCheck:
    """Run the FL loop from error states z~ and judge the runs against F (module docstring).

    Parameters
    ----------
    sim : BatchSimulator
        The FL regulator on the twin.
    loop : RegulatorLoop
        The loop in error coordinates (maps z~ to physical states).
    reference : Reference
    P : (10, 10) array
        The certificate's matrix.
    level : float
        Its level c (ratios are V / c).
    ztilde : (10, n) array
        Starting error states [SI, see ``closed_loop.ERROR_STATE_UNITS``].
    phase : float
        Reference phase at the start [rad].
    current_limit : float or None
        |u| limit [A] of F (None: no current constraint).

    Returns
    -------
    CertificateCheck
    """
    t0 = time.perf_counter()
    P = np.asarray(P, dtype=float)
    zt = np.asarray(ztilde, dtype=float).reshape(N_ERROR, -1)
    x, xi = loop.physical_state(zt, reference, phase)
    ref = reference_samples(reference, phase, sim.n_steps, sim.twin.sample_time)
    out = sim.run(x, regulator_state(x, xi), ref)
    bad = out.violations(current_limit)
    end_phase = phase + reference.omega * sim.twin.sample_time * sim.n_steps
    z_end = loop.error_state(out.final_twin[:4], out.final_controller[4:10], reference, end_phase)
    v_start = np.einsum("in,ij,jn->n", zt, P, zt) / level
    v_end = np.einsum("in,ij,jn->n", z_end, P, z_end) / level
    return CertificateCheck.of(
        {"total": time.perf_counter() - t0},
        reference=reference,
        level=level,
        n=zt.shape[1],
        violations=int(bad.sum()),
        violating=bad,
        start_ratio=v_start,
        final_ratio=np.where(out.finite, v_end, np.inf),
        min_margin=float(np.nanmin(out.min_margin)) if np.any(np.isfinite(out.min_margin)) else math.nan,
        max_current=float(np.nanmax(out.max_current)),
        outcome=out,
    )


def merge_checks(checks: list[CertificateCheck]) -> CertificateCheck:
    """One CertificateCheck holding the runs of several of the same certificate (in order).

    Parameters
    ----------
    checks : list of CertificateCheck
        Runs of one certificate (e.g. one group per reference phase).

    Returns
    -------
    CertificateCheck
    """
    if len(checks) == 1:
        return checks[0]
    first = checks[0]
    cat = np.concatenate
    return CertificateCheck.of(
        {"total": sum(c.timings["total"] for c in checks)},
        reference=first.reference,
        level=first.level,
        n=sum(c.n for c in checks),
        violations=sum(c.violations for c in checks),
        violating=cat([c.violating for c in checks]),
        start_ratio=cat([c.start_ratio for c in checks]),
        final_ratio=cat([c.final_ratio for c in checks]),
        min_margin=min(c.min_margin for c in checks),
        max_current=max(c.max_current for c in checks),
        outcome=_concat_outcomes([c.outcome for c in checks]),
    )


def _slice_verdict(unsafe_certified: int, coverage: float) -> tuple[bool, str, str]:
    message = (
        f"certificate covers {coverage:.1%} of the safe starts; {unsafe_certified} certified starts unsafe"
    )
    return unsafe_certified == 0, "sound" if unsafe_certified == 0 else "unsound", message


@dataclass(frozen=True)
class SliceCheck(Result):
    """A 2-D grid of starts on a slice, each labelled safe (empirically) and certified.

    For the FL regulator *safe* means the run never left F. The *conservativeness* figure is the
    share of the safe starts that the certificate covers, |certified and safe| / |safe|;
    ``unsafe_certified`` (certified but not safe) must be 0: ``success`` says so (``status``
    ``"sound"``, else ``"unsound"``).
    """

    success: bool
    status: str
    message: str
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
    starts: np.ndarray = field(repr=False)  # (10, ny * nx) error states z~ of the grid
    timings: Mapping[str, float] = field(default_factory=dict)  # [s] {"total": ...}

    @property
    def n(self) -> int:
        """Number of starts."""
        return self.safe.size

    def with_certificate(self, P, level: float, offset=None) -> SliceCheck:
        """The same runs judged against another certified set {(z - offset)' P (z - offset) <= level}.

        Parameters
        ----------
        P : (10, 10) array
        level : float
        offset : (10,) array, optional
            Centre of the set in the grid's error coordinates (default 0).

        Returns
        -------
        SliceCheck
        """
        z = self.starts - (0.0 if offset is None else np.asarray(offset, dtype=float)[:, None])
        cert = (np.einsum("in,ij,jn->n", z, np.asarray(P, float), z) <= level).reshape(self.safe.shape)
        unsafe = int(np.sum(cert & ~self.safe))
        coverage = float(np.sum(cert & self.safe) / max(np.sum(self.safe), 1))
        success, status, message = _slice_verdict(unsafe, coverage)
        return dataclasses.replace(
            self,
            success=success,
            status=status,
            message=message,
            certified=cert,
            unsafe_certified=unsafe,
            coverage=coverage,
        )


_SLICE_INDEX = {"e1": 0, "e1_rate": 1, "e2": 5, "e2_rate": 6}


def _grid(axes, x_range, y_range, n):
    for a in axes:
        if a not in _SLICE_INDEX:
            raise InputError(f"slice axes must be among {list(_SLICE_INDEX)}, got {a!r}")
    xs = np.linspace(*x_range, n)
    ys = np.linspace(*y_range, n)
    X, Y = np.meshgrid(xs, ys)
    z = np.zeros((N_ERROR, X.size))
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
    current_limit: float | None = PEAK_CURRENT_LIMIT,
) -> SliceCheck:
    """FL regulator on a slice of error states (deviations from the steady state at phase 0).

    Parameters
    ----------
    sim : BatchSimulator
        The FL regulator on the twin.
    loop : RegulatorLoop
    reference : Reference
    P : (10, 10) array
        The certificate judged against (V = z~' P z~).
    level : float
        Its level.
    axes : (str, str)
        Slice coordinates among e1 [m], e1_rate [m/s], e2 [m], e2_rate [m/s].
    x_range, y_range : (float, float)
        Their ranges, SI units.
    n : int
        Grid points per axis.
    current_limit : float or None
        |u| limit [A] of F.

    Returns
    -------
    SliceCheck
    """
    t0 = time.perf_counter()
    xs, ys, z = _grid(axes, x_range, y_range, n)
    chk = check_error_states(sim, loop, reference, P, level, z, current_limit=current_limit)
    shape = (ys.size, xs.size)
    safe = ~chk.violating.reshape(shape)
    cert = (chk.start_ratio <= 1.0).reshape(shape)
    unsafe = int(np.sum(cert & ~safe))
    coverage = float(np.sum(cert & safe) / max(np.sum(safe), 1))
    success, status, message = _slice_verdict(unsafe, coverage)
    return SliceCheck(
        success,
        status,
        message,
        sim.controller.name,
        reference,
        tuple(axes),
        xs,
        ys,
        safe,
        cert,
        unsafe,
        coverage,
        chk.outcome.min_gap.reshape(shape),
        chk.outcome.max_current.reshape(shape),
        z,
        {"total": time.perf_counter() - t0},
    )
