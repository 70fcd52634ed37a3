"""Numbers of ``maglev_oc.identification`` that a user relies on, as properties (issue 21, third
hand-injection round: the modules the first two rounds left alone).

Small plausible bugs were injected by hand into ``design``, ``eps_trend``, ``study``,
``verification``, ``result``, ``layout``, ``pipeline`` and ``equation_error``, one at a time, and the
quick tests that import each module run against each; these are the properties the bugs that
slipped through broke, each checked against a computation made here independently of the code
under test (numpy, a closed form, a definition in the docstring), with the origin of every
tolerance beside it.

* Results: a fit's relative errors are (estimate - truth) / truth and its z-scores use the HAC
  standard errors (by hand on a fit of chosen numbers).
* The parameter layout: constants bounded below by 0, the gap offset by +-5 mm on both sides (an
  encoder zero has no preferred sign); a name asked twice is refused.
* Verification: the parabola is numpy's least-squares quadratic, its ``rms`` a root mean square
  (``np.polyfit``); a current under the logs' 1 mA resolution is refused (L1 = -2 c2 / u1).
* Experiment design: the crest factor is of the excursion about the mean (sqrt 2 for a sine on an
  offset, 1 for a square wave); a long multisine repeats with whole periods of 20-40 s; the gap
  sweep stays inside its gaps and reaches both ends; the continuous-current limit is on the RMS of
  |i| (a run at 6 A mean, 7.35 A RMS is flagged).
* The eps trend reads from the smallest to the largest eps (Table III's C1 13.97 -> 16.23) and
  refuses columns in another order.
* The study's current delay is the twin amplifier's time constant 1 / (2 pi 1 kHz) plus half the
  5 kHz loop period.
* ``IdentificationOutcome``: NPFSI alone succeeds only if every run stayed well posed.
* Equation error: an axis that does not move (mover locked) adds no residuals (n_residuals =
  samples, chi-square's dof = samples - parameters); a window shorter than two filter kernels plus
  10 samples per parameter is refused.

About 3 s on one core: a 6 s locked-mover twin run, equation-error fits on it and on the 6 s twin
log of ``conftest.py``, the rest numpy.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.data.excitation import CURRENT_RESOLUTION
from maglev_oc.errors import InputError
from maglev_oc.identification.design import (
    RAMP_TIME,
    REFERENCE_RATE_HZ,
    FeasibleSet,
    crest_factor,
    gap_sweep_reference,
    multisine_reference,
)
from maglev_oc.identification.eps_trend import EpsTrend
from maglev_oc.identification.equation_error import EquationError
from maglev_oc.identification.experiments import excitation_log, verification_effects
from maglev_oc.identification.layout import ParameterLayout
from maglev_oc.identification.pipeline import IdentificationOutcome
from maglev_oc.identification.study import COMMAND_TO_CURRENT_DELAY
from maglev_oc.identification.verification import fit_parabola
from maglev_oc.model.hardware import RIG_SAMPLE_TIME
from maglev_oc.regression.base import GAP_OFFSET, GAP_OFFSET_BOUND
from maglev_oc.sim.effects import CurrentAmplifier
from tests.test_experiment_design_properties import _reference as _flat_reference
from tests.test_identification_outputs import make_fit, make_npfsi
from tests.test_identification_round2_properties import _fixed_gap_log


# --- result ----------------------------------------------------------------------------------------
def test_relative_errors_and_z_scores_are_against_the_truth_and_the_hac_errors():
    fit = make_fit()
    truth = {"C1": 14.0, "C2": 812.5, "gap_offset": 0.0, "friction.c": 0.01, "C3": 31.0}
    rel = fit.relative_errors(truth)
    # exact arithmetic on the same floats: equality to 1e-15 relative (one rounding)
    assert set(rel) == {"C1", "C2", "friction.c"}  # truth 0 has no relative error; C3 not estimated
    for k in rel:
        assert rel[k] == pytest.approx((fit.values[k] - truth[k]) / truth[k], rel=1e-15)
    z = fit.z_scores(truth)
    assert set(z) == {"C1", "C2", "gap_offset", "friction.c"}
    for k in z:
        assert z[k] == pytest.approx((fit.values[k] - truth[k]) / fit.stderr[k], rel=1e-15)
    # the estimate 14.2346 against 14: +1.676 %, not the -1.649 % of dividing by the estimate
    assert rel["C1"] == pytest.approx(0.23456789 / 14.0, rel=1e-12)


# --- layout ----------------------------------------------------------------------------------------
def test_layout_bounds_constants_below_by_zero_and_the_gap_offset_on_both_sides(model):
    lay = ParameterLayout(model, estimate=("C1", "C3", GAP_OFFSET))
    assert lay.names == ("C1", "C3", GAP_OFFSET)
    assert lay.lower == (0.0, 0.0, -GAP_OFFSET_BOUND)
    assert lay.upper == (np.inf, np.inf, GAP_OFFSET_BOUND)
    assert lay.initial == (model.constants.C1, model.constants.C3, 0.0)


def test_layout_refuses_a_name_asked_twice(model):
    with pytest.raises(InputError, match="duplicate"):
        ParameterLayout(model, estimate=("C2", "C2"))


# --- verification ----------------------------------------------------------------------------------
def test_the_parabola_fit_is_numpys_least_squares_with_its_rms():
    log = _fixed_gap_log(L1=7.3, u1=-0.5, n=600, seed=3)
    fit = fit_parabola(log, 0.02)
    t = log.t - log.t[0]
    c2, c1, c0 = np.polyfit(t, log.x[2], 2)  # an independent least-squares solver
    # coefficients of a well-posed 600 x 3 problem agree to far better than 1e-6 relative
    np.testing.assert_allclose(fit.coefficients, [c0, c1, c2], rtol=1e-6, atol=1e-12)
    res = log.x[2] - np.polyval([c2, c1, c0], t)
    # RMS, not mean |r| (smaller by 13-20 % for uniform to Gaussian errors); rel 1e-6 as above
    assert fit.rms == pytest.approx(np.sqrt(np.mean(res**2)), rel=1e-6)
    assert fit.L1 == pytest.approx(-2 * c2 / -0.5, rel=1e-6)
    np.testing.assert_allclose(fit.position(t), np.polyval([c2, c1, c0], t), rtol=0, atol=1e-12)


def test_the_parabola_refuses_a_current_below_the_logged_resolution():
    # u1 = 0.5 mA is under the logs' 1 mA current resolution: L1 = -2 c2 / u1 would divide the
    # quantization noise by nothing measured
    log = _fixed_gap_log(u1=0.5 * CURRENT_RESOLUTION)
    with pytest.raises(InputError, match="u1"):
        fit_parabola(log, 0.02)


# --- design: signals -------------------------------------------------------------------------------
def test_the_crest_factor_is_of_the_excursion_about_the_mean():
    # a set-point is an offset plus an excursion: 20 mm + 4 mm sin has the crest factor of a sine,
    # sqrt 2 (closed form); a square wave about any level has 1. Whole periods on a fine grid: the
    # sampled max and RMS are exact to rounding for 1000 samples of one period (tolerance 1e-9).
    t = np.arange(1000) / 1000
    assert crest_factor(0.02 + 0.004 * np.sin(2 * np.pi * t)) == pytest.approx(np.sqrt(2), rel=1e-9)
    assert crest_factor(-3.0 + np.sign(np.sin(2 * np.pi * t + 0.1))) == pytest.approx(1.0, rel=1e-9)


@pytest.mark.parametrize(("duration", "period"), [(50.0, 25.0), (90.0, 22.5)])
def test_a_long_multisine_repeats_with_whole_periods_of_20_to_40_s(duration, period):
    # the docstring's rule: a run over 20 s is split into floor(duration / 20) whole periods (20-40 s);
    # after the 2 s ramp every set-point, rate and acceleration repeats after one period (a whole
    # number of 1 ms samples; atol 1e-9: the sines' arguments reach 2e3 rad, whose 1e-13 rounding
    # times values up to ~10 m/s^2 is far below it)
    assert 20.0 <= period <= 40.0 and duration / period == int(duration // 20)
    ref = multisine_reference(duration)
    k = round(period * REFERENCE_RATE_HZ)
    after = ref.t >= RAMP_TIME
    after[-k:] = False
    idx = np.flatnonzero(after)
    np.testing.assert_allclose(ref.values[:, idx + k], ref.values[:, idx], rtol=0, atol=1e-9)
    # and not with a shorter one: the lowest tone is about 0.2 Hz, a harmonic of 1 / period
    assert np.max(np.abs(ref.values[3, idx[: k // 2] + k // 2] - ref.values[3, idx[: k // 2]])) > 1e-3


def test_the_gap_sweep_keeps_its_set_points_inside_its_gaps_and_reaches_both():
    # 000 Sec. V-B's range, 10-25 mm: the ripple rides on the sweep but may not carry the set-point
    # out (the stoppers are at 8 and 30 mm); the sweep reaches both ends to within the 4 mm ripple
    lo, hi = 10e-3, 25e-3
    ref = gap_sweep_reference(60.0, gaps=(lo, hi))
    r = ref.values[0]
    assert r.min() >= lo and r.max() <= hi
    assert r.min() < lo + 4e-3 and r.max() > hi - 4e-3


def test_the_continuous_current_limit_is_on_the_rms_of_the_current_magnitude():
    # |i| = 9 A (i_q 5.4, i_d 7.2: a 3-4-5 triangle) on 2/3 of the samples, 0 on the rest: the mean
    # is 6 A but the RMS 9 sqrt(2/3) = 7.35 A, over the amplifiers' 7 A continuous rating
    ref = _flat_reference()
    n = ref.t.size
    on = (np.arange(n) % 3) != 0
    u = np.vstack([5.4 * on, 7.2 * on])
    x = np.zeros((4, n))
    x[0] = 0.02
    run = SimpleNamespace(success=True, x=x, u=u, message="")
    flags = FeasibleSet().violations(ref, run)
    assert len(flags) == 1 and flags[0].startswith("RMS current 7.3"), flags


# --- eps trend -------------------------------------------------------------------------------------
def test_an_eps_trend_reads_from_the_smallest_to_the_largest_eps_and_refuses_another_order():
    tr = EpsTrend(
        "Table III", ("C1", "C3"), (0.001, 0.01, 0.05), [[13.97, 14.20, 16.23], [30.33, 31.04, 33.44]]
    )
    # Table III of 000: C1 13.97 -> 16.23 is +16.18 %, over 0.049 s of eps (exact arithmetic, 1e-12)
    assert tr.change["C1"] == pytest.approx(16.23 / 13.97 - 1, rel=1e-12)
    assert tr.slope["C1"] == pytest.approx((16.23 / 13.97 - 1) / 0.049, rel=1e-12)
    # the same numbers with the columns out of order would turn the change round: refused
    with pytest.raises(InputError, match="increase"):
        EpsTrend("shuffled", ("C1",), (0.05, 0.001, 0.01), [[16.23, 13.97, 14.20]])


# --- study -----------------------------------------------------------------------------------------
def test_the_study_delays_the_currents_by_the_amplifiers_lag_and_half_a_loop_period():
    # the twin's amplifier is first order at 1 kHz: time constant 1 / (2 pi 1000) = 0.159 ms (not
    # 1 / 1000 s); a zero-order hold of the 5 kHz loop delays by half its 0.2 ms period
    lag = CurrentAmplifier().time_constant
    assert lag == pytest.approx(1 / (2 * np.pi * 1000.0), rel=1e-12)
    assert COMMAND_TO_CURRENT_DELAY == pytest.approx(lag + RIG_SAMPLE_TIME / 2, rel=1e-12)


# --- pipeline --------------------------------------------------------------------------------------
def test_an_npfsi_only_outcome_succeeds_only_if_every_run_stayed_well_posed(model):
    ok = (make_npfsi(eps=0.001), make_npfsi(eps=0.01), make_npfsi(eps=0.05))
    base = model.constants
    good = IdentificationOutcome(None, None, ok, base, ("C1", "C2"), ("run_a.csv",))
    assert (good.status, good.success) == ("npfsi_only", True)
    for k in range(3):
        runs = tuple(make_npfsi(eps=r.eps, success=j != k) for j, r in enumerate(ok))
        bad = IdentificationOutcome(None, None, runs, base, ("C1", "C2"), ("run_a.csv",))
        assert (bad.status, bad.success) == ("failed", False)


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
