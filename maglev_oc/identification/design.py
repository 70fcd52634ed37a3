"""Experiment design for the identification: references the rig plays, chosen for their information.

The rig is excited through its closed loop: a reference (gap and horizontal set-points) is
tracked by the papers' PID regulators (000 Sec. IV; :func:`~maglev_oc.control.pid.paper_pid`) and
the log is handed to the equation-error fit (:mod:`~maglev_oc.identification.equation_error`).
A design is therefore a reference, and its worth is the covariance of the fit it leads to.

Signals
-------
* :func:`multisine` — periodic sums of harmonics with Schroeder phases (Schroeder 1970) and,
  optionally, a few clipping passes (Van der Ouderaa et al. 1988) that lower the crest factor
  further; :func:`crest_factor`.
* :func:`prbs` — maximum-length binary sequences (period 2^n - 1, flat spectrum).
* :func:`gap_sweep_reference` — slow levitation over 10-25 mm (the papers' equilibrium-current
  range, 000 Sec. V-B), which separates a constant vertical force from C2 (the force's column is
  constant, C2's, lam(x1) B(x1)^2, falls by a factor of four over that range).

Prediction (:class:`ExperimentDesigner`)
-----------------------------------------
The reference is simulated on a noise-free twin (the nominal model, the amplifiers, the PIDs);
the equation-error design columns X = F[Phi(x, u)] come from the regression layer itself
(:func:`~maglev_oc.regression.design.build_design`: the exact Jacobian of the filtered residual
with respect to the parameters). The residual of the fit is, on the twin, the Savitzky-Golay
acceleration of the encoder's error n (quantization q = 10 um and 2 um noise: white with variance
q^2 / 12 + 2 um^2), r = h2 * n. The estimate's covariance is then the sandwich

    Cov = H^-1 M H^-1,   H = sum_a X_a' X_a,   M = sigma_n^2 sum_a G_a' G_a,  G_a = h2 * X_a,

(h2 the SG second-derivative kernel; both axes see the same encoders, so the fit's per-axis
weights cancel). D-optimal designs maximise log det Cov^-1 of the parameters relative to their
nominal values. A candidate's amplitudes are scaled to the largest that keeps the reference in the
:class:`FeasibleSet` and the currents within the budget (information grows with amplitude, so the
optimum sits on that boundary): the D-optimal search runs over shapes only (band, number of tones,
spectral tilt per axis).

:func:`check_on_twin` plays a design on the rig twin (encoders, amplifiers, the true constants of
:data:`~maglev_oc.identification.experiments.TWIN_TRUTH`), identifies with the equation-error fit
of :func:`~maglev_oc.identification.pipeline.identify` and compares predicted with achieved
standard errors.

Both run the twin's closed loop as generated C where a C compiler is found, else in CasADi's
virtual machine: the same operations, and the same runs to the bit (compared on x86-64: the
D-optimal design of the tests and three seeds of the papers' excitation on the rig twin), three to
four times less CPU (a 60 s D-optimal design 13.8 -> 4.2 s, compilation included).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import scipy.io
from scipy.signal import fftconvolve, lsim, max_len_seq, savgol_coeffs

from maglev_oc.control.pid import paper_pid
from maglev_oc.errors import InputError, SolverError
from maglev_oc.fileio import atomic_path
from maglev_oc.identification.equation_error import EquationError
from maglev_oc.identification.experiments import LOG_RATE_HZ, TWIN_TRUTH, identification_effects
from maglev_oc.model.hardware import CONTINUOUS_CURRENT_LIMIT, PEAK_CURRENT_LIMIT, STOPPER_GAP
from maglev_oc.model.stage import StageModel
from maglev_oc.numerics import c_compiler
from maglev_oc.regression.base import CONSTANT_NAMES
from maglev_oc.regression.design import build_design
from maglev_oc.regression.terms import AccelerationTerm, constant_force
from maglev_oc.results import Result, jsonable
from maglev_oc.sim.effects import CurrentAmplifier, Encoder, TwinEffects
from maglev_oc.sim.engine import ClosedLoop, SimulationResult
from maglev_oc.sim.recording import result_to_log
from maglev_oc.sim.scenarios import Scenario, Sinusoids, excitation_scenario
from maglev_oc.sim.twin import RigTwin
from maglev_oc.units import MM_TO_M

__all__ = [
    "KINDS",
    "REFERENCE_COLUMNS",
    "CurrentBudget",
    "ExperimentDesign",
    "ExperimentDesigner",
    "FeasibleSet",
    "MultisineShape",
    "Prediction",
    "SampledReference",
    "TwinCheck",
    "check_on_twin",
    "crest_factor",
    "design_experiment",
    "encoder_noise_variance",
    "gap_sweep_reference",
    "multisine",
    "multisine_reference",
    "papers_reference",
    "prbs",
    "prbs_reference",
    "read_reference",
    "schroeder_phases",
    "write_design",
]

KINDS = ("multisine", "prbs", "gap_sweep", "doptimal")
REFERENCE_COLUMNS = (
    "t",
    "r_gap",
    "r_position",
    "r_gap_rate",
    "r_position_rate",
    "r_gap_acc",
    "r_position_acc",
)
"""Columns of a reference file: time [s], set-points [m], their rates [m/s] and accelerations
[m/s^2] (regulators with feedforward use the derivatives; a rig that plays set-points only
reads the first three)."""
REFERENCE_RATE_HZ = 1000.0
"""[Hz] Sample rate of a reference file (the 5 kHz loop interpolates linearly between samples)."""
RAMP_TIME = 2.0
"""[s] Amplitudes ramp in over this time (as the papers' excitation does)."""
RESIDUAL_FLOOR = 2e-7
"""[(m/s^2)^2/Hz] Low-frequency floor of the equation-error residual on the twin (see
:class:`ExperimentDesigner`)."""
EFFECT = "constant_force_vertical.force"
"""The effect parameter whose standard error the designs report: a constant vertical force [N]."""


def encoder_noise_variance(encoder: Encoder | None = None) -> float:
    """Variance of one encoder reading's error [m^2]: quantization q^2/12 plus the noise."""
    enc = Encoder() if encoder is None else encoder
    return enc.resolution**2 / 12 + enc.noise_std**2


# --- the feasibility set and the current budget ---------------------------------------------
@dataclass(frozen=True)
class FeasibleSet:
    """Where a reference and the run it produces must stay.

    Parameters
    ----------
    gap : (float, float)
        [m] Range of the gap set-point: 10-25 mm, the papers' equilibrium-current range (000
        Sec. V-B); the stoppers (8 and 30 mm) are outside it.
    position : (float, float)
        [m] Range of the horizontal set-point (travel +-50 mm, 002 Sec. 4, less 5 mm for the
        tracking error).
    true_gap : (float, float)
        [m] Range the simulated gap must keep (the stoppers less 1 mm).
    true_position : (float, float)
        [m] Range the simulated position must keep.
    peak_current : float
        [A] Peak of |i| (the amplifiers' 9 A).
    continuous_current : float
        [A] RMS of |i| over the run (the amplifiers' 7 A continuous rating).
    """

    gap: tuple[float, float] = (10e-3, 25e-3)
    position: tuple[float, float] = (-45e-3, 45e-3)
    true_gap: tuple[float, float] = (STOPPER_GAP[0] + 1e-3, STOPPER_GAP[1] - 1e-3)
    true_position: tuple[float, float] = (-50e-3, 50e-3)
    peak_current: float = PEAK_CURRENT_LIMIT
    continuous_current: float = CONTINUOUS_CURRENT_LIMIT

    def __post_init__(self) -> None:
        for name in ("gap", "position", "true_gap", "true_position"):
            lo, hi = getattr(self, name)
            if not lo < hi:
                raise InputError(f"FeasibleSet.{name}: need lower < upper, got {(lo, hi)!r}")
        if not 0 < self.continuous_current <= self.peak_current:
            raise InputError(
                f"FeasibleSet: need 0 < continuous_current <= peak_current, got "
                f"{self.continuous_current!r}, {self.peak_current!r}"
            )

    def violations(self, reference: SampledReference, run: SimulationResult) -> list[str]:
        """What the reference or its simulated run violates (empty when feasible)."""
        out = []
        r = reference.values
        for label, row, (lo, hi) in (
            ("gap set-point", 0, self.gap),
            ("position set-point", 3, self.position),
        ):
            if r[row].min() < lo - 1e-12 or r[row].max() > hi + 1e-12:
                out.append(
                    f"{label} {r[row].min() * 1e3:.2f}..{r[row].max() * 1e3:.2f} mm outside "
                    f"{lo * 1e3:g}..{hi * 1e3:g} mm"
                )
        if not run.success:
            out.append(f"run failed: {run.message}")
            return out
        for label, row, (lo, hi) in (("gap", 0, self.true_gap), ("position", 2, self.true_position)):
            if run.x[row].min() < lo or run.x[row].max() > hi:
                out.append(
                    f"simulated {label} {run.x[row].min() * 1e3:.2f}..{run.x[row].max() * 1e3:.2f} mm "
                    f"outside {lo * 1e3:g}..{hi * 1e3:g} mm"
                )
        mag = np.hypot(run.u[0], run.u[1])
        if mag.max() > self.peak_current:
            out.append(f"peak current {mag.max():.2f} A over {self.peak_current:g} A")
        if math.sqrt(float(np.mean(mag**2))) > self.continuous_current:
            out.append(
                f"RMS current {math.sqrt(float(np.mean(mag**2))):.2f} A over {self.continuous_current:g} A"
            )
        return out


@dataclass(frozen=True)
class CurrentBudget:
    """Peak commanded currents a design may use: |i_q| <= ``horizontal``, |i_d| <= ``vertical`` [A].

    The comparison with the papers' excitation gives every design the budget of that excitation
    (:meth:`ExperimentDesigner.papers_budget`): the same peaks, so a design gains only by spending
    the currents better (crest factor, frequencies), not by driving harder.
    """

    vertical: float = PEAK_CURRENT_LIMIT
    horizontal: float = PEAK_CURRENT_LIMIT

    def __post_init__(self) -> None:
        for name in ("vertical", "horizontal"):
            v = getattr(self, name)
            if not (0 < v <= PEAK_CURRENT_LIMIT):
                raise InputError(f"CurrentBudget.{name} must be in (0, {PEAK_CURRENT_LIMIT:g}] A, got {v!r}")


# --- signals ------------------------------------------------------------------------------
def crest_factor(x: np.ndarray) -> float:
    """max |x - mean| / RMS(x - mean) of a signal (1 for a square wave, sqrt 2 for one sine)."""
    x = np.asarray(x, dtype=float)
    d = x - x.mean()
    rms = math.sqrt(float(np.mean(d**2)))
    if rms == 0:
        raise InputError("crest_factor: the signal is constant")
    return float(np.max(np.abs(d)) / rms)


def schroeder_phases(amplitudes: Sequence[float]) -> np.ndarray:
    """Schroeder's phases for harmonics with the given amplitudes (Schroeder 1970, eq. (11)):
    phi_k = -2 pi sum_{j < k} (k - j) p_j, p_j the power share of tone j. For equal amplitudes
    this is phi_k = -pi k (k - 1) / N and the crest factor is near 1.5 whatever N, where zero
    phases give sqrt(2 N)."""
    a = np.asarray(amplitudes, dtype=float)
    if a.ndim != 1 or a.size == 0 or np.any(a < 0) or not np.any(a > 0):
        raise InputError(f"amplitudes must be a non-empty vector of non-negative numbers, got {amplitudes!r}")
    p = a**2 / np.sum(a**2)
    k = np.arange(1, a.size + 1)
    return np.array([-2 * math.pi * float(np.sum((kk - k[: kk - 1]) * p[: kk - 1])) for kk in k])


def multisine(
    harmonics: Sequence[int],
    amplitudes: Sequence[float],
    *,
    phases: Sequence[float] | None = None,
    clip_passes: int = 0,
    grid: int = 4096,
) -> tuple[np.ndarray, np.ndarray]:
    """Phases of a periodic multisine sum_k a_k sin(2 pi h_k t / T + phi_k) and its crest factor.

    Schroeder's phases by default; ``clip_passes`` passes of the clipping algorithm then clip
    the period (sampled on ``grid`` points) at 90 % of its peak, keep the phases of the clipped
    signal's harmonics and restore their amplitudes (the spectrum stays exactly the asked one).

    Returns
    -------
    phases : (k,) [rad]
    crest : float
        The crest factor of one period.
    """
    h = np.asarray(harmonics, dtype=int)
    a = np.asarray(amplitudes, dtype=float)
    if h.ndim != 1 or h.size == 0 or h.shape != a.shape or np.any(h < 1) or len(set(h.tolist())) != h.size:
        raise InputError(
            f"harmonics must be distinct positive integers, one per amplitude, got {harmonics!r}"
        )
    if not (isinstance(clip_passes, int) and clip_passes >= 0):
        raise InputError(f"clip_passes must be a non-negative integer, got {clip_passes!r}")
    grid = max(int(grid), 4 * int(h.max()) + 4)
    # Schroeder's phases are for cosines: sin(x + phi + pi/2) = cos(x + phi)
    phi = schroeder_phases(a) + math.pi / 2 if phases is None else np.asarray(phases, dtype=float)
    t = np.arange(grid) / grid

    def signal(ph):
        return np.sum(a[:, None] * np.sin(2 * math.pi * h[:, None] * t[None, :] + ph[:, None]), axis=0)

    best, best_cf = phi, crest_factor(signal(phi))
    for _ in range(clip_passes):
        x = signal(phi)
        level = 0.9 * np.max(np.abs(x))
        spec = np.fft.rfft(np.clip(x, -level, level))
        # sin(w t + phi) has the DFT coefficient -i e^{i phi} N/2: phi = angle + pi/2
        phi = np.angle(spec[h]) + math.pi / 2
        cf = crest_factor(signal(phi))
        if cf < best_cf:
            best, best_cf = phi, cf
    return best, best_cf


def prbs(order: int, *, seed: int = 0) -> np.ndarray:
    """A maximum-length binary sequence of +-1, period 2^order - 1 (``order`` 3..20).

    Its periodic autocorrelation is N at lag 0 and -1 at every other lag, so its periodic
    spectrum is flat: |DFT_k|^2 = N + 1 for k != 0 (1 at k = 0). ``seed`` shifts the start.
    """
    if not (isinstance(order, int) and 3 <= order <= 20):
        raise InputError(f"order must be an integer in 3..20, got {order!r}")
    seq = max_len_seq(order)[0].astype(float) * 2 - 1
    return np.roll(seq, -(seed % seq.size))


# --- references ------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class SampledReference:
    """A reference sampled at :data:`REFERENCE_RATE_HZ`: what a reference file holds.

    Attributes
    ----------
    t : (n,) [s] from 0
    values : (6, n) rows (r_v, r_v', r_v'', r_h, r_h', r_h'') [m, m/s, m/s^2], the layout of
        :mod:`maglev_oc.control.base`
    name : str
    description : str
    """

    t: np.ndarray
    values: np.ndarray
    name: str = "reference"
    description: str = ""

    def __post_init__(self) -> None:
        # copies, made read-only: the caller's arrays stay as they were, writeable
        t = np.array(self.t, dtype=float)
        v = np.array(self.values, dtype=float)
        if t.ndim != 1 or t.size < 2 or t[0] != 0 or np.any(np.diff(t) <= 0):
            raise InputError("SampledReference.t must start at 0 and increase")
        if v.shape != (6, t.size) or not np.all(np.isfinite(v)):
            raise InputError(
                f"SampledReference.values must be finite with shape (6, {t.size}), got {v.shape}"
            )
        if np.any(v[0] <= 0) or np.any(v[0] > 0.1):
            raise InputError("SampledReference: gap set-points must be in metres, in (0, 0.1]")
        t.setflags(write=False)
        v.setflags(write=False)
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "values", v)

    @property
    def duration(self) -> float:
        return float(self.t[-1] + (self.t[1] - self.t[0]))

    def sample(self, t: np.ndarray) -> np.ndarray:
        """(6, len(t)) by linear interpolation (held at the ends), as the rig plays the file."""
        t = np.asarray(t, dtype=float)
        return np.vstack([np.interp(t, self.t, row) for row in self.values])

    def scenario(self) -> Scenario:
        """The reference as a twin scenario, starting at rest at its first set-point."""
        r0 = self.values[:, 0]
        return Scenario(
            self.name, self.description or self.name, (r0[0], 0.0, r0[3], 0.0), self, self.duration
        )


def _grid(duration: float) -> np.ndarray:
    if not (duration >= 5.0 and math.isfinite(duration)):
        raise InputError(f"duration must be at least 5 s, got {duration!r}")
    return np.arange(round(duration * REFERENCE_RATE_HZ)) / REFERENCE_RATE_HZ


def papers_reference(
    duration: float = 60.0, *, seed: int = 0, gap_offset: float = 20 * MM_TO_M
) -> SampledReference:
    """The papers' sum-of-sines excitation (000 Sec. IV), sampled
    (:func:`~maglev_oc.sim.scenarios.excitation_scenario`)."""
    t = _grid(duration)
    sc = excitation_scenario(duration, seed=seed, gap_offset=gap_offset)
    return SampledReference(t, sc.reference.sample(t), "papers_sum_of_sines", sc.title)


@dataclass(frozen=True)
class MultisineShape:
    """The shape of one axis' multisine: which harmonics of the period and their amplitudes.

    Parameters
    ----------
    band : (float, float)
        [Hz] Lowest and highest tone (snapped to harmonics of the period).
    tones : int
        Number of tones, log-spaced over the band.
    tilt : float
        Position amplitudes fall as f^-tilt (0: flat; 2: equal accelerations).
    """

    band: tuple[float, float] = (0.2, 4.0)
    tones: int = 8
    tilt: float = 0.0

    def __post_init__(self) -> None:
        lo, hi = self.band
        if not (0 < lo < hi and math.isfinite(hi)):
            raise InputError(f"MultisineShape.band: need 0 < low < high [Hz], got {self.band!r}")
        if not (isinstance(self.tones, int) and self.tones >= 1):
            raise InputError(f"MultisineShape.tones must be a positive integer, got {self.tones!r}")
        if not (math.isfinite(self.tilt) and 0 <= self.tilt <= 3):
            raise InputError(f"MultisineShape.tilt must be in [0, 3], got {self.tilt!r}")

    def harmonics(self, period: float) -> np.ndarray:
        """The tones as harmonics of ``period`` [s]: log-spaced over the band; where rounding
        merges two, the lowest unused harmonics of the band are added."""
        lo = max(1, round(self.band[0] * period))
        hi = max(lo, round(self.band[1] * period))
        h = np.unique(np.round(np.geomspace(lo, hi, self.tones)).astype(int))
        missing = min(self.tones, hi - lo + 1) - h.size
        if missing > 0:
            h = np.union1d(h, np.setdiff1d(np.arange(lo, hi + 1), h)[:missing])
        return h

    def to_dict(self) -> dict:
        return {"band_hz": list(self.band), "tones": self.tones, "tilt": self.tilt}


def _period(duration: float) -> float:
    """The multisine's period: the whole run up to 20 s, else the run split into whole periods
    of 20-40 s (tones are harmonics of it; the spectrum of every period is the same)."""
    return duration / max(1, math.floor(duration / 20.0))


def _axis_terms(shape: MultisineShape, period: float, amplitude: float, clip_passes: int):
    h = shape.harmonics(period)
    f = h / period
    a = (f / f[0]) ** (-shape.tilt)
    phases, cf = multisine(h, a, clip_passes=clip_passes)
    # scale so that the period's peak is ``amplitude``
    t = np.arange(4096) / 4096
    peak = np.max(np.abs(np.sum(a[:, None] * np.sin(2 * math.pi * h[:, None] * t + phases[:, None]), axis=0)))
    a = a * amplitude / peak
    return tuple(
        (float(ak), float(2 * math.pi * fk), float(pk)) for ak, fk, pk in zip(a, f, phases, strict=True)
    ), cf


def multisine_reference(
    duration: float,
    *,
    vertical: MultisineShape | None = MultisineShape(),
    horizontal: MultisineShape | None = MultisineShape(),
    gap_amplitude: float = 4 * MM_TO_M,
    position_amplitude: float = 40 * MM_TO_M,
    gap_offset: float = 20 * MM_TO_M,
    clip_passes: int = 4,
    name: str = "multisine",
) -> SampledReference:
    """Schroeder-phased multisines on both axes, peaks ``gap_amplitude`` about ``gap_offset`` and
    ``position_amplitude`` about 0 [m], ramped in over 2 s; None leaves an axis at its offset."""
    t = _grid(duration)
    period = _period(duration)
    terms, crest = {}, {}
    for axis, shape, amp in (
        ("vertical", vertical, gap_amplitude),
        ("horizontal", horizontal, position_amplitude),
    ):
        if shape is None or amp == 0:
            terms[axis], crest[axis] = (), None
        else:
            terms[axis], crest[axis] = _axis_terms(shape, period, amp, clip_passes)
    ref = Sinusoids(gap_offset, terms["vertical"], terms["horizontal"], ramp_time=RAMP_TIME)
    cf = ", ".join(f"{k} {v:.2f}" for k, v in crest.items() if v is not None)
    return SampledReference(
        t, ref.sample(t), name, f"Schroeder multisine, {duration:g} s (crest factors {cf})"
    )


def _smoothed_levels(levels: np.ndarray, t: np.ndarray, bandwidth: float) -> np.ndarray:
    """(r, r', r'') of piecewise-constant ``levels`` through a critically damped second-order
    filter of ``bandwidth`` [rad/s] (the set-point steps become smooth, with finite rates)."""
    w = bandwidth
    a = np.array([[0.0, 1.0], [-(w**2), -2 * w]])
    b = np.array([[0.0], [w**2]])
    c = np.eye(2)
    d = np.zeros((2, 1))
    _, y, _ = lsim((a, b, c, d), levels, t, X0=[levels[0], 0.0], interp=False)
    acc = w**2 * (levels - y[:, 0]) - 2 * w * y[:, 1]
    return np.vstack([y[:, 0], y[:, 1], acc])


def prbs_reference(
    duration: float,
    *,
    gap_amplitude: float = 2 * MM_TO_M,
    position_amplitude: float = 30 * MM_TO_M,
    gap_offset: float = 20 * MM_TO_M,
    bit_time: tuple[float, float] = (0.25, 0.5),
    bandwidth: float = 2 * math.pi * 1.5,
    seed: int = 0,
    name: str = "prbs",
) -> SampledReference:
    """PRBS set-points on both axes: +-amplitude steps held for ``bit_time`` (vertical,
    horizontal) [s], smoothed by a critically damped filter of ``bandwidth`` [rad/s]. The order
    is the largest whose period fits the run (at least 3), so the sequence is played whole."""
    t = _grid(duration)
    rows = []
    for amp, offset, tb, s in (
        (gap_amplitude, gap_offset, bit_time[0], seed),
        (position_amplitude, 0.0, bit_time[1], seed + 1),
    ):
        if not tb > 0:
            raise InputError(f"bit_time must be positive [s], got {bit_time!r}")
        bits = duration / tb
        order = max(3, min(20, math.floor(math.log2(bits + 1))))
        seq = prbs(order, seed=s)
        idx = np.floor(t / tb).astype(int) % seq.size
        env = np.clip(t / RAMP_TIME, 0, 1)
        levels = offset + amp * seq[idx] * env
        rows.append(_smoothed_levels(levels, t, bandwidth))
    values = np.vstack(rows)
    return SampledReference(
        t, values, name, f"PRBS set-points, bits of {bit_time[0]:g}/{bit_time[1]:g} s, {duration:g} s"
    )


def gap_sweep_reference(
    duration: float,
    *,
    gaps: tuple[float, float] = (10 * MM_TO_M, 25 * MM_TO_M),
    sweep_period: float = 30.0,
    ripple: float = 4 * MM_TO_M,
    horizontal: MultisineShape | None = MultisineShape(),
    position_amplitude: float = 30 * MM_TO_M,
    name: str = "gap_sweep",
) -> SampledReference:
    """Slow levitation over ``gaps`` (a raised cosine of ``sweep_period`` [s], starting at the
    smallest gap) with a small Schroeder multisine ``ripple`` [m] on it (u2 off the equilibrium
    curve at every gap: C3 apart from C4) and a horizontal multisine (for C1).

    Separates a constant vertical force from C2: over 10-25 mm the equilibrium current goes from
    +5.3 A to -0.2 A (SPEC 1) and C2's column lam(x1) B(x1)^2 falls fourfold, while the force's
    column is constant; about one operating gap (the papers' +-4 mm at 20 mm) the two are nearly
    collinear.
    """
    t = _grid(duration)
    lo, hi = gaps
    if not 0 < lo < hi <= 0.1:
        raise InputError(f"gaps must be (low, high) in metres with low < high, got {gaps!r}")
    if not sweep_period > 0:
        raise InputError(f"sweep_period must be positive [s], got {sweep_period!r}")
    periods = max(1, round(duration / sweep_period))
    w = 2 * math.pi * periods / duration
    mid, half = (lo + hi) / 2, (hi - lo) / 2 - ripple
    if half <= 0:
        raise InputError(f"ripple {ripple!r} m leaves no room to sweep over {gaps!r}")
    sweep = np.vstack([mid - half * np.cos(w * t), half * w * np.sin(w * t), half * w**2 * np.cos(w * t)])
    period = _period(duration)
    vterms = _axis_terms(MultisineShape((0.2, 4.0), 8, 0.0), period, ripple, 4)[0] if ripple > 0 else ()
    hterms = _axis_terms(horizontal, period, position_amplitude, 4)[0] if horizontal is not None else ()
    values = Sinusoids(0.0, vterms, hterms, ramp_time=RAMP_TIME).sample(t)
    values[0:3] += sweep
    # the ripple may not carry the set-point out of the sweep's range
    values[0] = np.clip(values[0], lo, hi)
    return SampledReference(
        t,
        values,
        name,
        f"Gap sweep {lo * 1e3:g}-{hi * 1e3:g} mm ({periods} x {duration / periods:g} s) with a "
        f"{ripple * 1e3:g} mm ripple and a horizontal multisine, {duration:g} s",
    )


def _scaled(
    reference: SampledReference, vertical: float, horizontal: float, gap_offset: float
) -> SampledReference:
    """The reference with its excursions about ``gap_offset`` / 0 scaled per axis."""
    v = reference.values.copy()
    v[0] = gap_offset + vertical * (v[0] - gap_offset)
    v[1:3] *= vertical
    v[3:6] *= horizontal
    return SampledReference(reference.t, v, reference.name, reference.description)


# --- prediction ------------------------------------------------------------------------------
TARGETS = {
    "multisine": ("C1", "C2", "C3", "C4"),
    "prbs": ("C1", "C2", "C3", "C4"),
    "doptimal": ("C1", "C2", "C3", "C4"),
    "gap_sweep": ("C2", "C3", "C4", EFFECT),
    "papers": ("C1", "C2", "C3", "C4"),
}
"""The parameters each design targets (its D-optimality or its purpose)."""


@dataclass(frozen=True, eq=False)
class Prediction(Result):
    """A reference's predicted fit on the nominal twin.

    Attributes
    ----------
    names : tuple of str
        Parameters (C1..C4, then the effect parameter when asked).
    nominal : (p,) their nominal values
    covariance : (p, p) predicted covariance (sandwich, see the module docstring)
    log_det : float
        log det of the information of the parameters relative to ``nominal``, over C1..C4
        (-inf when singular).
    peak_current : (2,) [A] peak |i_q|, |i_d|; rms_current : float [A] RMS of |i|
    gap_range, position_range : (2,) [m] of the simulated run
    violations : tuple of str (feasibility set and budget)
    """

    names: tuple[str, ...]
    nominal: np.ndarray
    covariance: np.ndarray
    log_det: float
    peak_current: np.ndarray
    rms_current: float
    gap_range: np.ndarray
    position_range: np.ndarray
    violations: tuple[str, ...]
    timings: Mapping[str, float] = field(default_factory=dict)

    @property
    def success(self) -> bool:
        return not self.violations and math.isfinite(self.log_det)

    @property
    def status(self) -> str:
        return "feasible" if not self.violations else "infeasible"

    @property
    def message(self) -> str:
        return "; ".join(self.violations) if self.violations else "inside the feasibility set and the budget"

    @property
    def stderr(self) -> dict[str, float]:
        return dict(
            zip(self.names, np.sqrt(np.clip(np.diag(self.covariance), 0, None)).tolist(), strict=True)
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (plain floats and lists; a singular information's -inf log det -> None)."""
        return jsonable(
            {
                "stderr": self.stderr,
                "relative_stderr": {
                    k: v / abs(n) for (k, v), n in zip(self.stderr.items(), self.nominal, strict=True)
                },
                "log_det_relative_information": self.log_det,
                "peak_current_A": {"i_q": self.peak_current[0], "i_d": self.peak_current[1]},
                "rms_current_A": self.rms_current,
                "gap_range_m": self.gap_range,
                "position_range_m": self.position_range,
                "violations": list(self.violations),
                "success": self.success,
                "status": self.status,
                "message": self.message,
                "timings": dict(self.timings),
            }
        )


def _twin_backend() -> str:
    """The closed loops' backend here: "c" where a C compiler is found, else "vm" (module
    docstring: the same runs either way)."""
    return "c" if c_compiler() is not None else "vm"


class ExperimentDesigner:
    """Predicts the information of references on the nominal twin; build once, call many times.

    Parameters
    ----------
    model : StageModel
        The nominal model: the PIDs are placed on it, it is the prediction twin's plant, and the
        design is linearised at its constants.
    feasible : FeasibleSet
    encoder : Encoder
        The encoders whose error is the fit's residual (default: the twin's, 10 um and 2 um).
    design_gap : float
        [m] Where the PIDs are placed (20 mm, as the papers' excitation runs).
    residual_floor : float
        [(m/s^2)^2/Hz] One-sided density of the residual's low-frequency floor, added as white
        equation error to the encoders' h2-shaped part. Default 2e-7: measured on the twin (the
        fit's residual of the papers' excitation with the encoders on, 0.5-8 Hz, Welch; the
        quantization error of a slowly moving gap is not white but a staircase, and the h2 model
        alone underpredicts the density below 5 Hz by 10^2-10^5).
    """

    def __init__(
        self,
        model: StageModel,
        *,
        feasible: FeasibleSet | None = None,
        encoder: Encoder | None = None,
        design_gap: float = 20 * MM_TO_M,
        residual_floor: float = RESIDUAL_FLOOR,
    ) -> None:
        if not (residual_floor >= 0 and math.isfinite(residual_floor)):
            raise InputError(f"residual_floor must be non-negative, got {residual_floor!r}")
        self.residual_floor = residual_floor
        self.model = model
        self.feasible = FeasibleSet() if feasible is None else feasible
        self.noise_variance = encoder_noise_variance(encoder)
        self.controller = paper_pid(model, design_gap=design_gap)
        # noise-free prediction twin: the nominal plant behind the amplifiers (their lag and limit),
        # run as generated C where a compiler is found (:func:`_twin_backend`)
        twin = RigTwin(model, TwinEffects(amplifier=CurrentAmplifier()))
        self.loop = ClosedLoop(twin, self.controller, backend=_twin_backend())
        self.effect_term: AccelerationTerm = constant_force(model.params, "vertical")

    # ------------------------------------------------------------------------------------
    def simulate(self, reference: SampledReference) -> SimulationResult:
        return self.loop.run(reference.scenario())

    def predict(
        self,
        reference: SampledReference,
        *,
        effect: bool = False,
        budget: CurrentBudget | None = None,
        run: SimulationResult | None = None,
    ) -> Prediction:
        """Simulate ``reference`` on the noise-free twin and predict the fit's covariance.

        Parameters
        ----------
        reference : SampledReference
        effect : bool
            Estimate the constant vertical force too (:data:`EFFECT`).
        budget : CurrentBudget, optional
            Peak currents the run may use (checked beside the feasibility set).
        run : SimulationResult, optional
            A simulation of ``reference`` already made.
        """
        t0 = time.perf_counter()
        run = self.simulate(reference) if run is None else run
        t_sim = time.perf_counter() - t0
        violations = self.feasible.violations(reference, run)
        peak = np.nanmax(np.abs(run.u), axis=1) if run.success else np.full(2, np.nan)
        if budget is not None and run.success:
            for k, (axis, limit) in enumerate((("i_q", budget.horizontal), ("i_d", budget.vertical))):
                if peak[k] > limit * (1 + 1e-9):
                    violations.append(f"peak {axis} {peak[k]:.3f} A over the budget {limit:.3f} A")
        mag = np.hypot(run.u[0], run.u[1])
        names = CONSTANT_NAMES + ((EFFECT,) if effect else ())
        nominal = np.array([getattr(self.model.constants, c) for c in CONSTANT_NAMES] + [1.0] * effect)
        if not run.success:
            cov = np.full((len(names), len(names)), np.inf)
            log_det = -math.inf
        else:
            log = result_to_log(run, rate_hz=LOG_RATE_HZ)
            cov = self.covariance(log, effect=effect)
            rel = cov[:4, :4] / np.outer(nominal[:4], nominal[:4])
            sign, logdet_cov = np.linalg.slogdet(rel) if np.all(np.isfinite(rel)) else (0.0, 0.0)
            log_det = -float(logdet_cov) if sign > 0 else -math.inf
        return Prediction(
            names=names,
            nominal=nominal,
            covariance=cov,
            log_det=log_det,
            peak_current=peak,
            rms_current=math.sqrt(float(np.nanmean(mag**2))),
            gap_range=np.array([np.nanmin(run.x[0]), np.nanmax(run.x[0])]),
            position_range=np.array([np.nanmin(run.x[2]), np.nanmax(run.x[2])]),
            violations=tuple(violations),
            timings={"simulate": t_sim, "total": time.perf_counter() - t0},
        )

    def covariance(self, log, *, effect: bool = False) -> np.ndarray:
        """The sandwich covariance H^-1 M H^-1 of the equation-error fit of C1..C4 (and the
        constant vertical force) on a noise-free ``log`` with white encoder errors added."""
        terms = (self.effect_term,) if effect else ()
        problem = EquationError(log, self.model, estimate=CONSTANT_NAMES, terms=terms)
        prep = problem.prepared
        design = build_design(prep, self.model, estimate=CONSTANT_NAMES, terms=terms, weights=np.ones(2))
        x = design.columns * design.fit[None, None, :]
        sg = prep.differentiator
        h2 = savgol_coeffs(sg.acceleration_window, sg.polyorder, deriv=2, delta=sg.sample_time, use="conv")
        P = x.shape[0]
        H = np.zeros((P, P))
        M = np.zeros((P, P))

        def H_axis(xa):
            return xa @ xa.T

        for a in range(2):
            xa = x[:, a, :]
            H += H_axis(xa)
            g = fftconvolve(xa, h2[None, :], mode="full", axes=-1)
            M += self.noise_variance * (g @ g.T)
            # the low-frequency floor as white equation error of variance density * fs / 2
            M += self.residual_floor / (2 * sg.sample_time) * H_axis(xa)
        try:
            Hi = np.linalg.inv(H)
        except np.linalg.LinAlgError:
            return np.full((P, P), np.inf)
        if not np.all(np.isfinite(Hi)) or np.linalg.cond(H) > 1e14:
            return np.full((P, P), np.inf)
        cov = Hi @ M @ Hi
        return 0.5 * (cov + cov.T)

    # ------------------------------------------------------------------------------------
    def papers_budget(self, duration: float, *, seed: int = 0) -> tuple[CurrentBudget, Prediction]:
        """The current budget of the papers' excitation of ``duration`` (its simulated peaks)."""
        ref = papers_reference(duration, seed=seed)
        pred = self.predict(ref)
        if not pred.success:
            raise SolverError(f"the papers' excitation is infeasible on the nominal twin: {pred.message}")
        return CurrentBudget(
            vertical=float(pred.peak_current[1]), horizontal=float(pred.peak_current[0])
        ), pred

    def fit_to_budget(
        self,
        make,
        budget: CurrentBudget,
        *,
        effect: bool = False,
        iterations: int = 4,
    ) -> tuple[SampledReference, Prediction]:
        """The largest scaling of a reference family ``make(vertical, horizontal)`` (peak set-point
        excursions [m]) inside the feasibility set and the budget, and its prediction.

        The dynamic currents are nearly linear in the excursions, so each pass rescales by the
        ratio of the budget to the simulated peak (less the holding current for i_d), bounded
        by the set-point ranges; a pass that overshoots is scaled back by 3 %.
        """
        fs = self.feasible
        gap_offset = 20 * MM_TO_M
        hold = abs(self.controller_hold(gap_offset))
        amp_max = np.array(
            [min(gap_offset - fs.gap[0], fs.gap[1] - gap_offset), min(-fs.position[0], fs.position[1])]
        )
        amp = amp_max.copy()
        best: tuple[SampledReference, Prediction] | None = None
        pred = None
        for _ in range(iterations):
            ref = make(float(amp[0]), float(amp[1]))
            pred = self.predict(ref, effect=effect, budget=budget)
            if pred.success and (best is None or pred.log_det > best[1].log_det):
                best = (ref, pred)
            if not np.all(np.isfinite(pred.peak_current)):  # the run failed: back off
                amp = amp * 0.5
                continue
            dyn_v = max(pred.peak_current[1] - hold, 1e-6)
            ratio = np.array(
                [(budget.vertical - hold) / dyn_v, budget.horizontal / max(pred.peak_current[0], 1e-6)]
            )
            new = np.minimum(amp * ratio * 0.99, amp_max)
            if not pred.success and np.all(ratio >= 1):  # infeasible for another reason than the budget
                new = amp * 0.9
            if pred.success and np.allclose(new, amp, rtol=0.03):
                break
            amp = new
        if best is None:
            raise SolverError(
                f"no scaling of the {make(*amp).name} reference fits the feasibility set and the "
                f"budget: {pred.message}"
            )
        return best

    def controller_hold(self, gap: float) -> float:
        """The equilibrium i_d at ``gap`` on the nominal model [A]."""
        from maglev_oc.model.equilibrium import equilibrium_currents

        curve = equilibrium_currents(self.model, [gap])
        return float(curve.current[0])


# --- designs -------------------------------------------------------------------------------
DOPTIMAL_GRID = (
    MultisineShape((0.1, 3.0), 6, 0.5),
    *(MultisineShape((0.2, hi), 8, tilt) for hi in (2.0, 4.0) for tilt in (0.0, 1.0)),
)
"""The family the D-optimal design searches (per axis, paired): the papers' spectrum (6 tones over
0.1-3 Hz, amplitudes falling as 1/sqrt(f), 000 Sec. IV) with Schroeder phases, and 8 tones from
0.2 Hz to 2 or 4 Hz, position amplitudes flat or falling as 1/f (five shapes: about 20 simulations).
The papers' excitation itself is the incumbent: kept when no shape beats it."""


@dataclass(frozen=True, eq=False)
class ExperimentDesign(Result):
    """A designed experiment: the reference to play, what it targets and what it predicts.

    Attributes
    ----------
    kind : str
    reference : SampledReference
    targets : tuple of str
        Parameters the design is for.
    purpose : str
    prediction : Prediction
        On the nominal twin, within ``budget``.
    budget : CurrentBudget
    baseline : Prediction or None
        The papers' sum-of-sines excitation of the same duration, same budget.
    settings : dict
        The chosen shapes, seed, duration.
    candidates : list of dict
        The D-optimal search (shape, log det, feasible).
    """

    kind: str
    reference: SampledReference
    targets: tuple[str, ...]
    purpose: str
    prediction: Prediction
    budget: CurrentBudget
    baseline: Prediction | None
    settings: dict
    candidates: tuple[dict, ...] = ()
    timings: Mapping[str, float] = field(default_factory=dict)

    @property
    def success(self) -> bool:
        return self.prediction.success

    @property
    def status(self) -> str:
        return self.prediction.status

    @property
    def message(self) -> str:
        return self.prediction.message

    def improvement(self) -> dict[str, float]:
        """Predicted standard error of each target relative to the papers' excitation (< 1: better)."""
        if self.baseline is None:
            return {}
        a, b = self.prediction.stderr, self.baseline.stderr
        return {k: a[k] / b[k] for k in self.targets if k in a and k in b and b[k] > 0}

    def to_dict(self) -> dict[str, Any]:
        return jsonable(
            {
                "format": "maglev_oc experiment design 1",
                "kind": self.kind,
                "reference": {
                    "name": self.reference.name,
                    "description": self.reference.description,
                    "duration_s": self.reference.duration,
                    "sample_rate_hz": REFERENCE_RATE_HZ,
                    "columns": list(REFERENCE_COLUMNS),
                    "gap_range_m": [self.reference.values[0].min(), self.reference.values[0].max()],
                    "position_range_m": [self.reference.values[3].min(), self.reference.values[3].max()],
                },
                "targets": list(self.targets),
                "purpose": self.purpose,
                "controller": "paper PIDs placed at 20 mm (000 Sec. IV), the loop of the prediction",
                "budget_A": {"i_d": self.budget.vertical, "i_q": self.budget.horizontal},
                "predicted": self.prediction.to_dict(),
                "papers_excitation_predicted": None if self.baseline is None else self.baseline.to_dict(),
                "stderr_ratio_to_papers": self.improvement(),
                "settings": self.settings,
                "candidates": list(self.candidates),
                "success": self.success,
                "status": self.status,
                "message": self.message,
                "timings": dict(self.timings),
            }
        )

    def report(self) -> str:
        lines = [
            f"[[Experiment design: {self.kind}]] {self.reference.description}",
            f"  targets: {', '.join(self.targets)} — {self.purpose}",
        ]
        se = self.prediction.stderr
        base = self.baseline.stderr if self.baseline is not None else {}
        for name in self.prediction.names:
            b = f"   papers' excitation {base[name]:.3g}" if name in base else ""
            lines.append(f"  predicted SE {name:32s} {se[name]:.3g}{b}")
        lines.append(
            f"  peak currents i_q {self.prediction.peak_current[0]:.3f} A, "
            f"i_d {self.prediction.peak_current[1]:.3f} A "
            f"(budget {self.budget.horizontal:.3f} / {self.budget.vertical:.3f} A); "
            f"{self.status}: {self.message}"
        )
        return "\n".join(lines)


PURPOSE = {
    "multisine": "all four constants: Schroeder multisines (low crest factor) on both axes",
    "prbs": "all four constants: PRBS set-points on both axes (flat spectrum)",
    "doptimal": "all four constants: the multisine shape maximising log det of the information of C1..C4",
    "gap_sweep": "a constant vertical force apart from C2 (the scale of the vertical magnetic force): "
    "slow levitation over 10-25 mm, where C2's column changes fourfold and the force's does not, "
    "with a vertical multisine on it (the accelerations fix the magnetic constants' common scale, "
    "which quasi-static data trade against a constant force)",
}


def design_experiment(
    kind: str,
    duration: float = 60.0,
    *,
    model: StageModel | None = None,
    seed: int = 0,
    designer: ExperimentDesigner | None = None,
    budget: CurrentBudget | None = None,
    grid: Sequence[MultisineShape] = DOPTIMAL_GRID,
) -> ExperimentDesign:
    """Design an experiment of ``kind`` (:data:`KINDS`) lasting ``duration`` [s].

    The multisine, PRBS and D-optimal designs get the current budget of the papers' excitation
    of the same duration (unless ``budget`` is given) and are scaled to fill it; the gap sweep
    needs the holding current at 10 mm (5.3 A) and is bounded by the 9 A limit only. ``seed``
    sets the papers' excitation phases (the baseline) and the PRBS shift.
    """
    if kind not in KINDS:
        raise InputError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")
    if not (isinstance(duration, (int, float)) and math.isfinite(duration) and 10.0 <= duration <= 3600.0):
        raise InputError(f"duration must be between 10 and 3600 s, got {duration!r}")
    t0 = time.perf_counter()
    model = StageModel() if model is None else model
    designer = ExperimentDesigner(model) if designer is None else designer
    effect = kind == "gap_sweep"
    papers_budget, _ = designer.papers_budget(duration, seed=seed)
    baseline = designer.predict(papers_reference(duration, seed=seed), effect=effect)
    if budget is None:
        budget = CurrentBudget() if kind == "gap_sweep" else papers_budget
    candidates: list[dict] = []
    settings: dict[str, Any] = {"duration_s": duration, "seed": seed}
    if kind == "multisine":
        shape = MultisineShape()
        ref, pred = designer.fit_to_budget(
            lambda v, h: multisine_reference(
                duration, vertical=shape, horizontal=shape, gap_amplitude=v, position_amplitude=h
            ),
            budget,
        )
        settings |= {"vertical": shape.to_dict(), "horizontal": shape.to_dict()}
    elif kind == "prbs":
        ref, pred = designer.fit_to_budget(
            lambda v, h: prbs_reference(duration, gap_amplitude=v, position_amplitude=h, seed=seed), budget
        )
        settings |= {"bit_time_s": [0.25, 0.5], "filter_bandwidth_rad_s": 2 * math.pi * 1.5}
    elif kind == "doptimal":
        ref, pred, candidates, chosen = _doptimal(designer, duration, budget, grid)
        settings |= chosen
        candidates.append({"shape": "papers' sum of sines", "feasible": True, "log_det": baseline.log_det})
        if baseline.log_det > pred.log_det and budget == papers_budget:
            # the incumbent is in the family: no shape beat the papers' excitation at this duration
            ref, pred = papers_reference(duration, seed=seed), baseline
            settings |= {"vertical": "papers' sum of sines", "horizontal": "papers' sum of sines"}
    else:
        ref = gap_sweep_reference(duration)
        pred = designer.predict(ref, effect=True, budget=budget)
        settings |= {"gaps_m": [10e-3, 25e-3], "sweep_period_s": 30.0, "ripple_m": 4e-3}
    ref = dataclasses.replace(ref, name=kind)
    return ExperimentDesign(
        kind=kind,
        reference=ref,
        targets=TARGETS[kind],
        purpose=PURPOSE[kind],
        prediction=pred,
        budget=budget,
        baseline=baseline,
        settings=settings,
        candidates=tuple(candidates),
        timings={"total": time.perf_counter() - t0},
    )


def _doptimal(
    designer: ExperimentDesigner, duration: float, budget: CurrentBudget, grid: Sequence[MultisineShape]
):
    """Grid search: each shape on both axes at once (the axes' information blocks are nearly
    independent: C1 is horizontal only, C2..C4 vertical), scaled to the budget; then the best
    vertical shape is paired with the best horizontal one and scaled again."""
    if not grid:
        raise InputError("the D-optimal grid is empty")
    rows = []
    for shape in grid:
        try:
            ref, pred = designer.fit_to_budget(
                lambda v, h, s=shape: multisine_reference(
                    duration, vertical=s, horizontal=s, gap_amplitude=v, position_amplitude=h
                ),
                budget,
                iterations=3,
            )
        except SolverError as err:
            rows.append({"shape": shape.to_dict(), "feasible": False, "message": str(err)})
            continue
        cov = pred.covariance
        nom = pred.nominal
        ld_h = -math.log(cov[0, 0] / nom[0] ** 2)
        sign, ld = np.linalg.slogdet(cov[1:4, 1:4] / np.outer(nom[1:4], nom[1:4]))
        ld_v = -float(ld) if sign > 0 else -math.inf
        rows.append(
            {
                "shape": shape.to_dict(),
                "feasible": True,
                "log_det": pred.log_det,
                "log_det_C1": ld_h,
                "log_det_C2_C4": ld_v,
                "_s": shape,
            }
        )
    ok = [r for r in rows if r["feasible"]]
    if not ok:
        raise SolverError("no shape of the D-optimal grid fits the feasibility set and the budget")
    best_h = max(ok, key=lambda r: r["log_det_C1"])["_s"]
    best_v = max(ok, key=lambda r: r["log_det_C2_C4"])["_s"]
    best_joint = max(ok, key=lambda r: r["log_det"])
    ref, pred = designer.fit_to_budget(
        lambda v, h: multisine_reference(
            duration, vertical=best_v, horizontal=best_h, gap_amplitude=v, position_amplitude=h
        ),
        budget,
    )
    chosen = {"vertical": best_v.to_dict(), "horizontal": best_h.to_dict()}
    if best_joint["log_det"] > pred.log_det:  # pairing lost to a joint shape: keep the joint one
        s = best_joint["_s"]
        ref, pred = designer.fit_to_budget(
            lambda v, h: multisine_reference(
                duration, vertical=s, horizontal=s, gap_amplitude=v, position_amplitude=h
            ),
            budget,
        )
        chosen = {"vertical": s.to_dict(), "horizontal": s.to_dict()}
    for r in rows:
        r.pop("_s", None)
    return ref, pred, rows, chosen


# --- files ---------------------------------------------------------------------------------
def write_design(out_dir: str | os.PathLike, design: ExperimentDesign) -> dict[str, Path]:
    """Write ``reference.csv``, ``reference.mat`` (MATLAB v5) and ``design.json`` into ``out_dir``,
    each atomically (a temporary file renamed into place)."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: is a file; --out takes a folder")
    ref = design.reference
    table = np.vstack(
        [ref.t, ref.values[0], ref.values[3], ref.values[1], ref.values[4], ref.values[2], ref.values[5]]
    )
    meta = {
        "format": "maglev_oc reference (set-points for the closed loop)",
        "units": "SI (t [s]; r_gap, r_position [m]; *_rate [m/s]; *_acc [m/s^2])",
        "sample_rate_hz": f"{REFERENCE_RATE_HZ:g}",
        "design": design.kind,
        "targets": " ".join(design.targets),
        "description": ref.description,
    }
    lines = [f"# {k}: {v}\n" for k, v in meta.items()]
    lines.append(",".join(REFERENCE_COLUMNS) + "\n")
    row = ",".join(["%.17g"] * len(REFERENCE_COLUMNS)) + "\n"
    lines.append((row * table.shape[1]) % tuple(table.T.ravel().tolist()))
    paths = {"csv": out / "reference.csv", "mat": out / "reference.mat", "json": out / "design.json"}
    with atomic_path(paths["csv"]) as tmp:
        tmp.write_text("".join(lines), encoding="utf-8")
    payload: dict[str, object] = {name: table[k] for k, name in enumerate(REFERENCE_COLUMNS)}
    payload["metadata"] = {k.replace(" ", "_"): v for k, v in meta.items()}
    with atomic_path(paths["mat"]) as tmp, tmp.open("wb") as fh:
        scipy.io.savemat(fh, payload, oned_as="column", format="5")
    with atomic_path(paths["json"]) as tmp:
        tmp.write_text(json.dumps(design.to_dict(), indent=2) + "\n", encoding="utf-8")
    return paths


def read_reference(path: str | os.PathLike) -> SampledReference:
    """Read a reference file written by :func:`write_design` (.csv or .mat)."""
    path = Path(path)
    if path.suffix.lower() == ".mat":
        data = scipy.io.loadmat(path)
        missing = [c for c in REFERENCE_COLUMNS if c not in data]
        if missing:
            raise InputError(f"{path}: missing variables {missing}")
        cols = {c: np.asarray(data[c], dtype=float).ravel() for c in REFERENCE_COLUMNS}
    else:
        text = path.read_text(encoding="utf-8").splitlines()
        body = [ln for ln in text if not ln.startswith("#")]
        header = body[0].split(",")
        if tuple(header) != REFERENCE_COLUMNS:
            raise InputError(f"{path}: header {header} is not {list(REFERENCE_COLUMNS)}")
        table = np.loadtxt(body[1:], delimiter=",", ndmin=2)
        cols = {c: table[:, k] for k, c in enumerate(REFERENCE_COLUMNS)}
    values = np.vstack(
        [
            cols[c]
            for c in ("r_gap", "r_gap_rate", "r_gap_acc", "r_position", "r_position_rate", "r_position_acc")
        ]
    )
    return SampledReference(cols["t"], values, path.stem)


# --- the check on the rig twin ----------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class TwinCheck(Result):
    """A reference played on the rig twin and identified: predicted against achieved.

    Attributes
    ----------
    names : tuple of str
    predicted : dict name -> predicted standard error
    achieved : dict name -> mean over seeds of the fit's (HAC) standard error
    spread : dict name -> standard deviation of the estimates over seeds (NaN for one seed)
    error : dict name -> mean |estimate - truth| over seeds (the effect's truth is 0 N)
    peak_current : (2,) [A] peak commanded |i_q|, |i_d| on the rig twin
    """

    reference: str
    names: tuple[str, ...]
    predicted: dict[str, float]
    achieved: dict[str, float]
    spread: dict[str, float]
    error: dict[str, float]
    peak_current: np.ndarray
    seeds: tuple[int, ...]
    success: bool
    status: str
    message: str
    timings: Mapping[str, float] = field(default_factory=dict)


def check_on_twin(
    reference: SampledReference,
    prediction: Prediction,
    *,
    model: StageModel | None = None,
    truth: StageModel | None = None,
    seeds: Sequence[int] = (0,),
    effect: bool | None = None,
) -> TwinCheck:
    """Play ``reference`` on the rig twin (encoders, amplifiers, :data:`TWIN_TRUTH`; as generated
    C where a compiler is found, :func:`_twin_backend`), identify with the equation-error fit of
    :func:`~maglev_oc.identification.pipeline.identify` (C1..C4 and, if the prediction has it, the
    constant vertical force; the same checks of the log and the same fit, without identify's
    validation, which the comparison does not use) and compare the standard errors."""
    from maglev_oc.identification.pipeline import check_identifiable

    t0 = time.perf_counter()
    model = StageModel() if model is None else model
    truth = model.with_constants(TWIN_TRUTH) if truth is None else truth
    effect = (EFFECT in prediction.names) if effect is None else effect
    terms = (constant_force(model.params, "vertical"),) if effect else ()
    loop = ClosedLoop(
        RigTwin(truth, identification_effects()),
        paper_pid(model, design_gap=20 * MM_TO_M),
        backend=_twin_backend(),
    )
    names = CONSTANT_NAMES + ((EFFECT,) if effect else ())
    true_values = {c: getattr(truth.constants, c) for c in CONSTANT_NAMES} | {EFFECT: 0.0}
    est, se = {n: [] for n in names}, {n: [] for n in names}
    peak = np.zeros(2)
    t_sim = t_fit = 0.0
    for seed in seeds:
        ts = time.perf_counter()
        run = loop.run(reference.scenario(), seed=seed)
        t_sim += time.perf_counter() - ts
        if not run.success:
            return TwinCheck(
                reference.name,
                names,
                prediction.stderr,
                {},
                {},
                {},
                peak,
                tuple(seeds),
                False,
                "failed",
                run.message,
            )
        peak = np.maximum(peak, np.max(np.abs(run.u), axis=1))
        log = dataclasses.replace(
            result_to_log(run, rate_hz=LOG_RATE_HZ), source=f"twin:{reference.name}:seed{seed}"
        )
        ts = time.perf_counter()
        check_identifiable([log], CONSTANT_NAMES)
        fit = EquationError([log], model, estimate=CONSTANT_NAMES, terms=terms).fit()
        t_fit += time.perf_counter() - ts
        for n in names:
            est[n].append(fit.values[n])
            se[n].append(fit.stderr[n])
    achieved = {n: float(np.mean(se[n])) for n in names}
    spread = {n: float(np.std(est[n], ddof=1)) if len(seeds) > 1 else math.nan for n in names}
    error = {n: float(np.mean(np.abs(np.array(est[n]) - true_values[n]))) for n in names}
    return TwinCheck(
        reference=reference.name,
        names=names,
        predicted={n: prediction.stderr[n] for n in names},
        achieved=achieved,
        spread=spread,
        error=error,
        peak_current=peak,
        seeds=tuple(seeds),
        success=True,
        status="identified",
        message=f"{len(seeds)} run(s) identified",
        timings={"simulate": t_sim, "identify": t_fit, "total": time.perf_counter() - t0},
    )
