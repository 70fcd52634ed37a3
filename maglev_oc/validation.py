"""Model validation to the standard of system identification tools (Ljung 1999, Sec. 16.6;
MATLAB's ``resid`` and ``compare``), on data the fit did not see.

Three checks of a fitted model:

* **Residual whiteness** (:func:`whiteness`): the autocorrelation of the prediction residuals with
  its 95 % band +-1.96 / sqrt(N) and the Ljung-Box portmanteau test (statsmodels). A model that
  explains the data leaves residuals that are white: what one residual says does not predict
  the next.
* **Independence from past inputs** (:func:`independence`): the cross-correlation of the
  residuals with the currents k windows earlier, k = 0..K, with the same band. A residual that
  correlates with a past current means the model gets that current's effect wrong. Only past
  and present inputs are tested: under feedback the residual drives future currents.
* **Fit percentage** (:func:`fit_percent`): ``100 (1 - |y - yhat| / |y - mean(y)|)``, the System
  Identification Toolbox's NRMSE fit, of the simulated against the measured position over
  horizons up to seconds (:func:`simulation_fit`, like 002 Fig. 7).

The residuals (:func:`prediction_residuals`, on the one window simulator :func:`simulate_windows`,
which the diagnosis's output error uses too) are k-step-ahead prediction errors: each axis
simulated with the logged currents over ``horizon`` from the estimated state (the other axis's
measured state an input), the position error at the window's end. Windows start every
``horizon`` plus one differentiator window, so no two windows, nor a window and the next one's
initial state, share a sample: for a correct model the residuals are then independent, and
their autocorrelation says something about the model rather than about overlapping windows or
the smoother. (Every-sample predictions are MA(k-1) by construction and always fail.)

The gap is open-loop unstable (30-64 1/s), so its simulation over seconds with the logged
currents diverges whatever the constants; its long-horizon fit is reported as diverged and only
the short horizons say something. The horizontal axis is a double integrator driven by the
currents and simulates for seconds.

:func:`validate` runs all three on the held-out samples of prepared logs and returns a
:class:`Validation` (``to_dict()`` for the JSON, plain words in each verdict). Computing only: the
figures are in :mod:`maglev_oc.reporting.validation_plots`.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np
from scipy.stats import norm
from statsmodels.stats.diagnostic import acorr_ljungbox
from statsmodels.tsa.stattools import acf, ccf

from maglev_oc.errors import InputError
from maglev_oc.model.stage import StageModel
from maglev_oc.numerics import NumpyCall, rk4_step
from maglev_oc.regression.data import PreparedLogs
from maglev_oc.regression.payload import loaded
from maglev_oc.regression.terms import when_symbol
from maglev_oc.results import AXES, Result, jsonable

__all__ = [
    "DEFAULT_FIT_HORIZONS",
    "DEFAULT_HORIZON",
    "DEFAULT_LAGS",
    "INPUT_NAMES",
    "FitPercent",
    "Independence",
    "Validation",
    "Whiteness",
    "fit_percent",
    "independence",
    "prediction_residuals",
    "simulate_windows",
    "simulation_fit",
    "validate",
    "whiteness",
    "window_starts",
]

DEFAULT_HORIZON = 0.02
"""[s] Prediction horizon of the residuals: 20 samples at 1 kHz. Long enough that a wrong
constant shows above the encoder's 10 um (a 20 % error in C1 gives ~25 um on the papers'
excitation), short enough that the vertical mode (e^0.6-e^1.3) does not blow up the
initial-state error."""
DEFAULT_LAGS = 10
"""Lags of the autocorrelation and cross-correlation (in windows) and of the Ljung-Box test."""
DEFAULT_FIT_HORIZONS = (0.1, 1.0, 5.0)
"""[s] Horizons of the simulation fit (the held-out block tiled by windows of each length)."""
INPUT_NAMES = ("i_q", "i_d")
ALPHA = 0.05
"""Level of every test (95 % bands)."""
DIVERGED = 0.1
"""[m] A simulated position this far from the measured one has left the stage: diverged."""


# --- the three tests on plain arrays ---------------------------------------------------------------------
@dataclass(frozen=True)
class Whiteness:
    """Autocorrelation of a residual series and the Ljung-Box test of whiteness.

    Attributes
    ----------
    lags : (K,) int, 1..K
    acf : (K,) autocorrelation at those lags
    band : float
        Half-width of the 95 % band of a white sequence, 1.96 / sqrt(n).
    outside : int
        Lags outside the band (about 5 % of them for a white sequence).
    ljung_box : float
        Q = n (n + 2) sum_k acf_k^2 / (n - k) over the K lags.
    p_value : float
        P(chi^2_K > Q); small means not white.
    n : int
        Residuals used.
    white : bool
        ``p_value >= alpha``.
    verdict : str
    """

    lags: np.ndarray
    acf: np.ndarray
    band: float
    outside: int
    ljung_box: float
    p_value: float
    n: int
    white: bool
    verdict: str

    def to_dict(self) -> dict[str, Any]:
        return jsonable(
            {
                "lags": self.lags,
                "acf": self.acf,
                "band_95": self.band,
                "lags_outside_band": self.outside,
                "ljung_box_q": self.ljung_box,
                "p_value": self.p_value,
                "n": self.n,
                "white": self.white,
                "verdict": self.verdict,
            }
        )


def whiteness(
    residual: np.ndarray, lags: int = DEFAULT_LAGS, *, alpha: float = ALPHA, lag_time: float | None = None
) -> Whiteness:
    """Autocorrelation of ``residual`` at lags 1..``lags`` with the band +-z / sqrt(n), and the
    Ljung-Box test over those lags (statsmodels' ``acf`` and ``acorr_ljungbox``).

    ``lag_time`` [s], the spacing of the residuals, only makes the verdict speak in seconds.
    """
    e = _series(residual, "residual")
    if not 1 <= lags < e.size - 1:
        raise InputError(f"lags must be in [1, {e.size - 2}] for {e.size} residuals, got {lags!r}")
    r = acf(e, nlags=lags, fft=True)[1:]
    band = float(norm.ppf(1 - alpha / 2) / math.sqrt(e.size))
    lb = acorr_ljungbox(e, lags=[lags])
    q, p = float(lb["lb_stat"].iloc[0]), float(lb["lb_pvalue"].iloc[0])
    outside = int(np.sum(np.abs(r) > band))
    white = bool(p >= alpha)
    span = f" ({lags * lag_time:.3g} s)" if lag_time else ""
    words = (
        "white: nothing in one residual predicts the next"
        if white
        else "not white: the residuals are correlated in time, so the model leaves structure in them"
    )
    verdict = (
        f"{words} (Ljung-Box p = {p:.2g} over {lags} lags{span}; {outside} of {lags} lags outside "
        f"the 95 % band +-{band:.2f})"
    )
    return Whiteness(
        np.arange(1, lags + 1), np.asarray(r, float), band, outside, q, p, e.size, white, verdict
    )


@dataclass(frozen=True)
class Independence:
    """Cross-correlation of a residual series with past inputs.

    Attributes
    ----------
    inputs : tuple of str
    lags : (K+1,) int, 0..K: the input ``lag`` samples earlier than the residual
    ccf : (m, K+1) correlation of residual(t) with input_i(t - lag)
    band : float
        Half-width of the pointwise 95 % band, 1.96 / sqrt(n) (exact for a white residual
        independent of the input, whatever the input's spectrum).
    threshold : float
        The band corrected for the m (K+1) lags tested together (Bonferroni): the test rejects
        when any |ccf| exceeds it.
    worst_input, worst_lag, worst_ccf
        Where |ccf| is largest.
    independent : bool
    verdict : str
    """

    inputs: tuple[str, ...]
    lags: np.ndarray
    ccf: np.ndarray
    band: float
    threshold: float
    worst_input: str
    worst_lag: int
    worst_ccf: float
    n: int
    independent: bool
    verdict: str

    def to_dict(self) -> dict[str, Any]:
        return jsonable(
            {
                "inputs": list(self.inputs),
                "lags": self.lags,
                "ccf": {name: self.ccf[i] for i, name in enumerate(self.inputs)},
                "band_95": self.band,
                "threshold_all_lags": self.threshold,
                "worst": {"input": self.worst_input, "lag": self.worst_lag, "ccf": self.worst_ccf},
                "n": self.n,
                "independent": self.independent,
                "verdict": self.verdict,
            }
        )


def independence(
    residual: np.ndarray,
    inputs: np.ndarray,
    lags: int = DEFAULT_LAGS,
    *,
    names: Sequence[str] = INPUT_NAMES,
    alpha: float = ALPHA,
    lag_time: float | None = None,
) -> Independence:
    """Cross-correlation of ``residual`` (n,) with each row of ``inputs`` (m, n) at lags 0..``lags``
    (statsmodels' ``ccf``: corr(residual(t), input(t - k))), with the band +-z / sqrt(n).

    The verdict rejects independence when any |ccf| exceeds the band widened for the m (K+1)
    tests (Bonferroni, so a white residual passes 95 % of the time).
    """
    e = _series(residual, "residual")
    u = np.atleast_2d(np.asarray(inputs, dtype=float))
    names = tuple(names)[: u.shape[0]]
    if u.shape[1] != e.size or len(names) != u.shape[0]:
        raise InputError(f"inputs must be (m, {e.size}) with m names, got {u.shape} and {names!r}")
    if not 0 <= lags < e.size - 1:
        raise InputError(f"lags must be in [0, {e.size - 2}] for {e.size} residuals, got {lags!r}")
    rows = []
    for row in u:
        if not np.all(np.isfinite(row)):
            raise InputError("inputs must be finite")
        if np.std(row) == 0:
            rows.append(np.zeros(lags + 1))  # a constant input cannot correlate
        else:
            rows.append(ccf(e, row, adjusted=False, nlags=lags + 1))
    c = np.asarray(rows, dtype=float)
    band = float(norm.ppf(1 - alpha / 2) / math.sqrt(e.size))
    threshold = float(norm.ppf(1 - alpha / (2 * c.size)) / math.sqrt(e.size))
    i, k = np.unravel_index(int(np.argmax(np.abs(c))), c.shape)
    worst = float(c[i, k])
    ok = bool(abs(worst) <= threshold)
    when = ""
    if lag_time:
        when = " (the same window)" if k == 0 else f" ({k * lag_time:.3g} s earlier)"
    if ok:
        verdict = (
            f"independent of the past currents: no cross-correlation beyond +-{threshold:.2f} "
            f"(largest {worst:+.2f}, {names[i]} at lag {k})"
        )
    else:
        verdict = (
            f"not independent: the residual correlates with {names[i]} at lag {k}{when} "
            f"({worst:+.2f}, beyond +-{threshold:.2f}), so the model gets that current's effect wrong"
        )
    return Independence(
        names, np.arange(lags + 1), c, band, threshold, names[i], int(k), worst, e.size, ok, verdict
    )


def fit_percent(measured: np.ndarray, simulated: np.ndarray) -> np.ndarray:
    """NRMSE fit [%] per row: 100 (1 - |y - yhat| / |y - mean(y)|) over the last axis (the
    System Identification Toolbox's ``compare``). 100 for a perfect model, 0 for the mean, below 0
    for worse than the mean; -inf where the simulation is not finite, NaN where y is constant."""
    y = np.asarray(measured, dtype=float)
    yh = np.asarray(simulated, dtype=float)
    if y.shape != yh.shape:
        raise InputError(f"measured and simulated shapes differ: {y.shape} vs {yh.shape}")
    num = np.linalg.norm(y - yh, axis=-1)
    den = np.linalg.norm(y - np.mean(y, axis=-1, keepdims=True), axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        fit = 100.0 * (1.0 - num / den)
    fit = np.where(np.isfinite(num), fit, -np.inf)
    return np.where(den > 0, fit, np.nan)


def _series(a: np.ndarray, what: str) -> np.ndarray:
    e = np.asarray(a, dtype=float)
    if e.ndim != 1 or e.size < 4:
        raise InputError(f"{what} must be a 1-D series of at least 4 values, got shape {e.shape}")
    if not np.all(np.isfinite(e)):
        raise InputError(f"{what} has {int(np.sum(~np.isfinite(e)))} non-finite values")
    return e


# --- the model against logs ------------------------------------------------------------------------------
def window_starts(data: PreparedLogs, mask: np.ndarray, horizon: int, stride: int) -> np.ndarray:
    """Samples k of ``mask`` (every ``stride``-th) whose window k..k+horizon stays in ``mask`` and in
    one log."""
    idx = np.flatnonzero(mask)[::stride]
    end = idx + horizon
    ok = end < data.n
    idx, end = idx[ok], end[ok]
    return idx[mask[end] & (data.segment[end] == data.segment[idx])]


def simulate_windows(
    data: PreparedLogs,
    starts: np.ndarray,
    horizon: int,
    model,
    terms: Sequence[tuple] = (),
    *,
    axis: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The model simulated ``horizon`` samples from the estimated state at each of ``starts``
    with the logged currents (RK4 per sample, zero-order hold).

    Parameters
    ----------
    data : PreparedLogs
    starts : (w,) int array
        First samples of the windows (see :func:`window_starts`).
    horizon : int
        Samples per window.
    model : StageModel
    terms : sequence of (AccelerationTerm, coefficients)
        Extra accelerations added to the model's.
    axis : None, 0 or 1
        None: both axes simulated together. 0 (vertical) or 1 (horizontal): that axis alone, the
        other axis's estimated position and rate taken from the data (its model errors then do
        not reach this axis).

    Returns
    -------
    simulated, measured : (4, w, horizon) arrays
        States at samples k+1..k+horizon of each window (the other axis's rows, with ``axis``
        given, are the data's); NaN where the simulation left the model's domain.
    """
    ts = data.sample_time
    x, u, du, other = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("du", 2), ca.SX.sym("o", 2)
    place = when_symbol()  # the place in the log and the log, for a term that changes over it
    load = ca.SX.sym("load", 2)  # M / (M + m) of a log that declares a payload m (ones otherwise)
    if axis is None:
        xx = x
    else:
        own = slice(2 * axis, 2 * axis + 2)
        rows = [x[0], x[1], x[2], x[3]]
        rows[2 * (1 - axis)], rows[2 * (1 - axis) + 1] = other[0], other[1]
        xx = ca.vertcat(*rows)
    acc = model.f(xx, u)[[1, 3]]
    for term, coef in terms:
        acc = acc + term.acceleration_in_time(coef)(xx, u, du, place)
    if data.load_factor is not None:  # (without a payload, the model's arithmetic untouched)
        acc = loaded(acc, load, model.params.gravity)
    rhs = ca.vertcat(xx[1], acc[0], xx[3], acc[1])
    if axis is not None:
        keep = ca.SX.zeros(4)
        keep[own] = rhs[own]
        rhs = keep
    f = ca.Function("f", [x, u, du, other, place, load], [rhs])
    # common subexpressions merged: the four stages share the model's magnet field and
    # coefficients (a quarter to a third fewer instructions over every window; the same values)
    step = ca.Function(
        "rk4",
        [x, u, du, other, place, load],
        [rk4_step(f, x, ts, u, du, other, place, load)],
        {"cse": True},
    )
    sim = step.mapaccum("window", horizon)
    starts = np.asarray(starts, dtype=int)
    w = starts.size
    if w == 0:
        empty = np.full((4, 0, horizon), np.nan)
        return empty, empty.copy()
    take = (starts[:, None] + np.arange(horizon)[None, :]).ravel()  # samples k..k+h-1, window-major
    x0 = data.x[:, starts]
    o = 2 * (1 - axis) if axis is not None else 0
    traj = NumpyCall(sim.map(w))(
        x0,
        data.u[:, take],
        data.du[:, take],
        data.x[o : o + 2, take + 1],
        data.log_time[:, take],
        data.load_factors[:, take],
    )[0]
    traj = np.asarray(traj).reshape(4, w, horizon)
    measured = data.x[:, take + 1].reshape(4, w, horizon)
    if axis is not None:
        traj[o : o + 2] = measured[o : o + 2]
    traj[:, ~np.all(np.isfinite(traj), axis=(0, 2)), :] = np.nan
    return traj, measured


@dataclass(frozen=True)
class FitPercent:
    """Fit [%] of the simulated against the measured position at one horizon, per axis."""

    horizon: float  # [s]
    windows: int
    fit: Mapping[str, float]  # axis -> %, -inf when diverged, NaN when the axis does not move
    verdict: Mapping[str, str]
    t: np.ndarray = field(repr=False)  # (n,) [s] times of the first window, for a plot
    measured: np.ndarray = field(repr=False)  # (2, n) [m]
    simulated: np.ndarray = field(repr=False)  # (2, n) [m]

    def to_dict(self) -> dict[str, Any]:
        return {
            "horizon_s": float(self.horizon),
            "windows": int(self.windows),
            "fit_percent": {a: _fit_json(v) for a, v in self.fit.items()},
            "verdict": dict(self.verdict),
        }


def _fit_json(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def prediction_residuals(
    data: PreparedLogs,
    mask: np.ndarray,
    model: StageModel,
    terms: Sequence[tuple] = (),
    *,
    horizon: float = DEFAULT_HORIZON,
    gap_offset: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, float]:
    """k-step-ahead position residuals per axis on the samples of ``mask``.

    Returns ``(residuals (2, w) [m], inputs (2, w) [A], spacing [s])``: the measured minus the
    predicted position at the end of w non-overlapping windows (each axis simulated alone), the
    mean currents over each window, and the windows' spacing. ``gap_offset`` [m] is the true gap
    minus the reading (as estimated by ``identify``).
    """
    ts = data.sample_time
    h = max(1, round(horizon / ts))
    stride = h + data.differentiator.velocity_window
    data = _shifted(data, gap_offset)
    starts = window_starts(data, mask, h, stride)
    res = np.full((2, starts.size), np.nan)
    for a in range(2):
        sim, meas = simulate_windows(data, starts, h, model, terms, axis=a)
        res[a] = meas[2 * a, :, -1] - sim[2 * a, :, -1]
    take = starts[:, None] + np.arange(h)[None, :]
    inputs = data.u[:, take].mean(axis=2)
    return res, inputs, stride * ts


def simulation_fit(
    data: PreparedLogs,
    mask: np.ndarray,
    model: StageModel,
    terms: Sequence[tuple] = (),
    *,
    horizon: float = 1.0,
    gap_offset: float = 0.0,
) -> FitPercent:
    """Fit [%] per axis of the model simulated with the logged currents (each axis alone, the
    other's measured state an input) over back-to-back windows of ``horizon`` tiling ``mask``,
    restarted from the estimated state at each window."""
    ts = data.sample_time
    h = max(1, round(horizon / ts))
    data = _shifted(data, gap_offset)
    starts = window_starts(data, mask, h, h)
    fits, verdicts = {}, {}
    sims, meass = [], []
    for a, axis in enumerate(AXES):
        sim, meas = simulate_windows(data, starts, h, model, terms, axis=a)
        y, yh = meas[2 * a], sim[2 * a]
        diverged = ~np.isfinite(yh) | (np.abs(yh - y) > DIVERGED)
        yh = np.where(diverged, np.inf, yh)
        sims.append(yh[0] if starts.size else np.zeros(0))
        meass.append(y[0] if starts.size else np.zeros(0))
        if starts.size == 0:
            fits[axis], verdicts[axis] = math.nan, f"no held-out stretch of {horizon:g} s"
            continue
        if not data.moving[a]:
            fits[axis], verdicts[axis] = math.nan, "the axis does not move in the logs"
            continue
        fit = float(fit_percent(y.ravel(), yh.ravel()))
        fits[axis] = fit
        share = float(np.mean(np.any(diverged, axis=1)))
        if not math.isfinite(fit):
            why = " (the gap is open-loop unstable)" if a == 0 else ""
            verdicts[axis] = (
                f"diverged: {100 * share:.0f} % of the {horizon:g} s simulations left the stage{why}"
            )
        else:
            verdicts[axis] = f"{_fit_words(fit)}: fit {fit:.1f} % over {starts.size} windows of {horizon:g} s"
    t = np.arange(1, h + 1) * ts
    return FitPercent(horizon, int(starts.size), fits, verdicts, t, np.array(meass), np.array(sims))


def _fit_words(fit: float) -> str:
    if fit >= 90:
        return "follows the measurement"
    if fit >= 50:
        return "follows the trend only"
    return "does not follow the measurement"


def _shifted(data: PreparedLogs, gap_offset: float) -> PreparedLogs:
    """``data`` with the true gap (reading + offset) in x1; the same object when the offset is 0."""
    if not gap_offset:
        return data
    x = data.x.copy()
    x[0] += gap_offset
    return dataclasses.replace(data, x=x)


# --- the result ------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Validation(Result):
    """Validation of one model on one set of samples (see the module doc).

    Attributes
    ----------
    model : str
        What was validated (in words).
    data : str
        Which samples (``"held-out"``, or why not).
    horizon : float
        [s] Prediction horizon of the residuals.
    spacing : float
        [s] Time between successive residuals (one lag).
    residuals, inputs : (2, w) arrays
        Prediction residuals [m] per axis and the mean currents [A] over each window.
    whiteness : mapping axis -> Whiteness (axes that move and have enough residuals)
    independence : mapping axis -> Independence
    fits : tuple of FitPercent, one per horizon
    success, status, message, timings
        ``status``: ``"valid"`` (white and independent on every moving axis), ``"invalid"`` or
        ``"not_enough_data"``.
    """

    model: str
    data: str
    horizon: float
    spacing: float
    residuals: np.ndarray = field(repr=False)
    inputs: np.ndarray = field(repr=False)
    whiteness: Mapping[str, Whiteness]
    independence: Mapping[str, Independence]
    fits: tuple[FitPercent, ...]
    success: bool
    status: str
    message: str
    timings: Mapping[str, float] = field(default_factory=dict)

    def fit_table(self) -> dict[str, dict[float, float]]:
        """axis -> {horizon [s]: fit [%]}."""
        return {a: {f.horizon: f.fit[a] for f in self.fits} for a in AXES}

    def to_dict(self) -> dict[str, Any]:
        rms = {
            a: (float(np.sqrt(np.mean(self.residuals[i] ** 2))) if self.residuals.shape[1] else None)
            for i, a in enumerate(AXES)
        }
        return jsonable(
            {
                "model": self.model,
                "data": self.data,
                "residuals": "k-step-ahead prediction errors of the position [m]: each axis simulated "
                f"alone with the logged currents over {self.horizon:g} s from the estimated state, "
                f"non-overlapping windows {self.spacing:g} s apart (one lag)",
                "horizon_s": self.horizon,
                "lag_s": self.spacing,
                "n_residuals": int(self.residuals.shape[1]),
                "residual_rms_m": rms,
                "whiteness": {a: w.to_dict() for a, w in self.whiteness.items()},
                "input_independence": {a: c.to_dict() for a, c in self.independence.items()},
                "fit_metric": "100 (1 - |y - yhat| / |y - mean(y)|) of the simulated against the measured "
                "position, per axis, over back-to-back windows of each horizon restarted from the "
                "estimated state (null: diverged or the axis does not move)",
                "fit": [f.to_dict() for f in self.fits],
                "success": self.success,
                "status": self.status,
                "message": self.message,
                "timings": dict(self.timings),
            }
        )


def validate(
    data: PreparedLogs,
    mask: np.ndarray,
    model: StageModel,
    terms: Sequence[tuple] = (),
    *,
    description: str = "model",
    data_description: str = "held-out",
    horizon: float = DEFAULT_HORIZON,
    lags: int = DEFAULT_LAGS,
    fit_horizons: Sequence[float] = DEFAULT_FIT_HORIZONS,
    gap_offset: float = 0.0,
) -> Validation:
    """Whiteness, independence from past currents and fit % of ``model`` (plus ``terms``, pairs
    (AccelerationTerm, coefficients)) on the samples of ``mask`` (the held-out block).

    Parameters
    ----------
    data : PreparedLogs
    mask : (n,) bool
        Samples to validate on.
    model : StageModel
    terms : sequence of (AccelerationTerm, coefficients)
    description, data_description : str
        Words for the result: what model, which data.
    horizon : float
        [s] Prediction horizon of the residuals (:data:`DEFAULT_HORIZON`).
    lags : int
        Lags of the correlations and the Ljung-Box test.
    fit_horizons : sequence of float
        [s] Horizons of the simulation fits.
    gap_offset : float
        [m] True gap minus the reading.
    """
    t0 = time.perf_counter()
    mask = np.asarray(mask, dtype=bool)
    if mask.shape != (data.n,):
        raise InputError(f"mask must be a boolean array of shape ({data.n},), got {mask.shape}")
    res, inputs, spacing = prediction_residuals(
        data, mask, model, terms, horizon=horizon, gap_offset=gap_offset
    )
    t1 = time.perf_counter()
    white, indep, failed = {}, {}, []
    for a, axis in enumerate(AXES):
        e = res[a]
        if not data.moving[a] or e.size < 3 * lags or not np.all(np.isfinite(e)):
            continue
        white[axis] = whiteness(e, lags, lag_time=spacing)
        indep[axis] = independence(e, inputs, lags, lag_time=spacing)
        if not (white[axis].white and indep[axis].independent):
            failed.append(axis)
    t2 = time.perf_counter()
    fits = tuple(
        simulation_fit(data, mask, model, terms, horizon=h, gap_offset=gap_offset) for h in fit_horizons
    )
    timings = {
        "residuals": t1 - t0,
        "correlations": t2 - t1,
        "fits": time.perf_counter() - t2,
        "total": time.perf_counter() - t0,
    }
    if not white:
        status = "not_enough_data"
        message = (
            f"{res.shape[1]} prediction residuals on the moving axes: need at least {3 * lags} "
            f"({3 * lags * spacing:.3g} s of {data_description} data)"
        )
    elif failed:
        status = "invalid"
        message = (
            f"the residuals of the {' and '.join(failed)} axis are not white or not independent "
            "of the currents"
        )
    else:
        status = "valid"
        message = "the residuals are white and independent of the past currents on every moving axis"
    return Validation(
        description,
        data_description,
        float(horizon),
        float(spacing),
        res,
        inputs,
        white,
        indep,
        fits,
        status == "valid",
        status,
        message,
        timings,
    )
