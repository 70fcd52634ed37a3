"""Monte Carlo sweeps over sampled plants, split into Dask tasks.

The controller keeps the nominal constants C1..C4 it was designed with; the plant's constants
are drawn from an uncertainty set (:class:`PlantSet`: a confidence ellipsoid of an
identification, or a box), and each run starts inside a certified set (or at one given state).
A run *violates* when it leaves the feasible set F as :meth:`BatchOutcome.violations` judges it:
R < 0 in the controller's transformation, |u| above the current limit, a stopper hit, or a
non-finite state.

Sampled plants without a C build per plant: :class:`SampledPlantTwin` is the rig twin with the
plant's constants carried as four extra state rows that every step passes on unchanged, so one
generated-C closed loop (:class:`~maglev_oc.region.montecarlo.BatchSimulator`) runs any plant;
:class:`PlantBatchSimulator` sets those rows per run.

Sampled effects too: with ``SweepSpec(effects=TwinEffects.rig(), effect_ranges=...)`` each run
scales the twin's guide friction (vertical, horizontal: Coulomb level and viscous coefficient) and
its cogging force by factors drawn uniformly from those ranges (:data:`EFFECT_SCALES`), carried as
three more state rows the same way.

Reproducible with a seed whatever the number of workers: the runs are cut into tasks of a fixed
size (``task_size``, independent of the worker count), task k draws its plants and starts from
``numpy.random.SeedSequence(seed).spawn(n_tasks)[k]`` and the results are concatenated in task
order. On 1 worker the tasks run in this process; with more, on a ``dask.distributed``
``LocalCluster`` of single-threaded processes, or on any Dask scheduler by address. Dask is an
optional dependency (the ``sweeps`` extra), imported only when a cluster is asked for.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import math
import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.model.hardware import PEAK_CURRENT_LIMIT
from maglev_oc.model.parameters import DEFAULT_CONSTANTS, LumpedConstants, StageParameters
from maglev_oc.model.stage import StageModel
from maglev_oc.region.closed_loop import N_ERROR, Reference, RegulatorLoop
from maglev_oc.region.montecarlo import (
    BatchOutcome,
    BatchSimulator,
    reference_samples,
    regulator_state,
    uniform_in_ellipsoid,
)
from maglev_oc.results import Result
from maglev_oc.sim.effects import TwinEffects
from maglev_oc.sim.twin import ConstantsAsInput, RigTwin

__all__ = [
    "CONSTANT_NAMES",
    "CONTROLLERS",
    "EFFECT_SCALES",
    "PlantBatchSimulator",
    "PlantSet",
    "SampledPlantTwin",
    "SweepResult",
    "SweepSpec",
    "dask_client",
    "run_sweep",
]

CONSTANT_NAMES = ("C1", "C2", "C3", "C4")
CONTROLLERS = ("fl", "lqr", "linear")
"""Controllers a sweep can run: the FL regulator, the LQR regulator, the papers' linear regulator."""
EXTRA_HINT = "pip install 'maglev_oc[sweeps]'"
EFFECT_SCALES = ("friction_vertical", "friction_horizontal", "cogging")
"""The twin's effects a sweep can scale per run, in the order of ``SweepSpec.effect_ranges`` and
of the scale rows of :class:`SampledPlantTwin`."""
_N_SCALES = len(EFFECT_SCALES)


def _import_distributed():
    """``dask.distributed``, or an error naming the extra that installs it."""
    try:
        import dask.distributed as distributed
    except ImportError as exc:
        raise InputError(
            f"sweeps on more than one worker or on a scheduler need Dask ({exc}); install the "
            f"'sweeps' extra: {EXTRA_HINT}"
        ) from None
    return distributed


# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PlantSet:
    """An uncertainty set of the plant's constants (C1, C2, C3, C4), sampled uniformly.

    ``kind`` ``"ellipsoid"``: {C : (C - center)' S^+ (C - center) <= 1} with S = ``shape``
    (for a confidence set, the covariance times the chi-square quantile; directions where S is
    zero are held at the center). ``"box"``: ``lower <= C <= upper``. Use the constructors.
    """

    kind: str
    center: tuple[float, float, float, float]
    shape: tuple[tuple[float, ...], ...] = ()  # (4, 4) for an ellipsoid
    lower: tuple[float, ...] = ()  # (4,) for a box
    upper: tuple[float, ...] = ()
    label: str = ""

    def __post_init__(self) -> None:
        if self.kind not in ("ellipsoid", "box"):
            raise InputError(f"PlantSet.kind must be 'ellipsoid' or 'box', got {self.kind!r}")
        c = np.asarray(self.center, dtype=float)
        if c.shape != (4,) or not np.all(np.isfinite(c)) or np.any(c <= 0):
            raise InputError(f"PlantSet.center must be 4 positive constants, got {self.center!r}")
        if self.kind == "ellipsoid":
            s = np.asarray(self.shape, dtype=float)
            if s.shape != (4, 4) or not np.all(np.isfinite(s)) or not np.allclose(s, s.T):
                raise InputError(f"PlantSet.shape must be a symmetric finite 4 x 4 matrix, got {s.shape}")
            if np.linalg.eigvalsh(_relative(s, c)).min() < -1e-12:
                raise InputError("PlantSet.shape must be positive semidefinite")
        else:
            lo, hi = np.asarray(self.lower, dtype=float), np.asarray(self.upper, dtype=float)
            if lo.shape != (4,) or hi.shape != (4,) or not np.all(lo <= hi) or np.any(lo <= 0):
                raise InputError(
                    f"PlantSet box needs 0 < lower <= upper (4 each), got {self.lower!r}, {self.upper!r}"
                )

    @classmethod
    def confidence(cls, mean, covariance, level: float) -> PlantSet:
        """The confidence ellipsoid of an estimate: covariance scaled by the chi-square quantile of
        ``level`` with as many degrees of freedom as the covariance's rank.

        Parameters
        ----------
        mean : (4,) array or LumpedConstants
        covariance : (4, 4) array
            Of (C1, C2, C3, C4) [their units squared]; zero rows for constants held fixed.
        level : float
            Confidence level in (0, 1).
        """
        from scipy.stats import chi2

        if not (0 < level < 1):
            raise InputError(f"confidence level must be in (0, 1), got {level!r}")
        m = _constants_array(mean)
        cov = np.asarray(covariance, dtype=float)
        if cov.shape != (4, 4):
            raise InputError(f"covariance must be 4 x 4 over (C1, C2, C3, C4), got {cov.shape}")
        eig = np.linalg.eigvalsh(_relative(cov, m))
        rank = int(np.sum(eig > 1e-12 * max(eig.max(), 1e-300)))
        q = float(chi2.ppf(level, max(rank, 1)))
        return cls(
            "ellipsoid",
            tuple(m),
            tuple(map(tuple, q * cov)),
            label=f"{level:.3g} confidence ellipsoid ({rank} dof, chi2 quantile {q:.3g})",
        )

    @classmethod
    def box(cls, lower, upper) -> PlantSet:
        """Every constant in [lower, upper] (the center is the box's midpoint)."""
        lo, hi = _constants_array(lower), _constants_array(upper)
        ranges = ", ".join(
            f"{n} in [{a:.4g}, {b:.4g}]" for n, a, b in zip(CONSTANT_NAMES, lo, hi, strict=True)
        )
        return cls(
            "box",
            tuple(0.5 * (lo + hi)),
            lower=tuple(lo),
            upper=tuple(hi),
            label=f"box {ranges}",
        )

    @classmethod
    def point(cls, constants) -> PlantSet:
        """The zero-size set: the plant is exactly ``constants``."""
        c = _constants_array(constants)
        return cls("box", tuple(c), lower=tuple(c), upper=tuple(c), label="the nominal plant")

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """n plants drawn uniformly from the set: (4, n) constants."""
        c = np.asarray(self.center, dtype=float)[:, None]
        if self.kind == "box":
            lo, hi = np.asarray(self.lower)[:, None], np.asarray(self.upper)[:, None]
            return lo + (hi - lo) * rng.uniform(0.0, 1.0, (4, n))
        eig, vec = np.linalg.eigh(_relative(self.shape, self.center))
        keep = eig > 1e-12 * max(eig.max(), 1e-300)
        k = int(keep.sum())
        if k == 0:
            return np.repeat(c, n, axis=1)
        g = rng.standard_normal((k, n))
        g /= np.linalg.norm(g, axis=0, keepdims=True)
        radius = rng.uniform(0.0, 1.0, n) ** (1.0 / k)
        return c + c * (vec[:, keep] @ (np.sqrt(eig[keep])[:, None] * g * radius))

    def contains(self, constants) -> np.ndarray:
        """Whether each column of ``constants`` (4, n) lies in the set: (n,) bool."""
        C = np.asarray(constants, dtype=float).reshape(4, -1)
        d = C - np.asarray(self.center)[:, None]
        if self.kind == "box":
            lo, hi = np.asarray(self.lower)[:, None], np.asarray(self.upper)[:, None]
            return np.all((C >= lo) & (C <= hi), axis=0)
        # relative to the centre's constants (see _relative): d' S^+ d is unchanged by the scaling
        s = _relative(self.shape, self.center)
        d = d / np.asarray(self.center)[:, None]
        pinv = np.linalg.pinv(s, rcond=1e-12, hermitian=True)
        inside = np.einsum("in,ij,jn->n", d, pinv, d) <= 1 + 1e-9
        off = d - s @ pinv @ d  # components outside the ellipsoid's span, relative to the centre
        return inside & np.all(np.abs(off) <= 1e-9, axis=0)


def _relative(matrix, center) -> np.ndarray:
    """A (4, 4) matrix over (C1..C4) in units of the centre's constants, S_ij / (c_i c_j), symmetrised.

    The constants differ by up to six orders of magnitude (C4 ~ 2e-3, C2 ~ 8e2): an eigenvalue
    threshold relative to the largest one, applied to the covariance itself, took a correlated
    covariance's well-determined direction for a fixed one (its eigenvalue ~1e-12 of the largest),
    and S S^+ of a point off by rounding for a point off the span (contains() then refused 99.99 %
    of draws from the estimate's own distribution). Relative to the centre the scales are alike."""
    c = np.asarray(center, dtype=float)
    s = np.asarray(matrix, dtype=float) / np.outer(c, c)
    return 0.5 * (s + s.T)


def _constants_array(value) -> np.ndarray:
    if isinstance(value, LumpedConstants):
        return np.asarray(value.as_array(), dtype=float)
    a = np.asarray(value, dtype=float).reshape(-1)
    if a.shape != (4,):
        raise InputError(f"constants must be (C1, C2, C3, C4), got {value!r}")
    return a


# ----------------------------------------------------------------------------------------------
class SampledPlantTwin(RigTwin):
    """The rig twin whose plant is part of its state: scales of the effects of
    :data:`EFFECT_SCALES` (3 rows), then the constants C1..C4 (the last four rows).

    ``step`` passes those rows on unchanged and uses them: the constants for L1..L4, the scales
    on the guides' Coulomb friction (level, with any binding of a misalignment, and pre-sliding
    stiffness together), their viscous coefficients and the cogging forces, so one step
    Function (and one generated-C loop) simulates any plant; :meth:`initial_state` fills them
    (default: the model's constants, every scale 1). ``acceleration`` uses the model's constants
    and unit scales. The delay, amplifier, encoder and stoppers are the twin's
    (:class:`~maglev_oc.sim.twin.RigTwin`).
    """

    def _build(self) -> None:
        object.__setattr__(self, "n_state", self.n_state + _N_SCALES + 4)  # once, from __post_init__
        self._nominal_plant()
        super()._build()

    def _nominal_plant(self) -> None:
        object.__setattr__(self, "_plant_constants", ca.DM(self.model.constants.as_array()))
        object.__setattr__(self, "_effect_scales", ca.DM.ones(_N_SCALES))

    def _accelerations(self, x, i, friction):
        nominal = self.model
        object.__setattr__(self, "model", ConstantsAsInput(nominal, self._plant_constants))
        try:
            return super()._accelerations(x, i, friction)
        finally:
            object.__setattr__(self, "model", nominal)

    def _friction_scale(self, axis: int):
        return self._effect_scales[axis]

    def _viscous_force(self, axis: int, velocity):
        return self._effect_scales[axis] * super()._viscous_force(axis, velocity)

    def _cogging_forces(self, x, gap):
        normal, along = super()._cogging_forces(x, gap)
        return self._effect_scales[2] * normal, self._effect_scales[2] * along

    def _step_function(self) -> ca.Function:
        """RigTwin's step on the first rows, the plant's rows passed on."""
        nb = self.n_state - _N_SCALES - 4
        s = ca.SX.sym("s", self.n_state)
        u_cmd = ca.SX.sym("u", 2)
        object.__setattr__(self, "_effect_scales", s[nb : nb + _N_SCALES])
        object.__setattr__(self, "_plant_constants", s[nb + _N_SCALES :])
        base_next, flags = self._step_rows(s[:nb], u_cmd)
        self._nominal_plant()
        s_next = ca.vertcat(base_next, s[nb:])
        return ca.Function("twin_step", [s, u_cmd], [s_next, flags], ["s", "u"], ["s_next", "flags"])

    def initial_state(self, x0, u0=(0.0, 0.0), constants=None, scales=None) -> np.ndarray:
        """Twin state for ``x0`` and ``u0`` (:meth:`RigTwin.initial_state`), the effects' scales
        (3,) (default 1) and the plant's constants (4,) (default: the model's)."""
        c = self.model.constants.as_array() if constants is None else _constants_array(constants)
        k = np.ones(_N_SCALES) if scales is None else np.asarray(scales, dtype=float).reshape(-1)
        if k.shape != (_N_SCALES,):
            raise InputError(
                f"scales must be {_N_SCALES} values, one per effect of {EFFECT_SCALES}, got {scales!r}"
            )
        return np.concatenate([super().initial_state(x0, u0), k, c])


class PlantBatchSimulator(BatchSimulator):
    """:class:`BatchSimulator` on a :class:`SampledPlantTwin`: each run with its own plant."""

    def __init__(self, twin: SampledPlantTwin, controller, **kwargs) -> None:
        if not isinstance(twin, SampledPlantTwin):
            raise TypeError(f"twin must be a SampledPlantTwin, got {type(twin).__name__}")
        super().__init__(twin, controller, **kwargs)

    def run_plants(self, x0, c0, reference, constants, scales=None) -> BatchOutcome:
        """n runs, run k on the plant with constants ``constants[:, k]`` (and effect scales
        ``scales[:, k]``).

        Parameters
        ----------
        x0 : (4, n) array
        c0 : (n_ctrl, n) array
        reference : (6, n_steps) or (6,) array
        constants : (4, n) array
            The plants' C1..C4.
        scales : (3, n) array, optional
            Scales of the twin's effects (:data:`EFFECT_SCALES`); default 1.

        Returns
        -------
        BatchOutcome
            ``final_twin`` holds the constants in its last four rows.
        """
        constants = np.asarray(constants, dtype=float)
        x0 = np.asarray(x0, dtype=float)
        if x0.ndim != 2:
            raise InputError(f"x0 must have shape (4, n), one column per run, got {x0.shape}")
        n = x0.shape[1]
        if constants.shape != (4, n):
            raise InputError(f"constants must have shape (4, n) like x0, got {constants.shape}")
        scales = np.ones((_N_SCALES, n)) if scales is None else np.asarray(scales, dtype=float)
        if scales.shape != (_N_SCALES, n):
            raise InputError(f"scales must have shape ({_N_SCALES}, n) like x0, got {scales.shape}")
        states = np.column_stack(
            [
                self.twin.initial_state(x0[:, k], constants=constants[:, k], scales=scales[:, k])
                for k in range(x0.shape[1])
            ]
        )
        return self.run(x0, c0, reference, twin_states=states)


# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SweepSpec:
    """One sweep: which loop, which plants, which starts (picklable, sent to every task).

    Parameters
    ----------
    plants : PlantSet
        Where the plant's constants are drawn.
    reference : Reference
        The set-point (or sinusoid, at phase 0) the controller tracks.
    controller : {"fl", "lqr", "linear"}
    constants : (4,) tuple
        The controller's (nominal) constants.
    params : StageParameters
        Geometry of controller and plant.
    P, level : (10, 10) tuple, float
        With ``start`` None: starts uniform in {z~' P z~ <= level} (the FL loop's error
        coordinates, printed gains).
    start : (4,) tuple, optional
        One start for every run, at rest, internal models empty (e.g. the papers' large step).
    duration : float
        Horizon [s].
    current_limit : float or None
        |u| limit [A] of F.
    effects : TwinEffects, optional
        The twin's effects (default: none, the ideal plant).
    effect_ranges : ((lo, hi), (lo, hi), (lo, hi)), optional
        Ranges of the scales of the friction (vertical, horizontal) and cogging of ``effects``
        (:data:`EFFECT_SCALES`), drawn uniformly per run (default: every scale 1).
    """

    plants: PlantSet
    reference: Reference
    controller: str = "fl"
    constants: tuple[float, ...] = tuple(DEFAULT_CONSTANTS.as_array())
    params: StageParameters = field(default_factory=StageParameters)
    P: tuple[tuple[float, ...], ...] | None = None
    level: float = 0.0
    start: tuple[float, ...] | None = None
    duration: float = 1.0
    current_limit: float | None = PEAK_CURRENT_LIMIT
    effects: TwinEffects = field(default_factory=TwinEffects.ideal)
    effect_ranges: tuple[tuple[float, float], ...] | None = None

    def __post_init__(self) -> None:
        if self.effect_ranges is not None:
            ranges = np.asarray(self.effect_ranges, dtype=float)
            if ranges.shape != (_N_SCALES, 2) or not np.all(np.isfinite(ranges)):
                raise InputError(
                    f"effect_ranges must be {_N_SCALES} (lo, hi) pairs for {', '.join(EFFECT_SCALES)}, "
                    f"got {self.effect_ranges!r}"
                )
            if np.any(ranges[:, 0] < 0) or np.any(ranges[:, 0] > ranges[:, 1]):
                raise InputError(f"effect_ranges need 0 <= lo <= hi, got {self.effect_ranges!r}")
            object.__setattr__(self, "effect_ranges", tuple(map(tuple, ranges.tolist())))
        if self.controller not in CONTROLLERS:
            raise InputError(f"controller must be one of {CONTROLLERS}, got {self.controller!r}")
        if (self.P is None) == (self.start is None):
            raise InputError("give either P and level (starts in a certified set) or start")
        if self.P is not None:
            if np.asarray(self.P).shape != (N_ERROR, N_ERROR) or not self.level > 0:
                raise InputError(f"P must be 10 x 10 and level > 0, got {np.shape(self.P)}, {self.level!r}")
            if self.controller != "fl":
                raise InputError("starts in a certified set {z~' P z~ <= level} are for the FL loop")
        if self.start is not None and np.asarray(self.start).shape != (4,):
            raise InputError(f"start must be (x1, x2, x3, x4), got {self.start!r}")
        if not (self.duration > 0 and math.isfinite(self.duration)):
            raise InputError(f"duration must be positive [s], got {self.duration!r}")

    def with_plants(self, plants: PlantSet) -> SweepSpec:
        """The same sweep over another uncertainty set."""
        return dataclasses.replace(self, plants=plants)

    def draw(self, n: int, seed: np.random.SeedSequence) -> tuple[np.ndarray, np.ndarray]:
        """(constants (4, n), starts z~ (10, n); zeros for a fixed start) of a task's stream.

        Plants and starts come from two streams spawned from ``seed``: the same seed gives
        the same starts whatever the plant set (common random numbers across sets)."""
        # the children spawn(2) would give, made without advancing ``seed``'s spawn counter
        plant_seed, start_seed = (
            np.random.SeedSequence(seed.entropy, spawn_key=(*seed.spawn_key, k)) for k in range(2)
        )
        constants = self.plants.sample(n, np.random.default_rng(plant_seed))
        if self.P is None:
            return constants, np.zeros((N_ERROR, n))
        z = uniform_in_ellipsoid(np.asarray(self.P), self.level, n, np.random.default_rng(start_seed))
        return constants, z

    def draw_scales(self, n: int, seed: np.random.SeedSequence) -> np.ndarray:
        """(3, n) effect scales of a task's stream (a third stream of ``seed``; ones without
        ``effect_ranges``)."""
        if self.effect_ranges is None:
            return np.ones((_N_SCALES, n))
        rng = np.random.default_rng(np.random.SeedSequence(seed.entropy, spawn_key=(*seed.spawn_key, 2)))
        ranges = np.asarray(self.effect_ranges)
        return ranges[:, :1] + (ranges[:, 1:] - ranges[:, :1]) * rng.uniform(0.0, 1.0, (_N_SCALES, n))


@functools.lru_cache(maxsize=4)
def _simulator(
    controller: str, params: StageParameters, constants: tuple, duration: float, effects: TwinEffects
) -> PlantBatchSimulator:
    """The compiled loop of a worker (one C build per worker and loop, reused by its tasks)."""
    from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
    from maglev_oc.control.linear_regulator import paper_linear_regulator
    from maglev_oc.control.lqr import lqr_regulator

    model = StageModel(params, LumpedConstants(*constants, source="controller (nominal)"))
    build = {"fl": FeedbackLinearizingRegulator, "lqr": lqr_regulator, "linear": paper_linear_regulator}
    ctrl = build[controller](model)
    return PlantBatchSimulator(SampledPlantTwin(model, effects), ctrl, duration=duration, threads=1)


def _task(spec: SweepSpec, n: int, seed: np.random.SeedSequence) -> dict[str, np.ndarray]:
    """n runs of ``spec`` from the random stream ``seed``: the arrays of :class:`SweepResult`."""
    sim = _simulator(spec.controller, spec.params, tuple(spec.constants), spec.duration, spec.effects)
    constants, z = spec.draw(n, seed)
    scales = spec.draw_scales(n, seed)
    ref = reference_samples(spec.reference, 0.0, sim.n_steps, sim.twin.sample_time)
    if spec.P is None:
        x = np.repeat(np.asarray(spec.start, dtype=float)[:, None], n, axis=1)
        c0 = np.vstack([x, np.zeros((sim.controller.n_state - 4, n))])
        ratio = np.full(n, np.nan)
    else:
        x, xi = RegulatorLoop().physical_state(z, spec.reference, 0.0)
        c0 = regulator_state(x, xi)
        ratio = np.einsum("in,ij,jn->n", z, np.asarray(spec.P), z) / spec.level
    out = sim.run_plants(x, c0, ref, constants, scales)
    return {
        "violating": out.violations(spec.current_limit),
        "constants": constants,
        "effect_scales": scales,
        "start_ratio": ratio,
        "min_margin": out.min_margin,
        "max_current": out.max_current,
        "stopper_hit": out.stopper_hit,
        "min_gap": out.min_gap,
        "max_gap": out.max_gap,
        "finite": out.finite,
    }


@dataclass(frozen=True)
class SweepResult(Result):
    """The runs of one sweep, in task order (arrays (n,), constants (4, n)).

    ``success``: no run violated F (``status`` ``"no_violations"``, else ``"violations"``).
    ``share_feasible`` is the share of runs that stayed in F.
    """

    success: bool
    status: str
    message: str
    spec: SweepSpec = field(repr=False)
    n: int
    violations: int
    share_feasible: float
    seed: int
    task_size: int
    workers: str  # where the tasks ran
    violating: np.ndarray = field(repr=False)
    constants: np.ndarray = field(repr=False)
    effect_scales: np.ndarray = field(repr=False)  # (3, n) EFFECT_SCALES of each run
    start_ratio: np.ndarray = field(repr=False)  # V(start)/level, NaN for a fixed start
    min_margin: np.ndarray = field(repr=False)
    max_current: np.ndarray = field(repr=False)
    stopper_hit: np.ndarray = field(repr=False)
    min_gap: np.ndarray = field(repr=False)
    max_gap: np.ndarray = field(repr=False)
    finite: np.ndarray = field(repr=False)
    timings: Mapping[str, float] = field(default_factory=dict)


SCHEDULER_TIMEOUT_S = 10.0
"""[s] How long :func:`dask_client` tries to reach a scheduler before it gives up (Dask retries a
refused connection until then)."""


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int = 1) -> Iterator[object | None]:
    """Where a sweep's tasks run: None (this process) for 1 worker and no scheduler; a
    ``LocalCluster`` of ``workers`` single-threaded processes; or the Dask scheduler at
    ``scheduler`` (``tcp://host:port``). Closed on exit (a remote cluster is left running)."""
    if not isinstance(workers, int) or workers < 1:
        raise InputError(f"workers must be a positive integer, got {workers!r}")
    if scheduler is None and workers == 1:
        yield None
        return
    distributed = _import_distributed()
    if scheduler is not None:
        try:
            client = distributed.Client(scheduler, timeout=SCHEDULER_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(f"cannot connect to the Dask scheduler {scheduler!r}: {exc}") from None
        with client:
            yield client
        return
    cluster = distributed.LocalCluster(
        n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
    )
    with cluster, distributed.Client(cluster) as client:
        yield client


def run_sweep(
    spec: SweepSpec,
    n: int,
    *,
    seed: int = 0,
    task_size: int = 250,
    client=None,
    progress: bool = True,
) -> SweepResult:
    """Run ``n`` runs of ``spec`` as tasks of ``task_size`` runs (module docstring).

    Parameters
    ----------
    spec : SweepSpec
    n : int
        Runs.
    seed : int
        Root of every task's random stream: the same (spec, n, seed, task_size) give the same
        numbers on any number of workers.
    task_size : int
        Runs per task (the last may be smaller).
    client : dask.distributed.Client, optional
        Where the tasks run (:func:`dask_client`); None: in this process, in order.
    progress : bool
        Show progress on a terminal (silent otherwise).

    Returns
    -------
    SweepResult
    """
    if not isinstance(n, int) or n < 1:
        raise InputError(f"n must be a positive integer, got {n!r}")
    if not isinstance(task_size, int) or task_size < 1:
        raise InputError(f"task_size must be a positive integer, got {task_size!r}")
    if not isinstance(seed, int) or seed < 0:
        raise InputError(f"seed must be a non-negative integer, got {seed!r}")
    t0 = time.perf_counter()
    n_tasks = math.ceil(n / task_size)
    sizes = [min(task_size, n - k * task_size) for k in range(n_tasks)]
    seeds = np.random.SeedSequence(seed).spawn(n_tasks)
    if client is None:
        from maglev_oc.progress import progress as bar

        jobs = zip(sizes, seeds, strict=True)
        if progress:
            jobs = bar(jobs, total=n_tasks, desc="sweep", unit="task")
        parts = [_task(spec, m, s) for m, s in jobs]
        where = "this process"
    else:
        from maglev_oc.progress import shown

        futures = client.map(_task, [spec] * n_tasks, sizes, seeds, pure=False)
        if progress and shown():
            _import_distributed().progress(futures)
        parts = client.gather(futures)
        where = f"Dask, {len(client.scheduler_info().get('workers', {}))} workers"
    arrays = {k: np.concatenate([p[k] for p in parts], axis=-1) for k in parts[0]}
    bad = int(arrays["violating"].sum())
    message = f"{n} runs ({spec.plants.label}; {spec.reference.label}): {bad} left F"
    return SweepResult(
        bad == 0,
        "no_violations" if bad == 0 else "violations",
        message,
        spec,
        n,
        bad,
        1.0 - bad / n,
        seed,
        task_size,
        where,
        timings={"total": time.perf_counter() - t0},
        **arrays,
    )
