"""Where a log's platform rests on a stopper instead of levitating.

A log that begins before lift-off, or ends after the platform has landed, holds stretches where the
vertical stopper, not the magnets, holds the platform: the gap reading sits at the log's largest
gap and does not move, while the currents, which the loop keeps commanding, give
forces the model turns into an acceleration the platform does not have. Those samples are no
evidence about the magnets; in an equation-error fit they are wrong by the stopper's force.

On a 60 s log of the independent generator that began resting on the stopper at 30 mm and lifted
off after 1.2 s (``tests/independent``, ``Rig.stopper_gap``), the constants of the base fit came
out C2 +2 %, C3 +7.6 % and C4 +125 % off the plant's, without a word; the same log without its
first 1.5 s gave all four within 0.8 %.

A stretch is taken as resting when, at the log's start or end (within :data:`REST_JOIN`), the gap
reading stays within :data:`REST_BAND` of the log's largest gap (gravity opens the gap: the
platform falls onto the stopper there) with the gap rate under :data:`REST_SPEED`, and the model's
vertical acceleration (with the constants the fit starts from) exceeds the measured one, pushing
the platform into the stopper, either by more than :data:`REST_MISFIT` somewhere in a stretch of at
least :data:`REST_MIN_TIME` (a force no constants' error gives), or, over at least
:data:`WINDUP_MIN_TIME`, by more than :data:`WINDUP_MISFIT` with a change of at least
:data:`WINDUP_SPREAD` while the gap does not move (the loop winding up its command against the
stopper before lift-off). Levitating at a held set-point the model is off by the constants' error,
nearly the same all along (a spread of 0.24-0.35 m/s^2 over still stretches at a log's extreme
gap on the generator's logs). Resting before lift-off, the misfit rose from 0 to 1.3-4 m/s^2 over
1.1-1.3 s on four lift-off logs of the generator.

In the middle of a log (a reference that runs beyond the stopper: the loop presses the platform
against it, winding its current up to the amplifiers' limit), guides that stick at a reversal hold
the platform still at its extreme gap too, against misfits of 1-5 m/s^2 where the constants are a
few per cent off at small gaps (seven of 325 logs of the generator with 2 N of vertical friction,
at 12.9-24.1 mm); their stretches are the friction's evidence, not a stopper's. There the misfit
is judged against the misfit of the levitating platform beside the stretch
(:data:`TOUCH_BESIDE`, beyond :data:`TOUCH_SETTLE`), which carries the same constants' error at
nearly the same gap: a stopper's force changes it by more than :data:`REST_MISFIT`, sticking guides
by at most twice their static friction (1.1 m/s^2 for the generator's large vertical friction).
On three logs of the generator whose reference stepped 8 mm beyond a stopper at 26 mm for 1.5 s
(clean, beside horizontal friction, beside normal cogging) the misfit rose by 24 m/s^2 there, and
the fit that read those samples gave C4 six times the plant's and lost the cogging.

The stopper's gap is the highest gap the platform stays still at for :data:`REST_MIN_TIME`, not
the largest reading: the smoothed gap of a platform that hits its stopper overshoots the stop by
tens of micrometres for a few milliseconds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from maglev_oc.units import M_TO_MM

__all__ = [
    "RESTING_WHY",
    "REST_BAND",
    "REST_JOIN",
    "REST_MIN_TIME",
    "REST_MISFIT",
    "REST_OVERSHOOT",
    "REST_SPEED",
    "TOUCHING_WHY",
    "TOUCH_BESIDE",
    "TOUCH_SETTLE",
    "WINDUP_MIN_TIME",
    "WINDUP_MISFIT",
    "WINDUP_SPREAD",
    "RestingStretch",
    "resting_on_stoppers",
]

RESTING_WHY = "the platform rests on its stopper (before lift-off or after landing)"
"""What a result's ``left_out`` entries say of a resting stretch at a log's start or end."""

TOUCHING_WHY = "the platform is pressed against its stopper (the loop pushing it beyond)"
"""... and of one in the middle of a log."""

REST_BAND = 30e-6
"""[m] A resting platform's gap reading stays this close to the log's extreme (three counts of the
rig's 10 um encoder)."""

REST_SPEED = 5e-3
"""[m/s] ... and its gap rate under this."""

REST_OVERSHOOT = 0.25e-3
"""[m] How far the smoothed gap of a platform hitting its stopper may read beyond the stop (49 um
at 45 mm/s on the 10 Hz differentiator): the highest still level within this of the largest
reading is the stopper's."""

REST_JOIN = 0.25
"""[s] Still stretches less apart than this are one (a bounce on landing), and a stretch this close
to a log's first or last sample is at its start or end."""

REST_MIN_TIME = 0.05
"""[s] The shortest stretch taken as resting (a levitating platform passes through its extreme gap
in a few milliseconds)."""

REST_MISFIT = 2.5
"""[m/s^2] The model's vertical acceleration beyond the measured one, into the stopper, that shows a
stopper's force: 25 % of g, above what constants off by 20 % give at equilibrium."""

WINDUP_MIN_TIME = 0.3
"""[s] The shortest stretch judged by the loop winding up against a stopper (longer than guides
stick at a reversal)."""

WINDUP_MISFIT = 1.0
"""[m/s^2] ... its largest misfit into the stopper (twice the static friction of the generator's
large vertical friction, 0.55 m/s^2) ..."""

WINDUP_SPREAD = 1.0
"""[m/s^2] ... and how much that misfit changes over the stretch while the gap does not move (three
times the spread over still stretches of levitation at the extreme gap)."""

TOUCH_SETTLE = 0.1
"""[s] In the middle of a log, the levitating misfit beside a still stretch is read this far from it
(the smoothed acceleration of an impact spreads over the differentiator's half-window) ..."""

TOUCH_BESIDE = 0.3
"""[s] ... over this long on each side."""


@dataclass(frozen=True)
class RestingStretch:
    """A stretch of one log where the platform rests on a stopper."""

    log: int  # index among the logs prepared together
    source: str
    start: float  # [s] from the log's first sample
    stop: float  # [s]
    gap: float  # [m] the gap reading there
    misfit: float  # [m/s^2] the largest model acceleration beyond the measured one, into the stopper
    during: bool = False  # in the middle of the log (a touch), not at its start or end

    def what(self) -> str:
        """The stretch in words, without its log."""
        how = "is pressed against" if self.during else "rests on"
        beside = " beyond the levitating platform's beside it" if self.during else ""
        return (
            f"{self.start:.2f}-{self.stop:.2f} s the platform {how} its stopper "
            f"({self.gap * M_TO_MM:.2f} mm, the log's largest gap; the model's acceleration there is up to "
            f"{abs(self.misfit):.1f} m/s^2 off the measured{beside}, the stopper's force)"
        )

    def describe(self) -> str:
        """The stretch in words, with its log."""
        return f"{self.source}: {self.what()}: left out of the fit"

    def to_dict(self) -> dict:
        """A result's ``left_out`` entry."""
        return {
            "log": self.source,
            "from_s": self.start,
            "to_s": self.stop,
            "gap_m": self.gap,
            "why": TOUCHING_WHY if self.during else RESTING_WHY,
        }


def resting_on_stoppers(
    t: np.ndarray,
    segment: np.ndarray,
    x: np.ndarray,
    acc: np.ndarray,
    model_acc: np.ndarray,
    sample_time: float,
    sources: tuple[str, ...],
) -> tuple[np.ndarray, tuple[RestingStretch, ...]]:
    """(n,) mask of the samples where the platform rests on its stopper, and the stretches.

    ``t``, ``segment``: time in its log and log index of each sample; ``x`` (4, n) the states,
    ``acc`` (2, n) the measured and ``model_acc`` (n,) the model's vertical accelerations."""
    mask = np.zeros(t.size, dtype=bool)
    stretches: list[RestingStretch] = []
    shortest = max(round(REST_MIN_TIME / sample_time), 2)
    windup = max(round(WINDUP_MIN_TIME / sample_time), 2)
    join = round(REST_JOIN / sample_time)
    settle, beside = round(TOUCH_SETTLE / sample_time), round(TOUCH_BESIDE / sample_time)
    for k in np.unique(segment):
        idx = np.flatnonzero(segment == k)
        gap, rate, into = x[0, idx], x[1, idx], model_acc[idx] - acc[0, idx]
        slow = np.abs(rate) < REST_SPEED
        level = _stopper_level(gap, slow, shortest)
        still = slow & (gap >= level - REST_BAND)
        runs = _joined(_runs(still), join)
        judged = [_judged(a, b, into, join, shortest, windup, settle, beside) for a, b in runs]
        found = [r for r, (_, _, shown) in zip(runs, judged, strict=True) if shown]
        if not found:
            continue
        # once the stopper has shown itself, the platform still at its gap is on it, whatever the
        # misfit: a brief bounce after it lifts away (56 ms, its smeared impact up to 0.8 m/s^2 off,
        # gave C4 18 % high) is no levitation
        stop_gap = float(np.median(np.concatenate([gap[a:b] for a, b in found])))
        for (a, b), (during, push, shown) in zip(runs, judged, strict=True):
            if not (shown or abs(float(np.median(gap[a:b])) - stop_gap) <= REST_BAND):
                continue
            mask[idx[a:b]] = True
            stretches.append(
                RestingStretch(
                    int(k),
                    sources[int(k)],
                    float(t[idx[a]]),
                    float(t[idx[b - 1]]),
                    float(np.median(gap[a:b][still[a:b]])),
                    float(push.max()),
                    during,
                )
            )
    return mask, tuple(stretches)


def _judged(
    a: int, b: int, into: np.ndarray, join: int, shortest: int, windup: int, settle: int, beside: int
) -> tuple[bool, np.ndarray, bool]:
    """(in the middle of the log, the misfit into the stopper, whether it shows a stopper's force)
    of the still stretch ``a:b`` of one log's misfits ``into``."""
    during = a > join and b < into.size - join  # not at the log's start or end
    push = into[a:b]
    if during:  # against the levitating platform's misfit beside the stretch
        levitating = [
            m
            for m in (
                into[max(a - settle - beside, 0) : max(a - settle, 0)],
                into[b + settle : b + settle + beside],
            )
            if m.size
        ]
        if not levitating:
            return during, push, False
        push = push - max(float(np.median(m)) for m in levitating)
    strong = b - a >= shortest and push.max() > REST_MISFIT
    winding = not during and b - a >= windup and push.max() > WINDUP_MISFIT and np.ptp(push) > WINDUP_SPREAD
    return during, push, bool(strong or winding)


def _stopper_level(gap: np.ndarray, slow: np.ndarray, shortest: int) -> float:
    """[m] The highest gap the platform stays still at for ``shortest`` samples, held within
    :data:`REST_BAND` (the median of each such run), where a stopper would hold it, if it is within
    :data:`REST_OVERSHOOT` of the largest reading; else the largest reading (a hold below the log's
    largest gap is no stopper's)."""
    top = float(gap.max())
    levels = [
        float(np.median(gap[a:b]))
        for a, b in _runs(slow)
        if b - a >= shortest and np.ptp(np.percentile(gap[a:b], [5, 95])) <= REST_BAND  # held flat
    ]
    level = max(levels, default=top)
    return level if level >= top - REST_OVERSHOOT else top


def _runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of each run of True."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flags.astype(np.int8), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def _joined(runs: list[tuple[int, int]], gap: int) -> list[tuple[int, int]]:
    """``runs`` with those less than ``gap`` samples apart joined (a bounce on landing)."""
    out: list[tuple[int, int]] = []
    for a, b in runs:
        if out and a - out[-1][1] < gap:
            out[-1] = (out[-1][0], b)
        else:
            out.append((a, b))
    return out
