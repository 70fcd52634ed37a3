"""Refresh ``tests/durations.json``: the order in which the suite hands out its work.

    python bench/test_durations.py            # runs the whole suite (pytest -n 2), writes the file
    python bench/test_durations.py --from out.txt   # the output of a run with --durations=0

Runs the suite with ``--durations=0`` and keeps, per test of at least ``MIN_SECONDS``, the wall
seconds of its setup, call and teardown (``tests/conftest.py`` sums them per unit of work and
starts the longest units first). Measure on an otherwise idle machine: a stale or noisy figure
only changes the order, never what a test checks. Not run in CI.
"""

from __future__ import annotations

import argparse
import datetime
import json
import re
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET = ROOT / "tests" / "durations.json"
MIN_SECONDS = 1.0
LINE = re.compile(r"^([\d.]+)s (setup|call|teardown)\s+(\S+)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--from", dest="source", type=Path, help="a saved output of pytest --durations=0 (not run again)"
    )
    args = parser.parse_args()
    if args.source is not None:
        write(args.source.read_text(), f"the run saved in {args.source.name}")
        return
    cmd = [
        sys.executable,
        "-m",
        "pytest",
        "-p",
        "no:cacheprovider",
        "-q",
        "--durations=0",
        "--durations-min=0.05",
    ]
    out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if out.returncode not in (0, 1):
        sys.exit(f"pytest exited with {out.returncode}:\n{out.stdout[-3000:]}{out.stderr[-3000:]}")
    write(out.stdout, "pytest -n 2")


def write(stdout: str, run: str) -> None:
    """``tests/durations.json`` from the ``--durations=0`` lines of a pytest run's output."""
    seconds: dict[str, float] = defaultdict(float)
    for line in stdout.splitlines():
        m = LINE.match(line)
        if m:
            seconds[m.group(3)] += float(m.group(1))
    kept = {k: round(v, 1) for k, v in sorted(seconds.items(), key=lambda kv: -kv[1]) if v >= MIN_SECONDS}
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True)
    source = (
        f"wall seconds of setup + call + teardown per test of at least {MIN_SECONDS:g} s, {run} on "
        f"the 2-core machine, {datetime.date.today()} at {commit.stdout.strip()} (bench/test_durations.py). "
        "The order in which tests/conftest.py hands out work (a stale figure changes the order, "
        "never a result)"
    )
    TARGET.write_text(json.dumps({"source": source, "seconds": kept}, indent=1) + "\n")
    print(f"{len(kept)} tests of at least {MIN_SECONDS:g} s, {sum(kept.values()):.0f} s in all -> {TARGET}")


if __name__ == "__main__":
    main()
