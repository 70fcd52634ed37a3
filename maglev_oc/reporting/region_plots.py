"""Figures of the operating-region report. Each function takes computed results and returns a Figure."""

from __future__ import annotations

import math

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from maglev_oc.region.feasibility import CONSTRAINT_LABELS, CONSTRAINT_NAMES, SLICE_VARIABLES, FeasibilityMap
from maglev_oc.region.montecarlo import SliceCheck
from maglev_oc.region.study import LargeStepStudy, OperatingRegionStudy
from maglev_oc.reporting.pdf import new_figure
from maglev_oc.units import M_TO_MM

__all__ = [
    "CERT_STYLE",
    "COLORS",
    "certified_sets_figure",
    "feasibility_maps_figure",
    "large_step_figure",
    "montecarlo_figure",
    "slices_figure",
    "stopper_room",
    "sweep_figure",
]

COLORS = {
    "margin": "tab:purple",
    "headroom": "tab:red",
    "gap_low": "0.3",
    "gap_high": "0.3",
    "position_low": "0.55",
    "position_high": "0.55",
}
CERT_STYLE = {"Lyapunov P": ("tab:blue", "--"), "SDP P": ("tab:green", "-")}

# slice variable -> (label, scale to display units, offset source)
_AXIS = {
    "e1": ("air gap x1 [mm]", M_TO_MM),
    "e1_rate": ("gap rate x2 [mm/s]", M_TO_MM),
    "e2": ("horizontal position x3 [mm]", M_TO_MM),
    "e2_rate": ("horizontal rate x4 [mm/s]", M_TO_MM),
    "xi_v1": ("internal model xi_v1 (deviation) [mm s^2]", M_TO_MM),
    "xi_v2": ("internal model xi_v2 (deviation) [mm s]", M_TO_MM),
    "xi_v3": ("internal model xi_v3 (deviation) [mm]", M_TO_MM),
    "phase": ("exosystem phase omega0 t [rad]", 1.0),
}


def _offset(axis: str, ref, phase=0.0) -> float:
    """Display offset: absolute gap / position for e1 / e2 on a set-point (none on a sinusoid)."""
    if not ref.is_setpoint:
        return 0.0
    if axis == "e1":
        return ref.gap * M_TO_MM
    if axis == "e2":
        return ref.position * M_TO_MM
    return 0.0


def _label(axis: str, ref) -> str:
    if not ref.is_setpoint and axis in ("e1", "e2", "e1_rate", "e2_rate"):
        return {
            "e1": "gap deviation from the orbit e1 [mm]",
            "e2": "position deviation from the orbit e2 [mm]",
            "e1_rate": "gap-rate deviation [mm/s]",
            "e2_rate": "horizontal-rate deviation [mm/s]",
        }[axis]
    return _AXIS[axis][0]


def _ellipse(P2: np.ndarray, level: float, n: int = 241) -> np.ndarray:
    """Boundary (2, n) of {y' P2 y <= level}."""
    t = np.linspace(0, 2 * math.pi, n)
    circ = np.vstack([np.cos(t), np.sin(t)])
    L = np.linalg.cholesky(P2)
    return math.sqrt(level) * np.linalg.solve(L.T, circ)


def _cert_slice(ax, axes, P, level, ref, color, style, label):
    if level <= 0:
        return
    i, j = SLICE_VARIABLES[axes[0]], SLICE_VARIABLES[axes[1]]
    if "phase" in axes:
        k = j if axes[0] == "phase" else i
        half = math.sqrt(level / P[k, k]) * _AXIS[axes[1 if axes[0] == "phase" else 0]][1]
        if axes[0] == "phase":
            ax.axhline(half, color=color, ls=style, lw=1.6, label=label)
            ax.axhline(-half, color=color, ls=style, lw=1.6)
        else:
            ax.axvline(half, color=color, ls=style, lw=1.6, label=label)
            ax.axvline(-half, color=color, ls=style, lw=1.6)
        return
    e = _ellipse(P[np.ix_([i, j], [i, j])], level)
    sx, sy = _AXIS[axes[0]][1], _AXIS[axes[1]][1]
    ax.plot(
        e[0] * sx + _offset(axes[0], ref),
        e[1] * sy + _offset(axes[1], ref),
        color=color,
        ls=style,
        lw=1.6,
        label=label,
    )


def _map_axes(ax, fm: FeasibilityMap, certs):
    sx, sy = _AXIS[fm.axes[0]][1], _AXIS[fm.axes[1]][1]
    ox, oy = _offset(fm.axes[0], fm.reference), _offset(fm.axes[1], fm.reference)
    x = fm.x * sx + ox
    y = fm.y * sy + oy
    ax.contourf(x, y, fm.feasible.astype(float), levels=[0.5, 1.5], colors=["#d9f0d3"])
    for name in CONSTRAINT_NAMES:
        pts = fm.boundary[name]
        if pts.shape[1]:
            ax.plot(pts[0] * sx + ox, pts[1] * sy + oy, ".", ms=1.6, color=COLORS[name])
    for label, (P, level) in certs.items():
        color, style = CERT_STYLE[label]
        _cert_slice(ax, fm.axes, P, level, fm.reference, color, style, f"certified, {label}")
    ax.set_xlabel(_label(fm.axes[0], fm.reference))
    ax.set_ylabel(_label(fm.axes[1], fm.reference))
    ax.set_xlim(x[0], x[-1])
    ax.set_ylim(y[0], y[-1])
    ax.grid(alpha=0.25)


def _legend_handles(maps, with_certs=True):
    present = [n for n in CONSTRAINT_NAMES if any(m.boundary[n].shape[1] for m in maps)]
    seen, handles = set(), [Patch(color="#d9f0d3", label="feasible set F (grid)")]
    for n in present:
        lab = CONSTRAINT_LABELS[CONSTRAINT_NAMES.index(n)]
        key = "stoppers" if n.startswith(("gap", "position")) else lab
        if key in seen:
            continue
        seen.add(key)
        text = "boundary: " + ("stoppers (exact)" if key == "stoppers" else lab + " (Newton)")
        handles.append(Line2D([], [], marker=".", ls="", color=COLORS[n], label=text))
    if with_certs:
        for label, (color, style) in CERT_STYLE.items():
            handles.append(Line2D([], [], color=color, ls=style, label=f"certified level set, {label}"))
    return handles


def feasibility_maps_figure(maps, certs: dict[str, tuple[np.ndarray, float]], title: str) -> Figure:
    """Up to four slices of F with exact boundaries and the certified sets' slices."""
    fig = new_figure((8.27, 9.0))
    n = len(maps)
    axes = fig.subplots(2, 2) if n > 2 else fig.subplots(1, n, squeeze=False)
    axes = np.asarray(axes).ravel()
    for ax, fm in zip(axes, maps, strict=False):
        _map_axes(ax, fm, certs)
    for ax in axes[n:]:
        ax.axis("off")
    fig.legend(handles=_legend_handles(maps), loc="lower center", ncol=2, fontsize=7.5, frameon=False)
    fig.suptitle(title, fontsize=9.5)
    fig.get_layout_engine().set(rect=(0, 0.08, 1, 0.87))
    return fig


def certified_sets_figure(study: OperatingRegionStudy) -> Figure:
    """The certified (e1, e2) slices around every set-point in the (position, gap) plane, and
    the semi-axes per set-point for both P."""
    fig = new_figure((8.27, 9.5))
    ax_map, ax_bar = fig.subplots(2, 1, height_ratios=[1.3, 1])
    f = study.feasible
    sps = [r for r in study.references if r.reference.is_setpoint]
    for rs in sps:
        ref = rs.reference
        for label, cert in (("Lyapunov P", rs.lyapunov), ("SDP P", rs.sdp.certified if rs.sdp else None)):
            if cert is None or not cert.success:
                continue
            color, style = CERT_STYLE[label]
            e = _ellipse(cert.P[np.ix_([5, 0], [5, 0])], cert.level)
            ax_map.plot(
                e[0] * M_TO_MM + ref.position * M_TO_MM,
                e[1] * M_TO_MM + ref.gap * M_TO_MM,
                color=color,
                ls=style,
                lw=1.3,
            )
        ax_map.plot(ref.position * M_TO_MM, ref.gap * M_TO_MM, "k+", ms=8)
    if f.gap_range:
        for g in f.gap_range:
            ax_map.axhline(g * M_TO_MM, color="0.3", lw=1.2)
    if f.position_range:
        for p in f.position_range:
            ax_map.axvline(p * M_TO_MM, color="0.55", lw=1.2)
    ax_map.set_xlabel("horizontal position x3 [mm]")
    ax_map.set_ylabel("air gap x1 [mm]")
    ax_map.set_title(
        "Certified initial errors at rest (internal models empty), slice (x3, x1), per set-point (+)",
        fontsize=9,
    )
    ax_map.invert_yaxis()
    ax_map.grid(alpha=0.25)
    ax_map.legend(
        handles=[Line2D([], [], color=c, ls=s, label=f"certified, {k}") for k, (c, s) in CERT_STYLE.items()]
        + [Line2D([], [], color="0.3", label="stoppers")],
        fontsize=8,
        loc="upper right",
    )
    labels = [f"{r.reference.gap * M_TO_MM:g}" for r in sps]
    xs = np.arange(len(sps))
    w = 0.2
    for k, name in enumerate(("gap error e1", "horizontal error e2")):
        for m, label in enumerate(("Lyapunov P", "SDP P")):
            vals = []
            for rs in sps:
                cert = rs.lyapunov if label == "Lyapunov P" else (rs.sdp.certified if rs.sdp else None)
                vals.append(
                    cert.initial_conditions.rectangle[k] * M_TO_MM if cert is not None and cert.success else 0
                )
            color = CERT_STYLE[label][0]
            ax_bar.bar(
                xs + (2 * k + m - 1.5) * w,
                vals,
                w,
                color=color,
                alpha=0.5 + 0.4 * k,
                hatch="" if k == 0 else "//",
                label=f"{name}, {label}",
            )
    ax_bar.set_xticks(xs, labels)
    ax_bar.set_xlabel("set-point gap [mm] (horizontal set-point 0 mm)")
    ax_bar.set_ylabel("half-side of the certified rectangle [mm]")
    ax_bar.set_title(
        "Largest-area rectangle |e1| <= a1, |e2| <= a2 (at rest) inside each certified set", fontsize=9
    )
    ax_bar.legend(fontsize=7.5, ncol=2)
    ax_bar.grid(alpha=0.25, axis="y")
    return fig


def slices_figure(
    lyap: tuple[SliceCheck, ...], sdp: tuple[SliceCheck, ...], title: str, certs: dict | None = None
) -> Figure:
    """Empirically safe starts on the sampled twin vs the certified slices (both P).

    ``certs`` maps a set-point gap [m] to {"Lyapunov P": (P, level), "SDP P": (P, level)}."""
    n = len(lyap)
    cols = 2
    rows = math.ceil(n / cols)
    fig = new_figure((8.27, 3.4 * rows + 1.0))
    axes = np.asarray(fig.subplots(rows, cols, squeeze=False)).ravel()
    sdp_by_key = {(s.reference.gap, s.axes): s for s in sdp}
    for ax, s in zip(axes, lyap, strict=False):
        sx, sy = _AXIS[s.axes[0]][1], _AXIS[s.axes[1]][1]
        ox, oy = _offset(s.axes[0], s.reference), _offset(s.axes[1], s.reference)
        x, y = s.x * sx + ox, s.y * sy + oy
        ax.contourf(x, y, s.safe.astype(float), levels=[0.5, 1.5], colors=["#d9f0d3"])
        for label, other_slice in (("Lyapunov P", s), ("SDP P", sdp_by_key.get((s.reference.gap, s.axes)))):
            if other_slice is None:
                continue
            color, style = CERT_STYLE[label]
            if certs is not None and label in certs.get(s.reference.gap, {}):
                P, level = certs[s.reference.gap][label]
                _cert_slice(ax, s.axes, P, level, s.reference, color, style, label)
            else:
                ax.contour(
                    x,
                    y,
                    other_slice.certified.astype(float),
                    levels=[0.5],
                    colors=[color],
                    linestyles=[style],
                )
        txt = f"coverage: Lyapunov {100 * s.coverage:.0f} %"
        other = sdp_by_key.get((s.reference.gap, s.axes))
        if other is not None:
            txt += f", SDP {100 * other.coverage:.0f} %"
        bad = s.certified & ~s.safe
        if other is not None:
            bad = bad | (other.certified & ~other.safe)
        if np.any(bad):
            X, Y = np.meshgrid(x, y)
            ax.plot(X[bad], Y[bad], "rx", ms=4)
        ax.set_title(f"set-point {s.reference.gap * M_TO_MM:g} mm: {txt}", fontsize=8.5)
        ax.set_xlabel(_AXIS[s.axes[0]][0])
        ax.set_ylabel(_AXIS[s.axes[1]][0])
        ax.grid(alpha=0.25)
    for ax in axes[n:]:
        ax.axis("off")
    handles = [
        Patch(color="#d9f0d3", label="empirically safe start (sampled twin, never left F)"),
        Line2D([], [], color=CERT_STYLE["Lyapunov P"][0], ls="--", label="certified, Lyapunov P"),
        Line2D([], [], color=CERT_STYLE["SDP P"][0], label="certified, SDP P"),
        Line2D([], [], color="r", marker="x", ls="", label="certified but unsafe (none expected)"),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=2, fontsize=7.5, frameon=False)
    fig.suptitle(title, fontsize=10.5)
    fig.get_layout_engine().set(rect=(0, 0.06, 1, 0.9))
    return fig


def stopper_room(chk, study) -> np.ndarray:
    """Least distance [m] of each run to the gap or position stoppers."""
    f = study.feasible
    room = np.full(chk.n, np.inf)
    o = chk.outcome
    if f.gap_range is not None:
        room = np.minimum(room, np.minimum(o.min_gap - f.gap_range[0], f.gap_range[1] - o.max_gap))
    if f.position_range is not None:
        room = np.minimum(room, min(-f.position_range[0], f.position_range[1]) - o.max_abs_position)
    return room


def montecarlo_figure(study: OperatingRegionStudy) -> Figure:
    """Largest commanded current and least margin of every run started inside a certified set,
    against where it started (V/level)."""
    fig = new_figure((8.27, 6.5))
    ax_i, ax_m = fig.subplots(2, 1, sharex=True)
    lim = study.feasible.current_limit
    for rs in study.references:
        for name, chk in rs.checks.items():
            color = CERT_STYLE["SDP P" if name.startswith("SDP") else "Lyapunov P"][0]
            marker = "." if "full" in name else "x"
            ax_i.plot(chk.start_ratio, chk.outcome.max_current, marker, color=color, ms=2, alpha=0.35)
            ax_m.plot(
                chk.start_ratio, stopper_room(chk, study) * M_TO_MM, marker, color=color, ms=2, alpha=0.35
            )
        for name, chk in rs.worst_start.items():
            color = CERT_STYLE[name][0]
            ax_i.plot(chk.start_ratio, chk.outcome.max_current, "*", color=color, ms=9, mec="k")
            ax_m.plot(chk.start_ratio, stopper_room(chk, study) * M_TO_MM, "*", color=color, ms=9, mec="k")
    if lim is not None:
        ax_i.axhline(lim, color="tab:red", lw=1.2)
        ax_i.text(0.01, lim, f" current limit {lim:g} A", color="tab:red", va="bottom", fontsize=8)
    ax_m.axhline(0, color="0.3", lw=1.2)
    ax_i.set_ylabel("largest |u| commanded [A]")
    ax_m.set_ylabel("least distance to a stopper [mm]")
    ax_m.set_xlabel("V(start) / certified level  (<= 1: started inside the certified set)")
    ax_i.grid(alpha=0.25)
    ax_m.grid(alpha=0.25)
    handles = [
        Line2D(
            [], [], marker=".", ls="", color=CERT_STYLE["Lyapunov P"][0], label="Lyapunov P, full error state"
        ),
        Line2D([], [], marker="x", ls="", color=CERT_STYLE["Lyapunov P"][0], label="Lyapunov P, at rest"),
        Line2D([], [], marker=".", ls="", color=CERT_STYLE["SDP P"][0], label="SDP P, full error state"),
        Line2D([], [], marker="x", ls="", color=CERT_STYLE["SDP P"][0], label="SDP P, at rest"),
        Line2D(
            [],
            [],
            marker="*",
            ls="",
            color="0.5",
            mec="k",
            ms=9,
            label="worst certified start (from the witness)",
        ),
    ]
    ax_i.legend(handles=handles, fontsize=7, ncol=2, loc="lower left")
    fig.suptitle("Monte Carlo on the sampled ideal twin (5 kHz, observers, every reference)", fontsize=10.5)
    return fig


def large_step_figure(ls: LargeStepStudy) -> Figure:
    """Sampled estimate of where each controller converges: start gap x target gap (start at rest
    at position 0, target position 20 mm), with the papers' large step marked."""
    fig = new_figure((8.27, 9.0))
    axes = np.asarray(fig.subplots(2, 2, squeeze=False)).ravel()
    xs = ls.map_starts * M_TO_MM
    ys = ls.sweep_targets * M_TO_MM
    for ax, (name, d) in zip(axes, ls.maps.items(), strict=False):
        ax.contourf(xs, ys, d["success"].astype(float), levels=[0.5, 1.5], colors=["#d9f0d3"])
        ax.contourf(xs, ys, (~d["success"]).astype(float), levels=[0.5, 1.5], colors=["#f4cccc"])
        cs = ax.contour(xs, ys, d["max_current"], levels=[9.0], colors=["tab:red"], linestyles=[":"])
        ax.clabel(cs, fmt="9 A", fontsize=7)
        cg = ax.contour(xs, ys, d["min_gap"] * M_TO_MM, levels=[10, 12, 14], colors=["0.4"], linewidths=0.8)
        ax.clabel(cg, fmt="%g mm", fontsize=7)
        ax.plot(ls.start[0] * M_TO_MM, ls.reference.gap * M_TO_MM, "r*", ms=12, mec="k")
        share = 100 * d["success"].mean()
        ax.set_title(f"{name}: {share:.0f} % of the pairs converge", fontsize=8.5)
        ax.set_xlabel("start air gap x1(0) [mm]")
        ax.set_ylabel("target air gap [mm]")
        ax.grid(alpha=0.25)
    for ax in axes[len(ls.maps) :]:
        ax.axis("off")
    handles = [
        Patch(color="#d9f0d3", label="converges (|e| < 0.1 mm at 3 s, no stopper; FL also never leaves F)"),
        Patch(color="#f4cccc", label="fails (stopper hit, divergence, not settled, or FL left F)"),
        Line2D([], [], color="0.4", lw=0.8, label="least gap reached [mm] (contours)"),
        Line2D(
            [],
            [],
            color="tab:red",
            ls=":",
            label="largest commanded |u| = 9 A (not enforced by the ideal twin)",
        ),
        Line2D([], [], color="r", marker="*", ls="", mec="k", label="the papers' large step 26 mm -> 18 mm"),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=1, fontsize=7.5, frameon=False)
    fig.suptitle(
        "Sampled estimate (not a certificate): start gap x target gap, sampled ideal twin", fontsize=10.5
    )
    fig.get_layout_engine().set(rect=(0, 0.11, 1, 0.85))
    return fig


def sweep_figure(ls: LargeStepStudy, stoppers=None) -> Figure:
    """From the papers' start (26 mm, 0 mm) to targets (g, 20 mm): least gap reached and outcome."""
    fig = new_figure((8.27, 6.8))
    ax_g, ax_i = fig.subplots(2, 1, sharex=True)
    t = ls.sweep_targets * M_TO_MM
    styles = ["k-", "tab:orange", "tab:brown", "tab:cyan", "tab:olive"]
    for k, (name, d) in enumerate(ls.sweep.items()):
        st = styles[k % len(styles)]
        kw = {"color": st} if not st.startswith("k") else {"color": "k"}
        ax_g.plot(t, d["min_gap"] * M_TO_MM, "-", lw=1.3, label=name, **kw)
        ax_g.plot(t[~d["success"]], d["min_gap"][~d["success"]] * M_TO_MM, "x", ms=7, **kw)
        ax_i.plot(t, d["max_current"], "-", lw=1.3, **kw)
    if stoppers is not None:
        ax_g.axhline(stoppers[0] * M_TO_MM, color="0.3", lw=1.2)
        ax_g.text(t[-1], stoppers[0] * M_TO_MM, "lower stopper ", ha="right", va="bottom", fontsize=8)
    ax_g.axvline(ls.reference.gap * M_TO_MM, color="tab:red", ls=":", lw=1)
    ax_i.axvline(ls.reference.gap * M_TO_MM, color="tab:red", ls=":", lw=1)
    ax_i.axhline(9.0, color="tab:red", lw=1)
    ax_i.text(
        t[0], 9.0, " 9 A peak (not enforced by the ideal twin)", color="tab:red", va="bottom", fontsize=8
    )
    ax_g.set_ylabel("least air gap reached [mm]")
    ax_i.set_ylabel("largest |u| commanded [A]")
    ax_i.set_xlabel("target gap [mm] (start 26 mm at rest; target position 20 mm; dotted: the papers' 18 mm)")
    ax_g.legend(fontsize=8, title="x: failed (stopper, divergence or not settled in 3 s)", title_fontsize=7.5)
    ax_g.grid(alpha=0.25)
    ax_i.grid(alpha=0.25)
    fig.suptitle("Step from the papers' start to other targets, sampled ideal twin", fontsize=10.5)
    return fig
