"""Figures of the model report. Each function takes computed results and returns a ``draw(fig, rect)``
block for :class:`maglev_oc.reporting.pdf.Plot` (it draws into ``rect``, page fractions, and
returns its title)."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from matplotlib.figure import Figure

from maglev_oc.control.gains import GainCheck
from maglev_oc.model.hardware import CONTINUOUS_CURRENT_LIMIT, PEAK_CURRENT_LIMIT
from maglev_oc.model.summary import ModelSummary
from maglev_oc.reporting.pdf import caption, grid
from maglev_oc.units import M_TO_MM

__all__ = [
    "coefficients_plot",
    "equilibrium_plot",
    "field_fit_plot",
    "key_figure",
    "open_loop_plot",
]

Draw = Callable[[Figure, tuple[float, float, float, float]], str]
GAIN_WORDS = {"K_h": "K_h (horizontal)", "K_v": "K_v (vertical)", "K_v_retuned": "K_v retuned"}
"""The papers' gain vectors as the report names them."""


def _limits(ax, x_right: float) -> None:
    """The amplifiers' 7 A continuous and 9 A peak limits on a current axis."""
    for lim, style, text in (
        (CONTINUOUS_CURRENT_LIMIT, "-", "7 A continuous"),
        (PEAK_CURRENT_LIMIT, ":", "9 A peak"),
    ):
        for sign in (1, -1):
            ax.axhline(sign * lim, color="tab:red", ls=style, lw=0.9)
        ax.text(x_right, lim, f"{text} ", color="tab:red", va="bottom", ha="right", fontsize=7.5)


def _equilibrium_axes(ax, s: ModelSummary, spec: Sequence[tuple[float, float]], all_sets: bool) -> None:
    g = s.gap * M_TO_MM
    if all_sets:
        for name, curve in s.equilibrium_by_set.items():
            eps = name.split("eps")[-1]
            ax.plot(g, curve.current, lw=0.9, ls="--", label=f"Table III at eps = {eps}")
    ax.plot(g, s.equilibrium.current, "k", lw=1.6, label=f"this model ({s.model.constants.source})")
    if spec:
        ax.plot(
            [x * M_TO_MM for x, _ in spec],
            [i for _, i in spec],
            "o",
            mfc="none",
            mec="tab:blue",
            ms=7,
            mew=1.5,
            label="SPEC 1's values",
        )
    _limits(ax, g[-1])
    ax.axhline(0, color="0.6", lw=0.6)
    ax.axvspan(15, 25, color="tab:green", alpha=0.08, lw=0, label="verified 15-25 mm (000)")
    if s.zero_current_gap is not None:
        ax.axvline(s.zero_current_gap * M_TO_MM, color="0.4", lw=0.8, ls="-.")
    ax.set_xlim(g[0], g[-1])
    ax.set_ylim(-PEAK_CURRENT_LIMIT * 1.15, PEAK_CURRENT_LIMIT * 1.15)
    ax.set_xlabel("air gap x1 [mm]")
    ax.set_ylabel("equilibrium current i_d [A]")


def _pole_axes(ax, c: GainCheck, legend: bool) -> None:
    target = np.asarray(c.paper.poles, dtype=complex)
    ax.plot(target.real, target.imag, "kx", ms=8, mew=1.8, label="design poles")
    ax.plot(
        c.printed_poles.real,
        c.printed_poles.imag,
        "o",
        mfc="none",
        color="tab:red",
        ms=7,
        mew=1.3,
        label="poles of the printed integer gains",
    )
    ax.axhline(0, color="0.6", lw=0.5)
    ax.set_title(GAIN_WORDS.get(c.paper.name, c.paper.name))
    ax.set_xlabel("real part [1/s]")
    if legend:
        ax.set_ylabel("imaginary part [rad/s]")


def key_figure(s: ModelSummary, checks: Sequence[GainCheck], spec: Sequence[tuple[float, float]]) -> Draw:
    """Equilibrium current with SPEC 1's values (top); design poles against the printed gains' (bottom)."""

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 2, len(checks), hspace=0.62, wspace=0.3, top=0.065, bottom=0.065)
        ax = fig.add_subplot(gs[0, :])
        _equilibrium_axes(ax, s, spec, all_sets=False)
        ax.legend(loc="lower left", fontsize=7)
        axes = [fig.add_subplot(gs[1, k]) for k in range(len(checks))]
        for k, (a, c) in enumerate(zip(axes, checks, strict=True)):
            _pole_axes(a, c, k == 0)
        handles, labels = axes[0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="lower center", ncol=2, bbox_to_anchor=(0.54, rect[1] - 0.006))
        return caption(
            fig,
            rect,
            "Key figure: equilibrium current and the poles the printed gains give",
            "Top: the current that holds the mover at each gap (i_q = 0); circles: SPEC 1's values. "
            "Bottom: the augmented axes' poles, placed (x) and given by the papers' printed integer "
            "gains (o).",
        )

    return draw


def equilibrium_plot(s: ModelSummary, spec: Sequence[tuple[float, float]]) -> Draw:
    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 1, 1, top=0.055, bottom=0.06, right=0.66)
        ax = fig.add_subplot(gs[0, 0])
        _equilibrium_axes(ax, s, spec, all_sets=True)
        ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0))
        return caption(
            fig,
            rect,
            "Equilibrium current against the gap, for the three identified constant sets",
            "000 eq. (8) / 002 eq. (12) at i_q = 0. Dash-dotted: the gap held with no current.",
        )

    return draw


def coefficients_plot(s: ModelSummary) -> Draw:
    labels = (
        ("L1 [m/(s² A)]", "thrust gain L1 (horizontal)"),
        ("L2 [m/s²]", "magnets' pull L2 (vertical)"),
        ("L3 [m/(s² A)]", "field-current term L3"),
        ("L4 [m/(s² A²)]", "current-squared term L4"),
    )

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 2, 2, hspace=0.45, wspace=0.3, top=0.05, bottom=0.07)
        g = s.gap * M_TO_MM
        for k in range(4):
            ax = fig.add_subplot(gs[k // 2, k % 2])
            ax.plot(g, s.coefficients[k], "k")
            ax.set_ylabel(labels[k][0])
            ax.set_title(labels[k][1])
            ax.set_xlabel("air gap x1 [mm]")
            if k == 1:
                ax.axhline(s.model.params.gravity, color="tab:blue", ls="--", lw=1)
                ax.text(g[-1], s.model.params.gravity, "G ", ha="right", va="bottom", color="tab:blue")
        return caption(
            fig,
            rect,
            "The model's coefficients L_i(x1) = C_i l_i(x1) (002 eqs. (5)-(8))",
            "Where L2 exceeds G the magnets alone lift the mover against gravity.",
        )

    return draw


def open_loop_plot(s: ModelSummary) -> Draw:
    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 1, 2, wspace=0.3, top=0.06, bottom=0.06)
        g = s.gap * M_TO_MM
        ol = s.open_loop
        ax = fig.add_subplot(gs[0, 0])
        ax.plot(g, ol.vertical[:, 0].real, "tab:red", label="vertical, unstable")
        ax.plot(g, ol.vertical[:, 1].real, "tab:blue", label="vertical, stable")
        ax.plot(g, ol.horizontal[:, 0].real, "k--", label="horizontal (two at 0)")
        ax.axhline(0, color="0.6", lw=0.6)
        ax.set_xlabel("air gap x1 [mm]")
        ax.set_ylabel("open-loop pole [1/s]")
        ax.set_title("Open-loop poles at each equilibrium")
        ax.legend(loc="upper right")
        ax = fig.add_subplot(gs[0, 1])
        ax.plot(g, s.v2_max, "k")
        top = float(np.nanmax(s.v2_max)) * 1.1
        ax.fill_between(g, s.v2_max, top, color="tab:red", alpha=0.12, lw=0, label="R < 0: undefined")
        ax.set_ylim(0, top)
        ax.set_xlabel("air gap x1 [mm]")
        ax.set_ylabel("largest feasible v2 at v1 = 0 [m/s²]")
        ax.set_title("Where the feedback transformation exists")
        ax.legend(loc="upper right")
        return caption(
            fig,
            rect,
            "Open-loop poles, and the set where the feedback transformation exists",
            "Left: ±sqrt(dx2'/dx1) at the equilibrium current. Right: R(x1, 0, v2) >= 0 exactly when v2 "
            "is below the curve; v2 is the vertical acceleration the regulator asks for.",
        )

    return draw


def field_fit_plot(s: ModelSummary) -> Draw:
    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 2, 1, hspace=0.12, top=0.06, bottom=0.09)
        g = s.gap * M_TO_MM
        ax_b = fig.add_subplot(gs[0, 0])
        ax_e = fig.add_subplot(gs[1, 0], sharex=ax_b)
        ax_b.plot(g, s.field * 1e3, "k", lw=1.8, label="closed form (SPEC 1)")
        degree = len(s.field_fit.coefficients) - 1
        ax_b.plot(g, s.field_fit_values * 1e3, "tab:orange", ls="--", label=f"degree-{degree} polynomial")
        ax_b.set_ylabel("magnets' field B [mT]")
        ax_b.legend(loc="upper right")
        ax_b.tick_params(labelbottom=False)
        ax_e.plot(g, (s.field_fit_values - s.field) * 1e6, "tab:orange")
        ax_e.set_ylabel("polynomial − closed form [µT]")
        ax_e.set_xlabel("air gap x1 [mm]")
        f = s.field_fit
        return caption(
            fig,
            rect,
            "The magnets' field: closed form against the papers' 12th-degree polynomial",
            f"The polynomial fitted to the closed form over {f.fit_range[0] * M_TO_MM:g}-"
            f"{f.fit_range[1] * M_TO_MM:g} mm: largest error {f.max_error * 1e6:.3g} µT "
            f"({f.max_relative_error * 100:.2g} % of B).",
        )

    return draw
