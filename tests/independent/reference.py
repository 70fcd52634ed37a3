"""References for the closed loop: random sums of sines per seed, optional smoothed set-point steps.

Per axis,

.. math::

    r(t) = r_0 + w(t) \\sum_i a_i \\sin(2\\pi f_i t + \\varphi_i) + \\sum_j \\Delta_j h((t - t_j)/T_s)

with ``w`` a quintic ramp from 0 to 1 over ``ramp_time`` (so r(0) = r0 and r'(0) = 0: the stage
starts at rest on its reference) and ``h`` the quintic smoothstep 0 -> 1 over ``T_s``. One
frequency is drawn log-uniformly in each of ``n_sines`` log-spaced bands of
``[f_min, f_max]``; amplitudes fall as ``f^-slope`` (times a random factor in [0.5, 1]) and the
sum is scaled so that its largest excursion over max(run, 60 s) equals a target drawn in
``peak_range`` (vertical about 4-5 mm, horizontal 35-40 mm). With ``slope = 0.7`` the
accelerations stay below about 0.6 m/s^2 horizontally and 0.15 m/s^2 vertically, like the
reference log described in ``/work/shared/logs/README.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

SCALING_HORIZON = 60.0
"""[s] The amplitudes are scaled on max(duration, 60 s): a shorter run follows the beginning of
the same reference as the 60 s run of its seed (and, the noise being drawn sequentially, its log
is the beginning of that run's log)."""


def _quintic(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Smoothstep 10 s^3 - 15 s^4 + 6 s^5 on [0, 1] (clamped) and its derivative in s."""
    s = np.clip(s, 0.0, 1.0)
    return s**3 * (10.0 - 15.0 * s + 6.0 * s * s), 30.0 * s * s * (1.0 - s) ** 2


@dataclass(frozen=True)
class AxisReference:
    """A concrete reference for one axis (what the truth file records).

    Attributes
    ----------
    offset : float
        r0 [m].
    frequencies, amplitudes, phases : tuple of float
        Sines: [Hz], [m], [rad].
    ramp_time : float
        [s] quintic fade-in of the sines.
    steps : tuple of (float, float)
        (time [s], size [m]) of smoothed set-point steps.
    step_time : float
        [s] duration of each smoothed step.
    """

    offset: float
    frequencies: tuple[float, ...] = ()
    amplitudes: tuple[float, ...] = ()
    phases: tuple[float, ...] = ()
    ramp_time: float = 2.0
    steps: tuple[tuple[float, float], ...] = ()
    step_time: float = 0.3

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """r(t) [m] and r'(t) [m/s] at times ``t`` [s]."""
        t = np.asarray(t, dtype=float)
        s = np.zeros_like(t)
        ds = np.zeros_like(t)
        for f, a, ph in zip(self.frequencies, self.amplitudes, self.phases, strict=True):
            w = 2.0 * math.pi * f
            s += a * np.sin(w * t + ph)
            ds += a * w * np.cos(w * t + ph)
        if self.ramp_time > 0:
            h, dh = _quintic(t / self.ramp_time)
            r = self.offset + h * s
            dr = dh / self.ramp_time * s + h * ds
        else:
            r, dr = self.offset + s, ds
        for t0, size in self.steps:
            h, dh = _quintic((t - t0) / self.step_time)
            r = r + size * h
            dr = dr + size * dh / self.step_time
        return r, dr

    def as_dict(self) -> dict[str, Any]:
        """Plain dict for the truth file (units in the keys' descriptions of the file)."""
        return {
            "offset_m": self.offset,
            "frequencies_hz": list(self.frequencies),
            "amplitudes_m": list(self.amplitudes),
            "phases_rad": list(self.phases),
            "ramp_time_s": self.ramp_time,
            "steps": [{"time_s": t0, "size_m": d} for t0, d in self.steps],
            "step_time_s": self.step_time,
        }


@dataclass(frozen=True)
class ReferenceSpec:
    """How to draw a reference from a seed.

    Attributes
    ----------
    gap_center : float
        [m] vertical offset r0 (19.5 mm).
    gap_peak_range, horizontal_peak_range : (float, float)
        [m] range of the largest excursion of the sines (drawn uniformly).
    horizontal_center : float
        [m] horizontal offset.
    n_sines : int
        Sines per axis.
    f_min, f_max : float
        [Hz] frequency range.
    slope : float
        Amplitudes fall as f^-slope before scaling.
    ramp_time : float
        [s] fade-in.
    steps_v, steps_h : tuple of (time [s], size [m])
        Optional smoothed set-point steps added to the sines.
    step_time : float
        [s] duration of a smoothed step.
    """

    gap_center: float = 0.0195
    gap_peak_range: tuple[float, float] = (0.004, 0.005)
    horizontal_center: float = 0.0
    horizontal_peak_range: tuple[float, float] = (0.035, 0.040)
    n_sines: int = 4
    f_min: float = 0.05
    f_max: float = 2.0
    slope: float = 0.7
    ramp_time: float = 2.0
    steps_v: tuple[tuple[float, float], ...] = field(default=())
    steps_h: tuple[tuple[float, float], ...] = field(default=())
    step_time: float = 0.3

    def draw(self, rng: np.random.Generator, duration: float) -> tuple[AxisReference, AxisReference]:
        """Draw the (vertical, horizontal) references for a run of ``duration`` [s]."""
        out = []
        for center, peak_range, steps in (
            (self.gap_center, self.gap_peak_range, self.steps_v),
            (self.horizontal_center, self.horizontal_peak_range, self.steps_h),
        ):
            if self.n_sines == 0 or peak_range[1] <= 0:
                out.append(
                    AxisReference(center, ramp_time=self.ramp_time, steps=steps, step_time=self.step_time)
                )
                continue
            edges = np.geomspace(self.f_min, self.f_max, self.n_sines + 1)
            freqs = np.exp(rng.uniform(np.log(edges[:-1]), np.log(edges[1:])))
            amps = freqs ** (-self.slope) * rng.uniform(0.5, 1.0, self.n_sines)
            phases = rng.uniform(0.0, 2.0 * math.pi, self.n_sines)
            target = rng.uniform(*peak_range)
            trial = AxisReference(0.0, tuple(freqs), tuple(amps), tuple(phases), self.ramp_time)
            grid = np.arange(0.0, max(duration, SCALING_HORIZON), 1e-2)
            peak = float(np.max(np.abs(trial.evaluate(grid)[0])))
            amps = amps * (target / peak)
            out.append(
                AxisReference(
                    center,
                    tuple(float(f) for f in freqs),
                    tuple(float(a) for a in amps),
                    tuple(float(p) for p in phases),
                    self.ramp_time,
                    steps,
                    self.step_time,
                )
            )
        return out[0], out[1]
