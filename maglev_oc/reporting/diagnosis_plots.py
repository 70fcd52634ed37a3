"""Figures of the diagnosis report (closing the loop with measured data)."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from maglev_oc.diagnosis.feedback import CompensationStudy
from maglev_oc.diagnosis.pipeline import Diagnosis, Effect
from maglev_oc.reporting.pdf import new_figure
from maglev_oc.results import AXES
from maglev_oc.units import M_TO_MM

__all__ = [
    "before_after_figure",
    "compensation_figure",
    "dependence_figure",
    "plain",
    "spectrum_figure",
    "timeseries_figure",
]

_VARIABLE = {
    "gap": ("gap x1 [mm]", lambda d: d.x[0] * M_TO_MM),
    "gap_rate": ("gap rate x2 [mm/s]", lambda d: d.x[1] * M_TO_MM),
    "position": ("horizontal position x3 [mm]", lambda d: d.x[2] * M_TO_MM),
    "position_rate": ("horizontal rate x4 [mm/s]", lambda d: d.x[3] * M_TO_MM),
    "current_rate": ("d i_q / dt (horizontal), d i_d / dt (vertical) [A/s]", None),
    "current": ("i_d (horizontal), i_q (vertical) [A]", None),
}


def plain(name: str) -> str:
    """An identifier in words: ``guide_friction_horizontal`` -> ``guide friction, horizontal``."""
    words = name.replace("_", " ")
    for axis in ("vertical", "horizontal"):
        if words.endswith(" " + axis):
            return words[: -len(axis) - 1] + f", {axis}"
    return words


def spectrum_figure(diag: Diagnosis) -> Figure:
    tr = diag.trace
    fig = new_figure((8.27, 5.5))
    axes = fig.subplots(2, 1, sharex=True)
    for a, ax in enumerate(axes):
        ax.semilogx(tr.periods * M_TO_MM, tr.spectrum[a] * 100, "k", lw=1)
        for name, lam in tr.motor_periods.items():
            ax.axvline(lam * M_TO_MM, color="tab:red", ls=":", lw=1)
            if a == 0:
                ax.text(
                    lam * M_TO_MM,
                    0.97,
                    f"{name.replace('_', ' ')} ",
                    rotation=90,
                    va="top",
                    ha="right",
                    fontsize=7,
                    color="tab:red",
                    transform=ax.get_xaxis_transform(),
                )
        ax.set_ylabel(f"{AXES[a]}: variance\nexplained [%]")
        ax.grid(alpha=0.3, which="both")
    axes[-1].set_xlabel("period in the horizontal position x3 [mm]")
    fig.suptitle("Spatial spectrum of the base model's residual (red: motor periods)")
    return fig


def dependence_figure(diag: Diagnosis) -> Figure:
    tr = diag.trace
    fig = new_figure((8.27, 8.5))
    axes = fig.subplots(3, 2)
    panels = (
        ("gap", "gap [mm]", M_TO_MM),
        ("position", "x3 [mm]", M_TO_MM),
        ("gap_rate", "gap rate [mm/s]", M_TO_MM),
        ("position_rate", "x3 rate [mm/s]", M_TO_MM),
    )
    for ax, (key, label, scale) in zip(axes.ravel()[:4], panels, strict=True):
        b = tr.binned[key]
        for a, color in ((0, "tab:blue"), (1, "tab:orange")):
            ax.errorbar(
                b.centers * scale,
                b.mean[a],
                yerr=2 * b.stderr[a],
                color=color,
                lw=1,
                marker=".",
                label=AXES[a],
            )
        ax.axhline(0, color="0.5", lw=0.6)
        ax.set_xlabel(label)
        ax.set_ylabel("mean residual [m/s²]")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    for a, ax in enumerate(axes[2]):
        ax.plot(tr.lags * 1e3, tr.lag_correlation[a], "k")
        ax.axhline(0, color="0.5", lw=0.6)
        ax.set_xlabel("lag [ms]")
        ax.set_ylabel(f"corr({AXES[a]} residual, di/dt)")
        ax.grid(alpha=0.3)
    fig.suptitle("Base-model residual against the signals effects depend on (±2 s.e.)")
    return fig


def _variable(diag: Diagnosis, effect: Effect, axis: int) -> tuple[str, np.ndarray]:
    d = diag.data
    label, get = _VARIABLE[effect.candidate.variable]
    if effect.candidate.variable == "current_rate":
        return label, d.du[1 - axis]
    if effect.candidate.variable == "current":
        return label, d.u[1 - axis]
    return label, get(d)


def before_after_figure(diag: Diagnosis, effect: Effect) -> Figure:
    """The residual that the effect explains against its variable, before (base-model residual
    with the other effects removed) and after (final residual), held-out block, binned."""
    d = diag.data
    axes_used = [0, 1] if effect.axis == "both" else [AXES.index(effect.axis)]
    fig = new_figure((8.27, 4.3 * len(axes_used)))
    axs = np.atleast_1d(fig.subplots(len(axes_used), 1))
    contrib = np.asarray(effect.candidate.term.acceleration(effect.coefficients).map(d.n)(d.x, d.u, d.du))
    contrib = d.filter(contrib)
    hold = diag.holdout
    for ax, a in zip(axs, axes_used, strict=True):
        label, v = _variable(diag, effect, a)
        before = diag.residual_after[a] + contrib[a]
        after = diag.residual_after[a]
        vv = v[hold]
        edges = np.linspace(*np.percentile(vv, [1, 99]), 41)
        idx = np.clip(np.digitize(vv, edges) - 1, 0, 39)
        centers = 0.5 * (edges[1:] + edges[:-1])
        for series, color, name in (
            (before[hold], "tab:red", "before (without this effect)"),
            (after[hold], "tab:green", "after (effect added)"),
        ):
            m = np.array([series[idx == k].mean() if np.any(idx == k) else np.nan for k in range(40)])
            ax.plot(vv[::20], series[::20], ".", color=color, ms=1.5, alpha=0.25)
            ax.plot(centers, m, "-", color=color, lw=2, label=name)
        ax.axhline(0, color="0.4", lw=0.6)
        ax.set_xlabel(label)
        ax.set_ylabel(f"{AXES[a]} residual [m/s²]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"{plain(effect.name)}: residual before and after, held-out data (lines: bin means)")
    return fig


def timeseries_figure(diag: Diagnosis, seconds: float = 4.0) -> Figure:
    d = diag.data
    hold = np.nonzero(diag.holdout)[0]
    k0 = hold[0]
    k1 = min(hold[-1], k0 + int(seconds / d.sample_time))
    sl = slice(k0, k1)
    t = d.t[sl]
    fig = new_figure((8.27, 6.0))
    axes = fig.subplots(2, 1, sharex=True)
    for a, ax in enumerate(axes):
        meas = d.acc[a, sl]
        ax.plot(t, meas, "k", lw=1.2, label="measured (filtered)")
        ax.plot(t, meas - diag.residual_before[a, sl], "tab:red", lw=0.9, label="base model")
        ax.plot(
            t, meas - diag.residual_after[a, sl], "tab:green", lw=0.9, ls="--", label="base + found effects"
        )
        ax.set_ylabel(f"{AXES[a]} acceleration\n(x{2 if a == 0 else 4}') [m/s²]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[-1].set_xlabel("time in the log [s] (held-out block)")
    fig.suptitle("Held-out data: measured and modelled accelerations")
    return fig


def compensation_figure(study: CompensationStudy) -> Figure:
    fig = new_figure((8.27, 5.5))
    axes = fig.subplots(2, 1, sharex=True)
    for res, color, name in (
        (study.result_before, "tab:red", study.result_before.controller),
        (study.result_after, "tab:green", study.result_after.controller),
    ):
        err = np.vstack([res.y[0] - res.reference[0], res.y[1] - res.reference[3]])
        k = max(1, res.t.size // 3000)
        for a, ax in enumerate(axes):
            ax.plot(res.t[::k], err[a, ::k] * M_TO_MM, color=color, lw=0.8, label=name)
    for a, ax in enumerate(axes):
        ax.set_ylabel(f"{AXES[a]} error [mm]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"FL regulator on {study.scenario}: before and after compensating the found effects")
    return fig
