"""Benchmark: every step of the operating-region analysis, and 10^4 Monte Carlo runs inside a
certified set (which must show zero violations).

python bench/region.py [--runs 10000] [--threads 2]
"""

from __future__ import annotations

import argparse
import time

import casadi as ca
import numpy as np
from common import best_of, fmt, machine

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.control.linear_regulator import paper_linear_regulator
from maglev_oc.model.stage import StageModel
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet, feasibility_map
from maglev_oc.region.montecarlo import BatchSimulator, check_error_states, uniform_in_ellipsoid
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.region.roa import certify_roa
from maglev_oc.region.sdp import PolygonBuilder, enlarge, solve_sdp
from maglev_oc.sim.twin import RigTwin


def timed(fun):
    t0 = time.perf_counter()
    out = fun()
    return out, time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10_000)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    model = StageModel()
    print(f"machine: {machine()}; casadi {ca.__version__}")

    (feasible, loop), t = timed(lambda: (FeasibleSet(model), RegulatorLoop()))
    print(f"feasible set + loop (CasADi and interval graphs):   {fmt(t)}")
    proc, t = timed(lambda: Procedure2(feasible, loop))
    print(f"Procedure 2 build (IPOPT solvers, interval graph):  {fmt(t)}")

    # interval arithmetic throughput on the constraint graph
    n = 10_000
    rng = np.random.default_rng(0)
    x1 = rng.uniform(0.01, 0.03, n)
    lo = [x1[None, :], np.vstack([rng.uniform(-20, 20, n), rng.uniform(-20, 20, n)])]
    hi = [lo[0] + 1e-5, lo[1] + 0.1]
    best, _ = best_of(lambda: feasible.pointwise_interval(lo, hi), repeat=5)
    print(f"interval enclosure of (margin, headroom), 10^4 boxes: {fmt(best)} ({fmt(best / n)} per box)")

    ref = Reference.setpoint(0.02)
    fm, t = timed(
        lambda: feasibility_map(feasible, loop, ref, ("e1", "e1_rate"), (-0.012, 0.01), (-0.6, 0.6), n=101)
    )
    roots = fm.boundary["headroom"].shape[1]
    print(f"feasibility map 101 x 101 + Newton boundary:        {fmt(t)} ({roots} roots)")

    res, t = timed(lambda: proc.run(ref))
    nlp = sum(m.timings["total"] for m in res.minima)
    starts = sum(m.starts for m in res.minima)
    cert = sum(a.timings["total"] for a in res.attempts)
    boxes = sum(a.boxes for a in res.attempts)
    print(
        f"Procedure 2 at 20 mm (Lyapunov P):                  {fmt(t)}  "
        f"[IPOPT {fmt(nlp)} for {starts} starts, "
        f"branch and bound {fmt(cert)} for {boxes} boxes, c = {res.level:.4g}, c/upper = {res.tightness:.3f}]"
    )
    _, t = timed(lambda: proc.run(Reference.paper_sinusoid()))
    print(f"Procedure 2, sinusoid (phase as a 4th dimension):   {fmt(t)}")

    builder = PolygonBuilder(feasible, loop)
    poly, t = timed(lambda: builder.build(ref, 7.5e-3))
    print(f"inner polygon (24 vertices proved by intervals):    {fmt(t)} ({poly.cells} cells)")
    (status, _, dt), t = timed(lambda: solve_sdp(loop, ref, poly, feasible, 0.1, (1.0, 1.0)))
    print(f"one SDP (cvxpy + Clarabel), status {status}:        {fmt(dt)} solve, {fmt(t)} with modelling")
    sdp, t = timed(lambda: enlarge(proc, ref, builder=builder))
    print(f"SDP enlargement, 4 half-widths incl. certification: {fmt(t)} ({sdp.message})")

    roa, t = timed(lambda: certify_roa(model, paper_linear_regulator(model), Reference.setpoint(0.018, 0.02)))
    print(f"certified ROA, linear regulator at 18 mm:           {fmt(t)} ({roa.bisections} bisections)")

    sim, t = timed(
        lambda: BatchSimulator(
            RigTwin(model), FeedbackLinearizingRegulator(model), duration=1.0, threads=args.threads
        )
    )
    print(f"Monte Carlo build (step as C, C loop: {sim.compiled}):    {fmt(t)}")
    c = sdp.certified
    z = uniform_in_ellipsoid(c.P, c.level, args.runs, np.random.default_rng(1))
    chk, t = timed(lambda: check_error_states(sim, loop, ref, c.P, c.level, z))
    steps = args.runs * sim.n_steps
    print(
        f"Monte Carlo, {args.runs} runs x 1 s inside the SDP set at 20 mm: {fmt(t)} "
        f"({fmt(t / steps)} per closed-loop sample, {args.threads} threads): {chk.violations} violations, "
        f"largest |u| {chk.max_current:.3f} A, max V_end/c {np.max(chk.final_ratio):.2g}"
    )


if __name__ == "__main__":
    main()
