"""Benchmark: diagnose 60 s logs at 1 kHz (the issue asks for under 30 s on this machine).

The logs come from the independent generator (tests/independent), not from the project's twin:
the clean log, one with friction on both axes, one with two cogging forces, one with the papers'
hardware (friction and misalignment). Run from the repository root:

    python bench/diagnose_speed.py
"""

from __future__ import annotations

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
        print(f"machine: {machine()}")
        for stem, what in LOGS.items():
            log = read_log(Path(tmp) / f"{stem}.csv")
            runs = []
            for _ in range(2):
                t0 = time.perf_counter()
                d = diagnose([log])
                runs.append(time.perf_counter() - t0)
            found = ", ".join(e.name for e in d.effects) or "nothing"
            print(f"{stem} ({what}; found {found}): best {min(runs):.2f} s, worst {max(runs):.2f} s")
            print("  stages (last run): " + ", ".join(f"{k} {v:.2f} s" for k, v in d.timings.items()))


if __name__ == "__main__":
    main()
