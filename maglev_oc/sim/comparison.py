"""Every controller on every scenario on each twin: the controller comparison of issue 3.

The "rig" twin has every effect of :meth:`TwinEffects.rig` and true constants that differ from
the controllers' (Table III of 000 at eps = 0.001 while the controllers use eps = 0.01: the
papers' own spread between estimates), so no controller sees its own model.

A twin and a controller are joined once (:class:`LoopCache`) and every run of that pair reuses
the loop; with ``backend="c"`` each pair's closed loop is compiled once (a fraction of a second)
and its runs then cost microseconds a sample.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.model.parameters import PAPER_CONSTANTS
from maglev_oc.model.stage import StageModel
from maglev_oc.results import Result
from maglev_oc.sim.effects import TwinEffects
from maglev_oc.sim.engine import ClosedLoop, SimulationResult
from maglev_oc.sim.metrics import RunMetrics, evaluate
from maglev_oc.sim.scenarios import Scenario, SetpointSequence
from maglev_oc.sim.twin import RigTwin

__all__ = [
    "RIG_CONSTANTS",
    "Comparison",
    "LoopCache",
    "StepSweep",
    "run_comparison",
    "standard_twins",
    "step_sweep",
]

RIG_CONSTANTS = "table3_eps0.001"
"""The rig twin's true constants (the controllers use the model's, Table III at eps = 0.01)."""


def standard_twins(model: StageModel) -> dict[str, RigTwin]:
    """The two twins of the comparison.

    Parameters
    ----------
    model : StageModel
        The controllers' model.

    Returns
    -------
    dict of str to RigTwin
        ``ideal``: the controllers' own model, no effects. ``rig``: every effect on, and true
        constants :data:`RIG_CONSTANTS`.
    """
    return {
        "ideal": RigTwin(model, TwinEffects.ideal()),
        "rig": RigTwin(model.with_constants(PAPER_CONSTANTS[RIG_CONSTANTS]), TwinEffects.rig()),
    }


class LoopCache:
    """Closed loops by (twin, controller), each joined once and reused by every run of the pair.

    Parameters
    ----------
    backend : {"vm", "jit", "c"}
        The backend of every loop (:class:`~maglev_oc.sim.engine.ClosedLoop`); with "c" a pair's
        loop is compiled on its first run.
    """

    def __init__(self, backend: str = "vm") -> None:
        if backend not in ClosedLoop.BACKENDS:
            raise InputError(f"backend must be one of {ClosedLoop.BACKENDS}, got {backend!r}")
        self.backend = backend
        self._loops: dict[tuple[int, int], tuple[RigTwin, object, ClosedLoop]] = {}

    def loop(self, twin: RigTwin, controller) -> ClosedLoop:
        """The loop of ``controller`` on ``twin`` (built on the first call)."""
        key = (id(twin), id(controller))
        if key not in self._loops:  # the twin and controller are kept, so their ids stay theirs
            self._loops[key] = (twin, controller, ClosedLoop(twin, controller, backend=self.backend))
        return self._loops[key][2]

    def __len__(self) -> int:
        return len(self._loops)


@dataclass(frozen=True)
class Comparison(Result):
    """Runs and metrics keyed by (controller name, scenario name, twin name).

    ``success`` is True when every run stayed stable (``status`` ``"all_stable"``, else
    ``"some_unstable"``, and the ``message`` names the runs that were not); the papers expect some
    failures (the linear regulator on the large step), so a False here is a finding, not an error.
    """

    success: bool
    status: str
    message: str
    controllers: tuple[str, ...]
    scenarios: dict[str, Scenario] = field(repr=False)
    twins: tuple[str, ...]
    results: dict[tuple[str, str, str], SimulationResult] = field(repr=False)
    metrics: dict[tuple[str, str, str], RunMetrics]
    timings: Mapping[str, float] = field(default_factory=dict)  # [s] {"total": ...}

    def metric(self, controller: str, scenario: str, twin: str) -> RunMetrics:
        """The metrics of one run."""
        return self.metrics[(controller, scenario, twin)]


def run_comparison(
    controllers: Sequence[object],
    scenarios: Mapping[str, Scenario],
    twins: Mapping[str, RigTwin],
    *,
    seed: int = 0,
    backend: str = "vm",
    loops: LoopCache | None = None,
) -> Comparison:
    """Simulate each controller on each scenario on each twin (one ClosedLoop per pair).

    Parameters
    ----------
    controllers : sequence of controllers
        Expression or online controllers (:mod:`maglev_oc.control.base`).
    scenarios : mapping of str to Scenario
        The runs, by name.
    twins : mapping of str to RigTwin
        The plants, by name (e.g. :func:`standard_twins`).
    seed : int
        Encoder-noise seed of every run.
    backend : {"vm", "jit", "c"}
        Backend of the loops (when ``loops`` is not given).
    loops : LoopCache, optional
        Loops to reuse (and to add to), e.g. shared with :func:`step_sweep`.

    Returns
    -------
    Comparison
    """
    t0 = time.perf_counter()
    loops = loops if loops is not None else LoopCache(backend)
    results, metrics = {}, {}
    for twin_name, twin in twins.items():
        for ctrl in controllers:
            loop = loops.loop(twin, ctrl)
            for sc_name, sc in scenarios.items():
                res = loop.run(sc, seed=seed)
                key = (ctrl.name, sc_name, twin_name)
                results[key] = res
                metrics[key] = evaluate(res, sc)
    unstable = [" / ".join(key) for key, res in results.items() if not res.success]
    message = f"{len(results) - len(unstable)} of {len(results)} runs stable"
    if unstable:
        message += "; unstable: " + ", ".join(unstable)
    return Comparison(
        success=not unstable,
        status="some_unstable" if unstable else "all_stable",
        message=message,
        controllers=tuple(c.name for c in controllers),
        scenarios=dict(scenarios),
        twins=tuple(twins),
        results=results,
        metrics=metrics,
        timings={"total": time.perf_counter() - t0},
    )


@dataclass(frozen=True)
class StepSweep:
    """Outcome of steps from one start to a range of target gaps, per controller.

    A table of outcomes rather than one result: ``success`` is the (n_controllers, n_targets)
    array of which steps settled (the name the reports read).
    """

    start: tuple[float, float, float, float]
    target_gaps: np.ndarray  # [m]
    target_position: float  # [m]
    controllers: tuple[str, ...]
    success: np.ndarray  # (n_controllers, n_targets) bool
    min_gap: np.ndarray  # (n_controllers, n_targets) [m] smallest gap reached
    peak_current: np.ndarray  # (n_controllers, n_targets) [A]


def step_sweep(
    controllers: Sequence[object],
    twin: RigTwin,
    target_gaps,
    *,
    start=(0.026, 0.0, 0.0, 0.0),
    target_position: float = 0.020,
    duration: float = 5.0,
    backend: str = "vm",
    loops: LoopCache | None = None,
) -> StepSweep:
    """Steps from ``start`` to (gap, 0, ``target_position``, 0) for each target gap: where
    each controller stops coping (hits a stopper or diverges).

    Parameters
    ----------
    controllers : sequence of controllers
        Expression or online controllers.
    twin : RigTwin
        The plant.
    target_gaps : array-like (n,)
        Target gaps [m].
    start : (4,) mechanical state
        [m, m/s, m, m/s], default the papers' (0.026, 0, 0, 0).
    target_position : float
        Target horizontal position [m].
    duration : float
        Length of each run [s].
    backend : {"vm", "jit", "c"}
        Backend of the loops (when ``loops`` is not given).
    loops : LoopCache, optional
        Loops to reuse.

    Returns
    -------
    StepSweep
    """
    loops = loops if loops is not None else LoopCache(backend)
    gaps = np.asarray(target_gaps, dtype=float)
    ok = np.zeros((len(controllers), gaps.size), dtype=bool)
    gmin = np.full((len(controllers), gaps.size), np.nan)
    ipk = np.full((len(controllers), gaps.size), np.nan)
    for i, ctrl in enumerate(controllers):
        loop = loops.loop(twin, ctrl)
        for j, g in enumerate(gaps):
            sc = Scenario(
                "sweep",
                "sweep",
                tuple(start),
                SetpointSequence((0.0,), ((float(g), target_position),)),
                duration,
            )
            res = loop.run(sc)
            ok[i, j] = res.success
            gmin[i, j] = np.nanmin(res.x[0])
            ipk[i, j] = np.nanmax(np.hypot(res.u[0], res.u[1]))
    return StepSweep(tuple(start), gaps, target_position, tuple(c.name for c in controllers), ok, gmin, ipk)
