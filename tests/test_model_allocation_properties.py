"""Properties of the current allocations (the stage's feedback transformation and the
microstepper's), checked on the model's L1..L4 in numpy and on the platform's own state equation:

- the feedback transformation's feasibility margin is R / (4 L4), the room left in v2; its clipped
  currents are the physical root where R >= 0 and the vertex -L3 / (2 L4) where R < 0; it takes
  any real numbers (object arrays, fractions) and returns floats;
- the microstepper's allocation called by its named inputs realises the requested accelerations,
  and its maximum-margin allocation balances the two pairs' magnitudes below the minimum-norm
  peak.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.model.allocation import MicrostepperTransformation
from maglev_oc.model.feedback import FeedbackTransformation
from maglev_oc.model.platform import PlatformModel, microstepper


# --- the feedback transformation ---------------------------------------------------------------
def _L(model, x1):
    return [np.asarray(a).ravel() for a in model.L.map(x1.size)(x1[None, :])]


def test_the_margin_is_the_room_left_in_v2(model, transformation):
    """margin = R / (4 L4) with R = L3^2 - 4 L4 (L4 (v1 / L1)^2 + L2 - G + v2) evaluated here in
    numpy, and R at v2 + margin is zero (relative to L3^2: 1e-9, round-off of a difference of
    terms of size L3^2). v1 and v2 differ at every point, and over gaps, signs and sizes."""
    rng = np.random.default_rng(221)
    n = 40
    x1 = rng.uniform(8e-3, 32e-3, n)
    v1 = rng.uniform(-20.0, 20.0, n)
    v2 = rng.uniform(-20.0, 300.0, n)  # margins at v2 = 0 are 25-280 m/s^2 here
    L1, L2, L3, L4 = _L(model, x1)
    R = L3**2 - 4 * L4 * (L4 * (v1 / L1) ** 2 + L2 - model.params.gravity + v2)
    assert_allclose(transformation.discriminant(x1, v1, v2), R, rtol=1e-12, atol=1e-12 * np.max(L3**2))
    margin = transformation.feasibility_margin(x1, v1, v2)
    assert_allclose(margin, R / (4 * L4), rtol=1e-12, atol=1e-12)
    assert np.any(margin > 0) and np.any(margin < 0)  # both sides of the boundary are sampled
    at_edge = transformation.discriminant(x1, v1, v2 + margin)
    assert_allclose(at_edge, 0.0, rtol=0, atol=1e-9 * np.max(L3**2))


def test_clipped_currents_are_the_root_inside_and_the_vertex_outside(model, transformation):
    """Where R >= 0 the clipped currents are the transformation's (the physical root); where
    R < 0 (no real root) i_d is the vertex -L3 / (2 L4), the current that comes closest to the
    requested v2, and i_q is -v1 / L1 in both cases (rtol 1e-12: a few operations)."""
    x1 = np.full(6, 20e-3)
    v1 = np.array([0.0, 5.0, -5.0, 0.0, 40.0, -40.0])
    room = float(transformation.feasibility_margin(20e-3, 0.0, 0.0))  # about 35 m/s^2
    v2 = room * np.array([0.0, -0.5, 0.5, 2.0, 1.5, 0.9])
    R = transformation.discriminant(x1, v1, v2)
    assert np.any(R > 0) and np.any(R < 0)
    L1, _, L3, L4 = _L(model, x1)
    for k in range(x1.size):
        u, r = (np.asarray(a).ravel() for a in transformation.currents_clipped(x1[k], [v1[k], v2[k]]))
        assert_allclose(r[0], R[k], rtol=1e-12)
        assert_allclose(u[0], -v1[k] / L1[k], rtol=1e-12)
        if R[k] >= 0:
            exact = np.asarray(transformation.currents(x1[k], [v1[k], v2[k]])).ravel()
            assert_allclose(u, exact, rtol=1e-12)
            assert_allclose(u[1], (-L3[k] - np.sqrt(R[k])) / (2 * L4[k]), rtol=1e-12)
        else:
            assert_allclose(u[1], -L3[k] / (2 * L4[k]), rtol=1e-12)


# --- the microstepper's allocation -------------------------------------------------------------
@pytest.fixture(scope="module")
def stepper():
    platform = microstepper()
    return MicrostepperTransformation(platform), PlatformModel(platform)


def test_maximum_margin_realises_v_and_balances_the_pairs(stepper):
    """For requests that load the two pairs unequally (|v_x| != |v_y|): the maximum-margin
    currents give the platform the accelerations v on its own state equation (1e-9 relative, as
    for the minimum norm in tests/test_model_seed35_properties.py), both pairs carry the same
    magnitude (the minimax of two monotone functions of the split; 1e-4 A, the bounded Brent
    search's tolerance of 1e-5 in i_dA times a slope below 10), and that peak is below the
    minimum-norm one by more than that tolerance (measured 7 mA at v = (3, -2, 1) m/s^2)."""
    fl, pm = stepper
    rng = np.random.default_rng(222)
    for v in ([3.0, -2.0, 1.0], [0.0, 4.0, -1.0], *rng.uniform(-4.0, 4.0, (4, 3))):
        v = np.asarray(v)
        gap = 0.02
        plain, best = fl.allocate(gap, v), fl.allocate(gap, v, "maximum_margin")
        assert best.method == "maximum_margin" and best.defined
        u = best.currents
        x = np.array([0.0, 0.0, 0.0, 0.0, gap, 0.0])
        acc = np.asarray(pm.dynamics(x, u)).ravel()[1::2]
        assert_allclose(acc, v, rtol=1e-9, atol=1e-9 * 9.81)
        pair = np.hypot(u[[0, 2]], u[[1, 3]])
        assert_allclose(pair[0], pair[1], rtol=0, atol=1e-4)
        assert best.peak == pytest.approx(max(pair), abs=1e-12)
        assert plain.peak == pytest.approx(max(np.hypot(plain.currents[[0, 2]], plain.currents[[1, 3]])))
        assert best.peak <= plain.peak + 1e-12
    # the first request: the pairs' thrusts differ by 0.9 A, the balance gains 7 mA (measured)
    assert (
        fl.allocate(0.02, [3.0, -2.0, 1.0], "maximum_margin").peak
        < fl.allocate(0.02, [3.0, -2.0, 1.0]).peak - 1e-3
    )


# --- the microstepper's transformation ------------------------------------------------------------
def test_the_microstepper_transformation_by_its_named_inputs_realises_v():
    """function(gap=..., v=...) -> {u, R}: the currents give the platform the accelerations v
    (x'', y'', gap'') on :class:`PlatformModel` (rtol 1e-9: the minimum-norm allocation
    solves a quadratic for i_d, whose root carries round-off of the size of k3^2 / k4)."""
    platform = microstepper()
    fl, pm = MicrostepperTransformation(platform), PlatformModel(platform)
    rng = np.random.default_rng(35)
    for _ in range(10):
        gap = rng.uniform(0.02, 0.03)
        v = rng.uniform(-2.0, 2.0, 3)
        out = fl.function(gap=gap, v=v)
        assert set(out) == {"u", "R"} and float(out["R"]) > 0
        u = np.asarray(out["u"]).ravel()
        assert_allclose(u, fl.allocate(gap, v).currents, rtol=0, atol=0)
        x = np.array([rng.uniform(-0.05, 0.05), 0.0, rng.uniform(-0.05, 0.05), 0.0, gap, 0.0])
        acc = pm.dynamics(x, u)[1::2].ravel()
        assert_allclose(acc, v, rtol=1e-9, atol=1e-9 * platform.gravity[2])


# --- model.feedback -----------------------------------------------------------------------------
@pytest.mark.parametrize("method", ["discriminant", "feasibility_margin"])
def test_the_transformation_takes_any_real_numbers_and_returns_floats(model, method):
    """An object array (what pandas or a list of mixed numbers gives) and fractions are real numbers:
    the result is the float array of the same numbers as floats. Exact equality: every input here
    converts to the same float64 as the float input, and then the same evaluation follows."""
    fn = getattr(FeedbackTransformation(model), method)
    x1, v1, v2 = [0.02, 0.021, 0.019], [0.5, -1.0, 2.0], [3.0, -4.0, 0.25]
    want = fn(np.array(x1), np.array(v1), np.array(v2))
    assert want.dtype == np.float64 and np.all(np.isfinite(want))
    as_object = fn(*(np.array(a, dtype=object) for a in (x1, v1, v2)))
    assert as_object.dtype == np.float64
    assert np.array_equal(as_object, want)
    fractions = fn(Fraction(1, 50), Fraction(1, 2), Fraction(3))
    assert fractions.dtype == np.float64 and fractions.shape == ()
    assert fractions == want[0]
