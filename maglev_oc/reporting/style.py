"""One look for every report: the matplotlib style, a colour per controller, and the helpers every
time-series figure uses (thinning that keeps peaks, the papers' error bands).

:class:`maglev_oc.reporting.pdf.PdfReport` applies :data:`RC` to every figure made inside its
``with`` block, so no report sets fonts, grids or line widths of its own.
"""

from __future__ import annotations

import numpy as np

from maglev_oc.sim.metrics import BANDS

__all__ = ["CONTROLLER_COLOURS", "RC", "bands", "controller_colour", "thin"]

RC = {
    "font.family": "DejaVu Sans",
    "font.size": 8.5,
    "axes.titlesize": 9.5,
    "axes.labelsize": 8.5,
    "axes.grid": True,
    "grid.color": "0.88",
    "grid.linewidth": 0.5,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "xtick.labelsize": 7.5,
    "ytick.labelsize": 7.5,
    "legend.fontsize": 7.5,
    "legend.frameon": False,
    "lines.linewidth": 1.0,
    "figure.dpi": 100,
    "savefig.dpi": 150,
    "pdf.fonttype": 42,  # TrueType: text stays text (searchable, copyable)
}

# One colour per controller in every report (a controller's display name -> colour).
CONTROLLER_COLOURS = {
    "FL regulator": "#1f77b4",
    "linear regulator": "#ff7f0e",
    "linear regulator (no feedforward)": "#8c564b",
    "LQR": "#2ca02c",
    "PID": "#d62728",
    "NMPC": "#9467bd",
}
_OTHER = "0.35"


def controller_colour(name: str) -> str:
    """The colour of ``name`` (a variant such as "FL regulator, retuned K_v" takes its base's)."""
    for key in sorted(CONTROLLER_COLOURS, key=len, reverse=True):
        if name == key or name.startswith(key + " ") or name.startswith(key + ","):
            return CONTROLLER_COLOURS[key]
    return _OTHER


MAX_POINTS = 3000


def thin(t: np.ndarray, y: np.ndarray, max_points: int = MAX_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """At most about 2 * ``max_points`` points, keeping each block's minimum and maximum (the 10 µm
    encoder steps and the peaks survive)."""
    k = max(1, t.size // max_points)
    if k == 1:
        return t, y
    starts = np.arange(0, t.size, k)
    low, high = np.fmin.reduceat(y, starts), np.fmax.reduceat(y, starts)
    ends = np.minimum(starts + k, t.size) - 1
    return np.column_stack([t[starts], t[ends]]).ravel(), np.column_stack([low, high]).ravel()


def bands(ax, unit: float) -> None:
    """The papers' 0.1 mm and 10 µm error bands on ``ax``, ``unit`` display units per metre."""
    ax.axhspan(-BANDS[0] * unit, BANDS[0] * unit, color="0.93", zorder=0, lw=0)
    ax.axhspan(-BANDS[1] * unit, BANDS[1] * unit, color="0.8", zorder=0, lw=0)
