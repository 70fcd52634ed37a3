"""Time per call of the exported controllers (``maglev-oc export``) in a C driver.

Each controller is exported, compiled with ``-O2`` together with a small C driver, and replayed
on the readings and references of its own closed-loop run on the rig twin (the papers' set-point
steps; for the NMPC the large step, whose first samples have active current constraints).
The driver times every ``step`` call with ``clock_gettime(CLOCK_MONOTONIC)`` and repeats the
replay (whole replays, at least ``--calls`` calls, 10^5 by default); printed: the calls timed,
median, p99, p99.9 and worst per call, the memory struct's size, and the machine's load average
(1 min) before and after each controller. ``--cpu K`` pins the driver to core K.

    python bench/export_step.py [--calls 100000] [--cpu 1] [--only fl pid ...]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from maglev_oc.cli import QP_ITERATION_BUDGET
from maglev_oc.control.export import export_controller
from maglev_oc.control.nmpc import NonlinearMPC
from maglev_oc.control.registry import build_controller
from maglev_oc.model.stage import StageModel
from maglev_oc.numerics import c_compiler
from maglev_oc.sim.compiled_nmpc import CompiledNMPC
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.scenarios import paper_scenarios
from maglev_oc.sim.twin import RigTwin

DRIVER = r"""
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "{prefix}.h"

int main(int argc, char** argv) {{
  long n = atol(argv[2]), repeat = atol(argv[3]);
  double* data = malloc(sizeof(double) * 8 * n);  /* the driver's own buffers, not the controller's */
  double* times = malloc(sizeof(double) * n * repeat);
  FILE* f = fopen(argv[1], "rb");
  if (fread(data, sizeof(double), 8 * n, f) != (size_t)(8 * n)) return 2;
  fclose(f);
  static {prefix}_mem m;
  double u[2], u0[2] = {{0, 0}};
  for (long rep = 0; rep < repeat; ++rep) {{
    {prefix}_init(&m, data, data + 2, u0);
    for (long k = 0; k < n; ++k) {{
      struct timespec a, b;
      clock_gettime(CLOCK_MONOTONIC, &a);
      if ({prefix}_step(&m, data + 8 * k, data + 8 * k + 2, u)) return 3;
      clock_gettime(CLOCK_MONOTONIC, &b);
      times[rep * n + k] = (b.tv_sec - a.tv_sec) * 1e9 + (b.tv_nsec - a.tv_nsec);
    }}
  }}
  fwrite(times, sizeof(double), n * repeat, stdout);
  return 0;
}}
"""


def _run(ctrl, model, scenario: str, seconds: float):
    sc = dataclasses.replace(paper_scenarios()[scenario], duration=seconds)
    res = ClosedLoop(RigTwin(model), ctrl).run(sc)
    return np.vstack([res.y, res.reference])  # (8, n): y (2), r (6) per sample


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=100_000, help="at least this many timed calls")
    ap.add_argument("--cpu", type=int, default=None, help="pin the driver to this core")
    ap.add_argument("--only", nargs="+", default=["fl", "linear", "lqr", "pid", "nmpc"])
    ap.add_argument(
        "--qp-iterations",
        type=int,
        default=QP_ITERATION_BUDGET,
        help="the NMPC's QP iteration budget, as `maglev-oc export nmpc --qp-iterations` (default theirs)",
    )
    args = ap.parse_args(argv)
    cc = c_compiler()
    if cc is None:
        print("no C compiler", file=sys.stderr)
        return 1
    model = StageModel()
    pin = None if args.cpu is None else (lambda: os.sched_setaffinity(0, {args.cpu}))
    print(f"pinned to core {args.cpu}" if pin else "not pinned")
    head = ("controller", "calls", "median", "p99", "p99.9", "worst", "memory", "load")
    print("{:<12s} {:>8s} {:>9s} {:>9s} {:>9s} {:>9s} {:>9s} {:>11s}".format(*head))
    for name in args.only:
        if name == "nmpc":
            budget = {"max_iter": args.qp_iterations}
            nmpc = NonlinearMPC(model, preview=False, qp_solver="qrqp", qp_options=budget)
            ctrl = CompiledNMPC(nmpc, backend="vm")
            print(f"NMPC: qrqp with a budget of {args.qp_iterations} iterations")
            rows = _run(ctrl, model, "large_step", 0.5)
        else:
            ctrl = build_controller(name, model)
            rows = _run(ctrl, model, "setpoint_steps", 10.0)
        with tempfile.TemporaryDirectory() as tmp:
            tmp = Path(tmp)
            e = export_controller(ctrl, tmp / "export")
            (tmp / "driver.c").write_text(DRIVER.format(prefix=e.prefix))
            exe = tmp / "driver"
            cmd = [cc, "-std=c99", "-O2", f"-I{e.directory}", str(tmp / "driver.c"), *map(str, e.sources)]
            subprocess.run([*cmd, "-o", str(exe), "-lm"], check=True, capture_output=True)
            data = tmp / "data.bin"
            np.ascontiguousarray(rows.T).tofile(data)
            n = rows.shape[1]
            repeat = max(1, math.ceil(args.calls / n))
            replay = [str(exe), str(data), str(n), str(repeat)]
            load = os.getloadavg()[0]
            out = subprocess.run(replay, check=True, capture_output=True, preexec_fn=pin)
            load_after = os.getloadavg()[0]
            t = np.frombuffer(out.stdout, dtype=np.float64) * 1e-3  # [us]
        p99, p999 = np.percentile(t, [99, 99.9])
        print(
            f"{name:<12s} {t.size:8d} {np.median(t):7.2f}us {p99:7.2f}us {p999:7.2f}us {t.max():7.1f}us "
            f"{e.memory_bytes:7d} B {load:4.2f}-{load_after:4.2f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
