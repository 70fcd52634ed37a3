"""The stage built from motors: the 2-DOF stage as an instance, the 3-DOF microstepper's model,
its exact Jacobians, equilibria and the resolution of its input redundancy.

Cross-checks, each independent of the code under test:
* the 2-DOF instance against :class:`StageModel` (written separately, eq. (3) of 002): equal to
  rounding (1e-12 relative);
* the Jacobians against central finite differences (step h = 1e-6 relative: truncation error
  ~h^2 times the third derivative, rounding ~eps/h; 1e-5 relative covers both);
* the microstepper's equilibrium currents against the 2-DOF equilibrium solver (closed form of
  000 eq. (7)) for one motor carrying a quarter of the levitated mass (gravity scaled);
* the minimum-norm allocation against a brute-force scan of the free current.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from maglev_oc.errors import InputError
from maglev_oc.model.allocation import MicrostepperTransformation
from maglev_oc.model.equilibrium import equilibrium_currents
from maglev_oc.model.parameters import StageParameters
from maglev_oc.model.platform import Motor, Platform, PlatformModel, microstepper, two_dof_platform
from maglev_oc.model.stage import StageModel

TWO_DOF = PlatformModel(two_dof_platform())
STAGE = StageModel()
MICRO = microstepper()
MODEL3 = PlatformModel(MICRO)
FL3 = MicrostepperTransformation(MICRO)


def _states(rng, n, d, gaps=(0.02, 0.03)):
    """n random states of a platform with d coordinates, the last one the gap."""
    x = np.zeros((2 * d, n))
    for j in range(d - 1):
        x[2 * j] = rng.uniform(-0.05, 0.05, n)
    x[2 * (d - 1)] = rng.uniform(*gaps, n)
    x[1::2] = rng.normal(0, 0.05, (d, n))
    return x


# --- the 2-DOF stage is an instance ------------------------------------------------------------
def test_the_two_dof_stage_is_an_instance_of_the_platform():
    rng = np.random.default_rng(1)
    x = _states(rng, 200, 2, gaps=(0.008, 0.03))
    x = x[[2, 3, 0, 1]]  # the 2-DOF instance's coordinates are (gap, position)
    u = rng.uniform(-9, 9, (2, 200))
    a, b = TWO_DOF.dynamics(x, u), STAGE.dynamics(x, u)
    assert np.max(np.abs(a - b)) <= 1e-12 * np.max(np.abs(b))
    for k in range(0, 200, 20):
        ja, jb = TWO_DOF.jacobian(x[:, k], u[:, k]), STAGE.jacobian(x[:, k], u[:, k])
        for m1, m2 in zip(ja, jb, strict=True):
            np.testing.assert_allclose(np.asarray(m1), np.asarray(m2), rtol=1e-12, atol=1e-12)


# --- the microstepper's model ---------------------------------------------------------------------
def _finite_difference(model: PlatformModel, x: np.ndarray, u: np.ndarray):
    def f(xx, uu):
        return np.asarray(model.f(xx, uu)).ravel()

    def column(vec, k, other, wrt_x):
        h = 1e-6 * max(abs(vec[k]), 1e-2)
        d = np.zeros_like(vec)
        d[k] = h
        plus = f(vec + d, other) if wrt_x else f(other, vec + d)
        minus = f(vec - d, other) if wrt_x else f(other, vec - d)
        return (plus - minus) / (2 * h)

    A = np.column_stack([column(x, k, u, True) for k in range(x.size)])
    B = np.column_stack([column(u, k, x, False) for k in range(u.size)])
    return A, B


@given(seed=st.integers(0, 2**31 - 1))
@settings(max_examples=25, deadline=None)
def test_exact_jacobians_of_the_microstepper_match_finite_differences(seed):
    rng = np.random.default_rng(seed)
    x = _states(rng, 1, 3)[:, 0]
    u = rng.uniform(-9, 9, 4)
    A, B = (np.asarray(m) for m in MODEL3.jacobian(x, u))
    A_fd, B_fd = _finite_difference(MODEL3, x, u)
    scale = max(np.max(np.abs(A)), 1.0)
    np.testing.assert_allclose(A, A_fd, atol=1e-5 * scale)
    np.testing.assert_allclose(B, B_fd, atol=1e-5 * max(np.max(np.abs(B)), 1.0))


def test_what_the_microstepper_model_assumes_shows_in_its_forces():
    rng = np.random.default_rng(2)
    x = _states(rng, 50, 3)
    u = rng.uniform(-9, 9, (4, 50))
    T, N, y, s = (np.asarray(v) for v in MODEL3.motor_forces.map(50)(x, u))
    # a pair's motors carry the same currents at the same gap: equal forces (assumption 3)
    np.testing.assert_allclose(T[0], T[1], rtol=1e-14)
    np.testing.assert_allclose(N[2], N[3], rtol=1e-14)
    # every mover sits at the platform's gap; pair A moves along x, pair B along y
    np.testing.assert_allclose(y, np.tile(x[4], (4, 1)), rtol=1e-14)
    np.testing.assert_allclose(s[0], x[0], rtol=1e-14)
    np.testing.assert_allclose(s[2], x[2], rtol=1e-14)
    # moving across a stator leaves the forces alone (assumption 4): no dependence on x, y
    A = np.asarray(MODEL3.jacobian(x[:, 0], u[:, 0])[0])
    assert np.all(A[:, [0, 2]] == 0)
    # pair A's currents move x and the gap, never y; pair B's the other way
    B = np.asarray(MODEL3.jacobian(x[:, 0], u[:, 0])[1])
    assert np.all(B[3, :2] == 0) and np.all(B[1, 2:] == 0)
    # the thrust of a pair is twice the 2-DOF motor's at the same gap and i_q
    acc2 = STAGE.dynamics(np.vstack([x[4], 0 * x[4], 0 * x[4], 0 * x[4]]), np.vstack([u[0], 0 * u[0]]))
    thrust_2dof = acc2[3] * STAGE.params.mass_horizontal
    np.testing.assert_allclose(T[0] + T[1], 2 * thrust_2dof, rtol=1e-12)


def test_equilibrium_currents_match_the_two_dof_solver_for_a_quarter_of_the_load():
    gaps = np.linspace(0.020, 0.030, 11)
    mine = np.array([FL3.allocate(g, [0.0, 0.0, 0.0]).currents for g in gaps])
    assert np.all(mine[:, [0, 2]] == 0)  # no thrust at rest
    np.testing.assert_array_equal(mine[:, 1], mine[:, 3])  # the pairs share the load
    # one 2-DOF motor carrying m_gap / 4 is the 2-DOF stage under gravity G m_gap / (4 M_v)
    p = MICRO.params
    heavier = dataclasses.replace(p, gravity=p.gravity * MICRO.masses[2] / (4 * p.mass_vertical))
    reference = equilibrium_currents(StageModel(heavier), gaps)
    np.testing.assert_allclose(mine[:, 1], reference.current, rtol=1e-10)
    # and the platform is at rest there
    x = np.zeros((6, gaps.size))
    x[4] = gaps
    acc = MODEL3.dynamics(x, mine.T)[1::2]
    assert np.max(np.abs(acc)) < 1e-10


# --- the input redundancy -----------------------------------------------------------------------
requests = st.tuples(st.floats(-6, 6), st.floats(-6, 6), st.floats(-4, 4), st.floats(0.020, 0.030))


@given(requests)
@settings(max_examples=60, deadline=None)
def test_both_allocations_give_the_requested_accelerations(req):
    vx, vy, vg, gap = req
    x = np.zeros(6)
    x[4] = gap
    for method in ("minimum_norm", "maximum_margin"):
        a = FL3.allocate(gap, [vx, vy, vg], method)
        if not a.defined:
            continue
        acc = MODEL3.dynamics(x, a.currents)[1::2].ravel()
        np.testing.assert_allclose(acc, [vx, vy, vg], atol=1e-8)


@given(requests)
@settings(max_examples=40, deadline=None)
def test_minimum_norm_is_the_smallest_and_maximum_margin_the_lowest_peak(req):
    vx, vy, vg, gap = req
    low = FL3.allocate(gap, [vx, vy, vg], "minimum_norm")
    high = FL3.allocate(gap, [vx, vy, vg], "maximum_margin")
    if not low.defined:
        return
    assert high.peak <= low.peak + 1e-9
    # brute force over the free current i_dA: none with the same forces has a smaller norm
    scan = np.linspace(low.currents[1] - 3, low.currents[1] + 3, 4001)
    k = np.asarray(FL3.coefficients(gap)).ravel()
    n_a = k[1] + k[2] * scan + k[3] * (low.currents[0] ** 2 + scan**2)
    load = MICRO.masses[2] * (MICRO.gravity[2] - vg)
    c = k[1] + k[3] * low.currents[2] ** 2 - (load / 2 - n_a)
    disc = k[2] ** 2 - 4 * k[3] * c
    ok = disc >= 0
    idb = (-k[2] - np.sqrt(disc[ok])) / (2 * k[3])
    norms = scan[ok] ** 2 + idb**2
    assert low.currents[1] ** 2 + low.currents[3] ** 2 <= norms.min() + 1e-6


def test_a_pair_accelerating_hard_leaves_the_levitation_to_the_other():
    # 6 m/s^2 in x at a 25 mm gap: the minimum norm loads both pairs' i_d alike; the maximum
    # margin moves the normal load to pair B and lowers the peak current
    low = FL3.allocate(0.025, [6.0, 0.0, 0.0], "minimum_norm")
    high = FL3.allocate(0.025, [6.0, 0.0, 0.0], "maximum_margin")
    assert low.currents[1] == pytest.approx(low.currents[3])
    assert abs(high.currents[1]) < abs(low.currents[1]) and high.currents[3] > low.currents[3]
    assert high.peak < low.peak


# --- what else the structure admits, and what it refuses -------------------------------------------
def test_individually_driven_motors_are_another_instance():
    # the paper's future work: the four motors driven one by one (eight inputs)
    motors = tuple(dataclasses.replace(m, inputs=(2 * k, 2 * k + 1)) for k, m in enumerate(MICRO.motors))
    six = PlatformModel(dataclasses.replace(MICRO, motors=motors, n_inputs=8, name="individual"))
    x = np.zeros(6)
    x[4] = 0.025
    B = np.asarray(six.jacobian(x, np.full(8, 0.5))[1])
    # three translations, eight inputs: B has rank 3 on the accelerations
    assert np.linalg.matrix_rank(B[1::2]) == 3
    # with each motor's currents equal to its pair's, it is the microstepper again
    u4 = np.array([1.0, 0.5, -0.7, 0.8])
    np.testing.assert_allclose(
        six.dynamics(x, u4[[0, 1, 0, 1, 2, 3, 2, 3]]), MODEL3.dynamics(x, u4), rtol=1e-14
    )


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (dict(thrust=(1.0, 1.0, 0.0)), "unit vector"),
        (dict(normal=(1.0, 0.0, 0.0)), "orthogonal"),
        (dict(inputs=(0, 0)), "distinct"),
    ],
)
def test_a_motor_with_wrong_geometry_is_refused(change, message):
    base = dict(name="m", thrust=(1.0, 0.0, 0.0), normal=(0.0, 0.0, -1.0), inputs=(0, 1))
    with pytest.raises(InputError, match=message):
        Motor(**{**base, **change})


def test_a_platform_with_an_unwired_input_is_refused():
    with pytest.raises(InputError, match="drive no motor"):
        Platform(
            coordinates=("x", "gap"),
            masses=(1.0, 1.0),
            gravity=(0.0, 9.81),
            motors=(Motor("m", (1.0, 0.0), (0.0, -1.0), (0, 1)),),
            n_inputs=3,
            params=StageParameters(),
        )
