"""Figures of the model report. Each function takes computed results and returns a Figure."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from maglev_oc.control.gains import GainCheck
from maglev_oc.model.hardware import CONTINUOUS_CURRENT_LIMIT, PEAK_CURRENT_LIMIT
from maglev_oc.model.summary import ModelSummary
from maglev_oc.reporting.pdf import new_figure
from maglev_oc.units import M_TO_MM

__all__ = [
    "coefficients_figure",
    "equilibrium_figure",
    "feasible_acceleration_figure",
    "field_fit_figure",
    "gain_poles_figure",
    "open_loop_figure",
]


def equilibrium_figure(s: ModelSummary) -> Figure:
    fig = new_figure()
    ax = fig.subplots()
    g = s.gap * M_TO_MM
    for name, curve in s.equilibrium_by_set.items():
        ax.plot(g, curve.current, lw=1.0, ls="--", label=f"{name} (000 Table III)")
    ax.plot(g, s.equilibrium.current, "k", lw=2, label=f"this model ({s.model.constants.source})")
    for lim, style, text in (
        (CONTINUOUS_CURRENT_LIMIT, "-", "7 A continuous"),
        (PEAK_CURRENT_LIMIT, ":", "9 A peak"),
    ):
        for sign in (1, -1):
            ax.axhline(sign * lim, color="tab:red", ls=style, lw=1)
        ax.text(g[-1], lim, f" {text}", color="tab:red", va="bottom", ha="right", fontsize=8)
    ax.axhline(0, color="0.6", lw=0.6)
    ax.axvspan(15, 25, color="tab:green", alpha=0.08, label="verified range 15-25 mm (000)")
    if s.zero_current_gap is not None:
        ax.axvline(s.zero_current_gap * M_TO_MM, color="0.4", lw=0.8, ls="-.")
        ax.annotate(
            f"i_d = 0 at {s.zero_current_gap * M_TO_MM:.2f} mm",
            (s.zero_current_gap * M_TO_MM, 0),
            xytext=(8, 25),
            textcoords="offset points",
            fontsize=8,
        )
    ax.set_xlabel("air gap x1 [mm]")
    ax.set_ylabel("equilibrium current i_d = u2 [A]")
    ax.set_title("Equilibrium current vs air gap (u1 = 0, eq. (8) of 000 / (12) of 002)")
    ax.set_ylim(-PEAK_CURRENT_LIMIT * 1.15, PEAK_CURRENT_LIMIT * 1.15)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7.5, loc="lower left")
    return fig


def coefficients_figure(s: ModelSummary) -> Figure:
    fig = new_figure((8.27, 7.0))
    axes = fig.subplots(2, 2, sharex=True)
    g = s.gap * M_TO_MM
    labels = (
        ("L1 [m/(s² A)]", "propulsion gain L1 (horizontal)"),
        ("L2 [m/s²]", "PM attraction L2 (vertical)"),
        ("L3 [m/(s² A)]", "field-current coupling L3 (< 0)"),
        ("L4 [m/(s² A²)]", "current-squared term L4"),
    )
    for k, ax in enumerate(axes.ravel()):
        ax.plot(g, s.coefficients[k], "k")
        ax.set_ylabel(labels[k][0])
        ax.set_title(labels[k][1], fontsize=10)
        ax.grid(alpha=0.3)
    axes[0, 1].axhline(s.model.params.gravity, color="tab:blue", ls="--", lw=1)
    axes[0, 1].text(g[-1], s.model.params.gravity, "G ", ha="right", va="bottom", color="tab:blue")
    for ax in axes[1]:
        ax.set_xlabel("air gap x1 [mm]")
    fig.suptitle("Model coefficients L_i(x1) = C_i l_i(x1) (eqs. (5)-(8) of 002)")
    return fig


def open_loop_figure(s: ModelSummary) -> Figure:
    fig = new_figure()
    ax = fig.subplots()
    g = s.gap * M_TO_MM
    ol = s.open_loop
    ax.plot(g, ol.vertical[:, 0].real, "tab:red", label="vertical, unstable: +sqrt(dx2'/dx1)")
    ax.plot(g, ol.vertical[:, 1].real, "tab:blue", label="vertical, stable: -sqrt(dx2'/dx1)")
    ax.plot(g, ol.horizontal[:, 0].real, "k--", label="horizontal: double integrator (0, 0)")
    ax.axhline(0, color="0.6", lw=0.6)
    ax.set_xlabel("air gap x1 [mm]")
    ax.set_ylabel("open-loop pole [1/s]")
    ax.set_title("Open-loop poles of the linearization at each equilibrium")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def field_fit_figure(s: ModelSummary) -> Figure:
    fig = new_figure((8.27, 7.0))
    ax_b, ax_e = fig.subplots(2, 1, sharex=True)
    g = s.gap * M_TO_MM
    ax_b.plot(g, s.field * 1e3, "k", lw=2, label="closed form (magnetic-charge model, SPEC 1)")
    ax_b.plot(
        g,
        s.field_fit_values * 1e3,
        "tab:orange",
        ls="--",
        label=f"degree-{len(s.field_fit.coefficients) - 1} polynomial fit",
    )
    ax_b.set_ylabel("PM field B [mT]")
    ax_b.legend(fontsize=8)
    ax_b.grid(alpha=0.3)
    ax_e.plot(g, (s.field_fit_values - s.field) * 1e6, "tab:orange")
    ax_e.set_ylabel("fit - closed form [µT]")
    ax_e.set_xlabel("air gap x1 [mm]")
    ax_e.grid(alpha=0.3)
    f = s.field_fit
    ax_e.set_title(
        f"max |error| over {f.fit_range[0] * M_TO_MM:g}-{f.fit_range[1] * M_TO_MM:g} mm: "
        f"{f.max_error * 1e6:.3g} µT ({f.max_relative_error * 100:.2g} % of B)",
        fontsize=10,
    )
    fig.suptitle("PM field: closed form vs the papers' 12th-degree polynomial")
    return fig


def feasible_acceleration_figure(s: ModelSummary) -> Figure:
    fig = new_figure()
    ax = fig.subplots()
    ax.plot(s.gap * M_TO_MM, s.v2_max, "k")
    ax.fill_between(
        s.gap * M_TO_MM,
        s.v2_max,
        np.max(s.v2_max) * 1.1,
        color="tab:red",
        alpha=0.12,
        label="R < 0: transformation undefined",
    )
    ax.set_xlabel("air gap x1 [mm]")
    ax.set_ylabel("largest feasible v2 at v1 = 0 [m/s²]")
    ax.set_title("Feasibility of the feedback transformation: R(x1, 0, v2) >= 0 iff v2 <= bound")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def gain_poles_figure(checks: list[GainCheck]) -> Figure:
    fig = new_figure((8.27, 4.2))
    axes = fig.subplots(1, len(checks))
    for ax, c in zip(axes, checks, strict=True):
        target = np.asarray(c.paper.poles, dtype=complex)
        ax.plot(target.real, target.imag, "kx", ms=9, mew=2, label="design poles")
        ax.plot(
            c.printed_poles.real,
            c.printed_poles.imag,
            "o",
            mfc="none",
            color="tab:red",
            ms=8,
            label="poles of printed integer gains",
        )
        ax.set_title(c.paper.name, fontsize=10)
        ax.set_xlabel("Re [1/s]")
        ax.grid(alpha=0.3)
        ax.axhline(0, color="0.6", lw=0.5)
    axes[0].set_ylabel("Im [rad/s]")
    axes[0].legend(fontsize=7.5)
    fig.suptitle("Augmented-axis poles: placed vs what the printed gains give")
    return fig
