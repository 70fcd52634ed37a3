"""The diagnosis report: what the log's residual is made of, and what adding it is worth.

Page 1 says what was found, in plain words with sizes and uncertainties, what could not be told
apart from the constants on this log (and which experiment would), what no effect explains, and
the held-out error before and after; when the truth is known (a twin's log) a table of found
against true follows. Then every candidate's verdict with its reason, the constants, and the
figures.
"""

from __future__ import annotations

import math
import os
import textwrap
from collections.abc import Sequence

from maglev_oc.diagnosis.feedback import CompensationStudy, improvement
from maglev_oc.diagnosis.pipeline import ERROR_METRIC, Diagnosis
from maglev_oc.reporting import diagnosis_plots as plots
from maglev_oc.reporting.diagnosis_plots import plain
from maglev_oc.reporting.pdf import PdfReport, ReportContents
from maglev_oc.units import M_TO_UM

__all__ = ["write_diagnosis_report"]


def _fmt(value: float, err: float) -> str:
    if not math.isfinite(err) or err == 0:
        return f"{value:.4g}"
    return f"{value:.4g} ± {err:.2g}"


def _summary_paragraphs(diag: Diagnosis) -> list[str]:
    """The conclusions, in plain words (page 1)."""
    eb, ea = diag.error_before, diag.error_after
    out = []
    if diag.effects:
        out.append("Found (most important first):")
        for k, e in enumerate(diag.effects, 1):
            out.append(
                f"{k}. {plain(e.name).capitalize()} — {e.finding} It lowers the held-out error by "
                f"{e.gain:.0%} (z = {e.z:.1f}; chosen in {e.confidence:.0%} of bootstrap resamples)."
            )
    else:
        out.append("No missing effect found: the papers' model, refitted, explains the log to its noise.")
    if diag.not_separable:
        out.append(
            "Real in the fit but not separable on this log (not claimed): "
            + "; ".join(
                f"{plain(n.name)}, confounded with {', '.join(n.confounded_with)} — {n.experiment}"
                for n in diag.not_separable
            )
            + "."
        )
    if diag.unexplained:
        out.append(
            "Not explained by any effect of the library: " + " ".join(u.description for u in diag.unexplained)
        )
    out.append(
        "Held-out error before → after:  "
        + ";  ".join(f"{a} {b:.3g} → {ea[a]:.3g} m/s²" for a, b in eb.items() if math.isfinite(b))
        + f"  ({ERROR_METRIC})."
    )
    ob, oa = diag.output_error_before, diag.output_error_after
    out.append(
        "Position error of the model simulated over 50 ms from the estimated state (held out), "
        "before → after:  "
        + ";  ".join(
            f"{a} {b * M_TO_UM:.1f} → {oa[a] * M_TO_UM:.1f} µm" for a, b in ob.items() if math.isfinite(b)
        )
        + "."
    )
    return out


def write_diagnosis_report(
    path: str | os.PathLike,
    diag: Diagnosis,
    *,
    study: CompensationStudy | None = None,
    truth_rows: Sequence[Sequence[str]] = (),
    title: str = "maglev_oc — closing the loop with measured data",
    preamble: Sequence[str] = (),
    epilogue: Sequence[str] = (),
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
        For a log whose truth is known, rows (true effect, true size, found as, found size) for
        the found-against-true table.
    title, preamble, epilogue
        The report's title; paragraphs before and after the conclusions on page 1.

    Returns
    -------
    ReportContents
        What the report says, section by section.
    """
    summary = [*preamble, *_summary_paragraphs(diag)]
    if study is not None:
        summary.append(_control_paragraph(study))
    summary.extend(epilogue)
    summary.append(
        f"Logs: {', '.join(diag.sources)}; the last {diag.settings['holdout_fraction']:.0%} of each is held "
        f"out ({int(diag.holdout.sum())} samples; {int(diag.train.sum())} fitted)."
    )
    with PdfReport(path, title, subtitle="maglev-oc diagnose") as pdf:
        pdf.add_text("What the log shows", summary, first_page=True)
        if truth_rows:
            pdf.add_table(
                "Found against true (the log's truth is known)",
                ["true effect", "true size", "found as", "found size"],
                list(truth_rows),
            )
        _effects_page(pdf, diag)
        _verdicts_page(pdf, diag)
        pdf.add_table(
            "Lumped constants",
            ["constant", "base model alone", "refitted with the effects", "unit"],
            _constant_rows(diag),
        )
        pdf.add_figure(plots.spectrum_figure(diag))
        pdf.add_figure(plots.dependence_figure(diag))
        for e in diag.effects:
            pdf.add_figure(plots.before_after_figure(diag, e))
        pdf.add_figure(plots.timeseries_figure(diag))
        if study is not None:
            pdf.add_figure(plots.compensation_figure(study))
        pdf.add_text(
            "Timings",
            ["Wall time of each step [s]: " + ", ".join(f"{k} {v:.2f}" for k, v in diag.timings.items())],
        )
    return pdf.contents


def _control_paragraph(study: CompensationStudy) -> str:
    """The FL regulator's tracking error before and after compensating the found effects."""
    imp = improvement(study)
    return (
        f"In control ({study.scenario}, FL regulator, plant: {study.plant}): mean tracking error "
        f"vertical {study.before.mean_error[0] * 1e3:.3f} → {study.after.mean_error[0] * 1e3:.3f} mm "
        f"(÷ {imp[0]:.2f}), horizontal {study.before.mean_error[1] * 1e3:.3f} → "
        f"{study.after.mean_error[1] * 1e3:.3f} mm (÷ {imp[1]:.2f}); compensated: "
        f"{', '.join(plain(n) for n in study.compensated) or 'none'}"
        + (
            f"; left in the plant, not compensated (they depend on the currents): "
            f"{', '.join(plain(n) for n in study.not_compensated)}"
            if study.not_compensated
            else ""
        )
        + "."
    )


_POSITION_PARAMETERS = ("at_gap", "period", "low_end_position", "high_end_position", "width")
"""Parameters [m] that say where an effect acts, not how large it is (left out of the table)."""


def _effect_rows(diag: Diagnosis) -> list[tuple[str, str, str, str]]:
    """(effect, parameter, value ± standard error, unit) of every found effect's size parameters."""
    rows = []
    for e in diag.effects:
        for k, v in e.parameters.items():
            if k.startswith("rms_force") or (v.unit == "m" and k in _POSITION_PARAMETERS):
                continue
            rows.append((plain(e.name), k.replace("_", " "), _fmt(v.value, v.stderr), v.unit))
    return rows


def _effects_page(pdf: PdfReport, diag: Diagnosis) -> None:
    rows = _effect_rows(diag)
    if not rows:
        return
    pdf.add_table(
        "The effects' parameters",
        ["effect", "parameter", "value ± standard error", "unit"],
        rows,
        notes=[
            "Standard errors: long-run covariance of the joint fit with the base constants, "
            "plus half "
            "the spread over the effect's model-form variants and 1 % for the differentiator's "
            "calibration, in quadrature."
        ],
    )


def _verdict_rows(diag: Diagnosis) -> list[tuple[str, str, str, str]]:
    """(candidate, verdict, first-step held-out gain [%], reason), largest first-step gain first."""
    first = diag.selection.steps[0].judgements if diag.selection.steps else diag.selection.last
    rows = []
    for j in sorted(diag.selection.last.values(), key=lambda j: -first.get(j.name, j).gain):
        reason = "\n".join(textwrap.wrap(j.reason or "—", 62))
        rows.append((plain(j.name), j.verdict, f"{first.get(j.name, j).gain * 100:.1f}", reason))
    return rows


def _verdicts_page(pdf: PdfReport, diag: Diagnosis) -> None:
    pdf.add_table(
        "Every candidate and its verdict",
        ["candidate", "verdict", "first-step\nheld-out gain [%]", "reason"],
        _verdict_rows(diag),
        notes=[
            "Each candidate is fitted jointly with C1..C4 and the effects chosen before it. It "
            "is claimed "
            "only if it lowers the held-out error significantly (z >= 3 on 0.5 s blocks with a long-run "
            "standard error), its coefficients pass a Wald test (p < 1e-4), it changes the prediction by "
            "more than the 2.25e-3 m/s² a 15 rad/s loop turns into one encoder count, it is "
            "separable from "
            "the constants and the other effects (variance inflation <= 100) and it is physically "
            "plausible."
        ],
        font_size=7,
    )


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
