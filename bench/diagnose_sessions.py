"""Score ``diagnose`` on several logs of one rig diagnosed together: a session recorded while the
magnets warm up.

    python bench/diagnose_sessions.py [--seed 7501] [--out bench/out/diagnose_sessions]

Each session is a few 60 s logs of one rig (the same true constants; each log its own reference and
noise, from its own seed) from the independent generator (``tests/independent``, no code shared
with ``maglev_oc.sim``), recorded some time after the rig was switched on
(``MagnetWarming.start_time``): the magnets warm towards their running temperature over the whole
session, so each log drifts by its own amount and runs at its own mean field. All logs of a session
are diagnosed in one call, as a user hands them to ``maglev-oc diagnose``.

Scored per session: the effects claimed are the true ones (the magnets' drift where they warm, and
the session's other effect); each log's field change within 30 % of the truth (the issue's bound)
or, where the truth is below 0.1 % of the field, within 0.03 % (a tenth of the small warming's
change over a log); each log's field level against the logs' mean likewise. Prints a line per log
and writes ``OUT/summary.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.independent.core import with_generic_libm  # noqa: E402

SMALL_CHANGE = 1e-3
"""Below this relative change of the field a log's drift is judged in absolute terms."""
ABSOLUTE_TOLERANCE = 3e-4
"""[1] The absolute tolerance there: a tenth of the small warming's change over a 60 s log."""


def sessions() -> dict:
    """The sessions by name: (start times of the logs [s], the warming or None, other effects)."""
    from tests.independent import effects as E

    large = E.MagnetWarming.large()  # 15 K, time constant 60 s
    small = E.MagnetWarming.small()  # 6 K, time constant 120 s
    return {
        "cold_start_3": ((0.0, 90.0, 180.0), large, ()),
        "cold_start_then_steady": ((0.0, 600.0), large, ()),
        "slow_warming_3": ((0.0, 80.0, 160.0), small, ()),
        "clean_3": ((0.0, 90.0, 180.0), None, ()),
        "cold_start_3+lag": ((0.0, 90.0, 180.0), large, (E.AmplifierDynamics.large(),)),
        "cold_start_3+friction_h": ((0.0, 90.0, 180.0), large, (E.GuideFriction.large("horizontal"),)),
        "cold_start_2+cogging": ((0.0, 90.0), large, (E.NormalCogging.large(),)),
    }


def _judge(found: float, truth: float) -> bool:
    if abs(truth) < SMALL_CHANGE:
        return abs(found - truth) <= ABSOLUTE_TOLERANCE
    return abs(found - truth) <= 0.3 * abs(truth)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seed", type=int, default=7501, help="seed of the first log; one more per log")
    parser.add_argument("--only", nargs="*", default=None, help="only these sessions")
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "out" / "diagnose_sessions")
    args = parser.parse_args()
    with_generic_libm()  # the logs the test suite generates, whatever the CPU
    import dataclasses

    from maglev_oc.data.reading import read_log
    from maglev_oc.diagnosis.pipeline import diagnose
    from tests.independent.logio import write_log
    from tests.independent.scoring import SIZE_TOLERANCE, _name_for, sizes
    from tests.independent.simulate import Scenario, simulate

    summary, seed, totals = {}, args.seed, [0, 0, 0]
    for name, (starts, warming, others) in sessions().items():
        if args.only and name not in args.only:
            seed += len(starts)
            continue
        folder = args.out / "logs" / name
        paths, truths, constants = [], [], None
        for k, start in enumerate(starts):
            effects = (
                *others,
                *(() if warming is None else (dataclasses.replace(warming, start_time=start),)),
            )
            run = simulate(Scenario(name=f"{name}_{k + 1}", seed=seed, effects=effects, constants=constants))
            seed += 1
            if constants is None:  # one rig: the first log's drawn constants for every log
                constants = tuple(run.truth["plant"]["constants_true"][c] for c in ("C1", "C2", "C3", "C4"))
            paths.append(write_log(run, folder)[0])
            w = effects[-1] if warming is not None else None
            t = run.t - run.t[0]
            truths.append(
                (
                    0.0 if w is None else w.change_over_log(float(t[-1])),
                    1.0 if w is None else float(np.mean([w.field_factor(v) for v in t])),
                )
            )
        t0 = time.perf_counter()
        d = diagnose([read_log(p) for p in paths]).to_dict()
        seconds = time.perf_counter() - t0
        claimed = [e["name"] for e in d["effects"]]
        expected = {"magnet_field_drift"} if warming is not None else set()
        expected |= {_name_for(_truth_entry(e))[0] for e in others}
        right_claims = set(claimed) == expected
        levels = np.array([m for _, m in truths])
        levels = levels / levels.mean() - 1.0  # each log's mean field against the logs' mean
        drift = next((e["parameters"] for e in d["effects"] if e["name"] == "magnet_field_drift"), None)
        rows, sized = [], True
        for k, (change, _) in enumerate(truths):
            tag = f"_in_log{k + 1}" if len(paths) > 1 else "_over_log"
            found_change = drift[f"field_change{tag}"] if drift else 0.0
            found_level = drift.get(f"field_level{tag}", 0.0) if drift else 0.0
            ok = _judge(found_change, change) and _judge(found_level, float(levels[k]))
            sized &= ok if warming is not None else True
            rows.append(
                {
                    "log": paths[k].name,
                    "change": [change, found_change],
                    "level": [float(levels[k]), found_level],
                    "sized": ok,
                }
            )
        # the session's other effects sized as on one log (the first log's truth; one rig)
        first = json.loads(paths[0].with_suffix(".truth.json").read_text())
        for true in first["effects"]:
            if true["kind"] == "magnet_warming":
                continue
            found = next((e for e in d["effects"] if e["name"] in _name_for(true)), None)
            pair = None if found is None else sizes(true, found)
            ok = pair is not None and abs(pair[1] - pair[0]) <= SIZE_TOLERANCE * abs(pair[0])
            sized &= ok
            rows.append({"log": f"{true['kind']} (every log)", "size": pair, "sized": ok})
        marks = [right_claims, not (set(claimed) - expected), sized]
        totals = [a + int(b) for a, b in zip(totals, marks, strict=True)]
        summary[name] = {"claimed": claimed, "expected": sorted(expected), "marks": marks, "logs": rows}
        summary[name]["seconds"] = round(seconds, 1)
        print(f"{name}: claimed {claimed}, marks {marks}, {seconds:.1f} s")
        for r in rows:
            if "size" in r:
                print(f"   {r['log']:24s} size {r['size']}{'' if r['sized'] else '  (off)'}")
                continue
            print(
                f"   {r['log']:24s} change {100 * r['change'][0]:+.3f} % "
                f"found {100 * r['change'][1]:+.3f} %, "
                f"level {100 * r['level'][0]:+.3f} % found {100 * r['level'][1]:+.3f} %"
                f"{'' if r['sized'] else '  (off)'}"
            )
    print(f"sessions: all true effects claimed / no false claim / drifts sized: {totals} of {len(summary)}")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1))


def _truth_entry(effect) -> dict:
    """What the scoring reads of a generator effect (its truth file's entry, without the derived sizes)."""
    return {"kind": effect.kind, "axis": effect.axis_name(), "parameters": effect.parameters()}


if __name__ == "__main__":
    main()
