"""The rig twin and closed-loop simulation.

* :mod:`~maglev_oc.sim.effects` — the rig's effects the papers' model leaves out (:class:`TwinEffects`).
* :mod:`~maglev_oc.sim.twin` — the sampled plant with those effects (:class:`RigTwin`).
* :mod:`~maglev_oc.sim.scenarios` — references and the papers' test scenarios (:func:`paper_scenarios`).
* :mod:`~maglev_oc.sim.engine` — a controller on the twin (:class:`ClosedLoop`, :class:`SimulationResult`);
  :mod:`~maglev_oc.sim.native` its C backend.
* :mod:`~maglev_oc.sim.metrics` — the papers' figures of a run (:func:`evaluate`, :class:`RunMetrics`).
* :mod:`~maglev_oc.sim.comparison` — every controller on every scenario and twin (:func:`run_comparison`).
* :mod:`~maglev_oc.sim.recording` — a run as the log the rig would record (:func:`result_to_log`).
"""

from maglev_oc.sim.comparison import Comparison, run_comparison, standard_twins
from maglev_oc.sim.effects import TwinEffects
from maglev_oc.sim.engine import ClosedLoop, SimulationResult, simulate
from maglev_oc.sim.metrics import RunMetrics, evaluate
from maglev_oc.sim.recording import result_to_log
from maglev_oc.sim.scenarios import (
    Scenario,
    SetpointSequence,
    Sinusoids,
    excitation_scenario,
    paper_scenarios,
)
from maglev_oc.sim.twin import RigTwin

__all__ = [
    "ClosedLoop",
    "Comparison",
    "RigTwin",
    "RunMetrics",
    "Scenario",
    "SetpointSequence",
    "SimulationResult",
    "Sinusoids",
    "TwinEffects",
    "evaluate",
    "excitation_scenario",
    "paper_scenarios",
    "result_to_log",
    "run_comparison",
    "simulate",
    "standard_twins",
]
