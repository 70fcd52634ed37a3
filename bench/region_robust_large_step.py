"""The papers' large step (26, 0) -> (18, 20) mm under the certified robust region: up to which
confidence level of the constants' covariance its start is certified.

python bench/region_robust_large_step.py [--max-boxes 100000]

For each confidence level p (smallest first) the robust SDP chooses P for the p-ellipsoid of the
assumed identification covariance (robust.assumed_covariance), Procedure 2 gives the nominal level
for that P, and the robust certificate (maglev_oc.region.robust_certificate) its level for the same
ellipsoid. The start is certified at p when V(start) <= the robust level. Printed: per p, the
ratio V(start) / nominal level, the certificate's status and V(start) / robust level.

Then the same with P aimed at the start: the nominal SDP maximising the reach along the start's
error state (``sdp.enlarge(direction=...)``, as the operating-region report's large step), and the
robust SDP aimed the same way (``robust_lyapunov_matrix(direction=...)``), for the confidence
levels ``AIMED_CONFIDENCES`` (from one in a million: does any uncertainty at all break it?).
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
from maglev_oc.region.robust import assumed_covariance
from maglev_oc.region.robust_certificate import RobustCertifier, robust_lyapunov_matrix
from maglev_oc.region.sdp import enlarge
from maglev_oc.region.study import LARGE_STEP_START, LARGE_STEP_TARGET
from maglev_oc.region.sweep import PlantSet

CONFIDENCES = (0.01, 0.05, 0.1, 0.2, 0.3, 0.5, 0.9, 0.95, 0.99)
AIMED_CONFIDENCES = (1e-6, 1e-4, 1e-3, 0.01, 0.1, 0.5)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-boxes", type=int, default=100_000)
    args = parser.parse_args()
    with open("/proc/loadavg") as f:
        load = " ".join(f.read().split()[:3])
    print(f"{datetime.datetime.now():%Y-%m-%d %H:%M}; machine: {machine()}; load {load}")
    model = StageModel()
    loop = RegulatorLoop()
    feasible = FeasibleSet(model)
    proc = Procedure2(feasible, loop)
    cert = RobustCertifier(feasible, loop, max_boxes=args.max_boxes)
    ref = Reference.setpoint(*LARGE_STEP_TARGET)
    z0 = loop.error_state(np.array(LARGE_STEP_START), np.zeros(6), ref)[:, 0]
    lyap = proc.run(ref)
    print(f"Lyapunov P: V(start) / nominal level = {z0 @ lyap.P @ z0 / lyap.level:.3g} ({lyap.status})")
    C = np.asarray(model.constants.as_array())
    cov = assumed_covariance(model.constants)
    head = ("confidence", "V0/c_nom", "certificate", "c_rob/c_nom", "V0/c_rob")
    print("{:>10s} {:>9s} {:>14s} {:>11s} {:>9s}  time".format(*head))
    for p in CONFIDENCES:
        t0 = time.perf_counter()
        plants = PlantSet.confidence(C, cov, p)
        P, message = robust_lyapunov_matrix(cert, lyap, plants)
        if P is None:
            print(f"{p:10g}  no P: {message}")
            continue
        nominal = proc.run(ref, P)
        v0 = float(z0 @ P @ z0)
        if not nominal.success:
            print(f"{p:10g}  nominal certificate failed: {nominal.message}")
            continue
        robust = cert.run(nominal, plants)
        ratio = v0 / robust.level if robust.success and robust.level > 0 else float("inf")
        verdict = "start certified" if ratio <= 1 else "start outside"
        said = verdict if robust.success else robust.message[:80]
        print(
            f"{p:10g} {v0 / nominal.level:9.3g} {robust.status:>14s} {robust.level / nominal.level:11.3f} "
            f"{ratio:9.3g}  {fmt(time.perf_counter() - t0)}  {said}"
        )

    aimed = enlarge(proc, ref, direction=z0).certified
    if aimed is None:
        print("P aimed at the start: the nominal SDP certified nothing")
        return
    v_aim = float(z0 @ aimed.P @ z0)
    print(f"P aimed at the start (nominal SDP): V(start) / nominal level = {v_aim / aimed.level:.3g}")
    print(
        "{:>10s} {:>26s} {:>9s} {:>26s}  time".format(
            "confidence", "aimed P: robust", "V0/c_nom", "robust-aimed P: robust"
        )
    )
    for p in AIMED_CONFIDENCES:
        t0 = time.perf_counter()
        plants = PlantSet.confidence(C, cov, p)
        rob = cert.run(aimed, plants)
        cells = [_verdict(rob, v_aim, aimed.level)]
        P, message = robust_lyapunov_matrix(cert, aimed, plants, direction=z0)
        v0 = float(z0 @ P @ z0) if P is not None else float("nan")
        nominal = proc.run(ref, P) if P is not None else None
        if nominal is not None and nominal.success:
            cells += [f"{v0 / nominal.level:9.3g}", _verdict(cert.run(nominal, plants), v0, nominal.level)]
        else:
            cells += ["        -", f"no P: {message}"[:26]]
        print(f"{p:10g} {cells[0]:>26s} {cells[1]} {cells[2]:>26s}  {fmt(time.perf_counter() - t0)}")
        if not rob.success:
            print(f"{'':10s}   aimed P: {rob.message[:150]}")


def _verdict(robust, v0: float, nominal_level: float) -> str:
    """'status c_rob/c_nom V0/c_rob' in one cell."""
    if not robust.success or robust.level <= 0:
        return robust.status
    return f"{robust.level / nominal_level:.3f}; V0/c_rob {v0 / robust.level:.3g}"


if __name__ == "__main__":
    main()
