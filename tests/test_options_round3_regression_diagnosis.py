"""Options of ``maglev_oc.regression`` and ``maglev_oc.diagnosis`` that no test passed by name (issue
21: "tests that would catch a wrong answer", third round): for each, a property the option must
give, checked against an independent computation (a closed form, numpy by hand, the term's own
CasADi function), so that the option ignored (its default used) or inverted fails here. Every
tolerance's origin is written beside it. Small synthetic logs throughout; about 7 s for the file.

Regression layer:

* ``reduce_rate(max_rate=)`` and ``prepare(max_rate=)`` reduce by means over the fewest q samples
  that bring the rate to at most ``max_rate``, and a q-sample mean carries 1/q of the logging
  error's share;
* ``PreparedLogs.filter(inplace=)`` overwrites and returns its argument only when asked, with the
  same values as numpy's own per-log 'same' convolution;
* ``build_design(block_seconds=)`` cuts the fitted samples into blocks of that length, each
  block's Gram the X'X of its own rows, their sum the same for every block length; the block sums
  are the normal equations of every fitted sample once (a fault of ``_blocks`` found here, now
  fixed, dropped one block's samples and counted the next twice when a run's last piece was
  shorter than half a block);
* ``predicted(group=)`` is that group's filtered acceleration at its fitted coefficients (the
  term's CasADi function evaluated and filtered here), and the groups' predictions add up to
  the fit's;
* ``is_linear_in_parameters(parameter_input=)`` asks about the input it names;
* ``guide_friction(stick_speed=)``: the holding column falls to 1/e of the modelled acceleration at
  the stick speed (its variants' at the stick speed scaled as their reversal speed), default the
  reversal speed, and a speed that is not positive is refused;
* ``cogging_force(harmonics=, decay_scale=, scale_variants=)``: k = 1..harmonics sines of period
  P / k, the k-th decaying as exp(-2 pi k (x1 - g_ref) / (decay_scale P)) (Laplace in the gap),
  the variants' decay lengths scaled by ``scale_variants``.

Diagnosis:

* ``fmt(digits=)`` writes the value to that many significant digits, the error to one;
* ``refine_waviness_period(points=, span=)`` returns the best of the ``points`` periods within
  +-``span`` of the guess (a residual made of a waviness's own columns at a known period);
* the generic probes' Legendre columns are mean-free over the fitted samples, each variable
  about its own mean (the closure's ``means``);
* ``converged_references(max_rounds=, tolerance=)`` stops after ``max_rounds`` joint fits, or
  once the constants move by less than ``tolerance``; one round is the hand-built joint fit;
* ``trace(min_share=)`` and ``traces(min_share=)`` report no periodogram peak below
  ``min_share`` and the planted one above it;
* the selection's verdict refuses a motor-period force seen over fewer than ``min_periods``
  periods of travel (``periods_seen``) or beside an effect whose period the travel does not tell
  from its own (``unresolved``), and passes it otherwise;
* ``SelectionSettings.cross_parts``: zero judges on the held-out quarter alone, k pools the
  held-out quarter with k cross-fitted parts of the training data;
* ``SelectionSettings.parameter_penalty``: the choice, and every bootstrap vote, maximizes the gain
  less the penalty per reported coefficient (a one-harmonic force nested in a two-harmonic
  cogging wins beyond the gain per coefficient); ``max_effects`` stops after that many steps.
"""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose

import maglev_oc.diagnosis.refit as refit_module
from maglev_oc.data.logs import Log
from maglev_oc.diagnosis.candidate import Candidate, fmt
from maglev_oc.diagnosis.guides import refine_waviness_period, waviness_candidate
from maglev_oc.diagnosis.library import candidate_library
from maglev_oc.diagnosis.probes import PROBE_ORDER, smooth_probes
from maglev_oc.diagnosis.refit import converged_references, fitted_model
from maglev_oc.diagnosis.selection import (
    SMOOTH_POSITION,
    SelectionSettings,
    _CrossFit,
    _CrossParts,
    _verdict,
    judge,
    select,
)
from maglev_oc.diagnosis.trace import trace, traces
from maglev_oc.errors import InputError
from maglev_oc.model.parameters import LumpedConstants, StageParameters
from maglev_oc.regression.data import prepare, reduce_rate
from maglev_oc.regression.design import _blocks, build_design
from maglev_oc.regression.solve import fit_subset, predicted, residuals
from maglev_oc.regression.terms import cogging_force, guide_friction, is_linear_in_parameters, periodic_force
from maglev_oc.results import Estimate
from tests.test_diagnosis_injected_properties import _judgement
from tests.test_diagnosis_selection_properties import cogged_design
from tests.test_statistics_properties import RATE_FRICTION, _log


@pytest.fixture(scope="module")
def cogged(model):
    """(design, library by name): the horizontal sweep with a slot-pitch cogging planted
    (:func:`tests.test_diagnosis_selection_properties.cogged_design`), a quarter held out."""
    return cogged_design(model)


@pytest.fixture(scope="module")
def friction_data(model):
    """The 30 s horizontal sweep with viscous friction planted, prepared at a 10 Hz band."""
    return prepare([_log(model, friction=RATE_FRICTION)], bandwidth=10.0)


def _both_axes_log(seconds: float = 8.0, rate: float = 1000.0, seed: int = 0) -> Log:
    """A log moving on both axes: gap and position sums of two sines (periods of seconds, well inside
    a 10 Hz band), currents around equilibrium with a little white noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * rate)) / rate
    x = np.full((4, t.size), np.nan)
    x[0] = 0.020 + 1.0e-3 * np.sin(2 * math.pi * 0.4 * t) + 0.4e-3 * np.sin(2 * math.pi * 1.1 * t + 1.0)
    x[2] = 0.030 * np.sin(2 * math.pi * 0.23 * t) + 0.008 * np.sin(2 * math.pi * 0.9 * t + 0.3)
    u = np.vstack([0.5 * np.sin(2 * math.pi * 0.3 * t), 1.5 + 0.2 * np.sin(2 * math.pi * 0.7 * t)])
    u = u + 1e-3 * rng.standard_normal(u.shape)
    return Log(t, x, u, source=f"both axes seed {seed}")


# --- regression/data.py --------------------------------------------------------------------------------
@pytest.mark.parametrize(("max_rate", "q"), [(250.0, 4), (300.0, 4), (500.0, 2), (1000.0, 1), (2000.0, 1)])
def test_reduce_rate_uses_the_fewest_samples_per_mean_that_reach_max_rate(max_rate, q):
    """A 1 kHz log at ``max_rate``: q = ceil(1000 / max_rate) samples per mean (q - 1 would leave the
    rate above it), each reduced sample the numpy mean of its q samples, the incomplete tail dropped."""
    log = _both_axes_log(seconds=1.0, seed=1)
    log = dataclasses.replace(log, t=log.t[:-1], x=log.x[:, :-1], u=log.u[:, :-1])  # 999: a tail
    reduced, got = reduce_rate(log, max_rate=max_rate)
    assert got == q
    assert 1.0 / reduced.sample_time <= max_rate * (1 + 1e-9)
    if q > 1:
        assert 1000.0 / (q - 1) > max_rate  # fewest samples: one fewer would be too fast
    n = (log.n // q) * q
    # block means by numpy's reshape (exact to rounding: 1e-12 relative)
    assert_allclose(reduced.u, log.u[:, :n].reshape(2, -1, q).mean(axis=2), rtol=1e-12, atol=1e-15)
    assert_allclose(reduced.t, log.t[:n].reshape(-1, q).mean(axis=1), rtol=1e-12)
    assert reduced.n == n // q


def test_prepare_reduces_to_max_rate_and_keeps_the_logging_error_share():
    """prepare(max_rate=): a 1 kHz log of commands from a 5 kHz loop (logging-error share 1 - 1/5)
    prepared at max_rate 250 Hz is reduced by 4-sample means (sample time 4 ms, a quarter of the
    samples, the setting reported); the share is the logging's, the same after the means (they
    divide the error's variance and the floor it is a share of alike: the floor is measured on the
    reduced log, tests/test_regression_reduced_noise.py); at max_rate 1000 Hz nothing is reduced."""
    log = _both_axes_log(seconds=8.0, seed=2)
    kept = prepare([log], bandwidth=5.0, max_rate=1000.0)
    reduced = prepare([log], bandwidth=5.0, max_rate=250.0)
    assert kept.sample_time == pytest.approx(1e-3, rel=1e-9)
    assert reduced.sample_time == pytest.approx(4e-3, rel=1e-9)
    assert reduced.n == log.n // 4 and kept.n == log.n
    assert reduced.settings["max_rate_hz"] == 250.0
    assert kept.settings["logging_error_share"] == [pytest.approx(0.8, rel=1e-12)]
    assert reduced.settings["logging_error_share"] == [pytest.approx(0.8, rel=1e-12)]


def test_filter_overwrites_its_argument_only_in_place_and_is_the_per_log_convolution():
    """PreparedLogs.filter: F convolved with each log's samples ('same', zero outside the log; numpy's
    direct convolution here against the code's FFT: 1e-10 of the columns' size is far above the FFT's
    rounding); ``inplace=True`` returns the argument itself, overwritten; without it the argument is
    untouched and a new array returned."""
    logs = [_both_axes_log(seconds=3.0, seed=s) for s in (3, 4)]
    data = prepare(logs, bandwidth=10.0)
    rng = np.random.default_rng(0)
    cols = rng.standard_normal((3, 2, data.n))
    original = cols.copy()
    want = np.empty_like(cols)
    for start, stop in data.segment_bounds:
        for idx in np.ndindex(cols.shape[:-1]):
            want[(*idx, slice(start, stop))] = np.convolve(
                original[idx][start:stop], data.kernel, mode="same"
            )
    copy = data.filter(cols)
    assert copy is not cols
    assert np.array_equal(cols, original)  # not in place: the argument is left as it was
    assert_allclose(copy, want, rtol=0, atol=1e-10)
    same = data.filter(cols, inplace=True)
    assert same is cols  # in place: the argument itself, overwritten
    assert_allclose(cols, want, rtol=0, atol=1e-10)
    assert not np.allclose(cols, original)


# --- regression/design.py --------------------------------------------------------------------------------
@pytest.mark.parametrize("block_seconds", [0.3, 0.4])
def test_build_design_cuts_the_fitted_samples_into_blocks_of_block_seconds(
    friction_data, model, block_seconds
):
    """build_design(block_seconds=): blocks of round(block_seconds / T) fitted samples (a last piece
    shorter than half a block would join its predecessor: at 0.3 and 0.4 s the fitted run of 22 354
    samples leaves 154 and 354, not shorter), each block's Gram the X'X of its own weighted rows, and
    the blocks' Grams summing to the same total X'X whatever their length (1e-9: rounding of sums of
    a few thousand products)."""
    data = friction_data
    train, hold = data.masks(0.25)
    kw = dict(estimate=("C1",), fit=train, holdout=hold, weights=np.array([0.0, 1.0]))
    d = build_design(data, model, block_seconds=block_seconds, **kw)
    default = build_design(data, model, **kw)
    size = round(block_seconds / data.sample_time)
    assert d.block_seconds == pytest.approx(size * data.sample_time, rel=1e-12)
    counts = np.bincount(d.block_of[d.block_of >= 0])
    assert counts.size == d.gram.shape[0] == math.ceil(np.sum(d.fit) / size)
    assert np.all(counts[:-1] == size) and 0 < counts[-1] <= size
    assert np.array_equal(d.block_of >= 0, d.fit)
    for b in (0, counts.size // 2, counts.size - 1):
        x = d.columns[:, 1, d.block_of == b]
        assert_allclose(d.gram[b], x @ x.T, rtol=1e-9)
    assert_allclose(d.gram.sum(axis=0), default.gram.sum(axis=0), rtol=1e-9)
    assert d.gram.shape[0] != default.gram.shape[0]  # really another cut than the default 0.5 s


@pytest.mark.parametrize("block_seconds", [1.0, 0.25])
def test_the_block_sums_are_the_normal_equations_of_every_fitted_sample_once(
    friction_data, model, block_seconds
):
    """Whatever ``block_seconds``, every fitted sample is in exactly one block and the blocks' Grams
    and right-hand sides sum to X'X and X'y over the fitted rows (numpy on the rows; 1e-9 rounding).
    At 1 s (0.25 s) the fitted run of 22 354 samples ends in a piece of 354 (104) samples, shorter
    than half a block, which joins its predecessor."""
    data = friction_data
    train, hold = data.masks(0.25)
    d = build_design(
        data,
        model,
        estimate=("C1",),
        fit=train,
        holdout=hold,
        weights=np.array([0.0, 1.0]),
        block_seconds=block_seconds,
    )
    x, y = d.columns[:, 1, d.fit], d.target[1, d.fit]
    assert_allclose(d.gram.sum(axis=0), x @ x.T, rtol=1e-9)
    assert_allclose(d.rhs.sum(axis=0), x @ y, rtol=1e-9)
    assert np.array_equal(d.block_of >= 0, d.fit)


@pytest.mark.parametrize("seed", range(8))
def test_blocks_cover_every_fitted_sample_once_within_its_run(seed):
    """``_blocks`` on random masks and logs: the blocks, joined, are the fitted samples in order, each
    once; no block crosses a log or a gap in the mask; every block but a run's only one holds between
    half a block and one and a half blocks (a last piece under half a block joins its predecessor).
    A run of 1-1.5 blocks is the case where the merge's target index matters most (the fault's pop
    left one piece, and ``pieces[-2]`` raised IndexError)."""
    rng = np.random.default_rng(seed)
    n, size = 400, 16
    fit = rng.random(n) > 0.03  # gaps of one or two samples, runs of tens
    fit[rng.integers(0, n, 3)] = False
    segment = np.repeat(np.arange(3), [150, 21, 229])  # the middle log: one 1.3-block run
    blocks = _blocks(fit, segment, size)
    joined = np.concatenate(blocks)
    assert np.array_equal(joined, np.flatnonzero(fit))
    for b in blocks:
        assert np.all(np.diff(b) == 1) and np.unique(segment[b]).size == 1
        assert b.size <= size + size // 2
    idx = np.flatnonzero(fit)
    runs = np.split(idx, np.flatnonzero((np.diff(idx) > 1) | (np.diff(segment[idx]) != 0)) + 1)
    assert len(blocks) == sum(max(1, r.size // size + (r.size % size >= size // 2)) for r in runs)


def test_blocks_of_a_short_tail_join_the_block_before():
    """Nine samples in blocks of four: [0..3], [4..8] (the tail [8] joins [4..7]); five samples: one
    block of five."""
    blocks = _blocks(np.ones(9, bool), np.zeros(9, int), 4)
    assert [b.tolist() for b in blocks] == [[0, 1, 2, 3], [4, 5, 6, 7, 8]]
    assert [b.tolist() for b in _blocks(np.ones(5, bool), np.zeros(5, int), 4)] == [[0, 1, 2, 3, 4]]


# --- regression/solve.py --------------------------------------------------------------------------------
def test_the_prediction_of_one_group_is_its_terms_filtered_acceleration_at_the_fitted_coefficients(cogged):
    """predicted(design, fit, group): the term's own acceleration (its CasADi function at the fitted
    coefficients, evaluated at every sample and filtered by F) — not the whole fit's prediction and
    not another group's; the groups' predictions add up to the fit's (linear terms linearized at
    zero: columns x coefficients is the whole term). 1e-9 of the prediction's size: the same filter
    on the same values, summed in another order."""
    design, lib = cogged
    fit = fit_subset(design, list(design.groups), covariance=False)
    data = design.prepared
    total = predicted(design, fit)
    parts = []
    for name in ("cogging_horizontal_19mm", "guide_friction_horizontal"):
        term = lib[name].term
        coef, _ = fit.group(design, name)
        acc = np.asarray(term.acceleration(coef).map(data.n)(data.x, data.u, data.du))
        want = data.filter(acc)
        got = predicted(design, fit, group=name)
        scale = np.max(np.abs(want))
        assert scale > 0
        assert_allclose(got, want, rtol=0, atol=1e-9 * scale)
        assert np.max(np.abs(got - total)) > 1e-3 * np.max(np.abs(total))  # not the whole prediction
        parts.append(got)
    parts.append(predicted(design, fit, group="base"))
    assert_allclose(sum(parts), total, rtol=0, atol=1e-9 * np.max(np.abs(total)))
    assert_allclose(total, design.target - residuals(design, fit), rtol=0, atol=1e-12 * np.max(np.abs(total)))


# --- regression/terms.py --------------------------------------------------------------------------------
def test_is_linear_in_parameters_asks_about_the_input_it_names():
    """f(a, b) = a b^2 is linear in a (input 0) and not in b (the last input, the default); g(a, b) =
    a^2 b the other way round."""
    a, b = ca.SX.sym("a"), ca.SX.sym("b")
    f = ca.Function("f", [a, b], [a * b**2])
    g = ca.Function("g", [a, b], [a**2 * b])
    assert is_linear_in_parameters(f, parameter_input=0)
    assert not is_linear_in_parameters(f, parameter_input=1)
    assert not is_linear_in_parameters(f)
    assert not is_linear_in_parameters(g, parameter_input=0)
    assert is_linear_in_parameters(g, parameter_input=1)
    assert is_linear_in_parameters(g)


def _holding_factor(fn: ca.Function, v: float) -> float:
    """The horizontal holding column of a friction function with holding(x, u) = 1 m/s^2, at velocity v:
    -exp(-(v / v_s)^2) (parameters coulomb = viscous = 0, holding = 1)."""
    x = [0.02, 0.0, 0.0, v]
    return float(fn(x, [0.0, 1.5], [0.0, 0.0], [0.0, 0.0, 1.0])[1])


def test_the_guides_hold_the_axis_up_to_the_stick_speed_scaled_with_the_variants():
    """guide_friction(stick_speed=): the share held falls as exp(-(v / v_s)^2), so the holding column
    is -1/e of the modelled acceleration at v = v_s (closed form; 1e-12 rounding). The variants at
    reversal speeds v_r / 2 and 2 v_r scale the stick speed alike; without a stick speed it is the
    reversal speed; a stick speed that is not positive is refused."""
    params = StageParameters()
    one = lambda x, u: 1.0  # noqa: E731  the modelled acceleration: 1 m/s^2
    term = guide_friction(params, "horizontal", holding=one, stick_speed=1e-3)
    assert _holding_factor(term.function, 1e-3) == pytest.approx(-math.exp(-1), rel=1e-12)
    assert _holding_factor(term.function, 2e-3) == pytest.approx(-math.exp(-4), rel=1e-12)
    half, double = term.variants  # reversal speed 1 and 4 mm/s: stick speed 0.5 and 2 mm/s
    assert _holding_factor(half, 0.5e-3) == pytest.approx(-math.exp(-1), rel=1e-12)
    assert _holding_factor(double, 2e-3) == pytest.approx(-math.exp(-1), rel=1e-12)
    default = guide_friction(params, "horizontal", holding=one, reversal_speed=4e-3)
    assert _holding_factor(default.function, 4e-3) == pytest.approx(-math.exp(-1), rel=1e-12)
    for bad in (0.0, -1e-3):
        with pytest.raises(InputError, match="stick_speed"):
            guide_friction(params, "horizontal", holding=one, stick_speed=bad)


def _cogging_column(fn: ca.Function, n_p: int, j: int, gap: float, x3: float, axis: int) -> float:
    p = np.zeros(n_p)
    p[j] = 1.0
    return float(fn([gap, 0.0, x3, 0.0], [0.0, 1.5], [0.0, 0.0], p)[axis])


def test_cogging_has_the_harmonics_asked_for_each_decaying_with_its_own_length():
    """cogging_force(harmonics=3, decay_scale=2, scale_variants=(0.5, 3)): parameters sin_k, cos_k for
    k = 1..3; the k-th column at the reference gap is sin / cos(2 pi k x3 / P) / M_h (horizontal: F
    along +x3), and at 1 mm more gap it is exp(-2 pi k 1 mm / (decay_scale P)) of that (a field
    harmonic of wavelength P / k decays so away from its source); the variants' decay lengths are
    decay_scale x 0.5 and x 3; the reported decay length is decay_scale P / (2 pi). Closed forms
    (1e-12 rounding)."""
    params = StageParameters()
    period, g_ref = 0.019, 0.015
    term = cogging_force(
        params, "horizontal", period, harmonics=3, decay_scale=2.0, scale_variants=(0.5, 3.0)
    )
    assert term.parameter_names == ("sin1", "cos1", "sin2", "cos2", "sin3", "cos3")
    m, x3, dg = params.mass_horizontal, 0.0123, 1e-3
    for k in (1, 2, 3):
        arg = 2 * math.pi * k * x3 / period
        for j, base in ((2 * k - 2, math.sin(arg)), (2 * k - 1, math.cos(arg))):
            at_ref = _cogging_column(term.function, 6, j, g_ref, x3, 1)
            assert at_ref == pytest.approx(base / m, rel=1e-12)
            for fn, scale in ((term.function, 2.0), (term.variants[0], 1.0), (term.variants[1], 6.0)):
                ratio = _cogging_column(fn, 6, j, g_ref + dg, x3, 1) / at_ref
                assert ratio == pytest.approx(math.exp(-2 * math.pi * k * dg / (scale * period)), rel=1e-12)
    assert len(term.variants) == 2 and term.variant_note == "decay length x0.5-x3"
    phys = term.physical_parameters(np.ones(6), np.eye(6))
    assert phys["decay_length"].value == pytest.approx(2.0 * period / (2 * math.pi), rel=1e-12)
    assert "harmonic3_amplitude" in phys
    # no variants asked for: none made
    assert cogging_force(params, "horizontal", period, scale_variants=()).variants == ()


# --- diagnosis/candidate.py ------------------------------------------------------------------------------
def test_fmt_writes_the_value_to_the_digits_asked_for_and_the_error_to_one():
    e = Estimate(1.23456, 0.0123, "N")
    assert fmt(e, digits=4) == "1.235 ± 0.01 N"
    assert fmt(e, digits=3) == "1.23 ± 0.01 N"
    assert fmt(e) == "1.2 ± 0.01 N"
    assert fmt(e, digits=1) == "1 ± 0.01 N"
    assert fmt(Estimate(12345.6, 210.0, "um"), digits=3) == "12300 ± 200 um"


# --- diagnosis/guides.py -----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def waviness_residual(model, friction_data):
    """(data, residual, weights, fit, true period): the filtered acceleration of a guide waviness of
    30 mm (0.1 mm amplitude) on the friction sweep, from the waviness candidate's own term."""
    data = friction_data
    train, hold = data.masks(0.25)
    period = 0.030
    cand = waviness_candidate(model, data, period)
    d = build_design(data, model, estimate=(), terms=[cand.term], fit=train, holdout=hold, weights=np.ones(2))
    residual = np.einsum("p,pan->an", np.array([1e-4, 0.3e-4]), d.columns)
    return data, residual, np.array([0.0, 1.0]), train, period


@pytest.mark.parametrize(
    ("points", "span", "grid"),
    [
        (41, 0.25, None),  # the true period 1.2 x the guess is a grid point: found
        (3, 0.25, (0.75, 1.0, 1.25)),  # nearest of three: 1.25
        (41, 0.1, None),  # the scan ends at 1.1 x the guess, nearest the truth
        (5, 0.1, (0.9, 0.95, 1.0, 1.05, 1.1)),
    ],
)
def test_the_waviness_period_is_the_best_of_the_points_scanned_within_the_span(
    model, waviness_residual, points, span, grid
):
    """refine_waviness_period(points=, span=): the residual is a waviness of period P exactly, the
    guess P / 1.2; the answer is the scanned period (guess x linspace(1 - span, 1 + span, points))
    nearest P — P itself when it is on the grid (1e-9: linspace's rounding)."""
    data, residual, weights, fit, period = waviness_residual
    guess = period / 1.2
    got = refine_waviness_period(model, data, residual, weights, fit, guess, points=points, span=span)
    scanned = guess * np.linspace(1 - span, 1 + span, points)
    if grid is not None:
        assert_allclose(scanned / guess, grid, rtol=1e-12)
    nearest = scanned[np.argmin(np.abs(scanned - period))]
    assert got == pytest.approx(nearest, rel=1e-9)
    assert np.min(np.abs(scanned - got)) <= 1e-9 * got  # one of the scanned periods


# --- diagnosis/probes.py ------------------------------------------------------------------------------------
def test_the_generic_probes_legendre_columns_are_mean_free_over_the_fitted_samples():
    """smooth_probes: on each axis and for each state variable, the columns of Legendre orders 1..4
    average to zero over the fitted (valid) samples — each about its own variable's means (the gap's
    and the position's Legendre means differ: 1e-9 of the column's RMS is rounding, a mean left in is
    several per cent); the horizontal probe's constant column is one on that axis."""
    data = prepare([_both_axes_log(seconds=8.0, seed=5)], bandwidth=10.0)
    probes = smooth_probes(data)
    x = data.x[:, data.valid]
    n = x.shape[1]
    zeros = np.zeros((2, n))
    for (axis, var), term in probes.items():
        a = 0 if axis == "vertical" else 1
        cols = np.asarray(term.features.map(n)(x, data.u[:, data.valid], zeros))  # (2, k n)
        cols = cols.reshape(2, n, term.n_parameters)
        for i in range(PROBE_ORDER):
            col = cols[a, :, i]
            rms = float(np.sqrt(np.mean(col**2)))
            assert rms > 0.05, (axis, var, i)  # a real column (Legendre values of order 1)
            assert abs(np.mean(col)) <= 1e-9 * rms, (axis, var, i)
            assert np.all(cols[1 - a, :, i] == 0.0)
        if axis == "horizontal":
            assert np.all(cols[1, :, PROBE_ORDER] == 1.0)


# --- diagnosis/refit.py ------------------------------------------------------------------------------------
@pytest.fixture()
def count_rounds(monkeypatch):
    """A list that grows by one at every joint fit converged_references builds."""
    rounds = []
    real = refit_module.build_design

    def spy(*args, **kw):
        rounds.append(1)
        return real(*args, **kw)

    monkeypatch.setattr(refit_module, "build_design", spy)
    return rounds


def test_the_references_converge_within_max_rounds_and_stop_at_the_tolerance(
    model, friction_data, count_rounds
):
    """converged_references: started from references with C1 10 % off the log's, the first joint fit
    moves C1 back by about 10 %, and the second confirms it (the holding column is the modelled
    acceleration with the references' C1, whose scale its own coefficient absorbs: the first fit is
    already the fixed point). One round (``max_rounds=1``) is the hand-built joint fit at the given
    references; with a tolerance of 50 % it stops after that round too; with the default tolerance
    (1e-3) it takes the second; with a tolerance no change can meet, exactly ``max_rounds``."""
    data = friction_data
    train, hold = data.masks(0.25)
    weights = np.array([0.0, 1.0])
    c = model.constants
    off = model.with_constants(LumpedConstants(1.1 * c.C1, c.C2, c.C3, c.C4))
    chosen = ["guide_friction_horizontal"]

    def run(**kw):
        count_rounds.clear()
        out = converged_references(model, off, data, chosen, train, hold, weights, **kw)
        return np.asarray(out.constants.as_array(), dtype=float), len(count_rounds)

    one, n1 = run(max_rounds=1)
    assert n1 == 1
    # the same joint fit by hand: the library at the off references, the chosen term's columns
    lib = {cand.name: cand for cand in candidate_library(off, data)}
    d = build_design(data, off, terms=[lib[chosen[0]].term], fit=train, holdout=hold, weights=weights)
    by_hand = fitted_model(model, fit_subset(d, list(d.groups), covariance=False), data.moving, "by hand")
    assert_allclose(one, np.asarray(by_hand.constants.as_array(), dtype=float), rtol=1e-12)
    assert one[0] == pytest.approx(c.C1, rel=0.02)  # back near the log's C1 (it moved 10 %)
    loose, n_loose = run(max_rounds=5, tolerance=0.5)
    assert n_loose == 1 and np.array_equal(loose, one)
    full, n_full = run()
    assert n_full == 2
    assert_allclose(full, one, rtol=1e-9)  # the fixed point (1e-9: the refit's rounding)
    _, n_never = run(max_rounds=3, tolerance=-1.0)
    assert n_never == 3


# --- diagnosis/trace.py ------------------------------------------------------------------------------------
PLANTED_PERIODS = (0.020, 0.027)
"""[m] The periods of the sines in x3 of the two traced residuals."""


def _traced_residuals(n: int = 6000, seed: int = 0):
    """(x, du, residuals): a horizontal sweep over 80 mm and two residuals, each a sine in x3 of its
    period in :data:`PLANTED_PERIODS` (unit amplitude, variance 1/2) plus white noise of variance 1
    on the horizontal axis (share explained at the period about 1/3) and pure noise on the vertical."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-3
    x = np.zeros((4, n))
    x[0] = 0.02
    x[2] = 0.04 * np.sin(2 * math.pi * 0.37 * t)
    x[3] = np.gradient(x[2], 1e-3)
    du = rng.standard_normal((2, n))
    out = []
    for period in PLANTED_PERIODS:
        r = rng.standard_normal((2, n))
        r[1] += np.sin(2 * math.pi * x[2] / period)
        out.append(r)
    return x, du, out


@pytest.mark.parametrize("min_share", [0.1, 0.5])
def test_a_trace_reports_no_peak_below_min_share_and_the_planted_one_above_it(min_share):
    """trace(min_share=) and traces(min_share=): every reported peak explains at least ``min_share``
    of its axis's variance; each planted sine (share 0.5 / 1.5 = 1/3 of the horizontal residual, give
    or take the noise's 1/n) is reported at its own period at 0.1, not at 0.5; the vertical noise
    (shares of order 2/n) never. Each of ``traces`` is the ``trace`` of its own residual, to the bit."""
    x, du, residuals_ = _traced_residuals()
    params = StageParameters()
    many = traces(x, du, residuals_, params, 1e-3, min_share=min_share)
    assert len(many) == len(residuals_)
    for tr, residual, period in zip(many, residuals_, PLANTED_PERIODS, strict=True):
        one = trace(x, du, residual, params, 1e-3, min_share=min_share)
        assert np.array_equal(tr.spectrum, one.spectrum) and tr.peaks == one.peaks
        share = float(np.max(tr.spectrum[1]))
        assert share == pytest.approx(1 / 3, abs=0.05)  # 3 sigma of the noise's share at n = 6000
        assert all(s >= min_share for _, _, s in tr.peaks)
        horizontal = [p for a, p, s in tr.peaks if a == "horizontal"]
        if min_share < share:
            # the strongest peak at the planted period (the periods' grid is 1.2 % apart)
            strongest = max((s, p) for a, p, s in tr.peaks if a == "horizontal")[1]
            assert strongest == pytest.approx(period, rel=0.03)
        else:
            assert horizontal == []
        assert not any(a == "vertical" for a, _, _ in tr.peaks)


# --- diagnosis/selection.py --------------------------------------------------------------------------------
def _periodic_verdict(*, periods_seen=None, unresolved=()):
    """The verdict of a plausible periodic candidate (period 19 mm) whose evidence passes every
    other test (z and Wald far beyond their thresholds, 10 % gain, 0.01 m/s^2)."""
    j = dataclasses.replace(_judgement(z=10.0, wald=1e3), physical={"period": Estimate(0.019, 0.0, "m")})
    cand = SimpleNamespace(axis="both", plausible=lambda physical: None)
    cur = SimpleNamespace(compensation=1.0)
    return _verdict(j, cand, np.array([0, 1]), cur, SelectionSettings(), None, periods_seen, unresolved)


def test_a_periodic_force_over_too_short_a_travel_or_beside_an_unresolved_period_is_not_separable():
    """min_periods = 1.25 and min_beats = 1: a travel of 1.2 periods is refused with the travel named,
    1.3 passes, and a candidate that is not position-periodic (None) is not held to it; a chosen
    effect whose period drifts from its own by 0.5 cycle over the travel makes it not separable and
    is named, with none it passes."""
    assert _periodic_verdict() == ("passes", "")
    verdict, reason = _periodic_verdict(periods_seen=1.2)
    assert verdict == "not separable" and "1.2 periods of 19.0 mm" in reason
    assert "a travel of 24 mm or more separates them" in reason  # min_periods x 19 mm = 23.75 mm
    assert _periodic_verdict(periods_seen=1.3)[0] == "passes"
    verdict, reason = _periodic_verdict(unresolved=[("detent_57mm", 0.5)])
    assert verdict == "not separable" and "detent 57mm" in reason and "0.50 of a cycle" in reason
    assert _periodic_verdict(periods_seen=1.3, unresolved=[])[0] == "passes"


def test_cross_parts_pools_the_held_out_quarter_with_that_many_cross_fitted_parts(cogged):
    """SelectionSettings.cross_parts: 0 judges the first step on the held-out quarter alone (z is the
    quarter's), k pools it with the training data cut into k parts, each predicted by fits on the
    rest (the first step's z is that of a judgement with k such parts, and differs between k = 2
    and k = 3: other parts, other blocks)."""
    design, lib = cogged
    cand = lib["cogging_horizontal_19mm"]
    base = fit_subset(design, ["base"])
    r0 = residuals(design, base)[:, design.holdout]
    mse0 = np.maximum(np.mean(r0**2, axis=1), 1e-30)
    zs = {}
    for parts in (0, 2, 3):
        settings = SelectionSettings(cross_parts=parts, bootstrap=0)
        j = select(design, [cand], settings).steps[0].judgements[cand.name]
        if parts == 0:
            assert j.z == j.z_holdout
        else:
            cross = _CrossParts.of(_CrossFit(design, parts), ["base"], [], settings)
            want = judge(design, cand, ["base"], base, r0, mse0, settings, cross=cross)
            assert len(cross.fold.samples) == parts
            assert j.z == pytest.approx(want.z, rel=1e-9)  # the same sums in the same order
            assert j.z != pytest.approx(j.z_holdout, rel=1e-3)
        zs[parts] = j.z
    assert zs[2] != pytest.approx(zs[3], rel=1e-3)


def test_the_judgement_holds_a_motor_period_force_to_min_periods_of_the_logged_travel(cogged, model):
    """judge() passes the logged travel in periods to the verdict: the planted slot-pitch cogging,
    seen over T / t1 periods (T the 1st-99th percentile travel of the training samples), passes with
    min_periods 1 % below that and is not separable, confounded with a smooth dependence on the
    position, 1 % above it (1 %: far above the percentiles' rounding, far below the travel)."""
    design, lib = cogged
    cog = lib["cogging_horizontal_19mm"]
    travel = float(np.subtract(*np.percentile(design.prepared.x[2, design.fit], [99, 1])))
    seen = travel / model.params.slot_pitch
    assert seen > 1.25  # the default passes it
    base = fit_subset(design, ["base"])
    r0 = residuals(design, base)[:, design.holdout]
    mse0 = np.maximum(np.mean(r0**2, axis=1), 1e-30)
    for factor, verdict in ((0.99, "passes"), (1.01, "not separable")):
        settings = SelectionSettings(min_periods=factor * seen)
        j = judge(design, cog, ["base"], base, r0, mse0, settings)
        assert j.verdict == verdict, j.reason
        assert j.confounded_with == (() if verdict == "passes" else (SMOOTH_POSITION,))


@pytest.fixture(scope="module")
def nested_periodic(model):
    """(design, cogging, simple): the horizontal sweep with a slot-pitch force of 0.02 m/s^2 and its
    second harmonic of 0.006 m/s^2 planted; the library's two-harmonic cogging (4 reported
    coefficients) and a one-harmonic periodic force at the same period (2, nested in it) as candidates."""
    period = model.params.slot_pitch

    def force(x3):
        arg = 2 * math.pi * x3 / period
        return 0.02 * np.sin(arg + 0.5) + 0.006 * np.sin(2 * arg)

    data = prepare([_log(model, friction=0.0, force=force)], bandwidth=10.0)
    cog = {c.name: c for c in candidate_library(model, data)}["cogging_horizontal_19mm"]
    simple = Candidate(
        periodic_force(model.params, "horizontal", period, name="periodic_19mm"),
        "periodic",
        "position",
        "a longer travel",
        lambda physical: None,
        lambda physical: "",
    )
    fit, hold = data.masks(0.25)
    design = build_design(data, model, estimate=("C1",), terms=(cog.term, simple.term), fit=fit, holdout=hold)
    return design, cog, simple


def test_a_candidate_nested_in_the_chosen_one_is_judged_inseparable_without_a_warning(nested_periodic):
    """The simpler force chosen first (a large penalty per coefficient), the two-harmonic cogging is
    then judged beside the force its first harmonic repeats: their joint Gram is singular to
    rounding. The fit holds the repeated columns at 0 (regression.solve._spanned) and the
    judgement leaves them out of both spans: the variance inflation is that of the second
    harmonic alone against the rest, finite and small (under 2: a harmonic at half the period is
    nearly orthogonal to the first over the travel), without dividing by the zero variances of a
    singular inverse (the RuntimeWarning, an error under the project's warning filter, that a
    fault raised here). It is not accepted: its period is the chosen force's."""
    design, cog, simple = nested_periodic
    sel = select(design, [cog, simple], SelectionSettings(parameter_penalty=0.05, bootstrap=0))
    assert sel.selected == [simple.name]
    assert 1.0 <= sel.last[cog.name].vif < 2.0
    assert sel.last[cog.name].verdict != "accepted"


def test_the_parameter_penalty_prefers_the_nested_candidate_beyond_the_gain_per_coefficient(nested_periodic):
    """SelectionSettings.parameter_penalty: among the candidates that pass, the one chosen has the
    largest gain - penalty x reported coefficients, in the choice and in every bootstrap vote. The
    two-harmonic cogging gains g4, the one-harmonic force g2 < g4 (the planted second harmonic):
    the choice turns at penalty* = (g4 - g2) / (4 - 2). At 0.8 penalty* the cogging is chosen, at
    1.2 and 3 penalty* the simpler force, at 3 penalty* in every resample too (the margin, 4 penalty*,
    is far beyond the resamples' spread of the gains). One step only (max_effects = 1)."""
    design, cog, simple = nested_periodic
    first = select(
        design, [cog, simple], SelectionSettings(parameter_penalty=0.0, bootstrap=0, max_effects=1)
    )
    assert first.selected == [cog.name]
    gains = {n: j.gain for n, j in first.steps[0].judgements.items()}
    assert gains[cog.name] > gains[simple.name] + 0.02  # the second harmonic is real
    turn = (gains[cog.name] - gains[simple.name]) / 2
    for factor, chosen in ((0.8, cog.name), (1.2, simple.name), (3.0, simple.name)):
        settings = SelectionSettings(parameter_penalty=factor * turn, bootstrap=10, max_effects=1)
        sel = select(design, [cog, simple], settings)
        assert sel.selected == [chosen], factor
        verdicts = sorted(j.verdict for j in sel.steps[0].judgements.values())
        assert verdicts == ["accepted", "passes"]  # both passed: the penalty decided
        if factor == 3.0:
            assert sel.steps[0].confidence == 1.0


def test_the_waviness_scan_fits_both_axes_with_the_candidates_own_columns(model, waviness_residual):
    """Weighted on both axes, the scan's columns must be the waviness candidate's own (the gap's
    change through the gap sensitivity on both axes and, on the horizontal, the slope pushing the
    platform, in the candidate's relative sign): the candidate's exact residual at P is then fitted
    to rounding at P, the best of the grid (P on it: the guess P / 1.2, 41 points over +-25 %). On
    the horizontal axis alone a wrong relative sign hides in the coefficients' signs."""
    data, residual, _, fit, period = waviness_residual
    got = refine_waviness_period(model, data, residual, np.ones(2), fit, period / 1.2)
    assert got == pytest.approx(period, rel=1e-9)
