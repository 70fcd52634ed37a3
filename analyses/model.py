"""Model report: equilibria, coefficients, open-loop poles, field fit, and the papers' gains.

python analyses/model.py [--out reports/model.pdf] [--params stage.json]
"""

from __future__ import annotations

from pathlib import Path

from maglev_oc.control.gains import GainCheck, check_paper_gains
from maglev_oc.model.stage import StageModel
from maglev_oc.model.summary import ModelSummary, equilibrium_table_rows, summarize_model
from maglev_oc.reporting import model_plots as plots
from maglev_oc.reporting.pdf import PdfReport, ReportContents

__all__ = ["ORDER", "REPORT", "build", "main"]

REPORT = "model.pdf"
ORDER = 10
TITLE = "maglev_oc — stage model"


def build(out: Path, model: StageModel) -> ReportContents:
    """Summarize ``model``, check the papers' gains, and write the report to ``out``."""
    summary = summarize_model(model)
    gain_checks = check_paper_gains()
    with PdfReport(out, TITLE, subtitle="reports/model.pdf from analyses/model.py") as pdf:
        pdf.add_text("Model and constants", _intro(model, summary), first_page=True)
        _equilibrium_page(pdf, summary)
        pdf.add_figure(plots.equilibrium_figure(summary))
        pdf.add_figure(plots.coefficients_figure(summary))
        pdf.add_figure(plots.open_loop_figure(summary))
        pdf.add_figure(plots.field_fit_figure(summary))
        pdf.add_figure(plots.feasible_acceleration_figure(summary))
        _gains_page(pdf, gain_checks)
        pdf.add_figure(plots.gain_poles_figure(gain_checks))
    return pdf.contents


def _intro(model: StageModel, s: ModelSummary) -> list[str]:
    """The first page: state and input, the constants identified and from physics, the field fit."""
    c, phys = model.constants, s.physical_constants
    ratios = [a / b for a, b in zip(c.as_array(), phys.as_array(), strict=True)]
    return [
        "State x = (air gap [m], gap rate [m/s], horizontal position [m], its rate [m/s]); input "
        "u = (i_q, i_d) [A]. Model of SPEC 1 (eq. (2) of 000, eq. (3) of 002) with Carter's "
        f"coefficient, the closed-form PM field and lumped constants from: {c.source}.",
        f"Winding factor from 002's formula: k_w1 = {s.winding_factor:.4f}. "
        f"Field model used here: {model.field_model}.",
        "Lumped constants, identified (Table III of 000) next to the values 002's formulas give "
        "from Table I with sigma_m = H_c (SPEC 1's readings: C2 with 4 M_v, C3 > 0):\n"
        + "\n".join(
            f"   {k}:  identified {getattr(c, k):10.4g}    physical {getattr(phys, k):10.4g}"
            f"    ratio {getattr(c, k) / getattr(phys, k):6.3f}"
            for k in ("C1", "C2", "C3", "C4")
        ),
        "The physical values miss the identified ones by up to a factor of "
        f"{max(max(r, 1 / r) for r in ratios):.3g}: the magnetic-charge model with "
        "sigma_m = H_c and ideal geometry does not predict this stage's forces, which is why "
        "the papers identify C1..C4 (000 Sec. IV) and every controller here uses identified "
        "constants.",
        (
            f"Zero-current gap (i_d = 0 holds the mover): {s.zero_current_gap * 1e3:.2f} mm."
            if s.zero_current_gap is not None
            else "No gap in 5-35 mm is held with zero current."
        ),
        "12th-degree polynomial fit of B over 5-35 mm (the papers' approach), refitted here to "
        f"the closed form: max error {s.field_fit.max_error * 1e6:.3g} µT "
        f"({s.field_fit.max_relative_error * 100:.2g} %).",
    ]


def _equilibrium_page(pdf: PdfReport, s: ModelSummary) -> None:
    pdf.add_table(
        "Equilibrium currents (u1 = 0)",
        ["gap [mm]", "i_d [A]", "amplifier", "vertical open-loop pole [1/s]"],
        equilibrium_table_rows(s),
        notes=[
            "SPEC 1 expects about +5.3 A at 10 mm, +3.3 A at 15 mm, +1.5 A at 20 mm and "
            "-0.2 A at 25 mm (tests hold these to 0.05 A).",
            "Amplifier: LCAM limits 7 A continuous, 9 A peak (002 Sec. 4).",
        ],
    )


def _gain_rows(gain_checks: list[GainCheck]) -> list[tuple[str, ...]]:
    """Five rows per gain vector: computed and printed entry, their difference, the poles."""
    rows = []
    for chk in gain_checks:
        for k in range(5):
            rows.append(
                (
                    chk.paper.name if k == 0 else "",
                    f"k{k + 1}",
                    f"{chk.computed[k]:.2f}",
                    f"{chk.paper.printed[k]:.0f}",
                    f"{chk.abs_difference[k]:.2f}",
                    f"{chk.rel_difference[k] * 100:.2f} %",
                    f"{chk.paper.poles[k]:.4g}".replace("+0j", "").strip("()"),
                    f"{chk.printed_poles[k]:.4g}".strip("()"),
                )
            )
    return rows


def _gains_page(pdf: PdfReport, gain_checks: list[GainCheck]) -> None:
    pdf.add_table(
        "Output-regulator gains by pole placement (omega0 = 1.5 pi)",
        [
            "gains",
            "entry",
            "computed",
            "printed",
            "|diff|",
            "rel. diff",
            "design pole",
            "pole of printed K",
        ],
        _gain_rows(gain_checks),
        notes=[
            "Augmented axis z = (e, e', xi1, xi2, xi3), v = K z (002 eqs. (21)-(25)).",
            "The printed integers are the computed gains truncated; with five poles "
            "clustered within a few 1/s the characteristic polynomial is sensitive to "
            "k1 and k4, so truncating moves the poles by several 1/s (right column): "
            "K_h's real poles -9..-13 become two complex pairs.",
            "K_v_retuned: its poles are printed to one decimal in 002, so the recomputed "
            "gains differ from the printed ones by up to a few percent.",
        ],
    )


def main(argv: list[str] | None = None) -> int:
    from maglev_oc.analyses import analysis_parser

    from maglev_oc.model.loading import load_model

    parser = analysis_parser(__doc__, REPORT)
    args = parser.parse_args(argv)
    print(f"wrote {build(args.out, load_model(args.params)).path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
