"""Nonlinear MPC: grid and estimator pieces, the LQR cross-check, the unconstrained shortcut,
failure handling, closed-loop checks on the twins and the C export (slow)."""

from __future__ import annotations

import dataclasses
import math

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.linalg import solve_continuous_are

from maglev_oc.control.base import OnlineController
from maglev_oc.control.nmpc import (
    DIAG_NAMES,
    NMPCSettings,
    NMPCStep,
    NMPCWeights,
    NonlinearMPC,
    ShootingGrid,
    shift_matrix,
    step_status,
)
from maglev_oc.estimation.extended_high_gain import ExtendedHighGainObserver
from maglev_oc.estimation.high_gain import HighGainObserver
from maglev_oc.model.equilibrium import equilibrium
from maglev_oc.model.hardware import PEAK_CURRENT_LIMIT
from maglev_oc.model.linearization import linearize
from maglev_oc.model.parameters import PAPER_CONSTANTS
from maglev_oc.numerics import c_compiler
from maglev_oc.results import check_result
from maglev_oc.sim.effects import TwinEffects
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.nmpc_instances import record_instances
from maglev_oc.sim.scenarios import Scenario, SetpointSequence, paper_scenarios
from maglev_oc.sim.twin import RigTwin
from tests.compile_support import GENERATED_CFLAGS

MM = 1e-3
TS = 2e-4


@pytest.fixture(scope="module")
def mpc(model) -> NonlinearMPC:
    return NonlinearMPC(model)


def _diag(diag, name):
    return diag[DIAG_NAMES.index(name)]


def _equilibrium_inputs(ctrl: NonlinearMPC, model, gap, dx):
    """(memory, y, ref) of one RTI call at the equilibrium of ``gap`` displaced by dx, with the
    plan resting at the equilibrium and the reference on it."""
    op = equilibrium(model, gap)
    x = op.x + np.asarray(dx, dtype=float)
    mem = ctrl.initial_memory([gap, 0.0], None, op.u)
    mem[0:4] = [x[0], x[1], x[2], x[3]]  # observer: velocities enter the OCP
    y = np.array([x[0], x[2]])
    ref = np.zeros((6, ctrl.grid.horizon + 1))
    ref[0] = gap
    return mem, y, ref, op


# ------------------------------------------------------------------------------------------
def test_is_an_online_controller(mpc):
    assert isinstance(mpc, OnlineController)
    assert mpc.diag_names == DIAG_NAMES
    assert mpc.sample_time == TS


def test_settings_are_validated(model):
    with pytest.raises(ValueError, match="mode"):
        NonlinearMPC(model, mode="sqp")
    with pytest.raises(ValueError, match="qp_solver"):
        NonlinearMPC(model, qp_solver="gurobi")
    with pytest.raises(ValueError, match="multiple of sample_time"):
        NonlinearMPC(model, interval=5.1e-3)
    with pytest.raises(ValueError, match="gap_bounds"):
        NonlinearMPC(model, gap_bounds=(10.0, 29.0))
    with pytest.raises(ValueError, match="disturbance_bandwidth"):
        NonlinearMPC(model, disturbance_bandwidth=400.0)
    with pytest.raises(ValueError, match="i_q"):
        NMPCWeights(i_q=0.0)
    # the settings as one object: defaults resolved, the grid derived, replace re-validates
    settings = NMPCSettings(horizon=40, preview=False)
    assert settings.grid.horizon == 40 and settings.weights == NMPCWeights()
    assert settings.controller_name == "NMPC"
    assert dataclasses.replace(settings, mode="converged").controller_name == "NMPC (converged, IPOPT)"
    with pytest.raises(ValueError, match="mode"):
        dataclasses.replace(settings, mode="sqp")
    with pytest.raises(TypeError):
        NonlinearMPC(model, horizn=20)
    # a model that is not one (a stage file's path, say) is named with what it is
    with pytest.raises(TypeError, match="model must be a StageModel, got str"):
        NonlinearMPC("stage.json")
    with pytest.raises(RuntimeError, match="reset"):
        NonlinearMPC(model).control(0, np.array([0.02, 0.0]), np.zeros((6, 10)))


def test_grid_and_shift():
    grid = ShootingGrid(TS, 25, 20)
    assert grid.node_offsets[:4].tolist() == [0, 1, 26, 51]
    assert_allclose(grid.intervals[:2], [TS, 5e-3])
    assert_allclose(grid.preview, TS + 19 * 5e-3)
    s = shift_matrix(grid)
    # a plan linear in time moves by exactly one sample (interior nodes; the last node and
    # the last input are held): x_j(t) = t, u_j(t) = t at the node times
    t = np.concatenate([[0.0, TS], TS + 5e-3 * np.arange(1, 20)])
    z = np.zeros(120)
    z[0:2] = t[0]
    for j in range(1, 21):
        z[2 + (j - 1) * 6 : 6 + (j - 1) * 6] = t[j]
        if j < 20:
            z[6 + (j - 1) * 6 : 8 + (j - 1) * 6] = t[j]
    zs = s @ z
    assert_allclose(zs[0:2], t[1])  # new u_0 is the old u_1
    for j in range(1, 20):
        assert_allclose(zs[2 + (j - 1) * 6 : 6 + (j - 1) * 6], t[j] + TS, rtol=1e-12)
    # a constant plan is unchanged
    assert_allclose(s @ np.ones(120), np.ones(120))


def test_reference_preview_extrapolates_past_the_end(mpc, model):
    t = np.arange(100) * TS
    ref = np.zeros((6, 100))
    ref[3], ref[4] = 0.1 * t, 0.1
    nodes = mpc.node_references(90, ref)
    times = (90 + mpc.grid.node_offsets) * TS
    assert_allclose(nodes[3], 0.1 * times, atol=1e-15)  # a ramp continues
    assert_allclose(nodes[4], 0.1)
    # without preview a coming step is not seen; with it the nodes after the step read it
    step = np.zeros((6, 1000))
    step[0] = np.where(np.arange(1000) < 100, 20 * MM, 22 * MM)
    assert np.max(mpc.node_references(90, step)[0]) == 22 * MM
    causal = NonlinearMPC(model, preview=False)
    assert_allclose(causal.node_references(90, step)[0], 20 * MM)
    assert_allclose(causal.node_references(90, ref)[3], 0.1 * times, atol=1e-15)


def _estimator_function(est: ExtendedHighGainObserver) -> ca.Function:
    obs, d, y, u = ca.SX.sym("obs", 4), ca.SX.sym("d", 2), ca.SX.sym("y", 2), ca.SX.sym("u", 2)
    return ca.Function("est", [obs, d, y, u], list(est.update(obs, d, y, u)))


def test_estimator_reuses_the_high_gain_observer_and_its_poles(model):
    # With w_d = 0 the (p, q) update is HighGainObserver.step exactly (reuse, not a copy).
    est = ExtendedHighGainObserver(model, TS, 2e-3, 0.0, 5.0)
    hgo = HighGainObserver(TS, 2e-3)
    obs, d = np.array([0.02, 0.01, 0.003, -0.02]), np.array([0.1, -0.2])
    y, u = np.array([0.0201, 0.0031]), [0.2, 1.5]
    o_next, d_next = _estimator_function(est)(obs, d, y, u)
    o_next = np.asarray(o_next).ravel()
    acc = np.asarray(model.f([y[0], obs[1], y[1], obs[3]], u)).ravel()
    assert_allclose(o_next[0:2], hgo.step(obs[0:2, None], y[0], acc[1] + d[0])[:, 0], rtol=1e-13)
    assert_allclose(o_next[2:4], hgo.step(obs[2:4, None], y[1], acc[3] + d[1])[:, 0], rtol=1e-13)
    assert_allclose(np.asarray(d_next).ravel(), d)
    # With w_d = 30 rad/s: the observer pair stays near exp(-Ts/eps) = 0.905 (the slow loop moves
    # it by ~w_d eps = 6 %) and the third pole is the disturbance estimate's, near exp(-w_d Ts).
    ev = np.sort(
        np.abs(np.linalg.eigvals(ExtendedHighGainObserver(model, TS, 2e-3, 30.0, 5.0).error_dynamics()))
    )
    assert np.all(ev < 1)
    assert_allclose(ev[:2], math.exp(-TS / 2e-3), rtol=0.06)
    assert_allclose(-math.log(ev[2]) / TS, 30.0, rtol=0.25)


def test_disturbance_estimate_is_unbiased_on_a_moving_stage(model):
    # A stage moving on the papers' ellipse, measured exactly, with the true acceleration known
    # to the model: the disturbance estimate must stay ~0. (The rectangle-rule integral of the
    # innovation reads the half-sample lag v Ts / 2 as 3.5 m/s^2; the exact integral leaves the
    # curvature term, below 1e-3 m/s^2.)
    est = _estimator_function(ExtendedHighGainObserver(model, TS, 2e-3, 30.0, 5.0))
    t = np.arange(0, 3, TS)
    w, amp = 1.5 * math.pi, 0.03
    obs = np.array([0.02, 0.0, 0.0, amp * w])
    d = np.zeros(2)
    peak = 0.0
    u2 = float(equilibrium(model, 0.02).u[1])
    for tk in t:
        y = np.array([0.02, amp * math.sin(w * tk)])
        u1 = amp * w**2 * math.sin(w * tk) / float(model.L(0.02)[0])  # x4'' = -L1 u1
        o, dd = est(obs, d, y, [u1, u2])
        obs, d = np.asarray(o).ravel(), np.asarray(dd).ravel()
        if tk > 1.5:
            peak = max(peak, abs(d[1]))
    assert peak < 5e-3


def test_terminal_weight_solves_the_dare(mpc, model):
    # P at a tabulated gap is the fixed point of the Riccati map of the RK4-discretized
    # linearization with stage weights (h Q, h R); relative residual at round-off level.
    h = mpc.grid.interval
    q, r = mpc.weights.state_weight * h, mpc.weights.input_weight * h
    op = equilibrium(model, 20 * MM)
    _, a, b = (np.asarray(v) for v in mpc._ocp.rk4_lin(op.x, op.u, [0, 0], h))
    p = mpc.terminal_cost.at(20 * MM)
    k = np.linalg.solve(r + b.T @ p @ b, b.T @ p @ a)
    residual = a.T @ p @ a - a.T @ p @ b @ k + q - p
    assert np.max(np.abs(residual)) < 1e-8 * np.max(np.abs(p))


def test_nmpc_near_equilibrium_is_the_lqr(mpc, model):
    # Cross-check (STYLE): without active constraints the OCP at an equilibrium is the LQ problem
    # of the linearization, whose first input is u0 - u_eq = -K0 dx with the LQR gain of the
    # sampled problem (terminal weight P = its DARE solution). One RTI step from a plan at rest
    # at the equilibrium solves that LQ problem up to the model's curvature, so the difference
    # is O(|dx|^2): it must fall ~4x when dx is halved, and be < 1 % at dx = 10 um / 1 mm/s.
    lqr = mpc.local_lqr(20 * MM)
    errors = []
    for scale in (1.0, 0.5):
        dx = scale * np.array([10e-6, 1e-3, 10e-6, 1e-3])
        mem, y, ref, op = _equilibrium_inputs(mpc, model, 20 * MM, dx)
        step = mpc.step_rti(mem, y, ref)
        u, diag = step.u, step.diag
        assert _diag(diag, "solver_ok") == 1
        expected = -lqr.gain_first @ dx
        errors.append(np.max(np.abs((u - op.u) - expected)))
        assert_allclose(u - op.u, expected, rtol=1e-2, atol=1e-2 * np.max(np.abs(expected)))
    assert errors[1] < 0.35 * errors[0]
    # and the sampled LQR is the continuous-time LQR of (Q, R) to O(h): gains within 10 %
    lin = linearize(model, op.x, op.u)
    q, r = mpc.weights.state_weight, mpc.weights.input_weight
    k_ct = np.linalg.solve(r, lin.B.T @ solve_continuous_are(lin.A, lin.B, q, r))
    assert_allclose(lqr.gain_first, k_ct, rtol=0.1, atol=0.1 * np.max(np.abs(k_ct)))


def test_unconstrained_shortcut_is_the_qp_solution(model):
    # The Riccati step is taken only when it satisfies every inequality, and is then the QP's
    # solution: the two paths agree to the QP solver's accuracy (HPIPM stops at 1e-8 residuals).
    with_lq = NonlinearMPC(model)
    qp_only = NonlinearMPC(model, unconstrained_shortcut=False)
    for dx, constrained in (([50e-6, 0.0, 50e-6, 0.0], False), ([4e-3, 0.0, 15e-3, 0.0], True)):
        mem, y, ref, _ = _equilibrium_inputs(with_lq, model, 20 * MM, dx)
        s1, s2 = with_lq.step_rti(mem, y, ref), qp_only.step_rti(mem, y, ref)
        (u1, m1, d1), (u2, m2, d2) = (s1.u, s1.memory_next, s1.diag), (s2.u, s2.memory_next, s2.diag)
        assert _diag(d1, "solver_ok") == 1 and _diag(d2, "solver_ok") == 1
        assert (_diag(d1, "qp_iterations") != 0) == constrained  # 0: no QP was needed
        assert _diag(d1, "qp_status") == (0 if constrained else -1)
        assert (_diag(d1, "active_constraints") > 0) == constrained
        assert_allclose(u1, u2, atol=1e-6)
        assert_allclose(m1[6:], m2[6:], atol=1e-6)


def test_step_result_says_what_the_update_did(mpc, model):
    # The numeric diagnostics row of an RTI update in words (the result convention of
    # maglev_oc.results): 50 um from the equilibrium needs no QP, 4 mm / 15 mm needs it (as in
    # test_unconstrained_shortcut_is_the_qp_solution), a NaN reading gets the fallback.
    for status, dx in (("unconstrained", [50e-6, 0.0, 50e-6, 0.0]), ("qp_solved", [4e-3, 0.0, 15e-3, 0.0])):
        mem, y, ref, _ = _equilibrium_inputs(mpc, model, 20 * MM, dx)
        step = mpc.step_rti(mem, y, ref)
        check_result(step)
        assert isinstance(step, NMPCStep)
        assert step.success and step.status == status
        assert (step.qp_iterations > 0) == (status == "qp_solved")
        assert step.timings["step"] > 0
        assert_allclose(step.disturbance.as_array(), mem[4:6])
    failed = mpc.step_rti(mem, np.array([np.nan, 0.0]), ref)
    check_result(failed)
    assert not failed.success and failed.status == "fallback" and failed.active_constraints == -1
    assert "fallback" in failed.report()
    # rows the RTI step above does not produce: converged mode, statistics not available
    assert step_status([1, 12, 0.1, 0, 0, 3, 0], mode="converged") == "converged"
    assert step_status([0, 12, 0.1, 0, 0, -1, 1], mode="converged") == "fallback"
    assert step_status([1, -1, 0.1, 0, 0, 3, np.nan]) == "qp_unreported"
    assert step_status([1, 30, 0.1, 0, 0, 3, 1]) == "qp_accepted"


@pytest.mark.parametrize("case", ["nan_measurement", "infeasible"])
def test_failed_qp_is_reported_not_raised(model, case):
    ctrl = NonlinearMPC(model)
    ref = np.zeros((6, 1000))
    ref[0] = 20 * MM
    op = equilibrium(model, 20 * MM)
    ctrl.reset([20 * MM, 0.0], ref[:, 0], op.u)
    for k in range(3):
        ctrl.control(k, np.array([20 * MM, 0.0]), ref)
    plan_u = ctrl.plan()[1][:, 0]
    if case == "nan_measurement":
        y = np.array([np.nan, 0.0])
    else:
        # 28.9 mm and rising at 1 m/s: no current within 9 A stops it below the 29 mm bound
        # at node 2 (5.2 ms later), so the QP has no feasible point
        mem = ctrl.memory
        mem[1] = 1.0
        ctrl._memory = mem
        y = np.array([28.9 * MM, 0.0])
    u, diag = ctrl.control(3, y, ref)
    assert _diag(diag, "solver_ok") == 0
    assert np.all(np.isfinite(u))
    assert math.hypot(*u) <= PEAK_CURRENT_LIMIT + 1e-9
    if case == "nan_measurement":
        # no QP data at all (nor an unconstrained step): the shifted previous plan's first input
        assert_allclose(u, plan_u, atol=1e-9)
    else:
        # the QP is infeasible but its data are fine: the unconstrained (Riccati) step, saturated
        # on the current octagon, is still feedback: the whole available i_d pulls the opening
        # gap shut (negative i_d adds to the magnets' attraction), the flat side of the octagon
        # inscribed in 9 A, where the open-loop shifted plan would have held the +1.5 A of 20 mm
        assert plan_u[1] == pytest.approx(1.497, abs=0.01)
        assert u[1] == pytest.approx(-PEAK_CURRENT_LIMIT * math.cos(math.pi / 8), abs=1e-9)
    assert np.all(np.isfinite(ctrl.memory[6:]))
    # and the loop goes on
    u, diag = ctrl.control(4, np.array([20 * MM, 0.0]), ref)
    assert np.all(np.isfinite(u))


def test_a_qp_iteration_budget_bounds_the_step_and_falls_back_to_the_saturated_riccati_step(model):
    # qrqp limited to one iteration: every sample of the papers' large step that needs the QP
    # (54 of 7500; they need up to 7 iterations) fails and takes the fallback, the saturated
    # unconstrained step. The loop stays feedback: the trajectory keeps within 0.5 mm of the one
    # with exact QP solutions (measured 0.15 mm vertically; 0.5 mm is 5 % of the 10 mm step),
    # where the shifted previous plan as fallback dropped the stage with a budget of 5.
    sc = dataclasses.replace(paper_scenarios()["large_step"], duration=1.5)
    runs = {}
    for budget in (200, 1):
        ctrl = NonlinearMPC(model, preview=False, qp_solver="qrqp", qp_options={"max_iter": budget})
        runs[budget] = ClosedLoop(RigTwin(model), ctrl).run(sc)
        assert runs[budget].success
    needs_qp = runs[200].diagnostic("qp_iterations") != 0
    assert 20 <= np.sum(needs_qp) <= 200 and np.max(runs[200].diagnostic("qp_iterations")) <= 10
    assert np.all(runs[200].diagnostic("solver_ok") == 1)
    fell_back = runs[1].diagnostic("solver_ok") == 0
    assert np.array_equal(fell_back, runs[1].diagnostic("qp_iterations") != 0)  # every QP sample
    assert 20 <= np.sum(fell_back)
    gap_gap = np.max(np.abs(runs[1].x[0] - runs[200].x[0]))
    assert gap_gap < 0.5 * MM
    assert np.max(np.hypot(*runs[1].u)) <= PEAK_CURRENT_LIMIT + 1e-9


def test_prepare_then_feedback_is_the_step_when_the_reading_is_the_predicted_one(model):
    # The split (initial value embedding) linearizes at the predicted initial state x0_pred (the
    # observer's own positions); when the reading is exactly that prediction, x0 = x0_pred and the
    # split is the one-Function step's arithmetic on the same QP: the same current and memory to
    # round-off (1e-12 A, 1e-12 in the memory's units), on an unconstrained and on a constrained
    # sample (4 mm / 15 mm from the equilibrium: the QP with active current bounds)
    ctrl = NonlinearMPC(model)
    for dx, constrained in (([50e-6, 0.0, 50e-6, 0.0], False), ([4e-3, 0.0, 15e-3, 0.0], True)):
        mem, y, ref, _ = _equilibrium_inputs(ctrl, model, 20 * MM, dx)
        assert_allclose(y, mem[[0, 2]], atol=0)  # the reading the observer predicts
        u1, m1, d1 = (v.full().ravel() for v in ctrl.rti_step(mem, y, ref))
        prepared = ctrl.rti_prepare(mem, ref)
        assert prepared.numel() == ctrl.n_prepared
        u2, m2, d2 = (v.full().ravel() for v in ctrl.rti_feedback(mem, prepared, y))
        assert (_diag(d2, "qp_iterations") != 0) == constrained and _diag(d2, "solver_ok") == 1
        assert_allclose(u2, u1, rtol=0, atol=1e-12)
        assert_allclose(m2, m1, rtol=0, atol=1e-12)
        assert_allclose(d2[[0, 1, 5]], d1[[0, 1, 5]], atol=0)


def test_feedback_parts_around_the_qp_solver_are_the_feedback(model):
    # rti_feedback_parts (the C export's feedback, around its own QP solver) with the QP solved by
    # the NMPC's conic on the same data give rti_feedback's outputs, on an unconstrained sample
    # (bit for bit) and a constrained one (1e-12: the conic called on numbers instead of inside
    # the Function), with a reading 10 um off the prediction (the first dynamics rows' bounds
    # corrected by J (x0 - x0_pred)); the solver's steps and status go to the diagnostics
    from maglev_oc.control.nmpc.layout import NX
    from maglev_oc.control.nmpc.rti import PreparedLayout, qp_solver_function, rti_feedback_parts

    ctrl = NonlinearMPC(model, qp_solver="qrqp")
    parts = ctrl._parts
    lq, post = rti_feedback_parts(parts, ctrl._observer, horizon=ctrl.grid.horizon)
    qp = qp_solver_function("qrqp", {}, ctrl.grid.horizon, parts.qp_data)
    layout = PreparedLayout.of(parts.qp_data)
    for dx, constrained in (([50e-6, 0.0, 50e-6, 0.0], False), ([4e-3, 0.0, 15e-3, 0.0], True)):
        mem, y, ref, _ = _equilibrium_inputs(ctrl, model, 20 * MM, dx)
        prepared = ctrl.rti_prepare(mem, ref)
        y = y + 10e-6
        want = [v.full().ravel() for v in ctrl.rti_feedback(mem, prepared, y)]
        dz_lq, feasible = lq(mem, prepared, y)
        assert bool(float(feasible)) != constrained
        p = {k: np.array(v).ravel() for k, v in layout.split(prepared).items()}
        if constrained:
            x0 = np.array(ctrl._observer.state_estimate(ca.DM(mem[0:4]), ca.DM(y))).ravel()
            shift = p["J"].reshape(NX, NX, order="F") @ (x0 - p["x0_pred"])
            lba, uba = p["lba"].copy(), p["uba"].copy()
            lba[:NX] += shift
            uba[:NX] += shift
            h = ca.DM(parts.qp_data.sparsity_out("H"), p["H"])
            a = ca.DM(parts.qp_data.sparsity_out("A"), p["A"])
            sol = qp(h=h, g=p["g"], a=a, lba=lba, uba=uba, lbx=p["lbx"], ubx=p["ubx"])
            dz, lam_x, lam_a, info = sol["x"], sol["lam_x"], sol["lam_a"], (3, 0)
        else:
            dz, lam_x, lam_a, info = dz_lq, np.zeros(ctrl.nz), np.zeros(ctrl.na), (0, -1)
        got = [v.full().ravel() for v in post(mem, prepared, y, dz, lam_x, lam_a, dz_lq, *info)]
        assert_allclose(got[0], want[0], rtol=0, atol=1e-12 if constrained else 0)
        assert_allclose(got[1], want[1], rtol=0, atol=1e-12 if constrained else 0)
        assert (got[2][1], got[2][-1]) == info


def test_prepared_riccati_factor_applies_the_inverse_of_the_condensed_hessian(model):
    # riccati.riccati_factor's pass (its docstring; the export's QP solver runs it in C) written
    # in numpy, against the KKT system of min 1/2 dz' H dz + g' dz under the homogeneous dynamics
    # solved densely (an independent method): the same minimizer to 1e-9 of its scale, for the
    # QP's gradient and for a unit vector on a late state
    from maglev_oc.control.nmpc.rti import PreparedLayout

    ctrl = NonlinearMPC(model)
    n = ctrl.grid.horizon
    mem, _, ref, _ = _equilibrium_inputs(ctrl, model, 20 * MM, [4e-3, 0.0, 15e-3, 0.0])
    layout = PreparedLayout.of(ctrl._parts.qp_data)
    p = {k: np.array(v).ravel() for k, v in layout.split(ctrl.rti_prepare(mem, ref)).items()}
    h = ca.DM(ctrl._parts.qp_data.sparsity_out("H"), p["H"]).full()
    a = ca.DM(ctrl._parts.qp_data.sparsity_out("A"), p["A"]).full()
    dyn = a[np.tile(np.r_[np.ones(4), np.zeros(2)], n).astype(bool)]
    f = p["riccati"].reshape(n, 40)

    def factor_pass(g):
        pv, ks = g[6 * n - 4 :], [None] * n
        for j in range(n - 1, -1, -1):
            b, qi = f[j, :8].reshape(2, 4).T, f[j, 8:12].reshape(2, 2).T
            k_mat, a_mat = f[j, 12:20].reshape(4, 2).T, f[j, 20:36].reshape(4, 4).T
            qu = g[6 * j : 6 * j + 2] + b.T @ pv
            ks[j] = qi @ qu
            if j > 0:
                pv = g[6 * j - 4 : 6 * j] + a_mat.T @ pv - k_mat.T @ qu
        dz, dx = np.zeros(6 * n), np.zeros(4)
        for j in range(n):
            b, k_mat, a_mat = (
                f[j, :8].reshape(2, 4).T,
                f[j, 12:20].reshape(4, 2).T,
                f[j, 20:36].reshape(4, 4).T,
            )
            du = -ks[j] - (k_mat @ dx if j > 0 else 0)
            dx = a_mat @ dx + b @ du if j > 0 else b @ du
            dz[6 * j : 6 * j + 2], dz[6 * j + 2 : 6 * j + 6] = du, dx
        return dz

    kkt = np.block([[h, dyn.T], [dyn, np.zeros((dyn.shape[0], dyn.shape[0]))]])
    unit = np.zeros(6 * n)
    unit[6 * n - 10] = 1.0  # the gap of x_{N-1}
    for g in (p["g"], unit):
        want = np.linalg.solve(kkt, np.r_[-g, np.zeros(dyn.shape[0])])[: 6 * n]
        assert_allclose(factor_pass(g), want, rtol=0, atol=1e-9 * np.max(np.abs(want)))


def test_feedback_differs_from_the_step_by_the_linearization_point_only(model):
    # A reading off the prediction by e (x0 - x0_pred = (e, 0, e, 0)): the feedback's step is the
    # prepared one plus its exact sensitivity, the QP linearized at x0_pred; the one-Function step
    # linearizes at x0. Their currents differ by the change of the first interval's Jacobians
    # over e times the QP's step: bilinear in e and in the plan's distance d from the estimate,
    # plus e^2. With the plan at rest on the equilibrium (d = 0): second order, halving e quarters
    # the difference; with d = 0.5 mm and 0.25 mm: first order in e, halving e halves it, halving
    # d nearly halves it (ratios measured 3.998, 2.04 and 1.92; asserted +- 10 %)
    ctrl = NonlinearMPC(model)
    gaps = {}
    for d in (0.0, 0.25e-3, 0.5e-3):
        mem, y, ref, _ = _equilibrium_inputs(ctrl, model, 20 * MM, [d, 0.0, d, 0.0])
        prepared = ctrl.rti_prepare(mem, ref)
        for e in (20e-6, 10e-6):
            u1 = ctrl.rti_step(mem, y + e, ref)[0].full().ravel()
            u2 = ctrl.rti_feedback(mem, prepared, y + e)[0].full().ravel()
            gaps[d, e] = np.max(np.abs(u2 - u1))
    assert gaps[0.0, 20e-6] / gaps[0.0, 10e-6] == pytest.approx(4.0, rel=0.1)
    assert gaps[0.5e-3, 20e-6] / gaps[0.5e-3, 10e-6] == pytest.approx(2.0, rel=0.1)
    assert gaps[0.5e-3, 10e-6] / gaps[0.25e-3, 10e-6] == pytest.approx(2.0, rel=0.1)
    # at the encoder's resolution (10 um) and 0.5 mm off the plan: 0.5 mA
    assert gaps[0.5e-3, 10e-6] < 1e-3


def test_ideal_twin_small_step_settles_below_0_1_mm(model):
    # Papers' small step (002 Fig. 12) on the ideal twin, first 1 s of the 8 s scenario: the
    # MPC settles to 0.1 mm in ~0.15 s (dominant closed-loop poles 30-90 rad/s); from 0.5 s on
    # the error is below 0.1 mm and at the end below 1 um (the ideal twin has exact positions).
    sc = dataclasses.replace(paper_scenarios()["small_step"], duration=1.0)
    res = ClosedLoop(RigTwin(model), NonlinearMPC(model)).run(sc)
    assert res.success
    late = res.t >= 0.5
    assert np.max(np.abs(res.error[:, late])) < 0.1 * MM
    assert np.max(np.abs(res.error[:, -1])) < 1e-6
    assert np.all(res.diagnostic("solver_ok") == 1)
    # the current command respects the 9 A octagon (its facets at 9 cos(pi/8) A)
    assert np.max(np.hypot(res.u[0], res.u[1])) <= PEAK_CURRENT_LIMIT + 1e-9


# ------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_rig_twin_is_offset_free(model):
    # Rig twin: other constants (Table III at eps = 0.05: C1 +14 %, C4 x2), friction, guide
    # misalignment, cogging, amplifier, 10 um encoder with noise, one sample of delay. Set-point
    # (22 mm, 10 mm) from (20 mm, 0): at steady state the encoder reading sits on the set-point
    # within a count or two (|y - r| <= 20 um, the brief's 10-20 um) and the true error is
    # likewise within 20 um; without the disturbance states the model mismatch leaves an offset
    # several times larger.
    twin = RigTwin(model.with_constants(PAPER_CONSTANTS["table3_eps0.05"]), TwinEffects.rig(), substeps=4)
    sc = Scenario(
        "setpoint",
        "set-point",
        (20 * MM, 0.0, 0.0, 0.0),
        SetpointSequence((0.0,), ((22 * MM, 10 * MM),)),
        2.0,
    )
    res = ClosedLoop(twin, NonlinearMPC(model)).run(sc)
    assert res.success
    late = res.t >= 1.5
    y_err = res.y[:, late] - res.reference[[0, 3]][:, late]
    assert np.max(np.abs(np.mean(y_err, axis=1))) <= 10e-6
    assert np.max(np.abs(y_err)) <= 20e-6
    assert np.max(np.abs(res.error[:, late])) <= 20e-6
    no_d = ClosedLoop(twin, NonlinearMPC(model, disturbance_bandwidth=0.0)).run(sc)
    offset = np.abs(np.mean(no_d.error[:, no_d.t >= 1.5], axis=1))
    assert np.max(offset) > 3 * np.max(np.abs(np.mean(res.error[:, late], axis=1))) + 20e-6


@pytest.mark.slow
def test_rti_agrees_with_the_converged_solution_on_a_smooth_run(model):
    # The start of the ellipse (smooth ramp-in): one Gauss-Newton SQP step per sample vs IPOPT
    # to convergence every sample. The RTI's lag behind the exact solution is second order in the
    # per-sample change of the problem; measured ~4e-7 A. Tolerance 1e-4 A, 1e-4 of the current.
    # 0.15 s: 750 samples of the ramp-in, the reference accelerating from rest.
    sc = dataclasses.replace(paper_scenarios()["sinusoid"], duration=0.15)
    runs = {m: ClosedLoop(RigTwin(model), NonlinearMPC(model, mode=m)).run(sc) for m in ("rti", "converged")}
    for r in runs.values():
        assert r.success and np.all(r.diagnostic("solver_ok") == 1)
    assert_allclose(runs["rti"].u, runs["converged"].u, atol=1e-4)
    assert_allclose(runs["rti"].x, runs["converged"].x, atol=1e-8)


@pytest.mark.slow
def test_horizon_40_and_the_large_step(model):
    # N = 40 (195 ms preview) on the papers' large step, where the linear regulator fails: the
    # current polytope is active during the transient (QP path) and the step settles.
    sc = dataclasses.replace(paper_scenarios()["large_step"], duration=1.0)
    ctrl = NonlinearMPC(model, horizon=40)
    res = ClosedLoop(RigTwin(model), ctrl).run(sc)
    assert res.success
    assert np.all(res.diagnostic("solver_ok") == 1)
    assert np.max(res.diagnostic("active_constraints")) > 0
    qp = res.diagnostic("qp_iterations") != 0  # samples where HPIPM ran
    assert 0 < np.mean(qp) < 0.5
    assert np.all(res.diagnostic("qp_iterations")[qp] > 0)  # its statistics were read
    assert np.all(res.diagnostic("qp_status")[qp] == 0)
    assert np.max(np.abs(res.error[:, res.t >= 0.6])) < 0.1 * MM
    assert np.max(np.hypot(res.u[0], res.u[1])) <= PEAK_CURRENT_LIMIT + 1e-9


@pytest.mark.slow
@pytest.mark.parametrize(
    "qp_solver",
    ["hpipm", pytest.param("qrqp", marks=pytest.mark.extended)],  # hpipm: the default
)
def test_generated_c_matches_python(model, tmp_path, qp_solver):
    # The C export of the RTI step gives the Python Function's outputs on instances recorded in
    # closed loop (the large step: unconstrained and constrained samples). Same operations in the
    # same order, IEEE arithmetic (no -ffast-math at any -O level): the difference is at
    # round-off; tolerance 1e-9 absolute (A, m, m/s). Compiled at -O0 here (GENERATED_CFLAGS,
    # tests/compile_support.py: the same values as the closed-loop runs' -O1, in 40 % of the gcc
    # time on 1.3 MB; 150 instances run).
    codegen = pytest.importorskip("maglev_oc.control.codegen")
    if c_compiler() is None:
        pytest.skip("no C compiler (gcc/cc) available to compile the generated code")

    ctrl = NonlinearMPC(model, qp_solver=qp_solver)
    sc = dataclasses.replace(paper_scenarios()["large_step"], duration=0.3)
    inst = record_instances(ctrl, RigTwin(model), sc, every=10)
    assert len(inst) == 150
    code = codegen.generate_c(ctrl, tmp_path / "gen")
    lib = codegen.compile_shared(code, cflags=GENERATED_CFLAGS)
    external = ca.external(code.function, str(lib))
    expected = codegen.evaluate_instances(ctrl.rti_step, inst)
    got = codegen.evaluate_instances(external, inst)
    for a, b in zip(got, expected, strict=True):
        assert_allclose(a, b, rtol=0, atol=1e-9)
    # the harness replays the same instances and writes the same outputs: built from the
    # generated source (qrqp) or linked against the library just checked (hpipm, whose library
    # links HPIPM in turn; one gcc run of the source instead of two)
    library = lib if qp_solver == "hpipm" else None
    exe = codegen.build_harness(code, tmp_path / "harness", cflags=GENERATED_CFLAGS, library=library)
    path = codegen.write_instances(tmp_path / "inst.bin", inst)
    timing = codegen.run_harness(exe, path, tmp_path / "out.bin", repeat=2)
    assert timing.instances == 150 and timing.failed_calls == 0 and timing.median > 0
    check_result(timing)
    for a, b in zip(codegen.read_outputs(tmp_path / "out.bin"), expected, strict=True):
        assert_allclose(a, b, rtol=0, atol=1e-9)
