"""Benchmark: one 10 s closed-loop run of the 3-DOF microstepper (FL regulator with anti-windup on
the rig twin, 5 kHz: 50 000 steps), build and run timed separately.

    python bench/microstepper_sim.py

Build: the controller's and the twin's CasADi Functions, then the fused loop (and its compiled
form for the jit and c backends). Run: best of three runs of the 10 s sinusoid scenario of
002 Sec. 8 (every axis at once) after a first run.
"""

from __future__ import annotations

import time

import casadi as ca
from common import fmt, machine

from maglev_oc.control.microstepper import MicrostepperRegulator
from maglev_oc.model.platform import microstepper
from maglev_oc.sim.microstepper import MicrostepperLoop
from maglev_oc.sim.microstepper_scenarios import microstepper_scenarios
from maglev_oc.sim.microstepper_twin import MicrostepperTwin


def main() -> None:
    print(f"machine: {machine()}; casadi {ca.__version__}")
    scenario = microstepper_scenarios()["sinusoid"].shortened(10.0)
    n = round(scenario.duration / 2e-4)
    platform = microstepper()
    t0 = time.perf_counter()
    controller = MicrostepperRegulator(platform)
    t1 = time.perf_counter()
    twin = MicrostepperTwin(platform)
    t2 = time.perf_counter()
    print(f"build: controller {fmt(t1 - t0)}, rig twin {fmt(t2 - t1)}")
    for backend in MicrostepperLoop.BACKENDS:
        t0 = time.perf_counter()
        loop = MicrostepperLoop(twin, controller, backend=backend)
        build = time.perf_counter() - t0
        t0 = time.perf_counter()
        first = loop.run(scenario)
        first_wall = time.perf_counter() - t0
        best = min(loop.run(scenario).timings["total"] for _ in range(3))
        print(
            f"{backend:3s}: loop build {fmt(build)}; 10 s run first {fmt(first_wall)}, best of 3 {fmt(best)} "
            f"({n / best / 1e6:.2f} M steps/s); {first.status}; "
            f"instructions/step {loop.step_function.n_instructions()}"
        )


if __name__ == "__main__":
    main()
