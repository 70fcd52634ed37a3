"""How large each effect the diagnosis did not claim would have had to be for this log to show it.

"Not found" means absent or too small for the log. A control engineer needs to know which: a
thrust ripple of 3 % that a log of this rig cannot show is a ripple still to look for with a
better experiment, not a ripple ruled out. For every library effect whose last judgement was
"not significant" or "too small" (the log did not show it; refusals for other reasons, such as
"not separable", already say what the log would need), the selection's own tests of visibility
are repeated on this log with an effect of that kind added to it at growing sizes:

1. the effect of unit size, along the candidate's first coefficient (or its ``size_direction``,
   the commutation angle's), of the sign that is physical where only one is
   (``Candidate.physical_sign``), is computed at the currents the plant felt
   (:func:`felt_currents`: those that make the refitted model produce the measured accelerations),
   not at the logged ones, whose errors would carry the effect too;
2. s times it is added to the measured accelerations, and the fits with and without the candidate
   (beside the base constants and the effects claimed) are made as the selection makes them;
3. the tests that decide whether a log shows an effect are run as the selection runs them
   (:func:`~maglev_oc.diagnosis.selection.judge`'s test 1 and its size test): the held-out gain
   pooled over the held-out quarter and the cross-fitted training parts at least ``min_gain``, a
   drop on the quarter, z at least ``min_z``, and a change of the held-out prediction of at least
   ``min_effect`` RMS on one of its axes.

The smallest such size is the detection limit, reported in the candidate's first physical
parameter (a ripple's amplitude, a lag's time constant beyond the hold, a friction's Coulomb
force); when that size is one the candidate's plausibility test refuses, or no size up to
:data:`STEP` ** :data:`MAX_STEPS` standard errors shows it (a column made of the logged signals'
errors more than of their signal predicts nothing however large the effect), the effect is not
seen at any size. Where the log shows one before any is added (its last judgement refused it on
another test, or was made beside an effect dropped since), or leans so far towards one that the
smallest size tried shows it, there is no limit: NaN, with the reason (a log holding 5-7 % of end
effects was told "end effects below 0.039 %"). Every fit is linear in the target (the
errors-in-variables correction depends only on the columns), so the residuals at size s are
r + s r_unit: two pairs of fits per candidate, and the search over s is arithmetic on residuals.

**How close.** The limit is this log's, for an effect of the candidate's shape added to it. A real
effect can differ: the tests of separability, plausibility and the rivals can refuse one above the
limit; a shape other than the candidate's (a Stribeck friction, an end effect of another profile)
is seen at another size; and in closed loop the regulator answers a real effect with its currents
(a tilt's steady force with a steady thrust current, which the constants then share), which an
effect added to a log does not do. Measured with ``bench/diagnose_limits.py`` (bench/README, *What
a log could not have shown*): on the independent generator's default rig, thrust ripples were
claimed from 0.8 to 1.4 times their limits, amplifier lags from 1.2 to 1.6 times and tilts at 1.4
times (their limit there is the size test's floor); on its noisy rig, as noisy as
``../shared/logs``' clean log, tilts and cable carriers from 1 to 3 times their limits on most
seeds and up to 16 times on one; a lower bound there. A candidate proportional to the thrust
current is also tried on the thrust side where the selection uses it
(:mod:`~maglev_oc.diagnosis.thrust_current`: the same tests on the regression restated in amperes,
the effect added at the felt currents, the size test on the thrust per ampere times the change),
and its limit is the smaller of the two: on the noisy rig thrust ripples were then claimed from 1.1
to 1.25 times their limits on four seeds of five (bench/README, *Judged on the thrust current*);
on the accelerations alone they were not claimed at 30 % on three, whose logged thrust current is
mostly its error.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from maglev_oc.diagnosis.candidate import Candidate
from maglev_oc.diagnosis.currents import AMPLIFIER_LAG_NOT_LOGGED
from maglev_oc.diagnosis.library import frame_angle
from maglev_oc.diagnosis.selection import (
    CURRENT_STEP_SEPARATES,
    THRUST_SIDE,
    Judgement,
    Selection,
    SelectionSettings,
    _CrossFit,
    _friction_axes,
    _holdout_residual,
    evidence,
    fitted_constants,
    holdout_significance,
    judged_alone,
    judged_axes,
    pooled_gains,
    pooled_significance,
)
from maglev_oc.diagnosis.thrust_current import THRUST, felt_currents, judged_on_thrust_current, thrust_side
from maglev_oc.model.stage import StageModel
from maglev_oc.regression.design import Design, build_design
from maglev_oc.regression.solve import fit_subset
from maglev_oc.results import jsonable

__all__ = ["DetectionLimit", "detection_limits", "felt_currents", "with_target"]

STEP = 1.5
"""Ratio between the sizes tried before the limit is bracketed (then bisected)."""
MAX_STEPS = 35
"""Sizes tried upwards from the fit's naive standard error (1.5^35, about 1.5e6 of them; the limits
of the independent generator's logs lie 3-300 of them up): an effect not seen by then is reported
as not seen at any size."""
BISECTIONS = 5
"""Halvings of the bracket (in log size): the limit to 1.5^(1/32), 1.3 % (it is reported to two
significant digits)."""


@dataclass(frozen=True)
class DetectionLimit:
    """The smallest size of one effect that this log would have shown.

    ``value`` is in ``unit`` (SI; "1" for ratios), of ``parameter`` (the candidate's first physical
    parameter); ``math.inf`` when no size shows it; NaN when the log shows one with none added
    (:data:`ALREADY_SHOWN`: the last judgement refused it on another test, or was made beside an
    effect dropped since) or leans so far towards one that the smallest size tried shows it
    (:data:`NEARLY_SHOWN`); ``reason`` then says which and why. ``binding``: the test that held it
    back just below the limit ("z", "gain", "size", "quarter" or "physics": the candidate's
    plausibility). ``side``: "" when the accelerations would show it first,
    :data:`~maglev_oc.diagnosis.selection.THRUST_SIDE` when the logged thrust current would
    (:mod:`~maglev_oc.diagnosis.thrust_current`)."""

    name: str
    parameter: str
    value: float
    unit: str
    binding: str
    reason: str = ""
    side: str = ""

    @property
    def not_in_log(self) -> bool:
        """Whether no size of the effect can be in this log at all (the amplifiers' lag before a
        log's measured currents, :data:`~maglev_oc.diagnosis.currents.AMPLIFIER_LAG_NOT_LOGGED`), as
        against not shown at any size tried: said where the findings are read first."""
        return self.reason == AMPLIFIER_LAG_NOT_LOGGED

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "parameter": self.parameter,
            "value": jsonable(self.value),
            "unit": self.unit,
            "binding_test": self.binding,
            "reason": self.reason,
            "judged_on": self.side or "accelerations",
        }


@dataclass(frozen=True)
class _Residuals:
    """Held-out residuals (2, n_hold) and the cross-fitted parts' ((2, m) each), without and with
    the candidate, zero where a sample does not count."""

    r0: np.ndarray
    r1: np.ndarray
    parts0: list[np.ndarray]
    parts1: list[np.ndarray]

    def at(self, unit: _Residuals, s: float) -> _Residuals:
        return _Residuals(
            self.r0 + s * unit.r0,
            self.r1 + s * unit.r1,
            [a + s * b for a, b in zip(self.parts0, unit.parts0, strict=True)],
            [a + s * b for a, b in zip(self.parts1, unit.parts1, strict=True)],
        )


@dataclass(frozen=True)
class _Context:
    design: Design
    current: list[str]
    settings: SelectionSettings
    fold: _CrossFit | None
    counted: np.ndarray | None
    counted_parts: list[np.ndarray | None]
    friction: frozenset[int]
    felt: dict[str, np.ndarray]  # the candidates' columns at the currents the plant felt
    # on the thrust side: (2, n_hold) the acceleration per unit of each row's residual (the thrust
    # current's per ampere, zero on the other row), for the size test; None on the accelerations
    per_unit: np.ndarray | None = None

    def change(self, r0: np.ndarray, r1: np.ndarray) -> np.ndarray:
        """The change of the held-out prediction, as acceleration."""
        return r0 - r1 if self.per_unit is None else (r0 - r1) * self.per_unit


def detection_limits(
    design: Design,
    library: Sequence[Candidate],
    selection: Selection,
    settings: SelectionSettings,
    model: StageModel,
) -> list[DetectionLimit]:
    """The detection limit of every library effect not claimed whose last judgement in
    ``selection`` was that the log did not show it, in the order of its held-out gain as judged;
    ``model``: the references the library's columns were built with (its currents are inverted
    for the currents the plant felt)."""
    by_name = {c.name: c for c in library}
    current = list(selection.final.groups)
    chosen = [by_name[n] for n in current if n in by_name]
    claimed = {c.reported_name for c in chosen}
    judged = [
        (j, by_name[j.name])
        for j in sorted(selection.last.values(), key=lambda j: -j.gain)
        if j.name in by_name and j.name in design.groups and j.verdict in UNSEEN_VERDICTS
    ]
    judged = [(j, c) for j, c in judged if not (c.fallback_for or c.form_of or c.reported_name in claimed)]
    if not judged:
        return []
    fold = _CrossFit(design, settings.cross_parts) if settings.cross_parts else None
    counted = evidence(design, chosen, settings)
    angle = frame_angle(library)  # the felt currents in the frame the columns take (felt_currents)
    ctx = _Context(
        design,
        current,
        settings,
        fold,
        counted,
        fold.counted(chosen, settings) if fold else [],
        frozenset(_friction_axes(chosen)),
        _felt_columns(design, model, [c for _, c in judged], angle),
    )
    side = thrust_side(design, model, angle=angle) if any(c.thrust_proportional for _, c in judged) else None
    on_side = None
    if side is not None:
        per_unit = np.zeros((2, side.per_ampere.size))
        per_unit[THRUST] = side.per_ampere
        # the same parts as the accelerations' (the same blocks), so the same samples count there
        on_side = dataclasses.replace(
            ctx,
            design=side.design,
            fold=_CrossFit(side.design, settings.cross_parts) if settings.cross_parts else None,
            felt={},  # the restated columns are the felt currents' already
            per_unit=per_unit,
        )
    out = []
    for j, cand in judged:
        limit = _limit(ctx, cand, j)
        if on_side is not None and judged_on_thrust_current(cand, side):
            limit = min(limit, _limit(on_side, cand, j, np.array([THRUST])), key=lambda lim: lim.value)
        out.append(limit)
    return out


UNSEEN_VERDICTS = ("not significant", "too small")
"""The verdicts that say the log did not show an effect (the others say it showed something that
was refused, with their own reasons)."""
PHYSICS_RULES_OUT = "not seen at any size the physics allows"
ALREADY_SHOWN = (
    "no limit: before any is added, the log's residual passes the tests of what a log shows for an "
    "effect of this shape; it was not claimed on another test"
)
NEARLY_SHOWN = (
    "no limit: the log's residual leans towards an effect of this shape already, so that the "
    "smallest size tried shows one"
)
TEST_WORDS = {"gain": "held-out gain", "quarter": "held-out quarter", "z": "significance", "size": "size"}
"""The visibility tests (:func:`_failing`'s names) in words."""
NO_SIZE = (
    "not seen at any size tried: predicted from the logged signals, the effect does not improve the "
    "held-out error however large it is"
)


def _limit(
    ctx: _Context, cand: Candidate, judged: Judgement, rows: np.ndarray | None = None
) -> DetectionLimit:
    """``rows``: the rows judged (on the thrust side, the thrust current's); default the candidate's
    axes as the selection judges them."""
    design, current = ctx.design, ctx.current
    index = design.indices([cand.name])
    full = fit_subset(design, [*current, cand.name], covariance=False)
    constants = fitted_constants(full)
    direction = _direction(cand, constants, index.size)
    first, unit_name = _first_parameter(cand, direction, constants)
    signs = (1.0, -1.0)
    if cand.physical_sign:  # only one sign is physical: the direction along which its size grows
        grows = _physical(cand, direction, constants)[0] - _physical(cand, 0 * direction, constants)[0]
        direction = direction * (1.0 if grows * cand.physical_sign > 0 else -1.0)
        signs = (1.0,)
    side = "" if ctx.per_unit is None else THRUST_SIDE
    if judged.dominated_by_current_errors and not side:
        return DetectionLimit(
            cand.name, first, math.inf, unit_name, "", f"not seen at any size: {judged.reason}"
        )
    logged = _residuals(ctx, design, cand)
    _, hidden, left, axes = judged_axes(design, cand, ctx.friction)
    # judged on the axes without claimed friction: a size those never show says nothing of the others
    alone = f" ({judged_alone(left, hidden)}; {CURRENT_STEP_SEPARATES})" if hidden and left.size else ""
    if rows is not None:
        axes, alone = rows, ""
    if not (at_zero := _failing(ctx, logged, axes)):
        # the log shows one already by these tests: refused on another (or judged beside effects
        # since dropped), it has no size below which the log would not show it
        return DetectionLimit(
            cand.name, first, math.nan, unit_name, "", f"{ALREADY_SHOWN} ({judged.reason})", side
        )
    felt = np.tensordot(direction, ctx.felt.get(cand.name, design.columns[index]), axes=1)
    unit = _residuals(ctx, with_target(design, felt), cand)
    # the sizes tried start at the naive standard error along the direction, or at half the size
    # whose own change of the held-out prediction reaches the size test's floor if that is larger
    # (no smaller size passes it: the search's first steps would all fail there)
    pos = np.searchsorted(full.index, index)
    start = math.sqrt(max(float(direction @ full.naive[np.ix_(pos, pos)] @ direction), 0.0)) or 1e-12
    per_unit = float(np.max(np.sqrt(np.mean(ctx.change(unit.r0, unit.r1)[axes] ** 2, axis=1)), initial=0.0))
    if per_unit > 0:
        start = max(start, 0.5 * ctx.settings.min_effect / per_unit)

    def physics(size: float) -> str | None:  # the candidate's plausibility at that size
        at = cand.term.physical_parameters(size * direction, np.zeros((index.size, index.size)), constants)
        return cand.plausible(at)

    sizes = []
    for sign in signs:
        refused: list[str] = []  # this sign's, the sizes growing
        found = _smallest(ctx, logged, unit, axes, sign, start, physics, refused)
        if found is None:
            # the first size the physics refused, just past its bound: the search goes on growing
            # (the last it tried was a gap offset of 1.5 km on drawn pair 37007)
            why = (f"{PHYSICS_RULES_OUT}: {refused[0]}" if refused else NO_SIZE) + alone
            return DetectionLimit(cand.name, first, math.inf, unit_name, "", why, side)
        sizes.append(found)
    s, binding = max(sizes, key=lambda t: abs(t[0]))
    if not binding:  # no size tried failed: the log's residual leans towards one already
        test = TEST_WORDS.get(at_zero, at_zero)
        why = f"{NEARLY_SHOWN} (with none added, the {test} test fails: {judged.reason})"
        return DetectionLimit(cand.name, first, math.nan, unit_name, "", why, side)
    value = abs(_physical(cand, s * direction, constants)[0])
    return DetectionLimit(cand.name, first, value, unit_name, binding, "", side)


def _felt_columns(
    design: Design, model: StageModel, candidates: Sequence[Candidate], angle: float = 0.0
) -> dict[str, np.ndarray]:
    """Per candidate of the currents, its filtered columns (p, 2, n) evaluated at the currents the
    plant felt (:func:`felt_currents`) instead of the logged ones. The logged currents' errors
    (a sample of a current that changed four more times before the next log line) would carry an
    effect put in with the logged columns and make it look stronger than it is: a 10 % thrust
    ripple put into a noisy rig's clean log with the logged columns explained 5.6 % of its held-out
    error at z 5.0; the log of that plant with the ripple in it, 1.3 % at z 1.1."""
    terms = [c.term for c in candidates if c.term.depends_on_inputs()]
    felt = felt_currents(design.prepared, model, angle=angle) if terms else None
    if felt is None:
        return {}
    index = np.concatenate([design.indices([t.name]) for t in terms])
    columns = build_design(
        felt,
        model,
        estimate=(),
        terms=terms,
        fit=design.fit,
        holdout=design.holdout,
        at=design.at[index],
        weights=design.weights,
    ).columns
    out, k = {}, 0
    for t in terms:
        out[t.name] = columns[k : k + t.n_parameters]
        k += t.n_parameters
    return out


def with_target(design: Design, target: np.ndarray) -> Design:
    """``design`` with ``target`` (2, n) as its target: the blocks' right-hand sides and energies and
    the held-out normal equations recomputed from its columns."""
    weighted = target * design.weights[:, None] ** 2  # both factors of the weighted products
    per_sample = np.einsum("pan,an->np", design.columns, weighted)  # (n, P), no copy of the columns
    inside = np.flatnonzero(design.block_of >= 0)
    blocks = design.block_of[inside]
    n_blocks = design.rhs.shape[0]
    members = sparse.csr_matrix((np.ones(inside.size), (blocks, inside)), shape=(n_blocks, target.shape[1]))
    rhs = np.asarray(members @ per_sample)
    yy = np.bincount(blocks, np.sum(target[:, inside] * weighted[:, inside], axis=0), n_blocks)
    hold = design.holdout
    held = design.held_out_columns  # (P, 2, n_hold), copied once per design
    hold_rhs = np.stack([held[:, a] @ target[a, hold] for a in range(2)])
    hold_yy = np.array([float(target[a, hold] @ target[a, hold]) for a in range(2)])
    out = dataclasses.replace(design, target=target, rhs=rhs, yy=yy, hold_rhs=hold_rhs, hold_yy=hold_yy)
    # the same columns: the held-out copy is shared, not made again for each size tried
    out.__dict__["held_out_columns"] = held
    return out


def _residuals(ctx: _Context, design: Design, cand: Candidate) -> _Residuals:
    with_it = [*ctx.current, cand.name]
    fits = [fit_subset(design, g, covariance=False) for g in (ctx.current, with_it)]
    r0, r1 = (_holdout_residual(design, f, ctx.counted) for f in fits)
    if ctx.fold is None:
        return _Residuals(r0, r1, [], [])
    fold = ctx.fold.retargeted(design)

    def counted(parts):
        return [
            r if c is None else np.where(c, r, 0.0) for r, c in zip(parts, ctx.counted_parts, strict=True)
        ]

    return _Residuals(r0, r1, counted(fold.residuals(ctx.current)), counted(fold.residuals(with_it)))


def _failing(ctx: _Context, r: _Residuals, axes: np.ndarray) -> str:
    """The first of the visibility tests that residuals ``r`` fail ("" if none)."""
    settings, design = ctx.settings, ctx.design
    if axes.size == 0:
        return "axes"
    mse0 = np.maximum(np.mean(r.r0[axes] ** 2, axis=1), 1e-300)
    quarter = float(np.mean(1.0 - np.mean(r.r1[axes] ** 2, axis=1) / mse0))
    parts = list(zip(r.parts0, r.parts1, strict=True))
    if ctx.fold is not None:
        gain = float(np.mean(pooled_gains([(r.r0, r.r1), *parts], axes)))
        z = pooled_significance(design, ctx.fold, (r.r0, r.r1), parts, axes)
    else:
        gain = quarter
        z = holdout_significance(design, r.r0, r.r1, axes)[1]
    if gain < settings.min_gain:
        return "gain"
    if not quarter > 0:
        return "quarter"
    if z < settings.min_z:
        return "z"
    n = np.full(2, r.r0.shape[1]) if ctx.counted is None else np.maximum(ctx.counted.sum(axis=1), 1)
    contribution = np.sqrt(np.sum(ctx.change(r.r0, r.r1) ** 2, axis=1) / n)
    if np.max(contribution[axes]) < settings.min_effect:
        return "size"
    return ""


def _smallest(
    ctx: _Context,
    logged: _Residuals,
    unit: _Residuals,
    axes: np.ndarray,
    sign: float,
    start: float,
    physics: Callable[[float], str | None],
    refused: list[str],
) -> tuple[float, str] | None:
    """(size, the test failing just below it: "" when none of the sizes tried failed) of the
    smallest size along ``sign`` times the
    direction at which the log shows the effect and ``physics`` (its plausibility) allows it; None
    when no size tried is both (each plausibility refusal appended to ``refused``, smallest first). A lag
    seen at less than the loop's hold is claimed from the smallest lag beyond the hold that the
    plausibility test accepts; a ripple seen only beyond 30 % of the thrust is not seen at any
    size the physics allows."""

    def failing(size: float) -> str:
        why = physics(sign * size)  # first: it needs no residuals
        if why:
            refused.append(why)
            return "physics"
        return _failing(ctx, logged.at(unit, sign * size), axes)

    if _never_shown(ctx, unit, axes):
        return None

    below, why = 0.0, ""  # "" while no size tried has failed
    s = start
    for _ in range(MAX_STEPS):
        fails = failing(s)
        if not fails:
            break
        below, why = s, fails
        s *= STEP
    else:
        return None
    above = s
    for _ in range(BISECTIONS):
        mid = math.sqrt(max(below, start / STEP) * above)
        fails = failing(mid)
        if fails:
            below, why = mid, fails
        else:
            above = mid
    return sign * above, why


def _never_shown(ctx: _Context, unit: _Residuals, axes: np.ndarray) -> bool:
    """Whether no size can pass the gain tests: as the size grows the residuals tend to s times the
    unit's, so the gains tend to 1 - |r1_unit|^2 / |r0_unit|^2; below ``min_gain`` (pooled) or not
    positive (on the quarter) there, no size shows the effect (the logged columns' errors predict
    more noise than the effect removes)."""
    if axes.size == 0:
        return True
    quarter = 1.0 - np.sum(unit.r1[axes] ** 2) / max(float(np.sum(unit.r0[axes] ** 2)), 1e-300)
    if ctx.fold is None:
        return not quarter >= ctx.settings.min_gain
    parts = list(zip(unit.parts0, unit.parts1, strict=True))
    pooled = float(np.mean(pooled_gains([(unit.r0, unit.r1), *parts], axes)))
    return not (quarter > 0 and pooled >= ctx.settings.min_gain)


def _direction(cand: Candidate, constants: dict[str, float], size: int) -> np.ndarray:
    """A unit vector in the candidate's coefficients along which its reported size grows: its
    ``size_direction`` where it has one (the commutation angle moves both axes' coefficients),
    else its first coefficient (a ripple's sine over the slot pitch, a friction's Coulomb force, a
    lag's delay)."""
    d = np.zeros(size)
    if cand.size_direction is not None:
        v = np.asarray(cand.size_direction(constants), dtype=float)
        d[: v.size] = v
    else:
        d[0] = 1.0
    return d / np.linalg.norm(d)


def _physical(cand: Candidate, coef: np.ndarray, constants: dict[str, float]) -> tuple[float, str, str]:
    """(value, name, unit) of the candidate's first physical parameter at ``coef``."""
    values = cand.term.physical_parameters(coef, np.zeros((coef.size, coef.size)), constants)
    name, est = next(iter(values.items()))
    return float(est.value), name, est.unit


def _first_parameter(cand: Candidate, direction: np.ndarray, constants: dict[str, float]) -> tuple[str, str]:
    _, name, unit = _physical(cand, direction, constants)
    return name, unit
