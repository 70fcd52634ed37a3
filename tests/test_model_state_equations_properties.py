"""Properties of the state equations of the stage and the platforms, checked against an
independent numpy evaluation of the papers' formulas:

- the shape functions l1..l4 are eqs. (5)-(8) of paper 002 and obey the identities l3^2 = l2 l4
  and l3 = -l1 B cosh(a (h_m + y)); the state equation is the one the stage docstring writes;
- the 2-DOF platform is the stage model of its arguments, and the microstepper needs three masses;
- the platform's state equation reads any real array (integers, booleans, float32, objects such
  as Fractions) as the numbers it holds.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.errors import InputError
from maglev_oc.model.parameters import MU0, LumpedConstants, StageParameters
from maglev_oc.model.platform import PlatformModel, microstepper, two_dof_platform
from maglev_oc.model.stage import StageModel

GAPS = np.linspace(5e-3, 35e-3, 31)  # the papers' field-fit range [m]


def _shapes_numpy(p: StageParameters, y: np.ndarray) -> np.ndarray:
    """l1..l4 (4, n) written out from the papers, in numpy (no CasADi, no package code)."""
    b0, t1, hm, tau = p.slot_width, p.slot_pitch, p.magnet_height, p.pole_pitch
    lam = 1 - b0**2 / (4 * t1 * (y + b0 / 2 + hm / p.recoil_permeability))  # 000 eq. (1)
    r = b0 / (2 * y)
    gamma1 = 4 / np.pi * (r * np.arctan(r) - np.log(np.sqrt(1 + r**2)))
    kc = t1 / (t1 - y * gamma1)  # Carter, 002 Sec. 3
    a = np.pi / tau
    amplitude = 4 * MU0 * p.surface_charge / np.pi * np.sin(np.pi * p.magnet_width / (2 * tau))
    b = amplitude * np.sinh(a * hm) / np.sinh(a * (hm + y))  # SPEC 1 field
    arg = a * (hm + y)
    coth = 1 / np.tanh(arg)
    return np.vstack([lam / (kc * np.sinh(arg)), lam * b**2, -lam * b * coth / kc, lam * coth**2 / kc**2])


def test_shape_functions_are_the_papers_formulas(model):
    """The CasADi shape functions against the numpy formulas: the same operations in another
    order, so they agree to round-off (rtol 1e-12 on values of order 1e-2..1)."""
    got = np.asarray(model.shape.map(GAPS.size)(GAPS[None, :]))
    assert_allclose(got, _shapes_numpy(model.params, GAPS), rtol=1e-12, atol=0)
    c = np.array(model.constants.as_array())[:, None]
    assert_allclose(model.coefficients(GAPS), c * _shapes_numpy(model.params, GAPS), rtol=1e-12)


def test_shape_function_identities(model):
    """Identities of eqs. (5)-(8) of 002 that hold whatever lam, Kc and B are:
    l3^2 = l2 l4 (both lam^2 B^2 coth^2 / Kc^2) and l3 / l1 = -B cosh(a (h_m + y)).
    Round-off only: rtol 1e-12."""
    p = model.params
    l1, l2, l3, l4 = np.asarray(model.shape.map(GAPS.size)(GAPS[None, :]))
    assert_allclose(l3**2, l2 * l4, rtol=1e-12)
    arg = np.pi / p.pole_pitch * (p.magnet_height + GAPS)
    assert_allclose(l3 / l1, -model.field_at(GAPS) * np.cosh(arg), rtol=1e-12)
    assert np.all(l1 > 0) and np.all(l2 > 0) and np.all(l3 < 0) and np.all(l4 > 0)  # signs of SPEC 1


def test_state_equation_is_the_documented_one(model):
    """x' of the stage docstring with L_i from the numpy formulas, at random states and inputs
    (rtol 1e-10: accelerations are differences of terms of order G)."""
    rng = np.random.default_rng(21)
    n = 40
    x = np.vstack([rng.uniform(6e-3, 34e-3, n), rng.normal(0, 0.1, n), rng.normal(0, 0.03, n)])
    x = np.vstack([x, rng.normal(0, 0.1, n)])
    u = rng.uniform(-6, 6, (2, n))
    L1, L2, L3, L4 = np.array(model.constants.as_array())[:, None] * _shapes_numpy(model.params, x[0])
    G = model.params.gravity
    want = np.vstack(
        [x[1], G - L4 * (u[0] ** 2 + u[1] ** 2) - L3 * u[1] - L2, x[3], -L1 * u[0]],
    )
    assert_allclose(model.dynamics(x, u), want, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("masses", [(1.0, 2.0), (1.0, 2.0, 3.0, 4.0)])
def test_the_microstepper_needs_three_masses_and_says_so(masses):
    with pytest.raises(
        InputError, match=rf"^microstepper: three masses \(x, y, gap\) needed, got {len(masses)}$"
    ):
        microstepper(masses=masses)


# --- the 2-DOF platform -----------------------------------------------------------------------
def test_the_two_dof_platform_is_the_stage_model_of_its_arguments():
    """Other masses, geometry and constants than the defaults: the platform's dynamics are the
    StageModel's of the same arguments to rounding (rtol 1e-12 of the largest acceleration, as
    tests/test_platform.py for the defaults): gravity, masses and the attraction towards the
    stator with these numbers."""
    params = StageParameters(mass_vertical=3.9, mass_horizontal=1.4, slot_width=12.5e-3)
    constants = LumpedConstants(15.0, 780.0, 32.0, 0.09)
    platform = two_dof_platform(params, constants)
    assert [m.name for m in platform.motors] == ["PMLSM"]
    pm, stage = PlatformModel(platform), StageModel(params, constants)
    rng = np.random.default_rng(35)
    n = 100
    x = np.vstack(
        [
            rng.uniform(0.008, 0.03, n),
            rng.normal(0, 0.05, n),
            rng.uniform(-0.05, 0.05, n),
            rng.normal(0, 0.05, n),
        ]
    )
    u = rng.uniform(-9, 9, (2, n))
    a, b = pm.dynamics(x, u), stage.dynamics(x, u)
    assert np.max(np.abs(a - b)) <= 1e-12 * np.max(np.abs(b))


# --- the platform's state equation -------------------------------------------------------------
@pytest.fixture(scope="module")
def stepper() -> PlatformModel:
    """The microstepper: states (x, x', y, y', gap, gap'), inputs (i_qA, i_dA, i_qB, i_dB)."""
    return PlatformModel(microstepper())


def test_the_state_equation_reads_any_real_array_as_its_values(stepper):
    """States and inputs given as integers, booleans, float32 and object arrays hold the same
    numbers as the float64 arrays they are compared with (every value chosen exactly
    representable in each type: 0, 1, 2, 1/4, 1/2, -3/4, 0.03125 m of gap), so x' must be the
    same bit for bit: the CasADi function sees the same doubles. The gap row is 1 or 2 m for
    the integer states, a large gap at which the field is still defined (any gap > 0)."""
    u = np.array([[1.0, 0.5], [0.25, -0.75], [2.0, 0.0], [-1.0, 1.0]])  # two columns
    ints = np.array([0, 1, 0, -1, 2, 0])
    want = stepper.dynamics(ints.astype(float), u)
    assert want.shape == (6, 2) and np.all(np.isfinite(want))
    for given in (ints, ints.astype(np.int8), ints.tolist()):
        np.testing.assert_array_equal(stepper.dynamics(given, u), want)
    flags = np.array([False, True, False, True, True, False])
    np.testing.assert_array_equal(stepper.dynamics(flags, u), stepper.dynamics(flags.astype(float), u))
    exact = np.array([0.25, -0.5, 0.0, 0.75, 0.03125, 0.0])
    np.testing.assert_array_equal(
        stepper.dynamics(exact.astype(np.float32), u.astype(np.float32)), stepper.dynamics(exact, u)
    )


def test_the_state_equation_reads_an_object_array_of_numbers(stepper):
    """An object array (a row of Fractions and floats, as exact arithmetic or a table with
    mixed columns gives it) is read as the numbers it holds, not refused: the same x' as the
    float64 state, bit for bit (each Fraction is a dyadic rational, exactly a double)."""
    u = np.array([1.0, 0.5, 2.0, -1.0])
    exact = [Fraction(1, 4), Fraction(-1, 2), 0.0, Fraction(3, 4), Fraction(1, 32), 0.0]
    state = np.array(exact, dtype=object)
    assert state.dtype == object
    want = stepper.dynamics(np.array([0.25, -0.5, 0.0, 0.75, 0.03125, 0.0]), u)
    np.testing.assert_array_equal(stepper.dynamics(state, u), want)
    np.testing.assert_array_equal(
        stepper.dynamics(np.array([0.25, -0.5, 0, 0.75, 0.03125, 0], object), u), want
    )
