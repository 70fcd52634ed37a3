"""Benchmark: closed-loop simulation speed (FL regulator on the twin, 5 kHz).

    python bench/closed_loop_speed.py

Issue 3 asks for 10 s at 5 kHz (50 000 steps) of the FL regulator on the twin in well under
1 s; issue 7 for expression controllers at 10^6 steps per second or more.
"""

from __future__ import annotations

import time

import casadi as ca
from common import machine

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.model.stage import StageModel
from maglev_oc.sim.effects import TwinEffects
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.scenarios import Scenario, Sinusoids, paper_scenarios
from maglev_oc.sim.twin import RigTwin


def main() -> None:
    model = StageModel()
    ctrl = FeedbackLinearizingRegulator(model)
    ellipse = paper_scenarios()["sinusoid"].reference
    assert isinstance(ellipse, Sinusoids)
    scenario = Scenario("ten_seconds", "10 s ellipse", (0.02, 0, 0, 0), ellipse, 10.0)
    print(f"machine: {machine()}; casadi {ca.__version__}")
    for twin_name, effects in (("ideal", TwinEffects.ideal()), ("rig", TwinEffects.rig())):
        for backend in ClosedLoop.BACKENDS:
            loop = ClosedLoop(RigTwin(model, effects), ctrl, backend=backend)
            t0 = time.perf_counter()
            loop.run(scenario)  # builds (and compiles) once
            first = time.perf_counter() - t0
            walls = [loop.run(scenario).timings["total"] for _ in range(3)]
            best = min(walls)
            n = round(scenario.duration / 2e-4)
            print(
                f"{twin_name:5s} twin, {backend:3s}: 10 s at 5 kHz "
                f"in {best * 1e3:.0f} ms ({n / best / 1e6:.2f} M steps/s); first run incl. build "
                f"{first:.2f} s; instructions/step {loop.step_function.n_instructions()}"
            )


if __name__ == "__main__":
    main()
