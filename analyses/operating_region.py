"""Operating-region report: where the FL regulator's feedback transformation stays defined and the
currents fit the amplifiers. Page 1 is the scorecard (the feasible set, the certified Procedure 2,
the basins of the FL and linear regulators, the papers' large step) with its key figure; the method,
the feasible set, the certificates and their Monte Carlo checks, the certificates on sampled plants
whose constants differ from the controller's, the basins and the large step follow; timings are in
the appendix.

    python analyses/operating_region.py [--out reports/operating_region.pdf] [--params stage.json] [--quick]
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from maglev_oc.control.linear_regulator import axis_linearizations
from maglev_oc.model.stage import StageModel
from maglev_oc.model.stagefile import stage_covariance
from maglev_oc.region.study import (
    BASIN_OUTCOMES,
    OperatingRegionStudy,
    ReferenceStudy,
    RobustStudy,
    StudyConfig,
    certificate_rows,
    operating_region_study,
)
from maglev_oc.reporting import region_plots as plots
from maglev_oc.reporting.pdf import (
    PdfReport,
    Plot,
    ReportContents,
    Table,
    Text,
    block_height,
    page_room,
    wrap_cells,
)
from maglev_oc.reporting.twins import twin_sentence
from maglev_oc.sim.effects import Encoder, TwinEffects
from maglev_oc.units import M_TO_MM

__all__ = ["FL", "LINEAR", "ORDER", "QUICK", "REPORT", "build", "main", "scorecard_rows", "write_report"]

REPORT = "operating_region.pdf"
TITLE = "maglev_oc — operating region of the FL regulator"
ORDER = 60
FL, LINEAR = "FL regulator", "linear regulator"
"""The two controllers the papers compare (their names in the study)."""
PAPER_RANGE = (0.015, 0.025)
"""[m] The gaps the papers' set-point steps span (001 Sec. VI-A, 002 Sec. 7.1)."""

QUICK = StudyConfig(
    setpoints_mm=(15.0, 20.0, 25.0),
    samples=60,
    slice_setpoints_mm=(20.0,),
    slice_points=15,
    map_starts_mm=(12.0, 18.0, 26.0),
    map_targets_mm=(10.0, 14.0, 18.0),
    quantization_samples=60,
    map_points=41,
    robust_runs=20,
    robust_probe_runs=8,
    certify_boxes=60_000,
    certify_ladder=(1.0,),
    certify_runs=50,
)
"""A small configuration for smoke tests (coarse figures, few runs)."""


def build(
    out: Path,
    model: StageModel,
    config: StudyConfig | None = None,
    *,
    params: Path | None = None,
    covariance=None,
    covariance_source: str = "",
) -> ReportContents:
    """Run the operating-region study (the full one unless ``config``) and write its report.
    ``covariance`` (4, 4) of the model's C1..C4 for the robust page: given, else the one of the
    stage file ``params`` (the file ``model`` was read from), else an assumed one."""
    if covariance is None:
        covariance, covariance_source = stage_covariance(params)
    study = operating_region_study(
        model, config or StudyConfig(), covariance=covariance, covariance_source=covariance_source
    )
    return write_report(out, study, model)


# --- the numbers as printed -------------------------------------------------------------------------------
def _mm(x: float, digits: int = 3) -> str:
    return f"{x * M_TO_MM:.{digits}g}"


def _setpoints(st: OperatingRegionStudy) -> list[ReferenceStudy]:
    return [r for r in st.references if r.reference.is_setpoint]


def _middle(st: OperatingRegionStudy) -> ReferenceStudy:
    """The set-point study nearest 20 mm."""
    return min(_setpoints(st), key=lambda r: abs(r.reference.gap - 0.02))


def _name(rs: ReferenceStudy) -> str:
    return f"{_mm(rs.reference.gap, 4)} mm" if rs.reference.is_setpoint else "ellipse"


def _certs(rs: ReferenceStudy) -> dict[str, tuple[np.ndarray, float]]:
    """(P, level) of a reference's certified sets: the Lyapunov equation's and, if certified, the SDP's."""
    certs = {"Lyapunov P": (rs.lyapunov.P, rs.lyapunov.level)}
    if rs.sdp is not None and rs.sdp.certified is not None:
        certs["SDP P"] = (rs.best.P, rs.best.level)
    return certs


def _share(d, key: str = "success") -> float:
    return 100.0 * float(np.mean(d[key]))


def _paper_range_steps(st: OperatingRegionStudy) -> tuple[int, int]:
    """(FL runs that stay in F and settle, runs) over the map's pairs with start and target gap in
    the papers' 15-25 mm."""
    ls = st.large_step
    s_in = (ls.map_starts >= PAPER_RANGE[0] - 1e-9) & (ls.map_starts <= PAPER_RANGE[1] + 1e-9)
    t_in = (ls.sweep_targets >= PAPER_RANGE[0] - 1e-9) & (ls.sweep_targets <= PAPER_RANGE[1] + 1e-9)
    ok = ls.maps[FL]["success"][np.ix_(t_in, s_in)]
    return int(ok.sum()), int(ok.size)


def _edge_distance(st: OperatingRegionStudy, name: str) -> float:
    """[m] From the papers' 18 mm target down to the highest target that fails from 26 mm (inf if none)."""
    ls = st.large_step
    d = ls.sweep[name]
    bad = ls.sweep_targets[~d["success"] & (ls.sweep_targets < ls.reference.gap)]
    return float(ls.reference.gap - bad.max()) if bad.size else math.inf


def _reach(st: OperatingRegionStudy) -> float:
    """How far (in multiples of its initial error) an SDP aimed at the large step certifies it."""
    ls = st.large_step
    return ls.fl_direction.best.reach if ls.fl_direction is not None and ls.fl_direction.best else math.nan


def _stopper_agreement(st: OperatingRegionStudy) -> tuple[int, int, int]:
    """(FL stopper hits the linear error dynamics predict, FL stopper hits, pairs where prediction and
    simulation disagree)."""
    ls = st.large_step
    hit = ls.maps[FL]["outcome"] == BASIN_OUTCOMES.index("stopper")
    return int(np.sum(hit & ls.predicted_stopper)), int(hit.sum()), int(np.sum(hit != ls.predicted_stopper))


def scorecard_rows(st: OperatingRegionStudy) -> list[tuple[str, str, str, str]]:
    """(the papers' claim, their value, ours, verdict): page 1."""
    f = st.feasible
    limit = f.current_limit
    i0, g0 = st.r_zero_current
    lo, hi = f.gap_range or (math.nan, math.nan)
    binds = limit is not None and i0 > limit
    rows = [
        (
            "The transformation exists where\nR >= 0 (the set A; 001 Sec. V,\n002 Sec. 6)",
            "A = {R >= 0},\nno current limit",
            f"on R = 0, |u| >= {i0:.1f} A over\n{_mm(lo)}-{_mm(hi)} mm (least at {_mm(g0)} mm)",
            f"differs, because the {limit:g} A\namplifiers bind first: the\nregion is F, inside A (note 1)"
            if binds
            else "reproduced: R >= 0 binds",
        )
    ]
    sps = _setpoints(st)
    certified = [r for r in st.references if r.lyapunov.success]
    tight = min(r.lyapunov.tightness for r in certified) if certified else math.nan
    sin = " and the ellipse" if any(not r.reference.is_setpoint for r in certified) else ""
    rows.append(
        (
            "Procedure 2 must be adapted to\nestimate the range of operation\n(001 Sec. V, 002 Sec. 6)",
            "left undone\n('beyond the scope')",
            f"certified at {sum(r.reference.is_setpoint for r in certified)} set-points, "
            f"{_mm(sps[0].reference.gap)}-{_mm(sps[-1].reference.gap)} mm,\n"
            f"{sin.strip()}; levels within {1 - tight:.1%} of the\nleast infeasible V found",
            "new here" if len(certified) == len(st.references) else "not certified everywhere",
        )
    )
    mid = _middle(st)
    a1, a2 = mid.best.initial_conditions.rectangle
    b1, b2 = mid.lyapunov.initial_conditions.rectangle
    tot = st.inside_totals()
    rows.append(
        (
            f"Certified starts at rest around\nthe {_mm(mid.reference.gap)} mm set-point",
            "—",
            f"gap ±{_mm(a1)} mm with position ±{_mm(a2)} mm\n(SDP; Lyapunov ±{_mm(b1)} / ±{_mm(b2)} mm)",
            f"new; {tot['runs']} runs inside\nthe certified sets, {tot['violations']} left F",
        )
    )
    if st.robust is not None:
        rows.append(_robust_scorecard_row(st.robust))
    if st.large_step is None:
        return rows
    ls = st.large_step
    ok, n = _paper_range_steps(st)
    rows.append(
        (
            "The FL regulator works over the\nrange of interest, gaps 15-25 mm\n(002 Sec. 6, 7.1)",
            "shown on the rig",
            f"ideal twin: {ok} of {n} steps between\n15 and 25 mm stay in F and settle",
            "reproduced (sampled,\nnot certified)" if ok == n else "differs",
        )
    )
    reach = _reach(st)
    run = ls.fl_run
    fl_ok = reach >= 1 and run is not None and run.violations == 0
    rows.append(
        (
            "The FL regulator settles the\nlarge step 26 → 18 mm, 0 → 20 mm\n(001 Fig. 9, 002 Fig. 12)",
            "settles",
            f"certified: an SDP aimed at the start\ncovers {reach:.2f} times its error; ideal\n"
            f"twin: stays in F, |u| <= {run.max_current:.1f} A",
            "reproduced, and certified" if fl_ok else "differs",
        )
    )
    lin = next(x for x in ls.linear if x.controller == LINEAR)
    d = ls.sweep[LINEAR]
    k = int(np.argmin(np.abs(ls.sweep_targets - ls.reference.gap)))
    edge = _edge_distance(st, LINEAR)
    survives = bool(d["success"][k])
    rows.append(
        (
            "The linear regulator goes\nunstable on that step",
            "unstable; shut\ndown at 5.5 s",
            f"ideal twin: converges, least gap\n{_mm(d['min_gap'][k])} mm; its certified region is\n"
            f"{lin.large_step_ratio:,.0f} times too small to decide",
            f"differs: on the nominal model the\nstep is inside its basin, {_mm(edge, 2)} mm\n"
            "from the edge (note 2)"
            if survives
            else "reproduced on the ideal twin",
        )
    )
    fl, li = ls.maps[FL], ls.maps[LINEAR]
    overshoot = -ls.fl_step_range[0, 0]
    predicted, hits, _ = _stopper_agreement(st)
    rows.append(
        (
            "The FL regulator's range exceeds\nthe linear regulator's (001, 002:\nthe linear one fails "
            "that step)",
            "implied",
            f"start x target pairs that converge:\nFL {_share(fl):.0f} %, linear {_share(li):.0f} %; "
            f"within\n9 A: FL {_share(fl, 'within_limit'):.0f} %, linear {_share(li, 'within_limit'):.0f} %",
            f"differs, because both end where\nthe step's overshoot ({overshoot:.0%}) meets\na stopper: "
            f"{predicted} of the FL's {hits}\nstopper hits predicted (note 3)",
        )
    )
    return rows


def _robust_scorecard_row(rb: RobustStudy) -> tuple[str, str, str, str]:
    """The certified sets on plants whose constants differ from the controller's (sampled)."""
    level = "0.95" if "0.95" in rb.plant_sets() else rb.plant_sets()[-2]
    tot = rb.totals(level)
    n_sp = len(rb.certificates)
    whose = "an ASSUMED" if rb.assumed else "the stage file's"
    first = _first_broken(rb)
    verdict = "new; sampled, not certified"
    if first is not None:
        bracket = f"{_sigma(first.safe_radius)}-{_sigma(first.broken_radius)} σ"
        verdict += f"; first runs leave F at {bracket} ({first.reference})"
    return (
        "The certified sets hold on plants whose C1..C4 differ (the rig is not the model)",
        "not addressed",
        f"plants in the {level} set of {whose} covariance: {tot['violations']} of {tot['runs']} runs "
        f"from the sets at {n_sp} set-points left F",
        verdict,
    )


def _scorecard_notes(st: OperatingRegionStudy) -> list[str]:
    f = st.feasible
    i0, _ = st.r_zero_current
    notes = [
        f"1. F: R >= 0, |u| <= {f.current_limit:g} A and the stoppers (gap {_mm(f.gap_range[0])}-"
        f"{_mm(f.gap_range[1])} mm, position ±{_mm(f.position_range[1])} mm). On R = 0 the transformation "
        f"commands i_d = −L3/(2 L4), at least {i0:.1f} A, so the current limit is met before R = 0 anywhere.",
    ]
    if st.large_step is None:
        return notes
    ls = st.large_step
    fl, li = ls.outcomes(FL), ls.outcomes(LINEAR)
    _, _, disagree = _stopper_agreement(st)
    notes += [
        "2. The papers' step overshoots below 15 mm, where 000 found the model to stop predicting the rig "
        "(cogging above 1 N); the ideal twin has no cogging, friction, amplifier lag or sampling noise. "
        "The last section gives the frozen-gain analysis.",
        f"3. Both controllers place the same poles (the linear one at the target's linearization), so both "
        f"overshoot a gap step by about {-ls.fl_step_range[0, 0]:.0%} of its size; the FL loop's error "
        f"dynamics are exactly linear, and a step from rest predicts its stopper hits pair for pair "
        f"({disagree} disagree). Of the FL's failures, {fl['stopper']} are stopper hits, "
        f"{fl['over the current limit']} exceed 9 A and {fl['R < 0']} meet R < 0. The linear regulator "
        f"fails on {li['stopper']} pairs by the stoppers and converges on "
        f"{li['over the current limit']} more only by commanding over 9 A, which the rig's amplifiers "
        "would not give.",
    ]
    return notes


ROBUST_TABLE = "Per set-point: runs that left F / runs, and the share that stayed in F"
KEY_FIGURE_HEIGHT = 0.36
"""[page fraction] The key figure's height under the scorecard when the page has room."""
SCORECARD_WIDTHS = (30, 19, 36, 32)
"""Characters per line of the scorecard's columns (claim, papers, ours, verdict): narrow enough
for the table to print at a readable size."""


def _fit(rows, widths=SCORECARD_WIDTHS) -> list[tuple[str, ...]]:
    """Each cell re-wrapped to its column's width."""
    return wrap_cells(rows, widths)


# --- the report -------------------------------------------------------------------------------------------
def write_report(out: Path, st: OperatingRegionStudy, model: StageModel) -> ReportContents:
    """Write the report of a finished study (``model``: the one it was run on)."""
    t0 = time.perf_counter()
    with PdfReport(
        out, TITLE, subtitle="reports/operating_region.pdf from analyses/operating_region.py"
    ) as pdf:
        first = [
            Table(
                "",
                ("claim (source)", "papers", "ours", "verdict"),
                _fit(scorecard_rows(st)),
                _scorecard_notes(st),
            )
        ]
        if st.large_step is not None:
            # the key figure takes what the scorecard leaves, up to its designed 0.36 of the page
            room = page_room(first_page=True) - block_height(first[0]) - 0.01
            first.append(Plot(_key_figure(st), min(KEY_FIGURE_HEIGHT, room)))
        pdf.add_page("Scorecard: the papers' operating region beside ours", first, first_page=True)
        pdf.add_page("How the region is found", [Text(_method(st)), _parts_table(st)])
        _feasible_page(pdf, st)
        _certificate_page(pdf, st)
        _montecarlo_page(pdf, st)
        _slices_page(pdf, st)
        if st.robust is not None:
            _robust_page(pdf, st, model)
            if st.robust.certified is not None:
                _certified_robust_page(pdf, st)
        if st.large_step is not None:
            _basins_page(pdf, st)
            _large_step_pages(pdf, st, model)
        timings = {**st.timings, "writing the report (before this page)": time.perf_counter() - t0}
        pdf.add_page(
            "Appendix: compute times and each constraint's bounds",
            [_timing_table(st, timings), Text(_runs_text(st)), _levels_table(st)],
        )
    return pdf.contents


def _key_figure(st: OperatingRegionStudy):
    ls = st.large_step
    n = ls.map_starts.size * ls.sweep_targets.size
    return plots.basin_maps_plot(
        ls,
        [FL, LINEAR],
        "Key figure: where each start x target step ends, FL and linear regulator",
        f"{n} steps from rest at a start gap (position 0) to a target gap (position "
        f"{_mm(ls.target_position, 2)} mm), each simulated for {st.config.linear_horizon:g} s on the sampled "
        "ideal twin. Dashed: where the FL loop's linear error dynamics reach a stopper.",
    )


def _method(st: OperatingRegionStudy) -> list[str]:
    f = st.feasible
    encoder = "; ".join(TwinEffects(encoder=Encoder()).describe())
    return [
        "The question (001 Sec. V, 002 Sec. 6). The feedback transformation exists only where R(x1, v1, v2) "
        "≥ 0, and the amplifiers deliver |u| = sqrt(i_q² + i_d²) ≤ 9 A. Which initial conditions keep the "
        "loop feasible for all time? The papers left Procedure 2 of Maggiore & Becerril (2004) unadapted to "
        "their output regulator and showed the range on the rig instead; this report adapts and certifies "
        "it.",
        f"The feasible set F: {f.label}, position within ±{_mm(f.position_range[1])} mm (the stoppers).",
        "Adapted Procedure 2. While the loop is in F it is linear in the error coordinates z (the errors, "
        "their rates and the internal models' states, minus the reference's steady state): z' = A_cl z. "
        "With V = z' P z and A_cl' P + P A_cl ≤ 0, a level set {V ≤ c} that lies in F for every phase of "
        "the reference is invariant: every run started in it stays feasible forever and converges. F "
        "depends on z only through the gap and position errors and the two commanded accelerations; the "
        "stoppers give their level in closed form, and R ≥ 0 and the 9 A limit are checked on the exact "
        "image of {V ≤ c} by branch and bound with interval arithmetic. Two choices of P: the Lyapunov "
        "equation's (each state weighted by the acceleration it commands) and one from a semidefinite "
        "program (SDP) that enlarges the certified gap x position rectangle.",
        "'Certified' means every box of a cover of that image was proved feasible by outward-rounded "
        "interval arithmetic: the certified c is a sound lower bound on the least V outside F. A local "
        "optimiser (multistart IPOPT, exact derivatives) finds infeasible points, an upper bound; their "
        "ratio is the tightness.",
        "What the certificate assumes: plant = the controllers' model; the continuous-time loop with exact "
        "velocities and an ideal amplifier while |u| ≤ 9 A; references from the papers' exosystem "
        "(set-points, or the ellipse without its ramp-in); the printed gains K_h, K_v. What it leaves out, "
        "checked by Monte Carlo instead: the 5 kHz sampling, the high-gain observers and the encoder.",
        "Simulations. " + twin_sentence("ideal twin") + " Runs are sampled at 5 kHz with the observers "
        "started at the true velocities and the internal models at the start's value. One check adds the "
        f"encoders ({encoder}). Basins are sampled, not certified: a grid of start x target steps per "
        "controller, each judged by how it ends.",
    ]


def _parts_table(st: OperatingRegionStudy) -> Table:
    """What each part of the study computes, how much, and whether it proves or samples."""
    c, ls = st.config, st.large_step
    refs = len(st.references)
    sdp = sum(r.sdp is not None and r.sdp.certified is not None for r in st.references)
    slices = st.slices.get("Lyapunov P", ())
    rows = [
        (
            "the feasible set F",
            f"{len(st.maps)} slices, {c.map_points} x {c.map_points} grid, exact edges",
            "exact",
        ),
        ("Procedure 2", f"{refs} references: {refs} Lyapunov and {sdp} SDP certificates", "certified"),
        ("Monte Carlo inside", f"{st.inside_totals()['runs']} runs of {c.horizon:g} s", "sampled"),
        ("coverage on slices", f"{sum(x.n for x in slices)} starts on {len(slices)} slices", "sampled"),
        ("encoder check", f"{0 if st.quantization is None else st.quantization.n} runs", "sampled"),
    ]
    if st.robust is not None:
        rb = st.robust
        rows.append(
            (
                "on sampled plants",
                f"{sum(r.runs for r in rb.rows)} runs; {len(rb.radii)} bisections, "
                f"{rb.probe_runs} runs per probe",
                "sampled",
            )
        )
    if ls is not None:
        n = ls.map_starts.size * ls.sweep_targets.size
        rows += [
            ("basins", f"{n} start x target steps x {len(ls.maps)} controllers", "sampled"),
            ("linear regulators' regions", f"{len(ls.linear)} certified regions of attraction", "certified"),
        ]
    return Table("What the study computes", ("part", "how much", "proves or samples"), rows)


def _feasible_page(pdf: PdfReport, st: OperatingRegionStudy) -> None:
    if not st.maps:
        return
    mid = _middle(st)
    sin = next((r for r in st.references if not r.reference.is_setpoint), None)
    sp_maps = [m for m in st.maps if m.reference.is_setpoint]
    sin_maps = [m for m in st.maps if not m.reference.is_setpoint]
    i0, g0 = st.r_zero_current
    text = [
        f"F is where the regulator's commands are feasible. Its edge is the 9 A limit or a stopper: R = 0 "
        f"lies further out (at least {i0:.1f} A on R = 0, least at {_mm(g0)} mm). The certified sets (lines) "
        f"must lie in F for every phase of the reference. {_binding_sentence(st)}",
    ]
    pdf.add_page(
        "The feasible set F",
        [
            Text(text),
            Plot(plots.feasibility_plot(sp_maps, _certs(mid), sin_maps, _certs(sin) if sin else {}), 0.8),
        ],
    )


def _binding_sentence(st: OperatingRegionStudy) -> str:
    """Which constraint of F binds the Lyapunov equation's certificate, by reference."""
    by: dict[str, list[str]] = {}
    for rs in st.references:
        words = plots.BINDING_WORDS.get(rs.lyapunov.binding, rs.lyapunov.binding)
        by.setdefault(words, []).append(_name(rs))
    parts = [f"the {w} at {', '.join(names)}" for w, names in by.items()]
    return "Binding with the Lyapunov equation's P: " + "; ".join(parts) + "."


def _certificate_rows(st: OperatingRegionStudy) -> list[tuple[str, ...]]:
    """The study's certificate rows as printed (plain words for the reference, P and binding)."""
    words = {"sinusoid": "ellipse", "Lyapunov eq.": "Lyapunov"}
    return [
        (
            words.get(ref, ref),
            words.get(label, label),
            f"{level:.4g}",
            f"{upper:.4g}",
            f"{tight:.3f}",
            plots.BINDING_WORDS.get(binding, binding),
            f"{e1:.2f}",
            f"{e1_rate:.0f}",
            f"{e2:.1f}",
            f"{e2_rate:.0f}",
            rect,
        )
        for ref, label, level, upper, tight, binding, e1, e1_rate, e2, e2_rate, rect in certificate_rows(st)
    ]


def _certificate_page(pdf: PdfReport, st: OperatingRegionStudy) -> None:
    table = Table(
        "",
        (
            "reference",
            "P",
            "level c",
            "upper\nbound",
            "c / upper",
            "binding",
            "gap\n[mm]",
            "gap rate\n[mm/s]",
            "position\n[mm]",
            "pos. rate\n[mm/s]",
            "rectangle\n[mm]",
        ),
        _certificate_rows(st),
        notes=[
            "level c: certified (branch and bound, sound); upper bound: the least V found outside F; "
            "binding: the constraint at that point. Gap, gap rate, position, position rate: the largest "
            "deviation of that state alone from the steady state inside the certified set (set-point: at "
            "rest, internal models empty); rectangle: the largest-area box of gap x position errors inside "
            "it. Lyapunov: A_cl' P + P A_cl = −diag(K_v², K_h²); SDP: P maximising the rectangle over a "
            "proved inner polytope of F (decay rate 0.1 1/s), then certified against F itself. Ellipse: "
            "deviations from the steady-state orbit, every phase covered.",
        ],
        font_size=7.5,
    )
    pdf.add_page(
        "Certified sets: the adapted Procedure 2", [table, Plot(plots.certified_sets_plot(st), 0.42)]
    )


def _montecarlo_rows(st: OperatingRegionStudy) -> list[tuple]:
    rows = []
    for rs in st.references:
        for label in ("Lyapunov P", "SDP P"):
            chks = [c for k, c in rs.checks.items() if k.startswith(label)]
            if not chks:
                continue
            room = min(float(np.min(plots.stopper_room(c, st))) for c in chks)
            worst = rs.worst_start.get(label)
            rows.append(
                (
                    _name(rs),
                    label.removesuffix(" P"),
                    " + ".join(str(c.n) for c in chks),
                    sum(c.violations for c in chks),
                    f"{max(float(np.max(c.final_ratio)) for c in chks):.2g}",
                    f"{max(c.max_current for c in chks):.2f}",
                    f"{room * M_TO_MM:.2f}",
                    "—"
                    if worst is None
                    else f"{worst.max_current:.2f} / "
                    f"{float(np.min(plots.stopper_room(worst, st))) * M_TO_MM:.2f}",
                )
            )
    if st.quantization is not None:
        q = st.quantization
        rows.append(
            (
                _mm(q.reference.gap, 4) + " mm",
                "best, encoder",
                str(q.n),
                q.violations,
                "—",
                f"{q.max_current:.2f}",
                f"{np.min(plots.stopper_room(q, st)) * M_TO_MM:.2f}",
                "—",
            )
        )
    return rows


def _montecarlo_page(pdf: PdfReport, st: OperatingRegionStudy) -> None:
    if not any(rs.checks for rs in st.references):
        return
    table = Table(
        "",
        (
            "reference",
            "P",
            "runs (all\nstates + at rest)",
            "left F",
            "largest\nV_end / c",
            "largest\n|u| [A]",
            "least room to\na stopper [mm]",
            "worst certified start:\n|u| [A] / room [mm]",
        ),
        _montecarlo_rows(st),
        notes=[
            f"Each run: {st.config.horizon:g} s at 5 kHz with the FL regulator as implemented, from starts"
            " uniform in the certified set: all 10 error states, or the gap and position errors only (at "
            "rest). Left F: a sample with R < 0, a commanded |u| over 9 A, or a stopper hit. Largest "
            "V_end / c: far below 1 means every run is deep inside the certified set again. Worst "
            "certified start: the infeasible point nearest the set scaled back onto its edge. Encoder "
            "row: the 10 µm steps with 2 µm noise, starts in the best certified set.",
        ],
    )
    pdf.add_page("Monte Carlo inside the certified sets", [table, Plot(plots.montecarlo_plot(st), 0.46)])


def _slices_page(pdf: PdfReport, st: OperatingRegionStudy) -> None:
    lyap = st.slices.get("Lyapunov P", ())
    if not lyap:
        return
    sdp = {(x.reference.gap, x.axes): x for x in st.slices.get("SDP P", ())}
    rows = []
    for x in lyap:
        y = sdp.get((x.reference.gap, x.axes))
        rows.append(
            (
                _mm(x.reference.gap, 4) + " mm",
                " x ".join(plots.slice_axis_name(a) for a in x.axes),
                x.n,
                int(x.safe.sum()),
                f"{int(x.certified.sum())} / {'—' if y is None else int(y.certified.sum())}",
                x.unsafe_certified + (0 if y is None else y.unsafe_certified),
                f"{100 * x.coverage:.1f} %",
                "—" if y is None else f"{100 * y.coverage:.1f} %",
            )
        )
    table = Table(
        "",
        (
            "set-point",
            "slice",
            "starts",
            "safe",
            "certified\nLyapunov / SDP",
            "certified\nbut unsafe",
            "covers\nLyapunov",
            "covers\nSDP",
        ),
        rows,
        notes=[
            "Safe: the run never left F. Covers: |certified and safe| / |safe|, the share of the empirically "
            "safe starts that the certificate proves; the rest is the price of one quadratic V and of "
            "invariance.",
        ],
    )
    certs = {rs.reference.gap: _certs(rs) for rs in _setpoints(st)}
    pdf.add_page(
        "How much of the safe region the certificates cover",
        [table, Plot(plots.slices_plot(lyap, st.slices.get("SDP P", ()), certs), 0.64)],
    )


def _sigma(r: float) -> str:
    """A radius in standard deviations as printed."""
    return f"{r:.3g}" if math.isfinite(r) else "inf"


def _level_of(tail: float) -> str:
    """A confidence level 1 - tail as printed (the tail itself when it is tiny)."""
    return f"{1 - tail:.3f}" if tail > 1e-3 else f"1 − {tail:.0e}"


def _first_broken(rb: RobustStudy):
    """The bisection whose runs left F at the least radius (None: none did)."""
    broken = [c for c in rb.radii if math.isfinite(c.broken_radius)]
    return min(broken, key=lambda c: c.broken_radius) if broken else None


def _dof(rb: RobustStudy) -> int:
    eig = np.linalg.eigvalsh(rb.covariance)
    return int(np.sum(eig > 1e-12 * max(eig.max(), 1e-300)))


def _plant_set_name(rb: RobustStudy, name: str) -> str:
    from scipy.stats import chi2

    if name == "nominal":
        return "nominal (the\ncontroller's C)"
    if name == "box":
        return "papers' Tables\nII-III box"
    return f"{name} confidence\n(radius {math.sqrt(chi2.ppf(float(name), _dof(rb))):.2f} σ)"


def robust_rows(st: OperatingRegionStudy) -> list[tuple[str, ...]]:
    """The robust table as printed: per plant set, per set-point 'left F / runs' and the share
    of runs that stayed in F, then the largest |u| [A] and the least room to a gap stopper [mm]
    over the set-points."""
    rb = st.robust
    lo, hi = st.feasible.gap_range or (-math.inf, math.inf)
    rows = []
    for name in rb.plant_sets():
        cells, imax, room = [], 0.0, math.inf
        for ref in rb.certificates:
            r = rb.row(ref, name)
            cells.append(f"{r.violations} / {r.runs}\n{100 * r.share_feasible:.1f} %")
            imax = max(imax, float(np.nanmax(r.sweep.max_current)))
            room = min(room, float(np.nanmin(r.sweep.min_gap)) - lo, hi - float(np.nanmax(r.sweep.max_gap)))
        rows.append((_plant_set_name(rb, name), *cells, f"{imax:.2f}", f"{room * M_TO_MM:.2f}"))
    return rows


def _radius_rows(rb: RobustStudy) -> list[tuple[str, ...]]:
    rows = []
    for c in rb.radii:
        cert = rb.certificates.get(c.reference)
        rows.append(
            (
                c.reference,
                "the papers' start" if cert is None else cert.removesuffix(" P"),
                str(c.runs),
                _sigma(c.safe_radius),
                _sigma(c.broken_radius)
                if math.isfinite(c.broken_radius)
                else f"none up to {_sigma(c.safe_radius)}",
                f"{_level_of(c.safe_tail)} … {_level_of(c.broken_tail)}"
                if math.isfinite(c.broken_radius)
                else "—",
            )
        )
    return rows


def _robust_text(st: OperatingRegionStudy, model: StageModel) -> list[str]:
    rb = st.robust
    c = np.asarray(model.constants.as_array(), dtype=float)
    sd = np.sqrt(np.diag(rb.covariance))
    sds = ", ".join(f"C{k + 1} {100 * x / ck:.3g} %" for k, (x, ck) in enumerate(zip(sd, c, strict=True)))
    if rb.assumed:
        cov = (
            f"The covariance is ASSUMED: independent constants with standard errors {sds} of their "
            "values (no identification's covariance was given). Pass a stage file that has one "
            "(identify writes it) with --params to this report's script and this page uses it."
        )
    else:
        cov = f"The covariance of C1..C4 is read from {rb.covariance_source} (standard errors {sds})."
    names = ", ".join(rb.certificates)
    kinds = sorted(set(rb.certificates.values()))
    text = [
        "The FL regulator inverts the nominal constants C1..C4; the rig's lie somewhere in a confidence "
        "set around them. Each run here starts uniformly in a set-point's certified set {V ≤ c} "
        f"({' or '.join(k.removesuffix(' P') for k in kinds)} P, as on the previous pages) on a plant whose "
        f"constants are drawn uniformly from the row's set, and runs {st.config.horizon:g} s on the rig "
        "twin (no effects) with the controller's nominal constants; it fails when it leaves F (R < 0, "
        "|u| over the limit, a stopper). Every plant set sees the same starts. " + cov,
        "These are samples, never certificates: no violation in n runs says only that the share of "
        "failing start-and-plant pairs is probably (95 %) below about 3/n "
        f"({100 * 3 / rb.runs:.1f} % for the {rb.runs} runs per cell), not that there is none.",
    ]
    level = "0.95" if "0.95" in rb.plant_sets() else rb.plant_sets()[-2]
    tot, box = rb.totals(level), rb.totals("box")
    summary = (
        f"Over the {len(rb.certificates)} set-points ({names}): on plants within the {level} confidence set "
        f"{tot['violations']} of {tot['runs']} runs left F; within the papers' Tables II-III box "
        f"{box['violations']} of {box['runs']}."
    )
    first = _first_broken(rb)
    if first is not None:
        top = first.broken_radius * sd / c
        summary += (
            f" Growing the confidence set, runs first leave F at {first.reference}, between "
            f"{_sigma(first.safe_radius)} and {_sigma(first.broken_radius)} σ (confidence "
            f"{_level_of(first.safe_tail)} to {_level_of(first.broken_tail)}): there one constant alone may "
            "be off by " + ", ".join(f"C{k + 1} ±{100 * x:.2g} %" for k, x in enumerate(top)) + "."
        )
    elif rb.radii:
        summary += " No bisection found a violation up to its largest radius."
    text.append(summary)
    return text


def _certified_cell(cert) -> str:
    """A confidence level's cell: the certified share of the nominal level, or why none."""
    if cert.success:
        return f"{cert.ratio:.2f}"
    if cert.status == "failed":
        return "failed"
    return "refuted" if cert.witness_plant is not None else "undecided"


def certified_robust_rows(st: OperatingRegionStudy) -> list[tuple[str, ...]]:
    """The certified robust table as printed: per set-point the nominal level with the robust
    SDP's P, the certified robust level as a share of it per confidence level (``—``: not tried,
    a lower level already failed), and the highest confidence level still certified."""
    cr = st.robust.certified
    rows = []
    for row in cr.rows:
        cells = [_certified_cell(c) for c in row.certificates]
        cells += ["—"] * (len(cr.levels) - len(cells))
        best = cr.highest_certified(row)
        nominal = "no P" if row.nominal is None else f"{row.nominal.level:.3g}"
        rows.append((row.reference, nominal, *cells, "none" if best is None else f"{best:g}"))
    return rows


def _certified_robust_text(st: OperatingRegionStudy) -> list[str]:
    rb, cr = st.robust, st.robust.certified
    cov = "the assumed covariance" if rb.assumed else f"the covariance of {rb.covariance_source}"
    ladder = " and ".join(f"{f:g}" for f in cr.ladder)
    text = [
        "Unlike the sampled page before, this one proves something: a level set {V ≤ c} of the "
        "certificate's V that no run can leave, for every plant whose constants C1..C4 lie in the "
        f"confidence ellipsoid of {cov} (same ellipsoids as before) while the controller keeps the "
        "nominal ones. It holds for the continuous-time FL loop with constant constants in the set "
        "and no other effects (no cogging, friction, sampling or quantisation). The worst plant of "
        "the set is found exactly at each point of the boundary, and interval arithmetic proves that "
        "V decreases there; a point where it grows refutes the level with a real plant.",
        "P is chosen for robustness by a semidefinite program that treats the model error as a "
        f"bounded disturbance, for the {cr.design_level:g} confidence set; the nominal level is then "
        "Procedure 2's for that P. With the Lyapunov equation's P nothing is certified: V decays so "
        "slowly under it that the model error of even the 0.5 set pushes it up on every level set "
        "(bench/region_robust_certificate.py).",
        f"Each cell tries {ladder} times the nominal level with at most {cr.boxes:,} boxes "
        "each; 'undecided' means that budget ran out (neither proved nor refuted), 'refuted' that a "
        "plant of the set leaves the level. Higher confidence levels are not tried after the first "
        "that fails (their sets contain it).",
    ]
    if cr.checked is not None:
        ref, level = cr.checked
        text.append(
            f"Monte Carlo check: {cr.runs} runs of {st.config.horizon:g} s of the sampled loop at "
            f"{ref}, starts uniform in the certified set of the {level:g} confidence level and plants "
            f"uniform in that set: {cr.violations} left F (0 expected)."
        )
    else:
        text.append("No set-point was certified at the lowest confidence level, so no Monte Carlo check ran.")
    return text


def _certified_robust_page(pdf: PdfReport, st: OperatingRegionStudy) -> None:
    cr = st.robust.certified
    table = Table(
        "Certified robust level per set-point, as a share of the nominal level",
        (
            "set-point",
            "nominal\nlevel c",
            *(f"confidence\n{p:g}" for p in cr.levels),
            "highest confidence\ncertified",
        ),
        certified_robust_rows(st),
        notes=[
            "Nominal level: the level Procedure 2 certifies for the nominal plant with the robust "
            "P (V units). A share of 1.00 means the whole nominal set is certified for every plant of "
            "the set."
        ],
    )
    refuted = [
        (
            row.reference,
            f"{level:g}",
            f"{c.level_upper:.3g} ({c.level_upper / c.nominal_level:.2f} of nominal)",
            *(f"{x:.4g}" for x in c.witness_plant),
        )
        for row in cr.rows
        for level, c in zip(cr.levels, row.certificates, strict=False)
        if not c.success and c.witness_plant is not None
    ]
    blocks = [Text(_certified_robust_text(st)), table]
    if refuted:
        blocks.append(
            Table(
                "Refutations: a plant of the set that leaves the level",
                ("set-point", "confidence", "level refuted", "C1", "C2", "C3", "C4"),
                refuted,
                notes=[
                    "The lowest level tried that this plant leaves: on that level set's boundary V grows "
                    "for it. Its constants are on the boundary of the confidence set (the worst plant "
                    "there)."
                ],
            )
        )
    title = "Certified robust region: every plant of a confidence set"
    pdf.add_page(title, blocks)


def _robust_page(pdf: PdfReport, st: OperatingRegionStudy, model: StageModel) -> None:
    rb = st.robust
    box = ", ".join(
        f"C{k + 1} {lo:.4g}-{hi:.4g}"
        for k, (lo, hi) in enumerate(zip(rb.box.lower, rb.box.upper, strict=True))
    )
    table = Table(
        ROBUST_TABLE,
        (
            "plants",
            *(f"{ref}" for ref in rb.certificates),
            "largest\n|u| [A]",
            "least room to a\ngap stopper [mm]",
        ),
        robust_rows(st),
        notes=[
            "Confidence sets: the ellipsoid (C − C0)' Σ⁻¹ (C − C0) ≤ r² with r² the chi-square quantile of "
            f"the level ({_dof(rb)} degrees of freedom), C0 the controller's constants, Σ the covariance. "
            "Papers' "
            f"box: every column of Tables II and III of 000 ({box}). Largest |u| and least room: over every "
            "run of the row's set-points.",
        ],
        font_size=7.5,
    )
    blocks = [Text(_robust_text(st, model)), table]
    if rb.radii:
        blocks.append(
            Table(
                "Where runs first leave F as the confidence set grows (bisection on the radius)",
                (
                    "reference",
                    "starts",
                    "runs per\nprobe",
                    "no violation\nup to [σ]",
                    "first violation\nat [σ]",
                    "confidence level\nof the bracket",
                ),
                _radius_rows(rb),
                notes=[
                    "Radius r in standard deviations of the covariance (the set above with r² free). A "
                    "bracket is only as good as its probes: more runs per probe find violations at smaller "
                    "radii, so the first-violation radius is an upper estimate. Large step: every run "
                    f"from the papers' start (26, 0, 0, 0) mm to (18, 20) mm at rest, "
                    f"{st.config.linear_horizon:g} s.",
                ],
                font_size=7.5,
            )
        )
    pdf.add_page("Robust to the plant's uncertainty (sampled)", blocks)


def _basins_page(pdf: PdfReport, st: OperatingRegionStudy) -> None:
    ls = st.large_step
    rows = []
    for name in ls.maps:
        o = ls.outcomes(name)
        rows.append(
            (
                name,
                *(str(o[k]) for k in BASIN_OUTCOMES),
                f"{_share(ls.maps[name]):.0f} %",
                f"{_share(ls.maps[name], 'within_limit'):.0f} %",
            )
        )
    table = Table(
        "",
        (
            "controller",
            *(k.replace(" the ", "\nthe ") for k in BASIN_OUTCOMES),
            "converge",
            "converge\nwithin 9 A",
        ),
        rows,
        notes=[
            "How each step ends (study order: diverged, stopper, not settled, R < 0, over 9 A, else "
            "converged; 'converge' counts the last three for the linear regulators, whose ideal twin does "
            "not limit the current, and only the first for the FL regulator, which must stay in F).",
        ],
    )
    pdf.add_page(
        "Basins: every controller, start gap x target gap",
        [
            table,
            Plot(
                plots.basin_maps_plot(
                    ls,
                    list(ls.maps),
                    "How each step ends, per controller (sampled ideal twin)",
                    "Without equilibrium feedforward the internal model must build up the holding current: "
                    "the gap sags into the lower stopper on steps to small gaps.",
                ),
                0.7,
            ),
        ],
    )


def _roa_table(st: OperatingRegionStudy) -> Table:
    ls = st.large_step
    rows = []
    for x in ls.linear:
        r = x.roa
        s = r.initial_conditions.semi_axes
        rows.append(
            (
                x.controller,
                f"{r.level_stability:.3g}",
                f"{r.level_travel:.3g}",
                f"{r.level_current:.3g}",
                f"{s['e1'] * M_TO_MM:.3f}",
                f"{s['e2'] * M_TO_MM:.3f}",
                f"{x.large_step_ratio:.4g}",
            )
        )
    reach = _reach(st)
    rows.append((f"{FL} (aimed SDP)", "—", "—", "—", "—", "—", f"{1 / reach**2:.4g}" if reach > 0 else "inf"))
    return Table(
        "Certified regions of attraction at the large step's target (18 mm, 20 mm)",
        ("controller", "c stability", "c stoppers", "c 9 A", "gap [mm]", "position [mm]", "V(start) / c"),
        rows,
        notes=[
            "A linear regulator's certified region: V = z' P z (Lyapunov equation); on {V ≤ c} the Jacobian "
            "of the linearization's remainder is enclosed by interval arithmetic and V' < 0 checked at every "
            "vertex of the enclosure. c stability: the largest such c; c stoppers: exact; c 9 A: where the "
            "commanded current reaches 9 A. Gap, position: certified errors at rest. V(start) / c: the "
            "papers' start (26, 0, 0, 0) with empty internal models. FL row: 1 / reach² of the SDP aimed at "
            "that start.",
        ],
    )


def _large_step_pages(pdf: PdfReport, st: OperatingRegionStudy, model: StageModel) -> None:
    ls = st.large_step
    pdf.add_page(
        "The papers' large step, 26 → 18 mm",
        [
            _roa_table(st),
            Plot(plots.sweep_plot(ls, st.feasible.gap_range, st.feasible.current_limit), 0.42),
        ],
    )
    pdf.add_page(
        "Why the linear regulator failed on the rig and not on the twin",
        [Text(_large_step_text(st, model)), _frozen_table(st)],
    )


def _frozen_table(st: OperatingRegionStudy) -> Table:
    ls = st.large_step
    poles = ls.frozen_poles
    damping = np.min(-poles.real / np.abs(poles), axis=1)
    slowest = np.max(poles.real, axis=1)
    rows = [
        (f"{g * M_TO_MM:g}", f"{z:.2f}", f"{s:.2f}")
        for g, z, s in zip(ls.frozen_gaps, damping, slowest, strict=True)
    ]
    return Table(
        f"The linear regulator's gains for {_mm(ls.reference.gap)} mm, frozen at other gaps",
        ("plant linearised at [mm]", "least damping ratio", "slowest pole [1/s]"),
        rows,
    )


def _large_step_text(st: OperatingRegionStudy, model: StageModel) -> list[str]:
    ls = st.large_step
    k = int(np.argmin(np.abs(ls.sweep_targets - ls.reference.gap)))

    def least(name: str) -> str:
        d = ls.sweep.get(name)
        return "—" if d is None else f"{d['min_gap'][k] * M_TO_MM:.1f} mm"

    def highest_failing(name: str) -> str:
        d = ls.sweep[name]
        bad = ls.sweep_targets[~d["success"]]
        return f"{bad.max() * M_TO_MM:g} mm and below" if bad.size else "none"

    gmin = ls.sweep[LINEAR]["min_gap"][k]
    lin = axis_linearizations(model, [gmin, ls.reference.gap, ls.start[0]])
    stiff = lin.stiffness_v / lin.stiffness_v[1]
    l1 = lin.gain_h / lin.gain_h[1]
    poles = ls.frozen_poles
    damping = np.min(-poles.real / np.abs(poles), axis=1)
    kd = int(np.argmin(np.abs(ls.frozen_gaps - ls.reference.gap)))
    names = list(ls.sweep)
    return [
        "On the rig the linear regulator went unstable on the step 26 → 18 mm (with 0 → 20 mm horizontally) "
        "while the FL regulator settled (001 Fig. 9, 002 Fig. 12). On the sampled ideal twin every "
        "controller settles; the least gaps are " + "; ".join(f"{n}: {least(n)}" for n in names) + ".",
        "Certified regions of attraction cannot settle the question: for the linear regulators they are a "
        "few tenths of a millimetre (previous page). One quadratic V must absorb every combination of the "
        f"nonlinearity over the step: the vertical stiffness dx2'/dx1 is {stiff[0]:.2f} times its set-point "
        f"value at the least gap ({gmin * M_TO_MM:.1f} mm) and {stiff[2]:.2f} times at the start; the "
        f"horizontal gain L1 {l1[0]:.2f} and {l1[2]:.2f} times.",
        "The sampled basin and the frozen-gain picture explain the rig instead. From 26 mm the targets that "
        "fail are: " + "; ".join(f"{n}: {highest_failing(n)}" for n in names) + f". Along the step the "
        f"linear regulator keeps the gains designed at {_mm(ls.reference.gap)} mm; frozen at smaller gaps "
        f"they give vertical poles with less damping (table: {damping[kd]:.2f} at the design gap, "
        f"{damping[0]:.2f} at {_mm(ls.frozen_gaps[0])} mm), so its overshoot grows where the model is "
        f"worst. Its least gap, {least(LINEAR)}, is below the 15 mm under which 000/002 found the cogging "
        f"force (more than 1 N) to make the model wrong; without feedforward it reaches {least(names[2])}.",
        "Add the rig's unmodelled force below 15 mm, the 9 A limit, the amplifiers' lag and the observers' "
        "noise to a trajectory that already enters that region, a few millimetres from the edge of the "
        "basin, and the instability the papers saw is plausible. The FL regulator cancels the stiffness "
        "change exactly, keeps its designed damping, and an SDP aimed at the start certifies the step. "
        "What the ideal twin does not reproduce is the failure itself: this report does not claim that the "
        "linear regulator is unstable for this step on the nominal model.",
    ]


def _timing_table(st: OperatingRegionStudy, timings: dict[str, float]) -> Table:
    rows = [(k, f"{v:.2f}") for k, v in timings.items() if k != "total"]
    rows.append(("total (study and report)", f"{st.timings['total'] + timings[list(timings)[-1]]:.1f}"))
    return Table(
        "",
        ("step", "wall time [s]"),
        rows,
        notes=[
            "On the machine that wrote this report (2 cores, possibly shared). Monte Carlo runs are the "
            "closed-loop step generated as C, looped over samples and starts in C on 2 threads; "
            "bench/region.py times each step on its own.",
        ],
    )


LEVEL_COLUMNS = (
    ("margin", "R >= 0"),
    ("headroom", "9 A"),
    ("gap_low", "lower gap\nstopper"),
    ("gap_high", "upper gap\nstopper"),
    ("position_high", "horizontal\nstopper"),
)


def _levels_table(st: OperatingRegionStudy) -> Table:
    """Per reference and P: the certified level and, per constraint of F, the least V found where
    that constraint fails (the stoppers' exact)."""
    rows = []
    for rs in st.references:
        for label, c in (("Lyapunov", rs.lyapunov), ("SDP", rs.sdp.certified if rs.sdp else None)):
            if c is None:
                continue
            rows.append(
                (_name(rs), label, f"{c.level:.4g}", *(f"{c.levels[k][1]:.4g}" for k, _ in LEVEL_COLUMNS))
            )
    return Table(
        "Least V found where each constraint fails",
        ("reference", "P", "certified c", *(w for _, w in LEVEL_COLUMNS)),
        rows,
        notes=[
            "The certified c is at most the least of them; the constraint with the least is the binding one. "
            + _r_beyond_limit(st),
        ],
        font_size=7.5,
    )


def _r_beyond_limit(st: OperatingRegionStudy) -> str:
    """What the R >= 0 and 9 A columns say, in words (computed)."""
    certs = [c for rs in st.references for c in (rs.lyapunov, rs.sdp.certified if rs.sdp else None) if c]
    below = sum(c.levels["margin"][1] < c.levels["headroom"][1] for c in certs)
    i0, _ = st.r_zero_current
    text = (
        "The nonlinear columns are the least V a local optimiser found (upper bounds); the stoppers' are "
        f"exact. On R = 0 the commanded current is at least {i0:.1f} A, so along any path from the "
        "set-point the 9 A limit is crossed first"
    )
    if below:
        text += (
            f"; where the R >= 0 value is below the 9 A value ({below} of the {len(certs)} certificates) the "
            "optimiser's 9 A point is simply not the least one"
        )
    return text + "."


def _runs_text(st: OperatingRegionStudy) -> list[str]:
    c = st.config
    refs = len(st.references)
    slices = sum(s.n for s in st.slices.get("Lyapunov P", ()))
    ls = st.large_step
    pairs = 0 if ls is None else ls.map_starts.size * ls.sweep_targets.size * len(ls.maps)
    return [
        f"Runs: {st.inside_totals()['runs']} inside the certified sets ({c.samples} per set, kind and "
        f"reference, {refs} references, {c.horizon:g} s each), {slices} on slices, "
        f"{0 if st.quantization is None else st.quantization.n} with the encoder, {pairs} start x target "
        f"steps ({c.linear_horizon:g} s each)"
        + (
            ""
            if st.robust is None
            else f", {sum(r.runs for r in st.robust.rows)} on sampled plants and "
            f"{len(st.robust.radii)} bisections of {st.robust.probe_runs} runs per probe"
        )
        + f". Study status: {st.status.replace('_', ' ')} ({st.message}).",
    ]


def main(argv: list[str] | None = None) -> int:
    from maglev_oc.analyses import analysis_parser

    from maglev_oc.model.loading import load_model

    parser = analysis_parser(__doc__, REPORT)
    parser.add_argument("--quick", action="store_true", help="small sample counts (smoke test)")
    args = parser.parse_args(argv)
    contents = build(args.out, load_model(args.params), QUICK if args.quick else None, params=args.params)
    print(f"wrote {contents.path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
