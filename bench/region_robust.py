"""What the nominal certificates are worth on sampled plants (maglev_oc.region.robust; empirical).

python bench/region_robust.py [--runs 500] [--probe-runs 200] [--robust-runs 10000] [--workers 2]
"""

from __future__ import annotations

import argparse
import time

from common import fmt, machine

from maglev_oc.model.stage import StageModel
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.region.robust import (
    assumed_covariance,
    critical_radius,
    empirical_robust_level,
    paper_tables_box,
    robustness_table,
)
from maglev_oc.region.study import LARGE_STEP_START, LARGE_STEP_TARGET
from maglev_oc.region.sweep import PlantSet, SweepSpec, dask_client


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=500)
    parser.add_argument("--probe-runs", type=int, default=200)
    parser.add_argument("--robust-runs", type=int, default=10_000)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    print(f"machine: {machine()}")
    model = StageModel()
    C = tuple(model.constants.as_array())
    proc = Procedure2(FeasibleSet(model), RegulatorLoop())
    specs = {}
    for g in (15, 17.5, 20, 22.5, 25):
        cert = proc.run(Reference.setpoint(g * 1e-3))
        specs[f"{g:g} mm"] = SweepSpec(
            PlantSet.point(C), cert.reference, P=tuple(map(tuple, cert.P)), level=cert.level
        )
    cov = assumed_covariance(model.constants)
    box = paper_tables_box()
    step = SweepSpec(
        PlantSet.point(C), Reference.setpoint(*LARGE_STEP_TARGET), start=LARGE_STEP_START, duration=3.0
    )
    with dask_client(workers=args.workers) as client:
        t0 = time.perf_counter()
        for r in robustness_table(specs, cov, box=box, runs=args.runs, client=client):
            print(
                f"{r.reference:>8s}  {r.plants[:60]:60s} {r.violations:5d}/{r.runs}  {r.share_feasible:7.2%}"
            )
        print(f"table: {fmt(time.perf_counter() - t0)}")
        t0 = time.perf_counter()
        for label, spec in [*specs.items(), ("large step", step)]:
            cr = critical_radius(label, spec, cov, runs=args.probe_runs, client=client)
            print(
                f"{label:>10s}: no violation at {cr.safe_radius:.3g} sigma (1 - {cr.safe_tail:.1e}), "
                f"violations at {cr.broken_radius:.3g} sigma (1 - {cr.broken_tail:.1e})"
            )
        print(f"critical radii: {fmt(time.perf_counter() - t0)}")
        t0 = time.perf_counter()
        rl = empirical_robust_level("20 mm", specs["20 mm"], box, runs=args.robust_runs, client=client)
        print(
            f"empirical robust level at 20 mm, {box.label}: c_rob/c = {rl.ratio:.3f} after {rl.rounds} "
            f"round(s), {rl.check.violations} violations in {rl.check.n} ({fmt(time.perf_counter() - t0)})"
        )


if __name__ == "__main__":
    main()
