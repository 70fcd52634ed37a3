"""What the residual depends on: the evidence that points from a residual to an effect.

Analyses of an acceleration residual (per axis) against the signals that physical effects
depend on:

* the spatial spectrum over the horizontal position x3 (least-squares periodogram: the share of
  the residual's variance a sinusoid of period lambda in x3 explains), with the motor's physical
  periods marked — the slot pitch t1, 2 t1 (000 eq. (9)), the pole pitch tau and 2 tau;
* the mean residual against the gap, the velocity of each axis (a step at zero velocity is
  Coulomb friction, a slope viscous), the horizontal position (a ramp is a spring or a tilt);
* the cross-correlation with the rate of the commanded currents at lags up to 20 ms (a current
  lag or delay correlates with di/dt).

The periodogram's peaks that match no motor period become data-driven candidates
(guide waviness at the found period).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from maglev_oc.model.parameters import StageParameters
from maglev_oc.results import AXES

__all__ = ["Binned", "Trace", "motor_periods", "trace", "traces", "unexplained_periods"]


@dataclass(frozen=True)
class Binned:
    """Mean residual (and its standard error) in bins of a variable."""

    variable: str
    unit: str
    centers: np.ndarray  # (b,)
    mean: np.ndarray  # (2, b) per axis [m/s^2]
    stderr: np.ndarray  # (2, b)
    count: np.ndarray  # (b,)


@dataclass(frozen=True)
class Trace:
    periods: np.ndarray  # (m,) [m]
    spectrum: np.ndarray  # (2, m) variance share explained per period
    motor_periods: dict[str, float]  # name -> [m]
    peaks: list[tuple[str, float, float]]  # (axis, period [m], share)
    binned: dict[str, Binned]  # "gap", "gap_rate", "position", "position_rate"
    lags: np.ndarray  # (l,) [s]
    lag_correlation: np.ndarray  # (2, l) correlation of residual with di/dt (own axis)


def motor_periods(params: StageParameters) -> dict[str, float]:
    t1, tau = params.slot_pitch, params.pole_pitch
    return {"slot_pitch": t1, "twice_slot_pitch": 2 * t1, "pole_pitch": tau, "twice_pole_pitch": 2 * tau}


def _spatial_periodogram(x3: np.ndarray, residual: np.ndarray, periods: np.ndarray) -> np.ndarray:
    """Share of each row of ``residual`` (r, n) explained by a sinusoid in ``x3`` per period (each
    row's value does not depend on the other rows): the least-squares fit of a centred sine and
    cosine, share = rhs' G^-1 rhs / |r|^2 with its 2 x 2 Gram G solved in closed form (zero where
    G is singular)."""
    r = residual - residual.mean(axis=1, keepdims=True)
    total = np.maximum(np.sum(r**2, axis=1), 1e-30)
    n = x3.size
    out = np.zeros((r.shape[0], periods.size))
    # the phases, sines and cosines in single precision: NumPy's float32 sin and cos are vectorised
    # (about 20x faster than float64's, which were most of a trace's cost); at 40 mm from the
    # centre a 4 mm period's phase is 63 rad, and it errs by about 1e-5 rad: far below what a share of 0.02
    # (``min_share``) or a peak between neighbouring periods 1.2 % apart can notice. The sums
    # below are in double precision.
    x32 = x3.astype(np.float32)
    wavenumber = (2 * math.pi / periods).astype(np.float32)
    for start in range(0, periods.size, _PERIODS_AT_ONCE):
        arg = np.multiply.outer(wavenumber[start : start + _PERIODS_AT_ONCE], x32)
        sin, cos = np.sin(arg).astype(float), np.cos(arg).astype(float)
        ms, mc = sin.sum(axis=1) / n, cos.sum(axis=1) / n
        # the centred basis's Gram (sums about the means) and its products with the (centred) rows
        ss = np.einsum("kn,kn->k", sin, sin) - n * ms * ms
        cc = np.einsum("kn,kn->k", cos, cos) - n * mc * mc
        sc = np.einsum("kn,kn->k", sin, cos) - n * ms * mc
        # (k, rows), row by row (a matrix-vector product each: a row's sums do not depend on how
        # many rows are traced together, to the bit)
        rs = np.stack([sin @ row for row in r], axis=1)
        rc = np.stack([cos @ row for row in r], axis=1)
        det = ss * cc - sc * sc
        ok = det > 1e-12 * np.maximum(ss * cc, 1e-300)
        q = (cc[:, None] * rs * rs - 2 * sc[:, None] * rs * rc + ss[:, None] * rc * rc) / np.where(
            ok, det, 1.0
        )[:, None]
        out[:, start : start + arg.shape[0]] = np.where(ok[:, None], q, 0.0).T / total[:, None]
    return out


_PERIODS_AT_ONCE = 25
"""Periods of :func:`_spatial_periodogram` evaluated together (25 x 45 000 samples: 9 MB a basis)."""


def _binned(variable: str, unit: str, v: np.ndarray, residual: np.ndarray, edges: np.ndarray) -> Binned:
    idx = np.clip(np.digitize(v, edges) - 1, 0, edges.size - 2)
    b = edges.size - 1
    mean = np.full((2, b), np.nan)
    se = np.full((2, b), np.nan)
    count = np.bincount(idx, minlength=b)
    for k in range(b):
        sel = idx == k
        if count[k] >= 20:
            mean[:, k] = residual[:, sel].mean(axis=1)
            se[:, k] = residual[:, sel].std(axis=1) / math.sqrt(count[k])
    return Binned(variable, unit, 0.5 * (edges[:-1] + edges[1:]), mean, se, count)


def trace(
    x: np.ndarray,
    du: np.ndarray,
    residual: np.ndarray,
    params: StageParameters,
    sample_time: float,
    *,
    min_share: float = 0.02,
) -> Trace:
    """Analyse ``residual`` (2, n) at states ``x`` (4, n) and current rates ``du`` (2, n)."""
    return traces(x, du, [residual], params, sample_time, min_share=min_share)[0]


def traces(
    x: np.ndarray,
    du: np.ndarray,
    residuals: Sequence[np.ndarray],
    params: StageParameters,
    sample_time: float,
    *,
    min_share: float = 0.02,
) -> list[Trace]:
    """:func:`trace` of each of ``residuals`` (each (2, n), at the same samples): their spatial
    spectra in one pass over the periods (the sines of the position, most of a trace's cost, are
    computed once for all; each residual's values are those of its own trace)."""
    span = float(np.ptp(x[2]))
    hi = max(min(1.5 * span, 0.15), 0.01)
    periods = np.geomspace(4e-3, hi, 300)
    stacked = _spatial_periodogram(x[2], np.vstack(residuals), periods)
    return [
        _trace(x, du, residual, params, sample_time, periods, stacked[2 * k : 2 * k + 2].copy(), min_share)
        for k, residual in enumerate(residuals)
    ]


def _trace(x, du, residual, params, sample_time, periods, spec, min_share) -> Trace:
    mp = motor_periods(params)
    peaks = []
    for a in range(2):
        s = spec[a]
        for j in np.argsort(s)[::-1][:40]:
            if s[j] < min_share:
                break
            if 0 < j < s.size - 1 and s[j] >= s[j - 1] and s[j] >= s[j + 1]:
                peaks.append((AXES[a], float(periods[j]), float(s[j])))
    binned = {}
    for name, unit, v in (
        ("gap", "m", x[0]),
        ("gap_rate", "m/s", x[1]),
        ("position", "m", x[2]),
        ("position_rate", "m/s", x[3]),
    ):
        lo, up = np.percentile(v, [1, 99])
        if name.endswith("rate"):
            m = max(abs(lo), abs(up))
            edges = np.linspace(-m, m, 25)
        else:
            edges = np.linspace(lo, up, 21)
        binned[name] = _binned(name, unit, v, residual, edges)
    n_lag = round(0.02 / sample_time)
    lags = np.arange(-n_lag, n_lag + 1)
    corr = np.zeros((2, lags.size))
    for a, ia in ((0, 1), (1, 0)):  # vertical with di_d/dt, horizontal with di_q/dt
        r = residual[a] - residual[a].mean()
        d = du[ia] - du[ia].mean()
        denom = math.sqrt(float(r @ r) * float(d @ d)) or 1.0
        for k, lag in enumerate(lags):
            if lag >= 0:
                corr[a, k] = float(r[lag:] @ d[: d.size - lag]) / denom
            else:
                corr[a, k] = float(r[:lag] @ d[-lag:]) / denom
    return Trace(periods, spec, mp, peaks, binned, lags * sample_time, corr)


def unexplained_periods(
    tr: Trace,
    *,
    tolerance: float = 0.015,
    max_per_axis: int = 1,
    on_axis: Mapping[str, Sequence[float]] | None = None,
) -> list[tuple[str, float]]:
    """Periodogram peaks (axis, period) that match no motor period or its harmonics within
    ``tolerance``: candidates for guide waviness.

    ``on_axis``: axis -> the periods [m] a force on that axis can explain (the library's
    periodic candidates there); a peak is then set aside only for those of its own axis. Without
    it every motor period counts on both axes, though the library has no force at twice the slot
    pitch on the horizontal axis, nor at the pole pitch on the vertical one: a 40 mm guide
    waviness's horizontal peak (39 mm) was set aside as twice the slot pitch, and its vertical
    part went to a 38 mm normal cogging."""
    motor = list(tr.motor_periods.values())
    out: dict[str, list[tuple[float, float]]] = {}
    for axis, lam, share in sorted(tr.peaks, key=lambda p: -p[2]):
        near = motor if on_axis is None else on_axis.get(axis, ())
        if any(abs(lam / m - 1) < tolerance for m in near):
            continue
        out.setdefault(axis, [])
        if len(out[axis]) < max_per_axis:
            out[axis].append((lam, share))
    return [(axis, lam) for axis, items in out.items() for lam, _ in items]
