"""``diagnose``: fit the base model to logs, find what its residual is made of, add the effects it
traces to, and report the error before and after on held-out data (SPEC 3).

Steps:

1. :func:`maglev_oc.regression.data.prepare` — the shared data preparation (rate, zero-phase
   derivatives, one filter on both sides, the logged currents' errors), a held-out block at the
   end of each log;
2. base fit — C1..C4 by bias-compensated, filtered equation-error least squares
   (:mod:`maglev_oc.regression`), the same fit ``identify`` runs;
3. :mod:`~maglev_oc.diagnose.trace` — the residual against x3 (spatial spectrum), the gap, the
   velocities, the position and the current rates;
4. :mod:`~maglev_oc.diagnose.library` — the candidate effects;
5. :mod:`~maglev_oc.diagnose.selection` — each candidate judged in a joint fit with the base
   constants: held-out gain and its long-run significance, Wald test, physical size,
   separability, plausibility; forward selection with a bootstrap confidence. The candidates'
   magnetic references are the base fit's constants; when the selected effects move the
   constants by more than 2 %, the library is rebuilt on the refitted ones and the selection
   repeated once;
6. :mod:`~maglev_oc.diagnose.unexplained` — structure left in the residual that no candidate
   explains, reported with its signature;
7. the refit of base constants and effects together; held-out error per axis before and after,
   and the short-horizon output error (the model simulated over 50 ms windows).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.data.logs import Log, LogError
from maglev_oc.diagnose.library import (
    Candidate,
    candidate_library,
    refine_waviness_period,
    smooth_probes,
    waviness_candidate,
)
from maglev_oc.diagnose.selection import (
    Judgement,
    Selection,
    SelectionSettings,
    fitted_constants,
    judge,
    select,
)
from maglev_oc.diagnose.trace import Trace, trace, unexplained_periods
from maglev_oc.diagnose.unexplained import Unexplained, find_unexplained
from maglev_oc.model.parameters import LumpedConstants
from maglev_oc.model.stage import StageModel
from maglev_oc.regression.base import AXIS_NAMES, CONSTANT_AXIS, CONSTANT_NAMES, UNITS
from maglev_oc.regression.data import PreparedLogs, prepare
from maglev_oc.regression.design import Design, build_design
from maglev_oc.regression.solve import SubsetFit, fit_subset, predicted, residuals
from maglev_oc.regression.terms import Estimate

__all__ = ["DEFAULT_BANDWIDTH", "ERROR_METRIC", "Diagnosis", "Effect", "NotSeparable", "diagnose"]

DEFAULT_BANDWIDTH = 10.0
"""[Hz] Band of the diagnosis's differentiator: the spatial periods of interest (19-114 mm)
pass at speeds up to 0.2 m/s, guide-friction reversals and the regulators' poles (up to 9 Hz)
too; above it the differentiated encoder quantization (rising as f^4) and the closed-loop
currents' echo of it dominate the residual."""
ERROR_METRIC = (
    "RMS of the acceleration equation error (measured minus model, both through the same "
    "zero-phase filter) on the held-out block at the end of each log, per axis, in m/s^2 "
    "(null for an axis that does not move in the logs)"
)
CALIBRATION = 0.01
"""Relative uncertainty of every estimated acceleration: the Savitzky-Golay differentiator is
within 1 % of the exact derivative over its band (``SavitzkyGolay.tolerance``), so every
parameter proportional to an acceleration carries it."""
REFIT_TOLERANCE = 0.02
"""Rebuild the library when the refitted constants move by more than this from its references."""


@dataclass(frozen=True)
class Effect:
    """A selected effect with its physical parameters (value, standard error, unit)."""

    name: str
    explanation: str
    finding: str  # what was found, in one sentence with the sizes
    axis: str
    parameters: dict[str, Estimate]
    confidence: float  # bootstrap share choosing it at its step
    gain: float  # relative drop of the held-out error on its axes when it was added
    z: float
    contribution_rms: tuple[float, float]  # held-out RMS of its acceleration per axis [m/s^2]
    force_rms: tuple[float, float]  # the same in N
    runner_up: str
    signature: str
    coefficients: np.ndarray
    candidate: Candidate = field(repr=False)


@dataclass(frozen=True)
class NotSeparable:
    """A candidate that is real in the fit but confounded on this log."""

    name: str
    confounded_with: tuple[str, ...]
    experiment: str
    gain: float
    reason: str
    parameters: dict[str, Estimate]

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "confounded_with": list(self.confounded_with),
            "experiment": self.experiment,
            "holdout_gain": _num(self.gain),
            "reason": self.reason,
            "parameters_if_it_were_separable": {k: v.to_dict() for k, v in self.parameters.items()},
        }


@dataclass(frozen=True)
class Diagnosis:
    """What :func:`diagnose` found (``to_json()``: the SPEC 3 contract plus details)."""

    success: bool
    message: str
    sources: tuple[str, ...]
    constants_base: dict[str, Estimate]  # base model alone
    constants_final: dict[str, Estimate]  # refitted with the effects
    effects: list[Effect]
    not_separable: list[NotSeparable]
    rejected: list[Judgement]
    unexplained: list[Unexplained]
    error_before: dict[str, float]
    error_after: dict[str, float]
    output_error_before: dict[str, float]  # [m] RMS over 50 ms simulations, held out
    output_error_after: dict[str, float]
    selection: Selection
    trace: Trace
    residual_before: np.ndarray  # (2, n) [m/s^2]
    residual_after: np.ndarray
    data: PreparedLogs = field(repr=False)
    train: np.ndarray = field(repr=False)
    holdout: np.ndarray = field(repr=False)
    settings: dict = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def ranking(self) -> list[tuple[str, float]]:
        return self.selection.ranking

    def to_json(self) -> dict:
        """The SPEC 3 contract, plus details (all plain JSON types)."""

        def phys(d: dict[str, Estimate]) -> dict:
            return {k: _num(v.value) for k, v in d.items()}

        def phys_full(d: dict[str, Estimate]) -> dict:
            return {k: v.to_dict() for k, v in d.items()}

        return {
            "effects": [
                {
                    "name": e.name,
                    "explanation": e.explanation,
                    "finding": e.finding,
                    "axis": e.axis,
                    "parameters": phys(e.parameters),
                    "parameter_details": phys_full(e.parameters),
                    "confidence": _num(e.confidence),
                    "holdout_gain": _num(e.gain),
                    "z": _num(e.z),
                    "contribution_rms": dict(zip(AXIS_NAMES, map(_num, e.contribution_rms), strict=True)),
                    "force_rms_N": dict(zip(AXIS_NAMES, map(_num, e.force_rms), strict=True)),
                    "runner_up": e.runner_up,
                    "evidence": e.signature,
                }
                for e in self.effects
            ],
            "not_separable": [n.to_dict() for n in self.not_separable],
            "unexplained": [u.to_dict() for u in self.unexplained],
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
            "rejected": [
                {
                    "name": j.name,
                    "verdict": j.verdict,
                    "reason": j.reason,
                    "holdout_gain": _num(j.gain),
                    "z": _num(j.z),
                }
                for j in self.rejected
            ],
            "candidate_ranking": [{"name": n, "holdout_gain": _num(g)} for n, g in self.ranking],
            "selection_steps": [
                {
                    "chosen": s.chosen,
                    "confidence": _num(s.confidence),
                    "candidates": [
                        {
                            "name": j.name,
                            "verdict": j.verdict,
                            "holdout_gain": _num(j.gain),
                            "z": _num(j.z),
                            "wald": _num(j.wald),
                            "vif": _num(j.vif),
                        }
                        for j in sorted(s.judgements.values(), key=lambda j: -j.gain)
                    ],
                }
                for s in self.selection.steps
            ],
            "logs": list(self.sources),
            "holdout": {
                "fraction": self.settings.get("holdout_fraction"),
                "samples": int(self.holdout.sum()),
                "fit_samples": int(self.train.sum()),
            },
            "settings": _jsonable(self.settings),
            "success": self.success,
            "message": self.message,
            "timings_s": {k: _num(v) for k, v in self.timings.items()},
        }


def _num(v) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


def _jsonable(value):
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, (np.floating, float)):
        return _num(value)
    if isinstance(value, (np.integer, int, bool, str)) or value is None:
        return value.item() if isinstance(value, np.generic) else value
    return str(value)


def _constants(design: Design, fit: SubsetFit, model: StageModel) -> dict[str, Estimate]:
    """C1..C4 with standard errors; NaN for the constants of an axis that did not move."""
    out = {}
    for name in CONSTANT_NAMES:
        if design.moving[AXIS_NAMES.index(CONSTANT_AXIS[name])] and name in fit.names:
            out[name] = Estimate(fit.value(name), fit.stderr(name), UNITS[name])
        else:
            out[name] = Estimate(float("nan"), float("nan"), UNITS[name])
    return out


def _fitted_model(model: StageModel, fit: SubsetFit, moving: np.ndarray, source: str) -> StageModel:
    """The model with the fitted constants (a locked axis's, or a non-positive fit, keeps the model's)."""
    c = np.asarray(model.constants.as_array(), dtype=float)
    for k, name in enumerate(CONSTANT_NAMES):
        v = fit.value(name)
        if moving[AXIS_NAMES.index(CONSTANT_AXIS[name])] and math.isfinite(v) and v > 0:
            c[k] = v
    return model.with_constants(LumpedConstants(*c, source=source))


def _per_axis(values, moving) -> dict[str, float]:
    return {a: float(v) if m else float("nan") for a, v, m in zip(AXIS_NAMES, values, moving, strict=True)}


def diagnose(
    logs: Sequence[Log],
    model: StageModel | None = None,
    *,
    holdout_fraction: float = 0.25,
    bandwidth: float = DEFAULT_BANDWIDTH,
    settings: SelectionSettings | None = None,
    min_duration: float = 10.0,
    exclude: Sequence[str] = (),
) -> Diagnosis:
    """Diagnose ``logs`` against ``model`` (default: the papers' stage; its constants are only
    the starting point, they are refitted).

    Parameters
    ----------
    logs : sequence of Log
        At one sample rate; each at least ``min_duration`` long.
    model : StageModel, optional
    holdout_fraction : float
        Share of each log, at its end, held out for validation (0.05-0.5).
    bandwidth : float
        [Hz] Band of the equation error (see :data:`DEFAULT_BANDWIDTH`).
    settings : SelectionSettings, optional
        Thresholds of the selection.
    min_duration : float
        [s] Shortest log accepted: a held-out block of a quarter needs a few seconds.
    exclude : sequence of str
        Candidates to leave out of the library (effects known to be absent).
    """
    t0 = time.perf_counter()
    model = StageModel() if model is None else model
    settings = settings or SelectionSettings()
    logs = list(logs)
    if not 0.05 <= holdout_fraction <= 0.5:
        raise ValueError(f"holdout_fraction must be in [0.05, 0.5], got {holdout_fraction!r}")
    for log in logs:
        if log.duration < min_duration:
            raise LogError(
                log.source,
                f"{log.duration:.1f} s is too short to diagnose: need at least "
                f"{min_duration:g} s (a quarter is held out for validation)",
            )
    timings: dict[str, float] = {}
    data = prepare(logs, bandwidth=bandwidth)
    if not np.any(data.moving):
        raise LogError(
            ", ".join(data.sources),
            "neither axis moves (position standard deviation under 50 um): nothing to diagnose",
        )
    train, hold = data.masks(holdout_fraction)
    timings["prepare"] = time.perf_counter() - t0

    # 2. base fit
    t1 = time.perf_counter()
    design0 = build_design(data, model, fit=train, holdout=hold)
    base0 = fit_subset(design0, ["base"])
    fitted = _fitted_model(model, base0, data.moving, "diagnose: base fit")
    res0 = residuals(design0, base0)
    timings["base_fit"] = time.perf_counter() - t1

    # 3. trace
    t2 = time.perf_counter()
    tr = trace(data.x[:, train], data.du[:, train], res0[:, train], model.params, data.sample_time)
    timings["trace"] = time.perf_counter() - t2

    # 4.-5. library and selection (rebuilt once if the effects move the constants)
    t3 = time.perf_counter()
    probes = smooth_probes(data)
    for _ in range(2):
        full = candidate_library(fitted, data)
        unknown = sorted(set(exclude) - {c.name for c in full})
        if unknown:
            raise ValueError(
                f"exclude: unknown candidate(s) {unknown}; the library has {[c.name for c in full]}"
            )
        library = [c for c in full if c.name not in exclude]
        design = build_design(
            data, fitted, terms=_terms(library, probes), fit=train, holdout=hold, weights=design0.weights
        )
        sel = select(design, library, settings, {k: t.name for k, t in probes.items()})
        if not sel.selected:
            break
        converged = _converged_references(model, fitted, data, sel.selected, train, hold, design0.weights)
        if _moved(converged, fitted) <= REFIT_TOLERANCE:
            break
        fitted = converged
    # 5b. periodicities of the residual that no motor period explains: guide waviness
    res_sel = residuals(design, sel.final)
    tr_after = trace(data.x[:, train], data.du[:, train], res_sel[:, train], model.params, data.sample_time)
    periods = sorted(
        {
            round(refine_waviness_period(fitted, data, res_sel, design0.weights, train, lam), 4)
            for _, lam in unexplained_periods(tr_after, tolerance=0.03)
        }
    )
    if periods:
        wavy = {c.name: c for c in (waviness_candidate(fitted, data, lam) for lam in periods)}
        library = library + list(wavy.values())
        design = build_design(
            data, fitted, terms=_terms(library, probes), fit=train, holdout=hold, weights=design0.weights
        )
        sel = select(design, library, settings, {k: t.name for k, t in probes.items()})
    timings["selection"] = time.perf_counter() - t3

    by_name = {c.name: c for c in library}
    not_sep = [
        NotSeparable(j.name, j.confounded_with, by_name[j.name].separate_by, j.gain, j.reason, j.physical)
        for j in sel.last.values()
        if j.verdict == "not separable"
    ]
    not_sep.sort(key=lambda n: -n.gain)
    rejected = sorted((j for j in sel.last.values() if j.verdict in ("implausible",)), key=lambda j: -j.gain)

    # 6. what nothing explains; a named effect that a generic dependence found here explains as
    # well was the nearest candidate, not the cause: it is dropped and the search repeated
    t4 = time.perf_counter()
    dropped: list[Judgement] = []
    while True:
        chosen = [by_name[n] for n in sel.selected]
        explained = chosen + [by_name[n.name] for n in not_sep]
        unexplained = find_unexplained(
            data, fitted, explained, train, hold, design0.weights, unexplained_periods(tr), settings
        )
        stale = _explained_by_unexplained(
            data, fitted, chosen, unexplained, train, hold, design0.weights, settings
        )
        if not stale:
            break
        dropped.extend(stale)
        kept = [n for n in sel.selected if n not in {j.name for j in stale}]
        sel = dataclasses.replace(
            sel,
            steps=[st for st in sel.steps if st.chosen in kept],
            final=fit_subset(design, ["base", *kept]),
        )
    rejected.extend(dropped)
    timings["unexplained"] = time.perf_counter() - t4

    chosen = [by_name[n] for n in sel.selected]
    steps = {s.chosen: s for s in sel.steps}
    final_constants = fitted_constants(sel.final)
    effects = []
    for name in sel.selected:
        cand = by_name[name]
        coef, cov = sel.final.group(design, name)
        params = cand.term.physical_parameters(coef, cov, final_constants)
        params = _with_model_form_spread(params, data, fitted, chosen, cand, train, hold, design0.weights)
        contrib = np.sqrt(np.mean(predicted(design, sel.final, name)[:, hold] ** 2, axis=1))
        masses = (model.params.mass_vertical, model.params.mass_horizontal)
        force = tuple(float(c * m) for c, m in zip(contrib, masses, strict=True))
        for a, axis in enumerate(AXIS_NAMES):
            if cand.axis in (axis, "both") and data.moving[a]:
                params[f"rms_force_{axis}"] = Estimate(force[a], float("nan"), "N")
        st = steps[name]
        judged = sorted((j for j in st.judgements.values() if j.name != name), key=lambda j: -j.gain)
        effects.append(
            Effect(
                name=name,
                explanation=cand.term.explanation,
                finding=cand.describe(params),
                axis=cand.axis,
                parameters=params,
                confidence=st.confidence,
                gain=st.judgements[name].gain,
                z=st.judgements[name].z,
                contribution_rms=tuple(float(v) for v in contrib),
                force_rms=force,
                runner_up=judged[0].name if judged else "",
                signature=cand.term.signature,
                coefficients=coef,
                candidate=cand,
            )
        )
    effects = _merged_guide_geometry(effects)

    # 7. errors before and after
    t5 = time.perf_counter()
    oe_before = output_error(data, hold, model.with_constants(fitted.constants), [])
    final_model = _fitted_model(model, sel.final, data.moving, "diagnose: refit with the effects")
    oe_after = output_error(data, hold, final_model, [(e.candidate, e.coefficients) for e in effects])
    timings["output_error"] = time.perf_counter() - t5
    timings["total"] = time.perf_counter() - t0
    if effects:
        message = f"{len(effects)} effect(s) found: " + ", ".join(e.name for e in effects)
    else:
        message = "no missing effect found: the base model explains the log to its noise"
        if unexplained:
            message = "no named effect found, but part of the residual is unexplained"
    if not_sep:
        message += f"; {len(not_sep)} candidate(s) not separable on this log"
    success = bool(sel.base.compensated or not np.any(data.current_noise > 0))
    if not success:
        message += " (errors-in-variables compensation failed: constants may be biased low)"
    return Diagnosis(
        success=success,
        message=message,
        sources=data.sources,
        constants_base=_constants(design0, base0, model),
        constants_final=_constants(design, sel.final, model),
        effects=effects,
        not_separable=not_sep,
        rejected=rejected,
        unexplained=unexplained,
        error_before=_per_axis(sel.base.holdout_rms, data.moving),
        error_after=_per_axis(sel.final.holdout_rms, data.moving),
        output_error_before=oe_before,
        output_error_after=oe_after,
        selection=sel,
        trace=tr,
        residual_before=residuals(design, sel.base),
        residual_after=residuals(design, sel.final),
        data=data,
        train=train,
        holdout=hold,
        settings={
            "holdout_fraction": holdout_fraction,
            "bandwidth_hz": bandwidth,
            "selection": {k: getattr(settings, k) for k in settings.__dataclass_fields__},
            **data.settings,
        },
        timings=timings,
    )


def _explained_by_unexplained(
    data: PreparedLogs,
    model: StageModel,
    chosen: Sequence[Candidate],
    unexplained: Sequence[Unexplained],
    train: np.ndarray,
    hold: np.ndarray,
    weights: np.ndarray,
    settings: SelectionSettings,
) -> list[Judgement]:
    """The chosen effects that no longer pass once the unexplained dependences on other variables
    than their own are in the model (a dependence on an effect's own variable is that effect's
    imperfect shape, not a rival)."""
    probes = [u.term for u in unexplained if u.term is not None]
    if not probes or not chosen:
        return []
    design = build_design(
        data, model, terms=[c.term for c in chosen] + probes, fit=train, holdout=hold, weights=weights
    )
    out = []
    for c in chosen:
        rivals = [u for u in unexplained if u.term is not None and u.depends_on != c.variable]
        if not rivals:
            continue
        current = ["base", *[o.name for o in chosen if o is not c], *[u.term.name for u in rivals]]
        fit = fit_subset(design, current, covariance=False)
        r0 = design.target[:, hold] - np.einsum("p,pan->an", fit.coef, design.columns[fit.index][:, :, hold])
        mse0 = np.maximum(np.mean(r0**2, axis=1), 1e-30)
        j = judge(design, c, current, fit, r0, mse0, settings)
        # dropped only when its held-out contribution vanishes (a constant shared with a probe
        # makes it collinear, which says nothing about the effect)
        if j.verdict in ("not significant", "too small"):
            words = ", ".join(u.depends_on.replace("_", " ") for u in rivals)
            out.append(
                dataclasses.replace(
                    j,
                    verdict="not specific",
                    reason=f"what it explains is explained as well by a dependence on the {words} that no "
                    f"effect names (reported as unexplained): {j.reason}",
                )
            )
    return out


def _terms(library: Sequence[Candidate], probes: dict) -> list:
    """The candidates' terms (each name once) and the generic probes."""
    unique = {c.name: c.term for c in library}
    return list(unique.values()) + list(probes.values())


def _merged_guide_geometry(effects: list[Effect]) -> list[Effect]:
    """One effect for the guides' shape: a uniform slope and a waviness found together are the
    same physical object (the guide's line against the stator), reported as one misalignment."""
    names = [e.name for e in effects]
    if "guide_misalignment" not in names:
        return effects
    wavy = [e for e in effects if e.name.startswith("guide_waviness_")]
    if not wavy:
        return effects
    k = names.index("guide_misalignment")
    slope = effects[k]
    params = dict(slope.parameters)
    findings = [slope.finding]
    for w in wavy:
        params["waviness_amplitude"] = w.parameters["amplitude"]
        params["waviness_period"] = w.parameters["period"]
        findings.append(w.finding)
    merged = dataclasses.replace(
        slope,
        parameters=params,
        finding=" ".join(findings),
        contribution_rms=tuple(
            float(np.hypot(a, *(w.contribution_rms[i] for w in wavy)))
            for i, a in enumerate(slope.contribution_rms)
        ),
    )
    return [merged if e is slope else e for e in effects if e not in wavy]


def _moved(a: StageModel, b: StageModel) -> float:
    """Largest relative change between two models' constants."""
    return float(np.max(np.abs(np.asarray(a.constants.as_array()) / np.asarray(b.constants.as_array()) - 1)))


def _converged_references(
    model: StageModel,
    fitted: StageModel,
    data: PreparedLogs,
    chosen: Sequence[str],
    train: np.ndarray,
    hold: np.ndarray,
    weights: np.ndarray,
    *,
    tolerance: float = 1e-3,
    max_rounds: int = 12,
) -> StageModel:
    """The constants of the joint fit of the base model and the ``chosen`` effects, iterated until
    the effects' magnetic references (which scale some of their columns) agree with them.

    Terms such as the commutation offset are bilinear in a constant and their own parameter;
    their columns are linearized at the references, so each joint fit is a Gauss-Newton step,
    repeated here (a few tenths of a second each: only the chosen effects' columns) until the
    constants move by less than ``tolerance``."""
    for _ in range(max_rounds):
        by_name = {c.name: c for c in candidate_library(fitted, data)}
        terms = [by_name[n].term for n in chosen]
        design = build_design(data, fitted, terms=terms, fit=train, holdout=hold, weights=weights)
        refit = _fitted_model(
            model,
            fit_subset(design, list(design.groups), covariance=False),
            data.moving,
            "diagnose: refit with the effects",
        )
        done = _moved(refit, fitted) <= tolerance
        fitted = refit
        if done:
            break
    return fitted


def _with_model_form_spread(
    params: dict[str, Estimate],
    data: PreparedLogs,
    model: StageModel,
    chosen: list[Candidate],
    cand: Candidate,
    train: np.ndarray,
    hold: np.ndarray,
    weights: np.ndarray,
) -> dict[str, Estimate]:
    """Standard errors with the systematic parts added in quadrature: half the spread of each
    parameter over the candidate's variants (everything refitted with the variant) and the
    differentiator's calibration (:data:`CALIBRATION`, not applied to angles, periods, gaps)."""
    values: dict[str, list[float]] = {k: [v.value] for k, v in params.items()}
    for fn in cand.term.variants:
        alt = [c.term.with_function(fn) if c.name == cand.name else c.term for c in chosen]
        design = build_design(data, model, terms=alt, fit=train, holdout=hold, weights=weights)
        fit = fit_subset(design, list(design.groups))
        coef, cov = fit.group(design, cand.name)
        consts = fitted_constants(fit)
        for k, v in cand.term.physical_parameters(coef, cov, consts).items():
            values[k].append(v.value)
    out = {}
    for k, v in params.items():
        spread = 0.5 * (max(values[k]) - min(values[k]))
        systematic = 0.0 if v.unit in ("rad", "m") else CALIBRATION * abs(v.value)
        out[k] = Estimate(v.value, math.sqrt(v.stderr**2 + spread**2 + systematic**2), v.unit)
    return out


def output_error(
    data: PreparedLogs,
    holdout: np.ndarray,
    model: StageModel,
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
    acc = model.f(x, u)[[1, 3]]
    for cand, coef in effects:
        acc = acc + cand.term.acceleration(coef)(x, u, du)
    f = ca.Function("f", [x, u, du], [ca.vertcat(x[1], acc[0], x[3], acc[1])])
    k1 = f(x, u, du)
    k2 = f(x + ts / 2 * k1, u, du)
    k3 = f(x + ts / 2 * k2, u, du)
    k4 = f(x + ts * k3, u, du)
    step = ca.Function("rk4", [x, u, du], [x + ts / 6 * (k1 + 2 * k2 + 2 * k3 + k4)])
    sim = step.mapaccum("window", h)
    hold = np.flatnonzero(holdout)
    stride = max(1, round(every / ts))
    starts = [
        k
        for k in hold[::stride]
        if k + h < data.n and holdout[k + h] and data.segment[k + h] == data.segment[k]
    ]
    if not starts:
        return {a: float("nan") for a in AXIS_NAMES}
    x0 = data.x[:, starts]
    U = np.hstack([data.u[:, k : k + h] for k in starts])
    DU = np.hstack([data.du[:, k : k + h] for k in starts])
    traj = np.asarray(sim.map(len(starts))(x0, U, DU))
    meas = np.hstack([data.x[:, k + 1 : k + 1 + h] for k in starts])
    errs = traj[[0, 2]] - meas[[0, 2]]
    return _per_axis(np.sqrt(np.mean(errs**2, axis=1)), data.moving)
