"""How far ``diagnose``'s verdicts rest on the last bits of a log: each log of a set regenerated as
another machine would record it.

    python bench/diagnose_stability.py [--sets eleven pairs] [--only eleven_10 ...] [--copies 4]
                                       [--out bench/out/diagnose_stability]

The independent generator's logs are the same on every machine only up to the last bits of libm's
and numpy's transcendental functions (glibc and numpy pick SIMD variants by CPU), and a closed loop
with 10 um encoders turns a last-bit difference into another quantization at a few instants, so
into another fine realization of the same log. A verdict that flips between such copies was decided
by the draw, not by the effect: a test that asserts it passes on one machine and fails on another
(the large field shape of eleven_10 was claimed on the machine that wrote its test, not on the next).

Each log is generated ``--copies`` times with the reference's mean gap scaled by 1 + k 1e-15, a
few of its last bits (k = 0 is the set's own log; the encoder noise would not do: the controller
sees it only through the quantizer, where a last-bit change almost never crosses a step),
diagnosed with the defaults and scored as ``bench/diagnose_score.py`` does. Prints per log the
marks of every copy (true first / no false claim / size right) and flags the logs whose marks or
claims differ between copies; writes ``OUT/summary.json``.
Not run in CI.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sets", nargs="+", default=["eleven", "single", "pairs"])
    parser.add_argument("--only", nargs="*", default=None, help="these stems only")
    parser.add_argument("--copies", type=int, default=4, help="realizations per log, the set's own first")
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "out" / "diagnose_stability")
    args = parser.parse_args()
    sys.path.insert(0, str(ROOT))
    from tests.independent.core import with_generic_libm

    with_generic_libm()  # the logs the test suite generates, whatever the CPU
    from maglev_oc.data.reading import read_log
    from maglev_oc.diagnosis.pipeline import diagnose
    from tests.independent.logio import write_log
    from tests.independent.scoring import score
    from tests.independent.sets import named_set
    from tests.independent.simulate import simulate

    summary: dict[str, dict] = {}
    unstable = 0
    for name in args.sets:
        for stem, scenario in named_set(name):
            if args.only and stem not in args.only:
                continue
            marks, claims = [], []
            t0 = time.perf_counter()
            for k in range(args.copies):
                ref = scenario.reference
                ref = dataclasses.replace(ref, gap_center=ref.gap_center * (1 + k * 1e-15))
                run = simulate(dataclasses.replace(scenario, reference=ref))
                csv, truth = write_log(run, args.out / "logs", f"{stem}_copy{k}")
                s = score(stem, json.loads(truth.read_text()), diagnose([read_log(csv)]).to_dict()["effects"])
                marks.append(
                    "".join("x" if v else "." for v in (s.true_first, s.no_false_claim, s.size_right))
                )
                claims.append(s.claimed)
            stable = len(set(marks)) == 1 and all(c == claims[0] for c in claims)
            unstable += not stable
            summary[stem] = {"scenario": scenario.name, "marks": marks, "claimed": claims, "stable": stable}
            print(
                f"{stem:12s} {scenario.name:42s} {' '.join(marks)}  {'' if stable else 'UNSTABLE '}"
                f"{claims if not stable else claims[0]}  ({time.perf_counter() - t0:.0f} s)",
                flush=True,
            )
    print(f"{unstable} of {len(summary)} logs change their marks or claims between copies")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")


if __name__ == "__main__":
    main()
