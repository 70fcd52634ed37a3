"""How often the check of the model's conventions refuses a log it should not, and names the slips
of logs recorded another way (``maglev_oc.regression.conventions``).

    python bench/conventions.py --set eleven [clean ...] [--seed-offset 39000] [--out bench/out/conventions]
    python bench/conventions.py --logs 'DIR/*.csv' [...] [--limit 200]

Each log (of a named set of the independent generator, ``tests/independent``, no code shared with
``maglev_oc.sim``, written to OUT/logs; or CSV files given) is checked as recorded, which must show
no slip, and edited five ways a user's recording might differ: x3 counted the other way, u1 or u2
with the other sign, u1 and u2 exchanged, and exchanged with x3 the other way, each of which must
show the slips it makes. Prints one line per log with a mark per edit, the totals, the largest
margins of the logs as recorded (how close the exchanged columns came to the factor that reads an
exchange, and the smallest C1 and C3 in standard errors) and the check's time; writes
``OUT/summary.json``. Not run in CI.
"""

from __future__ import annotations

import argparse
import dataclasses
import glob
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from maglev_oc.data.reading import read_log
from maglev_oc.model.stage import StageModel
from maglev_oc.regression.conventions import SLIP_SIGMAS, SWAP_FACTOR, _base, _exchanged, convention_slips
from maglev_oc.regression.data import prepare

EXCHANGED = "u1 and u2 look exchanged"
THRUST = "the thrust acts with the other sign"
LEVITATION = "the levitating current acts with the other sign"
EDITS = {
    "x3 reversed": ({"x3": -1.0}, [THRUST]),
    "u1 reversed": ({"u1": -1.0}, [THRUST]),
    "u2 reversed": ({"u2": -1.0}, [LEVITATION]),
    "exchanged": ({"exchange": True}, [EXCHANGED]),
    "exchanged, x3 reversed": ({"exchange": True, "x3": -1.0}, [EXCHANGED, THRUST]),
}
BANDWIDTH = 10.0  # [Hz] the diagnosis's (identify's 8 Hz gives the same verdicts on these logs)


def _edited(log, *, exchange=False, x3=1.0, u1=1.0, u2=1.0):
    x, u = log.x.copy(), log.u.copy()
    if exchange:
        u = u[::-1].copy()
    x[2:] *= x3
    u *= np.array([[u1], [u2]])
    return dataclasses.replace(log, x=x, u=u)


def _margins(prepared, model) -> dict:
    """How far a log as recorded is from each rule: the exchanged columns' closeness per axis (the
    rule reads an exchange when a moving axis's exceeds SWAP_FACTOR) and C1, C3 in standard errors
    (a slip below -SLIP_SIGMAS)."""
    fit = prepared.valid
    as_logged, rms = _base(prepared, model, fit)
    _, rms_swapped = _base(_exchanged(prepared), model, fit)
    z = {c: as_logged.value(c) / as_logged.stderr(c) for c in ("C1", "C3")}
    close = [float(rms[k] / rms_swapped[k]) if prepared.moving[k] else math.nan for k in range(2)]
    return {
        "closeness": float(np.nanmax(close)) if np.any(prepared.moving) else math.nan,
        "closeness_vertical": close[0],
        "closeness_horizontal": close[1],
        "C1_z": float(z["C1"]) if prepared.moving[1] else math.nan,
        "C3_z": float(z["C3"]) if prepared.moving[0] else math.nan,
    }


def _logs(args) -> list[Path]:
    paths = sorted({Path(p) for pattern in args.logs for p in glob.glob(pattern)})
    if args.set:
        from tests.independent.logio import write_log
        from tests.independent.sets import named_set
        from tests.independent.simulate import simulate

        for name in args.set:
            for stem, scenario in named_set(name, seed_offset=args.seed_offset):
                csv = args.out / "logs" / name / f"{stem}.csv"
                if not csv.exists():
                    csv, _ = write_log(simulate(scenario), args.out / "logs" / name, stem=stem)
                paths.append(csv)
    return paths[: args.limit] if args.limit else paths


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--set", nargs="+", default=[], help="named sets of the independent generator")
    p.add_argument("--logs", nargs="+", default=[], help="CSV files (glob patterns)")
    p.add_argument("--seed-offset", type=int, default=0, help="fresh draws of the sets (named_set)")
    p.add_argument("--limit", type=int, default=0)
    p.add_argument("--out", type=Path, default=Path("bench/out/conventions"))
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    model = StageModel()
    rows, spent = [], []
    for path in _logs(args):
        log = read_log(path)
        t0 = time.perf_counter()
        prepared = prepare([log], model=model, bandwidth=BANDWIDTH)
        slips = convention_slips(prepared, model)
        spent.append(time.perf_counter() - t0)
        row = {"log": str(path), "as_recorded": [s.what for s in slips], **_margins(prepared, model)}
        for name, (edit, expected) in EDITS.items():
            found = [
                s.what
                for s in convention_slips(
                    prepare([_edited(log, **edit)], model=model, bandwidth=BANDWIDTH), model
                )
            ]
            row[name] = found == expected
        rows.append(row)
        marks = " ".join("+" if row[name] else "-" for name in EDITS)
        verdict = "ok" if not row["as_recorded"] else f"REFUSED {row['as_recorded']}"
        print(
            f"{path.name:28s} as recorded {verdict}  edits {marks}  closeness (vertical / horizontal) "
            f"{row['closeness_vertical']:.3g} / {row['closeness_horizontal']:.3g}"
            f"  C1 {row['C1_z']:.3g} se  C3 {row['C3_z']:.3g} se",
            flush=True,
        )
    if not rows:
        print("no logs", file=sys.stderr)
        return 2
    refused = sum(bool(r["as_recorded"]) for r in rows)
    named = {name: sum(r[name] for r in rows) for name in EDITS}
    summary = {
        "logs": len(rows),
        "refused_as_recorded": refused,
        "edits_named": named,
        "largest_closeness": float(np.nanmax([r["closeness"] for r in rows])),
        "swap_factor": SWAP_FACTOR,
        "smallest_C1_z": float(np.nanmin([r["C1_z"] for r in rows])),
        "smallest_C3_z": float(np.nanmin([r["C3_z"] for r in rows])),
        "slip_sigmas": SLIP_SIGMAS,
        "check_seconds_median": float(np.median(spent)),
        "check_seconds_max": float(np.max(spent)),
        "rows": rows,
    }
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1))
    print(
        f"{len(rows)} logs: refused as recorded {refused}; edits named "
        + ", ".join(f"{k} {v}/{len(rows)}" for k, v in named.items())
        + f"; largest closeness {summary['largest_closeness']:.3g} (rule {SWAP_FACTOR:g}); smallest C1 "
        f"{summary['smallest_C1_z']:.3g} se, C3 {summary['smallest_C3_z']:.3g} se (rule -{SLIP_SIGMAS:g}); "
        f"prepare and check {summary['check_seconds_median']:.2f} s median, "
        f"{summary['check_seconds_max']:.2f} s max"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
