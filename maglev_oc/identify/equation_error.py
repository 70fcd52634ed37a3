"""Equation-error fit: the measured accelerations against the model's, linear in C1..C4.

For every sample of a log, eq. (2) of paper 000 says (x2', x4') = Phi(x, u) C + b (+ terms).
The gap and position are measured; their second derivatives are estimated with the zero-phase
Savitzky-Golay differentiator of :mod:`maglev_oc.estimation.differentiate` (the observers lag,
and a lag between the acceleration and the regressors taken at the same instant biases the
constants; see that module). The SG acceleration is a linear filter of the true acceleration,
a_SG = F[x''] with F = g * [1, 10, 1]/12, where g is the SG second-derivative kernel divided
by the second difference (exact: the SG kernel annihilates constants and ramps) and [1, 10, 1]/12
is the second difference's own smoothing of x'' (exact for quadratics between samples). So the
model side is filtered with the same F:

    F[a_measured]  =  F[Phi(x, u)] C + F[b] + F[terms]      (filtered equation error)

which keeps the equation exact: the currents' and the gap's high-frequency content does not
leak into the comparison unfiltered. Positions and velocities inside Phi are the SG estimates
(the 10 um quantization steps averaged out).

When the accelerations are affine in the estimated parameters (constants and linear terms,
no gap offset) the fit is one linear least-squares solve (exact). Otherwise a Levenberg-
Marquardt iteration runs with the exact Jacobian from CasADi, started from the constants'
linear solution (5-10 iterations on the twin). The two axes are weighted by the inverse RMS
of their residuals after a first, unweighted pass. Standard errors come from the long-run
covariance of the estimate's influence (:mod:`maglev_oc.identify.uncertainty`): filtered
residuals are correlated, so the plain s^2 (J'J)^-1, which assumes independent samples, is no
guide (it is reported beside).

Commanded vs. applied currents: logs carry the commands (SPEC 2). The amplifiers follow them
with a first-order lag (1 kHz bandwidth, 0.16 ms) and the 5 kHz loop holds each command for
0.2 ms, together about a 0.26 ms delay. ``input_delay`` shifts the logged currents by a given
delay (linear interpolation) before they enter Phi; the default 0 leaves them as logged. On the
twin (60 s logs) a 0.26 ms delay changes C4 by 0.05-0.07 % and C1..C3 by less than 0.005 %,
below their standard errors (0.2-0.3 % and 0.003-0.015 %), so the commands are used as logged.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np
from scipy.ndimage import convolve1d
from scipy.signal import savgol_coeffs

from maglev_oc.data.logs import Log
from maglev_oc.estimation.differentiate import SavitzkyGolay, differentiate_log
from maglev_oc.identify.layout import CONSTANT_NAMES, ParameterLayout
from maglev_oc.identify.result import AXIS_NAMES, FitResult
from maglev_oc.identify.terms import AccelerationTerm
from maglev_oc.identify.uncertainty import DEFAULT_BAND, correlation_from, long_run_covariance
from maglev_oc.model.stage import StageModel

DEFAULT_BANDWIDTH = 8.0
"""[Hz] Band of the Savitzky-Golay differentiator for identification. Both sides of the
equation are filtered by the same F, so the band only selects which part of the spectrum the
fit uses, not an approximation: 8 Hz keeps the sum-of-sines excitation (up to 3 Hz) and the PID
loops' poles (up to 5 Hz) and drops the band where the differentiated quantization noise
(rising as f^4) and its echo in the closed-loop currents dominate. On the twin (20 s logs, six
seeds) the closed-loop correlation between that noise and u1 biases C1 by +0.047 % at 20 Hz
and +0.002 % at 8 Hz, and the scatter of C2..C4 is 30-40 % smaller."""

SampleSpec = slice | tuple[int, int] | np.ndarray | None


def matching_kernel(differentiator: SavitzkyGolay) -> np.ndarray:
    """The filter F with SG acceleration = F[true acceleration] (symmetric, unit DC gain)."""
    sg = differentiator
    h2 = savgol_coeffs(sg.acceleration_window, sg.polyorder, deriv=2, delta=sg.sample_time, use="conv")
    g, remainder = np.polydiv(h2, np.array([1.0, -2.0, 1.0]) / sg.sample_time**2)
    if np.max(np.abs(remainder)) > 1e-6 * np.max(np.abs(h2)):
        raise RuntimeError("the SG second-derivative kernel is not divisible by the second difference")
    kernel = np.convolve(g, [1 / 12, 10 / 12, 1 / 12])
    return kernel / kernel.sum()


def as_log_list(logs: Log | Sequence[Log]) -> list[Log]:
    if isinstance(logs, Log):
        return [logs]
    out = list(logs)
    if not out:
        raise ValueError("no logs given")
    for log in out:
        if not isinstance(log, Log):
            raise TypeError(f"expected Log objects, got {type(log).__name__}")
    return out


def sample_masks(samples: SampleSpec | Sequence[SampleSpec], logs: Sequence[Log]) -> list[np.ndarray]:
    """Boolean masks, one per log, from None / a slice / (start, stop) / a boolean array.

    With several logs, ``samples`` is None or a sequence with one entry per log.
    """
    if samples is None:
        return [np.ones(log.n, dtype=bool) for log in logs]
    single = isinstance(samples, (slice, np.ndarray)) or (
        isinstance(samples, tuple)
        and len(samples) == 2
        and all(isinstance(v, (int, np.integer)) for v in samples)
    )
    if single:
        if len(logs) != 1:
            raise ValueError(
                f"samples: {len(logs)} logs need one entry per log (a list), got a single "
                f"{type(samples).__name__}"
            )
        specs = [samples]
    else:
        specs = list(samples)
        if len(specs) != len(logs):
            raise ValueError(f"samples: {len(specs)} entries for {len(logs)} logs")
    masks = []
    for spec, log in zip(specs, logs, strict=True):
        mask = np.zeros(log.n, dtype=bool)
        if spec is None:
            mask[:] = True
        elif isinstance(spec, slice):
            mask[spec] = True
        elif isinstance(spec, tuple):
            start, stop = (int(v) for v in spec)
            if not 0 <= start < stop <= log.n:
                raise ValueError(f"samples: index range ({start}, {stop}) outside 0..{log.n} of {log.source}")
            mask[start:stop] = True
        else:
            arr = np.asarray(spec)
            if arr.dtype != bool or arr.shape != (log.n,):
                raise ValueError(
                    f"samples: a mask must be a boolean array of shape ({log.n},) for {log.source}, got "
                    f"dtype {arr.dtype} shape {arr.shape}"
                )
            mask[:] = arr
        masks.append(mask)
    return masks


def delayed_inputs(log: Log, delay: float) -> np.ndarray:
    """The logged currents shifted later by ``delay`` [s] (linear interpolation, held at the start)."""
    if delay == 0:
        return np.asarray(log.u, dtype=float)
    return np.vstack([np.interp(log.t - delay, log.t, row) for row in log.u])


@dataclass(frozen=True, eq=False)
class _Prepared:
    """One log, differentiated and ready: SG states, currents, filtered measured accelerations."""

    x: np.ndarray  # (4, n) SG position / velocity estimates
    u: np.ndarray  # (2, n)
    acc: np.ndarray  # (2, n) SG accelerations (= F[true])
    valid: np.ndarray  # (n,) bool, away from the filters' edges
    source: str


class EquationError:
    """An equation-error problem prepared once, fitted on any subset of samples.

    Parameters
    ----------
    logs : Log or sequence of Log
        Logs at one sampling rate (x2, x4 need not be logged).
    model : StageModel
        Geometry, and the values of constants that are not estimated (and initial guesses).
    estimate : sequence of str
        Among ``C1, C2, C3, C4, gap_offset`` (default the four constants).
    terms : sequence of AccelerationTerm
        Extra accelerations fitted jointly.
    differentiator : SavitzkyGolay, optional
        Default ``SavitzkyGolay(sample_time, bandwidth=8.0)`` (``DEFAULT_BANDWIDTH``, polyorder 5).
    input_delay : float
        [s] Delay applied to the logged currents (default 0; see the module docstring).

    Use :meth:`fit` (any subset of samples, e.g. with a block held out) and :meth:`residuals`
    (on every valid sample, for held-out errors).
    """

    def __init__(
        self,
        logs: Log | Sequence[Log],
        model: StageModel,
        *,
        estimate: Sequence[str] = CONSTANT_NAMES,
        terms: Sequence[AccelerationTerm] = (),
        differentiator: SavitzkyGolay | None = None,
        input_delay: float = 0.0,
    ) -> None:
        t0 = time.perf_counter()
        self.logs = as_log_list(logs)
        self.layout = ParameterLayout(model, tuple(estimate), tuple(terms))
        if not (math.isfinite(input_delay) and 0 <= input_delay < 0.01):
            raise ValueError(f"input_delay must be in [0, 0.01) s, got {input_delay!r}")
        self.input_delay = float(input_delay)
        dt = self.logs[0].sample_time
        for log in self.logs[1:]:
            if abs(log.sample_time - dt) > 0.01 * dt:
                raise ValueError(
                    f"logs at different rates: {self.logs[0].source} at {1 / dt:g} Hz, {log.source} at "
                    f"{1 / log.sample_time:g} Hz"
                )
        self.differentiator = (
            SavitzkyGolay(dt, bandwidth=DEFAULT_BANDWIDTH) if differentiator is None else differentiator
        )
        if not isinstance(self.differentiator, SavitzkyGolay):
            raise TypeError(
                "differentiator must be a SavitzkyGolay (zero phase; a lagging estimate biases an "
                f"equation-error fit), got {type(self.differentiator).__name__}"
            )
        self.kernel = matching_kernel(self.differentiator)
        sg = self.differentiator
        self.edge = max(sg.velocity_window, sg.acceleration_window) // 2 + self.kernel.size // 2
        self.min_samples = 2 * self.kernel.size
        self.sample_time = dt
        self.prepared = [self._prepare(log) for log in self.logs]
        fn = self.layout.acceleration_reading
        theta = ca.SX.sym("theta", self.layout.n)
        x, u = ca.SX.sym("x", 4), ca.SX.sym("u", 2)
        acc = fn(x, u, theta)
        self._acc_jac = ca.Function("acc_jac", [x, u, theta], [acc, ca.jacobian(acc, theta)])
        self._maps: dict[int, ca.Function] = {}
        self._affine: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._last: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self.prepare_time = time.perf_counter() - t0

    def _prepare(self, log: Log) -> _Prepared:
        n_needed = 2 * self.edge + 10
        if log.n < n_needed:
            raise ValueError(
                f"{log.source}: {log.n} samples; the differentiator's windows need at least {n_needed}"
            )
        der = differentiate_log(log, self.differentiator)
        x = np.vstack([der.position[0], der.velocity[0], der.position[1], der.velocity[1]])
        valid = np.zeros(log.n, dtype=bool)
        valid[self.edge : log.n - self.edge] = True
        return _Prepared(
            x, delayed_inputs(log, self.input_delay), np.asarray(der.acceleration), valid, log.source
        )

    # ------------------------------------------------------------------------------------
    def _evaluate(self, prep: _Prepared, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Filtered model accelerations (2, n) and their Jacobian (2, n, p) at ``theta``.

        Affine models are evaluated once (at theta = 0) and then composed; otherwise the last
        evaluation per log is remembered (the solver asks for residuals and Jacobians apart)."""
        theta = np.asarray(theta, dtype=float)
        key = id(prep)
        if self.layout.linear:
            if key not in self._affine:
                self._affine[key] = self._evaluate_raw(prep, np.zeros(self.layout.n))
            acc0, jac = self._affine[key]
            return acc0 + np.einsum("anp,p->an", jac, theta), jac
        cached = self._last.get(key)
        if cached is not None and np.array_equal(cached[0], theta):
            return cached[1], cached[2]
        acc_f, jac_f = self._evaluate_raw(prep, theta)
        self._last[key] = (theta.copy(), acc_f, jac_f)
        return acc_f, jac_f

    def _evaluate_raw(self, prep: _Prepared, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n = prep.x.shape[1]
        if n not in self._maps:
            self._maps[n] = self._acc_jac.map(n)
        acc, jac = self._maps[n](prep.x, prep.u, theta)
        acc = np.asarray(acc)
        jac = np.asarray(jac).reshape(2, n, self.layout.n)
        acc_f = convolve1d(acc, self.kernel, axis=1, mode="constant")
        jac_f = convolve1d(jac, self.kernel, axis=1, mode="constant")
        return acc_f, jac_f

    def residuals(self, values: FitResult | dict[str, float] | np.ndarray) -> list[np.ndarray]:
        """Measured minus model accelerations (2, n) [m/s^2] per log, at every valid sample
        (NaN within the filters' edges), for the given parameter values."""
        theta = self._theta(values)
        out = []
        for prep in self.prepared:
            acc_f, _ = self._evaluate(prep, theta)
            r = prep.acc - acc_f
            r[:, ~prep.valid] = np.nan
            out.append(r)
        return out

    def _theta(self, values: FitResult | dict[str, float] | np.ndarray) -> np.ndarray:
        if isinstance(values, FitResult):
            return values.vector()
        if isinstance(values, dict):
            missing = [k for k in self.layout.names if k not in values]
            if missing:
                raise ValueError(f"values: missing {missing}")
            return np.array([values[k] for k in self.layout.names], dtype=float)
        theta = np.asarray(values, dtype=float).ravel()
        if theta.size != self.layout.n:
            raise ValueError(
                f"values: expected {self.layout.n} numbers {self.layout.names}, got {theta.size}"
            )
        return theta

    # ------------------------------------------------------------------------------------
    def fit(
        self,
        samples: SampleSpec | Sequence[SampleSpec] = None,
        *,
        initial: dict[str, float] | None = None,
        hac_band: float = DEFAULT_BAND,
    ) -> FitResult:
        """Fit on the chosen samples (default all; the filters' edges are always left out).

        Parameters
        ----------
        samples : None, slice, (start, stop), boolean mask of shape (n,), or one per log
            Which samples enter the fit (e.g. everything but a held-out block). The filters run
            on the whole log first, so a held-out block leaks into the fitted samples within
            half a window (about 30 ms) of its edges.
        initial : dict, optional
            Starting values by name (used by the nonlinear path; the linear solve needs none).
        hac_band : float
            [Hz] Spectral window of the long-run covariance (default 0.25 Hz).
        """
        t0 = time.perf_counter()
        layout = self.layout
        masks = [
            m & prep.valid for m, prep in zip(sample_masks(samples, self.logs), self.prepared, strict=True)
        ]
        n_used = int(sum(m.sum() for m in masks))
        if n_used < 10 * layout.n + self.min_samples:
            raise ValueError(
                f"only {n_used} usable samples (after leaving out {self.edge} at each edge of each log); "
                f"need at least {10 * layout.n + self.min_samples} for {layout.n} parameters"
            )
        theta0 = layout.initial_vector(initial)
        scale = np.array(layout.scale)

        def stacked(theta: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            rs, js = [], []
            for prep, m in zip(self.prepared, masks, strict=True):
                acc_f, jac_f = self._evaluate(prep, theta)
                r = (prep.acc - acc_f)[:, m] * weights[:, None]
                j = jac_f[:, m, :] * weights[:, None, None]
                rs.append(r.ravel())
                js.append(j.reshape(-1, layout.n))
            return np.concatenate(rs), np.concatenate(js)

        status, message, iterations = 0, "", 0
        weights = np.ones(2)
        theta = theta0.copy()
        solve_t0 = time.perf_counter()
        for stage in range(2):  # unweighted, then each axis weighted by 1 / its residual RMS
            if layout.linear:
                r0, jac = stacked(np.zeros(layout.n), weights)
                js = jac * scale
                sol, _, rank, sv = np.linalg.lstsq(js, r0, rcond=None)
                theta = sol * scale
                iterations += 1
                if rank < layout.n:
                    status, message = (
                        -1,
                        (
                            f"not identifiable from these samples: the scaled regressor has rank {rank} < "
                            f"{layout.n} (singular values {np.array2string(sv, precision=3)})"
                        ),
                    )
                    break
                status, message = 1, "linear least squares (exact: the accelerations are affine in theta)"
            else:
                lower = np.array(layout.lower)
                upper = np.array(layout.upper)
                start = np.clip(theta, np.nextafter(lower, upper), np.nextafter(upper, lower))

                if stage == 0 and any(c in layout.names for c in CONSTANT_NAMES):
                    start = self._linear_start(start, masks)
                theta, status, message, nit = _levenberg_marquardt(
                    lambda th, w=weights: stacked(th, w), start, scale, lower, upper
                )
                iterations += nit
                if status <= 0:
                    break
            if stage == 0:
                r, _ = stacked(theta, np.ones(2))
                r2 = r.reshape(-1)
                rms = self._axis_rms(r2, masks)
                weights = np.array([1 / rms[a] if rms[a] > 0 else 1.0 for a in AXIS_NAMES])
        solve_time = time.perf_counter() - solve_t0

        cov_t0 = time.perf_counter()
        success = status > 0
        r, jac = stacked(theta, weights)
        chi2 = float(r @ r)
        n_res = r.size
        dof = max(n_res - layout.n, 1)
        hess = jac.T @ jac
        try:
            h_inv = np.linalg.inv(hess) if success else np.full((layout.n, layout.n), np.nan)
        except np.linalg.LinAlgError:
            h_inv = np.full((layout.n, layout.n), np.nan)
            success, status, message = False, -1, "singular normal matrix"
        if success:
            influence = []
            for prep, m in zip(self.prepared, masks, strict=True):
                acc_f, jac_f = self._evaluate(prep, theta)
                res = (prep.acc - acc_f) * weights[:, None]
                res[:, ~m] = 0.0
                jw = jac_f * weights[:, None, None]
                scores = np.einsum("anp,an->pn", jw, res)
                influence.append(h_inv @ scores)
            lr = long_run_covariance(influence, chi2 / dof * h_inv, self.sample_time, band=hac_band)
            cov, naive, hac_m, inflation = lr.covariance, lr.naive, lr.frequencies, lr.variance_inflation
        else:
            cov = naive = np.full((layout.n, layout.n), np.nan)
            hac_m, inflation = 0, np.full(layout.n, np.nan)
        cov_time = time.perf_counter() - cov_t0

        residuals = []
        for prep, m in zip(self.prepared, masks, strict=True):
            acc_f, _ = self._evaluate(prep, theta)
            res = prep.acc - acc_f
            res[:, ~m] = np.nan
            residuals.append(res)
        all_res = np.concatenate(residuals, axis=1)
        rms = {a: float(np.sqrt(np.nanmean(all_res[k] ** 2))) for k, a in enumerate(AXIS_NAMES)}
        names = layout.names
        total = time.perf_counter() - t0
        return FitResult(
            method="equation_error",
            names=names,
            values=dict(zip(names, theta, strict=True)),
            stderr=dict(zip(names, np.sqrt(np.diag(cov)), strict=True)),
            stderr_naive=dict(zip(names, np.sqrt(np.diag(naive)), strict=True)),
            initial=dict(zip(names, theta0, strict=True)),
            fixed=layout.fixed(),
            covariance=cov,
            correlation=correlation_from(cov) if success else np.full_like(cov, np.nan),
            residual_rms=rms,
            residual_unit="m/s^2",
            residuals=tuple(residuals),
            n_samples=n_used,
            n_residuals=n_res,
            chi_square=chi2,
            reduced_chi_square=chi2 / dof,
            hac_frequencies=hac_m,
            variance_inflation=dict(zip(names, inflation, strict=True)),
            success=success,
            status=status,
            message=message,
            iterations=iterations,
            timings={
                "prepare": self.prepare_time,
                "solve": solve_time,
                "covariance": cov_time,
                "total": total + self.prepare_time,
            },
            sources=tuple(p.source for p in self.prepared),
            settings={
                "differentiator": "savitzky_golay",
                "bandwidth_hz": self.differentiator.bandwidth,
                "hac_band_hz": hac_band,
                "polyorder": self.differentiator.polyorder,
                "velocity_window": self.differentiator.velocity_window,
                "acceleration_window": self.differentiator.acceleration_window,
                "edge_samples": self.edge,
                "input_delay_s": self.input_delay,
                "axis_weights": dict(zip(AXIS_NAMES, weights.tolist(), strict=True)),
                "linear": layout.linear,
                "terms": [t.name for t in layout.terms],
            },
        )

    def _axis_rms(self, r: np.ndarray, masks: list[np.ndarray]) -> dict[str, float]:
        """RMS per axis of a stacked residual (per log: vertical block then horizontal block)."""
        sums = np.zeros(2)
        count = 0
        k = 0
        for m in masks:
            n = int(m.sum())
            block = r[k : k + 2 * n].reshape(2, n)
            sums += np.sum(block**2, axis=1)
            count += n
            k += 2 * n
        return {a: float(np.sqrt(sums[i] / max(count, 1))) for i, a in enumerate(AXIS_NAMES)}

    def _linear_start(self, theta: np.ndarray, masks: list[np.ndarray]) -> np.ndarray:
        """The constants' linear LS solution with the nonlinear parameters at ``theta``."""
        names = self.layout.names
        idx = [k for k, nm in enumerate(names) if nm in CONSTANT_NAMES]
        rs, js = [], []
        for prep, m in zip(self.prepared, masks, strict=True):
            acc_f, jac_f = self._evaluate(prep, theta)
            rs.append((prep.acc - acc_f)[:, m].ravel())
            js.append(jac_f[:, m, :][:, :, idx].reshape(-1, len(idx)))
        r, j = np.concatenate(rs), np.concatenate(js)
        step, *_ = np.linalg.lstsq(j, r, rcond=None)
        out = theta.copy()
        out[idx] += step
        return out


def _levenberg_marquardt(
    stacked,
    theta: np.ndarray,
    scale: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    *,
    max_iterations: int = 100,
    tolerance: float = 1e-10,
) -> tuple[np.ndarray, int, str, int]:
    """Levenberg-Marquardt on ``stacked(theta) -> (r, J)`` (r = data - model, J = d model / d theta,
    exact), in the variables theta / scale, steps clipped to the bounds. Returns
    (theta, status > 0 on success, message, iterations)."""
    r, jac = stacked(theta)
    cost = float(r @ r)
    mu = 1e-9  # nearly Gauss-Newton: the collinear directions (gap offset vs C1..C3) need it
    for it in range(1, max_iterations + 1):
        js = jac * scale
        a = js.T @ js
        g = js.T @ r
        diag = np.diag(a).copy()
        diag[diag <= 0] = 1.0
        while True:
            try:
                step = np.linalg.solve(a + mu * np.diag(diag), g)
            except np.linalg.LinAlgError:
                step = np.full_like(g, np.inf)
            trial = np.clip(theta + step * scale, lower, upper)
            if np.all(np.isfinite(trial)):
                r_t, jac_t = stacked(trial)
                cost_t = float(r_t @ r_t)
                if np.isfinite(cost_t) and cost_t <= cost:
                    break
            mu *= 10.0
            if mu > 1e12:
                return theta, -1, "Levenberg-Marquardt: no decrease along any damped step", it
        moved = float(np.max(np.abs(trial - theta) / scale))
        decrease = cost - cost_t
        theta, r, jac, cost = trial, r_t, jac_t, cost_t
        mu = max(mu / 10.0, 1e-15)
        if moved < tolerance or decrease <= 1e-14 * cost:
            return theta, 1, f"Levenberg-Marquardt (exact Jacobian) converged in {it} iterations", it
    return theta, 0, f"Levenberg-Marquardt: {max_iterations} iterations without convergence", max_iterations


def fit_equation_error(
    logs: Log | Sequence[Log],
    model: StageModel,
    *,
    estimate: Sequence[str] = CONSTANT_NAMES,
    terms: Sequence[AccelerationTerm] = (),
    samples: SampleSpec | Sequence[SampleSpec] = None,
    differentiator: SavitzkyGolay | None = None,
    input_delay: float = 0.0,
    initial: dict[str, float] | None = None,
    hac_band: float = DEFAULT_BAND,
) -> FitResult:
    """Equation-error fit of ``estimate`` (and the terms' parameters) on ``logs``; see
    :class:`EquationError` for the parameters. One-off use; for several fits on the same logs
    (held-out blocks, cross-validation) build the :class:`EquationError` once."""
    problem = EquationError(
        logs, model, estimate=estimate, terms=terms, differentiator=differentiator, input_delay=input_delay
    )
    return problem.fit(samples, initial=initial, hac_band=hac_band)
