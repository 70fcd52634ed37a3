"""References and the papers' test scenarios (SPEC 4; 001 Sec. VI; 002 Sec. 7).

A reference is sampled into the fixed layout of :mod:`maglev_oc.control.base`:
rows (r_v, r_v', r_v'', r_h, r_h', r_h'') [m, m/s, m/s^2], shape (6, n).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from maglev_oc.control.gains import OMEGA0
from maglev_oc.errors import InputError
from maglev_oc.units import MM_TO_M

__all__ = ["Scenario", "SetpointSequence", "Sinusoids", "excitation_scenario", "paper_scenarios"]


@dataclass(frozen=True)
class SetpointSequence:
    """Piecewise-constant set-points: (gap, horizontal) = ``setpoints[k]`` from ``times[k]`` on.

    ``times`` [s] start at 0 and increase; ``setpoints`` [m] has shape (n, 2).
    """

    times: tuple[float, ...]
    setpoints: tuple[tuple[float, float], ...]

    def __post_init__(self) -> None:
        t = np.asarray(self.times, dtype=float)
        sp = np.asarray(self.setpoints, dtype=float)
        if t.ndim != 1 or t.size == 0 or t[0] != 0 or np.any(np.diff(t) <= 0):
            raise InputError(f"times must start at 0 and increase, got {self.times!r}")
        if sp.shape != (t.size, 2):
            raise InputError(f"setpoints must have shape ({t.size}, 2), got {sp.shape}")
        if np.any(sp[:, 0] <= 0) or np.any(sp[:, 0] > 0.1):
            raise InputError(f"gap set-points must be in metres (0, 0.1], got {sp[:, 0]}")

    def sample(self, t: np.ndarray) -> np.ndarray:
        idx = np.searchsorted(np.asarray(self.times), t, side="right") - 1
        sp = np.asarray(self.setpoints)[idx]
        out = np.zeros((6, t.size))
        out[0] = sp[:, 0]
        out[3] = sp[:, 1]
        return out

    def step_times(self) -> list[float]:
        return list(self.times)


@dataclass(frozen=True)
class Sinusoids:
    """r_v = gap_offset + sum_k a_v,k sin(w_k t + phi_v,k), r_h likewise.

    One frequency with a 90 degree phase shift between the axes is the papers' ellipse
    (002 Fig. 13); several frequencies give the sum-of-sines excitation of the identification
    experiments (000 Sec. IV, 002 Sec. 5).
    """

    gap_offset: float  # [m]
    vertical: tuple[tuple[float, float, float], ...]  # (amplitude [m], omega [rad/s], phase [rad])
    horizontal: tuple[tuple[float, float, float], ...]
    horizontal_offset: float = 0.0  # [m]
    ramp_time: float = 0.0  # [s] amplitudes ramp in with a smooth envelope over this time

    def sample(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        env, denv, ddenv = _envelope(t, self.ramp_time)
        out = np.zeros((6, t.size))
        for row, offset, terms in (
            (0, self.gap_offset, self.vertical),
            (3, self.horizontal_offset, self.horizontal),
        ):
            s = np.zeros((3, t.size))
            for amp, w, ph in terms:
                arg = w * t + ph
                s += amp * np.array([np.sin(arg), w * np.cos(arg), -(w**2) * np.sin(arg)])
            out[row] = offset + env * s[0]
            out[row + 1] = denv * s[0] + env * s[1]
            out[row + 2] = ddenv * s[0] + 2 * denv * s[1] + env * s[2]
        return out


def _envelope(t: np.ndarray, ramp: float):
    """Smoothstep 3s^2 - 2s^3 over [0, ramp] and its two derivatives (1 after the ramp)."""
    if ramp <= 0:
        return np.ones_like(t), np.zeros_like(t), np.zeros_like(t)
    s = np.clip(t / ramp, 0, 1)
    inside = (t > 0) & (t < ramp)
    env = 3 * s**2 - 2 * s**3
    denv = np.where(inside, (6 * s - 6 * s**2) / ramp, 0.0)
    ddenv = np.where(inside, (6 - 12 * s) / ramp**2, 0.0)
    return env, denv, ddenv


@dataclass(frozen=True)
class Scenario:
    """A test: initial mechanical state, reference, duration, and what the papers report."""

    name: str
    title: str
    x0: tuple[float, float, float, float]  # [m, m/s, m, m/s]
    reference: SetpointSequence | Sinusoids
    duration: float  # [s]
    evaluate_from: float = 0.0  # [s] tracking metrics ignore the start-up transient before this
    paper: dict[str, float | str] = field(default_factory=dict)  # reported numbers, for tables

    def sample(self, sample_time: float) -> tuple[np.ndarray, np.ndarray]:
        """(t (n,), reference (6, n)) on the controller's sample grid."""
        n = round(self.duration / sample_time)
        t = np.arange(n) * sample_time
        return t, self.reference.sample(t)


def paper_scenarios() -> dict[str, Scenario]:
    """The papers' experiments (SPEC 4), by name.

    Returns
    -------
    dict of str to Scenario
        ``setpoint_steps``, ``small_step``, ``large_step`` and ``sinusoid``, each with the
        numbers the papers report in ``paper``.
    """
    # Five set-points over [-50, 50] mm x [15, 25] mm, 5 s apart (002 Figs. 9-10 show steps
    # every 5 s). The exact set-points are not printed. With the printed gains the linear
    # closed loop overshoots 42 % horizontally and 45 % vertically (the papers measured 43 % and
    # 114 %), so steps are chosen to keep the overshoot inside the travel and the stoppers.
    steps = SetpointSequence(
        times=(0.0, 5.0, 10.0, 15.0, 20.0),
        setpoints=(
            (17.5 * MM_TO_M, -30 * MM_TO_M),
            (22.5 * MM_TO_M, 10 * MM_TO_M),
            (25 * MM_TO_M, 40 * MM_TO_M),
            (15 * MM_TO_M, 0.0),
            (20 * MM_TO_M, -40 * MM_TO_M),
        ),
    )
    return {
        "setpoint_steps": Scenario(
            "setpoint_steps",
            "Five set-point steps over [-50, 50] mm x [15, 25] mm",
            (20 * MM_TO_M, 0.0, 0.0, 0.0),
            steps,
            25.0,
            paper={
                "settle_v_0.1mm_s": 1.3,
                "settle_h_0.1mm_s": 1.2,
                "settle_h_fifth_s": 2.38,
                "settle_10um_s": 10.0,  # "in about 10 s", additional experiments not shown
                "overshoot_v_pct": 114.0,  # Fig. 9, at the step at t = 5 s
                "overshoot_h_pct": 43.0,
                "retuned_overshoot_v_pct": 40.0,  # Fig. 11, at the step at t = 5 s
                "retuned_settling_ratio": 3.0,  # Fig. 11: "the settling time increases by 200 %"
                "retuned_settle_v_0.1mm_s": 3.0,  # Sec. 7.1: "(still below 3 s)"
                "source": "002 Sec. 7.1, Figs. 9-11",
            },
        ),
        "small_step": Scenario(
            "small_step",
            "Small step (0.026, 0, 0, 0) -> (0.024, 0, 0.005, 0)",
            (26 * MM_TO_M, 0.0, 0.0, 0.0),
            SetpointSequence((0.0,), ((24 * MM_TO_M, 5 * MM_TO_M),)),
            8.0,
            paper={"outcome": "both linear and nonlinear settle", "source": "002 Fig. 12"},
        ),
        "large_step": Scenario(
            "large_step",
            "Large step (0.026, 0, 0, 0) -> (0.018, 0, 0.020, 0)",
            (26 * MM_TO_M, 0.0, 0.0, 0.0),
            SetpointSequence((0.0,), ((18 * MM_TO_M, 20 * MM_TO_M),)),
            8.0,
            paper={"outcome": "linear regulator unstable, nonlinear settles", "source": "002 Fig. 12"},
        ),
        "sinusoid": Scenario(
            "sinusoid",
            "Ellipse: r_h = 30 mm sin(w0 t), r_v = 20 + 5 cos(w0 t) mm, w0 = 1.5 pi",
            (20 * MM_TO_M, 0.0, 0.0, 0.0),  # the amplitudes ramp in from the centre over 2 s
            Sinusoids(
                20 * MM_TO_M,
                ((5 * MM_TO_M, OMEGA0, math.pi / 2),),
                ((30 * MM_TO_M, OMEGA0, 0.0),),
                ramp_time=2.0,
            ),
            20.0,
            evaluate_from=8.0,
            paper={
                "mean_err_h_mm": 0.11,
                "peak_err_h_mm": 0.4,
                "mean_err_v_mm": 0.24,
                "peak_err_v_mm": 0.8,
                "pid_mean_err_h_mm": 0.19,
                "pid_mean_err_v_mm": 0.9,
                "source": "001 Sec. VI-B, 002 Sec. 7.2",
            },
        ),
    }


def excitation_scenario(duration: float = 60.0, seed: int = 0, gap_offset: float = 20 * MM_TO_M) -> Scenario:
    """Sum-of-sines references for identification (000 Sec. IV: "a summation of sinusoids at
    various frequencies"), tracked by the PID regulators. Six incommensurate frequencies per
    axis over 0.1-3 Hz with random phases; amplitudes fall as 1/sqrt(f) and sum to at most
    3.8 mm about ``gap_offset`` vertically and 35 mm horizontally.

    Parameters
    ----------
    duration : float
        Length of the run [s].
    seed : int
        Seed of the random phases.
    gap_offset : float
        Centre of the vertical excursion [m].

    Returns
    -------
    Scenario
    """
    rng = np.random.default_rng(seed)
    freqs_v = np.array([0.13, 0.37, 0.71, 1.13, 1.9, 2.9])
    freqs_h = np.array([0.11, 0.29, 0.53, 0.97, 1.7, 2.6])
    amps_v = 4 * MM_TO_M / np.sqrt(freqs_v / freqs_v[0]) / 3
    amps_h = 40 * MM_TO_M / np.sqrt(freqs_h / freqs_h[0]) / 3.3
    vertical = tuple(
        (float(a), float(2 * math.pi * f), float(p))
        for a, f, p in zip(amps_v, freqs_v, rng.uniform(0, 2 * math.pi, freqs_v.size), strict=True)
    )
    horizontal = tuple(
        (float(a), float(2 * math.pi * f), float(p))
        for a, f, p in zip(amps_h, freqs_h, rng.uniform(0, 2 * math.pi, freqs_h.size), strict=True)
    )
    ref = Sinusoids(gap_offset, vertical, horizontal, ramp_time=2.0)
    return Scenario(
        "excitation",
        f"Sum-of-sines excitation, {duration:g} s",
        (gap_offset, 0.0, 0.0, 0.0),
        ref,
        duration,
        paper={"source": "000 Sec. IV"},
    )
