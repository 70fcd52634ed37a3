"""Figures and table rows of a model validation (:mod:`maglev_oc.validation`): the residuals'
autocorrelation and their cross-correlation with the currents with the 95 % bands, and the fit %
table. Drawing only: every number comes from :class:`~maglev_oc.validation.Validation`."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

import numpy as np
from matplotlib.figure import Figure

from maglev_oc.reporting.pdf import Plot, Table, grid, wrap_cells
from maglev_oc.results import AXES
from maglev_oc.validation import Validation

__all__ = ["FIT_COLUMNS", "FIT_NOTE", "correlation_plot", "fit_rows", "page_blocks", "verdict_rows"]

Draw = Callable[[Figure, tuple[float, float, float, float]], str]
FIT_COLUMNS = ("model", "axis", "fit % by horizon", "whiteness (Ljung-Box p)", "independence (largest ccf)")
FIT_NOTE = (
    "Residuals: the position predicted 20 ms ahead from the estimated state with the logged currents, each "
    "axis alone, in windows that share no sample (one lag = the windows' spacing). White: Ljung-Box p ≥ 0.05 "
    "over 10 lags. Independent: no cross-correlation with i_q or i_d at lags 0-10 beyond the 95 % band "
    "widened for the 22 tests. Fit % = 100 (1 − |y − ŷ| / |y − mean y|) of the position simulated over "
    "windows of each horizon; the gap is open-loop unstable, so over seconds it diverges whatever the model."
)
_MODEL_COLOURS = ("tab:blue", "tab:red", "tab:green", "tab:purple")
_INPUT_STYLE = {"i_q": "-", "i_d": "--"}


def correlation_plot(validations: Mapping[str, Validation]) -> Draw:
    """Top row: autocorrelation of the prediction residuals per axis; bottom row: their
    cross-correlation with the currents i_q (solid) and i_d (dashed) at past lags; one colour per
    model, the 95 % bands shaded (the narrowest model's band: they share the data)."""

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 2, 2, wspace=0.25, hspace=0.55, top=0.03, bottom=0.09)
        for col, axis in enumerate(AXES):
            top = fig.add_subplot(gs[0, col])
            bottom = fig.add_subplot(gs[1, col])
            band_a = band_c = 0.0
            for k, (label, v) in enumerate(validations.items()):
                colour = _MODEL_COLOURS[k % len(_MODEL_COLOURS)]
                if axis not in v.whiteness:
                    continue
                w, c = v.whiteness[axis], v.independence[axis]
                lag_s = v.spacing
                top.plot(w.lags * lag_s, w.acf, "o-", color=colour, ms=3, label=label)
                band_a = max(band_a, w.band)
                for i, name in enumerate(c.inputs):
                    bottom.plot(
                        c.lags * lag_s,
                        c.ccf[i],
                        _INPUT_STYLE.get(name, ":"),
                        color=colour,
                        marker="o",
                        ms=2.5,
                    )
                band_c = max(band_c, c.band)
            for ax, band, what in (
                (top, band_a, "autocorrelation"),
                (bottom, band_c, "cross-corr. with i_q, i_d"),
            ):
                ax.axhline(0, color="0.5", lw=0.6)
                if band:
                    ax.axhspan(-band, band, color="0.88", lw=0, zorder=0)
                ax.set_ylim(-1.05, 1.05)
                ax.set_xlabel("lag [s]" if ax is top else "current earlier than the residual by [s]")
                ax.set_ylabel(f"{what} [-]")
                ax.set_title(f"{axis} position residual", fontsize=8.5)
            if col == 0:
                if top.get_legend_handles_labels()[1]:  # none when no residual was validated
                    top.legend(loc="upper right", fontsize=7)
                bottom.plot([], [], "k-", label="i_q")
                bottom.plot([], [], "k--", label="i_d")
                bottom.legend(loc="upper right", fontsize=7)
        return "Prediction residuals: autocorrelation and cross-correlation with the currents (95 % bands)"

    return draw


def fit_rows(validations: Mapping[str, Validation]) -> list[tuple[str, str, str, str, str]]:
    """One row per model and axis: the fit % at each horizon, the whiteness and independence
    results in short words."""
    rows = []
    for label, v in validations.items():
        for axis in AXES:
            fits = ", ".join(f"{f.horizon:g} s: {_fit_cell(f.fit[axis])}" for f in v.fits)
            w, c = v.whiteness.get(axis), v.independence.get(axis)
            white = "—" if w is None else f"{'white' if w.white else 'NOT white'} (p = {w.p_value:.2g})"
            indep = (
                "—"
                if c is None
                else f"{'yes' if c.independent else 'NO'} "
                f"({c.worst_ccf:+.2f}, {c.worst_input} lag {c.worst_lag})"
            )
            rows.append((label, axis, fits, white, indep))
    return rows


def verdict_rows(validations: Mapping[str, Validation]) -> list[str]:
    """The verdicts in plain words, one paragraph per model."""
    out = []
    for label, v in validations.items():
        parts = [f"{label} ({v.data}): {v.message}."]
        for axis in AXES:
            if axis in v.whiteness:
                parts.append(f"{axis}: {v.whiteness[axis].verdict}; {v.independence[axis].verdict}.")
        out.append(" ".join(parts))
    return out


def _fit_cell(value: float) -> str:
    if math.isnan(value):
        return "—"
    if not np.isfinite(value):
        return "diverged"
    return f"{value:.1f} %"


def page_blocks(validations: Mapping[str, Validation]) -> list:
    """The validation page's figure (residual correlations) and fit table, as the identification
    and diagnosis reports both print them."""
    return [
        Plot(correlation_plot(validations), 0.42),
        Table(
            "",
            FIT_COLUMNS,
            wrap_cells(fit_rows(validations), (18, 10, 34, 22, 26)),
            notes=[FIT_NOTE],
            font_size=7.5,
        ),
    ]
