"""Properties of the controllers that small injected bugs break (issue 21).

A reviewer injects one plausible bug at a time (a wrong sign or index, an ignored option, a
dropped validation) into ``maglev_oc/control/``; the quick suite must then fail. The cases here
were found by trying such bugs and keeping those no other quick test caught. Each test checks
what a controller promises, against an independent computation:

- the observers of the output regulators are fed the acceleration the plant model predicts
  for the current the step outputs (exactly for the FL regulator, to second order in the
  current for the regulators on the Jacobian linearization);
- a compensation that depends on the velocities is evaluated at the observers' velocities;
- the FL regulator's ``margin`` diagnostic is the feasibility margin R / (4 L4) of
  :class:`~maglev_oc.model.feedback.FeedbackTransformation`;
- the internal model of every output regulator oscillates at the ``omega0`` it was given
  (discrete eigenvalues 1 and exp(+-j omega0 Ts));
- the LQR gains are optimal for their own axis's weights and ``omega0``: K = -R^-1 B^T P with P
  the cost matrix of K itself (a Lyapunov equation, not the Riccati equation the design solves);
  the Bryson maxima must be positive;
- the PID starts bumplessly from the current flowing, differentiates the error against the
  reference's rate, and is placed at the ``design_gap`` it is given;
- the registry's ``linear-noff`` regulator adds no equilibrium current, ``linear`` does.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.linalg import solve_continuous_lyapunov

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.control.gains import augmented_axis
from maglev_oc.control.linear_regulator import axis_linearizations, paper_linear_regulator
from maglev_oc.control.lqr import DEFAULT_WEIGHTS, AxisWeights, lqr_regulator
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


# --- LQR --------------------------------------------------------------------------------------------
def _bryson(w: AxisWeights) -> tuple[np.ndarray, np.ndarray]:
    """Bryson's rule written out: Q = diag(1 / max^2), R = 1 / current_max^2."""
    maxima = np.array([w.error, w.error_rate, *w.internal_model])
    return np.diag(maxima**-2.0), np.array([[w.current**-2.0]])


def test_lqr_gains_are_optimal_for_their_own_axis_and_frequency(model):
    """For w = K z the cost of K is z0' P z0 with (A + B K)' P + P (A + B K) + Q + K' R K = 0; K is
    optimal exactly when K = -R^-1 B' P (the stationarity condition). Checked with the axis's own
    weights and the omega0 given (2 pi, not the default), at three scheduled gaps. The Lyapunov
    solve of this 5 x 5 system (Q spanning 1e1..1e11) is accurate to about 1e-7 relative."""
    omega0 = 2.0 * np.pi
    reg = lqr_regulator(model, omega0=omega0)
    lin = reg.schedule
    for j in (0, len(lin.gap) // 2, len(lin.gap) - 1):
        axes = (
            ("vertical", reg.gains_v[:, j], lin.stiffness_v[j], lin.gain_v[j]),
            ("horizontal", reg.gains_h[:, j], 0.0, lin.gain_h[j]),
        )
        for axis, k, stiffness, gain in axes:
            a, b = augmented_axis(omega0, stiffness, gain)
            q, r = _bryson(DEFAULT_WEIGHTS[axis])
            closed = a + b @ k[None, :]
            assert np.all(np.linalg.eigvals(closed).real < 0), axis
            p = solve_continuous_lyapunov(closed.T, -(q + k[:, None] @ r @ k[None, :]))
            stationary = -np.linalg.solve(r, b.T @ p).ravel()
            assert_allclose(k, stationary, rtol=1e-5, err_msg=f"{axis} at {lin.gap[j]}")


@pytest.mark.parametrize("field", ["error", "error_rate", "current"])
@pytest.mark.parametrize("value", [0.0, -1.0, float("nan")])
def test_lqr_refuses_maxima_that_are_not_positive(field, value):
    """Bryson's rule divides by the maxima: a zero or negative one is refused when the weights are
    made (before any design uses them), naming the entry."""
    w = DEFAULT_WEIGHTS["vertical"]
    kwargs = {
        "error": w.error,
        "error_rate": w.error_rate,
        "internal_model": w.internal_model,
        "current": w.current,
    }
    kwargs[field] = value
    with pytest.raises(ValueError, match=f"positive and finite: {field} = "):
        AxisWeights(**kwargs)


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
