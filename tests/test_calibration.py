"""The rig twin calibrated to 002's step experiments (maglev_oc.sim.calibration; issue 14, item 3).

Papers' numbers (002 Sec. 7.1): 114 % vertical overshoot at the step at t = 5 s (Fig. 9), 43 %
horizontal (Fig. 10), 40 % and a settling time three times longer with the retuned K_v (Fig. 11),
and the linear regulator unstable on the large step (0.026, 0, 0, 0) -> (0.018, 0, 0.020, 0) that
the FL regulator handles (Fig. 12). "Reproduces" an overshoot means within TOLERANCE_PCT = 15
points: our set-points are not the papers' (unprinted) ones, and on the twins that come close the
same loop's overshoot differs by 30 points and more between the five steps of our sequence.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.linalg import expm

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.control.gains import OMEGA0, PAPER_K_V
from maglev_oc.errors import InputError
from maglev_oc.model.equilibrium import equilibrium_currents
from maglev_oc.model.hardware import PEAK_CURRENT_LIMIT
from maglev_oc.model.parameters import PAPER_CONSTANTS
from maglev_oc.results import check_result
from maglev_oc.sim.calibration import (
    TOLERANCE_PCT,
    Candidate,
    DifferentiatedVelocity,
    PaperTargets,
    TwinParameters,
    calibrate_to_paper,
    candidate_effects,
    paper_metrics,
)
from maglev_oc.sim.comparison import RIG_CONSTANTS
from maglev_oc.sim.effects import TwinEffects
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.metrics import evaluate
from maglev_oc.sim.scenarios import Scenario, SetpointSequence
from maglev_oc.sim.twin import RigTwin
from tests.test_controllers_report import _numbers, _peak, _row

PAPER = PaperTargets.from_papers()

# The reproducing twins of least departure (in units of the plausible limits) on the two grids
# of DEFAULT_GRIDS, as calibrate_to_paper finds them on this code (the slow end-to-end test
# recomputes both): a 14 Hz current amplifier alone, or C4 and the commutation offset at three
# times their limits together.
LAG_ROUTE = {"amplifier_bandwidth_hz": 1.85}
COUPLING_ROUTE = {"C4": 3.0, "commutation_offset": 3.0}


@pytest.fixture(scope="module")
def candidates(model):
    return {c.parameter: c for c in candidate_effects(model)}


def _twin(candidates, departures) -> TwinParameters:
    values = {k: candidates[k].value_at(d) for k, d in departures.items()}
    return dataclasses.replace(TwinParameters.nominal(), **values)


@pytest.fixture(scope="module")
def nominal(model):
    return paper_metrics(model, TwinParameters.nominal())


@pytest.fixture(scope="module")
def lag_route(model, candidates):
    return paper_metrics(model, _twin(candidates, LAG_ROUTE), full=True)


# --- the twin's unknowns -----------------------------------------------------------------------------
def test_nominal_parameters_are_the_comparison_rig_twin():
    p = TwinParameters.nominal()
    assert p.effects() == TwinEffects.rig()
    truth = PAPER_CONSTANTS[RIG_CONSTANTS]
    assert (p.C2, p.C3, p.C4) == (truth.C2, truth.C3, truth.C4)
    assert p.changes() == {}


def test_candidate_sizes_and_departures(candidates):
    for c in candidates.values():
        assert c.departure(c.limit) == pytest.approx(1.0)
        assert c.departure(c.value_at(0.0)) == pytest.approx(0.0)
        for d in c.screen:
            if c.parameter != "input_delay_samples":  # whole samples
                assert c.departure(c.value_at(d)) == pytest.approx(d)
    bw = candidates["amplifier_bandwidth_hz"]  # logarithmic: one decade per unit
    assert bw.value_at(2.0) == pytest.approx(10.0)
    assert candidates["input_delay_samples"].value_at(9.0) == 10


def test_constant_limits_sit_on_the_papers_5_percent_band(model, candidates):
    # 002 Fig. 6: model and measured equilibrium currents within 5 % over 15-25 mm; recomputed here
    # from the equilibrium currents directly (relative error where |u2| >= 1 A).
    gaps = np.arange(15.0, 25.01, 0.5) * 1e-3
    ref = equilibrium_currents(model, gaps).current
    use = np.abs(ref) >= 1.0
    for name in ("C2", "C3", "C4"):
        plant = dataclasses.replace(TwinParameters.nominal(), **{name: candidates[name].limit})
        cur = equilibrium_currents(model.with_constants(plant.constants()), gaps).current
        err = np.max(np.abs(cur[use] - ref[use]) / np.abs(ref[use]))
        assert err == pytest.approx(0.05, abs=1e-4), name


def test_invalid_inputs_are_refused(model):
    with pytest.raises(InputError, match="input_delay_samples"):
        dataclasses.replace(TwinParameters.nominal(), input_delay_samples=1.5)
    with pytest.raises(InputError, match="velocity_differentiation"):
        dataclasses.replace(TwinParameters.nominal(), velocity_differentiation=-1e-3)
    with pytest.raises(InputError, match="small angle"):
        dataclasses.replace(TwinParameters.nominal(), commutation_offset=0.7)
    with pytest.raises(InputError, match="TwinParameters field"):
        Candidate("x", "no_such_field", "-", 0.0, 1.0, (1.0,), "")
    with pytest.raises(InputError, match="tolerance_pct"):
        calibrate_to_paper(model, tolerance_pct=0.0)
    with pytest.raises(InputError, match="grid axis"):
        calibrate_to_paper(model, grids=((("C4", (0.0, 1.0)), ("no_such", (0.0, 1.0))),))
    with pytest.raises(InputError, match="grid axis"):
        calibrate_to_paper(model, grids=((("C4", (1.0, 2.0)), ("commutation_offset", (0.0, 1.0))),))
    with pytest.raises(TypeError):
        calibrate_to_paper(model, grid=())


# --- an independent check of a candidate ---------------------------------------------------------------
def _linear_overshoot(gains, epsilon: float, step: float) -> float:
    """Overshoot [%] of the feedback-linearized vertical axis e'' = v, v = K (e, e'_hat, xi), after
    a set-point step, by the matrix exponential of the continuous loop: with e'_hat = e' when
    epsilon = 0, else from a high-gain differentiator on the reading (no acceleration input)."""
    k = np.asarray(gains, dtype=float)
    n = 5 if epsilon == 0 else 7
    a = np.zeros((n, n))
    a[0, 1] = 1.0
    a[2, 3], a[3, 4], a[4, 3], a[4, 0] = 1.0, 1.0, -(OMEGA0**2), 1.0  # internal model, 002 (21)
    a[1, [0, 2, 3, 4]] = k[[0, 2, 3, 4]]
    x0 = np.zeros(n)
    x0[0] = -step
    if epsilon == 0:
        a[1, 1] += k[1]
    else:  # p' = q + 2/eps (e - p), q' = (e - p)/eps^2, p(0) = e(0): the observer starts at the reading
        a[1, 6] = k[1]
        a[5, 6], a[5, 0], a[5, 5] = 1.0, 2 / epsilon, -2 / epsilon
        a[6, 0], a[6, 5] = 1 / epsilon**2, -1 / epsilon**2
        x0[5] = -step
    phi = expm(a * 1e-3)
    x, peak = x0, -np.inf
    for _ in range(3000):
        x = phi @ x
        peak = max(peak, x[0])
    return 100 * max(peak, 0.0) / step


@pytest.mark.parametrize("epsilon", [0.0, 5e-3, 10e-3])
def test_differentiated_velocity_matches_the_linear_loop(model, epsilon):
    # On the ideal plant the FL regulator makes the vertical axis exactly linear, so the twin's
    # overshoot with velocities by differentiation must be the continuous loop's, up to the
    # sampled observer running one 0.2 ms sample behind: between the loop at epsilon and at
    # epsilon + 0.2 ms, with half a point for the hold (the model-fed observer: the loop itself).
    # Both stay below the design's 45 % until the loop loses stability near epsilon = 13 ms:
    # differentiation cannot give 114 %.
    step, period = 2e-3, 2e-4
    fl = FeedbackLinearizingRegulator(model)
    ctrl = fl if epsilon == 0 else DifferentiatedVelocity(fl, epsilon)
    target = SetpointSequence((0.0,), ((0.020 + step, 0.0),))
    sc = Scenario("vertical step", "20 -> 22 mm", (0.020, 0.0, 0.0, 0.0), target, 3.0)
    twin = evaluate(ClosedLoop(RigTwin(model), ctrl).run(sc), sc).steps[0].overshoot_pct.vertical
    bounds = [_linear_overshoot(PAPER_K_V, epsilon, step)]
    if epsilon > 0:
        bounds.append(_linear_overshoot(PAPER_K_V, epsilon + period, step))
    assert min(bounds) - 0.5 <= twin <= max(bounds) + 0.5
    assert twin <= 45.5


# --- the papers' claims on the twins -------------------------------------------------------------------
def test_nominal_twin_reproduces_neither_claim(nominal):
    # 002 Fig. 9: 114 %; the nominal rig twin about 50 % (the design's 45 % plus the rig's effects)
    assert nominal.overshoot_v_pct < PAPER.overshoot_v_pct - TOLERANCE_PCT
    assert nominal.linear_large_step == "completed"  # 002 Fig. 12: unstable
    assert nominal.fl_large_step == "completed"
    assert not nominal.reproduces(PAPER)
    # 002 Fig. 11 on the nominal twin: the retuned K_v overshoots less and settles 2-3x later
    assert nominal.retuned_overshoot_v_pct < nominal.overshoot_v_pct
    assert 2.0 < nominal.settling_ratio < 3.5


def test_plausible_limits_fall_short(model, candidates):
    # every effect with leverage at its plausible limit: 100 Hz amplifiers, C4 at the 5 % band,
    # 0.1 rad commutation offset; the overshoot stays below 114 % - 15 and the linear survives
    m = paper_metrics(
        model, _twin(candidates, {k: 1.0 for k in (*LAG_ROUTE, *COUPLING_ROUTE)}), retuned=False
    )
    assert m.overshoot_v_pct < PAPER.overshoot_v_pct - TOLERANCE_PCT
    assert m.linear_large_step == "completed"


@pytest.mark.parametrize("departures", [{"amplifier_bandwidth_hz": 1.0}, {"input_delay_samples": 9.0}])
def test_bandwidth_and_delay_without_leverage(model, candidates, nominal, departures):
    # 100 Hz amplifiers, or a 2 ms delay (ten times the rig's): the overshoot moves by < 3 points
    m = paper_metrics(model, _twin(candidates, departures), retuned=False)
    assert abs(m.overshoot_v_pct - nominal.overshoot_v_pct) < 3.0
    assert m.linear_large_step == "completed"


def test_lag_route_reproduces_both_claims(lag_route):
    # 002 Figs. 9 and 12 at once: a 14 Hz current loop (1.85 decades below the rig's, beyond the
    # 100 Hz limit) gives the overshoot within 15 points, the linear regulator failing on the large
    # step and the FL regulator surviving it and the steps
    m = lag_route
    assert abs(m.overshoot_v_pct - PAPER.overshoot_v_pct) <= TOLERANCE_PCT
    assert m.linear_large_step != "completed"
    assert m.fl_large_step == "completed" and m.steps_status == "completed"
    assert m.reproduces(PAPER)


def test_lag_route_contradicts_the_retuned_gains(lag_route):
    # 002 Fig. 11: 40 %. On the twin that reproduces Fig. 9 the retuned K_v overshoots by more than
    # 40 % + 15: the same lag that raises the printed gains' overshoot raises the retuned one's
    assert lag_route.retuned_overshoot_v_pct > PAPER.retuned_overshoot_v_pct + TOLERANCE_PCT


def test_lag_route_fails_the_linear_regulator_by_a_dip_not_an_oscillation(lag_route):
    # 002 Fig. 12: oscillations growing until a shutdown at 5.5 s. On the twin the linear regulator
    # dips into the 8 mm stopper within 0.1 s; without the stoppers it recovers and settles at
    # 18 mm. The FL regulator's own dip on the large step comes within about a millimetre of the
    # stopper, and our ten-millimetre step of the sequence (25 -> 15 mm) reaches it.
    assert lag_route.linear_unstopped == "settles"
    assert lag_route.linear_unstopped_min_gap < 8e-3
    assert lag_route.fl_min_gap < 10e-3
    assert lag_route.sequence_status == "stopper_hit"
    assert lag_route.linear_ff_large_step == "completed"  # with the feedforward it survives


def test_coupling_route_reproduces_both_claims_too(model, candidates):
    # a second, disjoint set of twins does the same: the fit is not unique
    m = paper_metrics(model, _twin(candidates, COUPLING_ROUTE))
    assert m.reproduces(PAPER)
    assert m.retuned_overshoot_v_pct > PAPER.retuned_overshoot_v_pct + TOLERANCE_PCT


# --- the whole calibration -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def calibration(shared_controllers_report):
    """The calibration, run once per session for its own checks and for the whole controller
    report (tests/report_support.py)."""
    return shared_controllers_report[0]


@pytest.mark.slow
def test_calibration_end_to_end(calibration):
    cal = calibration
    check_result(cal)
    assert cal.status == "implausible_only" and not cal.success
    assert not cal.nominal.reproduces and not cal.plausible.reproduces
    assert cal.plausible.plausible and not cal.required.plausible
    assert cal.required.reproduces
    assert cal.required.departures == pytest.approx(LAG_ROUTE)
    grid = next(g for g in cal.grids if g.parameters == tuple(COUPLING_ROUTE))
    i, j = (int(np.argmin(np.abs(grid.departures[k] - d))) for k, d in enumerate(COUPLING_ROUTE.values()))
    assert grid.reproduces[i, j] and grid.reproduces.sum() == 1
    assert cal.required.metrics.retuned_overshoot_v_pct > PAPER.retuned_overshoot_v_pct + TOLERANCE_PCT
    # the linear regulator with the equilibrium feedforward survives on every fitted twin, and its
    # small-step transient is the FL regulator's (002: "much larger")
    assert all(f.metrics.linear_ff_large_step == "completed" for f in cal.fits())
    fl, ff = cal.small_step["FL regulator"], cal.small_step["linear regulator"]
    assert abs(fl[0] - ff[0]) < 2.0
    for panel, controller in (
        ("papers_step", "FL regulator"),
        ("large_step", "linear regulator (no feedforward)"),
    ):
        tr = cal.trace(panel, "required", controller)
        assert tr.t.shape == tr.gap.shape == tr.reference.shape and tr.t.size > 1000
    assert cal.required.metrics.linear_unstopped == "settles"
    assert "overshoot at t = 5 s" in cal.report()


# --- the whole controller report, on this calibration --------------------------------------------------
@pytest.mark.slow
def test_the_whole_report_with_nmpc_and_the_calibrated_twin(calibration, shared_controllers_report):
    _, study, contents = shared_controllers_report
    assert study.calibration is calibration
    assert contents.sparse_pages() == []
    assert "NMPC" in study.comparison.controllers
    cal = study.calibration
    fit = cal.required if cal.required is not None else cal.plausible
    # the calibrated twin's overshoot at t = 5 s, recomputed from the calibration's own gap trace
    # (true gap at 1 kHz: within a few points of the encoder-based figure)
    tr = cal.trace("papers_step", fit.name, "FL regulator")
    seg = (tr.t >= 5.0) & (tr.t < 10.0)
    before = tr.reference[np.searchsorted(tr.t, 5.0) - 1]
    step = tr.reference[seg][0] - before
    over = max(float(np.max(np.sign(step) * (tr.gap[seg] - tr.reference[seg]))), 0.0) / abs(step) * 100
    _, paper, ours, _ = _row(contents, "Calibrated twin: 114 %")
    assert paper == "114 %"
    assert _numbers(ours)[0] == pytest.approx(over, abs=3.0)
    _, paper, ours, _ = _row(contents, "Calibrated twin: the linear")
    linear = cal.trace("large_step", fit.name, "linear regulator (no feedforward)")
    assert paper == "unstable"
    assert ours.startswith("linear " + ("survives" if linear.status == "completed" else "hits the stopper"))
    # the NMPC stays within its current polytope (inside 9 A)
    for sc in study.comparison.scenarios:
        assert _peak(study.result("NMPC", sc, "rig")) <= PEAK_CURRENT_LIMIT + 1e-6
