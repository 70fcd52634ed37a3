"""What a found effect is worth in control: the FL regulator with the effect compensated.

The identified effects become (a) an extra acceleration in a twin of the identified plant
(unless the real twin that produced the log is given) and (b) a compensation term in the FL
regulator's transformation (``FeedbackLinearizingRegulator(compensation=...)``). Effects that
depend on the currents or their rates (thrust ripple, commutation offset, current lag) stay in
the plant but are not compensated: the transformation would have to be solved with them.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.diagnosis.candidate import Candidate
from maglev_oc.diagnosis.pipeline import Diagnosis, Effect
from maglev_oc.model.parameters import LumpedConstants
from maglev_oc.model.stage import StageModel
from maglev_oc.sim.effects import Encoder, TwinEffects
from maglev_oc.sim.engine import ClosedLoop, SimulationResult
from maglev_oc.sim.metrics import RunMetrics, evaluate
from maglev_oc.sim.scenarios import Scenario, paper_scenarios
from maglev_oc.sim.twin import RigTwin

__all__ = ["CompensationStudy", "compensation_study", "improvement"]


def _compensable_coefficients(cand: Candidate, coefficients: np.ndarray) -> np.ndarray:
    """A chosen effect's coefficients with its nuisance ones (a friction's share held while sticking)
    set to zero: what a controller can feed forward."""
    names = cand.term.parameter_names
    return np.array([0.0 if q in cand.nuisance else c for q, c in zip(names, coefficients, strict=True)])


def _state_only(effect: Effect) -> bool:
    """Whether an effect's compensable part (with its parts') depends on the state alone (not on the
    currents or their rates)."""
    x, u, du = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("du", 2)
    for cand, coef in effect.terms():
        out = cand.term.acceleration(_compensable_coefficients(cand, coef))(x, u, du)
        if ca.depends_on(out, u) or ca.depends_on(out, du):
            return False
    return True


def _effects_acceleration(effects: list[Effect], *, with_inputs: bool) -> ca.Function:
    """Sum of the effects' accelerations: (x) -> acc (their compensable parts), or (x, i) -> acc
    with ``with_inputs`` (the whole effects, current rates taken as zero: a twin of the plant)."""
    x, u = ca.SX.sym("x", 4), ca.SX.sym("u", 2)
    acc = ca.SX.zeros(2, 1)
    # a drift over the logs (the magnets warming) is no part of the plant at any one time: the
    # constants fitted beside it are the logs' mean
    for cand, coefficients in (t for e in effects for t in e.terms() if not t[0].term.in_time):
        coef = coefficients if with_inputs else _compensable_coefficients(cand, coefficients)
        acc += cand.term.acceleration(coef)(x, u, ca.SX.zeros(2, 1))
    if with_inputs:
        return ca.Function("effects", [x, u], [acc], ["x", "i"], ["acc"])
    return ca.Function("effects", [x], [acc], ["x"], ["acc"])


def _constants(d: dict) -> LumpedConstants:
    return LumpedConstants(*(d[k].value for k in ("C1", "C2", "C3", "C4")), source="diagnose")


@dataclass(frozen=True)
class CompensationStudy:
    scenario: str
    plant: str  # what the controllers were run on
    compensated: tuple[str, ...]
    not_compensated: tuple[str, ...]
    before: RunMetrics
    after: RunMetrics
    result_before: SimulationResult
    result_after: SimulationResult


def compensation_study(
    diagnosis: Diagnosis,
    model: StageModel,
    *,
    twin: RigTwin | None = None,
    scenario: Scenario | None = None,
) -> CompensationStudy:
    """FL regulator on ``scenario`` (default: the papers' ellipse) before (base model fitted to
    the log, nothing compensated) and after (constants refitted with the effects, the state
    effects compensated). ``twin``: the plant; default a twin of the identified plant (fitted
    constants and every found effect, 10 um encoders)."""
    scenario = paper_scenarios()["sinusoid"] if scenario is None else scenario
    fx = [e for e in diagnosis.effects if _state_only(e)]
    fu = [e for e in diagnosis.effects if not _state_only(e)]
    if twin is None:
        plant = model.with_constants(_constants(diagnosis.constants_final))
        extra = _effects_acceleration(diagnosis.effects, with_inputs=True) if diagnosis.effects else None
        twin = RigTwin(plant, TwinEffects(encoder=Encoder(), extra=extra))
        plant_name = "twin of the identified plant (refitted constants + the found effects)"
    else:
        plant_name = "the rig twin that recorded the log"
    base = FeedbackLinearizingRegulator(
        model.with_constants(_constants(diagnosis.constants_base)), name="FL, base model fitted"
    )
    comp = _effects_acceleration(fx, with_inputs=False) if fx else None
    after = FeedbackLinearizingRegulator(
        model.with_constants(_constants(diagnosis.constants_final)),
        compensation=comp,
        name="FL, effects compensated",
    )
    rb = ClosedLoop(twin, base).run(scenario)
    ra = ClosedLoop(twin, after).run(scenario)
    return CompensationStudy(
        scenario.name,
        plant_name,
        tuple(e.name for e in fx),
        tuple(e.name for e in fu),
        evaluate(rb, scenario),
        evaluate(ra, scenario),
        rb,
        ra,
    )


def improvement(study: CompensationStudy) -> np.ndarray:
    """Ratio of mean tracking errors before / after per axis (vertical, horizontal)."""
    return np.asarray(study.before.mean_error) / np.maximum(np.asarray(study.after.mean_error), 1e-12)
