"""The filtered equation-error regression behind the diagnosis, in Gram-matrix form.

Rows are samples of both axes, stacked; columns are the base model's four constants followed by
every candidate's coefficients. The target is the measured acceleration minus the model's
known part (gravity). Each axis is weighted by the inverse of its base-fit residual scale so
that both axes count alike.

All fits of any subset of columns come from Gram matrices accumulated per block of samples
(blocks of ``block_seconds``), so that

* a fit of any subset on the training blocks is a small linear solve;
* its held-out error is a quadratic form in the held-out Gram matrix;
* the block bootstrap (resampling training blocks) needs no pass over the data;
* the standard errors are batch-means (block) estimates, which stay honest for the strongly
  autocorrelated residuals of filtered, differentiated data: sum over blocks of the block
  scores g_b = X_b' e_b gives the middle of the sandwich (X'X)^-1 S (X'X)^-1.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np

from maglev_oc.diagnose.data import DiagnosisData
from maglev_oc.diagnose.library import Candidate
from maglev_oc.model.stage import StageModel

BASE_NAMES = ("C1", "C2", "C3", "C4")


@dataclass(frozen=True)
class Design:
    """Filtered columns and their block Gram matrices.

    ``columns`` (P, 2, n): column j's contribution to (x2', x4') at each sample, filtered;
    ``target`` (2, n): measured acceleration minus gravity, filtered. ``groups`` maps a name
    ("base" or a candidate's) to its column indices.
    """

    columns: np.ndarray
    target: np.ndarray
    groups: dict[str, np.ndarray]
    weights: np.ndarray  # (2,) per-axis weights (1 / residual scale)
    train_gram: np.ndarray  # (B, P, P) per training block
    train_rhs: np.ndarray  # (B, P)
    train_yy: np.ndarray  # (B,)
    hold_gram: np.ndarray  # (2, P, P) per axis (unweighted), held-out block
    hold_rhs: np.ndarray  # (2, P)
    hold_yy: np.ndarray  # (2,)
    hold_n: int
    holdout: np.ndarray  # (n,) bool
    moving: np.ndarray  # (2,) bool: axes in the regression (vertical, horizontal)

    def indices(self, names: Sequence[str]) -> np.ndarray:
        return np.concatenate([self.groups[n] for n in names])


def _eval_columns(fn: ca.Function, data: DiagnosisData) -> np.ndarray:
    """Evaluate a (2, k) Function of (x, u, du) at every sample: returns (k, 2, n)."""
    n = data.n
    out = np.asarray(fn.map(n)(data.x, data.u, data.du))  # (2, k n)
    k = out.shape[1] // n
    return out.reshape(2, n, k).transpose(2, 0, 1)


def build_design(
    data: DiagnosisData,
    model: StageModel,
    candidates: Sequence[Candidate],
    *,
    block_seconds: float = 0.5,
) -> Design:
    """Evaluate, filter and accumulate every column."""
    n = data.n
    phi, b = model.regressor.map(n)(data.x, data.u)
    phi = np.asarray(phi).reshape(2, n, 4).transpose(2, 0, 1)  # (4, 2, n)
    b = np.asarray(b)  # (2, n)
    blocks = [phi] + [_eval_columns(c.features, data) for c in candidates]
    groups, start = {"base": np.arange(4)}, 4
    for c in candidates:
        groups[c.name] = np.arange(start, start + c.n_coefficients)
        start += c.n_coefficients
    cols = np.concatenate(blocks, axis=0)  # (P, 2, n)
    P = cols.shape[0]
    cols = data.lowpass(cols.reshape(P * 2, n)).reshape(P, 2, n)
    target = data.acc - data.lowpass(b)

    # axis weights from a base fit on the training part (robust residual scale)
    tr = data.train
    xb = cols[:4][:, :, tr].reshape(4, -1).T
    yb = target[:, tr].reshape(-1)
    coef, *_ = np.linalg.lstsq(xb, yb, rcond=None)
    resid = target[:, tr] - np.einsum("p,pan->an", coef, cols[:4][:, :, tr])
    scale = 1.4826 * np.median(np.abs(resid - np.median(resid, axis=1, keepdims=True)), axis=1)
    # an axis that does not move (locked by stoppers) has no equation to fit: weight zero
    weights = np.where(np.asarray(data.moving), 1.0 / np.maximum(scale, 1e-9), 0.0)

    # training blocks
    block = max(1, round(block_seconds / data.sample_time))
    idx = np.nonzero(tr)[0]
    # split at gaps between logs/segments so a block never spans two runs
    breaks = np.nonzero((np.diff(idx) > 1) | (np.diff(data.segment[idx]) != 0))[0] + 1
    runs = np.split(idx, breaks)
    grams, rhs, yys = [], [], []
    for run in runs:
        for k0 in range(0, run.size - block // 2, block):
            sel = run[k0 : k0 + block]
            xw = (cols[:, :, sel] * weights[None, :, None]).reshape(P, -1)
            yw = (target[:, sel] * weights[:, None]).reshape(-1)
            grams.append(xw @ xw.T)
            rhs.append(xw @ yw)
            yys.append(yw @ yw)
    ho = data.holdout
    hg = np.stack([cols[:, a, ho] @ cols[:, a, ho].T for a in range(2)])
    hr = np.stack([cols[:, a, ho] @ target[a, ho] for a in range(2)])
    hy = np.array([target[a, ho] @ target[a, ho] for a in range(2)])
    return Design(cols, target, groups, weights, np.array(grams), np.array(rhs), np.array(yys),
                  hg, hr, hy, int(ho.sum()), ho.copy(), np.asarray(data.moving))


@dataclass(frozen=True)
class SubsetFit:
    """A fit of some column groups on the training blocks."""

    names: tuple[str, ...]
    index: np.ndarray  # column indices
    coef: np.ndarray  # (p,)
    cov: np.ndarray  # (p, p) block (batch-means) sandwich covariance
    holdout_rms: np.ndarray  # (2,) [m/s^2] per axis (vertical, horizontal)

    def coefficients(self, design: Design, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(coefficients, covariance) of one group."""
        pos = np.array([int(np.nonzero(self.index == j)[0][0]) for j in design.groups[name]])
        return self.coef[pos], self.cov[np.ix_(pos, pos)]


def training_sums(design: Design, blocks: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(Gram, right-hand side) summed over ``blocks`` (with repetition for the bootstrap)."""
    if blocks is None:
        return design.train_gram.sum(axis=0), design.train_rhs.sum(axis=0)
    return design.train_gram[blocks].sum(axis=0), design.train_rhs[blocks].sum(axis=0)


def fit_subset(
    design: Design,
    names: Sequence[str],
    *,
    sums: tuple[np.ndarray, np.ndarray] | None = None,
    with_covariance: bool = True,
) -> SubsetFit:
    """Least squares on the chosen groups over the training blocks. ``sums`` from
    :func:`training_sums` (default: all blocks); the covariance needs all blocks."""
    idx = design.indices(names)
    gram, rhs = training_sums(design) if sums is None else sums
    g = gram[np.ix_(idx, idx)].copy()
    r = rhs[idx]
    # columns that vanish on the fitted rows (they act only on a locked axis) get a unit
    # diagonal, so their coefficient is zero instead of the solve failing
    dead = np.diag(g) <= 1e-12 * max(float(np.max(np.diag(g))), 1e-300)
    g[dead, dead] = 1.0
    try:
        coef = np.linalg.solve(g, r)
    except np.linalg.LinAlgError:
        coef = np.linalg.lstsq(g, r, rcond=None)[0]
    # held-out RMS per axis, unweighted
    ho = np.empty(2)
    for a in range(2):
        hg = design.hold_gram[a][np.ix_(idx, idx)]
        sse = design.hold_yy[a] - 2 * coef @ design.hold_rhs[a][idx] + coef @ hg @ coef
        mse = sse / max(design.hold_n, 1)
        ho[a] = np.sqrt(max(mse, 0.0))
    cov = np.full((idx.size, idx.size), np.nan)
    if with_covariance:
        scores = design.train_rhs[:, idx] - design.train_gram[:, idx][:, :, idx] @ coef
        meat = scores.T @ scores
        try:
            ginv = np.linalg.inv(g)
        except np.linalg.LinAlgError:
            ginv = np.linalg.pinv(g)
        cov = ginv @ meat @ ginv
    return SubsetFit(tuple(names), idx, coef, cov, ho)


def residuals(design: Design, fit: SubsetFit) -> np.ndarray:
    """Per-sample filtered acceleration residual (2, n) [m/s^2] of a fit, on every sample."""
    pred = np.einsum("p,pan->an", fit.coef, design.columns[fit.index])
    return design.target - pred


def contribution_rms(design: Design, fit: SubsetFit, name: str) -> np.ndarray:
    """RMS over the held-out block of one group's predicted acceleration, per axis [m/s^2]."""
    coef, _ = fit.coefficients(design, name)
    cols = design.columns[design.groups[name]]
    hold = np.nonzero(design.holdout)[0]
    pred = np.einsum("p,pan->an", coef, cols[:, :, hold])
    return np.sqrt(np.mean(pred**2, axis=1))
