"""Identification of the lumped constants from log files: checks, the fits, one result.

:func:`load_logs` reads and validates the files (:func:`maglev_oc.data.logs.read_log`; every
reading problem is a :class:`~maglev_oc.data.logs.LogError`). :func:`identify` refuses logs
that cannot identify what is asked (too short, no excitation on an axis whose constants are
estimated) with a ``LogError`` naming the file and what is missing, then runs the
equation-error fit, the multiple-shooting output-error fit and the NPFSI estimator, validates
the best fit (:mod:`maglev_oc.validation`: residual whiteness, independence from past currents,
fit % of long simulations) on ``validation_logs`` held out from the fit, or in-sample on the
fitted logs when none are given, and returns an :class:`IdentificationOutcome` (``to_dict()``
for JSON, ``report()`` for text).

This is what ``maglev-oc identify`` runs.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from maglev_oc.data.logs import CURRENT_RESOLUTION, Log, LogError, read_log
from maglev_oc.errors import InputError
from maglev_oc.identification.equation_error import DEFAULT_BANDWIDTH, EquationError, refuse_left_out
from maglev_oc.identification.layout import CONSTANT_NAMES, GAP_OFFSET
from maglev_oc.identification.masses import MassChange, moving_mass_change
from maglev_oc.identification.npfsi import PAPER_EPSILONS, PAPER_GAMMA, npfsi
from maglev_oc.identification.output_error import DEFAULT_SEGMENT, DEFAULT_WINDOW, MultipleShooting
from maglev_oc.identification.result import FitResult, NpfsiResult
from maglev_oc.model.hardware import ENCODER_RESOLUTION
from maglev_oc.model.parameters import LumpedConstants, StageParameters
from maglev_oc.model.stage import StageModel
from maglev_oc.regression.conventions import refuse_convention_slips
from maglev_oc.regression.data import as_log_list, delayed_inputs, levitating_parts, prepare
from maglev_oc.regression.payload import declared
from maglev_oc.regression.stoppers import RestingStretch
from maglev_oc.regression.terms import AccelerationTerm
from maglev_oc.results import Estimate, Result
from maglev_oc.validation import Validation, validate

__all__ = [
    "HORIZONTAL",
    "METHODS",
    "MIN_DURATION",
    "PLAUSIBLE_CHANGE",
    "PLAUSIBLE_Z",
    "VERTICAL",
    "WHAT_TAKES_ITS_PLACE",
    "IdentificationOutcome",
    "beyond_plausible",
    "check_identifiable",
    "identify",
    "load_logs",
]

METHODS = ("equation_error", "output_error", "npfsi")
VALIDATION_BANDWIDTH = 10.0
"""[Hz] Band of the differentiator that estimates the initial states of the validation's
simulations (the diagnosis's band: the regulators' poles pass, the encoder steps do not)."""
MIN_DURATION = 5.0
"""[s] Shortest log accepted for identification: the sum-of-sines excitation's lowest
frequencies (0.1-0.4 Hz) need a period or more to separate C2 from C3 and C4, and the
long-run covariance needs a few Fourier frequencies below 1 Hz."""
VERTICAL = ("C2", "C3", "C4", GAP_OFFSET)
HORIZONTAL = ("C1",)
PLAUSIBLE_CHANGE = 0.3
"""Largest relative change of a constant from the model's (its starting value) that a fit may
make without a warning, when the change is also :data:`PLAUSIBLE_Z` standard errors. The
geometry and the magnets fix C1..C3 to a few per cent across rigs of one design (the papers'
three NPFSI runs differ by up to 12 %, the independent generator draws its plants within 5 % of
the papers'), so 30 % is not a different rig: it is an effect the model lacks. Fitted without
the effect, on the independent generator's logs (bench/README, *Constants a fit without the
effect cannot give*): guide friction along the track C1 -93 %, a commutation offset -79 to -99 %,
a cable carrier -7 to -65 %, a misalignment -46 %, a tilted base -59 %, a detent force -36 to
-55 %, the field's shape C4 +39 to +100 %; on the other logs C1..C3 within 6 %."""
PLAUSIBLE_Z = 5.0
"""Standard errors a change beyond :data:`PLAUSIBLE_CHANGE` must also be, to be a warning and not
a constant the log determines poorly (its standard error says so)."""
WHAT_TAKES_ITS_PLACE = {
    "horizontal": "the currents along the track do more than the thrust the model has: guide friction, a "
    "detent, a cable carrier, a tilted base or a commutation offset take current that the fit then reads "
    "as a weaker (or stronger) motor",
    "vertical": "the vertical forces differ from the model's: a gap sensor offset, a constant vertical "
    "force or the field's shape over the gap take the place of the constant",
}
"""What takes the place of a constant that moved beyond the plausible, by the axis it acts on (the
diagnosis says it of its refit too)."""


def beyond_plausible(value: float, start: float, stderr: float) -> bool:
    """Whether a fitted constant moved from its model value ``start`` by more than
    :data:`PLAUSIBLE_CHANGE` of it and by more than :data:`PLAUSIBLE_Z` standard errors."""
    change = value / start - 1 if start else math.inf
    return abs(change) > PLAUSIBLE_CHANGE and abs(value - start) > PLAUSIBLE_Z * stderr


def load_logs(paths: Sequence[str | os.PathLike], *, params: StageParameters | None = None) -> list[Log]:
    """Read and validate every file (``LogError`` names the file, line and column at fault)."""
    if not paths:
        raise InputError("no log files given")
    return [read_log(p, params=params) for p in paths]


def _moves(values, resolution: float) -> bool:
    """As :func:`maglev_oc.data.logs.check_excitation`: a standard deviation above the resolution."""
    return float(np.std(values)) > resolution


def check_identifiable(
    logs: Sequence[Log], estimate: Sequence[str], *, min_duration: float = MIN_DURATION
) -> None:
    """Raise ``LogError`` if a log is too short for identification, or if the signals that the
    estimated constants multiply do not move (on any log, for that axis).

    A log that moves on neither needed axis is refused by name, even when others do.
    """
    need_v = any(e in VERTICAL for e in estimate)
    need_h = any(e in HORIZONTAL for e in estimate)
    signals = {"x1": ("position", 0), "x3": ("position", 2), "u1": ("current", 0), "u2": ("current", 1)}
    moving: dict[str, dict[str, bool]] = {}
    for log in logs:
        name = log.source or "<log>"
        if log.recorded < min_duration:
            raise LogError(
                name,
                f"too short for identification: {log.recorded:.6g} s ({log.n} samples); need at least "
                f"{min_duration:g} s of excitation (the sum-of-sines references of 000 Sec. IV have "
                "periods up to 10 s)",
            )
        flags = {}
        for sig, (kind, row) in signals.items():
            values = log.x[row] if kind == "position" else log.u[row]
            flags[sig] = _moves(values, ENCODER_RESOLUTION if kind == "position" else CURRENT_RESOLUTION)
        moving[name] = flags
        excited = {"vertical": flags["x1"] and flags["u2"], "horizontal": flags["x3"] and flags["u1"]}
        needed = [a for a, need in (("vertical", need_v), ("horizontal", need_h)) if need]
        if not any(excited[a] for a in needed):
            flat = [s for s, ok in flags.items() if not ok]
            what = []
            if need_v:
                names_v = ", ".join(e for e in estimate if e in VERTICAL)
                what.append(f"vertical (x1 and u2 = i_d must vary for {names_v})")
            if need_h:
                what.append("horizontal (x3 and u1 = i_q must vary for C1)")
            raise LogError(
                name,
                f"no excitation for identification: {' or '.join(what)}; constant to within the resolution "
                f"(encoder {ENCODER_RESOLUTION:g} m, current {CURRENT_RESOLUTION:g} A): {', '.join(flat)}. "
                "Record the run with the sum-of-sines references of 000 Sec. IV",
                column=flat[0] if flat else None,
            )
    for axis, needed, sigs, names in (
        ("vertical", need_v, ("x1", "u2"), [e for e in estimate if e in VERTICAL]),
        ("horizontal", need_h, ("x3", "u1"), [e for e in estimate if e in HORIZONTAL]),
    ):
        if needed and not any(all(moving[n][s] for s in sigs) for n in moving):
            files = ", ".join(moving)
            raise LogError(
                files,
                f"no excitation for identification: no log moves {axis}ly ({' and '.join(sigs)} constant "
                f"to within the resolution) but {', '.join(names)} need{'s' if len(names) == 1 else ''} it",
            )


@dataclass(frozen=True, eq=False)
class IdentificationOutcome(Result):
    """What :func:`identify` found: the fits that were run, in the papers' terms.

    Attributes
    ----------
    equation_error, output_error : FitResult or None
    npfsi : tuple of NpfsiResult (one per eps)
    base_constants : LumpedConstants
        The model's constants (initial guesses; the ones held fixed).
    estimate : tuple of str
    sources : tuple of str
    timings : mapping method -> s
        Wall times of each method and ``total``.
    validation : Validation or None
        The best fit validated (held-out logs when given, else in-sample; see ``data``).
    left_out : tuple of RestingStretch
        Where a log's platform rests on its stopper (before lift-off, after landing, or pressed
        against it in between): left out of every fit
        (:func:`~maglev_oc.regression.data.levitating_parts`).
    payload_kg : tuple of float
        The payload each log of ``sources`` declares (``# payload_kg``; 0 for none): every fit read
        its forces as the unloaded stage's (:mod:`~maglev_oc.regression.payload`).
    moving_mass : MassChange or None
        The best fit's constants moved together as movers heavier (or lighter) than the model's
        move them (a payload, :mod:`~maglev_oc.identification.masses`); the warnings judge them
        against the model's moved by that mass.
    success, status, message
        From the fits: ``"converged"`` when the best fit did, ``"npfsi_only"`` when only NPFSI
        ran (and stayed well posed), else ``"failed"`` with the solver's reason.
    """

    equation_error: FitResult | None
    output_error: FitResult | None
    npfsi: tuple[NpfsiResult, ...]
    base_constants: LumpedConstants
    estimate: tuple[str, ...]
    sources: tuple[str, ...]
    timings: dict[str, float] = field(default_factory=dict)
    validation: Validation | None = None
    left_out: tuple[RestingStretch, ...] = ()
    moving_mass: MassChange | None = None
    payload_kg: tuple[float, ...] = ()

    @property
    def payloads(self) -> tuple[str, ...]:
        """One sentence per log that declares a payload."""
        return declared(self.sources, self.payload_kg) if self.payload_kg else ()

    @property
    def success(self) -> bool:
        return self.status in ("converged", "npfsi_only")

    @property
    def status(self) -> str:
        if self.best is not None:
            return "converged" if self.best.success else "failed"
        return "npfsi_only" if self.npfsi and all(r.success for r in self.npfsi) else "failed"

    @property
    def message(self) -> str:
        if self.best is not None:
            return f"{self.best.method}: {self.best.message}"
        return "; ".join(f"NPFSI eps = {r.eps:g}: {r.message}" for r in self.npfsi)

    @property
    def best(self) -> FitResult | None:
        """The equation-error fit if it succeeded, else the output-error fit if it did, else the
        equation-error fit (None when it did not run).

        The equation error removes the logged currents' errors (their level measured where two
        bands of the fit agree, :mod:`maglev_oc.regression.noise_scale`); the output error drives
        the model with the logged currents and takes their errors for the plant's input, which
        pulls C1 low when the commands are noisy. On the independent generator's clean logs of a
        rig as noisy as ``../shared/logs/independent_clean.csv``: output error C1 -0.3 to -4.5 %
        (4 standard errors on one), equation error -0.4 to +0.7 %; on its quiet default rig and
        on the twin the two agree within 0.2 % (bench/README, *Which fit identify hands on*)."""
        for fit in (self.equation_error, self.output_error):
            if fit is not None and fit.success:
                return fit
        return self.equation_error

    @property
    def warnings(self) -> tuple[str, ...]:
        """Constants of :attr:`best` that moved more than :data:`PLAUSIBLE_CHANGE` from the model's
        and by more than :data:`PLAUSIBLE_Z` standard errors: the fit converged, but on this log
        the model lacks something that the constant took the place of (what the diagnosis is
        for)."""
        fit = self.best
        if fit is None or not fit.success:
            return ()
        out = []
        for k in CONSTANT_NAMES:
            if k not in fit.values:
                continue
            start, value, se = fit.initial[k], fit.values[k], fit.stderr[k]
            if self.moving_mass is not None:  # a payload is no effect the model lacks
                start *= self.moving_mass.factor(k)
            if not beyond_plausible(value, start, se):
                continue
            change = value / start - 1 if start else math.inf
            why = WHAT_TAKES_ITS_PLACE["horizontal" if k in HORIZONTAL else "vertical"]
            z = f"{abs(value - start) / se:.0f}" if se > 0 else "infinitely many"
            out.append(
                f"{k} = {value:.4g} is {abs(change):.0%} {'below' if change < 0 else 'above'} its starting "
                f"value {start:.4g} ({z} standard errors): {why}. A stage of "
                "this geometry does not change that much; run `maglev-oc diagnose` on this log, whose "
                "refit carries the constants beside the effects it finds."
            )
        return tuple(out)

    def constants(self) -> LumpedConstants:
        """The identified constants (from :attr:`best`; NPFSI at eps = 0.01 if no fit ran)."""
        if self.best is not None:
            return self.best.constants(self.base_constants)
        for run in self.npfsi:
            if math.isclose(run.eps, 0.01):
                return run.constants(self.base_constants)
        return self.npfsi[0].constants(self.base_constants)

    def report(self) -> str:
        parts = []
        for fit in (self.equation_error, self.output_error):
            if fit is not None:
                parts.append(fit.report())
        for run in self.npfsi:
            parts.append(run.report())
        c = self.constants()
        parts.append(
            "[[Identified constants]] "
            + ", ".join(f"{k} = {getattr(c, k):.6g}" for k in CONSTANT_NAMES)
            + f"  ({c.source})"
            + "".join(f"\n    WARNING: {w}" for w in self.warnings)
            + (f"\n    moving mass: {self.moving_mass.says()}" if self.moving_mass is not None else "")
            + "".join(f"\n    left out: {r.describe()}" for r in self.left_out)
            + "".join(f"\n    payload: {w}" for w in self.payloads)
        )
        return "\n\n".join(parts)

    def to_dict(self) -> dict[str, Any]:
        c = self.constants()
        return {
            "sources": list(self.sources),
            "estimate": list(self.estimate),
            "base_constants": self.base_constants.to_dict(),
            "identified_constants": c.to_dict(),
            "equation_error": None if self.equation_error is None else self.equation_error.to_dict(),
            "output_error": None if self.output_error is None else self.output_error.to_dict(),
            "npfsi": [run.to_dict() for run in self.npfsi],
            "success": self.success,
            "status": self.status,
            "message": self.message,
            "warnings": list(self.warnings),
            "left_out": [r.to_dict() for r in self.left_out],
            "payload_kg": list(self.payload_kg),
            "moving_mass": None if self.moving_mass is None else self.moving_mass.to_dict(),
            "timings": dict(self.timings),
            "validation": None if self.validation is None else self.validation.to_dict(),
        }


def identify(
    logs: Log | Sequence[Log],
    model: StageModel,
    *,
    estimate: Sequence[str] = CONSTANT_NAMES,
    terms: Sequence[AccelerationTerm] = (),
    methods: Sequence[str] = METHODS,
    npfsi_eps: Sequence[float] = PAPER_EPSILONS,
    npfsi_gamma: float = PAPER_GAMMA,
    segment_duration: float = DEFAULT_SEGMENT,
    window_duration: float = DEFAULT_WINDOW,
    input_delay: float = 0.0,
    min_duration: float = MIN_DURATION,
    validation_logs: Sequence[Log] = (),
) -> IdentificationOutcome:
    """Check the logs, then run the chosen methods.

    Parameters
    ----------
    logs : Log or sequence of Log
    model : StageModel
        Initial guesses and the constants held fixed.
    estimate : sequence of str
        Among C1..C4 and ``gap_offset`` (NPFSI estimates the constants among them).
    terms : sequence of AccelerationTerm
        Extra accelerations for the two least-squares fits.
    methods : sequence of str
        Among ``equation_error``, ``output_error``, ``npfsi``.
    npfsi_eps, npfsi_gamma
        The NPFSI settings (one run per eps, one log at a time: the first log).
    segment_duration, window_duration : float
        [s] Multiple-shooting segment and continuity window.
    input_delay : float
        [s] Delay applied to the logged currents (by every method, NPFSI included).
    min_duration : float
        [s] Shortest log accepted.
    validation_logs : sequence of Log
        Logs held out from the fit, to validate it on (default: none; the validation then runs
        on the fitted logs and says it is in-sample).

    Returns
    -------
    IdentificationOutcome
        Each method's result (None or empty when not run), the best fit and its constants
        (:meth:`~IdentificationOutcome.constants`), timings per method.

    Raises
    ------
    LogError
        A log is too short for identification or lacks excitation (message names the file).
    """
    logs = as_log_list(logs)
    methods = tuple(methods)
    unknown = [m for m in methods if m not in METHODS]
    if unknown or not methods:
        raise InputError(f"methods: choose among {METHODS}, got {methods!r}")
    estimate = tuple(estimate)
    check_identifiable(logs, estimate, min_duration=min_duration)
    # where the platform rests on its stopper (before lift-off, after landing, a touch) is no evidence
    sources = tuple(log.source for log in logs)
    payload_kg = tuple(float(log.payload) for log in logs)
    logs, resting = levitating_parts(logs, model)  # a touch mid-log cuts a log in two
    times: dict[str, float] = {}
    ee = oe = None
    t0 = time.perf_counter()
    problem = None
    if "equation_error" in methods or "output_error" in methods:
        problem = EquationError(logs, model, estimate=estimate, terms=terms, input_delay=input_delay)
        prepared = problem.prepared
    else:  # NPFSI alone: the least-squares fits' refusals, on their preparation of the logs
        prepared = prepare(logs, bandwidth=DEFAULT_BANDWIDTH, model=model)
        refuse_left_out(prepared, estimate)
    refuse_convention_slips(prepared, model)
    if problem is not None:
        ee = problem.fit()
        times["equation_error"] = time.perf_counter() - t0
    if "output_error" in methods:
        t0 = time.perf_counter()
        ms = MultipleShooting(
            logs,
            model,
            estimate=estimate,
            terms=terms,
            segment_duration=segment_duration,
            window_duration=window_duration,
            input_delay=input_delay,
        )
        oe = ms.fit(initial=ee if ee is not None and ee.success else None)
        times["output_error"] = time.perf_counter() - t0
    if "equation_error" not in methods:
        ee = None
    runs: list[NpfsiResult] = []
    constants = tuple(e for e in estimate if e in CONSTANT_NAMES)
    if "npfsi" in methods and constants:
        t0 = time.perf_counter()
        # the estimator sees the currents as the amplifiers applied them: shifted by the delay
        log0 = logs[0]
        if input_delay:
            log0 = dataclasses.replace(log0, u=delayed_inputs(log0, input_delay))
        for eps in npfsi_eps:
            runs.append(npfsi(log0, model, estimate=constants, eps=eps, gamma=npfsi_gamma))
        times["npfsi"] = time.perf_counter() - t0
    outcome = IdentificationOutcome(
        ee,
        oe,
        tuple(runs),
        model.constants,
        estimate,
        sources,
        times,
        left_out=resting,
        payload_kg=payload_kg,
    )
    t0 = time.perf_counter()
    held_out = as_log_list(validation_logs) if validation_logs else []
    checked = _validation(outcome, model, logs, held_out, tuple(terms), input_delay)
    times["validation"] = time.perf_counter() - t0
    times["total"] = sum(v for k, v in times.items() if k != "total")
    return dataclasses.replace(
        outcome, timings=times, validation=checked, moving_mass=_moving_mass(outcome, model)
    )


def _moving_mass(outcome: IdentificationOutcome, model: StageModel) -> MassChange | None:
    """The best fit's constants read as a payload's (:func:`~maglev_oc.identification.masses
    .moving_mass_change`), when it estimated C1..C3."""
    fit = outcome.best
    if fit is None or not fit.success or not all(k in fit.values for k in ("C1", "C2", "C3")):
        return None
    estimates = {k: Estimate(fit.values[k], fit.stderr[k], "") for k in CONSTANT_NAMES if k in fit.values}
    return moving_mass_change(estimates, {k: fit.initial[k] for k in estimates}, model.params)


def _validation(
    outcome: IdentificationOutcome,
    model: StageModel,
    logs: list[Log],
    held_out: list[Log],
    terms: tuple[AccelerationTerm, ...],
    input_delay: float,
) -> Validation:
    """The best fit (its constants, terms and gap offset) validated on ``held_out``, or in-sample on
    ``logs`` when there are none."""
    use = held_out or logs
    if input_delay:
        use = [dataclasses.replace(log, u=delayed_inputs(log, input_delay)) for log in use]
    data = prepare(use, bandwidth=VALIDATION_BANDWIDTH, model=model)
    fit = outcome.best
    fitted = model.with_constants(outcome.constants())
    fitted_terms, offset = [], 0.0
    if fit is not None:
        offset = fit.values.get(GAP_OFFSET, 0.0)
        for term in terms:
            fitted_terms.append((term, [fit.values[f"{term.name}.{p}"] for p in term.parameter_names]))
    where = (
        "held-out logs " + ", ".join(log.source for log in held_out)
        if held_out
        else "the fitted logs (in-sample: no held-out log was given)"
    )
    method = fit.method if fit is not None else "NPFSI"
    return validate(
        data,
        data.valid,
        fitted,
        fitted_terms,
        description=f"identified constants ({method})",
        data_description=where,
        gap_offset=offset,
    )
