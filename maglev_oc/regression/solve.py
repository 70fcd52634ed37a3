"""Least squares on a :class:`~maglev_oc.regression.design.Design`: one solver, one covariance.

A fit of any subset of column groups is the solve of its block-summed normal equations,

    (sum_b X_b'X_b - sum_b N_b) theta = sum_b X_b'y_b,

with the errors-in-variables part N_b of the logged currents removed (bias-compensated least
squares; ``compensate=False`` gives ordinary least squares). Its held-out error per axis is a
quadratic form in the held-out Gram matrices; a block bootstrap resamples the blocks' sums.

Covariance (the one choice of the project's equation-error fits): the sandwich
H^-1 S H^-1 with S the long-run covariance of the block scores s_b = X_b'y_b - (X_b'X_b - N_b)
theta, a time series per log, estimated by the averaged periodogram over its lowest Fourier
frequencies (:func:`~maglev_oc.regression.covariance.periodogram_long_run`, band 0.25 Hz; see that
module for why not Newey-West). Summing the samples into 0.5 s blocks does not change the series'
spectrum below 1 Hz, so this is the per-sample estimate at a fraction of the memory. The plain
s^2 H^-1 is reported beside it.

Parameters that enter nonlinearly are fitted by Gauss-Newton (:func:`fit_nonlinear`): the design
is rebuilt at each iterate, its columns being the exact Jacobian there, so each solve gives the
next iterate directly.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.regression.covariance import DEFAULT_BAND, per_log_long_run
from maglev_oc.regression.design import Design

__all__ = ["OPTIONAL_NOISE_SHARE", "SubsetFit", "fit_nonlinear", "fit_subset", "predicted", "residuals"]


@dataclass(frozen=True, eq=False)
class SubsetFit:
    """A fit of some column groups of a design.

    Attributes
    ----------
    groups : tuple of str
    index : (p,) column indices in the design; names : tuple of str
    coef : (p,)
    covariance : (p, p) long-run (sandwich) covariance; naive : (p, p) s^2 H^-1
    holdout_rms : (2,) per axis, unweighted [units of the target]; NaN without a held-out block
    chi_square : float  weighted residual sum of squares of the fitted blocks
    dof : int
    frequencies : int  Fourier frequencies the long-run covariance averaged (all logs)
    compensation : float  share of the estimated errors-in-variables part removed (1 = all, 0 = OLS)
    message : str
    """

    groups: tuple[str, ...]
    index: np.ndarray
    names: tuple[str, ...]
    coef: np.ndarray
    covariance: np.ndarray
    naive: np.ndarray
    holdout_rms: np.ndarray
    chi_square: float
    dof: int
    frequencies: int
    compensation: float
    message: str = ""

    @property
    def compensated(self) -> bool:
        """Whether the whole errors-in-variables part was removed."""
        return self.compensation == 1.0

    def group(self, design: Design, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(coefficients, covariance) of one group."""
        pos = (
            np.searchsorted(self.index, design.groups[name])
            if _sorted(self.index)
            else np.array([int(np.flatnonzero(self.index == j)[0]) for j in design.groups[name]])
        )
        return self.coef[pos], self.covariance[np.ix_(pos, pos)]

    def value(self, name: str) -> float:
        return float(self.coef[self.names.index(name)])

    def stderr(self, name: str) -> float:
        k = self.names.index(name)
        return float(np.sqrt(max(self.covariance[k, k], 0.0)))


def _sorted(a: np.ndarray) -> bool:
    return bool(np.all(np.diff(a) > 0))


SPANNED = 1e-9
"""A column is spanned by the columns before it in a fit when its share of variance left after
projecting on them is below this: only exact duplicates (two constant forces on one axis, filtered
alike, differ at 1e-16), never columns the data barely tell apart (a variance inflation of 1e9)."""


OPTIONAL_NOISE_SHARE = 0.5
"""A term's optional parameter (``AccelerationTerm.optional``) is held at zero in a compensated fit
when the logged currents' errors, as estimated, are at least this share of its column's variance:
its coefficient would be mostly the errors' correction. Half, so that the scales the diagnosis
calibrates the errors at (0.5-1 times the floor's estimate on the independent generator's noisy
rig) agree on it: a holding share 1.2 times its variance at 1 was 0.83 at 0.68."""

_SURELY_NOT_SPANNED = 1e3 * SPANNED
"""When every column's share left after projecting on all the columns before it (the squared pivots
of the normalized Gram's Cholesky factor) is above this, none is spanned; the margin of 1e3 keeps
the shortcut's answer that of the column-by-column solves that decide below it, whose share
differs from the pivot's by rounding (about 1e-16 times the Gram's condition)."""


def _spanned(gram: np.ndarray, dead: np.ndarray) -> np.ndarray:
    """(p,) bool: the live columns whose variance left after projecting on the live columns before
    them (in the fit's order) is below :data:`SPANNED` of their own. A duplicate left in the
    normal equations makes them singular, and the errors-in-variables compensation would then
    stop at a share of 0, as if the logged currents' errors dominated."""
    p = gram.shape[0]
    out = np.zeros(p, dtype=bool)
    scale = np.sqrt(np.where(dead, 1.0, np.diag(gram)))
    g = gram / np.outer(scale, scale)
    live = np.flatnonzero(~dead)
    try:  # the usual case, at once: the squared pivots of g's Cholesky factor are those shares
        pivots = np.diag(np.linalg.cholesky(g[np.ix_(live, live)])) ** 2
        if np.all(pivots >= _SURELY_NOT_SPANNED):
            return out
    except np.linalg.LinAlgError:
        pass
    kept: list[int] = []
    for j in range(p):
        if dead[j]:
            continue
        if kept:
            b = g[kept, j]
            try:
                left = 1.0 - float(b @ np.linalg.solve(g[np.ix_(kept, kept)], b))
            except np.linalg.LinAlgError:
                left = 1.0
            if left < SPANNED:
                out[j] = True
                continue
        kept.append(j)
    return out


def _solve_spd(g: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """Solution and inverse of a symmetric system; False when it is not positive definite."""
    try:
        c = np.linalg.cholesky(g)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(g, r, rcond=None)[0], np.linalg.pinv(g), False
    inv = np.linalg.inv(c)
    ginv = inv.T @ inv
    return ginv @ r, ginv, True


def _positive_definite(g: np.ndarray) -> bool:
    """Whether a symmetric matrix is positive definite (its Cholesky factor exists)."""
    try:
        np.linalg.cholesky(g)
    except np.linalg.LinAlgError:
        return False
    return True


def fit_subset(
    design: Design,
    groups: Sequence[str],
    *,
    blocks: np.ndarray | None = None,
    compensate: bool = True,
    covariance: bool = True,
    band: float = DEFAULT_BAND,
    extra: Sequence[int] = (),
    noise_scale: float = 1.0,
) -> SubsetFit:
    """Least squares on the chosen groups (and any ``extra`` single columns) over the fitted blocks.

    ``blocks``: indices of blocks to sum (with repetition, for a bootstrap); the covariance needs
    all blocks in order. With ``compensate`` the logged currents' errors are removed from the
    normal equations; if that leaves them indefinite (an error estimate larger than the signal in
    some direction), the largest share of those errors that keeps them positive definite is removed
    (bisected), ``compensation`` says which and ``message`` says so. Near that edge the equations
    are nearly singular and the coefficients can be far off (1e6 and more): the selection reads a
    compensation below the current model's as a candidate made of the currents' errors
    (``selection.EIV_REASON``). ``noise_scale``
    multiplies the design's estimate of those errors (:mod:`~maglev_oc.regression.noise_scale`).
    """
    if not (np.isfinite(noise_scale) and noise_scale >= 0.0):
        raise InputError(f"noise_scale must be finite and not negative, got {noise_scale!r}")
    idx = np.concatenate([design.indices(groups), np.asarray(extra, dtype=int)])
    sel = slice(None) if blocks is None else np.asarray(blocks)
    gram_raw = _blocks_of(design.gram, sel, idx).sum(axis=0)
    noise = noise_scale * _blocks_of(design.noise, sel, idx).sum(axis=0)
    rhs = _blocks_of(design.rhs, sel, idx).sum(axis=0)
    yy = float(design.yy[sel].sum())
    message = ""
    # columns that vanish on the fitted rows (they act only on a locked axis), or that the columns
    # before them span (a generic probe's constant beside a constant force): coefficient 0
    dead = np.diag(gram_raw) <= 1e-12 * max(float(np.max(np.diag(gram_raw), initial=0.0)), 1e-300)
    if compensate:  # an optional parameter whose column is mostly the currents' errors: held at 0
        dead |= design.optional[idx] & (np.diag(noise) >= OPTIONAL_NOISE_SHARE * np.diag(gram_raw))
    dead |= _spanned(gram_raw, dead)
    rhs = np.where(dead, 0.0, rhs)

    def system(share: float) -> np.ndarray:
        g = gram_raw - share * noise
        g[dead, :] = 0.0
        g[:, dead] = 0.0
        g[dead, dead] = 1.0
        return g

    share = 1.0 if compensate else 0.0
    coef, ginv, ok = _solve_spd(system(share), rhs)
    if not ok and share > 0:
        # the logged currents' errors, as estimated, are larger than some columns' signal: remove
        # the largest share of them that keeps the normal equations positive definite
        lo, hi = 0.0, 1.0
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if _positive_definite(system(mid)) else (lo, mid)
        share = lo
        coef, ginv, _ = _solve_spd(system(share), rhs)
        message = (
            f"only {share:.0%} of the estimated errors in the logged currents could be removed: some "
            "columns are dominated by them"
        )
    coef = np.where(dead, 0.0, coef)
    chi2 = max(yy - 2 * coef @ rhs + coef @ gram_raw @ coef, 0.0)
    rows = int(np.sum(design.fit)) * int(np.sum(design.weights > 0))
    dof = max(rows - idx.size, 1)
    naive = chi2 / dof * ginv
    ho = np.full(2, np.nan)
    if design.hold_n:
        for a in range(2):
            hg = design.hold_gram[a].take(idx, axis=0).take(idx, axis=1)
            sse = design.hold_yy[a] - 2 * coef @ design.hold_rhs[a][idx] + coef @ hg @ coef
            ho[a] = np.sqrt(max(sse, 0.0) / design.hold_n)
    cov = np.full((idx.size, idx.size), np.nan)
    total_m = 0
    if covariance and blocks is None and design.gram.shape[0]:
        meat, total_m = _long_run_meat(design, idx, coef, share * noise_scale, band)
        meat[dead, :] = 0.0
        meat[:, dead] = 0.0
        cov = ginv @ meat @ ginv
        cov[dead, :] = 0.0
        cov[:, dead] = 0.0
    return SubsetFit(
        groups=tuple(groups),
        index=idx,
        names=tuple(design.names[j] for j in idx),
        coef=coef,
        covariance=cov,
        naive=naive,
        holdout_rms=ho,
        chi_square=float(chi2),
        dof=dof,
        frequencies=total_m,
        compensation=share,
        message=message,
    )


def _long_run_meat(
    design: Design, idx: np.ndarray, coef: np.ndarray, share: float, band: float
) -> tuple[np.ndarray, int]:
    """Long-run covariance of the per-sample scores s_t = sum over axes w^2 x_t (y_t - x_t' theta)
    + (N_b / m_b) theta (the errors-in-variables correction spread evenly over its block's m_b
    samples): the averaged periodogram over the lowest Fourier frequencies, per log, summed.

    Per sample rather than per block: the scores of a filtered equation error have most of their
    power near twice the band, and summing them into 0.5 s blocks (a 2 Hz sampling of a boxcar
    average) folds part of it onto zero frequency, overstating the variance (2.3x on a synthetic
    log whose answer is known, tests/test_regression.py)."""
    fit = design.fit
    w = design.weights
    x = _fitted_columns(design, idx)  # (p, 2, n_fit)
    r = design.target[:, fit] - np.einsum("p,pan->an", coef, x)
    scores = np.einsum("pan,an->pn", x, r * (w**2)[:, None])
    blocks = design.block_of[fit]
    sizes = np.bincount(blocks[blocks >= 0], minlength=design.gram.shape[0])
    noise = _blocks_of(design.noise, slice(None), idx)
    corr = share * np.einsum("bpq,q->bp", noise, coef) / np.maximum(sizes, 1)[:, None]
    scores += corr[blocks].T
    return per_log_long_run(scores, design.prepared.segment[fit], design.prepared.sample_time, band)


def _blocks_of(a: np.ndarray, blocks, idx: np.ndarray) -> np.ndarray:
    """``a[blocks][:, idx][:, :, idx]`` ((B, P, P) Grams) or ``a[blocks][:, idx]`` ((B, P) right-hand
    sides): the same values in the same memory layout (the block index fastest, as numpy lays out
    that indexing), so that sums over the blocks add in the same order, to the bit; the chosen
    columns taken first (never every column of the chosen blocks), then the blocks: np.take copies
    runs of memory where an open mesh (np.ix_) gathers element by element, 1.6x slower here."""
    picked = a.take(idx, axis=1)
    if a.ndim == 3:
        picked = picked.take(idx, axis=2)
    if not (isinstance(blocks, slice) and blocks == slice(None)):
        picked = picked.take(np.arange(a.shape[0])[blocks], axis=0)
    order = tuple(range(picked.ndim))[::-1]
    return np.ascontiguousarray(picked.transpose(order)).transpose(order)


def _fitted_columns(design: Design, idx: np.ndarray) -> np.ndarray:
    """(p, 2, n_fit) the columns ``idx`` on the fitted samples: one copy of the slice when the fitted
    samples are one run (one log), else the columns then the samples picked."""
    at = np.flatnonzero(design.fit)
    if at.size and at[-1] - at[0] + 1 == at.size:
        return design.columns[idx, :, at[0] : at[-1] + 1]
    return np.take(design.columns[idx], at, axis=2)


def predicted(design: Design, fit: SubsetFit, group: str | None = None) -> np.ndarray:
    """Filtered prediction (2, n) of a fit (or of one of its groups) at every sample."""
    if group is None:
        return np.einsum("p,pan->an", fit.coef, design.columns[fit.index])
    coef, _ = fit.group(design, group)
    return np.einsum("p,pan->an", coef, design.columns[design.groups[group]])


def residuals(design: Design, fit: SubsetFit) -> np.ndarray:
    """Filtered residual (2, n), unweighted, at every sample (meaningful where ``valid``)."""
    return design.target - predicted(design, fit)


def _cost_at(design: Design, at: np.ndarray) -> float:
    """Weighted residual sum of squares of the model at ``at`` itself (the design being
    linearized there, its columns times ``at`` reproduce the model)."""
    r = design.target - np.einsum("p,pan->an", at, design.columns)
    return float(np.sum((r[:, design.fit] * design.weights[:, None]) ** 2))


def fit_nonlinear(
    build: Callable[[np.ndarray], Design],
    at: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    scale: np.ndarray,
    *,
    compensate: bool = True,
    max_iterations: int = 30,
    tolerance: float = 1e-8,
) -> tuple[Design, SubsetFit, str, str, int]:
    """Gauss-Newton with step halving: ``build(at)`` gives the design linearized at ``at`` (all
    parameters, in the design's order). Returns (design, fit, status, message, iterations);
    status "converged", "iteration_limit" or "no_decrease"."""
    at = np.clip(np.asarray(at, dtype=float), lower, upper)
    design = build(at)
    groups = list(design.groups)
    fit = fit_subset(design, groups, compensate=compensate, covariance=False)
    cost = _cost_at(design, at)
    for it in range(1, max_iterations + 1):
        step = fit.coef - at
        t = 1.0
        while True:
            trial = np.clip(at + t * step, lower, upper)
            d_t = build(trial)
            f_t = fit_subset(d_t, groups, compensate=compensate, covariance=False)
            c_t = _cost_at(d_t, trial)
            if c_t <= cost * (1 + 1e-12) or t < 1e-6:
                break
            t *= 0.5
        if t < 1e-6 and c_t > cost:
            return design, fit, "no_decrease", "Gauss-Newton: no decrease along the step", it
        moved = float(np.max(np.abs(trial - at) / scale))
        at, design, fit, cost = trial, d_t, f_t, c_t
        if moved < tolerance:
            return design, fit, "converged", f"Gauss-Newton (exact Jacobian) converged in {it} iterations", it
    return (
        design,
        fit,
        "iteration_limit",
        f"Gauss-Newton: {max_iterations} iterations without convergence",
        max_iterations,
    )
