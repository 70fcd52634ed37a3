"""Benchmark: diagnose a 60 s log at 1 kHz (the issue asks for under 30 s on this machine).

python bench/diagnose_speed.py
"""

from __future__ import annotations

import time

from common import machine

from maglev_oc.control.pid import paper_pid
from maglev_oc.diagnose.diagnosis import diagnose
from maglev_oc.model.stage import StageModel
from maglev_oc.sim.effects import TwinEffects
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.recording import result_to_log
from maglev_oc.sim.scenarios import excitation_scenario
from maglev_oc.sim.twin import RigTwin


def main() -> None:
    model = StageModel()
    res = ClosedLoop(RigTwin(model, TwinEffects.rig()), paper_pid(model)).run(excitation_scenario(60.0))
    log = result_to_log(res, rate_hz=1000)
    runs = []
    for _ in range(3):
        t0 = time.perf_counter()
        d = diagnose([log], model)
        runs.append(time.perf_counter() - t0)
    print(f"machine: {machine()}")
    print(
        f"diagnose, 60 s at 1 kHz (rig twin, {len(d.effects)} effects found): "
        f"best {min(runs):.2f} s, worst {max(runs):.2f} s"
    )
    print("  stages (last run): " + ", ".join(f"{k} {v:.2f} s" for k, v in d.timings.items()))


if __name__ == "__main__":
    main()
