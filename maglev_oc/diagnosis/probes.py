"""Generic smooth probes: additive functions of one state variable on one axis.

They are the rivals a named effect has to beat (it must explain the held-out data better than a
generic function of its variable with as many coefficients) and the probes of what nothing named
explains (:mod:`~maglev_oc.diagnosis.unexplained`).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from maglev_oc.diagnosis.candidate import legendre
from maglev_oc.regression.data import PreparedLogs
from maglev_oc.regression.terms import AccelerationTerm, term_function

__all__ = ["PROBE_ORDER", "PROBE_VARIABLES", "smooth_probes"]

PROBE_VARIABLES = {
    "gap": (0, "the gap"),
    "position": (2, "the horizontal position"),
    "gap_rate": (1, "the gap rate (vertical velocity)"),
    "position_rate": (3, "the horizontal velocity"),
}
"""State variables a generic probe depends on: name -> (row of x, words)."""
PROBE_ORDER = 4
"""Legendre orders 1..4: a smooth dependence with as many coefficients as the richest candidate."""


def smooth_probes(data: PreparedLogs) -> dict[tuple[str, str], AccelerationTerm]:
    """Generic smooth additive terms, one per (axis, state variable): mean-free Legendre polynomials
    of orders 1..4 of the variable over its logged range (1st-99th percentile), as an acceleration
    on that axis. They are the rivals a named effect has to beat (it must explain the held-out data
    better than a generic function of its variable) and the probes of what nothing named explains."""
    fit_x = data.x[:, data.valid]
    out = {}
    for axis in ("vertical", "horizontal"):
        for var, (row, _) in PROBE_VARIABLES.items():
            lo, hi = (float(v) for v in np.percentile(fit_x[row], [1, 99]))
            c, h = 0.5 * (lo + hi), max(0.5 * (hi - lo), 1e-12)
            orders = range(1, PROBE_ORDER + 1)
            means = [float(np.mean(b)) for b in legendre((fit_x[row] - c) / h, orders)]

            # horizontally the base model has no constant acceleration, so the probe carries one;
            # vertically a constant is the weight's business (C2..C4), so the probe is mean-free
            k = PROBE_ORDER + (axis == "horizontal")

            def build(x, u, du, q, row=row, c=c, h=h, means=means, axis=axis, orders=orders):
                basis = legendre((x[row] - c) / h, orders)
                val = sum(
                    (q[i] * (b - m) for i, (b, m) in enumerate(zip(basis, means, strict=True))), ca.SX(0)
                )
                if axis == "horizontal":
                    return ca.vertcat(0, val + q[PROBE_ORDER])
                return ca.vertcat(val, 0)

            name = f"probe_{axis}_{var}"
            out[(axis, var)] = AccelerationTerm(
                name,
                f"A smooth function of {PROBE_VARIABLES[var][1]} on the {axis} axis.",
                axis,
                tuple(f"P{i}" for i in orders) + (("P0",) if axis == "horizontal" else ()),
                function=term_function(name, build, k),
            )
    return out
