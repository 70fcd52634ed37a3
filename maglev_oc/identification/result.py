"""Result objects of the identification routines (lmfit's MinimizerResult in spirit).

:class:`FitResult` — a nonlinear least-squares fit (equation error or output error): values,
standard errors (HAC-corrected, with the plain ones beside them), covariance, correlation,
residual RMS per axis, per-sample residuals, solver status and timings, and a ``report()``.

:class:`NpfsiResult` — a run of the reduced-order NPFSI estimator: the parameter trajectories
along the log, the final values and the estimator's settings.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.identification.layout import CONSTANT_NAMES, UNITS
from maglev_oc.model.parameters import LumpedConstants
from maglev_oc.model.stage import StageModel
from maglev_oc.results import AXES, Estimate, Result, jsonable

__all__ = ["METHOD_TITLES", "FitResult", "NpfsiResult"]

METHOD_TITLES = {
    "equation_error": "equation error (filtered accelerations, linear in C)",
    "output_error": "output error (multiple shooting, constrained Gauss-Newton)",
}


def _frozen(mapping: Mapping[str, Any]) -> Mapping[str, Any]:
    return MappingProxyType(dict(mapping))


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class FitResult(Result):
    """A least-squares identification result.

    Attributes
    ----------
    method : str
        ``"equation_error"`` or ``"output_error"``.
    names : tuple of str
        Estimated parameters, in the order of ``covariance`` (constants, ``gap_offset``, then
        ``"<term>.<parameter>"``).
    values, stderr, stderr_naive, initial : mappings name -> float
        Estimates, HAC standard errors (honest under autocorrelated residuals), the plain
        s^2 (J'J)^-1 ones, and the starting values.
    fixed : mapping
        Constants held at the model's values.
    covariance, correlation : (p, p) arrays
    residual_rms : mapping axis -> float
        RMS of the fitted residuals per axis, in ``residual_unit``.
    residual_unit : str
        ``"m/s^2"`` (equation error: accelerations) or ``"m"`` (output error: positions).
    residuals : tuple of (2, n) arrays
        Per log, (vertical, horizontal) residual at every sample; NaN where not fitted.
    n_samples, n_residuals : int
        Time samples used and scalar residuals.
    chi_square, reduced_chi_square : float
        Of the weighted residuals.
    hac_frequencies : int
        Fourier frequencies the long-run covariance averages (:mod:`~maglev_oc.regression.covariance`);
        ``variance_inflation`` = HAC / plain variance per parameter.
    success, status, message : bool, str, str
        ``status``: ``"converged"``, or why not (``"iteration_limit"``, ``"no_decrease"``,
        ``"singular"``, ``"kkt_singular"``, ``"line_search_failed"``, ``"covariance_singular"``).
    iterations : int
    timings : mapping
        Wall times [s]: ``prepare`` (derivatives, regressors), ``solve``, ``covariance``, ``total``.
    sources : tuple of str
        The logs.
    settings : mapping
        What determined the fit (differentiator, segment length, weights, ...).
    """

    method: str
    names: tuple[str, ...]
    values: Mapping[str, float]
    stderr: Mapping[str, float]
    stderr_naive: Mapping[str, float]
    initial: Mapping[str, float]
    fixed: Mapping[str, float]
    covariance: np.ndarray
    correlation: np.ndarray
    residual_rms: Mapping[str, float]
    residual_unit: str
    residuals: tuple[np.ndarray, ...]
    n_samples: int
    n_residuals: int
    chi_square: float
    reduced_chi_square: float
    hac_frequencies: int
    variance_inflation: Mapping[str, float]
    success: bool
    status: str
    message: str
    iterations: int
    timings: Mapping[str, float]
    sources: tuple[str, ...]
    settings: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        for name in ("values", "stderr", "stderr_naive", "initial", "fixed", "residual_rms"):
            set_(self, name, _frozen({k: float(v) for k, v in getattr(self, name).items()}))
        set_(self, "variance_inflation", _frozen(dict(self.variance_inflation)))
        set_(self, "timings", _frozen(dict(self.timings)))
        set_(self, "settings", _frozen(dict(self.settings)))
        set_(self, "covariance", _readonly(self.covariance))
        set_(self, "correlation", _readonly(self.correlation))
        set_(self, "residuals", tuple(_readonly(r) for r in self.residuals))
        set_(self, "names", tuple(self.names))
        set_(self, "sources", tuple(self.sources))

    # ------------------------------------------------------------------------------------
    @property
    def estimates(self) -> dict[str, Estimate]:
        """Every estimated parameter as an :class:`~maglev_oc.results.Estimate` (value, HAC
        standard error, unit)."""
        return {k: Estimate(self.values[k], self.stderr[k], UNITS.get(k, "")) for k in self.names}

    def vector(self) -> np.ndarray:
        """The estimates in the order of ``names``."""
        return np.array([self.values[k] for k in self.names])

    def constants(self, base: LumpedConstants) -> LumpedConstants:
        """``base`` with the estimated constants replaced (the others kept)."""
        changes = {k: self.values[k] for k in CONSTANT_NAMES if k in self.values}
        return base.replace(**changes, source=f"identified ({self.method}) from {', '.join(self.sources)}")

    def model(self, base: StageModel) -> StageModel:
        """``base`` with the identified constants (terms and the gap offset are not part of it)."""
        return base.with_constants(self.constants(base.constants))

    def term_parameters(self, term_name: str) -> dict[str, float]:
        """The estimated parameters of one term, by their short names."""
        prefix = f"{term_name}."
        out = {k[len(prefix) :]: v for k, v in self.values.items() if k.startswith(prefix)}
        if not out:
            raise InputError(f"no term {term_name!r} in this fit; parameters: {self.names}")
        return out

    def relative_errors(self, truth: Mapping[str, float]) -> dict[str, float]:
        """(estimate - truth) / truth for every estimated parameter that ``truth`` has."""
        return {k: (self.values[k] - truth[k]) / truth[k] for k in self.names if k in truth and truth[k] != 0}

    def z_scores(self, truth: Mapping[str, float]) -> dict[str, float]:
        """(estimate - truth) / stderr: within +-2 about 95 % of the time if the errors are honest."""
        return {
            k: (self.values[k] - truth[k]) / self.stderr[k]
            for k in self.names
            if k in truth and self.stderr[k] > 0
        }

    # ------------------------------------------------------------------------------------
    def report(self, truth: Mapping[str, float] | None = None) -> str:
        """A readable summary (lmfit's fit_report layout); with ``truth``, errors against it."""
        title = METHOD_TITLES.get(self.method, self.method)
        lines = [f"[[Fit: {title}]]"]
        lines.append(f"    success            = {self.success} (status {self.status}: {self.message})")
        lines.append(f"    logs               = {', '.join(self.sources)}")
        lines.append(f"    # samples          = {self.n_samples}")
        lines.append(f"    # residuals        = {self.n_residuals}")
        lines.append(f"    # variables        = {len(self.names)}")
        lines.append(f"    iterations         = {self.iterations}")
        lines.append(f"    chi-square         = {self.chi_square:.6g}")
        lines.append(f"    reduced chi-square = {self.reduced_chi_square:.6g}")
        for axis in AXES:
            if axis in self.residual_rms:
                lines.append(
                    f"    residual RMS {axis:<10s}= {self.residual_rms[axis]:.4g} {self.residual_unit}"
                )
        lines.append(
            f"    wall time          = {self.timings.get('total', math.nan):.3f} s "
            + "("
            + ", ".join(f"{k} {v:.3f}" for k, v in self.timings.items() if k != "total")
            + ")"
        )
        lines.append("[[Variables]]")
        width = max(len(n) for n in self.names)
        for k in self.names:
            v, s = self.values[k], self.stderr[k]
            rel = f"({100 * abs(s / v):.3g}%)" if v != 0 else ""
            line = f"    {k:<{width}s}: {v:14.7g} +/- {s:<11.4g} {rel:<10s} (init = {self.initial[k]:.6g})"
            if truth is not None and k in truth:
                t = truth[k]
                err = f"{100 * (v - t) / t:+.3g}%" if t != 0 else f"{v - t:+.3g}"
                line += f"  truth {t:.6g}, error {err}" + (f", z {(v - t) / s:+.2f}" if s > 0 else "")
            unit = UNITS.get(k, "")
            if unit:
                line += f"  [{unit}]"
            lines.append(line)
        if self.fixed:
            lines.append("    fixed: " + ", ".join(f"{k} = {v:g}" for k, v in self.fixed.items()))
        lines.append(
            f"    (standard errors: long-run covariance over {self.hac_frequencies} frequencies; plain s^2 "
            "(J'J)^-1 ones are "
            + ", ".join(f"{k} {self.stderr_naive[k]:.3g}" for k in self.names if k in self.stderr_naive)
            + ")"
        )
        pairs = []
        p = len(self.names)
        for i in range(p):
            for j in range(i + 1, p):
                c = self.correlation[i, j]
                if abs(c) >= 0.1:
                    pairs.append((abs(c), f"    C({self.names[i]}, {self.names[j]}) = {c:+.4f}"))
        lines.append("[[Correlations]] (unreported correlations are < 0.100)")
        lines.extend(text for _, text in sorted(pairs, reverse=True))
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no per-sample residuals); NaN (a failed fit's errors) -> None."""
        return jsonable(
            {
                "method": self.method,
                "parameters": {
                    k: {
                        "value": self.values[k],
                        "stderr": self.stderr[k],
                        "stderr_naive": self.stderr_naive[k],
                        "initial": self.initial[k],
                        "unit": UNITS.get(k, ""),
                    }
                    for k in self.names
                },
                "fixed": dict(self.fixed),
                "covariance": self.covariance.tolist(),
                "correlation": self.correlation.tolist(),
                "residual_rms": dict(self.residual_rms),
                "residual_unit": self.residual_unit,
                "n_samples": self.n_samples,
                "n_residuals": self.n_residuals,
                "chi_square": self.chi_square,
                "reduced_chi_square": self.reduced_chi_square,
                "hac_frequencies": self.hac_frequencies,
                "success": self.success,
                "status": self.status,
                "message": self.message,
                "iterations": self.iterations,
                "timings": dict(self.timings),
                "sources": list(self.sources),
                "settings": dict(self.settings),
            }
        )


@dataclass(frozen=True, eq=False)
class NpfsiResult(Result):
    """A run of the reduced-order NPFSI estimator along a log (eq. (3) of 000, 002 sidebar).

    Attributes
    ----------
    names : tuple of str
    t : (n,) array [s]
    trajectory : (p, n) array
        theta_hat at every sample (column k: after the data up to t[k]).
    values : mapping name -> float
        The final estimates.
    eps, gamma : float
        The estimator's epsilon [s] (measurement confidence; also the time constant of its
        state-error filter) and attenuation level.
    Q : (p, p) array or None
        None: Q = A'A (002 sidebar, Sigma' = (1 - gamma^-2) A'A).
    Q0 : (p, p) array
        Sigma(0).
    theta0 : mapping
        The initial guesses.
    sigma_final : (p, p) array
        Sigma at the end (positive definite if the estimator stayed well posed).
    velocity_method : str
        How the velocities y2, y4 were obtained ("high_gain_observer" as in the papers).
    success, status, message
        ``status``: ``"completed"``, ``"diverged"`` or ``"ill_posed"`` (Sigma lost definiteness).
    timings : mapping
        Wall times [s]: ``total``.
    sources : tuple of str
    """

    names: tuple[str, ...]
    t: np.ndarray
    trajectory: np.ndarray
    values: Mapping[str, float]
    eps: float
    gamma: float
    Q: np.ndarray | None
    Q0: np.ndarray
    theta0: Mapping[str, float]
    sigma_final: np.ndarray
    velocity_method: str
    success: bool
    status: str
    message: str
    timings: Mapping[str, float]
    sources: tuple[str, ...] = ()
    settings: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "values", _frozen({k: float(v) for k, v in self.values.items()}))
        set_(self, "theta0", _frozen({k: float(v) for k, v in self.theta0.items()}))
        set_(self, "timings", _frozen(dict(self.timings)))
        set_(self, "settings", _frozen(dict(self.settings)))
        set_(self, "t", _readonly(self.t))
        set_(self, "trajectory", _readonly(self.trajectory))
        set_(self, "Q0", _readonly(self.Q0))
        set_(self, "sigma_final", _readonly(self.sigma_final))
        if self.Q is not None:
            set_(self, "Q", _readonly(self.Q))

    def settling_time(self, name: str, band: float = 0.01) -> float:
        """First time [s] after which ``name`` stays within ``band`` (relative) of its final value."""
        k = self.names.index(name)
        traj = self.trajectory[k]
        final = traj[-1]
        outside = np.abs(traj - final) > band * abs(final)
        if not np.any(outside):
            return float(self.t[0])
        last = int(np.flatnonzero(outside)[-1])
        return float(self.t[min(last + 1, self.t.size - 1)])

    def constants(self, base: LumpedConstants) -> LumpedConstants:
        changes = {k: self.values[k] for k in CONSTANT_NAMES if k in self.values}
        return base.replace(**changes, source=f"NPFSI, eps = {self.eps:g}")

    def report(self, truth: Mapping[str, float] | None = None) -> str:
        q = "A'A (002 sidebar)" if self.Q is None else "given matrix"
        lines = [
            f"[[NPFSI (reduced order, 000 eq. (3)): eps = {self.eps:g} s, gamma = {self.gamma:g}, Q = {q}]]",
            f"    success            = {self.success} (status {self.status}: {self.message})",
            f"    logs               = {', '.join(self.sources)}",
            f"    # samples          = {self.t.size}",
            f"    velocities         = {self.velocity_method}",
            f"    wall time          = {self.timings.get('total', math.nan):.3f} s",
            "[[Variables]]",
        ]
        width = max(len(n) for n in self.names)
        for k in self.names:
            v = self.values[k]
            line = f"    {k:<{width}s}: {v:14.7g}  (init = {self.theta0[k]:.6g}, 1 % band from t = "
            line += f"{self.settling_time(k):.2f} s)"
            if truth is not None and k in truth and truth[k] != 0:
                line += f"  truth {truth[k]:.6g}, error {100 * (v - truth[k]) / truth[k]:+.3g}%"
            lines.append(line)
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary; NaN (a diverged run) -> None."""
        return jsonable(
            {
                "method": "npfsi",
                "eps": self.eps,
                "gamma": self.gamma,
                "Q": None if self.Q is None else self.Q.tolist(),
                "Q0": self.Q0.tolist(),
                "values": dict(self.values),
                "theta0": dict(self.theta0),
                "velocity_method": self.velocity_method,
                "success": self.success,
                "status": self.status,
                "message": self.message,
                "timings": dict(self.timings),
                "sources": list(self.sources),
                "settings": dict(self.settings),
            }
        )
