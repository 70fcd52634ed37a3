"""Command line: write a named set of logs and their truth files.

Run from the repository root::

    python -m tests.independent.generate --set eleven --out /tmp/eleven [--duration 60]
    python -m tests.independent.generate --list

For every scenario of the set it writes ``<stem>.csv`` (SPEC 2 log) and ``<stem>.truth.json``,
and at the end ``<set>.index.json`` mapping each stem to its scenario name, seed and effects.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from .core import with_generic_libm
from .logio import write_log
from .sets import SET_NAMES, named_set
from .simulate import SimulationError, simulate


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status."""
    ap = argparse.ArgumentParser(
        prog="python -m tests.independent.generate",
        description="Independent simulator of the 2-DOF maglev stage: write a named set of closed-loop "
        "logs (1 kHz CSV) and their truth files.",
    )
    ap.add_argument("--set", choices=SET_NAMES, help="which set to write")
    ap.add_argument("--out", type=Path, help="output directory (created if needed)")
    ap.add_argument("--duration", type=float, default=60.0, help="length of each log [s] (default 60)")
    ap.add_argument(
        "--seed-offset", type=int, default=0, help="added to every seed: the set on fresh draws (default 0)"
    )
    ap.add_argument("--only", nargs="*", default=None, help="write only these stems (e.g. eleven_03)")
    ap.add_argument("--list", action="store_true", help="list the sets and their scenarios, write nothing")
    args = ap.parse_args(argv)
    if argv is None:  # the command line: the logs the test suite's workers generate
        with_generic_libm()

    if args.list:
        for name in SET_NAMES:
            print(f"{name}:")
            for stem, sc in named_set(name, args.duration):
                kinds = ", ".join(e.key() for e in sc.effects) or "no effect"
                print(f"  {stem}  seed {sc.seed:4d}  {sc.name}  [{kinds}]")
        return 0
    if args.set is None or args.out is None:
        ap.error("--set and --out are required (or --list)")
    if args.duration <= 0:
        ap.error("--duration must be positive [s]")

    scenarios = named_set(args.set, args.duration, args.seed_offset)
    if args.only:
        unknown = set(args.only) - {stem for stem, _ in scenarios}
        if unknown:
            ap.error(f"--only: no such stem in set {args.set}: {', '.join(sorted(unknown))}")
        scenarios = [(s, sc) for s, sc in scenarios if s in args.only]
    index = {}
    for stem, sc in scenarios:
        t0 = time.perf_counter()
        try:
            run = simulate(sc)
        except SimulationError as err:
            print(f"error: {err}", file=sys.stderr)
            return 1
        csv_path, _ = write_log(run, args.out, stem)
        index[stem] = {
            "scenario": sc.name,
            "seed": sc.seed,
            "effects": [e.key() for e in sc.effects],
            "truth": f"{stem}.truth.json",
        }
        print(f"{csv_path}  ({sc.name}, {time.perf_counter() - t0:.2f} s)")
    if not args.only:
        (args.out / f"{args.set}.index.json").write_text(json.dumps(index, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
