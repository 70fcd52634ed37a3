"""HPIPM on the NMPC's constrained QPs: first-current error, iterations and solver time, with and
without the QP's cost scale (issue 20 item 3; tests/test_export_qp.py checks the error).

The QPs are those the default NMPC (HPIPM, Riccati shortcut) solves on the papers' large step on
the rig twin (its first ``--seconds`` s): the RTI step's QP data at each recorded call, kept
where the Riccati step violates a bound. Each is solved by

* qpOASES (the reference, an active-set method: the exact solution to round-off),
* HPIPM as before the scale: the cost divided by ``Transcription.cost_scale`` and HPIPM's own
  initial barrier mu0 = 10 (mode "speed_abs"),
* HPIPM as the NMPC calls it now (the scaled cost, mu0 = 100).

Printed per variant: the largest |u_0 - u_0 reference| [A], the QPs off by more than 1e-4 A,
HPIPM's iterations (mean, max) and its solver time per QP (CasADi's ``t_wall_solver``, the
least of ``--repeat`` solves, so without Python's call overhead: median, max, sum), with the
machine's load average.

    python bench/qp_accuracy.py [--seconds 0.1] [--repeat 21]
"""

from __future__ import annotations

import argparse
import dataclasses
import os

import casadi as ca
import numpy as np

from maglev_oc.control.nmpc import NonlinearMPC
from maglev_oc.control.nmpc.rti import qp_solver_function, rti_parts
from maglev_oc.model.stage import StageModel
from maglev_oc.sim.nmpc_instances import record_instances
from maglev_oc.sim.scenarios import paper_scenarios
from maglev_oc.sim.twin import RigTwin

_QP = ("h", "g", "a", "lba", "uba", "lbx", "ubx")


def constrained_qps(nmpc: NonlinearMPC, seconds: float) -> tuple[list[dict], ca.Function]:
    """The QPs the RTI step hands to its solver on the large step, and the QP data Function."""
    model = nmpc.model
    sc = dataclasses.replace(paper_scenarios()["large_step"], duration=seconds)
    inst = record_instances(nmpc, RigTwin(model), sc)
    parts = rti_parts(nmpc._ocp, nmpc._observer, nmpc.shift)
    layout = nmpc._layout
    mem = ca.MX.sym("memory", nmpc.n_memory)
    y = ca.MX.sym("y", 2)
    ref = ca.MX.sym("ref", 6, nmpc.grid.horizon + 1)
    x0 = nmpc._observer.state_estimate(mem[layout.observer], y)
    data = parts.qp_data(mem[layout.plan], x0, mem[layout.disturbance], ref)
    _, feasible = parts.riccati(*data[:7])
    record = ca.Function("record", [mem, y, ref], [*data[:7], feasible])
    qps = []
    for k in range(len(inst)):
        m, yk, r = inst.split(k)
        *qp, shortcut = record(m, yk, ca.reshape(ca.DM(r), 6, nmpc.grid.horizon + 1))
        if not float(shortcut):
            qps.append(dict(zip(_QP, qp, strict=True)))
    return qps, parts.qp_data


def solve(conic: ca.Function, qp: dict, repeat: int) -> tuple[np.ndarray, int, float]:
    """(x, iterations, least solver wall time [s]) of a cold-started solve."""
    nz, na = qp["g"].numel(), qp["lba"].numel()
    best = np.inf
    for _ in range(repeat):
        sol = conic(**qp, x0=ca.DM.zeros(nz), lam_x0=ca.DM.zeros(nz), lam_a0=ca.DM.zeros(na))
        stats = conic.stats()
        best = min(best, stats.get("t_wall_solver", np.nan))
    return np.array(sol["x"]).ravel(), int(stats.get("iter_count", -1)), best


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=0.1, help="of the large step [s]")
    ap.add_argument("--repeat", type=int, default=21, help="solves per QP (the least time is kept)")
    args = ap.parse_args(argv)
    nmpc = NonlinearMPC(StageModel())
    qps, qp_data = constrained_qps(nmpc, args.seconds)
    c = nmpc._ocp.cost_scale
    horizon = nmpc.grid.horizon
    sparsity = {"h": qp_data.sparsity_out("H"), "a": qp_data.sparsity_out("A")}
    qpoases = ca.conic("reference", "qpoases", sparsity, {"printLevel": "none", "error_on_fail": False})
    reference = [solve(qpoases, qp, 1)[0] for qp in qps]
    u_scale = nmpc._ocp.z_scale[:2]
    print(f"{len(qps)} constrained QPs of the large step's first {args.seconds:g} s; cost scale c = {c:g}")
    print(f"load average {os.getloadavg()[0]:.2f} (1 min)")
    variants = (
        ("before: cost / c, mu0 10", 1 / c, {"hpipm": {"mu0": 10.0}}),
        ("cost scaled, mu0 10", 1.0, {"hpipm": {"mu0": 10.0}}),
        ("now: cost scaled, mu0 100", 1.0, dict(nmpc.qp_options)),
    )
    for label, scale, options in variants:
        hpipm = qp_solver_function("hpipm", options, horizon, qp_data)
        errors, iterations, times = [], [], []
        for qp, ref in zip(qps, reference, strict=True):
            x, it, t = solve(hpipm, {**qp, "h": qp["h"] * scale, "g": qp["g"] * scale}, args.repeat)
            errors.append(np.max(np.abs(x[:2] - ref[:2]) * u_scale))
            iterations.append(it)
            times.append(t)
        e, t = np.array(errors), np.array(times) * 1e6
        print(
            f"  HPIPM {label:<28s} max |du_0| {e.max():.1e} A, {np.sum(e > 1e-4):2d} QPs > 1e-4 A; "
            f"iterations mean {np.mean(iterations):.2f} max {max(iterations)}; solver time median "
            f"{np.median(t):.1f} us, max {t.max():.1f} us, sum {t.sum():.0f} us"
        )
    print(f"load average {os.getloadavg()[0]:.2f} (1 min)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
