"""Where a log's stage is held by a stopper instead of levitating and moving freely.

A log that begins before lift-off, or ends after the platform has landed, holds stretches where the
vertical stopper, not the magnets, holds the platform: the gap reading sits at the log's largest
gap and does not move, while the currents, which the loop keeps commanding, give
forces the model turns into an acceleration the platform does not have. Those samples are no
evidence about the magnets; in an equation-error fit they are wrong by the stopper's force. So are
the samples where a reference beyond a stop makes the loop press the stage against it in the middle
of a log: against the same stopper, against the stop at the smallest gap (the stator's cover), or
against an end stop of the horizontal travel (:data:`STOPS`).

On a 60 s log of the independent generator that began resting on the stopper at 30 mm and lifted
off after 1.2 s (``tests/independent``, ``Rig.stopper_gap``), the constants of the base fit came
out C2 +2 %, C3 +7.6 % and C4 +125 % off the plant's, without a word; the same log without its
first 1.5 s gave all four within 0.8 %. Pressed for 0.8-2 s against a stop in the middle of a log
(``Rig.top_stopper_gap``, ``Rig.end_stops``): C4 six times the plant's (the stopper at 26 mm), C2
-37 %, C3 -143 % and C4 -2500 % (a stop at 15 mm), C1 -99.9 % (an end stop at +45 mm).

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

In the middle of a log, and at the other stops anywhere, guides that stick at a reversal hold the
stage still at its extreme position too, against misfits of 1-5 m/s^2 where the constants are a
few per cent off at small gaps (seven of 325 logs of the generator with 2 N of vertical friction,
at 12.9-24.1 mm); their stretches are the friction's evidence, not a stopper's. There the misfit
is judged against the misfit of the moving stage beside the stretch (:data:`TOUCH_BESIDE`, beyond
:data:`TOUCH_SETTLE`), which carries the same constants' error at nearly the same position: a
stopper's force changes it by more than :data:`REST_MISFIT` (9-75 m/s^2 on the generator's logs
above, the loop winding its current up to the amplifiers' limit), sticking guides by at most twice
their static friction (1.1 m/s^2 for the generator's large vertical friction, 1.6 m/s^2 for its
large horizontal friction). Once a stop has shown itself so, the stage still at its position again
is on it, whatever the misfit (a bounce after it leaves).

A stop's position is the highest the stage stays still and flat at (within :data:`REST_BAND`) for
:data:`REST_MIN_TIME`, when it is within :data:`REST_OVERSHOOT` of the largest reading, else the
largest reading: the smoothed position of a stage that hits a stop overshoots it by tens of
micrometres for a few milliseconds. A log where neither axis moves is not searched (it is refused
as such).
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
    "STOPS",
    "TOUCHING_WHY",
    "TOUCH_BESIDE",
    "TOUCH_SETTLE",
    "WINDUP_MIN_TIME",
    "WINDUP_MISFIT",
    "WINDUP_SPREAD",
    "RestingStretch",
    "Stop",
    "resting_on_stoppers",
]

RESTING_WHY = "the platform rests on its stopper (before lift-off or after landing)"
"""What a result's ``left_out`` entries say of a resting stretch at a log's start or end."""

TOUCHING_WHY = "the platform is pressed against a stopper (the loop pushing it beyond)"
"""... and of one in the middle of a log, or at a stop it cannot rest on."""

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
class Stop:
    """A mechanical limit the stage can be held against."""

    name: str
    row: int  # the state row of its position (0: the gap, 2: x3)
    sign: float  # +1: the limit is at the position's largest values, -1: at its smallest
    what: str  # the limit in words
    extreme: str  # ... and where it is in the log
    lift_off: bool  # a log may begin or end resting on it (the platform's weight holds it there)

    @property
    def axis(self) -> str:
        return "vertical" if self.row == 0 else "horizontal"


STOPS = (
    Stop("largest_gap", 0, 1.0, "its stopper", "the log's largest gap", True),
    Stop("smallest_gap", 0, -1.0, "the stop at the smallest gap", "the log's smallest gap", False),
    Stop("high_end", 2, 1.0, "the travel's end stop", "the log's highest position", False),
    Stop("low_end", 2, -1.0, "the travel's end stop", "the log's lowest position", False),
)
"""The limits looked for: the stopper the platform falls onto (gravity opens the gap; a log may
begin before lift-off or end after landing there), the stop at the smallest gap (the stator's
cover) and the two ends of the horizontal travel, where only a loop pushing the stage beyond them
holds it."""

_STOP = {stop.name: stop for stop in STOPS}


@dataclass(frozen=True)
class RestingStretch:
    """A stretch of one log where a stopper holds the stage."""

    log: int  # index among the logs prepared together
    source: str
    start: float  # [s] from the log's first sample
    stop: float  # [s]
    position: float  # [m] the position reading there (the gap, or x3 at an end of the travel)
    misfit: float  # [m/s^2] the largest model acceleration beyond the measured one, into the stopper
    during: bool = False  # in the middle of the log (a touch), not at its start or end
    limit: str = "largest_gap"  # which of STOPS

    def what(self) -> str:
        """The stretch in words, without its log."""
        stop = _STOP[self.limit]
        how = "is pressed against" if self.during or not stop.lift_off else "rests on"
        beside = " beyond the levitating platform's beside it" if self.during else ""
        mm = self.position * M_TO_MM
        where = f"{mm:.2f} mm" if stop.row == 0 else f"x3 = {mm:+.2f} mm"
        return (
            f"{self.start:.2f}-{self.stop:.2f} s the platform {how} {stop.what} ({where}, {stop.extreme}; "
            f"the model's {stop.axis} acceleration there is up to {abs(self.misfit):.1f} m/s^2 off the "
            f"measured{beside}, the stopper's force)"
        )

    def describe(self) -> str:
        """The stretch in words, with its log."""
        return f"{self.source}: {self.what()}: left out of the fit"

    def to_dict(self) -> dict:
        """A result's ``left_out`` entry."""
        stop = _STOP[self.limit]
        return {
            "log": self.source,
            "from_s": self.start,
            "to_s": self.stop,
            "gap_m" if stop.row == 0 else "position_m": self.position,
            "stop": self.limit,
            "why": RESTING_WHY if stop.lift_off and not self.during else TOUCHING_WHY,
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
    """(n,) mask of the samples where a stopper holds the stage (:data:`STOPS`), and the stretches.

    ``t``, ``segment``: time in its log and log index of each sample; ``x`` (4, n) the states,
    ``acc`` (2, n) the measured and ``model_acc`` (2, n) the model's (vertical, horizontal)
    accelerations."""
    mask = np.zeros(t.size, dtype=bool)
    stretches: list[RestingStretch] = []
    steps = {
        "shortest": max(round(REST_MIN_TIME / sample_time), 2),
        "windup": max(round(WINDUP_MIN_TIME / sample_time), 2),
        "join": round(REST_JOIN / sample_time),
        "settle": round(TOUCH_SETTLE / sample_time),
        "beside": round(TOUCH_BESIDE / sample_time),
    }
    for k in np.unique(segment):
        idx = np.flatnonzero(segment == k)
        for stop in STOPS:
            axis = stop.row // 2
            position = stop.sign * x[stop.row, idx]  # the limit at its largest values
            into = stop.sign * (model_acc[axis, idx] - acc[axis, idx])
            for a, b, during, push in _held(position, x[stop.row + 1, idx], into, stop, steps):
                mask[idx[a:b]] = True
                stretches.append(
                    RestingStretch(
                        int(k),
                        sources[int(k)],
                        float(t[idx[a]]),
                        float(t[idx[b - 1]]),
                        stop.sign * float(np.median(position[a:b])),
                        float(push.max()),
                        during,
                        stop.name,
                    )
                )
    return mask, tuple(sorted(stretches, key=lambda r: (r.log, r.start)))


def _held(
    position: np.ndarray, rate: np.ndarray, into: np.ndarray, stop: Stop, steps: dict[str, int]
) -> list[tuple[int, int, bool, np.ndarray]]:
    """(start, stop, in the middle of the log, misfit into the stopper) of each stretch of one log
    where ``stop`` holds the stage (``position``, ``into``: signed so that the limit is at the
    position's largest values and pushing into it is positive)."""
    slow = np.abs(rate) < REST_SPEED
    level = _stopper_level(position, slow, steps["shortest"])
    still = slow & (position >= level - REST_BAND)
    runs = _joined(_runs(still), steps["join"])
    judged = [_judged(a, b, into, stop.lift_off, steps) for a, b in runs]
    found = [r for r, (_, _, shown) in zip(runs, judged, strict=True) if shown]
    if not found:
        return []
    # once the stopper has shown itself, the stage still at its position is on it, whatever the
    # misfit: a brief bounce after it lifts away (56 ms, its smeared impact up to 0.8 m/s^2 off,
    # gave C4 18 % high) is no levitation
    held_at = float(np.median(np.concatenate([position[a:b] for a, b in found])))
    return [
        (a, b, during, push)
        for (a, b), (during, push, shown) in zip(runs, judged, strict=True)
        if shown or abs(float(np.median(position[a:b])) - held_at) <= REST_BAND
    ]


def _judged(
    a: int, b: int, into: np.ndarray, lift_off: bool, steps: dict[str, int]
) -> tuple[bool, np.ndarray, bool]:
    """(in the middle of the log, the misfit into the stopper, whether it shows a stopper's force)
    of the still stretch ``a:b`` of one log's misfits ``into``. At the start or end of a log, a
    stopper the platform may rest on (``lift_off``) is judged by the misfit itself."""
    join, settle, beside = steps["join"], steps["settle"], steps["beside"]
    during = a > join and b < into.size - join  # not at the log's start or end
    push = into[a:b]
    if during or not lift_off:  # against the levitating platform's misfit beside the stretch
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
    strong = b - a >= steps["shortest"] and push.max() > REST_MISFIT
    winding = (
        lift_off
        and not during
        and b - a >= steps["windup"]
        and push.max() > WINDUP_MISFIT
        and np.ptp(push) > WINDUP_SPREAD
    )
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
