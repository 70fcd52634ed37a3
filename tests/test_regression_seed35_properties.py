"""Properties of ``maglev_oc.regression`` written against the survivors of the seed-35 mutation-testing run
at b484c31 (issue 21): each test states a property of a result a user sees, not the mutated token.

* ``delayed_inputs`` shifts the currents later by any delay, whole seconds included: the result is the
  currents read ``delay`` earlier (by index for a whole number of samples, the mean of the two
  neighbours for half a sample), held at their first value before the log starts.
* A least-squares fit depends on the axis weights only through their ratio: multiplying both by a
  common factor over 14 decades leaves the coefficients and their covariance unchanged.
* Gauss-Newton stopped by its iteration budget says so with its documented status word and the
  iterations it used; with the default budget the same fit converges to the offset planted in the log.
* A term's variant note describes its variants: the guide friction's states the reversal speeds its
  variants use (recovered from their functions), a periodic force's the gap exponents of its variants,
  and a periodic force without variants has no note.
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest

from maglev_oc.data.logs import Log
from maglev_oc.model.parameters import StageParameters
from maglev_oc.regression import solve
from maglev_oc.regression.base import GAP_OFFSET
from maglev_oc.regression.data import delayed_inputs, prepare
from maglev_oc.regression.design import build_design
from maglev_oc.regression.solve import fit_nonlinear, fit_subset
from maglev_oc.regression.terms import REFERENCE_GAP, guide_friction, periodic_force


# --- delayed currents ------------------------------------------------------------------------------------
def _log(seconds: float = 3.0) -> Log:
    """A 1 kHz log whose currents are two sines of different frequencies (every sample distinct)."""
    t = np.arange(round(seconds * 1000)) * 1e-3
    x = np.vstack([0.02 + 1e-3 * np.sin(t), np.zeros_like(t), 0.01 * np.cos(t), np.zeros_like(t)])
    u = np.vstack([3.0 * np.sin(2 * math.pi * 0.7 * t) + 1.0, -2.0 * np.cos(2 * math.pi * 1.3 * t)])
    return Log(t, x, u, source="sines")


@pytest.mark.parametrize("samples", [1, 7, 1000, 2000])
def test_currents_delayed_by_whole_samples_are_the_earlier_samples_held_at_the_start(samples):
    """u_delayed[k] = u[k - d] with d = delay / 1 ms, and u[0] for k < d (held at the start). Linear
    interpolation at a time that is a sample up to rounding of t - delay (a few 1e-16 s) is that sample
    to 1e-12 A (the currents change by at most 0.02 A per ms)."""
    log = _log()
    delay = samples * 1e-3
    u = np.asarray(log.u)
    expected = np.hstack([np.repeat(u[:, :1], samples, axis=1), u[:, :-samples]])
    np.testing.assert_allclose(delayed_inputs(log, delay), expected, rtol=0, atol=1e-12)


def test_currents_delayed_by_half_a_sample_are_the_mean_of_the_neighbours():
    """Linear interpolation halfway: (u[k - 3] + u[k - 2]) / 2 for a 2.5 ms delay; held before."""
    log = _log()
    u = np.asarray(log.u)
    got = delayed_inputs(log, 2.5e-3)
    np.testing.assert_allclose(got[:, 3:], 0.5 * (u[:, :-3] + u[:, 1:-2]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(got[:, :2], u[:, :1].repeat(2, axis=1), rtol=0, atol=0)
    np.testing.assert_array_equal(delayed_inputs(log, 0.0), u)


# --- least squares ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def prepared(twin_log):
    return prepare([twin_log], bandwidth=10.0)


@pytest.mark.parametrize("factor", [1e-7, 1e7])
def test_a_common_factor_on_the_axis_weights_changes_nothing(model, prepared, factor):
    """Weighted least squares minimises sum w_a^2 r_a^2: a common factor c on both weights multiplies
    the cost by c^2 and moves no minimum, and the covariance (the normal matrix's inverse times the
    weighted residuals' long-run covariance) is unchanged too. The Gram's diagonal goes from about 1e8
    to 1e-6 or 1e22 (its entries span four decades among C1..C4). Tolerances: the coefficients to 1e-9
    relative (measured 1e-11: round-off of sums over 6000 samples), the covariance to 1e-6 (measured
    3e-9: the long-run estimate sums products of residuals)."""
    design = build_design(prepared, model)
    scaled = build_design(prepared, model, weights=factor * design.weights)
    assert np.diag(scaled.gram.sum(axis=0)).max() == pytest.approx(
        factor**2 * np.diag(design.gram.sum(axis=0)).max(), rel=1e-9
    )
    ref, fit = (fit_subset(d, list(d.groups)) for d in (design, scaled))
    assert np.all(ref.coef > 0)  # the constants, not zeros
    np.testing.assert_allclose(fit.coef, ref.coef, rtol=1e-9)
    np.testing.assert_allclose(fit.covariance, ref.covariance, rtol=1e-6)


def test_gauss_newton_stopped_by_its_budget_says_so(truth_model, twin_log):
    """fit_nonlinear's docstring: status "converged", "iteration_limit" or "no_decrease". The gap offset
    enters nonlinearly; a log whose gap reading is 0.3 mm above the true gap needs a few Gauss-Newton
    iterations from 0: with a budget of one or two it stops with "iteration_limit" after that many;
    with the default budget it converges to -0.3 mm (gap_offset = true - reading), to 1 % (the
    offset's standard error on this log is about 0.3 um)."""
    words = set(re.findall(r'"([a-z_]+)"', solve.fit_nonlinear.__doc__))
    x = np.array(twin_log.x)
    x[0] += 3e-4
    data = prepare([dataclasses.replace(twin_log, x=x)], bandwidth=10.0)
    first = build_design(data, truth_model, estimate=(GAP_OFFSET,))

    def build(at):
        return build_design(data, truth_model, estimate=(GAP_OFFSET,), at=at, weights=first.weights)

    bounds = (np.array([-5e-3]), np.array([5e-3]), np.array([1e-3]))
    for budget in (1, 2):
        _, _, status, message, iterations = fit_nonlinear(build, np.zeros(1), *bounds, max_iterations=budget)
        assert status == "iteration_limit" and status in words
        assert iterations == budget and str(budget) in message
    _, fit, status, _, iterations = fit_nonlinear(build, np.zeros(1), *bounds)
    assert status == "converged" and status in words and 2 < iterations < 30
    assert fit.coef[0] == pytest.approx(-3e-4, rel=0.01)


# --- the terms' variant notes ----------------------------------------------------------------------------
def _numbers(note: str) -> tuple[float, float]:
    lo, hi = re.search(r"([0-9.]+)-([0-9.]+)", note).groups()
    return float(lo), float(hi)


@pytest.mark.parametrize("axis", ["horizontal", "vertical"])
@pytest.mark.parametrize("speed", [2e-3, 5e-3])
def test_the_friction_note_states_the_reversal_speeds_of_its_variants(axis, speed):
    """guide_friction: acc = -(F_c tanh(v / v_r) + c v) / M, variants at other v_r. With F_c = 1 N and
    c = 0 each variant's v_r is recovered from its function: tanh(v / v_r) = acc(v) / acc(v_big)
    (v_big = 1 m/s, 100 v_r or more, where tanh is 1 in double precision). The note "reversal speed
    A-B mm/s" gives the smallest and largest of them (to 1e-4: %g prints 6 significant digits)."""
    term = guide_friction(StageParameters(), axis, reversal_speed=speed)
    vi, row = (1, 0) if axis == "vertical" else (3, 1)

    def acc(fn, v):
        x = np.zeros(4)
        x[0], x[vi] = 0.02, v
        return float(np.asarray(fn(x, np.zeros(2), np.zeros(2), [1.0, 0.0])).ravel()[row])

    widths = sorted(speed / math.atanh(acc(fn, speed) / acc(fn, 1.0)) for fn in term.variants)
    assert len(widths) == 2 and widths[0] < speed < widths[1]
    assert "mm/s" in term.variant_note
    lo, hi = _numbers(term.variant_note)
    assert (lo, hi) == pytest.approx((widths[0] * 1e3, widths[1] * 1e3), rel=1e-4)


def test_a_periodic_forces_note_states_its_variants_gap_exponents_and_is_empty_without_any():
    """periodic_force: F = (a sin + b cos)(reference_gap / x1)^e; a variant's exponent is recovered as
    log2 of its force at half the reference gap over its force at the reference gap (exact to 1e-12).
    The note "gap exponent A-B" gives their range; without variants there is nothing to note."""
    p = StageParameters()
    term = periodic_force(p, "vertical", 0.02, gap_exponent=3.0, exponent_variants=(2.0, 4.0))

    def force(fn, gap):
        x = np.array([gap, 0.0, 0.005, 0.0])
        return float(np.asarray(fn(x, np.zeros(2), np.zeros(2), [1.0, 0.0])).ravel()[0])

    exps = sorted(math.log2(force(fn, REFERENCE_GAP / 2) / force(fn, REFERENCE_GAP)) for fn in term.variants)
    np.testing.assert_allclose(exps, [2.0, 4.0], rtol=0, atol=1e-12)
    assert "gap exponent" in term.variant_note
    assert _numbers(term.variant_note) == pytest.approx(tuple(exps), abs=1e-12)
    plain = periodic_force(p, "horizontal", 0.02)
    assert plain.variants == () and plain.variant_note == ""
