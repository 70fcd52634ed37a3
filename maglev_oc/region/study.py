"""The operating-region study: every number and map the report and ``maglev-oc region`` show.

One call, :func:`operating_region_study`, runs (for the papers' gains unless told otherwise):

1. the feasible set F on slices through the set-point and the sinusoid (exact boundaries);
2. the adapted Procedure 2 with the Lyapunov equation's P, and with P from the SDP, for
   set-points across 15-25 mm and the papers' sinusoid;
3. the linear regulators' certified regions of attraction, and the papers' large step for every
   controller; the sampled basins (start gap x target gap) with how each step ends (stopper,
   over the current limit, R < 0, ...), and the FL loop's stopper hits predicted from its linear
   error dynamics (:func:`step_extremes`);
4. Monte Carlo on the sampled ideal twin inside each certified set (violations must be zero),
   on grids of slices for the conservativeness figure, and with the quantising encoder;
5. optionally (``StudyConfig.robust_runs``) the nominal certificates on sampled plants whose
   C1..C4 differ from the controller's (:mod:`~maglev_oc.region.robust`): runs from each
   set-point's certified set on plants from confidence ellipsoids of the constants' covariance
   and from the papers' Tables II-III box, and the radius where runs first leave F. Sampled,
   never a certificate (:class:`RobustStudy`).

It returns frozen results with their timings; plotting and PDF writing live elsewhere.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.control.gains import OMEGA0, PAPER_K_H, PAPER_K_V
from maglev_oc.control.linear_regulator import paper_linear_regulator
from maglev_oc.control.lqr import lqr_regulator
from maglev_oc.errors import InputError
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
from maglev_oc.region.robust import (
    CONFIDENCE_LEVELS,
    CriticalRadius,
    RobustnessRow,
    assumed_covariance,
    critical_radius,
    paper_tables_box,
    robustness_table,
)
from maglev_oc.region.robust_certificate import RobustCertificate, RobustCertifier, robust_lyapunov_matrix
from maglev_oc.region.sdp import PolygonBuilder, SdpResult, enlarge
from maglev_oc.region.sweep import PlantSet, SweepSpec
from maglev_oc.results import Result
from maglev_oc.sim.effects import Encoder, TwinEffects
from maglev_oc.sim.twin import RigTwin
from maglev_oc.units import M_TO_MM, MM_TO_M

__all__ = [
    "BASIN_OUTCOMES",
    "LARGE_STEP_START",
    "LARGE_STEP_TARGET",
    "CertifiedRobustRow",
    "CertifiedRobustStudy",
    "Enlargement",
    "LargeStepStudy",
    "LinearStudy",
    "OperatingRegionStudy",
    "ReferenceStudy",
    "RobustStudy",
    "StudyConfig",
    "basin_outcomes",
    "certificate_rows",
    "operating_region_study",
    "step_extremes",
]

LARGE_STEP_START = (26 * MM_TO_M, 0.0, 0.0, 0.0)
LARGE_STEP_TARGET = (18 * MM_TO_M, 20 * MM_TO_M)
"""The papers' large step, 001 Sec. VI-A / 002 Sec. 7.1: (0.026, 0, 0, 0) -> (0.018, 0, 0.020, 0)."""
SETTLED = 1e-4
"""[m] A start x target run converged when its position error is below this (0.1 mm) at the end."""
BASIN_OUTCOMES = ("converged", "over the current limit", "R < 0", "stopper", "not settled", "diverged")
"""How a start x target run ends, the first that applies in this order: diverged (a non-finite
state), hit a stopper, not settled (position error above 0.1 mm at the end), met R < 0 (the
transformation had to clip), commanded more than the current limit; else converged. The last
three converged (the ideal twin does not limit the current)."""


def basin_outcomes(d: Mapping[str, np.ndarray]) -> dict[str, int]:
    """Counts of :data:`BASIN_OUTCOMES` over the pairs of one controller's start x target map."""
    out = d["outcome"]
    return {name: int(np.sum(out == k)) for k, name in enumerate(BASIN_OUTCOMES)}


def _outcome_codes(finite, stopper, settled, over_limit, negative_margin) -> np.ndarray:
    """Index into :data:`BASIN_OUTCOMES` per run (arrays of bool, one shape)."""
    code = np.zeros(np.shape(finite), dtype=int)
    code[over_limit] = 1
    code[negative_margin] = 2
    code[~settled] = 4
    code[stopper] = 3
    code[~finite] = 5
    return code


@dataclass(frozen=True)
class StudyConfig:
    """What the study computes and how much (the defaults are the report's).

    ``samples`` runs per certificate and kind (full error state, and at rest) per reference.
    ``robust_runs`` runs per set-point and plant set of the robust part (0: none; :class:`RobustStudy`),
    ``robust_probe_runs`` per probe of its critical-radius bisection.
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
    robust_runs: int = 150
    robust_probe_runs: int = 40
    # box budget per level of the certified robust level (0: no certificate): 30 000 keeps the
    # report's certified page to about 20 s; the bench's 200 000 certify 25 mm up to 0.95
    certify_boxes: int = 30_000
    certify_ladder: tuple[float, ...] = (1.0,)  # its fractions of the nominal level
    certify_runs: int = 2000  # Monte Carlo runs inside one certified robust set

    def __post_init__(self) -> None:
        if not self.setpoints_mm:
            raise InputError("setpoints_mm must not be empty")
        for g in (*self.setpoints_mm, *self.slice_setpoints_mm):
            if not (5 <= g <= 40):
                raise InputError(f"set-point gaps are in millimetres in [5, 40], got {g!r}")
        if self.samples < 0 or self.slice_points < 0 or self.quantization_samples < 0:
            raise InputError("sample counts must be >= 0")
        if self.robust_runs < 0 or self.robust_probe_runs < 0:
            raise InputError(
                f"robust run counts must be >= 0, got {self.robust_runs!r}, {self.robust_probe_runs!r}"
            )


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
    maps: dict[str, dict[str, np.ndarray]]  # controller -> BASIN_FIELDS, each (n_t, n_s)
    sweep: dict[str, dict[str, np.ndarray]]  # the same at the papers' start 26 mm, (n_t,)
    frozen_gaps: np.ndarray  # (m,) [m]
    frozen_poles: np.ndarray  # (m, 5) linear regulator's vertical poles with the 18 mm gains
    fl_step_range: np.ndarray  # (2, 2) FL error after a unit step at rest: (min, max) per axis (v, h)
    predicted_stopper: np.ndarray  # (n_t, n_s) bool: the FL loop's linear error dynamics reach a stopper
    target_position: float = LARGE_STEP_TARGET[1]  # [m] of every pair of the maps

    def outcomes(self, controller: str) -> dict[str, int]:
        """How the map's start x target pairs of ``controller`` end, by :data:`BASIN_OUTCOMES`."""
        return basin_outcomes(self.maps[controller])


@dataclass(frozen=True)
class CertifiedRobustRow:
    """One set-point of :class:`CertifiedRobustStudy`: the nominal certificate with the robust
    SDP's P (``nominal``, None when the SDP failed: ``sdp_message``) and the robust certificates
    per confidence level, in order, up to and including the first not certified."""

    reference: str  # "20 mm"
    nominal: Procedure2Result | None
    sdp_message: str
    certificates: tuple[RobustCertificate, ...]


@dataclass(frozen=True)
class CertifiedRobustStudy:
    """The certified robust operating region (:mod:`~maglev_oc.region.robust_certificate`) for the
    confidence ellipsoids at ``levels`` of :class:`RobustStudy`'s covariance: per set-point a P
    chosen by the robust SDP for the ``design_level`` set, then the robust level per confidence
    level (``boxes`` per level of ``ladder``), and ``runs`` runs of the sampled loop inside one
    certified robust set (``checked``: (set-point, confidence), None when nothing was certified)."""

    levels: tuple[float, ...]
    design_level: float
    boxes: int
    ladder: tuple[float, ...]
    rows: tuple[CertifiedRobustRow, ...]
    checked: tuple[str, float] | None
    runs: int
    violations: int

    def highest_certified(self, row: CertifiedRobustRow) -> float | None:
        """The highest of :attr:`levels` certified for ``row`` (with every lower one), or None."""
        best = None
        for level, c in zip(self.levels, row.certificates, strict=False):
            if not c.success:
                break
            best = level
        return best


@dataclass(frozen=True)
class RobustStudy:
    """The nominal certificates on sampled plants (:mod:`~maglev_oc.region.robust`): the FL
    regulator keeps the nominal C1..C4, the plant's are drawn uniformly from a set. Sampled,
    never a certificate.

    ``rows``: per set-point (starts uniform in its best certified set, ``certificates`` says
    which P), the nominal plant, the confidence ellipsoids of ``covariance`` at ``levels`` and
    ``box``, ``runs`` runs each, the same starts for every plant set (one seed). ``radii``: per
    set-point and, when the study has the large step, for it (from its one start), the bracket in
    standard deviations of ``covariance`` where runs first leave F, ``probe_runs`` runs per probe
    of the bisection (an upper estimate: more runs per probe can only find violations sooner).
    """

    covariance: np.ndarray  # (4, 4) of (C1, C2, C3, C4) [their units squared]
    covariance_source: str
    assumed: bool  # True: no identification's covariance was given (assumed_covariance)
    levels: tuple[float, ...]
    box: PlantSet
    certificates: dict[str, str]  # set-point label -> "SDP P" or "Lyapunov P"
    rows: tuple[RobustnessRow, ...]
    radii: tuple[CriticalRadius, ...]
    runs: int
    probe_runs: int
    certified: CertifiedRobustStudy | None = None  # None: config.certify_boxes 0

    def plant_sets(self) -> tuple[str, ...]:
        """The plant sets in table order: ``"nominal"``, the levels (``"0.95"``), ``"box"``."""
        return ("nominal", *(f"{p:g}" for p in self.levels), "box")

    def plant_set(self, row: RobustnessRow) -> str:
        """Which of :meth:`plant_sets` ``row`` ran on."""
        if math.isfinite(row.confidence):
            return f"{row.confidence:g}"
        return "box" if row.plants == self.box.label else "nominal"

    def row(self, reference: str, plant_set: str) -> RobustnessRow:
        """The row of set-point ``reference`` (e.g. ``"20 mm"``) on ``plant_set``."""
        found = [r for r in self.rows if r.reference == reference and self.plant_set(r) == plant_set]
        if len(found) != 1:
            raise KeyError(f"no row ({reference!r}, {plant_set!r}); plant sets: {self.plant_sets()}")
        return found[0]

    def totals(self, plant_set: str) -> dict[str, int]:
        """Runs and violations over the set-points on ``plant_set``."""
        rows = [r for r in self.rows if self.plant_set(r) == plant_set]
        return {"runs": sum(r.runs for r in rows), "violations": sum(r.violations for r in rows)}


@dataclass(frozen=True)
class OperatingRegionStudy(Result):
    """Everything the operating-region report shows (module docstring).

    ``status``: ``"certified"`` when every reference has a certificate, no run started inside a
    certified set left F and no certified slice start was unsafe; ``"violations"`` when a run or
    a slice contradicts a certificate (an assumption of the certificate does not hold on the
    sampled twin); ``"not_certified"`` when some reference has no certificate. ``timings`` [s]
    by step, in the order run, with the ``total``.
    """

    success: bool
    status: str
    message: str
    config: StudyConfig
    feasible: FeasibleSet
    loop: RegulatorLoop
    references: tuple[ReferenceStudy, ...]
    maps: tuple[FeasibilityMap, ...]
    slices: dict[str, tuple[SliceCheck, ...]]  # "Lyapunov P"/"SDP P" -> FL slices judged against it
    large_step: LargeStepStudy | None
    quantization: CertificateCheck | None
    r_zero_current: tuple[float, float]  # least |u| [A] where R = 0 over the gap range, and its gap [m]
    robust: RobustStudy | None = None  # None: robust_runs 0, or gains other than the sweeps' (papers')
    timings: Mapping[str, float] = field(default_factory=dict)

    def inside_totals(self) -> dict[str, int]:
        """Runs started inside certified sets and their violations, over all references."""
        n = sum(c.n for r in self.references for c in r.checks.values())
        bad = sum(c.violations for r in self.references for c in r.checks.values())
        return {"runs": n, "violations": bad}


def _verdict(references, slices) -> tuple[bool, str, str]:
    """(success, status, message) of a study from its certificates, inside runs and slices."""
    certified = sum(r.lyapunov.success for r in references)
    runs = sum(c.n for r in references for c in r.checks.values())
    bad = sum(c.violations for r in references for c in r.checks.values())
    unsafe = sum(s.unsafe_certified for v in slices.values() for s in v)
    message = (
        f"{certified} of {len(references)} references certified; {runs} runs inside the certified sets, "
        f"{bad} left F; {unsafe} certified slice starts unsafe"
    )
    if bad or unsafe:
        return False, "violations", message
    if certified < len(references):
        return False, "not_certified", message
    return True, "certified", message


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


@dataclass
class _Run:
    """What every step of one study shares."""

    model: StageModel
    config: StudyConfig
    feasible: FeasibleSet
    loop: RegulatorLoop
    rng: np.random.Generator
    say: Callable[[str], None]
    timings: dict[str, float]

    @property
    def limit(self) -> float | None:
        return self.feasible.current_limit

    def simulator(self, twin: RigTwin, controller, duration: float) -> BatchSimulator:
        c = self.config
        return BatchSimulator(twin, controller, duration=duration, threads=c.threads, compile=c.compile)


def operating_region_study(
    model: StageModel,
    config: StudyConfig | None = None,
    *,
    loop: RegulatorLoop | None = None,
    feasible: FeasibleSet | None = None,
    progress: Callable[[str], None] | None = None,
    covariance=None,
    covariance_source: str = "",
) -> OperatingRegionStudy:
    """Run the whole study (module docstring) for ``model`` (plant = controller model; in the
    robust part, plants around it).

    Parameters
    ----------
    model : StageModel
    config : StudyConfig, optional
        What to compute and how much (default: the report's).
    loop : RegulatorLoop, optional
        The FL loop (default: the papers' gains).
    feasible : FeasibleSet, optional
        F (default: 9 A and the stoppers).
    progress : callable, optional
        Called with a line of text as each step starts.
    covariance : (4, 4) array, optional
        Of the model's (C1, C2, C3, C4) [their units squared], e.g. a stage file's, for the robust
        part (default: :func:`~maglev_oc.region.robust.assumed_covariance`, said to be assumed).
    covariance_source : str
        Where ``covariance`` comes from, as the report prints it.

    Returns
    -------
    OperatingRegionStudy
    """
    t_all = time.perf_counter()
    config = config or StudyConfig()
    loop = loop or RegulatorLoop()
    feasible = feasible or FeasibleSet(model)
    run = _Run(
        model, config, feasible, loop, np.random.default_rng(config.seed), progress or (lambda _m: None), {}
    )
    t0 = time.perf_counter()
    proc = Procedure2(feasible, loop)
    builder = PolygonBuilder(feasible, loop)
    run.timings["build solvers"] = time.perf_counter() - t0
    certs = _certificates(run, proc, builder)
    maps = _timed(run, "feasibility maps", lambda: _maps(run))
    t0 = time.perf_counter()
    fl = FeedbackLinearizingRegulator(model, loop.K_h, loop.K_v, omega0=loop.omega0)
    sim = run.simulator(RigTwin(model), fl, config.horizon)
    run.timings["build Monte Carlo (FL)"] = time.perf_counter() - t0
    ref_studies = _timed(run, "Monte Carlo inside the certified sets", lambda: _inside_runs(run, sim, certs))
    slices = _timed(run, "Monte Carlo on slices (conservativeness)", lambda: _slices(run, sim, ref_studies))
    quant = _timed(run, "Monte Carlo with encoder quantisation", lambda: _quantization(run, fl, ref_studies))
    large = None
    if config.linear:
        run.say("large step and linear regulators")
        large = _large_step(run, proc, builder, sim)
    robust = _robust(run, ref_studies, covariance, covariance_source)
    run.timings["total"] = time.perf_counter() - t_all
    return OperatingRegionStudy(
        *_verdict(ref_studies, slices),
        config,
        feasible,
        loop,
        tuple(ref_studies),
        maps,
        slices,
        large,
        quant,
        _r_zero_current(model, feasible),
        robust,
        run.timings,
    )


def _robust(run: _Run, ref_studies: list[ReferenceStudy], covariance, source: str) -> RobustStudy | None:
    """The robust part (:class:`RobustStudy`), or None when it is off or the loop's gains are not
    the papers' (the sweeps build the FL regulator with those)."""
    config, loop, model = run.config, run.loop, run.model
    papers = np.array_equal(loop.K_h, PAPER_K_H) and np.array_equal(loop.K_v, PAPER_K_V)
    if not config.robust_runs or not (papers and loop.omega0 == OMEGA0):
        return None
    constants = tuple(float(c) for c in model.constants.as_array())
    assumed = covariance is None
    if assumed:
        covariance = assumed_covariance(model.constants)
        source = source or "assumed"
    covariance = np.asarray(covariance, dtype=float)
    if covariance.shape != (4, 4):
        raise InputError(f"covariance must be 4 x 4 over (C1, C2, C3, C4), got {covariance.shape}")
    nominal = PlantSet.point(constants)
    specs: dict[str, SweepSpec] = {}
    certificates: dict[str, str] = {}
    for rs in ref_studies:
        cert = rs.best
        if not (rs.reference.is_setpoint and cert.success):
            continue
        label = _short(rs.reference)
        certificates[label] = "SDP P" if cert is not rs.lyapunov else "Lyapunov P"
        specs[label] = SweepSpec(
            nominal,
            rs.reference,
            constants=constants,
            params=model.params,
            P=tuple(map(tuple, cert.P)),
            level=float(cert.level),
            duration=config.horizon,
            current_limit=run.limit,
        )
    if not specs:
        return None
    box = paper_tables_box()
    run.say("robust: nominal certificates on sampled plants")
    rows = _timed(
        run,
        "robust: runs on sampled plants (table)",
        lambda: robustness_table(specs, covariance, box=box, runs=config.robust_runs, seed=config.seed),
    )
    radii: list[CriticalRadius] = []
    if config.robust_probe_runs:
        probes = dict(specs)
        if config.linear:
            probes["large step"] = SweepSpec(
                nominal,
                Reference.setpoint(*LARGE_STEP_TARGET),
                constants=constants,
                params=model.params,
                start=LARGE_STEP_START,
                duration=config.linear_horizon,
                current_limit=run.limit,
            )
        run.say("robust: radius where runs first leave F")
        radii = _timed(
            run,
            "robust: critical radii (bisection)",
            lambda: [
                critical_radius(k, spec, covariance, runs=config.robust_probe_runs, seed=config.seed)
                for k, spec in probes.items()
            ],
        )
    certified = None
    if config.certify_boxes:
        run.say("robust: certified robust levels")
        certified = _timed(
            run, "robust: certified robust levels", lambda: _certified(run, ref_studies, covariance, specs)
        )
    return RobustStudy(
        covariance,
        source,
        assumed,
        tuple(CONFIDENCE_LEVELS),
        box,
        certificates,
        tuple(rows),
        tuple(radii),
        config.robust_runs,
        config.robust_probe_runs,
        certified,
    )


CERTIFY_DESIGN_LEVEL = 0.9
"""The confidence set the robust SDP chooses P for (bench/region_robust_certificate.py)."""


def _certified(run: _Run, ref_studies, covariance, specs: dict[str, SweepSpec]) -> CertifiedRobustStudy:
    """:class:`CertifiedRobustStudy` for the set-points of ``specs`` (labels as in the robust part)."""
    from maglev_oc.region.sweep import run_sweep

    config = run.config
    constants = np.asarray(run.model.constants.as_array(), dtype=float)
    sets = {p: PlantSet.confidence(constants, covariance, p) for p in CONFIDENCE_LEVELS}
    proc = Procedure2(run.feasible, run.loop)
    certifier = RobustCertifier(
        run.feasible, run.loop, max_boxes=config.certify_boxes, ladder=config.certify_ladder
    )
    rows = []
    for rs in ref_studies:
        label = _short(rs.reference)
        if label not in specs:
            continue
        P, message = robust_lyapunov_matrix(certifier, rs.lyapunov, sets[CERTIFY_DESIGN_LEVEL])
        nominal = None if P is None else proc.run(rs.reference, P)
        certs: list[RobustCertificate] = []
        if nominal is not None and nominal.success:
            for plants in sets.values():
                certs.append(certifier.run(nominal, plants))
                if not certs[-1].success:
                    break  # a larger set (same ellipsoid, larger radius) is not certified either
        rows.append(CertifiedRobustRow(label, nominal, message, tuple(certs)))
    checked, violations, runs = None, 0, 0
    candidates = [
        (r.certificates[0], r.reference) for r in rows if r.certificates and r.certificates[0].success
    ]
    if candidates and config.certify_runs:
        cert, label = max(candidates, key=lambda c: c[0].level)  # the largest certified set at 0.5
        level = CONFIDENCE_LEVELS[0]
        spec = replace(specs[label], plants=sets[level], P=tuple(map(tuple, cert.P)), level=float(cert.level))
        sweep = run_sweep(spec, config.certify_runs, seed=config.seed, progress=False)
        checked, violations, runs = (label, level), int(sweep.violations), int(sweep.n)
    return CertifiedRobustStudy(
        tuple(CONFIDENCE_LEVELS),
        CERTIFY_DESIGN_LEVEL,
        config.certify_boxes,
        tuple(config.certify_ladder),
        tuple(rows),
        checked,
        runs,
        violations,
    )


def _r_zero_current(model: StageModel, feasible: FeasibleSet) -> tuple[float, float]:
    """Least |u| [A] on R = 0 over the gap range, and the gap [m] where it is least. On R = 0 the
    transformation gives i_d = -L3 / (2 L4) whatever v1, and |u| >= |i_d|."""
    lo, hi = feasible.gap_range or (5 * MM_TO_M, 35 * MM_TO_M)
    gaps = np.linspace(lo, hi, 221)
    _, _, L3, L4 = model.coefficients(gaps)
    current = np.abs(L3 / (2 * L4))
    k = int(np.argmin(current))
    return float(current[k]), float(gaps[k])


def _timed(run: _Run, name: str, step: Callable[[], object]):
    t0 = time.perf_counter()
    out = step()
    run.timings[name] = time.perf_counter() - t0
    return out


def _certificates(run: _Run, proc: Procedure2, builder: PolygonBuilder) -> list[tuple]:
    """(reference, Procedure 2 with the Lyapunov equation's P, SDP result or None) per reference:
    the set-points across ``setpoints_mm`` and the papers' sinusoid."""
    config = run.config
    refs = [Reference.setpoint(g * MM_TO_M, config.position) for g in config.setpoints_mm]
    if config.sinusoid:
        refs.append(Reference.paper_sinusoid())
    certs = []
    t_p2 = t_sdp = 0.0
    for ref in refs:
        run.say(f"Procedure 2: {ref.label}")
        t0 = time.perf_counter()
        lyap = proc.run(ref, seed=config.seed)
        t_p2 += time.perf_counter() - t0
        sdp = None
        if config.sdp:
            t0 = time.perf_counter()
            sdp = enlarge(proc, ref, builder=builder)
            t_sdp += time.perf_counter() - t0
        certs.append((ref, lyap, sdp))
    run.timings["procedure 2 (Lyapunov P)"] = t_p2
    run.timings["SDP enlargement (incl. re-certification)"] = t_sdp
    return certs


def _maps(run: _Run) -> tuple[FeasibilityMap, ...]:
    """F on slices through the 20 mm set-point and, with the sinusoid, through its orbit."""
    feasible, loop, n = run.feasible, run.loop, run.config.map_points
    if not n:
        return ()
    mid = Reference.setpoint(20 * MM_TO_M, run.config.position)
    g_lo, g_hi = feasible.gap_range or (5 * MM_TO_M, 35 * MM_TO_M)
    e_rng = (g_lo - 2 * MM_TO_M - mid.gap, g_hi + 2 * MM_TO_M - mid.gap)
    slices = [
        (mid, ("e1", "e1_rate"), e_rng, (-0.6, 0.6)),
        (mid, ("e1", "e2"), e_rng, (-0.065, 0.065)),
        (mid, ("e2", "e2_rate"), (-0.065, 0.065), (-0.8, 0.8)),
        (mid, ("e1", "xi_v3"), e_rng, (-2e-3, 2e-3)),
    ]
    if run.config.sinusoid:
        sin = Reference.paper_sinusoid()
        slices.append((sin, ("phase", "e1"), (0, 2 * math.pi), (-0.012, 0.012)))
        slices.append((sin, ("phase", "e2"), (0, 2 * math.pi), (-0.04, 0.04)))
    return tuple(feasibility_map(feasible, loop, ref, axes, xr, yr, n=n) for ref, axes, xr, yr in slices)


def _inside_runs(run: _Run, sim: BatchSimulator, certs: list[tuple]) -> list[ReferenceStudy]:
    """Monte Carlo inside each certified set on the sampled ideal twin, and a run from the
    certified boundary point nearest F's edge."""
    studies = []
    for ref, lyap, sdp in certs:
        run.say(f"Monte Carlo: {ref.label}")
        checks: dict[str, CertificateCheck] = {}
        worst: dict[str, CertificateCheck] = {}
        pairs = [("Lyapunov P", lyap)]
        if sdp is not None and sdp.certified is not None:
            pairs.append(("SDP P", sdp.certified))
        for label, cert in pairs:
            if not cert.success:
                continue
            if run.config.samples:
                checks.update(
                    _inside_checks(sim, run.loop, ref, cert, run.config.samples, run.rng, label, run.limit)
                )
            w = _worst_start(sim, run.loop, ref, cert, run.limit)
            if w is not None:
                worst[label] = w
        studies.append(ReferenceStudy(ref, lyap, sdp, _enlargement(lyap, sdp), checks, worst))
    return studies


def _slices(
    run: _Run, sim: BatchSimulator, ref_studies: list[ReferenceStudy]
) -> dict[str, tuple[SliceCheck, ...]]:
    """Conservativeness: the empirical safe set vs each certificate on grids of slices."""
    slices: dict[str, list[SliceCheck]] = {"Lyapunov P": [], "SDP P": []}
    config, feasible = run.config, run.feasible
    if config.slice_points:
        by_gap = {round(r.reference.gap / MM_TO_M, 6): r for r in ref_studies if r.reference.is_setpoint}
        for g in config.slice_setpoints_mm:
            rs = by_gap.get(round(g, 6))
            if rs is None:
                continue
            run.say(f"slices at {g:g} mm")
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
                    run.loop,
                    ref,
                    rs.lyapunov.P,
                    rs.lyapunov.level,
                    axes,
                    e_rng,
                    yr,
                    n=config.slice_points,
                    current_limit=run.limit,
                )
                slices["Lyapunov P"].append(base)
                if rs.sdp is not None and rs.sdp.certified is not None:
                    slices["SDP P"].append(base.with_certificate(rs.sdp.certified.P, rs.sdp.certified.level))
    return {k: tuple(v) for k, v in slices.items()}


def _quantization(run: _Run, fl, ref_studies: list[ReferenceStudy]) -> CertificateCheck | None:
    """The quantising encoder (10 um) with noise, inside the best certificate at 20 mm."""
    if not run.config.quantization_samples:
        return None
    target = next(
        (r for r in ref_studies if r.reference.is_setpoint and abs(r.reference.gap - 20 * MM_TO_M) < 1e-9),
        None,
    )
    target = target or ref_studies[0]
    cert = target.best
    if not cert.success:
        return None
    run.say("Monte Carlo with the quantising encoder")
    twin_q = RigTwin(run.model, TwinEffects(encoder=Encoder()))
    sim_q = run.simulator(twin_q, fl, run.config.horizon)
    z = uniform_in_ellipsoid(cert.P, cert.level, run.config.quantization_samples, run.rng)
    x, xi = run.loop.physical_state(z, target.reference, 0.0)
    ref_s = reference_samples(target.reference, 0.0, sim_q.n_steps, twin_q.sample_time)
    noise = run.rng.standard_normal((2, sim_q.n_steps))
    out = sim_q.run(x, regulator_state(x, xi), ref_s, noise)
    bad = out.violations(run.limit)
    return CertificateCheck.of(
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


def _large_step(run: _Run, proc: Procedure2, builder: PolygonBuilder, sim: BatchSimulator) -> LargeStepStudy:
    """The papers' large step for every controller: the FL regulator's certificates and run, the
    linear regulators' certified regions of attraction, and the sampled start x target maps."""
    model, config = run.model, run.config
    ref = Reference.setpoint(*LARGE_STEP_TARGET)
    x0 = np.array(LARGE_STEP_START)
    z0 = run.loop.error_state(x0, np.zeros(6), ref)[:, 0]
    t0 = time.perf_counter()
    lyap = proc.run(ref, seed=config.seed)
    generic = enlarge(proc, ref, builder=builder) if config.sdp else None
    aimed = enlarge(proc, ref, builder=builder, direction=z0) if config.sdp else None
    run.timings["large step: FL certificates"] = time.perf_counter() - t0
    ratio_l = float(z0 @ lyap.P @ z0 / lyap.level) if lyap.success else math.inf
    ratio_s = math.inf
    if generic is not None and generic.certified is not None:
        ratio_s = float(z0 @ generic.certified.P @ z0 / generic.certified.level)
    fl_run = check_error_states(sim, run.loop, ref, lyap.P, lyap.level, z0[:, None], current_limit=run.limit)
    ctrls = [
        paper_linear_regulator(model),
        paper_linear_regulator(model, feedforward=False),
        lqr_regulator(model),
    ]
    linear = _timed(
        run, "large step: certified regions of attraction", lambda: _linear_regions(run, ctrls, ref, x0)
    )
    starts = np.asarray(config.map_starts_mm, dtype=float) * MM_TO_M
    targets = np.asarray(config.map_targets_mm, dtype=float) * MM_TO_M
    maps = _timed(
        run,
        "large step: sampled start x target map",
        lambda: _start_target_maps(run, sim, ctrls, starts, targets),
    )
    j = int(np.argmin(np.abs(starts - x0[0])))
    sweep = {name: {k: v[:, j] for k, v in d.items()} for name, d in maps.items()}
    fg = np.array([10, 12, 14, 16, 18, 22, 26], dtype=float) * MM_TO_M
    fp = frozen_poles(model, ctrls[0], ref, fg)
    extremes = step_extremes(run.loop)
    predicted = _predicted_stoppers(run.feasible, extremes, starts, targets)
    return LargeStepStudy(
        ref,
        x0,
        ratio_l,
        ratio_s,
        aimed,
        fl_run,
        linear,
        starts,
        targets,
        maps,
        sweep,
        fg,
        fp,
        extremes,
        predicted,
    )


def step_extremes(loop: RegulatorLoop, duration: float = 10.0, dt: float = 1e-3) -> np.ndarray:
    """The FL loop's error after a unit step from rest with empty internal models, per axis: its
    least and largest value over ``duration`` [s], (2, 2) = ((v min, v max), (h min, h max)).

    Where the transformation exists the loop is linear in the errors (z~' = A_cl z~), so a step of
    size d from rest gives the error d times this response: its least value is minus the overshoot."""
    from scipy.linalg import expm

    step = expm(loop.A * dt)
    out = np.zeros((2, 2))
    for axis, k in enumerate((E1, E2)):
        z = np.zeros(loop.A.shape[0])
        z[k] = 1.0
        low = high = 1.0
        for _ in range(round(duration / dt)):
            z = step @ z
            low, high = min(low, z[k]), max(high, z[k])
        out[axis] = (low, high)
    return out


def _predicted_stoppers(feasible: FeasibleSet, extremes, starts, targets) -> np.ndarray:
    """(n_t, n_s) bool: the FL loop's linear error dynamics reach a stopper on the step from (start
    gap, position 0) at rest to (target gap, the target position)."""
    S, T = np.meshgrid(starts, targets)
    hit = np.zeros(S.shape, dtype=bool)
    for rng, start, target, (low, high) in (
        (feasible.gap_range, S, T, extremes[0]),
        (feasible.position_range, 0.0, LARGE_STEP_TARGET[1], extremes[1]),
    ):
        if rng is None:
            continue
        d = start - target  # the initial error
        least = target + np.minimum(d * low, d * high)
        largest = target + np.maximum(d * low, d * high)
        hit |= (least <= rng[0]) | (largest >= rng[1])
    return hit


def _linear_regions(run: _Run, ctrls, ref: Reference, x0: np.ndarray) -> tuple[LinearStudy, ...]:
    """The linear regulators' certified regions of attraction and where the large step starts."""
    linear = []
    for ctrl in ctrls:
        roa = certify_roa(run.model, ctrl, ref, feasible=run.feasible)
        zh = LinearizedLoop(run.model, ctrl, ref).initial_error(x0)
        ratio = float(zh @ roa.P @ zh / roa.level) if roa.level > 0 else math.inf
        linear.append(LinearStudy(ctrl.name, roa, ratio))
    return tuple(linear)


def _start_target_maps(
    run: _Run, fl_sim: BatchSimulator, ctrls, starts: np.ndarray, targets: np.ndarray
) -> dict:
    """Sampled estimate: start gap x target gap (start at rest at position 0, target position
    20 mm), per controller, the FL regulator first: success (converged without a stopper; for the
    FL regulator also without leaving F), the outcome (:data:`BASIN_OUTCOMES`), least and largest
    gap [m], largest |u| [A] and least R / (4 L4) [m/s^2], each (n_targets, n_starts)."""
    limit = run.limit if run.limit is not None else math.inf
    duration = run.config.linear_horizon
    sims = [fl_sim.with_duration(duration)]
    sims += [run.simulator(RigTwin(run.model), ctrl, duration) for ctrl in ctrls]
    xs = np.vstack([starts, np.zeros((3, starts.size))])
    maps: dict[str, dict[str, np.ndarray]] = {}
    for k_ctrl, bsim in enumerate(sims):
        c0 = np.vstack([xs, np.zeros((bsim.controller.n_state - 4, starts.size))])
        rows = []
        for g in targets:
            out = bsim.run(xs, c0, np.array([g, 0, 0, LARGE_STEP_TARGET[1], 0, 0]))
            with np.errstate(invalid="ignore"):
                err = np.hypot(out.final_twin[0] - g, out.final_twin[2] - LARGE_STEP_TARGET[1])
                negative = out.min_margin < 0  # NaN (no margin) compares False
                over = out.max_current > limit * (1 + 1e-9)
            code = _outcome_codes(out.finite, out.stopper_hit, err < SETTLED, over, negative)
            rows.append((code, out.min_gap, out.max_gap, out.max_current, out.min_margin))
        code, gmin, gmax, imax, margin = (np.array(x) for x in zip(*rows, strict=True))
        converged = code <= 2
        success = (code == 0) if k_ctrl == 0 else converged
        maps[bsim.controller.name] = {
            "success": success,
            "outcome": code,
            "within_limit": code == 0,
            "min_gap": gmin,
            "max_gap": gmax,
            "max_current": imax,
            "min_margin": margin,
        }
    return maps


def certificate_rows(study: OperatingRegionStudy) -> list[tuple]:
    """A compact table of the certified sets, for reports.

    Parameters
    ----------
    study : OperatingRegionStudy

    Returns
    -------
    list of tuple
        Rows (reference, P, level, upper, tightness, binding, e1 [mm], e1' [mm/s], e2 [mm],
        e2' [mm/s], rectangle e1 x e2 [mm]).
    """
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
                    s["e1"] * M_TO_MM,
                    s["e1_rate"] * M_TO_MM,
                    s["e2"] * M_TO_MM,
                    s["e2_rate"] * M_TO_MM,
                    f"{a * M_TO_MM:.2f} x {b * M_TO_MM:.2f}",
                )
            )
    return rows


def _short(ref: Reference) -> str:
    if ref.is_setpoint:
        return f"{ref.gap * M_TO_MM:g} mm"
    return "sinusoid"
