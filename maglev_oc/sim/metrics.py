"""Performance figures of a closed-loop run, in the papers' terms (002 Sec. 7).

Errors are the *measured* tracking errors (encoder reading minus reference), as the papers
report them; on the twin the true error differs from it by the encoder's quantization and noise.

* settling time to a band (0.1 mm, 10 um): time from the set-point change until the error
  enters the band for good (NaN when it never does before the next change, or does so less than
  :data:`MIN_HOLD` before it: a reading that enters the band on the segment's last samples has
  not shown that it stays);
* overshoot: largest excursion past the new set-point, in % of the step (steps under 0.5 mm on
  an axis are not scored);
* tracking: mean and peak |error| after ``evaluate_from``;
* current: RMS and peak of the current-vector magnitude |(i_q, i_d)| of the commands, and the
  samples commanded above the amplifiers' 9 A peak rating (the rig twin's amplifier clips them,
  the ideal twin has no amplifier and applies them);
* the minimum feasibility margin R / (4 L4) of controllers that have one and the samples where
  the feedback transformation was undefined (R < 0: the controller clipped i_d to the nearest
  realisable value, a different event from the amplifier's current limit), and the
  controller's per-call time (online controllers).

A reading within a band by round-off (a 10 um error read as 1.0000000000000003e-05 m) is inside it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from maglev_oc.model.hardware import PEAK_CURRENT_LIMIT
from maglev_oc.results import PerAxis, Result
from maglev_oc.sim.engine import SimulationResult
from maglev_oc.sim.scenarios import Scenario, SetpointSequence

__all__ = ["BANDS", "MIN_HOLD", "MIN_STEP", "RunMetrics", "StepMetrics", "evaluate"]

BANDS = (1e-4, 1e-5)  # [m]: 0.1 mm (the papers' accuracy goal) and 10 um (encoder resolution)
MIN_STEP = 5e-4  # [m]: smaller steps are not scored for overshoot
MIN_HOLD = 0.2  # [s]: a band entered later than this before the segment ends is not settled
_ROUND_OFF = 1e-9  # relative: an error this close to a band's edge is on the edge (encoder counts)


@dataclass(frozen=True)
class StepMetrics:
    """One set-point change, per axis (:class:`~maglev_oc.results.PerAxis`: vertical, horizontal)."""

    time: float  # [s] when the set-point changed
    size: PerAxis  # [m] signed step per axis
    settling_01mm: PerAxis  # [s], NaN if not settled
    settling_10um: PerAxis  # [s]
    overshoot_pct: PerAxis  # [%], NaN for steps under MIN_STEP


@dataclass(frozen=True)
class RunMetrics(Result):
    """The papers' figures of one run (module docstring); ``success``, ``status``, ``message`` and
    ``timings`` are the run's (:class:`~maglev_oc.sim.engine.SimulationResult`)."""

    controller: str
    scenario: str
    success: bool
    status: str
    message: str
    steps: tuple[StepMetrics, ...]
    mean_error: PerAxis  # [m] after evaluate_from
    peak_error: PerAxis  # [m] after evaluate_from
    rms_current: float  # [A]
    peak_current: float  # [A]
    min_margin: float  # [m/s^2], NaN if the controller has no margin
    clipped: int  # samples where the feedback transformation was undefined (R < 0)
    current_limited: int  # samples the twin's amplifier limited the current (0 without amplifier)
    step_time_median: float  # [s], NaN for expression controllers
    step_time_p99: float
    step_time_max: float
    timings: Mapping[str, float]  # [s] the run's
    over_peak_rating: int = 0  # samples with the commanded |(i_q, i_d)| above the 9 A peak rating

    def worst_settling(self, axis: int | str, band: str = "01mm") -> float:
        """Longest settling time [s] over the steps on ``axis`` (0/"vertical", 1/"horizontal")
        to the band "01mm" or "10um"; NaN if a step never settled or there are none."""
        vals = [getattr(s, f"settling_{band}")[axis] for s in self.steps]
        return float(np.max(vals)) if vals and not np.any(np.isnan(vals)) else float("nan")

    def max_overshoot(self, axis: int | str) -> float:
        """Largest overshoot [%] over the scored steps on ``axis``; NaN if none was scored."""
        vals = [s.overshoot_pct[axis] for s in self.steps if not np.isnan(s.overshoot_pct[axis])]
        return float(np.max(vals)) if vals else float("nan")


def _settling(t: np.ndarray, err: np.ndarray, band: float) -> float:
    outside = np.nonzero(np.abs(err) > band * (1 + _ROUND_OFF))[0]
    if outside.size == 0:
        return 0.0
    last = outside[-1]
    if last >= t.size - 1 or t[-1] - t[last + 1] < MIN_HOLD:
        return float("nan")
    return float(t[last + 1] - t[0])


def evaluate(result: SimulationResult, scenario: Scenario) -> RunMetrics:
    """Metrics of ``result`` (a run of ``scenario``), in the papers' terms (module docstring).

    Parameters
    ----------
    result : SimulationResult
        The run.
    scenario : Scenario
        What was run; its set-point changes are scored one by one, its ``evaluate_from`` [s]
        starts the tracking window.

    Returns
    -------
    RunMetrics
    """
    t = result.t
    err = np.vstack([result.y[0] - result.reference[0], result.y[1] - result.reference[3]])
    steps = _step_metrics(t, err, scenario, result.sample_time)
    window = t >= scenario.evaluate_from
    e_win = np.abs(err[:, window])
    mag = np.hypot(result.u[0], result.u[1])
    margin = result.diagnostic("margin")
    st = result.step_times
    return RunMetrics(
        controller=result.controller,
        scenario=result.scenario,
        success=result.success,
        status=result.status,
        message=result.message,
        steps=steps,
        # a run shorter than the scenario's tracking window has no tracking figures (NaN)
        mean_error=PerAxis.of(np.nanmean(e_win, axis=1)) if e_win.size else PerAxis(math.nan, math.nan),
        peak_error=PerAxis.of(np.nanmax(e_win, axis=1)) if e_win.size else PerAxis(math.nan, math.nan),
        rms_current=float(np.sqrt(np.nanmean(mag**2))),
        peak_current=float(np.nanmax(mag)),
        min_margin=float(np.nanmin(margin)) if np.any(np.isfinite(margin)) else float("nan"),
        clipped=result.events.get("clipped", 0),
        current_limited=result.events.get("current_limited", 0),
        step_time_median=float(np.nanmedian(st)) if st is not None else float("nan"),
        step_time_p99=float(np.nanpercentile(st, 99)) if st is not None else float("nan"),
        step_time_max=float(np.nanmax(st)) if st is not None else float("nan"),
        timings=dict(result.timings),
        over_peak_rating=int(np.sum(mag > PEAK_CURRENT_LIMIT)),
    )


def _step_metrics(t: np.ndarray, err: np.ndarray, scenario: Scenario, sample_time: float) -> tuple:
    """Settling and overshoot of each set-point change of a SetpointSequence (none otherwise)."""
    if not isinstance(scenario.reference, SetpointSequence):
        return ()
    steps = []
    times = [*scenario.reference.times, t[-1] + sample_time]
    sp = np.asarray(scenario.reference.setpoints)
    x0 = np.asarray(scenario.x0)
    prev = np.array([x0[0], x0[2]])
    for k in range(len(times) - 1):
        seg = (t >= times[k]) & (t < times[k + 1])
        size = sp[k] - prev
        prev = sp[k]
        if not np.any(seg):
            continue
        settle01, settle10, over = [], [], []
        for a in range(2):
            e = err[a, seg]
            settle01.append(_settling(t[seg], e, BANDS[0]))
            settle10.append(_settling(t[seg], e, BANDS[1]))
            if abs(size[a]) < MIN_STEP:
                over.append(float("nan"))
            else:
                past = np.max(np.sign(size[a]) * e)  # positive = beyond the set-point
                over.append(float(max(past, 0.0) / abs(size[a]) * 100))
        per_axis = (PerAxis.of(v) for v in (size, settle01, settle10, over))
        steps.append(StepMetrics(times[k], *per_axis))
    return tuple(steps)
