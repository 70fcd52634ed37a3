"""The regression layer shared by identify and diagnose, against independent computations.

Synthetic logs with an exact answer: the gap held at 20 mm (the vertical axis locked, as in the
papers' horizontal experiments), the horizontal position a sum of sines, so the acceleration is
known in closed form and the current that produced it is -x3'' / L1(gap) exactly.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.data.logs import Log
from maglev_oc.model.stage import StageModel
from maglev_oc.regression.data import logging_error_share, prepare, reduce_rate
from maglev_oc.regression.design import build_design
from maglev_oc.regression.solve import fit_subset, residuals

GAP = 0.020
RATE = 1000.0
FREQS = np.array([0.13, 0.41, 0.97, 2.3])  # [Hz] well inside a 10 Hz band
AMPS = np.array([0.020, 0.010, 0.004, 0.001])  # [m]


def _synthetic(model: StageModel, *, seconds=60.0, current_noise=0.0, position_noise=0.0, seed=0, **meta):
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * RATE)) / RATE
    phases = rng.uniform(0, 2 * np.pi, FREQS.size)
    w = 2 * np.pi * FREQS
    x3 = np.sum(AMPS[:, None] * np.sin(np.outer(w, t) + phases[:, None]), axis=0)
    acc = -np.sum((AMPS * w**2)[:, None] * np.sin(np.outer(w, t) + phases[:, None]), axis=0)
    l1 = float(model.coefficients(GAP)[0, 0])  # L1 at the gap, with the model's C1
    u1 = -acc / l1
    x = np.full((4, t.size), np.nan)
    x[0] = GAP
    x[2] = x3 + position_noise * rng.standard_normal(t.size)
    u = np.vstack([u1 + current_noise * rng.standard_normal(t.size), np.full(t.size, 1.5)])
    return Log(
        t,
        x,
        u,
        metadata={k: str(v) for k, v in meta.items()},
        source=f"synthetic seed {seed}",
        currents_measured=bool(meta.get("currents") == "measured"),
    )


def test_fit_equals_numpy_least_squares(model):
    # Ordinary least squares from the block Gram sums is the least-squares solution of the stacked,
    # weighted, filtered rows; the held-out error is the RMS of the held-out residuals.
    log = _synthetic(model, seconds=20.0, position_noise=3e-6, seed=1)
    data = prepare([log], bandwidth=10.0)
    fit, hold = data.masks(0.25)
    design = build_design(data, model, estimate=("C1",), fit=fit, holdout=hold)
    sub = fit_subset(design, ["base"], compensate=False)
    cols = design.columns[:, :, fit] * design.weights[None, :, None]
    y = (design.target[:, fit] * design.weights[:, None]).reshape(-1)
    ref, *_ = np.linalg.lstsq(cols.reshape(cols.shape[0], -1).T, y, rcond=None)
    assert_allclose(sub.coef, ref, rtol=1e-10)  # the same normal equations, summed in blocks
    r = residuals(design, sub)
    assert_allclose(sub.holdout_rms[1], np.sqrt(np.mean(r[1, hold] ** 2)), rtol=1e-9)
    assert np.isnan(sub.holdout_rms[0]) or design.weights[0] == 0  # the locked axis has no error
    assert sub.coef[0] == pytest.approx(model.constants.C1, rel=1e-3)  # exact data, exact answer


def test_errors_in_the_currents_are_removed(model):
    # White errors in the logged current bias ordinary least squares towards zero by the share of
    # the error in the filtered regressor's power; the compensated fit removes that share. One log
    # carries a random error of a few per cent in the compensated estimate (the cross-products of
    # signal and noise), so the bias is measured over ten logs.
    ols, bcls, predicted = [], [], []
    for seed in range(10):
        log = _synthetic(model, seconds=30.0, current_noise=0.05, seed=20 + seed, currents="measured")
        data = prepare([log], bandwidth=10.0)
        assert data.current_noise[0] == pytest.approx(0.05**2, rel=0.1)  # the white floor, measured
        fit, _ = data.masks()
        design = build_design(data, model, estimate=("C1",), fit=fit)
        ols.append(fit_subset(design, ["base"], compensate=False).coef[0])
        bcls.append(fit_subset(design, ["base"]).coef[0])
        predicted.append(-design.noise[:, 0, 0].sum() / design.gram[:, 0, 0].sum())
    c1 = model.constants.C1
    bias_ols = np.mean(ols) / c1 - 1
    assert bias_ols == pytest.approx(np.mean(predicted), rel=0.2)  # first-order attenuation N / G
    assert bias_ols < -0.05  # the test has teeth: OLS is more than 5 % low
    assert abs(np.mean(bcls) / c1 - 1) < 0.01  # compensated: unbiased to 1 % over ten logs


def test_long_run_standard_errors_cover_the_scatter(model):
    # 30 seeds of position noise through the differentiator: the reported standard error of C1
    # agrees with the scatter of the estimates (the periodogram estimate over ~11 frequencies is
    # good to ~20 % per log; averaged over 30 logs the ratio is within [0.7, 1.4]).
    est, se = [], []
    for seed in range(30):
        data = prepare([_synthetic(model, seconds=40.0, position_noise=2e-5, seed=10 + seed)], bandwidth=10.0)
        fit, _ = data.masks()
        sub = fit_subset(build_design(data, model, estimate=("C1",), fit=fit), ["base"])
        est.append(sub.coef[0])
        se.append(sub.stderr("C1"))
    ratio = np.mean(se) / np.std(est, ddof=1)
    assert 0.7 < ratio < 1.4, ratio


def test_masks_keep_held_out_samples_away_from_fitted_ones(model):
    data = prepare([_synthetic(model, seconds=20.0)], bandwidth=10.0)
    fit, hold = data.masks(0.25)
    assert not np.any(fit & hold)
    last_fit, first_hold = np.flatnonzero(fit)[-1], np.flatnonzero(hold)[0]
    assert first_hold - last_fit > 2 * data.edge  # guard bands of one filter memory each side
    assert hold.sum() == pytest.approx(0.25 * data.n, rel=0.05)


def test_logging_error_share_follows_the_logging(model):
    def log(rate, **meta):
        t = np.arange(200) / rate
        x = np.vstack([np.full(200, GAP), np.zeros(200), np.linspace(0, 0.01, 200), np.zeros(200)])
        return Log(
            t,
            x,
            np.ones((2, 200)),
            metadata={k: str(v) for k, v in meta.items()},
            currents_measured=meta.get("currents") == "measured",
        )

    assert logging_error_share(log(1000.0)) == pytest.approx(0.8)  # every 5th command of a 5 kHz loop
    assert logging_error_share(log(5000.0)) == 0.0  # every command: each was applied
    assert logging_error_share(log(1000.0, control_rate_hz=2000)) == pytest.approx(0.5)
    assert logging_error_share(log(1000.0, currents="measured")) == 1.0  # sensor noise: all error
    reduced, q = reduce_rate(log(5000.0), 1000.0)
    assert q == 5 and reduced.sample_time == pytest.approx(1e-3)
    with pytest.raises(ValueError, match="control_rate_hz"):
        logging_error_share(log(1000.0, control_rate_hz="fast"))
    assert math.isfinite(logging_error_share(log(1000.0, control_rate_hz=1000)))


def test_design_does_not_depend_on_how_it_is_evaluated(model, monkeypatch):
    # The columns are evaluated in chunks of samples and filtered a few rows at a time (bounded
    # memory); chunk boundaries inside the log, and held-out normal equations summed run by run,
    # must give the same design as one pass over every sample.
    import maglev_oc.regression.data as data_module
    import maglev_oc.regression.design as design_module
    from maglev_oc.regression.terms import guide_friction

    log = _synthetic(model, seconds=12.0, position_noise=3e-6, current_noise=0.01, seed=4)
    data = prepare([log], bandwidth=10.0)
    fit, hold = data.masks(0.25)
    terms = (guide_friction(model.params, "horizontal"),)

    def design():
        return build_design(data, model, terms=terms, fit=fit, holdout=hold)

    one = design()
    monkeypatch.setattr(design_module, "_CHUNK", 997)  # not a divisor of n
    monkeypatch.setattr(data_module, "_FILTER_ROWS", 3)
    chunked = design()
    assert_allclose(chunked.columns, one.columns, rtol=1e-12, atol=1e-15)
    assert_allclose(chunked.gram, one.gram, rtol=1e-12)
    assert_allclose(chunked.noise, one.noise, rtol=1e-12, atol=1e-30)
    held = one.columns[:, :, hold]
    for a in range(2):
        assert_allclose(one.hold_gram[a], held[:, a] @ held[:, a].T, rtol=1e-12, atol=1e-30)
        assert_allclose(one.hold_rhs[a], held[:, a] @ one.target[a, hold], rtol=1e-12, atol=1e-30)
