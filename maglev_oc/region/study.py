"""The operating-region study: every number and map the report and ``maglev-oc region`` show.

One call, :func:`operating_region_study`, runs (for the papers' gains unless told otherwise):

1. the feasible set F on slices through the set-point and the sinusoid (exact boundaries);
2. the adapted Procedure 2 with the Lyapunov equation's P, and with P from the SDP, for
   set-points across 15-25 mm and the papers' sinusoid;
3. the linear regulators' certified regions of attraction, their sampled estimates, and the
   papers' large step for every controller;
4. Monte Carlo on the sampled ideal twin inside each certified set (violations must be zero),
   on grids of slices for the conservativeness figure, and with the quantising encoder.

It returns frozen results with their timings; plotting and PDF writing live elsewhere.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.control.linear_regulator import paper_linear_regulator
from maglev_oc.control.lqr import lqr_regulator
from maglev_oc.model.stage import StageModel
from maglev_oc.region.closed_loop import E1, E2, Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibilityMap, FeasibleSet, feasibility_map
from maglev_oc.region.montecarlo import (
    BatchSimulator,
    CertificateCheck,
    SliceCheck,
    check_error_states,
    fl_slice,
    merge_checks,
    reference_samples,
    regulator_state,
    uniform_in_ellipsoid,
)
from maglev_oc.region.procedure2 import Procedure2, Procedure2Result
from maglev_oc.region.roa import LinearizedLoop, RoaResult, certify_roa, frozen_poles
from maglev_oc.region.sdp import PolygonBuilder, SdpResult, enlarge
from maglev_oc.sim.effects import Encoder, TwinEffects
from maglev_oc.sim.twin import RigTwin
from maglev_oc.units import MM_TO_M

LARGE_STEP_START = (26 * MM_TO_M, 0.0, 0.0, 0.0)
LARGE_STEP_TARGET = (18 * MM_TO_M, 20 * MM_TO_M)
"""The papers' large step, 001 Sec. VI-A / 002 Sec. 7.1: (0.026, 0, 0, 0) -> (0.018, 0, 0.020, 0)."""


@dataclass(frozen=True)
class StudyConfig:
    """What the study computes and how much (the defaults are the report's).

    ``samples`` runs per certificate and kind (full error state, and at rest) per reference.
    """

    setpoints_mm: tuple[float, ...] = (15.0, 17.5, 20.0, 22.5, 25.0)
    position: float = 0.0  # [m]
    sinusoid: bool = True
    sdp: bool = True
    samples: int = 420
    slice_setpoints_mm: tuple[float, ...] = (15.0, 20.0, 25.0)
    slice_points: int = 33
    linear: bool = True
    map_starts_mm: tuple[float, ...] = tuple(np.arange(9.0, 29.5, 1.0))
    map_targets_mm: tuple[float, ...] = tuple(np.arange(9.0, 27.5, 1.0))
    horizon: float = 1.0  # [s] FL runs
    linear_horizon: float = 3.0  # [s] linear-regulator runs (they settle more slowly)
    quantization_samples: int = 500
    map_points: int = 101
    threads: int = 2
    compile: bool = True
    seed: int = 0

    def __post_init__(self) -> None:
        if not self.setpoints_mm:
            raise ValueError("setpoints_mm must not be empty")
        for g in (*self.setpoints_mm, *self.slice_setpoints_mm):
            if not (5 <= g <= 40):
                raise ValueError(f"set-point gaps are in millimetres in [5, 40], got {g!r}")
        if self.samples < 0 or self.slice_points < 0 or self.quantization_samples < 0:
            raise ValueError("sample counts must be >= 0")


@dataclass(frozen=True)
class Enlargement:
    """How much the SDP's P enlarged the certified set over the Lyapunov equation's P."""

    area: float  # ratio of the certified (e1, e2) rectangles' areas
    e1: float  # ratio of the rectangles' e1 half-sides
    e2: float
    semi_axes: dict[str, float]  # ratio per semi-axis (e1, e1_rate, e2, e2_rate)


@dataclass(frozen=True)
class ReferenceStudy:
    """Procedure 2 and its Monte Carlo for one reference."""

    reference: Reference
    lyapunov: Procedure2Result
    sdp: SdpResult | None
    enlargement: Enlargement | None
    checks: dict[str, CertificateCheck]
    worst_start: dict[str, CertificateCheck]  # a run from the certified boundary nearest F's edge

    @property
    def best(self) -> Procedure2Result:
        """The SDP's certificate when there is one, else the Lyapunov equation's."""
        if self.sdp is not None and self.sdp.certified is not None:
            return self.sdp.certified
        return self.lyapunov


@dataclass(frozen=True)
class LinearStudy:
    """A linear regulator's certified region of attraction and its sampled estimate."""

    controller: str
    roa: RoaResult
    large_step_ratio: float  # V(start)/level for the large step (<= 1: certified)
    slice: SliceCheck | None  # a sampled slice, when computed


@dataclass(frozen=True)
class LargeStepStudy:
    """The papers' large step (0.026, 0, 0, 0) -> (0.018, 0, 0.020, 0) for every controller."""

    reference: Reference
    start: np.ndarray  # (4,)
    fl_ratio_lyapunov: float  # V(start)/certified level with the Lyapunov equation's P
    fl_ratio_sdp: float  # with the SDP's P for the (e1, e2) rectangle
    fl_direction: SdpResult | None  # SDP aimed at this start: best.reach >= 1 means certified
    fl_run: CertificateCheck | None  # the run from the start on the sampled twin
    linear: tuple[LinearStudy, ...]
    map_starts: np.ndarray  # (n_s,) start gaps [m] (at rest, position 0, internal models empty)
    sweep_targets: np.ndarray  # (n_t,) target gaps [m] (target position 20 mm)
    maps: dict[str, dict[str, np.ndarray]]  # controller -> success, min_gap, max_current (n_t, n_s)
    sweep: dict[str, dict[str, np.ndarray]]  # the same at the papers' start 26 mm, (n_t,)
    frozen_gaps: np.ndarray  # (m,) [m]
    frozen_poles: np.ndarray  # (m, 5) linear regulator's vertical poles with the 18 mm gains


@dataclass(frozen=True)
class OperatingRegionStudy:
    config: StudyConfig
    feasible: FeasibleSet
    loop: RegulatorLoop
    references: tuple[ReferenceStudy, ...]
    maps: tuple[FeasibilityMap, ...]
    slices: dict[str, tuple[SliceCheck, ...]]  # "lyapunov"/"sdp" -> FL slices judged against it
    large_step: LargeStepStudy | None
    quantization: CertificateCheck | None
    timings: dict[str, float] = field(default_factory=dict)

    def inside_totals(self) -> dict[str, int]:
        """Runs started inside certified sets and their violations, over all references."""
        n = sum(c.n for r in self.references for c in r.checks.values())
        bad = sum(c.violations for r in self.references for c in r.checks.values())
        return {"runs": n, "violations": bad}


def _enlargement(lyap: Procedure2Result, sdp: SdpResult | None) -> Enlargement | None:
    if sdp is None or sdp.certified is None or not lyap.success:
        return None
    a0, b0 = lyap.initial_conditions.rectangle
    a1, b1 = sdp.certified.initial_conditions.rectangle
    s0, s1 = lyap.initial_conditions.semi_axes, sdp.certified.initial_conditions.semi_axes
    return Enlargement((a1 * b1) / (a0 * b0), a1 / a0, b1 / b0, {k: s1[k] / s0[k] for k in s0})


def _phases(reference: Reference, n: int) -> list[tuple[float, int]]:
    """(phase, count) groups: one group for a set-point, eight phases for a sinusoid."""
    if reference.is_setpoint or n == 0:
        return [(0.0, n)]
    k = 8
    return [(2 * math.pi * j / k, n // k + (1 if j < n % k else 0)) for j in range(k)]


def _inside_checks(sim, loop, reference, cert: Procedure2Result, n, rng, label, limit) -> dict:
    out = {}
    for kind, dims in (("full", None), ("at rest", [E1, E2])):
        runs = []
        for phase, count in _phases(reference, n):
            if count == 0:
                continue
            z = uniform_in_ellipsoid(cert.P, cert.level, count, rng, dims=dims)
            runs.append(
                check_error_states(
                    sim, loop, reference, cert.P, cert.level, z, phase=phase, current_limit=limit
                )
            )
        if runs:
            out[f"{label}, {kind}"] = merge_checks(runs)
    return out


def _worst_start(sim, loop, reference, cert: Procedure2Result, limit) -> CertificateCheck | None:
    """Run from the point of the certified boundary closest to F's edge: the IPOPT/branch-and-
    bound witness (V = level_upper) scaled back onto V = 0.999 level."""
    if cert.witness is None or not cert.success:
        return None
    z = np.asarray(cert.witness, dtype=float)
    v = z @ cert.P @ z
    z = z * math.sqrt(0.999 * cert.level / v)
    return check_error_states(
        sim, loop, reference, cert.P, cert.level, z[:, None], phase=cert.witness_phase, current_limit=limit
    )


def operating_region_study(
    model: StageModel,
    config: StudyConfig | None = None,
    *,
    loop: RegulatorLoop | None = None,
    feasible: FeasibleSet | None = None,
    progress: Callable[[str], None] | None = None,
) -> OperatingRegionStudy:
    """Run the whole study (module docstring) for ``model`` (plant = controller model)."""
    config = config or StudyConfig()
    say = progress or (lambda _msg: None)
    timings: dict[str, float] = {}
    t_all = time.perf_counter()
    loop = loop or RegulatorLoop()
    feasible = feasible or FeasibleSet(model)
    limit = feasible.current_limit
    rng = np.random.default_rng(config.seed)

    t0 = time.perf_counter()
    proc = Procedure2(feasible, loop)
    builder = PolygonBuilder(feasible, loop)
    timings["build solvers"] = time.perf_counter() - t0

    refs = [Reference.setpoint(g * MM_TO_M, config.position) for g in config.setpoints_mm]
    if config.sinusoid:
        refs.append(Reference.paper_sinusoid())

    # 1. Procedure 2 (Lyapunov P) and the SDP
    certs = []
    t_p2 = t_sdp = 0.0
    for ref in refs:
        say(f"Procedure 2: {ref.label}")
        t0 = time.perf_counter()
        lyap = proc.run(ref, seed=config.seed)
        t_p2 += time.perf_counter() - t0
        sdp = None
        if config.sdp:
            t0 = time.perf_counter()
            sdp = enlarge(proc, ref, builder=builder)
            t_sdp += time.perf_counter() - t0
        certs.append((ref, lyap, sdp))
    timings["procedure 2 (Lyapunov P)"] = t_p2
    timings["SDP enlargement (incl. re-certification)"] = t_sdp

    # 2. feasibility maps through the middle set-point and the sinusoid
    t0 = time.perf_counter()
    maps = []
    mid = Reference.setpoint(20 * MM_TO_M, config.position)
    if config.map_points:
        n = config.map_points
        g_lo, g_hi = feasible.gap_range or (5 * MM_TO_M, 35 * MM_TO_M)
        e_rng = (g_lo - 2 * MM_TO_M - mid.gap, g_hi + 2 * MM_TO_M - mid.gap)
        maps.append(feasibility_map(feasible, loop, mid, ("e1", "e1_rate"), e_rng, (-0.6, 0.6), n=n))
        maps.append(feasibility_map(feasible, loop, mid, ("e1", "e2"), e_rng, (-0.065, 0.065), n=n))
        maps.append(
            feasibility_map(feasible, loop, mid, ("e2", "e2_rate"), (-0.065, 0.065), (-0.8, 0.8), n=n)
        )
        maps.append(feasibility_map(feasible, loop, mid, ("e1", "xi_v3"), e_rng, (-2e-3, 2e-3), n=n))
        if config.sinusoid:
            sin = Reference.paper_sinusoid()
            maps.append(
                feasibility_map(feasible, loop, sin, ("phase", "e1"), (0, 2 * math.pi), (-0.012, 0.012), n=n)
            )
            maps.append(
                feasibility_map(feasible, loop, sin, ("phase", "e2"), (0, 2 * math.pi), (-0.04, 0.04), n=n)
            )
    timings["feasibility maps"] = time.perf_counter() - t0

    # 3. Monte Carlo inside the certified sets on the sampled ideal twin
    t0 = time.perf_counter()
    fl = FeedbackLinearizingRegulator(model, loop.K_h, loop.K_v, omega0=loop.omega0)
    sim = BatchSimulator(
        RigTwin(model), fl, duration=config.horizon, threads=config.threads, compile=config.compile
    )
    timings["build Monte Carlo (FL)"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    ref_studies = []
    for ref, lyap, sdp in certs:
        say(f"Monte Carlo: {ref.label}")
        checks: dict[str, CertificateCheck] = {}
        worst: dict[str, CertificateCheck] = {}
        pairs = [("Lyapunov P", lyap)]
        if sdp is not None and sdp.certified is not None:
            pairs.append(("SDP P", sdp.certified))
        for label, cert in pairs:
            if not cert.success:
                continue
            if config.samples:
                checks.update(_inside_checks(sim, loop, ref, cert, config.samples, rng, label, limit))
            w = _worst_start(sim, loop, ref, cert, limit)
            if w is not None:
                worst[label] = w
        ref_studies.append(ReferenceStudy(ref, lyap, sdp, _enlargement(lyap, sdp), checks, worst))
    timings["Monte Carlo inside the certified sets"] = time.perf_counter() - t0

    # 4. conservativeness: empirical safe set vs certificate on slices
    t0 = time.perf_counter()
    slices: dict[str, list[SliceCheck]] = {"Lyapunov P": [], "SDP P": []}
    if config.slice_points:
        by_gap = {round(r.reference.gap / MM_TO_M, 6): r for r in ref_studies if r.reference.is_setpoint}
        for g in config.slice_setpoints_mm:
            rs = by_gap.get(round(g, 6))
            if rs is None:
                continue
            say(f"slices at {g:g} mm")
            ref = rs.reference
            g_lo, g_hi = feasible.gap_range or (5 * MM_TO_M, 35 * MM_TO_M)
            p_lo, p_hi = feasible.position_range or (-0.06, 0.06)
            e_rng = (g_lo - ref.gap, g_hi - ref.gap)
            for axes, yr in (
                (("e1", "e2"), (p_lo - ref.position, p_hi - ref.position)),
                (("e1", "e1_rate"), (-0.8, 0.8)),
            ):
                base = fl_slice(
                    sim,
                    loop,
                    ref,
                    rs.lyapunov.P,
                    rs.lyapunov.level,
                    axes,
                    e_rng,
                    yr,
                    n=config.slice_points,
                    current_limit=limit,
                )
                slices["Lyapunov P"].append(base)
                if rs.sdp is not None and rs.sdp.certified is not None:
                    slices["SDP P"].append(base.with_certificate(rs.sdp.certified.P, rs.sdp.certified.level))
    timings["Monte Carlo on slices (conservativeness)"] = time.perf_counter() - t0

    # 5. quantising encoder (10 um) with noise, inside the best certificate at 20 mm
    quant = None
    t0 = time.perf_counter()
    if config.quantization_samples:
        target = next(
            (
                r
                for r in ref_studies
                if r.reference.is_setpoint and abs(r.reference.gap - 20 * MM_TO_M) < 1e-9
            ),
            None,
        )
        target = target or ref_studies[0]
        cert = target.best
        if cert.success:
            say("Monte Carlo with the quantising encoder")
            twin_q = RigTwin(model, TwinEffects(encoder=Encoder()))
            sim_q = BatchSimulator(
                twin_q, fl, duration=config.horizon, threads=config.threads, compile=config.compile
            )
            z = uniform_in_ellipsoid(cert.P, cert.level, config.quantization_samples, rng)
            x, xi = loop.physical_state(z, target.reference, 0.0)
            ref_s = reference_samples(target.reference, 0.0, sim_q.n_steps, twin_q.sample_time)
            noise = rng.standard_normal((2, sim_q.n_steps))
            out = sim_q.run(x, regulator_state(x, xi), ref_s, noise)
            bad = out.violations(limit)
            quant = CertificateCheck.of(
                out.timings,
                reference=target.reference,
                level=cert.level,
                n=z.shape[1],
                violations=int(bad.sum()),
                violating=bad,
                start_ratio=np.einsum("in,ij,jn->n", z, cert.P, z) / cert.level,
                final_ratio=np.full(z.shape[1], np.nan),
                min_margin=float(np.nanmin(out.min_margin)),
                max_current=float(np.nanmax(out.max_current)),
                outcome=out,
            )
    timings["Monte Carlo with encoder quantisation"] = time.perf_counter() - t0

    # 6. the papers' large step, linear regulators' regions of attraction
    large = None
    if config.linear:
        say("large step and linear regulators")
        large = _large_step(model, feasible, loop, proc, builder, sim, config, timings, limit)

    timings["total"] = time.perf_counter() - t_all
    return OperatingRegionStudy(
        config,
        feasible,
        loop,
        tuple(ref_studies),
        tuple(maps),
        {k: tuple(v) for k, v in slices.items()},
        large,
        quant,
        timings,
    )


def _large_step(model, feasible, loop, proc, builder, sim, config, timings, limit) -> LargeStepStudy:
    ref = Reference.setpoint(*LARGE_STEP_TARGET)
    x0 = np.array(LARGE_STEP_START)
    z0 = loop.error_state(x0, np.zeros(6), ref)[:, 0]
    t0 = time.perf_counter()
    lyap = proc.run(ref, seed=config.seed)
    generic = enlarge(proc, ref, builder=builder) if config.sdp else None
    aimed = enlarge(proc, ref, builder=builder, direction=z0) if config.sdp else None
    timings["large step: FL certificates"] = time.perf_counter() - t0
    ratio_l = float(z0 @ lyap.P @ z0 / lyap.level) if lyap.success else math.inf
    ratio_s = math.inf
    if generic is not None and generic.certified is not None:
        ratio_s = float(z0 @ generic.certified.P @ z0 / generic.certified.level)
    fl_run = check_error_states(sim, loop, ref, lyap.P, lyap.level, z0[:, None], current_limit=limit)

    # certified regions of attraction of the linear regulators
    t0 = time.perf_counter()
    ctrls = [
        paper_linear_regulator(model),
        paper_linear_regulator(model, feedforward=False),
        lqr_regulator(model),
    ]
    linear = []
    for ctrl in ctrls:
        roa = certify_roa(model, ctrl, ref, feasible=feasible)
        zh = LinearizedLoop(model, ctrl, ref).initial_error(x0)
        ratio = float(zh @ roa.P @ zh / roa.level) if roa.level > 0 else math.inf
        linear.append(LinearStudy(ctrl.name, roa, ratio, None))
    timings["large step: certified regions of attraction"] = time.perf_counter() - t0

    # sampled estimate: start gap x target gap (start at rest at position 0, target position 20 mm)
    t0 = time.perf_counter()
    starts = np.asarray(config.map_starts_mm, dtype=float) * MM_TO_M
    targets = np.asarray(config.map_targets_mm, dtype=float) * MM_TO_M
    fl_ctrl = sim.controller
    maps: dict[str, dict[str, np.ndarray]] = {}
    for ctrl in (fl_ctrl, *ctrls):
        bsim = BatchSimulator(
            RigTwin(model),
            ctrl,
            duration=config.linear_horizon,
            threads=config.threads,
            compile=config.compile,
        )
        xs = np.vstack([starts, np.zeros((3, starts.size))])
        c0 = np.vstack([xs, np.zeros((6, starts.size))])
        ok = np.zeros((targets.size, starts.size), dtype=bool)
        gmin = np.zeros_like(ok, dtype=float)
        imax = np.zeros_like(ok, dtype=float)
        for k, g in enumerate(targets):
            out = bsim.run(xs, c0, np.array([g, 0, 0, LARGE_STEP_TARGET[1], 0, 0]))
            with np.errstate(invalid="ignore"):
                err = np.hypot(out.final_twin[0] - g, out.final_twin[2] - LARGE_STEP_TARGET[1])
                good = out.finite & ~out.stopper_hit & (err < 1e-4)
            if ctrl is fl_ctrl:
                good &= ~out.violations(limit)
            ok[k], gmin[k], imax[k] = good, out.min_gap, out.max_current
        maps[ctrl.name] = {"success": ok, "min_gap": gmin, "max_current": imax}
    timings["large step: sampled start x target map"] = time.perf_counter() - t0
    j = int(np.argmin(np.abs(starts - x0[0])))
    sweep = {name: {k: v[:, j] for k, v in d.items()} for name, d in maps.items()}
    fg = np.array([10, 12, 14, 16, 18, 22, 26], dtype=float) * MM_TO_M
    fp = frozen_poles(model, ctrls[0], ref, fg)
    return LargeStepStudy(
        ref, x0, ratio_l, ratio_s, aimed, fl_run, tuple(linear), starts, targets, maps, sweep, fg, fp
    )


# convenience for reports: a compact table of the certified sets
def certificate_rows(study: OperatingRegionStudy) -> list[tuple]:
    """Rows (reference, P, level, upper, tightness, binding, e1 [mm], e1' [mm/s], e2 [mm],
    e2' [mm/s], rectangle e1 x e2 [mm])."""
    rows = []
    for rs in study.references:
        items = [("Lyapunov eq.", rs.lyapunov)]
        if rs.sdp is not None and rs.sdp.certified is not None:
            items.append(("SDP", rs.sdp.certified))
        for label, c in items:
            s = c.initial_conditions.semi_axes
            a, b = c.initial_conditions.rectangle
            rows.append(
                (
                    _short(rs.reference),
                    label,
                    c.level,
                    c.level_upper,
                    c.tightness,
                    c.binding,
                    s["e1"] / MM_TO_M,
                    s["e1_rate"] / MM_TO_M,
                    s["e2"] / MM_TO_M,
                    s["e2_rate"] / MM_TO_M,
                    f"{a / MM_TO_M:.2f} x {b / MM_TO_M:.2f}",
                )
            )
    return rows


def _short(ref: Reference) -> str:
    if ref.is_setpoint:
        return f"{ref.gap / MM_TO_M:g} mm"
    return "sinusoid"
