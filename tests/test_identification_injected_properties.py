"""Properties that catch wrong answers in ``maglev_oc.identification`` (and the shared regression
layer it stands on) which the other identification tests let through (issue 21: "tests that
would catch a wrong answer"). Each was found by injecting a small plausible bug (a wrong sign,
index, comparison, factor, a dropped validation or an ignored option) into the package, one at a
time, and running the quick identification and regression tests: these are the bugs nothing
caught, each turned into a property that holds for the right code whatever its implementation,
with the origin of every tolerance written beside it.

* An equation-error fit refuses a negative input delay (a current cannot act before it is
  logged), before any preparation.
* ``hac_band`` is used: the long-run covariance averages frequencies_for(n, T, band) Fourier
  frequencies of the fitted samples, for each band given.
* The residual RMS of a fit on a subset of samples is the RMS of its residuals on exactly the
  fitted samples (those the per-log residuals carry), not on every valid sample.
* z-scores are (estimate - truth) / the HAC standard error the result reports.
* NPFSI: the default Sigma(0) is 1 ms times the diagonal of the mean A'A (numpy); the settling time
  is the first time after which the estimate stays within the band of its FINAL value.
* The parabola experiment refuses a current that varies by more than 1 % of its mean.
* The parabola/NPFSI discrepancy is relative to the parabola's L1 (the papers' 3.8 % mean).
* Equilibrium currents: a percentage is given exactly where the MEASURED current is at least
  ``small_current``; ``max_pct`` includes both ends of its gap range.
* The cogging force from C2 is positive when C2 at the offset position exceeds the reference
  (more attraction), antisymmetric in the two.
* identify's validation with ``validation_logs`` is computed on those logs, and with the fitted
  gap offset (both recomputed by hand with the identified constants).
* ``check_identifiable`` refuses a log just shorter than ``min_duration`` and takes one just longer.
* The coverage study counts |z| = k as within k, and its z and z_naive are the errors over the HAC
  and the plain standard errors of the same fit.
* Regression layer: ``PreparedLogs.masks`` refuses a held-out share above one half; amplitude and
  phase reproduce the sine-cosine pair (phase error by the delta method, numerically); a constant
  force is F over its own axis's mass, vertically towards the stator; a log is reduced to at
  most ``max_rate`` by the fewest samples per mean; a control rate that is not positive is refused.
"""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.data.log import Log
from maglev_oc.data.logs import LogError
from maglev_oc.errors import InputError
from maglev_oc.identification.equation_error import EquationError
from maglev_oc.identification.experiments import TWIN_TRUTH, excitation_log
from maglev_oc.identification.layout import CONSTANT_NAMES
from maglev_oc.identification.npfsi import DEFAULT_Q0_SECONDS, NpfsiEstimator
from maglev_oc.identification.pipeline import VALIDATION_BANDWIDTH, check_identifiable, identify
from maglev_oc.identification.study import Coverage, _coverage
from maglev_oc.identification.study import _Clock as _StudyClock
from maglev_oc.identification.verification import (
    EquilibriumComparison,
    cogging_from_c2,
    compare_equilibrium_currents,
    compare_parabola_npfsi,
    fit_parabola,
)
from maglev_oc.model.equilibrium import equilibrium_currents
from maglev_oc.regression.base import GAP_OFFSET
from maglev_oc.regression.covariance import frequencies_for
from maglev_oc.regression.data import logging_error_share, prepare, reduce_rate
from maglev_oc.regression.terms import amplitude_phase, constant_force
from maglev_oc.validation import validate


# --- equation error ------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def problem(model, twin_log):
    return EquationError(twin_log, model)


@pytest.fixture(scope="module")
def fits(problem):
    """The full fit at two HAC bands, and a fit on the first two thirds of the log."""
    return {
        0.25: problem.fit(hac_band=0.25),
        2.0: problem.fit(hac_band=2.0),
        "part": problem.fit(samples=(0, 4000)),
    }


@pytest.mark.parametrize("delay", [-1e-3, -1e-9, 0.01, math.nan])
def test_an_input_delay_outside_zero_to_ten_ms_is_refused(model, twin_log, delay):
    with pytest.raises(InputError, match="input_delay"):
        EquationError(twin_log, model, input_delay=delay)


def test_the_hac_band_sets_the_frequencies_the_covariance_averages(problem, fits):
    # frequencies_for is the documented count (max(4, floor(band n T)), at most n/2 - 1); on the 6 s
    # log 0.25 Hz gives the minimum 4, 2 Hz about 10: more frequencies, other standard errors
    for band in (0.25, 2.0):
        fit = fits[band]
        assert fit.hac_frequencies == frequencies_for(fit.n_samples, problem.sample_time, band)
        assert fit.settings["hac_band_hz"] == band
    assert fits[2.0].hac_frequencies > fits[0.25].hac_frequencies
    assert fits[2.0].stderr["C2"] != fits[0.25].stderr["C2"]


def test_the_residual_rms_is_over_the_fitted_samples_only(fits):
    # the per-log residuals are NaN off the fitted samples: their RMS is the reported one to
    # round-off (1e-12: the same squares summed in another order)
    fit = fits["part"]
    assert fit.n_samples < 4000
    for k, axis in enumerate(("vertical", "horizontal")):
        r = np.concatenate([res[k] for res in fit.residuals])
        used = np.isfinite(r)
        assert used.sum() == fit.n_samples
        assert fit.residual_rms[axis] == pytest.approx(float(np.sqrt(np.mean(r[used] ** 2))), rel=1e-12)


def test_z_scores_use_the_reported_standard_errors(fits):
    fit = fits[0.25]
    truth = {k: getattr(TWIN_TRUTH, k) for k in fit.names}
    z = fit.z_scores(truth)
    assert set(z) == set(fit.names)
    # 1e-12: the same division, round-off only
    for k, v in z.items():
        assert v == pytest.approx((fit.values[k] - truth[k]) / fit.stderr[k], rel=1e-12)
    # HAC and naive errors differ here (variance inflation far from 1), so the test has teeth
    assert any(abs(fit.stderr[k] / fit.stderr_naive[k] - 1) > 0.1 for k in fit.names)


def test_masks_refuse_a_held_out_share_above_one_half(problem):
    with pytest.raises(InputError, match="holdout_fraction"):
        problem.prepared.masks(0.6)
    fit, hold = problem.prepared.masks(0.5)
    assert hold.sum() > 0 and fit.sum() > 0


# --- NPFSI ---------------------------------------------------------------------------------------------
def _npfsi_data(n=3000, h=1e-3, seed=0):
    """A (n, 1, 2) regressor of two sines, b = 0 and velocities integrating A theta exactly."""
    t = np.arange(n) * h
    rng = np.random.default_rng(seed)
    A = np.stack(
        [np.sin(2 * np.pi * 3.1 * t + rng.uniform()), 1.0 + 0.5 * np.cos(2 * np.pi * 1.7 * t)], axis=1
    )
    A = A[:, None, :]
    theta = np.array([2.0, -1.5])
    acc = A[:, 0, :] @ theta
    y = np.concatenate([[0.0], np.cumsum(acc[:-1]) * h])[:, None]
    return A, np.zeros((n, 1)), y, h, theta


def test_npfsi_default_sigma0_is_a_millisecond_of_the_mean_information():
    A, b, y, h, _ = _npfsi_data()
    res = NpfsiEstimator(0.01).run(A, b, y, h, [1.0, 1.0])
    info = np.einsum("nij,nik->jk", A, A) / A.shape[0]  # mean A'A, independently
    np.testing.assert_allclose(res.Q0, DEFAULT_Q0_SECONDS * np.diag(np.diag(info)), rtol=1e-12)
    assert DEFAULT_Q0_SECONDS == 1e-3


def test_npfsi_settling_time_is_relative_to_the_final_value():
    # started at a tenth of the truth: a band relative to the start would be ten times narrower
    A, b, y, h, theta = _npfsi_data()
    res = NpfsiEstimator(0.01).run(A, b, y, h, 0.1 * theta, names=("a", "b"))
    for k, name in enumerate(res.names):
        band = 0.01
        ts = res.settling_time(name, band)
        traj, final = res.trajectory[k], res.trajectory[k, -1]
        after = res.t >= ts
        assert np.all(np.abs(traj[after] - final) <= band * abs(final))
        i = int(np.flatnonzero(after)[0])
        assert i > 0 and abs(traj[i - 1] - final) > band * abs(final)  # it left the band just before


# --- verification --------------------------------------------------------------------------------------
def _parabola_log(u1, n=300):
    t = np.arange(n) * 1e-3
    x = np.full((4, n), np.nan)
    x[0], x[2] = 0.02, -0.05 - 0.5 * 7.3 * np.mean(u1) * t**2
    return Log(t, x, np.vstack([u1, np.zeros(n)]))


def test_the_parabola_needs_a_constant_current():
    # 000 eq. (5) holds for a constant u1; the documented tolerance is 1 % of its mean
    n = 300
    fit_parabola(_parabola_log(np.full(n, -0.5) + np.linspace(0, 0.004, n)), 0.02)  # 0.8 %: accepted
    with pytest.raises(InputError, match="constant"):
        fit_parabola(_parabola_log(np.full(n, -0.5) + np.linspace(0, 0.02, n)), 0.02)  # 4 %


def test_the_discrepancy_is_relative_to_the_parabola():
    par = [SimpleNamespace(gap=0.02, L1=10.0), SimpleNamespace(gap=0.025, L1=8.0)]
    runs = [SimpleNamespace(eps=0.01, values={"L1": 11.0}), SimpleNamespace(eps=0.01, values={"L1": 6.0})]
    cmp = compare_parabola_npfsi(par, runs)
    np.testing.assert_allclose(cmp.discrepancy_pct, [10.0, 25.0], rtol=1e-12)  # |11-10|/10, |6-8|/8


def test_a_percentage_is_given_exactly_where_the_measured_current_is_not_small(model):
    gaps = np.array([0.015, 0.018, 0.02])
    predicted = equilibrium_currents(model, gaps).current
    assert np.all(np.abs(predicted) > 0.3)  # the predictions are not small: only the measurement decides
    measured = np.array([0.1, -0.2, 0.5]) * np.sign(predicted)
    cmp = compare_equilibrium_currents(model, gaps, measured, small_current=0.3)
    assert np.isnan(cmp.error_pct[0]) and np.isnan(cmp.error_pct[1])
    assert cmp.error_pct[2] == pytest.approx(
        100 * abs(predicted[2] - measured[2]) / abs(measured[2]), rel=1e-12
    )


def test_max_pct_includes_both_ends_of_its_range():
    gap = np.array([0.015, 0.02, 0.025])
    pct = np.array([7.0, 1.0, 9.0])
    cmp = EquilibriumComparison(gap, np.ones(3), np.ones(3), np.zeros(3), pct, 0.3)
    assert cmp.max_pct(0.015, 0.025) == 9.0
    assert cmp.max_pct(0.015, 0.02) == 7.0
    assert cmp.max_pct(0.02, 0.025) == 9.0


def test_the_cogging_force_is_positive_when_the_offset_c2_is_larger(model):
    c2 = model.constants.C2
    gaps = np.array([0.015, 0.02, 0.025])
    up = cogging_from_c2(model, c2, 1.02 * c2, gaps)
    down = cogging_from_c2(model, c2, 0.98 * c2, gaps)
    assert np.all(up > 0)
    np.testing.assert_allclose(down, -up, rtol=1e-12)
    np.testing.assert_allclose(cogging_from_c2(model, c2, c2, gaps), 0.0, atol=0)


# --- identify and its checks ---------------------------------------------------------------------------
def test_identify_validates_on_the_validation_logs(model, twin_log):
    # recomputed by hand as validate(prepare(held-out logs), their valid samples, fitted constants);
    # 1e-9 relative: the same arithmetic on the same samples (round-off only)
    held = Log(
        twin_log.t[1000:] - twin_log.t[1000],
        twin_log.x[:, 1000:],
        twin_log.u[:, 1000:],
        source="held.csv",
    )
    out = identify(twin_log, model, methods=("equation_error",), validation_logs=[held])
    data = prepare([held], bandwidth=VALIDATION_BANDWIDTH)
    expected = validate(data, data.valid, model.with_constants(out.constants()), [])
    assert out.validation.inputs.shape == expected.inputs.shape
    np.testing.assert_allclose(out.validation.residuals, expected.residuals, rtol=1e-9, atol=1e-12)
    assert "held.csv" in out.validation.data
    # and it says what was validated: the identified constants, by the method that fitted them
    assert out.validation.model == f"identified constants ({out.best.method})"


def _moving_log(duration: float) -> Log:
    t = np.arange(0, duration, 1e-3)
    s = np.sin(2 * np.pi * 0.5 * t)
    x = np.full((4, t.size), np.nan)
    x[0], x[2] = 0.02 + 1e-3 * s, 0.03 * s
    return Log(t, x, np.vstack([0.5 * s, 1.5 + 0.5 * s]), source="run.csv")


def test_check_identifiable_refuses_a_log_just_shorter_than_min_duration():
    check_identifiable([_moving_log(5.5)], ("C1", "C2"), min_duration=5.0)
    with pytest.raises(LogError, match="too short"):
        check_identifiable([_moving_log(4.5)], ("C1", "C2"), min_duration=5.0)


def test_identify_validates_with_the_fitted_gap_offset(model, twin_log):
    # the gap readings 0.5 mm short of the true gap: a fitted offset of a few tenths of a mm, and the
    # validation simulates the model at the reading plus it (recomputed by hand, 1e-9 relative:
    # the same arithmetic); without the offset the residuals are different (the test has teeth)
    x = np.array(twin_log.x, dtype=float)
    x[0] -= 5e-4
    log = dataclasses.replace(twin_log, x=x, source="short.csv")
    out = identify(log, model, methods=("equation_error",), estimate=(*CONSTANT_NAMES, GAP_OFFSET))
    offset = out.equation_error.values[GAP_OFFSET]
    # correlated with C2..C4 on 6 s of data (0.38 mm found): only that it is far from zero matters here
    assert 1e-4 < offset < 1e-3
    data = prepare([log], bandwidth=VALIDATION_BANDWIDTH)
    fitted = model.with_constants(out.constants())
    expected = validate(data, data.valid, fitted, [], gap_offset=offset)
    np.testing.assert_allclose(out.validation.residuals, expected.residuals, rtol=1e-9, atol=1e-12)
    without = validate(data, data.valid, fitted, [], gap_offset=0.0)
    assert not np.allclose(without.residuals, expected.residuals, rtol=1e-6, atol=0)


# --- the coverage study ----------------------------------------------------------------------------------
def test_the_coverage_counts_a_z_on_the_bound_as_within():
    z = np.array([[2.0, 1.0], [3.0, -2.0], [-0.5, 2.5], [1.0, -1.0]])
    cov = Coverage(("C1", "C2"), (1, 2, 3, 4), 6.0, z, z, np.zeros_like(z), np.ones_like(z))
    np.testing.assert_allclose(cov.fraction_within(2.0), [0.75, 0.75])
    np.testing.assert_allclose(cov.fraction_within(1.0), [0.5, 0.5])


def test_the_coverage_runs_report_z_with_both_standard_errors(model, truth_model):
    # one 6 s run: the study's z and z_naive are the fit's errors over its HAC and its plain
    # standard errors (the fit redone here on the same seed-100 log: the same numbers to round-off)
    cov = _coverage(_StudyClock(), model, truth_model, 1, 6.0)
    log = excitation_log(truth_model, duration=6.0, seed=cov.seeds[0], controller_model=model)
    fit = EquationError(log, model).fit()
    truth = dict(zip(CONSTANT_NAMES, truth_model.constants.as_array(), strict=True))
    err = np.array([fit.values[k] - truth[k] for k in CONSTANT_NAMES])
    np.testing.assert_allclose(cov.z[0], err / [fit.stderr[k] for k in CONSTANT_NAMES], rtol=1e-9)
    np.testing.assert_allclose(cov.z_naive[0], err / [fit.stderr_naive[k] for k in CONSTANT_NAMES], rtol=1e-9)
    assert not np.allclose(cov.z[0], cov.z_naive[0], rtol=0.05)  # the two errors differ here


# --- the regression layer's terms and data -----------------------------------------------------------------
def test_amplitude_and_phase_reproduce_the_sine_and_cosine_pair():
    # a sin(x) + b cos(x) = A sin(x + phi): checked pointwise; the phase's standard error against
    # the delta method with a numerical gradient of atan2 (central differences, step 1e-6: the
    # truncation error is ~1e-12 relative, 1e-6 covers the round-off of the differences)
    a, b = 0.3, -0.7
    cov = np.array([[4e-4, 1e-4], [1e-4, 9e-4]])
    out = amplitude_phase("N", 2.0)(np.array([a, b]), cov, {})
    x = np.linspace(0, 2 * np.pi, 17)
    amp = out["amplitude"].value / 2.0
    np.testing.assert_allclose(
        amp * np.sin(x + out["phase"].value), a * np.sin(x) + b * np.cos(x), atol=1e-12
    )
    h = 1e-6
    g = np.array(
        [
            (math.atan2(b, a + h) - math.atan2(b, a - h)) / (2 * h),
            (math.atan2(b + h, a) - math.atan2(b - h, a)) / (2 * h),
        ]
    )
    assert out["phase"].stderr == pytest.approx(math.sqrt(g @ cov @ g), rel=1e-6)
    ga = np.array([a, b]) / math.hypot(a, b)
    assert out["amplitude"].stderr == pytest.approx(2.0 * math.sqrt(ga @ cov @ ga), rel=1e-12)


@pytest.mark.parametrize("axis", ["vertical", "horizontal"])
def test_a_constant_force_is_its_size_over_its_own_axis_mass_towards_the_stator(model, axis):
    # 1 N: vertically towards the stator (closes the gap, x2' = -F / M_v), horizontally along +x3
    p = model.params
    term = constant_force(p, axis)
    acc = np.asarray(term.function([0.02, 0, 0, 0], [0, 1.5], [0, 0], [1.0])).ravel()
    if axis == "vertical":
        np.testing.assert_allclose(acc, [-1.0 / p.mass_vertical, 0.0], rtol=1e-12)
    else:
        np.testing.assert_allclose(acc, [0.0, 1.0 / p.mass_horizontal], rtol=1e-12)
    assert p.mass_vertical != p.mass_horizontal


@pytest.mark.parametrize("rate", [800.0, 1000.0, 1500.0, 2500.0, 5000.0])
def test_a_log_is_reduced_to_at_most_max_rate_by_the_fewest_samples(rate):
    n = 2000
    t = np.arange(n) / rate
    x = np.vstack([np.full(n, 0.02), np.zeros(n), np.linspace(0, 0.01, n), np.zeros(n)])
    reduced, q = reduce_rate(Log(t, x, np.ones((2, n))), 1000.0)
    assert 1.0 / reduced.sample_time <= 1000.0 * (1 + 1e-9)
    assert q == 1 or rate / (q - 1) > 1000.0  # one sample fewer per mean would be too fast
    assert reduced.n == n // q


@pytest.mark.parametrize("meta", ["0", "-1000"])
def test_a_control_rate_that_is_not_positive_is_refused(meta):
    n = 200
    t = np.arange(n) / 1000.0
    x = np.vstack([np.full(n, 0.02), np.zeros(n), np.linspace(0, 0.01, n), np.zeros(n)])
    log = Log(t, x, np.ones((2, n)), metadata={"control_rate_hz": meta})
    with pytest.raises(LogError, match="control_rate_hz"):
        logging_error_share(log)
    with pytest.raises(LogError, match="control_rate_hz"):
        logging_error_share(Log(t, x, np.ones((2, n))), control_rate=float(meta))


def test_a_fit_on_chosen_samples_does_not_see_the_others(model, twin_log):
    """Samples outside those chosen do not enter the fit: currents corrupted (scaled by 1.5) from
    3.5 s on leave a fit of the first 3 s where it was, while a fit of every sample moves C1 by
    more than 1 % (about 50 of its standard errors). The filters reach only half a window (about
    30 ms) past an edge, so samples 0.5 s away never mix in; what does reach the part is the
    preparation's whole-log estimate of the logged currents' error (the errors-in-variables
    compensation), which moved each constant by 0.06-0.08 of its standard error: the bound is 0.15."""
    u = twin_log.u.copy()
    u[:, twin_log.t >= 3.5] *= 1.5
    corrupted = EquationError(dataclasses.replace(twin_log, u=u), model)
    clean = EquationError(twin_log, model)
    part = (0, int(np.searchsorted(twin_log.t, 3.0)))
    a, b = clean.fit(samples=part), corrupted.fit(samples=part)
    for name in a.names:
        assert abs(b.values[name] - a.values[name]) < 0.15 * a.stderr[name], name
    assert abs(corrupted.fit().values["C1"] / clean.fit().values["C1"] - 1) > 0.01
