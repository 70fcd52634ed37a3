"""Validation to the standard of system identification tools (maglev_oc.validation): the tests
say the right thing on series whose answer is known, and the fit % is the toolbox's number."""

from __future__ import annotations

import json

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.identification.experiments import TWIN_TRUTH, excitation_log
from maglev_oc.regression.data import prepare
from maglev_oc.validation import fit_percent, independence, validate, whiteness


# --- whiteness --------------------------------------------------------------------------------------------
def test_white_noise_passes_ljung_box_and_five_percent_of_lags_leave_the_band():
    """Over 200 seeds of 500 white samples and 20 lags: the Ljung-Box p-value is uniform under the
    null, so it falls below 0.05 in about 5 % of seeds and its median is about 0.5; the share of
    ACF lags outside the 95 % band is about 5 %. Tolerances: the binomial standard deviation of a
    5 % share over 200 seeds is 1.5 % (rejections) and over 4000 lag values 0.34 %; the 95 % band
    +-1.96/sqrt(n) is slightly wide at small lags (the ACF's variance is (n - k)/n^2), so allow
    3 to 7 %."""
    rejections, outside, medians = 0, 0, []
    for seed in range(200):
        e = np.random.default_rng(seed).standard_normal(500)
        w = whiteness(e, 20)
        rejections += not w.white
        outside += w.outside
        medians.append(w.p_value)
    assert 0.01 <= rejections / 200 <= 0.10
    assert 0.03 <= outside / (200 * 20) <= 0.07
    assert 0.35 <= np.median(medians) <= 0.65


def test_ar1_residual_is_not_white():
    """e_t = 0.5 e_{t-1} + w_t: the lag-1 autocorrelation is 0.5, far outside +-1.96/sqrt(500) =
    +-0.088 (5.7 standard errors); Ljung-Box rejects at any level we would use, on every seed."""
    for seed in range(10):
        w = np.random.default_rng(seed).standard_normal(500)
        e = np.zeros_like(w)
        for k in range(1, w.size):
            e[k] = 0.5 * e[k - 1] + w[k]
        r = whiteness(e, 10)
        assert not r.white
        assert r.p_value < 1e-6
        assert_allclose(r.acf[0], 0.5, atol=0.15)  # 3.4 standard errors of the ACF (0.044 at n = 500)
        assert "not white" in r.verdict


def test_acf_matches_the_textbook_estimator():
    """The ACF is sum (e_t - m)(e_{t+k} - m) / sum (e_t - m)^2 (Box-Jenkins), computed here directly."""
    e = np.random.default_rng(3).standard_normal(300).cumsum()
    r = whiteness(e, 5)
    d = e - e.mean()
    direct = [np.sum(d[:-k] * d[k:]) / np.sum(d * d) for k in range(1, 6)]
    assert_allclose(r.acf, direct, rtol=1e-10)
    assert_allclose(r.band, 1.959964 / np.sqrt(300), rtol=1e-6)


# --- independence from past inputs ------------------------------------------------------------------------
def test_residual_made_of_a_lagged_input_is_flagged_at_that_lag():
    """e_t = 0.6 u2_{t-3} + noise: the CCF with u2 peaks at lag 3 at about 0.6 / sqrt(0.36 + 0.64)
    = 0.6; with the unrelated u1 nothing exceeds the Bonferroni threshold (seed fixed)."""
    rng = np.random.default_rng(11)
    u = rng.standard_normal((2, 800))
    e = 0.8 * rng.standard_normal(800)
    e[3:] += 0.6 * u[1, :-3]
    c = independence(e, u, 8)
    assert not c.independent
    assert (c.worst_input, c.worst_lag) == ("i_d", 3)
    assert_allclose(c.worst_ccf, 0.6, atol=0.1)  # 2.8 standard errors at n = 800
    assert np.all(np.abs(c.ccf[0]) < c.threshold)
    assert "i_d at lag 3" in c.verdict


def test_independent_residual_passes_about_95_percent_of_the_time():
    """A white residual independent of smooth (autocorrelated) inputs: with the Bonferroni
    threshold the test rejects in at most ~5 % of 100 seeds (binomial sd 2.2 %: allow 12 %)."""
    rejections = 0
    for seed in range(100):
        rng = np.random.default_rng(seed)
        u = np.cumsum(rng.standard_normal((2, 400)), axis=1)
        rejections += not independence(rng.standard_normal(400), u, 10).independent
    assert rejections <= 12


# --- fit % ------------------------------------------------------------------------------------------------
def test_fit_percent_against_numpy_and_its_limits():
    """100 (1 - ||y - yh|| / ||y - mean y||), computed independently; 100 % for a perfect model,
    0 % for the mean, negative when worse than the mean."""
    rng = np.random.default_rng(2)
    y = np.sin(np.linspace(0, 20, 1000)) + 0.1 * rng.standard_normal(1000)
    yh = y + 0.05 * rng.standard_normal(1000)
    expected = 100 * (1 - np.sqrt(np.sum((y - yh) ** 2)) / np.sqrt(np.sum((y - np.mean(y)) ** 2)))
    assert_allclose(fit_percent(y, yh), expected, rtol=1e-12)
    assert_allclose(fit_percent(y, y), 100.0, rtol=0, atol=1e-12)
    assert_allclose(fit_percent(y, np.full_like(y, y.mean())), 0.0, atol=1e-12)
    assert fit_percent(y, -y) < 0
    rows = fit_percent(np.vstack([y, 2 * y]), np.vstack([yh, 2 * y]))
    assert_allclose(rows, [expected, 100.0], rtol=1e-12)
    assert fit_percent(y, np.full_like(y, np.inf)) == -np.inf


# --- on the twin ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def twin_data(truth_model, model):
    """40 s of the papers' excitation on the twin (encoder and amplifier effects), the last quarter
    held out (10 s: about 85 residuals 0.115 s apart)."""
    log = excitation_log(truth_model, duration=40.0, seed=3, controller_model=model)
    data = prepare([log], bandwidth=10.0)
    return data, data.masks(0.25)[1]


def test_true_model_is_valid_and_a_wrong_c1_is_not(twin_data, truth_model):
    """The twin's own constants: white, independent residuals, the horizontal position followed for
    seconds (fit above 90 %: the twin's logged currents are every fifth command of its 5 kHz loop
    and its amplifiers lag, so the measured currents are not exactly what drove it). C1 20 % high:
    the horizontal prediction residual is a 20 % error in the current's acceleration (about 25 um
    at 20 ms, five times the residual of the true model), tracking i_q: not white, not
    independent of i_q, and the 1 s fit falls by more than 30 points."""
    data, hold = twin_data
    good = validate(data, hold, truth_model)
    wrong = validate(data, hold, truth_model.with_constants(TWIN_TRUTH.replace(C1=1.2 * TWIN_TRUTH.C1)))
    assert good.status == "valid", good.message
    assert all(w.white for w in good.whiteness.values())
    assert all(c.independent for c in good.independence.values())
    fits_good, fits_wrong = good.fit_table(), wrong.fit_table()
    assert fits_good["horizontal"][1.0] > 90 and fits_good["horizontal"][5.0] > 80
    assert fits_good["vertical"][0.1] > 90
    assert fits_wrong["horizontal"][1.0] < fits_good["horizontal"][1.0] - 30
    assert wrong.status == "invalid"
    assert not wrong.whiteness["horizontal"].white
    assert not wrong.independence["horizontal"].independent
    assert wrong.independence["horizontal"].worst_input == "i_q"
    rms = wrong.to_dict()["residual_rms_m"]["horizontal"]
    assert rms > 3 * good.to_dict()["residual_rms_m"]["horizontal"]
    # the vertical axis does not depend on C1: the same verdicts
    assert wrong.whiteness["vertical"].white == good.whiteness["vertical"].white


def test_to_dict_is_plain_json_with_a_verdict_per_test(twin_data, truth_model):
    data, hold = twin_data
    d = validate(data, hold, truth_model).to_dict()
    text = json.dumps(d, allow_nan=False)  # NaN or infinities would fail here
    assert "NaN" not in text
    for axis in ("vertical", "horizontal"):
        assert isinstance(d["whiteness"][axis]["verdict"], str)
        assert isinstance(d["input_independence"][axis]["verdict"], str)
        assert len(d["whiteness"][axis]["acf"]) == len(d["whiteness"][axis]["lags"])
    vertical_long = next(f for f in d["fit"] if f["horizon_s"] == 5.0)
    assert vertical_long["fit_percent"]["vertical"] is None  # open-loop unstable: diverged
    assert vertical_long["verdict"]["vertical"].startswith("diverged")
