"""The paper's experiments on the 3-DOF microstepper (002 Sec. 8, Figs. 15-18) as references.

A reference is sampled into the layout of :mod:`~maglev_oc.control.microstepper`: rows
(r_x, r_x', r_x'', r_y, r_y', r_y'', r_gap, r_gap', r_gap'') [m, m/s, m/s^2], shape (9, n).
:func:`microstepper_scenarios` gives the paper's five set-points, its simultaneous sinusoids on
every axis, and a case that drives both pairs into the amplifiers' limit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from maglev_oc.control.gains import OMEGA0
from maglev_oc.control.microstepper import N_REFERENCE
from maglev_oc.errors import InputError
from maglev_oc.sim.scenarios import _envelope
from maglev_oc.units import MM_TO_M

__all__ = ["MicrostepperScenario", "MicrostepperSetpoints", "MicrostepperSinusoids", "microstepper_scenarios"]


@dataclass(frozen=True)
class MicrostepperSetpoints:
    """Piecewise-constant set-points (x, y, gap) = ``setpoints[k]`` [m] from ``times[k]`` [s] on."""

    times: tuple[float, ...]
    setpoints: tuple[tuple[float, float, float], ...]

    def __post_init__(self) -> None:
        t = np.asarray(self.times, dtype=float)
        sp = np.asarray(self.setpoints, dtype=float)
        if t.ndim != 1 or t.size == 0 or t[0] != 0 or np.any(np.diff(t) <= 0):
            raise InputError(f"times must start at 0 and increase, got {self.times!r}")
        if sp.shape != (t.size, 3):
            raise InputError(f"setpoints must have shape ({t.size}, 3), got {sp.shape}")
        if np.any(sp[:, 2] <= 0) or np.any(sp[:, 2] > 0.1) or np.any(np.abs(sp[:, :2]) > 0.1):
            raise InputError(f"set-points must be in metres (|x|, |y| <= 0.1, gap in (0, 0.1]), got {sp}")

    def sample(self, t: np.ndarray) -> np.ndarray:
        """(9, n) reference at times ``t`` [s] (rates and accelerations zero)."""
        idx = np.searchsorted(np.asarray(self.times), t, side="right") - 1
        out = np.zeros((N_REFERENCE, t.size))
        out[0::3] = np.asarray(self.setpoints)[idx].T
        return out


@dataclass(frozen=True)
class MicrostepperSinusoids:
    """r_j = offset_j + sum amplitude sin(omega t + phase) per axis j, amplitudes ramped in with
    the 2-DOF scenarios' smoothstep over ``ramp_time`` [s].

    ``terms`` has one tuple of (amplitude [m], omega [rad/s], phase [rad]) per axis (x, y, gap).
    """

    offsets: tuple[float, float, float]  # [m]
    terms: tuple[tuple[tuple[float, float, float], ...], ...]
    ramp_time: float = 0.0  # [s]

    def __post_init__(self) -> None:
        if len(self.offsets) != 3 or len(self.terms) != 3:
            raise InputError("offsets and terms need one entry per axis (x, y, gap)")

    def sample(self, t: np.ndarray) -> np.ndarray:
        """(9, n) reference with its first two derivatives at times ``t`` [s]."""
        t = np.asarray(t, dtype=float)
        env, denv, ddenv = _envelope(t, self.ramp_time)
        out = np.zeros((N_REFERENCE, t.size))
        for j in range(3):
            s = np.zeros((3, t.size))
            for amp, w, ph in self.terms[j]:
                arg = w * t + ph
                s += amp * np.array([np.sin(arg), w * np.cos(arg), -(w**2) * np.sin(arg)])
            out[3 * j] = self.offsets[j] + env * s[0]
            out[3 * j + 1] = denv * s[0] + env * s[1]
            out[3 * j + 2] = ddenv * s[0] + 2 * denv * s[1] + env * s[2]
        return out


@dataclass(frozen=True)
class MicrostepperScenario:
    """A test of the microstepper: start at rest at ``q0`` = (x, y, gap) [m], a reference, a
    duration [s], the start of the tracking window [s] and what the paper reports."""

    name: str
    title: str
    q0: tuple[float, float, float]
    reference: MicrostepperSetpoints | MicrostepperSinusoids
    duration: float
    evaluate_from: float = 0.0
    paper: dict[str, float | str] = field(default_factory=dict)

    def sample(self, sample_time: float) -> tuple[np.ndarray, np.ndarray]:
        """(t (n,) [s], reference (9, n)) on the controller's grid."""
        n = round(self.duration / sample_time)
        t = np.arange(n) * sample_time
        return t, self.reference.sample(t)

    def shortened(self, duration: float, evaluate_from: float | None = None) -> MicrostepperScenario:
        """The same scenario cut to ``duration`` [s] (for quick tests)."""
        ev = self.evaluate_from if evaluate_from is None else evaluate_from
        return MicrostepperScenario(self.name, self.title, self.q0, self.reference, duration, ev, self.paper)


def microstepper_scenarios() -> dict[str, MicrostepperScenario]:
    """The paper's experiments on the microstepper (002 Sec. 8), by name.

    * ``setpoints``: five set-points 5 s apart from rest at the centre (0, 0, 25) mm: the four
      corners (+-40, +-40) mm of the horizontal region, alternating between the bottom (21 mm) and
      the top (29 mm) of the gap range, then back to the centre. The first and last steps move x
      and y by 40 mm each, the three between them one of x or y by 80 mm (pairs saturate); every
      step moves the gap by 4 or 8 mm. The region is spanned with 10 mm of margin to the +-50 mm
      edge (overshoot stays inside the travel). 002 Figs. 15-16 do not print the set-points.
    * ``sinusoid``: simultaneous sinusoids at omega0 = 1.5 pi (the internal model's frequency):
      x = 40 sin(w t), y = 40 cos(w t) mm (a 40 mm circle, the 2-DOF's 30 mm ellipse axis scaled
      to the larger travel), gap = 25 + 4 sin(w t + pi/4) mm (the 2-DOF's 5 mm over a 10 mm
      range, kept 1 mm inside [20, 30] mm), ramped in over 2 s; 20 s, scored from 8 s, as the
      2-DOF sinusoid scenario. 002 Figs. 17-18 do not print amplitudes or frequency.
    * ``saturation``: one step of 90 mm on x and y at once, (-45, -45, 25) -> (45, 45, 25) mm:
      at the start the pairs ask for 42 A and 60 A of thrust current (5-7 times the 9 A limit).

    Returns
    -------
    dict of str to MicrostepperScenario
    """
    mm = MM_TO_M
    w0 = OMEGA0
    corners = ((-40, -40, 21), (40, -40, 29), (40, 40, 21), (-40, 40, 29), (0, 0, 25))
    setpoints = MicrostepperSetpoints(
        times=(0.0, 5.0, 10.0, 15.0, 20.0),
        setpoints=tuple(tuple(c * mm for c in p) for p in corners),
    )
    sinusoids = MicrostepperSinusoids(
        offsets=(0.0, 0.0, 25 * mm),
        terms=(((40 * mm, w0, 0.0),), ((40 * mm, w0, math.pi / 2),), ((4 * mm, w0, math.pi / 4),)),
        ramp_time=2.0,
    )
    return {
        "setpoints": MicrostepperScenario(
            "setpoints",
            "Five set-points at the corners of (+-40 mm)^2 x [21, 29] mm and the centre",
            (0.0, 0.0, 25 * mm),
            setpoints,
            25.0,
            paper={"settle_0.1mm_s": 3.0, "settle_10um_s": 5.0, "source": "002 Sec. 8, Figs. 15-16"},
        ),
        "sinusoid": MicrostepperScenario(
            "sinusoid",
            "x = 40 sin(w0 t), y = 40 cos(w0 t), gap = 25 + 4 sin(w0 t + pi/4) mm, w0 = 1.5 pi",
            (0.0, 0.0, 25 * mm),
            sinusoids,
            20.0,
            evaluate_from=8.0,
            paper={
                "mean_err_x_mm": 0.12,
                "mean_err_y_mm": 0.059,
                "mean_err_gap_mm": 0.13,
                "source": "002 Sec. 8, Figs. 17-18",
            },
        ),
        "saturation": MicrostepperScenario(
            "saturation",
            "Step of 90 mm on x and y at once: (-45, -45, 25) -> (45, 45, 25) mm",
            (-45 * mm, -45 * mm, 25 * mm),
            MicrostepperSetpoints((0.0,), ((45 * mm, 45 * mm, 25 * mm),)),
            6.0,
        ),
    }
