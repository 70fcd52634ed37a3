"""Check ``diagnose``'s detection limits against the effects real logs show.

    python bench/diagnose_limits.py --kind ripple --sizes 0.1 0.15 0.2 0.3 [--rig obs2800]
        [--seeds 202 203 204 205 206] [--out bench/out/diagnose_limits]

For each seed the independent generator (``tests/independent``, no code shared with
``maglev_oc.sim``) records a clean log; ``diagnose`` reports the size below which that log could
not show each effect it did not claim (``maglev_oc.diagnosis.limits``). Then the same seed (the
same constants, references and noise) is recorded again with one effect of that kind in its plant
at each of ``--sizes`` and diagnosed: the limit is right when the effect is not claimed below it
and is claimed from about it up. Kinds and their size (the limit's parameter):

* ``ripple``: thrust ripple over the slot pitch, amplitude as a fraction of the thrust;
* ``tilt``: horizontal guides off level, the force along the track [N];
* ``cable``: a cable carrier's stiffness [N/m];
* ``lag``: a first-order amplifier lag, its time constant [s] (no transport delay);
* ``friction``: horizontal guide friction (LuGre, breakaway 1.33 times the Coulomb force, the
  generator's default 2 N s/m viscous part), the Coulomb force [N]; the generator's loop is
  unstable with it below about 0.1 N on the noisy rig.

Prints one JSON line per seed (the limit and what it was judged on, and per size whether the effect
was claimed, its selection z, whether the accelerations or the logged thrust current showed it
(``maglev_oc.diagnosis.thrust_current``) and its size) and appends it to ``OUT/limits.jsonl``. Not
run in CI.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

NAMES = {
    "ripple": "thrust_ripple",
    "tilt": "horizontal_guides_not_level",
    "cable": "cable_carrier_force",
    "lag": "current_amplifier_lag",
    "friction": "guide_friction_horizontal",
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--kind", choices=sorted(NAMES), required=True)
    parser.add_argument("--sizes", type=float, nargs="+", required=True)
    parser.add_argument("--seeds", type=int, nargs="+", default=[202, 203, 204, 205, 206])
    parser.add_argument("--rig", default="obs2800", help="a rig of bench/diagnose_rigs.py (default obs2800)")
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "out" / "diagnose_limits")
    args = parser.parse_args()
    sys.path.insert(0, str(ROOT))
    from tests.independent.core import with_generic_libm

    with_generic_libm()  # the logs the test suite generates, whatever the CPU
    from maglev_oc.data.reading import read_log
    from maglev_oc.diagnosis.pipeline import diagnose
    from tests.independent.effects import (
        AmplifierDynamics,
        CableCarrier,
        GuideFriction,
        ThrustRipple,
        TiltedBase,
    )
    from tests.independent.logio import write_log
    from tests.independent.rigs import RIGS
    from tests.independent.simulate import Rig, Scenario, SimulationError, simulate

    rig = Rig(**RIGS[args.rig])
    name = NAMES[args.kind]
    folder = args.out / args.rig
    folder.mkdir(parents=True, exist_ok=True)

    def effect(size: float):
        if args.kind == "ripple":
            return ThrustRipple(ratio=size, ratio2=0.0)
        if args.kind == "tilt":
            return TiltedBase(angle=math.asin(size / (1.594 * 9.81)))  # the generator's M_h g
        if args.kind == "cable":
            return CableCarrier(stiffness=size)
        if args.kind == "friction":
            return GuideFriction(axis_="horizontal", coulomb_force=size, static_force=1.33 * size)
        return AmplifierDynamics(bandwidth=1.0 / (2 * math.pi * size), delay=0.0)

    def diagnosed(seed: int, stem: str, effects: tuple):
        csv = folder / f"{stem}.csv"
        if not csv.exists():
            try:
                run = simulate(Scenario(name=stem, seed=seed, effects=effects, rig=rig))
                write_log(run, folder, stem=stem)
            except SimulationError as err:
                print(f"{stem}: the generator's loop failed ({err}); skipped", flush=True)
                return None
        return diagnose([read_log(csv)])

    for seed in args.seeds:
        clean = diagnosed(seed, f"s{seed}_clean", ())
        if clean is None:
            continue
        limit = next((d for d in clean.detection_limits if d.name == name), None)
        row = {
            "rig": args.rig,
            "seed": seed,
            "kind": args.kind,
            "limit": None if limit is None or not math.isfinite(limit.value) else limit.value,
            "limit_reason": None if limit is None else limit.reason,
            "limit_judged_on": None if limit is None else (limit.side or "accelerations"),
            "clean_claims": [e.name for e in clean.effects],
            "sizes": {},
        }
        for size in args.sizes:
            d = diagnosed(seed, f"s{seed}_{args.kind}_{size:g}", (effect(size),))
            if d is None:
                continue
            j = d.selection.last.get(name)
            row["sizes"][f"{size:g}"] = {
                "claimed": name in [e.name for e in d.effects],
                "claims": [e.name for e in d.effects],
                "z": None if j is None else j.z,
                "judged_on": None if j is None else (j.side or "accelerations"),
                "size": next((_size(e) for e in d.effects if e.name == name), None),
            }
        print(json.dumps(row), flush=True)
        with open(args.out / "limits.jsonl", "a") as fh:
            fh.write(json.dumps(row) + "\n")


def _size(effect) -> float | None:
    """The claimed effect's first physical parameter (the limit's)."""
    first = next(iter(effect.parameters.values()), None)
    return None if first is None else first.value


if __name__ == "__main__":
    main()
