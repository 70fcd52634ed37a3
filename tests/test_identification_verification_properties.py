"""Properties of the papers' verification experiments (``maglev_oc.identification.verification``),
checked against ``np.polyfit``, the estimator run by hand and closed forms:

- the parabola is numpy's least-squares quadratic with its RMS, needs a constant current above
  the logged resolution, and the parabola/NPFSI discrepancy is relative to the parabola and made
  at one eps; the fixed-gap NPFSI run uses the gamma and Q0 it is given;
- equilibrium currents give a percentage exactly where the measured current is not small (none,
  and no warning, at 0 A), and ``max_pct`` includes both ends of its range;
- the cogging force from C2 is positive when C2 at the offset is larger.
"""

from __future__ import annotations

import math
import warnings
from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.data.excitation import CURRENT_RESOLUTION
from maglev_oc.data.log import Log
from maglev_oc.errors import InputError
from maglev_oc.estimation.differentiate import HighGainDifferentiator, differentiate_log
from maglev_oc.identification.npfsi import NpfsiEstimator
from maglev_oc.identification.verification import (
    EquilibriumComparison,
    cogging_from_c2,
    compare_equilibrium_currents,
    compare_parabola_npfsi,
    fit_parabola,
    npfsi_fixed_gap,
)
from maglev_oc.model.equilibrium import equilibrium_currents


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


# --- verification --------------------------------------------------------------------------------------
def test_the_parabola_npfsi_comparison_refuses_runs_at_different_eps():
    par = [SimpleNamespace(gap=0.02, L1=10.0), SimpleNamespace(gap=0.025, L1=8.0)]
    same = [SimpleNamespace(eps=0.01, values={"L1": 11.0}), SimpleNamespace(eps=0.01, values={"L1": 6.0})]
    assert compare_parabola_npfsi(par, same).eps == 0.01
    mixed = [SimpleNamespace(eps=0.01, values={"L1": 11.0}), SimpleNamespace(eps=0.05, values={"L1": 6.0})]
    with pytest.raises(InputError, match="eps"):
        compare_parabola_npfsi(par, mixed)


def _fixed_gap_log(L1=7.3, u1=-0.5, n=600, seed=0):
    """000 eq. (5) sampled at 1 kHz with 10 um quantization: x3 = -50 mm - L1 u1 t^2 / 2."""
    t = np.arange(n) * 1e-3
    x3 = -0.05 - 0.5 * L1 * u1 * t**2 + np.random.default_rng(seed).normal(0, 2e-6, n)
    x = np.full((4, n), np.nan)
    x[0], x[2] = 0.02, np.round(x3 / 1e-5) * 1e-5
    return Log(t, x, np.vstack([np.full(n, u1), np.zeros(n)]), source="fixed_gap.csv")


@pytest.mark.parametrize("gamma, q0", [(1.1, None), (1.5, None), (1.1, 50.0), (2.0, 0.02)])
def test_the_fixed_gap_npfsi_run_uses_the_gamma_and_q0_it_is_given(gamma, q0):
    # x4' = -L1 u1 (000 eq. (4)): the regressor is -u1, the data the observer's x4; run here by hand
    # through the estimator with the same settings. Exact to round-off (rtol 1e-12: the same
    # recursion on the same numbers); the settings change the answer (the test has teeth).
    log = _fixed_gap_log()
    Q0 = None if q0 is None else np.array([[q0]])
    run = npfsi_fixed_gap(log, eps=0.01, gamma=gamma, Q0=Q0, theta0=5.0)
    assert run.gamma == gamma
    der = differentiate_log(log, HighGainDifferentiator(log.sample_time))
    n = log.n
    by_hand = NpfsiEstimator(0.01, gamma, None, Q0).run(
        -log.u[0].reshape(n, 1, 1), np.zeros((n, 1)), der.velocity[1].reshape(n, 1), 1e-3, [5.0]
    )
    np.testing.assert_allclose(run.trajectory, by_hand.trajectory, rtol=1e-12)
    np.testing.assert_allclose(run.Q0, by_hand.Q0, rtol=1e-12)
    default = npfsi_fixed_gap(log, eps=0.01, theta0=5.0)
    if (gamma, q0) != (1.1, None):
        assert abs(run.trajectory[0, n // 10] - default.trajectory[0, n // 10]) > 1e-6


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


# --- equilibrium currents: a zero measured current ----------------------------------------------------
def _magnets_alone_model(model, gap: float):
    """``model`` with C2 set so that L2(gap) = g: the permanent magnets alone hold the mover at
    ``gap`` and the predicted equilibrium current there is exactly 0 A (the discriminant is L3^2
    and -L3 - |L3| = 0 for L3 < 0). C2 is nudged by ulps until the float result is exactly zero."""
    l2 = float(model.coefficients([gap])[1, 0])
    c2 = model.constants.C2 * model.params.gravity / l2
    for _ in range(50):
        m = model.with_constants(model.constants.replace(C2=c2))
        if float(equilibrium_currents(m, [gap]).current[0]) == 0.0:
            return m
        l2 = float(m.coefficients([gap])[1, 0])
        c2 = float(np.nextafter(c2, math.inf if l2 < model.params.gravity else -math.inf))
    pytest.fail("no C2 gives an exactly zero equilibrium current")


def test_a_zero_measured_current_gives_no_percentage_and_no_warning(model):
    gap = 20e-3
    alone = _magnets_alone_model(model, gap)
    gaps = np.array([gap, 15e-3, 25e-3])
    measured = np.array([0.0, 0.0, 1.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # 0 A / 0 A or x / 0 A must not reach the user as a warning
        cmp = compare_equilibrium_currents(alone, gaps, measured)
    assert cmp.predicted[0] == 0.0 and cmp.error[0] == 0.0
    # below small_current (0.3 A) no percentage is given, whatever the prediction
    assert np.isnan(cmp.error_pct[0]) and np.isnan(cmp.error_pct[1])
    # 1e-12 relative: the same formula, 100 |error| / |measured|, in another order
    assert cmp.error_pct[2] == pytest.approx(100 * abs(cmp.predicted[2] - 1.0), rel=1e-12)
