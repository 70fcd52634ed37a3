"""Options of the controllers that must change the answer in the stated direction: a test here
fails when an option is ignored or its sign inverted."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator


def _compensation(d_vertical: float, d_horizontal_slope: float) -> ca.Function:
    """An extra acceleration the model lacks: constant on the gap, position-proportional on x3."""
    x = ca.SX.sym("x", 4)
    return ca.Function("d", [x], [ca.vertcat(d_vertical, d_horizontal_slope * x[2])])


@pytest.mark.parametrize("seed", range(5))
def test_disturbance_compensation_makes_the_plant_see_v(model, seed):
    """With compensation d(x), the currents the FL step outputs give, on the model plus d, exactly
    the outer loop's v = (v1, v2) (002 eq. (14) with v - d asked of the transformation); without
    it, the model alone sees v and the plant with d sees v + d."""
    rng = np.random.default_rng(seed)
    d = _compensation(rng.uniform(-2.0, 2.0), rng.uniform(-30.0, 30.0))
    with_d = FeedbackLinearizingRegulator(model, compensation=d)
    without = FeedbackLinearizingRegulator(model)
    y = np.array([rng.uniform(0.016, 0.024), rng.uniform(-0.03, 0.03)])  # measured gap, position
    c = with_d.initial_state(y, None)
    c[1], c[3] = rng.uniform(-0.05, 0.05, 2)  # the observers' velocities
    c[4:] = rng.uniform(-1e-4, 1e-4, c.size - 4)  # internal-model states
    r = np.zeros(6)
    r[0], r[3] = 0.02, 0.0
    x_hat = np.array([y[0], c[1], y[1], c[3]])
    extra = np.asarray(d(x_hat)).ravel()
    for ctrl, expected_offset in ((with_d, 0.0), (without, 1.0)):
        u, _, diag = (np.asarray(v).ravel() for v in ctrl.step(c, y, r))
        assert diag[1] == 0  # R >= 0 here: the transformation is exact
        acc = np.asarray(model.dynamics(x_hat, u)).ravel()
        plant = np.array([acc[1] + extra[0], acc[3] + extra[1]])  # (x2', x4') with the effect
        v1, v2 = diag[2], diag[3]
        np.testing.assert_allclose(
            plant, [v2 + expected_offset * extra[0], v1 + expected_offset * extra[1]], rtol=1e-9, atol=1e-9
        )
