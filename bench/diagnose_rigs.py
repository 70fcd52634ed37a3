"""Score ``diagnose`` on independent logs recorded under other rig settings than the default.

    python bench/diagnose_rigs.py [--rigs log500 enc20um ...] [--out bench/out/diagnose_rigs]
    python bench/diagnose_rigs.py --experiments [steps short ...] [--out ...]

The sets of ``bench/diagnose_score.py`` all come from one rig: a 5 kHz loop logged at 1 kHz with
10 um encoders. A user's rig differs: it may log at 500 Hz or 2.5 kHz, have finer or coarser
encoders, or run its loop at 2 or 10 kHz. Each rig below records a clean log and four single
effects (large horizontal guide friction, normal cogging, a cable carrier, a commutation offset)
with the independent generator (``tests/independent``, no code shared with ``maglev_oc.sim``), each
is diagnosed with the defaults and scored as ``diagnose_score`` does: true effect first, no false
claim, size within 30 %. Prints one line per log and the totals per rig; writes
``OUT/summary.json``. Not run in CI.

``--experiments [NAME ...]``: the generator's ``experiments`` set instead (``tests/independent/sets.py``),
on the default rig: a user's experiments unlike the other sets' (set-point steps, a small
excursion, faster sines, a short log, an off-centre travel, softer and stiffer gains, constants
further from the papers'), each with a clean log and six large effects alone.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

RIGS = {
    "default": {},
    "log500": {"log_every": 10},
    "log2500": {"log_every": 2},
    "enc1um": {"encoder_resolution": 1e-6, "encoder_noise": 0.5e-6},
    "enc20um": {"encoder_resolution": 20e-6, "encoder_noise": 4e-6},
    "ctrl2k": {"control_rate": 2000.0, "log_every": 2},
    "ctrl10k": {"control_rate": 10000.0, "log_every": 10},
}
"""Rig settings (fields of ``tests.independent.simulate.Rig``) by name."""

EFFECTS = (None, "guide_friction_horizontal", "normal_cogging", "cable_carrier", "commutation_offset")
"""What each rig records: a clean log and these effects alone, at their large size."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rigs", nargs="+", default=list(RIGS), choices=list(RIGS))
    parser.add_argument(
        "--experiments", nargs="*", default=None, help="score the experiments set instead (all, or these)"
    )
    parser.add_argument("--seed", type=int, default=700, help="seed of the first log; one more per effect")
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "out" / "diagnose_rigs")
    args = parser.parse_args()
    sys.path.insert(0, str(ROOT))
    from maglev_oc.data.reading import read_log
    from maglev_oc.diagnosis.pipeline import diagnose
    from tests.independent.logio import write_log
    from tests.independent.scoring import score
    from tests.independent.sets import EXPERIMENTS, SINGLE_EFFECTS, named_set
    from tests.independent.simulate import Rig, Scenario, simulate

    groups: dict[str, list] = {}
    if args.experiments is not None:
        wanted = args.experiments or list(EXPERIMENTS)
        for stem, scenario in named_set("experiments"):
            experiment = next(e for e in EXPERIMENTS if scenario.name.startswith(e + "_"))
            if experiment in wanted:
                groups.setdefault(experiment, []).append((stem, scenario))
    else:
        for rig_name in args.rigs:
            for k, effect in enumerate(EFFECTS):
                effects = () if effect is None else (SINGLE_EFFECTS[effect]("large"),)
                stem = f"{rig_name}_{effect or 'clean'}"
                scenario = Scenario(name=stem, seed=args.seed + k, effects=effects, rig=Rig(**RIGS[rig_name]))
                groups.setdefault(rig_name, []).append((stem, scenario))
    summary: dict[str, dict] = {}
    totals = [0, 0, 0]
    for group, scenarios in groups.items():
        marks = [0, 0, 0]
        for stem, scenario in scenarios:
            csv, truth_path = write_log(simulate(scenario), args.out / "logs", stem)
            t0 = time.perf_counter()
            result = diagnose([read_log(csv)]).to_dict()
            s = score(stem, json.loads(truth_path.read_text()), result["effects"])
            row = {
                "scenario": scenario.name,
                "truth": s.truth,
                "claimed": s.claimed,
                "not_separable": [n["name"] for n in result["not_separable"]],
                "unexplained": [f"{u['axis']}: {u['depends_on']}" for u in result["unexplained"]],
                "marks": [s.true_first, s.no_false_claim, s.size_right],
                "notes": s.notes,
                "wall_s": time.perf_counter() - t0,
            }
            summary[stem] = row
            marks = [m + int(v) for m, v in zip(marks, row["marks"], strict=True)]
            flags = "".join("x" if v else "." for v in row["marks"])
            print(
                f"{stem:16s} {scenario.name:38s} {flags}  claimed {s.claimed}  "
                f"unexplained {row['unexplained']}  {'; '.join(s.notes)}  ({row['wall_s']:.1f} s)",
                flush=True,
            )
        n = len(scenarios)
        totals = [t + m for t, m in zip(totals, marks, strict=True)]
        print(
            f"{group}: {marks[0]}/{n} true first, {marks[1]}/{n} no false claim, {marks[2]}/{n} sized right"
        )
    n = sum(len(v) for v in groups.values())
    print(f"all: {totals[0]}/{n} true first, {totals[1]}/{n} no false claim, {totals[2]}/{n} sized right")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")


if __name__ == "__main__":
    main()
