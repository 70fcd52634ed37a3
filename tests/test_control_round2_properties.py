"""Properties of the controllers that a second hand-injection round found untested (issue 21).

Bugs were injected one at a time into ``maglev_oc/control/`` and the control tests run; these
tests kill the ones that slipped. Each checks what a control engineer relies on, against an
independent computation:

- the output regulators (FL, linear, LQR) differentiate each axis's error against the
  reference's rate: moving the observer's velocity and the reference's rate together leaves
  the current and the internal models unchanged (to 1e-12 relative: the same arithmetic on
  shifted operands), moving the velocity alone does not;
- their internal models are driven by the tracking error y - r and sampled exactly:
  xi+ = expm(phi Ts) xi + (int_0^Ts expm(phi s) ds N) (y - r), the integral by adaptive
  quadrature (scipy quad_vec, 1e-13 relative), checked on references whose rates and
  accelerations are not zero (1e-9 relative: the quadrature and a 4 x 4 expm);
- the scheduled linear regulators take their gains and feed-forward at the reference gap r_v,
  not the measured gap: u = (K_h(r_v) z_h, u2_eq(r_v) + K_v(r_v) z_v) with the tables
  interpolated by numpy (both linear interpolation: 1e-9 relative);
- :func:`check_paper_gains` calls a gain vector stable only if all five poles are in the
  open left half plane (at omega0 = 30 rad/s the printed K_h leaves two outside), and its
  relative difference is to the recomputed gains;
- the microstepper's levitation-first limiter flags the pair whose thrust it cut (each pair
  by itself), and an unreachable gap request sends i_d to the end of [-I, I] that comes
  closest: both ends are reached, one per direction (to the limiter's 1e-9 slack);
- the microstepper honours a given tracking time constant T_t: every axis's
  phi - L k_xi has characteristic polynomial (s + 1/T_t)^3 (coefficients, 1e-6 relative: the
  Ackermann solve on gains up to 4e5);
- the amplifiers' saturation scales each pair's (i_q, i_d) to Euclidean magnitude ``peak``
  with the direction kept, and leaves pairs under the limit alone (1e-12);
- the NMPC's settings refuse a disturbance bandwidth above 0.5 / eps, and R = diag(i_q, i_d)
  in the order of u;
- the PID integrates each axis's error against it (the k-th command under a held error is
  u0 - kp e - ki Ts k e, i_q on the horizontal error, i_d on the vertical);
- the microstepper's "margin" diagnostic is the room left in v_gap before R = 0;
- the linear regulators' vertical observer is fed a21 e1 + b22 du2: off the reference gap it
  matches the model's acceleration to second order.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.integrate import quad_vec
from scipy.linalg import expm

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.control.gains import augmented_axis, check_paper_gains, internal_model, place_axis
from maglev_oc.control.linear_regulator import paper_linear_regulator
from maglev_oc.control.lqr import lqr_regulator
from maglev_oc.control.microstepper import MicrostepperRegulator, saturated_currents
from maglev_oc.control.nmpc import NMPCSettings, NMPCWeights
from maglev_oc.control.pid import paper_pid
from maglev_oc.errors import InputError
from maglev_oc.estimation.high_gain import DEFAULT_EPSILON, HighGainObserver
from maglev_oc.model.platform import microstepper
from tests.test_control_injected_properties import _reference

GAP = 0.020  # [m] an operating gap of the papers' runs
PLATFORM = microstepper()
PEAK = 9.0  # [A] the amplifiers' limit per pair (002 Sec. 4)


def _controller(model, kind):
    return {
        "fl": lambda: FeedbackLinearizingRegulator(model),
        "linear": lambda: paper_linear_regulator(model),
        "lqr": lambda: lqr_regulator(model),
    }[kind]()


def _step(ctrl, c, y, r):
    return tuple(np.asarray(v, dtype=float).ravel() for v in ctrl.step(c, y, r))


def _state(rng) -> np.ndarray:
    """A regulator state near the operating point: observers at (GAP, 1 mm), moving; internal
    models charged."""
    c = np.zeros(10)
    c[0:4] = [GAP, rng.uniform(-0.02, 0.02), 1e-3, rng.uniform(-0.05, 0.05)]
    c[4:10] = rng.uniform(-1e-6, 1e-6, 6)
    return c


# --- the error rate is taken against the reference's rate ---------------------------------------------
@pytest.mark.parametrize("kind", ["fl", "linear", "lqr"])
def test_output_regulators_differentiate_against_the_reference_rate(model, kind):
    ctrl = _controller(model, kind)
    rng = np.random.default_rng(1)
    for _ in range(3):
        c = _state(rng)
        y = np.array([GAP + 2e-4, 1.2e-3])
        r = np.array([GAP, 0.003, 0.1, 1e-3, -0.02, 0.2])
        u, c_next, _ = _step(ctrl, c, y, r)
        for vel, rate in ((1, 1), (3, 4)):  # (q_v, r_v'), (q_h, r_h')
            shift = rng.uniform(0.01, 0.05)
            c2, r2 = c.copy(), r.copy()
            c2[vel] += shift
            r2[rate] += shift
            u2, c2_next, _ = _step(ctrl, c2, y, r2)
            assert_allclose(u2, u, rtol=1e-12, atol=1e-12)
            assert_allclose(c2_next[4:], c_next[4:], rtol=1e-12, atol=1e-18)
            u3, _, _ = _step(ctrl, c2, y, r)  # the velocity alone moved: the current does
            assert np.max(np.abs(u3 - u)) > 1e-3


# --- the internal models: driven by y - r, sampled exactly ---------------------------------------------
@pytest.mark.parametrize("kind", ["fl", "linear", "lqr"])
def test_internal_models_integrate_the_tracking_error_exactly(model, kind):
    ctrl = _controller(model, kind)
    ts, omega0 = ctrl.sample_time, ctrl.omega0
    phi, n, _ = internal_model(omega0)
    phi_d = expm(phi * ts)
    gamma_d, _ = quad_vec(lambda s: expm(phi * s) @ n, 0.0, ts, epsrel=1e-13, epsabs=0.0)
    rng = np.random.default_rng(2)
    for _ in range(3):
        c = _state(rng)
        y = np.array([GAP + rng.uniform(-5e-4, 5e-4), rng.uniform(-2e-3, 2e-3)])
        r = np.array([GAP, 0.004, -0.3, 5e-4, 0.03, 0.7])  # rates and accelerations not zero
        _, c_next, _ = _step(ctrl, c, y, r)
        for block, err in ((slice(4, 7), y[0] - r[0]), (slice(7, 10), y[1] - r[3])):
            want = phi_d @ c[block] + gamma_d.ravel() * err
            assert_allclose(c_next[block], want, rtol=1e-9, atol=1e-20)


# --- the scheduled regulators are scheduled on the reference gap -----------------------------------
@pytest.mark.parametrize("kind", ["linear", "lqr"])
def test_scheduled_regulators_use_the_reference_gaps_design(model, kind):
    ctrl = _controller(model, kind)
    rng = np.random.default_rng(3)
    lin = ctrl.schedule
    for r_v, y_v in ((0.0203, 0.0241), (0.0162, 0.0128)):  # reference between schedule points
        c = _state(rng)
        y = np.array([y_v, 2e-3])
        r = np.array([r_v, 0.002, 0.0, 1e-3, -0.01, 0.0])
        u, _, _ = _step(ctrl, c, y, r)
        kh, kv = ctrl.gains_at(r_v)
        z_h = np.r_[y[1] - r[3], c[3] - r[4], c[7:10]]
        z_v = np.r_[y[0] - r[0], c[1] - r[1], c[4:7]]
        u2_eq = np.interp(r_v, lin.gap, lin.u2_eq)
        assert_allclose(u, [kh @ z_h, u2_eq + kv @ z_v], rtol=1e-9)


# --- the paper gains' check ------------------------------------------------------------------------
def test_paper_gain_check_needs_every_pole_stable_and_compares_to_the_recomputed_gains():
    omega0 = 30.0  # [rad/s] the printed K_h leaves two poles in the right half plane here
    for check in check_paper_gains(omega0):
        printed = np.asarray(check.paper.printed, dtype=float)
        a, b = augmented_axis(omega0)
        stable = bool(np.all(np.linalg.eigvals(a + b @ printed[None, :]).real < 0))
        assert check.success is stable and check.status == ("stable" if stable else "unstable")
        computed = place_axis(check.paper.poles, omega0)
        assert_allclose(check.rel_difference, np.abs(printed - computed) / np.abs(computed), rtol=1e-12)
    assert [c.success for c in check_paper_gains(omega0)] == [False, True, True]


# --- the microstepper ---------------------------------------------------------------------------------
def test_microstepper_limiter_flags_each_pair_it_cuts():
    """A thrust request on x alone cuts pair A only, on y alone pair B only; a cut pair sits at
    the limit (slack 1e-9) and the uncut one below it."""
    reg = MicrostepperRegulator(PLATFORM)
    for v, flags in (([400.0, 0.0, 0.0], [1, 0, 0]), ([0.0, 400.0, 0.0], [0, 1, 0])):
        u, limited = (np.asarray(a, dtype=float).ravel() for a in reg.limiter(0.025, v))
        assert_allclose(limited, flags)
        mags = np.hypot(u[0::2], u[1::2])
        cut = np.array(flags[:2], dtype=bool)
        assert_allclose(mags[cut], PEAK, rtol=1e-8)
        assert np.all(mags[~cut] < PEAK * (1 - 1e-6))


def test_microstepper_unreachable_gap_request_goes_to_the_closest_end():
    """Far more and far less normal force than the motors give: i_d at -I and at +I."""
    reg = MicrostepperRegulator(PLATFORM)
    ends = []
    for v_gap in (-1e4, 1e4):  # [m/s^2]
        u, limited = (np.asarray(a, dtype=float).ravel() for a in reg.limiter(0.025, [0.0, 0.0, v_gap]))
        assert limited[2] == 1
        assert u[1] == u[3]
        ends.append(u[1])
    assert_allclose(sorted(ends), [-PEAK, PEAK], rtol=1e-8)


def test_microstepper_honours_the_tracking_time_constant_given():
    tau = 0.2  # [s] not the dominant time constant of either gain vector (0.130 s, 0.106 s)
    reg = MicrostepperRegulator(PLATFORM, tracking_time_constant=tau)
    assert_allclose(reg.tracking_time_constants, [tau] * 3, rtol=0)
    phi, _, _ = internal_model(reg.omega0)
    for gains, gain_l in zip((reg.K_h, reg.K_h, reg.K_v), reg.tracking_gains, strict=True):
        closed = phi - gain_l[:, None] @ gains[None, 2:]
        assert_allclose(np.poly(closed), np.poly([-1 / tau] * 3), rtol=1e-6)


def test_saturation_scales_each_pair_to_the_limit_keeping_its_direction():
    rng = np.random.default_rng(4)
    u_sym = ca.SX.sym("u", 4)
    sat = ca.Function("sat", [u_sym], list(saturated_currents(u_sym, PEAK)))
    for _ in range(20):
        u = rng.uniform(-12.0, 12.0, 4)
        got, over = (np.asarray(a, dtype=float).ravel() for a in sat(u))
        for j in range(2):
            pair, out = u[2 * j : 2 * j + 2], got[2 * j : 2 * j + 2]
            mag = np.hypot(*pair)
            assert over[j] == float(mag > PEAK)
            want = pair * min(1.0, PEAK / mag)  # the same direction, Euclidean magnitude <= peak
            assert_allclose(out, want, rtol=1e-12, atol=1e-12)


# --- the NMPC's settings --------------------------------------------------------------------------
def test_nmpc_refuses_a_disturbance_bandwidth_near_the_observers():
    limit = 0.5 / DEFAULT_EPSILON  # [rad/s] w_d eps <= 0.5 (settings' message)
    NMPCSettings(disturbance_bandwidth=limit * 0.99)
    with pytest.raises(InputError, match="disturbance_bandwidth"):
        NMPCSettings(disturbance_bandwidth=limit * 1.5)


def test_nmpc_input_weight_is_in_the_order_of_u():
    w = NMPCWeights(i_q=3.0, i_d=0.5)
    assert_allclose(w.input_weight, np.diag([3.0, 0.5]))
    assert_allclose(w.state_weight, np.diag([w.gap, w.gap_rate, w.position, w.position_rate]))


# --- LQR with a current maximum other than 1 A ------------------------------------------------------
def test_lqr_weighs_the_current_by_its_squared_maximum(model):
    """Bryson's rule R = 1 / current_max^2, visible only when current_max != 1 A (the defaults'
    1 A hides R = 1 / current_max): K = -R^-1 B' P with P the cost of K itself (Lyapunov), as in
    test_control_injected_properties (1e-5 relative, its tolerance)."""
    from scipy.linalg import solve_continuous_lyapunov

    from maglev_oc.control.lqr import AxisWeights
    from tests.test_control_injected_properties import _bryson

    weights = {
        "vertical": AxisWeights(2e-2, 0.5, (3e-6, 1e-4, 1e-3), 0.4),
        "horizontal": AxisWeights(2e-2, 0.2, (3e-5, 1e-4, 1e-3), 2.5),
    }
    reg = lqr_regulator(model, weights, gaps=[0.015, GAP])  # the interpolant needs two
    lin = reg.schedule
    for axis, k, stiffness, gain in (
        ("vertical", reg.gains_v[:, 1], lin.stiffness_v[1], lin.gain_v[1]),
        ("horizontal", reg.gains_h[:, 1], 0.0, lin.gain_h[1]),
    ):
        a, b = augmented_axis(reg.omega0, stiffness, gain)
        q, r = _bryson(weights[axis])
        p = solve_continuous_lyapunov((a + b @ k[None, :]).T, -(q + k[:, None] @ r @ k[None, :]))
        assert_allclose(k, -np.linalg.solve(r, b.T @ p).ravel(), rtol=1e-5, err_msg=axis)


def test_the_pid_integrates_each_axis_error_against_it(model):
    """du = -(kp e + kd e' + ki int e) on both axes (PidGains' docstring): held at constant errors
    (e1, e2) with the observers at rest on the reading (so e' = 0), the k-th command is
    u0 - kp e - ki Ts k e on each axis, i_q on the horizontal error and i_d on the vertical.
    1e-9 relative: the same sums in another order."""
    pid = paper_pid(model)
    r = np.array([0.02, 0.0, 0.0, 0.004, 0.0, 0.0])
    e = np.array([0.3e-3, -0.5e-3])  # (gap, horizontal) errors [m]
    y = np.array([r[0] + e[0], r[3] + e[1]])
    u0 = np.array([0.4, -1.1])  # (i_q, i_d) already flowing [A]
    c = pid.initial_state(y, r, u0)
    ts = pid.sample_time
    for k in range(25):
        u, c, _ = (np.asarray(v).ravel() for v in pid.step(c, y, r))
        expect_q = u0[0] - pid.horizontal.kp * e[1] - pid.horizontal.ki * ts * k * e[1]
        expect_d = u0[1] - pid.vertical.kp * e[0] - pid.vertical.ki * ts * k * e[0]
        assert_allclose(u, [expect_q, expect_d], rtol=1e-9, atol=1e-12)


def test_the_microsteppers_margin_is_the_room_left_in_v_gap():
    """The "margin" diagnostic is how much further v_gap could rise before R = 0 (R is affine in
    v_gap): with it added, R is zero (to 1e-9 of R's scale at v: rounding of an affine function),
    and it is positive exactly where R is (the allocation is defined), on sampled (gap, v)."""
    ctrl = MicrostepperRegulator(microstepper())
    margin = ctrl._margin_function()
    transform = ctrl.transformation.function
    rng = np.random.default_rng(26)
    signs = []
    for _ in range(40):
        gap = rng.uniform(0.015, 0.03)
        v = rng.uniform(-20.0, 20.0, 3)
        m = float(margin(gap, v))
        R = float(transform(gap, v)[1])
        R_at = float(transform(gap, v + np.array([0.0, 0.0, m]))[1])
        assert abs(R_at) <= 1e-9 * max(abs(R), 1.0)
        signs.append(np.sign(m) == np.sign(R))
    assert all(signs)


@pytest.mark.parametrize("kind", ["linear", "lqr"])
def test_the_linear_observers_are_fed_the_gap_errors_stiffness_too(model, kind):
    """The regulators on the Jacobian linearization feed their vertical observer
    e1'' = a21 e1 + b22 du2 (module docstring of linear_regulator): 50 um off the reference gap
    the a21 e1 part is tens of mm/s^2, and the fed acceleration (read off the observer's update,
    which is affine in it) equals the model's at the measured gap and the output current to
    second order. Measured 2e-4 (linear) and 4e-4 m/s^2 (LQR) at 50 um; 2e-3 m/s^2 allows 5x."""
    ctrl = paper_linear_regulator(model) if kind == "linear" else lqr_regulator(model)
    r = _reference()
    y = np.array([GAP + 50e-6, 1e-6])
    c = ctrl.initial_state(y, r)
    u, c_next, _ = _step(ctrl, c, y, r)
    obs = HighGainObserver(ctrl.sample_time, ctrl.observer_epsilon)
    base, unit = obs.step(c[0:2], y[0], 0.0), obs.step(c[0:2], y[0], 1.0)
    fed = float((c_next[0:2] - base) @ (unit - base) / ((unit - base) @ (unit - base)))
    acc = model.dynamics(np.array([y[0], c[1], y[1], c[3]]), u).ravel()
    assert abs(fed - acc[1]) <= 2e-3
