"""Controller comparison: the papers' step and ellipse experiments (002 Sec. 7, Figs. 9-13) with
the FL regulator, its retuned K_v, the papers' linear regulator, LQR, PID and NMPC, on the ideal
and the rig twin, and the twin calibrated to the papers' step experiments. Page 1 is the scorecard
with its key figure; methods, per-step tables and the figures follow; timings in the appendix.

    python analyses/controllers.py [--out reports/controllers.pdf] [--params stage.json]
                                   [--no-nmpc] [--no-calibration]

Every closed loop runs as generated C when a C compiler is there (the NMPC's real-time iteration
compiled once and called from the loop), else in CasADi's virtual machine.
"""

from __future__ import annotations

import contextlib
import math
import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.control.gains import PAPER_GAINS
from maglev_oc.control.nmpc import NonlinearMPC
from maglev_oc.control.registry import build_controller
from maglev_oc.model.hardware import PEAK_CURRENT_LIMIT, STOPPER_GAP
from maglev_oc.model.stage import StageModel
from maglev_oc.numerics import c_compiler
from maglev_oc.reporting import controller_plots as plots
from maglev_oc.reporting.pdf import PdfReport, Plot, ReportContents, Table, Text
from maglev_oc.reporting.twins import twin_table
from maglev_oc.sim.calibration import (
    RATIO_TOLERANCE,
    TOLERANCE_PCT,
    FitPoint,
    PaperCalibration,
    calibrate_to_paper,
)
from maglev_oc.sim.comparison import (
    Comparison,
    LoopCache,
    StepSweep,
    run_comparison,
    standard_twins,
    step_sweep,
)
from maglev_oc.sim.compiled_nmpc import CompiledNMPC, user_cache
from maglev_oc.sim.engine import SimulationResult
from maglev_oc.sim.metrics import RunMetrics, StepMetrics
from maglev_oc.sim.scenarios import paper_scenarios
from maglev_oc.units import M_TO_MM, M_TO_UM

__all__ = [
    "ORDER",
    "PAPER_STEP_TIME",
    "REPORT",
    "ControllerStudy",
    "build",
    "compare_controllers",
    "main",
    "scorecard_rows",
    "step_rows",
    "write_report",
]

REPORT = "controllers.pdf"
ORDER = 20
TITLE = "maglev_oc — controller comparison"

FL = "FL regulator"
RETUNED = "FL regulator, retuned K_v"
LINEAR = "linear regulator"
LINEAR_NOFF = "linear regulator (no feedforward)"
LQR = "LQR"
PID = "PID"
NMPC = "NMPC"
SWEPT = (FL, LINEAR, LINEAR_NOFF)
"""The regulators whose largest manageable step is swept."""
PAPER_STEP_TIME = 5.0
"""[s] The set-point change the papers quote ("overshoot of 114 % at t = 5 s", 002 Fig. 9)."""
SWEEP_TARGETS = np.arange(10e-3, 24.5e-3, 1e-3)
"""[m] Target gaps of the sweep from the papers' start (0.026, 0, 0, 0)."""
SCENARIO_WORDS = {
    "setpoint_steps": "five set-points",
    "small_step": "small step",
    "large_step": "large step",
    "sinusoid": "ellipse",
}
TWIN_WORDS = {"ideal": "ideal twin", "rig": "rig twin"}
REPRODUCED_RATIO = 1.5
"""A tracking error within this factor of the papers' (either way) reproduces it: the twin's
friction and misalignment are sized from the papers' words, not measured."""
FIT_WORDS = {
    "nominal": "rig twin",
    "plausible": "every effect at its plausible limit",
    "required": "the twin that reproduces",
}


# --- computing -------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ControllerStudy:
    """Everything the report prints, computed by :func:`compare_controllers`.

    ``calibration`` is :func:`~maglev_oc.sim.calibration.calibrate_to_paper`'s result (None when
    not run); ``timings`` [s] by step.
    """

    controllers: tuple
    skipped: tuple[str, ...]  # "name: reason" of controllers this install cannot build
    comparison: Comparison
    sweeps: dict[str, StepSweep]  # by twin name
    backend: str  # "c" or "vm"
    calibration: PaperCalibration | None = None
    timings: dict[str, float] = field(default_factory=dict)
    calibrated_aside: bool = False  # the calibration ran in a process of its own, beside the runs

    def result(self, controller: str, scenario: str, twin: str) -> SimulationResult:
        return self.comparison.results[(controller, scenario, twin)]

    def metric(self, controller: str, scenario: str, twin: str) -> RunMetrics:
        return self.comparison.metric(controller, scenario, twin)


def _controllers(model: StageModel, nmpc: bool) -> tuple[list, list[str], dict[str, float]]:
    """The compared controllers, those skipped and each one's build time [s]."""
    built, skipped, times = [], [], {}

    def add(name: str, make) -> None:
        t0 = time.perf_counter()
        try:
            ctrl = make()
        except ImportError as err:  # a controller this install does not have
            skipped.append(f"{name}: {err}")
            return
        built.append(ctrl)
        times[ctrl.name] = time.perf_counter() - t0

    retuned = np.asarray(PAPER_GAINS["K_v_retuned"].printed, dtype=float)
    add(FL, lambda: build_controller("fl", model))
    add(RETUNED, lambda: FeedbackLinearizingRegulator(model, K_v=retuned, name=RETUNED))
    for key in ("linear", "linear-noff", "lqr", "pid"):
        add(key, lambda key=key: build_controller(key, model))
    if nmpc:
        # the registry's causal NMPC (preview=False), its real-time iteration run as generated C
        add(NMPC, lambda: CompiledNMPC(NonlinearMPC(model, preview=False), cache=user_cache()))
    return built, skipped, times


def compare_controllers(
    model: StageModel,
    *,
    nmpc: bool = True,
    calibration: bool | PaperCalibration = True,
    calibrate_aside: bool | None = None,
) -> ControllerStudy:
    """Build the controllers for ``model``, run them on the papers' scenarios on both twins, sweep
    the regulators' large step, and calibrate the twin to the papers' step experiments
    (``calibration``: True to run it, False to leave it out, or a calibration of ``model`` already
    run, which is used as it is).

    The calibration does not depend on the rest: with ``calibrate_aside`` (default: when this
    process may use more than one core) it runs in a process of its own while the comparison and
    the sweeps run here (the same function on the same model: the same result, in about half the
    wall time of the two one after the other on two cores)."""
    t_start = time.perf_counter()
    if calibrate_aside is None:
        calibrate_aside = len(os.sched_getaffinity(0)) > 1
    with contextlib.ExitStack() as stack:
        aside = None
        if calibration is True and calibrate_aside:
            # spawned, not forked: CasADi and BLAS threads do not survive a fork
            spawn = multiprocessing.get_context("spawn")
            pool = stack.enter_context(ProcessPoolExecutor(1, mp_context=spawn))
            aside = pool.submit(calibrate_to_paper, model)
        controllers, skipped, build_times = _controllers(model, nmpc)
        t_built = time.perf_counter()
        backend = "c" if c_compiler() is not None else "vm"
        twins = standard_twins(model)
        loops = LoopCache(backend)
        cmp = run_comparison(controllers, paper_scenarios(), twins, loops=loops)
        t_runs = time.perf_counter()
        swept = [c for c in controllers if c.name in SWEPT]
        sweeps = {name: step_sweep(swept, twin, SWEEP_TARGETS, loops=loops) for name, twin in twins.items()}
        t_sweeps = time.perf_counter()
        if isinstance(calibration, PaperCalibration):
            cal = calibration
        elif aside is not None:
            cal = aside.result()
        else:
            cal = calibrate_to_paper(model) if calibration else None
    t_cal = time.perf_counter()
    timings = {f"build {name}": t for name, t in build_times.items()}
    timings.update(
        controllers=t_built - t_start,
        comparison=t_runs - t_built,
        sweeps=t_sweeps - t_runs,
        # aside: the calibration's own wall time (it ran beside the comparison and the sweeps)
        calibration=cal.timings["total"] if aside is not None else t_cal - t_sweeps,
        total=t_cal - t_start,
    )
    aside_run = aside is not None
    return ControllerStudy(tuple(controllers), tuple(skipped), cmp, sweeps, backend, cal, timings, aside_run)


# --- the numbers as printed ------------------------------------------------------------------------------
def _s(value: float) -> str:
    return "—" if not math.isfinite(value) else f"{value:.2f}"


def _pct(value: float) -> str:
    return "—" if not math.isfinite(value) else f"{value:.0f}"


def _mm(value: float, digits: int = 3) -> str:
    return "—" if not math.isfinite(value) else f"{value * M_TO_MM:.{digits}f}"


def _step_at(m: RunMetrics, when: float) -> StepMetrics:
    return next(s for s in m.steps if abs(s.time - when) < 1e-9)


def _ratio_words(ours: float, paper: float) -> str:
    r = paper / ours if ours < paper else ours / paper
    return f"{r:.1f}x {'lower' if ours < paper else 'higher'}"


def _residual(result: SimulationResult, metrics: RunMetrics, axis: int, last: float = 1.0) -> float:
    """Largest |reading − set-point| [m] over the last ``last`` seconds before each change, worst step."""
    err = (result.y[axis] - result.reference[(0, 3)[axis]])[None, :]
    ends = [s.time for s in metrics.steps[1:]] + [result.t[-1] + result.sample_time]
    worst = 0.0
    for end in ends:
        seg = (result.t >= end - last) & (result.t < end)
        worst = max(worst, float(np.nanmax(np.abs(err[0, seg]))))
    return worst


def _peaks(study: ControllerStudy, twin: str) -> dict[str, float]:
    """Each controller's largest commanded current magnitude over the scenarios [A]."""
    cmp = study.comparison
    return {n: max(cmp.metric(n, sc, twin).peak_current for sc in cmp.scenarios) for n in cmp.controllers}


def scorecard_rows(study: ControllerStudy) -> list[tuple[str, str, str, str]]:
    """(the papers' claim, the papers' value, ours, verdict): page 1."""
    paper = paper_scenarios()
    sp, sin = paper["setpoint_steps"].paper, paper["sinusoid"].paper
    rig, ideal = study.metric(FL, "setpoint_steps", "rig"), study.metric(FL, "setpoint_steps", "ideal")
    rows = []

    # settling to 0.1 mm, per step
    v = [s.settling_01mm[0] for s in rig.steps]
    limit_v = float(sp["settle_v_0.1mm_s"])
    ok_v = all(math.isfinite(x) and x < limit_v for x in v)
    rows.append(
        (
            "Vertical error below 0.1 mm\nafter each of five steps (Fig. 9)",
            f"< {limit_v:g} s",
            ", ".join(_s(x) for x in v) + " s",
            "reproduced" if ok_v else f"differs: {sum(x >= limit_v for x in v)} of {len(v)} slower",
        )
    )
    h = [s.settling_01mm[1] for s in rig.steps]
    h_ideal = [s.settling_01mm[1] for s in ideal.steps]
    limit_h, fifth = float(sp["settle_h_0.1mm_s"]), float(sp["settle_h_fifth_s"])
    under = sum(math.isfinite(x) and x < limit_h for x in h)
    verdict_h = (
        "reproduced"
        if under >= 4 and max(h) <= fifth
        else f"differs: {under} of {len(h)} under {limit_h:g} s;"
    )
    if verdict_h != "reproduced":
        verdict_h += f"\nthe design alone (ideal twin): {min(h_ideal):.2f}–{max(h_ideal):.2f} s"
    rows.append(
        (
            "Horizontal error below 0.1 mm\n(Fig. 10)",
            f"four < {limit_h:g} s,\nthe fifth {fifth:g} s",
            ", ".join(_s(x) for x in h) + " s",
            verdict_h,
        )
    )
    res = study.result(FL, "setpoint_steps", "rig")
    tv = [s.settling_10um[0] for s in rig.steps]
    th = [s.settling_10um[1] for s in rig.steps]
    hunting = _residual(res, rig, 0)
    settled_v = sum(math.isfinite(x) for x in tv)
    rows.append(
        (
            "Error within the encoders'\n10 µm (not shown in 002)",
            f"about {float(sp['settle_10um_s']):g} s",
            f"horizontal {_s(np.nanmin(th))}–{_s(np.nanmax(th))} s; vertical:\n{settled_v} of {len(tv)} "
            f"steps, ±{hunting * M_TO_UM:.0f} µm left",
            "horizontal: reproduced (steps 5 s apart)"
            if settled_v == len(tv)
            else f"differs: vertical hunts ±{hunting * M_TO_UM:.0f} µm;\nthe ideal twin settles in "
            f"{_s(ideal.worst_settling(0, '10um'))} s",
        )
    )

    # overshoots
    at5 = _step_at(rig, PAPER_STEP_TIME).overshoot_pct
    target_v = float(sp["overshoot_v_pct"])
    design_v = _step_at(ideal, PAPER_STEP_TIME).overshoot_pct[0]
    close_v = abs(at5[0] - target_v) <= TOLERANCE_PCT
    rows.append(
        (
            f"Vertical overshoot at t = {PAPER_STEP_TIME:g} s\n(Fig. 9)",
            f"{target_v:g} %",
            f"{at5[0]:.0f} % (largest of five {rig.max_overshoot(0):.0f} %)",
            "reproduced"
            if close_v
            else f"differs: the design gives {design_v:.0f} %\n(ideal twin); see the calibrated twin",
        )
    )
    target_h = float(sp["overshoot_h_pct"])
    rows.append(
        (
            "Horizontal overshoot (Fig. 10)",
            f"{target_h:g} %",
            f"{rig.max_overshoot(1):.0f} % (largest of five)",
            "reproduced"
            if abs(rig.max_overshoot(1) - target_h) <= TOLERANCE_PCT
            else f"differs by {rig.max_overshoot(1) - target_h:+.0f} points",
        )
    )
    ret = _step_at(study.metric(RETUNED, "setpoint_steps", "rig"), PAPER_STEP_TIME)
    printed = _step_at(rig, PAPER_STEP_TIME)
    ratio = ret.settling_01mm[0] / printed.settling_01mm[0]
    t_ret, t_ratio = float(sp["retuned_overshoot_v_pct"]), float(sp["retuned_settling_ratio"])
    ok_ret = abs(ret.overshoot_pct[0] - t_ret) <= TOLERANCE_PCT and abs(ratio - t_ratio) <= RATIO_TOLERANCE
    rows.append(
        (
            "Retuned K_v: overshoot and\nsettling time at t = 5 s (Fig. 11)",
            f"{t_ret:g} %, x{t_ratio:g}\n(still < {float(sp['retuned_settle_v_0.1mm_s']):g} s)",
            f"{ret.overshoot_pct[0]:.0f} %, x{ratio:.1f}\n({_s(ret.settling_01mm[0])} s)",
            "reproduced" if ok_ret else "differs",
        )
    )

    # linear against nonlinear
    small = {n: study.metric(n, "small_step", "rig") for n in (FL, LINEAR, LINEAR_NOFF)}
    both = small[FL].success and small[LINEAR_NOFF].success and small[LINEAR].success
    rows.append(
        (
            "Small step: both settle, the\nlinear one with a much larger\ntransient (Fig. 12)",
            "settle;\nmuch larger",
            f"overshoot FL {small[FL].max_overshoot(0):.0f} %, linear\n{small[LINEAR].max_overshoot(0):.0f} "
            f"% ({small[LINEAR_NOFF].max_overshoot(0):.0f} % without feedforward)",
            (
                "both settle: reproduced;\nlarger only without feedforward"
                if both
                else "differs: a run failed"
            ),
        )
    )
    large = study.metric(LINEAR_NOFF, "large_step", "rig")
    large_ff = study.metric(LINEAR, "large_step", "rig")
    sweep = study.sweeps["rig"]
    i = sweep.controllers.index(LINEAR_NOFF)
    fails = sweep.target_gaps[~sweep.success[i]]
    from_gap = f"fails from a {fails.max() * M_TO_MM:.0f} mm target" if fails.size else "never fails"
    min_gap = float(np.nanmin(study.result(LINEAR_NOFF, "large_step", "rig").x[0]))
    rows.append(
        (
            "Large step to (18, 20) mm: the\nlinear regulator goes unstable,\nFL does not (Fig. 12)",
            "unstable",
            "without feedforward: "
            + ("survives" if large.success else "hits the stopper")
            + f" (least gap\n{min_gap * M_TO_MM:.1f} mm), {from_gap};\nwith feedforward: "
            + ("survives" if large_ff.success else "hits the stopper"),
            "reproduced"
            if not large.success and study.metric(FL, "large_step", "rig").success
            else "differs: survives here;\nsee the calibrated twin",
        )
    )

    # the ellipse
    for axis, j, words in ((1, 1, "horizontal"), (0, 0, "vertical")):
        key = "h" if axis == 1 else "v"
        mean_p, peak_p = float(sin[f"mean_err_{key}_mm"]), float(sin[f"peak_err_{key}_mm"])
        m = study.metric(FL, "sinusoid", "rig")
        m_ideal = study.metric(FL, "sinusoid", "ideal")
        mean = m.mean_error[j] * M_TO_MM
        within = 1 / REPRODUCED_RATIO <= mean / mean_p <= REPRODUCED_RATIO
        rows.append(
            (
                f"Ellipse: mean (peak) |error|,\n{words} (Fig. 13)",
                f"{mean_p:g} ({peak_p:g}) mm",
                f"{mean:.3f} ({m.peak_error[j] * M_TO_MM:.2f}) mm;\nideal twin "
                f"{m_ideal.mean_error[j] * M_TO_UM:.2g} µm",
                "reproduced"
                if within
                else f"differs: {_ratio_words(mean, mean_p)}\n(the twin's guides, note 2)",
            )
        )
    pid = study.metric(PID, "sinusoid", "rig")
    pid_paper = (float(sin["pid_mean_err_h_mm"]), float(sin["pid_mean_err_v_mm"]))
    pid_ours = (pid.mean_error[1] * M_TO_MM, pid.mean_error[0] * M_TO_MM)
    pid_ok = all(
        1 / REPRODUCED_RATIO <= o / p <= REPRODUCED_RATIO for o, p in zip(pid_ours, pid_paper, strict=True)
    )
    rows.append(
        (
            "PID on the ellipse: mean |error|,\nhorizontal / vertical (001)",
            f"{pid_paper[0]:g} / {pid_paper[1]:g} mm",
            f"{pid_ours[0]:.3f} / {pid_ours[1]:.3f} mm",
            "reproduced" if pid_ok else "differs",
        )
    )
    peaks = _peaks(study, "rig")
    over = sorted(((v, n) for n, v in peaks.items() if v > PEAK_CURRENT_LIMIT), reverse=True)
    rows.append(
        (
            "Amplifiers: 9 A peak (002 Sec. 4)",
            f"≤ {PEAK_CURRENT_LIMIT:g} A",
            "commanded: "
            + (
                ",\n".join(
                    ", ".join(f"{_short(n)} {v:.1f} A" for v, n in over[k : k + 2])
                    for k in range(0, len(over), 2)
                )
                if over
                else "all within 9 A"
            ),
            f"flagged: {len(over)} of {len(peaks)} ask for more;\nthe rig twin's amplifier clips it"
            if over
            else "all within the rating",
        )
    )
    if study.calibration is not None:
        rows += _calibration_rows(study.calibration)
    return rows


SHORT = {FL: "FL", RETUNED: "FL retuned", LINEAR: "linear", LINEAR_NOFF: "linear (no ff)"}


def _short(name: str) -> str:
    return SHORT.get(name, name)


def _unit(unit: str) -> str:
    return unit.replace("^2", "²")


def _effect_name(name: str) -> str:
    """'normal force of the currents (plant C4)' -> 'plant C4'; other names as they are."""
    return name[name.index("(") + 1 : -1] if name.endswith(")") and "(plant " in name else name


def _effects_words(fit: FitPoint, cal: PaperCalibration) -> str:
    """The effects a fit changes, with their sizes against the rig twin's and the plausible limits."""
    by = {c.parameter: c for c in cal.candidates}
    parts = []
    for name, value in fit.parameters.changes().items():
        c = by.get(name)
        if c is None:
            continue
        unit = _unit(c.unit)
        far = fit.departures.get(name, math.nan)
        where = (
            "its plausible limit"
            if abs(far - 1) < 0.005
            else f"{far:.2g} times as far from the rig twin's {c.nominal:.4g} {unit} as its plausible limit "
            f"{c.limit:.4g}{' (on a log scale)' if c.log_scale else ''}"
        )
        parts.append(f"{c.name} {value:.3g} {unit}, {where}")
    return "; ".join(parts) or "none"


def _fit_outcome(status: str) -> str:
    return {"completed": "survives", "stopper_hit": "hits the stopper", "diverged": "diverges"}.get(
        status, status
    )


def _calibration_rows(cal: PaperCalibration) -> list[tuple[str, str, str, str]]:
    """Scorecard rows of the calibrated twin: the fit that reproduces (or comes closest)."""
    fit = cal.required if cal.required is not None else cal.plausible
    m, tg = fit.metrics, cal.targets
    plausible = "inside the plausible limits" if fit.plausible else "only beyond the plausible limits"
    where = FIT_WORDS.get(fit.name, fit.name)
    rows = [
        (
            "Calibrated twin: 114 % vertical\novershoot at t = 5 s (Fig. 9)",
            f"{tg.overshoot_v_pct:g} %",
            f"{m.overshoot_v_pct:.0f} % on {where};\n{cal.plausible.metrics.overshoot_v_pct:.0f} % with "
            f"{FIT_WORDS['plausible']}",
            (
                "reproduced "
                if abs(m.overshoot_v_pct - tg.overshoot_v_pct) <= cal.tolerance_pct
                else "differs, "
            )
            + plausible
            + ("" if m.sequence_status == "completed" else ";\nthen FL hits the stopper on our five steps"),
        ),
        (
            "Calibrated twin: the linear\nregulator unstable on the large\nstep, FL not (Fig. 12)",
            f"{tg.linear_large_step}",
            f"linear {_fit_outcome(m.linear_large_step)}, FL {_fit_outcome(m.fl_large_step)}",
            ("reproduced " if m.outcomes_as_papers else "differs, ")
            + plausible
            + (
                f";\nwithout the stoppers it {m.linear_unstopped}"
                if m.linear_large_step != "completed" and m.linear_unstopped
                else ""
            ),
        ),
        (
            "Calibrated twin: retuned K_v\n(Fig. 11)",
            f"{tg.retuned_overshoot_v_pct:g} %, x{tg.settling_ratio:g}",
            f"{m.retuned_overshoot_v_pct:.0f} %, x{m.settling_ratio:.1f}",
            "reproduced"
            if abs(m.retuned_overshoot_v_pct - tg.retuned_overshoot_v_pct) <= cal.tolerance_pct
            and abs(m.settling_ratio - tg.settling_ratio) <= RATIO_TOLERANCE
            else "differs: less contrast than\nthe papers' (page on the calibration)",
        ),
    ]
    return rows


def _scorecard_notes(study: ControllerStudy) -> list[str]:
    notes = [
        "1. Ours: the FL regulator with the printed gains on the rig twin, set-points 5 s apart (the "
        "papers do not print theirs; page 2); error = encoder reading − reference. Reproduced: an "
        f"overshoot within {TOLERANCE_PCT:g} points, an error within a factor {REPRODUCED_RATIO:g} of the "
        "papers'.",
        "2. The twin's guide friction and misalignment, which set the ellipse errors, are sized from the "
        "papers' words; the ideal twin shows the design alone.",
    ]
    if study.calibration is not None:
        cal = study.calibration
        fit = cal.required if cal.required is not None else cal.plausible
        notes.append(
            f"3. {FIT_WORDS[fit.name].capitalize()}: the rig twin with {_effects_words(fit, cal)}, found by "
            "fitting the twin's unknowns to the papers' numbers."
        )
    return notes


STEP_COLUMNS = (
    "step",
    "controller",
    "0.1 mm\nvertical [s]",
    "0.1 mm\nhorizontal [s]",
    "10 µm\nvertical [s]",
    "10 µm\nhorizontal [s]",
    "overshoot\nvertical [%]",
    "overshoot\nhorizontal [%]",
)


def step_rows(study: ControllerStudy, twin: str) -> list[tuple[str, ...]]:
    """Per set-point change and controller: settling to 0.1 mm and 10 µm and overshoot per axis."""
    cmp = study.comparison
    sequence = cmp.scenarios["setpoint_steps"].reference
    rows = []
    for k, when in enumerate(sequence.times):
        gap, x = (v * M_TO_MM for v in sequence.setpoints[k])
        for i, name in enumerate(cmp.controllers):
            m = cmp.metric(name, "setpoint_steps", twin)
            s = m.steps[k]
            first = f"{k + 1} at {when:g} s: to\n({gap:g}, {x:g}) mm" if i == 0 else ""
            rows.append(
                (
                    first,
                    name,
                    *(_s(v) for v in s.settling_01mm),
                    *(_s(v) for v in s.settling_10um),
                    *(_pct(v) for v in s.overshoot_pct),
                )
            )
    return rows


def _step_notes(study: ControllerStudy, twin: str) -> list[str]:
    failed = [
        f"{n} hits a stopper ({study.result(n, 'setpoint_steps', twin).message.split(' at ')[-1]})"
        for n in study.comparison.controllers
        if not study.metric(n, "setpoint_steps", twin).success
    ]
    return [
        "Settling: time from the change until the reading stays within the band (—: not within the 5 s to "
        "the next change, or only in its last 0.2 s). Overshoot: beyond the new set-point, in % of the "
        "step. "
        + (
            "; ".join(failed) + ": a failure; the stopper holds the mover and the run goes on, so its later "
            "steps are scored too."
            if failed
            else ""
        )
    ]


AMPLIFIER_COLUMNS = (
    "controller",
    "twin",
    "commanded peak [A]:\nfive set-points",
    "\nsmall step",
    "\nlarge step",
    "\nellipse",
    "over 9 A\n[ms]",
    "amplifier\nclipped [ms]",
    "R < 0\n[samples]",
    "least margin\nR / 4 L4 [m/s²]",
)


def amplifier_rows(study: ControllerStudy) -> list[tuple[str, ...]]:
    """Per controller and twin: the commanded peak current of each scenario, the time above the 9 A
    rating and the time the amplifier clipped (all scenarios), the samples where the feedback
    transformation was undefined (R < 0) and the least margin R / (4 L4)."""
    cmp = study.comparison
    rows = []
    for name in cmp.controllers:
        for k, twin in enumerate(("ideal", "rig")):
            ms = [cmp.metric(name, sc, twin) for sc in cmp.scenarios]
            ts = study.result(name, "setpoint_steps", twin).sample_time * 1e3
            margins = [m.min_margin for m in ms if math.isfinite(m.min_margin)]
            clipped = "—" if twin == "ideal" else f"{sum(m.current_limited for m in ms) * ts:.1f}"
            rows.append(
                (
                    name if k == 0 else "",
                    TWIN_WORDS[twin],
                    *(f"{m.peak_current:.1f}" for m in ms),
                    f"{sum(m.over_peak_rating for m in ms) * ts:.1f}",
                    clipped,
                    f"{sum(m.clipped for m in ms)}" if margins else "—",
                    f"{min(margins):.1f}" if margins else "—",
                )
            )
    return rows


def _outcome(m: RunMetrics) -> str:
    return "ok" if m.success else {"stopper_hit": "stopper", "diverged": "diverged"}.get(m.status, m.status)


ELLIPSE_COLUMNS = (
    "controller",
    "mean |e| vertical\nideal / rig [mm]",
    "peak |e| vertical\nideal / rig [mm]",
    "mean |e| horizontal\nideal / rig [mm]",
    "peak |e| horizontal\nideal / rig [mm]",
)


def ellipse_rows(study: ControllerStudy) -> list[tuple[str, ...]]:
    """Tracking errors on the ellipse from 8 s on, both twins."""
    rows = []
    for name in study.comparison.controllers:
        mi, mr = study.metric(name, "sinusoid", "ideal"), study.metric(name, "sinusoid", "rig")
        cells = []
        for j in (0, 1):
            cells.append(f"{_mm(mi.mean_error[j])} / {_mm(mr.mean_error[j])}")
            cells.append(f"{_mm(mi.peak_error[j])} / {_mm(mr.peak_error[j])}")
        rows.append((name, *cells))
    sin = paper_scenarios()["sinusoid"].paper
    rows.append(
        (
            "papers (FL regulator, rig)",
            f"{float(sin['mean_err_v_mm']):.2f}",
            f"{float(sin['peak_err_v_mm']):.1f}",
            f"{float(sin['mean_err_h_mm']):.2f}",
            f"{float(sin['peak_err_h_mm']):.1f}",
        )
    )
    rows.append(
        (
            "papers (PID, rig)",
            f"≈ {float(sin['pid_mean_err_v_mm']):.1f}",
            "",
            f"{float(sin['pid_mean_err_h_mm']):.2f}",
            "",
        )
    )
    return rows


RETUNED_COLUMNS = (
    "step",
    "twin",
    "overshoot\nprinted [%]",
    "overshoot\nretuned [%]",
    "0.1 mm printed\n[s]",
    "0.1 mm retuned\n[s]",
    "settling\nratio",
)


def retuned_rows(study: ControllerStudy) -> list[tuple[str, ...]]:
    """Vertical overshoot and settling per step, printed against retuned K_v, both twins."""
    rows = []
    for twin in ("ideal", "rig"):
        printed, retuned = (
            study.metric(FL, "setpoint_steps", twin),
            study.metric(RETUNED, "setpoint_steps", twin),
        )
        for k, (p, r) in enumerate(zip(printed.steps, retuned.steps, strict=True)):
            rows.append(
                (
                    f"{k + 1} at {p.time:g} s ({p.size[0] * M_TO_MM:+g} mm)",
                    TWIN_WORDS[twin],
                    _pct(p.overshoot_pct[0]),
                    _pct(r.overshoot_pct[0]),
                    _s(p.settling_01mm[0]),
                    _s(r.settling_01mm[0]),
                    f"{r.settling_01mm[0] / p.settling_01mm[0]:.1f}",
                )
            )
    return rows


LINEAR_COLUMNS = (
    "controller",
    "twin",
    "small step",
    "large step",
    "least gap,\nlarge step [mm]",
    "copes down to",
)


def linear_rows(study: ControllerStudy) -> list[tuple[str, ...]]:
    """The regulators on the papers' two steps and the smallest target gap each copes with."""
    rows = []
    for name in SWEPT:
        for twin in ("ideal", "rig"):
            sweep = study.sweeps[twin]
            i = sweep.controllers.index(name)
            ok = sweep.target_gaps[sweep.success[i]]
            rows.append(
                (
                    name,
                    TWIN_WORDS[twin],
                    _words(study.metric(name, "small_step", twin)),
                    _words(study.metric(name, "large_step", twin)),
                    f"{np.nanmin(study.result(name, 'large_step', twin).x[0]) * M_TO_MM:.1f}",
                    f"{ok.min() * M_TO_MM:.0f} mm" if ok.size else "no target",
                )
            )
    return rows


def _words(m: RunMetrics) -> str:
    if not m.success:
        return "hits the stopper" if m.status == "stopper_hit" else m.status
    return f"settles, {m.max_overshoot(0):.0f} % / {m.max_overshoot(1):.0f} %"


# --- the report ------------------------------------------------------------------------------------------
def build(out: Path, model: StageModel, *, nmpc: bool = True, calibration: bool = True) -> ReportContents:
    """Run the study and write its report to ``out``."""
    return write_report(out, compare_controllers(model, nmpc=nmpc, calibration=calibration))


def write_report(out: Path, study: ControllerStudy) -> ReportContents:
    """Write the report of a finished study."""
    t0 = time.perf_counter()
    cmp = study.comparison
    sp = cmp.scenarios["setpoint_steps"].paper
    limits = {
        "vertical": float(sp["settle_v_0.1mm_s"]),
        "horizontal": float(sp["settle_h_0.1mm_s"]),
        "horizontal_fifth": float(sp["settle_h_fifth_s"]),
    }
    fl_rig = study.result(FL, "setpoint_steps", "rig")
    with PdfReport(out, TITLE, subtitle="reports/controllers.pdf from analyses/controllers.py") as pdf:
        pdf.add_page(
            "Scorecard: the papers' claims beside ours",
            [
                Table(
                    "",
                    ("claim (002 Sec. 7; 001 Sec. VI)", "papers", "ours (rig twin)", "verdict"),
                    scorecard_rows(study),
                    notes=_scorecard_notes(study),
                    font_size=7.5,
                ),
                Plot(plots.key_plot(fl_rig, study.metric(FL, "setpoint_steps", "rig"), limits), 0.29),
            ],
            first_page=True,
        )
        pdf.add_page("What ran: controllers, twins, scenarios", _method_blocks(study))
        pdf.add_page(
            "Set-point steps with the FL regulator (002 Figs. 9-10)",
            [
                Plot(
                    plots.setpoint_plot(
                        fl_rig,
                        "The five set-point steps on the rig twin",
                        "Positions with their set-points, velocities, errors (reading − set-point, clipped "
                        f"to ±{plots.ERROR_VIEW:g} mm, the 0.1 mm and 10 µm bands shaded) and the commanded "
                        "currents.",
                    ),
                    0.88,
                )
            ],
        )
        for twin in ("rig", "ideal"):
            pdf.add_page(
                f"Set-point steps, step by step: {TWIN_WORDS[twin]}",
                [
                    Table(
                        "",
                        STEP_COLUMNS,
                        step_rows(study, twin),
                        notes=_step_notes(study, twin),
                        font_size=7.0,
                    )
                ],
            )
        others = [study.result(n, "setpoint_steps", "rig") for n in cmp.controllers if n != FL]
        pdf.add_page(
            "Every controller on one step",
            [Plot(plots.controller_steps_plot(others, fl_rig, PAPER_STEP_TIME, 2.5), 0.88)],
        )
        _retuned_page(pdf, study)
        _linear_page(pdf, study)
        _ellipse_page(pdf, study)
        _amplifier_pages(pdf, study)
        if study.calibration is not None:
            _calibration_page(pdf, study.calibration)
            _calibration_search_page(pdf, study.calibration)
        study.timings["report"] = time.perf_counter() - t0
        pdf.add_page("Appendix: every run and how long it took", _timing_blocks(study))
    return pdf.contents


def _method_blocks(study: ControllerStudy) -> list:
    paragraphs = ["Controllers (one colour each, the same in every report):"]
    paragraphs.append("\n".join(f" • {c.name}{_tuning(c)}" for c in study.controllers))
    if study.skipped:
        paragraphs.append("Not built on this install: " + "; ".join(study.skipped))
    scenarios = [
        (
            SCENARIO_WORDS[name],
            _start_words(sc.x0),
            _reference_words(name, sc),
            f"{sc.duration:g}",
            sc.paper.get("source", ""),
        )
        for name, sc in study.comparison.scenarios.items()
    ]
    rig = study.metric(FL, "setpoint_steps", "rig")
    hunting = _residual(study.result(FL, "setpoint_steps", "rig"), rig, 0)
    scoring = [
        "How a run is scored, in the papers' terms (002 Sec. 7). Settling time: from a set-point change "
        "until the reading stays within the band to the next change (0.1 mm, the papers' accuracy goal, or "
        "10 µm, one encoder count), held for at least the last 0.2 s. Overshoot: the largest excursion "
        "past the new set-point, in % of the step (steps under 0.5 mm are not scored). Ellipse: mean and "
        "peak |reading − reference| from 8 s on. Currents: the magnitude of the commanded (i_q, i_d), "
        "against the amplifiers' 9 A peak rating. A run fails when it touches a stopper (gap 8 or 30 mm, x "
        "±60 mm) or diverges.",
        "What the rig twin adds: with guide friction, the internal model's undamped ω0 oscillator keeps "
        f"the FL regulator hunting around each set-point (vertically up to ±{hunting * M_TO_UM:.0f} µm in "
        "the last second before a change), so its vertical error does not settle to 10 µm there; on the "
        "ideal twin it does, within "
        f"{_s(study.metric(FL, 'setpoint_steps', 'ideal').worst_settling(0, '10um'))} s.",
    ]
    return [
        Text(paragraphs, font_size=8.5),
        twin_table(("ideal twin", "rig twin")),
        Table(
            "The papers' experiments as we run them",
            ("scenario", "start (gap, x)", "reference", "length [s]", "papers"),
            scenarios,
            notes=[
                "The papers print neither their five set-points nor where the ellipse starts; ours span "
                f"{_span_words(study)}. Every run starts at rest, levitated by the current that holds the "
                "start. Errors are encoder readings − reference, as the papers measure them."
            ],
        ),
        Text(scoring, font_size=8.5),
    ]


def _span_words(study: ControllerStudy) -> str:
    """Where the set-points lie and how large their steps are, in words."""
    sc = study.comparison.scenarios["setpoint_steps"]
    points = np.asarray(sc.reference.setpoints) * M_TO_MM
    steps = np.abs(np.diff(np.vstack([[sc.x0[0] * M_TO_MM, sc.x0[2] * M_TO_MM], points]), axis=0))
    g, x = steps[:, 0], steps[:, 1]
    return (
        f"[{points[:, 0].min():g}, {points[:, 0].max():g}] mm x [{points[:, 1].min():g}, "
        f"{points[:, 1].max():g}] mm with steps of {g.min():g}–{g.max():g} mm vertically and "
        f"{x.min():g}–{x.max():g} mm horizontally"
    )


def _start_words(x0) -> str:
    return f"({x0[0] * M_TO_MM:g}, {x0[2] * M_TO_MM:g}) mm"


def _reference_words(name: str, sc) -> str:
    ref = sc.reference
    if name == "sinusoid":
        (av, w, _), (ah, _, _) = ref.vertical[0], ref.horizontal[0]
        return (
            f"gap {ref.gap_offset * M_TO_MM:g} + {av * M_TO_MM:g} cos(ω0 t) mm, x {ah * M_TO_MM:g} sin(ω0 t) "
            f"mm,\nω0 = {w / math.pi:g}π rad/s, ramped in over {ref.ramp_time:g} s; scored from "
            f"{sc.evaluate_from:g} s"
        )
    points = ", ".join(f"({g * M_TO_MM:g}, {x * M_TO_MM:g})" for g, x in ref.setpoints)
    if len(ref.setpoints) == 1:
        return f"to {points} mm"
    return "to " + points.replace("), (", "),\n(", 2) + f" mm,\n{ref.times[1] - ref.times[0]:g} s apart"


def _tuning(c) -> str:
    design = getattr(c, "design", {}) or {}
    if isinstance(c, FeedbackLinearizingRegulator):
        kv = ", ".join(f"{k:.0f}" for k in c.K_v)
        if c.name == FL:
            kh = ", ".join(f"{k:.0f}" for k in c.K_h)
            return f": the papers' nonlinear controller, printed gains K_h = [{kh}], K_v = [{kv}]"
        return f": the same with 002's retuned K_v = [{kv}]"
    if "poles_v" in design:
        ff = "" if c.name == LINEAR else "; without the equilibrium current, the literal reading of 002"
        return (
            ": the papers' linear regulator, the printed gains' poles placed on the linearization at the "
            f"set-point's gap, plus the equilibrium current there{ff}"
        )
    if "weights" in design:
        w = design["weights"]
        return (
            f": LQR on the same linearization, Bryson maxima vertical (error {w['vertical'].error * 1e3:g} "
            f"mm, rate {w['vertical'].error_rate:g} m/s, 1 A), horizontal ({w['horizontal'].error * 1e3:g} "
            f"mm, {w['horizontal'].error_rate:g} m/s, 1 A)"
        )
    if "poles" in design and isinstance(design["poles"], dict):
        p = design["poles"]
        return (
            f": the papers' identification PIDs, triple poles at {p['vertical'][0]:g} 1/s (vertical) and "
            f"{p['horizontal'][0]:g} 1/s (horizontal), no internal model"
        )
    if isinstance(c, CompiledNMPC):
        n = c.controller
        w, g = n.weights, n.grid
        return (
            f": real-time iteration, horizon {g.horizon} intervals (one sample, then "
            f"{g.interval_samples * g.sample_time * 1e3:g} ms), Q = diag({w.gap:g}, {w.gap_rate:g}, "
            f"{w.position:g}, {w.position_rate:g}), R = diag({w.i_q:g}, {w.i_d:g}) per second, currents kept "
            f"within {n.current_limit:g} A, {n.qp_solver.upper()} QP, a disturbance observer for offset-free "
            "tracking, no reference preview"
        )
    return ""


def _retuned_page(pdf: PdfReport, study: ControllerStudy) -> None:
    pairs = [
        (
            TWIN_WORDS[t].split()[0],
            study.result(FL, "setpoint_steps", t),
            study.result(RETUNED, "setpoint_steps", t),
        )
        for t in ("ideal", "rig")
    ]
    pdf.add_page(
        "The retuned K_v (002 Fig. 11)",
        [
            Table(
                "",
                RETUNED_COLUMNS,
                retuned_rows(study),
                notes=[
                    "Vertical overshoot and settling to 0.1 mm after each change, FL regulator with the "
                    "printed and the retuned K_v; settling ratio = retuned / printed (002: 40 % at t = 5 s "
                    "and three times longer, still below 3 s)."
                ],
                font_size=7.5,
            ),
            Plot(plots.retuned_plot(pairs, PAPER_STEP_TIME, 3.5), 0.52),
        ],
    )


def _linear_page(pdf: PdfReport, study: ControllerStudy) -> None:
    scenarios = paper_scenarios()
    columns = [
        (
            scenarios[sc]
            .title.replace("->", "→")
            .replace("Small step", "small step")
            .replace("Large step", "large step"),
            [study.result(n, sc, "rig") for n in SWEPT],
        )
        for sc in ("small_step", "large_step")
    ]
    pdf.add_page(
        "Linear against nonlinear (002 Fig. 12)",
        [
            Plot(plots.linear_plot(columns, 3.0), 0.42),
            Table(
                "",
                LINEAR_COLUMNS,
                linear_rows(study),
                notes=[
                    "Overshoot vertical / horizontal. 'Copes down to': the smallest target gap of the sweep "
                    f"the regulator reaches without touching the {STOPPER_GAP[0] * M_TO_MM:g} mm stopper."
                ],
                font_size=7.5,
            ),
            Plot(
                plots.sweep_plot([(TWIN_WORDS[t].split()[0], study.sweeps[t]) for t in ("ideal", "rig")]),
                0.24,
            ),
        ],
    )


def _ellipse_page(pdf: PdfReport, study: ControllerStudy) -> None:
    names = [n for n in (FL, PID) if n in study.comparison.controllers]
    results = [study.result(n, "sinusoid", "rig") for n in names]
    metrics = [study.metric(n, "sinusoid", "rig") for n in names]
    start = study.comparison.scenarios["sinusoid"].evaluate_from
    pdf.add_page(
        "The ellipse (002 Fig. 13)",
        [
            Plot(plots.ellipse_plot(results, metrics, start), 0.5),
            Table(
                "Every controller on the ellipse",
                ELLIPSE_COLUMNS,
                ellipse_rows(study),
                notes=[
                    f"Reading − reference from {start:g} s to the end (the amplitudes ramp in over 2 s). The "
                    "internal models run at the reference's ω0 and cancel it; the PID has none."
                ],
                font_size=7.5,
            ),
        ],
    )


def _amplifier_pages(pdf: PdfReport, study: ControllerStudy) -> None:
    cmp = study.comparison
    results = [study.result(n, "setpoint_steps", "rig") for n in cmp.controllers]
    metrics = [study.metric(n, "setpoint_steps", "rig") for n in cmp.controllers]
    pdf.add_page(
        "Currents: the 9 A rating and the transformation's domain",
        [
            Table(
                "",
                AMPLIFIER_COLUMNS,
                amplifier_rows(study),
                notes=[
                    "Commanded peak: the largest |(i_q, i_d)| a controller asks for; the amplifiers are "
                    "rated 9 A peak (002 Sec. 4). The ideal twin applies any current; the rig twin's "
                    "amplifier clips the magnitude to 9 A ('amplifier clipped'). R < 0: samples where the "
                    "feedback transformation has no real solution and the FL regulator commands the nearest "
                    "i_d it can (only the FL regulators have it; their least margin R / (4 L4) says how far "
                    "from it they stayed)."
                ],
                font_size=7.0,
            ),
            Plot(plots.currents_plot(results, metrics), 0.52),
        ],
    )


CALIBRATION_COLUMNS = ("papers' figure", "papers")


def _calibration_page(pdf: PdfReport, cal: PaperCalibration) -> None:
    fits = cal.fits()
    tg = cal.targets
    rows = [
        (
            "vertical overshoot at t = 5 s [%]",
            f"{tg.overshoot_v_pct:g}",
            *(_pct(f.metrics.overshoot_v_pct) for f in fits),
        ),
        (
            "largest over the five steps [%]",
            "",
            *(_pct(float(np.nanmax(f.metrics.overshoot_v_steps_pct))) for f in fits),
        ),
        (
            "horizontal overshoot [%]",
            f"{tg.overshoot_h_pct:g}",
            *(_pct(f.metrics.overshoot_h_pct) for f in fits),
        ),
        (
            "retuned K_v: overshoot [%]",
            f"{tg.retuned_overshoot_v_pct:g}",
            *(_pct(f.metrics.retuned_overshoot_v_pct) for f in fits),
        ),
        (
            "retuned K_v: settling ratio",
            f"{tg.settling_ratio:g}",
            *(f"{f.metrics.settling_ratio:.1f}" for f in fits),
        ),
        (
            "linear regulator, large step",
            tg.linear_large_step,
            *(_fit_outcome(f.metrics.linear_large_step) for f in fits),
        ),
        ("  its least gap [mm]", "", *(f"{f.metrics.linear_min_gap * M_TO_MM:.1f}" for f in fits)),
        (
            "FL regulator, large step",
            tg.fl_large_step,
            *(_fit_outcome(f.metrics.fl_large_step) for f in fits),
        ),
        ("FL regulator, five steps", "stable", *(_fit_outcome(f.metrics.sequence_status) for f in fits)),
        ("within the plausible limits", "", *("yes" if f.plausible else "no" for f in fits)),
    ]
    columns = (
        *CALIBRATION_COLUMNS,
        *(FIT_WORDS.get(f.name, f.name).replace(" the ", "\nthe ", 1) for f in fits),
    )
    effects = [
        f"{FIT_WORDS.get(f.name, f.name)}: {_effects_words(f, cal)}" for f in fits if f.name != "nominal"
    ]
    candidates = "; ".join(f"{c.name} (limit {c.limit:.3g} {_unit(c.unit)})" for c in cal.candidates)
    text = [
        "Which effects the rig twin lacks, and how large they must be, for the papers' 114 % vertical "
        "overshoot and the linear regulator's failure on the large step to hold at once: every unknown of "
        f"the twin was varied within a plausible limit and beyond ({candidates}), each alone and in pairs "
        f"on grids, and fitted to the papers' numbers (an overshoot within {cal.tolerance_pct:g} points "
        "reproduces it).",
        "Verdict: " + cal.message + ".",
        " ".join(f"{e[0].upper()}{e[1:]}." for e in effects),
    ]
    fit = cal.required if cal.required is not None else cal.plausible
    m = fit.metrics
    if m.linear_large_step != "completed":
        text.append(
            f"How the linear regulator fails there: it touches the {STOPPER_GAP[0] * M_TO_MM:g} mm gap "
            f"stopper on its first undershoot; without the stoppers it {m.linear_unstopped} (least gap "
            f"{m.linear_unstopped_min_gap * M_TO_MM:.1f} mm), where the papers' oscillation grew until their "
            "safety mechanism shut the loop down."
        )
    panels = [
        (f"{FL}, the step at t = {PAPER_STEP_TIME:g} s", "papers_step", FL, PAPER_STEP_TIME, 2.5),
        (f"{RETUNED}, the same step", "retuned", RETUNED, PAPER_STEP_TIME, 2.5),
        (f"{LINEAR_NOFF}, large step", "large_step", LINEAR_NOFF, 0.0, 3.0),
        (f"{FL}, large step", "large_step", FL, 0.0, 3.0),
    ]
    traces = [
        (title, cal.trace(panel, "nominal", name), cal.trace(panel, fit.name, name), t0, window)
        for title, panel, name, t0, window in panels
    ]
    pdf.add_page(
        "The twin calibrated to the papers' step experiments",
        [
            Text(text, font_size=8.5),
            Table("", columns, rows, font_size=7.5),
            Plot(plots.calibrated_plot(traces, FIT_WORDS[fit.name]), 0.4),
        ],
    )


def _calibration_search_page(pdf: PdfReport, cal: PaperCalibration) -> None:
    """The calibration's profiles and grids: how unique the fit is."""
    rows = []
    for prof in cal.profiles:
        c = prof.candidate
        cells = []
        for value, m in zip(prof.values, prof.metrics, strict=True):
            mark = ("L" if m.linear_large_step != "completed" else "") + (
                "" if m.fl_large_step == m.steps_status == "completed" else "F"
            )
            cells.append(f"{value:.4g}: {m.overshoot_v_pct:.0f}{mark}")
        rows.append((c.name, _unit(c.unit), f"{c.limit:.4g}", ",  ".join(cells)))
    blocks: list = [
        Text(
            [
                "Each effect alone, from the rig twin's size (first) to its plausible limit and beyond: "
                f"the vertical overshoot at t = {PAPER_STEP_TIME:g} s [%] with the printed gains; L: the "
                "linear regulator (no feedforward) fails the large step; F: the FL regulator fails it or "
                "the steps.",
            ],
            font_size=8.5,
        ),
        Table("", ("effect (alone)", "unit", "plausible\nlimit", "size: overshoot [%]"), rows, font_size=7.5),
    ]
    by = {c.parameter: c for c in cal.candidates}
    for g in cal.grids:
        a, b = (by[name] for name in g.parameters)
        grid_rows = []
        for i, va in enumerate(g.values[0]):
            cells = []
            for j in range(g.values[1].size):
                mark = "*" if g.reproduces[i, j] else ("" if np.isfinite(g.misfit[i, j]) else " –")
                cells.append(f"{g.overshoot_v[i, j]:.0f} / {g.retuned_overshoot_v[i, j]:.0f}{mark}")
            grid_rows.append((f"{va:.4g}", *cells))
        blocks.append(
            Table(
                f"Grid: {_effect_name(a.name)} [{_unit(a.unit)}] down, {_effect_name(b.name)} "
                f"[{_unit(b.unit)}] across",
                (f"{_effect_name(a.name)} \\ {_effect_name(b.name)}", *(f"{vb:.4g}" for vb in g.values[1])),
                grid_rows,
                font_size=7.5,
            )
        )
    blocks.append(
        Text(
            [
                "Grid cells: overshoot at t = 5 s with the printed / the retuned K_v [%]; *: reproduces "
                f"both claims (within {cal.tolerance_pct:g} points of {cal.targets.overshoot_v_pct:g} %, "
                "the linear regulator failing and the FL regulator not); –: the large-step outcomes differ "
                f"from the papers'. {cal.simulations} simulations in all.",
                _uniqueness_words(cal),
            ],
            font_size=8.5,
        )
    )
    pdf.add_page("Appendix: how the calibration searched", blocks)


LEVERAGE = 10.0
"""[% points] An effect that moves the overshoot at t = 5 s by more than this alone, within its
plausible limit, has leverage on it."""


def _uniqueness_words(cal: PaperCalibration) -> str:
    """How unique the fit is: which effects alone have leverage within their limits, and which grid
    twins reproduce."""
    strong = []
    for prof in cal.profiles:
        inside = prof.departures <= 1.0 + 1e-9
        ov = prof.overshoot_v
        moved = np.abs(ov[inside] - ov[0])
        if np.any(inside) and np.nanmax(moved) > LEVERAGE:
            strong.append(f"{prof.candidate.name} ({ov[0]:.0f} to {ov[inside][np.nanargmax(moved)]:.0f} %)")
    by = {c.parameter: c for c in cal.candidates}
    found = []
    total = 0
    for g in cal.grids:
        total += g.reproduces.size
        for i, j in zip(*np.nonzero(g.reproduces), strict=True):
            a, b = (by[name] for name in g.parameters)
            found.append(
                f"{_effect_name(a.name)} {g.values[0][i]:.4g} {_unit(a.unit)} with {_effect_name(b.name)} "
                f"{g.values[1][j]:.4g} {_unit(b.unit)}"
            )
    lever = (
        "Alone and within its plausible limit, "
        + ("; ".join(strong) + (" moves" if len(strong) == 1 else " move") if strong else "no effect moves")
        + f" the overshoot at t = 5 s by more than {LEVERAGE:g} points. "
    )
    return (
        lever
        + f"{len(found)} of the {total} grid twins reproduce both claims"
        + (": " + "; ".join(found) + "." if found else ".")
    )


RUN_COLUMNS = (
    "controller",
    "twin",
    *(SCENARIO_WORDS[k] + "\n[s]" for k in ("setpoint_steps", "small_step", "large_step", "sinusoid")),
    "per sample\n[µs]",
)


def run_rows(study: ControllerStudy) -> list[tuple[str, ...]]:
    """Every run's wall time (and how it failed, if it did), and a controller's cost per sample on a
    twin over its runs after the first (which includes compiling the loop)."""
    cmp = study.comparison
    rows = []
    for name in cmp.controllers:
        for k, twin in enumerate(("ideal", "rig")):
            cells = []
            for sc in ("setpoint_steps", "small_step", "large_step", "sinusoid"):
                r = cmp.results[(name, sc, twin)]
                failed = (
                    ""
                    if r.success
                    else f"\n{_outcome(cmp.metric(name, sc, twin))} {r.message.split(' at ')[-1]}"
                )
                cells.append(f"{r.timings['total']:.2f}{failed}")
            later = [cmp.results[(name, sc, twin)] for sc in ("small_step", "large_step", "sinusoid")]
            per = sum(r.timings["total"] for r in later) / max(sum(r.t.size for r in later), 1) * 1e6
            rows.append((name if k == 0 else "", TWIN_WORDS[twin], *cells, f"{per:.1f}"))
    return rows


def _timing_blocks(study: ControllerStudy) -> list:
    cmp = study.comparison
    t = study.timings
    steps = [("building the controllers", t.get("controllers", math.nan))]
    nmpc = next((c for c in study.controllers if isinstance(c, CompiledNMPC)), None)
    if nmpc is not None:
        where = "loaded from the cache" if nmpc.cached else "generated and compiled"
        steps.append((f"  of which the NMPC's C library ({where})", nmpc.build_time))
    n_sweep = sum(s.target_gaps.size * len(s.controllers) for s in study.sweeps.values())
    steps += [
        (f"the {len(cmp.results)} runs of the comparison", t.get("comparison", math.nan)),
        (f"the {n_sweep} runs of the step sweeps", t.get("sweeps", math.nan)),
    ]
    if study.calibration is not None:
        beside = ", in a process of its own beside the runs above" if study.calibrated_aside else ""
        steps.append(
            (
                f"the calibration ({study.calibration.simulations} runs{beside})",
                t.get("calibration", math.nan),
            )
        )
    steps += [
        ("writing the pages", t.get("report", math.nan)),
        ("total", t.get("total", 0.0) + t.get("report", 0.0)),
    ]
    backend = {
        "c": "generated C, each controller fused with the twin in a C loop",
        "vm": "CasADi's virtual machine",
    }
    return [
        Table(
            "Every run: wall time",
            RUN_COLUMNS,
            run_rows(study),
            font_size=7.5,
            notes=[
                f"Closed loops at 5 kHz as {backend[study.backend]}. The first run of a controller on a twin "
                "(the five set-points) includes generating and compiling its loop; 'per sample' is over the "
                "later runs. The NMPC's real-time iteration is compiled once and called from each twin's "
                "loop; the 5 kHz sample is 200 µs."
            ],
        ),
        Table(
            "Where the time went", ("step", "wall [s]"), [(w, f"{v:.1f}") for w, v in steps], font_size=7.5
        ),
    ]


def main(argv: list[str] | None = None) -> int:
    from maglev_oc.analyses import analysis_parser

    from maglev_oc.model.loading import load_model

    parser = analysis_parser(__doc__, REPORT)
    parser.add_argument("--no-nmpc", action="store_true", help="leave NMPC out (faster)")
    parser.add_argument(
        "--no-calibration", action="store_true", help="leave the calibrated twin out (faster)"
    )
    args = parser.parse_args(argv)
    contents = build(
        args.out, load_model(args.params), nmpc=not args.no_nmpc, calibration=not args.no_calibration
    )
    print(f"wrote {contents.path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
