"""Properties of ``maglev_oc.identification`` written against the survivors of the seed-34 mutation-testing
run at ef280fd (issue 21): each test states a property the code should have, not the mutated token.

* signals: a clipping pass of the multisine keeps the phases of the clipped signal's harmonics
  (Van der Ouderaa et al. 1988), computed here by projection on sines and cosines; Schroeder's phases
  refuse amplitudes that are all zero (no power to share);
* multisine shapes: a shape gives exactly min(tones, harmonics in the band) distinct harmonics, and the
  reference built from it has exactly those lines in its spectrum (FFT of one whole period);
* the gap sweep refuses a lowest gap at or below 0 and a ripple that leaves no room to sweep;
* check_identifiable: an axis is excited only when both of its signals move (position and current), so a
  log with one of them flat is refused by name even among logs that move;
* identify validates with the currents shifted by ``input_delay`` (recomputed here with the shift done
  by hand: two samples at 1 kHz);
* single shooting and the multiple-shooting segments are the model's response to currents interpolated
  linearly between samples (against an independent tight-tolerance ODE solution);
* NPFSI's ``sigma_final`` is Sigma(0) + h sum (A'A - gamma^-2 Q) (the recursion's closed form);
* the study's coverage records the length of its runs; the vertical runs are centred on VERTICAL_GAP.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from maglev_oc.data.logs import Log, LogError
from maglev_oc.errors import InputError
from maglev_oc.identification import study
from maglev_oc.identification.design import (
    MultisineShape,
    crest_factor,
    gap_sweep_reference,
    multisine,
    multisine_reference,
    schroeder_phases,
)
from maglev_oc.identification.equation_error import EquationError
from maglev_oc.identification.experiments import excitation_log, verification_effects
from maglev_oc.identification.layout import CONSTANT_NAMES, GAP_OFFSET
from maglev_oc.identification.npfsi import DEFAULT_Q0_SECONDS, NpfsiEstimator
from maglev_oc.identification.output_error import MultipleShooting, simulate_open_loop
from maglev_oc.identification.pipeline import VALIDATION_BANDWIDTH, check_identifiable, identify
from maglev_oc.regression.data import prepare
from maglev_oc.sim.scenarios import excitation_scenario
from maglev_oc.validation import validate


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


# --- check_identifiable ------------------------------------------------------------------------------------
def _log(source: str, *, x1: bool, u2: bool, x3: bool, u1: bool, duration: float = 6.0) -> Log:
    """A log whose chosen signals move (0.5 Hz sines far above the resolutions) and the others do not."""
    t = np.arange(0, duration, 1e-3)
    s = np.sin(2 * np.pi * 0.5 * t)
    x = np.full((4, t.size), np.nan)
    x[0] = 0.02 + (1e-3 * s if x1 else 0.0)
    x[2] = 0.03 * s if x3 else 0.0 * t
    u = np.vstack([0.5 * s if u1 else 0.0 * t, 1.5 + (0.5 * s if u2 else 0.0 * t)])
    return Log(t, x, u, source=source)


@pytest.mark.parametrize(
    ("flat", "estimate", "column"),
    [("u2", ("C2", "C3"), "u2"), ("x1", ("C2", "C3"), "x1"), ("u1", ("C1",), "u1"), ("x3", ("C1",), "x3")],
)
def test_an_axis_with_one_flat_signal_is_not_excited(flat, estimate, column):
    """An axis is excited only when its position and its current both move (x1 and u2 vertically, x3 and u1
    horizontally: the constants multiply their products). A log with one of them flat moves on no needed
    axis and is refused by name, even when another log moves on every signal."""
    good = _log("good.csv", x1=True, u2=True, x3=True, u1=True)
    moving = {k: k != flat for k in ("x1", "u2", "x3", "u1")}
    half = _log("half.csv", **moving)
    check_identifiable([good], estimate)
    with pytest.raises(LogError, match="no excitation") as info:
        check_identifiable([good, half], estimate)
    assert info.value.source == "half.csv"
    assert info.value.column == column
    with pytest.raises(LogError, match="no excitation"):
        check_identifiable([half], estimate)


# --- identify: validation with the input delay -------------------------------------------------------------
def test_identify_validates_on_the_currents_shifted_by_the_input_delay(model, twin_log):
    """identify(input_delay=d) fits the model to the currents delayed by d, and validates the fit on the same
    delayed currents. Recomputed here with the shift done by hand (d = 2 ms = 2 samples at 1 kHz, held at
    the start). Tolerance 1e-9 relative: the validation's numbers from the same arithmetic, up to the
    round-off of the library's interpolation at t - d (about 1e-16 of the currents)."""
    d = 0.002
    out = identify(twin_log, model, methods=("equation_error",), input_delay=d)
    assert out.validation is not None
    u = np.asarray(twin_log.u, dtype=float)
    shifted = np.hstack([np.repeat(u[:, :1], 2, axis=1), u[:, :-2]])
    fit = out.equation_error
    fitted = model.with_constants(out.constants())

    def by_hand(currents):
        data = prepare([dataclasses.replace(twin_log, u=currents)], bandwidth=VALIDATION_BANDWIDTH)
        return validate(data, data.valid, fitted, [], gap_offset=fit.values.get(GAP_OFFSET, 0.0))

    expected = by_hand(shifted)
    np.testing.assert_allclose(out.validation.inputs, expected.inputs, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(out.validation.residuals, expected.residuals, rtol=1e-9, atol=1e-12)
    got, want = out.validation.fit_table(), expected.fit_table()
    for axis in want:
        for horizon, value in want[axis].items():
            assert got[axis][horizon] == pytest.approx(value, rel=1e-9, abs=1e-9), (axis, horizon)
    # the delay matters here: the unshifted currents give other residuals
    assert not np.allclose(by_hand(u).residuals, expected.residuals, rtol=1e-6, atol=0)


# --- output error: the model's response to linearly interpolated currents ----------------------------------
def _exact_response(model, x0: np.ndarray, u: np.ndarray, h: float) -> np.ndarray:
    """(4, k) states at the samples: the model driven by the currents interpolated linearly between samples,
    integrated sample by sample (the current's kinks are at the samples) by DOP853 at rtol 1e-12."""
    k = u.shape[1]
    out = np.empty((4, k))
    out[:, 0] = x = np.asarray(x0, dtype=float)
    for i in range(k - 1):
        u0, u1 = u[:, i], u[:, i + 1]

        def rhs(t, x, u0=u0, u1=u1):
            return np.asarray(model.f(x, u0 + (u1 - u0) * t / h)).ravel()

        x = solve_ivp(rhs, (0.0, h), x, method="DOP853", rtol=1e-12, atol=1e-15).y[:, -1]
        out[:, i + 1] = x
    return out


STEPS = 50
"""Samples (50 ms at 1 kHz, one shooting segment) over which the responses are compared."""
RK4_TOL = 1e-9
"""[m] RK4 at h = 1 ms on this smooth right side: global error of order h^4 times the fourth derivative,
measured 1e-12 m over 50 ms (1e-11 m/s); 1e-9 m is 1e-4 of the encoder's 10 um count. A current taken at
the wrong point of the step is a first-order error, far above it."""


@pytest.fixture(scope="module")
def exact(truth_model, twin_log):
    x0 = np.array([0.02, 0.0, 0.0, 0.0])
    x0[0], x0[2] = twin_log.x[0, 0], twin_log.x[2, 0]
    u = np.asarray(twin_log.u[:, : STEPS + 1], dtype=float)
    return x0, u, _exact_response(truth_model, x0, u, twin_log.sample_time)


def test_single_shooting_is_the_response_to_linearly_interpolated_currents(truth_model, twin_log, exact):
    """simulate_open_loop: RK4 per sample with the logged currents interpolated linearly between samples
    (its docstring, 'as in the fit'), against the tight ODE solution."""
    x0, _, ref = exact
    sim = simulate_open_loop(twin_log, truth_model, STEPS * twin_log.sample_time, x0=x0)
    assert sim.shape == ref.shape
    np.testing.assert_allclose(sim[[0, 2]], ref[[0, 2]], rtol=0, atol=RK4_TOL)
    np.testing.assert_allclose(sim[[1, 3]], ref[[1, 3]], rtol=0, atol=RK4_TOL / twin_log.sample_time)


def test_a_shooting_segment_is_the_response_to_linearly_interpolated_currents(truth_model, twin_log, exact):
    """The multiple-shooting fit's segment simulation (module docstring: RK4 per sample, the logged currents
    interpolated linearly) with the model's own constants is the model's response: outputs (gap, horizontal)
    at the samples and the state at the segment's end, against the tight ODE solution."""
    x0, u, ref = exact
    segment = STEPS * twin_log.sample_time
    ms = MultipleShooting(twin_log, truth_model, estimate=("C1",), segment_duration=segment)
    assert ms.M == STEPS
    Y, s_end, _, _ = ms._segment(x0, u, [truth_model.constants.C1])
    Y = np.asarray(Y).reshape(STEPS, 2).T  # time-major (gap, horizontal)
    np.testing.assert_allclose(Y, ref[[0, 2], :STEPS], rtol=0, atol=RK4_TOL)
    s_end = np.asarray(s_end).ravel()
    np.testing.assert_allclose(s_end[[0, 2]], ref[[0, 2], -1], rtol=0, atol=RK4_TOL)


# --- NPFSI: Sigma at the end ------------------------------------------------------------------------------
@pytest.mark.parametrize("given_q", [False, True])
def test_npfsi_sigma_final_is_the_closed_form_of_its_recursion(given_q):
    """Sigma' = A'A - gamma^-2 Q, stepped as Sigma_{k+1} = Sigma_k + h (A_k'A_k - gamma^-2 Q) over the n - 1
    steps of n samples, from Sigma(0) = Q0 (default 1 ms times the diagonal of the mean A'A; Q default A'A).
    Tolerance 1e-11 relative: round-off of sums of 60 terms."""
    rng = np.random.default_rng(34)
    n, m, p, h, gamma = 60, 2, 3, 1e-3, 1.1
    A = rng.normal(size=(n, m, p))
    b = rng.normal(size=(n, m))
    y = 0.01 * rng.normal(size=(n, m))
    Q = np.diag([0.5, 1.0, 2.0]) if given_q else None
    run = NpfsiEstimator(0.01, gamma, Q=Q).run(A, b, y, h, np.zeros(p))
    ata = np.einsum("nij,nik->njk", A, A)
    q0 = DEFAULT_Q0_SECONDS * np.diag(np.diag(ata.mean(axis=0)))
    if given_q:
        expected = q0 + h * ata[:-1].sum(axis=0) - h * (n - 1) * Q / gamma**2
    else:
        expected = q0 + h * (1 - gamma**-2) * ata[:-1].sum(axis=0)
    assert run.sigma_final.shape == (p, p)
    np.testing.assert_allclose(run.sigma_final, expected, rtol=1e-11, atol=0)
    np.testing.assert_allclose(run.Q0, q0, rtol=1e-12)
    assert run.success == bool(np.linalg.eigvalsh(expected).min() > 0)


# --- the identification study ------------------------------------------------------------------------------
def test_the_coverage_records_the_length_of_its_runs(model, truth_model):
    """Coverage.duration is how long each coverage run is (the report prints 'k x duration s'): one run of
    5 s, seed 100, whose z-scores are those of an equation-error fit on a 5 s twin run of that seed made here
    (same arithmetic: equal to round-off, 1e-9)."""
    cov = study._coverage(study._Clock(), model, truth_model, 1, 5.0)
    assert cov.duration == 5.0 and f"{cov.duration:g}" == "5"
    assert cov.seeds == (100,) and cov.z.shape == (1, len(CONSTANT_NAMES))
    log = excitation_log(truth_model, duration=5.0, seed=100, controller_model=model)
    tv = dict(zip(CONSTANT_NAMES, truth_model.constants.as_array(), strict=True))
    z = EquationError(log, model).fit().z_scores(tv)
    np.testing.assert_allclose(cov.z[0], [z[k] for k in CONSTANT_NAMES], rtol=1e-9, atol=1e-12)


def test_the_vertical_runs_are_centred_on_the_vertical_gap(model, truth_model):
    """The vertical-only runs excite about VERTICAL_GAP (16 mm, where the cogging acts): the logged gap
    follows the papers' sum-of-sines reference centred there. Tolerance 0.5 mm on the mean gap against the
    reference's mean: the PIDs' tracking error (measured 0.3 mm RMS, its mean 4 um), well below the 4 mm to
    the default 20 mm centre."""
    out = study._vertical_runs(study._Clock(), model, truth_model, verification_effects(), 5.0, 1)
    for key, offset in (("vertical_log", 1), ("cogging_log", 2)):
        log = out[key]
        scenario = excitation_scenario(5.0, seed=1 + offset, gap_offset=study.VERTICAL_GAP)
        ref = scenario.reference.sample(log.t)[0]
        assert abs(np.mean(log.x[0]) - np.mean(ref)) < 0.5e-3, key
