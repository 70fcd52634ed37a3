"""Properties of the output-error fit (``maglev_oc.identification.output_error``: multiple and single
shooting), checked against an independent tight-tolerance ODE solution, dense numpy on the KKT
matrix and fits on reordered or shifted logs:

- single shooting and a shooting segment are the response to linearly interpolated currents, and
  single shooting starts from the smoothed state at the first sample;
- the fit does not depend on the order of its logs, starts from the given constants, stops at the
  tolerance it is given and passes its window and HAC band on; the starting nodes reproduce the
  logged gap through the offset, and a shift of the gap reading moves the offset by minus the shift;
- the plain covariance is s^2 times the inverse KKT block; the residuals are counted and their RMS
  pooled over the logs;
- a too-short log, a segment that is not a positive duration and the input delays equation error
  refuses are refused with what is needed.
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from maglev_oc.data.log import Log
from maglev_oc.errors import InputError
from maglev_oc.identification import output_error
from maglev_oc.identification.constrained_gn import GaussNewtonOutcome
from maglev_oc.identification.equation_error import EquationError
from maglev_oc.identification.experiments import TWIN_TRUTH
from maglev_oc.identification.layout import CONSTANT_NAMES, GAP_OFFSET
from maglev_oc.identification.output_error import (
    DEFAULT_SEGMENT,
    MultipleShooting,
    fit_output_error,
    simulate_open_loop,
)
from maglev_oc.model.stage import StageModel
from maglev_oc.regression.covariance import frequencies_for

TRUTH = dict(zip(CONSTANT_NAMES, TWIN_TRUTH.as_array(), strict=True))


# --- output error ----------------------------------------------------------------------------------------
def test_a_too_short_log_is_refused_with_the_length_two_segments_need(model, twin_log):
    """The multiple-shooting fit needs two whole segments; a shorter log is refused with a message
    naming the length that is enough, and a log of exactly that length is accepted (one sample
    fewer is not). The length is 2 segments = 2 x 50 samples at 1 kHz = 0.1 s; the message prints
    it with ``:g`` (6 significant digits), hence the relative tolerance 1e-5."""
    dt = twin_log.sample_time
    m = round(DEFAULT_SEGMENT / dt)
    with pytest.raises(InputError) as info:
        MultipleShooting(twin_log.index_slice(0, 2 * m), model)
    found = re.search(r"a log of ([0-9.eE+-]+) s or more", str(info.value))
    assert found, str(info.value)
    needed = float(found.group(1))
    assert needed == pytest.approx(2 * DEFAULT_SEGMENT, rel=1e-5)
    samples = round(needed / dt) + 1  # a log spanning ``needed`` seconds
    ms = MultipleShooting(twin_log.index_slice(0, samples), model)
    assert [s.J for s in ms.segments] == [2]
    with pytest.raises(InputError, match="need at least 2"):
        MultipleShooting(twin_log.index_slice(0, samples - 1), model)


def test_the_residual_rms_over_two_logs_pools_both_logs(model, twin_log):
    """A fit over two logs reports one RMS per axis over the residuals of both logs and counts the
    samples of both: n_samples is the number of residual samples the result holds (NaN past the
    last segment excluded), and RMS^2 * n_samples is the sum of squares over both logs. The pooled
    RMS lies between the two logs' own (the logs are of different lengths and parts of the run, so
    their RMS differ). The solve's convergence does not matter here (two iterations from the
    truth); the tolerance 1e-9 is rounding of the sums."""
    a = twin_log.index_slice(0, 1500)
    b = twin_log.index_slice(3000, 4200)
    fit = MultipleShooting([a, b], model).fit(initial=TRUTH, max_iterations=2)
    assert len(fit.residuals) == 2
    used = [np.isfinite(r[0]) for r in fit.residuals]
    assert fit.n_samples == sum(int(u.sum()) for u in used)
    for i, axis in enumerate(("vertical", "horizontal")):
        sums = [float(np.sum(r[i, u] ** 2)) for r, u in zip(fit.residuals, used, strict=True)]
        assert fit.residual_rms[axis] ** 2 * fit.n_samples == pytest.approx(sum(sums), rel=1e-9)
        own = [math.sqrt(s / u.sum()) for s, u in zip(sums, used, strict=True)]
        assert min(own) < fit.residual_rms[axis] < max(own)


@pytest.fixture(scope="module")
def oe_fits(model, two_logs):
    """The output-error fit of two logs in both orders at a 7.5 Hz HAC band (7 frequencies of a 1 s
    log, where the default 0.25 Hz gives the minimum 4), started at the truth."""
    a, b = two_logs
    ab = MultipleShooting([a, b], model).fit(initial=TRUTH, hac_band=7.5)
    ba = fit_output_error([b, a], model, initial=TRUTH, hac_band=7.5)
    return ab, ba


def test_the_output_error_fit_does_not_depend_on_the_order_of_its_logs(oe_fits):
    # values, HAC and plain standard errors are sums over the logs; 1e-6 relative: the solver's
    # tolerance on the scaled step (1e-9) and round-off of sums in another order
    ab, ba = oe_fits
    assert ab.success and ba.success
    for k in CONSTANT_NAMES:
        assert ba.values[k] == pytest.approx(ab.values[k], rel=1e-6)
        assert ba.stderr[k] == pytest.approx(ab.stderr[k], rel=1e-6)
        assert ba.stderr_naive[k] == pytest.approx(ab.stderr_naive[k], rel=1e-6)


def test_the_output_error_hac_band_sets_the_frequencies_it_averages(oe_fits):
    # fit_output_error passes hac_band on: each log's covariance averages frequencies_for(n, T, band)
    # Fourier frequencies of its J x M fitted samples (7.5 Hz: away from a tie of band n T with an
    # integer, where the floor would depend on the last bit of a log's sample time)
    _, ba = oe_fits
    assert ba.settings["hac_band_hz"] == 7.5
    assert ba.hac_frequencies == 2 * frequencies_for(1000, 1e-3, 7.5)
    assert ba.hac_frequencies > 2 * frequencies_for(1000, 1e-3, 0.25)


def test_fit_output_error_passes_the_window_on(model, two_logs, oe_fits):
    """``window_duration`` reaches the problem: 50 ms windows (one segment each, no continuity)
    give the fit MultipleShooting gives with them (1e-9: the same computation), recorded in the
    settings, and another fit than the default 0.2 s windows (continuity moves the estimates)."""
    a, _ = two_logs
    short = fit_output_error(a, model, initial=TRUTH, window_duration=0.05)
    same = MultipleShooting(a, model, window_duration=0.05).fit(initial=TRUTH)
    default = fit_output_error(a, model, initial=TRUTH)
    assert short.settings["window_duration_s"] == 0.05 and default.settings["window_duration_s"] == 0.2
    for k in CONSTANT_NAMES:
        assert short.values[k] == pytest.approx(same.values[k], rel=1e-9)
    assert max(abs(short.values[k] / default.values[k] - 1) for k in CONSTANT_NAMES) > 1e-6


def test_the_plain_output_error_covariance_is_s2_times_the_inverse_kkt_block(model, two_logs):
    # the constrained least-squares covariance (theta block of the inverse KKT matrix) times the
    # residual variance s^2 = r'r / (residuals - (variables - constraints)), recomputed with dense
    # numpy at the fit's starting point; 1e-6 relative: a dense against a sparse LU of the same
    # matrix, which is badly scaled (2-norm condition 4e16, the node states beside the scaled
    # constants): they agree to 1e-9-2e-8 depending on the machine's BLAS. A covariance not scaled
    # by s^2 (0.62 here), or with the degrees of freedom off by the 60 constraints (3 % of 1976),
    # is off by far more
    ms = MultipleShooting(two_logs[0], model)
    theta, nodes, _ = ms._start(TRUTH)
    w = ms._pack(theta, nodes)
    r, c, Jr, Jc = ms._linearize(w)
    gn = GaussNewtonOutcome(w, r, c, Jr, Jc, "converged", "", 1)
    scale = np.array(ms.layout.scale)
    _, naive, *_ = ms._covariance(gn, scale, 0.25)
    Jr, Jc = Jr.toarray(), Jc.toarray()
    nv, nc, q = Jr.shape[1], Jc.shape[0], scale.size
    kkt = np.block([[Jr.T @ Jr, Jc.T], [Jc, np.zeros((nc, nc))]])
    s2 = float(r @ r) / (r.size - (nv - nc))
    expected = s2 * np.linalg.inv(kkt)[:q, :q] * np.outer(scale, scale)
    np.testing.assert_allclose(naive, expected, rtol=1e-6)


def test_the_output_error_counts_its_residuals(oe_fits):
    # every fitted sample gives two output residuals (gap and position), and the reduced chi-square
    # is the chi-square over the residuals less the free variables: n_residuals is what the report
    # and the JSON print as "# residuals" and what the degrees of freedom start from
    for fit in oe_fits:
        assert fit.n_residuals == 2 * fit.n_samples, (fit.n_residuals, fit.n_samples)
        dof = fit.chi_square / fit.reduced_chi_square
        assert 0 < fit.n_residuals - dof < 0.1 * fit.n_residuals


def test_the_starting_nodes_reproduce_the_logged_gap_through_the_offset(model, two_logs):
    """The output map is y = (x1 - gap_offset, x3): the node states a fit starts from carry the
    logged gap plus the starting offset, so that at every node the model's output is the reading
    (1e-15 m: one addition and one subtraction of the same number). With a 0.2 mm offset a node
    state on the wrong side of the reading would be 0.4 mm off."""
    ms = MultipleShooting(two_logs[0], model, estimate=(*CONSTANT_NAMES, "gap_offset"))
    start = {k: getattr(TWIN_TRUTH, k) for k in CONSTANT_NAMES} | {"gap_offset": 2e-4}
    theta, nodes, _ = ms._start(start)
    offset = theta[ms.layout.names.index("gap_offset")]
    assert offset == pytest.approx(2e-4, rel=1e-12)
    for sg, S in zip(ms.segments, nodes, strict=True):
        assert np.max(np.abs((S[0] - offset) - sg.nodes0[0])) < 1e-15
        assert np.array_equal(S[1:], sg.nodes0[1:])


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
    Y, s_end, _, _ = ms._segment(x0, u, [truth_model.constants.C1], [1.0, 1.0])  # (no payload)
    Y = np.asarray(Y).reshape(STEPS, 2).T  # time-major (gap, horizontal)
    np.testing.assert_allclose(Y, ref[[0, 2], :STEPS], rtol=0, atol=RK4_TOL)
    s_end = np.asarray(s_end).ravel()
    np.testing.assert_allclose(s_end[[0, 2]], ref[[0, 2], -1], rtol=0, atol=RK4_TOL)


# --- multiple shooting -------------------------------------------------------------------------------------
@pytest.mark.parametrize("delay", [0.01, 0.02, -1e-9, math.nan])
def test_multiple_shooting_refuses_the_input_delays_equation_error_refuses(model, twin_log, delay):
    """Both fits take input_delay in [0, 0.01) s (their messages say so): 10 ms is outside, as in
    EquationError."""
    with pytest.raises(InputError, match="input_delay"):
        EquationError(twin_log, model, input_delay=delay)
    with pytest.raises(InputError, match="input_delay"):
        MultipleShooting(twin_log, model, input_delay=delay)


def test_a_shift_of_the_gap_reading_moves_the_fitted_gap_offset_by_minus_the_shift(truth_model, twin_log):
    """gap_offset = true gap - reading (the fits' convention): adding 100 um to every gap reading of a
    log is the same plant seen by an encoder 100 um off, so the multiple-shooting fit of the offset
    (the other constants the twin's) moves by -100 um. The two problems are the same after the shift,
    so the estimates differ by the shift to the solver's tolerance; 1 % of the offset's standard error
    (0.3 um on 2 s) is far above that and far below the shift."""
    log = twin_log.index_slice(0, 2000)
    shift = 1e-4
    x = np.array(log.x)
    x[0] += shift
    shifted = dataclasses.replace(log, x=x)
    fits = [
        MultipleShooting(g, truth_model, estimate=(GAP_OFFSET,)).fit(initial={GAP_OFFSET: 0.0})
        for g in (log, shifted)
    ]
    assert all(f.success for f in fits)
    tol = 0.01 * fits[0].stderr[GAP_OFFSET]
    assert tol < 0.01 * shift
    assert fits[1].values[GAP_OFFSET] - fits[0].values[GAP_OFFSET] == pytest.approx(-shift, abs=tol)


# --- multiple shooting: the segment length ---------------------------------------------------------------
@pytest.fixture(scope="module")
def still_log() -> Log:
    """0.5 s at 1 kHz, the stage held at a 20 mm gap: long enough to cut into segments."""
    t = np.arange(500) / 1000.0
    x = np.vstack([np.full(t.size, 20e-3), np.zeros(t.size), np.zeros(t.size), np.zeros(t.size)])
    return Log(t, x, np.ones((2, t.size)), source="still.csv")


@pytest.mark.parametrize("segment", [0.0, -0.05, math.nan, math.inf])
def test_multiple_shooting_refuses_a_segment_that_is_not_a_positive_duration(model, still_log, segment):
    """A segment of zero, negative, NaN or infinite length cannot cut a log: refused when the problem
    is made, the message naming the option, that it must be positive, its unit and the value."""
    expected = f"segment_duration must be positive [s], got {segment!r}"
    with pytest.raises(InputError, match=re.escape(expected)):
        MultipleShooting(still_log, model, segment_duration=segment)


def test_the_output_error_fit_starts_from_the_given_constants(model, twin_log, monkeypatch):
    """1 s of the twin log, started at the true constants with no iteration allowed: the values are
    the start, exactly, and the equation-error fit that would otherwise give the start is never
    called."""

    def refused(*args, **kwargs):
        raise AssertionError("an equation-error start was fitted although one was given")

    monkeypatch.setattr(output_error, "fit_equation_error", refused)
    fit = output_error.fit_output_error(twin_log.index_slice(0, 1000), model, initial=TRUTH, max_iterations=0)
    assert [fit.values[c] for c in CONSTANT_NAMES] == [TRUTH[c] for c in CONSTANT_NAMES]


# --- the output-error fit's tolerance -------------------------------------------------------------
def test_the_output_error_fit_stops_at_the_tolerance_it_is_given(model, twin_log):
    """One second of the twin log fitted from the papers' constants at a tolerance of 1e-2 and of
    1e-9 on the scaled step: the loose fit takes no more iterations than the tight one, and a fit
    that converged on its step says so with the tolerance in force (``constrained_gn``'s message:
    "scaled step below {tolerance:g}" or the full step's size, below 1000 x tolerance)."""
    log = twin_log.index_slice(0, 1001)
    loose = MultipleShooting([log], model).fit(tolerance=1e-2, hac_band=7.5)
    tight = MultipleShooting([log], model).fit(tolerance=1e-9, hac_band=7.5)
    assert loose.success and tight.success, (loose.message, tight.message)
    assert loose.iterations <= tight.iterations
    for fit, tolerance in ((loose, 1e-2), (tight, 1e-9)):
        below = re.search(r"scaled step below (\S+),", fit.message)
        full = re.search(r"scaled step ([0-9.e+-]+), continuity", fit.message)
        assert below or full, fit.message
        if below:
            assert float(below.group(1)) == tolerance
        else:
            assert float(full.group(1)) < 1e3 * tolerance
    assert loose.iterations < tight.iterations or "below 0.01" in loose.message


def test_single_shooting_starts_from_the_smoothed_state_at_the_first_sample(generated):
    from maglev_oc.data.reading import read_log
    from maglev_oc.estimation.differentiate import SavitzkyGolay, differentiate_log
    from maglev_oc.identification.output_error import simulate_open_loop
    from tests.independent.sets import named_set

    stem = next(s for s, sc in named_set("single") if sc.name == "normal_cogging_large")
    # from 20 s on, where both axes move (the log starts at rest on the horizontal axis)
    whole = read_log(generated("single", stem)[0])
    log = whole.index_slice(round(20.0 / whole.sample_time))
    der = differentiate_log(log, SavitzkyGolay(log.sample_time))
    assert np.all(np.abs(der.velocity[:, :2]) > 1e-4)
    out = simulate_open_loop(log, StageModel(), 0.01)
    expected = [der.position[0, 0], der.velocity[0, 0], der.position[1, 0], der.velocity[1, 0]]
    np.testing.assert_array_equal(out[:, 0], expected)
