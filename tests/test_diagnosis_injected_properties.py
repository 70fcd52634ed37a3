"""Properties that catch wrong answers in ``maglev_oc.diagnosis`` which the other diagnosis tests
let through (issue 21: "tests that would catch a wrong answer"). Each was found by injecting a
small plausible bug (a wrong sign, index, comparison, factor, tail of a test, a dropped
validation) into the package, one at a time, and running the quick diagnosis tests: these are the
bugs nothing caught, each turned into a property that holds for the right code whatever its
implementation, with the origin of every tolerance written beside it.

* The blocks' z of a null series (white log-ratios of mean zero) is calibrated: its spread over
  seeds is that of a Student t with 2m degrees of freedom, not sqrt(n) times larger.
* A candidate's Wald threshold is the upper-alpha quantile of chi^2 with as many degrees of
  freedom as the candidate has columns (scipy.stats), and its Wald statistic is coef' cov^-1 coef.
* The "strong" shortcut needs BOTH z >= min_z_strong and Wald >= strong_wald x threshold; an effect
  large on one of its axes is not "too small"; ``own_gain`` is the mean over the axes it acts on.
* The delta method's standard error of a linear function a'p is sqrt(a' C a) (exact).
* ``moved`` is the LARGEST relative change of a constant; ``fitted_model`` keeps the model's
  constant where the fit is not positive or its axis is locked.
* Once friction is chosen on an axis, exactly its samples at least ``slow_speed`` fast count.
* The peak contribution is the largest RMS over held-out blocks of the samples that count.
* The differentiator's 1 % calibration is added to every parameter except angles and lengths.
* ``diagnose`` refuses a held-out share below 5 % (no held-out block to judge on).
* The trace: a bin's standard error is its sd over the root of its count (numpy); each axis's
  residual is correlated with its OWN current's rate (vertical with i_d, horizontal with i_q) at
  the lag it follows it by.
* Unexplained structure: its force is its size times its own axis's mass; it is reported only at
  or above ``min_effect`` and at most ``max_per_axis`` times per axis.
"""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from maglev_oc.diagnosis.candidate import delta_method
from maglev_oc.diagnosis.pipeline import diagnose
from maglev_oc.diagnosis.refit import CALIBRATION, fitted_model, moved, with_model_form_spread
from maglev_oc.diagnosis.selection import (
    Judgement,
    SelectionSettings,
    _block_peak,
    _block_z,
    _verdict,
    evidence,
    judge,
    pooled_gains,
)
from maglev_oc.diagnosis.trace import trace
from maglev_oc.diagnosis.unexplained import _unexplained, find_unexplained
from maglev_oc.errors import InputError
from maglev_oc.regression.covariance import DEFAULT_BAND, frequencies_for
from maglev_oc.regression.data import prepare
from maglev_oc.regression.design import build_design
from maglev_oc.regression.solve import fit_subset, residuals
from maglev_oc.results import Estimate
from tests.test_diagnosis_selection_properties import cogged_design
from tests.test_statistics_properties import _log


@pytest.fixture(scope="module")
def cogged(model):
    """(design, library by name): the horizontal sweep with a cogging force planted at the slot
    pitch (0.02 m/s^2), the cogging and friction candidates' columns beside C1."""
    return cogged_design(model)


# --- significance --------------------------------------------------------------------------------------
def test_the_block_z_of_a_null_series_is_calibrated():
    # n = 120 white blocks of 0.5 s: the periodogram averages m = frequencies_for(120, 0.5, 0.25) = 15
    # frequencies, so z is Student t with 2m = 30 dof (sd sqrt(30/28) = 1.035). Over 400 seeds the
    # sample sd is within 1.035 (1 +- 3/sqrt(800)) = [0.93, 1.14] (3 sigma of a sd estimate)
    n = 120
    assert frequencies_for(n, 0.5, DEFAULT_BAND) == 15
    logs = np.zeros(n, dtype=int)
    z = np.array([_block_z(np.random.default_rng(s).normal(0.0, 0.3, n), logs, 0.5) for s in range(400)])
    assert 0.93 < np.std(z) < 1.14
    # and a shift of half a standard deviation per block is found: mean z ~ 0.5 sqrt(120) = 5.5
    shifted = [_block_z(np.random.default_rng(s).normal(0.15, 0.3, n), logs, 0.5) for s in range(50)]
    assert 4.0 < np.mean(shifted) < 7.0


def _judged(design, cand, settings):
    base = fit_subset(design, ["base"])
    r0 = residuals(design, base)[:, design.holdout]
    mse0 = np.maximum(np.mean(r0**2, axis=1), 1e-30)
    return judge(design, cand, ["base"], base, r0, mse0, settings)


@pytest.mark.parametrize("alpha", [1e-4, 0.05])
def test_the_wald_threshold_is_the_upper_chi2_quantile_with_the_candidates_dof(cogged, alpha):
    design, lib = cogged
    cand = lib["cogging_horizontal_19mm"]
    j = _judged(design, cand, SelectionSettings(alpha=alpha))
    k = design.groups[cand.name].size
    assert k >= 2  # a sine and a cosine: dof 1 would be another quantile
    assert j.wald_threshold == pytest.approx(stats.chi2.ppf(1 - alpha, k), rel=1e-9)
    assert j.verdict == "passes"  # the planted cogging (z ~ 10): its Wald statistic was computed
    coef, cov = j.fit.group(design, cand.name)
    assert j.wald == pytest.approx(float(coef @ np.linalg.inv(cov) @ coef), rel=1e-8)


# --- verdicts from measured evidence -------------------------------------------------------------------
def _judgement(*, z, wald, gain_axes=(0.1, 0.1), rms=(0.01, 0.01), peak=(0.01, 0.01), threshold=10.0):
    fit = SimpleNamespace(compensation=1.0)
    gain_axes = np.asarray(gain_axes, dtype=float)
    return Judgement(
        "effect",
        "passes",
        "",
        float(np.nanmean(gain_axes)),
        gain_axes,
        z,
        z,
        wald,
        threshold,
        1.0,
        (),
        np.asarray(rms, dtype=float),
        np.asarray(peak, dtype=float),
        {},
        fit,
    )


def _verdict_of(j, axes=(0, 1)):
    cand = SimpleNamespace(axis="both", plausible=lambda physical: None)
    return _verdict(j, cand, np.array(axes), SimpleNamespace(compensation=1.0), SelectionSettings(), None)[0]


def test_the_strong_shortcut_needs_both_z_and_wald():
    s = SelectionSettings()
    z_mid = 0.5 * (s.min_z_strong + s.min_z)  # below min_z, above min_z_strong
    assert _verdict_of(_judgement(z=z_mid, wald=2 * s.strong_wald * 10.0)) == "passes"
    assert _verdict_of(_judgement(z=z_mid, wald=0.5 * s.strong_wald * 10.0)) == "not significant"
    assert (
        _verdict_of(_judgement(z=0.5 * s.min_z_strong, wald=100 * s.strong_wald * 10.0)) == "not significant"
    )
    assert _verdict_of(_judgement(z=s.min_z + 1, wald=2 * 10.0)) == "passes"
    assert _verdict_of(_judgement(z=s.min_z + 1, wald=0.5 * 10.0)) == "not significant"


def test_an_effect_large_on_one_of_its_axes_is_not_too_small():
    s = SelectionSettings()
    big, small = 4 * s.min_effect, 0.1 * s.min_effect
    j = _judgement(z=s.min_z + 1, wald=100.0, rms=(big, small), peak=(big, small))
    assert _verdict_of(j) == "passes"
    j = _judgement(z=s.min_z + 1, wald=100.0, rms=(small, small), peak=(small, small))
    assert _verdict_of(j) == "too small"


def test_own_gain_is_the_mean_over_the_axes_it_acts_on():
    j = _judgement(z=5.0, wald=100.0, gain_axes=(0.02, 0.1))
    assert j.own_gain == pytest.approx(0.06, rel=1e-12)
    assert _judgement(z=5.0, wald=100.0, gain_axes=(np.nan, 0.1)).own_gain == pytest.approx(0.1)
    # a gain of 0.8 % on one axis and 0.1 % on the other is below the 0.5 % minimum on average
    s = SelectionSettings()
    j = _judgement(z=s.min_z + 1, wald=100.0, gain_axes=(0.008, 0.001))
    assert _verdict_of(j) == "not significant"


def test_min_gain_is_held_to_the_pooled_gain_and_the_quarter_must_drop_too():
    s = SelectionSettings()
    j = _judgement(z=s.min_z + 1, wald=100.0, gain_axes=(np.nan, 0.8 * s.min_gain))
    assert _verdict_of(j, axes=(1,)) == "not significant"  # the quarter alone is short of min_gain
    pooled = dataclasses.replace(j, pooled_gain_axes=np.array([np.nan, 1.2 * s.min_gain]))
    assert pooled.own_pooled_gain == pytest.approx(1.2 * s.min_gain, rel=1e-12)
    assert _verdict_of(pooled, axes=(1,)) == "passes"  # ... the four quarters together are not
    # pooled over min_gain, but the held-out quarter (never in any fit) does not improve: the
    # effect is in the training data only
    for quarter in (0.0, -0.01):
        trained = dataclasses.replace(pooled, gain_axes=np.array([np.nan, quarter]))
        assert _verdict_of(trained, axes=(1,)) == "not significant"
    # the quarter over min_gain but the pooled gain under it: the pooled estimate decides
    short = dataclasses.replace(j, gain_axes=np.array([np.nan, 2 * s.min_gain]))
    short = dataclasses.replace(short, pooled_gain_axes=np.array([np.nan, 0.9 * s.min_gain]))
    assert _verdict_of(short, axes=(1,)) == "not significant"


def test_a_rival_is_compared_with_the_gain_over_the_same_samples():
    # the smooth rivals' gains are measured over the held-out quarter, so a candidate is held to
    # them with its quarter's gain, not with its pooled one (which the rivals do not have): a
    # commutation offset whose pooled gain (16 %) was set against a gap rival's quarter (23 %)
    # lost to it, and a constant force took its place (a cable carrier left out of the library)
    s = SelectionSettings()
    j = _judgement(z=s.min_z + 1, wald=100.0, gain_axes=(0.3, 0.3))
    j = dataclasses.replace(j, pooled_gain_axes=np.array([0.1, 0.1]))
    term = SimpleNamespace(parameter_names=("a",))
    cand = SimpleNamespace(axis="both", plausible=lambda physical: None, term=term, nuisance=())
    for rival, verdict in ((0.2, "passes"), (0.3 + 2 * s.rival_margin, "not specific")):
        rivals = {("both", 1): (rival, "gap")}
        out = _verdict(j, cand, np.array([0, 1]), SimpleNamespace(compensation=1.0), s, rivals)[0]
        assert out == verdict
    # the reason names the rival's variable in words and both gains (a variable's identifier, with
    # its underscore, is not a word)
    rivals = {("both", 1): (0.4, "gap_rate")}
    _, reason = _verdict(j, cand, np.array([0, 1]), SimpleNamespace(compensation=1.0), s, rivals)
    assert reason.startswith("a smooth function of the gap rate explains more of the held-out error")
    assert "(40.0% against 30.0%)" in reason


def test_pooled_gains_are_the_drop_of_the_summed_squares_over_every_part():
    rng = np.random.default_rng(5)
    every = [(rng.normal(size=(2, m)), rng.normal(size=(2, m))) for m in (40, 70, 55)]
    axes = np.array([0, 1])
    expected = [
        1.0 - sum(float(r1[a] @ r1[a]) for _, r1 in every) / sum(float(r0[a] @ r0[a]) for r0, _ in every)
        for a in axes
    ]
    np.testing.assert_allclose(pooled_gains(every, axes), expected, rtol=1e-12)
    # weighted by each part's sum of squares, not an average of the parts' own gains
    parts = np.mean([1.0 - np.sum(r1[0] ** 2) / np.sum(r0[0] ** 2) for r0, r1 in every])
    assert abs(pooled_gains(every, axes[:1])[0] - parts) > 1e-3


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


def test_moved_is_the_largest_relative_change(model):
    c = model.constants
    other = model.with_constants(c.replace(C3=1.05 * c.C3))
    assert moved(other, model) == pytest.approx(0.05, rel=1e-9)
    both = model.with_constants(c.replace(C1=0.99 * c.C1, C3=1.05 * c.C3))
    assert moved(both, model) == pytest.approx(0.05, rel=1e-9)


def test_fitted_model_keeps_the_models_constant_where_the_fit_is_not_usable(model):
    c = model.constants
    values = {"C1": 1.1 * c.C1, "C2": -5.0, "C3": 0.0, "C4": 1.2 * c.C4}
    fit = SimpleNamespace(value=lambda name: values[name])
    out = fitted_model(model, fit, np.array([True, True]), "test").constants
    assert (out.C1, out.C2, out.C3, out.C4) == pytest.approx((1.1 * c.C1, c.C2, c.C3, 1.2 * c.C4))
    # horizontal axis locked: C1 (horizontal) keeps the model's value
    out = fitted_model(model, fit, np.array([True, False]), "test").constants
    assert out.C1 == pytest.approx(c.C1)


def test_the_calibration_is_added_to_every_parameter_but_angles_and_lengths():
    params = {
        "force": Estimate(2.0, 0.03, "N"),
        "phase": Estimate(1.0, 0.02, "rad"),
        "period": Estimate(0.019, 1e-4, "m"),
    }
    cand = SimpleNamespace(term=SimpleNamespace(variants=()))  # no variants: no spread
    out = with_model_form_spread(params, None, None, [], cand, None, None, None)
    assert out["force"].stderr == pytest.approx(math.hypot(0.03, CALIBRATION * 2.0), rel=1e-12)
    assert out["phase"].stderr == pytest.approx(0.02, rel=1e-12)
    assert out["period"].stderr == pytest.approx(1e-4, rel=1e-12)


# --- which held-out samples count ----------------------------------------------------------------------
def test_the_samples_counted_beside_friction_are_those_at_least_slow_speed_fast(cogged):
    design, _ = cogged
    speed = np.abs(design.prepared.x[3, design.holdout])
    slow = float(np.percentile(speed, 30))  # a split with many samples on both sides
    settings = SelectionSettings(slow_speed=slow)
    assert evidence(design, [], settings) is None
    friction = SimpleNamespace(family="friction", axis="horizontal")
    counted = evidence(design, [friction], settings)
    np.testing.assert_array_equal(counted[1], speed >= slow)
    assert np.all(counted[0])  # the other axis is not affected


def test_the_peak_contribution_is_over_the_counted_samples_of_each_block(cogged):
    # recomputed here: the held-out samples cut into whole blocks of block_seconds from the start
    # of the held-out block (one log), the RMS of each block over its counted samples, the largest
    design, _ = cogged
    rng = np.random.default_rng(4)
    n_hold = int(design.holdout.sum())
    change = rng.normal(size=(2, n_hold))
    change[:, : n_hold // 3] *= 5.0  # one region larger, so the peak block is not any block
    counted = rng.uniform(size=(2, n_hold)) > 0.5
    change = np.where(counted, change, 0.0)  # as judge passes it: residuals zero where not counted
    size = round(design.block_seconds / design.prepared.sample_time)
    nb = n_hold // size
    expected = np.zeros(2)
    for b in range(nb):
        sl = slice(b * size, (b + 1) * size)
        for a in range(2):
            c = counted[a, sl]
            expected[a] = max(expected[a], math.sqrt(np.sum(change[a, sl][c] ** 2) / max(c.sum(), 1)))
    np.testing.assert_allclose(_block_peak(design, change, counted), expected, rtol=1e-12)
    # and the same whatever the caller left at the samples not counted (it need not zero them)
    noisy = np.where(counted, change, 1e3)
    np.testing.assert_allclose(_block_peak(design, noisy, counted), expected, rtol=1e-12)


def test_diagnose_refuses_a_held_out_share_below_five_percent(model):
    log = _log(model, friction=0.0)
    for fraction in (0.0, 0.01, 0.6):
        with pytest.raises(InputError, match="holdout_fraction"):
            diagnose([log], model, holdout_fraction=fraction)


# --- what the residual depends on --------------------------------------------------------------------
def _traced(seed=5, n=6000, lag=7):
    """A trace of residuals that are the own-axis current rates delayed by ``lag`` samples (the two
    rates independent), at states that sweep the gap and the position."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-3
    x = np.vstack(
        [
            0.02 + 2e-3 * np.sin(2 * np.pi * 0.3 * t),
            rng.normal(0, 0.01, n),
            0.03 * np.sin(2 * np.pi * 0.2 * t),
            rng.normal(0, 0.02, n),
        ]
    )
    du = rng.normal(size=(2, n))
    residual = np.vstack([np.roll(du[1], lag), np.roll(du[0], lag)]) + 0.1 * rng.normal(size=(2, n))
    return x, du, residual


def test_the_binned_standard_error_is_the_sd_over_the_root_of_the_count(model):
    # recomputed with numpy in the trace's own bins (their edges from its centres): std / sqrt(count)
    x, du, residual = _traced()
    tr = trace(x, du, residual, model.params, 1e-3)
    for name, row in (("gap", 0), ("position", 2)):
        b = tr.binned[name]
        half = 0.5 * (b.centers[1] - b.centers[0])
        edges = np.concatenate([b.centers - half, [b.centers[-1] + half]])
        idx = np.clip(np.digitize(x[row], edges) - 1, 0, edges.size - 2)
        for k in np.flatnonzero(b.count >= 20)[:5]:
            sel = idx == k
            assert sel.sum() == b.count[k]
            want = residual[:, sel].std(axis=1) / math.sqrt(sel.sum())
            np.testing.assert_allclose(b.stderr[:, k], want, rtol=1e-9)


def test_each_axis_is_correlated_with_its_own_current_rate_at_the_lag(model):
    # vertical residual = d(i_d)/dt 7 samples late, horizontal = d(i_q)/dt: each axis's
    # correlation peaks at +7 ms near 1 (1/sqrt(1 + 0.1^2) = 0.995, the added noise), the rates
    # being independent white sequences
    lag = 7
    x, du, residual = _traced(lag=lag)
    tr = trace(x, du, residual, model.params, 1e-3)
    for a in range(2):
        k = int(np.argmax(tr.lag_correlation[a]))
        assert tr.lags[k] == pytest.approx(lag * 1e-3)
        assert tr.lag_correlation[a, k] > 0.95


def test_an_unexplained_force_is_its_size_times_its_own_axis_mass(model):
    p = model.params
    assert p.mass_vertical != p.mass_horizontal
    for axis, mass in (("vertical", p.mass_vertical), ("horizontal", p.mass_horizontal)):
        entry = (SimpleNamespace(axis=axis), "gap", "the gap", None)
        u = _unexplained(model, entry, 0.01, 0.1, 5.0)
        assert u.force_rms == pytest.approx(0.01 * mass, rel=1e-12)


@pytest.fixture(scope="module")
def bumpy(model):
    """The horizontal sweep with a smooth position-dependent force (0.05 m/s^2, a cubic in x3) that
    no candidate is given: the position probe finds it."""
    log = _log(model, friction=0.0, force=lambda x3: 0.05 * (x3 / 0.03) ** 3)
    data = prepare([log], bandwidth=10.0)
    fit, hold = data.masks(0.25)
    design = build_design(data, model, estimate=("C1",), fit=fit, holdout=hold)
    return data, fit, hold, design.weights


def test_unexplained_structure_is_reported_only_when_large_enough_and_at_most_max_per_axis(model, bumpy):
    data, fit, hold, weights = bumpy
    settings = SelectionSettings()
    found = find_unexplained(data, model, [], fit, hold, weights, [], settings)
    assert found, "the planted force is found"
    assert all(u.size >= settings.min_effect for u in found)
    biggest = max(u.size for u in found)
    for most in (0, 1):  # one moving axis: at most ``most`` reports in all
        assert (
            len(find_unexplained(data, model, [], fit, hold, weights, [], settings, max_per_axis=most))
            <= most
        )
    # the same structure, with a size threshold above it: nothing is reported
    larger = SelectionSettings(min_effect=1.5 * biggest)
    assert find_unexplained(data, model, [], fit, hold, weights, [], larger) == []
