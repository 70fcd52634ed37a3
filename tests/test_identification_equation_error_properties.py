"""Properties of the equation-error fit (``maglev_oc.identification.equation_error``), checked against
numpy recomputations on the twin's log and hand-made masks:

- an input delay outside 0-10 ms, a window shorter than two filter kernels and an unknown initial
  value are refused by name, and the masks refuse a held-out share above one half;
- the HAC band sets the frequencies the covariance averages; the residual RMS is over the fitted
  samples only, and z-scores use the reported standard errors;
- a fit on chosen samples does not see the others, an axis that does not move adds no residuals,
  and on a fast log the means a choice covers whole are fitted (a reduced mask keeps a mean iff
  all its samples are chosen).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from maglev_oc.errors import InputError
from maglev_oc.identification.equation_error import EquationError, _reduced_mask
from maglev_oc.identification.experiments import TWIN_TRUTH, excitation_log, verification_effects
from maglev_oc.regression.base import CONSTANT_NAMES
from maglev_oc.regression.covariance import frequencies_for
from tests.test_identify_properties import _synthetic
from tests.test_identify_rate_properties import fast_log


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


# --- equation error --------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def locked_log(truth_model, model):
    """6 s of the vertical-only excitation (mover locked at x3 = 0, 16 mm; Table II's procedure)."""
    return excitation_log(
        truth_model,
        duration=6.0,
        seed=7,
        controller_model=model,
        effects=verification_effects(),
        gap_offset=16e-3,
        locked_position=0.0,
    )


def test_a_still_axis_contributes_no_residuals_to_the_fit(locked_log, model):
    fit = EquationError(locked_log, model, estimate=("C2", "C3", "C4")).fit()
    assert np.ptp(locked_log.x[2]) <= 2e-5  # the mover does not move (two 10 um encoder steps)
    # one axis of residuals: as many scalar residuals as samples, and the chi-square's degrees of
    # freedom are those residuals less the three parameters
    assert fit.n_residuals == fit.n_samples
    assert fit.reduced_chi_square == pytest.approx(fit.chi_square / (fit.n_samples - 3), rel=1e-12)
    # the weight is 1 / RMS of the first pass, which for one axis is the fit itself: chi^2 / n = 1
    # up to the errors-in-variables correction (1e-5 on this log; 1e-3 allows for it)
    assert fit.chi_square / fit.n_residuals == pytest.approx(1.0, rel=1e-3)


def test_a_window_shorter_than_two_filter_kernels_is_refused(twin_log, model):
    # besides 10 samples per parameter, the fitted samples must span two Savitzky-Golay kernels:
    # a shorter window holds fewer independent filtered residuals than samples
    problem = EquationError(twin_log, model)
    need = 10 * 4 + 2 * problem.kernel.size
    start = twin_log.n // 2 - need // 2  # well inside the filters' edges
    with pytest.raises(InputError, match="usable samples"):
        problem.fit((start, start + need - 1))
    assert problem.fit((start, start + need)).n_samples == need


# --- equation error on a fast log -------------------------------------------------------------------------
@pytest.mark.parametrize("q", [2, 3])
def test_a_reduced_mask_keeps_a_mean_iff_all_its_samples_are_chosen(q):
    """q-sample block means of a log: one entry per whole block (a partial block at the end is dropped, as
    the reduction drops it), True exactly when every sample of the block is True. Checked on random masks
    against the definition written out block by block."""
    rng = np.random.default_rng(q)
    for n in (6 * q, 6 * q + 1, 6 * q + q - 1):
        mask = rng.uniform(size=n) < 0.8
        mask[:q] = True  # one whole block chosen, so both answers occur
        want = [all(mask[j * q : (j + 1) * q]) for j in range(n // q)]
        assert _reduced_mask(mask, q).tolist() == want


def test_at_the_fitting_rate_the_mask_is_the_one_given():
    """q = 1 (a 1 kHz log is not reduced): the samples chosen are the samples fitted."""
    mask = np.array([True, False, True, True, False])
    assert _reduced_mask(mask, 1).tolist() == mask.tolist()


@pytest.mark.parametrize("q", [2, 3])
def test_equation_error_on_a_fast_log_fits_the_means_a_choice_covers_whole(model, q):
    """A log at q kHz is fitted at 1 kHz. Choosing samples [start, stop) at the log's rate, with both ends
    inside a block, fits the blocks lying wholly inside, [ceil(start / q) q, floor(stop / q) q): the same
    number of fitted means, the same C1 to rounding (1e-12: same samples), found to 1e-3 (the 1 um
    position noise through the differentiator). The count is that of the whole blocks inside less the
    differentiator's edge at each end of the log (none of which the choice reaches)."""
    problem = EquationError(fast_log(model, 6.0, rate=1000.0 * q, seed=36), model, estimate=("C1",))
    assert problem.sample_time == pytest.approx(1e-3, rel=1e-12)
    n = problem.logs[0].n
    start, stop = 1000 * q + 1, 5000 * q - 1  # 1 s to 5 s, each end one sample into a block
    mask = np.zeros(n, dtype=bool)
    mask[start:stop] = True
    first, last = -(-start // q), stop // q  # the whole blocks inside: [first, last)
    whole = np.zeros(n, dtype=bool)
    whole[first * q : last * q] = True
    a, b = problem.fit(mask), problem.fit(whole)
    assert a.success and b.success
    edge = problem.prepared.edge
    assert edge < first and last <= n // q - edge  # the choice stays clear of the filters' edges
    assert a.n_samples == b.n_samples == last - first
    assert a.values["C1"] == pytest.approx(b.values["C1"], rel=1e-12)
    assert a.values["C1"] == pytest.approx(model.constants.C1, rel=1e-3)


# --- equation error: an unknown initial value ------------------------------------------------------
@pytest.mark.parametrize(
    ("estimate", "initial", "unknown"),
    [(("C2", "C3", "C4"), {"C1": 14.0}, "C1"), (CONSTANT_NAMES, {"C2": 790.0, "offset": 1e-4}, "offset")],
)
def test_an_equation_error_fit_refuses_an_unknown_initial_value_by_name(model, estimate, initial, unknown):
    log = _synthetic("both.csv", vertical=True, horizontal=True, duration=2.0)
    problem = EquationError(log, model, estimate=estimate)
    with pytest.raises(InputError) as info:
        problem.fit(initial=initial)
    msg = str(info.value)
    assert repr(unknown) in msg and "initial" in msg
    assert all(n in msg for n in problem.names), msg  # the names it could have used
