"""Why the NPFSI estimates move with eps, and which way (Tables II and III of paper 000).

The papers' estimates grow with eps (Table III: C1 13.97 -> 16.23, C3 30.33 -> 33.44, C4 0.06 ->
0.15 from eps = 0.001 to 0.05; C2 almost still); on the identification twin ours fall (C1 by about
4 %). :func:`eps_trend_study` recomputes both and the condition that turns ours round.

What eps does in the estimator (000 eq. (3), 002 sidebar). The Riccati-like recursion
Sigma' = A'A - gamma^-2 Q does not contain eps, and at low frequency the gain eps^-1 cancels
against the state error e = y - x_hat, which is the acceleration residual low-passed by
F_eps = 1 / (eps s + 1). Once the log has been seen the estimate sits at the solution of

    sum_k w_k A_k' F_eps[y' - b - A theta]_k = 0,    w_k = (k / n)^(1 / (gamma^2 - 1))

(:func:`npfsi_stationary_point`): an instrumental-variable estimate that correlates the
regressors with the residual delayed by about eps. The weights w_k are the estimator's memory:
with Sigma growing like t, the final estimate weights data by Sigma(t)^(1/(gamma^2 - 1)); at
gamma = 1.1 that is t^4.8, so the last half of a log carries 98 % of the weight.

A residual in phase with the acceleration biases every eps alike. A residual in quadrature is
turned by the delay into an in-phase one of relative size about eps (beta - tau omega^2):

* a lag tau of the measured acceleration behind the regressors (the high-gain observer's
  2 eps_obs plus one sample, the amplifier) lowers the gains as eps grows;
* a force in phase with the velocity, -beta M v (damping beta = b / M: guide friction, eddy
  currents), raises them: for x4' = -L1 C1 u1 - beta x4 the limit is C1 (1 + beta eps) to
  first order.

The twin of the identification study has the lag and no friction, hence our downward trend; the
rig twin's guide friction (:meth:`~maglev_oc.sim.effects.TwinEffects.rig`, set from the papers'
10 um settling, not from these tables) turns it upward. The computing is here; the identification
report shows the result.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.signal import lfilter

from maglev_oc.data.logs import Log
from maglev_oc.errors import InputError
from maglev_oc.estimation.differentiate import HighGainDifferentiator, SavitzkyGolay
from maglev_oc.identification.experiments import (
    TWIN_TRUTH,
    excitation_log,
    identification_effects,
    verification_effects,
)
from maglev_oc.identification.layout import CONSTANT_NAMES
from maglev_oc.identification.npfsi import PAPER_EPSILONS, PAPER_GAMMA, npfsi, stage_regression
from maglev_oc.identification.study import PARTIAL as TABLE2_NAMES
from maglev_oc.identification.study import VERTICAL_GAP
from maglev_oc.model.parameters import PAPER_CONSTANTS, LumpedConstants
from maglev_oc.model.stage import StageModel
from maglev_oc.results import Result, jsonable
from maglev_oc.sim.effects import GuideFriction, TwinEffects

__all__ = [
    "FLAT_BAND",
    "RIG_FRICTION",
    "EpsTrend",
    "EpsTrendStudy",
    "eps_trend_study",
    "npfsi_stationary_point",
    "stationary_point",
]

FLAT_BAND = 0.01
"""A relative change from eps = 0.001 to 0.05 smaller than this is called flat. 1 %: the papers'
own C2 differs by 0.75 % between Tables II and III at the same eps, so their 0.25 % change of
C2 with eps is not a trend they resolve; ours of C1 is 4 % and its spread over seeds 0.05 %."""
_RIG = TwinEffects.rig()
RIG_FRICTION = (_RIG.friction_horizontal, _RIG.friction_vertical)
"""(horizontal, vertical) guide friction of the rig twin: the reversing condition by default."""


@dataclass(frozen=True, eq=False)
class EpsTrend:
    """Estimates of some of C1..C4 at each eps from one source (a table of the papers or a run).

    Attributes
    ----------
    source : str
        What produced them, in words.
    names : tuple of str
        The constants, in the order of the rows of ``values``.
    eps : tuple of float
        [s] The estimator's eps, increasing, in the order of the columns.
    values : (len(names), len(eps)) array
        The estimates (units of C1..C4, see :class:`~maglev_oc.model.parameters.LumpedConstants`).
    """

    source: str
    names: tuple[str, ...]
    eps: tuple[float, ...]
    values: np.ndarray

    def __post_init__(self) -> None:
        v = np.array(self.values, dtype=float, copy=True)
        if v.shape != (len(self.names), len(self.eps)) or len(self.eps) < 2:
            raise InputError(
                f"values must be ({len(self.names)}, {len(self.eps)}) with 2+ eps, got {v.shape}"
            )
        if list(self.eps) != sorted(self.eps):
            raise InputError(f"eps must increase, got {self.eps}")
        v.setflags(write=False)
        object.__setattr__(self, "values", v)
        object.__setattr__(self, "names", tuple(self.names))
        object.__setattr__(self, "eps", tuple(float(e) for e in self.eps))

    def value(self, name: str, eps: float) -> float:
        """The estimate of ``name`` at ``eps``."""
        return float(self.values[self.names.index(name), self.eps.index(eps)])

    @property
    def change(self) -> dict[str, float]:
        """Relative change [-] of each constant from the smallest to the largest eps."""
        return {k: float(self.values[i, -1] / self.values[i, 0] - 1) for i, k in enumerate(self.names)}

    @property
    def slope(self) -> dict[str, float]:
        """[1/s] ``change`` per unit of eps: the rate the first-order reading compares with beta."""
        span = self.eps[-1] - self.eps[0]
        return {k: c / span for k, c in self.change.items()}

    def direction(self, band: float = FLAT_BAND) -> dict[str, str]:
        """``"up"``, ``"down"`` or ``"flat"`` (|change| < ``band``) for each constant."""
        return {k: "flat" if abs(c) < band else ("up" if c > 0 else "down") for k, c in self.change.items()}

    def to_dict(self) -> dict[str, Any]:
        return jsonable(
            {
                "source": self.source,
                "eps": list(self.eps),
                "values": {k: self.values[i].tolist() for i, k in enumerate(self.names)},
                "change": self.change,
            }
        )


@dataclass(frozen=True, eq=False)
class EpsTrendStudy(Result):
    """The eps trend of Tables II/III: the papers', ours on the study's twin, ours with friction.

    Attributes
    ----------
    success, status, message : bool, str, str
        ``status``: ``"reproduced"`` when with friction every constant of both tables moves the
        papers' way (up, down or flat within ``band``), ``"partly_reproduced"`` otherwise (the
        message names the rest), ``"failed"`` when an estimator run did not complete.
    papers_table2, papers_table3 : EpsTrend
        Tables II and III of 000.
    default_table2, default_table3 : EpsTrend
        Ours on the identification study's twin runs (observer velocities, as the papers).
    friction_table2, friction_table3 : EpsTrend
        The same runs with guide friction added (``friction``).
    zero_phase_table3 : EpsTrend
        The default Table III log with zero-phase (Savitzky-Golay) velocities: no observer lag.
    limit_default_table3, limit_friction_table3 : EpsTrend
        :func:`npfsi_stationary_point` on the two Table III logs (the recursion's end point
        without the recursion).
    truth : mapping
        The twin's true constants.
    friction : mapping
        The guide friction of the reversing condition, per axis (Coulomb [N], viscous [N s/m]).
    observer_lag : float
        [s] Lag of the observer velocity behind the regressors: 2 eps_obs plus one sample.
    damping_rate : float
        [1/s] Effective beta of the friction on the horizontal axis, read from the C1 slopes
        (friction minus default: the first-order reading).
    papers_damping : float
        [N s/m] Horizontal damping that gives the papers' C1 slope in the first-order reading
        (papers' slope minus our default's, times M_h).
    band : float
        The flat band of the directions.
    explanation : str
        One paragraph, built from the numbers above.
    timings : mapping
        Wall times [s] by step.
    """

    success: bool
    status: str
    message: str
    papers_table2: EpsTrend
    papers_table3: EpsTrend
    default_table2: EpsTrend
    default_table3: EpsTrend
    friction_table2: EpsTrend
    friction_table3: EpsTrend
    zero_phase_table3: EpsTrend
    limit_default_table3: EpsTrend
    limit_friction_table3: EpsTrend
    truth: Mapping[str, float]
    friction: Mapping[str, Mapping[str, float]]
    observer_lag: float
    damping_rate: float
    papers_damping: float
    band: float
    explanation: str
    timings: Mapping[str, float] = field(default_factory=dict)

    def agreement(self) -> dict[str, dict[str, bool]]:
        """Per table, per constant: does the friction run move the papers' way?"""
        out = {}
        for table in ("table2", "table3"):
            paper = getattr(self, f"papers_{table}").direction(self.band)
            ours = getattr(self, f"friction_{table}").direction(self.band)
            out[table] = {k: ours[k] == paper[k] for k in paper}
        return out

    def directions(self) -> dict[str, dict[str, str]]:
        """``"up"``/``"down"``/``"flat"`` (within ``band``) per trend field and constant."""
        return {
            f"{row}_{table}": getattr(self, f"{row}_{table}").direction(self.band)
            for row in ("papers", "default", "friction")
            for table in ("table2", "table3")
        } | {"zero_phase_table3": self.zero_phase_table3.direction(self.band)}

    def to_dict(self) -> dict[str, Any]:
        """Every field in JSON types, plus the directions and the agreement with the papers."""
        return super().to_dict() | {"directions": self.directions(), "agreement": self.agreement()}

    def report(self) -> str:
        """The directions and changes by table, constant and condition."""
        lines = [f"EpsTrendStudy: {self.status}: {self.message}"]
        rows = ("papers", "default", "friction")
        for table in ("table3", "table2"):
            lines.append(
                f"  {table}: relative change from eps = {PAPER_EPSILONS[0]:g} to {PAPER_EPSILONS[-1]:g}"
            )
            for row in rows:
                tr = getattr(self, f"{row}_{table}")
                d = tr.direction(self.band)
                cells = ", ".join(f"{k} {100 * c:+.2f} % ({d[k]})" for k, c in tr.change.items())
                lines.append(f"    {row:<9s} {cells}")
        lines.append(f"  explanation: {self.explanation}")
        lines.append("  timings [s]: " + ", ".join(f"{k} {v:.2f}" for k, v in self.timings.items()))
        return "\n".join(lines)


# --- the estimator's end point --------------------------------------------------------------------
def stationary_point(
    regressor: np.ndarray,
    offset: np.ndarray,
    velocity: np.ndarray,
    sample_time: float,
    eps: float,
    gamma: float = PAPER_GAMMA,
) -> np.ndarray:
    """Where :meth:`NpfsiEstimator.run <maglev_oc.identification.npfsi.NpfsiEstimator.run>` ends
    on the same data once its initial guess is forgotten, computed without running it.

    With theta frozen, one step of the recursion moves Sigma theta by
    g_k(theta) = A_k' [(1 - phi) e_k + beta (dy_k - b_k - A_k theta)], where
    e_k = eps (1 - phi) sum_{j<k} phi^(k-1-j) (dy_j - b_j - A_j theta) is the state error
    (phi = exp(-h / eps), beta = h - eps (1 - phi), dy the forward difference of the velocity,
    as in ``npfsi.py``). The end point solves sum_k w_k g_k(theta) = 0 with the estimator's
    memory w_k = (k / n)^(1 / (gamma^2 - 1)): with Sigma' = (1 - gamma^-2) A'A growing like t,
    the weight of the data at t in the final estimate grows as Sigma(t)^(1/(gamma^2 - 1)) (exact
    for one parameter and stationary excitation); the initial guess's share decays as
    (Sigma(0) / Sigma(t))^(1 / (1 - gamma^-2)).

    Parameters
    ----------
    regressor : (n, m, p) array
        A at each sample (the acceleration model is velocity' = A theta + b).
    offset : (n, m) array
        b [m/s^2].
    velocity : (n, m) array
        The measured velocities [m/s].
    sample_time : float
        h [s].
    eps : float
        [s] The estimator's eps.
    gamma : float
        Attenuation level (> 1); Q = A'A (002 sidebar).

    Returns
    -------
    (p,) array
        theta at the end point.
    """
    if not (math.isfinite(eps) and eps > 0):
        raise InputError(f"eps must be positive [s], got {eps!r}")
    if not (math.isfinite(gamma) and gamma > 1):
        raise InputError(f"gamma must be > 1, got {gamma!r}")
    if not (math.isfinite(sample_time) and sample_time > 0):
        raise InputError(f"sample_time must be positive [s], got {sample_time!r}")
    A = np.asarray(regressor, dtype=float)
    if A.ndim != 3:
        raise InputError(f"regressor must have shape (n, m, p), got {A.shape}")
    n, m, _ = A.shape
    b = np.asarray(offset, dtype=float).reshape(n, m)
    y = np.asarray(velocity, dtype=float).reshape(n, m)
    h = float(sample_time)
    dy = np.zeros_like(y)
    dy[:-1] = np.diff(y, axis=0) / h
    s = dy - b  # the acceleration the parameters must explain
    phi = math.exp(-h / eps)
    beta = h - eps * (1 - phi)
    c = (1 - phi) ** 2 * eps

    def past(z: np.ndarray) -> np.ndarray:
        """sum_{j<k} phi^(k-1-j) z_j along the samples (strictly causal)."""
        return lfilter([0.0, 1.0], [1.0, -phi], z, axis=0)

    w = (np.arange(n) / n) ** (1.0 / (gamma**2 - 1.0))
    lhs = np.einsum("n,nip,niq->pq", w, A, c * past(A) + beta * A)
    rhs = np.einsum("n,nip,ni->p", w, A, c * past(s) + beta * s)
    return np.linalg.solve(lhs, rhs)


def npfsi_stationary_point(
    log: Log,
    model: StageModel,
    eps: float,
    *,
    estimate: Sequence[str] = CONSTANT_NAMES,
    gamma: float = PAPER_GAMMA,
    differentiator: HighGainDifferentiator | SavitzkyGolay | None = None,
) -> np.ndarray:
    """:func:`stationary_point` of :func:`~maglev_oc.identification.npfsi.npfsi` on a log: the
    constants its run at ``eps`` ends at once the initial guess is forgotten.

    Parameters
    ----------
    log : Log
    model : StageModel
        Geometry and the constants held fixed (those not in ``estimate``).
    eps : float
        [s] The estimator's eps.
    estimate : sequence of str
        Among C1..C4.
    gamma : float
        Attenuation level (> 1).
    differentiator : optional
        The velocities, as in :func:`~maglev_oc.identification.npfsi.npfsi` (default: the
        papers' high-gain observer).

    Returns
    -------
    (len(estimate),) array
        The constants at the end point.
    """
    diff = HighGainDifferentiator(log.sample_time) if differentiator is None else differentiator
    A, b, y, _ = stage_regression(log, model, estimate, diff)
    return stationary_point(A, b, y, log.sample_time, eps, gamma)


# --- runs -----------------------------------------------------------------------------------------
def _papers(table: str, names: Sequence[str]) -> EpsTrend:
    values = [
        [PAPER_CONSTANTS[f"{table}_eps{e:g}"].as_array()[CONSTANT_NAMES.index(k)] for e in PAPER_EPSILONS]
        for k in names
    ]
    label = {"table2": "paper 000, Table II (mover locked at x3 = 0)", "table3": "paper 000, Table III"}
    return EpsTrend(label[table], tuple(names), PAPER_EPSILONS, np.array(values))


def _npfsi_trend(
    source: str, log: Log, model: StageModel, names: Sequence[str], **kw
) -> tuple[EpsTrend, bool]:
    runs = [npfsi(log, model, estimate=names, eps=e, **kw) for e in PAPER_EPSILONS]
    values = np.array([[r.values[k] for r in runs] for k in names])
    return EpsTrend(source, tuple(names), PAPER_EPSILONS, values), all(r.success for r in runs)


def _with_friction(effects: TwinEffects, friction: tuple[GuideFriction | None, GuideFriction | None]):
    return dataclasses.replace(effects, friction_horizontal=friction[0], friction_vertical=friction[1])


def _logs(truth, model, effects_t3, effects_t2, duration, vertical_duration, seed) -> tuple[Log, Log]:
    """The Table III log (60 s sum of sines, both axes) and the Table II one (mover locked at
    x3 = 0, gap about 16 mm), with the identification study's seeds (seed, seed + 1)."""
    t3 = excitation_log(truth, duration=duration, seed=seed, controller_model=model, effects=effects_t3)
    t2 = excitation_log(
        truth,
        duration=vertical_duration,
        seed=seed + 1,
        controller_model=model,
        effects=effects_t2,
        gap_offset=VERTICAL_GAP,
        locked_position=0.0,
    )
    return t3, t2


def _twin_trend(
    model: StageModel,
    friction: tuple[GuideFriction | None, GuideFriction | None] = (None, None),
    *,
    truth_constants: LumpedConstants = TWIN_TRUTH,
    duration: float = 60.0,
    vertical_duration: float = 40.0,
    seed: int = 1,
    label: str = "",
) -> tuple[EpsTrend, EpsTrend, Log, bool]:
    """NPFSI at the papers' three eps on the identification study's twin runs, with friction.

    Parameters
    ----------
    model : StageModel
        The nominal model (controllers, estimator's fixed constants and initial guesses).
    friction : (GuideFriction or None, GuideFriction or None)
        (horizontal, vertical) guide friction added to the study's twin effects.
    truth_constants : LumpedConstants
        The twin's constants.
    duration, vertical_duration : float
        [s] Lengths of the Table III and Table II logs.
    seed : int
        Seed of the Table III log (the Table II log uses seed + 1, as the study does).
    label : str
        Words for the ``source`` of the trends.

    Returns
    -------
    (EpsTrend, EpsTrend, Log, bool)
        Table III trend (C1..C4), Table II trend (C2..C4), the Table III log, and whether every
        estimator run completed.
    """
    _check_friction(friction)
    truth = model.with_constants(truth_constants)
    t3_log, t2_log = _logs(
        truth,
        model,
        _with_friction(identification_effects(), friction),
        _with_friction(verification_effects(), friction),
        duration,
        vertical_duration,
        seed,
    )
    t3, ok3 = _npfsi_trend(f"twin {label}, Table III run".strip(), t3_log, model, CONSTANT_NAMES)
    t2, ok2 = _npfsi_trend(f"twin {label}, Table II run".strip(), t2_log, model, TABLE2_NAMES)
    return t3, t2, t3_log, ok3 and ok2


def _check_friction(friction) -> None:
    if not (isinstance(friction, tuple) and len(friction) == 2):
        raise InputError(f"friction must be a (horizontal, vertical) pair, got {friction!r}")
    for f in friction:
        if f is not None and not isinstance(f, GuideFriction):
            raise TypeError(f"friction entries must be GuideFriction or None, got {type(f).__name__}")


def _limit(source: str, log: Log, model: StageModel) -> EpsTrend:
    values = np.array([npfsi_stationary_point(log, model, e) for e in PAPER_EPSILONS]).T
    return EpsTrend(source, CONSTANT_NAMES, PAPER_EPSILONS, values)


# --- the study ------------------------------------------------------------------------------------
def eps_trend_study(
    model: StageModel,
    *,
    friction: tuple[GuideFriction | None, GuideFriction | None] = RIG_FRICTION,
    truth_constants: LumpedConstants = TWIN_TRUTH,
    duration: float = 60.0,
    vertical_duration: float = 40.0,
    seed: int = 1,
    band: float = FLAT_BAND,
) -> EpsTrendStudy:
    """The eps trend of the NPFSI estimates: the papers', ours, and ours with guide friction.

    Runs the identification study's twin experiments (Table III: 60 s sum of sines on both
    axes; Table II: mover locked at x3 = 0) twice, without and with ``friction``, and applies
    NPFSI (observer velocities, gamma = 1.1) at eps = 0.001, 0.01, 0.05 to each; plus the
    default Table III log with zero-phase velocities and the stationary points of both
    Table III logs. About 25 s on one core.

    Parameters
    ----------
    model : StageModel
        The nominal model (Table III at eps = 0.01: controllers, fixed constants, initial guesses).
    friction : (GuideFriction or None, GuideFriction or None)
        (horizontal, vertical) guide friction of the reversing condition (default: the rig
        twin's, :data:`RIG_FRICTION`).
    truth_constants : LumpedConstants
        The twin's constants (default: the identification study's).
    duration, vertical_duration : float
        [s] Lengths of the Table III and Table II logs (the study's 60 s and 40 s).
    seed : int
        Seed of the Table III logs (Table II: seed + 1), as in the study.
    band : float
        Relative changes below it are called flat (default :data:`FLAT_BAND`).

    Returns
    -------
    EpsTrendStudy
    """
    _check_friction(friction)
    if not (math.isfinite(band) and 0 <= band < 1):
        raise InputError(f"band must be in [0, 1), got {band!r}")
    if not any(f is not None for f in friction):
        raise InputError("friction: give at least one axis's friction (the default run has none)")
    clock: dict[str, float] = {}
    t0 = time.perf_counter()
    common = dict(truth_constants=truth_constants, duration=duration, vertical_duration=vertical_duration)
    d3, d2, d_log, ok_d = _twin_trend(model, (None, None), seed=seed, label="(study's effects)", **common)
    clock["default runs (simulate + NPFSI)"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    f3, f2, f_log, ok_f = _twin_trend(model, friction, seed=seed, label="with guide friction", **common)
    clock["friction runs (simulate + NPFSI)"] = time.perf_counter() - t1
    t1 = time.perf_counter()
    zp, ok_z = _npfsi_trend(
        "twin (study's effects), Table III run, zero-phase velocities",
        d_log,
        model,
        CONSTANT_NAMES,
        differentiator=SavitzkyGolay(d_log.sample_time),
    )
    clock["zero-phase NPFSI"] = time.perf_counter() - t1
    t1 = time.perf_counter()
    lim_d = _limit("stationary point, twin (study's effects), Table III run", d_log, model)
    lim_f = _limit("stationary point, twin with guide friction, Table III run", f_log, model)
    clock["stationary points"] = time.perf_counter() - t1

    p3, p2 = _papers("table3", CONSTANT_NAMES), _papers("table2", TABLE2_NAMES)
    m_h = model.params.mass_horizontal
    damping_rate = f3.slope["C1"] - d3.slope["C1"]
    papers_damping = m_h * (p3.slope["C1"] - d3.slope["C1"])
    observer = HighGainDifferentiator(d_log.sample_time)
    lag = 2 * observer.epsilon + d_log.sample_time
    names = ("horizontal", "vertical")
    fr = {
        axis: {"coulomb_N": f.coulomb, "viscous_N_s_per_m": f.viscous}
        for axis, f in zip(names, friction, strict=True)
        if f is not None
    }
    truth = dict(zip(CONSTANT_NAMES, truth_constants.as_array(), strict=True))
    fields = dict(
        papers_table2=p2,
        papers_table3=p3,
        default_table2=d2,
        default_table3=d3,
        friction_table2=f2,
        friction_table3=f3,
        zero_phase_table3=zp,
        limit_default_table3=lim_d,
        limit_friction_table3=lim_f,
        truth=truth,
        friction=fr,
        observer_lag=lag,
        damping_rate=damping_rate,
        papers_damping=papers_damping,
        band=band,
    )
    text = _explanation(model, friction, observer.epsilon, d_log.sample_time, **fields)
    clock["total"] = time.perf_counter() - t0
    if not (ok_d and ok_f and ok_z):
        success, status, message = False, "failed", "an NPFSI run did not complete (diverged or ill posed)"
    else:
        success = True
        mismatch = []
        for table, (paper, ours) in {"Table II": (p2, f2), "Table III": (p3, f3)}.items():
            dp, do = paper.direction(band), ours.direction(band)
            mismatch += [f"{table} {k} ({do[k]}, papers {dp[k]})" for k in dp if do[k] != dp[k]]
        if mismatch:
            status = "partly_reproduced"
            message = "with guide friction the eps trend differs from the papers' for " + ", ".join(mismatch)
        else:
            status = "reproduced"
            message = "with guide friction every constant of Tables II and III moves with eps the papers' way"
    return EpsTrendStudy(
        success=success, status=status, message=message, explanation=text, timings=clock, **fields
    )


def _pct(x: float) -> str:
    return f"{100 * x:+.1f} %"


def _changes(trend: EpsTrend, names: Sequence[str], band: float) -> str:
    """'C1 -4.3 % (down), C3 ...' for ``names``."""
    d = trend.direction(band)
    return ", ".join(f"{k} {_pct(trend.change[k])} ({d[k]})" for k in names)


def _explanation(
    model: StageModel,
    pair: tuple[GuideFriction | None, GuideFriction | None],
    eps_obs: float,
    h: float,
    **f: Any,
) -> str:
    """The paragraph of :attr:`EpsTrendStudy.explanation`, from the computed numbers only."""
    p3, p2, d3, d2 = (f[k] for k in ("papers_table3", "papers_table2", "default_table3", "default_table2"))
    f3, f2, lim, zp = (
        f[k] for k in ("friction_table3", "friction_table2", "limit_default_table3", "zero_phase_table3")
    )
    band = f["band"]
    e0, e1 = PAPER_EPSILONS[0], PAPER_EPSILONS[-1]
    moving = ("C1", "C3", "C4")
    gap = max(
        abs(lim.values[i, j] / d3.values[i, j] - 1) for i in range(3) for j in range(len(PAPER_EPSILONS))
    )
    c2_ours = max(abs(t.change["C2"]) for t in (d3, d2, f3, f2))
    fh, fv = pair
    words = []
    if fh is not None:
        words.append(f"{fh.coulomb:g} N Coulomb + {fh.viscous:g} N s/m horizontally")
    if fv is not None:
        words.append(f"{fv.coulomb:g} N + {fv.viscous:g} N s/m vertically")
    which = "the rig twin's guide friction" if pair == RIG_FRICTION else "guide friction"
    origin = ", set from the papers' 10 um settling, not from these tables" if pair == RIG_FRICTION else ""
    agree = [
        f"{t} {k}"
        for t, paper, ours in (("Table III", p3, f3), ("Table II", p2, f2))
        for k in moving
        if k in ours.names and ours.direction(band)[k] == paper.direction(band)[k]
    ]
    n_moving = sum(1 for t in (p3, p2) for k in moving if k in t.names)
    verdict = (
        "the papers' direction for all of them"
        if len(agree) == n_moving
        else f"the papers' direction for {', '.join(agree) or 'none of them'}"
    )
    text = (
        f"From eps = {e0:g} to {e1:g} the papers' estimates grow (Table III: {_changes(p3, moving, band)}; "
        f"Table II: {_changes(p2, moving[1:], band)}); ours on the study's twin do not (Table III: "
        f"{_changes(d3, moving, band)}; Table II: {_changes(d2, moving[1:], band)}). eps does not enter the "
        "estimator's Riccati recursion; it is the time constant of the filter through which the acceleration "
        "residual reaches the parameter update, so the estimate converges to the instrumental-variable "
        "solution that correlates the regressors with the residual delayed by about eps (computed directly, "
        f"it matches the recursion's end value within {100 * gap:.2f} % for C1..C3: the initial guess, Q0 "
        "and the transient play no part in Table III). A residual a quarter period behind the acceleration "
        "pulls the estimates down as eps grows, one a quarter period ahead (a force in phase with the "
        "velocity: damping b/M) pushes them up, at a relative rate of about eps (b/M - tau omega^2). On the "
        "twin the only such residual is the lag of the papers' high-gain observer velocity (tau = 2 eps_obs "
        f"+ one sample = {1e3 * (2 * eps_obs + h):.0f} ms); with zero-phase velocities C1 changes by "
        f"{_pct(zp.change['C1'])}. With {which} ({' and '.join(words)}{origin}) the trend is Table III: "
        f"{_changes(f3, moving, band)}; Table II: {_changes(f2, moving[1:], band)}, {verdict}. C2, pinned by "
        "the static balance against gravity that neither the filter nor damping changes, moves by at most "
        f"{100 * c2_ours:.1f} % in any of our runs (papers {_pct(p3.change['C2'])})."
    )
    if fh is not None and f["damping_rate"] > 0:
        m_h = model.params.mass_horizontal
        equivalent = m_h * f["damping_rate"]
        text += (
            f" In this first-order reading, and with our observer's lag, the papers' C1 slope needs about "
            f"{f['papers_damping']:.1f} N s/m of horizontal damping on M_h = {m_h:g} kg, "
            f"{f['papers_damping'] / equivalent:.1f} times the {equivalent:.1f} N s/m this friction acts as."
        )
    return text + (
        " The eps trend of Tables II/III thus measures the rig's damping against its velocity lag; it is not "
        "a property of the estimator."
    )
