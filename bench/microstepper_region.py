"""Benchmark: the microstepper's certified level with and without the centred form.

For each set-point the bracket (certified level, level at which a constraint fails), the boxes
evaluated and the wall time, once with the natural interval extension alone (the centred form
switched off by setting ``CENTRED_AFTER`` to infinity) and once as shipped (the centred form joins
after half of each level's budget). The report's three set-points use the default budget; 15 mm
and 8 mm without stoppers show where the natural extension is loose.

python bench/microstepper_region.py [--budget 1000000]
"""

from __future__ import annotations

import argparse
import math
import time

import casadi as ca
from common import machine

from maglev_oc.model.platform import microstepper
from maglev_oc.region import microstepper as module
from maglev_oc.region.microstepper import MicrostepperRegion

CASES = (
    ("report, corner near the stator", (-0.04, -0.04, 0.021), {}),
    ("report, corner far", (0.04, -0.04, 0.029), {}),
    ("report, centre", (0.0, 0.0, 0.025), {}),
    ("15 mm (the 8 mm stopper binds)", (0.0, 0.0, 0.015), {}),
    ("8 mm, no stoppers", (0.0, 0.0, 0.008), {"stoppers": False}),
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", type=int, default=1_000_000, help="boxes per level")
    args = parser.parse_args()
    print(f"machine: {machine()}; casadi {ca.__version__}; {args.budget:,} boxes per level")
    shipped = module.CENTRED_AFTER
    regions = {}
    head = ("case", "enclosure", "certified", "fails at", "bracket", "boxes", "wall")
    print("{:34s} {:9s} {:>9s} {:>9s} {:>8s} {:>10s} {:>7s}".format(*head))
    for name, setpoint, options in CASES:
        key = tuple(sorted(options.items()))
        region = regions.setdefault(key, MicrostepperRegion(microstepper(), **options))
        for label, after in (("natural", math.inf), ("centred", shipped)):
            module.CENTRED_AFTER = after
            try:
                t0 = time.perf_counter()
                res = region.largest_level(setpoint, max_boxes=args.budget)
                wall = time.perf_counter() - t0
            finally:
                module.CENTRED_AFTER = shipped
            bracket = res.refuted_level / res.level - 1 if res.level > 0 else math.inf
            print(
                f"{name:34s} {label:9s} {res.level:9.4g} {res.refuted_level:9.4g} {bracket:8.1%} "
                f"{res.boxes:10,d} {wall:6.1f}s"
            )


if __name__ == "__main__":
    main()
