"""The diagnosis report: what the log's residual is made of, and what adding it is worth.

Page 1 is the scorecard: each effect found with its size (and, for a log whose truth is known, the
truth beside it and the verdict), what could not be told apart from the constants on this log,
what no effect explains, the held-out error before and after, and the closed loop before and
after compensating; then the key figure. The pages after it hold the findings in words, the
parameters and constants, every candidate's verdict with its reason, the figures behind them, and
an appendix of timings and settings.
"""

from __future__ import annotations

import itertools
import math
import os
import textwrap
from collections.abc import Sequence

import numpy as np

from maglev_oc.diagnosis.feedback import CompensationStudy, improvement
from maglev_oc.diagnosis.guides import HELD_BEYOND_BREAKAWAY
from maglev_oc.diagnosis.limits import DetectionLimit
from maglev_oc.diagnosis.pipeline import Diagnosis, Effect
from maglev_oc.diagnosis.result import NotSeparable
from maglev_oc.diagnosis.selection import SMOOTH_POSITION, THE_CONSTANTS, best_first, shared_along_the_track
from maglev_oc.diagnosis.unexplained import TIMING
from maglev_oc.diagnosis.words import plain
from maglev_oc.reporting import diagnosis_plots as plots
from maglev_oc.reporting import validation_plots
from maglev_oc.reporting.pdf import (
    MIN_FILL,
    PdfReport,
    Plot,
    ReportContents,
    Table,
    Text,
    block_height,
    page_room,
    split_table,
)
from maglev_oc.units import M_TO_MM, M_TO_UM

__all__ = ["KEY_PANELS", "effect_sizes", "outcome_rows", "scorecard_table", "write_diagnosis_report"]

KEY_PANELS = 3
"""Found effects the key figure shows (the first ones); the rest get a page of their own."""

NBSP = "\u00a0"
"""Joins a value and its unit so that a table cell never breaks between them."""


def _fmt(value: float, err: float) -> str:
    if not math.isfinite(err) or err == 0:
        return f"{value:.4g}"
    return f"{value:.4g} ± {err:.2g}"


def _wrap(text: str, width: int) -> str:
    return "\n".join(line for part in text.split("\n") for line in (textwrap.wrap(part, width) or [""]))


_POSITION_PARAMETERS = ("at_gap", "period", "low_end_position", "high_end_position", "width", "decay_length")
"""Parameters [m] that say where an effect acts, not how large it is (left out of the sizes)."""
_CHECK_PARAMETERS = ("forces_lost_at_low_end_alone", "forces_lost_at_high_end_alone", "held_force")
"""Parameters an effect's plausibility is judged on (an end effect's each end on its own, the force a
friction's guides hold while the axis sticks), shown in the table of every parameter, not among the
sizes."""


def _size_parameters(parameters: dict, nuisance: tuple[str, ...] = ()) -> dict:
    """The parameters that say how large an effect is (not where it acts, not its shape)."""
    return {
        k: v
        for k, v in parameters.items()
        if not k.startswith("rms_force")
        and k not in nuisance
        and k not in _CHECK_PARAMETERS
        and not (v.unit == "m" and k in _POSITION_PARAMETERS)
    }


_MILLI = {"rad": "mrad", "m": "mm"}
"""Units a small size reads better in thousandths of: a tilt of 0.0023 rad is 2.3 mrad, a change of
the gap over the travel of 0.0003 m is 0.3 mm."""


def _sizes(parameters: dict) -> str:
    """'coulomb 0.128 ± 0.0048 N, viscous ...': value ± standard error; a ratio (unit "1") in per cent,
    an angle or length below 0.1 of its unit in thousandths of it (mrad, mm)."""

    def size(v) -> str:
        if v.unit == "1":
            return f"{_fmt(100 * v.value, 100 * v.stderr)}{NBSP}%"
        if v.unit in _MILLI and abs(v.value) < 0.1:
            return f"{_fmt(1e3 * v.value, 1e3 * v.stderr)}{NBSP}{_MILLI[v.unit]}"
        return f"{_fmt(v.value, v.stderr)}{NBSP}{v.unit}".rstrip(NBSP)

    return ", ".join(f"{k.replace('_', ' ')} {size(v)}" for k, v in parameters.items())


def effect_sizes(effect: Effect) -> str:
    """'coulomb 0.128 ± 0.0048 N, viscous ...': an effect's size parameters, value ± standard error;
    a ratio (unit "1") in per cent."""
    return _sizes(_size_parameters(effect.parameters, effect.candidate.nuisance))


def _beside_effects(n: NotSeparable) -> str:
    """A not separable candidate's sizes as fitted, when what it is confounded with are effects
    (a tilt of the guides and guides sloping against the stator: the same force along the track,
    sized alike by either); "" when it is confounded with the constants, whose trade makes its
    size mean nothing."""
    if not n.confounded_with or any(c in THE_CONSTANTS or c == SMOOTH_POSITION for c in n.confounded_with):
        return ""
    sizes = _sizes(_size_parameters(n.parameters))
    return f" Fitted in its place: {sizes}." if sizes else ""


def _drop(before: float, after: float) -> str:
    """The relative drop in per cent, one decimal below 10 % (a 0.3 % drop is not "0 %")."""
    if not before > 0:
        return "—"
    drop = 100 * (1 - after / before)
    return f"{drop:.{0 if abs(drop) >= 10 else 1}f} %"


def outcome_rows(diag: Diagnosis, study: CompensationStudy | None) -> list[tuple[str, str, str]]:
    """(what, found, verdict) for the errors before and after and the closed loop."""
    eb, ea = diag.error_before, diag.error_after
    axes = [a for a, b in eb.items() if math.isfinite(b)]
    # the "after" model carries the force along the track of a pair not told apart (its constants
    # are fitted beside it, pipeline._shared_terms): what lowers the errors then is named
    shared = [f"{plain(one)} or {plain(both)}" for one, both in shared_along_the_track(diag.not_separable)]
    beside = f" with the force along the track of {' and '.join(shared)} (not separable)" if shared else ""
    added = bool(diag.effects or shared)
    rows = [
        (
            "held-out acceleration error (RMS)",
            "; ".join(f"{a} {eb[a]:.3g} → {ea[a]:.3g}{NBSP}m/s²" for a in axes),
            "lowered by " + " and ".join(f"{_drop(eb[a], ea[a])} ({a})" for a in axes) + beside
            if added
            else "nothing to add",
        )
    ]
    ob, oa = diag.output_error_before, diag.output_error_after
    oaxes = [a for a, b in ob.items() if math.isfinite(b)]
    rows.append(
        (
            "held-out position error, model simulated 50 ms ahead (RMS)",
            "; ".join(f"{a} {ob[a] * M_TO_UM:.1f} → {oa[a] * M_TO_UM:.1f}{NBSP}µm" for a in oaxes),
            "lowered by " + " and ".join(f"{_drop(ob[a], oa[a])} ({a})" for a in oaxes) + beside
            if added
            else "—",
        )
    )
    if study is not None:
        imp = improvement(study)
        b, a = study.before.mean_error, study.after.mean_error
        rows.append(
            (
                f"FL regulator tracking the {study.scenario}: mean error",
                f"vertical {b[0] * M_TO_UM:.1f} → {a[0] * M_TO_UM:.1f}{NBSP}µm; horizontal "
                f"{b[1] * M_TO_UM:.1f} → {a[1] * M_TO_UM:.1f}{NBSP}µm",
                f"÷ {imp[0]:.1f} and ÷ {imp[1]:.1f} with "
                + (", ".join(plain(n) for n in study.compensated) or "nothing")
                + " compensated",
            )
        )
    return rows


def _finding_rows(diag: Diagnosis) -> list[tuple[str, str, str]]:
    """(what, found, verdict) for each found, not separable and unexplained item (no truth known)."""
    rows = [
        (
            plain(e.name),
            effect_sizes(e),
            f"claimed: held-out error −{_drop(1.0, 1.0 - e.gain)}{_predicting(e.judged_on)} (z = {e.z:.1f}), "
            f"chosen in {100 * e.confidence:.0f} % of resamples",
        )
        for e in diag.effects
    ]
    rows += [
        (
            plain(n.name),
            f"real in the fit, confounded with {', '.join(map(plain, n.confounded_with))}",
            "not claimed",
        )
        for n in diag.not_separable
    ]
    # a constant no stage of this design has (pipeline.constant_warnings: "<what>: <why>")
    rows += [
        (
            "warning: a refitted constant",
            w.partition(": ")[0],
            "something the model lacks takes its place: sizes and limits on that axis not to be trusted "
            "(page 2)",
        )
        for w in diag.warnings
    ]
    if diag.moving_mass is not None:  # the constants moved as a payload moves them (identification.masses)
        mass = diag.moving_mass
        rows.append(
            (
                "movers heavier than the model's"
                if mass.added.value > 0
                else "movers lighter than the model's",
                f"{abs(mass.added.value):.2g} ± {mass.added.stderr:.1g}{NBSP}kg "
                f"(C1 {mass.changes['C1']:+.0%}, C2 {mass.changes['C2']:+.0%})",
                "a payload, not an effect: diagnosed again as carrying it (the note below)"
                if mass.carried
                else "a payload, not an effect: forces in N here use the model's masses (the note below)",
            )
        )
    rows += [
        (
            f"{u.axis} residual varying with the {u.depends_on.replace('_', ' ')}",
            f"{u.size:.3g}{NBSP}m/s² RMS",
            "unexplained: the logged currents are late against the positions (not a force of the stage)"
            if u.depends_on == TIMING
            else "unexplained: no effect of the library fits it",
        )
        for u in diag.unexplained
    ]
    seen = [d for d in diag.detection_limits if math.isfinite(d.value)][:LIMITS_ON_SCORECARD]
    if seen:
        rows.append(
            (
                "not shown by this log",
                ", ".join(f"{plain(d.name)} below {limit_size(d)}" for d in seen),
                "may be there, too small for this log (every limit: page 2 on)",
            )
        )
    elif not diag.limits_worked_out:
        rows.append(("not shown by this log", "not worked out (diagnose --no-limits)", "not known"))
    rows += [
        (
            "not in this log at any size",
            plain(d.name),
            "its currents are the amplifiers' measured output, after their lag: log the commands to see it",
        )
        for d in diag.detection_limits
        if d.not_in_log
    ]
    return rows


def _predicting(judged_on: str) -> str:
    """What the held-out error of an effect's claim was the error of (``Effect.judged_on``): nothing
    said for the accelerations, the logged thrust current named."""
    return "" if judged_on == "accelerations" else " predicting the logged thrust current"


SIDE_SENTENCE = (
    "It was seen by predicting the logged thrust current from the measured motion: on this log that "
    "current is mostly its logging error, so accelerations predicted from it could not show an effect "
    "proportional to it."
)
"""Said of a finding the thrust side showed (:mod:`maglev_oc.diagnosis.thrust_current`)."""


LIMITS_ON_SCORECARD = 3
"""Detection limits the first page names (the most promising candidates first)."""

SCORECARD_WIDTHS = {3: (30, 44, 44), 4: (26, 26, 34, 34)}
"""Characters per line of the scorecard's columns (without, with the truth column)."""


def scorecard_table(
    diag: Diagnosis, study: CompensationStudy | None, truth_rows: Sequence[Sequence[str]] = ()
) -> Table:
    """Page 1's table: with ``truth_rows`` (what, true, found, verdict) those and the outcome rows
    with the truth column; without, what was found on the log."""
    if truth_rows:
        columns = ("", "true (twin)", "found on the log", "verdict")
        rows = [tuple(r) for r in truth_rows] + [(w, "—", f, v) for w, f, v in outcome_rows(diag, study)]
    else:
        columns = ("", "found on the log", "verdict")
        rows = _finding_rows(diag) + outcome_rows(diag, study)
    widths = SCORECARD_WIDTHS[len(columns)]
    cells = [tuple(_wrap(c, w) for c, w in zip(r, widths, strict=True)) for r in rows]
    holdout = (
        f"Held out: the last {diag.settings['holdout_fraction']:.0%} of each log "
        f"({int(diag.holdout.sum())} samples; {int(diag.train.sum())} fitted). Acceleration error: measured "
        "minus modelled acceleration, both through the same zero-phase filter."
    )
    left_out = [f"Left out of the fit: {os.path.basename(r.source)}, {r.what()}." for r in diag.left_out]
    mass = [diag.moving_mass.says()] if diag.moving_mass is not None else []
    payloads = [f"Payload: {w}." for w in diag.payloads]
    return Table("", columns, cells, notes=[holdout, *left_out, *payloads, *mass], font_size=7.5)


# --- the pages after the scorecard -----------------------------------------------------------------------
TEXT_BLOCK_CHARS = 1800
"""Paragraphs are shared out over pages in blocks of about this many characters (a third of a page
of text): one block of them all ran over a page on the closing-the-loop report once its twin's
friction was found changing along the track beside a tilt read two ways."""


def _text_blocks(paragraphs: Sequence[str], limit: int = TEXT_BLOCK_CHARS) -> list[Text]:
    """``paragraphs`` in order, in blocks of whole paragraphs of at most ``limit`` characters (a
    longer paragraph is a block of its own), for the page plan to place (:func:`_plan`)."""
    blocks: list[list[str]] = []
    for para in paragraphs:
        if blocks and sum(map(len, blocks[-1])) + len(para) <= limit:
            blocks[-1].append(para)
        else:
            blocks.append([para])
    return [Text(b) for b in blocks]


def _finding_paragraphs(diag: Diagnosis) -> list[str]:
    """What was found, in the diagnosis's own sentences."""
    out = [f"Warning: {w}." for w in diag.warnings]
    if diag.effects:
        out += [
            f"{k}. {plain(e.name).capitalize()}: {e.finding} {e.explanation}"
            + ("" if e.judged_on == "accelerations" else f" {SIDE_SENTENCE}")
            for k, e in enumerate(diag.effects, 1)
        ]
    elif diag.unexplained:
        out.append(
            "No effect of the library found, but the refitted papers' model does not explain the log to its "
            "noise: what is left is described below by what it depends on, not named."
        )
    elif diag.not_separable:
        out.append(
            "No effect found that this log can tell from the lumped constants: the candidates below "
            "explain part of the residual, but only an experiment that separates them can say which."
        )
    elif diag.warnings:
        out.append(
            "No effect found, but a refitted constant is one no stage of this design has (the warning "
            "above): something the model lacks takes its place, and the log is not explained to its noise."
        )
    else:
        out.append("No missing effect found: the papers' model, refitted, explains the log to its noise.")
    out += [
        f"Real in the fit but not separable on this log (not claimed): {plain(n.name)}, confounded with "
        f"{', '.join(map(plain, n.confounded_with))}.{_beside_effects(n)} What would separate it: "
        f"{n.experiment}."
        for n in diag.not_separable
    ]
    out += [f"Not explained by any effect of the library: {u.description}" for u in diag.unexplained]
    out += [f"Judged and not claimed ({j.verdict}): {plain(j.name)}, {j.reason}." for j in diag.rejected]
    seen = [d for d in diag.detection_limits if math.isfinite(d.value)]
    if seen:
        smallest = ", ".join(f"{plain(d.name)} below {limit_size(d)}" for d in seen[:LIMITS_IN_WORDS])
        out.append(
            f"Not found does not mean absent: this log could not have shown {smallest} (each put into the "
            "log at that size and judged as the diagnosis judges; every limit is in the table below)."
        )
    out += [
        f"{plain(d.name).capitalize()}: {d.reason}."
        for d in diag.detection_limits
        if d.not_in_log  # an effect this log holds none of, said where it is read
    ]
    if not diag.limits_worked_out:
        out.append(
            "What this log could not have shown was not worked out (diagnose --no-limits): an effect not "
            "found may be there below a size this log cannot show."
        )
    return out


LIMITS_IN_WORDS = 4
"""Detection limits named in the findings' words (the most promising candidates first)."""


def limit_size(limit: DetectionLimit) -> str:
    """A detection limit's size in the units a control engineer reads: ratios in per cent, times in
    milliseconds, angles in degrees, lengths in millimetres or micrometres, currents below an ampere
    in milliamperes; "no size" when none shows it."""
    if not math.isfinite(limit.value):
        return "no size"
    lengths = (1e3, "mm") if limit.value >= 1e-3 else (1e6, "µm")
    currents = (1.0, "A") if limit.value >= 1.0 else (1e3, "mA")
    scale, unit = {
        "1": (100.0, "%"),
        "s": (1e3, "ms"),
        "rad": (180 / math.pi, "deg"),
        "m": lengths,
        "A": currents,
    }.get(limit.unit, (1.0, limit.unit))
    return f"{limit.value * scale:.2g}{NBSP}{unit}"


def _limit_rows(diag: Diagnosis) -> list[tuple[str, str, str, str]]:
    """(effect, size parameter, size below which this log cannot show it, the test that holds it
    back there) of every effect with a finite limit."""
    words = {
        "z": "significance",
        "gain": "held-out gain",
        "quarter": "held-out quarter",
        "size": "size",
        "physics": "plausibility",
    }
    return [
        (
            plain(d.name),
            d.parameter.replace("_", " "),
            limit_size(d),
            words.get(d.binding, d.binding) + (" (thrust current)" if d.side else ""),
        )
        for d in diag.detection_limits
        if math.isfinite(d.value)
    ]


def _limit_notes(diag: Diagnosis) -> list[str]:
    """The table's note, and the effects no size would show, with why."""
    never = [d for d in diag.detection_limits if not math.isfinite(d.value)]
    return [_LIMIT_NOTE] + [f"{plain(d.name).capitalize()}: {d.reason}." for d in never]


_LIMIT_NOTE = (
    "Each effect the log did not show was put into it at growing sizes (along its first parameter, of "
    "either physical sign, computed from the currents that make the refitted model produce the measured "
    "accelerations) and judged by the selection's tests of what a log shows: held-out gain, its "
    "significance and the size of the change. The tests of separability, plausibility and the rivals "
    "can still refuse an effect larger than its limit, and in closed loop the regulator's own response "
    "hides part of a real effect. On the independent generator's logs real effects were claimed from 0.8 to "
    "1.6 times these limits on a quiet rig; on one whose logged currents are 20 times noisier, "
    "mostly from 1 to 3 times, up to 16 times (bench/README). Where a limit's test is marked "
    "(thrust current), the effect was judged predicting the logged thrust current from the measured "
    "motion, as the diagnosis judges effects of that current when its logging error dominates."
)


def _control_paragraph(study: CompensationStudy) -> str:
    """The FL regulator's tracking error before and after compensating the found effects."""
    imp = improvement(study)
    return (
        f"In control ({study.scenario}, FL regulator, plant: {study.plant}): mean tracking error "
        f"vertical {study.before.mean_error[0] * M_TO_MM:.3f} → {study.after.mean_error[0] * M_TO_MM:.3f} mm "
        f"(÷ {imp[0]:.2f}), horizontal {study.before.mean_error[1] * M_TO_MM:.3f} → "
        f"{study.after.mean_error[1] * M_TO_MM:.3f} mm (÷ {imp[1]:.2f}); compensated: "
        f"{', '.join(plain(n) for n in study.compensated) or 'none'}"
        + (
            f"; left in the plant, not compensated (they depend on the currents): "
            f"{', '.join(plain(n) for n in study.not_compensated)}"
            if study.not_compensated
            else ""
        )
        + "."
    )


def _effect_rows(diag: Diagnosis) -> list[tuple[str, str, str, str]]:
    """(effect, parameter, value ± standard error, unit) of every found effect's parameters."""
    rows = []
    for e in diag.effects:
        for k, v in e.parameters.items():
            if k.startswith("rms_force") or (v.unit == "m" and k in _POSITION_PARAMETERS):
                continue
            rows.append((plain(e.name), k.replace("_", " "), _fmt(v.value, v.stderr), v.unit))
    return rows


def _held_notes(diag: Diagnosis) -> list[str]:
    """What a friction's held force is, when one is in the table: the check its claim passed."""
    if not any("held_force" in e.parameters for e in diag.effects):
        return []
    return [
        "Held force: what the guides hold while the axis sticks (nine samples in ten less); a friction is "
        f"claimed only where it is at most {HELD_BEYOND_BREAKAWAY:g} times its breakaway force (static "
        "friction holds no more than the force it breaks away at)."
    ]


def _variant_notes(diag: Diagnosis) -> list[str]:
    """What each found effect's model-form variants range over (its fixed hyper-parameter)."""
    return [
        f"{plain(e.name).capitalize()}: model-form variants over {e.candidate.term.variant_note}."
        for e in diag.effects
        if e.candidate.term.variant_note
    ]


def _constant_rows(diag: Diagnosis) -> list[tuple[str, str, str, str]]:
    return [
        (
            k,
            _fmt(diag.constants_base[k].value, diag.constants_base[k].stderr),
            _fmt(v.value, v.stderr),
            v.unit,
        )
        for k, v in diag.constants_final.items()
    ]


def _verdict_rows(diag: Diagnosis) -> list[tuple[str, str, str, str]]:
    """(candidate, verdict, first-step held-out gain [%], reason), largest first-step gain first."""
    first = diag.selection.steps[0].judgements if diag.selection.steps else diag.selection.last
    rows = []
    for j in sorted(diag.selection.last.values(), key=lambda j: best_first(first.get(j.name, j))):
        reason = "\n".join(textwrap.wrap(j.reason or "—", 60))
        at_first = first.get(j.name, j)
        if at_first.dominated_by_current_errors:  # a nearly singular fit: its gain means nothing
            gain = "—"
        else:
            gain = f"{at_first.gain * 100:.1f}" if at_first.gain >= -1.0 else "< -100"
        rows.append((plain(j.name), j.verdict, gain, reason))
    return rows


_PARAMETER_NOTE = (
    "Standard errors: long-run covariance of the joint fit with the base constants, plus half the spread "
    "over the effect's model-form variants and 1 % for the differentiator's calibration, in quadrature."
)
_VERDICT_NOTE = (
    "Each candidate is fitted jointly with C1..C4 and the effects chosen before it. It is claimed only if "
    "it lowers the held-out error significantly (z ≥ 3 on the 0.5 s blocks of the held-out quarter and of "
    "the training data held out in turn, with a long-run standard error), "
    "its coefficients pass a Wald test (p < 1e-4), it changes the prediction by more than the "
    "2.25e-3 m/s² a 15 rad/s loop turns into one encoder count, it is separable from the constants and "
    "the other effects (variance inflation ≤ 100) and it is physically plausible."
)


Part = tuple[str, Sequence[Text | Table | Plot]]


def _plan(parts: Sequence[Part]):
    """(key, pages) for ``parts`` (heading, blocks), the blocks in order: of every way to cut them into
    pages that fit, the one with the fewest near-empty pages, then the fewest pages, then the fewest
    parts cut in two, then the fullest emptiest page (the key compares plans)."""
    blocks = [(j, k, block) for j, (_, bl) in enumerate(parts) for k, block in enumerate(bl)]
    heights = [block_height(b) for *_, b in blocks]
    room, heading = page_room(), 0.032  # the page's heading takes 0.032 of its fill
    n = len(blocks)
    best, best_key = [(i, i + 1) for i in range(n)], (math.inf,)  # one block a page if none fits
    for mask in range(1 << max(0, n - 1)):
        cuts = [0, *(i + 1 for i in range(n - 1) if mask >> i & 1), n]
        pages = list(itertools.pairwise(cuts))
        fills = [heading + sum(heights[a:b]) for a, b in pages]
        if max(fills) > room + heading:
            continue
        inside = sum(1 for a, _ in pages[1:] if blocks[a][1] > 0)
        key = (sum(f < MIN_FILL for f in fills), len(pages), inside, -min(fills))
        if key < best_key:
            best, best_key = pages, key
    return best_key, [
        (parts[blocks[a][0]][0] + ("" if blocks[a][1] == 0 else " (continued)"), [b for *_, b in blocks[a:b]])
        for a, b in best
    ]


def _pack(pdf: PdfReport, orders: Sequence[Sequence[Part]]) -> None:
    """The pages of the best plan (:func:`_plan`) of any of ``orders`` (the same parts in orders a
    reader can follow); a page is headed by the part of its first block ("(continued)" when that
    part began on an earlier page)."""
    _, pages = min((_plan(parts) for parts in orders), key=lambda plan: plan[0])
    for heading, blocks in pages:
        pdf.add_page(heading, blocks)


def write_diagnosis_report(
    path: str | os.PathLike,
    diag: Diagnosis,
    *,
    study: CompensationStudy | None = None,
    truth_rows: Sequence[Sequence[str]] = (),
    title: str = "maglev_oc — closing the loop with measured data",
    subtitle: str = "maglev-oc diagnose",
    preamble: Sequence[str] = (),
    epilogue: Sequence[str] = (),
    timings: dict[str, float] | None = None,
) -> ReportContents:
    """Write the PDF (atomically).

    Parameters
    ----------
    path : path-like
        Where the PDF goes.
    diag : Diagnosis
        The diagnosis to report.
    study : CompensationStudy, optional
        The FL regulator before and after compensating the found effects.
    truth_rows : sequence of rows
        For a log whose truth is known, rows (what, true size, found, verdict) of the scorecard.
    title, subtitle : str
        The report's title and the line under it.
    preamble, epilogue : sequence of str
        Paragraphs before and after the findings on page 2 (what the log is, how it was made).
    timings : dict, optional
        [s] Wall times of steps outside the diagnosis (the log's simulation, the closed loop), for
        the appendix.

    Returns
    -------
    ReportContents
        What the report says, section by section.
    """
    with PdfReport(path, title, subtitle=subtitle) as pdf:
        pdf.add_page(
            "Scorecard: what the log's residual is made of",
            [scorecard_table(diag, study, truth_rows), Plot(plots.key_plot(diag, study, KEY_PANELS), 0.34)],
            first_page=True,
        )
        words = [*preamble, *_finding_paragraphs(diag), *epilogue]
        found: list[Text | Table | Plot] = list(_text_blocks(words))
        if diag.effects:
            found.append(
                Table(
                    "The found effects' parameters",
                    ("effect", "parameter", "value ± standard error", "unit"),
                    _effect_rows(diag),
                    notes=[_PARAMETER_NOTE, *_variant_notes(diag), *_held_notes(diag)],
                )
            )
        constants = Table(
            "Lumped constants",
            ("constant", "base model alone", "refitted with the effects", "unit"),
            _constant_rows(diag),
            notes=[*_shared_force_notes(diag), *_noise_scale_notes(diag)],
        )
        verdicts = Table(
            "Every candidate and its verdict",
            ("candidate", "verdict", "first-step\nheld-out gain [%]", "reason"),
            _verdict_rows(diag),
            notes=[_VERDICT_NOTE],
            font_size=7.5,
        )
        limits = Table(
            "What this log could not have shown",
            ("effect", "size of", "not shown below", "test that holds it back"),
            _limit_rows(diag),
            notes=_limit_notes(diag),
            font_size=7.5,
        )
        n_panels = len(plots.panels(diag))
        held_out: list[Text | Table | Plot] = []
        if n_panels and (study is None or n_panels > KEY_PANELS):
            held_out.append(Plot(plots.effects_plot(diag), 0.28 * max(1, -(-n_panels // 3))))
        held_out.append(Plot(plots.timeseries_plot(diag), 0.36))
        if study is not None:
            held_out += [Text([_control_paragraph(study)]), Plot(plots.compensation_plot(study), 0.42)]
        found_part: Part = ("What was found, in words", [*found, constants])
        residual_part: Part = (
            "Where the base model's residual lives",
            [Plot(plots.spectrum_plot(diag), 0.3), Plot(plots.dependence_plot(diag), 0.56)],
        )
        held_part: Part = (
            "Held-out data" + (", and the closed loop before and after" if study else ""),
            held_out,
        )
        # a long library (waviness candidates, long reasons) runs over a page: in parts the plan places
        verdict_part: Part = ("Every candidate and its verdict", split_table(verdicts))
        parts = [found_part, residual_part, held_part, verdict_part]
        # what the log could not have shown: after the findings or after the verdicts it qualifies
        unseen: list[Part] = (
            [("What this log could not have shown", split_table(limits))] if diag.detection_limits else []
        )
        checks = _validation_part(diag)
        if checks is not None:
            parts.append(checks)
        _pack(
            pdf,
            [
                [*parts, *unseen],
                [found_part, *unseen, *parts[1:]],
                [found_part, verdict_part, *unseen, residual_part, held_part, *parts[4:]],
                [found_part, *unseen, verdict_part, residual_part, held_part, *parts[4:]],
            ],
        )
        times = {
            **(timings or {}),
            **{f"diagnosis: {k.replace('_', ' ')}": v for k, v in diag.timings.items()},
        }
        settings = Table(
            "Settings of the diagnosis",
            ("setting", "value", "setting", "value"),
            _two_columns(
                [
                    (_SETTING_WORDS.get(k, k.replace("_", " ")), _wrap(str(v), 34))
                    for k, v in _flat(_compact_noise_scale(diag.settings)).items()
                ]
            ),
            font_size=7.5,  # every selection threshold: about 45 settings
        )
        wall = Table(
            "Wall times [s]",
            ("step", "wall time [s]"),
            [(k, f"{v:.2f}") for k, v in times.items()],
            font_size=7.5,  # a closed-loop study's steps beside the diagnosis's: about 20 rows
        )
        # on a second page when both do not fit one (a closed-loop study adds its own times)
        _pack(pdf, [[("Appendix: wall times and settings", [wall, *split_table(settings)])]])
    return pdf.contents


def _shared_force_notes(diag: Diagnosis) -> list[str]:
    """That the refitted constants carry the force along the track of a pair the log does not tell
    apart (``pipeline._with_shared_force``), when they do."""
    return [
        f"Refitted beside the force along the track that {plain(one)} and {plain(both)} both explain: "
        "the log does not tell which of the two it is (neither is claimed), but without that force "
        "the fit would read it in the constants."
        for one, both in shared_along_the_track(diag.not_separable)
    ]


def _noise_scale_notes(diag: Diagnosis) -> list[str]:
    """What the constants' errors-in-variables correction took the logged currents' error to be
    (:mod:`maglev_oc.regression.noise_scale`), when it was not the noise floor's estimate."""
    scale = diag.settings.get("current_noise_scale")
    if not isinstance(scale, dict) or scale.get("scale", 1.0) == 1.0:
        return []
    lo, hi = scale.get("interval") or (None, None)
    span = f" (95 % range {lo:.2f}-{hi:.2f})" if lo is not None and hi is not None else ""
    return [
        f"The logged currents' error is taken at {scale['scale']:.2f}{span} times their noise floor's "
        "estimate: there the constants fitted on a 2 Hz band and on the diagnosis's own agree "
        f"(disagreement {scale['misfit_best']:.1f} against {scale['misfit_at_one']:.1f} at 1, sum of "
        "squared standardized differences)."
    ]


def _two_columns(pairs: list[tuple[str, str]]) -> list[tuple[str, str, str, str]]:
    """(name, value) pairs as rows of two pairs, the first half down the left columns and the rest
    down the right ones (in reading order, half the height)."""
    half = -(-len(pairs) // 2)
    right = pairs[half:]
    return [(*pairs[k], *(right[k] if k < len(right) else ("", ""))) for k in range(half)]


def _compact_noise_scale(settings: dict) -> dict:
    """``settings`` with the noise scale's record as one line (the appendix's table)."""
    scale = settings.get("current_noise_scale")
    if not isinstance(scale, dict):
        return settings
    if scale.get("best") is None:  # not looked for (effects found, or no narrow band)
        return {
            **settings,
            "current_noise_scale": f"{scale['scale']:.3g} (the floor's estimate; not calibrated)",
        }
    if scale["scale"] != 1.0:
        verdict = "agree"
    elif scale["misfit_best"] <= (scale.get("agreement_threshold") or -math.inf):
        verdict = "agree, in a range from 0 (not taken),"
    else:
        verdict = "agree at no level; least"
    line = (
        f"{scale['scale']:.3g} (bands {verdict} at {scale['best']:.3g}: misfit "
        f"{scale['misfit_best']:.2f}, against {scale['misfit_at_one']:.2f} at 1)"
    )
    return {**settings, "current_noise_scale": line}


def _validation_part(diag: Diagnosis) -> Part | None:
    """The validation page: residual correlations with their bands and the fit % table, base model
    and model with the effects, on the held-out block."""
    runs = {
        "base model": diag.validation_before,
        "with the effects": diag.validation_after,
    }
    runs = {k: v for k, v in runs.items() if v is not None}
    if not runs:
        return None
    return (
        "Validation on the held-out block: residual whiteness and fit",
        validation_plots.page_blocks(runs),
    )


_SETTING_WORDS = {
    "holdout_fraction": "held-out share of each log",
    "bandwidth_hz": "differentiator band [Hz]",
    "sg_windows": "Savitzky-Golay windows [samples]",
    "edge_samples": "filter edge left out [samples]",
    "logging_error_share": "share of the current error from logging",
    "max_rate_hz": "highest sample rate kept [Hz]",
    "control_rate_hz": "control loop's rate [Hz]",
    "current_noise_scale": "current error's scale (two bands)",
}


def _flat(settings: dict, prefix: str = "") -> dict[str, object]:
    """Nested settings as one level: {"selection": {"min_z": 3}} -> {"selection, min_z": 3}; numbers
    to 6 significant digits."""
    out: dict[str, object] = {}
    for k, v in settings.items():
        if isinstance(v, dict):
            out |= _flat(v, f"{prefix}{k}, ")
        elif isinstance(v, list | tuple | np.ndarray):
            out[f"{prefix}{k}"] = ", ".join(
                f"{x:.6g}" if isinstance(x, float) else str(x) for x in np.ravel(v)
            )
        else:
            out[f"{prefix}{k}"] = f"{v:.6g}" if isinstance(v, float) else v
    return out
