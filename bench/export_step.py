"""Time per call of the exported controllers (``maglev-oc export``) in a C driver.

Each controller is exported, compiled with ``-O2`` (``--cflags``) together with a small C
driver, and replayed on the readings and references of its own closed-loop run on the rig twin
(the papers' set-point steps; for the NMPC the large step, whose first samples have active
current constraints).
The driver times every ``step`` call with ``clock_gettime(CLOCK_MONOTONIC)`` and repeats the
replay (whole replays, at least ``--calls`` calls, 10^5 by default); printed: the calls timed,
median, p99, p99.9 and worst per call, the memory struct's size, and the machine's load average
(1 min) before and after each controller. ``--cpu K`` pins the driver to core K.

The NMPC is replayed a second time as on the rig, ``<prefix>_prepare`` then
``<prefix>_feedback`` every sample, each call timed apart: the feedback is the latency from the
reading to the current. Printed for it: prepare, feedback and their sum, the feedback on the
samples without and with a QP to solve, and the feedback calls that had to prepare late (their
reference was not the predicted one).

    python bench/export_step.py [--calls 100000] [--cpu 1] [--only fl pid ...] [--qp-iterations K]
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

# The NMPC as on the rig: prepare (timed), then feedback with the reading (timed apart: the
# latency from the reading to the current); also the feedback calls that had to prepare late.
SPLIT_DRIVER = r"""
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "{prefix}.h"

static double ns(struct timespec a, struct timespec b) {{
  return (b.tv_sec - a.tv_sec) * 1e9 + (b.tv_nsec - a.tv_nsec);
}}

int main(int argc, char** argv) {{
  long n = atol(argv[2]), repeat = atol(argv[3]), late = 0;
  double* data = malloc(sizeof(double) * 8 * n);  /* the driver's own buffers, not the controller's */
  double* times = malloc(sizeof(double) * 2 * n * repeat);
  FILE* f = fopen(argv[1], "rb");
  if (fread(data, sizeof(double), 8 * n, f) != (size_t)(8 * n)) return 2;
  fclose(f);
  static {prefix}_mem m;
  double u[2], u0[2] = {{0, 0}};
  for (long rep = 0; rep < repeat; ++rep) {{
    {prefix}_init(&m, data, data + 2, u0);
    for (long k = 0; k < n; ++k) {{
      struct timespec a, b, c;
      clock_gettime(CLOCK_MONOTONIC, &a);
      if ({prefix}_prepare(&m)) return 3;
      clock_gettime(CLOCK_MONOTONIC, &b);
      if ({prefix}_feedback(&m, data + 8 * k, data + 8 * k + 2, u)) return 3;
      clock_gettime(CLOCK_MONOTONIC, &c);
      times[2 * (rep * n + k)] = ns(a, b);
      times[2 * (rep * n + k) + 1] = ns(b, c);
    }}
    late += (long)m.late_preparations;
  }}
  fwrite(times, sizeof(double), 2 * n * repeat, stdout);
  fprintf(stderr, "%ld\n", late);
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
    ap.add_argument("--cflags", default="-O2", help="the export's compiler flags, one string (default -O2)")
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
            cmd = [cc, "-std=c99", *args.cflags.split(), f"-I{e.directory}", str(tmp / "driver.c")]
            subprocess.run(
                [*cmd, *map(str, e.sources), "-o", str(exe), "-lm"], check=True, capture_output=True
            )
            data = tmp / "data.bin"
            np.ascontiguousarray(rows.T).tofile(data)
            n = rows.shape[1]
            repeat = max(1, math.ceil(args.calls / n))
            replay = [str(exe), str(data), str(n), str(repeat)]
            load = os.getloadavg()[0]
            out = subprocess.run(replay, check=True, capture_output=True, preexec_fn=pin)
            load_after = os.getloadavg()[0]
            t = np.frombuffer(out.stdout, dtype=np.float64) * 1e-3  # [us]
            _row(name, t, e.memory_bytes, load, load_after)
            if name == "nmpc":  # the same replay through prepare and feedback
                (tmp / "split.c").write_text(SPLIT_DRIVER.format(prefix=e.prefix))
                split = tmp / "split"
                cmd[-1] = str(tmp / "split.c")
                subprocess.run(
                    [*cmd, *map(str, e.sources), "-o", str(split), "-lm"], check=True, capture_output=True
                )
                load = os.getloadavg()[0]
                out = subprocess.run(
                    [str(split), *replay[1:]], check=True, capture_output=True, preexec_fn=pin
                )
                load_after = os.getloadavg()[0]
                t = np.frombuffer(out.stdout, dtype=np.float64).reshape(-1, 2) * 1e-3  # [us]
                _row("  prepare", t[:, 0], e.memory_bytes, load, load_after)
                _row("  feedback", t[:, 1], e.memory_bytes, load, load_after)
                _row("  sum", t.sum(axis=1), e.memory_bytes, load, load_after)
                qp = np.tile(_qp_samples(ctrl, rows), repeat)
                _row("  fb, no QP", t[~qp, 1], e.memory_bytes, load, load_after)
                _row("  fb, QP", t[qp, 1], e.memory_bytes, load, load_after)
                late = int(out.stderr.decode().split()[-1])
                print(
                    f"  feedback calls that prepared late (reference not the predicted one): {late} of "
                    f"{t.shape[0]}; samples whose feedback solves the QP: {int(qp.sum()) // repeat} of "
                    f"{n} per replay"
                )
    return 0


def _row(name: str, t: np.ndarray, memory: int, load: float, load_after: float) -> None:
    p99, p999 = np.percentile(t, [99, 99.9])
    print(
        f"{name:<12s} {t.size:8d} {np.median(t):7.2f}us {p99:7.2f}us {p999:7.2f}us {t.max():7.1f}us "
        f"{memory:7d} B {load:4.2f}-{load_after:4.2f}"
    )


def _qp_samples(ctrl, rows: np.ndarray) -> np.ndarray:
    """(n,) bool: the samples of the replay at which the step solves the QP (qp_iterations != 0),
    from the controller's own Function in CasADi's virtual machine."""
    c = ctrl.initial_state(rows[0:2, 0], rows[2:8, 0], np.zeros(2))
    k_iter = list(ctrl.diag_names).index("qp_iterations")
    out = np.zeros(rows.shape[1], dtype=bool)
    for k in range(rows.shape[1]):
        _, c, diag = ctrl.step(c, rows[0:2, k], rows[2:8, k])
        out[k] = float(diag[k_iter]) != 0
    return out


if __name__ == "__main__":
    raise SystemExit(main())
