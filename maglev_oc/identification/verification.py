"""The papers' model-verification procedures (000 Sec. V, 002 Sec. 5), as computations on logs.

* Horizontal dynamics at a fixed gap (000 Sec. V-A, 002 Sec. 5.1): with the gap locked and a
  constant u1 from rest, x3(t) = x3(0) - L1(gap) u1 t^2 / 2 (000 eq. (5)). :func:`fit_parabola`
  fits a parabola to the position and returns L1; :func:`npfsi_fixed_gap` estimates the same
  L1 with the NPFSI estimator applied to x4' = -L1 u1 (000 eq. (4)); :func:`compare_parabola_npfsi`
  gives the papers' discrepancy in % (average 3.8 %, maximum 10 % on the rig).
* Vertical dynamics (000 Sec. V-B, 002 Sec. 5.2): the equilibrium currents measured at fixed
  gaps against eq. (8) of 000 with identified constants (:func:`compare_equilibrium_currents`;
  the papers: within 5 % over 15-25 mm, diverging below 15 mm).
* Cogging (000 Sec. V-C): C2 re-estimated with the mover at x3 = 3 t1 / 2, where eq. (9)'s
  cogging peaks, with C3 and C4 held; the peak cogging force is then
  xi(x1) = K2_hat - K2 = M_v (C2_hat - C2) lam(x1) B(x1)^2 (:func:`cogging_from_c2`). Sign:
  positive xi pulls the mover towards the stator (more attraction than at x3 = 0).

Every function here computes; the twin runs that produce the logs are in
:mod:`~maglev_oc.identification.experiments`, the figures in :mod:`maglev_oc.reporting.identification_plots`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from maglev_oc.data.logs import Log
from maglev_oc.errors import InputError
from maglev_oc.estimation.differentiate import HighGainDifferentiator, differentiate_log
from maglev_oc.identification.npfsi import PAPER_GAMMA, NpfsiEstimator
from maglev_oc.identification.result import NpfsiResult
from maglev_oc.model.equilibrium import equilibrium_currents
from maglev_oc.model.stage import StageModel

__all__ = [
    "EquilibriumComparison",
    "ParabolaComparison",
    "ParabolaFit",
    "cogging_from_c2",
    "compare_equilibrium_currents",
    "compare_parabola_npfsi",
    "fit_parabola",
    "npfsi_fixed_gap",
]


# --- horizontal: parabolas vs NPFSI ------------------------------------------------------------
@dataclass(frozen=True)
class ParabolaFit:
    """x3(t) = c0 + c1 t + c2 t^2 fitted to a constant-current run at a fixed gap.

    Attributes
    ----------
    gap : float [m]
    current : float [A] the (mean) u1 of the run
    L1 : float [m/(s^2 A)] = -2 c2 / u1 (000 eq. (5))
    L1_stderr : float
    coefficients : (3,) c0 [m], c1 [m/s], c2 [m/s^2]
    rms : float [m] residual RMS (about 3.5 um for 10 um quantization plus 2 um noise)
    t : (n,) [s] time since the start of the run; x3 : (n,) [m]
    """

    gap: float
    current: float
    L1: float
    L1_stderr: float
    coefficients: np.ndarray
    rms: float
    t: np.ndarray
    x3: np.ndarray

    def position(self, t: np.ndarray) -> np.ndarray:
        c0, c1, c2 = self.coefficients
        return c0 + c1 * t + c2 * t**2


def fit_parabola(log: Log, gap: float) -> ParabolaFit:
    """Least-squares parabola through x3 of a fixed-gap run; L1 = -2 c2 / u1.

    The initial speed c1 is fitted, not assumed zero (000 eq. (5) assumes it): a mover that is
    not quite at rest at the start would otherwise bias L1.
    """
    t = log.t - log.t[0]
    x3 = log.x[2]
    u1 = float(np.mean(log.u[0]))
    if abs(u1) < 1e-3:
        raise InputError(
            f"{log.source}: u1 is {u1:.3g} A; the parabola experiment needs a constant u1 (e.g. -0.5 A)"
        )
    if np.ptp(log.u[0]) > 0.01 * abs(u1):
        raise InputError(
            f"{log.source}: u1 varies by {np.ptp(log.u[0]):.3g} A; the experiment needs it constant"
        )
    X = np.column_stack([np.ones_like(t), t, t**2])
    coef, *_ = np.linalg.lstsq(X, x3, rcond=None)
    res = x3 - X @ coef
    dof = max(t.size - 3, 1)
    cov = float(res @ res) / dof * np.linalg.inv(X.T @ X)
    L1 = -2 * coef[2] / u1
    return ParabolaFit(
        float(gap),
        u1,
        float(L1),
        float(2 * np.sqrt(cov[2, 2]) / abs(u1)),
        coef,
        float(np.sqrt(np.mean(res**2))),
        t,
        x3,
    )


def npfsi_fixed_gap(
    log: Log,
    *,
    eps: float = 0.01,
    gamma: float = PAPER_GAMMA,
    Q0: np.ndarray | None = None,
    theta0: float,
    differentiator: HighGainDifferentiator | None = None,
) -> NpfsiResult:
    """NPFSI on x4' = -L1 u1 (000 eq. (4)): one parameter, L1 at the locked gap.

    Velocities from the papers' high-gain observer unless ``differentiator`` says otherwise.
    ``theta0`` is the initial guess for L1 [m/(s^2 A)].
    """
    diff = HighGainDifferentiator(log.sample_time) if differentiator is None else differentiator
    der = differentiate_log(log, diff)
    n = log.n
    A = -log.u[0].reshape(n, 1, 1)
    b = np.zeros((n, 1))
    y = der.velocity[1].reshape(n, 1)
    est = NpfsiEstimator(eps, gamma, None, Q0)
    return est.run(
        A,
        b,
        y,
        log.sample_time,
        [theta0],
        names=("L1",),
        t=log.t - log.t[0],
        sources=(log.source,),
        velocity_method=der.method,
    )


@dataclass(frozen=True)
class ParabolaComparison:
    """L1 at each gap from parabolas and from NPFSI (one eps), and their discrepancy.

    discrepancy_pct = 100 |L1_npfsi - L1_parabola| / L1_parabola, per gap; the papers report
    its mean (3.8 %) and maximum (10 %).
    """

    gap: np.ndarray
    parabola: np.ndarray
    npfsi: np.ndarray
    eps: float
    discrepancy_pct: np.ndarray

    @property
    def mean_pct(self) -> float:
        return float(np.mean(self.discrepancy_pct))

    @property
    def max_pct(self) -> float:
        return float(np.max(self.discrepancy_pct))


def compare_parabola_npfsi(
    parabolas: Sequence[ParabolaFit], npfsi_runs: Sequence[NpfsiResult]
) -> ParabolaComparison:
    """The papers' comparison of the two L1 estimates (same gaps, same order)."""
    if len(parabolas) != len(npfsi_runs) or not parabolas:
        raise InputError(f"need one NPFSI run per parabola, got {len(parabolas)} and {len(npfsi_runs)}")
    eps = {r.eps for r in npfsi_runs}
    if len(eps) != 1:
        raise InputError(f"the NPFSI runs use different eps {sorted(eps)}")
    par = np.array([p.L1 for p in parabolas])
    est = np.array([r.values["L1"] for r in npfsi_runs])
    return ParabolaComparison(
        np.array([p.gap for p in parabolas]), par, est, eps.pop(), 100 * np.abs(est - par) / np.abs(par)
    )


# --- vertical: equilibrium currents --------------------------------------------------------------
@dataclass(frozen=True)
class EquilibriumComparison:
    """Measured vs predicted equilibrium currents (000 eq. (8)) over a set of gaps.

    error = predicted - measured [A]; error_pct = 100 |error| / |measured| (NaN where
    |measured| < ``small_current``: near the zero crossing a percentage means nothing and the
    absolute error is the figure to read).
    """

    gap: np.ndarray
    measured: np.ndarray
    predicted: np.ndarray
    error: np.ndarray
    error_pct: np.ndarray
    small_current: float

    def max_pct(self, lo: float, hi: float) -> float:
        """Largest error in % over gaps lo..hi [m] (points near zero current excluded)."""
        sel = (self.gap >= lo - 1e-9) & (self.gap <= hi + 1e-9) & np.isfinite(self.error_pct)
        return float(np.max(self.error_pct[sel])) if np.any(sel) else float("nan")


def compare_equilibrium_currents(
    model: StageModel, gaps: np.ndarray, measured: np.ndarray, *, small_current: float = 0.3
) -> EquilibriumComparison:
    """Predict the equilibrium currents at ``gaps`` [m] with ``model`` (000 eq. (8)) and compare
    them with ``measured`` [A]. ``small_current`` [A]: below it no percentage is given."""
    gaps = np.asarray(gaps, dtype=float)
    measured = np.asarray(measured, dtype=float)
    if gaps.shape != measured.shape:
        raise InputError(f"gaps {gaps.shape} and measured {measured.shape} differ in shape")
    predicted = equilibrium_currents(model, gaps).current
    error = predicted - measured
    with np.errstate(divide="ignore", invalid="ignore"):
        pct = np.where(np.abs(measured) >= small_current, 100 * np.abs(error) / np.abs(measured), np.nan)
    return EquilibriumComparison(gaps, measured, predicted, error, pct, small_current)


# --- cogging -----------------------------------------------------------------------------------------
def cogging_from_c2(model: StageModel, c2_reference: float, c2_offset: float, gaps) -> np.ndarray:
    """Peak cogging force xi(x1) = M_v (C2_offset - C2_reference) lam B^2 [N] at ``gaps`` [m]
    (000 Sec. V-C: K2_hat - K2 with K2 = M_v L2). Positive: more attraction at the offset
    position than at x3 = 0."""
    gaps = np.atleast_1d(np.asarray(gaps, dtype=float))
    l2 = np.asarray(model.shape.map(gaps.size)(gaps[None, :]))[1]
    return model.params.mass_vertical * (c2_offset - c2_reference) * l2
