"""The states a compensated feasible set depends on (``FeasibleSet.loop_variables``), which the
branch and bound then varies over the certified ellipsoid: a state left out would be held at its
offset, and the certificate would not cover how the compensation changes along it. Checked for a
compensation of each state alone, against the dependence measured by perturbing that state in
the set's own pointwise constraints. CasADi, milliseconds."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from maglev_oc.region.feasibility import FeasibleSet

STATES = ("x1", "x2", "x3", "x4")


def _compensation(k: int) -> ca.Function:
    """d(x) = (0.5 sin(200 x_k), 0.3 tanh(500 x_k)) [m/s^2]: a force of state k alone."""
    x = ca.SX.sym("x", 4)
    return ca.Function("d", [x], [ca.vertcat(0.5 * ca.sin(200 * x[k]), 0.3 * ca.tanh(500 * x[k]))])


@pytest.mark.parametrize("k", range(4))
def test_a_compensation_of_one_state_adds_that_state_and_only_it(model, k):
    """(x1, v1, v2) always (the constraints depend on them without compensation), then the one
    state the compensation depends on; and that state does change the compensated constraints
    (a step of 1 mm or 1 mm/s moves them by far more than their rounding)."""
    feasible = FeasibleSet(model, compensation=_compensation(k))
    expected = ("x1", "v1", "v2") if k == 0 else ("x1", "v1", "v2", STATES[k])
    assert feasible.loop_variables == expected
    x = np.array([0.02, 0.0, 0.0, 0.0])
    v = np.array([0.3, -0.2])
    step = x.copy()
    step[k] += 1e-3
    h0, h1 = (np.asarray(feasible.pointwise(s, v)).ravel() for s in (x, step))
    assert np.max(np.abs(h1 - h0)) > 1e-6
