"""Benchmark: one Monte Carlo sweep over sampled plants (maglev_oc.region.sweep) on 1 worker (in
this process) against a Dask LocalCluster of 2 single-threaded worker processes; the numbers
must be bit-identical.

python bench/region_sweep.py [--runs 10000] [--task-size 250] [--workers 2]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from common import fmt, machine

from maglev_oc.model.stage import StageModel
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.region.robust import assumed_covariance
from maglev_oc.region.sweep import PlantSet, SweepSpec, dask_client, run_sweep

FIELDS = ("violating", "constants", "start_ratio", "min_margin", "max_current")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10_000)
    parser.add_argument("--task-size", type=int, default=250)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    model = StageModel()
    print(f"machine: {machine()}; load {os.getloadavg()[0]:.1f}")
    ref = Reference.setpoint(0.020)
    cert = Procedure2(FeasibleSet(model), RegulatorLoop()).run(ref)
    plants = PlantSet.confidence(model.constants, assumed_covariance(model.constants), 0.99)
    spec = SweepSpec(plants, ref, P=tuple(map(tuple, cert.P)), level=cert.level)
    print(f"{args.runs} runs x 1 s at 20 mm, starts in the Lyapunov-P certificate, plants: {plants.label}")

    t0 = time.perf_counter()
    one = run_sweep(spec, args.runs, seed=0, task_size=args.task_size)
    t_one = time.perf_counter() - t0
    print(f"1 worker (this process):          {fmt(t_one)}  ({one.violations} violations)")

    t0 = time.perf_counter()
    with dask_client(workers=args.workers) as client:
        t_up = time.perf_counter() - t0
        t1 = time.perf_counter()
        many = run_sweep(spec, args.runs, seed=0, task_size=args.task_size, client=client)
        t_run = time.perf_counter() - t1
    t_all = time.perf_counter() - t0
    same = all(np.array_equal(getattr(one, k), getattr(many, k), equal_nan=True) for k in FIELDS)
    print(
        f"LocalCluster, {args.workers} workers:          {fmt(t_run)} sweep (cluster start {fmt(t_up)}, "
        f"total {fmt(t_all)}); speed-up {t_one / t_run:.2f}x sweep, {t_one / t_all:.2f}x with the start"
    )
    print(f"bit-identical: {same}; load after {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
