"""maglev_oc: model, identify, control and analyse the Quanser maglev positioning stage.

The everyday names are importable from here, in the manner of python-control::

    import maglev_oc as mo

    model = mo.StageModel()                         # Table I, Table III at eps = 0.01
    op = mo.equilibrium(model, 0.020)               # u = (0, 1.497) A at a 20 mm gap
    lin = mo.linearize(model, op.x, op.u)           # exact A, B from CasADi
    loop = mo.ClosedLoop(mo.RigTwin(model, mo.TwinEffects.rig()), mo.FeedbackLinearizingRegulator(model))
    run = loop.run(mo.paper_scenarios()["sinusoid"])

Groups (each subpackage documents its modules):

* model — :class:`StageModel`, :class:`StageParameters`, :class:`LumpedConstants`,
  :func:`paper_constants`, :func:`load_model`, :func:`equilibrium`, :func:`equilibrium_currents`,
  :func:`linearize`, :func:`open_loop_poles`, :class:`FeedbackTransformation`;
* control — :class:`FeedbackLinearizingRegulator`, :func:`paper_linear_regulator`,
  :func:`lqr_regulator`, :func:`paper_pid`, :class:`NonlinearMPC`, :func:`build_controller`;
* simulation — :class:`RigTwin`, :class:`TwinEffects`, :class:`ClosedLoop`, :func:`simulate`,
  :func:`paper_scenarios`, :func:`excitation_scenario`, :func:`evaluate`, :func:`run_comparison`,
  :func:`result_to_log`;
* data — :class:`Log`, :func:`read_log`, :func:`write_log`, :func:`check_excitation`;
* identification — :func:`identify`, :func:`fit_equation_error`, :func:`fit_output_error`,
  :func:`npfsi`; diagnosis — :func:`diagnose`;
* operating region — :func:`operating_region_study`, :class:`FeasibleSet`, :class:`Procedure2`;
* results and errors — :class:`Estimate`, :class:`PerAxis`, ``AXES``; :class:`MaglevError`,
  :class:`InputError`, :class:`LogError`, :class:`ParameterError`, :class:`SolverError`.

Everything but the results and errors is loaded on first use (CasADi and the solvers are heavy).
"""

from __future__ import annotations

import importlib

from maglev_oc.errors import InputError, LogError, MaglevError, ParameterError, SolverError
from maglev_oc.results import AXES, Estimate, PerAxis

__version__ = "0.1.0"

_LAZY = {
    # model
    "StageModel": "maglev_oc.model.stage",
    "StageParameters": "maglev_oc.model.parameters",
    "LumpedConstants": "maglev_oc.model.parameters",
    "DEFAULT_CONSTANTS": "maglev_oc.model.parameters",
    "PAPER_CONSTANTS": "maglev_oc.model.parameters",
    "paper_constants": "maglev_oc.model.parameters",
    "load_model": "maglev_oc.model.loading",
    "equilibrium": "maglev_oc.model.equilibrium",
    "equilibrium_currents": "maglev_oc.model.equilibrium",
    "linearize": "maglev_oc.model.linearization",
    "open_loop_poles": "maglev_oc.model.linearization",
    "FeedbackTransformation": "maglev_oc.model.feedback",
    # control
    "FeedbackLinearizingRegulator": "maglev_oc.control.fl_regulator",
    "paper_linear_regulator": "maglev_oc.control.linear_regulator",
    "lqr_regulator": "maglev_oc.control.lqr",
    "paper_pid": "maglev_oc.control.pid",
    "NonlinearMPC": "maglev_oc.control.nmpc",
    "build_controller": "maglev_oc.control.registry",
    # simulation
    "RigTwin": "maglev_oc.sim.twin",
    "TwinEffects": "maglev_oc.sim.effects",
    "ClosedLoop": "maglev_oc.sim.engine",
    "simulate": "maglev_oc.sim.engine",
    "paper_scenarios": "maglev_oc.sim.scenarios",
    "excitation_scenario": "maglev_oc.sim.scenarios",
    "evaluate": "maglev_oc.sim.metrics",
    "run_comparison": "maglev_oc.sim.comparison",
    "result_to_log": "maglev_oc.sim.recording",
    # data
    "Log": "maglev_oc.data.log",
    "read_log": "maglev_oc.data.reading",
    "write_log": "maglev_oc.data.writing",
    "check_excitation": "maglev_oc.data.excitation",
    # identification and diagnosis
    "identify": "maglev_oc.identification.pipeline",
    "fit_equation_error": "maglev_oc.identification.equation_error",
    "fit_output_error": "maglev_oc.identification.output_error",
    "npfsi": "maglev_oc.identification.npfsi",
    "diagnose": "maglev_oc.diagnosis.pipeline",
    # operating region
    "operating_region_study": "maglev_oc.region.study",
    "FeasibleSet": "maglev_oc.region.feasibility",
    "Procedure2": "maglev_oc.region.procedure2",
}

__all__ = [
    "AXES",
    "DEFAULT_CONSTANTS",
    "PAPER_CONSTANTS",
    "ClosedLoop",
    "Estimate",
    "FeasibleSet",
    "FeedbackLinearizingRegulator",
    "FeedbackTransformation",
    "InputError",
    "Log",
    "LogError",
    "LumpedConstants",
    "MaglevError",
    "NonlinearMPC",
    "ParameterError",
    "PerAxis",
    "Procedure2",
    "RigTwin",
    "SolverError",
    "StageModel",
    "StageParameters",
    "TwinEffects",
    "build_controller",
    "check_excitation",
    "diagnose",
    "equilibrium",
    "equilibrium_currents",
    "evaluate",
    "excitation_scenario",
    "fit_equation_error",
    "fit_output_error",
    "identify",
    "linearize",
    "load_model",
    "lqr_regulator",
    "npfsi",
    "open_loop_poles",
    "operating_region_study",
    "paper_constants",
    "paper_linear_regulator",
    "paper_pid",
    "paper_scenarios",
    "read_log",
    "result_to_log",
    "run_comparison",
    "simulate",
    "write_log",
]


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # loaded once
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
