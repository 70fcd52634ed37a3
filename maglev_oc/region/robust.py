"""What the nominal certificate is worth on a plant whose constants are uncertain (sampled, not certified).

The FL regulator keeps the nominal constants; the plant's C1..C4 lie in an uncertainty set.
Everything here is *empirical*: Monte Carlo over plants and starts (:mod:`~maglev_oc.region.sweep`),
never a proof.

* :func:`robustness_table` — per set-point and per confidence level (covariance scaled by the
  chi-square quantile), the share of runs started uniformly in the *nominal* certified set
  {z~' P z~ <= c} that stay in F (R >= 0, |u| <= limit, no stopper): the empirical robustness
  of the nominal certificate.
* :func:`critical_radius` — how far the confidence set can grow (in standard deviations of the
  covariance, and as the confidence level that means) before runs from the nominal set (or from
  one start, e.g. the papers' large step) leave F: a bracket [last radius with no violation,
  first radius with one] found by bisection.
* :func:`empirical_robust_level` — the nominal level shrunk until ``n`` plant-and-start samples
  inside {z~' P z~ <= c_rob} show no violation: an *empirical* robust level, not a certified one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.model.parameters import PAPER_CONSTANTS, LumpedConstants
from maglev_oc.region.sweep import PlantSet, SweepResult, SweepSpec, run_sweep

__all__ = [
    "ASSUMED_RELATIVE_STDERR",
    "CONFIDENCE_LEVELS",
    "CriticalRadius",
    "RobustLevel",
    "RobustnessRow",
    "assumed_covariance",
    "critical_radius",
    "empirical_robust_level",
    "paper_tables_box",
    "robustness_table",
]

CONFIDENCE_LEVELS = (0.5, 0.9, 0.95, 0.99)
ASSUMED_RELATIVE_STDERR = (0.02, 0.02, 0.02, 0.10)
"""Relative standard errors of C1..C4 of :func:`assumed_covariance`: an assumption for when no
identification's covariance is at hand, about 50-100 times the long-run standard errors the
identification bench finds on a 60 s excitation log (bench/README.md), C4 the least known."""


def assumed_covariance(constants: LumpedConstants, relative=ASSUMED_RELATIVE_STDERR) -> np.ndarray:
    """diag((relative * C)^2) (4, 4): independent constants with the given relative standard errors."""
    c = np.asarray(constants.as_array(), dtype=float)
    rel = np.asarray(relative, dtype=float)
    if rel.shape != (4,) or np.any(rel < 0):
        raise InputError(f"relative standard errors must be 4 values >= 0, got {relative!r}")
    return np.diag((rel * c) ** 2)


def paper_tables_box() -> PlantSet:
    """The box spanned by every column of the papers' Tables II and III: the spread of the
    papers' own estimates of C1..C4 across eps and procedure."""
    values = np.array([c.as_array() for c in PAPER_CONSTANTS.values()])
    box = PlantSet.box(values.min(axis=0), values.max(axis=0))
    return PlantSet(
        box.kind, box.center, lower=box.lower, upper=box.upper, label="papers' Tables II-III " + box.label
    )


@dataclass(frozen=True)
class RobustnessRow:
    """One reference on one plant set: runs from the nominal certified set."""

    reference: str
    plants: str
    confidence: float  # NaN for the nominal plant or a box
    runs: int
    violations: int
    share_feasible: float
    sweep: SweepResult


def robustness_table(
    specs: dict[str, SweepSpec],
    covariance,
    *,
    levels=CONFIDENCE_LEVELS,
    box: PlantSet | None = None,
    runs: int = 2000,
    seed: int = 0,
    task_size: int = 250,
    client=None,
) -> list[RobustnessRow]:
    """Per reference: the nominal plant, the confidence sets at ``levels`` and optionally a box.

    Parameters
    ----------
    specs : dict label -> SweepSpec
        One sweep per reference (starts in its nominal certified set); the plant set is replaced.
    covariance : (4, 4) array or None
        Of the plant's constants around the controller's (None: no confidence rows).
    levels : sequence of float
    box : PlantSet, optional
    runs, seed, task_size, client
        Of every sweep (:func:`~maglev_oc.region.sweep.run_sweep`); the same seed gives every
        set the same starts.

    Returns
    -------
    list of RobustnessRow
    """
    rows = []
    for label, spec in specs.items():
        sets: list[tuple[PlantSet, float]] = [(PlantSet.point(spec.constants), math.nan)]
        if covariance is not None:
            sets += [(PlantSet.confidence(spec.constants, covariance, p), p) for p in levels]
        if box is not None:
            sets.append((box, math.nan))
        for plants, p in sets:
            res = run_sweep(spec.with_plants(plants), runs, seed=seed, task_size=task_size, client=client)
            rows.append(RobustnessRow(label, plants.label, p, res.n, res.violations, res.share_feasible, res))
    return rows


@dataclass(frozen=True)
class CriticalRadius:
    """Where growing the confidence set first breaks a certificate (or a start), sampled.

    ``safe_radius``: the largest radius r (in standard deviations: the set
    (C - C0)' cov^-1 (C - C0) <= r^2) with no violation in ``runs`` runs; ``broken_radius``:
    the least with one (inf: none up to ``max_radius``). The confidence levels are the
    chi-square probabilities of r^2 (``*_tail`` = 1 - level, which can be far below 1e-16).
    """

    reference: str
    safe_radius: float
    broken_radius: float
    dof: int
    runs: int

    @property
    def safe_tail(self) -> float:
        from scipy.stats import chi2

        return float(chi2.sf(self.safe_radius**2, self.dof))

    @property
    def broken_tail(self) -> float:
        from scipy.stats import chi2

        return float(chi2.sf(self.broken_radius**2, self.dof)) if math.isfinite(self.broken_radius) else 0.0


def critical_radius(
    label: str,
    spec: SweepSpec,
    covariance,
    *,
    runs: int = 400,
    max_radius: float = 200.0,
    rel_tol: float = 0.1,
    seed: int = 0,
    task_size: int = 250,
    client=None,
) -> CriticalRadius:
    """Bisection (on log r) for the radius of the confidence set where runs of ``spec`` first
    leave F (class docstring). Each probe is a sweep of ``runs`` runs with the same seed."""
    cov = np.asarray(covariance, dtype=float)
    eig = np.linalg.eigvalsh(cov)
    dof = int(np.sum(eig > 1e-12 * max(eig.max(), 1e-300)))
    if dof == 0:
        raise InputError("the covariance is zero: no confidence set to grow")

    def broken(r: float) -> bool:
        plants = PlantSet(
            "ellipsoid", tuple(spec.constants), tuple(map(tuple, r**2 * cov)), label=f"{r:.3g} sigma"
        )
        res = run_sweep(
            spec.with_plants(plants), runs, seed=seed, task_size=task_size, client=client, progress=False
        )
        return res.violations > 0

    lo, hi = 0.0, max_radius
    if not broken(hi):
        return CriticalRadius(label, max_radius, math.inf, dof, runs)
    r = 1.0
    while r < hi and not broken(r):  # bracket from below, doubling
        lo, r = r, 2 * r
    hi = min(r, hi)
    while hi - lo > rel_tol * hi:
        mid = math.sqrt(lo * hi) if lo > 0 else hi / 2
        if broken(mid):
            hi = mid
        else:
            lo = mid
    return CriticalRadius(label, lo, hi, dof, runs)


@dataclass(frozen=True)
class RobustLevel:
    """An *empirical* robust level: no violation in ``runs`` plant-and-start samples inside
    {z~' P z~ <= level} (the nominal certificate's P), plants from ``plants``. Sampled, not
    certified. ``check`` is the last sweep: ``check.success`` False when ``max_rounds`` of
    shrinking did not reach a sweep without violations."""

    reference: str
    plants: str
    nominal_level: float
    level: float
    runs: int
    rounds: int
    check: SweepResult

    @property
    def ratio(self) -> float:
        """level / nominal level (1: the nominal set needed no shrinking)."""
        return self.level / self.nominal_level


def empirical_robust_level(
    label: str,
    spec: SweepSpec,
    plants: PlantSet,
    *,
    runs: int = 10_000,
    seed: int = 0,
    task_size: int = 250,
    client=None,
    max_rounds: int = 8,
) -> RobustLevel:
    """Shrink the nominal level until a sweep of ``runs`` samples inside it shows no violation:
    each round the level drops to 0.95 times the least V/c of a violating run; every round draws
    fresh samples (seed + round)."""
    if spec.P is None:
        raise InputError("an empirical robust level needs a certified set (P, level), not a fixed start")
    level = spec.level
    for k in range(max_rounds):
        res = run_sweep(
            replace(spec, plants=plants, level=level),  # every other setting (effects, ...) kept
            runs,
            seed=seed + k,
            task_size=task_size,
            client=client,
        )
        if res.violations == 0:
            return RobustLevel(label, plants.label, spec.level, level, runs, k + 1, res)
        level *= 0.95 * float(np.min(res.start_ratio[res.violating]))
    return RobustLevel(label, plants.label, spec.level, level, runs, max_rounds, res)  # res.success False
