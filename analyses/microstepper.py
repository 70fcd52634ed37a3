"""The 3-DOF microstepper of 002 Sec. 8: the paper's claims beside the rig twin's, the model and
its assumptions, equilibria and the input redundancy, the figures of 002 Figs. 15-18, the
amplifier limit with and without anti-windup, and the certified region at the paper's set-points.

    python analyses/microstepper.py [--out reports/microstepper.pdf] [--params stage.json] [--quick]

The closed loops run as generated C when a C compiler is there (all of them together take a few
seconds), else in CasADi's virtual machine; the certified region takes most of the time.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Ellipse

from maglev_oc.control.microstepper import MicrostepperRegulator
from maglev_oc.model.allocation import Allocation, MicrostepperTransformation
from maglev_oc.model.hardware import MICROSTEPPER_STOPPER_GAP, PEAK_CURRENT_LIMIT, STOPPER_POSITION
from maglev_oc.model.platform import MICROSTEPPER_ASSUMPTIONS, Platform, PlatformModel, microstepper
from maglev_oc.model.stage import StageModel
from maglev_oc.numerics import c_compiler
from maglev_oc.region.microstepper import MicrostepperRegion, MicrostepperRegionResult
from maglev_oc.reporting.pdf import PAGE_SIZE, PdfReport, Plot, ReportContents, Table, Text, caption, grid
from maglev_oc.reporting.style import bands, thin
from maglev_oc.sim.effects import GuideFriction
from maglev_oc.sim.metrics import BANDS
from maglev_oc.sim.microstepper import (
    MicrostepperLoop,
    MicrostepperMetrics,
    MicrostepperResult,
    evaluate_microstepper,
)
from maglev_oc.sim.microstepper_scenarios import MicrostepperScenario, microstepper_scenarios
from maglev_oc.sim.microstepper_twin import MicrostepperEffects, MicrostepperTwin
from maglev_oc.units import M_TO_MM, M_TO_UM, MM_TO_M

__all__ = [
    "ORDER",
    "QUICK",
    "REPORT",
    "MicrostepperConfig",
    "MicrostepperStudy",
    "build",
    "main",
    "run_study",
    "scorecard_rows",
    "step_rows",
    "write_report",
]

REPORT = "microstepper.pdf"
ORDER = 70
TITLE = "maglev_oc — the 3-DOF microstepper"
AXES = ("x", "y", "gap")
HEAVY_FRICTION = GuideFriction(coulomb=1.0, viscous=1.0)
"""The x and y guides of the friction variant: 1 N Coulomb, ten times the rig twin's 0.1 N."""
HEAVY = "1 N friction on x and y"
SCENARIO_WORDS = {"setpoints": "set-points", "sinusoid": "sinusoid", "saturation": "90 mm step"}


@dataclass(frozen=True)
class MicrostepperConfig:
    """How much work the report does.

    Attributes
    ----------
    region_rel_tol : float
        Relative width of the certified region's bracket to aim for.
    region_max_boxes : int
        Branch-and-bound budget per certified level.
    seed : int
        Seed of the encoder noise of every run.
    """

    region_rel_tol: float = 0.01
    region_max_boxes: int = 1_000_000
    seed: int = 0


QUICK = MicrostepperConfig(region_rel_tol=0.05, region_max_boxes=300_000)
"""Coarser certificates (brackets up to 14 % wide) for tests; the runs are the full ones."""


@dataclass(frozen=True)
class Run:
    """One closed-loop run: what ran, its result, the paper's figures of it, the loop's build time."""

    label: str
    scenario: MicrostepperScenario
    result: MicrostepperResult
    metrics: MicrostepperMetrics
    build_time: float  # [s]


@dataclass(frozen=True)
class RegionRow:
    """The certificate at one set-point; ``mirror`` is the set-point it was computed at when this
    one mirrors it (the constraints are even in x and y)."""

    setpoint: tuple[float, float, float]  # [m]
    result: MicrostepperRegionResult
    mirror: tuple[float, float, float] | None
    start_ratio: float  # V at the start of the step to this set-point / certified level


@dataclass(frozen=True)
class MicrostepperStudy:
    """Everything the report prints, computed by :func:`run_study`."""

    platform: Platform
    scenarios: dict[str, MicrostepperScenario]
    runs: dict[str, Run]
    breakdown: tuple[tuple[str, MicrostepperMetrics], ...]
    equilibria: tuple[tuple[float, float, float, float, float], ...]
    allocations: tuple[tuple[float, tuple[float, float, float], Allocation, Allocation], ...]
    region: tuple[RegionRow, ...]
    lyapunov_matrix: np.ndarray  # (15, 15) P of the certificates
    backend: str
    config: MicrostepperConfig
    timings: dict[str, float] = field(default_factory=dict)


# --- computing ---------------------------------------------------------------------------------------
VARIANTS = {
    "anti_windup": "anti-windup and levitation first (as designed)",
    "no_anti_windup": "without anti-windup",
    "no_levitation_first": "without levitation first",
    "neither": "without either (the 2-DOF regulator on three axes)",
}
"""The controller variants on the amplifier limit, as the report names them."""
VARIANT_COLORS = {
    "anti_windup": "tab:blue",
    "no_anti_windup": "tab:red",
    "no_levitation_first": "tab:purple",
    "neither": "tab:brown",
}
BREAKDOWN = (
    ("rig twin", None),
    ("no cogging", {"cogging": None}),
    ("no guide friction", {"friction": (None, None, None)}),
    ("exact positions (no encoder)", {"encoder": None}),
    ("ideal amplifiers", {"amplifier": None}),
    ("no loop delay", {"input_delay_samples": 0}),
    (HEAVY, {"friction": "heavy"}),
    ("ideal twin", "ideal"),
)
"""Sinusoid runs with the rig twin changed: what sets each axis's error."""


def _regulators(platform: Platform) -> dict[str, MicrostepperRegulator]:
    return {
        "anti_windup": MicrostepperRegulator(platform),
        "no_anti_windup": MicrostepperRegulator(platform, anti_windup=False),
        "no_levitation_first": MicrostepperRegulator(platform, levitation_first=False),
        "neither": MicrostepperRegulator(platform, anti_windup=False, levitation_first=False),
    }


def _twin(platform: Platform, change) -> MicrostepperTwin:
    if change == "ideal":
        return MicrostepperTwin(platform, MicrostepperEffects.ideal())
    change = dict(change or {})
    if change.get("friction") == "heavy":
        change["friction"] = (HEAVY_FRICTION, HEAVY_FRICTION, MicrostepperEffects.rig().friction[2])
    return MicrostepperTwin(platform, MicrostepperEffects.rig(**change))


def run_study(model: StageModel, config: MicrostepperConfig | None = None) -> MicrostepperStudy:
    """Run every simulation and certificate the report shows, on the microstepper built from
    ``model``'s geometry and constants (controller and twin alike)."""
    config = config or MicrostepperConfig()
    t_start = time.perf_counter()
    platform = microstepper(model.params, model.constants)
    scenarios = microstepper_scenarios()
    backend = "c" if c_compiler() is not None else "vm"
    rig = MicrostepperTwin(platform)
    ctrl = _regulators(platform)
    runs: dict[str, Run] = {}

    def run(
        key: str, twin: MicrostepperTwin, variant: str, scenario: MicrostepperScenario, label: str
    ) -> Run:
        loop = MicrostepperLoop(twin, ctrl[variant], backend=backend)
        result = loop.run(scenario, seed=config.seed)
        runs[key] = Run(label, scenario, result, evaluate_microstepper(result, scenario), loop.build_time)
        return runs[key]

    run("setpoints", rig, "anti_windup", scenarios["setpoints"], "as designed, rig twin")
    run("setpoints:no_anti_windup", rig, "no_anti_windup", scenarios["setpoints"], VARIANTS["no_anti_windup"])
    for name, label in VARIANTS.items():
        run(f"saturation:{name}", rig, name, scenarios["saturation"], label)
    free = MicrostepperTwin(platform, MicrostepperEffects.rig(stoppers=None))
    long_step = scenarios["saturation"].shortened(10.0)
    label = "without anti-windup, no stoppers"
    run("saturation:no_anti_windup:no_stoppers", free, "no_anti_windup", long_step, label)
    breakdown = []
    for label, change in BREAKDOWN:
        key = "sinusoid" if change is None else f"sinusoid:{label}"
        twin = rig if change is None else _twin(platform, change)
        breakdown.append((label, run(key, twin, "anti_windup", scenarios["sinusoid"], label).metrics))
    t_runs = time.perf_counter()
    region, lyapunov = _region_rows(platform, scenarios["setpoints"], config)
    t_region = time.perf_counter()
    equilibria, allocations = _equilibria(platform, ctrl["anti_windup"]), _allocations(platform)
    timings = {
        "simulations": t_runs - t_start,
        "region": t_region - t_runs,
        "equilibria": time.perf_counter() - t_region,
        "total": time.perf_counter() - t_start,
    }
    return MicrostepperStudy(
        platform,
        scenarios,
        runs,
        tuple(breakdown),
        equilibria,
        allocations,
        region,
        lyapunov,
        backend,
        config,
        timings,
    )


def _region_rows(platform: Platform, scenario: MicrostepperScenario, config: MicrostepperConfig):
    """The certificate at each of the scenario's set-points, and P. The constraints depend on x
    and y only through i_q^2 and the room to the symmetric travel limits, so a set-point that
    mirrors one computed before shares its certificate."""
    region = MicrostepperRegion(platform)
    done: dict[tuple[float, float, float], tuple] = {}
    rows = []
    previous = np.asarray(scenario.q0, dtype=float)
    for sp in scenario.reference.setpoints:
        key = (round(abs(sp[0]), 12), round(abs(sp[1]), 12), round(sp[2], 12))
        mirror = None
        if key in done:
            mirror, res = done[key]
        else:
            res = region.largest_level(sp, rel_tol=config.region_rel_tol, max_boxes=config.region_max_boxes)
            done[key] = (tuple(sp), res)
        z = np.zeros(15)
        z[[0, 5, 10]] = previous - np.asarray(sp)  # the step's start: errors only, at rest
        ratio = float(z @ region.P @ z) / res.level if res.level > 0 else math.inf
        rows.append(RegionRow(tuple(sp), res, mirror, ratio))
        previous = np.asarray(sp, dtype=float)
    return tuple(rows), region.P


def _equilibria(platform: Platform, ctrl: MicrostepperRegulator) -> tuple[tuple[float, ...], ...]:
    """(gap [mm], i_d per pair [A], open-loop gap pole [1/s], the largest thrust acceleration on x
    and on y within 9 A with the gap held [m/s^2]) over 20-30 mm."""
    model, fl = PlatformModel(platform), MicrostepperTransformation(platform)
    rows = []
    for gap_mm in np.arange(20.0, 30.5, 1.0):
        gap = gap_mm * MM_TO_M
        alloc = fl.allocate(gap, np.zeros(3))
        x = np.zeros(6)
        x[4] = gap
        a, _ = model.jacobian(x, alloc.currents)
        pole = math.sqrt(max(float(np.asarray(a)[5, 4]), 0.0))
        thrust = []
        for axis in (0, 1):
            v = np.zeros(3)
            v[axis] = 1e3  # far beyond reach: the limiter gives what the pair can
            u, _ = ctrl.limiter(gap, v)
            thrust.append(float(np.asarray(model.f(x, u)).ravel()[2 * axis + 1]))
        rows.append((float(gap_mm), float(alloc.currents[1]), pole, *thrust))
    return tuple(rows)


ALLOCATION_REQUESTS = (
    (21.0, (10.0, 0.0, 0.0)),
    (21.0, (0.0, 19.5, 0.0)),
    (25.0, (20.0, 0.0, 0.0)),
    (25.0, (0.0, 10.0, 0.0)),
    (25.0, (15.0, 15.0, 0.0)),
    (25.0, (20.0, 0.0, -5.0)),
    (29.0, (10.0, 0.0, 0.0)),
    (29.0, (0.0, 10.0, 0.0)),
)
"""(gap [mm], accelerations (x, y, gap) [m/s^2]) of the allocation comparison."""


def _allocations(platform: Platform):
    """(gap [mm], v, minimum-norm allocation, maximum-margin allocation) per request."""
    fl = MicrostepperTransformation(platform)
    return tuple(
        (gap_mm, v, fl.allocate(gap_mm * MM_TO_M, v), fl.allocate(gap_mm * MM_TO_M, v, "maximum_margin"))
        for gap_mm, v in ALLOCATION_REQUESTS
    )


# --- the numbers as printed ----------------------------------------------------------------------------
def _s(value: float) -> str:
    return "—" if not math.isfinite(value) else f"{value:.2f}"


def _um(value: float) -> str:
    return "—" if not math.isfinite(value) else f"{value * M_TO_UM:.1f}"


def _mm_tuple(values) -> str:
    return "(" + ", ".join(f"{v * M_TO_MM:g}" for v in values) + ")"


def _dominant_effect(study: MicrostepperStudy, axis: int) -> tuple[str, float]:
    """The effect whose removal lowers the sinusoid's error on ``axis`` most, and the error without it."""
    removed = [(label, m.mean_error[axis]) for label, m in study.breakdown if label.startswith("no ")]
    label, value = min(removed, key=lambda lv: lv[1])
    return label.removeprefix("no "), value


def scorecard_rows(study: MicrostepperStudy) -> list[tuple[str, str, str, str]]:
    """(the paper's claim, the paper's value, ours, verdict): page 1."""
    paper_sp, paper_sin = study.scenarios["setpoints"].paper, study.scenarios["sinusoid"].paper
    sp = study.runs["setpoints"].metrics
    rows = []
    for band, key, words in (
        ("01mm", "settle_0.1mm_s", "below 0.1 mm"),
        ("10um", "settle_10um_s", "to 10 µm"),
    ):
        worst = sp.worst_settling(band)
        limit = float(paper_sp[key])
        ok = bool(np.all(np.isfinite(worst)) and np.all(worst < limit))
        ours = ", ".join(f"{a} {_s(v)} s" for a, v in zip(AXES, worst, strict=True))
        rows.append(
            (
                f"Set-points: error {words}",
                f"< {limit:g} s",
                f"{ours}\n(slowest of {len(sp.steps)} steps per axis)",
                "reproduced" if ok else "not reproduced",
            )
        )
    sin = study.runs["sinusoid"].metrics.mean_error
    heavy = dict(study.breakdown)[HEAVY].mean_error
    keys = ("mean_err_x_mm", "mean_err_y_mm", "mean_err_gap_mm")
    for j, (axis, key) in enumerate(zip(AXES, keys, strict=True)):
        paper = float(paper_sin[key]) * MM_TO_M
        if sin[j] < paper:
            effect, without = _dominant_effect(study, j)
            verdict = f"differs: {paper / sin[j]:.2g}x lower (note 2);\n"
            verdict += f"{effect} sets it ({_um(without)} µm without)"
            if effect == "guide friction":
                ratio = heavy[j] / paper
                verdict += ";\n1 N: " + (
                    "the paper's order" if 0.5 <= ratio <= 2 else f"{ratio:.2g}x the paper's"
                )
        else:
            verdict = "reproduced" if sin[j] < 2 * paper else "differs: higher"
        name = "gap\n(the paper's z)" if axis == "gap" else axis
        rows.append(
            (
                f"Sinusoid: mean |error|, {name}",
                f"{paper * M_TO_UM:.0f} µm",
                f"{_um(sin[j])} µm\n(1 N friction: {_um(heavy[j])} µm)",
                verdict,
            )
        )
    paper_y, paper_x = (float(paper_sin[k]) * 1e3 for k in ("mean_err_y_mm", "mean_err_x_mm"))
    rows.append(
        (
            "Sinusoid: y error below x error",
            f"{paper_y:.0f} < {paper_x:.0f} µm",
            f"{_um(sin[1])} < {_um(sin[0])} µm",
            "reproduced" if sin[1] < sin[0] else "not reproduced",
        )
    )
    aw, no_aw = study.runs["saturation:anti_windup"], study.runs["saturation:no_anti_windup"]
    recovers = aw.result.success and not no_aw.result.success
    rows.append(
        (
            "Anti-windup: the loop recovers\nfrom the 9 A amplifier limit",
            "stated,\nno data",
            f"90 mm step: x, y to 0.1 mm in {_s(np.max(aw.metrics.worst_settling('01mm')[:2]))} s,\n"
            f"overshoot {np.nanmax(aw.metrics.max_overshoot()):.0f} %; without anti-windup\n"
            f"{_outcome(no_aw)}",
            "shown on the twin" if recovers else "not shown",
        )
    )
    return rows


def _outcome(run: Run) -> str:
    """What became of a run, in words."""
    r = run.result
    if r.status == "stopper_hit":
        k = int(np.argmax(r.flags[2] > 0))
        return f"{_stopper_axis(r, k)} hits its stopper at {r.t[k]:.2f} s"
    if r.status == "diverged":
        return "diverges"
    reach = np.nanmax(np.abs(r.x[0:4:2]), axis=1)
    if np.any(reach > STOPPER_POSITION[1]):
        j = int(np.argmax(reach))
        return f"leaves the travel ({AXES[j]} reaches {reach[j]:.2g} m)"
    return "completes"


def _stopper_axis(r: MicrostepperResult, k: int) -> str:
    """Which axis is at a stopper just after sample k."""
    k1 = min(k + 1, r.t.size - 1)
    for j, (lo, hi) in enumerate((STOPPER_POSITION, STOPPER_POSITION, MICROSTEPPER_STOPPER_GAP)):
        if r.x[2 * j, k1] <= lo + 1e-12 or r.x[2 * j, k1] >= hi - 1e-12:
            return AXES[j]
    return "an axis"


STEP_COLUMNS = (
    "step",
    "to (x, y, gap)\n[mm]",
    "0.1 mm\nx [s]",
    "0.1 mm\ny [s]",
    "0.1 mm\ngap [s]",
    "10 µm\nx [s]",
    "10 µm\ny [s]",
    "10 µm\ngap [s]",
    "overshoot\nx [%]",
    "overshoot\ny [%]",
    "overshoot\ngap [%]",
)


def step_rows(m: MicrostepperMetrics, scenario: MicrostepperScenario) -> list[tuple[str, ...]]:
    """Per set-point change: where to, then settling to 0.1 mm and 10 µm and overshoot per axis;
    "—" where the axis does not move and never leaves the band."""

    def settle(size, values) -> list[str]:
        return ["—" if (size[j] == 0 and values[j] == 0) else _s(values[j]) for j in range(3)]

    rows = []
    for k, s in enumerate(m.steps):
        rows.append(
            (
                f"{k + 1} at {s.time:g} s",
                _mm_tuple(scenario.reference.setpoints[k]),
                *settle(s.size, s.settling_01mm),
                *settle(s.size, s.settling_10um),
                *("—" if not math.isfinite(v) else f"{v:.0f}" for v in s.overshoot_pct),
            )
        )
    return rows


SATURATION_COLUMNS = (
    "scenario",
    "controller",
    "outcome",
    "x, y to 0.1 mm\n[s]",
    "overshoot\nx, y [%]",
    "largest |x|, |y|\n[mm]",
    "gap from-to\n[mm]",
    "over 9 A\n[ms]",
)


def saturation_rows(study: MicrostepperStudy) -> list[tuple[str, ...]]:
    """The amplifier limit: the 90 mm step and the paper's set-points, per controller variant."""
    keys = [
        *(f"saturation:{k}" for k in VARIANTS),
        "saturation:no_anti_windup:no_stoppers",
        "setpoints",
        "setpoints:no_anti_windup",
    ]
    rows = []
    for key in keys:
        run = study.runs[key]
        r, m = run.result, run.metrics
        if key.startswith("setpoints"):
            scenario, label = "5 set-points", VARIANTS[key.partition(":")[2] or "anti_windup"]
        else:
            scenario = "90 mm step" + ("\n(no stoppers)" if key.endswith("no_stoppers") else "")
            label = run.label.removesuffix(", no stoppers")
        over = np.nanmax(m.max_overshoot()[:2])
        peak_xy = np.nanmax(np.abs(r.x[0:4:2])) * M_TO_MM
        rows.append(
            (
                scenario,
                label.replace(" (", "\n("),
                _outcome(run).replace(" (", "\n("),
                _s(np.max(m.worst_settling("01mm")[:2])) if r.success else "—",
                "—" if not math.isfinite(over) else (f"{over:.0f}" if over < 1e3 else "> 1000"),
                f"{peak_xy:.1f}" if peak_xy < 1e3 else f"{peak_xy:.2g}",
                f"{np.nanmin(r.x[4]) * M_TO_MM:.1f}-{np.nanmax(r.x[4]) * M_TO_MM:.1f}",
                f"{m.saturated * r.sample_time * 1e3:.0f}",
            )
        )
    return rows


REGION_COLUMNS = (
    "set-point\n(x, y, gap) [mm]",
    "certified\nlevel c",
    "fails at\nlevel",
    "bracket",
    "binding",
    "half-width\nx [mm]",
    "half-width\ny [mm]",
    "half-width\ngap [mm]",
    "step start:\nV / c",
    "computed",
)
BINDING_WORDS = {
    "margin": "R >= 0",
    "headroom_A": "pair A at 9 A",
    "headroom_B": "pair B at 9 A",
    "x": "x travel",
    "y": "y travel",
    "gap": "gap stoppers",
}


def region_rows(study: MicrostepperStudy) -> list[tuple[str, ...]]:
    rows = []
    for row in study.region:
        r = row.result
        bracket = r.refuted_level / r.level - 1 if r.level > 0 else math.inf
        rows.append(
            (
                _mm_tuple(row.setpoint),
                f"{r.level:.4g}",
                f"{r.refuted_level:.4g}",
                f"{bracket * 100:.1f} %",
                BINDING_WORDS.get(r.binding, r.binding),
                *(f"{r.half_widths[a] * M_TO_MM:.2f}" for a in AXES),
                f"{row.start_ratio:.0f}",
                f"as {_mm_tuple(row.mirror)}" if row.mirror else f"{r.timings.get('total', math.nan):.1f} s",
            )
        )
    return rows


# --- figures ---------------------------------------------------------------------------------------------
def _key_figure(study: MicrostepperStudy):
    run = study.runs["setpoints"]
    r, m = run.result, run.metrics
    limits = study.scenarios["setpoints"].paper

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 2, 3, wspace=0.08, hspace=0.12, bottom=0.07, top=0.07)
        top = [fig.add_subplot(gs[0, j]) for j in range(3)]
        low = [fig.add_subplot(gs[1, j]) for j in range(3)]
        for k, s in enumerate(m.steps):
            seg = (r.t >= s.time) & (r.t < s.time + 5.0)
            t = r.t[seg] - s.time
            for j in range(3):
                e = r.measured_error[j, seg]
                worst_from_here = np.maximum.accumulate(np.abs(e)[::-1])[::-1]
                top[j].plot(t, e * M_TO_MM, lw=0.9, color=f"C{k}", label=f"step {k + 1}")
                low[j].plot(t, worst_from_here * M_TO_UM, lw=1.1, color=f"C{k}")
        for j in range(3):
            bands(top[j], M_TO_MM)
            top[j].set_ylim(-0.3, 0.3)
            top[j].set_title(AXES[j], fontsize=9.5)
            top[j].tick_params(labelbottom=False)
            low[j].axhspan(0, BANDS[1] * M_TO_UM, color="0.78", zorder=0)
            low[j].set_ylim(0, 60)
            low[j].set_xlabel("time since the set-point change [s]", fontsize=8)
            for ax in (top[j], low[j]):
                ax.axvline(float(limits["settle_0.1mm_s"]), color="k", ls="--", lw=0.8)
                ax.axvline(float(limits["settle_10um_s"]), color="k", ls=":", lw=0.8)
                ax.set_xlim(0, 5)
                ax.tick_params(labelsize=7.5)
                ax.grid(alpha=0.3)
                if j:
                    ax.tick_params(labelleft=False)
        top[0].set_ylabel("error [mm]", fontsize=8)
        low[0].set_ylabel("largest |error| from\nthen on [µm]", fontsize=8)
        handles, labels = top[0].get_legend_handles_labels()
        fig.legend(
            handles,
            labels,
            loc="lower center",
            ncol=5,
            fontsize=7.5,
            frameon=False,
            bbox_to_anchor=(0.54, rect[1] - 0.006),
        )
        return caption(
            fig,
            rect,
            "Key figure: the error after each set-point change (rig twin)",
            "Top: reading − set-point of the five steps, clipped to ±0.3 mm, the 0.1 mm band shaded. Bottom: "
            "the largest |error| from each time on: a step has settled to 10 µm where its curve enters the "
            "shaded band. Dashed: the paper's 3 s; dotted: its 5 s.",
        )

    return draw


def _setpoint_errors_plot(study: MicrostepperStudy):
    run = study.runs["setpoints"]
    r = run.result

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 3, 1, hspace=0.1, top=0.05, bottom=0.045)
        err = r.measured_error * M_TO_UM
        for j in range(3):
            ax = fig.add_subplot(gs[j, 0])
            ax.plot(*thin(r.t, err[j]), lw=0.6, color="tab:blue")
            bands(ax, M_TO_UM)
            for s in run.metrics.steps:
                ax.axvline(s.time, color="0.5", lw=0.6, ls=":")
            ax.set_ylim(-200, 200)
            ax.set_xlim(0, r.t[-1])
            ax.set_ylabel(f"{AXES[j]} error [µm]")
            ax.grid(alpha=0.3)
            if j < 2:
                ax.tick_params(labelbottom=False)
        ax.set_xlabel("time [s]")
        return caption(
            fig,
            rect,
            "Set-point errors (002 Fig. 16)",
            "Reading − set-point over the whole run, clipped to ±200 µm; dotted: the set-point changes; "
            "shaded: the 0.1 mm and 10 µm bands.",
        )

    return draw


def _setpoint_response_figure(study: MicrostepperStudy) -> Figure:
    r = study.runs["setpoints"].result
    fig = Figure(figsize=PAGE_SIZE, layout="constrained")
    axes = fig.subplots(5, 1, sharex=True)
    for j in range(3):
        axes[j].plot(*thin(r.t, r.x[2 * j] * M_TO_MM), lw=0.9, color="tab:blue", label="position")
        axes[j].plot(r.t, r.reference[3 * j] * M_TO_MM, "k--", lw=0.8, label="set-point")
        axes[j].set_ylabel(f"{AXES[j]} [mm]")
    for j, c in enumerate(("tab:blue", "tab:orange", "tab:green")):
        axes[3].plot(*thin(r.t, r.x[2 * j + 1] * M_TO_MM), lw=0.8, color=c, label=AXES[j])
    axes[3].set_ylabel("velocity [mm/s]")
    for k, (pair, c) in enumerate((("A", "tab:blue"), ("B", "tab:orange"))):
        axes[4].plot(*thin(r.t, np.hypot(r.u[2 * k], r.u[2 * k + 1])), lw=0.8, color=c, label=f"pair {pair}")
    axes[4].axhline(PEAK_CURRENT_LIMIT, color="tab:red", ls=":", lw=0.9, label="9 A limit")
    axes[4].set_ylabel("pair current\nmagnitude [A]")
    axes[4].set_ylim(0, 10)
    axes[4].set_xlabel("time [s]")
    axes[4].set_xlim(0, r.t[-1])
    for k in (0, 3, 4):
        axes[k].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.suptitle(
        "Set-point response on the rig twin (002 Fig. 15): positions, velocities, commanded currents"
    )
    return fig


def _sinusoid_response_figure(study: MicrostepperStudy) -> Figure:
    r = study.runs["sinusoid"].result
    window = 8.0
    show = r.t <= window
    late = r.t >= r.evaluate_from
    fig = Figure(figsize=(PAGE_SIZE[0], 9.5), layout="constrained")
    gs = fig.add_gridspec(4, 2, width_ratios=(1.35, 1))
    for j in range(3):
        ax = fig.add_subplot(gs[j, 0])
        ax.plot(r.t[show], r.x[2 * j, show] * M_TO_MM, lw=1.0, color="tab:blue")
        ax.plot(r.t[show], r.reference[3 * j, show] * M_TO_MM, "k--", lw=0.8)
        ax.set_ylabel(f"{AXES[j]} [mm]")
        ax.tick_params(labelbottom=False)
    ax = fig.add_subplot(gs[3, 0])
    for k, (pair, c) in enumerate((("A", "tab:blue"), ("B", "tab:orange"))):
        ax.plot(r.t[show], r.u[2 * k, show], lw=0.8, color=c, label=f"i_q{pair}")
        ax.plot(r.t[show], r.u[2 * k + 1, show], lw=0.8, color=c, ls="--", label=f"i_d{pair}")
    ax.set_ylabel("currents [A]")
    ax.set_xlabel("time [s]")
    ax.legend(fontsize=7.5, ncol=4, loc="lower left", bbox_to_anchor=(0.0, 1.0), frameon=False)
    for a in fig.axes:
        a.set_xlim(0, window)
        a.grid(alpha=0.3)
    xy = fig.add_subplot(gs[0:2, 1])
    xy.plot(r.reference[0, late] * M_TO_MM, r.reference[3, late] * M_TO_MM, "k--", lw=0.8, label="reference")
    xy.plot(r.x[0, late] * M_TO_MM, r.x[2, late] * M_TO_MM, lw=0.8, color="tab:blue", label="platform")
    xy.set_aspect("equal")
    xy.set(xlabel="x [mm]", ylabel="y [mm]")
    xy.set_title(f"x-y plane, from {r.evaluate_from:g} s", fontsize=9)
    xy.legend(fontsize=7.5, loc="center")
    gz = fig.add_subplot(gs[2:4, 1])
    gz.plot(r.reference[0, late] * M_TO_MM, r.reference[6, late] * M_TO_MM, "k--", lw=0.8)
    gz.plot(r.x[0, late] * M_TO_MM, r.x[4, late] * M_TO_MM, lw=0.8, color="tab:blue")
    gz.set(xlabel="x [mm]", ylabel="gap [mm]")
    gz.set_title(f"gap against x, from {r.evaluate_from:g} s", fontsize=9)
    for a in (xy, gz):
        a.grid(alpha=0.3)
    fig.suptitle(
        "Sinusoids on every axis at ω0 = 1.5π rad/s (002 Fig. 17), rig twin\n"
        "the first 8 s (amplitudes ramped in over 2 s) and the orbit from 8 s on; dashed: the reference",
        fontsize=10,
    )
    return fig


def _sinusoid_errors_plot(study: MicrostepperStudy):
    runs = (("rig twin (0.1 N on x, y)", study.runs["sinusoid"]), (HEAVY, study.runs[f"sinusoid:{HEAVY}"]))

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 3, 2, hspace=0.12, wspace=0.05, top=0.06, bottom=0.045)
        for j in range(3):
            lim = 1.1 * M_TO_UM * max(np.nanmax(np.abs(run.result.measured_error[j])) for _, run in runs)
            for col, (label, run) in enumerate(runs):
                r, m = run.result, run.metrics
                ax = fig.add_subplot(gs[j, col])
                ax.axvspan(0, r.evaluate_from, color="0.93", zorder=0)
                color = "tab:blue" if col == 0 else "tab:green"
                ax.plot(*thin(r.t, r.measured_error[j] * M_TO_UM), lw=0.5, color=color)
                for sign in (1, -1):
                    ax.axhline(sign * m.mean_error[j] * M_TO_UM, color="k", lw=0.8, ls="--")
                ax.set_ylim(-lim, lim)
                ax.set_xlim(0, r.t[-1])
                ax.grid(alpha=0.3)
                ax.text(
                    0.99,
                    0.96,
                    f"mean |e| {_um(m.mean_error[j])} µm",
                    transform=ax.transAxes,
                    ha="right",
                    va="top",
                    fontsize=7.5,
                    bbox=dict(fc="white", ec="none", alpha=0.85),
                )
                if j == 0:
                    ax.set_title(label, fontsize=9)
                if col == 0:
                    ax.set_ylabel(f"{AXES[j]} error [µm]")
                else:
                    ax.tick_params(labelleft=False)
                if j < 2:
                    ax.tick_params(labelbottom=False)
                else:
                    ax.set_xlabel("time [s]")
        return caption(
            fig,
            rect,
            "Sinusoid errors (002 Fig. 18): reading − reference",
            "Grey: the ramp-in and settling, not scored; dashed: ± the mean |error| from 8 s on. Same scale "
            "in each row.",
        )

    return draw


def _saturation_plot(study: MicrostepperStudy):
    runs = [(k, study.runs[f"saturation:{k}"]) for k in VARIANTS]

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 4, 1, hspace=0.1, top=0.055, bottom=0.085)
        axes = [fig.add_subplot(gs[i, 0]) for i in range(4)]
        window = 3.0
        for key, run in runs:
            r = run.result
            show = r.t <= window
            for j in range(3):
                axes[j].plot(
                    r.t[show],
                    r.x[2 * j, show] * M_TO_MM,
                    lw=1.0,
                    color=VARIANT_COLORS[key],
                    label=VARIANTS[key],
                )
            axes[3].plot(
                r.t[show], np.hypot(r.current[0, show], r.current[1, show]), lw=0.9, color=VARIANT_COLORS[key]
            )
        r = runs[0][1].result
        show = r.t <= window
        for j in range(3):
            axes[j].plot(r.t[show], r.reference[3 * j, show] * M_TO_MM, "k--", lw=0.8, label="set-point")
        for j in range(2):
            for lim in STOPPER_POSITION:
                axes[j].axhline(lim * M_TO_MM, color="0.3", lw=1.2, ls="-.")
            axes[j].set_ylim(-70, 70)
        for lim in MICROSTEPPER_STOPPER_GAP:
            axes[2].axhline(lim * M_TO_MM, color="0.3", lw=1.2, ls="-.")
        axes[2].set_ylim(5, 38)
        axes[3].axhline(PEAK_CURRENT_LIMIT, color="tab:red", ls=":", lw=0.9)
        axes[3].set_ylim(0, 10)
        for ax, label in zip(
            axes, ("x [mm]", "y [mm]", "gap [mm]", "pair A current\n(applied) [A]"), strict=True
        ):
            ax.set_ylabel(label)
            ax.set_xlim(0, window)
            ax.grid(alpha=0.3)
        for ax in axes[:3]:
            ax.tick_params(labelbottom=False)
        axes[3].set_xlabel("time [s]")
        handles, labels = axes[0].get_legend_handles_labels()
        fig.legend(
            handles,
            labels,
            loc="lower center",
            ncol=3,
            fontsize=7.5,
            frameon=False,
            bbox_to_anchor=(0.54, rect[1] - 0.006),
        )
        return caption(
            fig,
            rect,
            "The 90 mm step with and without anti-windup and levitation first (the first 3 s)",
            "Dash-dotted: the stoppers (x and y at ±60 mm, the gap at 8 and 35 mm); a run that reaches one "
            "stops there.",
        )

    return draw


def _region_plot(study: MicrostepperStudy):
    P = study.lyapunov_matrix
    idx = {"x": 0, "y": 5, "gap": 10}

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 1, 2, wspace=0.25, top=0.06, bottom=0.06)
        for col, (a, b) in enumerate((("x", "y"), ("x", "gap"))):
            ax = fig.add_subplot(gs[0, col])
            sub = P[np.ix_([idx[a], idx[b]], [idx[a], idx[b]])]
            vals, vecs = np.linalg.eigh(sub)
            angle = math.degrees(math.atan2(vecs[1, 1], vecs[0, 1]))
            k = 0
            for row in study.region:
                if row.mirror is not None:
                    continue
                c = row.result.level
                w, h = (2 * math.sqrt(c / v) * M_TO_MM for v in vals[::-1])
                label = f"set-point {_mm_tuple(row.setpoint)} mm"
                ax.add_patch(
                    Ellipse((0, 0), w, h, angle=angle, fill=False, lw=1.4, color=f"C{k}", label=label)
                )
                k += 1
            ax.set_xlim(-12, 12)
            ax.set_ylim(-12, 12)
            ax.set_aspect("equal")
            ax.axhline(0, color="0.6", lw=0.5)
            ax.axvline(0, color="0.6", lw=0.5)
            ax.set(xlabel=f"{a} error [mm]", ylabel=f"{b} error [mm]")
            ax.grid(alpha=0.3)
        handles, labels = ax.get_legend_handles_labels()
        fig.legend(
            handles,
            labels,
            loc="lower center",
            ncol=3,
            fontsize=7.5,
            frameon=False,
            bbox_to_anchor=(0.54, rect[1] - 0.004),
        )
        return caption(
            fig,
            rect,
            "Certified starts at rest",
            "The certified set {V <= c} cut where every other state is zero: position errors at rest, "
            "internal "
            "models empty.",
        )

    return draw


# --- the report ----------------------------------------------------------------------------------------
def build(out: Path, model: StageModel, config: MicrostepperConfig | None = None) -> ReportContents:
    """Run the study (the full one unless ``config``) and write its report to ``out``."""
    return write_report(out, run_study(model, config))


def write_report(out: Path, study: MicrostepperStudy) -> ReportContents:
    """Write the report of a finished study."""
    t0 = time.perf_counter()
    sp = study.runs["setpoints"]
    with PdfReport(out, TITLE, subtitle="reports/microstepper.pdf from analyses/microstepper.py") as pdf:
        scorecard = Table(
            "",
            ("claim (002 Sec. 8)", "paper", "ours (rig twin)", "verdict"),
            scorecard_rows(study),
            notes=_scorecard_notes(study),
        )
        pdf.add_page(
            "Scorecard: 002 Sec. 8's claims beside ours",
            [scorecard, Plot(_key_figure(study), 0.43)],
            first_page=True,
        )
        pdf.add_page("The model and its assumptions", [Text(_model_text(study))])
        pdf.add_page(
            "Rig twin, scenarios, equilibria",
            [Text(_twin_text(study)), _equilibrium_table(study), _allocation_table(study)],
        )
        pdf.add_page(
            "Set-points, step by step",
            [
                Table("", STEP_COLUMNS, step_rows(sp.metrics, sp.scenario), notes=_step_notes(study)),
                Plot(_setpoint_errors_plot(study), 0.66),
            ],
        )
        pdf.add_figure(_setpoint_response_figure(study))
        pdf.add_figure(_sinusoid_response_figure(study))
        pdf.add_page(
            "Sinusoid: what sets the error",
            [_breakdown_table(study), Plot(_sinusoid_errors_plot(study), 0.58)],
        )
        pdf.add_page(
            "The amplifier limit: anti-windup and levitation first",
            [
                Table("", SATURATION_COLUMNS, saturation_rows(study), notes=_saturation_notes(study)),
                Plot(_saturation_plot(study), 0.55),
            ],
        )
        pdf.add_page(
            "Certified region at the paper's set-points",
            [
                Table("", REGION_COLUMNS, region_rows(study), notes=_region_notes(study)),
                Plot(_region_plot(study), 0.4),
            ],
        )
        study.timings["report"] = time.perf_counter() - t0
        pdf.add_page("Appendix: timings", [_timing_table(study)])
    return pdf.contents


def _scorecard_notes(study: MicrostepperStudy) -> list[str]:
    rig = MicrostepperEffects.rig()
    b = dict(study.breakdown)
    nf, nc, ideal = b["no guide friction"].mean_error, b["no cogging"].mean_error, b["ideal twin"].mean_error
    return [
        f"1. Rig twin: 10 µm encoders, 9 A amplifiers with a {rig.amplifier.bandwidth_hz:g} Hz response, one "
        f"sample of delay at 5 kHz, guide friction ({rig.friction[0].coulomb:g} N on x and y, "
        f"{rig.friction[2].coulomb:g} N on the gap), cogging, stoppers. Error = encoder reading − reference.",
        "2. Ours are lower because the reference runs exactly at the internal models' frequency ω0, which "
        "they "
        f"cancel (ideal twin: {_um(max(ideal))} µm), the twin has no guide misalignment (the paper credits "
        "the "
        "microstepper's precision to better-aligned guides) and its friction is light. Without friction x "
        "and y "
        f"drop to {_um(nf[0])} / {_um(nf[1])} µm, without cogging the gap to {_um(nc[2])} µm; with 1 N of "
        "friction on the x and y guides x and y reach the paper's order.",
        "3. The paper prints neither its set-points nor the sinusoid's amplitudes; ours span the operating "
        "region (page 3). Settling per step and axis: page 4.",
    ]


def _model_text(study: MicrostepperStudy) -> list[str]:
    pf = study.platform
    p, k = pf.params, pf.force_constants()
    taus = MicrostepperRegulator(pf).tracking_time_constants
    assumptions = list(MICROSTEPPER_ASSUMPTIONS)
    return [
        "Platform coordinates q = (x, y, gap) [m]; inputs u = (i_qA, i_dA, i_qB, i_dB) [A], the quadrature "
        "and "
        "direct currents of two pairs of PMLSMs. Pair A's two motors push along x, pair B's along y; all "
        "four "
        "pull the platform towards their stators, closing the one shared gap. Each motor is the 2-DOF "
        "stage's "
        "PMLSM (002 eq. (3)): thrust T = −K1 l1(gap) i_q and normal force N = K2 l2(gap) + K3 l3(gap) i_d + "
        "K4 l4(gap) (i_q² + i_d²), with the 2-DOF rig's lumped constants times the masses they were "
        f"normalised by: K1 = C1 M_h = {k[0]:.4g}, K2 = C2 M_v = {k[1]:.5g}, K3 = C3 M_v = {k[2]:.5g}, "
        f"K4 = C4 M_v = {k[3]:.4g} (N per unit of l_i). So",
        "      x'' = 2 T_A / m_x,        y'' = 2 T_B / m_y,        gap'' = g − 2 (N_A + N_B) / m_gap.",
        "Masses per axis (stacked guides; Table I gives only the 2-DOF's M_v = "
        f"{p.mass_vertical:g} kg and M_h = {p.mass_horizontal:g} kg):  "
        + ",  ".join(f"m_{a} = {m:.3f} kg" for a, m in zip(pf.coordinates, pf.masses, strict=True))
        + ". x moves the platform and the four movers (4 M_h); y adds a guide carriage (M_v − M_h); the gap "
        "another.",
        "Assumptions where the paper is silent:\n" + "\n".join(f" • {a}" for a in assumptions),
        "Controller (002 Sec. 8: the 2-DOF one 'enhanced with an antiwindup mechanism'): on each axis the FL "
        "output regulator of 002 eqs. (21)-(24) with internal models at ω0 = 1.5π rad/s, the printed K_h on "
        "x "
        "and y and K_v on the gap, rates from high-gain observers; the feedback transformation resolves the "
        "four currents by minimum current norm (equal i_d in both pairs).",
        "Anti-windup, in two parts. Levitation first: the controller limits its own currents to 9 A per "
        "pair, "
        "realising the gap's acceleration exactly and cutting only thrust (the gap is the open-loop unstable "
        "axis). Back-calculation in observer form (Åström & Wittenmark's tracking anti-windup): each axis's "
        "internal model and observer are driven by the acceleration actually realised, with a tracking time "
        f"constant equal to the axis's dominant closed-loop one ({taus[0]:.3f} s on x and y, {taus[2]:.3f} s "
        "on the gap). Chosen because it needs no tuning beyond that constant, is exactly inactive below the "
        "limit, and treats the current limit and R < 0 alike.",
    ]


def _twin_text(study: MicrostepperStudy) -> list[str]:
    rig = MicrostepperEffects.rig()
    cog, fx, fz = rig.cogging, rig.friction[0], rig.friction[2]

    def cogging(gap: float) -> str:
        return f"{cog.peak_at_reference * (cog.reference_gap / gap) ** cog.exponent:.2f} N"

    return [
        "Rig twin: the same model (no mismatch between controller and plant) sampled at 5 kHz with a "
        "zero-order hold; 10 µm encoders with 2 µm noise; amplifiers limiting each pair's current magnitude "
        "to "
        f"{rig.amplifier.peak:g} A with a {rig.amplifier.bandwidth_hz:g} Hz first-order response; one sample "
        f"of loop delay; Dahl guide friction {fx.coulomb:g} N + {fx.viscous:g} N s/m on x and y, "
        f"{fz.coulomb:g} N + {fz.viscous:g} N s/m on the gap; cogging of each motor at its own gap and "
        f"position ({cogging(0.020)} at 20 mm, {cogging(0.030)} at 30 mm); stoppers at "
        f"±{STOPPER_POSITION[1] * M_TO_MM:g} mm on x and y, {MICROSTEPPER_STOPPER_GAP[0] * M_TO_MM:g} and "
        f"{MICROSTEPPER_STOPPER_GAP[1] * M_TO_MM:g} mm on the gap.",
        "Scenarios: five set-points 5 s apart from the centre (0, 0, 25) mm to the corners (±40, ±40) mm, "
        "the "
        "gap alternating between 21 and 29 mm, then back to the centre; sinusoids on every axis at ω0 (x = "
        "40 "
        "sin ω0t, y = 40 cos ω0t, gap = 25 + 4 sin(ω0t + π/4) mm, ramped in over 2 s, scored from 8 to 20 "
        "s); "
        "a 90 mm step on x and y at once, (−45, −45, 25) to (45, 45, 25) mm, far into the 9 A limit.",
    ]


def _step_notes(study: MicrostepperStudy) -> list[str]:
    sp = study.runs["setpoints"]
    moves = [np.abs(s.size) * M_TO_MM for s in sp.metrics.steps]
    horizontal = sorted({round(v) for m in moves for v in m[:2] if v > 0})
    vertical = sorted({round(m[2]) for m in moves if m[2] > 0})
    return [
        "Settling: the time after the change until the reading stays within the band; overshoot in % of the "
        "step (steps under 0.5 mm not scored); —: the axis does not move in that step and stays within 10 "
        "µm. "
        f"Horizontal moves of {' and '.join(f'{v} mm' for v in horizontal)} saturate the pairs "
        f"({sp.metrics.saturated * sp.result.sample_time * 1e3:.0f} ms over 9 A in all); the gap moves "
        f"{' or '.join(f'{v}' for v in vertical)} mm.",
    ]


def _equilibrium_table(study: MicrostepperStudy) -> Table:
    rows = [
        (f"{g:.0f}", f"{i_d:.3f}", f"{pole:.1f}", f"{ax:.1f}", f"{ay:.1f}")
        for g, i_d, pole, ax, ay in study.equilibria
    ]
    m = study.platform.masses
    return Table(
        "Equilibrium currents over 20-30 mm (at rest: i_qA = i_qB = 0)",
        (
            "gap [mm]",
            "i_d per pair [A]",
            "open-loop gap pole\n[1/s]",
            "largest x thrust\n[m/s²]",
            "largest y thrust\n[m/s²]",
        ),
        rows,
        notes=[
            f"Each motor carries a quarter of the weight, {m[2] * study.platform.gravity[2] / 4:.2f} N; at "
            "rest "
            "both allocations give these currents. Largest thrust: what a pair gives at 9 A with the gap "
            "held "
            f"(levitation first); y moves {m[1] / m[0]:.2f} times x's mass.",
        ],
    )


def _fits(minimum_norm: float, maximum_margin: float) -> str:
    """Which allocations keep the peak pair current within the amplifiers' limit."""
    if minimum_norm <= PEAK_CURRENT_LIMIT:
        return "both"
    return "max. margin" if maximum_margin <= PEAK_CURRENT_LIMIT else "neither"


def _allocation_table(study: MicrostepperStudy) -> Table:
    def currents(a: Allocation) -> str:
        return "(" + ", ".join(f"{round(c, 2) + 0.0:.2f}" for c in a.currents) + ")"

    rows = [
        (
            f"{gap_mm:g}",
            "(" + ", ".join(f"{a:g}" for a in v) + ")",
            currents(mn),
            f"{mn.peak:.2f}",
            currents(mm),
            f"{mm.peak:.2f}",
            _fits(mn.peak, mm.peak),
        )
        for gap_mm, v, mn, mm in study.allocations
    ]
    return Table(
        "Four currents for three forces: minimum norm against maximum margin",
        (
            "gap\n[mm]",
            "request (x, y, gap)\n[m/s²]",
            "minimum norm\n(i_qA, i_dA, i_qB, i_dB) [A]",
            "peak\n[A]",
            "maximum margin\n(i_qA, i_dA, i_qB, i_dB) [A]",
            "peak\n[A]",
            "within\n9 A",
        ),
        rows,
        notes=[
            "Peak: the larger pair's magnitude sqrt(i_q² + i_d²). Minimum norm (closed form) gives both "
            "pairs the "
            "same i_d; maximum margin (a one-dimensional minimisation) moves the normal load to the pair "
            "that is "
            "not pushing, lowering the peak by a few per cent. The controller uses the closed form, with "
            "levitation-first limiting.",
        ],
    )


def _breakdown_table(study: MicrostepperStudy) -> Table:
    paper = study.scenarios["sinusoid"].paper
    keys = ("mean_err_x_mm", "mean_err_y_mm", "mean_err_gap_mm")
    rows = [("paper (002 Sec. 8)", *(f"{float(paper[k]) * 1e3:.0f}" for k in keys))]
    rows += [(label, *(_um(v) for v in m.mean_error)) for label, m in study.breakdown]
    return Table(
        "Mean |error| from 8 to 20 s with the rig twin changed",
        ("twin", "x [µm]", "y [µm]", "gap [µm]"),
        rows,
        notes=[
            "Guide friction sets the x and y errors, cogging the gap's; the encoder, the amplifiers and the "
            "delay hardly matter. y's guides carry more mass for the same friction: a smaller error, as in "
            "the "
            "paper."
        ],
    )


def _saturation_notes(study: MicrostepperStudy) -> list[str]:
    aw = study.runs["saturation:anti_windup"].metrics
    return [
        "The 90 mm step asks for 42 A and 60 A of thrust current at the start. With anti-windup and "
        "levitation "
        f"first the loop settles (overshoot {aw.max_overshoot()[0]:.0f} % on x) and the gap holds. Without "
        "anti-windup the internal models wind up and the observers integrate the accelerations asked for, "
        "not "
        "those got: the platform overshoots into a stopper; without stoppers it leaves the travel. Without "
        "levitation first the amplifiers scale each saturated pair's current vector: the lost i_d and the "
        "thrust current's own normal force drop the platform to the gap stopper. On the paper's set-points "
        "the "
        "loop without anti-windup hits the stoppers too. Settling is not scored for runs that hit a stopper "
        "(their overshoot is where the stopper held them).",
    ]


def _region_notes(study: MicrostepperStudy) -> list[str]:
    m = study.platform.masses
    return [
        "Procedure 2 adapted to the 3-DOF loop: V = z' P z on the 15 error states (errors, rates, internal "
        "models of the three axes), P from the Lyapunov equation; the largest level c such that {V <= c} "
        "keeps "
        "R >= 0, both pairs within 9 A, x and y within ±60 mm and the gap between 8 and 35 mm. Certified: "
        "every "
        "box of a cover of {V <= c}'s image in (gap error, three accelerations) proved feasible by interval "
        "arithmetic (the natural extension, then its mean-value form on the boxes it leaves open). "
        "'Fails at': a state of that V where the binding constraint fails; c* lies between. "
        "Half-width: the largest error of one axis inside {V <= c}.",
        f"Pair B binds: it drives y, whose mass is {m[1] / m[0]:.2f} times x's, with the same gains. "
        "Mirrored "
        "set-points share one computation (the constraints are even in x and y). 'Step start: V / c': the "
        "paper's steps start far outside the certified set; levitation first and anti-windup carry them. "
        "Assumed: plant = model, continuous time, exact velocities, ideal amplifiers within the limit; the "
        "sampling, observers, encoder, friction and cogging are left to the twin's runs.",
    ]


def _timing_table(study: MicrostepperStudy) -> Table:
    rows = [
        (
            f"{SCENARIO_WORDS[run.scenario.name]}: {run.label}",
            f"{run.build_time:.2f}",
            f"{run.result.timings['total']:.2f}",
        )
        for run in study.runs.values()
    ]
    rows += [
        (f"certified region at {_mm_tuple(row.setpoint)} mm", "", f"{row.result.timings['total']:.2f}")
        for row in study.region
        if row.mirror is None
    ]
    t = study.timings
    rows += [
        ("all simulations (building and running)", "", f"{t['simulations']:.1f}"),
        ("all certificates", "", f"{t['region']:.1f}"),
        ("equilibria and allocations", "", f"{t['equilibria']:.1f}"),
        ("writing the pages before this one", "", f"{t.get('report', math.nan):.1f}"),
        ("total", "", f"{t['total'] + t.get('report', 0.0):.1f}"),
    ]
    backend = {"c": "generated C with a C loop", "vm": "CasADi's virtual machine"}[study.backend]
    return Table(
        "",
        ("what", "build [s]", "run [s]"),
        rows,
        notes=[
            f"Closed loops at 5 kHz as {backend}. Certificates with a bracket target of "
            f"{study.config.region_rel_tol:.0%} and {study.config.region_max_boxes:,} boxes per level.",
        ],
    )


def main(argv: list[str] | None = None) -> int:
    from maglev_oc.analyses import analysis_parser

    from maglev_oc.model.loading import load_model

    parser = analysis_parser(__doc__, REPORT)
    parser.add_argument("--quick", action="store_true", help="coarser certificates (a smoke test)")
    args = parser.parse_args(argv)
    contents = build(args.out, load_model(args.params), QUICK if args.quick else None)
    print(f"wrote {contents.path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
