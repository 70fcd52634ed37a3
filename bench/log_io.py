"""Benchmark: reading logs, and the independent generator's speed (timings out of the tests);
with ``--memory``, the peak memory of reading and diagnosing a long log at the rig's rate.

    python bench/log_io.py [--memory]

Reads a 60 s log at the rig's 5 kHz (300 000 rows, full-precision values) with ``read_log``, and
simulates one 60 s scenario with the independent generator (tests/independent: a 5 kHz FL loop
in its own C code, logged at 1 kHz). ``--memory``: a 10-minute closed-loop log logged at the
loop's 5 kHz (3 M rows) by the same generator; ``read_log`` and ``maglev-oc diagnose`` each run in
a fresh process whose peak resident memory (``ru_maxrss``) is printed, also per million rows.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from common import best_of, fmt, machine

from maglev_oc.data.reading import read_log
from maglev_oc.data.writing import write_log_arrays


def _log_file(path: Path, n: int, dt: float) -> Path:
    t = np.arange(n) * dt
    x = np.vstack(
        [
            0.020 + 0.002 * np.sin(2 * np.pi * 1.3 * t),
            0.002 * 2 * np.pi * 1.3 * np.cos(2 * np.pi * 1.3 * t),
            0.010 * np.sin(2 * np.pi * 0.7 * t + 0.4),
            0.010 * 2 * np.pi * 0.7 * np.cos(2 * np.pi * 0.7 * t + 0.4),
        ]
    )
    u = np.vstack([0.8 * np.sin(2 * np.pi * 2.1 * t), 1.5 + 0.4 * np.cos(2 * np.pi * 0.9 * t)])
    return write_log_arrays(path, t, x, u)


def _peak_memory(code: str) -> tuple[float, float]:
    """(peak resident memory [MB], wall time [s]) of running ``code`` in a fresh Python."""
    # VmHWM: this process's peak (ru_maxrss would include the parent's, kept across exec)
    report = "\nprint([ln.split()[1] for ln in open('/proc/self/status') if ln.startswith('VmHWM')][0])"
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", code + report], check=True, capture_output=True, text=True)
    return int(out.stdout.split()[-1]) / 1024, time.perf_counter() - t0


def memory() -> None:
    from tests.independent.logio import write_log
    from tests.independent.simulate import Rig, Scenario, simulate

    with tempfile.TemporaryDirectory() as tmp:
        run = simulate(Scenario(name="long", seed=7, duration=600.0, rig=Rig(log_every=1)))
        csv, _ = write_log(run, tmp)
        rows = run.t.size
        print(f"10-minute log at 5 kHz: {rows} rows, {csv.stat().st_size / 1e6:.0f} MB CSV")
        out = str(Path(tmp) / "d.json")
        runs = {
            "imports alone": "import maglev_oc.diagnosis.pipeline",
            "read_log": f"from maglev_oc.data.reading import read_log; read_log({str(csv)!r})",
            "diagnose": "from maglev_oc.cli import main; "
            f"main(['diagnose', {str(csv)!r}, '--json', {out!r}])",
        }
        base = None
        for label, code in runs.items():
            peak, wall = _peak_memory(code)
            base = peak if base is None else base
            per_million = (peak - base) * 1e6 / rows
            above = f"{per_million:4.0f} MB per million rows above the imports"
            print(f"  {label:14s} peak {peak:6.0f} MB ({above}), {wall:.1f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--memory", action="store_true", help="peak memory on a 10-minute 5 kHz log")
    args = parser.parse_args()
    root = Path(__file__).resolve().parents[1]
    sys.path.insert(0, str(root))
    if args.memory:
        memory()
        return
    from tests.independent.simulate import Scenario, simulate

    print(f"machine: {machine()}")
    with tempfile.TemporaryDirectory() as tmp:
        path = _log_file(Path(tmp) / "big.csv", 300_000, 2e-4)
        best, median = best_of(lambda: read_log(path), repeat=3)
        size = path.stat().st_size / 1e6
        print(
            f"read_log, 60 s at 5 kHz (300 000 rows, {size:.0f} MB): best {fmt(best)}, median {fmt(median)}"
        )
    best, median = best_of(lambda: simulate(Scenario(name="speed", seed=1, duration=60.0)), repeat=3)
    label = "independent generator, 60 s scenario (5 kHz loop, 1 kHz log)"
    print(f"{label}: best {fmt(best)}, median {fmt(median)}")


if __name__ == "__main__":
    main()
