"""Figures of the operating-region report. Each function takes computed results and returns a
``draw(fig, rect)`` block for :class:`maglev_oc.reporting.pdf.Plot` (it draws into ``rect``, page
fractions, and returns its title)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from maglev_oc.region.feasibility import CONSTRAINT_NAMES, SLICE_VARIABLES, FeasibilityMap
from maglev_oc.region.montecarlo import SliceCheck
from maglev_oc.region.study import BASIN_OUTCOMES, LargeStepStudy, OperatingRegionStudy
from maglev_oc.reporting.pdf import caption, grid
from maglev_oc.reporting.style import controller_colour
from maglev_oc.units import M_TO_MM

__all__ = [
    "BINDING_WORDS",
    "CERT_STYLE",
    "OUTCOME_COLOURS",
    "basin_maps_plot",
    "certified_sets_plot",
    "feasibility_plot",
    "montecarlo_plot",
    "slice_axis_name",
    "slices_plot",
    "stopper_room",
    "sweep_plot",
]

Draw = Callable[[Figure, tuple[float, float, float, float]], str]
Certs = Mapping[str, tuple[np.ndarray, float]]

BINDING_WORDS = {
    "margin": "R >= 0",
    "headroom": "9 A limit",
    "gap_low": "lower gap stopper",
    "gap_high": "upper gap stopper",
    "position_low": "horizontal stopper",
    "position_high": "horizontal stopper",
}
"""The constraints of F in words."""
BOUNDARY_COLOURS = {
    "margin": "tab:purple",
    "headroom": "tab:red",
    "gap_low": "0.3",
    "gap_high": "0.3",
    "position_low": "0.55",
    "position_high": "0.55",
}
CERT_STYLE = {"Lyapunov P": ("tab:blue", "--"), "SDP P": ("tab:green", "-")}
"""Line colour and style of the two certificates (the Lyapunov equation's P and the SDP's)."""
CERT_WORDS = {"Lyapunov P": "certified set, Lyapunov equation's P", "SDP P": "certified set, SDP's P"}
OUTCOME_COLOURS = {
    "converged": "#d9f0d3",
    "over the current limit": "#fdd49e",
    "R < 0": "#cbc9e2",
    "stopper": "#f4a6a6",
    "not settled": "0.75",
    "diverged": "0.35",
}
"""Fill of each start x target outcome (study.BASIN_OUTCOMES)."""
FEASIBLE_FILL = "#d9f0d3"

# slice variable -> (label, scale to display units)
_AXIS = {
    "e1": ("air gap x1 [mm]", M_TO_MM),
    "e1_rate": ("gap rate x2 [mm/s]", M_TO_MM),
    "e2": ("horizontal position x3 [mm]", M_TO_MM),
    "e2_rate": ("horizontal rate x4 [mm/s]", M_TO_MM),
    "xi_v1": ("vertical internal model state 1 [mm s²]", M_TO_MM),
    "xi_v2": ("vertical internal model state 2 [mm s]", M_TO_MM),
    "xi_v3": ("vertical internal model state 3 [mm]", M_TO_MM),
    "phase": ("reference phase omega0 t [rad]", 1.0),
}
_ORBIT = {
    "e1": "gap deviation from the orbit [mm]",
    "e2": "position deviation from the orbit [mm]",
    "e1_rate": "gap-rate deviation [mm/s]",
    "e2_rate": "horizontal-rate deviation [mm/s]",
}


def slice_axis_name(axis: str) -> str:
    """A slice coordinate in words, without its unit."""
    return _AXIS[axis][0].split(" [")[0]


def _offset(axis: str, ref) -> float:
    """Display offset: absolute gap / position for e1 / e2 on a set-point (none on a sinusoid)."""
    if not ref.is_setpoint:
        return 0.0
    return {"e1": ref.gap * M_TO_MM, "e2": ref.position * M_TO_MM}.get(axis, 0.0)


def _label(axis: str, ref) -> str:
    if not ref.is_setpoint and axis in _ORBIT:
        return _ORBIT[axis]
    return _AXIS[axis][0]


def _ellipse(P2: np.ndarray, level: float, n: int = 241) -> np.ndarray:
    """Boundary (2, n) of {y' P2 y <= level}."""
    t = np.linspace(0, 2 * math.pi, n)
    circ = np.vstack([np.cos(t), np.sin(t)])
    L = np.linalg.cholesky(P2)
    return math.sqrt(level) * np.linalg.solve(L.T, circ)


def _cert_slice(ax, axes, P, level, ref, label) -> None:
    """The certified set {V <= level} cut by the slice ``axes`` (other states at their steady state)."""
    if level <= 0:
        return
    color, style = CERT_STYLE[label]
    i, j = SLICE_VARIABLES[axes[0]], SLICE_VARIABLES[axes[1]]
    if "phase" in axes:
        k = j if axes[0] == "phase" else i
        half = math.sqrt(level / P[k, k]) * _AXIS[axes[1 if axes[0] == "phase" else 0]][1]
        line = ax.axhline if axes[0] == "phase" else ax.axvline
        for sign in (1, -1):
            line(sign * half, color=color, ls=style, lw=1.4)
        return
    e = _ellipse(P[np.ix_([i, j], [i, j])], level)
    sx, sy = _AXIS[axes[0]][1], _AXIS[axes[1]][1]
    ax.plot(
        e[0] * sx + _offset(axes[0], ref), e[1] * sy + _offset(axes[1], ref), color=color, ls=style, lw=1.4
    )


def _cert_handles(labels) -> list:
    return [Line2D([], [], color=CERT_STYLE[k][0], ls=CERT_STYLE[k][1], label=CERT_WORDS[k]) for k in labels]


def _legend_below(fig: Figure, rect, handles, ncol: int) -> None:
    fig.legend(handles=handles, loc="lower center", ncol=ncol, bbox_to_anchor=(0.54, rect[1] - 0.004))


# --- the feasible set -------------------------------------------------------------------------------------
def _map_axes(ax, fm: FeasibilityMap, certs: Certs) -> None:
    sx, sy = _AXIS[fm.axes[0]][1], _AXIS[fm.axes[1]][1]
    ox, oy = _offset(fm.axes[0], fm.reference), _offset(fm.axes[1], fm.reference)
    x, y = fm.x * sx + ox, fm.y * sy + oy
    ax.contourf(x, y, fm.feasible.astype(float), levels=[0.5, 1.5], colors=[FEASIBLE_FILL])
    for name in CONSTRAINT_NAMES:
        pts = fm.boundary[name]
        if pts.shape[1]:
            ax.plot(pts[0] * sx + ox, pts[1] * sy + oy, ".", ms=1.4, color=BOUNDARY_COLOURS[name])
    for label, (P, level) in certs.items():
        _cert_slice(ax, fm.axes, P, level, fm.reference, label)
    ax.set_xlabel(_label(fm.axes[0], fm.reference))
    ax.set_ylabel(_label(fm.axes[1], fm.reference))
    ax.set_xlim(x[0], x[-1])
    ax.set_ylim(y[0], y[-1])


def _boundary_handles(maps) -> list:
    handles = [Patch(color=FEASIBLE_FILL, label="feasible set F")]
    seen = set()
    for name in CONSTRAINT_NAMES:
        if not any(m.boundary[name].shape[1] for m in maps):
            continue
        words = "stoppers" if name.startswith(("gap", "position")) else BINDING_WORDS[name]
        if words not in seen:
            seen.add(words)
            handles.append(
                Line2D([], [], marker=".", ls="", color=BOUNDARY_COLOURS[name], label=f"edge of F: {words}")
            )
    return handles


def feasibility_plot(setpoint_maps: Sequence[FeasibilityMap], certs: Certs, sinusoid_maps, sin_certs) -> Draw:
    """F on slices through the middle set-point (up to four) and along the sinusoid (up to two),
    with the certified sets' cuts."""
    maps = [*setpoint_maps[:4], *sinusoid_maps[:2]]

    def draw(fig: Figure, rect) -> str:
        rows = math.ceil(len(maps) / 2)
        gs = grid(fig, rect, rows, 2, hspace=0.42, wspace=0.3, top=0.06, bottom=0.075)
        for k, fm in enumerate(maps):
            ax = fig.add_subplot(gs[k // 2, k % 2])
            _map_axes(ax, fm, certs if fm.reference.is_setpoint else sin_certs)
            if fm.reference.is_setpoint:
                ax.set_title(f"set-point {fm.reference.gap * M_TO_MM:g} mm", fontsize=8.5)
            else:
                ax.set_title("along the ellipse (every phase)", fontsize=8.5)
        _legend_below(fig, rect, _boundary_handles(maps) + _cert_handles(CERT_STYLE), 3)
        return caption(
            fig,
            rect,
            "The feasible set F on slices, with the certified sets",
            "Set-point slices: the other states at rest, internal models empty. Ellipse slices: deviations "
            "from the steady-state orbit of r_v = 20 + 5 cos(omega0 t) mm, r_h = 30 sin(omega0 t) mm. "
            "Edges found exactly (Newton on the grid lines).",
        )

    return draw


# --- certificates -----------------------------------------------------------------------------------------
def certified_sets_plot(study: OperatingRegionStudy) -> Draw:
    """The certified starts at rest around each set-point in the (position, gap) plane, and the
    largest certified rectangle per set-point for both P."""
    sps = [r for r in study.references if r.reference.is_setpoint]
    f = study.feasible

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 1, 2, wspace=0.3, top=0.06, bottom=0.1, width_ratios=(1.2, 1))
        ax = fig.add_subplot(gs[0, 0])
        for rs in sps:
            ref = rs.reference
            for label, cert in (("Lyapunov P", rs.lyapunov), ("SDP P", rs.sdp.certified if rs.sdp else None)):
                if cert is None or not cert.success:
                    continue
                color, style = CERT_STYLE[label]
                e = _ellipse(cert.P[np.ix_([5, 0], [5, 0])], cert.level)
                x, y = e[0] * M_TO_MM + ref.position * M_TO_MM, e[1] * M_TO_MM + ref.gap * M_TO_MM
                ax.plot(x, y, color=color, ls=style, lw=1.1)
            ax.plot(ref.position * M_TO_MM, ref.gap * M_TO_MM, "k+", ms=7)
        for g in f.gap_range or ():
            ax.axhline(g * M_TO_MM, color="0.3", lw=1.2)
        for p in f.position_range or ():
            ax.axvline(p * M_TO_MM, color="0.55", lw=1.2)
        ax.set_xlabel("horizontal position x3 [mm]")
        ax.set_ylabel("air gap x1 [mm]")
        ax.set_title("certified starts at rest around each set-point (+)", fontsize=8.5)
        ax.invert_yaxis()
        bar = fig.add_subplot(gs[0, 1])
        xs = np.arange(len(sps))
        w = 0.2
        for k, name in enumerate(("gap", "horizontal")):
            for m, label in enumerate(CERT_STYLE):
                vals = []
                for rs in sps:
                    cert = rs.lyapunov if label == "Lyapunov P" else (rs.sdp.certified if rs.sdp else None)
                    ok = cert is not None and cert.success
                    vals.append(cert.initial_conditions.rectangle[k] * M_TO_MM if ok else 0.0)
                bar.bar(
                    xs + (2 * k + m - 1.5) * w,
                    vals,
                    w,
                    color=CERT_STYLE[label][0],
                    alpha=0.45 + 0.45 * k,
                    hatch="" if k == 0 else "//",
                    label=f"{name}, {'SDP' if label == 'SDP P' else 'Lyapunov'}",
                )
        bar.set_xticks(xs, [f"{r.reference.gap * M_TO_MM:g}" for r in sps])
        bar.set_xlabel("set-point gap [mm]")
        bar.set_ylabel("half-side of the certified rectangle [mm]")
        bar.set_title("largest certified |gap error| x |position error|", fontsize=8.5)
        bar.set_ylim(0, 1.45 * max(1e-9, bar.get_ylim()[1]))
        bar.legend(loc="upper left", fontsize=6.5, ncol=2)
        handles = [*_cert_handles(CERT_STYLE), Line2D([], [], color="0.3", lw=1.2, label="stoppers")]
        _legend_below(fig, rect, handles, 3)
        return caption(
            fig,
            rect,
            "Certified initial errors at rest (internal models empty)",
            "Left: the certified sets cut at rest in the (position, gap) plane. Right: the largest-area "
            "rectangle of gap and position errors inside each.",
        )

    return draw


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


def montecarlo_plot(study: OperatingRegionStudy) -> Draw:
    """Largest commanded current and least room to a stopper of every run started inside a
    certified set, against where it started (V / level)."""
    lim = study.feasible.current_limit

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 2, 1, hspace=0.12, top=0.06, bottom=0.09)
        ax_i = fig.add_subplot(gs[0, 0])
        ax_m = fig.add_subplot(gs[1, 0], sharex=ax_i)
        for rs in study.references:
            for name, chk in rs.checks.items():
                color = CERT_STYLE["SDP P" if name.startswith("SDP") else "Lyapunov P"][0]
                marker = "." if "full" in name else "x"
                ax_i.plot(chk.start_ratio, chk.outcome.max_current, marker, color=color, ms=1.6, alpha=0.3)
                room = stopper_room(chk, study) * M_TO_MM
                ax_m.plot(chk.start_ratio, room, marker, color=color, ms=1.6, alpha=0.3)
            for name, chk in rs.worst_start.items():
                color = CERT_STYLE[name][0]
                ax_i.plot(chk.start_ratio, chk.outcome.max_current, "*", color=color, ms=8, mec="k")
                ax_m.plot(
                    chk.start_ratio, stopper_room(chk, study) * M_TO_MM, "*", color=color, ms=8, mec="k"
                )
        if lim is not None:
            ax_i.axhline(lim, color="tab:red", lw=1.1)
            ax_i.text(0.01, lim, f" {lim:g} A limit", color="tab:red", va="bottom", fontsize=7.5)
        ax_m.axhline(0, color="0.3", lw=1.1)
        ax_i.set_ylabel("largest |u| commanded [A]")
        ax_m.set_ylabel("least room to a stopper [mm]")
        ax_m.set_xlabel("V(start) / certified level (1: on the certified set's edge)")
        ax_i.tick_params(labelbottom=False)
        handles = [
            Line2D(
                [], [], marker=".", ls="", color=CERT_STYLE["Lyapunov P"][0], label="Lyapunov, all states"
            ),
            Line2D([], [], marker="x", ls="", color=CERT_STYLE["Lyapunov P"][0], label="Lyapunov, at rest"),
            Line2D([], [], marker=".", ls="", color=CERT_STYLE["SDP P"][0], label="SDP, all states"),
            Line2D([], [], marker="x", ls="", color=CERT_STYLE["SDP P"][0], label="SDP, at rest"),
            Line2D([], [], marker="*", ls="", color="0.5", mec="k", ms=8, label="worst certified start"),
        ]
        _legend_below(fig, rect, handles, 5)
        return caption(
            fig,
            rect,
            "Every run started inside a certified set, on the sampled ideal twin",
            "Worst certified start: the infeasible point nearest the certified set, scaled back onto its "
            "edge.",
        )

    return draw


def slices_plot(lyap: Sequence[SliceCheck], sdp: Sequence[SliceCheck], certs: Mapping[float, Certs]) -> Draw:
    """Empirically safe starts on a grid of each slice against the certified sets (both P)."""
    sdp_by_key = {(s.reference.gap, s.axes): s for s in sdp}

    def draw(fig: Figure, rect) -> str:
        rows = math.ceil(len(lyap) / 2)
        gs = grid(fig, rect, rows, 2, hspace=0.5, wspace=0.3, top=0.07, bottom=0.065)
        for k, s in enumerate(lyap):
            ax = fig.add_subplot(gs[k // 2, k % 2])
            sx, sy = _AXIS[s.axes[0]][1], _AXIS[s.axes[1]][1]
            ox, oy = _offset(s.axes[0], s.reference), _offset(s.axes[1], s.reference)
            x, y = s.x * sx + ox, s.y * sy + oy
            ax.contourf(x, y, s.safe.astype(float), levels=[0.5, 1.5], colors=[FEASIBLE_FILL])
            other = sdp_by_key.get((s.reference.gap, s.axes))
            for label, sl in (("Lyapunov P", s), ("SDP P", other)):
                if sl is not None and label in certs.get(s.reference.gap, {}):
                    P, level = certs[s.reference.gap][label]
                    _cert_slice(ax, s.axes, P, level, s.reference, label)
            bad = s.certified & ~s.safe
            if other is not None:
                bad = bad | (other.certified & ~other.safe)
            if np.any(bad):
                X, Y = np.meshgrid(x, y)
                ax.plot(X[bad], Y[bad], "rx", ms=4)
            cover = f"Lyapunov {100 * s.coverage:.0f} %" + (
                f", SDP {100 * other.coverage:.0f} %" if other is not None else ""
            )
            ax.set_title(f"set-point {s.reference.gap * M_TO_MM:g} mm: covers {cover}", fontsize=8)
            ax.set_xlabel(_AXIS[s.axes[0]][0])
            ax.set_ylabel(_AXIS[s.axes[1]][0])
        handles = [Patch(color=FEASIBLE_FILL, label="safe start (never left F)"), *_cert_handles(CERT_STYLE)]
        handles.append(Line2D([], [], color="r", marker="x", ls="", label="certified but unsafe"))
        _legend_below(fig, rect, handles, 4)
        return caption(
            fig,
            rect,
            "Safe starts on the sampled ideal twin against the certified sets",
            "A grid of starts per slice (other states at rest, internal models empty); 'covers': the share "
            "of the safe starts inside the certified set.",
        )

    return draw


# --- basins -----------------------------------------------------------------------------------------------
_OUTCOME_CMAP = ListedColormap([OUTCOME_COLOURS[k] for k in BASIN_OUTCOMES])


def _basin_axes(ax, ls: LargeStepStudy, name: str, predicted: bool) -> None:
    d = ls.maps[name]
    xs, ys = ls.map_starts * M_TO_MM, ls.sweep_targets * M_TO_MM
    dx = (xs[1] - xs[0]) / 2 if xs.size > 1 else 0.5
    dy = (ys[1] - ys[0]) / 2 if ys.size > 1 else 0.5
    ax.imshow(
        d["outcome"],
        origin="lower",
        cmap=_OUTCOME_CMAP,
        vmin=-0.5,
        vmax=len(BASIN_OUTCOMES) - 0.5,
        extent=(xs[0] - dx, xs[-1] + dx, ys[0] - dy, ys[-1] + dy),
        aspect="auto",
        interpolation="nearest",
    )
    if predicted and np.any(ls.predicted_stopper) and not np.all(ls.predicted_stopper):
        ax.contour(
            xs,
            ys,
            ls.predicted_stopper.astype(float),
            levels=[0.5],
            colors=["k"],
            linestyles=["--"],
            linewidths=1.1,
        )
    ax.plot(ls.start[0] * M_TO_MM, ls.reference.gap * M_TO_MM, "*", color="gold", ms=11, mec="k")
    share = 100 * d["success"].mean()
    within = 100 * d["within_limit"].mean()
    ax.set_title(
        f"{name}: {share:.0f} % converge, {within:.0f} % within 9 A",
        fontsize=8,
        color=controller_colour(name),
    )
    ax.set_xlabel("start gap [mm] (at rest)")
    ax.set_ylabel("target gap [mm]")
    ax.grid(False)


def _basin_handles(ls: LargeStepStudy, names) -> list:
    present = set()
    for n in names:
        present |= {BASIN_OUTCOMES[k] for k in np.unique(ls.maps[n]["outcome"])}
    handles = [Patch(color=OUTCOME_COLOURS[k], label=k) for k in BASIN_OUTCOMES if k in present]
    handles.append(Line2D([], [], color="k", ls="--", label="stopper predicted from the FL loop's overshoot"))
    handles.append(
        Line2D([], [], marker="*", ls="", color="gold", mec="k", ms=10, label="the papers' large step")
    )
    return handles


def basin_maps_plot(ls: LargeStepStudy, names: Sequence[str], title: str, text: str) -> Draw:
    """Start gap x target gap maps of ``names``: how each run ends on the sampled ideal twin."""

    def draw(fig: Figure, rect) -> str:
        cols = min(2, len(names))
        rows = math.ceil(len(names) / cols)
        gs = grid(fig, rect, rows, cols, hspace=0.4, wspace=0.25, top=0.065, bottom=0.072)
        for k, name in enumerate(names):
            ax = fig.add_subplot(gs[k // cols, k % cols])
            _basin_axes(ax, ls, name, predicted=True)
        _legend_below(fig, rect, _basin_handles(ls, names), 4)
        return caption(fig, rect, title, text)

    return draw


def sweep_plot(ls: LargeStepStudy, stoppers=None, limit: float | None = None) -> Draw:
    """From the papers' start (26 mm, 0 mm) to targets (g, 20 mm): least gap reached and largest current."""

    def draw(fig: Figure, rect) -> str:
        gs = grid(fig, rect, 1, 2, wspace=0.3, top=0.06, bottom=0.085)
        ax_g, ax_i = fig.add_subplot(gs[0, 0]), fig.add_subplot(gs[0, 1])
        t = ls.sweep_targets * M_TO_MM
        for name, d in ls.sweep.items():
            c = controller_colour(name)
            ax_g.plot(t, d["min_gap"] * M_TO_MM, "-", lw=1.2, color=c, label=name)
            bad = ~d["success"]
            ax_g.plot(t[bad], d["min_gap"][bad] * M_TO_MM, "x", ms=6, color=c)
            ax_i.plot(t, d["max_current"], "-", lw=1.2, color=c)
        if stoppers is not None:
            ax_g.axhline(stoppers[0] * M_TO_MM, color="0.3", lw=1.1)
            ax_g.text(t[-1], stoppers[0] * M_TO_MM, "lower stopper ", ha="right", va="bottom", fontsize=7.5)
        ax_g.axhline(15, color="0.5", lw=0.8, ls="-.")
        ax_g.text(t[0], 15, " 15 mm: model verified above (000)", va="bottom", fontsize=7)
        for ax in (ax_g, ax_i):
            ax.axvline(ls.reference.gap * M_TO_MM, color="0.2", ls=":", lw=1)
            ax.set_xlabel("target gap [mm]")
        if limit is not None:
            ax_i.axhline(limit, color="tab:red", lw=1)
            ax_i.text(t[-1], limit, f"{limit:g} A ", color="tab:red", ha="right", va="bottom", fontsize=7.5)
        ax_g.set_ylabel("least gap reached [mm]")
        ax_i.set_ylabel("largest |u| commanded [A]")
        handles, _labels = ax_g.get_legend_handles_labels()
        handles.append(Line2D([], [], color="0.4", marker="x", ls="", label="fails (stopper)"))
        _legend_below(fig, rect, handles, 5)
        return caption(
            fig,
            rect,
            "From the papers' start (26 mm, at rest) to other targets, sampled ideal twin",
            "Target position 20 mm throughout; dotted: the papers' 18 mm target. The ideal twin does not "
            "limit the current.",
        )

    return draw
