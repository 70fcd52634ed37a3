"""The diagnosis's result: the effects found, what is not separable or not explained, the
errors before and after (SPEC 3: ``Diagnosis.to_dict()`` is the JSON ``maglev-oc diagnose`` writes)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from maglev_oc.diagnosis.candidate import Candidate
from maglev_oc.diagnosis.limits import DetectionLimit
from maglev_oc.diagnosis.selection import (
    SIDE_WORDS,
    Judgement,
    Ranked,
    Selection,
    best_first,
    shared_along_the_track,
)
from maglev_oc.diagnosis.trace import Trace
from maglev_oc.diagnosis.unexplained import Unexplained
from maglev_oc.identification.masses import MassChange
from maglev_oc.regression.data import PreparedLogs
from maglev_oc.regression.payload import declared
from maglev_oc.regression.stoppers import RestingStretch
from maglev_oc.results import Estimate, PerAxis, Result, jsonable
from maglev_oc.validation import Validation

__all__ = ["ERROR_METRIC", "Diagnosis", "Effect", "NotSeparable"]

ERROR_METRIC = (
    "RMS of the acceleration equation error (measured minus model, both through the same "
    "zero-phase filter) on the held-out block at the end of each log, per axis, in m/s^2 "
    "(null for an axis that does not move in the logs)"
)


def _num(v) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


def _measured(j: Judgement, *, wald: bool = True) -> dict[str, float | None]:
    """A judgement's held-out gain, z and (with ``wald``) Wald statistic; null where its fit means
    nothing (its columns dominated by the logged currents' errors: a nearly singular fit, gains of
    -1e15 and beyond, :attr:`~maglev_oc.diagnosis.selection.Judgement.dominated_by_current_errors`)."""
    meaningless = j.dominated_by_current_errors
    out = {"holdout_gain": None if meaningless else _num(j.gain), "z": None if meaningless else _num(j.z)}
    if wald:
        out["wald"] = None if meaningless else _num(j.wald)
    return out


@dataclass(frozen=True)
class Effect:
    """A selected effect with its physical parameters (value, standard error, unit)."""

    name: str
    explanation: str
    finding: str  # what was found, in one sentence with the sizes
    axis: str
    parameters: dict[str, Estimate]
    confidence: float  # bootstrap share choosing it at its step
    gain: float  # relative drop of the held-out error on its axes when it was added
    z: float  # its significance: the held-out quarter and the cross-fitted training parts pooled
    contribution_rms: PerAxis  # held-out RMS of its acceleration per axis [m/s^2]
    force_rms: PerAxis  # the same in N
    runner_up: str
    signature: str
    coefficients: np.ndarray
    candidate: Candidate = field(repr=False)
    # what the held-out test predicted: "accelerations", or the logged thrust current where the
    # accelerations could not show an effect of it (:mod:`~maglev_oc.diagnosis.thrust_current`)
    judged_on: str = "accelerations"
    # chosen effects reported as part of this one (a guide's waviness in its misalignment): their
    # terms are in the fitted model all the same
    parts: tuple[tuple[Candidate, np.ndarray], ...] = field(default=(), repr=False)

    def terms(self) -> tuple[tuple[Candidate, np.ndarray], ...]:
        """(candidate, coefficients) of every chosen effect this one reports: itself and its parts."""
        return ((self.candidate, self.coefficients), *self.parts)


@dataclass(frozen=True)
class NotSeparable:
    """A candidate that is real in the fit but confounded on this log."""

    name: str
    confounded_with: tuple[str, ...]
    experiment: str
    gain: float
    reason: str
    parameters: dict[str, Estimate]

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "confounded_with": list(self.confounded_with),
            "experiment": self.experiment,
            "holdout_gain": _num(self.gain),
            "reason": self.reason,
            "parameters_if_it_were_separable": {k: v.to_dict() for k, v in self.parameters.items()},
        }


def _after_carries(not_separable: Sequence[NotSeparable]) -> str:
    """What ``error_after`` holds beside the effects, said in the error metric: the force along the
    track of a pair not separable from each other (``pipeline._shared_terms``), which the refitted
    constants carry too."""
    pairs = [f"{one} or {both}" for one, both in shared_along_the_track(not_separable)]
    if not pairs:
        return ""
    return (
        "; after: with the effects and the force along the track of "
        + " and ".join(pairs)
        + " (listed in not_separable: the log does not tell which)"
    )


@dataclass(frozen=True)
class Diagnosis(Result):
    """What :func:`diagnose` found (``to_dict()``: the SPEC 3 contract plus details)."""

    success: bool
    status: str  # "effects_found", "nothing_found" or "unexplained_only"
    message: str
    sources: tuple[str, ...]
    constants_base: dict[str, Estimate]  # base model alone
    # refitted with the effects (and the force along the track of a pair not separable from each
    # other, pipeline._with_shared_force)
    constants_final: dict[str, Estimate]
    effects: list[Effect]
    not_separable: list[NotSeparable]
    rejected: list[Judgement]
    unexplained: list[Unexplained]
    error_before: PerAxis  # [m/s^2] held-out RMS of the equation error, base model
    error_after: PerAxis  # [m/s^2] with the effects
    output_error_before: PerAxis  # [m] RMS over 50 ms simulations, held out
    output_error_after: PerAxis
    selection: Selection
    trace: Trace
    residual_before: np.ndarray  # (2, n) [m/s^2]
    residual_after: np.ndarray
    data: PreparedLogs = field(repr=False)
    train: np.ndarray = field(repr=False)
    holdout: np.ndarray = field(repr=False)
    settings: dict = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    validation_before: Validation | None = None  # the base model on the held-out block
    validation_after: Validation | None = None  # the model with the effects
    # the effects the log did not show, and the size below which it could not
    detection_limits: list[DetectionLimit] = field(default_factory=list)
    # constants refitted beside the effects that no rig of this design has (pipeline.constant_warnings)
    warnings: tuple[str, ...] = ()
    # the constants moved together as movers heavier than the model's move them (identification.masses)
    moving_mass: MassChange | None = None

    @property
    def limits_worked_out(self) -> bool:
        """Whether the detection limits were worked out (``diagnose(limits=...)``): an empty
        ``detection_limits`` then means the log showed every effect it judged, not that none was
        looked for."""
        return bool(self.settings.get("detection_limits", True))

    @property
    def left_out(self) -> tuple[RestingStretch, ...]:
        """Where a log's platform rests on its stopper, left out of every fit
        (:mod:`~maglev_oc.regression.stoppers`; none without prepared data)."""
        return () if self.data is None else self.data.resting

    @property
    def payloads(self) -> tuple[str, ...]:
        """One sentence per log that declares a payload (``# payload_kg``): its forces were read as the
        unloaded stage's (:mod:`~maglev_oc.regression.payload`)."""
        masses = self.settings.get("payload_kg")
        return declared(self.sources, masses) if masses else ()

    @property
    def ranking(self) -> list[Ranked]:
        return self.selection.ranking

    def to_dict(self) -> dict:
        """The SPEC 3 contract, plus details (all plain JSON types)."""

        def phys(d: dict[str, Estimate]) -> dict:
            return {k: _num(v.value) for k, v in d.items()}

        def phys_full(d: dict[str, Estimate]) -> dict:
            return {k: v.to_dict() for k, v in d.items()}

        return {
            "effects": [
                {
                    "name": e.name,
                    "explanation": e.explanation,
                    "finding": e.finding,
                    "axis": e.axis,
                    "parameters": phys(e.parameters),
                    "parameter_details": phys_full(e.parameters),
                    "confidence": _num(e.confidence),
                    "holdout_gain": _num(e.gain),
                    "z": _num(e.z),
                    "judged_on": e.judged_on,
                    "contribution_rms": e.contribution_rms.to_dict(),
                    "force_rms_N": e.force_rms.to_dict(),
                    "runner_up": e.runner_up,
                    "evidence": e.signature,
                    # the hyper-parameters the model-form spread in the standard errors ranges over
                    "model_form_variants": e.candidate.term.variant_note,
                }
                for e in self.effects
            ],
            "not_separable": [n.to_dict() for n in self.not_separable],
            "unexplained": [u.to_dict() for u in self.unexplained],
            "error_before": self.error_before.to_dict(),
            "error_after": self.error_after.to_dict(),
            "error_metric": ERROR_METRIC + _after_carries(self.not_separable),
            "output_error_before": self.output_error_before.to_dict(),
            "output_error_after": self.output_error_after.to_dict(),
            "output_error_metric": "RMS position error of the model simulated over 50 ms windows "
            "from the estimated state with the logged currents, held-out "
            "block, per axis, in m",
            "validation": {
                "before": None if self.validation_before is None else self.validation_before.to_dict(),
                "after": None if self.validation_after is None else self.validation_after.to_dict(),
            },
            "constants_base": phys_full(self.constants_base),
            "constants_final": phys_full(self.constants_final),
            "rejected": [
                {
                    "name": j.name,
                    "verdict": j.verdict,
                    "reason": j.reason,
                    **_measured(j, wald=False),
                    "judged_on": j.side or "accelerations",
                }
                for j in self.rejected
            ],
            "detection_limits": [d.to_dict() for d in self.detection_limits],
            "candidate_ranking": [
                {"name": r.name, "holdout_gain": _num(r.gain), "verdict": r.verdict} for r in self.ranking
            ],
            "selection_steps": [
                {
                    "chosen": s.chosen,
                    "confidence": _num(s.confidence),
                    "candidates": [
                        {
                            "name": j.name,
                            "verdict": j.verdict,
                            **_measured(j),
                            "vif": _num(j.vif),
                            "judged_on": j.side or "accelerations",
                        }
                        for j in sorted(s.judgements.values(), key=best_first)
                    ],
                }
                for s in self.selection.steps
            ],
            "logs": list(self.sources),
            "left_out": [r.to_dict() for r in self.left_out],
            "holdout": {
                "fraction": self.settings.get("holdout_fraction"),
                "samples": int(self.holdout.sum()),
                "fit_samples": int(self.train.sum()),
            },
            "settings": jsonable(self.settings),
            "success": self.success,
            "status": self.status,
            "message": self.message,
            "warnings": list(self.warnings),
            "moving_mass": None if self.moving_mass is None else self.moving_mass.to_dict(),
            "timings": {k: _num(v) for k, v in self.timings.items()},
        }

    def report(self) -> str:
        """What was found, in plain words (the first page of the PDF report as text)."""
        lines = [f"Diagnosis ({self.status}): {self.message}"]
        lines += [f"  WARNING: {w}" for w in self.warnings]
        lines += [f"  moving mass: {self.moving_mass.says()}"] if self.moving_mass is not None else []
        lines += [f"  left out: {r.describe()}" for r in self.left_out]
        lines += [f"  payload: {w}" for w in self.payloads]
        for e in self.effects:
            seen = "" if e.judged_on == "accelerations" else f"; seen predicting {SIDE_WORDS[e.judged_on]}"
            lines.append(f"  {e.name} [{e.axis}, confidence {e.confidence:.2f}{seen}]: {e.finding}")
        for n in self.not_separable:
            lines.append(
                f"  not separable: {n.name} (confounded with {', '.join(n.confounded_with)}): {n.experiment}"
            )
        for u in self.unexplained:
            lines.append(f"  unexplained: {u.description}")
        for j in self.rejected:
            lines.append(f"  not claimed: {j.name} ({j.verdict}): {j.reason}")
        for d in self.detection_limits:
            size = f"{d.value:.3g} {d.unit}" if math.isfinite(d.value) else d.reason
            side = f" (predicting {SIDE_WORDS[d.side]})" if d.side and math.isfinite(d.value) else ""
            lines.append(
                f"  not seen: {d.name} ({d.parameter}) — smallest size this log would show: {size}{side}"
            )
        for a, before in self.error_before.items():
            if math.isfinite(before):
                lines.append(f"  held-out error {a}: {before:.4g} -> {self.error_after[a]:.4g} m/s^2")
        return "\n".join(lines)
