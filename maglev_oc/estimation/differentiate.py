"""Velocity and acceleration from sampled, quantized positions (for identification from logs).

Two estimators with the same call, ``estimator(y) -> Derivatives``:

:class:`SavitzkyGolay`
    Zero-phase, non-causal smoothing differentiator (local polynomial fit over a centred window,
    ``scipy.signal.savgol_filter``). The window is the longest whose gain error stays within
    ``tolerance`` (1 %) of the exact derivative up to ``bandwidth`` [Hz], chosen separately for
    velocity and acceleration; above the bandwidth the filter attenuates the quantization noise.
:class:`HighGainDifferentiator`
    The papers' high-gain observer (002 NPFSI sidebar, 000 Sec. IV) for the velocity, exactly the
    :class:`~maglev_oc.estimation.high_gain.HighGainObserver` the real-time controller runs
    (causal, one sample late, phase lag of about 2 eps omega at low frequency), plus a
    third-order variant with error polynomial (s + 1/eps_a)^3 for the acceleration.

Which to use
------------
Offline equation-error identification (regress x2' on the model's terms at the same instants)
wants derivatives without phase lag: a lag turns into a bias of the identified constants,
because the regressors (currents, gap) are taken at t while a lagged estimate belongs to an
earlier t. Use :class:`SavitzkyGolay` there; its errors are 25-55x smaller for the velocity and
4-10x for the acceleration (table below). Use :class:`HighGainDifferentiator` to reproduce what
the papers' NPFSI estimator and the real-time controller saw (their velocities are observer
estimates), or wherever a causal estimate is needed.

Measured (``tests/test_differentiate.py::test_docstring_table`` recomputes it): position =
20 mm + five sines, amplitudes (3, 2, 2, 1, 1) mm at (0.2, 0.5, 1.3, 2.9, 5.0) Hz (the papers'
PID runs track "a sum of sinusoids at various frequencies", 000 Sec. IV, without giving them),
10 s, quantized to 10 um; RMS error over 0.5..9.5 s (the observers' start-up transient left
out; with the window edges included the SG figures grow by less than 10 %). True RMS velocity
28.6 mm/s, acceleration 0.74 m/s^2. Defaults: SG bandwidth 20 Hz, polyorder 5, 1 % in-band
gain error; observers eps = 2 ms (velocity, the controller's), eps_a = 5 ms (acceleration).

    rate   method                  velocity RMS error   acceleration RMS error  SG windows
    1 kHz  Savitzky-Golay 20 Hz    0.13 mm/s            0.072 m/s^2             47, 27
    1 kHz  high-gain observers     3.5 mm/s             0.32 m/s^2
    5 kHz  Savitzky-Golay 20 Hz    0.057 mm/s           0.031 m/s^2             241, 135
    5 kHz  high-gain observers     3.0 mm/s             0.33 m/s^2

The observers' error is lag (2 eps omega for the velocity, plus the one-sample delay), not
noise: without quantization it is 3.4 and 3.0 mm/s. Savitzky-Golay's error is the quantization
noise left in the band: 0.00006 mm/s without quantization, and with it sigma_q ||h||_2 where
sigma_q = q / sqrt(12) = 2.9 um (``SavitzkyGolay.noise_gain``; 0.136 mm/s predicted at 1 kHz).
A lower bandwidth lowers it (10 Hz: 0.047 mm/s and 0.013 m/s^2 at 1 kHz) if the data allow.

The observers are discretized for samples held over each period (exact ZOH, as in
``high_gain.py``), but a position sampled from a moving stage is not held: the sawtooth between
the staircase and the true position, aliased at the sample instants, scales the velocity
estimate by 1 - (T/eps)^2 / 12 (-2.1 % at 1 kHz, -0.08 % at 5 kHz with eps = 2 ms) and biases
the acceleration estimate by -v T^2 / (12 eps_a^3) (-0.67 s^-1 times the velocity at 1 kHz,
-0.027 s^-1 at 5 kHz). ``test_third_order_observer_on_a_parabola`` checks the formula.

The samples are taken as equally spaced at the log's median step (the log reader refuses
gaps larger than 1.5 steps).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np
from scipy.linalg import expm
from scipy.signal import lfilter, savgol_coeffs, savgol_filter, ss2tf

from maglev_oc.data.logs import Log
from maglev_oc.errors import InputError
from maglev_oc.estimation.high_gain import DEFAULT_EPSILON, HighGainObserver
from maglev_oc.model.hardware import ENCODER_RESOLUTION

__all__ = [
    "DEFAULT_ACCELERATION_EPSILON",
    "DEFAULT_BANDWIDTH",
    "QUANTIZATION_STEP",
    "Derivatives",
    "HighGainDifferentiator",
    "SavitzkyGolay",
    "differentiate_log",
    "savgol_gain_error",
    "with_estimated_velocities",
]

DEFAULT_BANDWIDTH = 20.0
"""[Hz] Default band of the smoothing differentiator: 4x the highest frequency of the sum-of-sines
excitation above (5 Hz) and 2x the fastest regulator pole of SPEC 4 (-57.9 rad/s = 9.2 Hz), so
the closed-loop transients pass too."""
DEFAULT_ACCELERATION_EPSILON = 5e-3
"""[s] Time constant of the third-order observer for the acceleration: poles at -200 rad/s.
Measured on the sum of sines of the table above scaled to 5 % (so that lag does not matter),
quantized to 10 um: the acceleration error is 0.20 m/s^2 at eps_a = 2 ms and 0.03 m/s^2 at 5 ms
(1 and 5 kHz alike); the price is lag, 3 eps_a omega = 0.09 rad at 1 Hz."""
QUANTIZATION_STEP = ENCODER_RESOLUTION
"""[m] Encoder resolution (000 Sec. II, 002), used for the noise figures in the settings."""


@dataclass(frozen=True)
class Derivatives:
    """Position, velocity and acceleration estimates, each the shape of the input position.

    Attributes
    ----------
    position : array [m]
    velocity : array [m/s]
    acceleration : array [m/s^2]
    sample_time : float
        [s]
    method : str
        "savitzky_golay" or "high_gain_observer".
    settings : mapping
        Everything that determined the estimates (windows, bandwidth, eps, ...); for
        Savitzky-Golay also ``velocity_quantization_noise`` [m/s] and
        ``acceleration_quantization_noise`` [m/s^2], the RMS error 10 um steps cause.
    """

    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    sample_time: float
    method: str
    settings: Mapping[str, float | int | str]


def _as_rows(y: np.ndarray, name: str = "y") -> np.ndarray:
    y = np.asarray(y, dtype=float)
    if y.ndim not in (1, 2) or y.shape[-1] < 2:
        raise InputError(f"{name}: expected shape (n,) or (m, n) with n >= 2 samples, got {y.shape}")
    if not np.all(np.isfinite(y)):
        raise InputError(
            f"{name}: positions must be finite (NaN or inf at index {np.argwhere(~np.isfinite(y))[0]})"
        )
    return y


def _check_sample_time(sample_time: float) -> None:
    if not (sample_time > 0 and math.isfinite(sample_time)):
        raise InputError(f"sample_time must be positive [s], got {sample_time!r}")


# --- Savitzky-Golay ---------------------------------------------------------------------------
def savgol_gain_error(window: int, polyorder: int, deriv: int, sample_time: float, bandwidth: float) -> float:
    """Largest relative gain error |H(f) / (j 2 pi f)^deriv - 1| of the centred SG filter on (0, bandwidth].

    Evaluated at 32 frequencies bandwidth/32 .. bandwidth; the SG filter is exact for
    polynomials, so the error grows from zero at f = 0.

    Parameters
    ----------
    window : int
        Window length [samples], odd.
    polyorder : int
        Degree of the local polynomial.
    deriv : int
        Order of the derivative (1 velocity, 2 acceleration).
    sample_time : float
        [s].
    bandwidth : float
        [Hz].

    Returns
    -------
    float
        The largest relative gain error [-].
    """
    h = savgol_coeffs(window, polyorder, deriv=deriv, use="dot")  # unit spacing
    offsets = np.arange(window) - (window - 1) // 2
    omega = 2 * np.pi * sample_time * bandwidth * np.arange(1, 33) / 32  # rad/sample
    response = np.exp(1j * np.outer(omega, offsets)) @ h
    return float(np.max(np.abs(response / (1j * omega) ** deriv - 1)))


def _longest_window(
    sample_time: float, bandwidth: float, polyorder: int, deriv: int, tolerance: float
) -> int:
    """Longest odd window whose in-band gain error is within tolerance (bisection; error grows with it)."""
    shortest = polyorder + 1 if polyorder % 2 == 0 else polyorder + 2

    def ok(w: int) -> bool:
        return savgol_gain_error(w, polyorder, deriv, sample_time, bandwidth) <= tolerance

    if not ok(shortest):
        raise InputError(
            f"bandwidth {bandwidth:g} Hz is too close to the Nyquist frequency {0.5 / sample_time:g} Hz: "
            f"even a {shortest}-sample window misses the derivative by more than {tolerance:g}"
        )
    upper = shortest + 2 * max(1, round(1 / (bandwidth * sample_time)))  # one period of the band edge
    while ok(upper):
        upper = 2 * upper + 1
        if upper > 10_000_000:
            raise InputError(f"no window limit found for bandwidth {bandwidth:g} Hz")
    lo, hi = (shortest - 1) // 2, (upper - 1) // 2  # half-widths: lo passes, hi fails
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if ok(2 * mid + 1) else (lo, mid)
    return 2 * lo + 1


@dataclass(frozen=True)
class SavitzkyGolay:
    """Zero-phase smoothing differentiator with its windows chosen from a bandwidth.

    Parameters
    ----------
    sample_time : float
        [s]
    bandwidth : float
        [Hz] Up to this frequency the velocity and acceleration gains are within ``tolerance``
        of the exact derivative's (default 20 Hz, see ``DEFAULT_BANDWIDTH``).
    polyorder : int
        Degree of the local polynomial, 2..5 (default 5). For the velocity 3 and 4 give the same
        filter, as do 5 and 6; for the acceleration 2 and 3, and 4 and 5. Higher degrees allow
        longer windows for the same in-band error, hence less noise; above 5 scipy's
        coefficients lose accuracy (their sum, which should be 0, leaks the offset).
    tolerance : float
        Relative gain error allowed in the band (default 0.01).

    Attributes
    ----------
    velocity_window, acceleration_window : int
        Window lengths [samples] (the position uses the velocity window).
    noise_gain : mapping
        ||h||_2 of the velocity [1/s] and acceleration [1/s^2] filters: white position noise of
        standard deviation sigma gives sigma * noise_gain RMS in the estimate.
    """

    sample_time: float
    bandwidth: float = DEFAULT_BANDWIDTH
    polyorder: int = 5
    tolerance: float = 0.01
    velocity_window: int = field(init=False)
    acceleration_window: int = field(init=False)
    noise_gain: Mapping[str, float] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        _check_sample_time(self.sample_time)
        if not (self.bandwidth > 0 and math.isfinite(self.bandwidth)):
            raise InputError(f"bandwidth must be positive [Hz], got {self.bandwidth!r}")
        if isinstance(self.polyorder, bool) or self.polyorder not in (2, 3, 4, 5):
            raise InputError(f"polyorder must be 2, 3, 4 or 5, got {self.polyorder!r}")
        if not (0 < self.tolerance < 1):
            raise InputError(f"tolerance must be in (0, 1), got {self.tolerance!r}")
        args = (self.sample_time, self.bandwidth, self.polyorder)
        wv = _longest_window(*args, deriv=1, tolerance=self.tolerance)
        wa = _longest_window(*args, deriv=2, tolerance=self.tolerance)
        gain = {
            "velocity": float(np.linalg.norm(savgol_coeffs(wv, self.polyorder, deriv=1))) / self.sample_time,
            "acceleration": float(np.linalg.norm(savgol_coeffs(wa, self.polyorder, deriv=2)))
            / self.sample_time**2,
        }
        object.__setattr__(self, "velocity_window", wv)
        object.__setattr__(self, "acceleration_window", wa)
        object.__setattr__(self, "noise_gain", MappingProxyType(gain))

    def __call__(self, y: np.ndarray) -> Derivatives:
        """Estimates from positions ``y`` [m], shape (n,) or (m, n) (samples along the last axis)."""
        y = _as_rows(y)
        n = y.shape[-1]
        longest = max(self.velocity_window, self.acceleration_window)
        if n < longest:
            raise InputError(
                f"y has {n} samples but the {self.bandwidth:g} Hz bandwidth needs windows of "
                f"{self.velocity_window} and {self.acceleration_window}; raise the bandwidth or use "
                "a longer log"
            )
        y0 = y[..., :1]
        dy = y - y0  # the filters are linear and kill constants; this keeps rounding off the offset
        kw = {"polyorder": self.polyorder, "delta": self.sample_time, "axis": -1, "mode": "interp"}
        position = y0 + savgol_filter(dy, self.velocity_window, deriv=0, **kw)
        velocity = savgol_filter(dy, self.velocity_window, deriv=1, **kw)
        acceleration = savgol_filter(dy, self.acceleration_window, deriv=2, **kw)
        sigma = QUANTIZATION_STEP / math.sqrt(12)
        settings = {
            "bandwidth_hz": self.bandwidth,
            "polyorder": self.polyorder,
            "tolerance": self.tolerance,
            "velocity_window": self.velocity_window,
            "acceleration_window": self.acceleration_window,
            "velocity_quantization_noise": sigma * self.noise_gain["velocity"],
            "acceleration_quantization_noise": sigma * self.noise_gain["acceleration"],
            "edges": "polynomial fit over the first/last window (mode='interp')",
        }
        return Derivatives(
            position, velocity, acceleration, self.sample_time, "savitzky_golay", MappingProxyType(settings)
        )


# --- high-gain observers ----------------------------------------------------------------------
def _third_order_observer(sample_time: float, epsilon: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact ZOH discretization of the third-order high-gain observer (position, velocity, acceleration).

        p' = v + (3/eps) (y - p),  v' = a + (3/eps^2) (y - p),  a' = (1/eps^3) (y - p),

    error polynomial (s + 1/eps)^3, the same construction as the second-order observer of
    ``high_gain.py`` with one more integrator.
    """
    e = epsilon
    a = np.array([[-3 / e, 1.0, 0.0], [-3 / e**2, 0.0, 1.0], [-1 / e**3, 0.0, 0.0]])
    b = np.array([[3 / e], [3 / e**2], [1 / e**3]])
    m = np.zeros((4, 4))
    m[:3, :3], m[:3, 3:] = a, b
    d = expm(m * sample_time)
    return d[:3, :3], d[:3, 3:4]


def _run_observer(ad: np.ndarray, by: np.ndarray, y: np.ndarray) -> np.ndarray:
    """xhat[k+1] = ad xhat[k] + by y[k] with xhat[0] = (y[0], 0, ...); returns (order, n) estimates.

    The estimate at k uses y[0..k-1], as ``HighGainObserver.filter`` does; it runs as a linear
    filter (``lfilter``) instead of a Python loop (300k samples: ms instead of seconds).
    The start (y[0], 0, ...) is an equilibrium for a constant y[0], so the estimate is y[0] in the
    first state plus the zero-state response to y - y[0].
    """
    order = ad.shape[0]
    num, den = ss2tf(ad, by, np.eye(order), np.zeros((order, 1)))  # num[:, 0] = 0: one sample late
    out = np.vstack([lfilter(num[i], den, y - y[0]) for i in range(order)])
    out[0] += y[0]
    return out


@dataclass(frozen=True)
class HighGainDifferentiator:
    """The papers' high-gain observer for the velocity, a third-order one for the acceleration.

    Parameters
    ----------
    sample_time : float
        [s]
    epsilon : float
        [s] Velocity observer time constant (default 2 ms, ``high_gain.DEFAULT_EPSILON``).
    acceleration_epsilon : float
        [s] Third-order observer time constant (default 5 ms, ``DEFAULT_ACCELERATION_EPSILON``).

    Attributes
    ----------
    observer : HighGainObserver
        The second-order observer; its exact discretization gives position and velocity.
    """

    sample_time: float
    epsilon: float = DEFAULT_EPSILON
    acceleration_epsilon: float = DEFAULT_ACCELERATION_EPSILON
    observer: HighGainObserver = field(init=False, repr=False)
    _third: tuple[np.ndarray, np.ndarray] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        _check_sample_time(self.sample_time)
        if not (self.acceleration_epsilon > 0 and math.isfinite(self.acceleration_epsilon)):
            raise InputError(f"acceleration_epsilon must be positive [s], got {self.acceleration_epsilon!r}")
        object.__setattr__(self, "observer", HighGainObserver(self.sample_time, self.epsilon))
        object.__setattr__(self, "_third", _third_order_observer(self.sample_time, self.acceleration_epsilon))

    def __call__(self, y: np.ndarray) -> Derivatives:
        """Estimates from positions ``y`` [m], shape (n,) or (m, n); causal, x0 = (y[0], 0, 0)."""
        y = _as_rows(y)
        rows = y.reshape(-1, y.shape[-1])
        obs = self.observer
        out = np.empty((3, *rows.shape))
        for r, yr in enumerate(rows):
            out[:2, r] = _run_observer(obs.Ad, obs.By, yr)
            out[2, r] = _run_observer(*self._third, yr)[2]
        settings = {
            "epsilon": self.epsilon,
            "alpha": str(obs.alpha),
            "acceleration_epsilon": self.acceleration_epsilon,
            "acceleration_alpha": "(3, 3, 1)",
            "delay": "causal: the estimate at sample k uses y[0..k-1]",
        }
        shape = y.shape
        return Derivatives(
            out[0].reshape(shape),
            out[1].reshape(shape),
            out[2].reshape(shape),
            self.sample_time,
            "high_gain_observer",
            MappingProxyType(settings),
        )


# --- logs ---------------------------------------------------------------------------------------
def differentiate_log(log: Log, estimator: SavitzkyGolay | HighGainDifferentiator) -> Derivatives:
    """Derivatives of the measured positions (x1, x3) of ``log``.

    Parameters
    ----------
    log : Log
    estimator : SavitzkyGolay or HighGainDifferentiator
        Its ``sample_time`` must match the log's median step within 1 %.

    Returns
    -------
    Derivatives
        Arrays of shape (2, n): gap and horizontal position.
    """
    if abs(estimator.sample_time - log.sample_time) > 0.01 * log.sample_time:
        raise InputError(
            f"{log.source}: estimator sample_time {estimator.sample_time!r} s does not match the log's "
            f"median step {log.sample_time!r} s"
        )
    return estimator(log.x[[0, 2]])


def with_estimated_velocities(log: Log, estimator: SavitzkyGolay | HighGainDifferentiator) -> Log:
    """The log with its unmeasured x2 / x4 rows filled from x1 / x3.

    Parameters
    ----------
    log : Log
    estimator : SavitzkyGolay or HighGainDifferentiator

    Returns
    -------
    Log
        A copy with the velocities [m/s] estimated where they were not measured (measured rows
        kept) and a note saying how; ``log`` itself when both were measured.
    """
    missing = [row for row in (1, 3) if not log.states_measured[row]]
    if not missing:
        return log
    est = differentiate_log(log, estimator)
    x = log.x.copy()
    for row in missing:
        x[row] = est.velocity[0 if row == 1 else 1]
    names = " and ".join(f"x{row + 1}" for row in missing)
    settings = ", ".join(f"{k}={v}" for k, v in est.settings.items() if isinstance(v, (int, float)))
    note = f"{names} estimated by {est.method} ({settings})"
    return dataclasses.replace(log, x=x, notes=(*log.notes, note))
