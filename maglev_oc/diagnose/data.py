"""Logs prepared for the diagnosis: states, accelerations, a held-out block, one common filter.

The diagnosis regresses the measured accelerations on the model's terms (an equation error).
Accelerations come from zero-phase Savitzky-Golay differentiation of the encoder readings
(:mod:`maglev_oc.estimation.differentiate`); the regressors are evaluated at the estimated
states. Both sides then pass through the *same* zero-phase low-pass (Butterworth, applied
forwards and backwards): the model is linear in its parameters, so filtering commutes with it,
and the regression compares like with like (unfiltered regressors would carry the currents'
high-frequency content that the acceleration estimate has lost).

Held out: a contiguous block at the end of each log (``holdout_fraction``), separated from the
fitting part by guard bands as long as the filters' memory, so no sample of one block leaks
into the other.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, sosfiltfilt

from maglev_oc.data.logs import Log, LogError
from maglev_oc.estimation.differentiate import SavitzkyGolay

DEFAULT_BANDWIDTH = 30.0
"""Savitzky-Golay derivative bandwidth [Hz]: flat to 1 % up to here."""
DEFAULT_LOWPASS = 12.0
"""Common low-pass corner [Hz] applied to accelerations and regressors alike (well inside the
differentiator's flat band, above the excitation and the spatial frequencies of interest:
a 19 mm period passed at 0.2 m/s is 10 Hz)."""
MIN_DURATION = 10.0
"""Shortest log [s] the diagnosis accepts: a held-out block of a quarter needs a few seconds."""
MAX_RATE = 1000.0
"""Logs faster than this [Hz] are reduced to it by block means (an anti-aliasing filter that
is flat to 1 % up to 55 Hz at 1 kHz): the effects of interest live below 30 Hz, and the
regression's memory grows with the number of samples."""
MOTION = 50e-6
"""An axis whose position varies by less than this (standard deviation, 5 encoder counts) is
taken as locked (stoppers) and left out of the regression."""


@dataclass(frozen=True)
class DiagnosisData:
    """Concatenated, prepared signals of one or more logs. Arrays are (rows, n)."""

    t: np.ndarray  # (n,) time within its log [s]
    segment: np.ndarray  # (n,) index of the log each sample comes from
    x: np.ndarray  # (4, n) gap [m], gap rate [m/s] (SG), position [m], rate [m/s] (SG)
    u: np.ndarray  # (2, n) commanded currents (i_q, i_d) [A]
    du: np.ndarray  # (2, n) their rates [A/s] (SG)
    acc: np.ndarray  # (2, n) measured accelerations (x2', x4') [m/s^2], low-passed
    train: np.ndarray  # (n,) bool: fitting block
    holdout: np.ndarray  # (n,) bool: held-out block
    sample_time: float  # [s]
    moving: tuple[bool, bool]  # (vertical, horizontal) axis moved in the logs
    sources: tuple[str, ...]
    sos: np.ndarray  # the common low-pass (second-order sections)
    settings: dict

    @property
    def n(self) -> int:
        return self.t.size

    def lowpass(self, columns: np.ndarray) -> np.ndarray:
        """The common zero-phase low-pass applied to each row of ``columns`` (k, n), per log."""
        columns = np.atleast_2d(np.asarray(columns, dtype=float))
        out = np.empty_like(columns)
        for s in np.unique(self.segment):
            idx = self.segment == s
            out[:, idx] = sosfiltfilt(self.sos, columns[:, idx], axis=1)
        return out


def prepare(
    logs: Sequence[Log],
    *,
    holdout_fraction: float = 0.25,
    bandwidth: float = DEFAULT_BANDWIDTH,
    lowpass_hz: float = DEFAULT_LOWPASS,
    min_duration: float = MIN_DURATION,
) -> DiagnosisData:
    """Differentiate, filter and split ``logs`` (all at the same sample rate)."""
    if not logs:
        raise ValueError("no logs given")
    if not 0.05 <= holdout_fraction <= 0.5:
        raise ValueError(f"holdout_fraction must be in [0.05, 0.5], got {holdout_fraction!r}")
    logs = [_reduced(log) for log in logs]
    ts = logs[0].sample_time
    for log in logs:
        if abs(log.sample_time - ts) > 1e-6 * ts:
            raise LogError(log.source,
                           f"sample time {log.sample_time:g} s differs from the first log's {ts:g} s; "
                           "diagnose logs of one rate together")
        if log.duration < min_duration:
            raise LogError(log.source,
                           f"{log.duration:.1f} s is too short to diagnose: need at least "
                           f"{min_duration:g} s (a quarter is held out for validation)")
    if lowpass_hz >= 0.8 * bandwidth or lowpass_hz >= 0.4 / ts:
        raise ValueError(f"lowpass_hz = {lowpass_hz} must be below the differentiator's bandwidth "
                         f"({bandwidth} Hz) and the Nyquist rate")
    sg = SavitzkyGolay(ts, bandwidth=bandwidth)
    sos = butter(4, lowpass_hz, fs=1.0 / ts, output="sos")
    # guard: the SG half-window plus the low-pass's memory (about 4 / (2 pi fc) s, twice for
    # forward-backward)
    guard = sg.acceleration_window // 2 + int(np.ceil(2 * 4 / (2 * np.pi * lowpass_hz) / ts))
    parts = []
    for k, log in enumerate(logs):
        pos = np.vstack([log.x[0], log.x[2]])
        d = sg(pos)
        du = sg(np.asarray(log.u)).velocity
        x = np.vstack([d.position[0], d.velocity[0], d.position[1], d.velocity[1]])
        acc = sosfiltfilt(sos, d.acceleration, axis=1)
        n = log.n
        split = round(n * (1 - holdout_fraction))
        train = np.zeros(n, dtype=bool)
        hold = np.zeros(n, dtype=bool)
        train[guard : split - guard] = True
        hold[split + guard : n - guard] = True
        parts.append((log.t - log.t[0], np.full(n, k), x, np.asarray(log.u), du, acc, train, hold))
    cat = [np.concatenate([p[i] for p in parts], axis=-1) for i in range(8)]
    moving = (bool(np.std(cat[2][0]) > MOTION), bool(np.std(cat[2][2]) > MOTION))
    if not any(moving):
        raise LogError(", ".join(log.source for log in logs),
                       "neither axis moves (position standard deviation under 50 um): nothing to diagnose")
    return DiagnosisData(
        t=cat[0], segment=cat[1], x=cat[2], u=cat[3], du=cat[4], acc=cat[5], train=cat[6],
        holdout=cat[7], sample_time=ts, moving=moving, sources=tuple(log.source for log in logs),
        sos=sos,
        settings={"bandwidth_hz": bandwidth, "lowpass_hz": lowpass_hz,
                  "holdout_fraction": holdout_fraction, "guard_samples": guard,
                  "sg_windows": (sg.velocity_window, sg.acceleration_window)},
    )


def _reduced(log: Log) -> Log:
    """``log`` at no more than :data:`MAX_RATE`, by means over blocks of samples."""
    q = int(np.ceil(1.0 / (log.sample_time * MAX_RATE) - 1e-9))
    if q <= 1:
        return log
    n = (log.n // q) * q

    def blocks(a: np.ndarray) -> np.ndarray:
        return a[..., :n].reshape(*a.shape[:-1], n // q, q).mean(axis=-1)

    return Log(blocks(np.asarray(log.t)), blocks(np.asarray(log.x)), blocks(np.asarray(log.u)),
               metadata=dict(log.metadata), source=log.source,
               notes=(*log.notes, f"reduced to {1 / (log.sample_time * q):g} Hz by {q}-sample means"),
               currents_measured=log.currents_measured)
