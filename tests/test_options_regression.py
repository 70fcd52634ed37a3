"""Options of ``maglev_oc.regression`` passed by name, each checked against an independent
computation (a closed form, numpy by hand, the term's own CasADi function), so that the option
ignored (its default used) or inverted fails here:

- ``reduce_rate(max_rate=)`` and ``prepare(max_rate=)`` reduce by means over the fewest samples
  that bring the rate to at most ``max_rate``, a mean carrying its share of the logging error;
- ``PreparedLogs.filter(inplace=)`` overwrites its argument only when asked, with numpy's per-log
  convolution's values;
- ``build_design(block_seconds=)`` cuts the fitted samples into blocks of that length, whose sums
  are the normal equations of every fitted sample once;
- ``predicted(group=)`` is that group's filtered acceleration at its fitted coefficients;
- ``is_linear_in_parameters(parameter_input=)`` asks about the input it names;
- ``guide_friction(stick_speed=)`` and ``cogging_force(harmonics=, decay_scale=,
  scale_variants=)`` give the closed forms their docstrings write.
"""

from __future__ import annotations

import dataclasses
import math

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.errors import InputError
from maglev_oc.model.parameters import StageParameters
from maglev_oc.regression.data import prepare, reduce_rate
from maglev_oc.regression.design import _blocks, build_design
from maglev_oc.regression.solve import fit_subset, predicted, residuals
from maglev_oc.regression.terms import cogging_force, guide_friction, is_linear_in_parameters
from tests._regression_cases import _both_axes_log


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
