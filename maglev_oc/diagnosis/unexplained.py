"""What is left when no named effect explains it: the residual's signature, not a guess.

After the selection, the residual of the final fit may still hold structure that no candidate
of the library explains (or explains only by being confounded with the constants). Rather than
naming the nearest candidate, the diagnosis probes the residual with generic, smooth additive
terms on each axis — Legendre polynomials (orders 1-4) of one variable at a time (gap, position,
gap rate, horizontal rate), and sinusoids of the position at the periods the residual's
spatial spectrum points to that match no motor period — and the motor's forces varying smoothly
along the travel (:func:`_force_probes`) — each judged as the selection judges a candidate (its
test 1: the held-out gain and its long-run significance over the held-out quarter pooled with the
cross-fitted parts of the training data; then its physical size), on top of the base model, the
chosen effects and the candidates that were significant but not separable (so that nothing is reported
twice). Judged on the held-out quarter alone, a residual where the stage goes now and then was
not reported: drawn pair 10116 of the noisy rig (end effects the selection had judged beside a
friction it dropped later) left 60 % of its vertical held-out error to the forces along the
position, at z 2.5 on the quarter and 6.5 pooled. Polynomials of the currents are not probed:
the logged currents' errors are as large as their slow part on such logs, and a polynomial of a
noisy variable is biased in ways the errors-in-variables compensation (first order) does not
remove. What passes is reported in ``unexplained`` with the variable it depends on, its size and
its spectrum.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import NamedTuple

import casadi as ca
import numpy as np

from maglev_oc.diagnosis.candidate import LibraryContext, legendre
from maglev_oc.diagnosis.currents import LAG_BOUND
from maglev_oc.diagnosis.library import PROBE_VARIABLES, Candidate, smooth_probes
from maglev_oc.diagnosis.selection import (
    STATE_OF_AXIS,
    Judgement,
    SelectionSettings,
    _CrossFit,
    _CrossParts,
    _held_out_test,
    _HeldOutTest,
    _holdout_residual,
    evidence,
    stands_in_for_the_constants,
)
from maglev_oc.diagnosis.words import listed, log_names
from maglev_oc.model.stage import StageModel
from maglev_oc.regression.data import PreparedLogs
from maglev_oc.regression.design import build_design
from maglev_oc.regression.solve import fit_subset
from maglev_oc.regression.terms import REVERSAL_SPEED, AccelerationTerm, term_function, when_symbol
from maglev_oc.results import AXES
from maglev_oc.units import M_TO_MM, M_TO_UM

__all__ = [
    "BOTH_ENDS",
    "FRICTION_ALONG_PROBE",
    "FRICTION_OVER_TIME_PROBE",
    "Unexplained",
    "along_the_stator",
    "currents_late",
    "delayed_rates",
    "find_unexplained",
    "rate_direction",
    "rate_sense",
]


@dataclass(frozen=True)
class Unexplained:
    """A significant residual that no candidate explains."""

    axis: str
    depends_on: str  # variable name (gap, position, ..., or "position (period 12.3 mm)")
    size: float  # RMS of the probe's acceleration on the held-out block [m/s^2]
    force_rms: float  # the same as a force [N] (times the axis's mass)
    gain: float  # relative drop of the held-out error it gives
    z: float
    description: str
    period: float | None = None  # [m] for a periodic signature
    term: AccelerationTerm | None = field(default=None, repr=False, compare=False)  # the probe

    def to_dict(self) -> dict:
        out = {
            "axis": self.axis,
            "depends_on": self.depends_on,
            "size": self.size,
            "size_unit": "m/s^2 RMS (held out)",
            "force_rms_N": self.force_rms,
            "holdout_gain": self.gain,
            "z": self.z,
            "description": self.description,
        }
        if self.period is not None:
            out["period_m"] = self.period
        return out


class _Probe(NamedTuple):
    """A generic probe of the residual and how a finding of it is said."""

    term: AccelerationTerm
    key: str  # the variable it depends on, as ``Unexplained.depends_on``
    words: str  # that variable in words
    period: float | None = None  # [m] of a periodic probe
    detail: Callable[[np.ndarray], str] | None = None  # its coefficients -> what they mean physically


def _probe(name: str, axis: int, build, k: int) -> AccelerationTerm:
    def fn(x, u, du, q):
        val = build(x, u, du, q)
        return ca.vertcat(val, 0) if axis == 0 else ca.vertcat(0, val)

    return AccelerationTerm(
        name, "probe", AXES[axis], tuple(f"q{i}" for i in range(k)), function=term_function(name, fn, k)
    )


def _sine_probe(name: str, axis: int, period: float):
    def build(x, u, du, q):
        arg = 2 * math.pi * x[2] / period
        return q[0] * ca.sin(arg) + q[1] * ca.cos(arg)

    return _probe(name, axis, build, 2)


def find_unexplained(
    data: PreparedLogs,
    model: StageModel,
    explained: Sequence[Candidate],
    fit_mask: np.ndarray,
    holdout: np.ndarray,
    weights: np.ndarray,
    periods: Sequence[tuple[str, float]],
    settings: SelectionSettings,
    *,
    max_per_axis: int = 2,
) -> list[Unexplained]:
    """Probe the residual of (base + ``explained``) for structure nothing named explains: the
    best probe is added while it passes the selection's significance and size tests, at most
    ``max_per_axis`` per axis."""
    friction = frozenset(c.term.axis for c in explained if c.family == "friction")
    lagging = frozenset(r for c in explained for r in delayed_rates(c))
    probes = (
        _probes(data, periods, friction, lagging)
        + _force_probes(data, model)
        + _friction_along_track(data, model, friction)
        + _friction_over_time(data, model, friction)
    )
    if not probes:
        return []
    terms = [c.term for c in explained] + [p.term for p in probes]
    design = build_design(data, model, terms=terms, fit=fit_mask, holdout=holdout, weights=weights)
    current = ["base", *[c.name for c in explained]]
    out: list[Unexplained] = []
    found = {axis: 0 for axis in AXES}
    # a probe confounded with the base constants stands in for them (a smooth function of the gap
    # for C2's column): it shows no dependence they lack (selection._rival_gains)
    remaining = [
        e
        for e in probes
        if not stands_in_for_the_constants(design, design.groups[e.term.name], settings.max_vif)
    ]
    counted = evidence(design, explained, settings)  # the samples that count (see there)
    n_counted = np.full(2, design.held_out_target.shape[1]) if counted is None else counted.sum(axis=1)
    fold = _CrossFit(design, settings.cross_parts) if settings.cross_parts else None
    while remaining:
        cur_fit = fit_subset(design, current, covariance=False)
        r0 = _holdout_residual(design, cur_fit, counted)
        open_probes = [e for e in remaining if found[e.term.axis] < max_per_axis]
        if not open_probes:
            break
        cross = _CrossParts.of(fold, current, explained, settings) if fold else None
        entry, seen = _best_probe(design, current, open_probes, r0, counted, cross)
        term = entry.term
        a = AXES.index(term.axis)
        size = float(np.sqrt(np.sum((r0[a] - seen.r1[a]) ** 2) / max(n_counted[a], 1)))  # net change
        if not seen.shows(settings) or size < settings.min_effect:
            break
        # what its coefficients say, in the words of the forces they scale
        detail = "" if entry.detail is None else entry.detail(seen.fit.group(design, term.name)[0])
        out.append(_unexplained(model, entry, size, float(seen.pooled_axes[a]), seen.z, detail))
        found[term.axis] += 1
        current.append(term.name)
        remaining.remove(entry)
    return out


TIMING = "currents' timing"
"""What a residual of logged currents late against the positions depends on (:func:`currents_late`)."""


def currents_late(
    j: Judgement,
    candidate: Candidate,
    model: StageModel,
    data: PreparedLogs,
    max_axis_loss: float = SelectionSettings.max_axis_loss,
) -> Unexplained | None:
    """The residual of logged currents that are late against the positions, when the amplifier lag
    (``j``, its judgement; ``candidate``, the lag on both axes) was significant, large enough and
    separable, and refused only because it is negative: the forces lead the logged currents by
    more than half the loop's zero-order hold (the lag's ``hold_delay``) and two standard errors.

    No amplifier makes a force before its current, so the lag refuses such a delay. But a log can
    be late against its own positions: a filter on the current sensors delays measured currents,
    and a logger can stamp the currents a sample after the positions they acted on. On
    ``../shared/logs/independent_clean.csv`` with its current columns moved one sample (1 ms) late,
    the lag's fit was -0.91 +- 0.10 ms on both axes (-0.96 ms less the 0.1 ms hold of its 5 kHz
    loop: the 1 ms skew, to its standard error), and -1.96 +- 0.11 ms with them two samples late;
    on the log as it is, +0.12 ms (the hold), not significant. With the lag refused, the residual
    went to the probe of the gap rate, read as "a force against the motion, as damping or friction
    the model lacks gives": over an oscillation a lead is a damping (-tau da/dt = tau omega^2 v), but
    the guides' viscous friction made the held-out error 14 % worse there. On the independent
    generator's clean_01 one sample late, a horizontal guide friction was claimed. Measured currents
    through a 300 Hz first-order sensor filter (0.53 ms; the generator's
    ``Rig.current_sensor_bandwidth``) gave a lead of 0.47 +- 0.05 ms. The words now say what the
    lag's fit says: the currents' timing, by how much, and what to do about it. ``candidate``'s term
    is kept with the entry, so the probes and the chosen effects are judged beside it and nothing is
    reported twice.

    ``data``: the prepared logs, for their sample time and whether their currents are measured (no
    hold between a measured current and its force, so the lead is the whole delay).

    A lead is only the log's timing where both axes move, the vertical axis shows it (lowers its
    held-out error; its column is the one the logged currents' errors do not swamp,
    :func:`~maglev_oc.diagnosis.currents.lag_candidates`), and it makes no axis it was judged on
    worse by more than the selection lets any effect (``max_axis_loss``; beside a claimed friction
    the horizontal axis is not judged): over an oscillation, a damping of one axis is a lead of
    that axis's forces. The project's twin with 3.2 N s/m of viscous friction on the horizontal
    guides alone, its vertical axis locked (``tests/test_diagnose_fallback_and_rates.py``), fitted a
    lead of 15 ms there. Nor is a lead beyond the lag's own bound
    (:data:`~maglev_oc.diagnosis.currents.LAG_BOUND`, 5 ms: five samples of a 1 kHz log) taken as
    timing. The filtered rig's cogging log (`bench/diagnose_rigs.py --rigs filtered`) has a lead
    of 0.49 +- 0.05 ms that lowers the vertical error by 1.8 % and the horizontal one by -0.1 %.
    """
    delay, hold_delay = j.physical.get("total_delay"), j.physical.get("hold_delay")
    if j.verdict != "implausible" or delay is None or hold_delay is None:
        return None
    lead, sd, hold = -delay.value, delay.stderr, hold_delay.value
    if not 0.5 * hold + 2.0 * sd < lead <= LAG_BOUND:
        return None
    gains = j.pooled_gain_axes if j.pooled_gain_axes is not None else j.gain_axes
    judged = np.isfinite(gains)
    if not (np.all(data.moving) and judged[0] and gains[0] > 0 and np.all(gains[judged] > -max_axis_loss)):
        return None  # one axis alone: a damping of that axis (the docstring)
    a = int(np.argmax(np.where(judged, gains, -np.inf)))
    size = float(j.contribution_rms[a])
    p = model.params
    mass = p.mass_vertical if a == 0 else p.mass_horizontal
    dt = data.sample_time
    if data.settings.get("currents_measured"):
        late = lead
        why = (
            f"{late * 1e3:.2g} ms ({late / dt:.1f} sample periods of {dt * 1e3:g} ms), as a first-order "
            f"filter on the current sensors of bandwidth {1 / (2 * math.pi * late):.3g} Hz, or a logger "
            "that stamps the currents after the positions they acted on, makes them"
        )
    else:
        late = lead + hold  # the skew: the lead, and the hold every sampled loop adds
        why = (
            f"about {late * 1e3:.2g} ms with the loop's {hold * 1e3:.2g} ms hold ({late / dt:.1f} sample "
            f"periods of {dt * 1e3:g} ms), as a logger that stamps the currents after the positions they "
            "acted on makes them"
        )
    return Unexplained(
        axis=AXES[a],
        depends_on=TIMING,
        size=size,
        force_rms=size * mass,
        gain=float(gains[a]),
        z=float(j.z),
        description=(
            f"The forces lead the logged currents by {lead * 1e3:.2f} ± {sd * 1e3:.2f} ms ({size:.3g} m/s² "
            f"RMS on the {AXES[a]} axis, lowering its held-out error by {gains[a]:.1%}, z = {j.z:.1f}): "
            "fitted as the amplifiers' lag, it comes out negative. No amplifier or loop makes a force "
            f"before its current: the logged currents are late against the positions, by {why}. Align "
            f"them with the positions (maglev-oc diagnose --currents-late {late:.2g}) or log the commanded "
            "currents, and diagnose again: the constants and every effect of the currents are fitted to "
            "currents out of place in time."
        ),
        term=candidate.term,
    )


def delayed_rates(c: Candidate) -> tuple[str, ...]:
    """The velocities of the axes whose forces ``c`` delays behind the logged currents (the
    amplifier lag; none for any other effect). On a regulated stage a delay's column is a function
    of them (the regulator's currents follow the motion; over an oscillation a delay is a force
    along it), so a dependence on them left beside the chosen lag is the lag's own imperfect shape
    (a pure delay beside a first-order lag), not its rival. Set 21707 of the independent generator
    (a 218 Hz amplifier with 0.24 ms of delay beside a detent and a tilted base, 20 um encoders):
    the lag was chosen at 1.17 ms, then dropped beside a polynomial of the gap rate that fitted its
    effect as well, and the log's residual was reported as an unexplained dependence on the gap rate."""
    if not (c.variable == "current_rate" and c.physical_sign > 0):
        return ()
    return tuple(f"{STATE_OF_AXIS[a]}_rate" for a in AXES if c.axis in (a, "both"))


def rate_sense(q: np.ndarray) -> int:
    """+1 when a probe of an axis's own velocity (mean-free Legendre polynomials of orders 1-4 over
    the logged rates, coefficients ``q``) rises with the velocity (a force along the motion), -1 when
    it falls (against it), 0 when its even part (both ends against the middle) outweighs its odd part
    (the change from the slowest to the fastest logged rate: P1 and P3 are odd)."""
    q = np.asarray(q, dtype=float)
    odd = q[0] + q[2]  # (f(+1) - f(-1)) / 2: P1 and P3 are 1 at +1 and -1 at -1
    even = 1.5 * q[1] + 0.625 * q[3]  # (f(+1) + f(-1)) / 2 - f(0): P2(0) = -1/2, P4(0) = 3/8
    if not abs(odd) > abs(even):
        return 0
    return 1 if odd > 0 else -1


def rate_direction(q: np.ndarray, beside_friction: bool = False, beside_lag: bool = False) -> str:
    """What a probe of an axis's own velocity (mean-free Legendre polynomials of orders 1-4 over the
    logged rates, coefficients ``q``) says of the force's direction, when its odd part (the change
    from the slowest to the fastest logged rate: P1 and P3 are odd) outweighs its even part (both
    ends against the middle); "" otherwise. ``beside_friction``: guide friction is claimed on the
    axis, and the residual is then read against it; ``beside_lag``: an amplifier lag is claimed on
    the axis (:func:`delayed_rates`), or fitted for the currents' timing (:func:`currents_late`),
    and the residual is read against its fit (set 21707 of the
    independent generator: a 218 Hz amplifier with 0.24 ms of delay, fitted as a first-order lag of
    1.17 ms, left a residual falling with the gap rate, which without this was read as damping).

    Against the motion is what damping or friction the model lacks gives. Along the motion no
    passive force gives: a delay between the logged signals and the forces does on a regulated stage
    (the force follows the commanded acceleration late, a residual of -tau da/dt, and over an
    oscillation da/dt = -omega^2 v: +tau omega^2 v, a negative damping). Measured on logs of the
    independent generator whose residual a probe of the gap rate explained (no limits, 14 logs):
    along the motion on all four with an amplifier lag and no friction claimed on that axis (noisy
    single_20, eleven_07 twice, pair 10015: 0.018-0.048 m/s^2 across the logged rates), but also on
    two experiment logs with a detent or an end effect and no lag (0.014 and 0.009 m/s^2), so the
    words name what gives that sign, not an effect; beside a claimed vertical friction, along the
    motion on six logs without a lag (0.03-0.42 m/s^2), and against it (1.2 m/s^2) beside a claimed
    horizontal friction and an unclaimed lag (pair 10074): there the words say only how the residual
    stands to the friction found."""
    sense = rate_sense(q)
    if not sense:
        return ""
    odd = float(np.asarray(q, dtype=float)[[0, 2]].sum())
    falls = sense < 0
    change = f"{2 * abs(odd):.2g} m/s² across the logged rates"
    said = f" It {'falls as the velocity grows' if falls else 'rises with the velocity'} ({change})"
    if beside_friction:
        return (
            f"{said}, beside the guide friction found on this axis: {'more' if falls else 'less'} force "
            "against the motion at speed than the fit of that friction gives."
        )
    if beside_lag:
        return (
            f"{said}, beside the delay between the logged currents and the forces found on this log: "
            f"{'less' if falls else 'more'} force along the motion at speed than the fit of that delay "
            "gives, as a delay of another shape than a first-order lag leaves (a pure delay, a lag of "
            "higher order, a filter); or a force of the axis beside it."
        )
    if falls:
        return f"{said}: a force against the motion, as damping or friction the model lacks gives."
    return (
        f"{said}: a force along the motion, which no friction or damping gives; a delay between the "
        "logged signals and the forces does (an amplifier lag, a loop delay the log does not declare, "
        "a timing skew between the logged currents and positions)."
    )


def _probes(
    data: PreparedLogs,
    periods: Sequence[tuple[str, float]],
    friction_axes: frozenset[str] = frozenset(),
    lagging: frozenset[str] = frozenset(),
) -> list[_Probe]:
    """The additive and periodic probes on the moving axes; a probe of an axis's own velocity says
    which way the force it finds points (:func:`rate_direction`; ``friction_axes``: the axes with
    guide friction claimed; ``lagging``: the velocities of the axes with a lag claimed,
    :func:`delayed_rates`)."""
    probes: list[_Probe] = []
    for (axis, var), term in smooth_probes(data).items():
        if data.moving[AXES.index(axis)]:
            own_rate = var == f"{STATE_OF_AXIS[axis]}_rate"  # the axis's velocity (PROBE_VARIABLES)
            detail = (
                partial(rate_direction, beside_friction=axis in friction_axes, beside_lag=var in lagging)
                if own_rate
                else None
            )
            probes.append(_Probe(term, var, PROBE_VARIABLES[var][1], detail=detail))
    # a period longer than the logged travel shows no period there, only a smooth change along it:
    # the smooth probe of the position is that dependence. Taken as a dependence on another
    # variable than the position, a sine over 93.4 mm on a 66 mm travel dropped the true end
    # effects beside it (drawn pair 28604 of the independent generator: a raised-cosine fall of 9 %
    # of the attraction towards the stator ends beside a commutation offset, observer velocities
    # and a 0.5 kg payload; a thrust ripple was claimed in their place).
    lo, hi = np.percentile(data.x[2, data.valid], [1, 99])
    for axis, period in periods:
        a = AXES.index(axis)
        if data.moving[a] and period <= hi - lo:
            probes.append(
                _Probe(
                    _sine_probe(f"probe_{axis}_period_{period * M_TO_UM:.0f}um", a, period),
                    f"position (period {period * M_TO_MM:.1f} mm)",
                    f"the horizontal position, periodically over {period * M_TO_MM:.1f} mm",
                    period,
                )
            )
    return probes


FORCE_PROBE_ORDER = 2
"""Legendre orders 1..2 of the position for the forces along the travel: a slope and a bow of each
force's share (a constant share is a change of the constants)."""


BOTH_ENDS = 0.25
"""The smaller end's change, as a share of the larger's, above which forces lower (or higher) at
both logged ends than at the centre are said to change at both ends, not towards one."""


def along_the_stator(low: float, high: float, lo: float, hi: float) -> str:
    """What a change of the motor's forces along the travel looks like, in the physical words of
    what gives it (issue 19, item 5: end effects, a field not uniform along the stator): ``low``,
    ``high`` [%] the forces' share at the logged ends ``lo``, ``hi`` [m] relative to the centre. The
    forces fall where the mover overhangs a stator end, at both ends if both are near the travel and
    towards one if one is (drawn pair 9813 of the independent generator: a stator end just beyond
    +50 mm, the other far off, the forces falling over the whole travel towards +33 mm); forces
    higher towards an end are no end effect. The magnets ride on the mover (000 Sec. II: four N35
    magnets on a ferromagnetic backing), so what else changes along the travel is the stator and
    the true gap to it: its face not parallel to the guides (the gap encoder reads the mover
    against the frame, not against the stator), or its iron not uniform along it. A sentence, or ""
    when the forces do not change."""
    larger = max(abs(low), abs(high))
    if not larger > 0:
        return ""
    if low * high > 0 and min(abs(low), abs(high)) >= BOTH_ENDS * larger:
        if low < 0:
            return (
                " Lower at both ends: what the stator's ends give where the mover overhangs them "
                "(end effects)."
            )
        return (
            " Higher at both ends: the stator's face nearer the mover towards both ends (the true gap "
            "narrower there than the gap encoder reads), which no end effect gives."
        )
    at_high = abs(high) >= abs(low)
    towards = f"the high end ({hi * M_TO_MM:.0f} mm)" if at_high else f"the low end ({lo * M_TO_MM:.0f} mm)"
    if (high if at_high else low) < 0:
        return (
            f" Falling towards {towards}: what a stator end near that end of the travel gives (an end "
            "effect), or the stator's face drawing away from the mover towards it (the true gap wider there "
            "than the gap encoder reads) or its iron not uniform along the travel."
        )
    return (
        f" Rising towards {towards}: the stator's face nearer the mover towards it (the true gap narrower "
        "there than the gap encoder reads) or its iron not uniform along the travel; an end effect lowers "
        "the forces."
    )


class _AlongTravel(NamedTuple):
    """Mean-free Legendre polynomials of the position (orders 1 to :data:`FORCE_PROBE_ORDER`) over
    its logged range [lo, hi] (1st-99th percentile), for probes of something changing along it."""

    lo: float
    hi: float
    shares: Callable  # x -> the polynomials at x[2], less their means over the logged samples
    changes: Callable[[np.ndarray], tuple[float, float]]  # q -> sum_i q_i (P_i(-+1) - P_i(0))


def _along_travel(data: PreparedLogs) -> _AlongTravel:
    """The position basis of the force and friction probes: a change at each logged end relative to
    the centre is sum_i q_i (P_i(+-1) - P_i(0)); an odd order is a slope (one end up, the other
    down), an even one a bow (both ends down or both up)."""
    x3 = data.x[2, data.valid]
    lo, hi = (float(v) for v in np.percentile(x3, [1, 99]))
    c, h = 0.5 * (lo + hi), max(0.5 * (hi - lo), 1e-12)
    orders = range(1, FORCE_PROBE_ORDER + 1)
    means = [float(np.mean(b)) for b in legendre((x3 - c) / h, orders)]
    centre = legendre(0.0, orders)
    at_end = [
        [float(e - m) for e, m in zip(legendre(end, orders), centre, strict=True)] for end in (-1.0, 1.0)
    ]

    def shares(x):
        return [b - m for b, m in zip(legendre((x[2] - c) / h, orders), means, strict=True)]

    def changes(q) -> tuple[float, float]:
        low, high = (sum(float(qi) * d for qi, d in zip(q, row, strict=True)) for row in at_end)
        return low, high

    return _AlongTravel(lo, hi, shares, changes)


def _force_probes(data: PreparedLogs, model: StageModel) -> list[_Probe]:
    """The motor's forces varying smoothly along the travel, one
    probe per moving axis: the thrust (horizontally) and, vertically, the magnets' attraction and the
    currents' normal force, each times mean-free Legendre polynomials of the position (orders 1 to
    :data:`FORCE_PROBE_ORDER` over its logged range), with their own coefficients.

    An additive function of the position does not describe such a residual on a regulated stage:
    where the attraction is lower the loop raises the levitation current, so the residual is the
    lost share of each force at that gap and current, not a function of the position alone. A
    one-sided end effect of the independent generator (the forces falling towards one end over the
    whole travel, the attraction 2 % and the thrust 7 % lower at one logged end than at the other)
    left a vertical residual of 0.12 m/s^2 RMS that the additive probe of the position made worse
    on half of the held-out blocks (z -0.1); the end effects' own profiles, anchored at the logged
    ends, fitted it only as a growth at one end and a fall at the other, which they refuse.
    """
    ctx = LibraryContext(model, data)
    along = _along_travel(data)
    lo, hi, shares = along.lo, along.hi, along.shares
    k = FORCE_PROBE_ORDER

    def vertical(x, u, du, q):
        _, winding, magnets = ctx.force_terms(x, u)
        p = shares(x)
        return sum((p[i] * (q[i] * winding + q[k + i] * magnets) for i in range(k)), ca.SX(0))

    def horizontal(x, u, du, q):
        thrust, _, _ = ctx.force_terms(x, u)
        p = shares(x)
        return sum((p[i] * q[i] for i in range(k)), ca.SX(0)) * thrust

    # each force's share at a logged end relative to the centre of the travel (both ends down: end
    # effects; both up: a field stronger towards the ends)
    def changes(q) -> tuple[float, float]:
        """[%] the force's share at the low and the high logged end, relative to the centre."""
        low, high = along.changes(q)
        return 100.0 * low, 100.0 * high

    def ends(q) -> str:
        low, high = changes(q)
        return f"{low:+.1f} % at {lo * M_TO_MM:.0f} mm and {high:+.1f} % at {hi * M_TO_MM:.0f} mm"

    def vertical_detail(q) -> str:
        both = np.add(changes(q[k:]), changes(q[:k]))
        return (
            f" Fitted so, relative to the centre of the travel, the magnets' attraction is {ends(q[k:])}, "
            f"the currents' normal force {ends(q[:k])}.{along_the_stator(*both, lo, hi)}"
        )

    def horizontal_detail(q) -> str:
        return (
            f" Fitted so, relative to the centre of the travel, the thrust is {ends(q)}."
            f"{along_the_stator(*changes(q), lo, hi)}"
        )

    out = []
    for a, (build, n, words, detail) in enumerate(
        (
            (vertical, 2 * k, "the magnets' attraction and the currents' normal force", vertical_detail),
            (horizontal, k, "the thrust", horizontal_detail),
        )
    ):
        if data.moving[a]:
            name = f"probe_{AXES[a]}_forces_along_position"
            out.append(
                _Probe(
                    _probe(name, a, build, n),
                    "position",
                    f"the horizontal position in proportion to {words} (as if they changed along the stator)",
                    detail=detail,
                )
            )
    return out


FRICTION_ALONG_PROBE = "probe_horizontal_friction_along_position"
"""The name of the probe of the horizontal guides' friction changing along the track."""


def _friction_along_track(
    data: PreparedLogs, model: StageModel, friction_axes: frozenset[str]
) -> list[_Probe]:
    """Beside friction claimed on the horizontal guides, that friction's level changing along the
    track (a rail whose preload or lubrication changes): the smoothed sign of the velocity (the
    friction term's, :data:`~maglev_oc.regression.terms.REVERSAL_SPEED`) times mean-free Legendre
    polynomials of the position (orders 1 to :data:`FORCE_PROBE_ORDER` over its logged range).

    On a regulated stage the thrust current follows the friction, so such a residual is also the
    thrust changing along the travel: on six logs of the independent generator whose guides' friction
    changed by 20-32 % over the logged travel (``bench/diagnose_rigs.py --friction-shapes``), the
    thrust's probe took it and was read as the forces rising towards one end. The friction's own
    probe explains it better, and says what it is."""
    if "horizontal" not in friction_axes or not data.moving[1]:
        return []
    along = _along_travel(data)
    lo, hi = along.lo, along.hi
    mass = model.params.mass_horizontal

    def build(x, u, du, q):  # q: the friction's change [N] per mean-free Legendre polynomial
        shares = along.shares(x)
        return (
            -ca.tanh(x[3] / REVERSAL_SPEED) * sum((q[i] * p for i, p in enumerate(shares)), ca.SX(0)) / mass
        )

    def detail(q) -> str:
        low, high = along.changes(q)
        return (
            f" Fitted so, relative to the centre of the travel, the friction of the horizontal guides is "
            f"{low:+.2g} N at {lo * M_TO_MM:.0f} mm and {high:+.2g} N at {hi * M_TO_MM:.0f} mm: friction "
            "that changes along the track (a rail whose preload or lubrication changes), which the "
            "friction found does not model."
        )

    probe = _Probe(
        _probe(FRICTION_ALONG_PROBE, 1, build, FORCE_PROBE_ORDER),
        "position",
        "the horizontal position against the direction of motion (as if the guides' friction changed "
        "along the track)",
        detail=detail,
    )
    return [probe]


FRICTION_OVER_TIME_PROBE = "probe_{axis}_friction_over_time"
"""The name of the probe of an axis's guide friction changing over the log (``axis`` filled in)."""


def _friction_over_time(data: PreparedLogs, model: StageModel, friction_axes: frozenset[str]) -> list[_Probe]:
    """Beside friction claimed on an axis, that friction's level changing over the log (guides whose
    lubricant thins as they warm, or that run in): the smoothed sign of the velocity (the friction
    term's) times the Legendre polynomials P1, P2 of the place in the log (mean-free over it,
    :attr:`~maglev_oc.regression.data.PreparedLogs.log_place`), so that the friction found stays the
    log's mean.

    On six logs of the independent generator whose large guide friction fell by 30 % with a time
    constant of 60 s (``bench/diagnose_rigs.py --warming``) the friction was claimed at its mean
    level and nothing else, neither the magnets' drift (whose force follows the thrust and the
    attraction, not the direction of motion) nor anything unexplained: the change went unsaid.

    Several logs of one rig: each log has its own change and its own level (against the logs'
    mean, the levels summing to zero), as logs recorded one after another while the guides warm
    have, as the magnets' drift has (:func:`~maglev_oc.diagnosis.magnetics.field_drift_candidate`)."""
    logs = log_names(data.sources)
    n_logs = len(logs)
    n_q = 2 if n_logs == 1 else 3 * n_logs - 1
    out = []
    for a, axis in enumerate(AXES[:2]):
        if axis not in friction_axes or not data.moving[a]:
            continue
        v = 1 if a == 0 else 3  # the axis's velocity in the state
        p = model.params
        mass = p.mass_vertical if a == 0 else p.mass_horizontal
        name = FRICTION_OVER_TIME_PROBE.format(axis=axis)
        x, u, du, s, q = (
            ca.SX.sym("x", 4),
            ca.SX.sym("u", 2),
            ca.SX.sym("du", 2),
            when_symbol(),
            ca.SX.sym("q", n_q),
        )
        p1, p2 = legendre(s[0], (1, 2))  # mean-free over each log
        if n_logs == 1:
            level = q[0] * p1 + q[1] * p2
        else:  # each log's own change, and its own level (the last one's minus the others')
            level = sum((s[1] == k) * (q[2 * k] * p1 + q[2 * k + 1] * p2) for k in range(n_logs))
            level += sum(((s[1] == k) - (s[1] == n_logs - 1)) * q[2 * n_logs + k] for k in range(n_logs - 1))
        val = -ca.tanh(x[v] / REVERSAL_SPEED) * level / mass
        fn = ca.Function(name, [x, u, du, s, q], [ca.vertcat(val, 0) if a == 0 else ca.vertcat(0, val)])
        term = AccelerationTerm(
            name, "probe", axis, tuple(f"q{i}" for i in range(n_q)), function=fn, in_time=True
        )

        def detail(q, axis=axis) -> str:
            q = np.asarray(q, dtype=float).ravel()
            if n_logs == 1:
                change = 2.0 * float(q[0])  # P1 from -1 to +1; P2 is the same at both ends
                return (
                    f" Fitted so, the friction of the {axis} guides changes by {change:+.2g} N from the "
                    "log's first sample to its last: friction that changes as the guides warm (their "
                    "lubricant thinning) or run in, which the friction found, the log's mean, does not model."
                )
            changes = listed([f"{2.0 * q[2 * k]:+.2g} N in {name}" for k, name in enumerate(logs)])
            rest = q[2 * n_logs :]
            levels = listed(
                [f"{v:+.2g} N in {name}" for v, name in zip([*rest, -rest.sum()], logs, strict=True)]
            )
            return (
                f" Fitted so, the friction of the {axis} guides changes by {changes} from a log's first "
                f"sample to its last, and its level over a log is {levels} against the logs' mean: friction "
                "that changes as the guides warm (their lubricant thinning) or run in, which the friction "
                "found, the logs' mean, does not model."
            )

        out.append(
            _Probe(
                term,
                "time",
                f"the time in the log against the direction of motion (as if the {axis} guides' friction "
                "changed over the log)",
                detail=detail,
            )
        )
    return out


def _best_probe(
    design, current: list[str], probes: list[_Probe], r0: np.ndarray, counted, cross: _CrossParts | None
) -> tuple[_Probe, _HeldOutTest]:
    """(probe, its held-out test) that lowers the error of its axis the most, over the held-out
    quarter and the cross-fitted parts of the training data (``cross``) as the selection's test 1
    pools them."""
    tests = [
        (entry, _held_out_test(design, [*current, entry.term.name], r0, counted, cross, np.array([a])))
        for entry in probes
        for a in (AXES.index(entry.term.axis),)
    ]
    return max(tests, key=lambda t: t[1].pooled_axes[AXES.index(t[0].term.axis)])


def _unexplained(
    model: StageModel,
    entry: _Probe,
    size: float,
    gain: float,
    z: float,
    detail: str = "",
) -> Unexplained:
    term, key, words, period = entry.term, entry.key, entry.words, entry.period
    p = model.params
    mass = p.mass_vertical if term.axis == "vertical" else p.mass_horizontal
    return Unexplained(
        axis=term.axis,
        depends_on=key,
        size=size,
        force_rms=size * mass,
        gain=gain,
        z=z,
        description=(
            f"A {term.axis} residual of {size:.3g} m/s² RMS ({size * mass:.3g} N) that varies with "
            f"{words}; no effect of the library explains it (it lowers the held-out error by "
            f"{gain:.1%}, z = {z:.1f})." + detail
        ),
        period=period,
        term=term,
    )
