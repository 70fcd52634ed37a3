"""Benchmark: diagnose 60 s logs at 1 kHz (the issue asks for under 30 s on this machine).

The logs come from the independent generator (tests/independent), not from the project's twin:
the clean log, one with friction on both axes, one with two cogging forces, one with the papers'
hardware (friction and misalignment). Each is diagnosed twice with the detection limits and twice
without (``diagnose(limits=False)``, ``--no-limits``), then once by the whole command,
``maglev-oc diagnose LOG --json OUT`` in a new process (start-up, reading, the diagnosis, the stage
file and the JSON). The start-up depends on whether Python may write bytecode: where
``PYTHONDONTWRITEBYTECODE`` is set and the installed packages were not compiled (``uv pip install``
without ``--compile-bytecode``), every process compiles the libraries' sources again (measured
2026-12-01: 8.5 s to import the diagnosis against 2.9 s compiled). Run from the repository root:

    python bench/diagnose_speed.py
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import machine

from maglev_oc.data.logs import read_log
from maglev_oc.diagnosis.pipeline import diagnose

LOGS = {
    "eleven_04": "clean",
    "eleven_06": "guide friction, both axes",
    "eleven_09": "normal cogging and detent",
    "eleven_02": "friction and misalignment",
}


def main() -> None:
    root = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run(
            [sys.executable, "-m", "tests.independent.generate", "--set", "eleven", "--out", tmp],
            cwd=root,
            check=True,
            capture_output=True,
        )
        bytecode = "not written" if os.environ.get("PYTHONDONTWRITEBYTECODE") else "written"
        print(f"machine: {machine()}; bytecode {bytecode}")
        command = shutil.which("maglev-oc")
        for stem, what in LOGS.items():
            path = Path(tmp) / f"{stem}.csv"
            log = read_log(path)
            for limits in (True, False):
                runs = []
                for _ in range(2):
                    t0 = time.perf_counter()
                    d = diagnose([log], limits=limits)
                    runs.append(time.perf_counter() - t0)
                found = ", ".join(e.name for e in d.effects) or "nothing"
                label = "with limits" if limits else "without limits"
                best, worst = min(runs), max(runs)
                print(f"{stem} ({what}; found {found}), {label}: best {best:.2f} s, worst {worst:.2f} s")
                print("  stages (last run): " + ", ".join(f"{k} {v:.2f} s" for k, v in d.timings.items()))
            if command is not None:
                t0 = time.perf_counter()
                subprocess.run(
                    [command, "diagnose", str(path), "--json", str(Path(tmp) / f"{stem}.json")],
                    check=True,
                    capture_output=True,
                )
                print(f"  maglev-oc diagnose (a new process, with limits): {time.perf_counter() - t0:.2f} s")


if __name__ == "__main__":
    main()
