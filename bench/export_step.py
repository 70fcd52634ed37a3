"""Time per call of the exported controllers (``maglev-oc export``) in a C driver.

Each controller is exported, compiled with ``-O2`` (``--cflags``) together with a small C
driver, and replayed on the readings and references of its own closed-loop run on the rig twin
(the papers' set-point steps; for the NMPC the large step, whose first samples have active
current constraints).
The driver times every ``step`` call with ``clock_gettime(CLOCK_MONOTONIC)`` and repeats the
replay (whole replays, at least ``--calls`` calls, 10^5 by default); printed: the calls timed,
median, p99, p99.9 and worst per call, the memory struct's size, and the machine's load average
(1 min) before and after each controller. ``--cpu K`` pins the driver to core K; ``--fifo P``
runs it at real-time priority P (SCHED_FIFO, as the loop of a real-time target runs: the other
jobs of a shared machine then no longer preempt it, within the kernel's real-time throttling of
5 % per second).

The NMPC is exported with each QP solver of ``--nmpc-qp`` (default both, side by side in one
run): the dual active-set method on the prepared Riccati factorization (``dual``, the default
export, budget ``--dual-iterations``) and CasADi's generated qrqp (``qrqp``, budget
``--qp-iterations``). Each is replayed a second time as on the rig, ``<prefix>_prepare`` then
``<prefix>_feedback`` every sample, each call timed apart: the feedback is the latency from the
reading to the current. Printed for it: prepare, feedback and their sum, the feedback on the
samples without and with a QP to solve, the QP's iterations and fallbacks (from the diagnostics
the C writes), and the feedback calls that had to prepare late (their reference was not the
predicted one).

The budget's worst case (dual): the same replay with the bounds of every current of the prepared
QP moved to [+1, +2] mA from the plan after each preparation, so that the unconstrained step
violates all 2 N lower bounds and every feedback solves a QP that needs more steps than the
budget: the solver runs to its budget and falls back (counted). Printed: the feedback's time
there, i.e. the feedback with the whole budget spent.

    python bench/export_step.py [--calls 100000] [--cpu 1] [--only fl pid ...] [--nmpc-qp dual qrqp]
        [--qp-iterations K] [--dual-iterations K]
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
from maglev_oc.control.export import DUAL_QP_BUDGET, QP_SOLVERS, export_controller
from maglev_oc.control.nmpc import NonlinearMPC
from maglev_oc.control.nmpc.rti import PreparedLayout
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
# latency from the reading to the current); per call also the diagnostics qp_iterations and
# solver_ok; the feedback calls that had to prepare late. With a 4th argument (stress), the
# current bounds of the prepared QP narrowed after each preparation (module docstring).
SPLIT_DRIVER = r"""
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "{prefix}.h"

#define OFF_LBX {off_lbx}
#define OFF_UBX {off_ubx}
#define N_INTERVALS {horizon}
#define I_ITER {i_iter}
#define I_OK {i_ok}

static void narrow(casadi_real* p) {{
  int j, c;
  for (j = 0; j < N_INTERVALS; ++j)
    for (c = 0; c < 2; ++c) {{
      casadi_real* lo = p + OFF_LBX + 6 * j + c;
      casadi_real* up = p + OFF_UBX + 6 * j + c;
      if (*lo < 0.001) *lo = 0.001;
      if (*up > 0.002) *up = 0.002;
    }}
}}

static double ns(struct timespec a, struct timespec b) {{
  return (b.tv_sec - a.tv_sec) * 1e9 + (b.tv_nsec - a.tv_nsec);
}}

int main(int argc, char** argv) {{
  long n = atol(argv[2]), repeat = atol(argv[3]), late = 0;
  int stress = argc > 4;
  double* data = malloc(sizeof(double) * 8 * n);  /* the driver's own buffers, not the controller's */
  double* times = malloc(sizeof(double) * 4 * n * repeat);
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
      if (stress) narrow(m.prepared);
      clock_gettime(CLOCK_MONOTONIC, &b);
      if ({prefix}_feedback(&m, data + 8 * k, data + 8 * k + 2, u)) return 3;
      clock_gettime(CLOCK_MONOTONIC, &c);
      times[4 * (rep * n + k)] = ns(a, b);
      times[4 * (rep * n + k) + 1] = ns(b, c);
      times[4 * (rep * n + k) + 2] = m.diag[I_ITER];
      times[4 * (rep * n + k) + 3] = m.diag[I_OK];
    }}
    late += (long)m.late_preparations;
  }}
  fwrite(times, sizeof(double), 4 * n * repeat, stdout);
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
    ap.add_argument("--fifo", type=int, default=None, help="run the driver at this SCHED_FIFO priority")
    ap.add_argument("--only", nargs="+", default=["fl", "linear", "lqr", "pid", "nmpc"])
    ap.add_argument("--nmpc-qp", nargs="+", default=list(QP_SOLVERS), choices=QP_SOLVERS)
    ap.add_argument(
        "--qp-iterations",
        type=int,
        default=QP_ITERATION_BUDGET,
        help="qrqp's iteration budget, as `maglev-oc export nmpc --qp-solver qrqp --qp-iterations` "
        "(default theirs)",
    )
    ap.add_argument(
        "--dual-iterations",
        type=int,
        default=DUAL_QP_BUDGET,
        help="the dual solver's budget, as `maglev-oc export nmpc --qp-iterations` (default theirs)",
    )
    ap.add_argument("--cflags", default="-O2", help="the export's compiler flags, one string (default -O2)")
    args = ap.parse_args(argv)
    cc = c_compiler()
    if cc is None:
        print("no C compiler", file=sys.stderr)
        return 1
    model = StageModel()
    pin = _placement(args.cpu, args.fifo)
    print(
        (f"pinned to core {args.cpu}" if args.cpu is not None else "not pinned")
        + (f", SCHED_FIFO priority {args.fifo}" if args.fifo is not None else "")
    )
    head = ("controller", "calls", "median", "p99", "p99.9", "worst", "memory", "load")
    print("{:<12s} {:>8s} {:>9s} {:>9s} {:>9s} {:>9s} {:>9s} {:>11s}".format(*head))
    jobs = [(name, solver) for name in args.only for solver in (args.nmpc_qp if name == "nmpc" else [None])]
    for name, solver in jobs:
        options = {}
        if name == "nmpc":
            budget = {"max_iter": args.qp_iterations}
            nmpc = NonlinearMPC(model, preview=False, qp_solver="qrqp", qp_options=budget)
            ctrl = CompiledNMPC(nmpc, backend="vm")
            options = {"qp_solver": solver}
            if solver == "dual":
                options["qp_iterations"] = args.dual_iterations
                print(
                    f"NMPC: the dual active-set QP solver with a budget of {args.dual_iterations} iterations"
                )
            else:
                print(f"NMPC: qrqp with a budget of {args.qp_iterations} iterations")
            rows = _run(ctrl, model, "large_step", 0.5)
        else:
            ctrl = build_controller(name, model)
            rows = _run(ctrl, model, "setpoint_steps", 10.0)
        with tempfile.TemporaryDirectory() as tmp:
            tmp = Path(tmp)
            e = export_controller(ctrl, tmp / "export", **options)
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
            _row(name if solver is None else f"{name} {solver}", t, e.memory_bytes, load, load_after)
            if name == "nmpc":  # the same replay through prepare and feedback
                (tmp / "split.c").write_text(SPLIT_DRIVER.format(**_split_fields(e, nmpc)))
                split = tmp / "split"
                cmd[-1] = str(tmp / "split.c")
                subprocess.run(
                    [*cmd, *map(str, e.sources), "-o", str(split), "-lm"], check=True, capture_output=True
                )
                _split_rows(split, replay, pin, e, "")
                if solver == "dual":  # the budget's worst case
                    _split_rows(split, replay, pin, e, "stress")
    return 0


def _placement(cpu: int | None, fifo: int | None):
    """The driver's preexec_fn: its core and real-time priority (None: neither)."""
    if cpu is None and fifo is None:
        return None

    def place() -> None:
        if cpu is not None:
            os.sched_setaffinity(0, {cpu})
        if fifo is not None:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(fifo))

    return place


def _split_fields(e, nmpc) -> dict[str, object]:
    """The split driver's constants: the prepared bounds' offsets, N, the diagnostics' rows."""
    offsets, k = {}, 0
    for part, size in PreparedLayout.of(nmpc._parts.qp_data).sizes:
        offsets[part] = k
        k += size
    return {
        "prefix": e.prefix,
        "off_lbx": offsets["lbx"],
        "off_ubx": offsets["ubx"],
        "horizon": nmpc.grid.horizon,
        "i_iter": e.diag_names.index("qp_iterations"),
        "i_ok": e.diag_names.index("solver_ok"),
    }


def _split_rows(split: Path, replay: list[str], pin, e, stress: str) -> None:
    """Run the split driver (prepare, then feedback, timed apart) and print its rows."""
    load = os.getloadavg()[0]
    out = subprocess.run(
        [str(split), *replay[1:], *([stress] if stress else [])],
        check=True,
        capture_output=True,
        preexec_fn=pin,
    )
    load_after = os.getloadavg()[0]
    t = np.frombuffer(out.stdout, dtype=np.float64).reshape(-1, 4)
    prep, fb, iterations, ok = t[:, 0] * 1e-3, t[:, 1] * 1e-3, t[:, 2], t[:, 3]  # [us]
    qp = iterations != 0  # a QP was solved (dual: its steps; qrqp: -1)
    mem = e.memory_bytes
    if stress:
        print(
            "  the budget's worst case: every current's bounds moved to [+1, +2] mA from the plan "
            f"({int(np.sum(qp))} of {ok.size} feedbacks solve a QP, {int(np.sum(ok == 0))} fell back, "
            f"steps max {int(iterations.max())}, budget {e.qp_iterations})"
        )
        _row("  fb, stress", fb[qp], mem, load, load_after)
        _row("  fb, budget", fb[qp & (iterations >= e.qp_iterations)], mem, load, load_after)
        return
    _row("  prepare", prep, mem, load, load_after)
    _row("  feedback", fb, mem, load, load_after)
    _row("  sum", prep + fb, mem, load, load_after)
    _row("  fb, no QP", fb[~qp], mem, load, load_after)
    _row("  fb, QP", fb[qp], mem, load, load_after)
    late = int(out.stderr.decode().split()[-1])
    steps = (
        f"; its steps mean {iterations[qp].mean():.2f}, max {int(iterations[qp].max())}"
        if np.all(iterations[qp] > 0)
        else ""
    )
    print(
        f"  feedback calls that prepared late (reference not the predicted one): {late} of "
        f"{fb.size}; feedbacks that solve the QP: {int(qp.sum())} ({100 * qp.mean():.1f} %){steps}; "
        f"fallbacks: {int(np.sum(ok == 0))}"
    )


def _row(name: str, t: np.ndarray, memory: int, load: float, load_after: float) -> None:
    p99, p999 = np.percentile(t, [99, 99.9])
    print(
        f"{name:<12s} {t.size:8d} {np.median(t):7.2f}us {p99:7.2f}us {p999:7.2f}us {t.max():7.1f}us "
        f"{memory:7d} B {load:4.2f}-{load_after:4.2f}"
    )


if __name__ == "__main__":
    raise SystemExit(main())
