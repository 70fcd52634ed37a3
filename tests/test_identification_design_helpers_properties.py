"""The experiment design's building blocks (maglev_oc.identification.design) against independent
computations: the reference grid, the multisine's period and its per-axis tones, the smoothed
set-point steps of the PRBS, the scaling of a reference's excursions, the encoder's noise
variance and the equilibrium hold. These helpers had no test of their own (the designs that use
them are checked end to end, on the twin, where a factor in one of them moves a number without
failing anything).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from maglev_oc.errors import InputError
from maglev_oc.identification import design
from maglev_oc.identification.design import (
    REFERENCE_RATE_HZ,
    MultisineShape,
    SampledReference,
    encoder_noise_variance,
)
from maglev_oc.model.equilibrium import equilibrium_currents
from maglev_oc.sim.effects import Encoder


# --- the grid and the period ----------------------------------------------------------------------
@given(st.floats(5.0, 400.0))
@settings(max_examples=60, deadline=None)
def test_the_grid_is_the_reference_rate_over_the_duration(duration):
    t = design._grid(duration)
    assert t.size == round(duration * REFERENCE_RATE_HZ) and t[0] == 0.0
    np.testing.assert_allclose(np.diff(t), 1 / REFERENCE_RATE_HZ, rtol=1e-9)


@pytest.mark.parametrize("duration", [4.999, 0.0, -1.0, math.inf, math.nan])
def test_a_grid_shorter_than_five_seconds_is_refused(duration):
    with pytest.raises(InputError, match="at least 5 s"):
        design._grid(duration)


@given(st.floats(5.0, 1000.0))
@settings(max_examples=80, deadline=None)
def test_the_multisine_period_is_the_run_or_whole_periods_of_20_to_40_s(duration):
    period = design._period(duration)
    periods = duration / period
    assert periods == pytest.approx(round(periods), abs=1e-9) and round(periods) >= 1
    if duration < 20.0:
        assert period == duration
    else:
        assert 20.0 <= period < 40.0


# --- one axis's tones ------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("shape", "period", "amplitude"),
    [(MultisineShape((0.1, 3.0), 6, 0.5), 20.0, 4e-3), (MultisineShape((0.2, 4.0), 8, 2.0), 30.0, 0.02)],
)
def test_an_axis_multisine_peaks_at_its_amplitude_with_the_tilted_spectrum(shape, period, amplitude):
    """(amplitude, angular frequency, phase) per tone: the frequencies are the shape's harmonics
    of the period, the amplitudes fall as f^-tilt from the first tone, and the period's peak (on a
    grid 16 times finer than the helper's own) is the asked amplitude to the grid's resolution."""
    terms, crest = design._axis_terms(shape, period, amplitude, clip_passes=0)
    h = shape.harmonics(period)
    a, w, phi = (np.array(col) for col in zip(*terms, strict=True))
    np.testing.assert_allclose(w, 2 * math.pi * h / period, rtol=1e-15)
    np.testing.assert_allclose(a / a[0], (h / h[0]) ** (-shape.tilt), rtol=1e-12)
    t = np.linspace(0.0, period, 16 * 4096, endpoint=False)
    signal = np.sum(a[:, None] * np.sin(w[:, None] * t + phi[:, None]), axis=0)
    # the helper scales on 4096 points of the period: its peak can sit between them, by at most
    # the signal's largest slope times half a step
    slack = np.sum(a * w) * period / 4096 / 2
    assert amplitude <= np.max(np.abs(signal)) <= amplitude + slack
    assert crest > 1.0


# --- the smoothed set-point steps -------------------------------------------------------------------
def test_smoothed_steps_are_a_critically_damped_response_with_consistent_rates():
    """(r, r', r'') of piecewise-constant levels: r starts at the first level, settles to each new
    one, never overshoots (critical damping), and r' and r'' are its derivatives (the trapezoidal
    integral of r' is r, that of r'' is r'; to the grid's second-order error, away from the two
    samples where a level jumps and r'' with it)."""
    t = np.arange(4000) / REFERENCE_RATE_HZ
    levels = np.where(t < 1.0, 0.0, np.where(t < 2.5, 1.0, -0.5))
    w = 2 * math.pi * 1.5
    r, rd, rdd = design._smoothed_levels(levels, t, w)
    assert r[0] == 0.0 and rd[0] == 0.0
    k1, k2 = np.searchsorted(t, [2.5, 4.0]) - 1
    assert r[k1] == pytest.approx(1.0, abs=2e-3) and r[k2] == pytest.approx(-0.5, abs=2e-3)
    assert np.max(r) <= 1.0 + 1e-9 and np.min(r) >= -0.5 - 1e-9  # no overshoot
    h = t[1] - t[0]
    np.testing.assert_allclose(np.diff(r), 0.5 * h * (rd[1:] + rd[:-1]), atol=2e-5)
    smooth = np.diff(levels) == 0  # the intervals with no jump of the level (r'' jumps with it)
    assert np.sum(~smooth) == 2
    np.testing.assert_allclose(np.diff(rd)[smooth], (0.5 * h * (rdd[1:] + rdd[:-1]))[smooth], atol=2e-3 * w)


# --- a reference scaled per axis ---------------------------------------------------------------------
def test_a_scaled_reference_scales_the_excursions_about_the_gap_offset_and_zero():
    rng = np.random.default_rng(4)
    values = 1e-3 * rng.normal(size=(6, 50))
    values[0] += 0.02  # a gap set-point in metres
    ref = SampledReference(np.arange(50) / REFERENCE_RATE_HZ, values, "r", "d")
    out = design._scaled(ref, 0.5, 3.0, 0.02)
    np.testing.assert_allclose(out.values[0] - 0.02, 0.5 * (values[0] - 0.02), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(out.values[1:3], 0.5 * values[1:3], rtol=1e-15)
    np.testing.assert_allclose(out.values[3:6], 3.0 * values[3:6], rtol=1e-15)
    assert (out.name, out.description) == ("r", "d") and np.array_equal(out.t, ref.t)
    np.testing.assert_array_equal(ref.values, values)  # the input is left as it was


# --- the encoder and the equilibrium hold -----------------------------------------------------------
def test_the_encoder_noise_variance_is_quantization_plus_noise():
    assert encoder_noise_variance(Encoder(resolution=10e-6, noise_std=2e-6)) == pytest.approx(
        (10e-6) ** 2 / 12 + (2e-6) ** 2, rel=1e-15
    )
    assert encoder_noise_variance(Encoder(resolution=1e-6, noise_std=0.0)) == pytest.approx(1e-12 / 12)
    assert encoder_noise_variance() == encoder_noise_variance(Encoder())


def test_the_designers_hold_current_is_the_equilibrium_current(model):
    designer = design.ExperimentDesigner(model)
    for gap in (12e-3, 20e-3):
        assert designer.controller_hold(gap) == float(equilibrium_currents(model, [gap]).current[0])
