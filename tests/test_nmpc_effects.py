"""The NMPC on the model augmented with found effects (a stage file's ``plant_effects()``): the
prediction, the observer and the feedforward carry them, so the disturbance estimate is only what
the effects leave unexplained."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from maglev_oc.control.nmpc import NonlinearMPC
from maglev_oc.errors import InputError
from maglev_oc.sim.effects import TwinEffects
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.scenarios import Scenario, SetpointSequence
from maglev_oc.sim.twin import RigTwin

MM = 1e-3
STIFFNESS = 60.0  # [N/m] a cable carrier's spring along the track, about 5x the independent generator's
CENTRE = 5 * MM  # [m] where it pulls to


def _spring(model) -> ca.Function:
    """(x, i) -> (x2', x4'): the spring's acceleration of the horizontal mass (no vertical part)."""
    x, i = ca.SX.sym("x", 4), ca.SX.sym("i", 2)
    acc = ca.vertcat(0, -STIFFNESS * (x[2] - CENTRE) / model.params.mass_horizontal)
    return ca.Function("spring", [x, i], [acc], ["x", "i"], ["acc"])


def test_the_observer_is_left_only_what_the_effects_do_not_explain(model):
    # Ideal twin (exact constants) plus the spring. Hold (20 mm, 20 mm): the spring pulls with
    # 60 * 0.015 / 1.594 = 0.565 m/s^2. Without the effect in its model the NMPC's disturbance
    # estimate carries it (within the observer's 5 % at steady state); with it, the estimate is
    # 0 to the encoder's resolution (the 10 um quantization alone gives d_h of a few mm/s^2).
    spring = _spring(model)
    twin = RigTwin(model, TwinEffects(extra=spring), substeps=2)
    sc = Scenario(
        "hold", "set-point", (20 * MM, 0.0, 0.0, 0.0), SetpointSequence((0.0,), ((20 * MM, 20 * MM),)), 1.0
    )
    expected = -STIFFNESS * (20 * MM - CENTRE) / model.params.mass_horizontal
    plain = ClosedLoop(twin, NonlinearMPC(model)).run(sc)
    augmented = ClosedLoop(twin, NonlinearMPC(model, effects=spring)).run(sc)
    assert plain.success and augmented.success
    late = plain.t >= 0.7
    d_plain = float(np.mean(plain.diagnostic("d_h")[late]))
    d_aug = float(np.mean(augmented.diagnostic("d_h")[late]))
    assert d_plain == pytest.approx(expected, rel=0.05)
    assert abs(d_aug) < 0.02 * abs(expected)
    # both hold the set-point (the disturbance state makes the plain one offset-free too)
    for res in (plain, augmented):
        assert np.max(np.abs(res.error[:, late])) <= 20e-6


def test_the_prediction_is_the_model_plus_the_effects(model):
    # The OCP's RK4 step with the effects against one RK4 step of model.f + effects written here
    spring = _spring(model)
    ocp = NonlinearMPC(model, effects=spring)._ocp
    x, u, h = np.array([18 * MM, 0.01, 25 * MM, -0.02]), np.array([0.3, 1.5]), 5e-3

    def f(x):
        e = np.asarray(spring(x, u)).ravel()
        return np.asarray(model.f(x, u)).ravel() + np.array([0.0, e[0], 0.0, e[1]])

    k1 = f(x)
    k2 = f(x + h / 2 * k1)
    k3 = f(x + h / 2 * k2)
    k4 = f(x + h * k3)
    expected = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    step = np.asarray(ocp.rk4(x, u, np.zeros(2), h)).ravel()
    np.testing.assert_allclose(step, expected, rtol=1e-12, atol=1e-15)
    plain = NonlinearMPC(model)._ocp
    assert np.asarray(plain.rk4(x, u, np.zeros(2), h)).ravel()[3] - expected[3] > 1e-4  # the spring's part


def test_effects_of_the_wrong_shape_are_refused(model):
    x = ca.SX.sym("x", 4)
    with pytest.raises(InputError, match="effects must map x"):
        NonlinearMPC(model, effects=ca.Function("f", [x], [x[:2]]))
    with pytest.raises(InputError, match=r"casadi\.Function"):
        NonlinearMPC(model, effects=lambda x, i: x)


def test_the_feedforward_current_makes_the_plant_with_the_effects_follow_the_reference(model):
    # r = (r_v, r_v', r_v'', r_h, r_h', r_h''): u_ff applied at the reference state on the model
    # plus the effects (and the disturbance estimate d) gives exactly the reference's
    # accelerations, recomputed here from model.f and the effect (the spring depends on the state
    # alone, so the feedforward's fixed-point step is exact: 1e-9 of the 0.565 m/s^2 it carries).
    spring = _spring(model)
    ff = NonlinearMPC(model, effects=spring)._ocp.feedforward
    plain = NonlinearMPC(model)._ocp.feedforward
    r = np.array([18 * MM, 0.02, 0.3, 20 * MM, -0.05, -0.8])
    x = r[[0, 1, 3, 4]]
    for d in (np.zeros(2), np.array([0.2, -0.1])):
        u = np.asarray(ff(r, d)).ravel()
        acc = np.asarray(model.f(x, u)).ravel()[[1, 3]] + np.asarray(spring(x, u)).ravel() + d
        np.testing.assert_allclose(acc, r[[2, 5]], rtol=0, atol=1e-9)
        # without the effect in the model the same current misses the horizontal acceleration
        u0 = np.asarray(plain(r, d)).ravel()
        acc0 = np.asarray(model.f(x, u0)).ravel()[[1, 3]] + np.asarray(spring(x, u0)).ravel() + d
        assert abs(acc0[1] - r[5]) > 0.5
