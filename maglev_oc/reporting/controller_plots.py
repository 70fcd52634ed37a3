"""Figures of the controller comparison, laid out like 002 Figs. 9-13 (positions, velocities,
errors, currents; the ellipse in the x3-x1 plane).

Each function returns a ``draw(fig, rect) -> title`` for a :class:`~maglev_oc.reporting.pdf.Plot`
block. Errors are encoder readings minus reference on linear axes with the papers' 0.1 mm and
10 um bands; time axes span the transient shown; one comparison per panel (a controller beside
the FL regulator, or the printed gains beside the retuned ones), small multiples otherwise.
Nothing here computes a result: the runs come from :mod:`maglev_oc.sim.comparison`.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from maglev_oc.model.hardware import PEAK_CURRENT_LIMIT, STOPPER_GAP
from maglev_oc.reporting.pdf import caption, grid
from maglev_oc.reporting.style import bands, controller_colour, thin
from maglev_oc.sim.comparison import StepSweep
from maglev_oc.sim.engine import SimulationResult
from maglev_oc.sim.metrics import BANDS, RunMetrics
from maglev_oc.units import M_TO_MM

__all__ = [
    "ERROR_VIEW",
    "calibrated_plot",
    "controller_steps_plot",
    "currents_plot",
    "ellipse_plot",
    "key_plot",
    "linear_plot",
    "retuned_plot",
    "setpoint_plot",
    "sweep_plot",
]

ERROR_VIEW = 0.5  # [mm] error axes span +- this (transients beyond it are clipped, and say so)
STEP_COLOURS = ("#1b9e77", "#d95f02", "#7570b3", "#e7298a", "#66a61e")
"""The five set-point steps, wherever they are told apart."""
_GREY = "0.62"
_REFERENCE = dict(color="k", ls="--", lw=0.8)


def _room(text: str, titled: bool = True) -> float:
    """Page fraction to leave above a block's axes for its caption (title and ``text`` wrapped as
    :func:`~maglev_oc.reporting.pdf.caption` wraps it) and, if ``titled``, the axes' titles."""
    lines = len(textwrap.wrap(text, 125)) if text else 0
    return 0.03 + 0.0128 * lines + (0.016 if titled else 0.0)


def _legend_below(fig: Figure, rect, handles, labels, ncol: int, offset: float = 0.004) -> None:
    """A legend under a block's axes, outside the data."""
    fig.legend(
        handles, labels, loc="lower center", ncol=ncol, fontsize=7.5, bbox_to_anchor=(0.54, rect[1] - offset)
    )


def _segment(r: SimulationResult, start: float, window: float) -> np.ndarray:
    return (r.t >= start - 1e-12) & (r.t < start + window)


def _error(r: SimulationResult) -> np.ndarray:
    """Reading minus reference, (2, n) [m]: vertical, horizontal."""
    return np.vstack([r.y[0] - r.reference[0], r.y[1] - r.reference[3]])


def _error_axis(ax, limit: float = ERROR_VIEW) -> None:
    bands(ax, M_TO_MM)
    ax.set_ylim(-limit, limit)


def _current_axis(ax, peaks: Sequence[float], low: float = 0.0) -> None:
    """y from ``low`` to just above the signal; the 9 A rating drawn where the signal comes near it."""
    top = max(max(peaks), 1e-3)
    if top > 0.75 * PEAK_CURRENT_LIMIT:
        ax.axhline(PEAK_CURRENT_LIMIT, color="tab:red", ls=":", lw=0.9)
        top = max(top, PEAK_CURRENT_LIMIT)
    ax.set_ylim(low, 1.08 * top)


# --- page 1 ----------------------------------------------------------------------------------------------
def key_plot(result: SimulationResult, metrics: RunMetrics, limits: dict[str, float], window: float = 3.0):
    """The error after each set-point change, both axes: the reading (top) and the largest |error|
    from then on (bottom), against the papers' settling times."""

    text = (
        "Top: reading − set-point, clipped to ±0.3 mm. Bottom: the largest |error| from then on; a step has "
        "settled where it enters the band for good. Shaded: 0.1 mm and 10 µm. Dashed: the papers' "
        f"{limits['vertical']:g} s (vertical) and {limits['horizontal']:g} s (horizontal); dotted: their "
        f"fifth step's {limits['horizontal_fifth']:g} s."
    )

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 2, 2, wspace=0.1, hspace=0.12, bottom=0.075, top=_room(text))
        top = [fig.add_subplot(gs[0, j]) for j in range(2)]
        low = [fig.add_subplot(gs[1, j]) for j in range(2)]
        err = _error(result)
        for k, s in enumerate(metrics.steps):
            seg = _segment(result, s.time, window)
            t = result.t[seg] - s.time
            for j in range(2):
                e = err[j, seg]
                after = np.maximum.accumulate(np.abs(e)[::-1])[::-1]
                c = STEP_COLOURS[k % len(STEP_COLOURS)]
                top[j].plot(t, e * M_TO_MM, color=c, lw=0.9, label=f"step {k + 1} at {s.time:g} s")
                low[j].plot(t, after * M_TO_MM, color=c, lw=1.1)
        for j, axis in enumerate(("vertical (gap)", "horizontal")):
            _error_axis(top[j], 0.3)
            low[j].axhspan(0, BANDS[0] * M_TO_MM, color="0.93", lw=0, zorder=0)
            low[j].axhspan(0, BANDS[1] * M_TO_MM, color="0.8", lw=0, zorder=0)
            low[j].set_ylim(0, 0.3)
            top[j].set_title(axis)
            top[j].tick_params(labelbottom=False)
            low[j].set_xlabel("time since the set-point change [s]")
            for ax in (top[j], low[j]):
                ax.set_xlim(0, window)
                if j:
                    ax.tick_params(labelleft=False)
        for ax in (top[0], low[0]):
            ax.axvline(limits["vertical"], color="k", ls="--", lw=0.8)
        for ax in (top[1], low[1]):
            ax.axvline(limits["horizontal"], color="k", ls="--", lw=0.8)
            ax.axvline(limits["horizontal_fifth"], color="k", ls=":", lw=0.8)
        top[0].set_ylabel("error [mm]")
        low[0].set_ylabel("|error| from\nthen on [mm]", fontsize=7.5)
        handles, labels = top[0].get_legend_handles_labels()
        _legend_below(fig, rect, handles, labels, ncol=5)
        return caption(
            fig, rect, "Key figure: the FL regulator's error after each set-point change (rig twin)", text
        )

    return draw


# --- 002 Figs. 9-10 --------------------------------------------------------------------------------------
def setpoint_plot(result: SimulationResult, title: str, text: str):
    """Positions, velocities, errors and currents of a set-point sequence, vertical beside horizontal."""

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 4, 2, wspace=0.22, hspace=0.14, bottom=0.05, top=_room(text, False), left=0.1)
        t = result.t
        err = _error(result)
        rows = (
            ((0, "gap x1 [mm]"), (2, "horizontal position x3 [mm]")),
            ((1, "gap velocity x2 [mm/s]"), (3, "horizontal velocity x4 [mm/s]")),
        )
        axes = [[fig.add_subplot(gs[i, j]) for j in range(2)] for i in range(4)]
        for j in range(2):
            (state, label), ref_row = rows[0][j], (0, 3)[j]
            axes[0][j].plot(*thin(t, result.x[state] * M_TO_MM), color=controller_colour(result.controller))
            axes[0][j].plot(t, result.reference[ref_row] * M_TO_MM, **_REFERENCE)
            axes[0][j].set_ylabel(label)
            state, label = rows[1][j]
            axes[1][j].plot(*thin(t, result.x[state] * M_TO_MM), color=controller_colour(result.controller))
            axes[1][j].set_ylabel(label)
            axes[2][j].plot(*thin(t, err[j] * M_TO_MM), color=controller_colour(result.controller), lw=0.7)
            _error_axis(axes[2][j])
            axes[2][j].set_ylabel(("gap", "horizontal")[j] + " error [mm]")
            current = result.u[(1, 0)[j]]
            axes[3][j].plot(*thin(t, current), color=controller_colour(result.controller), lw=0.7)
            axes[3][j].set_ylabel(("i_d [A]", "i_q [A]")[j])
            peak = float(np.nanmax(np.abs(current)))
            axes[3][j].set_ylim(-1.08 * peak, 1.08 * peak)
            if peak > 0.75 * PEAK_CURRENT_LIMIT:
                for sign in (1, -1):
                    axes[3][j].axhline(sign * PEAK_CURRENT_LIMIT, color="tab:red", ls=":", lw=0.9)
                axes[3][j].set_ylim(-1.08 * max(peak, 9), 1.08 * max(peak, 9))
            axes[3][j].set_xlabel("time [s]")
            for i in range(4):
                axes[i][j].set_xlim(t[0], t[-1])
                if i < 3:
                    axes[i][j].tick_params(labelbottom=False)
        handles = [
            Line2D([], [], color=controller_colour(result.controller), label=result.controller),
            Line2D([], [], label="set-point", **_REFERENCE),
        ]
        _legend_below(fig, rect, handles, [h.get_label() for h in handles], ncol=2)
        return caption(fig, rect, title, text)

    return draw


# --- every controller on one step ------------------------------------------------------------------------
def controller_steps_plot(
    results: Sequence[SimulationResult], reference: SimulationResult, step_time: float, window: float
):
    """Small multiples: a row per controller (gap, its error, horizontal position, its error over
    ``window`` seconds from the set-point change at ``step_time``), the FL regulator in grey in
    every panel."""

    text = (
        "One row per controller, its colour over the FL regulator's grey; errors are readings − set-point "
        f"on ±{ERROR_VIEW:g} mm with the 0.1 mm and 10 µm bands shaded."
    )

    def draw(fig: Figure, rect) -> str:
        n = len(results)
        gs = grid(fig, rect, n, 4, wspace=0.32, hspace=0.16, bottom=0.055, top=_room(text), left=0.09)
        for i, r in enumerate(results):
            row_axes = [fig.add_subplot(gs[i, j]) for j in range(4)]
            for res, colour, lw in ((reference, _GREY, 1.4), (r, controller_colour(r.controller), 0.9)):
                seg = _segment(res, step_time, window)
                t = res.t[seg] - step_time
                err = _error(res)[:, seg]
                for j, row in enumerate((0, 2)):
                    row_axes[2 * j].plot(t, res.x[row, seg] * M_TO_MM, color=colour, lw=lw)
                    row_axes[2 * j + 1].plot(t, err[j] * M_TO_MM, color=colour, lw=lw)
            seg = _segment(reference, step_time, window)
            for j, ref_row in enumerate((0, 3)):
                t = reference.t[seg] - step_time
                row_axes[2 * j].plot(t, reference.reference[ref_row, seg] * M_TO_MM, **_REFERENCE)
            for j, ax in enumerate(row_axes):
                ax.set_xlim(0, window)
                if j % 2:
                    _error_axis(ax)
                if i < n - 1:
                    ax.tick_params(labelbottom=False)
                else:
                    ax.set_xlabel("time since the change [s]")
            name = r.controller.replace("(no feedforward)", "\n(no feedforward)").replace(", ", ",\n")
            row_axes[0].set_ylabel(name, color=controller_colour(r.controller), fontsize=8)
            if not r.success:
                row_axes[0].text(
                    0.97,
                    0.08,
                    "hit a stopper",
                    transform=row_axes[0].transAxes,
                    ha="right",
                    fontsize=7,
                    color="r",
                )
            if i == 0:
                for ax, title in zip(
                    row_axes,
                    ("gap [mm]", "gap error [mm]", "horizontal [mm]", "horizontal error [mm]"),
                    strict=True,
                ):
                    ax.set_title(title, fontsize=8.5)
        handles = [
            Line2D([], [], color=_GREY, lw=1.4, label=f"{reference.controller} (every panel)"),
            Line2D([], [], label="set-point", **_REFERENCE),
        ]
        _legend_below(fig, rect, handles, [h.get_label() for h in handles], ncol=2)
        return caption(
            fig,
            rect,
            f"Gap and horizontal position after the change at t = {step_time:g} s (rig twin)",
            text,
        )

    return draw


def currents_plot(results: Sequence[SimulationResult], metrics: Sequence[RunMetrics], window: float = 0.4):
    """The commanded current magnitude after each set-point change, one panel per controller,
    against the amplifiers' 9 A peak rating."""

    text = (
        f"The magnitude of the commanded (i_q, i_d) over the first {window * 1e3:.0f} ms after each change; "
        "the peaks come in the first milliseconds. The rig twin's amplifier clips what is above 9 A."
    )

    def draw(fig: Figure, rect) -> str:
        n = len(results)
        ncol = 2
        nrow = -(-n // ncol)
        gs = grid(fig, rect, nrow, ncol, wspace=0.1, hspace=0.5, bottom=0.075, top=_room(text))
        axes = []
        top = max(float(np.nanmax(np.hypot(r.u[0], r.u[1]))) for r in results)
        for i, (r, m) in enumerate(zip(results, metrics, strict=True)):
            ax = fig.add_subplot(gs[i // ncol, i % ncol])
            axes.append(ax)
            mag = np.hypot(r.u[0], r.u[1])
            for k, s in enumerate(m.steps):
                seg = _segment(r, s.time, window)
                ax.plot(
                    (r.t[seg] - s.time) * 1e3, mag[seg], color=STEP_COLOURS[k], lw=0.9, label=f"step {k + 1}"
                )
            ax.axhline(PEAK_CURRENT_LIMIT, color="tab:red", ls=":", lw=0.9)
            ax.set_ylim(0, 1.08 * max(top, PEAK_CURRENT_LIMIT))
            ax.set_xlim(0, window * 1e3)
            over = m.over_peak_rating * r.sample_time * 1e3
            note = f"peak {m.peak_current:.1f} A" + (f", {over:.1f} ms over 9 A" if over else "")
            ax.set_title(f"{r.controller}: {note}", fontsize=8, color=controller_colour(r.controller))
            if i % ncol:
                ax.tick_params(labelleft=False)
            else:
                ax.set_ylabel("|i| [A]")
            if i // ncol == nrow - 1 or i + ncol >= n:
                ax.set_xlabel("time since the set-point change [ms]")
            else:
                ax.tick_params(labelbottom=False)
        handles, labels = axes[-1].get_legend_handles_labels()
        handles.append(Line2D([], [], color="tab:red", ls=":", lw=0.9))
        labels.append("9 A peak rating")
        _legend_below(fig, rect, handles, labels, ncol=6)
        return caption(
            fig,
            rect,
            "Commanded current after each of the five set-point changes (rig twin)",
            text,
        )

    return draw


# --- 002 Fig. 11 -----------------------------------------------------------------------------------------
def retuned_plot(
    pairs: Sequence[tuple[str, SimulationResult, SimulationResult]], step_time: float, window: float
):
    """Printed against retuned K_v on the vertical step at ``step_time``: gap, its error, velocity and
    i_d, one column per twin in ``pairs`` (twin name, printed run, retuned run)."""
    text = "FL regulator with the printed and with the retuned vertical gains; the same horizontal gains."

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 4, len(pairs), wspace=0.2, hspace=0.13, bottom=0.075, top=_room(text), left=0.1)
        for j, (twin, printed, retuned) in enumerate(pairs):
            axes = [fig.add_subplot(gs[i, j]) for i in range(4)]
            for res, ls in ((printed, "-"), (retuned, "--")):
                seg = _segment(res, step_time, window)
                t = res.t[seg] - step_time
                c = controller_colour(res.controller)
                axes[0].plot(t, res.x[0, seg] * M_TO_MM, color=c, ls=ls)
                axes[1].plot(t, (res.y[0, seg] - res.reference[0, seg]) * M_TO_MM, color=c, ls=ls, lw=0.9)
                axes[2].plot(t, res.x[1, seg] * M_TO_MM, color=c, ls=ls, lw=0.9)
                axes[3].plot(t, res.u[1, seg], color=c, ls=ls, lw=0.9)
            seg = _segment(printed, step_time, window)
            axes[0].plot(printed.t[seg] - step_time, printed.reference[0, seg] * M_TO_MM, **_REFERENCE)
            _error_axis(axes[1])
            axes[0].set_title(f"{twin} twin")
            for i, (ax, label) in enumerate(
                zip(axes, ("gap x1 [mm]", "gap error [mm]", "gap velocity [mm/s]", "i_d [A]"), strict=True)
            ):
                ax.set_xlim(0, window)
                if j == 0:
                    ax.set_ylabel(label)
                if i < 3:
                    ax.tick_params(labelbottom=False)
            axes[3].set_xlabel("time since the set-point change [s]")
        c = controller_colour(pairs[0][1].controller)
        handles = [
            Line2D([], [], color=c, label="printed K_v (poles -11..-15)"),
            Line2D([], [], color=c, ls="--", label="retuned K_v (poles -57.9, -9.9 ± 11.3i, -1.6 ± 1.4i)"),
            Line2D([], [], label="set-point", **_REFERENCE),
        ]
        _legend_below(fig, rect, handles, [h.get_label() for h in handles], ncol=3)
        return caption(
            fig,
            rect,
            f"The retuned K_v on the step at t = {step_time:g} s (002 Fig. 11)",
            text,
        )

    return draw


# --- 002 Fig. 12 -----------------------------------------------------------------------------------------
def linear_plot(columns: Sequence[tuple[str, Sequence[SimulationResult]]], window: float):
    """Linear against nonlinear regulators: a column per scenario (title, runs), rows gap,
    horizontal position and commanded current magnitude."""
    text = (
        "The linear regulator has the FL regulator's poles on the linearization at the target; with the "
        "equilibrium current added it follows the FL regulator closely. Dash-dotted: the gap stopper."
    )

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 3, len(columns), wspace=0.18, hspace=0.14, bottom=0.085, top=_room(text))
        first = None
        for j, (title, runs) in enumerate(columns):
            axes = [fig.add_subplot(gs[i, j]) for i in range(3)]
            first = first or axes[0]
            peaks = []
            for k, r in enumerate(runs):
                show = r.t <= window
                ls = ("-", "--", ":")[k % 3]
                c = controller_colour(r.controller)
                label = r.controller + ("" if r.success else " (hits the stopper)")
                axes[0].plot(r.t[show], r.x[0, show] * M_TO_MM, color=c, ls=ls, label=r.controller)
                axes[1].plot(r.t[show], r.x[2, show] * M_TO_MM, color=c, ls=ls)
                mag = np.hypot(r.u[0, show], r.u[1, show])
                axes[2].plot(r.t[show], mag, color=c, ls=ls, lw=0.9)
                peaks.append(float(np.nanmax(mag)))
                if not r.success:
                    axes[0].text(
                        0.98, 0.05, label, transform=axes[0].transAxes, ha="right", fontsize=7, color=c
                    )
            r0 = runs[0]
            show = r0.t <= window
            axes[0].plot(r0.t[show], r0.reference[0, show] * M_TO_MM, **_REFERENCE, label="set-point")
            axes[1].plot(r0.t[show], r0.reference[3, show] * M_TO_MM, **_REFERENCE)
            least = min(float(np.nanmin(r.x[0, r.t <= window])) for r in runs)
            if least < STOPPER_GAP[0] + 4e-3:  # the stopper only where a run comes near it
                axes[0].axhline(STOPPER_GAP[0] * M_TO_MM, color="0.3", ls="-.", lw=1.0)
            axes[0].set_title(title)
            _current_axis(axes[2], peaks)
            for i, (ax, label) in enumerate(
                zip(axes, ("gap x1 [mm]", "horizontal x3 [mm]", "|(i_q, i_d)| [A]"), strict=True)
            ):
                ax.set_xlim(0, window)
                if j == 0:
                    ax.set_ylabel(label)
                if i < 2:
                    ax.tick_params(labelbottom=False)
            axes[2].set_xlabel("time [s]")
        handles, labels = first.get_legend_handles_labels()
        _legend_below(fig, rect, handles, labels, ncol=4)
        return caption(
            fig, rect, "The papers' small and large steps, linear against nonlinear (rig twin)", text
        )

    return draw


def sweep_plot(sweeps: Sequence[tuple[str, StepSweep]]):
    """Smallest gap reached against the target gap of the step from 26 mm, one panel per twin."""
    text = "Steps from (26, 0) mm to (target gap, 20) mm, each run 5 s; dash-dotted: the gap stopper."

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 1, len(sweeps), wspace=0.12, bottom=0.1, top=_room(text))
        axes = [fig.add_subplot(gs[0, j]) for j in range(len(sweeps))]
        for ax, (twin, sweep) in zip(axes, sweeps, strict=True):
            g = sweep.target_gaps * M_TO_MM
            for i, name in enumerate(sweep.controllers):
                ok = sweep.success[i]
                c = controller_colour(name)
                ls = ("-", "--", ":")[i % 3]
                ax.plot(g, sweep.min_gap[i] * M_TO_MM, color=c, ls=ls, label=name)
                ax.plot(g[~ok], sweep.min_gap[i, ~ok] * M_TO_MM, "x", color=c, ms=7, mew=1.6)
            ax.plot(g, g, color="k", ls=":", lw=0.8, label="target gap")
            ax.axhline(STOPPER_GAP[0] * M_TO_MM, color="0.3", ls="-.", lw=1.0)
            ax.set_title(f"{twin} twin")
            ax.set_xlabel("target gap [mm]")
        axes[0].set_ylabel("least gap [mm]")
        for ax in axes[1:]:
            ax.tick_params(labelleft=False)
        handles, labels = axes[0].get_legend_handles_labels()
        handles.append(Line2D([], [], color="k", marker="x", ls="", mew=1.6))
        labels.append("hits the stopper")
        _legend_below(fig, rect, handles, labels, ncol=5)
        return caption(fig, rect, "How large a step each regulator copes with", text)

    return draw


# --- 002 Fig. 13 -----------------------------------------------------------------------------------------
def ellipse_plot(results: Sequence[SimulationResult], metrics: Sequence[RunMetrics], start: float):
    """The sinusoids: the x3-x1 plane from ``start`` on (one panel per run, the reference in black),
    and each run's errors over time, vertical and horizontal."""
    text = (
        "Left: the platform in the x3-x1 plane, the reference in black (axes not to scale). Right: reading "
        "− reference; dashed: ± the mean |error|; shaded: the 0.1 mm and 10 µm bands."
    )

    def draw(fig: Figure, rect) -> str:
        n = len(results)
        gs = grid(
            fig,
            rect,
            2 * n,
            2,
            wspace=0.22,
            hspace=0.3,
            bottom=0.045,
            top=_room(text),
            width_ratios=(1, 1.6),
        )
        for i, (r, m) in enumerate(zip(results, metrics, strict=True)):
            late = r.t >= start
            c = controller_colour(r.controller)
            ax = fig.add_subplot(gs[2 * i : 2 * i + 2, 0])
            ax.plot(r.reference[3, late] * M_TO_MM, r.reference[0, late] * M_TO_MM, color="k", lw=0.8)
            ax.plot(r.x[2, late] * M_TO_MM, r.x[0, late] * M_TO_MM, color=c, lw=0.8)
            ax.set_ylabel("gap x1 [mm]")
            ax.text(
                0.5,
                0.5,
                f"{r.controller}\nfrom {start:g} s",
                transform=ax.transAxes,
                ha="center",
                va="center",
                fontsize=8,
                color=c,
            )
            if i == n - 1:
                ax.set_xlabel("horizontal x3 [mm]")
            err = _error(r)
            for j, axis in enumerate(("gap", "horizontal")):
                ax_e = fig.add_subplot(gs[2 * i + j, 1])
                ax_e.plot(*thin(r.t[late], err[j, late] * M_TO_MM), color=c, lw=0.6)
                for sign in (1, -1):
                    ax_e.axhline(sign * m.mean_error[j] * M_TO_MM, color="k", ls="--", lw=0.7)
                limit = max(1.15 * float(np.nanmax(np.abs(err[j, late]))) * M_TO_MM, 0.12)
                bands(ax_e, M_TO_MM)
                ax_e.set_ylim(-limit, limit)
                ax_e.set_xlim(start, r.t[-1])
                ax_e.set_ylabel(f"{axis} error [mm]", fontsize=8)
                ax_e.text(
                    0.99,
                    0.95,
                    f"mean |e| {m.mean_error[j] * M_TO_MM:.3f} mm, peak {m.peak_error[j] * M_TO_MM:.2f} mm",
                    transform=ax_e.transAxes,
                    ha="right",
                    va="top",
                    fontsize=7,
                    bbox=dict(fc="white", ec="none", alpha=0.85),
                )
                if i < n - 1 or j == 0:
                    ax_e.tick_params(labelbottom=False)
                else:
                    ax_e.set_xlabel("time [s]")
        return caption(fig, rect, "The ellipse on the rig twin", text)

    return draw


# --- the calibrated twin ---------------------------------------------------------------------------------
def calibrated_plot(panels: Sequence[tuple[str, object, object, float, float]], twin: str):
    """Gap trajectories of the calibration's runs: a panel per (title, trace on the rig twin, trace on
    the calibrated twin, t0, window), traces as :class:`~maglev_oc.sim.calibration.Trace` (t, gap,
    reference at 1 kHz); the rig twin grey, the calibrated twin in the controller's colour."""
    text = (
        f"Gap on the rig twin (grey) and on {twin} (colour), from the calibration's runs. Dash-dotted: the "
        "gap stopper; touching it fails the run (the stopper holds the mover; the run goes on)."
    )

    def draw(fig: Figure, rect) -> str:
        ncol = 2
        nrow = -(-len(panels) // ncol)
        gs = grid(fig, rect, nrow, ncol, wspace=0.15, hspace=0.55, bottom=0.04, top=_room(text), left=0.08)
        for k, (title, nominal, calibrated, t0, window) in enumerate(panels):
            ax = fig.add_subplot(gs[k // ncol, k % ncol])
            for tr, colour, lw in (
                (nominal, _GREY, 1.3),
                (calibrated, controller_colour(calibrated.controller), 1.0),
            ):
                show = (tr.t >= t0) & (tr.t <= t0 + window)
                ax.plot(tr.t[show] - t0, tr.gap[show] * M_TO_MM, color=colour, lw=lw)
            show = (nominal.t >= t0) & (nominal.t <= t0 + window)
            ax.plot(nominal.t[show] - t0, nominal.reference[show] * M_TO_MM, **_REFERENCE)
            ax.axhline(STOPPER_GAP[0] * M_TO_MM, color="0.3", ls="-.", lw=1.0)
            ax.set_title(title, fontsize=8.5, color=controller_colour(calibrated.controller))
            ax.set_xlim(0, window)
            ax.set_xlabel("time since the change [s]" if t0 else "time [s]")
            if k % ncol == 0:
                ax.set_ylabel("gap x1 [mm]")
        return caption(fig, rect, "The papers' step experiments on the calibrated twin", text)

    return draw
