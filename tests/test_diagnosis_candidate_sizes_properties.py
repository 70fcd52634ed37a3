"""Properties of the candidate library's physical sizes and plausibility bounds
(``maglev_oc.diagnosis`` candidates), checked against the terms' own accelerations, the model's
Jacobian (CasADi) and percentiles of the logged travel:

- thrust ripple, the attraction's change and the share sticking guides hold are relative to the
  fitted constants; the cogging peak at 15 mm is the force's peak at that gap; a cable spring is
  bounded by its force at the far end of the travel;
- the lag candidate is the model's first-order change under late currents, and a lag within the
  loop's hold is refused with its size in milliseconds;
- a guide slope's gap change is over the logged travel; a slope, a geometry or a commutation
  error beyond its physical bound, a constant force beyond a quarter of the weight, and end
  effects that do not grow towards the ends together, are refused in plain words;
- a viscous part within two standard errors of zero is "not resolved"; a negative parameter is
  refused with how many standard errors below zero it is; the delta method is exact for a linear
  function; every candidate's experiment continues the report's sentence.
"""

from __future__ import annotations

import dataclasses
import math
import re
from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest

from maglev_oc.diagnosis.candidate import MAX_FORCE_SHARE, LibraryContext, delta_method
from maglev_oc.diagnosis.currents import lag_candidate, ripple_candidate
from maglev_oc.diagnosis.guides import (
    cable_candidate,
    friction_candidates,
    level_candidates,
    misalignment_candidate,
)
from maglev_oc.diagnosis.library import candidate_library, waviness_candidate
from maglev_oc.diagnosis.magnetics import (
    cogging_candidates,
    end_effects_candidate,
    field_shape_candidate,
    gap_dependence_candidate,
)
from maglev_oc.diagnosis.result import NotSeparable
from maglev_oc.regression.data import prepare
from tests._diagnosis_cases import _ctx
from tests.diagnosis_support import stub_diagnosis
from tests.test_statistics_properties import _log


# --- physical parameters -------------------------------------------------------------------------------
def test_the_delta_method_is_exact_for_a_linear_function():
    # se(a'p) = sqrt(a' C a) exactly; the central differences are exact for a linear f up to
    # round-off (1e-6 relative: steps of 1e-6 |p| and a difference of two O(1) values)
    rng = np.random.default_rng(2)
    a, p = rng.normal(size=3), rng.normal(size=3)
    m = rng.normal(size=(3, 3))
    cov = m @ m.T
    e = delta_method(lambda q: float(a @ q), p, cov, "N")
    assert e.value == pytest.approx(float(a @ p), rel=1e-12)
    assert e.stderr == pytest.approx(math.sqrt(a @ cov @ a), rel=1e-6)


# --- sizes relative to the fitted model ----------------------------------------------------------------
@pytest.fixture(scope="module")
def sweep_ctx(model, cogged):
    """The candidates' context on the cogged sweep, the papers' constants as references."""
    return LibraryContext(model, cogged[0].prepared)


def test_the_thrust_ripple_is_relative_to_the_fitted_thrust(model, sweep_ctx):
    # the ripple's columns carry the reference thrust -C1_ref l1 u1; what a user reads is the
    # ripple of the fitted thrust (C1 twice the reference here). Computed from the term's own
    # acceleration over one slot pitch (2000 points: the sampled maximum of a sine is within
    # 1.3e-6 of its peak) divided by the fitted model's thrust at the same state: rel 1e-5
    cand = ripple_candidate(sweep_ctx)
    refs = model.constants
    fitted = model.with_constants(dataclasses.replace(refs, C1=2.0 * refs.C1))
    consts = {"C1": 2.0 * refs.C1, "C2": refs.C2, "C3": refs.C3, "C4": refs.C4}
    q = np.array([0.03, -0.04, 0.0, 0.0])
    u, gap = np.array([1.5, 0.0]), sweep_ctx.gap_median
    ratios = []
    for x3 in np.linspace(0.0, model.params.slot_pitch, 2000):
        x = np.array([gap, 0.0, x3, 0.0])
        term = float(np.asarray(cand.term.function(x, u, np.zeros(2), q)).ravel()[1])
        ratios.append(term / float(np.asarray(fitted.f(x, u)).ravel()[3]))
    params = cand.term.physical_parameters(q, 1e-8 * np.eye(4), consts)
    assert params["amplitude"].value == pytest.approx(max(np.abs(ratios)), rel=1e-5)
    assert params["amplitude"].value == pytest.approx(0.025, rel=1e-5)  # 0.05 of the reference's


def test_the_share_held_by_sticking_horizontal_guides_is_of_the_fitted_models_force(model, sweep_ctx):
    # the holding column is -h a_model(x, u) at standstill with the reference constants; the share
    # a user reads is of the fitted model's acceleration (C1 half the reference here): the term's
    # acceleration at rest over the fitted model's horizontal acceleration, sign reversed
    cand = next(c for c in friction_candidates(sweep_ctx) if c.name == "guide_friction_horizontal")
    refs = model.constants
    fitted = model.with_constants(dataclasses.replace(refs, C1=0.5 * refs.C1))
    consts = {"C1": 0.5 * refs.C1, "C2": refs.C2, "C3": refs.C3, "C4": refs.C4}
    q = np.array([0.0, 0.0, 0.4])  # no Coulomb, no viscous part: the holding alone
    x, u = np.array([sweep_ctx.gap_median, 0.0, 0.01, 0.0]), np.array([2.0, 0.5])
    term = float(np.asarray(cand.term.function(x, u, np.zeros(2), q)).ravel()[1])
    held = -term / float(np.asarray(fitted.f(x, u)).ravel()[3])
    params = cand.term.physical_parameters(q, 1e-8 * np.eye(3), consts)
    assert held == pytest.approx(0.8, rel=1e-9)
    assert params["holding"].value == pytest.approx(held, rel=1e-9)


# --- plausibility --------------------------------------------------------------------------------------
def test_a_cable_spring_is_bounded_by_its_force_at_the_far_end_of_the_travel(model):
    # a log over 10..50 mm of the track (not centred on the spring's zero): the spring's force
    # -k x3 reaches k x 50 mm at the far end, which is what must stay within a quarter of the
    # platform's weight. A stiffness between the bounds at the near and the far end is refused
    x = np.zeros((4, 2001))
    x[0] = 0.02
    x[2] = np.linspace(0.01, 0.05, 2001)
    data = SimpleNamespace(x=x, valid=np.ones(2001, dtype=bool), settings={})
    ctx = LibraryContext(model, data)
    lo, hi = ctx.position_range
    limit = MAX_FORCE_SHARE * ctx.weight("horizontal")
    cand = cable_candidate(ctx)
    from maglev_oc.results import Estimate

    def verdict(k):
        return cand.plausible({"stiffness": Estimate(k, 0.01 * k, "N/m")})

    assert verdict(0.9 * limit / hi) is None
    assert "spring force" in verdict(1.1 * limit / hi)
    assert "spring force" in verdict(0.5 * limit * (1 / hi + 1 / lo))  # beyond at the far end only


def test_the_cogging_peak_at_15_mm_is_the_forces_peak_at_that_gap(model, sweep_ctx):
    # the candidate's fundamental decays with the gap as exp(-2 pi (gap - at_gap) / P) from the
    # gap it is fitted at (the log's median); its peak at the papers' 15 mm is read off the term's
    # own force at a 15 mm gap over one period (2000 points: 1.3e-6 of the peak), times the mass
    cand = next(c for c in cogging_candidates(sweep_ctx) if c.name == "cogging_horizontal_19mm")
    q = np.array([0.02, 0.01, 0.0, 0.0])
    params = cand.term.physical_parameters(q, 1e-8 * np.eye(4), {})
    assert abs(params["at_gap"].value - 0.015) > 1e-3  # fitted away from 15 mm: the decay matters
    period = model.params.slot_pitch
    force = [
        float(np.asarray(cand.term.function([0.015, 0.0, x3, 0.0], [0.0, 0.0], [0.0, 0.0], q)).ravel()[1])
        * model.params.mass_horizontal
        for x3 in np.linspace(0.0, period, 2000)
    ]
    assert params["amplitude_15mm"].value == pytest.approx(max(np.abs(force)), rel=1e-5)


def test_end_effects_are_refused_only_when_the_forces_together_grow_towards_the_ends(model, sweep_ctx):
    # over the ends the mover overhangs the stator and its forces fall; what is refused is forces
    # that grow there. The thrust's loss, estimated beside a large fall of the attraction, may come
    # out slightly negative: an attraction falling by 10 % with the thrust growing by 1 % is a fall.
    # The thrust's change is checked here on the term's own acceleration (its horizontal part over
    # the model's thrust at the logged ends and the centre, the references' constants; the same
    # algebra two ways: rel 1e-12). The losses here: thrust -0.9 %, attraction +9.3 %
    cand = end_effects_candidate(sweep_ctx)
    lo, hi = sweep_ctx.position_range
    gap, u = sweep_ctx.gap_median, np.array([1.5, 0.0])

    def thrust_loss(q, x3):
        x = np.array([gap, 0.0, x3, 0.0])
        term = float(np.asarray(cand.term.function(x, u, np.zeros(2), q)).ravel()[1])
        return -term / float(np.asarray(model.f(x, u)).ravel()[3])

    consts = {n: getattr(model.constants, n) for n in ("C1", "C2", "C3", "C4")}
    for winding, magnet, refused in ((-0.012, 0.12, False), (-0.012, -0.02, True), (0.05, -0.02, False)):
        q = np.array([winding, winding, magnet, magnet])
        e = cand.term.physical_parameters(q, 1e-8 * np.eye(4), consts)
        mid = 0.5 * (lo + hi)
        at_ends = 0.5 * (thrust_loss(q, lo) + thrust_loss(q, hi)) - thrust_loss(q, mid)
        assert e["thrust_loss_at_ends"].value == pytest.approx(at_ends, rel=1e-12)
        verdict = cand.plausible(e)
        assert (verdict is not None) is refused, (winding, magnet, verdict)


# --- physical sizes of the guides' and the currents' candidates --------------------------------------
def test_a_guide_slopes_gap_change_is_over_the_logged_travel(model):
    """A guide slope of 2 mrad on a log whose positions run -30..40 mm (not centred on zero): the
    gap error it reports over the travel is the slope times the travel between the 1st and 99th
    percentiles of the logged positions (numpy here), with the slope's standard error scaled alike;
    the same change is what the term's vertical acceleration sees, through the model's gap
    sensitivity, between those two positions (1e-9: the same arithmetic in another order)."""
    from maglev_oc.diagnosis.guides import misalignment_candidate

    ctx = _ctx(model)
    cand = misalignment_candidate(ctx)
    slope = 2e-3
    p = cand.term.physical_parameters(np.array([slope]), np.array([[1e-8]]), {})
    lo, hi = np.percentile(ctx.fitted_states[2], [1, 99])
    assert p["gap_change_over_travel"].value == pytest.approx(slope * (hi - lo), rel=1e-12)
    assert p["gap_change_over_travel"].stderr == pytest.approx(1e-4 * (hi - lo), rel=1e-12)
    u = np.array([0.3, 1.2])

    def vertical(x3):
        x = np.array([0.02, 0.0, x3, 0.0])
        return float(cand.term.acceleration([slope])(x, u, np.zeros(2)).full()[0, 0])

    sensitivity = float(ctx.gap_sensitivity(ca.DM([0.02, 0.0, 0.0, 0.0]), u)[0])
    assert vertical(hi) - vertical(lo) == pytest.approx(
        sensitivity * p["gap_change_over_travel"].value, rel=1e-9
    )


def _bounded(model, name):
    """The candidate ``name`` of the stand-in log's context (:func:`_ctx`)."""
    from maglev_oc.diagnosis.currents import commutation_candidate
    from maglev_oc.diagnosis.guides import gap_offset_candidate, misalignment_candidate

    ctx = _ctx(model)
    return {
        "gap_sensor_offset": gap_offset_candidate(ctx),
        "guide_misalignment": misalignment_candidate(ctx),
        "commutation_offset": commutation_candidate(ctx),
    }[name]


@pytest.mark.parametrize(
    "name, parameter, bound",
    [
        ("gap_sensor_offset", "offset", 2e-3),  # a tenth of the papers' 20 mm gap
        ("guide_misalignment", "slope", 0.05),  # 50 mrad: 5 mm over a 100 mm travel
        ("commutation_offset", "angle", 0.35),  # 20 degrees, where the first-order mixing still holds
    ],
)
def test_a_geometry_or_commutation_error_beyond_its_physical_bound_is_refused_on_either_side(
    model, name, parameter, bound
):
    """Each candidate's parameter (the commutation offset's two axes' angles alike), fitted 5 %
    inside its bound (either sign), is plausible, and 5 % beyond it is refused with a reason naming
    the bound (the library's stated bounds)."""
    cand = _bounded(model, name)
    n = len(cand.term.parameter_names)
    for sign in (1.0, -1.0):
        for factor, ok in ((0.95, True), (1.05, False)):
            q = np.full(n, sign * factor * bound)
            p = cand.term.physical_parameters(q, 1e-14 * np.eye(n), {})
            assert p[parameter].value == pytest.approx(q[0], rel=1e-12)
            reason = cand.plausible(p)
            assert (reason is None) == ok, (name, sign, factor, reason)
            if not ok:  # the reason names what is beyond its bound, in words
                words = {"gap_sensor_offset": "gap offset", "guide_misalignment": "guide slope"}
                assert reason.startswith(words.get(name, reason.split(" of ")[0])), reason
                assert f"beyond the physical bound {bound:g}" in reason, reason


@pytest.fixture(scope="module")
def ctx(model, data) -> LibraryContext:
    """The candidates' context on the twin's log, with the papers' constants as references."""
    return LibraryContext(model, data)


def test_the_lag_candidate_is_the_models_first_order_change_under_late_currents(ctx, model):
    """For a lag T the forces see u(t - T) = u - T du to first order, so the term must equal
    -J_u(x, u) du T with J_u the Jacobian of the model's (x2', x4') in the currents (d/du of
    model.f, computed by CasADi here, not by the candidate's own formula). Both are linear in T and
    du, so they agree to round-off: 1e-12 relative to the largest component. States and currents
    drawn over the rig's gaps, positions and +-8 A, rates up to 2 kA/s, both signs."""
    x, u = ca.SX.sym("x", 4), ca.SX.sym("u", 2)
    jac = ca.Function("J", [x, u], [ca.jacobian(model.f(x, u)[[1, 3]], u)])
    term = lag_candidate(ctx).term.function
    rng = np.random.default_rng(35)
    for _ in range(20):
        xs = np.array(
            [rng.uniform(0.01, 0.028), rng.normal(0, 0.05), rng.uniform(-0.05, 0.05), rng.normal(0, 0.1)]
        )
        us = rng.uniform(-8.0, 8.0, 2)
        dus = rng.uniform(-2000.0, 2000.0, 2)
        T = rng.uniform(1e-4, 2e-3)
        expected = -np.asarray(jac(xs, us)) @ dus * T
        got = np.asarray(term(xs, us, dus, [T])).ravel()
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    # and it is the change of the accelerations for a small lag (first order: relative error ~ T/tau,
    # tau the currents' time scale |u| / |du| = 4 ms here, so 1e-6 s leaves < 1e-3)
    xs, us, dus, T = np.array([0.018, 0.0, 0.02, 0.0]), np.array([3.0, -2.0]), np.array([400.0, -300.0]), 1e-6
    change = (np.asarray(model.f(xs, us - T * dus)) - np.asarray(model.f(xs, us))).ravel()[[1, 3]]
    np.testing.assert_allclose(np.asarray(term(xs, us, dus, [T])).ravel(), change, rtol=1e-3)


@pytest.mark.parametrize(("slope", "plausible"), [(0.01, True), (-0.049, True), (0.06, False), (-0.2, False)])
def test_a_guide_slope_is_judged_against_its_physical_bound(ctx, slope, plausible):
    """misalignment_candidate: the slope's physical bound is 0.05 rad (a guide tilted 3 degrees off the
    stator is no misalignment). The physical parameters of a fitted slope pass the candidate's check
    within the bound, of either sign, and fail it beyond, with a reason that names the bound."""
    cand = misalignment_candidate(ctx)
    params = cand.term.physical_parameters(np.array([slope]), np.array([[1e-8]]), {})
    assert params["slope"].value == slope
    reason = cand.plausible(params)
    if plausible:
        assert reason is None
    else:
        assert reason and "0.05" in reason and "slope" in reason


# --- the gap-dependence candidates' sizes ----------------------------------------------------------------
@pytest.mark.parametrize("field", [True, False])
def test_the_attraction_change_is_relative_to_the_fitted_constants(model, ctx, field):
    """The candidates' columns are built with the reference constants (C1 for the thrust, C2 for the
    attraction); the change a user reads is relative to the fitted model. Computed here from the
    term's own acceleration and the fitted model (``model.with_constants``, C1 twice and C2 half
    the references, so a ratio taken from the wrong constant is off by 4): for the attraction
    candidate the vertical acceleration over the fitted attraction G - x2'(u = 0); for the field
    shape the horizontal acceleration over the fitted thrust x4'(u1 = 1 A) times 2 (the attraction
    follows the field squared, the thrust the field). Each at the smallest (largest) logged gap minus
    at the centre of the logged gaps. Both linear in q: 1e-9 relative (the delta method evaluates
    the same expression; round-off of a few operations)."""
    cand = (field_shape_candidate if field else gap_dependence_candidate)(ctx)
    refs = model.constants
    fitted_constants = dataclasses.replace(refs, C1=2.0 * refs.C1, C2=0.5 * refs.C2)
    fitted = model.with_constants(fitted_constants)
    consts = {"C1": fitted_constants.C1, "C2": fitted_constants.C2, "C3": refs.C3, "C4": refs.C4}
    q = np.array([0.08, 0.02])
    lo, hi = ctx.gap_range
    u = np.array([1.0, 0.0]) if field else np.zeros(2)
    row = 1 if field else 0

    def relative_change(gap):
        x = np.array([gap, 0.0, 0.0, 0.0])
        term = float(np.asarray(cand.term.function(x, u, np.zeros(2), q)).ravel()[row])
        acc = np.asarray(fitted.f(x, u)).ravel()
        if field:
            return 2.0 * term / float(acc[3])  # the thrust -C1 l1 u1 (nothing else acts along x3)
        # x2' = G - C2 l2 at u = 0: the attraction's acceleration is G - x2', the term's part of it -term
        return -term / (fitted.params.gravity - float(acc[1]))

    centre = relative_change(0.5 * (lo + hi))
    params = cand.term.physical_parameters(q, 1e-6 * np.eye(2), consts)
    for label, gap in (("at_smallest_gap", lo), ("at_largest_gap", hi)):
        expected = relative_change(gap) - centre
        assert abs(expected) > 0.01  # a change the test can see
        got = params[f"attraction_change_{label}"].value
        assert got == pytest.approx(expected, rel=1e-9), label


# --- reasons in plain units ------------------------------------------------------------------------------
@pytest.mark.parametrize("control_rate", [None, 500.0])
def test_a_lag_within_the_hold_is_refused_with_its_size_in_milliseconds(ctx, data, control_rate):
    """The lag beyond the hold must exceed half the hold's delay (half a control period: 0.1 ms at
    the rig's 5 kHz, 1 ms for a 500 Hz loop). A lag of 0.4 hold (0.04 ms, 0.4 ms) is refused and the
    reason prints the lag, the floor (0.5 hold) and the hold in ms, the numbers equal to the sizes
    to the 3 (2) significant digits printed; a lag of 3 holds with a small standard error passes."""
    if control_rate is not None:
        data = dataclasses.replace(data, settings={**data.settings, "control_rate_hz": control_rate})
        ctx = LibraryContext(ctx.model, data)
    hold = ctx.hold_delay
    assert hold == pytest.approx(0.5 / (control_rate or 5000.0))
    cand = lag_candidate(ctx)
    lag = 0.4 * hold
    params = cand.term.physical_parameters(np.array([hold + lag]), np.array([[(0.01 * hold) ** 2]]), {})
    assert params["time_constant"].value == pytest.approx(lag)
    reason = cand.plausible(params)
    assert reason and "ms" in reason
    value, floor, hold_ms = (
        float(v)
        for v in re.search(
            r"([-0-9.e]+) ± .* above ([0-9.e]+) ms \(half the hold's ([0-9.e]+) ms", reason
        ).groups()
    )
    assert value == pytest.approx(lag * 1e3, rel=1e-3)
    assert floor == pytest.approx(0.5 * hold * 1e3, rel=1e-2)
    assert hold_ms == pytest.approx(hold * 1e3, rel=1e-2)
    ok = cand.term.physical_parameters(np.array([4 * hold]), np.array([[(0.01 * hold) ** 2]]), {})
    assert cand.plausible(ok) is None


@pytest.mark.parametrize("axis", ["horizontal", "vertical"])
def test_a_constant_force_beyond_a_quarter_of_the_weight_is_refused_in_plain_words(ctx, axis):
    """A constant force on an axis beyond MAX_FORCE_SHARE (a quarter) of that axis's weight M g would
    have shown in the equilibrium currents (the papers' model predicts them to 5 %): the candidate
    refuses it with a reason naming the "<axis> force", its size and the bound M g / 4 in N (3.9 N
    horizontal, 10.7 N vertical for the papers' masses, printed with %g: 6 digits). Just inside the
    bound, of either sign, it is plausible."""
    horizontal, vertical = level_candidates(ctx)
    cand = horizontal if axis == "horizontal" else vertical
    bound = (
        MAX_FORCE_SHARE
        * ctx.params.gravity
        * (ctx.params.mass_horizontal if axis == "horizontal" else ctx.params.mass_vertical)
    )
    for force in (1.2 * bound, -1.2 * bound):
        params = cand.term.physical_parameters(np.array([force]), np.array([[1e-4]]), {})
        reason = cand.plausible(params)
        assert reason and reason.startswith(f"{axis} force of ")
        size, printed = (
            float(v) for v in re.search(r"of ([-0-9.e]+) N .* bound ([0-9.e]+) N", reason).groups()
        )
        assert size == pytest.approx(force, rel=1e-3) and printed == pytest.approx(bound, rel=1e-5)
    for force in (0.99 * bound, -0.99 * bound):
        params = cand.term.physical_parameters(np.array([force]), np.array([[1e-4]]), {})
        assert cand.plausible(params) is None


# --- what separates a candidate -------------------------------------------------------------------------
def test_every_candidates_experiment_continues_the_reports_sentence(model):
    """The library on the synthetic horizontal log (every candidate, a waviness too): each
    ``separate_by`` starts in lower case, has no word of two or more capitals (none is an acronym;
    "C2..C4", "L1", "000 Sec. V-A" are not words of capitals) and no full stop at its end; the
    report's line for a not-separable amplifier lag reads as one sentence naming current steps
    measured with a current probe."""
    data = prepare([_log(model, friction=0.0)], bandwidth=10.0)
    library = [*candidate_library(model, data), waviness_candidate(model, data, 0.06)]
    assert len(library) > 15
    for cand in library:
        text = cand.separate_by
        assert text[:1].islower(), (cand.name, text)
        assert re.search(r"\b[A-Z]{2,}\b", text) is None, (cand.name, text)
        assert not text.rstrip().endswith("."), (cand.name, text)
    lag = next(c for c in library if c.name == "current_amplifier_lag")
    assert "current steps at several amplitudes, measured with a current probe" in lag.separate_by
    sep = NotSeparable(lag.name, ("C1",), lag.separate_by, 0.01, "confounded", {})
    diag = dataclasses.replace(stub_diagnosis(), not_separable=[sep])
    line = next(s for s in diag.report().splitlines() if "not separable" in s)
    assert line.endswith(f"(confounded with C1): {lag.separate_by}")
    assert "with C1): current steps at several amplitudes" in line


@pytest.mark.parametrize("form", ["full", "stribeck"])
def test_a_viscous_part_within_two_standard_errors_of_zero_is_reported_as_not_resolved(form):
    """The friction's finding names its viscous part as found only when it is 2 standard errors
    from zero (the independent generator's vertical friction: 48 ± 81 N s/m for a true 10; a slow
    gap axis does not resolve it), else as not resolved, with the estimate beside it."""
    from maglev_oc.diagnosis.guides import _friction_words
    from maglev_oc.results import Estimate

    est = {
        "coulomb": Estimate(1.78, 0.65, "N"),
        "breakaway": Estimate(2.4, 0.7, "N"),
        "viscous": Estimate(47.6, 81.0, "N s/m"),
    }
    words = _friction_words("vertical", form, 0.05)(est)  # a fast axis: no caveat
    assert words.startswith("The vertical linear guides resist motion with 1.8 ± 0.7 N of Coulomb friction")
    assert words.endswith(
        "(and hold the axis while it sticks); their viscous friction is not resolved on this log "
        "(48 ± 80 N s/m)."
    )
    est["viscous"] = Estimate(4.91, 0.12, "N s/m")
    words = _friction_words("horizontal", form, 0.05)(est)
    assert words.endswith("4.9 ± 0.1 N s/m of viscous friction (and hold the axis while it sticks).")
    assert "not resolved" not in words
    if form == "full":  # the sentence as before the check
        assert words == (
            "The horizontal linear guides resist motion with 1.8 ± 0.7 N of Coulomb friction and "
            "4.9 ± 0.1 N s/m of viscous friction (and hold the axis while it sticks)."
        )


@pytest.mark.parametrize("form", ["full", "without_viscous", "stribeck", "stribeck_without_viscous"])
def test_a_holding_share_held_at_zero_is_not_said_to_hold_the_axis(form):
    """A share held while sticking that the fit held at zero (its column mostly the logged currents'
    errors: ``AccelerationTerm.optional``) is said to be so; one fitted keeps the sentence."""
    from maglev_oc.diagnosis.guides import _friction_words
    from maglev_oc.results import Estimate

    est = {
        "coulomb": Estimate(0.18, 0.2, "N"),
        "breakaway": Estimate(0.3, 0.2, "N"),
        "viscous": Estimate(1.4, 20.0, "N s/m"),
        "holding": Estimate(0.0, 0.0, "1"),
    }
    words = _friction_words("vertical", form, 0.05)(est)
    assert "hold the axis while it sticks" not in words
    assert "The axis hardly sticks on this log" in words
    est["holding"] = Estimate(0.6, 0.1, "1")
    words = _friction_words("vertical", form, 0.05)(est)
    assert "hold the axis while it sticks" in words and "hardly sticks" not in words


def test_a_negative_parameter_is_refused_with_how_many_standard_errors_below_zero_it_is():
    """not_below's reason gives value / standard error (seed-45 survivor: value times it)."""
    from maglev_oc.diagnosis.candidate import not_below
    from maglev_oc.results import Estimate

    check = not_below("viscous", "viscous friction")
    assert check({"viscous": Estimate(-6.0, 2.0, "N s/m")}) == (
        "viscous friction of -6 N s/m is negative (-3.0 standard errors)"
    )
    assert check({"viscous": Estimate(-3.0, 2.0, "N s/m")}) is None  # 1.5 standard errors: not refused
