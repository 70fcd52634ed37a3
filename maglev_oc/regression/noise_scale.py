"""How large the logged currents' errors are, from the fit's consistency across two bands.

The errors-in-variables correction (:mod:`~maglev_oc.regression.data`, item 4) takes the logged
currents' error to be white at the level of their noise floor between 0.3 and 0.45 of the sample
rate, times the share a logging decimation does not apply (1 - 1/q). What the fit needs is the
error's level inside its own band, a few Hz, and the floor measures it there only when the
commands' fast content is white. A loop whose velocity observer is fast puts real, applied
command content into that floor (an observer at 2800 rad/s is 446 Hz, inside it): the correction
is then too large and C1 comes out high (+4.5 % on a clean log of the independent generator with
such an observer; OLS gives -18 %, the output-error fit -3.5 %).

The level inside the band is identifiable from the log itself. The constants are the same in any
band of the equation error, while a white error's share of the columns grows with the band: fitted
on a narrow band (:data:`LOW_BAND`) and on the fit's own, the constants agree only at the right
error level. :func:`band_consistent_scale` finds the multiple s of the estimated error at which
they agree best (standardized differences of the compared parameters, squared and summed), and
takes it when the bands do agree there (the disagreement below the 95 % point of chi-square with
one degree of freedom fewer than the parameters compared) and its 95 % range (the scales whose
disagreement is within the chi-square(1) 95 % point of the best) excludes 0. When they agree at
no level, the model lacks something that depends on the band; when the range reaches 0 (no error
at all in the logged currents, which a loop logged by taking every q-th command always has), the
bands do not tell the level. Either way the floor's estimate stands (s = 1). Beside effects the
diagnosis has chosen, a range reaching 0 is what an effect's misfit does: on the independent
generator's noisy rig an end effect beside guide friction gave 0 (range 0-0.05), and the refit
at it put C1 7.5 % low.

s = 1 is not privileged: the floor's estimate is itself an estimate, biased by any command
content in the floor's band. A first version took the best scale only when it fitted 95 % better
than 1; on `../shared/logs/independent_clean.csv` the bands agreed best at 0.74 (C1 14.78, the
2 Hz fits 14.69-14.81, the output-error fit 14.70) and 1 was inside the range, so C1 stayed at
the floor's 14.93. On 20 clean logs of each rig the best scale gives C1 as close or closer (mean
error +0.00 % and +0.06 % against +0.05 % and +0.11 %, largest unchanged).

Measured (bench/README, *The logged currents' error from two bands*): on clean logs of the
independent generator under eight rig settings, C1 within 0.45 % of the truth (before: up to
+4.5 %); the references' content must lie below the narrow band (the papers' and the generator's
sines are at 0.1-1 Hz; steps have most of their energy there too).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.stats import chi2

from maglev_oc.regression.design import Design
from maglev_oc.regression.solve import fit_subset

__all__ = ["LOW_BAND", "MAX_SCALE", "NoiseScale", "band_consistent_scale"]

LOW_BAND = 2.0
"""[Hz] The narrow band the fit's own is compared with: above the papers' references (0.1-1 Hz
sines and the steps' bulk), five times below the default 10 Hz."""

MAX_SCALE = 2.0
"""The largest multiple of the floor's estimate considered: a loop whose commands have more fast
content above the log's Nyquist rate than in the floor's band makes the error larger than the
floor says, not without bound."""

CONFIDENCE = 0.95
"""The level of the bands' agreement test (chi-square, one degree of freedom fewer than the
parameters compared) and of the scale's range (chi-square, one degree of freedom)."""


@dataclass(frozen=True)
class NoiseScale:
    """The multiple of the logged currents' estimated error that makes two bands agree.

    Attributes
    ----------
    scale : float  taken (1 when the bands agree at no level, agree in a range reaching 0, or
        nothing was looked for)
    best : float  where the bands agree best, in [0, MAX_SCALE]
    misfit_best, misfit_one : float  the bands' disagreement (sum of squared standardized
        differences of the compared parameters) at ``best`` and at 1
    parameters : tuple of str  the parameters compared
    message : str
    interval : (float, float)  the scales whose disagreement is within the chi-square(1) 95 % point
        of the best (on the search's 0.05 grid, widened to ``best``)
    agreement : float  the disagreement the bands may show and still agree (chi-square 95 % point,
        one degree of freedom fewer than the parameters compared)
    """

    scale: float
    best: float
    misfit_best: float
    misfit_one: float
    parameters: tuple[str, ...]
    message: str
    interval: tuple[float, float] = (float("nan"), float("nan"))
    agreement: float = float("nan")

    @classmethod
    def not_calibrated(cls, reason: str) -> NoiseScale:
        """Scale 1, with why no other was looked for."""
        return cls(1.0, float("nan"), float("nan"), float("nan"), (), reason)

    @property
    def calibrated(self) -> bool:
        return self.scale != 1.0

    def to_dict(self) -> dict:
        """JSON: NaN (nothing looked for) as null."""

        def num(x: float) -> float | None:
            return x if np.isfinite(x) else None

        return {
            "scale": self.scale,
            "best": num(self.best),
            "misfit_best": num(self.misfit_best),
            "misfit_at_one": num(self.misfit_one),
            "parameters": list(self.parameters),
            "interval": [num(self.interval[0]), num(self.interval[1])],
            "agreement_threshold": num(self.agreement),
            "message": self.message,
        }


def band_consistent_scale(
    wide: Design, narrow: Design, groups: Sequence[str], compared: Sequence[str] = ("base",)
) -> NoiseScale:
    """The scale s of the errors' estimate at which the fits of ``groups`` on the ``wide`` and the
    ``narrow`` design (the same logs, terms and masks, two bands) agree best on the parameters of
    the ``compared`` groups, each difference over its standard error in the narrow fit at s = 1
    (long-run covariance; the narrow fit's are the larger)."""
    idx_w, idx_n = wide.indices(compared), narrow.indices(compared)
    names = tuple(wide.names[j] for j in idx_w)
    if names != tuple(narrow.names[j] for j in idx_n):
        raise ValueError(f"the designs' compared parameters differ: {names} and {narrow.names}")
    reference = fit_subset(narrow, groups)
    pos = np.searchsorted(reference.index, idx_n)
    se = np.sqrt(np.diag(reference.covariance)[pos])
    live = np.isfinite(se) & (se > 0)
    if not live.any():
        return NoiseScale.not_calibrated("no compared parameter has a standard error on the narrow band")

    def coefficients(design: Design, idx: np.ndarray, s: float) -> np.ndarray:
        fit = fit_subset(design, groups, covariance=False, noise_scale=s)
        return fit.coef[np.searchsorted(fit.index, idx)]

    def misfit(s: float) -> float:
        d = (coefficients(wide, idx_w, s) - coefficients(narrow, idx_n, s))[live] / se[live]
        return float(d @ d)

    grid = np.linspace(0.0, MAX_SCALE, 41)
    values = np.array([misfit(s) for s in grid])
    k = int(np.argmin(values))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    found = minimize_scalar(misfit, bounds=(lo, hi), method="bounded", options={"xatol": 1e-4})
    best, at_best = float(grid[k]), float(values[k])
    if found.fun < at_best:
        best, at_best = float(found.x), float(found.fun)
    at_one = misfit(1.0)
    span = float(chi2.ppf(CONFIDENCE, 1))
    inside = grid[values - at_best <= span]
    interval = (
        (min(float(inside.min()), best), max(float(inside.max()), best)) if inside.size else (best, best)
    )
    agreement = float(chi2.ppf(CONFIDENCE, max(int(live.sum()) - 1, 1)))
    where = f"{best:.2f} (95 % range {interval[0]:.2f}-{interval[1]:.2f})"
    if at_best <= agreement and interval[0] > 0:
        return NoiseScale(
            best,
            best,
            at_best,
            at_one,
            names,
            f"the logged currents' error taken at {where} times its floor's estimate, where the "
            f"{', '.join(names)} fitted on two bands agree (disagreement {at_best:.2f}, within "
            f"{agreement:.2f}; {at_one:.2f} at 1)",
            interval,
            agreement,
        )
    if at_best <= agreement:
        why = (
            f"the bands agree best at {where}, a range down to no error at all in the logged "
            "currents: the bands do not tell their level here"
        )
    else:
        why = (
            f"the bands agree at no level (the least disagreement, {at_best:.2f} at {best:.2f}, is "
            f"above {agreement:.2f}); the model lacks something that depends on the band"
        )
    return NoiseScale(
        1.0,
        best,
        at_best,
        at_one,
        names,
        f"the logged currents' error as its floor estimates it: {why}",
        interval,
        agreement,
    )
