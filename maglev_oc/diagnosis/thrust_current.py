"""Effects of the thrust current judged by how well they predict the logged thrust current.

The selection judges a candidate by how much better the model, with it, predicts held-out
accelerations from the logged signals. An effect proportional to the thrust current (a thrust
ripple, the thrust's dependence on the gap, saturation) is then predicted from the logged thrust
current, and where that current is mostly its logging error the prediction carries the error with
it: on the independent generator's noisy rig, whose 5 kHz loop logs one control sample in five
from observers 2.8 times faster than the papers' (currents as noisy as
``../shared/logs/independent_clean.csv``'s), the error floor of the logged currents made 79-84 % of
the base fit's horizontal residual on five clean logs (99 % on the shared log; 13-23 % on the
default rig), and a 30 % thrust ripple explained -1 % of the held-out error at z 0.4. Whatever its
size it could not be told: its column is the error times the ripple.

The same log read the other way round shows it. The accelerations are measured well (10 um
encoders, a matched filter), so the model is inverted on them, sample by sample
(:func:`felt_currents`: the currents that make the model produce the measured accelerations, by
Newton's method), and the residual is the logged current minus that felt current. To first order
in a change ``dq`` of the parameters this residual is ``J^-1 X(felt) dq`` (``J`` the model's
Jacobian in the currents, ``X(felt)`` the design's columns at the felt currents): the whole
regression restated in amperes (:func:`thrust_side`, :func:`maglev_oc.regression.design.restated`)
with columns free of the logged currents' error. The same 30 % ripple then explained 17 % of the
held-out thrust-current error at z 5.2 (seed 202 of bench/diagnose_limits.py); on five clean logs
of that rig no candidate of the thrust current explained more than 0.1 % (z at most 2.6).

The columns at the felt currents carry the acceleration's own measurement error instead, as much
as the target does, so this side is used only where the currents' error dominates
(:data:`ERROR_SHARE`) and only for the candidates whose horizontal force is proportional to the
thrust current (``Candidate.thrust_proportional``), on the thrust current alone: the levitation
current, several amperes, is logged with a small relative error, and judged there the
attraction's gap dependence took the residual of an amplifier lag (eleven_07 of the independent
set: 10.9 % at z 5.1).
"""

from __future__ import annotations

import dataclasses
import weakref
from dataclasses import dataclass

import casadi as ca
import numpy as np

from maglev_oc.diagnosis.candidate import Candidate
from maglev_oc.model.stage import StageModel
from maglev_oc.regression.base import AXIS_INDEX
from maglev_oc.regression.data import PreparedLogs
from maglev_oc.regression.design import Design, build_design, restated
from maglev_oc.regression.solve import fit_subset

__all__ = [
    "ERROR_SHARE",
    "ThrustSide",
    "error_share",
    "felt_currents",
    "judged_on_thrust_current",
    "thrust_side",
]

ERROR_SHARE = 0.5
"""How large the logged thrust current's error floor must be against the horizontal residual no
column of the design explains (:func:`error_share`) for the thrust side to be used: that residual
is then mostly the error. The independent generator's noisy rig 1.03-1.40 on five clean logs and
1.08-1.25 on six pairs of a ripple beside a large effect, ``../shared/logs``' clean log 1.33, its
default rig 0.23-0.25 on five clean logs and eight pairs (bench/README, *Judged on the thrust
current*)."""

THRUST = AXIS_INDEX["horizontal"]
"""The row of the restated design that holds the thrust current (the row of the axis it drives)."""


def felt_currents(
    prepared: PreparedLogs, model: StageModel, iterations: int = 3, angle: float = 0.0
) -> PreparedLogs | None:
    """``prepared`` with the currents (and their rates) that make ``model`` produce the measured
    accelerations: the currents the plant felt, within the band, as far as the model is right
    (Newton on the two accelerations in the two currents from the logged ones). None when the
    model cannot be inverted on some valid sample (a singular Jacobian, a non-finite value).

    ``angle``: the commutation offset d [rad] the columns they are put into were built beside
    (``Candidate.commutation_angle``). The model has no offset, so the currents it needs are in the
    magnets' frame; the columns take the amplifiers' (i_q, i_d) and turn them by d
    (:meth:`~maglev_oc.diagnosis.candidate.LibraryContext.force_terms`), so the felt currents are
    turned back first: i_q - d i_d and i_d + d i_q. Left in the magnets' frame, a column of i_q + d i_d
    counted the offset's thrust twice: on a measured-current log with a 2.5 degree offset and end
    effects (drawn pair 21030 of the independent generator) the residual that left on the thrust
    side was claimed as a 0.6 % thrust ripple the log does not have."""
    xs, us, acc = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("a", 2)
    out = model.f(xs, us)[[1, 3]]
    step = ca.Function("newton", [xs, us, acc], [us - ca.solve(ca.jacobian(out, us), out - acc)])
    n = prepared.n
    mapped = step.map(n)
    u = prepared.u.copy()
    for _ in range(iterations):
        u = np.asarray(mapped(prepared.x, u, prepared.acc))
    # on an axis that does not move its acceleration is not measured: the logged current stays
    for a, moving in enumerate(prepared.moving):
        if not moving:
            u[1 - a] = prepared.u[1 - a]
    if not np.all(np.isfinite(u[:, prepared.valid])):
        return None
    u = np.where(np.isfinite(u), u, prepared.u)
    if angle:
        u = np.stack([u[0] - angle * u[1], u[1] + angle * u[0]])
    du = np.empty_like(u)
    for start, stop in prepared.segment_bounds:
        du[:, start:stop] = np.gradient(u[:, start:stop], prepared.sample_time, axis=1)
    return dataclasses.replace(prepared, u=u, du=du)


@dataclass(frozen=True, eq=False)
class ThrustSide:
    """The regression restated in amperes.

    ``design`` has the original design's parameters, samples and blocks; row a of its target and
    columns is the current that drives axis a (i_d for the vertical axis, i_q for the horizontal
    one), its target the logged current in the model's linearization about the base fit, so that
    the residual of any fit is the logged current minus the current the fitted model needs for
    the measured accelerations. ``per_ampere``: (n_hold,) the horizontal acceleration per ampere
    of thrust current on the held-out samples [m/s^2/A], which turns a change of the predicted
    thrust current back into the force's acceleration."""

    design: Design
    per_ampere: np.ndarray


def judged_on_thrust_current(cand: Candidate, side: ThrustSide | None) -> bool:
    """Whether ``cand`` is judged on the thrust side too: there is one, and its force is the thrust
    current's on the horizontal axis alone."""
    return side is not None and cand.thrust_proportional and cand.axis == "horizontal"


def _inverse_jacobian(model: StageModel, prepared: PreparedLogs) -> tuple[np.ndarray, np.ndarray]:
    """(J^-1 (2 currents, 2 axes, n), J (2 axes, 2 currents, n)): the model's Jacobian of the two
    accelerations in the two currents at ``prepared``'s states and currents, and its inverse."""
    xs, us = ca.SX.sym("x", 4), ca.SX.sym("u", 2)
    jac = ca.jacobian(model.f(xs, us)[[1, 3]], us)
    fn = ca.Function("jacobian", [xs, us], [ca.reshape(jac, 4, 1)]).map(prepared.n)
    J = np.asarray(fn(prepared.x, prepared.u)).reshape(2, 2, prepared.n, order="F")
    det = J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = np.stack([np.stack([J[1, 1], -J[0, 1]]), np.stack([-J[1, 0], J[0, 0]])]) / det
    return inverse, J


_SIDES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
"""design -> (model, min_share, its thrust side): the selections on one design and its detection
limits share one restated design (0.8 s of a 60 s log's diagnosis each), which lives as long as
the design does."""


def thrust_side(
    design: Design, model: StageModel, min_share: float = ERROR_SHARE, angle: float = 0.0
) -> ThrustSide | None:
    """The thrust side of ``design`` (whose constants' references ``model`` holds), or None when the
    horizontal axis does not move, the model cannot be inverted on the log, or the logged thrust
    current's error floor is less than ``min_share`` of the horizontal residual no column of the
    design explains (:func:`error_share`). ``angle``: the commutation offset its columns were built
    beside (:func:`felt_currents`).

    The felt currents are the base fit's; the restated target is
    ``J^-1 (y - X(logged) q) + J^-1 X(felt) q`` with ``q`` that fit, whose residual at ``q`` is
    the base fit's residual in amperes."""
    known = _SIDES.get(design)
    if known is not None and known[0] is model and known[1] == (min_share, angle):
        return known[2]
    side = _restated(design, model, min_share, angle)
    _SIDES[design] = (model, (min_share, angle), side)
    return side


def error_share(design: Design, model: StageModel) -> float:
    """The logged thrust current's error floor (``PreparedLogs.current_noise`` through the filter,
    times the thrust's acceleration per ampere at the logged currents) over the horizontal residual
    variance on the fitted samples of ``design`` that none of its columns explains
    (:func:`_unexplained`); 0 when the horizontal axis does not move or the currents have no error
    floor. Above 1 where the columns, made of the logged currents, absorb part of their own error.

    Against the residual left by every candidate and generic probe at once, not the base fit's: a
    large effect beside a ripple (a cable carrier, a detent, a misaligned guide) took the base
    fit's share to 0.07-0.48 and the ripple off the thrust side (noisy-rig pairs of the independent
    generator; 1.08-1.25 against the residual no column explains; bench/README, *Judged on the
    thrust current*)."""
    prep = design.prepared
    if not prep.moving[THRUST] or not np.any(prep.current_noise > 0):
        return 0.0
    _, J = _inverse_jacobian(model, prep)
    fitted = design.fit
    floor = prep.current_noise[0] * float(np.sum(prep.kernel**2)) * np.mean(J[THRUST, 0, fitted] ** 2)
    return float(floor / max(_unexplained(design), 1e-300))


def _unexplained(design: Design) -> float:
    """The mean square of the horizontal residual on the fitted samples of the ordinary
    least-squares fit of all of ``design``'s columns at once, accumulated a chunk at a time (no copy
    of the columns)."""
    fitted = np.flatnonzero(design.fit)
    columns, target = design.columns[:, THRUST], design.target[THRUST]
    P = columns.shape[0]
    gram, rhs = np.zeros((P, P)), np.zeros(P)
    chunks = [fitted[k : k + _CHUNK] for k in range(0, fitted.size, _CHUNK)]
    for idx in chunks:
        x = columns[:, idx]
        gram += x @ x.T
        rhs += x @ target[idx]
    coef = np.linalg.lstsq(gram, rhs, rcond=None)[0]
    ss = sum(float(np.sum((target[idx] - coef @ columns[:, idx]) ** 2)) for idx in chunks)
    return ss / max(fitted.size, 1)


_CHUNK = 5_000
"""Samples turned into amperes (:func:`_in_amperes`) or accumulated (:func:`_unexplained`) at a time."""


def _in_amperes(rows: np.ndarray, inverse: np.ndarray) -> np.ndarray:
    """``rows`` (..., 2 axes, n), accelerations, overwritten with ``inverse`` (2 currents, 2 axes, n)
    times them, in the rows of the axes the currents drive: row 0 (vertical) i_d, row 1
    (horizontal) i_q. Returns ``rows``."""
    for start in range(0, rows.shape[-1], _CHUNK):
        s = slice(start, start + _CHUNK)
        vertical, horizontal = rows[..., 0, s].copy(), rows[..., 1, s].copy()
        rows[..., 0, s] = inverse[1, 0, s] * vertical + inverse[1, 1, s] * horizontal  # i_d
        rows[..., 1, s] = inverse[0, 0, s] * vertical + inverse[0, 1, s] * horizontal  # i_q
    return rows


def _restated(design: Design, model: StageModel, min_share: float, angle: float) -> ThrustSide | None:
    if error_share(design, model) < min_share:
        return None
    prep = design.prepared
    felt = felt_currents(prep, model, angle=angle)
    if felt is None:
        return None
    base = fit_subset(design, ["base"], covariance=False)
    residual = design.target - np.tensordot(base.coef, design.columns[base.index], axes=1)
    inverse, J = _inverse_jacobian(model, felt)
    estimated = tuple(design.names[i] for i in design.groups["base"])
    columns = build_design(
        felt,
        model,
        estimate=estimated,
        terms=design.terms,
        fit=design.fit,
        holdout=design.holdout,
        at=design.at,
        weights=design.weights,
    ).columns  # its own copy, turned into amperes in place, a chunk at a time: the peak memory is
    # the two designs (a 5-minute log's is about 0.5 GB each), not three
    _in_amperes(columns, inverse)
    target = _in_amperes(residual.copy(), inverse) + np.tensordot(base.coef, columns[base.index], axes=1)
    bad = ~(np.all(np.isfinite(target), axis=0) & np.all(np.isfinite(columns), axis=(0, 1)))
    if np.any(bad & (design.fit | design.holdout)):
        return None
    columns[:, :, bad], target[:, bad] = 0.0, 0.0  # samples neither fitted nor held out
    left = target - np.tensordot(base.coef, columns[base.index], axes=1)
    rms = np.sqrt(np.mean(left[:, design.fit] ** 2, axis=1))
    weights = np.where(rms > 0, 1.0 / np.maximum(rms, 1e-300), 0.0)
    return ThrustSide(restated(design, columns, target, weights), J[THRUST, 0, design.holdout])
