"""The certified robust operating region (maglev_oc.region.robust_certificate): nominal vs robust
level by confidence, timings, and Monte Carlo inside every certified robust set.

python bench/region_robust_certificate.py [--runs 10000] [--probe-runs 10000] [--max-boxes 200000]

Per set-point of the papers (15-25 mm): the Lyapunov equation's P, then the P of the robust SDP
designed for the 0.9 confidence set; for each, the nominal level (Procedure 2) and the robust
level for the 0.5/0.9/0.95/0.99 confidence ellipsoids of the assumed identification covariance
(robust.assumed_covariance). Every certified robust set gets ``--runs`` runs of the sampled loop
(plants of the set, starts uniform in the set) and must show 0 violations; ``--probe-runs`` runs
started in twice the nominal set give the share of the empirically safe starts each certificate
covers (conservativeness).

``--design-each`` designs the robust SDP's P for each confidence level instead (the P that level
would use), to find the level at which each set-point stops being certified; ``--gaps`` and
``--confidences`` choose the cells, e.g.

    python bench/region_robust_certificate.py --design-each --gaps 15 17.5 20 \
        --confidences 0.01 0.05 0.1 0.2 0.3 --runs 2000 --probe-runs 0
"""

from __future__ import annotations

import argparse
import datetime
import time

import numpy as np
from common import fmt, machine

from maglev_oc.model.stage import StageModel
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.region.robust import CONFIDENCE_LEVELS, assumed_covariance
from maglev_oc.region.robust_certificate import RobustCertifier, coverage, robust_lyapunov_matrix
from maglev_oc.region.sweep import PlantSet, SweepSpec, run_sweep

GAPS_MM = (15, 17.5, 20, 22.5, 25)
DESIGN_CONFIDENCE = 0.9


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10_000)
    parser.add_argument("--probe-runs", type=int, default=10_000)
    parser.add_argument("--max-boxes", type=int, default=200_000)
    parser.add_argument("--gaps", type=float, nargs="+", default=list(GAPS_MM), metavar="MM")
    parser.add_argument("--confidences", type=float, nargs="+", default=list(CONFIDENCE_LEVELS))
    parser.add_argument("--design-each", action="store_true", help="the robust SDP's P per confidence level")
    args = parser.parse_args()
    with open("/proc/loadavg") as f:
        load = f.read().split()[:3]
    print(f"{datetime.datetime.now():%Y-%m-%d %H:%M}; machine: {machine()}; load {' '.join(load)}")
    model = StageModel()
    loop = RegulatorLoop()
    feasible = FeasibleSet(model)
    proc = Procedure2(feasible, loop)
    t0 = time.perf_counter()
    cert = RobustCertifier(feasible, loop, max_boxes=args.max_boxes)
    print(f"certifier build (CasADi + interval graph): {fmt(time.perf_counter() - t0)}")
    C = np.asarray(model.constants.as_array())
    cov = assumed_covariance(model.constants)
    sets = {p: PlantSet.confidence(C, cov, p) for p in (*args.confidences, DESIGN_CONFIDENCE)}
    if args.design_each:
        certified = _design_each(args, proc, cert, sets)
        _monte_carlo(args, sets, certified)
        print(f"total: {fmt(time.perf_counter() - t0)}")
        return
    sets = {p: sets[p] for p in args.confidences}
    print(
        f"{'gap':>6s} {'P':>8s} {'c_nom':>9s} "
        + " ".join(f"{'c_rob/c_nom @' + format(p, 'g'):>16s}" for p in sets)
    )
    certified = []
    for g in args.gaps:
        ref = Reference.setpoint(g * 1e-3)
        lyap = proc.run(ref)
        t1 = time.perf_counter()
        P, msg = robust_lyapunov_matrix(cert, lyap, sets[DESIGN_CONFIDENCE])
        t_sdp = time.perf_counter() - t1
        rows = [("Lyapunov", lyap)]
        if P is not None:
            rows.append(("SDP", proc.run(ref, P)))
        else:
            print(f"{g:6g} robust SDP: {msg}")
        for name, nominal in rows:
            cells = []
            for p, plants in sets.items():
                res = cert.run(nominal, plants)
                cells.append(f"{res.ratio:6.3f} {res.status[:4]} {fmt(res.timings['certify']):>8s}")
                if res.success:
                    certified.append((g, name, p, res))
            print(
                f"{g:6g} {name:>8s} {nominal.level:9.4g} " + " ".join(f"{c:>16s}" for c in cells), flush=True
            )
        if P is not None:
            print(f"{'':6s} (robust SDP {fmt(t_sdp)}: {msg})")
    _monte_carlo(args, sets, certified)
    print(f"total: {fmt(time.perf_counter() - t0)}")


def _design_each(args, proc, cert, sets) -> list:
    """Per set-point and confidence p: the robust SDP's P for the p set, Procedure 2's nominal
    level for it and the certified robust level."""
    print(f"{'gap':>6s} " + " ".join(f"{'c_rob/c_nom @' + format(p, 'g'):>22s}" for p in args.confidences))
    certified = []
    for g in args.gaps:
        ref = Reference.setpoint(g * 1e-3)
        lyap = proc.run(ref)
        cells = []
        for p in args.confidences:
            P, _ = robust_lyapunov_matrix(cert, lyap, sets[p])
            if P is None:
                cells.append("no P")
                continue
            res = cert.run(proc.run(ref, P), sets[p])
            cells.append(f"{res.ratio:6.3f} {res.status[:4]} {fmt(res.timings['certify']):>8s}")
            if res.success:
                certified.append((g, f"SDP@{p:g}", p, res))
        print(f"{g:6g} " + " ".join(f"{c:>22s}" for c in cells), flush=True)
    return certified


def _monte_carlo(args, sets, certified) -> None:
    print("\nMonte Carlo (sampled 5 kHz loop, 1 s, plants of the set, starts uniform in the set):")
    for g, name, p, res in certified:
        P = tuple(map(tuple, res.P))
        t1 = time.perf_counter()
        inside = run_sweep(
            SweepSpec(sets[p], res.reference, P=P, level=res.level), args.runs, seed=1, progress=False
        )
        t_in = time.perf_counter() - t1
        if not args.probe_runs:
            print(
                f"{g:6g} mm {name:>8s} conf {p:4g}: {inside.violations} violations in {inside.n} "
                f"({fmt(t_in)})"
            )
            continue
        probe = run_sweep(
            SweepSpec(sets[p], res.reference, P=P, level=2 * res.nominal_level),
            args.probe_runs,
            seed=2,
            progress=False,
        )
        cv = coverage(probe, res.nominal_level, res.level)
        print(
            f"{g:6g} mm {name:>8s} conf {p:4g}: {inside.violations} violations in {inside.n} ({fmt(t_in)}); "
            f"safe starts in 2 x nominal set {cv.safe}/{cv.runs}, covered: nominal {cv.nominal:.1%} "
            f"({cv.unsafe_in_nominal} unsafe inside), robust {cv.robust:.1%} "
            f"({cv.unsafe_in_robust} unsafe inside)",
            flush=True,
        )


if __name__ == "__main__":
    main()
