"""``diagnose``: fit the base model to logs, find what its residual is made of, add the effect it
traces to, and report the error before and after on held-out data (SPEC 3).

Steps (each in its own module):

1. :mod:`~maglev_oc.diagnose.data` — velocities and accelerations from the encoder readings,
   one common zero-phase low-pass, a held-out block at the end of each log;
2. base fit — C1..C4 by (filtered) equation-error least squares on the fitting block;
3. :mod:`~maglev_oc.diagnose.trace` — the residual against x3 (spatial spectrum), the gap, the
   velocities, the position and the current rates;
4. :mod:`~maglev_oc.diagnose.library` — the candidate effects, plus guide waviness at any
   unexplained spatial period the trace found;
5. :mod:`~maglev_oc.diagnose.selection` — forward stepwise selection by held-out error with a
   complexity penalty, significance and physical-size tests and a bootstrap confidence;
6. refit of base constants and effect parameters together; held-out error per axis before and
   after, and the short-horizon output error (simulating the model over 50 ms windows).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.data.logs import Log
from maglev_oc.diagnose.data import DiagnosisData, prepare
from maglev_oc.diagnose.library import Candidate, Physical, candidate_library, waviness_candidate
from maglev_oc.diagnose.regression import BASE_NAMES, build_design, fit_subset, residuals
from maglev_oc.diagnose.selection import Selection, select
from maglev_oc.diagnose.trace import AXIS_NAMES, Trace, trace, unexplained_periods
from maglev_oc.model.parameters import LumpedConstants
from maglev_oc.model.stage import StageModel

ERROR_METRIC = (
    "RMS of the acceleration equation error (measured minus model, both through the same "
    "zero-phase low-pass) on the held-out block at the end of each log, per axis, in m/s^2 "
    "(null for an axis that does not move in the logs)"
)


@dataclass(frozen=True)
class Effect:
    """A selected effect with its physical parameters (value, standard error, unit)."""

    name: str
    explanation: str
    axis: str
    parameters: dict[str, Physical]
    confidence: float  # bootstrap share choosing it at its step
    gain: float  # relative drop of the held-out error when it was added
    contribution_rms: tuple[float, float]  # held-out RMS of its acceleration per axis [m/s^2]
    runner_up: str
    signature: str
    coefficients: np.ndarray  # fitted coefficients (linear in the candidate's features)
    candidate: Candidate = field(repr=False)


@dataclass(frozen=True)
class Diagnosis:
    success: bool
    message: str
    sources: tuple[str, ...]
    constants_base: dict[str, Physical]  # base model alone
    constants_final: dict[str, Physical]  # refitted with the effects
    effects: list[Effect]
    error_before: dict[str, float]
    error_after: dict[str, float]
    output_error_before: dict[str, float]  # [m] RMS over 50 ms simulations, held out
    output_error_after: dict[str, float]
    ranking: list[tuple[str, float]]
    selection: Selection
    trace: Trace
    residual_before: np.ndarray  # (2, n) [m/s^2]
    residual_after: np.ndarray
    data: DiagnosisData = field(repr=False)
    timings: dict[str, float] = field(default_factory=dict)

    def to_json(self) -> dict:
        """The SPEC 3 contract, plus details (all plain JSON types)."""

        def phys(d: dict[str, Physical]) -> dict:
            return {k: _num(v.value) for k, v in d.items()}

        def phys_full(d: dict[str, Physical]) -> dict:
            return {k: {"value": _num(v.value), "stderr": _num(v.stderr), "unit": v.unit}
                    for k, v in d.items()}

        return {
            "effects": [
                {
                    "name": e.name,
                    "explanation": e.explanation,
                    "axis": e.axis,
                    "parameters": phys(e.parameters),
                    "parameter_details": phys_full(e.parameters),
                    "confidence": _num(e.confidence),
                    "holdout_gain": _num(e.gain),
                    "contribution_rms": {a: _num(v) for a, v in zip(AXIS_NAMES, e.contribution_rms,
                                                                     strict=True)},
                    "runner_up": e.runner_up,
                    "evidence": e.signature,
                }
                for e in self.effects
            ],
            "error_before": {k: _num(v) for k, v in self.error_before.items()},
            "error_after": {k: _num(v) for k, v in self.error_after.items()},
            "error_metric": ERROR_METRIC,
            "output_error_before": {k: _num(v) for k, v in self.output_error_before.items()},
            "output_error_after": {k: _num(v) for k, v in self.output_error_after.items()},
            "output_error_metric": "RMS position error of the model simulated over 50 ms windows "
                                   "from the estimated state with the logged currents, held-out "
                                   "block, per axis, in m",
            "constants_base": phys_full(self.constants_base),
            "constants_final": phys_full(self.constants_final),
            "candidate_ranking": [{"name": n, "holdout_gain": _num(g)} for n, g in self.ranking],
            "selection_steps": [
                {"name": s.name, "accepted": bool(s.accepted), "holdout_gain": _num(s.gain),
                 "wald": _num(s.wald), "wald_threshold": _num(s.wald_threshold),
                 "contribution_rms": [_num(v) for v in s.contribution_rms],
                 "confidence": _num(s.confidence), "runner_up": s.runner_up}
                for s in self.selection.steps
            ],
            "logs": list(self.sources),
            "holdout": {"fraction": self.data.settings["holdout_fraction"],
                        "samples": int(self.data.holdout.sum()),
                        "fit_samples": int(self.data.train.sum())},
            "success": self.success,
            "message": self.message,
            "timings_s": {k: _num(v) for k, v in self.timings.items()},
        }


def _num(v: float) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


def _constants(design, fit) -> dict[str, Physical]:
    """C1..C4 with standard errors; NaN for the constants of an axis that did not move."""
    coef, cov = fit.coefficients(design, "base")
    units = ("m/(s^2 A)", "m/(s^2 T^2)", "m/(s^2 A T)", "m/(s^2 A^2)")
    axis_of = (1, 0, 0, 0)  # C1 horizontal, C2..C4 vertical
    out = {}
    for k, n in enumerate(BASE_NAMES):
        if design.moving[axis_of[k]]:
            out[n] = Physical(float(coef[k]), float(math.sqrt(max(cov[k, k], 0))), units[k])
        else:
            out[n] = Physical(float("nan"), float("nan"), units[k])
    return out


def _per_axis(values, moving) -> dict[str, float]:
    return {a: float(v) if m else float("nan") for a, v, m in zip(AXIS_NAMES, values, moving, strict=True)}


def diagnose(
    logs: Sequence[Log],
    model: StageModel | None = None,
    *,
    holdout_fraction: float = 0.25,
    bootstrap: int = 30,
    seed: int = 0,
) -> Diagnosis:
    """Diagnose ``logs`` against ``model`` (default: the papers' stage; its constants are only
    the starting point, they are refitted)."""
    t0 = time.perf_counter()
    model = StageModel() if model is None else model
    timings = {}
    data = prepare(list(logs), holdout_fraction=holdout_fraction)
    timings["prepare"] = time.perf_counter() - t0

    # 2. base fit (no candidates) and its residual
    t1 = time.perf_counter()
    design0 = build_design(data, model, [])
    base0 = fit_subset(design0, ["base"])
    # constants of a locked axis cannot be fitted: keep the model's
    c = np.where([data.moving[1], *[data.moving[0]] * 3], base0.coef[:4], model.constants.as_array())
    fitted = model
    if np.all(c > 0) and np.all(np.isfinite(c)):
        fitted = model.with_constants(LumpedConstants(*c, source="diagnose: base fit"))
    res0 = residuals(design0, base0)
    timings["base_fit"] = time.perf_counter() - t1

    # 3. trace, 4. library
    t2 = time.perf_counter()
    tr_mask = data.train
    tr = trace(data.x[:, tr_mask], data.du[:, tr_mask], res0[:, tr_mask], model.params, data.sample_time)
    candidates = candidate_library(fitted)
    for axis, period in unexplained_periods(tr):
        candidates.append(waviness_candidate(fitted, axis, period))
    timings["trace"] = time.perf_counter() - t2

    # 5. selection; the features of some candidates carry the constants (thrust ripple,
    # commutation, lag), so when effects are found the library is rebuilt once on the constants
    # refitted with them and the selection repeated
    t3 = time.perf_counter()
    for _ in range(2):
        design = build_design(data, fitted, candidates)
        sel = select(design, [c.name for c in candidates], bootstrap=bootstrap, seed=seed)
        if not sel.selected:
            break
        c_new = np.where([data.moving[1], *[data.moving[0]] * 3],
                         sel.final.coefficients(design, "base")[0], fitted.constants.as_array())
        if not (np.all(c_new > 0) and np.max(np.abs(c_new / fitted.constants.as_array() - 1)) > 0.01):
            break
        fitted = model.with_constants(LumpedConstants(*c_new, source="diagnose: refit with effects"))
        candidates = candidate_library(fitted) + [
            waviness_candidate(fitted, axis, period) for axis, period in unexplained_periods(tr)]
    timings["selection"] = time.perf_counter() - t3

    def fitted_constants(fit) -> np.ndarray:
        return np.where([data.moving[1], *[data.moving[0]] * 3],
                        fit.coefficients(design, "base")[0], model.constants.as_array())

    # 6. refit and report, with the model-form spread over each effect's variants
    by_name = {c.name: c for c in candidates}
    chosen = [by_name[n] for n in sel.selected]
    effects = []
    steps = {s.name: s for s in sel.steps if s.accepted}
    for name in sel.selected:
        cand = by_name[name]
        coef, cov = sel.final.coefficients(design, name)
        params = _with_model_form_spread(cand.physical(coef, cov), data, fitted, chosen, cand)
        st = steps[name]
        effects.append(Effect(
            name=name, explanation=cand.explanation, axis=cand.axis,
            parameters=params, confidence=st.confidence, gain=st.gain,
            contribution_rms=tuple(float(v) for v in st.contribution_rms), runner_up=st.runner_up,
            signature=cand.signature, coefficients=coef, candidate=cand,
        ))
    res1 = residuals(design, sel.final)
    t4 = time.perf_counter()
    oe_before = output_error(data, fitted, fitted_constants(sel.base), [])
    oe_after = output_error(data, fitted, fitted_constants(sel.final),
                            [(e.candidate, e.coefficients) for e in effects])
    timings["output_error"] = time.perf_counter() - t4
    timings["total"] = time.perf_counter() - t0
    n_eff = len(effects)
    message = (f"{n_eff} effect(s) found: " + ", ".join(e.name for e in effects) if effects
               else "nothing significant left: the base model explains the log to its noise")
    return Diagnosis(
        success=True, message=message, sources=data.sources,
        constants_base=_constants(design, sel.base), constants_final=_constants(design, sel.final),
        effects=effects,
        error_before=_per_axis(sel.base.holdout_rms, data.moving),
        error_after=_per_axis(sel.final.holdout_rms, data.moving),
        output_error_before=oe_before, output_error_after=oe_after,
        ranking=sel.ranking, selection=sel, trace=tr, residual_before=residuals(design, sel.base),
        residual_after=res1, data=data, timings=timings,
    )


CALIBRATION = 0.01
"""Relative uncertainty of every estimated acceleration: the Savitzky-Golay differentiator is
designed to be within 1 % of the exact derivative over its band (``SavitzkyGolay.tolerance``),
so every parameter proportional to an acceleration carries it."""


def _with_model_form_spread(
    params: dict[str, Physical],
    data: DiagnosisData,
    model: StageModel,
    chosen: list[Candidate],
    cand: Candidate,
) -> dict[str, Physical]:
    """Standard errors with the systematic parts added in quadrature: half the spread of each
    parameter over the candidate's variants (refitting everything with the variant's features)
    and the differentiator's calibration (:data:`CALIBRATION`, not applied to phases/periods)."""
    values: dict[str, list[float]] = {k: [v.value] for k, v in params.items()}
    for feats in cand.variants:
        alt = [cand.with_features(feats) if c.name == cand.name else c for c in chosen]
        design = build_design(data, model, alt)
        fit = fit_subset(design, ["base", *[c.name for c in alt]])
        coef, cov = fit.coefficients(design, cand.name)
        for k, v in cand.physical(coef, cov).items():
            values[k].append(v.value)
    out = {}
    for k, v in params.items():
        spread = 0.5 * (max(values[k]) - min(values[k]))
        calibration = 0.0 if v.unit in ("rad", "m") and k in ("phase", "period", "at_gap") else (
            CALIBRATION * abs(v.value))
        out[k] = Physical(v.value, math.sqrt(v.stderr**2 + spread**2 + calibration**2), v.unit)
    return out


def output_error(
    data: DiagnosisData,
    model: StageModel,
    constants: np.ndarray,
    effects: Sequence[tuple[Candidate, np.ndarray]],
    *,
    horizon: float = 0.05,
    every: float = 0.25,
) -> dict[str, float]:
    """RMS position error [m] per axis of the model simulated over ``horizon`` from the
    estimated state at window starts (every ``every`` s) in the held-out block, with the logged
    currents. Short windows because the gap is open-loop unstable (30-64 1/s): 50 ms lets an
    initial velocity error grow by at most e^3."""
    ts = data.sample_time
    h = max(1, round(horizon / ts))
    x, u, du = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("du", 2)
    acc = model.f_theta(x, u, ca.DM(np.asarray(constants, dtype=float)))[[1, 3]]
    for cand, coef in effects:
        acc = acc + cand.acceleration(coef)(x, u, du)
    f = ca.Function("f", [x, u, du], [ca.vertcat(x[1], acc[0], x[3], acc[1])])
    k1 = f(x, u, du)
    k2 = f(x + ts / 2 * k1, u, du)
    k3 = f(x + ts / 2 * k2, u, du)
    k4 = f(x + ts * k3, u, du)
    step = ca.Function("rk4", [x, u, du], [x + ts / 6 * (k1 + 2 * k2 + 2 * k3 + k4)])
    sim = step.mapaccum("window", h)
    starts = []
    hold = np.nonzero(data.holdout)[0]
    stride = max(1, round(every / ts))
    for k in hold[::stride]:
        if k + h < data.n and data.holdout[k + h] and data.segment[k + h] == data.segment[k]:
            starts.append(k)
    if not starts:
        return {a: float("nan") for a in AXIS_NAMES}
    errs = []
    batch = sim.map(len(starts))
    x0 = data.x[:, starts]
    U = np.hstack([data.u[:, k : k + h] for k in starts])
    DU = np.hstack([data.du[:, k : k + h] for k in starts])
    traj = np.asarray(batch(x0, U, DU))  # (4, h * m)
    meas = np.hstack([data.x[:, k + 1 : k + 1 + h] for k in starts])
    errs = traj[[0, 2]] - meas[[0, 2]]
    return _per_axis(np.sqrt(np.mean(errs**2, axis=1)), data.moving)
