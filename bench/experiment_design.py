"""Benchmark: designed experiments against the papers' sum-of-sines excitation on the rig twin.

python bench/experiment_design.py [--duration 60] [--seeds 4]

For each design (multisine, PRBS, D-optimal, gap sweep) and the papers' excitation of the same
duration and current budget: the predicted standard errors (nominal twin, sandwich covariance),
the achieved ones (rig twin with encoders and amplifiers, TWIN_TRUTH, equation-error fit; HAC
standard error averaged over seeds, and the spread of the estimates over seeds), and the ratio
of each target's standard error to the papers' excitation's. Timings per step.
"""

from __future__ import annotations

import argparse
import time

from common import fmt, machine

from maglev_oc.identification.design import (
    EFFECT,
    ExperimentDesigner,
    check_on_twin,
    design_experiment,
    papers_reference,
)
from maglev_oc.model.stage import StageModel


def _row(label: str, names, values) -> str:
    return f"  {label:28s}" + "".join(f"{values.get(n, float('nan')):>12.3g}" for n in names)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=60.0)
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--kinds", nargs="+", default=["multisine", "prbs", "doptimal", "gap_sweep"])
    args = parser.parse_args()
    model = StageModel()
    designer = ExperimentDesigner(model)
    seeds = tuple(range(args.seeds))
    print(f"machine: {machine()}; duration {args.duration:g} s; seeds {seeds}")
    checks = {}
    for effect in (False, True):
        t0 = time.perf_counter()
        pred = designer.predict(papers_reference(args.duration), effect=effect)
        checks[effect] = (
            pred,
            check_on_twin(papers_reference(args.duration), pred, model=model, seeds=seeds),
        )
        print(f"papers' excitation (effect={effect}): {fmt(time.perf_counter() - t0)}")
    for kind in args.kinds:
        t0 = time.perf_counter()
        design = design_experiment(kind, args.duration, model=model, designer=designer)
        t_design = time.perf_counter() - t0
        check = check_on_twin(design.reference, design.prediction, model=model, seeds=seeds)
        _, base = checks[EFFECT in design.prediction.names]
        names = check.names
        print(f"\n[{kind}] {design.reference.description}")
        print(f"  targets: {', '.join(design.targets)}")
        print(
            f"  peak currents (nominal twin) i_q {design.prediction.peak_current[0]:.3f} A, "
            f"i_d {design.prediction.peak_current[1]:.3f} A; budget {design.budget.horizontal:.3f} / "
            f"{design.budget.vertical:.3f} A; rig twin {check.peak_current[0]:.3f} / "
            f"{check.peak_current[1]:.3f} A"
        )
        print("  " + " " * 28 + "".join(f"{n[:11]:>12s}" for n in names))
        print(_row("predicted SE", names, check.predicted))
        print(_row("achieved SE (HAC, mean)", names, check.achieved))
        print(_row("spread over seeds", names, check.spread))
        print(_row("mean |error|", names, check.error))
        print(_row("papers: predicted SE", names, base.predicted))
        print(_row("papers: achieved SE", names, base.achieved))
        print(_row("papers: spread", names, base.spread))
        print(_row("ratio achieved/papers", names, {n: check.achieved[n] / base.achieved[n] for n in names}))
        print(_row("ratio spread/papers", names, {n: check.spread[n] / base.spread[n] for n in names}))
        print(
            f"  timings: design {fmt(t_design)}, twin runs {fmt(check.timings['simulate'])}, "
            f"identification {fmt(check.timings['identify'])} ({len(seeds)} seeds)"
        )
        if design.candidates:
            for c in design.candidates:
                print(f"    candidate {c['shape']}: log det {c.get('log_det', float('nan')):.2f}")
            print(f"    chosen {design.settings.get('vertical')} / {design.settings.get('horizontal')}")


if __name__ == "__main__":
    main()
