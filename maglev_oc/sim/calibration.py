"""Calibrating the rig twin to the papers' step experiments (002 Sec. 7.1, Figs. 9-12; issue 14).

Paper 002 reports, on the hardware: 114 % vertical overshoot at the set-point step at t = 5 s
with the printed gains (Fig. 9; horizontal 43 %, Fig. 10); 40 % and a settling time three times
longer with the retuned K_v (Fig. 11); and the linear output regulator destabilizing the plant on
the large step (0.026, 0, 0, 0) -> (0.018, 0, 0.020, 0) that the FL regulator handles (Fig. 12).
The nominal rig twin (:func:`~maglev_oc.sim.comparison.standard_twins`) gives about 50 % and a
linear regulator that survives. This module finds which effects, of which sizes, the twin needs
for both claims to hold at once. Every figure is a closed-loop simulation on the sampled twin.

1. *Candidates* (:func:`candidate_effects`): each unknown of the twin is a field of
   :class:`TwinParameters` with a plausible limit and the reason for it. The plant constants'
   limits come from the papers' own check, equilibrium currents of the controllers' model within
   5 % of the plant's (002 Fig. 6).
2. *Profiles*: each candidate alone, at its limit and beyond.
3. *Grids*: amplifier bandwidth x C4 and C4 x commutation offset (the effects with leverage),
   in units of their limits, with the retuned K_v at every node: the set of nodes that
   reproduces both claims and the least-squares misfit to all four of the papers' numbers.
4. *Fits*: ``plausible``, every grid effect at its limit in the direction that raises the
   overshoot; ``required``, the reproducing node of least departure (Euclidean, in units of the
   limits), moved by bisection along its ray towards nominal to the edge of the reproducing set.

"Reproduces both" means the overshoot of our step at t = 5 s within :data:`TOLERANCE_PCT` of
114 %, the linear regulator failing on the large step, the FL regulator surviving it and the
sequence up to the end of that step. Failing is the engine's verdict
(:func:`~maglev_oc.sim.engine.run_outcome`): a stopper hit or a diverging state; the fits also
run the linear regulator without the stoppers, to tell a deep first dip from the growing
oscillation of 002 Fig. 12. The linear regulator is
:func:`~maglev_oc.control.linear_regulator.paper_linear_regulator` without the equilibrium
feedforward, the literal reading of "(21)-(24) without using the feedback transformation": with
the feedforward its small-step transient equals the FL regulator's, against 002's "much larger
transient" (:attr:`PaperCalibration.small_step` holds the evidence); the fits run it too.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np
from scipy.optimize import brentq

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.control.gains import PAPER_GAINS
from maglev_oc.control.linear_regulator import paper_linear_regulator
from maglev_oc.control.output_regulator import N_REGULATOR_STATE
from maglev_oc.errors import InputError
from maglev_oc.estimation.high_gain import HighGainObserver
from maglev_oc.model.equilibrium import equilibrium_currents
from maglev_oc.model.parameters import PAPER_CONSTANTS, LumpedConstants
from maglev_oc.model.stage import StageModel
from maglev_oc.numerics import c_compiler
from maglev_oc.results import Result
from maglev_oc.sim.comparison import RIG_CONSTANTS
from maglev_oc.sim.effects import CommutationOffset, TwinEffects
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.metrics import StepMetrics, evaluate
from maglev_oc.sim.parametric_twin import ParametricTwin
from maglev_oc.sim.scenarios import Scenario, SetpointSequence, paper_scenarios
from maglev_oc.sim.twin import RigTwin

__all__ = [
    "DEFAULT_GRIDS",
    "PAPER_STEP_TIME",
    "RATIO_TOLERANCE",
    "TOLERANCE_PCT",
    "Candidate",
    "DifferentiatedVelocity",
    "FitPoint",
    "GridStudy",
    "PaperCalibration",
    "PaperMetrics",
    "PaperTargets",
    "Profile",
    "Trace",
    "TwinParameters",
    "calibrate_to_paper",
    "candidate_effects",
    "paper_metrics",
]

PAPER_STEP_TIME = 5.0
"""[s] The step the papers quote: "overshoot of 114 % at t = 5 s" (002 Fig. 9), 40 % (Fig. 11)."""

TOLERANCE_PCT = 15.0
"""[% points] How close an overshoot must come to a paper's to reproduce it. The set-points of
Figs. 9-11 are not printed and ours (:func:`~maglev_oc.sim.scenarios.paper_scenarios`) are a
choice; the same twin's overshoot differs between the five steps of our sequence by 8 points on
the nominal twin and by 30 points and more where the effects that raise it act, because they
couple each step's horizontal move into the vertical axis (:attr:`FitPoint.step_spread`). A twin
within 15 points of 114 % on our step at t = 5 s is as close as a different step can be expected
to come."""

RATIO_TOLERANCE = 0.5
"""[-] Of the settling-time ratio: 002 says "increases by 200 %", a rounded figure."""

DEFAULT_GRIDS = (
    (("amplifier_bandwidth_hz", (0.0, 1.0, 1.5, 1.85)), ("C4", (0.0, 1.0, 2.0, 3.0))),
    (("C4", (0.0, 1.0, 2.0, 3.0)), ("commutation_offset", (0.0, 1.0, 2.0, 3.0))),
)
"""The grids of :func:`calibrate_to_paper`: pairs of (parameter, departures in units of its
limit). Bandwidth departures are logarithmic: 1000, 100, 32 and 14 Hz."""

_EQUILIBRIUM_BAND = 0.05  # 002 Fig. 6: model and measured equilibrium currents within 5 %
_EQUILIBRIUM_GAPS = np.arange(15.0, 25.01, 0.5) * 1e-3  # [m] where 002 makes that claim
_EQUILIBRIUM_MIN_CURRENT = 1.0  # [A] relative errors only where |u2| >= 1 A (u2 crosses 0 at 24 mm)
_TRACE_RATE = 1e3  # [Hz] sample rate of the stored gap trajectories
_BISECTIONS = 3  # steps of the required fit towards nominal (its scale to 1/8)
_SETTLED = 1e-4  # [m] the papers' accuracy goal: settled means within 0.1 mm


# --- what the papers report ----------------------------------------------------------------------
@dataclass(frozen=True)
class PaperTargets:
    """The papers' numbers the twin is calibrated to (002 Sec. 7.1)."""

    overshoot_v_pct: float  # Fig. 9, step at t = 5 s, printed K_v
    overshoot_h_pct: float  # Fig. 10, largest horizontal overshoot
    retuned_overshoot_v_pct: float  # Fig. 11, step at t = 5 s, retuned K_v
    settling_ratio: float  # Fig. 11: settling to 0.1 mm, retuned over printed
    linear_large_step: str  # Fig. 12
    fl_large_step: str  # Fig. 12
    source: str

    @classmethod
    def from_papers(cls) -> PaperTargets:
        """The numbers of :func:`paper_scenarios` (Fig. 11's: 40 % and a ratio of 3 where the
        scenario does not carry them)."""
        steps = paper_scenarios()["setpoint_steps"].paper
        return cls(
            overshoot_v_pct=float(steps["overshoot_v_pct"]),
            overshoot_h_pct=float(steps["overshoot_h_pct"]),
            retuned_overshoot_v_pct=float(steps.get("retuned_overshoot_v_pct", 40.0)),
            settling_ratio=float(steps.get("retuned_settling_ratio", 3.0)),
            linear_large_step="unstable",
            fl_large_step="stable",
            source="002 Sec. 7.1, Figs. 9-12",
        )


# --- the twin's unknowns ---------------------------------------------------------------------------
@dataclass(frozen=True)
class TwinParameters:
    """The rig twin's unknowns that the calibration varies; every other effect is
    :meth:`TwinEffects.rig`'s. Start from :meth:`nominal`, change fields with ``dataclasses.replace``.

    Attributes
    ----------
    amplifier_bandwidth_hz : float
        [Hz] Current amplifiers' first-order bandwidth.
    input_delay_samples : int
        Computation delay of the loop [samples of 0.2 ms].
    commutation_offset : float
        [rad] Electrical angle error of the d-q transform (:class:`CommutationOffset`).
    C2, C3, C4 : float
        The plant's lumped constants (the controllers keep their model's); C1 is the rig's.
    vertical_friction : float
        [N] Coulomb level of the vertical guides (the rig's Dahl pre-sliding and viscous part).
    cogging_peak : float
        [N] Normal cogging force at 15 mm (growing as gap^-3).
    velocity_differentiation : float
        [s] 0: the controllers' observers, fed the model's acceleration (exact on a matched plant).
        > 0: velocities by differentiating the encoders, a high-gain observer with this epsilon
        fed no acceleration (lag about 2 epsilon).
    """

    amplifier_bandwidth_hz: float
    input_delay_samples: int
    commutation_offset: float
    C2: float
    C3: float
    C4: float
    vertical_friction: float
    cogging_peak: float
    velocity_differentiation: float

    def __post_init__(self) -> None:
        if isinstance(self.input_delay_samples, bool) or not isinstance(self.input_delay_samples, int):
            raise InputError(f"input_delay_samples must be an integer, got {self.input_delay_samples!r}")
        if not (math.isfinite(self.velocity_differentiation) and self.velocity_differentiation >= 0):
            raise InputError(
                f"velocity_differentiation must be >= 0 [s], got {self.velocity_differentiation!r}"
            )
        self.effects()  # the effects and constants validate their own fields
        self.constants()

    @classmethod
    def nominal(cls) -> TwinParameters:
        """The controller comparison's rig twin: :meth:`TwinEffects.rig`, constants
        :data:`~maglev_oc.sim.comparison.RIG_CONSTANTS`."""
        rig = TwinEffects.rig()
        c = PAPER_CONSTANTS[RIG_CONSTANTS]
        return cls(
            amplifier_bandwidth_hz=rig.amplifier.bandwidth_hz,
            input_delay_samples=rig.input_delay_samples,
            commutation_offset=0.0,
            C2=c.C2,
            C3=c.C3,
            C4=c.C4,
            vertical_friction=rig.friction_vertical.coulomb,
            cogging_peak=rig.cogging.peak_at_reference,
            velocity_differentiation=0.0,
        )

    def effects(self) -> TwinEffects:
        """:meth:`TwinEffects.rig` with these sizes."""
        rig = TwinEffects.rig()
        return TwinEffects.rig(
            amplifier=dataclasses.replace(rig.amplifier, bandwidth_hz=self.amplifier_bandwidth_hz),
            input_delay_samples=self.input_delay_samples,
            commutation=CommutationOffset(self.commutation_offset) if self.commutation_offset else None,
            friction_vertical=dataclasses.replace(rig.friction_vertical, coulomb=self.vertical_friction),
            cogging=dataclasses.replace(rig.cogging, peak_at_reference=self.cogging_peak),
        )

    def constants(self) -> LumpedConstants:
        """The plant's lumped constants."""
        return PAPER_CONSTANTS[RIG_CONSTANTS].replace(C2=self.C2, C3=self.C3, C4=self.C4, source="calibrated")

    def twin(self, model: StageModel, *, stoppers: bool = True) -> RigTwin:
        """The twin: ``model``'s geometry with :meth:`constants` and :meth:`effects` (without the
        mechanical stoppers if ``stoppers`` is False)."""
        return RigTwin(*self._plant(model, stoppers))

    def _plant(self, model: StageModel, stoppers: bool) -> tuple[StageModel, TwinEffects]:
        """(true plant, effects) of :meth:`twin`."""
        effects = self.effects() if stoppers else dataclasses.replace(self.effects(), stoppers=None)
        return model.with_constants(self.constants()), effects

    def changes(self) -> dict[str, float]:
        """The fields that differ from :meth:`nominal`."""
        nom = TwinParameters.nominal()
        names = [f.name for f in dataclasses.fields(self)]
        return {n: getattr(self, n) for n in names if getattr(self, n) != getattr(nom, n)}


@dataclass(frozen=True)
class Candidate:
    """An effect the twin may lack: the parameter it sets, its nominal size and plausible limit.

    ``limit`` lies in the direction that raises the vertical overshoot. Sizes are measured by
    their departure, in units of the limit (0 nominal, 1 at the limit; logarithmic for the
    bandwidth); ``screen`` are the departures of the profile.
    """

    name: str
    parameter: str
    unit: str
    nominal: float
    limit: float
    screen: tuple[float, ...]
    reason: str
    log_scale: bool = False

    def __post_init__(self) -> None:
        if self.parameter not in {f.name for f in dataclasses.fields(TwinParameters)}:
            raise InputError(f"Candidate.parameter must be a TwinParameters field, got {self.parameter!r}")
        if self.limit == self.nominal:
            raise InputError(f"Candidate {self.name!r}: the limit equals the nominal size {self.nominal!r}")

    def departure(self, value: float) -> float:
        """``value`` in units of the limit's departure from nominal."""
        if self.log_scale:
            return math.log(self.nominal / value) / math.log(self.nominal / self.limit)
        return (value - self.nominal) / (self.limit - self.nominal)

    def value_at(self, departure: float) -> float:
        """The size at ``departure`` (inverse of :meth:`departure`; whole samples for a delay)."""
        if self.log_scale:
            value = self.nominal * (self.limit / self.nominal) ** departure
        else:
            value = self.nominal + departure * (self.limit - self.nominal)
        return round(value) if self.parameter == "input_delay_samples" else float(value)


def _equilibrium_error(model: StageModel, constants: LumpedConstants) -> float:
    """Largest relative difference of the equilibrium currents of a plant with ``constants`` from
    those of ``model`` over 15-25 mm where |u2| >= 1 A; inf where the plant has no equilibrium."""
    ref = equilibrium_currents(model, _EQUILIBRIUM_GAPS).current
    cur = equilibrium_currents(model.with_constants(constants), _EQUILIBRIUM_GAPS).current
    use = np.abs(ref) >= _EQUILIBRIUM_MIN_CURRENT
    if not np.all(np.isfinite(cur[use])):
        return math.inf
    return float(np.max(np.abs(cur[use] - ref[use]) / np.abs(ref[use])))


def _constant_limit(model: StageModel, name: str, factor: float) -> float:
    """The plant constant ``name``, moved from the rig's towards ``factor`` times it, at which the
    equilibrium currents leave the papers' 5 % band around the model's (002 Fig. 6)."""
    base = TwinParameters.nominal()
    nominal = getattr(base, name)

    def excess(value: float) -> float:
        err = _equilibrium_error(model, dataclasses.replace(base, **{name: value}).constants())
        return min(err, 1.0) - _EQUILIBRIUM_BAND

    far = nominal * factor
    if excess(nominal) >= 0 or excess(far) <= 0:
        raise InputError(f"no 5 % equilibrium limit for {name} between {nominal:g} and {far:g}")
    return float(brentq(excess, nominal, far, xtol=1e-6 * nominal))


def candidate_effects(model: StageModel) -> tuple[Candidate, ...]:
    """The effects screened, with their plausible limits and why.

    Parameters
    ----------
    model : StageModel
        The controllers' model (the plant constants' limits are relative to it).

    Returns
    -------
    tuple of Candidate
    """
    nom = TwinParameters.nominal()
    c2, c3, c4 = (_constant_limit(model, n, f) for n, f in (("C2", 1.2), ("C3", 0.8), ("C4", 6.0)))
    eq = "equilibrium currents within 5 % of the controllers' model (002 Fig. 6)"
    rows = (
        ("current-amplifier bandwidth", "amplifier_bandwidth_hz", "Hz", nom.amplifier_bandwidth_hz, 100.0,
         (1.0, 1.5, 1.85, 1.95), "amplifiers factory tuned to the coils (002 Sec. 4); below 100 Hz a "
         "lag over 1.6 ms, no longer a current source", True),
        ("normal force of the currents (plant C4)", "C4", "m/(s^2 A^2)", nom.C4, c4, (1.0, 2.0, 3.0),
         f"{eq}; C4 also scales the pull of the thrust current, which the FL regulator cancels with "
         "its model's C4 and the linear one not at all", False),
        ("commutation offset", "commutation_offset", "rad", 0.0, -0.1, (1.0, 2.0, 3.0),
         "1.8 mm of encoder-zero error over the 57 mm pole pitch; it also rotates thrust current "
         "into the vertical force and lowers the horizontal overshoot", False),
        ("computation delay", "input_delay_samples", "samples", float(nom.input_delay_samples), 2.0,
         (1.0, 9.0), "the 5 kHz loop reads, computes and writes within two 0.2 ms samples; 10 "
         "samples (2 ms) is the twin's most", False),
        ("velocity by differentiating the encoders", "velocity_differentiation", "s", 0.0, 5e-3,
         (1.0, 2.4), "a high-gain observer slower than 5 ms (poles at -200 1/s, under 4x the "
         "retuned design's -57.9 1/s) is no longer high-gain", False),
        ("vertical guide friction", "vertical_friction", "N", nom.vertical_friction, 1.0, (1.0, 3.0),
         "the papers' rig settles to the encoders' 10 um, which the twin's friction hunting bounds "
         "to about 0.3 N (effects.GuideFriction); 1 N is generous", False),
        ("cogging force", "cogging_peak", "N", nom.cogging_peak, 3.0, (1.0, 3.0),
         "over 1 N below 15 mm and negligible above (000 Sec. V-C); 3 N at 15 mm is twice the "
         "rig twin's", False),
        ("magnet attraction (plant C2)", "C2", "m/(s^2 T^2)", nom.C2, c2, (1.0, 2.0), eq, False),
        ("current force gain (plant C3)", "C3", "m/(s^2 A T)", nom.C3, c3, (1.0, 2.0), eq, False),
    )  # fmt: skip
    return tuple(Candidate(*row) for row in rows)


# --- controllers and runs --------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class DifferentiatedVelocity:
    """``controller`` (an output regulator, state laid out as in
    :mod:`~maglev_oc.control.output_regulator`) with its velocity observers fed no acceleration:
    velocities by differentiating the encoder readings, as a high-gain differentiator does
    (the candidate ``velocity_differentiation``; an ExpressionController).

    Parameters
    ----------
    controller : ExpressionController
        The FL or a linear output regulator.
    epsilon : float
        [s] Observer time constant (poles at -1/epsilon).
    """

    controller: Any
    epsilon: float

    def __post_init__(self) -> None:
        ctrl = self.controller
        if ctrl.n_state != N_REGULATOR_STATE:
            raise InputError(f"{ctrl.name} is not an output regulator ({ctrl.n_state} states)")
        obs = HighGainObserver(ctrl.sample_time, self.epsilon)
        c, y, r = ca.SX.sym("c", ctrl.n_state), ca.SX.sym("y", 2), ca.SX.sym("r", 6)
        u, c_next, diag = ctrl.step(c, y, r)
        c_next = ca.vertcat(obs.step(c[0:2], y[0], 0.0), obs.step(c[2:4], y[1], 0.0), c_next[4:])
        step = ca.Function(
            "differentiated", [c, y, r], [u, c_next, diag], ["c", "y", "r"], ["u", "c_next", "diag"]
        )
        for name, value in (
            ("name", f"{ctrl.name}, differentiated velocity"),
            ("sample_time", ctrl.sample_time),
            ("n_state", ctrl.n_state),
            ("diag_names", ctrl.diag_names),
            ("step", step),
        ):
            object.__setattr__(self, name, value)

    def initial_state(self, y0, r0, u0=None) -> np.ndarray:
        return self.controller.initial_state(y0, r0, u0)


def _controllers(model: StageModel, differentiation: float) -> dict[str, Any]:
    """The four regulators of the calibration, by key."""
    retuned = np.asarray(PAPER_GAINS["K_v_retuned"].printed, dtype=float)
    out = {
        "fl": FeedbackLinearizingRegulator(model),
        "fl_retuned": FeedbackLinearizingRegulator(model, K_v=retuned, name="FL regulator, retuned K_v"),
        "linear": paper_linear_regulator(model, feedforward=False),
        "linear_ff": paper_linear_regulator(model),
    }
    if differentiation > 0:
        out = {k: DifferentiatedVelocity(c, differentiation) for k, c in out.items()}
    return out


def _scenarios() -> dict[str, Scenario]:
    """The papers' scenarios plus the set-point sequence up to the next change after its step at
    :data:`PAPER_STEP_TIME` (``to_papers_step``, the profiles' and grids' cheaper run)."""
    sc = paper_scenarios()
    seq = sc["setpoint_steps"]
    times = seq.reference.times
    if PAPER_STEP_TIME not in times:
        raise InputError(f"the set-point sequence has no step at t = {PAPER_STEP_TIME} s: {times}")
    k = times.index(PAPER_STEP_TIME) + 1
    end = times[k] if k < len(times) else seq.duration
    reference = SetpointSequence(times[:k], seq.reference.setpoints[:k])
    sc["to_papers_step"] = Scenario("to_papers_step", f"{seq.title}, until {end:g} s", seq.x0, reference, end)
    return sc


@dataclass(frozen=True)
class Trace:
    """A gap trajectory for the figures, sampled at 1 kHz.

    ``panel``: ``"papers_step"`` (printed K_v on the set-point sequence), ``"retuned"`` (retuned
    K_v on it) or ``"large_step"``; ``twin``: a :class:`FitPoint` name.
    """

    panel: str
    twin: str
    controller: str
    t: np.ndarray  # (n,) [s]
    gap: np.ndarray  # (n,) [m] true x1
    reference: np.ndarray  # (n,) [m] r_v
    status: str


@dataclass(frozen=True)
class _Run:
    success: bool
    status: str
    steps: tuple[StepMetrics, ...]
    min_gap: float  # [m]
    trace: tuple[np.ndarray, np.ndarray, np.ndarray]  # t, gap, r_v at 1 kHz


_CFLAGS = ("-O1",)
"""Compiler flags of the calibration's loops. When every twin had its own build, compiling
dominated and -O1 took two thirds of -O3's time with the same results; with one build per
controller and loop structure (:class:`_Bench`) the runs dominate, at about the same cost
either way."""


class _Bench:
    """Builds and runs the calibration's closed loops (C backend when a compiler is found), with
    a cache of the runs keyed by (parameters, controller, scenario, stoppers).

    The twins differ in the sizes of :data:`~maglev_oc.sim.parametric_twin.TUNABLE` (constants,
    amplifier bandwidth, commutation offset, vertical Coulomb level, cogging), which a
    :class:`ParametricTwin` carries as state rows: one loop per controller, computation delay and
    stopper setting runs every twin of those (:meth:`ClosedLoop.on`), the same runs to the bit
    as a loop built for each twin. A twin without vertical Coulomb friction gets a loop of its own.
    """

    def __init__(self, model: StageModel) -> None:
        self.model = model
        self.backend = "c" if c_compiler() is not None else "vm"
        self.scenarios = _scenarios()
        self.simulations = 0
        self._controllers: dict[float, dict[str, Any]] = {}
        self._templates: dict[tuple[int, bool], ParametricTwin] = {}
        self._loops: dict[tuple, ClosedLoop] = {}
        self._runs: dict[tuple[TwinParameters, str, str, bool], _Run] = {}

    def controllers(self, differentiation: float) -> dict[str, Any]:
        """The regulators for a velocity estimate, built once."""
        if differentiation not in self._controllers:
            self._controllers[differentiation] = _controllers(self.model, differentiation)
        return self._controllers[differentiation]

    def _loop(self, params: TwinParameters, controller: str, stoppers: bool) -> ClosedLoop:
        """The loop of ``controller`` on the twin ``params``: the shared loop of its structure on
        that twin's plant, or (no vertical Coulomb friction) a loop of its own."""
        ctrl = self.controllers(params.velocity_differentiation)[controller]
        plant, effects = params._plant(self.model, stoppers)
        if params.vertical_friction <= 0:
            return ClosedLoop(RigTwin(plant, effects), ctrl, backend=self.backend, cflags=_CFLAGS)
        shape = (params.input_delay_samples, stoppers)
        if shape not in self._templates:
            self._templates[shape] = ParametricTwin(plant, effects)
        template = self._templates[shape]
        key = (shape, params.velocity_differentiation, controller)
        if key not in self._loops:
            self._loops[key] = ClosedLoop(template, ctrl, backend=self.backend, cflags=_CFLAGS)
        return self._loops[key].on(template.at(plant, effects))

    def run(self, params: TwinParameters, controller: str, scenario: str, *, stoppers: bool = True) -> _Run:
        key = (params, controller, scenario, stoppers)
        if key in self._runs:
            return self._runs[key]
        sc = self.scenarios[scenario]
        res = self._loop(params, controller, stoppers).run(sc)
        self.simulations += 1
        k = max(1, round(1.0 / (_TRACE_RATE * res.sample_time)))
        trace = (res.t[::k], res.x[0, ::k], res.reference[0, ::k])
        out = _Run(res.success, res.status, evaluate(res, sc).steps, float(np.nanmin(res.x[0])), trace)
        self._runs[key] = out
        return out


def _step_at(steps: tuple[StepMetrics, ...], when: float) -> StepMetrics:
    for s in steps:
        if abs(s.time - when) < 1e-9:
            return s
    raise InputError(f"no set-point step at t = {when} s")


# --- the papers' figures on one twin ---------------------------------------------------------------
@dataclass(frozen=True)
class PaperMetrics:
    """The papers' figures on one twin. Overshoots [%] and settling to 0.1 mm [s] are of the step
    at t = 5 s unless stated; NaN or "" for what was not run (``full=False`` of :func:`paper_metrics`).
    Large-step entries are run statuses: ``"completed"`` or how the run failed."""

    overshoot_v_pct: float
    overshoot_v_steps_pct: tuple[float, ...]  # every step run (NaN: under 0.5 mm)
    overshoot_h_pct: float  # the largest over the steps run
    settling_v_s: float
    steps_status: str  # FL regulator on the sequence up to the end of the step at t = 5 s
    linear_large_step: str
    linear_min_gap: float  # [m]
    fl_large_step: str
    fl_min_gap: float  # [m]
    retuned_overshoot_v_pct: float = math.nan
    retuned_settling_v_s: float = math.nan
    sequence_status: str = ""  # FL regulator on all five steps
    linear_ff_large_step: str = ""  # the linear regulator with the equilibrium feedforward
    linear_ff_min_gap: float = math.nan  # [m]
    linear_unstopped: str = ""  # the linear regulator on the large step without the stoppers:
    # "settles" (within 0.1 mm over the last second), "does not settle" or "diverged"
    linear_unstopped_min_gap: float = math.nan  # [m]

    @property
    def settling_ratio(self) -> float:
        """Settling time at t = 5 s, retuned K_v over printed (002 Fig. 11: about 3)."""
        return self.retuned_settling_v_s / self.settling_v_s

    @property
    def outcomes_as_papers(self) -> bool:
        """The linear regulator fails on the large step; the FL regulator survives it and the steps."""
        return (
            self.linear_large_step != "completed"
            and self.fl_large_step == "completed"
            and (self.steps_status == "completed")
        )

    def reproduces(self, targets: PaperTargets, tolerance: float = TOLERANCE_PCT) -> bool:
        """Both claims: the papers' outcomes and the overshoot within ``tolerance`` [% points]."""
        return self.outcomes_as_papers and abs(self.overshoot_v_pct - targets.overshoot_v_pct) <= tolerance


def _metrics(bench: _Bench, params: TwinParameters, *, retuned: bool, full: bool) -> PaperMetrics:
    seq = "setpoint_steps" if full else "to_papers_step"
    printed = bench.run(params, "fl", seq)
    steps = bench.run(params, "fl", "to_papers_step")
    lin, fl = bench.run(params, "linear", "large_step"), bench.run(params, "fl", "large_step")
    s = _step_at(printed.steps, PAPER_STEP_TIME)
    h = [x.overshoot_pct.horizontal for x in printed.steps if not math.isnan(x.overshoot_pct.horizontal)]
    extra: dict[str, Any] = {}
    if retuned:
        r = _step_at(bench.run(params, "fl_retuned", seq).steps, PAPER_STEP_TIME)
        extra.update(
            retuned_overshoot_v_pct=r.overshoot_pct.vertical, retuned_settling_v_s=r.settling_01mm.vertical
        )
    if full:
        ff = bench.run(params, "linear_ff", "large_step")
        free = bench.run(params, "linear", "large_step", stoppers=False)
        t, gap, ref = free.trace
        settles = free.success and bool(np.all(np.abs(gap - ref)[t >= t[-1] - 1.0] < _SETTLED))
        extra.update(
            sequence_status=printed.status,
            linear_ff_large_step=ff.status,
            linear_ff_min_gap=ff.min_gap,
            linear_unstopped="settles" if settles else ("does not settle" if free.success else free.status),
            linear_unstopped_min_gap=free.min_gap,
        )
    return PaperMetrics(
        overshoot_v_pct=s.overshoot_pct.vertical,
        overshoot_v_steps_pct=tuple(x.overshoot_pct.vertical for x in printed.steps),
        overshoot_h_pct=max(h) if h else math.nan,
        settling_v_s=s.settling_01mm.vertical,
        steps_status=steps.status,
        linear_large_step=lin.status,
        linear_min_gap=lin.min_gap,
        fl_large_step=fl.status,
        fl_min_gap=fl.min_gap,
        **extra,
    )


def paper_metrics(
    model: StageModel, params: TwinParameters, *, retuned: bool = True, full: bool = False
) -> PaperMetrics:
    """The papers' figures on the twin ``params`` (one-off; three to eight short simulations).

    Parameters
    ----------
    model : StageModel
        The controllers' model.
    params : TwinParameters
        The twin.
    retuned : bool
        Also run the retuned K_v (002 Fig. 11).
    full : bool
        Run the whole five-step sequence (else up to the end of the step at t = 5 s), and the
        linear regulator with the equilibrium feedforward and without the stoppers too.

    Returns
    -------
    PaperMetrics
    """
    return _metrics(_Bench(model), params, retuned=retuned, full=full)


# --- the studies -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Profile:
    """One candidate alone: sizes (nominal first), their departures and the figures at each."""

    candidate: Candidate
    values: np.ndarray  # (n,)
    departures: np.ndarray  # (n,)
    metrics: tuple[PaperMetrics, ...]

    @property
    def overshoot_v(self) -> np.ndarray:
        return np.array([m.overshoot_v_pct for m in self.metrics])


@dataclass(frozen=True)
class GridStudy:
    """Two candidates on a grid of departures, every node with the retuned K_v.

    Arrays are (n_first, n_second). ``reproduces``: both claims (:meth:`PaperMetrics.reproduces`).
    ``misfit``: sum of squared standardized residuals to the papers' four numbers (the vertical
    and horizontal overshoots and the retuned one over :data:`TOLERANCE_PCT`, the settling ratio
    over :data:`RATIO_TOLERANCE`), NaN where the outcomes differ from the papers'.
    """

    parameters: tuple[str, str]
    departures: tuple[np.ndarray, np.ndarray]
    values: tuple[np.ndarray, np.ndarray]
    metrics: tuple[tuple[PaperMetrics, ...], ...] = field(repr=False)
    overshoot_v: np.ndarray
    overshoot_h: np.ndarray
    retuned_overshoot_v: np.ndarray
    settling_ratio: np.ndarray
    linear_fails: np.ndarray
    fl_survives: np.ndarray  # the large step, and the sequence to the end of the step at t = 5 s
    reproduces: np.ndarray
    misfit: np.ndarray

    def best_misfit(self) -> tuple[int, int] | None:
        """Node of least misfit (None if no node has the papers' outcomes)."""
        if not np.any(np.isfinite(self.misfit)):
            return None
        i, j = np.unravel_index(np.nanargmin(self.misfit), self.misfit.shape)
        return int(i), int(j)

    def reproducing_ranges(self) -> dict[str, tuple[float, float]]:
        """Per parameter, the (smallest, largest) size over the reproducing nodes (NaN if none)."""
        i, j = np.nonzero(self.reproduces)
        out = {}
        for k, idx in enumerate((i, j)):
            v = self.values[k][idx]
            out[self.parameters[k]] = (float(v.min()), float(v.max())) if v.size else (math.nan, math.nan)
        return out


@dataclass(frozen=True)
class FitPoint:
    """A twin of the calibration: parameters, departures from nominal in units of the limits
    (those that differ), the papers' figures from the full runs, and the verdicts.

    ``step_spread`` is half the range of the printed-K_v overshoots over the sequence's steps
    [% points]: how much our choice of set-points moves the figure (see :data:`TOLERANCE_PCT`).
    ``bisection`` lists (scale along the ray, reproduces) of the required fit's steps.
    """

    name: str
    parameters: TwinParameters
    departures: dict[str, float]
    metrics: PaperMetrics
    reproduces: bool
    plausible: bool
    step_spread: float
    bisection: tuple[tuple[float, bool], ...] = ()


@dataclass(frozen=True)
class PaperCalibration(Result):
    """What the twin needs to reproduce 002's step experiments (module docstring).

    ``success`` is True when a twin inside every plausible limit reproduces both the 114 %
    overshoot and the large-step outcomes. ``status``: ``"reproduced"`` (so), ``"implausible_only"``
    (only twins outside the limits do: ``required``) or ``"not_reproduced"`` (no twin of the
    grids does). A False is a finding about the twin and the papers, not an error.
    """

    success: bool
    status: str
    message: str
    targets: PaperTargets
    tolerance_pct: float
    candidates: tuple[Candidate, ...]
    profiles: tuple[Profile, ...] = field(repr=False)
    grids: tuple[GridStudy, ...] = field(repr=False)
    nominal: FitPoint
    plausible: FitPoint
    required: FitPoint | None
    small_step: Mapping[str, tuple[float, float]]  # controller -> (overshoot [%], settling [s]), nominal twin
    traces: tuple[Trace, ...] = field(repr=False)
    simulations: int = 0
    timings: Mapping[str, float] = field(default_factory=dict)

    def fits(self) -> tuple[FitPoint, ...]:
        return tuple(f for f in (self.nominal, self.plausible, self.required) if f is not None)

    def trace(self, panel: str, twin: str, controller: str) -> Trace:
        """The trace of ``controller`` (its name) on the fit ``twin`` in ``panel`` (:class:`Trace`)."""
        for tr in self.traces:
            if (tr.panel, tr.twin, tr.controller) == (panel, twin, controller):
                return tr
        raise KeyError(f"no trace {(panel, twin, controller)}")

    def report(self) -> str:
        """The fits against the papers' numbers, the profiles and the grids, as text."""
        tg, fits = self.targets, self.fits()
        lines = [
            f"PaperCalibration: {'success' if self.success else 'failure'} ({self.status}): {self.message}"
        ]
        lines.append(f"    {'':34s}{'papers':>10s}" + "".join(f"{f.name:>13s}" for f in fits))
        rows = (
            ("overshoot at t = 5 s [%]", f"{tg.overshoot_v_pct:.0f}", "{:.0f}", lambda m: m.overshoot_v_pct),
            ("largest over the five steps [%]", "", "{:.0f}", lambda m: np.nanmax(m.overshoot_v_steps_pct)),
            ("horizontal overshoot [%]", f"{tg.overshoot_h_pct:.0f}", "{:.0f}", lambda m: m.overshoot_h_pct),
            ("retuned K_v overshoot [%]", f"{tg.retuned_overshoot_v_pct:.0f}", "{:.0f}",
             lambda m: m.retuned_overshoot_v_pct),
            ("settling ratio retuned/printed", f"{tg.settling_ratio:.1f}", "{:.2f}",
             lambda m: m.settling_ratio),
            ("linear regulator, large step", tg.linear_large_step, "{}", lambda m: m.linear_large_step),
            ("  its smallest gap [mm]", "", "{:.1f}", lambda m: 1e3 * m.linear_min_gap),
            ("  without stoppers", "", "{}", lambda m: m.linear_unstopped),
            ("  its smallest gap then [mm]", "", "{:.1f}", lambda m: 1e3 * m.linear_unstopped_min_gap),
            ("FL regulator, large step", tg.fl_large_step, "{}", lambda m: m.fl_large_step),
            ("  its smallest gap [mm]", "", "{:.1f}", lambda m: 1e3 * m.fl_min_gap),
            ("FL regulator, steps to t = 10 s", "stable", "{}", lambda m: m.steps_status),
            ("FL regulator, all five steps", "stable", "{}", lambda m: m.sequence_status),
            ("linear with feedforward, large", "", "{}", lambda m: m.linear_ff_large_step),
        )  # fmt: skip
        for label, paper, fmt, get in rows:
            lines.append(
                f"    {label:34s}{paper:>10s}" + "".join(f"{fmt.format(get(f.metrics)):>13s}" for f in fits)
            )
        for f in fits:
            dep = ", ".join(f"{k} {v:.2f}" for k, v in f.departures.items()) or "none"
            lines.append(f"    {f.name}: {f.parameters.changes() or 'nominal'}; departures {dep}")
        small = "; ".join(f"{k} {o:.0f} %, {t:.2f} s" for k, (o, t) in self.small_step.items())
        lines.append(f"    small step on the nominal twin (overshoot, settling): {small}")
        lines.append("    profiles, overshoot at t = 5 s [%] by size (L linear fails, F FL fails):")
        for p in self.profiles:
            cells = ", ".join(
                f"{v:.4g}: {m.overshoot_v_pct:.0f}" + ("L" if m.linear_large_step != "completed" else "")
                + ("" if m.fl_large_step == m.steps_status == "completed" else "F")
                for v, m in zip(p.values, p.metrics, strict=True)
            )  # fmt: skip
            lines.append(f"      {p.candidate.name} [{p.candidate.unit}]: {cells}")
        for g in self.grids:
            lines.append(
                f"    grid {g.parameters[0]} (rows) x {g.parameters[1]} (columns): overshoot at t = 5 s"
            )
            lines.append("      [%] / retuned [%], * reproduces both, - outcomes differ from the papers'")
            for i, v in enumerate(g.values[0]):
                cells = " ".join(
                    f"{g.overshoot_v[i, j]:4.0f}/{g.retuned_overshoot_v[i, j]:3.0f}"
                    + ("*" if g.reproduces[i, j] else " " if np.isfinite(g.misfit[i, j]) else "-")
                    for j in range(g.values[1].size)
                )
                lines.append(f"      {v:9.4g} | {cells}")
            lines.append("      columns: " + ", ".join(f"{v:.3g}" for v in g.values[1]))
        ratio = np.concatenate([(g.overshoot_v / g.retuned_overshoot_v).ravel() for g in self.grids])
        lines.append(
            f"    overshoot at t = 5 s, printed over retuned K_v: papers "
            f"{tg.overshoot_v_pct / tg.retuned_overshoot_v_pct:.2f}; grid nodes "
            f"{np.nanmin(ratio):.2f}-{np.nanmax(ratio):.2f}; fits "
            + ", ".join(f"{f.metrics.overshoot_v_pct / f.metrics.retuned_overshoot_v_pct:.2f}" for f in fits)
        )
        lines.append(f"    simulations {self.simulations}")
        lines.append("    timings [s]: " + ", ".join(f"{k} {v:.1f}" for k, v in self.timings.items()))
        return "\n".join(lines)


def _profile(bench: _Bench, cand: Candidate) -> Profile:
    nominal = TwinParameters.nominal()
    values = [cand.value_at(d) for d in (0.0, *cand.screen)]
    metrics = tuple(
        _metrics(bench, dataclasses.replace(nominal, **{cand.parameter: v}), retuned=False, full=False)
        for v in values
    )
    deps = np.array([cand.departure(v) for v in values])
    return Profile(cand, np.array(values, dtype=float), deps, metrics)


def _grid(bench: _Bench, axes, targets: PaperTargets, tolerance: float) -> GridStudy:
    (ca_, da), (cb, db) = axes
    nominal = TwinParameters.nominal()
    va, vb = np.array([ca_.value_at(d) for d in da]), np.array([cb.value_at(d) for d in db])
    mets = tuple(
        tuple(
            _metrics(
                bench,
                dataclasses.replace(nominal, **{ca_.parameter: a, cb.parameter: b}),
                retuned=True,
                full=False,
            )
            for b in vb
        )
        for a in va
    )

    def arr(get) -> np.ndarray:
        return np.array([[get(m) for m in row] for row in mets])

    ov, oh = arr(lambda m: m.overshoot_v_pct), arr(lambda m: m.overshoot_h_pct)
    ret, ratio = arr(lambda m: m.retuned_overshoot_v_pct), arr(lambda m: m.settling_ratio)
    outcomes = arr(lambda m: m.outcomes_as_papers).astype(bool)
    misfit = (
        ((ov - targets.overshoot_v_pct) / TOLERANCE_PCT) ** 2
        + ((oh - targets.overshoot_h_pct) / TOLERANCE_PCT) ** 2
        + ((ret - targets.retuned_overshoot_v_pct) / TOLERANCE_PCT) ** 2
        + ((ratio - targets.settling_ratio) / RATIO_TOLERANCE) ** 2
    )
    return GridStudy(
        parameters=(ca_.parameter, cb.parameter),
        departures=(np.asarray(da, dtype=float), np.asarray(db, dtype=float)),
        values=(va, vb),
        metrics=mets,
        overshoot_v=ov,
        overshoot_h=oh,
        retuned_overshoot_v=ret,
        settling_ratio=ratio,
        linear_fails=arr(lambda m: m.linear_large_step != "completed").astype(bool),
        fl_survives=arr(lambda m: m.fl_large_step == m.steps_status == "completed").astype(bool),
        reproduces=arr(lambda m: m.reproduces(targets, tolerance)).astype(bool),
        misfit=np.where(outcomes, misfit, np.nan),
    )


def _required(bench, grids, by_name, targets, tolerance) -> tuple[TwinParameters, tuple] | None:
    """The reproducing grid node of least departure norm, moved along its ray towards nominal by
    bisection to the edge of the reproducing set; None if no node reproduces."""
    best = None
    for g in grids:
        for i, j in zip(*np.nonzero(g.reproduces), strict=True):
            deps = {g.parameters[0]: g.departures[0][i], g.parameters[1]: g.departures[1][j]}
            norm = math.hypot(*deps.values())
            if best is None or norm < best[0]:
                best = (norm, deps)
    if best is None:
        return None
    nominal, deps = TwinParameters.nominal(), best[1]

    def at(scale: float) -> TwinParameters:
        return dataclasses.replace(nominal, **{k: by_name[k].value_at(scale * d) for k, d in deps.items()})

    lo, hi, steps = 0.0, 1.0, []
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        ok = _metrics(bench, at(mid), retuned=False, full=False).reproduces(targets, tolerance)
        steps.append((mid, ok))
        lo, hi = (lo, mid) if ok else (mid, hi)
    return at(hi), tuple(steps)


def _fit(bench, name, params, by_name, targets, tolerance, bisection=()) -> tuple[FitPoint, list[Trace]]:
    metrics = _metrics(bench, params, retuned=True, full=True)
    deps = {k: by_name[k].departure(v) for k, v in params.changes().items() if k in by_name}
    steps = [v for v in metrics.overshoot_v_steps_pct if not math.isnan(v)]
    fit = FitPoint(
        name=name,
        parameters=params,
        departures=deps,
        metrics=metrics,
        reproduces=metrics.reproduces(targets, tolerance),
        plausible=all(d <= 1.0 + 1e-9 for d in deps.values()),
        step_spread=(max(steps) - min(steps)) / 2 if steps else math.nan,
        bisection=bisection,
    )
    names = {k: c.name for k, c in bench.controllers(params.velocity_differentiation).items()}
    traces = []
    for panel, ctrl, sc in (
        ("papers_step", "fl", "setpoint_steps"),
        ("retuned", "fl_retuned", "setpoint_steps"),
        ("large_step", "fl", "large_step"),
        ("large_step", "linear", "large_step"),
        ("large_step", "linear_ff", "large_step"),
    ):
        run = bench.run(params, ctrl, sc)
        traces.append(Trace(panel, name, names[ctrl], *run.trace, run.status))
    return fit, traces


def calibrate_to_paper(
    model: StageModel, *, grids=DEFAULT_GRIDS, tolerance_pct: float = TOLERANCE_PCT
) -> PaperCalibration:
    """Which effects, of which sizes, make the rig twin reproduce 002's 114 % vertical overshoot
    and the linear regulator's failure on the large step at the same time (module docstring).

    Parameters
    ----------
    model : StageModel
        The controllers' model (Table III at eps = 0.01 by default).
    grids : sequence of ((str, sequence of float), (str, sequence of float))
        The grids: two (parameter, departures) pairs each; departures start at 0 and increase
        (:data:`DEFAULT_GRIDS`).
    tolerance_pct : float
        [% points] How close to 114 % reproduces it (:data:`TOLERANCE_PCT`).

    Returns
    -------
    PaperCalibration
    """
    if not (math.isfinite(tolerance_pct) and tolerance_pct > 0):
        raise InputError(f"tolerance_pct must be positive, got {tolerance_pct!r}")
    t_start, cpu_start = time.perf_counter(), _cpu_seconds()
    timings: dict[str, float] = {}
    targets = PaperTargets.from_papers()
    bench = _Bench(model)
    candidates = candidate_effects(model)
    by_name = {c.parameter: c for c in candidates}
    axes = []
    for pair in grids:
        if len(pair) != 2:
            raise InputError(f"a grid is two (parameter, departures) pairs, got {pair!r}")
        for parameter, deps in pair:
            d = np.asarray(deps, dtype=float)
            if parameter not in by_name or d.ndim != 1 or d.size < 2 or d[0] != 0 or np.any(np.diff(d) <= 0):
                raise InputError(
                    f"grid axis must be a candidate and departures from 0 up, got {parameter!r}: {deps!r}"
                )
        axes.append(tuple((by_name[p], tuple(float(x) for x in d)) for p, d in pair))
    timings["limits"] = time.perf_counter() - t_start

    t0 = time.perf_counter()
    grid_studies = tuple(_grid(bench, ax, targets, tolerance_pct) for ax in axes)
    timings["grids"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    profiles = tuple(_profile(bench, c) for c in candidates)
    timings["profiles"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    nominal = TwinParameters.nominal()
    on_grids = {c.parameter: c.limit for ax in axes for c, _ in ax}
    fits, traces = {}, []
    for name, params in (("nominal", nominal), ("plausible", dataclasses.replace(nominal, **on_grids))):
        fits[name], tr = _fit(bench, name, params, by_name, targets, tolerance_pct)
        traces += tr
    found = _required(bench, grid_studies, by_name, targets, tolerance_pct)
    if found is not None:
        fits["required"], tr = _fit(bench, "required", found[0], by_name, targets, tolerance_pct, found[1])
        traces += tr
    small = {}
    for key in ("fl", "linear_ff", "linear"):
        s = bench.run(nominal, key, "small_step").steps[0]
        small[bench.controllers(0.0)[key].name] = (s.overshoot_pct.vertical, s.settling_01mm.vertical)
    timings["fits"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_start
    timings["cpu"] = _cpu_seconds() - cpu_start

    success, status, message = _verdict(fits["plausible"], fits.get("required"), targets, tolerance_pct)
    return PaperCalibration(
        success=success,
        status=status,
        message=message,
        targets=targets,
        tolerance_pct=float(tolerance_pct),
        candidates=candidates,
        profiles=profiles,
        grids=grid_studies,
        nominal=fits["nominal"],
        plausible=fits["plausible"],
        required=fits.get("required"),
        small_step=small,
        traces=tuple(traces),
        simulations=bench.simulations,
        timings=timings,
    )


def _cpu_seconds() -> float:
    """CPU time of this process and its finished children (the C compiler) [s]: the calibration's
    cost on one core, whatever else the machine runs."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _verdict(plausible: FitPoint, required: FitPoint | None, targets: PaperTargets, tol: float):
    """(success, status, message) from the plausible and the required fits."""
    pm = plausible.metrics
    if plausible.reproduces or (required is not None and required.reproduces and required.plausible):
        fit = plausible if plausible.reproduces else required
        return (
            True,
            "reproduced",
            (
                f"a twin inside every plausible limit reproduces both claims: "
                f"{fit.metrics.overshoot_v_pct:.0f} % at t = 5 s, the linear regulator failing on the "
                "large step and the FL regulator not"
            ),
        )
    inside = (
        f"inside the plausible limits the overshoot at t = 5 s reaches {pm.overshoot_v_pct:.0f} % "
        f"(papers {targets.overshoot_v_pct:.0f} %) and the linear regulator "
        + ("fails" if pm.linear_large_step != "completed" else "survives")
    )
    if required is not None and required.reproduces:
        worst = max(required.departures.values())
        return (
            False,
            "implausible_only",
            (
                f"{inside}; {required.metrics.overshoot_v_pct:.0f} % with the linear regulator failing needs "
                f"effects up to {worst:.1f} times their limits"
            ),
        )
    return (
        False,
        "not_reproduced",
        (
            f"{inside}; no twin of the grids reproduces {targets.overshoot_v_pct:.0f} % within "
            f"{tol:.0f} points with the papers' large-step outcomes"
        ),
    )
