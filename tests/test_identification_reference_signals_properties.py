"""Properties of the excitation references (``maglev_oc.identification.design``: multisines, PRBS,
gap sweeps and sampled references), checked against FFTs, closed-form filter responses and
integrals of the signals themselves:

- a multisine has exactly its harmonics in its spectrum (distinct positive integers, one
  amplitude and one phase each), a shape gives as many harmonics as tones in its band and accepts
  the closed range of tilts; a clipping pass keeps the harmonics' phases; Schroeder's phases
  refuse what their docstring excludes; the crest factor is of the excursion about the mean;
  a long multisine repeats with whole periods of 20-40 s;
- a PRBS reference plays a whole period of an m-sequence, its set-points are the filter driven by
  levels held over each sample, its description states its bit times, and its accelerations and
  rates integrate to the set-points;
- the gap sweep stays inside its gaps and reaches both, names its ripple in millimetres, and
  refuses gaps outside (0, 0.1] m or a ripple that leaves no room;
- a sampled reference refuses gaps outside metres' range and a time that does not increase.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from maglev_oc.errors import InputError
from maglev_oc.identification.design import (
    RAMP_TIME,
    REFERENCE_RATE_HZ,
    MultisineShape,
    SampledReference,
    _smoothed_levels,
    crest_factor,
    gap_sweep_reference,
    multisine,
    multisine_reference,
    prbs_reference,
    schroeder_phases,
)


# --- experiment design: references --------------------------------------------------------------------
def test_prbs_reference_accelerations_and_rates_integrate_to_the_set_points():
    """A reference file's rows are a set-point, its rate and its acceleration: on both axes the
    trapezoidal integral of the acceleration is the rate and that of the rate is the set-point.
    Tolerance: the filtered PRBS's acceleration jumps at every bit (w^2 times the step), where the
    trapezoid errs by up to half a jump times a 1 ms sample; over 10 s that adds up to 0.6 % of
    the peak rate (measured), allowed 2 %; the rate is smooth (5e-6 of the range measured, 1e-4
    allowed)."""
    ref = prbs_reference(10.0)
    v = ref.values
    for row in (0, 3):
        rate = v[row + 1, 0] + cumulative_trapezoid(v[row + 2], ref.t, initial=0)
        assert np.max(np.abs(rate - v[row + 1])) < 0.02 * np.max(np.abs(v[row + 1]))
        point = v[row, 0] + cumulative_trapezoid(v[row + 1], ref.t, initial=0)
        assert np.max(np.abs(point - v[row])) < 1e-4 * np.ptp(v[row])


def test_gap_sweep_description_names_its_ripple_in_millimetres():
    """The gap sweep's description states its gap range and its ripple in mm (3 mm given in metres
    as 3e-3): what a reader of the design file sees of the reference."""
    ref = gap_sweep_reference(10.0, ripple=3e-3)
    assert "10-25 mm" in ref.description
    assert "with a 3 mm ripple" in ref.description


def _is_maximum_length(bits: np.ndarray) -> bool:
    """Periodic autocorrelation N at lag 0 and -1 at every other lag (the m-sequence's signature)."""
    n = bits.size
    return all(int(np.dot(bits, np.roll(bits, k))) == (n if k == 0 else -1) for k in range(n))


@pytest.mark.parametrize("duration", [10.0, 17.0])
def test_a_prbs_reference_plays_a_whole_period_of_its_sequence(duration):
    # documented: "the order is the largest whose period fits the run, so the sequence is played
    # whole". The bits are read back from the set-point at the end of each bit (the smoothing
    # filter, critically damped at 9.4 rad/s, has covered 68 % of a full step by then, so the sign
    # is the bit's); the first 2^k - 1 of them form an m-sequence for the largest such k that fits.
    ref = prbs_reference(duration)
    for row, offset, bit_time in ((0, 0.02, 0.25), (3, 0.0, 0.5)):
        ends = np.round((np.arange(1, int(duration / bit_time)) * bit_time - 1e-3) * 1000).astype(int)
        bits = np.sign(ref.values[row, ends] - offset).astype(int)
        k = int(np.floor(np.log2(bits.size + 1)))
        assert _is_maximum_length(bits[: 2**k - 1]), (row, k)


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


# --- signals ----------------------------------------------------------------------------------------------
def _projected_phases(x: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Phases phi_k of the components a_k sin(2 pi h_k t + phi_k) of one period ``x`` sampled on a uniform
    grid: by projection on sin and cos (s_k = a cos phi, c_k = a sin phi), not by the FFT."""
    t = np.arange(x.size) / x.size
    s = np.array([2 * np.mean(x * np.sin(2 * math.pi * k * t)) for k in h])
    c = np.array([2 * np.mean(x * np.cos(2 * math.pi * k * t)) for k in h])
    return np.arctan2(c, s)


def _wrapped(d: np.ndarray) -> np.ndarray:
    return (np.asarray(d) + math.pi) % (2 * math.pi) - math.pi


def test_a_clipping_pass_keeps_the_phases_of_the_clipped_signals_harmonics():
    """One pass of the clipping algorithm (multisine's docstring; Van der Ouderaa et al. 1988) clips the
    period at 90 % of its peak and keeps the phases of the clipped signal's harmonics. For 16 equal tones the
    pass lowers the crest factor (1.83 -> 1.79), so the pass's phases are the ones returned: they must be the
    clipped Schroeder signal's, computed here by projection. Tolerance 1e-9 rad: round-off of sums over
    4096 points (about 1e-13), far below any phase error."""
    h = np.arange(1, 17)
    a = np.ones(h.size)
    grid = 4096
    t = np.arange(grid) / grid
    phi0 = schroeder_phases(a) + math.pi / 2  # Schroeder's cosine phases as sine phases (the default)
    x = np.sum(a[:, None] * np.sin(2 * math.pi * h[:, None] * t + phi0[:, None]), axis=0)
    level = 0.9 * np.max(np.abs(x))
    expected = _projected_phases(np.clip(x, -level, level), h)
    phases, cf = multisine(h, a, clip_passes=1, grid=grid)
    assert np.max(np.abs(_wrapped(phases - expected))) < 1e-9
    # the crest factor returned is that of the signal with the returned phases, below Schroeder's
    y = np.sum(a[:, None] * np.sin(2 * math.pi * h[:, None] * t + phases[:, None]), axis=0)
    assert cf == pytest.approx(crest_factor(y), rel=1e-12)
    assert cf < multisine(h, a, grid=grid)[1]


def test_schroeder_phases_refuse_what_their_docstring_excludes():
    """Amplitudes must be a non-empty vector of non-negative numbers with some power: all zero leaves no
    power to share (p_j = a_j^2 / sum a^2 is 0/0) and is refused, as are negative or empty ones; the
    multisine built on them refuses too. Equal amplitudes give -pi k (k - 1) / N (docstring)."""
    for bad in ([0.0, 0.0, 0.0], [0.0], [1.0, -1.0], [], [[1.0, 2.0]]):
        with pytest.raises(InputError, match="amplitudes"):
            schroeder_phases(bad)
    with pytest.raises(InputError, match="amplitudes"):
        multisine([1, 2, 3], [0.0, 0.0, 0.0])
    n = 7
    k = np.arange(1, n + 1)
    expected = -math.pi * k * (k - 1) / n
    np.testing.assert_allclose(schroeder_phases(np.ones(n)), expected, rtol=1e-12, atol=1e-12)
    assert np.all(np.isfinite(schroeder_phases([0.0, 1.0, 0.0])))  # some zero amplitudes are fine


# --- multisine shapes ---------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("band", "tones", "period"),
    [((0.2, 4.0), 8, 20.0), ((0.05, 0.5), 12, 20.0), ((0.1, 1.0), 8, 20.0), ((0.2, 4.0), 1, 20.0)],
)
def test_a_shape_gives_as_many_harmonics_as_tones_within_its_band(band, tones, period):
    """tones log-spaced harmonics of the period within the band; when rounding merges some, unused ones of the
    band fill in, so there are exactly min(tones, harmonics in the band), distinct, in the band."""
    shape = MultisineShape(band, tones)
    h = shape.harmonics(period)
    lo = max(1, round(band[0] * period))
    hi = max(lo, round(band[1] * period))
    assert h.size == len(set(h.tolist())) == min(tones, hi - lo + 1)
    assert h.min() >= lo and h.max() <= hi
    assert (h.min() == lo and h.max() == hi) or tones == 1  # log-spaced from the lowest to the highest


def test_a_multisine_reference_has_exactly_its_harmonics_in_its_spectrum():
    """A 40 s run has a 20 s period (tones are its harmonics); the second period is past the 2 s ramp, so its
    FFT holds lines at the shape's harmonics and nothing else. 'Nothing': below 1e-9 of the largest line
    (round-off of a 20000-point FFT is about 1e-13 of it)."""
    shape = MultisineShape((0.2, 4.0), 8, 0.0)
    ref = multisine_reference(40.0, vertical=None, horizontal=shape)
    period = ref.t.size // 2
    spec = np.abs(np.fft.rfft(ref.values[3, period:]))
    lines = np.flatnonzero(spec > 1e-9 * spec.max())
    np.testing.assert_array_equal(lines, shape.harmonics(20.0))
    assert np.all(ref.values[0] == ref.values[0, 0])  # vertical None: the gap stays at its offset


# --- gap sweep refusals ------------------------------------------------------------------------------------
@pytest.mark.parametrize("gaps", [(0.0, 0.025), (-0.005, 0.025), (0.02, 0.02), (0.025, 0.01), (0.01, 0.11)])
def test_the_gap_sweep_refuses_gaps_outside_zero_to_a_tenth_of_a_metre(gaps):
    """gaps must be (low, high) in metres with 0 < low < high <= 0.1: a gap of 0 is the mover on the stator
    (and a reading of mm as m); the error names the gaps given."""
    with pytest.raises(InputError, match=r"gaps must be .* got \(") as info:
        gap_sweep_reference(10.0, gaps=gaps)
    assert repr(gaps) in str(info.value)


def test_the_gap_sweep_refuses_a_ripple_that_leaves_no_room_to_sweep():
    """The sweep's half-range is (high - low) / 2 - ripple: at 0 or below there is nothing to sweep. Values
    exact in binary (2^-7, 3 x 2^-7 m) make the half-range exactly 0; a ripple a hair smaller is accepted."""
    lo, hi = 2.0**-7, 3 * 2.0**-7
    ripple = (hi - lo) / 2
    assert (hi - lo) / 2 - ripple == 0.0
    for r in (ripple, 1.5 * ripple):
        with pytest.raises(InputError, match="leaves no room to sweep"):
            gap_sweep_reference(10.0, gaps=(lo, hi), ripple=r, horizontal=None)
    ref = gap_sweep_reference(10.0, gaps=(lo, hi), ripple=0.9 * ripple, horizontal=None)
    assert lo <= ref.values[0].min() and ref.values[0].max() <= hi


# --- PRBS references ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("bit_time", [(0.25, 0.5), (0.5, 0.2)])
def test_a_prbs_references_description_states_its_bit_times(bit_time):
    """The description "bits of A/B s" gives the vertical and horizontal bit times. The smoothing filter
    is critically damped and of second order, so each step of the levels makes the set-point's
    acceleration jump; after the ramp (RAMP_TIME) every jump lies on a multiple of the stated bit time of
    its axis (to 1.5 samples of 1 ms), and the closest two are one bit apart."""
    ref = prbs_reference(8.0, bit_time=bit_time)
    m = re.search(r"bits of ([0-9.]+)/([0-9.]+) s", ref.description)
    assert m is not None, ref.description
    stated = (float(m.group(1)), float(m.group(2)))
    assert stated == pytest.approx(bit_time, rel=1e-12)
    dt = ref.t[1] - ref.t[0]
    for row, bit in ((2, stated[0]), (5, stated[1])):
        jump = np.abs(np.diff(ref.values[row]))
        at = ref.t[1:][jump > 0.3 * jump.max()]
        at = at[at >= RAMP_TIME]
        assert at.size >= 4
        k = at / bit
        np.testing.assert_allclose(k, np.round(k), rtol=0, atol=1.5 * dt / bit)
        assert np.diff(at).min() == pytest.approx(bit, abs=1.5 * dt)


# --- sampled references -------------------------------------------------------------------------------------
def _reference(gap: float) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(5) / REFERENCE_RATE_HZ
    values = np.zeros((6, t.size))
    values[0] = 0.02
    values[0, 2] = gap
    return t, values


@pytest.mark.parametrize("gap", [0.0, -0.02, 0.1 + 1e-12, 20.0])
def test_a_reference_refuses_gaps_outside_metres_range_and_says_so(gap):
    """A gap set-point must be in (0, 0.1] m; 20.0 is 20 mm written in millimetres, 0 a closed gap. The
    message says metres and gives the range, so the caller knows the unit to write."""
    t, values = _reference(gap)
    with pytest.raises(InputError) as err:
        SampledReference(t, values)
    assert str(err.value) == "SampledReference: gap set-points must be in metres, in (0, 0.1]"


@pytest.mark.parametrize("gap", [1e-6, 0.1])
def test_a_reference_accepts_gaps_in_range(gap):
    """Both ends of (0, 0.1]: the reference keeps the values given."""
    t, values = _reference(gap)
    assert SampledReference(t, values).values[0, 2] == gap


@pytest.mark.parametrize("where", [1, 5, 9])
@pytest.mark.parametrize("step", [0.0, -1.0 / REFERENCE_RATE_HZ])
def test_a_reference_whose_time_does_not_increase_is_refused(where, step):
    """t[k] - t[k-1] must be > 0 for every k: a repeated sample (step 0) or one going back in time,
    at the start, the middle or the end of a 10-sample reference, is refused; the same reference with
    increasing times is accepted."""
    t = np.arange(10) / REFERENCE_RATE_HZ
    values = np.zeros((6, 10))
    values[0] = 0.02
    SampledReference(t, values)  # increasing: accepted
    bad = t.copy()
    bad[where] = bad[where - 1] + step
    with pytest.raises(InputError, match="must start at 0 and increase"):
        SampledReference(bad, values)


# --- the PRBS set-points: a zero-order hold through the smoothing filter -----------------------------
def _held_filter(levels: np.ndarray, t: np.ndarray, w: float) -> np.ndarray:
    """(r, r') of the critically damped filter r'' = w^2 (u - r) - 2 w r', started at rest at
    levels[0], with u = levels[k] held over [t_k, t_k+1): the closed form of each interval, with
    e = r - u: e(s) = (e0 + (v0 + w e0) s) exp(-w s), r'(s) = (v0 - w (v0 + w e0) s) exp(-w s)."""
    r = np.empty(levels.size)
    v = np.empty(levels.size)
    r[0], v[0] = levels[0], 0.0
    for k in range(levels.size - 1):
        h = t[k + 1] - t[k]
        e0 = r[k] - levels[k]
        b = v[k] + w * e0
        decay = math.exp(-w * h)
        r[k + 1] = levels[k] + (e0 + b * h) * decay
        v[k + 1] = (v[k] - w * b * h) * decay
    return np.vstack([r, v])


def test_smoothed_levels_hold_each_level_over_its_sample():
    """Levels that step (up, down, by different sizes) and change at every sample over a stretch:
    the smoothed (r, r') is the closed-form response to each level held over its sample, and r''
    is the filter's right-hand side at the held level. 1e-12 x the 5 mm level scale (and x w for the
    rates): round-off (measured 5e-16 m); the linear interpolation of the input instead of the hold
    moves r' by about w^2 x step x h / 2 = 1e-4 m/s at the 2.5 mm steps here."""
    w = 2 * math.pi * 1.5
    t = np.arange(1500) / REFERENCE_RATE_HZ
    levels = np.full(t.size, 20e-3)
    levels[100:400] = 22.5e-3
    levels[400:700] = 17e-3
    levels[700:1000] = 20e-3 + 2e-3 * np.sin(np.arange(300) / 7.0)  # a new level every sample
    levels[1000:] = 25e-3
    out = _smoothed_levels(levels, t, w)
    expected = _held_filter(levels, t, w)
    scale = 5e-3
    np.testing.assert_allclose(out[0], expected[0], rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(out[1], expected[1], rtol=0, atol=1e-12 * scale * w)
    acc = w**2 * (levels - expected[0]) - 2 * w * expected[1]
    np.testing.assert_allclose(out[2], acc, rtol=0, atol=1e-12 * scale * w**2)


def test_prbs_set_points_are_the_filter_driven_by_held_levels():
    """Each axis of a PRBS reference (the design's filter of 1.5 Hz, 2 pi x 1.5 rad/s): the level
    at each sample, read back from r'' = w^2 (u - r) - 2 w r', held over the sample, carries
    (r, r') to the next sample exactly as the closed-form filter does. The levels read back take
    the PRBS values offset +- amplitude x ramp (after the 2 s ramp: offset +- amplitude). Same
    tolerances as above (scale: the 2 and 30 mm amplitudes; measured 1e-17 m)."""
    w = 2 * math.pi * 1.5
    ref = prbs_reference(10.0)
    h = 1 / REFERENCE_RATE_HZ
    for row, offset, amp in ((0, 20e-3, 2e-3), (3, 0.0, 30e-3)):
        r, v, a = ref.values[row : row + 3]
        levels = r + (a + 2 * w * v) / w**2
        after_ramp = ref.t >= 2.0
        np.testing.assert_allclose(np.abs(levels[after_ramp] - offset), amp, rtol=0, atol=1e-9 * amp)
        decay = math.exp(-w * h)
        e0 = r[:-1] - levels[:-1]
        b = v[:-1] + w * e0
        np.testing.assert_allclose(r[1:], levels[:-1] + (e0 + b * h) * decay, rtol=0, atol=1e-12 * amp)
        np.testing.assert_allclose(v[1:], (v[:-1] - w * b * h) * decay, rtol=0, atol=1e-12 * amp * w)


# --- multisine: one amplitude per harmonic ---------------------------------------------------------------
@pytest.mark.parametrize(
    ("harmonics", "amplitudes"),
    [
        ([1, 2, 3], [1.0, 0.5]),  # fewer amplitudes: NumPy cannot broadcast (2,) against (3,)
        ([1, 2, 3], [1.0]),  # one amplitude: NumPy would broadcast it over the three tones
        ([2], [1.0, 0.5]),  # more amplitudes than harmonics: would broadcast the one tone
    ],
)
def test_multisine_refuses_harmonics_and_amplitudes_of_different_lengths(harmonics, amplitudes):
    """The docstring's sum_k a_k sin(2 pi h_k t / T + phi_k) pairs each harmonic with one amplitude;
    a mismatch is the user's mistake and the message says what is expected and shows the harmonics."""
    expected = "harmonics must be distinct positive integers, one per amplitude, got " + repr(harmonics)
    with pytest.raises(InputError, match=re.escape(expected)):
        multisine(harmonics, amplitudes)


def test_multisine_returns_one_phase_per_harmonic():
    """The accepted case beside the refused ones: as many phases as harmonics, and a finite crest
    factor of at least 1 (the peak of a signal is at least its RMS)."""
    phases, crest = multisine([1, 2, 3], [1.0, 0.5, 0.25])
    assert phases.shape == (3,)
    assert math.isfinite(crest) and crest >= 1.0


@pytest.mark.parametrize("harmonics", [[0, 2], [-1, 3], [1, 1]])
def test_a_multisine_refuses_harmonics_that_are_not_distinct_positive_integers(harmonics):
    """A harmonic 0 is a constant, not a sine of the period; a negative one is a positive one with
    its phase moved; a repeated one would add two amplitudes at one frequency: each refused by
    name, never a design built on it."""
    from maglev_oc.errors import InputError
    from maglev_oc.identification.design import multisine

    with pytest.raises(InputError, match="distinct positive integers"):
        multisine(harmonics, [1.0, 1.0])
    phases, crest = multisine([1, 2], [1.0, 1.0])  # the same call with valid harmonics
    assert phases.shape == (2,) and crest > 0


# --- MultisineShape: tilt in [0, 3] ------------------------------------------------------------------
@pytest.mark.parametrize("tilt", [0.0, 1.0, 2.0, 3.0])
def test_a_multisine_accepts_every_tilt_of_the_closed_range(tilt):
    shape = MultisineShape(tilt=tilt)
    assert shape.tilt == tilt and shape.to_dict()["tilt"] == tilt


@pytest.mark.parametrize("tilt", [-1e-9, math.nextafter(3.0, math.inf), 3.5, math.inf, math.nan])
def test_a_multisine_refuses_a_tilt_outside_the_closed_range(tilt):
    with pytest.raises(InputError, match=r"tilt must be in \[0, 3\]"):
        MultisineShape(tilt=tilt)
