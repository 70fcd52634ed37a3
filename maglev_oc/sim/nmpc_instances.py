"""Problem instances of the NMPC recorded in closed loop, for the replay of the generated C.

A closed-loop run of an RTI :class:`~maglev_oc.control.nmpc.NonlinearMPC` on the twin, with
the inputs of its RTI calls recorded on the way: the instances that
:mod:`maglev_oc.control.codegen` writes for the C harness and evaluates in Python.
"""

from __future__ import annotations

import numpy as np

from maglev_oc.control.codegen import RecordedInstances, instance_row
from maglev_oc.control.nmpc import NonlinearMPC
from maglev_oc.errors import InputError
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.scenarios import Scenario
from maglev_oc.sim.twin import RigTwin

__all__ = ["record_instances"]


class _Recorder:
    """An OnlineController that forwards to an RTI NonlinearMPC and records its step inputs."""

    def __init__(self, controller: NonlinearMPC, every: int, limit: int) -> None:
        self.controller = controller
        self.name = controller.name
        self.sample_time = controller.sample_time
        self.diag_names = controller.diag_names
        self.every = every
        self.limit = limit
        self.rows: list[np.ndarray] = []

    def reset(self, y0, r0, u0) -> None:
        self.controller.reset(y0, r0, u0)

    def control(self, k, y, reference):
        if k % self.every == 0 and len(self.rows) < self.limit:
            self.rows.append(instance_row(self.controller, k, y, reference))
        return self.controller.control(k, y, reference)


def record_instances(
    controller: NonlinearMPC,
    twin: RigTwin,
    scenario: Scenario,
    *,
    every: int = 1,
    limit: int = 100_000,
    seed: int = 0,
) -> RecordedInstances:
    """Run ``scenario`` in closed loop and record the inputs of every ``every``-th RTI call.

    Parameters
    ----------
    controller : NonlinearMPC
        In mode "rti".
    twin : RigTwin
        The plant.
    scenario : Scenario
    every : int
        Record one call in ``every``.
    limit : int
        At most this many instances.
    seed : int
        Seed of the twin's noise.

    Returns
    -------
    RecordedInstances

    Raises
    ------
    InputError
        For a controller not in mode "rti" or a non-positive ``every``.
    """
    if controller.mode != "rti":
        raise InputError(f"instances are recorded from an RTI controller, got mode {controller.mode!r}")
    if not (isinstance(every, int) and every >= 1):
        raise InputError(f"every must be a positive integer, got {every!r}")
    rec = _Recorder(controller, every, limit)
    ClosedLoop(twin, rec).run(scenario, seed=seed)
    return RecordedInstances.of(controller, rec.rows)
