"""Logs that break the model's conventions, named before anything is fitted or claimed.

The model reads u1 as i_q and u2 as i_d (SPEC 2), and its signs are fixed (SPEC 1): a positive
i_q accelerates the platform toward negative x3 (x4' = -L1 u1, L1 > 0), and a positive i_d
weakens the magnets' pull and opens the gap (x2' = ... - L3 u2, L3 < 0). A log recorded with
another convention passes every check of the file, and its fits then say the wrong thing: on a
30 s log of the independent generator with 1 N of horizontal guide friction (bench/README l),

- x3 counted the other way: the friction was found beside C1 = -13.5 and a warning that
  "something the model still lacks takes the place" of the thrust constant; identify stopped on
  "LumpedConstants.C1: must be positive";
- u1 and u2 exchanged: a cable carrier was claimed (falsely) beside C1 = 0.0024 and C3 = -6.2;
- u2 with the other sign: C3 = -32.1, and the same misleading warning.

Each slip shows in C1..C4 fitted alone by equation error (:func:`convention_slips`), log by log:

- **A sign.** C1 or C3 below zero by more than :data:`SLIP_SIGMAS` standard errors (the long-run
  covariance). Friction and springs that the base model lacks bias C1 toward zero (0.68 for
  14.8 on the log above) but not across it: the thrust current carries whatever the motor pushes,
  so its correlation with the acceleration keeps the motor's sign. x3 counted the other way and
  u1 with the other sign are the same slip to C1..C4, whose forces do not depend on x3.
- **Exchanged currents.** C1..C4 fitted with u1 and u2 exchanged explain one moving axis's
  acceleration more than :data:`SWAP_FACTOR` times closer (RMS) than as logged, with C3 positive.
  The current that drives an axis explains its acceleration at least as well as the other one
  does (the fit can always give the wrong current a coefficient of zero), so on a log as it should
  be the exchanged fit is never much closer on either axis: near equilibrium i_d carries the
  weight and i_q is a tenth of an ampere or less. As logged / exchanged, the gap's acceleration
  0.018 / 0.41 m/s^2 on the log above, 0.041 / 0.59 on ``../shared/logs/independent_clean.csv``.
  Both axes are judged because large friction on one makes that axis's fit poor either way
  (vertical guide friction: 0.975 of the exchanged fit's RMS on a log as it should be). Where
  friction on both axes leaves the two fits within that factor, C4 tells: the pull of the currents'
  own field makes it positive, while with i_d in u1 the fit reads the levitating current's effect
  through its square and C4 comes out negative. As logged, C4 below zero by more than
  :data:`SLIP_SIGMAS` standard errors (and not so with the columns exchanged) reads an exchange: on
  660 logs of the independent generator, C4 alone was at least -1.8 standard errors (-0.092) as
  recorded and at most -8.9 (-0.80) exchanged (bench/README m).

Nothing is corrected silently: :func:`refuse_convention_slips` raises a
:class:`~maglev_oc.errors.LogError` naming the logs, what the fit shows and which column to change.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from maglev_oc.errors import LogError
from maglev_oc.regression.base import AXIS_INDEX, CONSTANT_NAMES, UNITS
from maglev_oc.regression.design import build_design
from maglev_oc.regression.solve import SubsetFit, fit_subset, residuals

if TYPE_CHECKING:
    from maglev_oc.model.stage import StageModel
    from maglev_oc.regression.data import PreparedLogs

__all__ = [
    "SIGNS",
    "SLIP_SIGMAS",
    "SWAP_FACTOR",
    "ConventionSlip",
    "convention_slips",
    "refuse_convention_slips",
    "sign_slip",
]

SLIP_SIGMAS = 5.0
"""A constant is read as fitted with the other sign when it is below zero by more than this many of
its standard errors: far beyond chance (the long-run covariance already allows for coloured
residuals), while the slips measured sit 15 (C1) and 3000 (C3) standard errors below zero."""
SWAP_FACTOR = 2.5
"""How many times closer (RMS of an axis's acceleration residual) C1..C4 must fit with u1 and u2
exchanged for the columns to be read as exchanged. The right current explains its axis at least as
well as the wrong one, so a log as it should be stays near or below 1 (at most 0.99 on the
independent generator's logs of bench/README m), while an exchange gives 6 to 23 on the axis whose
fit no friction swamps (2.8 beside large vertical friction)."""


@dataclass(frozen=True)
class ConventionSlip:
    """A log that breaks a convention of the model.

    Attributes
    ----------
    source : str
        The log (its file).
    what : str
        The slip, in words ("u1 and u2 look exchanged").
    evidence : str
        What the fit shows, with numbers.
    fix : str
        What to change in the log.
    """

    source: str
    what: str
    evidence: str
    fix: str

    def __str__(self) -> str:
        return f"{self.what}: {self.evidence}; {self.fix}"


_ACCELERATION = ("gap's acceleration", "acceleration along the track")
"""What each axis's residual is, by ``AXIS_INDEX``."""


def _exchanged(prepared: PreparedLogs) -> PreparedLogs:
    """The same samples with u1 and u2 (their rates and error estimates) exchanged."""
    return replace(
        prepared,
        u=prepared.u[::-1].copy(),
        du=prepared.du[::-1].copy(),
        current_noise=prepared.current_noise[::-1].copy(),
    )


def _base(prepared: PreparedLogs, model: StageModel, fit: np.ndarray) -> tuple[SubsetFit, np.ndarray]:
    """C1..C4 alone on the ``fit`` samples, and the RMS of their residual per axis [m/s^2]. The axes'
    constants are apart (C1 on one, C2..C4 on the other), so the axes' weights change neither."""
    design = build_design(prepared, model, estimate=CONSTANT_NAMES, fit=fit, weights=np.ones(2))
    sub = fit_subset(design, ["base"])
    r = residuals(design, sub)[:, design.fit]
    rms = np.sqrt(np.mean(r**2, axis=1)) if r.size else np.full(2, math.nan)
    return sub, rms


def _negative(value: float, stderr: float) -> bool:
    """Below zero by more than :data:`SLIP_SIGMAS` standard errors."""
    return math.isfinite(value) and math.isfinite(stderr) and value + SLIP_SIGMAS * stderr < 0.0


def _below_zero(sub: SubsetFit, name: str) -> bool:
    return _negative(sub.value(name), sub.stderr(name))


def _stated(sub: SubsetFit, name: str) -> str:
    return f"{name} = {sub.value(name):.4g} ± {sub.stderr(name):.2g} {UNITS[name]}"


SIGNS = {
    "C1": (
        "the thrust acts with the other sign",
        "in the model a positive i_q accelerates the platform toward negative x3 (x4' = -L1 u1, SPEC 1), "
        "in this log toward positive x3",
        "either the horizontal encoder counts the other way (negate x3, and x4 if logged) or u1 has the "
        "other sign (negate u1); C1..C4 cannot tell which, their forces do not depend on x3",
    ),
    "C3": (
        "the levitating current acts with the other sign",
        "in the model a positive i_d weakens the magnets' pull and opens the gap (x2' = ... - L3 u2 with "
        "L3 < 0, SPEC 1), in this log it closes the gap",
        "negate u2",
    ),
}
"""For each constant whose sign a convention fixes (C1 the thrust's, C3 the levitating current's):
(the slip in words, what the model says against what the log shows, the fix)."""


def sign_slip(name: str, value: float, stderr: float) -> str | None:
    """The slip a fitted ``name`` (``C1`` or ``C3``) below zero by more than :data:`SLIP_SIGMAS`
    standard errors shows, in words with its fix (for a constant fitted beside effects); None
    otherwise."""
    if name not in SIGNS or not _negative(value, stderr):
        return None
    what, physics, fix = SIGNS[name]
    return f"{what} ({physics}): the log looks recorded another way; {fix}"


def _signs(source: str, sub: SubsetFit, model: StageModel, moving: np.ndarray) -> list[ConventionSlip]:
    """The slips of sign that ``sub`` (C1..C4 alone, as the log's columns read) shows."""
    out = []
    for name, axis in (("C1", "horizontal"), ("C3", "vertical")):
        if moving[AXIS_INDEX[axis]] and _below_zero(sub, name):
            what, physics, fix = SIGNS[name]
            given = getattr(model.constants, name)
            shown = f"C1..C4 fitted alone give {_stated(sub, name)} (the model's {given:.4g} is positive): "
            out.append(ConventionSlip(source, what, shown + physics, fix))
    return out


def convention_slips(prepared: PreparedLogs, model: StageModel) -> list[ConventionSlip]:
    """The slips of convention each log of ``prepared`` shows (module doc), in the order of the logs;
    empty when there are none.

    Each log is fitted on its own valid samples (the pieces of one file together), so that one log
    recorded the other way among several is named. An axis that does not move (``prepared.moving``)
    tells nothing of its constant or of an exchange. A log whose fit the logged currents' errors
    swamp (the bias compensation not whole, ``SubsetFit.compensated``) is not read: its diagnosis
    says it failed, and why.
    """
    slips: list[ConventionSlip] = []
    exchanged = _exchanged(prepared)
    sources = list(dict.fromkeys(prepared.sources))
    for source in sources:
        pieces = [k for k, s in enumerate(prepared.sources) if s == source]
        mine = np.isin(prepared.segment, pieces) & prepared.valid
        if not np.any(mine):
            continue
        as_logged, rms = _base(prepared, model, mine)
        if not (as_logged.compensated and np.all(np.isfinite(as_logged.coef))):
            continue  # the currents' errors swamp the fit (its own diagnosis says so): nothing to read
        swapped, rms_swapped = _base(exchanged, model, mine)
        # per moving axis, how many times closer the exchanged columns fit (0 on an axis held still)
        closer = np.zeros(2)
        shown = prepared.moving & (rms_swapped > 0)
        closer[shown] = rms[shown] / rms_swapped[shown]
        axis = int(np.argmax(closer))
        by_fit = closer[axis] > SWAP_FACTOR
        by_c4 = _below_zero(as_logged, "C4") and not _below_zero(swapped, "C4")
        if (by_fit or by_c4) and swapped.compensated and swapped.value("C3") > 0.0:
            evidence = (
                f"with the two columns exchanged, C1..C4 fitted alone explain the {_ACCELERATION[axis]} "
                f"{closer[axis]:.3g} times closer (RMS {rms_swapped[axis]:.3g} against {rms[axis]:.3g} m/s^2)"
                if by_fit
                else f"as logged C1..C4 fitted alone give {_stated(as_logged, 'C4')}, where the pull of the "
                f"currents' own field makes C4 positive (the model's {model.constants.C4:.4g}): the "
                "levitating current, logged in u1, reaches the gap's fit only through its square, so C4 "
                "stands in for C3; with the columns exchanged "
                f"{_stated(swapped, 'C4')}"
            )
            slips.append(
                ConventionSlip(
                    source,
                    "u1 and u2 look exchanged",
                    f"{evidence}, with {_stated(swapped, 'C1')} and {_stated(swapped, 'C3')}; as logged "
                    f"{_stated(as_logged, 'C1')} and {_stated(as_logged, 'C3')}. The model reads u1 as i_q, "
                    "the thrust current, and u2 as i_d, the current that levitates (SPEC 2)",
                    "exchange the names of the two columns",
                )
            )
            # the signs are read from the fit with the columns as they should be
            slips.extend(_signs(source, swapped, model, prepared.moving))
            continue
        slips.extend(_signs(source, as_logged, model, prepared.moving))
    return slips


def refuse_convention_slips(prepared: PreparedLogs, model: StageModel) -> None:
    """Raise a :class:`~maglev_oc.errors.LogError` naming the logs that break the model's
    conventions (:func:`convention_slips`), each slip with its evidence and its fix."""
    slips = convention_slips(prepared, model)
    if not slips:
        return
    named = list(dict.fromkeys(s.source for s in slips))
    said = "; ".join(str(s) if len(named) == 1 else f"{s.source}: {s}" for s in slips)
    raise LogError(
        ", ".join(named),
        f"the log breaks the model's conventions, so nothing is fitted: {said}",
    )
