"""Benchmark: our closed-loop simulation against python-control's input_output_response, in one run.

    python bench/peer_python_control.py [--seconds 10] [--json OUT.json]

Issue 7 asks for "closed-loop simulation of expression controllers at 10^6 steps per second or
more" and a side-by-side comparison with a peer.

The same system in both: the papers' FL regulator (observers, internal models, feedback
transformation) sampled at 5 kHz on the ideal twin (the model itself, RK4 over each 0.2 ms
sample with the current held), tracking the papers' ellipse for ``--seconds`` (default 10 s,
50 000 steps; the scenario of bench/closed_loop_speed.py). python-control has no hybrid
(sampled controller, continuous plant) simulation: every subsystem of an interconnection must
share one time base, so the loop is simulated as what it is, a discrete-time system, in both.

* ours: :class:`~maglev_oc.sim.engine.ClosedLoop` with each backend ("vm": chunked mapaccum in
  CasADi's VM; "jit": the chunk JIT-compiled; "c": the fused step generated as C with a C loop);
* python-control 0.10, the way its documentation builds a loop: two discrete-time ``nlsys``
  (dt = 0.2 ms), the plant (update = the twin's step, output = the encoder reading) and the
  controller (update = the regulator's state update, output = its current command), joined by
  ``interconnect`` and run by ``input_output_response`` with the sampled reference as input.
  Their update and output functions call the same CasADi Functions our engine fuses (compiled
  kernels, not Python arithmetic), so the dynamics are identical and the times compare the
  simulation machinery;
* python-control with the fused step as one ``nlsys`` (update = our fused closed-loop step): the
  least python-control can do per step with these kernels.

Accuracy: the trajectories must agree to rounding (the same recursion); the largest state and
current differences are printed. Times: wall time of a run after a first (build) run, best of
three for ours, one run for python-control (seconds per run).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
from pathlib import Path

import casadi as ca
import numpy as np
from common import fmt, machine

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.model.equilibrium import equilibrium_currents
from maglev_oc.model.stage import StageModel
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.scenarios import Scenario, Sinusoids, paper_scenarios
from maglev_oc.sim.twin import RigTwin

try:
    import control as ct
except ImportError:
    sys.exit(
        "bench/peer_python_control.py needs python-control (a peer, not a dependency): "
        "pip install -e '.[peers]'"
    )


def _vec(value) -> np.ndarray:
    return np.asarray(value, dtype=float).ravel()


def python_control_interconnect(twin: RigTwin, ctrl: FeedbackLinearizingRegulator):
    """Plant and controller as two discrete-time nlsys, joined by interconnect."""
    ts = twin.sample_time
    zero_noise = np.zeros(2)

    plant = ct.nlsys(
        lambda t, s, u, p: _vec(twin.step(s, u)[0]),
        lambda t, s, u, p: _vec(twin.measure(s, zero_noise)),
        inputs=["i_q", "i_d"],
        outputs=["y_gap", "y_pos"],
        states=twin.n_state,
        dt=ts,
        name="plant",
    )
    refs = ["r_v", "dr_v", "ddr_v", "r_h", "dr_h", "ddr_h"]

    def ctrl_update(t, c, inp, p):
        return _vec(ctrl.step(c, inp[0:2], inp[2:8])[1])

    def ctrl_output(t, c, inp, p):
        # interconnect resolves the feedthrough y -> u by iterating from y = 0; at a zero gap the
        # FL law is NaN, and 0 * NaN in connect_map @ outputs turns every signal into NaN, which
        # python-control then reports as "algebraic loop detected". Answer 0 until y arrives.
        if inp[0] <= 0:
            return np.zeros(2)
        return _vec(ctrl.step(c, inp[0:2], inp[2:8])[0])

    controller = ct.nlsys(
        ctrl_update,
        ctrl_output,
        inputs=["y_gap", "y_pos", *refs],
        outputs=["i_q", "i_d"],
        states=ctrl.n_state,
        dt=ts,
        name="controller",
    )
    return ct.interconnect(
        [plant, controller], inplist=refs, outlist=["i_q", "i_d", "y_gap", "y_pos"], dt=ts, name="loop"
    )


def python_control_fused(loop: ClosedLoop):
    """Our fused closed-loop step as one discrete-time nlsys (state z = (twin, controller))."""
    step = loop.step_function
    nz = step.size1_in(0)
    zero_noise = np.zeros(2)

    def update(t, z, r, p):
        return _vec(step(z, r, zero_noise)[0])

    def output(t, z, r, p):
        out = _vec(step(z, r, zero_noise)[1])
        return out[0:4]  # y (2), u (2)

    return ct.nlsys(update, output, inputs=6, outputs=4, states=nz, dt=loop.twin.sample_time, name="fused")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="simulated time [s]")
    parser.add_argument("--json", type=Path, help="write the figures to this file")
    args = parser.parse_args()

    model = StageModel()
    twin = RigTwin(model)
    ctrl = FeedbackLinearizingRegulator(model)
    ellipse = paper_scenarios()["sinusoid"].reference
    assert isinstance(ellipse, Sinusoids)
    scenario = Scenario("ellipse", f"{args.seconds:g} s ellipse", (0.02, 0, 0, 0), ellipse, args.seconds)
    t, ref = scenario.sample(twin.sample_time)
    n = t.size
    print(f"machine: {machine()}; casadi {ca.__version__}, python-control {ct.__version__}")
    print(f"load average at start: {os.getloadavg()[0]:.2f} (2 cores)")
    print(f"FL regulator on the ideal twin, {scenario.title}, 5 kHz: {n} steps\n")

    results: dict = {"machine": machine(), "steps": n, "seconds": args.seconds}
    ours: dict = {}
    reference_run = None
    for backend in ClosedLoop.BACKENDS:
        loop = ClosedLoop(twin, ctrl, backend=backend)
        t0 = time.perf_counter()
        res = loop.run(scenario)
        first = time.perf_counter() - t0
        best = min(loop.run(scenario).timings["total"] for _ in range(3))
        ours[backend] = {"wall_s": best, "steps_per_s": n / best, "first_run_s": first}
        if backend == "vm":
            reference_run = res
        else:
            ours[backend]["max_abs_dx_vs_vm"] = float(np.max(np.abs(res.x - reference_run.x)))
    assert reference_run is not None
    results["ours"] = ours

    # initial states exactly as the engine makes them
    x0 = np.asarray(scenario.x0, dtype=float)
    curve = equilibrium_currents(model, [x0[0]])
    u_init = np.array([0.0, float(curve.current[0])])
    s0 = twin.initial_state(x0, u_init)
    y0 = _vec(twin.measure(s0, np.zeros(2)))
    c0 = ctrl.initial_state(y0, ref[:, 0], u_init)

    peer: dict = {}
    for label, build, z0 in (
        (
            "interconnect (plant + controller nlsys)",
            lambda: python_control_interconnect(twin, ctrl),
            np.concatenate([s0, c0]),
        ),
        (
            "one nlsys around our fused step",
            lambda: python_control_fused(ClosedLoop(twin, ctrl)),
            np.concatenate([s0, c0]),
        ),
    ):
        t0 = time.perf_counter()
        sys_ = build()
        build_s = time.perf_counter() - t0
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t0 = time.perf_counter()
            resp = ct.input_output_response(sys_, t, ref, z0, return_states=True)
            wall = time.perf_counter() - t0
        states = np.asarray(resp.states)
        outputs = np.asarray(resp.outputs)
        x_pc = states[0:4]
        u_pc = outputs[0:2] if label.startswith("interconnect") else outputs[2:4]
        dx = np.max(np.abs(x_pc - reference_run.x), axis=1)
        du = float(np.max(np.abs(u_pc - reference_run.u)))
        peer[label] = {
            "wall_s": wall,
            "steps_per_s": n / wall,
            "build_s": build_s,
            "max_abs_dx_vs_ours": dx.tolist(),
            "max_abs_du_vs_ours_A": du,
        }
    results["python_control"] = peer

    c_rate = ours["c"]["steps_per_s"]
    print(f"  {'simulator':<50s} {'wall':>10s} {'steps/s':>12s}  {'ours (c) faster by':>18s}")
    for backend, s in ours.items():
        print(
            f"  {'ours, ClosedLoop backend=' + repr(backend):<50s} {fmt(s['wall_s']):>10s} "
            f"{s['steps_per_s']:12.3g}  {c_rate / s['steps_per_s']:17.1f}x"
        )
    for label, s in peer.items():
        print(
            f"  {'python-control, ' + label:<50s} {fmt(s['wall_s']):>10s} "
            f"{s['steps_per_s']:12.3g}  {c_rate / s['steps_per_s']:17.0f}x"
        )
    print("\n  agreement with ours (vm), largest |difference| over the run:")
    for backend in ("jit", "c"):
        print(f"    ours {backend}: state {ours[backend]['max_abs_dx_vs_vm']:.1e}")
    for label, s in peer.items():
        dx = s["max_abs_dx_vs_ours"]
        print(
            f"    python-control, {label}: gap {dx[0]:.1e} m, gap rate {dx[1]:.1e} m/s, "
            f"position {dx[2]:.1e} m, rate {dx[3]:.1e} m/s, current {s['max_abs_du_vs_ours_A']:.1e} A"
        )
    print(f"\nload average at the end: {os.getloadavg()[0]:.2f}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=2) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
