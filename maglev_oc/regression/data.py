"""Logs prepared for the filtered equation-error regression shared by identify and diagnose.

One data preparation and one filter policy for every equation-error fit in the project:

1. **Rate.** Logs faster than ``max_rate`` are reduced by block means (an anti-aliasing filter:
   the mean of q samples is flat to 1 % up to 0.055 / T at the reduced rate). Block means of
   the currents are also what drove the plant over the block, so reduction removes, rather than
   adds, the logging error of item 4.
2. **Derivatives.** Positions, velocities and accelerations of the encoder readings from the
   zero-phase Savitzky-Golay differentiator (:class:`~maglev_oc.estimation.differentiate.SavitzkyGolay`)
   with a chosen ``bandwidth``; the currents' rates from its velocity filter.
3. **One filter, both sides.** The SG acceleration is a linear filter of the true one,
   a_SG = F[x''] (:func:`matching_kernel`), so every model column is filtered by the same F
   (:meth:`PreparedLogs.filter`): the equation error compares like with like and stays exact for
   any model that is linear in its parameters. The bandwidth only selects which part of the
   spectrum the fit uses.
4. **Logged currents are not the applied ones.** A 5 kHz loop logged at 1 kHz by taking every
   fifth command logs one sample of a current that changed four more times before the next log
   line; the plant felt the mean. The difference is an error in the regressors (errors in
   variables) that biases every coefficient multiplying a current towards zero: on such logs C1
   comes out 2-3 % low at a 10 Hz band. Its size is measured from the log itself: the logged
   currents' spectrum above the closed-loop band is flat (aliased high-frequency noise of the
   fast loop), and that floor, times the share of it that did not reach the plant
   (:func:`logging_error_share`), is the variance per sample of the current error
   (``current_noise``). :mod:`~maglev_oc.regression.design` removes its expected contribution
   from the normal equations (bias-compensated least squares, Söderström 2018, Ch. 7).
5. **Masks.** Samples within the filters' memory of a log's ends are invalid, and so, given the
   model the fits start from, are stretches where a stopper holds the stage and their filters'
   memory (:mod:`~maglev_oc.regression.stoppers`: before lift-off, after landing, pressed against
   a stop in between); an optional held-out block at the end of each log is separated from the
   fitted samples by guard bands as long as the filters' memory, so that no sample of one leaks
   into the other.
6. **Payload.** A log that declares a payload (``payload_kg``) is read as the unloaded stage's
   (:mod:`~maglev_oc.regression.payload`): its accelerations' force parts are scaled back by
   (M + m) / M, so that the constants and terms fitted over logs of several loads are the stage's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np
from scipy.signal import fftconvolve, savgol_coeffs, welch

from maglev_oc.data.logs import Log, LogError
from maglev_oc.errors import InputError
from maglev_oc.estimation.differentiate import SavitzkyGolay
from maglev_oc.model.hardware import RIG_SAMPLE_TIME
from maglev_oc.regression.payload import load_factors, payload_note, unloaded
from maglev_oc.regression.stoppers import RestingStretch, resting_on_stoppers

if TYPE_CHECKING:
    from maglev_oc.model.parameters import StageParameters
    from maglev_oc.model.stage import StageModel

__all__ = [
    "DEFAULT_MAX_RATE",
    "LEVITATION_MARGIN",
    "MIN_LEVITATION",
    "RESTING_BANDWIDTH",
    "PreparedLogs",
    "as_log_list",
    "control_rate_of",
    "delayed_inputs",
    "levitating_parts",
    "levitating_pieces",
    "logging_error_share",
    "matching_kernel",
    "prepare",
    "reduce_rate",
    "without_resting",
]

_FILTER_ROWS = 16
"""Rows filtered per FFT call: the workspace is a few times 16 x n complex values."""

DEFAULT_MAX_RATE = 1000.0
"""[Hz] Logs faster than this are reduced to it by block means: every effect the fits look for
lives below 30 Hz, and the regression's memory grows with the number of samples."""
MOTION = 50e-6
"""[m] An axis whose position varies by less than this (standard deviation, 5 encoder counts)
is taken as locked by the stoppers and left out of the regression."""
THRUST_ERROR_SHARE = 0.5
"""The horizontal axis is left out of the fit (as a locked one is) when the logged thrust current's
errors, as estimated (``current_noise``), are at least this share of its energy in the fitting band
(:meth:`PreparedLogs.thrust_error_share`): C1's column is then mostly those errors, and its
errors-in-variables fit is singular. A slow scan of the track (sines of 0.01-0.05 Hz over
+-40 mm, nothing along the track but the motor) and a log whose platform moved +-1 mm along it gave
shares of 3.1 and 1.3 on the independent generator, and C1 at -1.1e9 and 1.4e10 with held-out
errors of 4e5 and 7e6 m/s^2; ``../shared/logs/independent_clean.csv`` gives 0.04, the independent
generator's default rig 0.003-0.006, and 400 logs of the benches' rigs at most 0.17 (the noisy
observers' rig). Half, as :data:`~maglev_oc.regression.solve.OPTIONAL_NOISE_SHARE`
holds an optional parameter's column mostly made of those errors at zero."""
NOISE_BAND = (0.3, 0.45)
"""Band of the current-noise floor, as fractions of the sample rate: above the closed-loop band
of any regulator of this stage (<= 60 rad/s) by a factor of 30 at 1 kHz, below Nyquist."""


def as_log_list(logs: Log | Sequence[Log]) -> list[Log]:
    """``logs`` as a non-empty list of Log (TypeError for anything else)."""
    if isinstance(logs, Log):
        return [logs]
    out = list(logs)
    if not out:
        raise InputError("no logs given")
    for log in out:
        if not isinstance(log, Log):
            raise TypeError(f"expected Log objects, got {type(log).__name__}")
    return out


def delayed_inputs(log: Log, delay: float) -> np.ndarray:
    """The logged currents shifted later by ``delay`` [s] (linear interpolation, held at the start)."""
    if delay == 0:
        return np.asarray(log.u, dtype=float)
    return np.vstack([np.interp(log.t - delay, log.t, row) for row in log.u])


def matching_kernel(differentiator: SavitzkyGolay) -> np.ndarray:
    """The filter F with SG acceleration = F[true acceleration] (symmetric, unit DC gain).

    The SG second-derivative kernel g2 annihilates constants and ramps, so it factors exactly as
    g2 = g * D2 with D2 the second difference / T^2; D2 of a signal smooth between samples is
    [1, 10, 1]/12 of its second derivative (exact for quadratics). Hence F = g * [1, 10, 1]/12.
    """
    sg = differentiator
    h2 = savgol_coeffs(sg.acceleration_window, sg.polyorder, deriv=2, delta=sg.sample_time, use="conv")
    # Dividing by the second difference is a double running sum; its last two entries are the
    # remainder, zero up to the rounding of savgol_coeffs' least squares (relative 5e-6 at a
    # 0.5 Hz window of 795 samples; np.polydiv's own rounding grows far faster with the length).
    running = np.cumsum(np.cumsum(h2 * sg.sample_time**2))
    g, remainder = running[:-2], running[-2:]
    if np.max(np.abs(remainder)) > 1e-4 * np.max(np.abs(g)):
        raise RuntimeError("the SG second-derivative kernel is not divisible by the second difference")
    kernel = np.convolve(g, [1 / 12, 10 / 12, 1 / 12])
    return kernel / kernel.sum()


def control_rate_of(log: Log, control_rate: float | None = None) -> float:
    """[Hz] The rate of the loop that commanded ``log``'s currents: ``control_rate`` if given, else
    the log's ``control_rate_hz`` metadata, else the rig's 5 kHz
    (:data:`~maglev_oc.model.hardware.RIG_SAMPLE_TIME`). A value that is not a positive number is
    an error naming the log."""
    if control_rate is None:
        raw = log.metadata.get("control_rate_hz")
        try:
            control_rate = float(raw) if raw is not None else 1.0 / RIG_SAMPLE_TIME
        except ValueError as err:
            raise LogError(
                log.source, f"metadata control_rate_hz: expected a number [Hz], got {raw!r}"
            ) from err
    if not (math.isfinite(control_rate) and control_rate > 0):
        raise LogError(log.source, f"metadata control_rate_hz must be positive, got {control_rate!r}")
    return control_rate


def logging_error_share(log: Log, control_rate: float | None = None) -> float:
    """The share of the logged currents' white noise floor that did not reach the plant.

    * currents measured by sensors (``log.currents_measured``): 1 — sensor noise is all error;
    * commands logged at the control rate or faster: 0 — each logged value was applied over its
      interval;
    * commands of a loop at ``control_rate`` logged by taking one of every q = rate ratio: the
      logged sample differs from the interval's mean by the q - 1 commands it did not see; for
      commands that vary independently from one control step to the next the error variance is
      (1 - 1/q) of the logged floor. (Slower-varying commands would make it smaller, faster
      ones cannot make it larger than 1.)

    ``control_rate`` [Hz]: the log's ``control_rate_hz`` metadata if present, else the rig's
    5 kHz (:data:`~maglev_oc.model.hardware.RIG_SAMPLE_TIME`).
    """
    if log.currents_measured:
        return 1.0
    q = control_rate_of(log, control_rate) * log.sample_time
    return max(0.0, 1.0 - 1.0 / q) if q > 1.0 + 1e-9 else 0.0


def reduce_rate(log: Log, max_rate: float = DEFAULT_MAX_RATE) -> tuple[Log, int]:
    """``log`` at no more than ``max_rate`` [Hz] by means over blocks of q samples; returns (log, q)."""
    q = math.ceil(1.0 / (log.sample_time * max_rate) - 1e-9)
    if q <= 1:
        return log, 1
    n = (log.n // q) * q

    def blocks(a: np.ndarray) -> np.ndarray:
        return a[..., :n].reshape(*a.shape[:-1], n // q, q).mean(axis=-1)

    reduced = Log(
        blocks(np.asarray(log.t)),
        blocks(np.asarray(log.x)),
        blocks(np.asarray(log.u)),
        metadata=dict(log.metadata),
        source=log.source,
        notes=(*log.notes, f"reduced to {1 / (log.sample_time * q):g} Hz by {q}-sample means"),
        currents_measured=log.currents_measured,
    )
    return reduced, q


def _white_floor(u: np.ndarray, sample_time: float) -> np.ndarray:
    """Variance per sample [A^2] of a white noise with the PSD level of ``u``'s noise band."""
    n = u.shape[1]
    nper = int(min(4096, max(256, n // 8)))
    f, p = welch(u - u.mean(axis=1, keepdims=True), fs=1.0 / sample_time, nperseg=nper, axis=1)
    fs = 1.0 / sample_time
    band = (f >= NOISE_BAND[0] * fs) & (f <= NOISE_BAND[1] * fs)
    level = np.median(p[:, band], axis=1)  # one-sided PSD [A^2/Hz]
    return level * fs / 2.0


@dataclass(frozen=True, eq=False)
class PreparedLogs:
    """Logs differentiated and concatenated for a filtered equation-error fit.

    Arrays are (rows, n) over the samples of all logs, one after another.

    Attributes
    ----------
    t : (n,) time within its log [s]
    segment : (n,) index of the log each sample comes from
    x : (4, n) gap [m], gap rate [m/s], position [m], its rate [m/s] (SG estimates)
    u : (2, n) currents (i_q, i_d) as logged [A]
    du : (2, n) their rates [A/s] (SG)
    acc : (2, n) measured accelerations (x2', x4') [m/s^2], = F[true] (see module doc); of a log
        that declares a payload, as the unloaded stage would have had them
        (:func:`~maglev_oc.regression.payload.unloaded`)
    valid : (n,) bool — outside the filters' memory of each log's ends and of any stretch where
        the platform rests on a stopper (``resting``)
    sample_time : float [s]
    differentiator : SavitzkyGolay
    kernel : (k,) the matching filter F
    current_noise : (2,) variance per sample of the logged currents' error [A^2]
    moving : (2,) bool — (vertical, horizontal) axis moves in the logs
    sources : tuple of str
    notes : tuple of str
    resting : tuple of RestingStretch
        Where the platform rests on a stopper (found when :func:`prepare` is given a model).
    load_factor : (2, n) or None
        M / (M + m) per sample (vertical, horizontal) of logs that declare a payload m; None when
        none does. A simulation of these samples scales the model's forces by it
        (:func:`~maglev_oc.regression.payload.loaded`).
    """

    t: np.ndarray
    segment: np.ndarray
    x: np.ndarray
    u: np.ndarray
    du: np.ndarray
    acc: np.ndarray
    valid: np.ndarray
    sample_time: float
    differentiator: SavitzkyGolay
    kernel: np.ndarray
    current_noise: np.ndarray
    moving: np.ndarray
    sources: tuple[str, ...]
    notes: tuple[str, ...] = ()
    resting: tuple[RestingStretch, ...] = ()
    settings: dict = field(default_factory=dict)
    load_factor: np.ndarray | None = None

    @property
    def n(self) -> int:
        return int(self.t.size)

    @cached_property
    def log_place(self) -> np.ndarray:
        """(n,) each sample's place in its log, from -1 at its first sample to +1 at its last (linear
        in time): what a term that changes over the log reads (a constant drifting as the rig warms,
        :attr:`~maglev_oc.regression.terms.AccelerationTerm.in_time`). Computed once: every design
        built on these logs passes it."""
        out = np.zeros(self.n)
        for k in np.unique(self.segment):
            mine = self.segment == k
            t = self.t[mine]
            lo, hi = float(t.min()), float(t.max())
            out[mine] = 2.0 * (t - lo) / (hi - lo) - 1.0 if hi > lo else 0.0
        return out

    @cached_property
    def load_factors(self) -> np.ndarray:
        """(2, n) :attr:`load_factor`, ones where no payload is declared (what a simulation reads)."""
        return np.ones((2, self.n)) if self.load_factor is None else self.load_factor

    @cached_property
    def log_time(self) -> np.ndarray:
        """(2, n) what a term that changes over the log reads of each sample
        (:data:`~maglev_oc.regression.terms.WHEN_NAMES`): its place in its log (:attr:`log_place`)
        and the index of that log among these (0, 1, ...)."""
        return np.vstack([self.log_place, self.segment.astype(float)])

    @property
    def n_logs(self) -> int:
        return len(self.sources)

    def with_noise_scale(self, scale: float) -> PreparedLogs:
        """The same samples with the logged currents' error estimate multiplied by ``scale``
        (:mod:`~maglev_oc.regression.noise_scale`), recorded in ``settings``."""
        if not (math.isfinite(scale) and scale >= 0.0):
            raise InputError(f"noise scale must be finite and not negative, got {scale!r}")
        return replace(
            self,
            current_noise=self.current_noise * scale,
            settings={**self.settings, "current_noise_scale": float(scale)},
        )

    def thrust_error_share(self) -> float:
        """The logged thrust current's errors (``current_noise``) over its energy in the fitting
        band, on the valid samples: both through the filter F, as C1's column and its errors enter
        the equations (:class:`~maglev_oc.regression.design.Design`; C1's column is L1(gap) i_q,
        L1 nearly constant over the gaps a log covers). Infinite where the current is zero."""
        filtered = self.filter(self.u[:1])[0][self.valid]
        energy = float(np.sum(filtered**2))
        errors = float(self.current_noise[0]) * float(np.sum(self.kernel**2)) * filtered.size
        return errors / energy if energy > 0 else math.inf

    def same_samples(self, other: PreparedLogs) -> bool:
        """Whether ``other`` holds these very arrays (one made from the other by
        :meth:`with_noise_scale`): their designs' columns are the same."""
        fields = ("t", "x", "u", "du", "acc", "valid", "kernel")
        return all(getattr(self, f) is getattr(other, f) for f in fields)

    @property
    def edge(self) -> int:
        """Samples left out at each end of a log (the SG window plus F, half each)."""
        sg = self.differentiator
        return max(sg.velocity_window, sg.acceleration_window) // 2 + self.kernel.size // 2

    def filter(self, columns: np.ndarray, *, inplace: bool = False) -> np.ndarray:
        """F applied along the last axis of ``columns`` (..., n), log by log (zero outside).

        A few rows at a time, so that the FFT's workspace stays small next to the columns;
        ``inplace`` overwrites ``columns`` (a float, C-contiguous array) instead of copying it."""
        columns = np.ascontiguousarray(columns, dtype=float)
        out = columns if inplace else np.empty_like(columns)
        rows_in, rows_out = columns.reshape(-1, self.n), out.reshape(-1, self.n)
        kernel = self.kernel.reshape(1, -1)
        for start, stop in self.segment_bounds:
            for r in range(0, rows_in.shape[0], _FILTER_ROWS):
                block = rows_in[r : r + _FILTER_ROWS, start:stop]
                # zero-padded 'same' convolution by FFT (the kernel is symmetric: no flip needed)
                rows_out[r : r + _FILTER_ROWS, start:stop] = fftconvolve(block, kernel, mode="same", axes=-1)
        return out

    @property
    def segment_bounds(self) -> list[tuple[int, int]]:
        """(start, stop) of each log's samples (logs are concatenated in order)."""
        edges = np.flatnonzero(np.diff(self.segment)) + 1
        starts = [0, *edges.tolist()]
        stops = [*edges.tolist(), self.n]
        return list(zip(starts, stops, strict=True))

    def masks(self, holdout_fraction: float = 0.0, samples: Sequence[np.ndarray] | None = None):
        """(fit, held-out) boolean masks (n,).

        ``holdout_fraction``: a contiguous block at the end of each log is held out, separated
        from the fitted part by guard bands of one filter memory. ``samples``: per log, a boolean
        mask of the samples a fit may use (default all); held-out samples are never fitted.
        """
        if not 0.0 <= holdout_fraction <= 0.5:
            raise InputError(f"holdout_fraction must be in [0, 0.5], got {holdout_fraction!r}")
        fit = np.zeros(self.n, dtype=bool)
        hold = np.zeros(self.n, dtype=bool)
        guard = self.edge
        for s in range(self.n_logs):
            idx = np.flatnonzero(self.segment == s)
            n = idx.size
            use = np.ones(n, dtype=bool) if samples is None else np.asarray(samples[s], dtype=bool)
            if use.shape != (n,):
                raise InputError(f"samples[{s}]: expected a boolean mask of shape ({n},), got {use.shape}")
            valid = self.valid[idx]
            if holdout_fraction > 0:
                split = round(n * (1 - holdout_fraction))
                f = np.zeros(n, dtype=bool)
                h = np.zeros(n, dtype=bool)
                f[: max(split - guard, 0)] = True
                h[split + guard :] = True
                fit[idx] = f & valid & use
                hold[idx] = h & valid
            else:
                fit[idx] = valid & use
        return fit, hold


MIN_LEVITATION = 2.0
"""[s] The least a log must levitate, once its stretches on the stopper are left out, to be fitted."""

LEVITATION_MARGIN = 0.1
"""[s] Kept off a resting stretch by :func:`levitating_parts` (the lift-off's first motion, an impact)."""


def levitating_parts(
    logs: Log | Sequence[Log], model: StageModel
) -> tuple[list[Log], tuple[RestingStretch, ...]]:
    """The logs' pieces where the platform levitates: without the stretches where it rests on (or
    is pressed against) its stopper (:mod:`~maglev_oc.regression.stoppers`, found as
    :func:`prepare` finds them), as :func:`levitating_pieces` cuts them: for the fits that read a
    log's samples themselves (the output-error fit, NPFSI), as :func:`prepare` leaves them out of
    the equation error. A touch in the middle of a log cuts it in two. Returns the pieces (in the
    logs' order) and the stretches left out."""
    out, found = [], []
    for k, log in enumerate(as_log_list(logs)):
        # each log prepared alone: its stretches renumbered as the k-th of the logs
        resting = [
            replace(r, log=k) for r in prepare([log], bandwidth=RESTING_BANDWIDTH, model=model).resting
        ]
        out.extend(levitating_pieces(log, resting))
        found.extend(resting)
    return out, tuple(found)


def levitating_pieces(log: Log, resting: Sequence[RestingStretch]) -> list[Log]:
    """``log`` cut where those of the stretches ``resting`` that are its own (by source) lie, with
    :data:`LEVITATION_MARGIN` more beside each (the lift-off's first motion, the impact): its pieces
    of at least :data:`MIN_LEVITATION`, in time order (``[log]`` when no stretch is its own)."""
    mine = sorted((r for r in resting if r.source == log.source), key=lambda r: r.start)
    if not mine:
        return [log]
    t0 = float(log.t[0])
    held: list[list[float]] = []  # the stretches with their margins, overlapping ones merged
    for r in mine:
        a, b = t0 + r.start - LEVITATION_MARGIN, t0 + r.stop + LEVITATION_MARGIN
        if held and a <= held[-1][1]:
            held[-1][1] = max(held[-1][1], b)
        else:
            held.append([a, b])
    edges = [t0, *(e for span in held for e in span), float(log.t[-1]) + log.sample_time]
    pieces = [
        log.time_slice(a, b) for a, b in zip(edges[::2], edges[1::2], strict=True) if b - a >= MIN_LEVITATION
    ]
    if not pieces:
        raise LogError(
            log.source,
            f"{'; '.join(r.what() for r in mine)}: no stretch between them levitates for "
            f"{MIN_LEVITATION:g} s; record the run after lift-off, with the reference within the "
            "stops",
        )
    return pieces


def without_resting(log: Log, resting: Sequence[RestingStretch]) -> Log:
    """The first of ``log``'s :func:`levitating_pieces` (the log itself when no stretch of
    ``resting`` is its own): the samples of a fit's first residuals, for what reads them again (a
    report's residuals)."""
    return levitating_pieces(log, resting)[0]


RESTING_BANDWIDTH = 10.0
"""[Hz] The band :func:`levitating_parts` prepares a log on to find where it rests (the fits')."""


def _widened(mask: np.ndarray, segment: np.ndarray, width: int) -> np.ndarray:
    """``mask`` with ``width`` samples more on each side of every run, within each log."""
    out = mask.copy()
    for k in np.unique(segment):
        idx = np.flatnonzero(segment == k)
        m = mask[idx]
        if not m.any():
            continue
        grown = np.convolve(m.astype(float), np.ones(2 * width + 1), mode="same") > 0.5
        out[idx] = grown
    return out


def _reduced(logs: list[Log], max_rate: float, control_rate: float | None, logging_error: bool):
    """The logs reduced to at most ``max_rate`` and each one's share of the white current floor
    that is logging error; refuses mixed rates. The share is the log's own: a mean of q samples
    carries 1/q of the error's variance, and so of the floor, which :func:`prepare` measures on
    the reduced log (dividing the share by q too counted the means twice: a 5 kHz log of measured
    currents was corrected for a fifth of its error)."""
    shares, reduced = [], []
    for log in logs:
        shares.append(logging_error_share(log, control_rate) if logging_error else 0.0)
        reduced.append(reduce_rate(log, max_rate)[0])
    ts = reduced[0].sample_time
    for log in reduced[1:]:
        if abs(log.sample_time - ts) > 0.01 * ts:
            raise LogError(
                log.source,
                f"sample time {log.sample_time:g} s differs from {reduced[0].source}'s {ts:g} s; "
                "fit logs of one rate together",
            )
    return reduced, shares


def _differentiated(k: int, log: Log, sg: SavitzkyGolay, edge: int) -> tuple:
    """(t, segment, x, u, du, acceleration, valid) of one log; its first and last ``edge``
    samples, where the filters run off the data, are not valid."""
    ts = sg.sample_time
    if log.n < 2 * edge + 10:
        raise LogError(
            log.source,
            f"{log.n} samples at {1 / ts:g} Hz; the {sg.bandwidth:g} Hz differentiator needs at least "
            f"{2 * edge + 10} ({(2 * edge + 10) * ts:.2f} s)",
        )
    d = sg(np.vstack([log.x[0], log.x[2]]))
    u = np.asarray(log.u, dtype=float)
    x = np.vstack([d.position[0], d.velocity[0], d.position[1], d.velocity[1]])
    valid = np.zeros(log.n, dtype=bool)
    valid[edge : log.n - edge] = True
    return log.t - log.t[0], np.full(log.n, k), x, u, sg(u).velocity, np.asarray(d.acceleration), valid


def prepare(
    logs: Log | Sequence[Log],
    *,
    bandwidth: float | None = None,
    differentiator: SavitzkyGolay | None = None,
    max_rate: float = DEFAULT_MAX_RATE,
    control_rate: float | None = None,
    logging_error: bool = True,
    model: StageModel | None = None,
    resting: Sequence[RestingStretch] | None = None,
    params: StageParameters | None = None,
) -> PreparedLogs:
    """Reduce, differentiate and concatenate ``logs`` (all at one sample rate).

    Parameters
    ----------
    logs : sequence of Log
    bandwidth : float
        [Hz] Band of the SG differentiator (and so of the fit).
    differentiator : SavitzkyGolay, optional
        Instead of ``bandwidth``: a differentiator for the (reduced) sample rate.
    max_rate : float
        [Hz] Faster logs are reduced by block means.
    control_rate : float, optional
        [Hz] Rate of the loop that produced the logged currents (see :func:`logging_error_share`).
    logging_error : bool
        Estimate the logged currents' error (item 4 of the module doc); False sets it to zero.
    model : StageModel, optional
        The model the fits start from: with it, stretches where the platform rests on a stopper
        (before lift-off, after landing, pressed against it in between) are found and left out
        (item 5 of the module doc, :mod:`~maglev_oc.regression.stoppers`), and said in ``notes``.
    resting : sequence of RestingStretch, optional
        Instead of ``model``: the stretches to leave out, as found on another band of the same logs
        (on a narrow band the smoothed gap and misfit no longer show them: a log that lifted off
        after 1.2 s gave none at 2 Hz).
    params : StageParameters, optional
        Instead of ``model``: the stage whose masses read a log that declares a payload
        (:mod:`~maglev_oc.regression.payload`; the model's when it is given).
    """
    logs = as_log_list(logs)
    if (bandwidth is None) == (differentiator is None):
        raise InputError("give exactly one of bandwidth and differentiator")
    if differentiator is not None and not isinstance(differentiator, SavitzkyGolay):
        raise TypeError(
            "differentiator must be a SavitzkyGolay (zero phase; a lagging estimate biases an "
            f"equation-error fit), got {type(differentiator).__name__}"
        )
    reduced, shares = _reduced(logs, max_rate, control_rate, logging_error)
    ts = reduced[0].sample_time
    sg = SavitzkyGolay(ts, bandwidth=bandwidth) if differentiator is None else differentiator
    if abs(sg.sample_time - ts) > 0.01 * ts:
        raise InputError(f"differentiator sample_time {sg.sample_time!r} s does not match the logs' {ts!r} s")
    bandwidth = sg.bandwidth
    kernel = matching_kernel(sg)
    edge = max(sg.velocity_window, sg.acceleration_window) // 2 + kernel.size // 2
    parts = [_differentiated(k, log, sg, edge) for k, log in enumerate(reduced)]
    weight = sum(log.n for log in reduced)
    noise = sum(
        share * _white_floor(np.asarray(log.u, dtype=float), ts) * log.n
        for log, share in zip(reduced, shares, strict=True)
    )
    cat = [np.concatenate([p[i] for p in parts], axis=-1) for i in range(7)]
    stage = model.params if model is not None else params
    load = load_factors(reduced, cat[1], stage)
    if load is not None:  # the forces of a log with a payload read as the unloaded stage's
        cat[5] = unloaded(cat[5], load, stage.gravity)
    moving = np.array([np.std(cat[2][0]) > MOTION, np.std(cat[2][2]) > MOTION])
    notes = tuple(n for log in reduced for n in log.notes if "reduced to" in n) + _still_axes(cat[2], moving)
    notes += tuple(payload_note(log, stage) for log in logs if log.payload)
    if resting is not None:  # found on another band: the same stretches, by their times
        resting = tuple(resting)
        mask = np.zeros(cat[0].size, dtype=bool)
        for r in resting:
            mask |= (cat[1] == r.log) & (cat[0] >= r.start) & (cat[0] <= r.stop)
    elif model is not None and moving.any():  # (a log where nothing moves is refused as such)
        model_acc = model.dynamics(cat[2], cat[3])[[1, 3]]
        mask, resting = resting_on_stoppers(
            cat[0], cat[1], cat[2], cat[5], model_acc, ts, tuple(log.source for log in logs)
        )
    else:
        mask, resting = np.zeros(cat[0].size, dtype=bool), ()
    if resting:
        cat[6] = cat[6] & ~_widened(mask, cat[1], edge)
        notes += tuple(r.describe() for r in resting)
        for k, log in enumerate(logs):
            left = int(np.count_nonzero(cat[6][cat[1] == k]))
            if left < max(4 * edge, round(MIN_LEVITATION / ts)):
                rests = "; ".join(r.what() for r in resting if r.log == k)
                raise LogError(
                    log.source,
                    f"{rests}: the platform levitates for {left * ts:.2f} s of the log, too little to fit "
                    f"(at least {max(4 * edge * ts, MIN_LEVITATION):g} s); record the run after lift-off",
                )
    rates = [control_rate_of(log, control_rate) for log in logs]
    declared = [
        control_rate is not None or log.currents_measured or "control_rate_hz" in log.metadata for log in logs
    ]
    prepared = PreparedLogs(
        t=cat[0],
        segment=cat[1],
        x=cat[2],
        u=cat[3],
        du=cat[4],
        acc=cat[5],
        valid=cat[6],
        sample_time=ts,
        differentiator=sg,
        kernel=kernel,
        current_noise=np.asarray(noise, dtype=float) / max(weight, 1),
        moving=moving,
        sources=tuple(log.source for log in logs),
        notes=notes,
        resting=resting,
        load_factor=load,
        settings={
            "bandwidth_hz": bandwidth,
            "sg_windows": (sg.velocity_window, sg.acceleration_window),
            "edge_samples": edge,
            "logging_error_share": [float(s) for s in shares],
            # the loop's rate (the lag candidate's hold delay); logs of several rates: the slowest
            "control_rate_hz": min(rates),
            # that rate is the rig's 5 kHz, assumed: a log of commanded currents does not declare its own
            "control_rate_assumed": any(
                r == min(rates) and not d for r, d in zip(rates, declared, strict=True)
            ),
            "max_rate_hz": max_rate,
            # every log's currents are its amplifiers' measured output, not commands held by the loop
            "currents_measured": all(log.currents_measured for log in logs),
            # each log's declared payload [kg], when any log declares one (regression.payload)
            **({"payload_kg": [log.payload for log in logs]} if load is not None else {}),
        },
    )
    return _thrust_shown(prepared)


THRUST_LEFT_OUT = "the horizontal axis is left out of the fit"
"""How the notes of a horizontal axis left out begin, held still (:func:`_still_axes`) or with a
thrust current made of its errors (:func:`_thrust_shown`); :func:`axes_left_out` finds them by it."""

_LEFT_OUT = ("the vertical axis is left out of the fit", THRUST_LEFT_OUT)


def axes_left_out(prepared: PreparedLogs) -> tuple[str, ...]:
    """The notes of ``prepared`` that say why an axis is left out of the fit (:func:`_still_axes`,
    :func:`_thrust_shown`), vertical first."""
    return tuple(n for prefix in _LEFT_OUT for n in prepared.notes if n.startswith(prefix))


def _still_axes(x: np.ndarray, moving: np.ndarray) -> tuple[str, ...]:
    """The notes for the axes whose position varies by less than :data:`MOTION`: held still (on a
    stopper, or levitated at one gap), nothing on them can be fitted."""
    out = []
    for k, (row, what, names) in enumerate(((0, "gap", "C2, C3 and C4"), (2, "position", "C1"))):
        if not moving[k]:
            out.append(
                f"{_LEFT_OUT[k]}: its {what} varies by {float(np.std(x[row])) * 1e6:.3g} um (standard "
                f"deviation), less than the {MOTION * 1e6:g} um a fit needs, so {names} "
                f"{'is' if k else 'are'} not determined by this log"
            )
    return tuple(out)


def _thrust_shown(prepared: PreparedLogs) -> PreparedLogs:
    """``prepared`` with its horizontal axis left out of the fit, and a note saying why, when the
    logged thrust current is mostly its errors (:data:`THRUST_ERROR_SHARE`)."""
    if not prepared.moving[1]:
        return prepared
    share = prepared.thrust_error_share()
    if share < THRUST_ERROR_SHARE:
        return prepared
    note = (
        f"{THRUST_LEFT_OUT}: the logged thrust current is mostly its errors "
        f"({min(share, 99.0):.2g} times its energy in the fitting band, as estimated from its noise "
        "floor), so nothing along the track can be told from them and C1 is not determined by this "
        "log; moves along the track that need thrust (faster, or against a force) determine it"
    )
    return replace(prepared, moving=np.array([prepared.moving[0], False]), notes=(*prepared.notes, note))
