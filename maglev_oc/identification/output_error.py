"""Output-error fit by multiple shooting: simulated positions against the encoder readings.

The output-error estimate minimizes sum_k |y_k - h(x(t_k))|^2 over the constants, where x(t)
is the model's response to the logged currents. The stage is open-loop unstable (a vertical
pole of 33-64 1/s over 25-10 mm), so a single simulation over a 60 s log diverges within a
fraction of a second and single shooting is hopeless. Multiple shooting (Bock 1983) cuts the
log into segments of ``segment_duration`` (default 50 ms, over which the unstable mode grows
by at most e^3), gives each segment its own initial state S_j as an unknown, and asks for
continuity, F(S_j, theta) = S_{j+1}, as equality constraints:

    min_{theta, S}  sum_j sum_{k in segment j} |y_k - h(x_j(t_k; S_j, theta))|^2 / sigma^2
    s.t.            x_j(t_{j+1}; S_j, theta) = S_{j+1}

solved by a constrained Gauss-Newton method: each iteration solves the sparse KKT system of
the linearized problem (scipy's SuperLU), with a line search on the l1 merit function. The
segment simulations and their exact Jacobians come from one CasADi Function (RK4 per sample,
the logged currents interpolated linearly between samples) mapped over the segments.

Why windows: the log holds 1 kHz samples of the 5 kHz current commands, which the amplifiers
follow with a lag; the difference acts as process noise that a simulation integrates twice.
Continuity over the whole log makes the horizontal residual grow (twin, 10 s log: 3.4 um RMS
with 50 ms segments and no continuity, 4.6 um with 0.2 s windows, 12 um with 1 s, 37 um with
3 s) and biases C2..C4 (C4 by +4 % with 1 s windows, +130 % with 3 s). So continuity joins the
segments within windows of ``window_duration`` (default 0.2 s, four segments) and the windows
are independent. Within 0.2 s the unstable vertical mode still grows e^8-e^13, which is why
each window needs the multiple shooting.

Starting point: the constants from the equation-error fit (run first unless ``initial`` is
given), node states from the Savitzky-Golay estimates. Standard errors: the constrained
Gauss-Newton covariance (the theta block of the inverse KKT matrix) and its long-run
(HAC) version from the per-sample influence, as for the equation-error fit.

Output map: y = (x1 - gap_offset, x3), so the estimated ``gap_offset`` is the true gap minus
the reading, as in the equation-error fit.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from maglev_oc.data.logs import Log
from maglev_oc.errors import InputError
from maglev_oc.estimation.differentiate import SavitzkyGolay, differentiate_log
from maglev_oc.identification.constrained_gn import (
    GaussNewtonOutcome,
    constrained_gauss_newton,
    constrained_inverse_rows,
)
from maglev_oc.identification.equation_error import fit_equation_error
from maglev_oc.identification.layout import CONSTANT_NAMES, GAP_OFFSET, ParameterLayout
from maglev_oc.identification.result import FitResult
from maglev_oc.model.hardware import ENCODER_RESOLUTION
from maglev_oc.model.stage import StageModel
from maglev_oc.numerics import rk4_step
from maglev_oc.regression.covariance import DEFAULT_BAND, correlation_from, long_run_covariance
from maglev_oc.regression.data import as_log_list, delayed_inputs
from maglev_oc.regression.payload import factors, loaded
from maglev_oc.regression.terms import AccelerationTerm
from maglev_oc.results import AXES

__all__ = [
    "DEFAULT_SEGMENT",
    "DEFAULT_WINDOW",
    "OUTPUT_SCALE",
    "STATE_SCALE",
    "MultipleShooting",
    "fit_output_error",
    "simulate_open_loop",
]

DEFAULT_SEGMENT = 0.05
"""[s] Shooting segment: the fastest open-loop pole (64 1/s at 10 mm) grows e^3.2-fold over it."""
DEFAULT_WINDOW = 0.2
"""[s] Continuity joins the segments within windows of this length; windows are independent."""
OUTPUT_SCALE = ENCODER_RESOLUTION
"""[m] Residuals are scaled by one encoder count (conditioning only)."""
STATE_SCALE = np.array([1e-3, 1e-2, 1e-2, 1e-1])
"""Typical state magnitudes [m, m/s, m, m/s] (conditioning only)."""


@dataclass(frozen=True, eq=False)
class _Segments:
    """One log cut into J segments of M samples."""

    source: str
    n: int  # samples in the log
    M: int
    J: int
    y: np.ndarray  # (2, J*M) readings at the residual samples (gap, horizontal)
    u: np.ndarray  # (2, J*(M+1)) currents at each segment's M+1 points
    nodes0: np.ndarray  # (4, J) initial node states (true gap)
    links: np.ndarray  # indices j whose end is joined to segment j + 1 (same window)
    load: np.ndarray  # (2, 1) M / (M + m) of the log's payload m (ones: none declared)


class MultipleShooting:
    """An output-error problem prepared once (segments, CasADi functions); :meth:`fit` solves it.

    Parameters
    ----------
    logs : Log or sequence of Log
    model : StageModel
    estimate : sequence of str
        Among ``C1, C2, C3, C4, gap_offset``.
    terms : sequence of AccelerationTerm
    segment_duration : float
        [s] Shooting segment length (default 0.05 s).
    input_delay : float
        [s] Delay applied to the logged currents (see :mod:`.equation_error`).
    """

    def __init__(
        self,
        logs: Log | Sequence[Log],
        model: StageModel,
        *,
        estimate: Sequence[str] = CONSTANT_NAMES,
        terms: Sequence[AccelerationTerm] = (),
        segment_duration: float = DEFAULT_SEGMENT,
        window_duration: float = DEFAULT_WINDOW,
        input_delay: float = 0.0,
    ) -> None:
        t0 = time.perf_counter()
        self.logs = as_log_list(logs)
        self.model = model
        self.estimate = tuple(estimate)
        self.terms = tuple(terms)
        self.layout = ParameterLayout(model, self.estimate, self.terms)
        if not (math.isfinite(segment_duration) and segment_duration > 0):
            raise InputError(f"segment_duration must be positive [s], got {segment_duration!r}")
        if not (math.isfinite(input_delay) and 0 <= input_delay < 0.01):
            raise InputError(f"input_delay must be in [0, 0.01) s, got {input_delay!r}")
        self.input_delay = float(input_delay)
        dt = self.logs[0].sample_time
        for log in self.logs[1:]:
            if abs(log.sample_time - dt) > 0.01 * dt:
                raise InputError(f"logs at different rates: {self.logs[0].source}, {log.source}")
        self.sample_time = dt
        self.M = max(2, round(segment_duration / dt))
        self.segment_duration = self.M * dt
        if not (math.isfinite(window_duration) and window_duration >= self.segment_duration * (1 - 1e-9)):
            raise InputError(
                f"window_duration must be at least the segment ({self.segment_duration:g} s), got "
                f"{window_duration!r}"
            )
        self.window_duration = float(window_duration)
        self.segments = [self._cut(log) for log in self.logs]
        self._build()
        self.prepare_time = time.perf_counter() - t0

    # ------------------------------------------------------------------------------------
    def _cut(self, log: Log) -> _Segments:
        M = self.M
        J = (log.n - 1) // M
        if J < 2:
            raise InputError(
                f"{log.source}: {log.n} samples make {J} segment(s) of {M}; need at least 2 (a log of "
                f"{2 * M * log.sample_time:g} s or more)"
            )
        y = np.vstack([log.x[0], log.x[2]])[:, : J * M]
        u = delayed_inputs(log, self.input_delay)
        idx = (np.arange(J)[:, None] * M + np.arange(M + 1)[None, :]).ravel()
        sg = SavitzkyGolay(log.sample_time)
        der = differentiate_log(log, sg)
        x = np.vstack([der.position[0], der.velocity[0], der.position[1], der.velocity[1]])
        nodes = x[:, np.arange(J) * M]
        per_window = max(1, round(self.window_duration / (M * log.sample_time)))
        j = np.arange(J - 1)
        links = j[(j + 1) % per_window != 0]
        load = factors(self.model.params, log.payload).reshape(2, 1)
        return _Segments(log.source, log.n, M, J, y, u[:, idx], nodes, links, load)

    def _build(self) -> None:
        layout, M, h = self.layout, self.M, self.sample_time
        q = layout.n
        s0 = ca.SX.sym("s", 4)
        U = ca.SX.sym("U", 2, M + 1)
        theta = ca.SX.sym("theta", q)
        load = ca.SX.sym("load", 2)  # M / (M + m) of a log's payload m
        acc = layout.acceleration_true
        offset = theta[layout.names.index(GAP_OFFSET)] if GAP_OFFSET in layout.names else 0
        payload = any(log.payload for log in self.logs)  # (without one, the arithmetic untouched)

        def f(x, u):
            a = acc(x, u, theta)
            if payload:
                a = loaded(a, load, self.model.params.gravity)
            return ca.vertcat(x[1], a[0], x[3], a[1])

        x = s0
        ys = []
        for k in range(M):
            ys.append(ca.vertcat(x[0] - offset, x[2]))
            u0, u1 = U[:, k], U[:, k + 1]
            x = rk4_step(f, x, h, u0, args_mid=(0.5 * (u0 + u1),), args_end=(u1,))
        Y = ca.vertcat(*ys)  # (2M,) time-major, (gap, horizontal) at each sample
        z = ca.vertcat(s0, theta)
        jy = ca.jacobian(Y, z)
        jx = ca.jacobian(x, z)
        seg = ca.Function(
            "segment",
            [s0, U, theta, load],
            [Y, x, jy, jx],
            ["s", "U", "theta", "load"],
            ["Y", "s_end", "dY", "ds"],
        )
        self._segment = seg
        self._maps = {sg.J: seg.map(sg.J, "thread", 2) for sg in self.segments}

    # ------------------------------------------------------------------------------------
    def _evaluate(self, theta: np.ndarray, nodes: list[np.ndarray]):
        out = []
        for sg, S in zip(self.segments, nodes, strict=True):
            Y, s_end, dY, ds = self._maps[sg.J](S, sg.u, theta, sg.load)
            out.append((np.asarray(Y), np.asarray(s_end), np.asarray(dY), np.asarray(ds)))
        return out

    def fit(
        self,
        *,
        initial: FitResult | dict[str, float] | None = None,
        max_iterations: int = 30,
        tolerance: float = 1e-9,
        hac_band: float = DEFAULT_BAND,
    ) -> FitResult:
        """Solve by constrained Gauss-Newton from ``initial`` (default: the equation-error fit).

        Parameters
        ----------
        initial : FitResult or dict, optional
            Starting values by name. Default: an equation-error fit on the same logs.
        max_iterations : int
        tolerance : float
            Stop when the largest scaled step is below this and the constraints are met.
        hac_band : float
            [Hz] Spectral window of the long-run covariance.

        Returns
        -------
        FitResult
            ``status`` is a word of :mod:`.constrained_gn` or ``"covariance_singular"``.
        """
        t0 = time.perf_counter()
        theta, nodes, init_time = self._start(initial)
        start = theta.copy()
        th_scale = np.array(self.layout.scale)
        col_scale = np.concatenate([th_scale] + [np.tile(STATE_SCALE, sg.J) for sg in self.segments])
        gn = constrained_gauss_newton(
            self._linearize,
            self._pack(theta, nodes),
            col_scale,
            max_iterations=max_iterations,
            tolerance=tolerance,
        )
        theta, _ = self._unpack(gn.w)
        tc = time.perf_counter()
        cov, naive, hac_m, inflation, status, message = self._covariance(gn, th_scale, hac_band)
        cov_t = time.perf_counter() - tc
        residuals, rms, count = self._residual_arrays(gn.r)
        names, q = self.layout.names, self.layout.n
        chi2 = float(gn.r @ gn.r)
        dof = max(gn.r.size - (gn.Jr.shape[1] - gn.Jc.shape[0]), 1)
        success = status == "converged"
        return FitResult(
            method="output_error",
            names=names,
            values=dict(zip(names, theta, strict=True)),
            stderr=dict(zip(names, np.sqrt(np.clip(np.diag(cov), 0, None)), strict=True)),
            stderr_naive=dict(zip(names, np.sqrt(np.clip(np.diag(naive), 0, None)), strict=True)),
            initial=dict(zip(names, start, strict=True)),
            fixed=self.layout.fixed(),
            covariance=cov,
            correlation=correlation_from(cov) if success else np.full((q, q), np.nan),
            residual_rms=rms,
            residual_unit="m",
            residuals=residuals,
            n_samples=count,
            n_residuals=gn.r.size,
            chi_square=chi2,
            reduced_chi_square=chi2 / dof,
            hac_frequencies=hac_m,
            variance_inflation=dict(zip(names, inflation, strict=True)),
            success=success,
            status=status,
            message=gn.message if message is None else message,
            iterations=gn.iterations,
            timings={
                "prepare": self.prepare_time,
                "initial_fit": init_time,
                "simulate_and_linearize": gn.timings["linearize"],
                "kkt_solves": gn.timings["kkt_solves"],
                "covariance": cov_t,
                "total": time.perf_counter() - t0 + self.prepare_time,
            },
            sources=tuple(dict.fromkeys(sg.source for sg in self.segments)),  # a log cut in pieces once
            settings={
                "segment_duration_s": self.segment_duration,
                "window_duration_s": self.window_duration,
                "segments": [sg.J for sg in self.segments],
                "integrator": "RK4, one step per sample, currents linear between samples",
                "input_delay_s": self.input_delay,
                "hac_band_hz": hac_band,
                "residual_scale_m": OUTPUT_SCALE,
                "chi_square_units": "encoder counts^2 (residuals divided by 10 um)",
                "terms": [t.name for t in self.terms],
            },
        )

    # ------------------------------------------------------------------------------------
    def _start(self, initial):
        """Starting constants (an equation-error fit unless given) and node states."""
        init_time = 0.0
        if initial is None:
            ti = time.perf_counter()
            ee = fit_equation_error(self.logs, self.model, estimate=self.estimate, terms=self.terms)
            init_time = time.perf_counter() - ti
            initial = ee if ee.success else None
        if isinstance(initial, FitResult):
            initial = {k: initial.values[k] for k in self.layout.names if k in initial.values}
        theta = self.layout.initial_vector(initial)
        names = self.layout.names
        offset0 = theta[names.index(GAP_OFFSET)] if GAP_OFFSET in names else 0.0
        nodes = []
        for sg in self.segments:
            S = sg.nodes0.copy()
            S[0] += offset0
            nodes.append(S)
        return theta, nodes, init_time

    def _pack(self, theta: np.ndarray, nodes: list[np.ndarray]) -> np.ndarray:
        return np.concatenate([theta] + [S.T.ravel() for S in nodes])

    def _unpack(self, w: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
        q = self.layout.n
        nodes, k = [], q
        for sg in self.segments:
            nodes.append(w[k : k + 4 * sg.J].reshape(sg.J, 4).T.copy())
            k += 4 * sg.J
        return w[:q], nodes

    def _linearize(self, w: np.ndarray):
        """Residuals r (in encoder counts), continuity defects c (in STATE_SCALE) and their sparse
        Jacobians with respect to the scaled variables."""
        theta, nodes = self._unpack(w)
        q = self.layout.n
        rs, cs, jr, jc = [], [], ([], [], []), ([], [], [])
        r_off = c_off = 0
        var_off = q
        for sg, S, (Y, s_end, dY, ds) in zip(self.segments, nodes, self._evaluate(theta, nodes), strict=True):
            J, M, nz = sg.J, sg.M, 4 + q
            y_meas = sg.y.reshape(2, J, M).transpose(1, 2, 0).reshape(J, 2 * M)  # time-major
            rs.append(((y_meas - Y.T) / OUTPUT_SCALE).ravel())
            # segment j's Jacobian block sits at columns j*nz:(j+1)*nz of the mapped output
            dYr = dY.reshape(2 * M, J, nz).transpose(1, 0, 2)  # (J, 2M, nz)
            col = np.empty((J, 1, nz), dtype=np.int64)
            col[:, 0, :4] = var_off + 4 * np.arange(J)[:, None] + np.arange(4)[None, :]
            col[:, 0, 4:] = np.arange(q)[None, :]
            row = r_off + (np.arange(J)[:, None] * 2 * M + np.arange(2 * M)[None, :])[:, :, None]
            _append(jr, np.broadcast_to(row, dYr.shape), np.broadcast_to(col, dYr.shape), -dYr / OUTPUT_SCALE)
            links = sg.links  # segments j joined to j + 1 by continuity
            nl = links.size
            dsr = ds.reshape(4, J, nz).transpose(1, 0, 2)[links] / STATE_SCALE[None, :, None]  # (nl, 4, nz)
            cs.append(((s_end[:, links] - S[:, links + 1]) / STATE_SCALE[:, None]).T.ravel())
            crow = c_off + (4 * np.arange(nl)[:, None] + np.arange(4)[None, :])[:, :, None]
            _append(jc, np.broadcast_to(crow, dsr.shape), np.broadcast_to(col[links], dsr.shape), dsr)
            next_node = var_off + 4 * (links[:, None] + 1) + np.arange(4)[None, :]
            _append(jc, crow[:, :, 0], next_node, np.broadcast_to(-1.0 / STATE_SCALE, (nl, 4)))
            r_off += J * 2 * M
            c_off += 4 * nl
            var_off += 4 * J
        r, c = np.concatenate(rs), np.concatenate(cs)
        D = sp.diags(
            np.concatenate([self.layout.scale] + [np.tile(STATE_SCALE, sg.J) for sg in self.segments])
        )
        return r, c, (_sparse(jr, r.size, var_off) @ D).tocsc(), (_sparse(jc, c.size, var_off) @ D).tocsc()

    def _covariance(self, gn: GaussNewtonOutcome, th_scale: np.ndarray, hac_band: float):
        """(covariance, plain covariance, HAC frequencies, inflation, status, message or None)
        of the constants at the solution: the theta block of the inverse KKT matrix and its
        long-run version from the per-sample influence."""
        q = self.layout.n
        nan = np.full((q, q), np.nan)
        if not gn.success:
            return nan, nan, 0, np.full(q, np.nan), gn.status, None
        try:
            P = constrained_inverse_rows(gn.Jr, gn.Jc, q)  # (q, nvar), scaled
        except RuntimeError as err:
            return (
                nan,
                nan,
                0,
                np.full(q, np.nan),
                "covariance_singular",
                f"covariance: KKT matrix singular ({err})",
            )
        dof = max(gn.r.size - (gn.Jr.shape[1] - gn.Jc.shape[0]), 1)
        naive = float(gn.r @ gn.r) / dof * P[:, :q] * np.outer(th_scale, th_scale)
        G = (gn.Jr @ P.T).T  # (q, n_res) sensitivity of theta~ to each residual
        contrib = (G * gn.r[None, :]) * th_scale[:, None]  # (q, n_res) in theta units
        influence, k = [], 0
        for sg in self.segments:
            size = sg.J * 2 * sg.M
            influence.append(contrib[:, k : k + size].reshape(q, sg.J * sg.M, 2).sum(axis=2))
            k += size
        lr = long_run_covariance(influence, naive, self.sample_time, band=hac_band)
        return lr.covariance, naive, lr.frequencies, lr.variance_inflation, gn.status, None

    def _residual_arrays(self, r: np.ndarray):
        """Per log (2, n) residuals [m] (NaN past the last segment), RMS per axis, samples used."""
        residuals, k, acc, count = [], 0, np.zeros(2), 0
        for sg in self.segments:
            size = sg.J * 2 * sg.M
            rr = r[k : k + size].reshape(sg.J * sg.M, 2).T * OUTPUT_SCALE
            full = np.full((2, sg.n), np.nan)
            full[:, : sg.J * sg.M] = rr
            residuals.append(full)
            acc += np.sum(rr**2, axis=1)
            count += sg.J * sg.M
            k += size
        rms = {a: float(np.sqrt(acc[i] / count)) for i, a in enumerate(AXES)}
        return tuple(residuals), rms, count


def _append(triplets, rows, cols, values) -> None:
    """Add (rows, cols, values) of one block to the (rows, cols, values) lists of a sparse matrix."""
    for store, a in zip(triplets, (rows, cols, values), strict=True):
        store.append(np.asarray(a).ravel())


def _sparse(triplets, n_rows: int, n_cols: int) -> sp.csr_matrix:
    rows, cols, values = (np.concatenate(a) for a in triplets)
    return sp.csr_matrix((values, (rows, cols)), shape=(n_rows, n_cols))


def fit_output_error(
    logs: Log | Sequence[Log],
    model: StageModel,
    *,
    estimate: Sequence[str] = CONSTANT_NAMES,
    terms: Sequence[AccelerationTerm] = (),
    segment_duration: float = DEFAULT_SEGMENT,
    input_delay: float = 0.0,
    window_duration: float = DEFAULT_WINDOW,
    initial: FitResult | dict[str, float] | None = None,
    max_iterations: int = 30,
    hac_band: float = DEFAULT_BAND,
) -> FitResult:
    """Multiple-shooting output-error fit (one-off use; see :class:`MultipleShooting`).

    Parameters
    ----------
    logs, model, estimate, terms, segment_duration, input_delay, window_duration
        As for :class:`MultipleShooting`.
    initial : FitResult or dict, optional
        Starting values by name (default: an equation-error fit on the same logs).
    max_iterations : int
        Constrained Gauss-Newton iterations at most.
    hac_band : float
        [Hz] Spectral window of the long-run covariance.

    Returns
    -------
    FitResult
        ``residual_unit`` is ``"m"`` (positions); ``status`` says why a solve stopped.
    """
    problem = MultipleShooting(
        logs,
        model,
        estimate=estimate,
        terms=terms,
        segment_duration=segment_duration,
        input_delay=input_delay,
        window_duration=window_duration,
    )
    return problem.fit(initial=initial, max_iterations=max_iterations, hac_band=hac_band)


def simulate_open_loop(
    log: Log, model: StageModel, duration: float, *, x0: np.ndarray | None = None
) -> np.ndarray:
    """Single shooting: the model driven by the logged currents from ``x0`` (default: the
    Savitzky-Golay state at the first sample), RK4 per sample as in the fit; returns the state
    (4, k) over the first ``duration`` seconds (NaN once it leaves 0..0.1 m of gap).

    This is what single-shooting output error would have to fit; on the unstable stage it
    leaves the data within a fraction of a second even with the true constants.
    """
    k = min(log.n, round(duration / log.sample_time) + 1)
    if x0 is None:
        der = differentiate_log(log, SavitzkyGolay(log.sample_time))
        x0 = np.array([der.position[0, 0], der.velocity[0, 0], der.position[1, 0], der.velocity[1, 0]])

    s_v, s_h = factors(model.params, log.payload)
    g = model.params.gravity

    def rhs(x, u):
        d = np.asarray(model.f(x, u)).ravel()
        if log.payload:  # the model's forces move the platform and its payload
            d[1], d[3] = g + s_v * (d[1] - g), s_h * d[3]
        return d

    h = log.sample_time
    u = np.asarray(log.u, dtype=float)
    out = np.full((4, k), np.nan)
    x = np.asarray(x0, dtype=float).copy()
    for i in range(k):
        out[:, i] = x
        if i == k - 1:
            break
        u0, u1 = u[:, i], u[:, i + 1]
        x = rk4_step(rhs, x, h, u0, args_mid=(0.5 * (u0 + u1),), args_end=(u1,))
        if not (np.all(np.isfinite(x)) and 0 < x[0] < 0.1):
            break
    return out
