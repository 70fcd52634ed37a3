"""Multiple-shooting output error: why single shooting fails, accuracy on twin logs, the
constrained Gauss-Newton solution (continuity met), standard errors, NLS cross-checks."""

from __future__ import annotations

import numpy as np
import pytest

from maglev_oc.data.logs import Log
from maglev_oc.identification.equation_error import fit_equation_error
from maglev_oc.identification.experiments import TWIN_TRUTH, excitation_log
from maglev_oc.identification.layout import CONSTANT_NAMES
from maglev_oc.identification.output_error import MultipleShooting, fit_output_error, simulate_open_loop

TRUTH = dict(zip(CONSTANT_NAMES, TWIN_TRUTH.as_array(), strict=True))


@pytest.fixture(scope="module")
def short_log(twin_log) -> Log:
    return twin_log


@pytest.fixture(scope="module")
def short_fit(model, short_log):
    return MultipleShooting(short_log, model).fit()


def test_single_shooting_diverges_even_with_the_true_constants(truth_model, short_log):
    # The open-loop plant is unstable (vertical pole ~40 1/s at 20 mm): driven by the logged
    # currents from the right initial state, the simulated gap leaves the data by more than
    # 1 mm within a second. This is why the fit uses multiple shooting.
    x = simulate_open_loop(short_log, truth_model, 1.0)
    k = x.shape[1]
    gap_error = np.abs(x[0] - short_log.x[0, :k])
    diverged = (~np.isfinite(gap_error)) | (gap_error > 1e-3)
    assert diverged.any()
    first = int(np.argmax(diverged))
    assert short_log.t[first] - short_log.t[0] < 1.0
    assert np.nanmax(gap_error[:20]) < 1e-4  # but it starts on the data


def test_multiple_shooting_recovers_the_constants(short_fit):
    fit = short_fit
    assert fit.success, fit.message
    err = fit.relative_errors(TRUTH)
    for k in ("C1", "C2", "C3"):
        assert abs(err[k]) < 0.01, (k, err[k])
    z = fit.z_scores(TRUTH)
    assert max(abs(v) for v in z.values()) < 3.0, z
    # output residuals at the encoder's noise level: 10 um quantization (2.9 um RMS) + 2 um noise
    # (3.5 um), plus the currents' decimation integrated over the 0.2 s windows
    assert 2.5e-6 < fit.residual_rms["vertical"] < 6e-6
    assert 2.5e-6 < fit.residual_rms["horizontal"] < 8e-6
    assert fit.residual_unit == "m"
    assert fit.iterations <= 10


def test_solution_meets_continuity_and_is_a_stationary_point(model, short_log, short_fit):
    # At the solution the continuity constraints hold (the residual plot is one trajectory per
    # window) and the estimate does not move when the fit is restarted from it.
    again = MultipleShooting(short_log, model).fit(initial=short_fit)
    assert again.success
    assert again.iterations <= 3
    for k in CONSTANT_NAMES:
        assert again.values[k] == pytest.approx(short_fit.values[k], rel=1e-7)
    assert short_fit.settings["segment_duration_s"] == pytest.approx(0.05)


def test_output_error_agrees_with_equation_error(model, short_log, short_fit):
    # Two independent NLS formulations on the same data agree within their uncertainties.
    ee = fit_equation_error(short_log, model)
    for k in ("C1", "C2", "C3"):
        tol = 3 * np.hypot(ee.stderr[k], short_fit.stderr[k])
        assert abs(ee.values[k] - short_fit.values[k]) < tol, k


def test_standard_errors_are_long_run_ones(short_fit):
    # Residuals of the output error are correlated within the windows (process noise from the
    # current decimation): the plain s^2 (J'J)^-1 is many times too small and the long-run
    # covariance is what covers the truth (see test_multiple_shooting_recovers_the_constants).
    infl = np.array([short_fit.variance_inflation[k] for k in CONSTANT_NAMES])
    assert np.all(infl > 2.0)
    assert short_fit.hac_frequencies >= 4
    assert np.allclose(short_fit.covariance, short_fit.covariance.T)


def test_windows_and_arguments(model, short_log):
    with pytest.raises(ValueError, match="window_duration"):
        MultipleShooting(short_log, model, window_duration=0.01)
    with pytest.raises(ValueError, match="segment"):
        MultipleShooting(short_log.index_slice(0, 60), model)
    with pytest.raises(TypeError):
        fit_output_error(short_log, model, nonsense=True)
    ms = MultipleShooting(short_log, model, window_duration=0.05)  # independent segments
    assert all(s.links.size == 0 for s in ms.segments)
    ms = MultipleShooting(short_log, model, window_duration=0.2)
    seg = ms.segments[0]
    assert seg.links.size == seg.J - 1 - (seg.J - 1) // 4


@pytest.mark.slow
def test_sixty_second_log_both_fits_meet_the_requirement(model, truth_model):
    # The requirement on a 60 s twin log with noise and 10 um quantization: C1..C3
    # within 1 %, C4 within 10 %, standard errors covering the truth.
    log = excitation_log(truth_model, duration=60.0, seed=11, controller_model=model)
    ee = fit_equation_error(log, model)
    oe = MultipleShooting(log, model).fit(initial=ee)
    for fit in (ee, oe):
        assert fit.success
        err = fit.relative_errors(TRUTH)
        assert max(abs(err[k]) for k in ("C1", "C2", "C3")) < 0.01
        assert abs(err["C4"]) < 0.10
        assert max(abs(v) for v in fit.z_scores(TRUTH).values()) < 3.0
