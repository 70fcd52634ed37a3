"""Figures of the controller comparison (like 001/002 Figs. 9-13: states, errors, currents)."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from maglev_oc.model.hardware import PEAK_CURRENT_LIMIT
from maglev_oc.reporting.pdf import new_figure
from maglev_oc.reporting.style import controller_colour
from maglev_oc.sim.comparison import Comparison, StepSweep
from maglev_oc.sim.engine import SimulationResult
from maglev_oc.sim.metrics import BANDS
from maglev_oc.units import M_TO_MM

__all__ = ["MAX_POINTS", "scenario_figure", "sweep_figure"]

MAX_POINTS = 2500


def _stride(n: int) -> int:
    return max(1, n // MAX_POINTS)


def _envelope(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Block maxima of |y| (keeps the peaks when a long trace is thinned for plotting)."""
    k = _stride(t.size)
    n = (t.size // k) * k
    return t[:n:k], np.nanmax(np.abs(y[:n]).reshape(-1, k), axis=1)


def scenario_figure(cmp: Comparison, scenario: str, twin: str) -> Figure:
    """Positions with references, |error| (log) and currents, per axis, all controllers."""
    fig = new_figure((8.27, 10.5))
    axes = fig.subplots(3, 2, sharex=True)
    sc = cmp.scenarios[scenario]
    first: SimulationResult | None = None
    # drawn in reverse so that the papers' FL regulator (first) ends up on top, thicker
    for name in reversed(cmp.controllers):
        res = cmp.results.get((name, scenario, twin))
        if res is None:
            continue
        first = first or res
        k = _stride(res.t.size)
        c = controller_colour(name)
        lw = 1.6 if name == cmp.controllers[0] else 0.8
        label = name if res.success else f"{name} (failed)"
        for col, (row_x, row_r, row_u) in enumerate(((0, 0, 1), (2, 3, 0))):
            axes[0, col].plot(res.t[::k], res.x[row_x, ::k] * M_TO_MM, color=c, lw=lw, label=label)
            te, ee = _envelope(res.t, (res.y[col] - res.reference[row_r]))
            axes[1, col].semilogy(te, np.maximum(ee * M_TO_MM, 1e-4), color=c, lw=lw)
            axes[2, col].plot(res.t[::k], res.u[row_u, ::k], color=c, lw=lw)
    if first is not None:
        k = _stride(first.t.size)
        for col, row_r in enumerate((0, 3)):
            axes[0, col].plot(
                first.t[::k], first.reference[row_r, ::k] * M_TO_MM, "k--", lw=0.8, label="reference"
            )
    for col in range(2):
        for band in BANDS:
            axes[1, col].axhline(band * M_TO_MM, color="0.5", ls=":", lw=0.8)
        axes[1, col].set_ylim(1e-4, 50)
        for lim in (PEAK_CURRENT_LIMIT, -PEAK_CURRENT_LIMIT):
            axes[2, col].axhline(lim, color="tab:red", ls=":", lw=0.8)
        axes[2, col].set_xlabel("time [s]")
        for row in range(3):
            axes[row, col].grid(alpha=0.3)
    axes[0, 0].set_ylabel("air gap x1 [mm]")
    axes[0, 1].set_ylabel("horizontal position x3 [mm]")
    axes[1, 0].set_ylabel("|gap error| [mm] (encoder)")
    axes[1, 1].set_ylabel("|horizontal error| [mm] (encoder)")
    axes[2, 0].set_ylabel("i_d = u2 [A]")
    axes[2, 1].set_ylabel("i_q = u1 [A]")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    axes[0, 0].legend(handles[::-1], labels[::-1], fontsize=7, loc="best")
    axes[1, 0].text(
        0.01, 0.02, "dotted: 0.1 mm and 10 µm", transform=axes[1, 0].transAxes, fontsize=7, color="0.4"
    )
    fig.suptitle(f"{sc.title} — {twin} twin")
    return fig


def sweep_figure(sweep: StepSweep) -> Figure:
    fig = new_figure((8.27, 4.8))
    ax = fig.subplots()
    g = sweep.target_gaps * M_TO_MM
    for i, name in enumerate(sweep.controllers):
        ok = sweep.success[i]
        ax.plot(g, sweep.min_gap[i] * M_TO_MM, "-", color=controller_colour(name), label=name)
        ax.plot(g[~ok], sweep.min_gap[i, ~ok] * M_TO_MM, "x", color=controller_colour(name), ms=9, mew=2)
    ax.plot(g, g, "k:", lw=0.8, label="target gap")
    ax.set_xlabel(
        "target gap [mm] (start 26 mm, horizontal step to %.0f mm)" % (sweep.target_position * M_TO_MM)
    )
    ax.set_ylabel("smallest gap reached [mm]")
    ax.set_title("Step size each controller copes with (x: hit a stopper / diverged)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig
