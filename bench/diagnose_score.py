"""Score ``diagnose`` on sets of logs from the independent generator (no code shared with our sim).

    python bench/diagnose_score.py [--sets eleven single pairs clean] [--seed-offset N] [--rig R] [--out D]

Each set is generated once into ``OUT/logs/<set>`` (``python -m tests.independent.generate``; skipped
when present), every log diagnosed with the defaults, and scored by ``tests/independent/scoring``:
true effect first, no false claim, size within 30 %. Prints one line per log that misses a mark and
the totals per set; writes ``OUT/summary.json``. ``--seed-offset N`` adds N to every seed: the same
scenarios on fresh constants, references and noise, which no rule of the diagnosis was tuned on
(written to ``OUT/logs/<set>+N``). ``--rig NAME`` records the sets on a rig of
``bench/diagnose_rigs.py`` instead of the generator's default (``obs2800``: currents as noisy as
``../shared/logs/independent_clean.csv``'s; written to ``OUT/logs/<set>@NAME``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sets", nargs="+", default=["eleven", "single", "pairs", "clean"])
    parser.add_argument("--seed-offset", type=int, default=0, help="added to every seed (fresh draws)")
    parser.add_argument("--rig", default="default", help="a rig of bench/diagnose_rigs.py")
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "out" / "diagnose_score")
    args = parser.parse_args()
    sys.path.insert(0, str(ROOT))
    from tests.independent.core import with_generic_libm

    with_generic_libm()  # the logs the test suite generates, whatever the CPU
    from maglev_oc.data.reading import read_log
    from maglev_oc.diagnosis.pipeline import diagnose
    from tests.independent.scoring import score

    if args.rig != "default":
        from tests.independent.rigs import RIGS

        if args.rig not in RIGS:
            parser.error(f"--rig: no rig {args.rig!r}; the rigs are {', '.join(RIGS)}")

    summary: dict[str, dict] = {}
    for name in args.sets:
        folder = args.out / "logs" / (name + (f"+{args.seed_offset}" if args.seed_offset else ""))
        if args.rig != "default":
            folder = folder.with_name(f"{folder.name}@{args.rig}")
        if not any(folder.glob("*.csv")) and args.rig != "default":
            _write_on_rig(name, args.seed_offset, RIGS[args.rig], folder)
        elif not any(folder.glob("*.csv")):
            cmd = [sys.executable, "-m", "tests.independent.generate", "--set", name, "--out", str(folder)]
            cmd += ["--seed-offset", str(args.seed_offset)]
            subprocess.run(cmd, cwd=ROOT, check=True, capture_output=True)
        marks = [0, 0, 0]
        for csv in sorted(folder.glob("*.csv")):
            truth = json.loads(csv.with_suffix(".truth.json").read_text())
            t0 = time.perf_counter()
            result = diagnose([read_log(csv)]).to_dict()
            s = score(csv.stem, truth, result["effects"])
            row = {
                "truth": s.truth,
                "claimed": s.claimed,
                # what else a user reads: the residual left unnamed, and constants no rig has
                "unexplained": [f"{u['axis']}: {u['depends_on']}" for u in result["unexplained"]],
                "warnings": result["warnings"],
                "marks": [s.true_first, s.no_false_claim, s.size_right],
                "notes": s.notes,
                "wall_s": time.perf_counter() - t0,
            }
            summary[csv.stem] = row
            marks = [m + int(v) for m, v in zip(marks, row["marks"], strict=True)]
            if not all(row["marks"]) or row["unexplained"] or row["warnings"]:
                print(
                    f"{csv.stem}: marks {row['marks']}, truth {s.truth}, claimed {s.claimed}, "
                    f"unexplained {row['unexplained']}, warnings {len(row['warnings'])}",
                    flush=True,
                )
        n = len(list(folder.glob("*.csv")))
        print(f"{name}: {marks[0]}/{n} true first, {marks[1]}/{n} no false claim, {marks[2]}/{n} sized right")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")


def _write_on_rig(name: str, seed_offset: int, rig_settings: dict, folder: Path) -> None:
    """Write set ``name`` with every scenario's rig changed by ``rig_settings`` into ``folder``."""
    import dataclasses

    from tests.independent.logio import write_log
    from tests.independent.sets import named_set
    from tests.independent.simulate import simulate

    for stem, scenario in named_set(name, seed_offset=seed_offset):
        rig = dataclasses.replace(scenario.rig, **rig_settings)
        write_log(simulate(dataclasses.replace(scenario, rig=rig)), folder, stem)


if __name__ == "__main__":
    main()
