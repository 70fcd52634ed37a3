"""Equation-error fit: the measured accelerations against the model's, linear in C1..C4.

For every sample of a log, eq. (2) of paper 000 says (x2', x4') = Phi(x, u) C + b (+ terms).
The gap and position are measured; their second derivatives come from the zero-phase
Savitzky-Golay differentiator, and every model column passes through the filter F that the
differentiator applies to the true acceleration, so the filtered equation stays exact:

    F[a_measured]  =  F[Phi(x, u)] C + F[b] + F[terms]      (filtered equation error)

All of it — data preparation, the filter, the logged currents' errors (errors in variables,
removed from the normal equations), the block Gram matrices, the solver and the covariance — is
the project's one regression layer, :mod:`maglev_oc.regression`, which the diagnosis uses too.
This module is the identification's front end to it: which parameters, which samples, and a
:class:`~maglev_oc.identification.result.FitResult`.

When the accelerations are affine in the estimated parameters (constants and linear terms, no
gap offset) the fit is one linear solve (exact). Otherwise Gauss-Newton iterates on the exact
Jacobian (:func:`~maglev_oc.regression.solve.fit_nonlinear`), started from the model's constants.
The two axes are weighted by the inverse RMS of their residuals after a first, unweighted pass.

Band: 8 Hz (:data:`DEFAULT_BANDWIDTH`). Both sides are filtered by the same F, so the band only
selects which part of the spectrum the fit uses: the sum-of-sines excitation (up to 3 Hz) and the
regulators' poles (up to 9 Hz) pass; the band where the differentiated quantization noise (rising
as f^4) and its echo in the closed-loop currents dominate is left out.

Commanded vs. applied currents: logs carry the commands (SPEC 2). ``input_delay`` shifts the
logged currents by a given delay (linear interpolation) before they enter Phi; default 0.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np

from maglev_oc.data.logs import Log, LogError
from maglev_oc.errors import InputError
from maglev_oc.estimation.differentiate import SavitzkyGolay
from maglev_oc.identification.result import FitResult
from maglev_oc.model.stage import StageModel
from maglev_oc.regression.base import (
    CONSTANT_AXIS,
    CONSTANT_NAMES,
    GAP_OFFSET,
    GAP_OFFSET_BOUND,
    GAP_OFFSET_SCALE,
)
from maglev_oc.regression.covariance import DEFAULT_BAND, correlation_from
from maglev_oc.regression.data import (
    PreparedLogs,
    as_log_list,
    axes_left_out,
    delayed_inputs,
    prepare,
)
from maglev_oc.regression.design import Design, build_design
from maglev_oc.regression.noise_scale import LOW_BAND, NoiseScale, band_consistent_scale
from maglev_oc.regression.solve import fit_nonlinear, fit_subset, residuals
from maglev_oc.regression.terms import AccelerationTerm
from maglev_oc.results import AXES

__all__ = ["DEFAULT_BANDWIDTH", "EquationError", "fit_equation_error", "refuse_left_out"]

DEFAULT_BANDWIDTH = 8.0
"""[Hz] Band of the Savitzky-Golay differentiator for identification (see the module doc)."""

SampleSpec = slice | tuple[int, int] | np.ndarray | None


def _sample_masks(samples: SampleSpec | Sequence[SampleSpec], logs: Sequence[Log]) -> list[np.ndarray]:
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
            raise InputError(
                f"samples: {len(logs)} logs need one entry per log (a list), got a single "
                f"{type(samples).__name__}"
            )
        specs = [samples]
    else:
        specs = list(samples)
        if len(specs) != len(logs):
            raise InputError(f"samples: {len(specs)} entries for {len(logs)} logs")
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
                raise InputError(f"samples: index range ({start}, {stop}) outside 0..{log.n} of {log.source}")
            mask[start:stop] = True
        else:
            arr = np.asarray(spec)
            if arr.dtype != bool or arr.shape != (log.n,):
                raise InputError(
                    f"samples: a mask must be a boolean array of shape ({log.n},) for {log.source}, got "
                    f"dtype {arr.dtype} shape {arr.shape}"
                )
            mask[:] = arr
        masks.append(mask)
    return masks


class EquationError:
    """An equation-error problem prepared once, fitted on any subset of samples.

    Parameters
    ----------
    logs : Log or sequence of Log
        Logs at one sampling rate (x2, x4 need not be logged; logs above 1 kHz are reduced).
    model : StageModel
        Geometry, and the values of constants that are not estimated (and initial guesses).
    estimate : sequence of str
        Among ``C1, C2, C3, C4, gap_offset`` (default the four constants).
    terms : sequence of AccelerationTerm
        Extra accelerations fitted jointly.
    differentiator : SavitzkyGolay, optional
        Default ``SavitzkyGolay(sample_time, bandwidth=8.0)`` (``DEFAULT_BANDWIDTH``, polyorder 5).
    input_delay : float
        [s] Delay applied to the logged currents (default 0).
    logging_error : bool
        Remove the logged currents' errors from the normal equations (default True; see
        :mod:`maglev_oc.regression.data`).
    calibrate_noise : bool
        Take those errors at the level where the fit on a 2 Hz band agrees with the fit on its
        own (default True; :mod:`maglev_oc.regression.noise_scale`, the diagnosis's rule); False
        keeps the noise floor's estimate.

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
        logging_error: bool = True,
        calibrate_noise: bool = True,
    ) -> None:
        t0 = time.perf_counter()
        self.logs = as_log_list(logs)
        self.model = model
        if not (math.isfinite(input_delay) and 0 <= input_delay < 0.01):
            raise InputError(f"input_delay must be in [0, 0.01) s, got {input_delay!r}")
        self.input_delay = float(input_delay)
        self.estimate = (estimate,) if isinstance(estimate, str) else tuple(estimate)
        self.terms = tuple(terms)
        for term in self.terms:
            if not isinstance(term, AccelerationTerm):
                raise TypeError(f"terms must be AccelerationTerm, got {type(term).__name__}")
        if not self.estimate and not self.terms:
            raise InputError("nothing to estimate: give constants in estimate or at least one term")
        dt = self.logs[0].sample_time
        for log in self.logs[1:]:
            if abs(log.sample_time - dt) > 0.01 * dt:
                raise InputError(
                    f"logs at different rates: {self.logs[0].source} at {1 / dt:g} Hz, {log.source} at "
                    f"{1 / log.sample_time:g} Hz"
                )
        shifted = [
            log if self.input_delay == 0 else _with_inputs(log, delayed_inputs(log, self.input_delay))
            for log in self.logs
        ]
        kw = (
            {"bandwidth": DEFAULT_BANDWIDTH} if differentiator is None else {"differentiator": differentiator}
        )
        self.prepared = prepare(shifted, logging_error=logging_error, model=self.model, **kw)
        refuse_left_out(self.prepared, self.estimate)
        self._shifted = shifted
        self._narrow: PreparedLogs | None = None
        # a narrow band well below the fit's own, and an error to scale
        self.calibrate_noise = bool(
            calibrate_noise
            and self.prepared.differentiator.bandwidth >= 2.0 * LOW_BAND
            and np.any(self.prepared.current_noise > 0)
        )
        self.differentiator = self.prepared.differentiator
        self.sample_time = self.prepared.sample_time
        self.kernel = self.prepared.kernel
        # the first design validates the names and gives the layout (names, initial values)
        self._probe = build_design(self.prepared, model, estimate=self.estimate, terms=self.terms)
        self.names = self._probe.names
        self.linear = not (GAP_OFFSET in self.estimate or any(not t.linear for t in self.terms))
        self.prepare_time = time.perf_counter() - t0

    # ------------------------------------------------------------------------------------
    def _bounds(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Initial values, lower and upper bounds and scales of every parameter, design order."""
        init, lo, hi, sc = [], [], [], []
        for name in self.names:
            if name in CONSTANT_NAMES:
                v = getattr(self.model.constants, name)
                init.append(v)
                lo.append(0.0)
                hi.append(math.inf)
                sc.append(abs(v) or 1.0)
            elif name == GAP_OFFSET:
                init.append(0.0)
                lo.append(-GAP_OFFSET_BOUND)
                hi.append(GAP_OFFSET_BOUND)
                sc.append(GAP_OFFSET_SCALE)
        for term in self.terms:
            init.extend(term.initial)
            lo.extend(term.lower)
            hi.extend(term.upper)
            sc.extend(term.scale)
        return np.array(init), np.array(lo), np.array(hi), np.array(sc)

    def _values(self, values: FitResult | dict[str, float] | np.ndarray) -> np.ndarray:
        if isinstance(values, FitResult):
            return values.vector()
        if isinstance(values, dict):
            missing = [k for k in self.names if k not in values]
            if missing:
                raise InputError(f"values: missing {missing}")
            return np.array([values[k] for k in self.names], dtype=float)
        theta = np.asarray(values, dtype=float).ravel()
        if theta.size != len(self.names):
            raise InputError(f"values: expected {len(self.names)} numbers {self.names}, got {theta.size}")
        return theta

    def _per_log(self, rows: np.ndarray, mask: np.ndarray) -> list[np.ndarray]:
        """Split a (2, n) array of the prepared samples into one array per log, NaN off ``mask``."""
        out = []
        r = np.where(mask[None, :], rows, np.nan)
        for s in range(self.prepared.n_logs):
            out.append(r[:, self.prepared.segment == s])
        return out

    def residuals(self, values: FitResult | dict[str, float] | np.ndarray) -> list[np.ndarray]:
        """Measured minus model accelerations (2, n) [m/s^2] per log, at every valid sample
        (NaN within the filters' edges), for the given parameter values."""
        theta = self._values(values)
        design = build_design(
            self.prepared, self.model, estimate=self.estimate, terms=self.terms, at=theta, weights=np.ones(2)
        )
        r = design.target - np.einsum("p,pan->an", theta, design.columns)
        return self._per_log(r, self.prepared.valid)

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
        fit_mask = self._fit_mask(samples)
        init = self._initial(initial)
        solve_t0 = time.perf_counter()
        design, sub, status, message, iterations = self._solve(self.prepared, fit_mask, init, hac_band)
        scale = self._noise_scale(samples, design, sub) if self.calibrate_noise else None
        if scale is not None and scale.calibrated:
            prepared = self.prepared.with_noise_scale(scale.scale)
            design, sub, status, message, iterations = self._solve(prepared, fit_mask, init, hac_band)
        solve_time = time.perf_counter() - solve_t0
        if sub.message:
            message = f"{message}; {sub.message}"
        cov = sub.covariance
        success = status == "converged" and bool(np.all(np.isfinite(cov)))
        if status == "converged" and not success:
            status, message = "singular", "singular normal matrix"
        res = residuals(design, sub)
        n_used = int(fit_mask.sum())
        with np.errstate(divide="ignore", invalid="ignore"):
            inflation = np.where(np.diag(sub.naive) > 0, np.diag(cov) / np.diag(sub.naive), np.nan)
        names = self.names
        return FitResult(
            method="equation_error",
            names=names,
            values=dict(zip(names, sub.coef, strict=True)),
            stderr=dict(zip(names, np.sqrt(np.clip(np.diag(cov), 0, None)), strict=True)),
            stderr_naive=dict(zip(names, np.sqrt(np.clip(np.diag(sub.naive), 0, None)), strict=True)),
            initial=dict(zip(names, init, strict=True)),
            fixed={k: getattr(self.model.constants, k) for k in CONSTANT_NAMES if k not in names},
            covariance=cov,
            correlation=correlation_from(cov) if success else np.full_like(cov, np.nan),
            residual_rms={a: float(np.sqrt(np.mean(res[k, fit_mask] ** 2))) for k, a in enumerate(AXES)},
            residual_unit="m/s^2",
            residuals=tuple(self._per_log(res, fit_mask)),
            n_samples=n_used,
            n_residuals=n_used * int(np.sum(design.weights > 0)),
            chi_square=sub.chi_square,
            reduced_chi_square=sub.chi_square / sub.dof,
            hac_frequencies=sub.frequencies,
            variance_inflation=dict(zip(names, inflation, strict=True)),
            success=success,
            status=status,
            message=message,
            iterations=iterations,
            timings={
                "prepare": self.prepare_time,
                "solve": solve_time,
                "covariance": 0.0,
                "total": time.perf_counter() - t0 + self.prepare_time,
            },
            sources=tuple(dict.fromkeys(log.source for log in self.logs)),  # a log cut in pieces once
            settings={
                **self._settings(hac_band, design.weights, sub.compensated),
                "current_noise_scale": None if scale is None else scale.to_dict(),
            },
        )

    # ------------------------------------------------------------------------------------
    def _noise_scale(self, samples, design: Design, sub) -> NoiseScale:
        """The scale of the logged currents' errors at which this fit and the same fit on
        :data:`~maglev_oc.regression.noise_scale.LOW_BAND` agree on the constants."""
        if self._narrow is None:
            try:
                self._narrow = prepare(
                    self._shifted, bandwidth=LOW_BAND, resting=self.prepared.resting, params=self.model.params
                )
            except (InputError, LogError) as err:  # a log too short for the narrow band's window
                return NoiseScale.not_calibrated(f"no {LOW_BAND:g} Hz fit to compare with: {err}")
        narrow = self._narrow
        try:
            fit = self._fit_mask(samples, narrow)
        except InputError as err:
            return NoiseScale.not_calibrated(
                f"too few samples for a {LOW_BAND:g} Hz fit to compare with: {err}"
            )
        low = build_design(
            narrow,
            self.model,
            estimate=self.estimate,
            terms=self.terms,
            fit=fit,
            at=sub.coef,
            weights=design.weights,
        )
        return band_consistent_scale(design, low, list(design.groups))

    def _sample_masks(self, samples) -> list[np.ndarray]:
        """Per log, the samples to fit, at the prepared (reduced) rate."""
        return [
            _reduced_mask(m, round(self.sample_time / log.sample_time))
            for m, log in zip(_sample_masks(samples, self.logs), self.logs, strict=True)
        ]

    def _fit_mask(self, samples, prep: PreparedLogs | None = None) -> np.ndarray:
        """The fitted samples of the prepared (rate-reduced) data, or of ``prep`` (the same logs
        on another band); refuses too few."""
        prep = self.prepared if prep is None else prep
        fit_mask, _ = prep.masks(0.0, self._sample_masks(samples))
        n_used, p = int(fit_mask.sum()), len(self.names)
        min_samples = 2 * prep.kernel.size
        if n_used < 10 * p + min_samples:
            raise InputError(
                f"only {n_used} usable samples (after leaving out {prep.edge} at each edge of each log); "
                f"need at least {10 * p + min_samples} for {p} parameters"
            )
        return fit_mask

    def _initial(self, initial: dict[str, float] | None) -> np.ndarray:
        init = self._bounds()[0]
        for key, value in (initial or {}).items():
            if key not in self.names:
                raise InputError(f"initial: {key!r} is not estimated; estimated: {self.names}")
            init[self.names.index(key)] = float(value)
        return init

    def _solve(self, prepared: PreparedLogs, fit_mask: np.ndarray, init: np.ndarray, hac_band: float):
        """(design, fit, status, message, iterations): one linear solve, or Gauss-Newton with the
        exact Jacobian when a parameter enters nonlinearly (axis weights of the first design)."""

        def build(at: np.ndarray, weights=None) -> Design:
            return build_design(
                prepared,
                self.model,
                estimate=self.estimate,
                terms=self.terms,
                fit=fit_mask,
                at=at,
                weights=weights,
            )

        first = build(init)
        if self.linear:
            sub = fit_subset(first, list(first.groups), band=hac_band)
            return (
                first,
                sub,
                "converged",
                "linear least squares (exact: the accelerations are affine in theta)",
                1,
            )
        _, lower, upper, scale = self._bounds()
        design, sub, status, message, iterations = fit_nonlinear(
            lambda at: build(at, first.weights), init, lower, upper, scale
        )
        design = build(sub.coef, first.weights) if status == "converged" else design
        sub = fit_subset(design, list(design.groups), band=hac_band)
        # the final solve is unconstrained: an estimate beyond its bounds (a gap offset over 5 mm
        # is a wrong setup, not a parameter) is reported, and the fit does not count as a success
        outside = [
            n for n, v, lo, hi in zip(design.names, sub.coef, lower, upper, strict=True) if not lo <= v <= hi
        ]
        if outside:
            status = "at_bound"
            message = (
                f"{', '.join(outside)} beyond the bounds the fit allows: check the rig's setup (encoder zero)"
            )
        return design, sub, status, message, iterations

    def _settings(self, hac_band: float, weights: np.ndarray, compensated: bool) -> dict:
        sg = self.differentiator
        return {
            "differentiator": "savitzky_golay",
            "bandwidth_hz": sg.bandwidth,
            "hac_band_hz": hac_band,
            "polyorder": sg.polyorder,
            "velocity_window": sg.velocity_window,
            "acceleration_window": sg.acceleration_window,
            "edge_samples": self.prepared.edge,
            "input_delay_s": self.input_delay,
            "axis_weights": dict(zip(AXES, weights.tolist(), strict=True)),
            "linear": self.linear,
            "terms": [t.name for t in self.terms],
            "logging_error_variance_A2": self.prepared.current_noise.tolist(),
            "errors_in_variables_compensated": compensated,
        }


def _reduced_mask(mask: np.ndarray, q: int) -> np.ndarray:
    """A sample mask of a log reduced by q-sample means: a mean is used if all its samples are."""
    if q <= 1:
        return mask
    return mask[: (mask.size // q) * q].reshape(-1, q).all(axis=1)


def refuse_left_out(prepared: PreparedLogs, estimate: Sequence[str]) -> None:
    """Refuse, naming the logs, constants to estimate on an axis the fit leaves out
    (:func:`~maglev_oc.regression.data.axes_left_out`: one held still, or one that moves but whose
    thrust current is mostly its errors), as :func:`~maglev_oc.identification.pipeline.identify`
    refuses a log that does not move. Fitted, C1 came out at 4e10 on a log whose platform moved
    +-1 mm along the track, and a gap held within 10 um ended in "LumpedConstants.C2: must be
    positive, got 0.0"."""
    for k, axis in enumerate(AXES):
        names = [c for c in estimate if CONSTANT_AXIS.get(c) == axis]
        said = [n for n in axes_left_out(prepared) if n.startswith(f"the {axis} axis")]
        if not names or prepared.moving[k] or not said:
            continue
        others = " ".join(c for c in CONSTANT_NAMES if CONSTANT_AXIS[c] != axis)
        raise LogError(
            ", ".join(prepared.sources),
            f"no excitation for identification: {', '.join(names)} need{'s' if len(names) == 1 else ''} "
            f"the {axis} axis, and {said[0]} (--estimate {others} fits the other axis's constants alone)",
        )


def _with_inputs(log: Log, u: np.ndarray) -> Log:
    import dataclasses

    return dataclasses.replace(log, u=u, notes=(*log.notes, "currents shifted by input_delay"))


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
    """Equation-error fit of ``estimate`` (and the terms' parameters) on ``logs``.

    One-off use; for several fits on the same logs (held-out blocks, cross-validation) build the
    :class:`EquationError` once.

    Parameters
    ----------
    logs, model, estimate, terms, differentiator, input_delay
        As for :class:`EquationError`.
    samples, initial, hac_band
        As for :meth:`EquationError.fit`.

    Returns
    -------
    FitResult
        Estimates with HAC standard errors; ``success``/``status`` say whether the solve
        converged (a failed solve is returned, not raised).

    Raises
    ------
    InputError
        Unknown names in ``estimate``, an invalid delay, or logs at different rates.
    """
    problem = EquationError(
        logs, model, estimate=estimate, terms=terms, differentiator=differentiator, input_delay=input_delay
    )
    return problem.fit(samples, initial=initial, hac_band=hac_band)
