"""Identification report: the papers' identification and verification results (000 Sec. IV-V,
Tables II/III; 002 Sec. "Model verification") beside ours on a twin whose true constants are
known, then the methods: least squares with uncertainty, NPFSI, the eps study, parabolas,
equilibrium currents and cogging.

    python analyses/identification.py [--out reports/identification.pdf] [--params stage.json]
"""

from __future__ import annotations

import math
import textwrap
import time
from pathlib import Path

import numpy as np

from maglev_oc.identification.eps_trend import EpsTrend, EpsTrendStudy, eps_trend_study
from maglev_oc.identification.equation_error import DEFAULT_BANDWIDTH
from maglev_oc.identification.experiments import FIXED_GAPS, excitation_log, verification_effects
from maglev_oc.identification.layout import CONSTANT_NAMES, GAP_OFFSET
from maglev_oc.identification.npfsi import DEFAULT_Q0_SECONDS, PAPER_EPSILONS, PAPER_GAMMA
from maglev_oc.identification.study import (
    COMMAND_TO_CURRENT_DELAY,
    VERTICAL_GAP,
    IdentificationStudy,
    run_study,
)
from maglev_oc.model.equilibrium import equilibrium_currents
from maglev_oc.model.parameters import PAPER_CONSTANTS
from maglev_oc.model.stage import StageModel
from maglev_oc.regression.data import prepare
from maglev_oc.reporting import identification_plots as plots
from maglev_oc.reporting import validation_plots
from maglev_oc.reporting.pdf import PdfReport, Plot, ReportContents, Table, Text
from maglev_oc.reporting.twins import twin_sentence
from maglev_oc.units import M_TO_MM, M_TO_UM
from maglev_oc.validation import Validation, validate

__all__ = [
    "ORDER",
    "PAPER_COGGING_FORCE",
    "PAPER_EQUILIBRIUM_PCT",
    "PAPER_L1_DISCREPANCY",
    "PREDICTION_BAND",
    "REPORT",
    "SCORECARD_COLUMNS",
    "TARGET_PCT",
    "build",
    "main",
    "scorecard_rows",
    "write_report",
]

REPORT = "identification.pdf"
ORDER = 30
TITLE = "maglev_oc — parameter identification"

PREDICTION_BAND = (15e-3, 25e-3)
"""[m] Gaps over which the papers compare predicted and measured equilibrium currents (5 %)."""
PAPER_L1_DISCREPANCY = (3.8, 10.0)
"""[%] Mean and largest difference between the L1 estimates of NPFSI and of the parabola fits
(002 Sec. "Model verification": "the average error ... is 3.8%, while the maximum error is 10%")."""
PAPER_EQUILIBRIUM_PCT = 5.0
"""[%] Predicted equilibrium currents within this of the measured ones for gaps 15-25 mm (002)."""
PAPER_COGGING_FORCE = 1.0
"""[N] The estimated peak cogging force is "greater than 1 N when the air-gap is smaller than
15 mm, and otherwise negligible" (000 Sec. V-C, Fig. 6)."""
PAPER_COGGING_C2 = PAPER_CONSTANTS["cogging_x3_3t1_2"].C2
"""C2 = 769.99 from the cogging procedure at x3 = 3 t1/2, eps = 0.01 (000 Sec. V-C)."""
TARGET_PCT = {"C1": 1.0, "C2": 1.0, "C3": 1.0, "C4": 10.0}
"""[%] The project's accuracy target for an estimate against the twin's truth (C4 multiplies a
small term and is the weakly determined direction)."""
SCORECARD_COLUMNS = ("claim (000, 002)", "paper", "ours (identification twin)", "verdict")


def build(out: Path, model: StageModel) -> ReportContents:
    """Run the identification study and the eps-trend study on the twin and write the report to
    ``out``."""
    return write_report(out, run_study(model), eps_trend_study(model))


# --- numbers the pages share -----------------------------------------------------------------------------
def _wrap(text: str, width: int) -> str:
    """A table cell broken into lines of at most ``width`` characters (explicit breaks kept)."""
    return "\n".join(line for part in text.split("\n") for line in (textwrap.wrap(part, width) or [""]))


def _pct(value: float, digits: int = 3) -> str:
    """A signed percentage to ``digits`` significant digits, without exponents ("—" if not finite)."""
    if not math.isfinite(value):
        return "—"
    decimals = max(0, digits - 1 - math.floor(math.log10(abs(value)))) if value else digits - 1
    return f"{value:+.{decimals}f} %"


def _error_pct(values, truth, names=CONSTANT_NAMES) -> dict[str, float]:
    """[%] Error of each estimate against the truth."""
    return {k: 100 * (values[k] - truth[k]) / truth[k] for k in names}


def _at_eps(runs, eps: float):
    """The run of an eps study (one per PAPER_EPSILONS) at ``eps``."""
    return runs[PAPER_EPSILONS.index(eps)]


def _at_gap(gaps: np.ndarray, values: np.ndarray, gap: float) -> float:
    """``values`` at the entry of ``gaps`` nearest ``gap`` [m]."""
    return float(values[int(np.argmin(np.abs(np.asarray(gaps) - gap)))])


NBSP = "\u00a0"
"""Joins a constant's name, value and unit so that a table cell never breaks between them."""


def _errors_text(errors: dict[str, float], digits: int = 2) -> str:
    return ", ".join(f"{k}{NBSP}{v:+.{digits}f}{NBSP}%" for k, v in errors.items())


def _meets_target(errors: dict[str, float]) -> bool:
    return all(abs(v) <= TARGET_PCT[k] for k, v in errors.items())


def _changes_text(changes: dict[str, float]) -> str:
    return ", ".join(f"{k}{NBSP}{v:+.{0 if abs(v) >= 1 else 1}f}{NBSP}%" for k, v in changes.items())


def cogging_c2(st: IdentificationStudy) -> tuple[float, float]:
    """C2 from the cogging procedure (x3 = 3 t1/2) and from the Table II run at x3 = 0, eps = 0.01."""
    return st.cogging_npfsi.values["C2"], _at_eps(st.table2, 0.01).values["C2"]


# --- page 1: the scorecard -------------------------------------------------------------------------------
def scorecard_rows(st: IdentificationStudy, trend: EpsTrendStudy) -> list[tuple[str, str, str, str]]:
    """(the papers' claim, their value, ours, verdict) for page 1; every number from ``st`` and
    ``trend``."""
    truth = st.truth_values
    rows = []

    # Table III: NPFSI on the excitation log
    paper3 = PAPER_CONSTANTS["table3_eps0.01"]
    obs = _error_pct(_at_eps(st.npfsi_observer, 0.01).values, truth)
    zero = _error_pct(_at_eps(st.npfsi_zero_phase, 0.01).values, truth)
    rows.append(
        (
            "NPFSI finds C1..C4 (Table III, eps = 0.01)",
            f"{paper3.C1:g}, {paper3.C2:g}, {paper3.C3:g}, {paper3.C4:g}",
            _errors_text(obs) + " off the truth",
            "reproduced"
            if _meets_target(obs)
            else "differs, because the papers' observer velocity lags: with zero-phase velocities all "
            f"within {max(map(abs, zero.values())):.2f} %",
        )
    )

    # Table II: mover locked at x3 = 0
    paper2 = PAPER_CONSTANTS["table2_eps0.01"]
    t2 = _error_pct(_at_eps(st.table2, 0.01).values, truth, ("C2", "C3", "C4"))
    rows.append(
        (
            "NPFSI finds C2..C4, mover locked at x3 = 0 (Table II, eps = 0.01)",
            f"{paper2.C2:g}, {paper2.C3:g}, {paper2.C4:g}",
            _errors_text(t2) + " off the truth",
            "reproduced" if _meets_target(t2) else "differs: the observer's lag again",
        )
    )

    # the trend with eps
    moving = ("C1", "C3", "C4")
    paper, ours, rough = (
        {k: 100 * t.change[k] for k in moving}
        for t in (trend.papers_table3, trend.default_table3, trend.friction_table3)
    )
    same = all(np.sign(paper[k]) == np.sign(ours[k]) for k in moving)
    rows.append(
        (
            "The estimates grow with eps (Tables II, III)",
            "Table III, eps 0.001 → 0.05: " + _changes_text(paper),
            f"{_changes_text(ours)}; with the rig twin's guide friction {_changes_text(rough)}",
            "reproduced"
            if same
            else "differs: the twin's only delayed residual is the observer's lag, which turns the trend "
            "down; "
            + (
                "with guide friction (damping) every constant of both tables moves the papers' way"
                if trend.status == "reproduced"
                else f"with guide friction: {trend.message}"
            )
            + " (page 7)",
        )
    )

    # parabolas against NPFSI
    comp = st.parabola_comparisons[0.01]
    ok = comp.mean_pct <= PAPER_L1_DISCREPANCY[0] and comp.max_pct <= PAPER_L1_DISCREPANCY[1]
    rows.append(
        (
            "Parabolas and NPFSI agree on L1 (gaps 10-27.5 mm)",
            f"{PAPER_L1_DISCREPANCY[0]:g} % mean, {PAPER_L1_DISCREPANCY[1]:g} % max",
            f"{comp.mean_pct:.1f} % mean, {comp.max_pct:.1f} % max (eps = 0.01)",
            f"reproduced; the parabolas are within {_parabola_error_max(st):.2g} % of the truth"
            if ok
            else "differs: larger than the papers'",
        )
    )

    # equilibrium currents
    p0 = st.prediction_x0
    worst_x0 = p0.max_pct(*PREDICTION_BAND)
    rows.append(
        (
            "Eq. (8) predicts equilibrium currents within 5 % over 15-25 mm",
            f"< {PAPER_EQUILIBRIUM_PCT:g} %",
            f"{worst_x0:.1f} % at most (mover at x3 = 0)",
            "reproduced" if worst_x0 < PAPER_EQUILIBRIUM_PCT else "differs: more than 5 %",
        )
    )

    # divergence below 15 mm and the cogging force
    p1 = st.prediction_cogging
    e15, e10 = (1e3 * _at_gap(p1.gap, p1.error, g) for g in (15e-3, 10e-3))
    xi15 = abs(_at_gap(st.cogging_gaps, st.cogging_xi_npfsi, 15e-3))
    true15 = abs(_at_gap(st.cogging_gaps, st.cogging_xi_true, 15e-3))
    cog, ref = cogging_c2(st)
    paper_ref = PAPER_CONSTANTS["table2_eps0.01"].C2
    grows = e10 > 1.5 * e15 > 0 and xi15 > PAPER_COGGING_FORCE
    rows.append(
        (
            "Below 15 mm they diverge: cogging over 1 N (Figs. 5-7)",
            f"diverge below 15 mm; C2 at 3 t1/2 {100 * (PAPER_COGGING_C2 / paper_ref - 1):+.1f} %",
            f"at 3 t1/2: {e15:+.0f} mA at 15 mm, {e10:+.0f} mA at 10 mm; cogging {xi15:.2f} N at 15 mm "
            f"(twin {true15:.2f} N); C2 {100 * (cog / ref - 1):+.1f} %",
            "reproduced at 3 t1/2, where eq. (9)'s cogging peaks; at x3 = 0 it vanishes and nothing diverges"
            if grows
            else "differs: no divergence on the twin",
        )
    )

    # our least squares, with uncertainty
    ee, oe = (_error_pct(f.values, truth) for f in (st.equation_error, st.output_error))
    worst = max(abs(v) for e in (ee, oe) for v in e.values())
    z = max(abs(v) for f in (st.equation_error, st.output_error) for v in f.z_scores(truth).values())
    cov = st.coverage
    inside = int(np.sum(np.abs(cov.z) <= 2.0))
    rows.append(
        (
            "Not in the papers: least squares with standard errors",
            "—",
            f"errors {worst:.2f} % at most, within {z:.1f} standard errors; |z| ≤ 2 for {inside} of "
            f"{cov.z.size} estimates on {cov.z.shape[0]} more runs",
            "meets the target; the uncertainty is honest"
            if _meets_target(ee) and _meets_target(oe)
            else "misses the target",
        )
    )
    widths = (24, 22, 34, 34)
    return [tuple(_wrap(c, w) for c, w in zip(row, widths, strict=True)) for row in rows]


def _parabola_error_max(st: IdentificationStudy) -> float:
    """[%] Largest error of the parabolas' L1 against the truth."""
    true_l1 = st.truth.coefficients(np.array(FIXED_GAPS))[0]
    return float(np.max(np.abs(100 * (np.array([p.L1 for p in st.parabolas]) / true_l1 - 1))))


def _scorecard_notes() -> list[str]:
    return [
        "Ours: on the identification twin, whose true constants (page 2) the estimates are scored against; "
        "target C1-C3 within 1 %, C4 within 10 %. The papers' values are the rig's (its truth unknown).",
    ]


def _cogging_words() -> str:
    words = [w for w in verification_effects().describe() if w.startswith("cogging")]
    return words[0] + " (000 eq. (9): zero at x3 = 0, largest at x3 = 3 t1/2)"


def _key_plot(st: IdentificationStudy, trend: EpsTrendStudy) -> plots.Draw:
    return plots.key_plot(
        st.parabola_comparisons,
        PAPER_L1_DISCREPANCY,
        {"ours, x3 = 0": st.prediction_x0, "ours, x3 = 3 t1/2": st.prediction_cogging},
        PREDICTION_BAND,
        PAPER_EQUILIBRIUM_PCT,
        st.cogging_gaps,
        {"ours (NPFSI, eps = 0.01)": st.cogging_xi_npfsi},
        st.cogging_xi_true,
        PAPER_COGGING_FORCE,
        {
            "paper, Table III": (trend.papers_table3.eps, trend.papers_table3.values[0]),
            "ours": (trend.default_table3.eps, trend.default_table3.values[0]),
            "ours, guide friction": (trend.friction_table3.eps, trend.friction_table3.values[0]),
        },
    )


# --- page 2: the twin and the experiments ----------------------------------------------------------------
def _experiment_rows(st: IdentificationStudy) -> list[tuple[str, str, str]]:
    cov = st.coverage
    return [
        (
            "sum of sines, both axes",
            f"{st.log.duration:.0f} s, papers' PIDs (000 Sec. IV)",
            "least squares C1..C4; NPFSI at three eps (Table III)",
        ),
        (
            "the same, other seeds",
            f"{cov.z.shape[0]} x {cov.duration:g} s",
            "do the standard errors cover the truth?",
        ),
        (
            "vertical sines, mover locked at x3 = 0",
            f"{st.vertical_log.duration:.0f} s about {VERTICAL_GAP * M_TO_MM:g} mm",
            "NPFSI for C2..C4 (Table II)",
        ),
        (
            "the same at x3 = 3 t1/2",
            f"{st.cogging_log.duration:.0f} s",
            "C2 again: the cogging procedure (Fig. 6)",
        ),
        (
            "gap locked, u1 = −0.5 A from rest",
            f"{len(st.parabolas)} gaps {FIXED_GAPS[0] * M_TO_MM:g}-{FIXED_GAPS[-1] * M_TO_MM:g} mm",
            "L1: parabolas against NPFSI (Figs. 3, 4)",
        ),
        (
            "gap held by the vertical PID",
            f"{st.prediction_x0.gap.size} gaps {st.prediction_x0.gap[0] * M_TO_MM:g}-"
            f"{st.prediction_x0.gap[-1] * M_TO_MM:g} mm, at x3 = 0 and 3 t1/2",
            "equilibrium currents against eq. (8) (Figs. 5, 7)",
        ),
    ]


def _constant_rows(st: IdentificationStudy) -> list[tuple[str, str, str, str]]:
    start = st.nominal.constants
    return [
        (k, f"{v:.5g}", f"{getattr(start, k):.5g}", f"{v / getattr(start, k):.3f}")
        for k, v in st.truth_values.items()
    ]


def _method_text(st: IdentificationStudy) -> list[str]:
    ee, eed, oe = st.equation_error, st.equation_error_delayed, st.output_error
    delay_shift = max(abs(100 * (eed.values[k] / ee.values[k] - 1)) for k in CONSTANT_NAMES)
    oe_ratio = {k: float(np.sqrt(v)) for k, v in oe.variance_inflation.items()}
    return [
        "Data. A log holds the encoder readings x1, x3 and the commanded currents at 1 kHz (SPEC 2); "
        "velocities and accelerations are estimated. The least-squares fits use a zero-phase "
        f"Savitzky-Golay differentiator ({DEFAULT_BANDWIDTH:g} Hz band) and pass the model through the same "
        "filter (filtered equation error); a lagging estimate would pair accelerations with regressors "
        "from another instant. NPFSI uses what the papers used, the high-gain observer's velocities, so "
        "that its bias can be set against Tables II/III; the same estimator with zero-phase velocities is "
        f"shown beside it. NPFSI: gamma = {PAPER_GAMMA:g}, Q = A'A (002 sidebar), Q0 = the mean A'A times "
        f"{DEFAULT_Q0_SECONDS * 1e3:g} ms, initial guesses the papers' constants.",
        "Commanded and applied currents. The amplifiers lag the commands by 0.16 ms and each command is "
        f"held 0.2 ms; shifting the logged commands by that {COMMAND_TO_CURRENT_DELAY * 1e3:.2f} ms moves "
        f"the equation-error estimates by at most {delay_shift:.3f} %, less than their standard errors, so "
        "the fits use the logged commands as they are.",
        "Output error. The stage is open-loop unstable (vertical pole 33-64 1/s over 25-10 mm), so a "
        "simulation from one initial state leaves the data within a fraction of a second even with the "
        "true constants (page 4). The fit gives each 50 ms segment its own initial state and joins them by "
        "continuity constraints within 0.2 s windows (constrained Gauss-Newton).",
        "Standard errors. Both fits report the long-run (HAC) covariance of the estimate beside the plain "
        "s²(J'J)⁻¹. The output-error residuals are correlated over the windows and the plain errors are "
        f"{min(oe_ratio.values()):.0f}x (C2..C4) to {max(oe_ratio.values()):.0f}x (C1) too small.",
    ]


# --- least squares ---------------------------------------------------------------------------------------
NLS_COLUMNS = (
    "",
    "truth",
    "initial",
    "equation\nerror",
    "stderr",
    "error",
    "z",
    "output\nerror",
    "stderr",
    "error",
    "z",
)


def nls_rows(st: IdentificationStudy) -> list[list[str]]:
    """C1..C4: truth, initial guess, then estimate, standard error, error and z of each fit."""
    truth = st.truth_values
    rows = []
    for k in CONSTANT_NAMES:
        t = truth[k]
        row = [k, f"{t:.5g}", f"{st.nominal.constants.as_array()[CONSTANT_NAMES.index(k)]:.5g}"]
        for fit in (st.equation_error, st.output_error):
            v, s = fit.values[k], fit.stderr[k]
            row += [f"{v:.6g}", f"{s:.2g}", _pct(100 * (v - t) / t), f"{(v - t) / s:+.2f}"]
        rows.append(row)
    return rows


def _nls_notes(st: IdentificationStudy) -> list[str]:
    ee, oe = st.equation_error, st.output_error
    return [
        "z = (estimate − truth) / stderr, with the long-run standard errors. Equation error: "
        f"{ee.n_samples} samples, residual RMS {ee.residual_rms['vertical']:.3g} / "
        f"{ee.residual_rms['horizontal']:.3g} m/s² (vertical / horizontal). Output error: "
        f"{oe.settings['segments'][0]} segments, residual RMS {oe.residual_rms['vertical'] * M_TO_UM:.2f} / "
        f"{oe.residual_rms['horizontal'] * M_TO_UM:.2f} µm (the 10 µm encoder steps alone give 2.9 µm, "
        "with the 2 µm noise 3.5 µm).",
        f"Correlations of the equation-error estimates: C2-C3 {ee.correlation[1, 2]:+.3f}, C3-C4 "
        f"{ee.correlation[2, 3]:+.3f}, C2-C4 {ee.correlation[1, 3]:+.3f}: C4 is the weakly determined "
        "direction. Fit statistics in the appendix.",
    ]


COVERAGE_COLUMNS = (
    "",
    "RMS error",
    "mean stated\nstderr",
    "std of z\n(long-run)",
    "|z| ≤ 2\n(long-run)",
    "std of z\n(plain)",
    "|z| ≤ 2\n(plain)",
)


def coverage_rows(cov) -> list[list[str]]:
    within2 = cov.fraction_within(2.0)
    within2_naive = np.mean(np.abs(cov.z_naive) <= 2.0, axis=0)
    return [
        [
            k,
            f"{np.sqrt(np.mean(cov.error_pct[:, i] ** 2)):.3g} %",
            f"{np.mean(cov.stderr_pct[:, i]):.3g} %",
            f"{np.std(cov.z[:, i]):.2f}",
            f"{100 * within2[i]:.0f} %",
            f"{np.std(cov.z_naive[:, i]):.2f}",
            f"{100 * within2_naive[i]:.0f} %",
        ]
        for i, k in enumerate(cov.names)
    ]


# --- NPFSI and the eps study -----------------------------------------------------------------------------
def _estimate_cell(value: float, truth: float) -> str:
    return f"{value:.5g} ({100 * (value - truth) / truth:+.2f} %)"


def table3_rows(st: IdentificationStudy) -> list[list[str]]:
    """C1..C4 by eps with observer, then zero-phase velocities; the papers' Table III below."""
    truth = st.truth_values
    rows = []
    for label, runs in (("observer", st.npfsi_observer), ("zero-phase", st.npfsi_zero_phase)):
        rows += [
            [f"{k}, {label}", f"{truth[k]:.5g}", *(_estimate_cell(r.values[k], truth[k]) for r in runs)]
            for k in CONSTANT_NAMES
        ]
    rows += [
        [f"{k}, paper", "", *(f"{getattr(PAPER_CONSTANTS[f'table3_eps{e:g}'], k):g}" for e in PAPER_EPSILONS)]
        for k in CONSTANT_NAMES
    ]
    return rows


def table2_rows(st: IdentificationStudy) -> list[list[str]]:
    """C2..C4 by eps with the mover locked, the equation error beside; the papers' Table II below."""
    truth, ee2 = st.truth_values, st.table2_equation_error
    rows = [
        [
            k,
            f"{truth[k]:.5g}",
            *(_estimate_cell(r.values[k], truth[k]) for r in st.table2),
            _estimate_cell(ee2.values[k], truth[k]),
        ]
        for k in ("C2", "C3", "C4")
    ]
    rows += [
        [
            f"{k}, paper",
            "",
            *(f"{getattr(PAPER_CONSTANTS[f'table2_eps{e:g}'], k):g}" for e in PAPER_EPSILONS),
            "",
        ]
        for k in ("C2", "C3", "C4")
    ]
    return rows


TREND_SOURCES = (
    ("papers", "paper 000"),
    ("default", "twin"),
    ("friction", "twin + guide friction"),
    ("zero_phase", "twin, zero-phase velocities"),
)


def trend_rows(trend: EpsTrendStudy) -> list[list[str]]:
    """Change of each constant from eps = 0.001 to 0.05 by table and source (the direction in
    brackets: flat within the band)."""
    rows = []
    for table, label in (("table3", "Table III"), ("table2", "Table II")):
        for source, words in TREND_SOURCES:
            t: EpsTrend | None = getattr(trend, f"{source}_{table}", None)
            if t is None:
                continue
            d = t.direction(trend.band)
            cells = [
                f"{_pct(100 * t.change[k], 2)} ({d[k]})" if k in t.change else "—" for k in CONSTANT_NAMES
            ]
            rows.append([f"{label}: {words}", *cells])
    return rows


def _trend_note(trend: EpsTrendStudy) -> str:
    fr = trend.friction
    words = "; ".join(
        f"{axis} {f['coulomb_N']:g} N Coulomb + {f['viscous_N_s_per_m']:g} N s/m" for axis, f in fr.items()
    )
    return (
        "Twin: the identification study's runs (observer velocities, as the papers). Twin + guide friction: "
        f"the same runs with the rig twin's guide friction ({words}). Zero-phase: the twin's Table III run "
        "with Savitzky-Golay velocities."
    )


def _trend_plot(trend: EpsTrendStudy) -> plots.Draw:
    series = {
        k: {
            label: (t.eps, t.values[t.names.index(k)])
            for label, t in (
                ("paper, Table III", trend.papers_table3),
                ("twin", trend.default_table3),
                ("twin + guide friction", trend.friction_table3),
                ("twin, zero-phase velocities", trend.zero_phase_table3),
            )
        }
        for k in CONSTANT_NAMES
    }
    return plots.eps_trend_plot(series, "The Table III estimates against eps, relative to eps = 0.01")


# --- verification ----------------------------------------------------------------------------------------
PARABOLA_COLUMNS = (
    "gap\n[mm]",
    "truth",
    "parabola",
    "NPFSI\neps 0.001",
    "NPFSI\neps 0.01",
    "NPFSI\neps 0.05",
)


def parabola_rows(st: IdentificationStudy) -> list[list[str]]:
    """L1 at each fixed gap: truth, parabola, NPFSI at each eps (discrepancy in %)."""
    comps = st.parabola_comparisons
    true_l1 = st.truth.coefficients(np.array(FIXED_GAPS))[0]
    rows = []
    for i, f in enumerate(st.parabolas):
        row = [f"{f.gap * M_TO_MM:g}", f"{true_l1[i]:.4f}", f"{f.L1:.4f} ± {f.L1_stderr:.1g}"]
        row += [f"{comps[e].npfsi[i]:.4f} ({comps[e].discrepancy_pct[i]:.2f} %)" for e in PAPER_EPSILONS]
        rows.append(row)
    rows.append(
        [
            "mean / max",
            "",
            "",
            *(f"{comps[e].mean_pct:.2f} / {comps[e].max_pct:.2f} %" for e in PAPER_EPSILONS),
        ]
    )
    return rows


def _l1_curves(st: IdentificationStudy) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """L1 over 10-27.5 mm of the truth, the equation-error fit and NPFSI at eps = 0.01."""
    gaps = np.linspace(10e-3, 27.5e-3, 60)
    obs001 = _at_eps(st.npfsi_observer, 0.01)
    return {
        "truth (twin)": (gaps, st.truth.coefficients(gaps)[0]),
        "equation error, full model": (gaps, st.equation_error.model(st.nominal).coefficients(gaps)[0]),
        "NPFSI eps = 0.01, full model": (
            gaps,
            st.nominal.with_constants(obs001.constants(st.nominal.constants)).coefficients(gaps)[0],
        ),
    }


EQUILIBRIUM_COLUMNS = (
    "gap\n[mm]",
    "measured\nx3 = 0 [A]",
    "predicted\n[A]",
    "error\n[%]",
    "measured\nx3 = 3 t1/2 [A]",
    "predicted −\nmeasured [mA]",
    "error\n[%]",
    "with cogging\nC2 [mA]",
)


def equilibrium_rows(st: IdentificationStudy) -> list[list[str]]:
    p0, p1, p1c = st.prediction_x0, st.prediction_cogging, st.prediction_cogging_corrected

    def pct(v: float) -> str:
        return "—" if not math.isfinite(v) else f"{v:.2f}"

    return [
        [
            f"{g * M_TO_MM:g}",
            f"{p0.measured[i]:.3f}",
            f"{p0.predicted[i]:.3f}",
            pct(p0.error_pct[i]),
            f"{p1.measured[i]:.3f}",
            f"{1e3 * p1.error[i]:+.0f}",
            pct(p1.error_pct[i]),
            f"{1e3 * p1c.error[i]:+.0f}",
        ]
        for i, g in enumerate(p0.gap)
    ]


def _equilibrium_plot(st: IdentificationStudy) -> plots.Draw:
    p0, p1 = st.prediction_x0, st.prediction_cogging
    cog, _ = cogging_c2(st)
    gaps = np.linspace(10e-3, 25e-3, 61)
    corrected = st.table2_model.with_constants(st.table2_model.constants.replace(C2=cog))
    return plots.equilibrium_plot(
        {"measured, x3 = 0": (p0.gap, p0.measured), "measured, x3 = 3 t1/2": (p1.gap, p1.measured)},
        {
            "eq. (8), constants from the x3 = 0 run": (
                gaps,
                equilibrium_currents(st.table2_model, gaps).current,
            ),
            "eq. (8), C2 from the cogging procedure": (gaps, equilibrium_currents(corrected, gaps).current),
        },
        {
            "x3 = 0": p0,
            "x3 = 3 t1/2": p1,
            "x3 = 3 t1/2, C2 from the cogging procedure": st.prediction_cogging_corrected,
        },
        PREDICTION_BAND,
        PAPER_EQUILIBRIUM_PCT,
    )


def _equilibrium_notes(st: IdentificationStudy) -> list[str]:
    p0, p1, p1c = st.prediction_x0, st.prediction_cogging, st.prediction_cogging_corrected
    cog, _ = cogging_c2(st)
    return [
        "Predicted: eq. (8) of 000 with C2..C4 from NPFSI (eps = 0.01) on the x3 = 0 run, C1 the papers'. "
        "The vertical PID, placed at each gap, holds it 1.5 s; the current is the mean of the last 0.5 s.",
        f"At x3 = 0 the prediction is within {p0.max_pct(*PREDICTION_BAND):.2f} % over 15-25 mm. At 3 t1/2 "
        f"it misses by up to {p1.max_pct(*PREDICTION_BAND):.1f} % there (largest near the zero crossing), "
        "and the error in mA grows as the gap closes; with C2 from the cogging procedure "
        f"({cog:.2f}) the largest error over 15-25 mm is {p1c.max_pct(*PREDICTION_BAND):.1f} %.",
    ]


COGGING_COLUMNS = ("gap [mm]", "procedure, NPFSI [N]", "procedure, equation error [N]", "twin's truth [N]")
COGGING_GAPS = (10e-3, 12.5e-3, 15e-3, 17.5e-3, 20e-3, 25e-3)


def cogging_rows(st: IdentificationStudy) -> list[list[str]]:
    g = st.cogging_gaps
    return [
        [
            f"{gap * M_TO_MM:g}",
            f"{abs(_at_gap(g, st.cogging_xi_npfsi, gap)):.2f}",
            f"{abs(_at_gap(g, st.cogging_xi_equation_error, gap)):.2f}",
            f"{abs(_at_gap(g, st.cogging_xi_true, gap)):.2f}",
        ]
        for gap in COGGING_GAPS
    ]


def _cogging_text(st: IdentificationStudy) -> list[str]:
    cog, ref = cogging_c2(st)
    lo, hi = (float(f(st.cogging_log.x[0])) * M_TO_MM for f in (np.min, np.max))
    paper_ref = PAPER_CONSTANTS["table2_eps0.01"].C2
    return [
        "The procedure (000 Sec. V-C): lock the mover at x3 = 3 t1/2, where eq. (9)'s cogging peaks, "
        "estimate C2 alone with C3, C4 from the x3 = 0 run, and read the peak cogging force as "
        "M_v (C2 at 3 t1/2 − C2 at x3 = 0) λ B². Ours: C2 = "
        f"{cog:.2f} against {ref:.2f} ({100 * (cog / ref - 1):+.2f} %); the papers': {PAPER_COGGING_C2:g} "
        f"against {paper_ref:g} ({100 * (PAPER_COGGING_C2 / paper_ref - 1):+.2f} %). The run covered gaps "
        f"{lo:.1f}-{hi:.1f} mm: there the estimate follows the twin's force; outside, the procedure's "
        "B² shape decays more slowly than the twin's (15 mm / gap)³, so it reads low below 15 mm and high "
        "above 20 mm.",
    ]


# --- appendix --------------------------------------------------------------------------------------------
def fit_statistics_rows(st: IdentificationStudy) -> list[list[str]]:
    """Statistics of both fits (what their text reports hold), one row per quantity."""
    ee, oe = st.equation_error, st.output_error

    def both(fn) -> list[str]:
        return [fn(ee), fn(oe)]

    rows = [
        ["status", *both(lambda f: f"{f.status}, {f.iterations} iterations")],
        ["samples / residuals", *both(lambda f: f"{f.n_samples} / {f.n_residuals}")],
        ["reduced chi-square", *both(lambda f: f"{f.reduced_chi_square:.4g}")],
        [
            "residual RMS, vertical / horizontal",
            f"{ee.residual_rms['vertical']:.3g} / {ee.residual_rms['horizontal']:.3g} m/s²",
            f"{oe.residual_rms['vertical'] * M_TO_UM:.2f} / {oe.residual_rms['horizontal'] * M_TO_UM:.2f} µm",
        ],
        ["long-run covariance: frequencies", *both(lambda f: f"{f.hac_frequencies}")],
    ]
    for k in CONSTANT_NAMES:
        rows.append(
            [
                f"{k}: stderr long-run / plain",
                *both(lambda f, k=k: f"{f.stderr[k]:.3g} / {f.stderr_naive[k]:.3g}"),
            ]
        )
    rows.append(["wall time [s]", *both(lambda f: f"{f.timings['total']:.2f}")])
    return rows


def timing_rows(st: IdentificationStudy, trend: EpsTrendStudy) -> list[list[str]]:
    rows = [[k, f"{v:.2f}"] for k, v in st.timings.items() if k != "report"]
    rows += [[f"eps trend: {k}", f"{v:.2f}"] for k, v in trend.timings.items() if k != "total"]
    if "report" in st.timings:
        rows.append(["report (figures and PDF)", f"{st.timings['report']:.2f}"])
    rows.append(
        [
            "NPFSI on the 60 s log, per eps (observer velocities)",
            " / ".join(f"{r.timings['total']:.2f}" for r in st.npfsi_observer),
        ]
    )
    return rows


# --- the report ------------------------------------------------------------------------------------------
HELD_OUT_SEED, HELD_OUT_DURATION = 101, 20.0
"""The validation's held-out run: the same excitation with other phases and noise, 20 s [s]."""


def validation_runs(st: IdentificationStudy) -> dict[str, Validation]:
    """The output-error fit and the papers' constants (the estimators' start) validated on a held-out
    run of the same experiment (:mod:`maglev_oc.validation`)."""
    log = excitation_log(
        st.truth, duration=HELD_OUT_DURATION, seed=HELD_OUT_SEED, controller_model=st.nominal
    )
    data = prepare([log], bandwidth=DEFAULT_BANDWIDTH)
    where = f"held-out run, seed {HELD_OUT_SEED}, {HELD_OUT_DURATION:g} s"
    oe = st.output_error
    return {
        "output-error fit": validate(
            data,
            data.valid,
            oe.model(st.nominal),
            description="output-error fit",
            data_description=where,
            gap_offset=oe.values.get(GAP_OFFSET, 0.0),
        ),
        "papers' constants": validate(
            data, data.valid, st.nominal, description="Table III (eps = 0.01)", data_description=where
        ),
    }


def write_report(
    out: Path, st: IdentificationStudy, trend: EpsTrendStudy, validations: dict[str, Validation] | None = None
) -> ReportContents:
    """Write the report of a finished identification study and eps-trend study (nothing is computed
    here but the figures' curves, and the validation on a held-out run unless ``validations`` are
    given: :func:`validation_runs`)."""
    t0 = time.perf_counter()
    truth = st.truth_values
    validations = validation_runs(st) if validations is None else validations
    with PdfReport(out, TITLE, subtitle="reports/identification.pdf from analyses/identification.py") as pdf:
        pdf.add_page(
            "Scorecard: the papers' identification results beside ours",
            [
                Table(
                    "", SCORECARD_COLUMNS, scorecard_rows(st, trend), notes=_scorecard_notes(), font_size=7.5
                ),
                Plot(_key_plot(st, trend), 0.44),
            ],
            first_page=True,
        )
        pdf.add_page(
            "The twin, the experiments and the methods",
            [
                Text(
                    [
                        twin_sentence("identification twin"),
                        "The verification runs add " + _cogging_words() + ".",
                    ]
                ),
                Table("", ("experiment", "length", "what it gives"), _experiment_rows(st)),
                Table(
                    "The twin's true constants and the estimators' starting point",
                    ("", "truth", "start: the papers' (Table III, eps = 0.01)", "truth / start"),
                    _constant_rows(st),
                ),
                Text(_method_text(st)),
            ],
        )
        pdf.add_page(
            "Least squares: C1..C4 with their uncertainty",
            [
                Table("", NLS_COLUMNS, nls_rows(st), notes=_nls_notes(st), font_size=7.5),
                Plot(plots.residuals_plot((st.equation_error, st.output_error), st.log), 0.5),
            ],
        )
        cov = st.coverage
        pdf.add_page(
            "Multiple shooting, and standard errors that cover the truth",
            [
                Plot(plots.shooting_plot(st.log, st.open_loop, st.output_error), 0.3),
                Table(
                    f"Equation error on {cov.z.shape[0]} further runs of {cov.duration:g} s (other seeds)",
                    COVERAGE_COLUMNS,
                    coverage_rows(cov),
                    notes=[
                        "z = (estimate − truth) / stderr. Honest standard errors give std(z) near 1 and "
                        "|z| ≤ 2 in about 95 % of runs; a long-run covariance from a few frequencies (8-10 "
                        "degrees of freedom) gives std(z) near 1.1.",
                    ],
                ),
                Plot(plots.coverage_plot(cov.names, cov.z, cov.z_naive), 0.3),
            ],
        )
        pdf.add_page(
            "Validation on a held-out run: residual whiteness and fit",
            [
                Text(validation_plots.verdict_rows(validations), font_size=8.0),
                *validation_plots.page_blocks(validations),
            ],
        )
        bands = {"C1": 10, "C2": 2, "C3": 5, "C4": 25}
        pdf.add_page(
            "NPFSI on the 60 s log (Table III)",
            [
                Plot(
                    plots.npfsi_plot(
                        {
                            "observer velocities (as the papers)": st.npfsi_observer,
                            "zero-phase velocities": st.npfsi_zero_phase,
                        },
                        truth,
                        bands,
                        "Estimates along the log at each eps",
                        "The papers' high-gain observer lags the positions by about 2 ms; the zero-phase "
                        "(Savitzky-Golay) velocities do not.",
                    ),
                    0.5,
                ),
                Table(
                    "",
                    ("", "truth", "eps = 0.001", "eps = 0.01", "eps = 0.05"),
                    table3_rows(st),
                    notes=[
                        "Estimate (error against the truth). The papers' rows are the rig's: their truth is "
                        "unknown."
                    ],
                    font_size=7.5,
                ),
            ],
        )
        pdf.add_page(
            "NPFSI with the mover locked at x3 = 0 (Table II)",
            [
                Plot(
                    plots.npfsi_plot(
                        {"observer velocities": st.table2},
                        truth,
                        bands,
                        "Estimates along the vertical run at each eps",
                    ),
                    0.4,
                ),
                Table(
                    "",
                    ("", "truth", "eps = 0.001", "eps = 0.01", "eps = 0.05", "equation error"),
                    table2_rows(st),
                    notes=[
                        f"Vertical sum of sines about {VERTICAL_GAP * M_TO_MM:g} mm, "
                        f"{st.vertical_log.duration:.0f} s, C1 held at the papers' value; NPFSI with "
                        "observer velocities, the equation error on the same log beside it."
                    ],
                    font_size=7.5,
                ),
            ],
        )
        pdf.add_page(
            "The trend with eps (Tables II and III)",
            [
                Table(
                    f"Change from eps = 0.001 to 0.05 (direction; flat: within {100 * trend.band:g} %)",
                    ("", *CONSTANT_NAMES),
                    trend_rows(trend),
                    notes=[_trend_note(trend)],
                ),
                Text([trend.explanation]),
                Plot(_trend_plot(trend), 0.26),
            ],
        )
        pdf.add_page(
            "Horizontal dynamics: L1 from parabolas and from NPFSI (000 Sec. V-A)",
            [
                Plot(plots.parabola_plot(st.parabolas), 0.28),
                Plot(plots.l1_plot(st.parabola_comparisons, _l1_curves(st), PAPER_L1_DISCREPANCY), 0.3),
                Table(
                    "L1 at the fixed gaps [m/(s² A)]: estimate (|NPFSI − parabola| / parabola)",
                    PARABOLA_COLUMNS,
                    parabola_rows(st),
                    notes=[
                        "Runs of 0.18-0.30 s (180-300 samples). NPFSI on x4' = −L1 u1 with observer "
                        f"velocities from the papers' L1. The papers: {PAPER_L1_DISCREPANCY[0]:g} % mean, "
                        f"{PAPER_L1_DISCREPANCY[1]:g} % max. The parabolas are within "
                        f"{_parabola_error_max(st):.2g} % of the truth; NPFSI's discrepancy is the "
                        "observer's velocity bias and, at eps = 0.05, a transient that a 0.2-0.3 s run "
                        "cannot outlast."
                    ],
                    font_size=7.5,
                ),
            ],
        )
        pdf.add_page(
            "Vertical dynamics: equilibrium currents (000 Sec. V-B)",
            [
                Plot(_equilibrium_plot(st), 0.36),
                Table(
                    "", EQUILIBRIUM_COLUMNS, equilibrium_rows(st), notes=_equilibrium_notes(st), font_size=7.5
                ),
            ],
        )
        gap_range = (float(st.cogging_log.x[0].min()), float(st.cogging_log.x[0].max()))
        cog, ref = cogging_c2(st)
        c = verification_effects().cogging
        pdf.add_page(
            "Cogging (000 Sec. V-C)",
            [
                Text(_cogging_text(st)),
                Plot(
                    plots.cogging_plot(
                        st.cogging_gaps,
                        {
                            f"NPFSI, eps = 0.01 (C2 {cog:.2f} against {ref:.2f})": st.cogging_xi_npfsi,
                            "equation error, same procedure": st.cogging_xi_equation_error,
                        },
                        st.cogging_xi_true,
                        f"twin: {c.peak_at_reference:g} N (15 mm / gap)^{c.exponent:g}",
                        gap_range,
                        PAPER_COGGING_FORCE,
                    ),
                    0.36,
                ),
                Table("Peak cogging force at some gaps", COGGING_COLUMNS, cogging_rows(st)),
            ],
        )
        st.timings["report"] = time.perf_counter() - t0
        pdf.add_page(
            "Appendix: fit statistics and wall times",
            [
                Table(
                    "Both least-squares fits on the 60 s log",
                    ("", "equation error", "output error"),
                    fit_statistics_rows(st),
                ),
                Table("Wall times [s] (2-core machine)", ("step", "wall time [s]"), timing_rows(st, trend)),
            ],
        )
    return pdf.contents


def main(argv: list[str] | None = None) -> int:
    from maglev_oc.analyses import analysis_parser

    from maglev_oc.model.loading import load_model

    parser = analysis_parser(__doc__, REPORT)
    args = parser.parse_args(argv)
    print(f"wrote {build(args.out, load_model(args.params)).path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
