"""Options of ``maglev_oc.diagnosis`` passed by name, each checked against an independent computation
(a closed form, numpy by hand, a planted effect), so that the option ignored (its default used) or
inverted fails here:

- ``fmt(digits=)`` writes the value to that many significant digits, the error to one;
- ``refine_waviness_period(points=, span=)`` returns the best of the periods scanned within the
  span, the scan fitting both axes with the candidate's own columns;
- the generic probes' Legendre columns are mean-free over the fitted samples;
- ``converged_references(max_rounds=, tolerance=)`` stops after that many joint fits or at the
  tolerance; ``trace(min_share=)`` reports no peak below the share and the planted one above it;
- the verdict holds a motor-period force to ``min_periods`` of travel and refuses one beside an
  unresolved period; ``SelectionSettings.cross_parts`` pools the held-out quarter with that many
  cross-fitted parts; ``parameter_penalty`` decides between nested candidates.
"""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest
from numpy.testing import assert_allclose

import maglev_oc.diagnosis.refit as refit_module
from maglev_oc.diagnosis.candidate import Candidate, fmt
from maglev_oc.diagnosis.guides import refine_waviness_period, waviness_candidate
from maglev_oc.diagnosis.library import candidate_library
from maglev_oc.diagnosis.probes import PROBE_ORDER, smooth_probes
from maglev_oc.diagnosis.refit import converged_references, fitted_model
from maglev_oc.diagnosis.selection import (
    SMOOTH_POSITION,
    SelectionSettings,
    _CrossFit,
    _CrossParts,
    judge,
    select,
)
from maglev_oc.diagnosis.trace import trace, traces
from maglev_oc.model.parameters import LumpedConstants, StageParameters
from maglev_oc.regression.data import prepare
from maglev_oc.regression.design import build_design
from maglev_oc.regression.solve import fit_subset, residuals
from maglev_oc.regression.terms import periodic_force
from maglev_oc.results import Estimate
from tests._diagnosis_cases import _judgement, _verdict
from tests._regression_cases import _both_axes_log
from tests.test_statistics_properties import _log


# --- diagnosis/candidate.py ------------------------------------------------------------------------------
def test_fmt_writes_the_value_to_the_digits_asked_for_and_the_error_to_one():
    e = Estimate(1.23456, 0.0123, "N")
    assert fmt(e, digits=4) == "1.235 ± 0.01 N"
    assert fmt(e, digits=3) == "1.23 ± 0.01 N"
    assert fmt(e) == "1.2 ± 0.01 N"
    assert fmt(e, digits=1) == "1 ± 0.01 N"
    assert fmt(Estimate(12345.6, 210.0, "um"), digits=3) == "12300 ± 200 um"


# --- diagnosis/guides.py -----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def waviness_residual(model, friction_data):
    """(data, residual, weights, fit, true period): the filtered acceleration of a guide waviness of
    30 mm (0.1 mm amplitude) on the friction sweep, from the waviness candidate's own term."""
    data = friction_data
    train, hold = data.masks(0.25)
    period = 0.030
    cand = waviness_candidate(model, data, period)
    d = build_design(data, model, estimate=(), terms=[cand.term], fit=train, holdout=hold, weights=np.ones(2))
    residual = np.einsum("p,pan->an", np.array([1e-4, 0.3e-4]), d.columns)
    return data, residual, np.array([0.0, 1.0]), train, period


@pytest.mark.parametrize(
    ("points", "span", "grid"),
    [
        (41, 0.25, None),  # the true period 1.2 x the guess is a grid point: found
        (3, 0.25, (0.75, 1.0, 1.25)),  # nearest of three: 1.25
        (41, 0.1, None),  # the scan ends at 1.1 x the guess, nearest the truth
        (5, 0.1, (0.9, 0.95, 1.0, 1.05, 1.1)),
    ],
)
def test_the_waviness_period_is_the_best_of_the_points_scanned_within_the_span(
    model, waviness_residual, points, span, grid
):
    """refine_waviness_period(points=, span=): the residual is a waviness of period P exactly, the
    guess P / 1.2; the answer is the scanned period (guess x linspace(1 - span, 1 + span, points))
    nearest P — P itself when it is on the grid (1e-9: linspace's rounding)."""
    data, residual, weights, fit, period = waviness_residual
    guess = period / 1.2
    got = refine_waviness_period(model, data, residual, weights, fit, guess, points=points, span=span)
    scanned = guess * np.linspace(1 - span, 1 + span, points)
    if grid is not None:
        assert_allclose(scanned / guess, grid, rtol=1e-12)
    nearest = scanned[np.argmin(np.abs(scanned - period))]
    assert got == pytest.approx(nearest, rel=1e-9)
    assert np.min(np.abs(scanned - got)) <= 1e-9 * got  # one of the scanned periods


# --- diagnosis/probes.py ------------------------------------------------------------------------------------
def test_the_generic_probes_legendre_columns_are_mean_free_over_the_fitted_samples():
    """smooth_probes: on each axis and for each state variable, the columns of Legendre orders 1..4
    average to zero over the fitted (valid) samples — each about its own variable's means (the gap's
    and the position's Legendre means differ: 1e-9 of the column's RMS is rounding, a mean left in is
    several per cent); the horizontal probe's constant column is one on that axis."""
    data = prepare([_both_axes_log(seconds=8.0, seed=5)], bandwidth=10.0)
    probes = smooth_probes(data)
    x = data.x[:, data.valid]
    n = x.shape[1]
    zeros = np.zeros((2, n))
    for (axis, var), term in probes.items():
        a = 0 if axis == "vertical" else 1
        cols = np.asarray(term.features.map(n)(x, data.u[:, data.valid], zeros))  # (2, k n)
        cols = cols.reshape(2, n, term.n_parameters)
        for i in range(PROBE_ORDER):
            col = cols[a, :, i]
            rms = float(np.sqrt(np.mean(col**2)))
            assert rms > 0.05, (axis, var, i)  # a real column (Legendre values of order 1)
            assert abs(np.mean(col)) <= 1e-9 * rms, (axis, var, i)
            assert np.all(cols[1 - a, :, i] == 0.0)
        if axis == "horizontal":
            assert np.all(cols[1, :, PROBE_ORDER] == 1.0)


# --- diagnosis/refit.py ------------------------------------------------------------------------------------
@pytest.fixture()
def count_rounds(monkeypatch):
    """A list that grows by one at every joint fit converged_references builds."""
    rounds = []
    real = refit_module.build_design

    def spy(*args, **kw):
        rounds.append(1)
        return real(*args, **kw)

    monkeypatch.setattr(refit_module, "build_design", spy)
    return rounds


def test_the_references_converge_within_max_rounds_and_stop_at_the_tolerance(
    model, friction_data, count_rounds
):
    """converged_references: started from references with C1 10 % off the log's, the first joint fit
    moves C1 back by about 10 %, and the second confirms it (the holding column is the modelled
    acceleration with the references' C1, whose scale its own coefficient absorbs: the first fit is
    already the fixed point). One round (``max_rounds=1``) is the hand-built joint fit at the given
    references; with a tolerance of 50 % it stops after that round too; with the default tolerance
    (1e-3) it takes the second; with a tolerance no change can meet, exactly ``max_rounds``."""
    data = friction_data
    train, hold = data.masks(0.25)
    weights = np.array([0.0, 1.0])
    c = model.constants
    off = model.with_constants(LumpedConstants(1.1 * c.C1, c.C2, c.C3, c.C4))
    chosen = ["guide_friction_horizontal"]

    def run(**kw):
        count_rounds.clear()
        out = converged_references(model, off, data, chosen, train, hold, weights, **kw)
        return np.asarray(out.constants.as_array(), dtype=float), len(count_rounds)

    one, n1 = run(max_rounds=1)
    assert n1 == 1
    # the same joint fit by hand: the library at the off references, the chosen term's columns
    lib = {cand.name: cand for cand in candidate_library(off, data)}
    d = build_design(data, off, terms=[lib[chosen[0]].term], fit=train, holdout=hold, weights=weights)
    by_hand = fitted_model(model, fit_subset(d, list(d.groups), covariance=False), data.moving, "by hand")
    assert_allclose(one, np.asarray(by_hand.constants.as_array(), dtype=float), rtol=1e-12)
    assert one[0] == pytest.approx(c.C1, rel=0.02)  # back near the log's C1 (it moved 10 %)
    loose, n_loose = run(max_rounds=5, tolerance=0.5)
    assert n_loose == 1 and np.array_equal(loose, one)
    full, n_full = run()
    assert n_full == 2
    assert_allclose(full, one, rtol=1e-9)  # the fixed point (1e-9: the refit's rounding)
    _, n_never = run(max_rounds=3, tolerance=-1.0)
    assert n_never == 3


# --- diagnosis/trace.py ------------------------------------------------------------------------------------
PLANTED_PERIODS = (0.020, 0.027)
"""[m] The periods of the sines in x3 of the two traced residuals."""


def _traced_residuals(n: int = 6000, seed: int = 0):
    """(x, du, residuals): a horizontal sweep over 80 mm and two residuals, each a sine in x3 of its
    period in :data:`PLANTED_PERIODS` (unit amplitude, variance 1/2) plus white noise of variance 1
    on the horizontal axis (share explained at the period about 1/3) and pure noise on the vertical."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-3
    x = np.zeros((4, n))
    x[0] = 0.02
    x[2] = 0.04 * np.sin(2 * math.pi * 0.37 * t)
    x[3] = np.gradient(x[2], 1e-3)
    du = rng.standard_normal((2, n))
    out = []
    for period in PLANTED_PERIODS:
        r = rng.standard_normal((2, n))
        r[1] += np.sin(2 * math.pi * x[2] / period)
        out.append(r)
    return x, du, out


@pytest.mark.parametrize("min_share", [0.1, 0.5])
def test_a_trace_reports_no_peak_below_min_share_and_the_planted_one_above_it(min_share):
    """trace(min_share=) and traces(min_share=): every reported peak explains at least ``min_share``
    of its axis's variance; each planted sine (share 0.5 / 1.5 = 1/3 of the horizontal residual, give
    or take the noise's 1/n) is reported at its own period at 0.1, not at 0.5; the vertical noise
    (shares of order 2/n) never. Each of ``traces`` is the ``trace`` of its own residual, to the bit."""
    x, du, residuals_ = _traced_residuals()
    params = StageParameters()
    many = traces(x, du, residuals_, params, 1e-3, min_share=min_share)
    assert len(many) == len(residuals_)
    for tr, residual, period in zip(many, residuals_, PLANTED_PERIODS, strict=True):
        one = trace(x, du, residual, params, 1e-3, min_share=min_share)
        assert np.array_equal(tr.spectrum, one.spectrum) and tr.peaks == one.peaks
        share = float(np.max(tr.spectrum[1]))
        assert share == pytest.approx(1 / 3, abs=0.05)  # 3 sigma of the noise's share at n = 6000
        assert all(s >= min_share for _, _, s in tr.peaks)
        horizontal = [p for a, p, s in tr.peaks if a == "horizontal"]
        if min_share < share:
            # the strongest peak at the planted period (the periods' grid is 1.2 % apart)
            strongest = max((s, p) for a, p, s in tr.peaks if a == "horizontal")[1]
            assert strongest == pytest.approx(period, rel=0.03)
        else:
            assert horizontal == []
        assert not any(a == "vertical" for a, _, _ in tr.peaks)


# --- diagnosis/selection.py --------------------------------------------------------------------------------
def _periodic_verdict(*, periods_seen=None, unresolved=()):
    """The verdict of a plausible periodic candidate (period 19 mm) whose evidence passes every
    other test (z and Wald far beyond their thresholds, 10 % gain, 0.01 m/s^2)."""
    j = dataclasses.replace(_judgement(z=10.0, wald=1e3), physical={"period": Estimate(0.019, 0.0, "m")})
    cand = SimpleNamespace(axis="both", plausible=lambda physical: None)
    cur = SimpleNamespace(compensation=1.0)
    return _verdict(j, cand, np.array([0, 1]), cur, SelectionSettings(), None, periods_seen, unresolved)


def test_a_periodic_force_over_too_short_a_travel_or_beside_an_unresolved_period_is_not_separable():
    """min_periods = 1.25 and min_beats = 1: a travel of 1.2 periods is refused with the travel named,
    1.3 passes, and a candidate that is not position-periodic (None) is not held to it; a chosen
    effect whose period drifts from its own by 0.5 cycle over the travel makes it not separable and
    is named, with none it passes."""
    assert _periodic_verdict() == ("passes", "")
    verdict, reason = _periodic_verdict(periods_seen=1.2)
    assert verdict == "not separable" and "1.2 periods of 19.0 mm" in reason
    assert "a travel of 24 mm or more separates them" in reason  # min_periods x 19 mm = 23.75 mm
    assert _periodic_verdict(periods_seen=1.3)[0] == "passes"
    verdict, reason = _periodic_verdict(unresolved=[("detent_57mm", 0.5)])
    assert verdict == "not separable" and "detent 57mm" in reason and "0.50 of a cycle" in reason
    assert _periodic_verdict(periods_seen=1.3, unresolved=[])[0] == "passes"


def test_cross_parts_pools_the_held_out_quarter_with_that_many_cross_fitted_parts(cogged):
    """SelectionSettings.cross_parts: 0 judges the first step on the held-out quarter alone (z is the
    quarter's), k pools it with the training data cut into k parts, each predicted by fits on the
    rest (the first step's z is that of a judgement with k such parts, and differs between k = 2
    and k = 3: other parts, other blocks)."""
    design, lib = cogged
    cand = lib["cogging_horizontal_19mm"]
    base = fit_subset(design, ["base"])
    r0 = residuals(design, base)[:, design.holdout]
    mse0 = np.maximum(np.mean(r0**2, axis=1), 1e-30)
    zs = {}
    for parts in (0, 2, 3):
        settings = SelectionSettings(cross_parts=parts, bootstrap=0)
        j = select(design, [cand], settings).steps[0].judgements[cand.name]
        if parts == 0:
            assert j.z == j.z_holdout
        else:
            cross = _CrossParts.of(_CrossFit(design, parts), ["base"], [], settings)
            want = judge(design, cand, ["base"], base, r0, mse0, settings, cross=cross)
            assert len(cross.fold.samples) == parts
            assert j.z == pytest.approx(want.z, rel=1e-9)  # the same sums in the same order
            assert j.z != pytest.approx(j.z_holdout, rel=1e-3)
        zs[parts] = j.z
    assert zs[2] != pytest.approx(zs[3], rel=1e-3)


def test_the_judgement_holds_a_motor_period_force_to_min_periods_of_the_logged_travel(cogged, model):
    """judge() passes the logged travel in periods to the verdict: the planted slot-pitch cogging,
    seen over T / t1 periods (T the 1st-99th percentile travel of the training samples), passes with
    min_periods 1 % below that and is not separable, confounded with a smooth dependence on the
    position, 1 % above it (1 %: far above the percentiles' rounding, far below the travel)."""
    design, lib = cogged
    cog = lib["cogging_horizontal_19mm"]
    travel = float(np.subtract(*np.percentile(design.prepared.x[2, design.fit], [99, 1])))
    seen = travel / model.params.slot_pitch
    assert seen > 1.25  # the default passes it
    base = fit_subset(design, ["base"])
    r0 = residuals(design, base)[:, design.holdout]
    mse0 = np.maximum(np.mean(r0**2, axis=1), 1e-30)
    for factor, verdict in ((0.99, "passes"), (1.01, "not separable")):
        settings = SelectionSettings(min_periods=factor * seen)
        j = judge(design, cog, ["base"], base, r0, mse0, settings)
        assert j.verdict == verdict, j.reason
        assert j.confounded_with == (() if verdict == "passes" else (SMOOTH_POSITION,))


@pytest.fixture(scope="module")
def nested_periodic(model):
    """(design, cogging, simple): the horizontal sweep with a slot-pitch force of 0.02 m/s^2 and its
    second harmonic of 0.006 m/s^2 planted; the library's two-harmonic cogging (4 reported
    coefficients) and a one-harmonic periodic force at the same period (2, nested in it) as candidates."""
    period = model.params.slot_pitch

    def force(x3):
        arg = 2 * math.pi * x3 / period
        return 0.02 * np.sin(arg + 0.5) + 0.006 * np.sin(2 * arg)

    data = prepare([_log(model, friction=0.0, force=force)], bandwidth=10.0)
    cog = {c.name: c for c in candidate_library(model, data)}["cogging_horizontal_19mm"]
    simple = Candidate(
        periodic_force(model.params, "horizontal", period, name="periodic_19mm"),
        "periodic",
        "position",
        "a longer travel",
        lambda physical: None,
        lambda physical: "",
    )
    fit, hold = data.masks(0.25)
    design = build_design(data, model, estimate=("C1",), terms=(cog.term, simple.term), fit=fit, holdout=hold)
    return design, cog, simple


def test_a_candidate_nested_in_the_chosen_one_is_judged_inseparable_without_a_warning(nested_periodic):
    """The simpler force chosen first (a large penalty per coefficient), the two-harmonic cogging is
    then judged beside the force its first harmonic repeats: their joint Gram is singular to
    rounding. The fit holds the repeated columns at 0 (regression.solve._spanned) and the
    judgement leaves them out of both spans: the variance inflation is that of the second
    harmonic alone against the rest, finite and small (under 2: a harmonic at half the period is
    nearly orthogonal to the first over the travel), without dividing by the zero variances of a
    singular inverse (the RuntimeWarning, an error under the project's warning filter, that a
    fault raised here). It is not accepted: its period is the chosen force's."""
    design, cog, simple = nested_periodic
    sel = select(design, [cog, simple], SelectionSettings(parameter_penalty=0.05, bootstrap=0))
    assert sel.selected == [simple.name]
    assert 1.0 <= sel.last[cog.name].vif < 2.0
    assert sel.last[cog.name].verdict != "accepted"


def test_the_parameter_penalty_prefers_the_nested_candidate_beyond_the_gain_per_coefficient(nested_periodic):
    """SelectionSettings.parameter_penalty: among the candidates that pass, the one chosen has the
    largest gain - penalty x reported coefficients, in the choice and in every bootstrap vote. The
    two-harmonic cogging gains g4, the one-harmonic force g2 < g4 (the planted second harmonic):
    the choice turns at penalty* = (g4 - g2) / (4 - 2). At 0.8 penalty* the cogging is chosen, at
    1.2 and 3 penalty* the simpler force, at 3 penalty* in every resample too (the margin, 4 penalty*,
    is far beyond the resamples' spread of the gains). One step only (max_effects = 1)."""
    design, cog, simple = nested_periodic
    first = select(
        design, [cog, simple], SelectionSettings(parameter_penalty=0.0, bootstrap=0, max_effects=1)
    )
    assert first.selected == [cog.name]
    gains = {n: j.gain for n, j in first.steps[0].judgements.items()}
    assert gains[cog.name] > gains[simple.name] + 0.02  # the second harmonic is real
    turn = (gains[cog.name] - gains[simple.name]) / 2
    for factor, chosen in ((0.8, cog.name), (1.2, simple.name), (3.0, simple.name)):
        settings = SelectionSettings(parameter_penalty=factor * turn, bootstrap=10, max_effects=1)
        sel = select(design, [cog, simple], settings)
        assert sel.selected == [chosen], factor
        verdicts = sorted(j.verdict for j in sel.steps[0].judgements.values())
        assert verdicts == ["accepted", "passes"]  # both passed: the penalty decided
        if factor == 3.0:
            assert sel.steps[0].confidence == 1.0


def test_the_waviness_scan_fits_both_axes_with_the_candidates_own_columns(model, waviness_residual):
    """Weighted on both axes, the scan's columns must be the waviness candidate's own (the gap's
    change through the gap sensitivity on both axes and, on the horizontal, the slope pushing the
    platform, in the candidate's relative sign): the candidate's exact residual at P is then fitted
    to rounding at P, the best of the grid (P on it: the guess P / 1.2, 41 points over +-25 %). On
    the horizontal axis alone a wrong relative sign hides in the coefficients' signs."""
    data, residual, _, fit, period = waviness_residual
    got = refine_waviness_period(model, data, residual, np.ones(2), fit, period / 1.2)
    assert got == pytest.approx(period, rel=1e-9)
