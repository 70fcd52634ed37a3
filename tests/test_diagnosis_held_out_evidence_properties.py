"""Properties of the held-out evidence a diagnosis judges candidates by (``maglev_oc.diagnosis
.selection``: the blocks' z, the gains, the samples that count, the cross-fitted parts), checked
against numpy recomputations:

- the blocks' z is calibrated on a null series, and on one log (or short logs) it is the mean
  log-ratio over its long-run standard error (the averaged periodogram, numpy's FFT);
- each block's log-ratio is its full log(SS0 / SS1), and the evidence on no axis is none;
- pooled gains are the drop of the summed squares over every part, and the held-out significance
  does not depend on the axes' units;
- beside guide friction only the samples at least ``slow_speed`` fast count: for a candidate's
  and an unexplained residual's size, the peak contribution and the cross-fitted parts;
- a training part's residuals are those of the fit on the other blocks.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.diagnosis.selection import (
    SelectionSettings,
    _block_peak,
    _block_z,
    _CrossFit,
    evidence,
    holdout_significance,
    judge,
    pooled_gains,
)
from maglev_oc.diagnosis.unexplained import find_unexplained
from maglev_oc.regression.covariance import DEFAULT_BAND, frequencies_for
from maglev_oc.regression.design import build_design
from maglev_oc.regression.solve import fit_subset


# --- significance --------------------------------------------------------------------------------------
def test_the_block_z_of_a_null_series_is_calibrated():
    # n = 120 white blocks of 0.5 s: the periodogram averages m = frequencies_for(120, 0.5, 0.25) = 15
    # frequencies, so z is Student t with 2m = 30 dof (sd sqrt(30/28) = 1.035). Over 400 seeds the
    # sample sd is within 1.035 (1 +- 3/sqrt(800)) = [0.93, 1.14] (3 sigma of a sd estimate)
    n = 120
    assert frequencies_for(n, 0.5, DEFAULT_BAND) == 15
    logs = np.zeros(n, dtype=int)
    z = np.array([_block_z(np.random.default_rng(s).normal(0.0, 0.3, n), logs, 0.5) for s in range(400)])
    assert 0.93 < np.std(z) < 1.14
    # and a shift of half a standard deviation per block is found: mean z ~ 0.5 sqrt(120) = 5.5
    shifted = [_block_z(np.random.default_rng(s).normal(0.15, 0.3, n), logs, 0.5) for s in range(50)]
    assert 4.0 < np.mean(shifted) < 7.0


def test_pooled_gains_are_the_drop_of_the_summed_squares_over_every_part():
    rng = np.random.default_rng(5)
    every = [(rng.normal(size=(2, m)), rng.normal(size=(2, m))) for m in (40, 70, 55)]
    axes = np.array([0, 1])
    expected = [
        1.0 - sum(float(r1[a] @ r1[a]) for _, r1 in every) / sum(float(r0[a] @ r0[a]) for r0, _ in every)
        for a in axes
    ]
    np.testing.assert_allclose(pooled_gains(every, axes), expected, rtol=1e-12)
    # weighted by each part's sum of squares, not an average of the parts' own gains
    parts = np.mean([1.0 - np.sum(r1[0] ** 2) / np.sum(r0[0] ** 2) for r0, r1 in every])
    assert abs(pooled_gains(every, axes[:1])[0] - parts) > 1e-3


# --- which held-out samples count ----------------------------------------------------------------------
def test_the_samples_counted_beside_friction_are_those_at_least_slow_speed_fast(cogged):
    design, _ = cogged
    speed = np.abs(design.prepared.x[3, design.holdout])
    slow = float(np.percentile(speed, 30))  # a split with many samples on both sides
    settings = SelectionSettings(slow_speed=slow)
    assert evidence(design, [], settings) is None
    friction = SimpleNamespace(family="friction", axis="horizontal")
    counted = evidence(design, [friction], settings)
    np.testing.assert_array_equal(counted[1], speed >= slow)
    assert np.all(counted[0])  # the other axis is not affected


def test_the_peak_contribution_is_over_the_counted_samples_of_each_block(cogged):
    # recomputed here: the held-out samples cut into whole blocks of block_seconds from the start
    # of the held-out block (one log), the RMS of each block over its counted samples, the largest
    design, _ = cogged
    rng = np.random.default_rng(4)
    n_hold = int(design.holdout.sum())
    change = rng.normal(size=(2, n_hold))
    change[:, : n_hold // 3] *= 5.0  # one region larger, so the peak block is not any block
    counted = rng.uniform(size=(2, n_hold)) > 0.5
    change = np.where(counted, change, 0.0)  # as judge passes it: residuals zero where not counted
    size = round(design.block_seconds / design.prepared.sample_time)
    nb = n_hold // size
    expected = np.zeros(2)
    for b in range(nb):
        sl = slice(b * size, (b + 1) * size)
        for a in range(2):
            c = counted[a, sl]
            expected[a] = max(expected[a], math.sqrt(np.sum(change[a, sl][c] ** 2) / max(c.sum(), 1)))
    np.testing.assert_allclose(_block_peak(design, change, counted), expected, rtol=1e-12)
    # and the same whatever the caller left at the samples not counted (it need not zero them)
    noisy = np.where(counted, change, 1e3)
    np.testing.assert_allclose(_block_peak(design, noisy, counted), expected, rtol=1e-12)


def _held_out_prediction(design, fit):
    """(2, n_hold) a fit's prediction on the held-out samples, from its coefficients and columns."""
    return np.einsum("p,pan->an", fit.coef, design.columns[fit.index][:, :, design.holdout])


# --- sizes -------------------------------------------------------------------------------------------
def test_a_candidates_size_beside_friction_is_the_rms_change_over_the_samples_that_count(cogged):
    # friction chosen on the horizontal axis: its samples slower than slow_speed (here the 40th
    # percentile of the held-out speeds, so that 40 % are left out) do not count; the size is the
    # RMS over the counted samples of how much adding the candidate moves the prediction. Exact
    # arithmetic on the same numbers: rtol 1e-9
    design, lib = cogged
    speed = np.abs(design.prepared.x[3, design.holdout])
    settings = SelectionSettings(slow_speed=float(np.percentile(speed, 40)))
    counted = evidence(design, [lib["guide_friction_horizontal"]], settings)
    assert 0.3 < 1.0 - counted[1].mean() < 0.5
    current = ["base", "guide_friction_horizontal"]
    cur = fit_subset(design, current)
    r0 = np.where(counted, design.target[:, design.holdout] - _held_out_prediction(design, cur), 0.0)
    mse0 = np.maximum(np.mean(r0**2, axis=1), 1e-30)
    j = judge(design, lib["cogging_horizontal_19mm"], current, cur, r0, mse0, settings, counted=counted)
    new = fit_subset(design, [*current, "cogging_horizontal_19mm"], covariance=False)
    change = _held_out_prediction(design, new) - _held_out_prediction(design, cur)
    expected = math.sqrt(np.mean(change[1][counted[1]] ** 2))
    assert j.contribution_rms[1] == pytest.approx(expected, rel=1e-9)


def test_an_unexplained_residuals_size_beside_friction_is_the_rms_change_over_the_samples_that_count(
    model, two_effects
):
    # the sweep with friction and a slot-pitch cogging planted, friction explained: the cogging is
    # left for the probes (a sine at the slot pitch among them). Its size is the RMS change of the
    # held-out prediction over the samples that count beside friction (slow_speed the 40th
    # percentile of the held-out speeds), recomputed from the two fits' columns: rel 1e-9
    design, lib = two_effects
    speed = np.abs(design.prepared.x[3, design.holdout])
    settings = SelectionSettings(slow_speed=float(np.percentile(speed, 40)))
    friction = lib["guide_friction_horizontal"]
    period = model.params.slot_pitch
    found = find_unexplained(
        design.prepared,
        model,
        [friction],
        design.fit,
        design.holdout,
        design.weights,
        [("horizontal", period)],
        settings,
        max_per_axis=1,
    )
    assert [u.period for u in found] == [period]
    probe = found[0].term
    d = build_design(
        design.prepared,
        model,
        terms=[friction.term, probe],
        fit=design.fit,
        holdout=design.holdout,
        weights=design.weights,
    )
    counted = evidence(d, [friction], settings)
    before = fit_subset(d, ["base", friction.name], covariance=False)
    after = fit_subset(d, ["base", friction.name, probe.name], covariance=False)
    change = _held_out_prediction(d, after) - _held_out_prediction(d, before)
    assert found[0].size == pytest.approx(math.sqrt(np.mean(change[1][counted[1]] ** 2)), rel=1e-9)


# --- which training samples count ----------------------------------------------------------------------
def test_the_cross_fitted_parts_count_the_samples_of_the_friction_axis_at_least_slow_speed_fast(cogged):
    # as on the held-out quarter (:func:`evidence`): beside horizontal friction, a part's samples
    # count on the horizontal axis where |x4| >= slow_speed (the 40th percentile of the training
    # speeds: 40 % left out), on the vertical axis all of them; with no friction chosen, all
    design, lib = cogged
    speed = np.abs(design.prepared.x[3])
    settings = SelectionSettings(slow_speed=float(np.percentile(speed[design.fit], 40)))
    fold = _CrossFit(design, 3)
    assert fold.counted([], settings) == [None] * len(fold.samples)
    counted = fold.counted([lib["guide_friction_horizontal"]], settings)
    assert len(counted) == len(fold.samples) == 3
    for samples, c in zip(fold.samples, counted, strict=True):
        np.testing.assert_array_equal(c[1], speed[samples] >= settings.slow_speed)
        assert np.all(c[0])
        assert 0.2 < 1.0 - c[1].mean() < 0.6


# --- significance --------------------------------------------------------------------------------------
def test_the_held_out_significance_of_an_effect_on_both_axes_does_not_depend_on_their_units(cogged):
    # each axis's squared residuals are scaled by that axis's mean square before the blocks' sums
    # are taken, so neither axis rules the test by its units: z and the gain are the same when one
    # axis's residuals (before and after) are multiplied by 1e3. Random residuals whose drop differs
    # between the axes and along the log (otherwise any weighting gives one answer); the same
    # arithmetic up to the factor: rel 1e-9
    design, _ = cogged
    rng = np.random.default_rng(21)
    n = int(design.holdout.sum())
    r0 = rng.normal(size=(2, n)) * np.array([[1.0], [3.0]])
    shrink = np.vstack([np.linspace(0.3, 1.0, n), np.linspace(1.0, 0.8, n)])
    r1 = r0 * shrink
    both = np.array([0, 1])
    gain, z = holdout_significance(design, r0, r1, both)
    scale = np.array([[1e3], [1.0]])
    gain_s, z_s = holdout_significance(design, r0 * scale, r1 * scale, both)
    assert abs(z) > 1.0
    assert z_s == pytest.approx(z, rel=1e-9) and gain_s == pytest.approx(gain, rel=1e-9)


def _z_short_logs(ratios: np.ndarray, logs: np.ndarray) -> float:
    """Mean / standard error with, per log of fewer than 4 blocks, the long-run variance the square
    of its summed deviations from the overall mean (the periodogram at zero frequency)."""
    mean = ratios.mean()
    total = sum(np.sum(ratios[logs == s] - mean) ** 2 for s in np.unique(logs))
    return mean / (math.sqrt(total) / ratios.size)


def test_the_pooled_z_of_short_logs_is_the_mean_over_its_long_run_standard_error():
    """Logs of 2 and 3 blocks (too short for a periodogram): the z is the mean log-ratio over the
    standard error from the summed deviations per log, to round-off (1e-12 relative: a handful of
    sums). The deviations are from the overall mean: shifting every ratio by a constant moves
    the mean and keeps the standard error."""
    rng = np.random.default_rng(34)
    ratios = 0.3 + rng.standard_normal(8)
    logs = np.array([0, 0, 1, 1, 1, 2, 2, 2])
    z = _block_z(ratios, logs, 0.5)
    assert z == pytest.approx(_z_short_logs(ratios, logs), rel=1e-12)
    shifted = _block_z(ratios + 1.0, logs, 0.5)
    assert shifted / z == pytest.approx((ratios.mean() + 1.0) / ratios.mean(), rel=1e-12)


# --- the cross-fitted training parts ---------------------------------------------------------------------
def test_a_training_parts_residuals_are_those_of_the_fit_on_the_other_blocks(model, data):
    """_CrossFit: the fitted blocks of each log cut into 3 contiguous parts; a part's residuals come
    from the fit on the blocks outside the part and its neighbours in the same log. Computed here:
    the blocks of each part (np.array_split of the log's blocks in time order), the excluded ones
    (the part's and one on each side), and the residual of ``fit_subset(design, groups, blocks=...)``
    on the part's samples, with the fit's errors-in-variables compensation (the twin's currents carry
    amplifier noise: on these blocks the compensation moves C4 by up to 3 %). The same normal
    equations summed in another order: 1e-9 relative to the largest residual."""
    fit, hold = data.masks(0.25)
    design = build_design(data, model, fit=fit, holdout=hold)
    assert np.any(design.noise != 0)
    groups = list(design.groups)
    fold = _CrossFit(design, 3)
    n_blocks = design.gram.shape[0]
    parts = []
    for log in np.unique(design.block_log):
        mine = np.flatnonzero(design.block_log == log)
        parts.extend((log, run) for run in np.array_split(mine, 3) if run.size)
    residuals = fold.residuals(groups)
    assert len(residuals) == len(parts) == 3
    for (log, held), r in zip(parts, residuals, strict=True):
        excluded = {
            k for b in held for k in (b - 1, b, b + 1) if 0 <= k < n_blocks and design.block_log[k] == log
        }
        others = np.array([b for b in range(n_blocks) if b not in excluded])
        samples = np.flatnonzero(np.isin(design.block_of, held))
        f = fit_subset(design, groups, blocks=others, covariance=False)
        expected = design.target[:, samples] - np.tensordot(
            f.coef, design.columns[f.index][:, :, samples], axes=1
        )
        assert r.shape == expected.shape
        np.testing.assert_allclose(r, expected, rtol=0, atol=1e-9 * np.abs(expected).max())


# --- the held-out significance of a dominant effect -----------------------------------------------------
def test_the_held_out_z_of_an_effect_that_removes_most_of_the_error_uses_each_blocks_full_log_ratio(
    two_periodic,
):
    """A candidate that shrinks the held-out residual by a factor k_b in 0.5 s block b (here
    10^-1.5 to 10^-3: an effect that is most of the residual) lowers that block's sum of squares
    by k_b^2 exactly, so its log-ratio log(SS0_b / SS1_b) is -2 log k_b, whatever the block's sum
    in units of the base model's mean square (here SS1_b is below 1, the block holding 500 samples
    of SS0_b about 500). The blocks are recomputed here: each log's held-out samples in order, cut
    into whole blocks of round(0.5 s / sample time) samples, a shorter rest left out. z is then the
    mean of those log-ratios over their long-run standard error (the same series statistic,
    ``_block_z``, fed the ratios computed here; 1e-9: the rounding of the sums of 500 squares);
    the gain is the relative drop of the held-out mean square, computed here."""
    _, _, d = two_periodic
    axes = np.array([1])  # the horizontal axis, the one that moves
    assert d.moving[1]
    n = int(d.holdout.sum())
    size = round(d.block_seconds / d.prepared.sample_time)
    assert size == 500
    nb = n // size  # one log: its held-out samples are the last quarter
    rng = np.random.default_rng(5)
    k_block = 10.0 ** -rng.uniform(1.5, 3.0, nb)
    k = np.ones(n)
    k[: nb * size] = np.repeat(k_block, size)
    r0 = rng.standard_normal((2, n))
    r1 = r0 * k
    gain, z = holdout_significance(d, r0, r1, axes)
    assert gain == pytest.approx(1 - np.mean(r1[1] ** 2) / np.mean(r0[1] ** 2), rel=1e-12)
    ratios = -2.0 * np.log(k_block)
    expected = _block_z(ratios, np.zeros(nb), d.block_seconds)
    assert expected > 10
    assert z == pytest.approx(expected, rel=1e-9)


# --- held-out evidence on no axis ------------------------------------------------------------------------
def test_held_out_evidence_on_no_axis_is_none(two_periodic):
    """On no axis there is nothing to judge: (gain, z) is (0, 0), exactly what replacing the
    held-out residuals by themselves gives on a judged axis (no change: no gain, no evidence),
    although here the replacement residual differs from the first on every sample."""
    _, _, d = two_periodic
    n = int(d.holdout.sum())
    rng = np.random.default_rng(39)
    r0 = rng.standard_normal((2, n))
    r1 = 0.1 * rng.standard_normal((2, n))
    assert holdout_significance(d, r0, r0, np.array([1])) == (0.0, 0.0)
    assert holdout_significance(d, r0, r1, np.array([], dtype=int)) == (0.0, 0.0)
    # on a judged axis the same replacement is strong evidence: the zero above is the empty axis set's
    gain, z = holdout_significance(d, r0, r1, np.array([1]))
    assert gain == pytest.approx(1 - np.mean(r1[1] ** 2) / np.mean(r0[1] ** 2), rel=1e-12)
    assert gain > 0.9 and z > 3


@pytest.mark.parametrize("n", [4, 5, 6, 9, 16, 40])
def test_the_block_z_of_one_log_is_its_mean_over_the_periodograms_standard_error(n):
    """One log of n blocks: z = mean / (sqrt(P) / n), P = mean over j = 1..m of |FFT(x - mean)_j|^2
    (numpy's FFT here; 1e-9: the same sums in another order)."""
    rng = np.random.default_rng(n)
    ratios = rng.normal(0.1, 0.3, n)
    x = ratios - ratios.mean()
    m = frequencies_for(n, 0.5, DEFAULT_BAND)
    p = np.mean(np.abs(np.fft.fft(x)[1 : m + 1]) ** 2)
    want = ratios.mean() / (np.sqrt(p) / n)
    got = _block_z(ratios, np.zeros(n, dtype=int), 0.5)
    assert got != 0.0
    assert got == pytest.approx(want, rel=1e-9)


@pytest.mark.parametrize(("axis", "row"), [("vertical", 0), ("horizontal", 1)])
def test_only_samples_slower_than_the_slow_speed_are_left_out(axis, row):
    """Held-out speeds of 0, 0.9, 1 and 1.1 times ``slow_speed`` (either sign) on the friction's axis:
    the first two are left out, the others count; the other axis counts everywhere."""
    s = SelectionSettings().slow_speed
    v = s * np.array([0.0, 0.9, 1.0, 1.1, -0.9, -1.0, -1.1])
    x = np.zeros((4, v.size))
    x[1 if row == 0 else 3] = v
    x[3 if row == 0 else 1] = 1e-6  # the other axis almost still: not left out, no friction there
    design = SimpleNamespace(prepared=SimpleNamespace(x=x), holdout=np.ones(v.size, bool))
    friction = SimpleNamespace(family="friction", axis=axis)
    counted = evidence(design, [friction], SelectionSettings())
    assert counted[row].tolist() == [False, False, True, True, False, True, True]
    assert counted[1 - row].all()
