"""Properties of ``maglev_oc.diagnosis`` (and the regression layer it stands on) that a second round
of hand-injected bugs found unguarded (issue 21: "tests that would catch a wrong answer"; the
round is summed up in bench/README.md, "Second hand-injected round"). Each is a property a correct
implementation must satisfy, checked against an independent computation (numpy or scipy by hand, an
identity, the term's own acceleration), not against the text of one line; every tolerance's origin
is written beside it.

Sizes and significance:

* a candidate's size, and an unexplained residual's, beside guide friction is the RMS change of
  the held-out prediction over the samples that count (:func:`~maglev_oc.diagnosis.selection.evidence`),
  recomputed from the two fits' columns; the cross-fitted training parts count the same samples;
* the held-out z and gain of an effect on both axes do not depend on either axis's units;
* a strong effect is judged on the strong path (its Wald statistic coef' C^-1 coef computed) when
  the ordinary z threshold is out of reach.

Verdicts and separability:

* a candidate whose joint fit removes less of the logged currents' errors than the current fit is
  not significant; a variance inflation beyond ``max_vif`` is not separable without named partners;
  a rival must beat the candidate by more than ``rival_margin``;
* the variance inflation is 1 / sin^2 of the smallest principal angle between the candidate's
  columns and the others' (scipy's ``subspace_angles``), errors-in-variables part removed; a
  correlation beyond ``max_correlation`` of either sign names the partner;
* a rival of k coefficients is a constant and Legendre orders 1..k-1 of one variable on the
  candidate's axis (columns picked by name); the bootstrap draws from every training block.

Physical sizes:

* thrust ripple and the share held by sticking horizontal guides are relative to the fitted
  constants, not the references (the term's own acceleration over the fitted model's);
* the cogging peak at 15 mm is the term's force at a 15 mm gap; the model-form spread is half the
  range over the variants (refitted here), added in quadrature with the 1 % calibration;
* a cable spring is bounded by its force at the far end of the travel; a periodogram peak 2 % off a
  motor period is that period within the tolerance asked for, and not within a smaller one.

The selection's outcome and the reported effects (six bugs of that round the suite let through):

* no effect of the final selection fails its judgement given the others, with two effects chosen
  as with more (the backward step);
* an effect's reported contribution and RMS force are over the held-out samples (recomputed from
  its columns; the planted cogging's own RMS there);
* an effect in the currents' rates is reported from the narrower band, half the two bands'
  difference added to its standard error (both bands refitted here);
* a diagnosis fails only when the logged currents carry errors that the base fit could not remove;
* end effects are refused only when the thrust and the attraction together grow towards the ends
  (the thrust's change checked on the term's own acceleration).

Regression layer:

* the plain covariance is s^2 (X'X)^-1 with s^2 = RSS / (rows - parameters) (numpy's lstsq);
* an overlarge errors-in-variables part is removed up to the largest share that keeps the normal
  equations positive definite (scipy's generalized eigenvalues);
* the periodogram of a long series (the FFT path) is its definition, zero frequency left out;
* the long-run covariance is the sandwich H^-1 S H^-1 of the per-sample scores with the
  errors-in-variables correction (recomputed with numpy's FFT on the twin's noisy currents).
"""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.linalg import eigh, subspace_angles

import maglev_oc.diagnosis.pipeline as pipeline_module
import maglev_oc.diagnosis.selection as selection_module
from maglev_oc.diagnosis.candidate import MAX_FORCE_SHARE, LibraryContext
from maglev_oc.diagnosis.currents import ripple_candidate
from maglev_oc.diagnosis.guides import cable_candidate, friction_candidates
from maglev_oc.diagnosis.library import candidate_library
from maglev_oc.diagnosis.magnetics import cogging_candidates, end_effects_candidate
from maglev_oc.diagnosis.pipeline import RATE_TERM_BAND
from maglev_oc.diagnosis.probes import smooth_probes
from maglev_oc.diagnosis.refit import CALIBRATION, with_model_form_spread
from maglev_oc.diagnosis.selection import (
    SelectionSettings,
    _CrossFit,
    _HeldOutGrams,
    _rival_gains,
    _separability,
    _verdict,
    evidence,
    fitted_constants,
    holdout_significance,
    judge,
)
from maglev_oc.diagnosis.trace import Trace, motor_periods, unexplained_periods
from maglev_oc.diagnosis.unexplained import find_unexplained
from maglev_oc.regression.covariance import DIRECT_DFT_SIZE, periodogram_long_run
from maglev_oc.regression.data import prepare
from maglev_oc.regression.design import build_design
from maglev_oc.regression.solve import fit_subset, residuals
from tests import test_diagnosis_seed36_properties as seed36
from tests.test_diagnosis_injected_properties import _judgement
from tests.test_diagnosis_selection_properties import cogged_design
from tests.test_regression_covariance import _direct_periodogram, _series
from tests.test_statistics_properties import _rows


@pytest.fixture(scope="module")
def cogged(model):
    """(design, library by name): the horizontal sweep with a cogging force planted at the slot pitch
    (0.02 m/s^2), the cogging and horizontal friction candidates' columns beside C1, a quarter held
    out (:func:`tests.test_diagnosis_selection_properties.cogged_design`)."""
    return cogged_design(model)


@pytest.fixture(scope="module")
def two_effects(model):
    """(design, library by name): the sweep with guide friction and a slot-pitch cogging planted
    (``tests/test_diagnosis_seed36_properties.two_effects_design``), both candidates' columns beside C1."""
    return seed36.two_effects_design(model)


def _held_out_prediction(design, fit):
    """(2, n_hold) a fit's prediction on the held-out samples, from its coefficients and columns."""
    return np.einsum("p,pan->an", fit.coef, design.columns[fit.index][:, :, design.holdout])


# --- sizes -------------------------------------------------------------------------------------------
def test_a_candidates_size_beside_friction_is_the_rms_change_over_the_samples_that_count(cogged):
    # friction chosen on the horizontal axis: its samples slower than slow_speed (here the 40th
    # percentile of the held-out speeds, so that 40 % are left out) do not count; the size is the
    # RMS over the counted samples of how much adding the candidate moves the prediction. Exact
    # arithmetic on the same numbers: rtol 1e-9
    design, lib = cogged
    speed = np.abs(design.prepared.x[3, design.holdout])
    settings = SelectionSettings(slow_speed=float(np.percentile(speed, 40)))
    counted = evidence(design, [lib["guide_friction_horizontal"]], settings)
    assert 0.3 < 1.0 - counted[1].mean() < 0.5
    current = ["base", "guide_friction_horizontal"]
    cur = fit_subset(design, current)
    r0 = np.where(counted, design.target[:, design.holdout] - _held_out_prediction(design, cur), 0.0)
    mse0 = np.maximum(np.mean(r0**2, axis=1), 1e-30)
    j = judge(design, lib["cogging_horizontal_19mm"], current, cur, r0, mse0, settings, counted=counted)
    new = fit_subset(design, [*current, "cogging_horizontal_19mm"], covariance=False)
    change = _held_out_prediction(design, new) - _held_out_prediction(design, cur)
    expected = math.sqrt(np.mean(change[1][counted[1]] ** 2))
    assert j.contribution_rms[1] == pytest.approx(expected, rel=1e-9)


def test_an_unexplained_residuals_size_beside_friction_is_the_rms_change_over_the_samples_that_count(
    model, two_effects
):
    # the sweep with friction and a slot-pitch cogging planted, friction explained: the cogging is
    # left for the probes (a sine at the slot pitch among them). Its size is the RMS change of the
    # held-out prediction over the samples that count beside friction (slow_speed the 40th
    # percentile of the held-out speeds), recomputed from the two fits' columns: rel 1e-9
    design, lib = two_effects
    speed = np.abs(design.prepared.x[3, design.holdout])
    settings = SelectionSettings(slow_speed=float(np.percentile(speed, 40)))
    friction = lib["guide_friction_horizontal"]
    period = model.params.slot_pitch
    found = find_unexplained(
        design.prepared,
        model,
        [friction],
        design.fit,
        design.holdout,
        design.weights,
        [("horizontal", period)],
        settings,
        max_per_axis=1,
    )
    assert [u.period for u in found] == [period]
    probe = found[0].term
    d = build_design(
        design.prepared,
        model,
        terms=[friction.term, probe],
        fit=design.fit,
        holdout=design.holdout,
        weights=design.weights,
    )
    counted = evidence(d, [friction], settings)
    before = fit_subset(d, ["base", friction.name], covariance=False)
    after = fit_subset(d, ["base", friction.name, probe.name], covariance=False)
    change = _held_out_prediction(d, after) - _held_out_prediction(d, before)
    assert found[0].size == pytest.approx(math.sqrt(np.mean(change[1][counted[1]] ** 2)), rel=1e-9)


# --- separability ------------------------------------------------------------------------------------
def _fake_fit(x, own, noise=None, blocks=3):
    """A design-like object over the columns ``x`` (n, P) split into ``blocks`` blocks of rows, the
    candidate "cand" owning the columns ``own`` and every other column a base parameter; ``noise``
    (P, P) added to the Gram (the errors-in-variables part the fit removes), spread over the blocks."""
    n, p = x.shape
    cuts = np.array_split(np.arange(n), blocks)
    noise = np.zeros((p, p)) if noise is None else noise
    design = SimpleNamespace(
        gram=np.stack([x[c].T @ x[c] + noise / blocks for c in cuts]),
        noise=np.stack([noise / blocks for _ in cuts]),
        groups={"base": np.array([k for k in range(p) if k not in own]), "cand": np.array(own)},
        names=tuple(f"p{k}" for k in range(p)),
    )
    cand = SimpleNamespace(
        name="cand", nuisance=(), term=SimpleNamespace(parameter_names=tuple(f"q{k}" for k in own))
    )
    fit = SimpleNamespace(index=np.arange(p), compensation=1.0)
    return design, cand, fit


@pytest.mark.parametrize("own", [(2,), (1, 3)])
def test_the_variance_inflation_is_that_of_the_smallest_principal_angle(own):
    # the largest canonical correlation between two spans is the cosine of their smallest principal
    # angle (scipy, from an SVD of orthonormal bases): VIF = 1 / sin^2. The candidate's columns are
    # built partly from the others (a correlation of about 0.9), and the Gram the code sees carries
    # an errors-in-variables part that the fit removes (compensation 1). Two routes of double
    # precision arithmetic on a 4 x 4 problem: rtol 1e-8
    rng = np.random.default_rng(11)
    x = rng.normal(size=(400, 4))
    others = [k for k in range(4) if k not in own]
    for k in own:
        x[:, k] = 0.5 * x[:, k] + x[:, others] @ rng.normal(size=len(others))
    noise_root = rng.normal(size=(4, 4))
    design, cand, fit = _fake_fit(x, list(own), noise=noise_root @ noise_root.T * 50.0)
    vif, partners = _separability(design, cand, fit, SelectionSettings())
    angle = float(np.min(subspace_angles(x[:, list(own)], x[:, others])))
    assert vif == pytest.approx(1.0 / math.sin(angle) ** 2, rel=1e-8)
    assert vif > 2.0  # a real inflation, not the trivial 1
    assert partners == ()


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_an_estimate_correlated_with_another_of_either_sign_names_it(sign):
    # the candidate's column is another's (times +-1) plus 0.5 % noise: their estimates are
    # correlated by about -+0.99997 (computed here from the inverse of the Gram), beyond the
    # default 0.99 whichever the sign, and the other parameter is named as the partner
    rng = np.random.default_rng(12)
    x = rng.normal(size=(400, 3))
    x[:, 2] = sign * x[:, 0] + 0.005 * rng.normal(size=400)
    design, cand, fit = _fake_fit(x, [2])
    inv = np.linalg.inv(x.T @ x)
    corr = inv[0, 2] / math.sqrt(inv[0, 0] * inv[2, 2])
    assert abs(corr) > 0.999 and np.sign(corr) == -sign
    _, partners = _separability(design, cand, fit, SelectionSettings())
    assert partners == ("p0",)


# --- verdicts from measured evidence -----------------------------------------------------------------
def _verdict_with(j, *, current_compensation=1.0, rivals=None, axis="horizontal"):
    """(verdict, reason) of a measured judgement ``j`` of a plausible candidate on one axis."""
    cand = SimpleNamespace(
        axis=axis, plausible=lambda physical: None, nuisance=(), term=SimpleNamespace(parameter_names=("q",))
    )
    axes = np.array([1]) if axis == "horizontal" else np.array([0, 1])
    current = SimpleNamespace(compensation=current_compensation)
    return _verdict(j, cand, axes, current, SelectionSettings(), rivals)


def test_a_candidate_whose_fit_removes_less_of_the_current_errors_is_not_judged_significant():
    # evidence that passes every other test: z and Wald far beyond their thresholds, 10 % gain, a
    # size of 0.01 m/s^2 (4x min_effect). Its joint fit could remove only half the logged currents'
    # errors where the current fit removed all: what it explains is their bias, not an effect
    j = _judgement(z=10.0, wald=1e3)
    assert _verdict_with(j)[0] == "passes"
    half = dataclasses.replace(j, fit=SimpleNamespace(compensation=0.5))
    verdict, reason = _verdict_with(half)
    assert verdict == "not significant" and "logged currents" in reason
    # the other way round (the current fit is the one with less removed) is no reason to refuse
    assert _verdict_with(j, current_compensation=0.5)[0] == "passes"


def test_a_candidate_with_a_large_variance_inflation_is_not_separable_without_named_partners():
    # max_vif = 100: an inflation of 1e3 is refused even when no single correlation exceeds 0.99
    # (a group of columns confounded with a combination of several base parameters)
    j = _judgement(z=10.0, wald=1e3)
    verdict, reason = _verdict_with(dataclasses.replace(j, vif=1e3, confounded_with=()))
    assert verdict == "not separable" and "1e+03" in reason
    assert _verdict_with(dataclasses.replace(j, vif=50.0, confounded_with=()))[0] == "passes"


@pytest.mark.parametrize(
    ("rival_gain", "verdict"), [(0.12, "passes"), (0.14, "passes"), (0.16, "not specific")]
)
def test_a_generic_rival_must_beat_the_candidate_by_more_than_the_margin(rival_gain, verdict):
    # the candidate lowers its axis's held-out error by 10 %; rival_margin = 0.05: a smooth function
    # of a state variable with as many coefficients that explains up to 15 % does not make it
    # unspecific, one that explains 16 % does
    j = _judgement(z=10.0, wald=1e3, gain_axes=(np.nan, 0.10))
    assert _verdict_with(j, rivals={("horizontal", 1): (rival_gain, "gap")})[0] == verdict


def test_a_strong_effect_is_judged_on_the_strong_path_when_the_ordinary_z_is_out_of_reach(cogged):
    # min_z = 1e6 is out of reach; the planted cogging has z about 17 and a Wald statistic 1e6 times
    # its threshold, so the strong path (z >= min_z_strong = 2 and Wald >= 10 x threshold) must
    # judge it: its Wald statistic is coef' C^-1 coef with the long-run covariance of the joint fit
    # (recomputed here; the same numbers, rtol 1e-9) and it passes
    design, lib = cogged
    base = fit_subset(design, ["base"])
    r0 = residuals(design, base)[:, design.holdout]
    mse0 = np.maximum(np.mean(r0**2, axis=1), 1e-30)
    settings = SelectionSettings(min_z=1e6)
    name = "cogging_horizontal_19mm"
    j = judge(design, lib[name], ["base"], base, r0, mse0, settings)
    coef, cov = fit_subset(design, ["base", name]).group(design, name)
    assert j.wald == pytest.approx(float(coef @ np.linalg.solve(cov, coef)), rel=1e-9)
    assert settings.min_z_strong <= j.z < settings.min_z
    assert j.verdict == "passes"


# --- which training samples count ----------------------------------------------------------------------
def test_the_cross_fitted_parts_count_the_samples_of_the_friction_axis_at_least_slow_speed_fast(cogged):
    # as on the held-out quarter (:func:`evidence`): beside horizontal friction, a part's samples
    # count on the horizontal axis where |x4| >= slow_speed (the 40th percentile of the training
    # speeds: 40 % left out), on the vertical axis all of them; with no friction chosen, all
    design, lib = cogged
    speed = np.abs(design.prepared.x[3])
    settings = SelectionSettings(slow_speed=float(np.percentile(speed[design.fit], 40)))
    fold = _CrossFit(design, 3)
    assert fold.counted([], settings) == [None] * len(fold.samples)
    counted = fold.counted([lib["guide_friction_horizontal"]], settings)
    assert len(counted) == len(fold.samples) == 3
    for samples, c in zip(fold.samples, counted, strict=True):
        np.testing.assert_array_equal(c[1], speed[samples] >= settings.slow_speed)
        assert np.all(c[0])
        assert 0.2 < 1.0 - c[1].mean() < 0.6


# --- the regression layer's solve and covariance -------------------------------------------------------
def test_the_plain_covariance_is_the_residual_variance_times_the_inverse_normal_matrix(cogged):
    # ordinary least squares on the weighted rows the fit sees (numpy's lstsq): s^2 (X'X)^-1 with
    # s^2 the residual sum of squares over rows minus parameters. Two solvers on the same rows:
    # rtol 1e-7 (the normal equations square the columns' condition number, about 1e3 here)
    design, _ = cogged
    fit = fit_subset(design, ["base", "cogging_horizontal_19mm"], compensate=False)
    x, y = _rows(design, fit.index, design.fit)
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    s2 = float(np.sum((y - x @ coef) ** 2)) / (x.shape[0] - x.shape[1])
    np.testing.assert_allclose(fit.coef, coef, rtol=1e-7)
    assert fit.chi_square == pytest.approx(s2 * (x.shape[0] - x.shape[1]), rel=1e-7)
    np.testing.assert_allclose(fit.naive, s2 * np.linalg.inv(x.T @ x), rtol=1e-7)


@pytest.mark.parametrize("excess", [1.5, 4.0])
def test_an_overlarge_errors_in_variables_part_is_removed_up_to_the_largest_share_that_keeps_a_solution(
    cogged, excess
):
    # an errors-in-variables estimate N larger than the signal (here N = excess / 4 x M D M', D the
    # diagonal of X'X and M a random mixing near the identity) leaves X'X - N indefinite; the fit
    # removes the largest share s of N for which X'X - s N is still positive definite: s* = 1 /
    # lambda_max of the pencil (N, X'X) (scipy's generalized symmetric eigensolver). The bisection's
    # 30 halvings reach s* to 1e-9 from below: rel 1e-6
    design, _ = cogged
    idx = design.indices(["base", "cogging_horizontal_19mm"])
    rng = np.random.default_rng(5)
    mix = np.eye(design.n_parameters) + 0.3 * rng.normal(size=(design.n_parameters,) * 2)
    noise = np.stack([excess * mix @ np.diag(np.diag(g)) @ mix.T / 4 for g in design.gram])
    noisy = dataclasses.replace(design, noise=noise)
    fit = fit_subset(noisy, ["base", "cogging_horizontal_19mm"])
    g, n = (a[:, idx][:, :, idx].sum(axis=0) for a in (design.gram, noise))
    critical = 1.0 / float(eigh(n, g, eigvals_only=True)[-1])
    assert 0.0 < critical < 1.0  # the whole N cannot be removed
    assert fit.compensation == pytest.approx(critical, rel=1e-6)
    assert fit.compensation <= critical and "could be removed" in fit.message


def test_the_long_run_covariance_of_a_long_series_is_its_definition():
    # a series long enough (n m beyond DIRECT_DFT_SIZE) that the periodogram takes the FFT path: the
    # mean over j = 1..m of Re(D_j D_j^*), the zero frequency left out (at the least-squares solution
    # the influence sums to zero, and any mean must not count), against the explicit sum; FFT
    # round-off over 70 000 samples: rtol 1e-9
    n, m = 70_000, 17
    assert n * m > DIRECT_DFT_SIZE
    d = _series(n, seed=3) + np.array([[0.3], [-0.2]])  # a mean the zero frequency would pick up
    np.testing.assert_allclose(periodogram_long_run(d, m), _direct_periodogram(d, m), rtol=1e-9)


# --- significance --------------------------------------------------------------------------------------
def test_the_held_out_significance_of_an_effect_on_both_axes_does_not_depend_on_their_units(cogged):
    # each axis's squared residuals are scaled by that axis's mean square before the blocks' sums
    # are taken, so neither axis rules the test by its units: z and the gain are the same when one
    # axis's residuals (before and after) are multiplied by 1e3. Random residuals whose drop differs
    # between the axes and along the log (otherwise any weighting gives one answer); the same
    # arithmetic up to the factor: rel 1e-9
    design, _ = cogged
    rng = np.random.default_rng(21)
    n = int(design.holdout.sum())
    r0 = rng.normal(size=(2, n)) * np.array([[1.0], [3.0]])
    shrink = np.vstack([np.linspace(0.3, 1.0, n), np.linspace(1.0, 0.8, n)])
    r1 = r0 * shrink
    both = np.array([0, 1])
    gain, z = holdout_significance(design, r0, r1, both)
    scale = np.array([[1e3], [1.0]])
    gain_s, z_s = holdout_significance(design, r0 * scale, r1 * scale, both)
    assert abs(z) > 1.0
    assert z_s == pytest.approx(z, rel=1e-9) and gain_s == pytest.approx(gain, rel=1e-9)


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


# --- the residual's periods ----------------------------------------------------------------------------
@pytest.mark.parametrize(("tolerance", "kept"), [(0.015, True), (0.03, False)])
def test_a_peak_near_a_motor_period_is_a_motor_period_within_the_tolerance_asked_for(model, tolerance, kept):
    # a peak 2 % off the slot pitch: beyond a 1.5 % tolerance it is a period no motor period
    # explains (a waviness candidate), within 3 % it is the slot pitch
    t1 = model.params.slot_pitch
    tr = Trace(
        np.array([t1]),
        np.zeros((2, 1)),
        motor_periods(model.params),
        [("horizontal", 1.02 * t1, 0.2)],
        {},
        np.zeros(1),
        np.zeros((2, 1)),
    )
    assert (unexplained_periods(tr, tolerance=tolerance) == [("horizontal", 1.02 * t1)]) is kept


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


def test_the_model_form_spread_is_half_the_range_over_the_variants_added_in_quadrature(model, two_effects):
    # guide friction's variants reverse over half and twice its 2 mm/s (the planted friction
    # reverses over 5 mm/s, so they differ): each refitted here beside the cogging (a design of the
    # variant's term), the Coulomb force's standard error is then sqrt(se^2 + (half the range of
    # the three values)^2 + (1 % of the value)^2). The same fits: rel 1e-9
    design, lib = two_effects
    cand, other = lib["guide_friction_horizontal"], lib["cogging_horizontal_19mm"]
    data, fit_mask, hold = design.prepared, design.fit, design.holdout
    values = []
    for fn in (cand.term.function, *cand.term.variants):
        terms = [cand.term.with_function(fn), other.term]
        d = build_design(data, model, terms=terms, fit=fit_mask, holdout=hold, weights=design.weights)
        coef, cov = fit_subset(d, list(d.groups)).group(d, cand.name)
        physical = cand.term.physical_parameters(coef, cov, {})
        values.append(physical["coulomb"].value)
        if fn is cand.term.function:
            params = physical
    out = with_model_form_spread(params, data, model, [cand, other], cand, fit_mask, hold, design.weights)
    spread = 0.5 * (max(values) - min(values))
    c = params["coulomb"]
    assert spread > c.stderr  # the variants do differ
    expected = math.sqrt(c.stderr**2 + spread**2 + (CALIBRATION * c.value) ** 2)
    assert out["coulomb"].stderr == pytest.approx(expected, rel=1e-9)


# --- rivals and the bootstrap --------------------------------------------------------------------------
@pytest.fixture(scope="module")
def with_probes(model, cogged):
    """(design, probes by (axis, variable) -> group name): the cogged sweep's design with the
    generic smooth probes beside the candidates."""
    design = cogged[0]
    probes = smooth_probes(design.prepared)
    terms = [*design.terms, *probes.values()]
    d = build_design(
        design.prepared, model, estimate=("C1",), terms=terms, fit=design.fit, holdout=design.holdout
    )
    return d, {k: t.name for k, t in probes.items()}


@pytest.mark.parametrize("k", [1, 2, 3])
def test_a_rival_is_a_constant_and_the_lowest_legendre_orders_of_one_variable_on_the_candidates_axis(
    with_probes, k
):
    # a horizontal candidate with k coefficients is rivalled by a smooth function of one state
    # variable with as many: a constant (P0) and the Legendre orders 1..k-1 (P1..) of that variable,
    # on the horizontal axis. Its held-out gain is recomputed here with the columns picked by name,
    # the best over the variables; the same fits by two routes: rel 1e-7
    design, probes = with_probes
    base = fit_subset(design, ["base"], covariance=False)
    r0 = design.held_out_target - np.einsum("p,pan->an", base.coef, design.held_out_columns[base.index])
    mse0 = np.mean(r0**2, axis=1)
    around = _HeldOutGrams(design).around(base)
    got = _rival_gains(design, ["base"], mse0, probes, {("horizontal", k)}, around)[("horizontal", k)]
    best, gains = (-np.inf, ""), []
    for (axis, var), group in probes.items():
        if axis != "horizontal":
            continue
        names = [f"{group}.P{i}" for i in range(k)]
        cols = [design.names.index(nm) for nm in names]
        f = fit_subset(design, ["base"], covariance=False, extra=cols)
        r1 = design.held_out_target - np.einsum("p,pan->an", f.coef, design.held_out_columns[f.index])
        gain = 1.0 - np.mean(r1[1] ** 2) / mse0[1]
        best = max(best, (gain, var))
        gains.append(gain)
    assert np.ptp(gains) > 1e-4 or k == 1  # the variables' rivals differ (with k = 1 all are a constant)
    assert got[0] == pytest.approx(best[0], rel=1e-7)


def test_the_bootstrap_resamples_draw_from_every_training_block(two_effects, monkeypatch):
    # each resample draws as many blocks as there are, with replacement, from all of them: over 30
    # resamples of 45 blocks a block is missed with probability (44/45)^1350 = 1e-13
    design, lib = two_effects
    drawn = []
    real = selection_module.fit_subset

    def spy(d, groups, **kw):
        if kw.get("blocks") is not None:
            drawn.append(np.asarray(kw["blocks"]))
        return real(d, groups, **kw)

    monkeypatch.setattr(selection_module, "fit_subset", spy)
    cands = [lib["guide_friction_horizontal"], lib["cogging_horizontal_19mm"]]
    selection_module.select(design, cands, SelectionSettings(bootstrap=30))
    n_blocks = design.gram.shape[0]
    assert drawn and all(b.size == n_blocks for b in drawn)
    assert set(np.concatenate(drawn).tolist()) == set(range(n_blocks))


def test_the_long_run_covariance_is_the_sandwich_of_the_compensated_scores(model, twin_log):
    # the twin's log (its logged currents carry amplifier noise, so the fit removes an
    # errors-in-variables part N): per sample the score sum_a w_a^2 x_a r_a plus the block's N_b theta
    # spread evenly over its m_b samples; per log the mean over j = 1..m of Re(D_j D_j^*) of their
    # DFT (numpy's FFT, m = max(4, floor(0.25 Hz x duration))); the covariance H^-1 S H^-1 with
    # H = sum_b (X_b'X_b - N_b). An FFT against the code's tabulated DFT: rtol 1e-7
    data = prepare([twin_log], bandwidth=10.0)
    fit_mask, hold = data.masks(0.25)
    design = build_design(data, model, fit=fit_mask, holdout=hold)
    fit = fit_subset(design, ["base"])
    assert fit.compensation == 1.0 and np.any(design.noise != 0)
    idx = fit.index
    x = design.columns[idx][:, :, design.fit]
    r = design.target[:, design.fit] - np.einsum("p,pan->an", fit.coef, x)
    scores = np.einsum("pan,an->pn", x, r * design.weights[:, None] ** 2)
    blocks = design.block_of[design.fit]
    noise = design.noise[:, idx][:, :, idx]
    for b in range(design.gram.shape[0]):
        scores[:, blocks == b] += (noise[b] @ fit.coef / np.sum(blocks == b))[:, None]
    n = scores.shape[1]
    m = max(4, math.floor(0.25 * n * data.sample_time))
    f = np.fft.fft(scores, axis=1)[:, 1 : m + 1]
    meat = (f @ f.conj().T).real / m
    h = design.gram[:, idx][:, :, idx].sum(axis=0) - noise.sum(axis=0)
    hinv = np.linalg.inv(h)
    np.testing.assert_allclose(fit.covariance, hinv @ meat @ hinv, rtol=1e-7, atol=0)


# --- the selection's outcome and the reported effects ------------------------------------------------
def test_an_effect_a_later_choice_explains_is_dropped_even_when_two_were_chosen(two_effects, monkeypatch):
    # select()'s contract: no effect of the final selection fails its judgement given the others
    # (an effect chosen early may be explained by later ones). Both planted effects pass at their
    # steps (friction first: 52 % against 28 % of the held-out mean square); here the judgement of
    # friction beside the cogging is made to find it explained (as a constant force is by a
    # commutation offset that also makes one). With exactly two effects chosen the friction must
    # go, the final fit being that of the cogging alone (recomputed: the same fit, rel 1e-12)
    design, lib = two_effects
    friction, cogging = lib["guide_friction_horizontal"], lib["cogging_horizontal_19mm"]
    real = selection_module.judge

    def explained_later(d, cand, current, *args, **kw):
        j = real(d, cand, current, *args, **kw)
        if cand.name == friction.name and cogging.name in current:
            return dataclasses.replace(j, verdict="not significant", reason="explained by the cogging")
        return j

    monkeypatch.setattr(selection_module, "judge", explained_later)
    sel = selection_module.select(design, [friction, cogging], SelectionSettings(bootstrap=5))
    assert sel.selected == [cogging.name]
    assert sel.last[friction.name].reason.startswith("dropped after the later choices")
    alone = fit_subset(design, ["base", cogging.name])
    np.testing.assert_array_equal(sel.final.index, alone.index)
    np.testing.assert_allclose(sel.final.coef, alone.coef, rtol=1e-12)


def test_a_reported_effects_contribution_is_its_rms_acceleration_over_the_held_out_samples(
    model, two_effects
):
    # what a user reads as an effect's contribution (and, times the mass, its RMS force) is the RMS
    # of its own columns times its coefficients in the final fit over the held-out quarter, not
    # over the training data (on this sweep the cogging's RMS differs by 4 % between the two).
    # Recomputed from the design's columns: rel 1e-9. Independently, the planted cogging (0.02 m/s^2
    # at the slot pitch, evaluated at the held-out positions) has the same RMS to 2 % (0.5 % measured:
    # the fit's error; the training samples' RMS is 3.6 % off it)
    design, lib = two_effects
    cands = [lib["guide_friction_horizontal"], lib["cogging_horizontal_19mm"]]
    sel = selection_module.select(design, cands, SelectionSettings(bootstrap=5))
    assert sel.selected == [c.name for c in cands]
    session = SimpleNamespace(
        data=design.prepared,
        model=model,
        train=design.fit,
        hold=design.holdout,
        weights=design.weights,
        settings=SelectionSettings(),
    )
    effects = {e.name: e for e in pipeline_module._effects(session, model, cands, design, sel)}
    coef = np.zeros(design.n_parameters)
    coef[sel.final.index] = sel.final.coef
    mass = model.params.mass_horizontal
    for cand in cands:
        cols = design.groups[cand.name]
        accel = np.einsum("p,pan->an", coef[cols], design.columns[cols])
        held, train = (math.sqrt(np.mean(accel[1, m] ** 2)) for m in (design.holdout, design.fit))
        effect = effects[cand.reported_name]
        assert effect.contribution_rms[1] == pytest.approx(held, rel=1e-9)
        assert effect.force_rms[1] == pytest.approx(held * mass, rel=1e-9)
        if cand is cands[1]:
            assert abs(train / held - 1.0) > 0.02  # the two sets of samples do differ
            x3 = design.prepared.x[2, design.holdout]
            planted = 0.02 * np.sin(2 * math.pi * x3 / model.params.slot_pitch + 0.5)
            assert held == pytest.approx(math.sqrt(np.mean(planted**2)), rel=0.02)


def test_a_lag_is_reported_from_the_narrower_band_with_half_the_bands_difference_in_its_error(
    model, twin_log
):
    # an effect in the currents' rates is sized on RATE_TERM_BAND x the fit's band: the value
    # reported is the narrower band's (refitted here from the log: prepared at 5 Hz, the same
    # holdout and weights), its standard error the wider band's with half the difference of the
    # two values added in quadrature. The same fits: rel 1e-9
    data = prepare([twin_log], bandwidth=10.0)
    train, hold = data.masks(0.25)
    lag = next(c for c in candidate_library(model, data) if c.name == "current_amplifier_lag")
    d = build_design(data, model, terms=[lag.term], fit=train, holdout=hold)
    fit = fit_subset(d, list(d.groups))
    wide = lag.term.physical_parameters(*fit.group(d, lag.name), fitted_constants(fit))
    session = SimpleNamespace(data=data, logs=(twin_log,), holdout_fraction=0.25, weights=d.weights)
    out = pipeline_module._on_a_narrower_band(wide, session, model, [lag], lag)
    narrow_data = prepare([twin_log], bandwidth=10.0 * RATE_TERM_BAND)
    n_train, n_hold = narrow_data.masks(0.25)
    nd = build_design(narrow_data, model, terms=[lag.term], fit=n_train, holdout=n_hold, weights=d.weights)
    nfit = fit_subset(nd, list(nd.groups))
    narrow = lag.term.physical_parameters(*nfit.group(nd, lag.name), fitted_constants(nfit))
    w, n = wide["time_constant"], narrow["time_constant"]
    spread = 0.5 * abs(w.value - n.value)
    assert spread > 0.2 * w.stderr  # 0.22 measured: the spread raises the error by 2 %, far beyond 1e-9
    assert out["time_constant"].value == pytest.approx(n.value, rel=1e-9)
    assert out["time_constant"].stderr == pytest.approx(math.hypot(w.stderr, spread), rel=1e-9)


def test_a_diagnosis_fails_only_where_the_logged_currents_errors_could_not_be_removed(
    model, twin_log, cogged
):
    # success means the constants are not biased low by the logged currents' errors: it fails only
    # when the currents carry errors (current_noise > 0) and the base fit could not remove them
    # whole. The twin's currents carry amplifier noise that its base fit removes (compensation 1):
    # a success. A fit that could remove only part (an errors-in-variables part 4x beyond the
    # signal, as above) fails on noisy currents; on currents without errors it has none to remove
    data = prepare([twin_log], bandwidth=10.0)
    train, hold = data.masks(0.25)
    whole = fit_subset(build_design(data, model, fit=train, holdout=hold), ["base"])
    assert whole.compensation == 1.0 and np.all(data.current_noise > 0)
    design, _ = cogged
    rng = np.random.default_rng(5)
    mix = np.eye(design.n_parameters) + 0.3 * rng.normal(size=(design.n_parameters,) * 2)
    noise = np.stack([mix @ np.diag(np.diag(g)) @ mix.T for g in design.gram])
    part = fit_subset(dataclasses.replace(design, noise=noise), ["base"])
    assert part.compensation < 1.0
    clean = SimpleNamespace(current_noise=np.zeros(2))

    def outcome(fit, d):
        return pipeline_module._outcome([], [], [], SimpleNamespace(base=fit), d)

    assert outcome(whole, data)[1] is True
    _, success, message = outcome(part, data)
    assert success is False and "compensation failed" in message
    assert outcome(part, clean)[1] is True
    assert outcome(whole, clean)[1] is True


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
