"""Figures of the diagnosis report (closing the loop with measured data), and the effects' names in
plain words.

Each ``*_plot`` function returns a ``draw(fig, rect) -> title`` for a
:class:`~maglev_oc.reporting.pdf.Plot` block; it takes a finished
:class:`~maglev_oc.diagnosis.pipeline.Diagnosis` (and the closed-loop study) and draws it.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from maglev_oc.diagnosis.feedback import CompensationStudy
from maglev_oc.diagnosis.pipeline import Diagnosis, Effect
from maglev_oc.diagnosis.words import plain
from maglev_oc.reporting.pdf import caption, grid
from maglev_oc.reporting.style import bands, thin
from maglev_oc.results import AXES
from maglev_oc.units import M_TO_MM, M_TO_UM

__all__ = [
    "AFTER",
    "BEFORE",
    "Draw",
    "compensation_plot",
    "dependence_plot",
    "effect_contribution",
    "effects_plot",
    "key_plot",
    "panels",
    "plain",
    "spectrum_plot",
    "timeseries_plot",
]

Draw = Callable[[Figure, tuple[float, float, float, float]], str]
"""What a ``*_plot`` function returns: draws into a band of the page, returns the title."""

BEFORE, AFTER = "tab:red", "tab:green"
"""The base model alone (before) and with the found effects (after), in every figure."""
AXIS_COLORS = ("tab:blue", "tab:orange")
"""Vertical and horizontal, in every figure."""

_VARIABLE = {
    "gap": ("gap x1 [mm]", lambda d: d.x[0] * M_TO_MM),
    "gap_rate": ("gap rate x2 [mm/s]", lambda d: d.x[1] * M_TO_MM),
    "position": ("horizontal position x3 [mm]", lambda d: d.x[2] * M_TO_MM),
    "position_rate": ("horizontal rate x4 [mm/s]", lambda d: d.x[3] * M_TO_MM),
    "current_rate": ("rate of the axis's own current [A/s]", None),
    "current": ("the other axis's current [A]", None),
    "axis_current": ("the axis's own current [A]", None),
    "time": ("time in the log [s]", lambda d: d.t),
}


def _variable(diag: Diagnosis, effect: Effect, axis: int) -> tuple[str, np.ndarray]:
    """(label, values) of the variable a found effect's residual is plotted against on ``axis``
    (0 vertical, 1 horizontal). The currents: u[0] = i_q drives the thrust (horizontal), u[1] = i_d
    the attraction (vertical), so the axis's own current is u[1 - axis] and the other axis's u[axis]."""
    d = diag.data
    label, get = _VARIABLE[effect.candidate.variable]
    if effect.candidate.variable == "current_rate":  # the lag: each axis's force lags its own current
        return label, d.du[1 - axis]
    if effect.candidate.variable == "current":  # the commutation offset: i_d makes thrust, i_q attraction
        return label, d.u[axis]
    if effect.candidate.variable == "axis_current":
        return label, d.u[1 - axis]
    return label, get(d)


def effect_contribution(diag: Diagnosis, effect: Effect) -> np.ndarray:
    """(2, n) [m/s^2] The effect's acceleration along the log, through the diagnosis's filter."""
    d = diag.data
    term = effect.candidate.term.acceleration_in_time(effect.coefficients)
    return d.filter(np.asarray(term.map(d.n)(d.x, d.u, d.du, d.log_time)))


def panels(diag: Diagnosis) -> list[tuple[Effect, int]]:
    """(effect, axis index) of every axis a found effect acts on."""
    return [(e, a) for e in diag.effects for a in ([0, 1] if e.axis == "both" else [AXES.index(e.axis)])]


def _before_after(ax, diag: Diagnosis, effect: Effect, a: int, contrib: np.ndarray, bins: int = 30) -> None:
    """Held-out residual against the effect's variable, before (without this effect) and after,
    bin means as lines over a cloud of every 20th sample."""
    label, v = _variable(diag, effect, a)
    hold = diag.holdout
    before = diag.residual_after[a] + contrib[a]
    after = diag.residual_after[a]
    vv = v[hold]
    edges = np.linspace(*np.percentile(vv, [1, 99]), bins + 1)
    idx = np.clip(np.digitize(vv, edges) - 1, 0, bins - 1)
    centers = 0.5 * (edges[1:] + edges[:-1])
    for series, color in ((before[hold], BEFORE), (after[hold], AFTER)):
        counts = np.bincount(idx, minlength=bins)
        sums = np.bincount(idx, weights=series, minlength=bins)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(counts > 0, sums / counts, np.nan)
        ax.plot(vv[::20], series[::20], ".", color=color, ms=1.2, alpha=0.2, rasterized=True)
        ax.plot(centers, mean, "-", color=color, lw=1.8)
    ax.axhline(0, color="0.4", lw=0.6)
    lo, hi = np.nanpercentile(np.concatenate([before[hold], after[hold]]), [1, 99])
    ax.set_ylim(lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo))
    ax.set_xlabel(label)
    ax.set_ylabel(f"{AXES[a]} residual [m/s²]")
    ax.set_title(plain(effect.name), fontsize=8.5)


def _legend_below(fig: Figure, rect, handles, labels, ncol: int, y: float = 0.0) -> None:
    fig.legend(
        handles, labels, loc="lower center", ncol=ncol, fontsize=7.5, bbox_to_anchor=(0.54, rect[1] + y)
    )


def _before_after_handles() -> tuple[list[Line2D], list[str]]:
    return (
        [Line2D([], [], color=BEFORE, lw=1.8), Line2D([], [], color=AFTER, lw=1.8)],
        ["before: the base model (this effect left out)", "after: with the found effects"],
    )


# --- page 1 ----------------------------------------------------------------------------------------------
def _tracking_panel(ax, runs) -> None:
    """|encoder - reference| of both axes [um] over time, one line per (run, colour)."""
    for res, color in runs:
        err = np.hypot(res.y[0] - res.reference[0], res.y[1] - res.reference[3]) * M_TO_UM
        ax.plot(*thin(res.t, err, 1500), color=color, lw=0.7)
    ax.set_ylim(0, None)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("|tracking error|, both axes [µm]")


def key_plot(diag: Diagnosis, study: CompensationStudy | None, n_effects: int = 3) -> Draw:
    """The residual each found effect explains, before and after, on held-out data (the first
    ``n_effects`` panels), and the FL regulator's tracking error before and after compensating them."""

    def draw(fig: Figure, rect) -> str:
        shown = panels(diag)[:n_effects]
        n = len(shown) + (study is not None)
        if n == 0:
            if diag.unexplained:
                return caption(fig, rect, "No effect of the library found; part of the residual unexplained")
            return caption(fig, rect, "Nothing found: the refitted papers' model explains the log")
        if not shown:  # nothing to compensate: the loop with the refitted constants, one line
            ax = fig.add_subplot(grid(fig, rect, 1, 1, top=0.075, bottom=0.085)[0, 0])
            _tracking_panel(ax, ((study.result_after, AFTER),))
            ax.set_title(f"FL regulator with the refitted constants, {study.scenario}", fontsize=8.5)
            why = (
                "No effect of the library found; part of the residual is unexplained (the scorecard), and "
                "only a named effect is compensated."
                if diag.unexplained
                else "No effect found, but a refitted constant is one no stage of this design has (the "
                "scorecard's warning): nothing named to compensate."
                if diag.warnings
                else "The refitted papers' model explains the log to its noise, so there is nothing to "
                "compensate."
            )
            return caption(
                fig,
                rect,
                "Key figure: nothing found; the FL regulator with the refitted constants",
                f"{why} The closed loop's error (encoder − reference) on the rig twin.",
            )
        gs = grid(fig, rect, 1, n, wspace=0.38, top=0.075, bottom=0.085)
        for k, (effect, a) in enumerate(shown):
            _before_after(fig.add_subplot(gs[0, k]), diag, effect, a, effect_contribution(diag, effect))
        if study is not None:
            ax = fig.add_subplot(gs[0, n - 1])
            _tracking_panel(ax, ((study.result_before, BEFORE), (study.result_after, AFTER)))
            ax.set_title(f"FL regulator, {study.scenario}", fontsize=8.5)
        h, lab = _before_after_handles()
        _legend_below(fig, rect, h, lab, 2, y=-0.008)
        return caption(
            fig,
            rect,
            "Key figure: what the found effects explain, and what compensating them is worth",
            "Residual of the acceleration on held-out data against the variable each effect depends on "
            "(dots: samples; lines: bin means). Right: the closed loop's error (encoder − reference).",
        )

    return draw


# --- where the residual lives ----------------------------------------------------------------------------
def spectrum_plot(diag: Diagnosis) -> Draw:
    tr = diag.trace

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 1, 2, wspace=0.3, top=0.06, bottom=0.07)
        names = {
            "slot_pitch": "t1",
            "twice_slot_pitch": "2 t1",
            "pole_pitch": "τ",
            "twice_pole_pitch": "2 τ",
        }
        for a in range(2):
            ax = fig.add_subplot(gs[0, a])
            ax.semilogx(tr.periods * M_TO_MM, tr.spectrum[a] * 100, color=AXIS_COLORS[a], lw=1)
            for name, lam in tr.motor_periods.items():
                ax.axvline(lam * M_TO_MM, color="0.5", ls=":", lw=0.9)
                ax.text(
                    lam * M_TO_MM,
                    1.0,
                    names.get(name, name),
                    ha="center",
                    va="bottom",
                    fontsize=7,
                    transform=ax.get_xaxis_transform(),
                )
            ax.set_xlabel("period in the horizontal position x3 [mm]")
            ax.set_ylabel(f"{AXES[a]} residual explained [%]")
            ax.set_ylim(0, None)
        return caption(
            fig,
            rect,
            "Spatial spectrum of the base model's residual",
            "Share of the residual a sinusoid in x3 of each period explains; dotted: the motor's periods "
            "(slot pitch t1, pole pitch τ and twice each).",
        )

    return draw


def dependence_plot(diag: Diagnosis) -> Draw:
    tr = diag.trace

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 2, 3, wspace=0.4, hspace=0.55, top=0.06, bottom=0.075)
        signals = (
            ("gap", "gap x1 [mm]"),
            ("position", "horizontal position x3 [mm]"),
            ("gap_rate", "gap rate x2 [mm/s]"),
            ("position_rate", "horizontal rate x4 [mm/s]"),
        )
        slots = ((0, 0), (0, 1), (1, 0), (1, 1))
        for (key, label), (r, c) in zip(signals, slots, strict=True):
            ax = fig.add_subplot(gs[r, c])
            b = tr.binned[key]
            for a in range(2):
                ax.errorbar(
                    b.centers * M_TO_MM,
                    b.mean[a],
                    yerr=2 * b.stderr[a],
                    color=AXIS_COLORS[a],
                    lw=1,
                    marker=".",
                    ms=3,
                )
            ax.axhline(0, color="0.5", lw=0.6)
            ax.set_xlabel(label)
            ax.set_ylabel("mean residual [m/s²]")
        for a in range(2):
            ax = fig.add_subplot(gs[a, 2])
            ax.plot(tr.lags * 1e3, tr.lag_correlation[a], color=AXIS_COLORS[a])
            ax.axhline(0, color="0.5", lw=0.6)
            ax.set_xlabel("lag [ms]")
            ax.set_ylabel(f"corr({AXES[a]} residual,\nits current's rate) [-]")
        h = [Line2D([], [], color=c) for c in AXIS_COLORS]
        _legend_below(fig, rect, h, list(AXES), 2, y=-0.008)
        return caption(
            fig,
            rect,
            "The base model's residual against the signals effects depend on",
            "Bin means ± 2 standard errors; right: correlation with the rate of the axis's own current "
            "(a lag of the amplifiers would show as a peak).",
        )

    return draw


def effects_plot(diag: Diagnosis) -> Draw:
    """Every found effect on every axis it acts on, before and after, held out."""

    def draw(fig: Figure, rect) -> str:
        every = panels(diag)
        ncol = min(3, max(1, len(every)))
        nrow = -(-len(every) // ncol)
        gs = grid(fig, rect, nrow, ncol, wspace=0.38, hspace=0.5, top=0.045, bottom=0.08)
        for k, (effect, a) in enumerate(every):
            ax = fig.add_subplot(gs[k // ncol, k % ncol])
            _before_after(ax, diag, effect, a, effect_contribution(diag, effect))
        h, lab = _before_after_handles()
        _legend_below(fig, rect, h, lab, 2, y=-0.008)
        return caption(fig, rect, "Each found effect on held-out data: the residual before and after")

    return draw


def timeseries_plot(diag: Diagnosis, seconds: float = 3.0) -> Draw:
    d = diag.data
    hold = np.nonzero(diag.holdout)[0]
    k0 = hold[0]
    k1 = min(hold[-1], k0 + int(seconds / d.sample_time))

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 2, 1, hspace=0.25, top=0.045, bottom=0.08)
        sl = slice(k0, k1)
        t = d.t[sl]
        for a in range(2):
            ax = fig.add_subplot(gs[a, 0])
            meas = d.acc[a, sl]
            ax.plot(t, meas, "k", lw=1.1)
            ax.plot(t, meas - diag.residual_before[a, sl], color=BEFORE, lw=0.9)
            ax.plot(t, meas - diag.residual_after[a, sl], color=AFTER, lw=0.9, ls="--")
            ax.set_ylabel(f"{AXES[a]} acceleration\n[m/s²]")
            if a == 0:
                ax.tick_params(labelbottom=False)
        ax.set_xlabel("time in the log [s] (held-out block)")
        h = [Line2D([], [], color="k"), Line2D([], [], color=BEFORE), Line2D([], [], color=AFTER, ls="--")]
        _legend_below(
            fig, rect, h, ["measured (filtered)", "base model", "with the found effects"], 3, y=-0.008
        )
        return caption(fig, rect, "Held-out data: measured and modelled accelerations")

    return draw


def compensation_plot(study: CompensationStudy) -> Draw:
    """Tracking error of the FL regulator before and after compensating the found effects."""

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 2, 1, hspace=0.25, top=0.045, bottom=0.08)
        rb, ra = study.result_before, study.result_after
        for a, (axis, j) in enumerate((("vertical", 0), ("horizontal", 3))):
            ax = fig.add_subplot(gs[a, 0])
            for res, color in ((rb, BEFORE), (ra, AFTER)):
                ax.plot(*thin(res.t, (res.y[a] - res.reference[j]) * M_TO_UM), color=color, lw=0.6)
            bands(ax, M_TO_UM)
            lim = 1.1 * max(np.nanmax(np.abs((r.y[a] - r.reference[j]) * M_TO_UM)) for r in (rb, ra))
            ax.set_ylim(-lim, lim)
            ax.set_xlim(0, rb.t[-1])
            ax.set_ylabel(f"{axis} error [µm]")
            if a == 0:
                ax.tick_params(labelbottom=False)
        ax.set_xlabel("time [s]")
        h = [Line2D([], [], color=BEFORE), Line2D([], [], color=AFTER)]
        _legend_below(fig, rect, h, [rb.controller, ra.controller], 2, y=-0.008)
        return caption(
            fig,
            rect,
            f"FL regulator on {study.scenario}: before and after compensating the found effects",
            "Encoder reading − reference; shaded: the 10 µm band.",
        )

    return draw
