"""Figures and pages of the identification reports. Each figure function takes computed results
(:mod:`maglev_oc.identification`) and returns a Figure; nothing here computes a model.

:func:`write_outcome_report` is the PDF of ``maglev-oc identify --report``.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.figure import Figure

from maglev_oc.data.logs import Log
from maglev_oc.identification.layout import CONSTANT_NAMES, UNITS
from maglev_oc.identification.result import FitResult, NpfsiResult
from maglev_oc.identification.verification import EquilibriumComparison, ParabolaComparison, ParabolaFit
from maglev_oc.reporting.pdf import PdfReport, ReportContents, new_figure
from maglev_oc.units import M_TO_MM, M_TO_UM

__all__ = [
    "EPS_COLORS",
    "cogging_figure",
    "coverage_figure",
    "equilibrium_figure",
    "l1_comparison_figure",
    "npfsi_convergence_figure",
    "parabola_figure",
    "residuals_figure",
    "single_shooting_figure",
    "text_figure",
    "write_outcome_report",
]

EPS_COLORS = {0.001: "tab:blue", 0.01: "tab:green", 0.05: "tab:red"}


def _thin(n: int, max_points: int = 2500) -> slice:
    """Every k-th sample so that a line has at most ``max_points`` (smooth curves only)."""
    return slice(None, None, max(1, -(-n // max_points)))


def _eps_color(eps: float) -> str:
    for key, color in EPS_COLORS.items():
        if np.isclose(eps, key):
            return color
    return "tab:purple"


def text_figure(title: str, blocks: Sequence[str], *, font_size: float = 6.8) -> Figure:
    """A page of preformatted text (fit reports) in a monospaced font, lines kept as they are."""
    from maglev_oc.reporting.pdf import PAGE_SIZE

    fig = Figure(figsize=PAGE_SIZE)
    fig.text(0.06, 0.95, title, fontsize=13, weight="bold", va="top")
    fig.text(0.04, 0.91, "\n\n".join(blocks), fontsize=font_size, family="monospace", va="top")
    return fig


# --- least squares -------------------------------------------------------------------------------
def residuals_figure(fit: FitResult, log: Log, *, window: tuple[float, float] = (10.0, 15.0)) -> Figure:
    """Residuals of a fit along a 5 s stretch of one log, and their autocorrelation."""
    fig = new_figure((8.27, 6.4))
    axes = fig.subplots(2, 2, width_ratios=(2.2, 1))
    r = fit.residuals[0]
    t = log.t - log.t[0]
    sel = (t >= window[0]) & (t < window[1])
    scale, unit = (M_TO_UM, "µm") if fit.residual_unit == "m" else (1.0, "m/s²")
    for row, (axis_name, color) in enumerate((("vertical", "tab:blue"), ("horizontal", "tab:orange"))):
        ax = axes[row, 0]
        ax.plot(t[sel], r[row, sel] * scale, color=color, lw=0.6)
        ax.set_ylabel(f"{axis_name} residual [{unit}]")
        ax.grid(alpha=0.3)
        ax.set_title(
            f"{axis_name}: RMS {fit.residual_rms[axis_name] * scale:.3g} {unit} (whole log)", fontsize=9
        )
        ok = np.isfinite(r[row])
        x = r[row, ok] - np.mean(r[row, ok])
        lags = np.arange(0, 200)
        acf = np.array([np.dot(x[: x.size - k], x[k:]) for k in lags]) / np.dot(x, x)
        ax2 = axes[row, 1]
        ax2.plot(lags * log.sample_time * 1e3, acf, color=color)
        ax2.axhline(0, color="0.5", lw=0.6)
        ax2.set_ylabel("autocorrelation [-]")
        ax2.grid(alpha=0.3)
    axes[1, 0].set_xlabel("time [s]")
    axes[1, 1].set_xlabel("lag [ms]")
    title = (
        "equation error (filtered accelerations)"
        if fit.method == "equation_error"
        else "output error (positions)"
    )
    fig.suptitle(f"Residuals of the {title}", fontsize=11)
    return fig


def single_shooting_figure(log: Log, open_loop: np.ndarray, output_error: FitResult) -> Figure:
    """The model driven open loop by the logged currents (single shooting) leaves the data;
    the multiple-shooting fit stays within a few micrometres."""
    fig = new_figure((8.27, 5.2))
    ax1, ax2 = fig.subplots(1, 2)
    k = open_loop.shape[1]
    t = log.t[:k] - log.t[0]
    ax1.plot(t, log.x[0, :k] * M_TO_MM, "k.", ms=1.5, label="encoder reading x1")
    ax1.plot(t, open_loop[0] * M_TO_MM, "tab:red", lw=1.2, label="model, true constants, open loop")
    ax1.set_xlabel("time [s]")
    ax1.set_ylabel("air gap [mm]")
    ax1.set_title("Single shooting: the unstable gap diverges", fontsize=9)
    ax1.legend(fontsize=8)
    ax1.grid(alpha=0.3)
    finite = np.isfinite(open_loop[0])
    lo = float(np.nanmin(log.x[0, :k])) * M_TO_MM - 1
    hi = float(np.nanmax(log.x[0, :k])) * M_TO_MM + 1
    ax1.set_ylim(max(lo, 0), hi)
    if not np.all(finite):
        ax1.axvline(t[np.argmin(finite)], color="tab:red", ls=":", lw=0.8)
    r = output_error.residuals[0]
    n = min(r.shape[1], 1000)
    tt = log.t[:n] - log.t[0]
    ax2.plot(tt, r[0, :n] * M_TO_UM, lw=0.7, label="vertical")
    ax2.plot(tt, r[1, :n] * M_TO_UM, lw=0.7, label="horizontal")
    seg = output_error.settings.get("segment_duration_s", 0.05)
    for s in np.arange(0, tt[-1], seg):
        ax2.axvline(s, color="0.85", lw=0.5, zorder=0)
    ax2.set_xlabel("time [s]")
    ax2.set_ylabel("output residual [µm]")
    ax2.set_title(f"Multiple shooting ({seg * 1e3:.0f} ms segments): residuals", fontsize=9)
    ax2.legend(fontsize=8)
    ax2.grid(alpha=0.3)
    return fig


def coverage_figure(names: Sequence[str], z: np.ndarray, z_naive: np.ndarray, duration: float) -> Figure:
    """z-scores (estimate - truth) / stderr of repeated fits, long-run vs plain standard errors."""
    fig = new_figure((8.27, 4.6))
    ax = fig.subplots()
    x = np.arange(len(names))
    for k in range(z.shape[0]):
        ax.plot(
            x - 0.1,
            z[k],
            "o",
            color="tab:blue",
            ms=4,
            label="long-run (HAC) standard errors" if k == 0 else None,
        )
        ax.plot(
            x + 0.1,
            z_naive[k],
            "s",
            color="tab:gray",
            ms=3.5,
            mfc="none",
            label="plain s²(J'J)⁻¹" if k == 0 else None,
        )
    for lim in (-2, 2):
        ax.axhline(lim, color="tab:red", ls="--", lw=0.8)
    ax.axhline(0, color="0.5", lw=0.6)
    ax.set_xticks(x, list(names))
    ax.set_ylabel("(estimate - truth) / standard error [-]")
    ax.set_title(
        f"Equation error on {z.shape[0]} twin runs of {duration:g} s: do the standard errors cover the "
        "truth?",
        fontsize=9,
    )
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    return fig


# --- NPFSI --------------------------------------------------------------------------------------------
def npfsi_convergence_figure(
    runs: Sequence[NpfsiResult],
    truth: Mapping[str, float] | None = None,
    *,
    title: str = "",
    band_pct: Mapping[str, float] | None = None,
) -> Figure:
    """theta_hat(t) of each run (one per eps), one panel per parameter, truth dashed."""
    names = runs[0].names
    ncol = 2 if len(names) > 1 else 1
    nrow = int(np.ceil(len(names) / ncol))
    fig = new_figure((8.27, 2.6 * nrow + 1.0))
    axes = np.atleast_1d(fig.subplots(nrow, ncol, sharex=True)).ravel()
    for k, name in enumerate(names):
        ax = axes[k]
        for run in runs:
            th = _thin(run.t.size)
            ax.plot(
                run.t[th],
                run.trajectory[k, th],
                color=_eps_color(run.eps),
                lw=1.0,
                label=f"eps = {run.eps:g}",
            )
        if truth is not None and name in truth:
            tv = truth[name]
            ax.axhline(tv, color="k", ls="--", lw=1.0, label="truth")
            width = (band_pct or {}).get(name, 15.0) / 100
            ax.set_ylim(tv * (1 - width), tv * (1 + width))
        ax.set_ylabel(f"{name} [{UNITS.get(name, '')}]", fontsize=8)
        ax.grid(alpha=0.3)
        if k == 0:
            ax.legend(fontsize=7.5)
    for ax in axes[len(names) :]:
        ax.set_visible(False)
    for k in range(len(names)):
        if k + ncol >= len(names):  # nothing visible below: label this one
            axes[k].set_xlabel("time [s]")
            axes[k].tick_params(labelbottom=True)
    fig.suptitle(
        title or f"NPFSI convergence (gamma = {runs[0].gamma:g}, {runs[0].velocity_method} velocities)",
        fontsize=10,
    )
    return fig


# --- verification ---------------------------------------------------------------------------------
def parabola_figure(fits: Sequence[ParabolaFit]) -> Figure:
    """000 Fig. 3: horizontal position at fixed gaps with the fitted parabolas."""
    fig = new_figure((8.27, 6.2))
    ax1, ax2 = fig.subplots(2, 1, height_ratios=(2.2, 1), sharex=True)
    cmap = [f"C{k}" for k in range(10)]
    for k, f in enumerate(fits):
        c = cmap[k % 10]
        ax1.plot(f.t[::8], f.x3[::8] * M_TO_MM, ".", color=c, ms=2.5)
        ax1.plot(
            f.t,
            f.position(f.t) * M_TO_MM,
            "-",
            color=c,
            lw=0.9,
            label=f"{f.gap * M_TO_MM:g} mm: L1 = {f.L1:.3f}",
        )
        ax2.plot(f.t, (f.x3 - f.position(f.t)) * M_TO_UM, color=c, lw=0.5)
    ax1.set_ylabel("horizontal position x3 [mm]")
    ax1.set_title(
        "Parabolas fitted to x3 at fixed gaps (u1 = -0.5 A from x3 = -50 mm; 000 Fig. 3)", fontsize=9
    )
    ax1.legend(fontsize=7, ncol=2, title="gap: L1 [m/(s² A)]", title_fontsize=7)
    ax1.grid(alpha=0.3)
    ax2.set_xlabel("time since start [s]")
    ax2.set_ylabel("data - parabola [µm]")
    ax2.grid(alpha=0.3)
    return fig


def l1_comparison_figure(
    comparisons: Mapping[float, ParabolaComparison],
    curves: Mapping[str, tuple[np.ndarray, np.ndarray]],
) -> Figure:
    """000 Figs. 4 and 8: L1 from parabolas, from NPFSI at each eps, and from full models."""
    fig = new_figure((8.27, 6.2))
    ax1, ax2 = fig.subplots(2, 1, height_ratios=(2.2, 1), sharex=True)
    first = next(iter(comparisons.values()))
    g = first.gap * M_TO_MM
    for label, (gaps, values) in curves.items():
        ax1.plot(gaps * M_TO_MM, values, lw=1.0, ls="--" if "truth" in label else "-", label=label)
    ax1.plot(g, first.parabola, "ko", ms=5, mfc="none", label="parabola fits")
    for eps, comp in comparisons.items():
        color = _eps_color(eps)
        ax1.plot(g, comp.npfsi, "x", color=color, ms=6, label=f"NPFSI eps = {eps:g}")
        ax2.plot(
            g,
            comp.discrepancy_pct,
            "o-",
            color=color,
            ms=3.5,
            lw=0.9,
            label=f"eps = {eps:g}: mean {comp.mean_pct:.2f} %, max {comp.max_pct:.2f} %",
        )
    ax2.axhline(3.8, color="0.4", ls="--", lw=0.8, label="papers: mean 3.8 %, max 10 %")
    ax2.axhline(10.0, color="0.4", ls=":", lw=0.8)
    ax1.set_ylabel("L1 [m/(s² A)]")
    ax1.set_title("L1 at fixed gaps: parabolas vs NPFSI (000 Figs. 4, 8)", fontsize=9)
    ax1.legend(fontsize=7)
    ax1.grid(alpha=0.3)
    ax2.set_xlabel("air gap [mm]")
    ax2.set_ylabel("|NPFSI - parabola| / parabola [%]")
    ax2.legend(fontsize=6.5)
    ax2.grid(alpha=0.3)
    return fig


def equilibrium_figure(
    measured: Mapping[str, tuple[np.ndarray, np.ndarray]],
    models: Mapping[str, tuple[np.ndarray, np.ndarray]],
    errors: Mapping[str, EquilibriumComparison],
) -> Figure:
    """000 Figs. 5 and 7: measured equilibrium currents (markers) against eq. (8) with
    identified constants (lines), and the errors of each comparison in mA and %."""
    fig = new_figure((8.27, 7.6))
    ax1, ax2, ax3 = fig.subplots(3, 1, height_ratios=(2, 1.2, 1.2), sharex=True)
    markers = ("o", "s", "^", "d")
    for k, (label, (gaps, current)) in enumerate(measured.items()):
        ax1.plot(gaps * M_TO_MM, current, markers[k % 4], ms=5, mfc="none", label=label)
    for k, (label, (gaps, current)) in enumerate(models.items()):
        ax1.plot(gaps * M_TO_MM, current, "-", lw=1.0, color=f"C{k + 2}", label=label)
    styles = ("o-", "s--", "^:")
    for k, (label, comp) in enumerate(errors.items()):
        color = f"C{k + 5}"
        ax2.plot(comp.gap * M_TO_MM, comp.error * 1e3, styles[k % 3], ms=3, lw=0.9, color=color, label=label)
        ax3.plot(comp.gap * M_TO_MM, comp.error_pct, styles[k % 3], ms=3, lw=0.9, color=color)
    ax1.axvspan(15, 25, color="tab:green", alpha=0.07)
    ax1.set_ylabel("equilibrium i_d = u2 [A]")
    ax1.set_title("Equilibrium currents: measured on the twin vs predicted by eq. (8) of 000", fontsize=9)
    ax1.legend(fontsize=7)
    ax1.grid(alpha=0.3)
    ax2.axhline(0, color="0.5", lw=0.6)
    ax2.set_ylabel("predicted - measured [mA]")
    ax2.legend(fontsize=7)
    ax2.grid(alpha=0.3)
    ax3.axhline(5, color="tab:red", ls="--", lw=0.8, label="5 % (papers, over 15-25 mm)")
    ax3.set_ylabel("|error| / |measured| [%]")
    ax3.set_xlabel("air gap [mm]")
    ax3.set_ylim(0, 8)
    ax3.legend(fontsize=7, loc="upper left")
    ax3.grid(alpha=0.3)
    return fig


def cogging_figure(
    gaps: np.ndarray, estimates: Mapping[str, np.ndarray], truth: np.ndarray, excited: tuple[float, float]
) -> Figure:
    """000 Fig. 6: the peak cogging force from the C2 difference, against the twin's."""
    fig = new_figure((8.27, 4.8))
    ax = fig.subplots()
    ax.plot(
        gaps * M_TO_MM, np.abs(truth), "k--", lw=1.2, label="twin's cogging, |xi(x1)| = 1.5 N (15 mm / x1)^3"
    )
    for k, (label, xi) in enumerate(estimates.items()):
        ax.plot(gaps * M_TO_MM, np.abs(xi), lw=2.2 - k, ls=("-", "--", ":")[k % 3], label=label)
    ax.axvspan(
        excited[0] * M_TO_MM,
        excited[1] * M_TO_MM,
        color="tab:green",
        alpha=0.08,
        label="gaps covered by the run",
    )
    ax.axhline(1.0, color="0.5", ls=":", lw=0.8)
    ax.set_xlabel("air gap [mm]")
    ax.set_ylabel("peak cogging force |xi| [N]")
    ax.set_title("Cogging procedure (000 Sec. V-C): |M_v (C2 at 3 t1/2 - C2 at 0) lam B^2|", fontsize=9)
    ax.legend(fontsize=7.5)
    ax.grid(alpha=0.3)
    return fig


# --- the CLI's report -----------------------------------------------------------------------------
def write_outcome_report(path: str | os.PathLike, outcome, logs: Sequence[Log]) -> ReportContents:
    """PDF for ``maglev-oc identify --report``: summary, tables, residuals, NPFSI convergence.

    Returns what the report says, section by section (:class:`~maglev_oc.reporting.pdf.ReportContents`).
    """
    rows = []
    ee, oe = outcome.equation_error, outcome.output_error
    names = ee.names if ee is not None else (oe.names if oe is not None else ())
    for k in names:
        row: list[object] = [k, f"{(ee or oe).initial[k]:.6g}"]
        for fit in (ee, oe):
            if fit is None:
                row += ["—", "—"]
            else:
                row += [f"{fit.values[k]:.6g}", f"{fit.stderr[k]:.3g}"]
        row.append(UNITS.get(k, ""))
        rows.append(row)
    npfsi_rows = [
        [
            f"{run.eps:g}",
            *(f"{run.values.get(k, float('nan')):.5g}" for k in CONSTANT_NAMES),
            f"{run.timings['total']:.2f}",
        ]
        for run in outcome.npfsi
    ]
    c = outcome.constants()
    summary = [
        "Logs: " + ", ".join(outcome.sources),
        "Identified constants ("
        + c.source
        + "): "
        + ", ".join(f"{k} = {getattr(c, k):.6g}" for k in CONSTANT_NAMES),
        "Equation error: the Savitzky-Golay acceleration (zero phase) against the model's, both filtered "
        "by the same kernel; output error: multiple shooting over 50 ms segments joined by continuity "
        "within 0.2 s windows. Standard errors are long-run (HAC) ones: residuals of both fits are "
        "autocorrelated.",
        "Wall times: " + ", ".join(f"{k} {v:.2f} s" for k, v in outcome.timings.items()),
    ]
    with PdfReport(path, "maglev_oc — identification", subtitle="maglev-oc identify") as pdf:
        pdf.add_text("Identification of C1..C4", summary, first_page=True)
        if rows:
            pdf.add_table(
                "Least-squares estimates",
                ["parameter", "initial", "equation error", "stderr", "output error", "stderr", "unit"],
                rows,
            )
        if npfsi_rows:
            pdf.add_table(
                "NPFSI (000 eq. (3)), final values", ["eps", *CONSTANT_NAMES, "wall time [s]"], npfsi_rows
            )
        for fit in (ee, oe):
            if fit is not None and fit.success:
                pdf.add_figure(text_figure(f"Fit report: {fit.method}", [fit.report()]))
                pdf.add_figure(residuals_figure(fit, logs[0], window=(1.0, min(3.0, logs[0].duration))))
        if outcome.npfsi:
            pdf.add_figure(npfsi_convergence_figure(outcome.npfsi, None))
    return pdf.contents
