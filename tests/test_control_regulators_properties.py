"""Properties of the output regulators (FL, scheduled linear, LQR, PID) and the registry that builds
them, each checked against an independent computation (the plant model's own acceleration, a
matrix exponential and quadrature, numpy's interpolation, the closed-form characteristic
polynomial):

- the observers are fed the acceleration the model predicts for the current a step outputs
  (exactly for the FL regulator, to second order for the regulators on the Jacobian
  linearization, whose vertical observer also sees the gap error's stiffness a21 e1);
- a compensation that depends on the velocities is evaluated at the observers' velocities, and
  the FL regulator's ``margin`` is the feasibility margin R / (4 L4);
- every axis's error is differentiated against the reference's rate, and the internal models
  run at the ``omega0`` given and integrate the tracking error y - r exactly (zero-order hold);
- the scheduled linear regulators take their gains and feed-forward at the reference gap;
- the PID starts bumplessly, integrates each axis's error, differentiates against the
  reference's rate and is placed at its ``design_gap``;
- the registry's ``linear`` regulator adds the equilibrium current, ``linear-noff`` does not.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.integrate import quad_vec
from scipy.linalg import expm

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.control.gains import internal_model
from maglev_oc.control.linear_regulator import axis_linearizations, paper_linear_regulator
from maglev_oc.control.lqr import lqr_regulator
from maglev_oc.control.pid import paper_pid
from maglev_oc.control.registry import build_controller
from maglev_oc.estimation.high_gain import HighGainObserver
from maglev_oc.model.equilibrium import equilibrium_currents

GAP = 0.020  # [m] a scheduled gap (8 mm + 24 x 0.5 mm)


def _step(ctrl, c, y, r):
    return tuple(np.asarray(v, dtype=float).ravel() for v in ctrl.step(c, y, r))


def _reference(gap: float = GAP, position: float = 0.0) -> np.ndarray:
    r = np.zeros(6)
    r[0], r[3] = gap, position
    return r


# --- observers are fed the model's acceleration ----------------------------------------------------
@pytest.mark.parametrize("kind", ["fl", "linear", "lqr"])
def test_observers_are_fed_the_models_acceleration(model, kind):
    """Regulator state (p_v, q_v, p_h, q_h, ...): the observers' update uses the acceleration
    the controller expects its current to cause. On the model that is model.dynamics at
    x = (y1, q_v, y2, q_h) and the output u: exact for the FL regulator (it inverts the model),
    to second order in the deviations for the linear ones (the L4 du^2 terms: under 1e-3 m/s^2
    for du of 0.05 A and errors of 1 um). The observers' sensitivity to a 5e-3 m/s^2 error in the
    acceleration is the tolerance (a sign or index error in it is of order 1 m/s^2)."""
    ctrl = {
        "fl": lambda: FeedbackLinearizingRegulator(model),
        "linear": lambda: paper_linear_regulator(model),
        "lqr": lambda: lqr_regulator(model),
    }[kind]()
    r = _reference()
    y = np.array([GAP + 1e-6, 1e-6])
    c = ctrl.initial_state(y, r)
    c[1], c[3] = 2e-4, -3e-4  # the observers' velocities
    kh, kv = (np.asarray(ctrl.K_h), np.asarray(ctrl.K_v)) if kind == "fl" else ctrl.gains_at(GAP)
    c[4:7] = 0.05 * kv[2:] / (kv[2:] @ kv[2:])  # internal model asking about 0.05 A (or m/s^2)
    c[7:10] = -0.05 * kh[2:] / (kh[2:] @ kh[2:])
    u, c_next, _ = _step(ctrl, c, y, r)
    assert np.all(np.abs(u - ctrl.step(ctrl.initial_state(y, r), y, r)[0].full().ravel()) > 1e-3)
    x_hat = np.array([y[0], c[1], y[1], c[3]])
    acc = model.dynamics(x_hat, u).ravel()
    obs = HighGainObserver(ctrl.sample_time, ctrl.observer_epsilon)
    tol = np.abs(obs.step(np.zeros(2), 0.0, 5e-3) - obs.step(np.zeros(2), 0.0, 0.0))
    if kind == "fl":
        tol = tol * 1e-6  # exact up to round-off
    assert_allclose(c_next[0:2], obs.step(c[0:2], y[0], acc[1]), rtol=0, atol=float(tol.max()))
    assert_allclose(c_next[2:4], obs.step(c[2:4], y[1], acc[3]), rtol=0, atol=float(tol.max()))


def test_compensation_uses_the_observers_velocities(model):
    """FL ``compensation`` d(x) is evaluated at the measured positions and the observers'
    velocities; with a viscous d (proportional to x2, x4) the model plus d then sees exactly v."""
    x = ca.SX.sym("x", 4)
    d = ca.Function("d", [x], [ca.vertcat(-3.0 * x[1], -40.0 * x[3])])
    ctrl = FeedbackLinearizingRegulator(model, compensation=d)
    r = _reference()
    y = np.array([0.021, 0.004])
    c = ctrl.initial_state(y, r)
    c[1], c[3] = 0.03, -0.02
    u, _, diag = _step(ctrl, c, y, r)
    x_hat = np.array([y[0], c[1], y[1], c[3]])
    acc = model.dynamics(x_hat, u).ravel()
    extra = np.asarray(d(x_hat)).ravel()
    # plant acceleration with the effect = (v2, v1); round-off of the transformation only
    assert_allclose([acc[1] + extra[0], acc[3] + extra[1]], [diag[3], diag[2]], rtol=1e-9, atol=1e-9)


def test_fl_margin_is_the_feasibility_margin(model, transformation):
    """diag[0] of the FL step is R / (4 L4) [m/s^2] at the measured gap and the v it asks for
    (feedback.py), positive exactly when the transformation is not clipped."""
    ctrl = FeedbackLinearizingRegulator(model)
    rng = np.random.default_rng(3)
    seen = set()
    for _ in range(12):
        r = _reference(rng.uniform(0.012, 0.028))
        y = np.array([rng.uniform(0.010, 0.030), rng.uniform(-0.01, 0.01)])
        c = ctrl.initial_state(y, r)
        c[1], c[3] = rng.uniform(-0.2, 0.2, 2)
        kv = np.asarray(ctrl.K_v)[2:]
        c[4:7] = rng.uniform(-600.0, 600.0) * kv / (kv @ kv)  # asking up to 600 m/s^2 (R < 0 above ~250)
        _, _, diag = _step(ctrl, c, y, r)
        margin = transformation.feasibility_margin(y[0], diag[2], diag[3])
        assert_allclose(diag[0], margin, rtol=1e-9, atol=1e-12)
        assert diag[1] == float(margin < 0)
        seen.add(bool(margin < 0))
    assert seen == {False, True}  # both sides of the boundary were checked


# --- the internal model runs at omega0 -------------------------------------------------------------
@pytest.mark.parametrize("kind", ["fl", "linear", "lqr"])
def test_internal_model_runs_at_the_given_frequency(model, kind):
    """xi' = phi xi + N e with eig(phi) = {0, +-j omega0} (002 eqs. (21)-(22)), sampled exactly:
    the update of xi in the step has eigenvalues 1 and exp(+-j omega0 Ts), for the omega0 given
    (here 2.2 pi, not the default 1.5 pi). Round-off of a 3 x 3 eigenproblem: 1e-9."""
    omega0 = 2.2 * np.pi
    ctrl = {
        "fl": lambda: FeedbackLinearizingRegulator(model, omega0=omega0),
        "linear": lambda: paper_linear_regulator(model, omega0=omega0),
        "lqr": lambda: lqr_regulator(model, omega0=omega0),
    }[kind]()
    c = ca.SX.sym("c", ctrl.n_state)
    _, c_next, _ = ctrl.step(c, ca.DM([GAP, 0.0]), ca.DM(_reference()))
    jac = ca.Function("j", [c], [ca.jacobian(c_next, c)])(np.r_[GAP, 0, 0, 0, np.zeros(6)]).full()
    want = np.sort_complex(np.exp(np.array([0, 1j * omega0, -1j * omega0]) * ctrl.sample_time))
    for block in (slice(4, 7), slice(7, 10)):
        got = np.sort_complex(np.linalg.eigvals(jac[block, block]))
        assert_allclose(got, want, rtol=0, atol=1e-9)


# --- PID ----------------------------------------------------------------------------------------------
def test_pid_starts_bumplessly(model):
    """At zero error the first output of the PID is the current already flowing, per axis."""
    pid = paper_pid(model)
    r = _reference(GAP, 0.01)
    y = np.array([GAP, 0.01])
    u0 = np.array([0.7, 1.6])  # (i_q, i_d) [A]
    u, _, _ = _step(pid, pid.initial_state(y, r, u0), y, r)
    assert_allclose(u, u0, rtol=0, atol=1e-15)


def test_pid_differentiates_against_the_reference_rate(model):
    """e' = (observer velocity) - (reference velocity) per axis: a stage following a moving
    reference exactly (position and rate) gets only the integrators' current."""
    pid = paper_pid(model)
    r = np.array([GAP, 0.004, 0.0, 0.012, -0.03, 0.0])  # (r_v, r_v', r_v'', r_h, r_h', r_h'')
    y = np.array([r[0], r[3]])
    c = pid.initial_state(y, r, (0.2, 1.5))
    c[1], c[3] = r[1], r[4]
    u, _, _ = _step(pid, c, y, r)
    assert_allclose(u, [0.2, 1.5], rtol=0, atol=1e-15)


@pytest.mark.parametrize("design_gap", [0.014, 0.026])
def test_pid_is_placed_at_the_design_gap(model, design_gap):
    """s^3 + b kd s^2 + (b kp - a) s + b ki has the requested roots for a, b of the linearization
    at ``design_gap`` (not the default 20 mm). Coefficients compared: rtol 1e-10."""
    poles = {"vertical": (-25.0, -30.0, -35.0), "horizontal": (-15.0, -20.0, -25.0)}
    pid = paper_pid(model, poles, design_gap=design_gap)
    lin = axis_linearizations(model, [design_gap])
    for gains, a, b, want in (
        (pid.vertical, lin.stiffness_v[0], lin.gain_v[0], poles["vertical"]),
        (pid.horizontal, 0.0, lin.gain_h[0], poles["horizontal"]),
    ):
        got = np.array([1.0, b * gains.kd, b * gains.kp - a, b * gains.ki])
        assert_allclose(got, np.poly(want), rtol=1e-10)


# --- registry -------------------------------------------------------------------------------------------
def test_registry_linear_with_and_without_feedforward(model):
    """At the set-point with nothing to correct, ``linear`` outputs the equilibrium current of the
    set-point (its feed-forward) and ``linear-noff`` nothing (its internal model builds it up)."""
    r = _reference(GAP, 0.0)
    y = np.array([GAP, 0.0])
    eq = float(equilibrium_currents(model, [GAP]).current[0])
    for name, want in (("linear", eq), ("linear-noff", 0.0)):
        ctrl = build_controller(name, model)
        u, _, _ = _step(ctrl, ctrl.initial_state(y, r), y, r)
        assert_allclose(u, [0.0, want], rtol=1e-9, atol=1e-12, err_msg=name)


def _controller(model, kind):
    return {
        "fl": lambda: FeedbackLinearizingRegulator(model),
        "linear": lambda: paper_linear_regulator(model),
        "lqr": lambda: lqr_regulator(model),
    }[kind]()


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
