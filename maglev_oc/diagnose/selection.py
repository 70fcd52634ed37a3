"""Forward stepwise selection of effects by held-out error, with a complexity penalty, a
significance test and a block-bootstrap confidence.

Gain of adding a candidate c to the current set S: the relative drop of the held-out
mean-square residual per axis, averaged over the two axes (each axis counts alike whatever its
noise level), less ``penalty`` per coefficient:

    gain(c) = 1/2 sum_axis [1 - MSE_holdout(base + S + c, axis) / MSE_holdout(base + S, axis)]
              - penalty * k_c

At each step the candidate with the largest gain is added if

* the gain exceeds ``min_gain`` (default 0.01: one percent of what is left of the held-out
  error on average, two percent on a single axis), and
* its coefficients are jointly significant on the training data: a Wald test with the block
  (batch-means) covariance at ``alpha`` (default 1e-4), and
* it matters physically: its predicted acceleration has an RMS of at least ``min_effect``
  on the held-out block on some axis. The default 2.25e-3 m/s^2 is the disturbance that the
  regulated stage (closed-loop bandwidth about 15 rad/s) turns into the encoder's 10 um:
  a / omega_c^2 = 10 um. Smaller effects exist in every log (the zero-order hold alone delays
  the currents by half a sample) but nothing a user could see or compensate.

It stops when no candidate passes or after ``max_effects``. The confidence of each choice is the
share of block-bootstrap resamples of the training data in which the same candidate wins that
step (given the earlier choices).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from maglev_oc.diagnose.regression import (
    Design,
    SubsetFit,
    contribution_rms,
    fit_subset,
    training_sums,
)


@dataclass(frozen=True)
class Step:
    """One accepted (or the first rejected) step of the selection."""

    name: str
    gain: float  # relative drop of the held-out error (see module doc)
    wald: float  # chi^2 statistic of the coefficients
    wald_threshold: float
    holdout_rms: np.ndarray  # (2,) after adding it [m/s^2]
    contribution_rms: np.ndarray  # (2,) RMS of its predicted acceleration, held out [m/s^2]
    confidence: float  # bootstrap share choosing it
    runner_up: str
    runner_up_gain: float
    accepted: bool


@dataclass(frozen=True)
class Selection:
    steps: list[Step]
    ranking: list[tuple[str, float]]  # first-step gains of every candidate, best first
    base: SubsetFit
    final: SubsetFit

    @property
    def selected(self) -> list[str]:
        return [s.name for s in self.steps if s.accepted]


def _gains(design: Design, chosen: list[str], pool: Sequence[str], current: SubsetFit,
           penalty: float, sums=None) -> dict[str, float]:
    ref = np.maximum(current.holdout_rms**2, 1e-30)
    out = {}
    for name in pool:
        fit = fit_subset(design, ["base", *chosen, name], sums=sums, with_covariance=False)
        k = design.groups[name].size
        drop = (1 - fit.holdout_rms**2 / ref)[design.moving]
        out[name] = float(np.mean(drop)) - penalty * k
    return out


def select(
    design: Design,
    candidates: Sequence[str],
    *,
    min_gain: float = 0.01,
    penalty: float = 0.002,
    alpha: float = 1e-4,
    max_effects: int = 4,
    min_effect: float = 2.25e-3,
    bootstrap: int = 40,
    seed: int = 0,
) -> Selection:
    """Forward stepwise selection over the candidate names (groups of ``design``)."""
    rng = np.random.default_rng(seed)
    n_blocks = design.train_gram.shape[0]
    base = fit_subset(design, ["base"])
    chosen: list[str] = []
    pool = list(candidates)
    current = base
    steps: list[Step] = []
    ranking: list[tuple[str, float]] = []
    resamples = [training_sums(design, rng.integers(0, n_blocks, n_blocks)) for _ in range(bootstrap)]
    while pool and len(chosen) < max_effects:
        gains = _gains(design, chosen, pool, current, penalty)
        order = sorted(gains, key=gains.get, reverse=True)
        if not chosen:
            ranking = [(n, gains[n]) for n in order]
        best = order[0]
        runner = order[1] if len(order) > 1 else ""
        fit = fit_subset(design, ["base", *chosen, best])
        coef, cov = fit.coefficients(design, best)
        try:
            wald = float(coef @ np.linalg.solve(cov, coef))
        except np.linalg.LinAlgError:
            wald = 0.0
        threshold = float(chi2.ppf(1 - alpha, coef.size))
        contribution = contribution_rms(design, fit, best)
        accepted = bool(gains[best] > min_gain and wald > threshold
                        and contribution[design.moving].max() >= min_effect)
        votes = 0
        for sums in resamples:
            current_b = fit_subset(design, ["base", *chosen], sums=sums, with_covariance=False)
            g = _gains(design, chosen, pool, current_b, penalty, sums)
            votes += max(g, key=g.get) == best
        steps.append(Step(best, gains[best], wald, threshold, fit.holdout_rms, contribution,
                          votes / max(len(resamples), 1), runner,
                          gains.get(runner, float("nan")), accepted))
        if not accepted:
            break
        chosen.append(best)
        pool.remove(best)
        current = fit
    final = fit_subset(design, ["base", *chosen])
    return Selection(steps, ranking, base, final)
