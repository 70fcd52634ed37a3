"""Benchmark: identification of C1..C4 from a 60 s twin log at 1 kHz.

python bench/identification.py

Times the equation-error fit (the diagnosis layer calls it in loops), the multiple-shooting
output-error fit and one NPFSI run, each best of a few repetitions on a fresh problem.
"""

from __future__ import annotations

import casadi as ca
from common import best_of, fmt, machine

from maglev_oc.identification.equation_error import EquationError, fit_equation_error
from maglev_oc.identification.experiments import TWIN_TRUTH, excitation_log
from maglev_oc.identification.npfsi import npfsi
from maglev_oc.identification.output_error import MultipleShooting
from maglev_oc.model.stage import StageModel


def main() -> None:
    model = StageModel()
    log = excitation_log(model.with_constants(TWIN_TRUTH), duration=60.0, seed=1, controller_model=model)
    problem = EquationError(log, model)
    ee_once, ee_med = best_of(lambda: fit_equation_error(log, model), repeat=5)
    ee_refit, _ = best_of(lambda: problem.fit(), repeat=5)
    half = log.n // 2
    ee_block, _ = best_of(lambda: problem.fit((half, log.n)), repeat=5)
    ee = problem.fit()
    oe, oe_med = best_of(lambda: MultipleShooting(log, model).fit(initial=ee), repeat=2)
    np1, _ = best_of(lambda: npfsi(log, model, eps=0.01), repeat=3)
    off, _ = best_of(
        lambda: fit_equation_error(log, model, estimate=("C1", "C2", "C3", "C4", "gap_offset")), repeat=2
    )

    print(f"machine: {machine()}; casadi {ca.__version__}; log: {log.n} samples at 1 kHz (60 s)")
    print(f"equation error, one-off (derivatives + fit):   best {fmt(ee_once)}  median {fmt(ee_med)}")
    print(f"equation error, refit on a prepared problem:   best {fmt(ee_refit)}")
    print(f"equation error, refit on half the samples:     best {fmt(ee_block)}")
    print(f"equation error with gap offset (nonlinear, LM): best {fmt(off)}")
    print(f"output error, multiple shooting (1199 segs):   best {fmt(oe)}  median {fmt(oe_med)}")
    print(f"NPFSI, C1..C4, one eps (incl. mapaccum build): best {fmt(np1)}")


if __name__ == "__main__":
    main()
