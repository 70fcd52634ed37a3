"""Benchmark: exact Jacobian of the stage model, one point and 10^4 points with ``map``.

python bench/model_jacobian.py
"""

from __future__ import annotations

import casadi as ca
import numpy as np
from common import best_of, fmt, machine

from maglev_oc.model.stage import StageModel


def main() -> None:
    model = StageModel()
    x = np.array([0.02, 0.01, 0.003, -0.02])
    u = np.array([0.5, 1.4])
    n = 10_000
    rng = np.random.default_rng(0)
    xs = np.vstack(
        [
            rng.uniform(8e-3, 35e-3, n),
            rng.normal(0, 0.1, n),
            rng.uniform(-0.05, 0.05, n),
            rng.normal(0, 0.3, n),
        ]
    )
    us = rng.uniform(-9, 9, (2, n))

    jac = model.jacobian
    one, one_med = best_of(lambda: jac(x, u), repeat=7, number=2000)
    # raw CasADi call overhead vs the numeric kernel: call on DM inputs
    xd, ud = ca.DM(x), ca.DM(u)
    one_dm, _ = best_of(lambda: jac(xd, ud), repeat=7, number=2000)
    serial = jac.map(n)  # built once
    batch, batch_med = best_of(lambda: serial(xs, us), repeat=7)
    threads = jac.map(n, "thread", 2)
    batch_thr, _ = best_of(lambda: threads(xs, us), repeat=7)
    f_batch = model.f.map(n)
    fb, _ = best_of(lambda: f_batch(xs, us), repeat=7)

    print(f"machine: {machine()}; casadi {ca.__version__}")
    print(f"jacobian, one point (numpy in):        best {fmt(one)}  median {fmt(one_med)}")
    print(f"jacobian, one point (DM in):           best {fmt(one_dm)}")
    print(
        f"jacobian, 10^4 points, map serial:     best {fmt(batch)}  median {fmt(batch_med)}"
        f"  ({fmt(batch / n)} per point)"
    )
    print(f"jacobian, 10^4 points, map 2 threads:  best {fmt(batch_thr)}")
    print(f"dynamics f, 10^4 points, map serial:   best {fmt(fb)}")


if __name__ == "__main__":
    main()
