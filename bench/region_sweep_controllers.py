"""Benchmark: the controllers compared over sampled plants on Dask (issue 16 item 3): constants
from a confidence set of the identification, the rig twin's guide friction and cogging scaled
per run within ranges, each controller from the papers' large step start and from starts in the
20 mm certificate. Prints, per controller and plant set, the share of runs that stay in F and the
wall time, on a LocalCluster of ``--workers`` processes.

python bench/region_sweep_controllers.py [--runs 2000] [--workers 2] [--confidence 0.95]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time

from common import fmt, machine

from maglev_oc.model.stage import StageModel
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.region.robust import assumed_covariance
from maglev_oc.region.study import LARGE_STEP_START, LARGE_STEP_TARGET
from maglev_oc.region.sweep import CONTROLLERS, PlantSet, SweepSpec, dask_client, run_sweep
from maglev_oc.sim.effects import TwinEffects

RANGES = ((0.0, 3.0), (0.0, 3.0), (0.0, 3.0))
"""Scales of the rig twin's vertical and horizontal guide friction and its cogging (0 to 3 times
the rig preset: 0.3 N / 0.1 N Coulomb, the papers' cogging)."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=2000)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--confidence", type=float, default=0.95)
    args = parser.parse_args()
    model = StageModel()
    print(f"machine: {machine()}; load {os.getloadavg()[0]:.1f}")
    C = model.constants.as_array()
    plant_sets = {
        "nominal plant, ideal twin": (PlantSet.point(C), None),
        f"{args.confidence:g} set, ideal twin": (
            PlantSet.confidence(C, assumed_covariance(model.constants), args.confidence),
            None,
        ),
        f"{args.confidence:g} set, rig effects x 0-3": (
            PlantSet.confidence(C, assumed_covariance(model.constants), args.confidence),
            RANGES,
        ),
    }
    step = Reference.setpoint(*LARGE_STEP_TARGET)
    at20 = Reference.setpoint(0.020)
    cert = Procedure2(FeasibleSet(model), RegulatorLoop()).run(at20)
    with dask_client(workers=args.workers) as client:
        for label, (plants, ranges) in plant_sets.items():
            effects = TwinEffects.ideal() if ranges is None else TwinEffects.rig()
            base = {"plants": plants, "effects": effects, "effect_ranges": ranges}
            for ctrl in CONTROLLERS:
                t0 = time.perf_counter()
                spec = SweepSpec(
                    reference=step, controller=ctrl, start=LARGE_STEP_START, duration=3.0, **base
                )
                res = run_sweep(spec, args.runs, seed=0, client=client, progress=False)
                line = f"{label:34s} {ctrl:7s} large step: {res.share_feasible:7.2%} in F"
                if ctrl == "fl":
                    inside = dataclasses.replace(
                        spec, reference=at20, start=None, P=tuple(map(tuple, cert.P)), level=cert.level
                    )
                    res20 = run_sweep(inside, args.runs, seed=0, client=client, progress=False)
                    line += f"; 20 mm certificate: {res20.share_feasible:7.2%}"
                print(f"{line}  ({fmt(time.perf_counter() - t0)})", flush=True)
    print(f"load after {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
