"""The 3-DOF microstepper's FL regulator with anti-windup on its rig twin (issue 13, items 3-4;
002 Sec. 8, Figs. 15-18).

* (a) the paper's five set-points settle below 0.1 mm in < 3 s and to 10 um in < 5 s on the rig
  twin (noise, quantization, friction, cogging, amplifier limit and lag, delay);
* (b) the sinusoid's mean tracking errors, bounded by the paper's and by the encoder's floor;
* (c) a 90 mm step on x and y at once drives both pairs into the 9 A limit: with anti-windup the
  loop settles; without back-calculation it overshoots into the stoppers (and diverges without
  them); with the amplifiers' own vector scaling instead of levitation-first limiting it drops;
* (d) the controller's transformation against the model: the currents it commands give the
  accelerations it asked for (PlatformModel.f), and its levitation-first limiter against a
  bisection on the model.

Measured on this twin (seed 0) when written: set-points settle to 0.1 mm in 1.30-1.41 s (x, y)
and 0.76-0.87 s (gap), to 10 um in 1.67-1.75 s (x, y) and 0.97-1.72 s (gap); sinusoid mean
errors 8.0 / 5.9 / 45 um (x / y / gap) against the paper's 120 / 59 / 130 um.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.control.gains import PAPER_K_H, PAPER_K_V, internal_model
from maglev_oc.control.microstepper import MicrostepperRegulator, anti_windup_gain, dominant_time_constant
from maglev_oc.errors import InputError
from maglev_oc.model.allocation import MicrostepperTransformation
from maglev_oc.model.platform import PlatformModel, microstepper
from maglev_oc.results import check_result
from maglev_oc.sim.effects import Cogging, GuideFriction
from maglev_oc.sim.microstepper import MicrostepperLoop, evaluate_microstepper
from maglev_oc.sim.microstepper_scenarios import microstepper_scenarios
from maglev_oc.sim.microstepper_twin import MicrostepperEffects, MicrostepperTwin

MM = 1e-3
UM = 1e-6
PEAK = 9.0  # [A] the amplifiers' limit per pair (002 Sec. 4)
# 002 Sec. 8: "the position error settles below 0.1 mm in less than 3 s and to the encoder
# resolution of 10 um in less than 5 s"; "average x-axis and z-axis tracking errors are about
# 0.12 mm and 0.13 mm ... The average y-axis tracking error is 59 um".
PAPER_SETTLE_01MM = 3.0  # [s]
PAPER_SETTLE_10UM = 5.0  # [s]
PAPER_MEAN_ERROR = np.array([0.12 * MM, 59 * UM, 0.13 * MM])  # x, y, gap [m]

PLATFORM = microstepper()
SCENARIOS = microstepper_scenarios()


@pytest.fixture(scope="module")
def rig_twin():
    return MicrostepperTwin(PLATFORM)


@pytest.fixture(scope="module")
def with_anti_windup(rig_twin):
    return MicrostepperLoop(rig_twin, MicrostepperRegulator(PLATFORM))


@pytest.fixture(scope="module")
def saturation_runs(rig_twin, with_anti_windup):
    """The saturation scenario with anti-windup, without back-calculation, and with the
    amplifiers' vector scaling instead of levitation-first limiting."""
    scenario = SCENARIOS["saturation"]
    no_aw = MicrostepperRegulator(PLATFORM, anti_windup=False, name="no anti-windup")
    radial = MicrostepperRegulator(PLATFORM, levitation_first=False, name="amplifier scaling")
    return {
        "anti_windup": with_anti_windup.run(scenario),
        "no_anti_windup": MicrostepperLoop(rig_twin, no_aw).run(scenario),
        "amplifier_scaling": MicrostepperLoop(rig_twin, radial).run(scenario),
    }


# --- the anti-windup design ------------------------------------------------------------------------
def test_tracking_time_constant_and_gain_place_the_poles():
    # The printed gains' slowest closed-loop poles are -7.71 +- 1.62j (K_h) and -9.42 +- 1.83j
    # (K_v) (gains.axis_poles); 4 digits is the precision quoted in the module docstring.
    assert_allclose(dominant_time_constant(PAPER_K_H), 1 / 7.7096, rtol=1e-4)
    assert_allclose(dominant_time_constant(PAPER_K_V), 1 / 9.4191, rtol=1e-4)
    phi, _, _ = internal_model()
    for gains in (PAPER_K_H, PAPER_K_V):
        tau = dominant_time_constant(gains)
        L = anti_windup_gain(gains, tau)
        poles = np.linalg.eigvals(phi - np.outer(L, gains[2:]))
        # a triple eigenvalue moves by ~ (machine eps * |phi|)^(1/3) ~ 1e-4 relative under rounding
        assert_allclose(poles, np.full(3, -1 / tau), rtol=1e-3)


def test_options_are_validated():
    with pytest.raises(InputError, match="anti_windup"):
        MicrostepperRegulator(PLATFORM, anti_windup="yes")
    with pytest.raises(InputError, match="time_constant"):
        MicrostepperRegulator(PLATFORM, tracking_time_constant=-0.1)
    with pytest.raises(TypeError, match="unknown effect"):
        MicrostepperEffects.rig(misalignment=None)


# --- the twin --------------------------------------------------------------------------------------
def test_ideal_twin_holds_the_holding_currents():
    # Open loop at the minimum-norm holding currents the RK4 step of an equilibrium is the
    # equilibrium up to rounding (1e-12 m over 100 steps).
    twin = MicrostepperTwin(PLATFORM, MicrostepperEffects.ideal())
    q0 = np.array([12 * MM, 0, -30 * MM, 0, 27 * MM, 0])
    u0 = twin.holding_currents(q0[4])
    s = twin.initial_state(q0, u0)
    for _ in range(100):
        s, _ = twin.step(s, u0)
    assert_allclose(np.asarray(s).ravel()[:6], q0, atol=1e-12)


def test_twin_cogging_and_friction_per_motor_and_axis():
    # Cogging (000 eq. (9)) of each motor at its own gap and position along its stator: pair A's
    # two movers at x, pair B's at y, all pulling along their normal (-gap); friction opposes
    # each axis's velocity. Written out by hand from the Cogging and GuideFriction docstrings.
    cog = Cogging()
    friction = (GuideFriction(0.1, 1.0), GuideFriction(0.2, 1.5), GuideFriction(0.3, 2.0))
    twin = MicrostepperTwin(PLATFORM, MicrostepperEffects(cogging=cog, friction=friction))
    bare = MicrostepperTwin(PLATFORM, MicrostepperEffects.ideal())
    q = np.array([7 * MM, 0.02, -11 * MM, -0.03, 22 * MM, 0.01])
    i = np.array([0.5, 1.5, -0.4, 1.5])
    dahl = np.array([0.05, -0.1, 0.2])  # [N]
    extra = np.asarray(twin.acceleration(q, i, dahl) - bare.acceleration(q, i, dahl)).ravel()
    xi = cog.peak_at_reference * (cog.reference_gap / q[4]) ** cog.exponent
    t1 = PLATFORM.params.slot_pitch
    normal = 2 * xi * (np.sin(np.pi * q[0] / t1) + np.sin(np.pi * q[2] / t1))
    m = np.asarray(PLATFORM.masses)
    expected = -(dahl + np.array([f.viscous for f in friction]) * q[1::2]) / m
    expected[2] -= normal / m[2]
    assert_allclose(extra, expected, rtol=1e-12, atol=1e-12)


# --- (d) the transformation against the model ------------------------------------------------------
def _random_controller_inputs(rng, n, error_scale):
    """Controller states, readings and references in the operating region; errors ~ error_scale [m]."""
    y = np.vstack([rng.uniform(-50, 50, (2, n)) * MM, rng.uniform(20, 30, n) * MM])
    r = np.zeros((9, n))
    r[0::3] = y - rng.normal(0, error_scale, (3, n))
    r[1::3] = rng.normal(0, 0.01, (3, n))  # [m/s]
    c = np.zeros((15, n))
    c[0:6:2] = y
    c[1:6:2] = rng.normal(0, 0.01, (3, n))
    # internal models of the size a few m/s^2 of v take (gains 1.5e5, 4.5e4, 1.2e4 on xi1..xi3)
    c[6:] = rng.normal(0, 1, (9, n)) * np.tile([1e-6, 1e-5, 1e-4], 3)[:, None]
    return c, y, r


def test_commanded_currents_give_the_requested_accelerations_on_the_model():
    # v from the printed gains in numpy, the currents from the controller's CasADi step, the
    # accelerations from PlatformModel.f: the transformation is the model's exact inverse, so
    # they agree to rounding (|v| ~ 1-10 m/s^2; 1e-9 m/s^2 is a millionth of the 10 um encoder
    # step's equivalent acceleration and far above double rounding).
    ctrl = MicrostepperRegulator(PLATFORM)
    n = 400
    c, y, r = _random_controller_inputs(np.random.default_rng(3), n, error_scale=1 * MM)
    u, c_next, diag = (np.asarray(a) for a in ctrl.step.map(n)(c, y, r))
    z = [
        np.vstack([y[j] - r[3 * j], c[2 * j + 1] - r[3 * j + 1], c[6 + 3 * j : 9 + 3 * j]]) for j in range(3)
    ]
    v = np.vstack([PAPER_K_H @ z[0], PAPER_K_H @ z[1], PAPER_K_V @ z[2]])
    names = ctrl.diag_names
    unlimited = (diag[names.index("saturated_A")] == 0) & (diag[names.index("saturated_B")] == 0)
    unlimited &= diag[names.index("clipped")] == 0
    assert unlimited.sum() > 0.9 * n  # 1 mm errors rarely ask for more than 9 A
    x = np.zeros((6, n))
    x[0::2] = y
    acc = PlatformModel(PLATFORM).dynamics(x, u)[1::2]
    assert_allclose(acc[:, unlimited], v[:, unlimited], rtol=0, atol=1e-9)
    assert_allclose(diag[names.index("v_x") : names.index("v_gap") + 1], v, rtol=1e-12, atol=1e-12)
    # nothing limited: the anti-windup is inactive (same next state to rounding)
    plain = MicrostepperRegulator(PLATFORM, anti_windup=False, levitation_first=False)
    _, c_plain, _ = plain.step.map(n)(c, y, r)
    assert_allclose(c_next[:, unlimited], np.asarray(c_plain)[:, unlimited], rtol=1e-9, atol=1e-12)


def test_levitation_first_limiter_against_bisection_on_the_model():
    # Requests far beyond 9 A: the limiter keeps each pair within the limit, realises the gap's
    # acceleration exactly and cuts only thrust. Its closed-form i_d is checked against a
    # bisection on the model's gap acceleration over i_d in [-9, 9] A (monotone there), with the
    # unlimited thrust currents taken from the lead's MicrostepperTransformation.
    ctrl = MicrostepperRegulator(PLATFORM)
    model, fl = PlatformModel(PLATFORM), MicrostepperTransformation(PLATFORM)
    rng = np.random.default_rng(7)
    n = 300
    gap = rng.uniform(20, 30, n) * MM
    v = np.vstack([rng.uniform(-100, 100, (2, n)), rng.uniform(-15, 15, n)])  # [m/s^2]
    u, limited = (np.asarray(a) for a in ctrl.limiter.map(n)(gap[None, :], v))
    iq = np.asarray(fl.function.map(n)(gap[None, :], v)[0])[0::2]  # unlimited (i_qA, i_qB)
    assert np.all(np.hypot(u[0::2], u[1::2]) <= PEAK * (1 + 1e-12))
    x = np.zeros((6, n))
    x[4] = gap

    def gap_acc(i_d):
        room = np.sqrt(np.maximum(PEAK**2 - i_d**2, 0))
        cur = np.vstack([np.clip(iq[0], -room, room), i_d, np.clip(iq[1], -room, room), i_d])
        return model.dynamics(x, cur)[5]

    lo, hi = np.full(n, -PEAK), np.full(n, PEAK)
    for _ in range(60):  # the gap acceleration increases with i_d on [-9, 9] A
        mid = (lo + hi) / 2
        below = gap_acc(mid) < v[2]
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    reachable = limited[2] == 0
    assert reachable.sum() > 0.8 * n
    # bisection to 2^-60 * 18 A; the closed form to rounding of ~10 A-scale quantities
    assert_allclose(u[1, reachable], (lo + hi)[reachable] / 2, atol=1e-9)
    acc = model.dynamics(x, u)[1::2]
    assert_allclose(acc[2, reachable], v[2, reachable], atol=1e-9)
    # thrust: never more than asked, same sign, exactly as asked where its pair was not cut
    for axis, flag in ((0, limited[0]), (1, limited[1])):
        assert np.all(np.abs(acc[axis]) <= np.abs(v[axis]) + 1e-9)
        assert np.all(acc[axis] * v[axis] >= 0)
        assert_allclose(acc[axis, flag == 0], v[axis, flag == 0], atol=1e-9)
    assert limited[:2].sum() > n  # most of these requests are cut


# --- (a) the paper's five set-points --------------------------------------------------------------
def test_setpoints_settle_as_in_the_paper(with_anti_windup):
    scenario = SCENARIOS["setpoints"]
    result = with_anti_windup.run(scenario)
    check_result(result)
    assert result.success, result.message
    assert result.events["saturated"] > 500  # the 80 mm steps ask for far more than 9 A (measured 986)
    metrics = evaluate_microstepper(result, scenario)
    check_result(metrics)
    assert len(metrics.steps) == 5
    s01, s10 = (
        np.array([s.settling_01mm for s in metrics.steps]),
        np.array([s.settling_10um for s in metrics.steps]),
    )
    # the paper's bounds, every step and axis (measured: <= 1.41 s and <= 1.75 s; seeds 1-3 give
    # up to 1.99 s to 10 um on the gap)
    assert np.all(s01 < PAPER_SETTLE_01MM), s01
    assert np.all(s10 < PAPER_SETTLE_10UM), s10
    # regression bounds with room over the measured 34 % (x, y) and 45 % (gap: the printed K_v's
    # own linear overshoot; the gap steps do not saturate)
    over = metrics.max_overshoot()
    assert over[0] < 40 and over[1] < 40 and over[2] < 50, over


# --- (b) the sinusoid ------------------------------------------------------------------------------
def test_sinusoid_mean_errors_against_the_paper(with_anti_windup):
    scenario = SCENARIOS["sinusoid"]
    result = with_anti_windup.run(scenario)
    assert result.success, result.message
    assert result.events["saturated"] == 0  # 40 mm at 1.5 pi rad/s needs 0.9 m/s^2: no limit
    mean = evaluate_microstepper(result, scenario).mean_error
    # Upper bound: the paper's figures. The twin's are smaller (measured 8.0 / 5.9 / 45 um)
    # because the reference runs at exactly omega0, which the internal models cancel, and the
    # twin has no guide misalignment and light guide friction (0.1 N on x and y; with 1 N the
    # twin gives 76 / 53 um on x / y, the paper's order); the paper blames current transients.
    assert np.all(mean < PAPER_MEAN_ERROR), mean
    # Lower bound: readings are rounded to 10 um, which alone costs 2.5 um on average.
    assert np.all(mean > 2 * UM), mean
    # y's guides carry the x stage too (more mass, same friction): smaller error, as in the paper
    assert mean[1] < mean[0]


def test_sinusoid_error_is_the_twins_effects_not_the_controller():
    # On the ideal twin the internal models at omega0 leave the sinusoid's error at rounding
    # level of the observers' start-up (measured 0.04-0.16 um): 1 um bounds it.
    scenario = SCENARIOS["sinusoid"].shortened(12.0, evaluate_from=8.0)
    loop = MicrostepperLoop(
        MicrostepperTwin(PLATFORM, MicrostepperEffects.ideal()), MicrostepperRegulator(PLATFORM)
    )
    mean = evaluate_microstepper(loop.run(scenario), scenario).mean_error
    assert np.all(mean < 1 * UM), mean


# --- (c) the amplifier limit ----------------------------------------------------------------------
def test_saturated_step_recovers_with_anti_windup(saturation_runs):
    result = saturation_runs["anti_windup"]
    assert result.success, result.message
    # the limit is hit: at the start v = 1182 * 0.09 = 106 m/s^2 on x and y, i.e. 42 A and 60 A
    assert result.events["saturated"] > 200  # measured 295 samples (59 ms)
    mag = np.hypot(result.u[0::2], result.u[1::2])
    assert_allclose(mag.max(), PEAK, rtol=1e-6)  # commanded right up to 9 A, never above
    metrics = evaluate_microstepper(result, SCENARIOS["saturation"])
    s01, s10 = metrics.worst_settling("01mm"), metrics.worst_settling("10um")
    assert np.all(s01 < PAPER_SETTLE_01MM) and np.all(s10 < PAPER_SETTLE_10UM), (s01, s10)
    # measured overshoot 14 % (x) and 5 % (y); x peaks at 57.8 mm, inside the 60 mm stopper
    over = metrics.max_overshoot()
    assert over[0] < 20 and over[1] < 10, over
    assert np.abs(result.x[4] - 25 * MM).max() < 0.5 * MM  # the gap holds (measured 0.08 mm)


def test_without_back_calculation_the_saturated_step_overshoots_into_the_stoppers(saturation_runs):
    # Same levitation-first limiting, internal models and observers of the 2-DOF regulator: the
    # internal models wind up and the observers integrate the accelerations asked for, not got.
    result = saturation_runs["no_anti_windup"]
    assert result.status == "stopper_hit"
    hit = result.t[np.argmax(result.flags[2] > 0)]
    assert hit < 0.2, hit  # measured 0.10 s
    assert np.nanmax(result.x[0]) >= 60 * MM - 1e-12  # at the x stopper (+60 mm)


def test_without_back_calculation_and_stoppers_the_saturated_step_diverges():
    # The stoppers removed, what the overshoot becomes: 73 % on x and a y excursion of tens of
    # metres within 10 s (measured), i.e. no recovery at all; 50 % and 1 m are loose marks.
    twin = MicrostepperTwin(PLATFORM, MicrostepperEffects.rig(stoppers=None))
    scenario = SCENARIOS["saturation"].shortened(10.0)
    result = MicrostepperLoop(twin, MicrostepperRegulator(PLATFORM, anti_windup=False)).run(scenario)
    step = evaluate_microstepper(result, scenario).steps[0]
    assert step.overshoot_pct[0] > 50, step.overshoot_pct
    assert np.nanmax(np.abs(result.x[2])) > 1.0


def test_amplifier_scaling_of_the_currents_drops_the_platform(saturation_runs):
    # Back-calculation on, but the controller commands the unlimited minimum-norm currents and
    # the amplifiers scale each pair's vector: the thrust current's K4 l4 i_q^2 and the lost i_d
    # leave the gap uncontrolled and the platform falls to the gap stopper (35 mm) within 50 ms
    # (measured 46 ms).
    result = saturation_runs["amplifier_scaling"]
    assert result.status == "stopper_hit"
    hit = result.t[np.argmax(result.flags[2] > 0)]
    assert hit < 0.1, hit
    assert np.nanmax(result.x[4]) >= 35 * MM - 1e-12
    assert result.events["limited_A"] > 0 and result.events["limited_B"] > 0
