"""Figures of the identification reports. Each function takes computed results
(:mod:`maglev_oc.identification`) and draws them; nothing here computes a model.

The functions ending in ``_plot`` return a ``draw(fig, rect) -> title`` for a
:class:`~maglev_oc.reporting.pdf.Plot` block of ``reports/identification.pdf``; those ending in
``_figure`` return a Figure of their own (the PDF of ``maglev-oc identify --report``,
:func:`write_outcome_report`).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from maglev_oc.data.logs import Log
from maglev_oc.identification.layout import CONSTANT_NAMES, UNITS
from maglev_oc.identification.result import FitResult, NpfsiResult
from maglev_oc.identification.verification import EquilibriumComparison, ParabolaComparison, ParabolaFit
from maglev_oc.regression.data import without_resting
from maglev_oc.reporting.pdf import PdfReport, ReportContents, caption, grid, new_figure
from maglev_oc.reporting.style import thin
from maglev_oc.units import M_TO_MM, M_TO_UM

__all__ = [
    "EPS_COLORS",
    "Draw",
    "autocorrelation",
    "cogging_plot",
    "coverage_plot",
    "eps_trend_plot",
    "equilibrium_plot",
    "key_plot",
    "l1_plot",
    "npfsi_convergence_figure",
    "npfsi_plot",
    "parabola_plot",
    "residuals_figure",
    "residuals_plot",
    "shooting_plot",
    "text_figure",
    "write_outcome_report",
]

Draw = Callable[[Figure, tuple[float, float, float, float]], str]
"""What a ``*_plot`` function returns: draws into a band of the page, returns the title."""

EPS_COLORS = {0.001: "tab:blue", 0.01: "tab:green", 0.05: "tab:red"}
"""One colour per eps of the NPFSI estimator, in every figure."""
TRUTH_STYLE = {"color": "k", "ls": "--", "lw": 1.0}
"""The twin's true values: black dashed, in every figure."""
PAPER_COLOR = "0.45"
"""The papers' values and bounds: grey."""
X0_COLOR, COGGING_COLOR = "tab:blue", "tab:orange"
"""Mover locked at x3 = 0 (a cogging null) and at 3 t1/2 (the cogging peak)."""


def _eps_color(eps: float) -> str:
    for key, color in EPS_COLORS.items():
        if np.isclose(eps, key):
            return color
    return "tab:purple"


def autocorrelation(x: np.ndarray, lags: int) -> np.ndarray:
    """Sample autocorrelation of ``x`` (NaN dropped, mean removed) at lags 0..lags-1 [-]."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    x = x - np.mean(x)
    n = 1 << int(np.ceil(np.log2(2 * x.size)))
    spec = np.fft.rfft(x, n)
    acov = np.fft.irfft(spec * np.conj(spec), n)[:lags]
    return acov / acov[0]


def _legend_below(fig: Figure, rect, handles, labels, ncol: int, y: float = 0.0) -> None:
    """A legend along the bottom of ``rect`` (outside the axes)."""
    fig.legend(
        handles, labels, loc="lower center", ncol=ncol, fontsize=7.5, bbox_to_anchor=(0.54, rect[1] + y)
    )


# --- page 1 ----------------------------------------------------------------------------------------------
def key_plot(
    comparisons: Mapping[float, ParabolaComparison],
    paper_l1: tuple[float, float],
    equilibrium: Mapping[str, EquilibriumComparison],
    band: tuple[float, float],
    paper_equilibrium_pct: float,
    cogging_gaps: np.ndarray,
    cogging: Mapping[str, np.ndarray],
    cogging_truth: np.ndarray,
    paper_cogging: float,
    trends: Mapping[str, tuple[Sequence[float], np.ndarray]],
) -> Draw:
    """The papers' four verification results beside ours, one panel each: L1 from NPFSI against
    the parabolas (002: 3.8 % mean, 10 % max), the equilibrium-current error (5 % over 15-25 mm),
    the peak cogging force (above 1 N below 15 mm), and C1 against eps (Table III).

    ``trends``: label -> (eps values, C1 estimates) drawn relative to the value at eps = 0.01."""

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 2, 2, wspace=0.3, hspace=0.5, top=0.07, bottom=0.04)
        a, b = fig.add_subplot(gs[0, 0]), fig.add_subplot(gs[0, 1])
        c, d = fig.add_subplot(gs[1, 0]), fig.add_subplot(gs[1, 1])
        for eps, comp in comparisons.items():
            a.plot(comp.gap * M_TO_MM, comp.discrepancy_pct, "o-", ms=3, color=_eps_color(eps))
            a.plot([], [], "o-", ms=3, color=_eps_color(eps), label=f"ours, eps = {eps:g}")
        a.axhline(paper_l1[0], color=PAPER_COLOR, ls="--", lw=0.9, label=f"paper: mean {paper_l1[0]:g} %")
        a.axhline(paper_l1[1], color=PAPER_COLOR, ls=":", lw=0.9, label=f"paper: max {paper_l1[1]:g} %")
        a.set_ylim(0, paper_l1[1] * 1.25)
        a.set_xlabel("air gap [mm]")
        a.set_ylabel("|L1 NPFSI − L1 parabola|\n/ L1 parabola [%]")
        a.set_title("Horizontal: L1 from NPFSI vs parabolas")
        a.legend(fontsize=6.5, loc="upper left", ncol=2, bbox_to_anchor=(0, 1.0))
        for (label, comp), color in zip(equilibrium.items(), (X0_COLOR, COGGING_COLOR), strict=False):
            b.plot(comp.gap * M_TO_MM, comp.error_pct, "o-", ms=3, color=color, label=label)
        b.axvspan(band[0] * M_TO_MM, band[1] * M_TO_MM, color="0.93", lw=0, zorder=0)
        b.axhline(paper_equilibrium_pct, color=PAPER_COLOR, ls="--", lw=0.9, label="paper: 5 % over 15-25 mm")
        b.set_ylim(0, 2 * paper_equilibrium_pct)
        b.set_xlabel("air gap [mm]")
        b.set_ylabel("|predicted − measured|\n/ |measured| [%]")
        b.set_title("Vertical: equilibrium current, eq. (8)")
        b.legend(fontsize=6.5, loc="upper right")
        c.plot(cogging_gaps * M_TO_MM, np.abs(cogging_truth), **TRUTH_STYLE, label="twin's truth")
        for (label, xi), ls in zip(cogging.items(), ("-", ":"), strict=False):
            c.plot(cogging_gaps * M_TO_MM, np.abs(xi), color=COGGING_COLOR, ls=ls, lw=1.4, label=label)
        c.axhline(paper_cogging, color=PAPER_COLOR, ls="--", lw=0.9, label="paper: > 1 N below 15 mm")
        c.axvline(15, color=PAPER_COLOR, ls=":", lw=0.8)
        c.set_ylim(0, None)
        c.set_xlabel("air gap [mm]")
        c.set_ylabel("peak cogging force [N]")
        c.set_title("Cogging: C2 at 3 t1/2 minus C2 at x3 = 0")
        c.legend(fontsize=6.5, loc="upper right")
        colors = iter(("tab:green", "tab:brown", "tab:purple"))
        for label, (eps, values) in trends.items():
            values = np.asarray(values, dtype=float)
            ref = values[list(eps).index(0.01)]
            paper = label.startswith("paper")
            d.plot(
                eps,
                100 * (values / ref - 1),
                "s--" if paper else "o-",
                color=PAPER_COLOR if paper else next(colors),
                ms=4,
                label=label,
            )
        d.axhline(0, color="0.6", lw=0.6)
        d.set_xscale("log")
        d.set_xlabel("eps of the NPFSI estimator [s]")
        d.set_ylabel("C1 relative to eps = 0.01 [%]")
        d.set_title("C1 against eps (Table III)")
        d.legend(fontsize=6.5, loc="upper left")
        return caption(
            fig,
            rect,
            "Key figure: the papers' verification results beside ours (identification twin)",
            "Grey: the papers' values. x3 = 0 is a null of the twin's cogging, x3 = 3 t1/2 its peak; "
            "shaded: the 15-25 mm of the papers' 5 % claim.",
        )

    return draw


# --- least squares ---------------------------------------------------------------------------------------
def residuals_plot(fits: Sequence[FitResult], log: Log, window: tuple[float, float] = (10.0, 12.0)) -> Draw:
    """Residuals of each fit along ``window`` of the log (vertical, horizontal) and their
    autocorrelation over 0.2 s, one row per fit."""

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, len(fits), 3, wspace=0.32, hspace=0.55, top=0.07, bottom=0.06)
        t = log.t - log.t[0]
        sel = (t >= window[0]) & (t < window[1])
        lags = np.arange(200)
        for row, fit in enumerate(fits):
            scale, unit = (M_TO_UM, "µm") if fit.residual_unit == "m" else (1.0, "m/s²")
            name = "equation error" if fit.method == "equation_error" else "output error"
            r = fit.residuals[0]
            acf_ax = fig.add_subplot(gs[row, 2])
            for col, (axis, color) in enumerate((("vertical", "tab:blue"), ("horizontal", "tab:orange"))):
                ax = fig.add_subplot(gs[row, col])
                ax.plot(t[sel], r[col, sel] * scale, color=color, lw=0.5)
                ax.set_title(f"{name}, {axis}: RMS {fit.residual_rms[axis] * scale:.3g} {unit}", fontsize=8)
                ax.set_ylabel(f"residual [{unit}]")
                ax.set_xlabel("time in the log [s]")
                acf_ax.plot(lags * log.sample_time * 1e3, autocorrelation(r[col], lags.size), color=color)
            acf_ax.axhline(0, color="0.5", lw=0.6)
            acf_ax.set_ylim(-0.5, 1.0)
            acf_ax.set_title(f"{name}: autocorrelation", fontsize=8)
            acf_ax.set_xlabel("lag [ms]")
            acf_ax.set_ylabel("[-]")
        handles = [Line2D([], [], color=c) for c in ("tab:blue", "tab:orange")]
        _legend_below(fig, rect, handles, ["vertical", "horizontal"], 2, y=-0.012)
        return caption(
            fig,
            rect,
            f"Residuals of both fits, {window[1] - window[0]:g} s of the 60 s log",
            "Equation error: measured − modelled acceleration, both through one zero-phase filter; output "
            "error: encoder − model simulated over 50 ms segments. Both are correlated over tens of ms.",
        )

    return draw


def shooting_plot(log: Log, open_loop: np.ndarray, output_error: FitResult) -> Draw:
    """The model driven open loop by the logged currents (single shooting) leaves the data;
    the multiple-shooting fit stays within a few micrometres."""

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 1, 2, wspace=0.3, top=0.04, bottom=0.07)
        ax1, ax2 = fig.add_subplot(gs[0, 0]), fig.add_subplot(gs[0, 1])
        k = open_loop.shape[1]
        t = log.t[:k] - log.t[0]
        ax1.plot(t, log.x[0, :k] * M_TO_MM, "k.", ms=1.2, label="encoder reading")
        ax1.plot(t, open_loop[0] * M_TO_MM, "tab:red", lw=1.2, label="model, true constants, open loop")
        lo = float(np.nanmin(log.x[0, :k])) * M_TO_MM - 1
        hi = float(np.nanmax(log.x[0, :k])) * M_TO_MM + 1
        ax1.set_ylim(max(lo, 0), hi)
        ax1.set_xlabel("time [s]")
        ax1.set_ylabel("air gap [mm]")
        ax1.set_title("Single shooting: the unstable gap runs away", fontsize=8.5)
        ax1.legend(fontsize=7, loc="lower left")
        r = output_error.residuals[0]
        n = min(r.shape[1], 1000)
        tt = log.t[:n] - log.t[0]
        ax2.plot(tt, r[0, :n] * M_TO_UM, lw=0.6, color="tab:blue", label="vertical")
        ax2.plot(tt, r[1, :n] * M_TO_UM, lw=0.6, color="tab:orange", label="horizontal")
        seg = output_error.settings.get("segment_duration_s", 0.05)
        for s in np.arange(0, tt[-1], seg):
            ax2.axvline(s, color="0.85", lw=0.5, zorder=0)
        ax2.set_xlabel("time [s]")
        ax2.set_ylabel("encoder − model [µm]")
        ax2.set_title(f"Multiple shooting ({seg * 1e3:.0f} ms segments, grey lines)", fontsize=8.5)
        ax2.legend(fontsize=7, loc="upper center", ncol=2, bbox_to_anchor=(0.5, -0.2))
        return caption(fig, rect, "Why the output-error fit uses multiple shooting (first second of the log)")

    return draw


def coverage_plot(names: Sequence[str], z: np.ndarray, z_naive: np.ndarray) -> Draw:
    """z-scores (estimate - truth) / stderr of repeated fits, long-run against plain standard errors."""

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 1, 1, top=0.04, bottom=0.05, right=0.72)
        ax = fig.add_subplot(gs[0, 0])
        x = np.arange(len(names))
        jitter = np.linspace(-0.06, 0.06, z.shape[0])
        for k in range(z.shape[0]):
            ax.plot(x - 0.15 + jitter[k], z[k], "o", color="tab:blue", ms=3.5)
            ax.plot(x + 0.15 + jitter[k], z_naive[k], "s", color="0.5", ms=3, mfc="none")
        ax.axhspan(-2, 2, color="0.94", lw=0, zorder=0)
        ax.axhline(0, color="0.5", lw=0.6)
        ax.set_xticks(x, list(names))
        ax.set_xlim(-0.6, len(names) - 0.4)
        ax.set_ylabel("(estimate − truth) / standard error [-]")
        handles = [
            Line2D([], [], marker="o", ls="", color="tab:blue", ms=3.5),
            Line2D([], [], marker="s", ls="", color="0.5", ms=3, mfc="none"),
        ]
        ax.legend(
            handles,
            ["long-run (HAC) standard errors", "plain s²(J'J)⁻¹"],
            fontsize=7,
            loc="upper left",
            bbox_to_anchor=(1.0, 1.0),
        )
        return caption(
            fig, rect, f"Equation error on {z.shape[0]} further runs: z of each estimate (shaded: |z| ≤ 2)"
        )

    return draw


# --- NPFSI -----------------------------------------------------------------------------------------------
def npfsi_plot(
    columns: Mapping[str, Sequence[NpfsiResult]],
    truth: Mapping[str, float],
    band_pct: Mapping[str, float],
    title: str,
    text: str = "",
) -> Draw:
    """theta_hat(t) of each run (one per eps): one row per parameter, one column per entry of
    ``columns`` (title -> runs), the truth dashed, each row on one y scale (band_pct around the truth)."""

    def draw(fig: Figure, rect) -> str:
        names = next(iter(columns.values()))[0].names
        ncol = len(columns)
        gs = grid(fig, rect, len(names), ncol, wspace=0.12, hspace=0.18, top=0.06 if text else 0.04)
        axes = np.array([[fig.add_subplot(gs[i, j]) for j in range(ncol)] for i in range(len(names))])
        for j, (col_title, runs) in enumerate(columns.items()):
            for i, name in enumerate(names):
                ax = axes[i, j]
                for run in runs:
                    k = run.names.index(name)
                    tt, yy = thin(run.t, run.trajectory[k], 1500)
                    ax.plot(tt, yy, color=_eps_color(run.eps), lw=0.9)
                tv = truth[name]
                ax.axhline(tv, **TRUTH_STYLE)
                width = band_pct.get(name, 15.0) / 100
                ax.set_ylim(tv * (1 - width), tv * (1 + width))
                if j == 0:
                    ax.set_ylabel(f"{name} [{UNITS.get(name, '')}]", fontsize=7.5)
                else:
                    ax.tick_params(labelleft=False)
                if i == 0 and ncol > 1:
                    ax.set_title(col_title, fontsize=8.5)
                if i < len(names) - 1:
                    ax.tick_params(labelbottom=False)
                else:
                    ax.set_xlabel("time in the log [s]")
        runs0 = next(iter(columns.values()))
        handles = [Line2D([], [], color=_eps_color(r.eps)) for r in runs0] + [Line2D([], [], **TRUTH_STYLE)]
        labels = [f"eps = {r.eps:g}" for r in runs0] + ["twin's truth"]
        _legend_below(fig, rect, handles, labels, len(labels), y=-0.014)
        return caption(fig, rect, title, text)

    return draw


def eps_trend_plot(
    panels: Mapping[str, Mapping[str, tuple[Sequence[float], np.ndarray]]], title: str, text: str = ""
) -> Draw:
    """Estimates against eps relative to their value at eps = 0.01: one panel per constant
    (name -> label -> (eps, values)); the papers' grey, ours coloured."""

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 1, len(panels), wspace=0.35, top=0.06 if text else 0.04, bottom=0.06)
        colors = ["tab:green", "tab:brown", "tab:purple", "tab:cyan"]
        handles: dict[str, Line2D] = {}
        for j, (name, series) in enumerate(panels.items()):
            ax = fig.add_subplot(gs[0, j])
            k = 0
            for label, (eps, values) in series.items():
                values = np.asarray(values, dtype=float)
                ref = values[list(eps).index(0.01)]
                paper = label.startswith("paper")
                style = dict(color=PAPER_COLOR, ls="--", marker="s") if paper else dict(color=colors[k])
                if not paper:
                    style |= {"marker": "o", "ls": "-"}
                    k += 1
                (line,) = ax.plot(eps, 100 * (values / ref - 1), ms=3.5, lw=1.0, **style)
                handles.setdefault(label, line)
            ax.axhline(0, color="0.6", lw=0.6)
            ax.set_xscale("log")
            ax.set_title(name, fontsize=8.5)
            ax.set_xlabel("eps [s]")
            if j == 0:
                ax.set_ylabel("relative to eps = 0.01 [%]")
        _legend_below(fig, rect, list(handles.values()), list(handles), min(len(handles), 3), y=-0.012)
        return caption(fig, rect, title, text)

    return draw


# --- verification ----------------------------------------------------------------------------------------
def parabola_plot(fits: Sequence[ParabolaFit]) -> Draw:
    """000 Fig. 3: horizontal position at fixed gaps with the fitted parabolas, and what is left."""

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 1, 2, wspace=0.25, top=0.065, bottom=0.085, width_ratios=(1.3, 1))
        ax1, ax2 = fig.add_subplot(gs[0, 0]), fig.add_subplot(gs[0, 1])
        for k, f in enumerate(fits):
            c = f"C{k % 10}"
            ax1.plot(f.t[::10], f.x3[::10] * M_TO_MM, ".", color=c, ms=2)
            ax1.plot(f.t, f.position(f.t) * M_TO_MM, "-", color=c, lw=0.8, label=f"{f.gap * M_TO_MM:g} mm")
            ax2.plot(f.t, (f.x3 - f.position(f.t)) * M_TO_UM, color=c, lw=0.5)
        ax1.set_xlabel("time since the start [s]")
        ax1.set_ylabel("horizontal position x3 [mm]")
        h, lab = ax1.get_legend_handles_labels()
        _legend_below(fig, rect, h, [f"gap {x}" for x in lab], 4, y=-0.008)
        ax2.axhspan(-5, 5, color="0.93", lw=0, zorder=0)
        ax2.set_xlabel("time since the start [s]")
        ax2.set_ylabel("encoder − parabola [µm]")
        return caption(
            fig,
            rect,
            "Parabolas fitted to x3 at fixed gaps (000 Fig. 3)",
            "u1 = −0.5 A from rest at x3 = −50 mm until +50 mm; dots: every 10th encoder reading. Right: "
            "what the parabola leaves, the 10 µm encoder steps (shaded ±5 µm).",
        )

    return draw


def l1_plot(
    comparisons: Mapping[float, ParabolaComparison],
    curves: Mapping[str, tuple[np.ndarray, np.ndarray]],
    paper: tuple[float, float],
) -> Draw:
    """000 Figs. 4 and 8: L1 from parabolas, from NPFSI at each eps and from full models, and the
    discrepancy in %."""

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 1, 2, wspace=0.3, top=0.035, bottom=0.075)
        ax1, ax2 = fig.add_subplot(gs[0, 0]), fig.add_subplot(gs[0, 1])
        first = next(iter(comparisons.values()))
        g = first.gap * M_TO_MM
        styles = {"truth": TRUTH_STYLE}
        for k, (label, (gaps, values)) in enumerate(curves.items()):
            style = styles.get(label.split(" ")[0], {"color": f"C{k + 4}", "lw": 1.0})
            ax1.plot(gaps * M_TO_MM, values, label=label, **style)
        ax1.plot(g, first.parabola, "ko", ms=4, mfc="none", label="parabola fits")
        for eps, comp in comparisons.items():
            ax1.plot(g, comp.npfsi, "x", color=_eps_color(eps), ms=5, label=f"NPFSI eps = {eps:g}")
            ax2.plot(g, comp.discrepancy_pct, "o-", color=_eps_color(eps), ms=3, lw=0.9)
        ax2.axhline(paper[0], color=PAPER_COLOR, ls="--", lw=0.9)
        ax2.axhline(paper[1], color=PAPER_COLOR, ls=":", lw=0.9)
        ax2.text(g[-1], paper[0], f"paper: mean {paper[0]:g} %", ha="right", va="bottom", fontsize=7)
        ax2.text(g[-1], paper[1], f"paper: max {paper[1]:g} %", ha="right", va="bottom", fontsize=7)
        ax2.set_ylim(0, paper[1] * 1.2)
        ax1.set_xlabel("air gap [mm]")
        ax1.set_ylabel("L1 [m/(s² A)]")
        ax2.set_xlabel("air gap [mm]")
        ax2.set_ylabel("|NPFSI − parabola| / parabola [%]")
        h, lab = ax1.get_legend_handles_labels()
        _legend_below(fig, rect, h, lab, 4, y=-0.004)
        return caption(fig, rect, "L1 at fixed gaps: parabolas against NPFSI (000 Figs. 4, 8)")

    return draw


def equilibrium_plot(
    measured: Mapping[str, tuple[np.ndarray, np.ndarray]],
    models: Mapping[str, tuple[np.ndarray, np.ndarray]],
    errors: Mapping[str, EquilibriumComparison],
    band: tuple[float, float],
    paper_pct: float,
) -> Draw:
    """000 Figs. 5 and 7: measured equilibrium currents (markers) against eq. (8) with
    identified constants (lines), and the errors of each comparison in mA and %."""

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 1, 3, wspace=0.4, top=0.05, bottom=0.1)
        ax1, ax2, ax3 = (fig.add_subplot(gs[0, j]) for j in range(3))
        colors = (X0_COLOR, COGGING_COLOR)
        for (label, (gaps, current)), color in zip(measured.items(), colors, strict=False):
            ax1.plot(gaps * M_TO_MM, current, "o", ms=3.5, mfc="none", color=color, label=label)
        for (label, (gaps, current)), ls in zip(models.items(), ("-", ":"), strict=False):
            ax1.plot(gaps * M_TO_MM, current, ls=ls, lw=1.0, color="k", label=label)
        styles = (("o-", X0_COLOR), ("s-", COGGING_COLOR), ("^:", COGGING_COLOR))
        for (label, comp), (st, color) in zip(errors.items(), styles, strict=False):
            ax2.plot(comp.gap * M_TO_MM, comp.error * 1e3, st, ms=3, lw=0.9, color=color, label=label)
            ax3.plot(comp.gap * M_TO_MM, comp.error_pct, st, ms=3, lw=0.9, color=color)
        for ax in (ax1, ax2, ax3):
            ax.axvspan(band[0] * M_TO_MM, band[1] * M_TO_MM, color="0.94", lw=0, zorder=0)
            ax.set_xlabel("air gap [mm]")
        ax1.set_ylabel("equilibrium current i_d = u2 [A]")
        ax2.axhline(0, color="0.5", lw=0.6)
        ax2.set_ylabel("predicted − measured [mA]")
        ax3.axhline(paper_pct, color=PAPER_COLOR, ls="--", lw=0.9)
        ax3.text(
            band[1] * M_TO_MM, paper_pct, f"paper: {paper_pct:g} % ", ha="right", va="bottom", fontsize=7
        )
        ax3.set_ylabel("|error| / |measured| [%]")
        ax3.set_ylim(0, 2 * paper_pct)
        h1, l1 = ax1.get_legend_handles_labels()
        h2, l2 = ax2.get_legend_handles_labels()
        _legend_below(fig, rect, h1 + h2, l1 + l2, 2, y=-0.006)
        return caption(
            fig,
            rect,
            "Equilibrium currents: measured on the twin against eq. (8) of 000 (Figs. 5, 7)",
            "Shaded: 15-25 mm, where the papers claim 5 %. No percentage where |measured| < 0.3 A (the "
            "current crosses zero near 24 mm).",
        )

    return draw


def cogging_plot(
    gaps: np.ndarray,
    estimates: Mapping[str, np.ndarray],
    truth: np.ndarray,
    truth_label: str,
    excited: tuple[float, float],
    paper_force: float,
) -> Draw:
    """000 Fig. 6: the peak cogging force from the C2 difference, against the twin's."""

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 1, 1, top=0.04, bottom=0.05, right=0.62)
        ax = fig.add_subplot(gs[0, 0])
        ax.plot(gaps * M_TO_MM, np.abs(truth), **TRUTH_STYLE, label=truth_label)
        for (label, xi), ls in zip(estimates.items(), ("-", ":"), strict=False):
            ax.plot(gaps * M_TO_MM, np.abs(xi), color=COGGING_COLOR, ls=ls, lw=1.5, label=label)
        ax.axvspan(excited[0] * M_TO_MM, excited[1] * M_TO_MM, color="0.93", lw=0, zorder=0)
        ax.plot([], [], "s", color="0.93", ms=8, label="gaps the run covered")
        ax.axhline(paper_force, color=PAPER_COLOR, ls="--", lw=0.9, label="paper: > 1 N below 15 mm")
        ax.set_xlabel("air gap [mm]")
        ax.set_ylabel("peak cogging force [N]")
        ax.set_ylim(0, None)
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0))
        return caption(fig, rect, "Peak cogging force from the cogging procedure (000 Sec. V-C, Fig. 6)")

    return draw


# --- figures of their own (maglev-oc identify --report) --------------------------------------------------
def text_figure(title: str, blocks: Sequence[str], *, font_size: float = 6.8) -> Figure:
    """A page of preformatted text (fit reports) in a monospaced font, lines kept as they are."""
    from maglev_oc.reporting.pdf import PAGE_SIZE

    fig = Figure(figsize=PAGE_SIZE)
    fig.text(0.06, 0.95, title, fontsize=13, weight="bold", va="top")
    fig.text(0.04, 0.91, "\n\n".join(blocks), fontsize=font_size, family="monospace", va="top")
    return fig


def residuals_figure(fit: FitResult, log: Log, *, window: tuple[float, float] = (10.0, 15.0)) -> Figure:
    """Residuals of a fit along a stretch of one log, and their autocorrelation."""
    fig = new_figure((8.27, 6.4))
    axes = fig.subplots(2, 2, width_ratios=(2.2, 1))
    r = fit.residuals[0]
    t = log.t - log.t[0]
    sel = (t >= window[0]) & (t < window[1])
    scale, unit = (M_TO_UM, "µm") if fit.residual_unit == "m" else (1.0, "m/s²")
    lags = np.arange(200)
    for row, (axis_name, color) in enumerate((("vertical", "tab:blue"), ("horizontal", "tab:orange"))):
        ax = axes[row, 0]
        ax.plot(t[sel], r[row, sel] * scale, color=color, lw=0.6)
        ax.set_ylabel(f"{axis_name} residual [{unit}]")
        ax.set_title(f"{axis_name}: RMS {fit.residual_rms[axis_name] * scale:.3g} {unit} (whole log)")
        ax2 = axes[row, 1]
        ax2.plot(lags * log.sample_time * 1e3, autocorrelation(r[row], lags.size), color=color)
        ax2.axhline(0, color="0.5", lw=0.6)
        ax2.set_ylabel("autocorrelation [-]")
    axes[1, 0].set_xlabel("time [s]")
    axes[1, 1].set_xlabel("lag [ms]")
    kind = "equation error (filtered accelerations)" if fit.method == "equation_error" else "output error"
    fig.suptitle(f"Residuals of the {kind}", fontsize=11)
    return fig


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
            tt, yy = thin(run.t, run.trajectory[k], 1500)
            ax.plot(tt, yy, color=_eps_color(run.eps), lw=1.0, label=f"eps = {run.eps:g}")
        if truth is not None and name in truth:
            tv = truth[name]
            ax.axhline(tv, **TRUTH_STYLE, label="truth")
            width = (band_pct or {}).get(name, 15.0) / 100
            ax.set_ylim(tv * (1 - width), tv * (1 + width))
        ax.set_ylabel(f"{name} [{UNITS.get(name, '')}]", fontsize=8)
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
        *(f"Warning: {w}" for w in outcome.warnings),
        *([f"Moving mass: {outcome.moving_mass.says()}"] if outcome.moving_mass is not None else []),
        *(f"Left out of every fit: {r.source}, {r.what()}." for r in outcome.left_out),
        *(f"Payload: {w}." for w in outcome.payloads),
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
                log = without_resting(logs[0], outcome.left_out)  # the samples the fit read
                pdf.add_figure(residuals_figure(fit, log, window=(1.0, min(3.0, log.duration))))
        if outcome.npfsi:
            pdf.add_figure(npfsi_convergence_figure(outcome.npfsi, None))
    return pdf.contents
