"""Twin experiments for identification and for the papers' verification procedures.

Each function runs the rig twin (:mod:`maglev_oc.sim`) the way the papers ran the rig and
returns what the rig would record: a :class:`~maglev_oc.data.logs.Log` of encoder readings and
commanded currents at 1 kHz. The identification and verification code never sees the twin's
true constants; the callers (tests, the report) compare against them.

* :func:`excitation_log` — the PID regulators tracking sum-of-sines references (000 Sec. IV),
  optionally with the mover locked horizontally (vertical-only runs of Tables II and the
  cogging procedure, 000 Sec. V-B/C).
* :func:`fixed_gap_logs` — the gap locked by the hardware, the mover started at rest near
  x3 = -50 mm, a constant u1 = -0.5 A (000 Sec. V-A, 002 Sec. 5.1).
* :func:`equilibrium_current_runs` — the mover locked horizontally, the gap held at set-points
  by the vertical PID; the current at rest is the measured equilibrium current (000 Sec. V-B).

Twin effects for identification: the encoders (10 um quantization plus 2 um noise) and the
current amplifiers (1 kHz lag, limits) by default; :func:`verification_effects` adds cogging.

The excitation runs of :data:`COMPILED_RUN` seconds or more run their closed loop as generated C
where a C compiler is found (:mod:`maglev_oc.sim.native`), the shorter ones and every run without
a compiler in CasADi's virtual machine: the same operations, and the same logs to the bit
(compared on x86-64 for the eps-trend study's four runs, with and without guide friction, mover
free and locked), a quarter of the CPU (the four, 200 s of twin time: 4.0 -> 1.0 s, compilation
included).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np

from maglev_oc.control.pid import paper_pid
from maglev_oc.data.logs import Log
from maglev_oc.errors import SolverError
from maglev_oc.model.parameters import DEFAULT_CONSTANTS, LumpedConstants
from maglev_oc.model.stage import StageModel
from maglev_oc.numerics import c_compiler
from maglev_oc.sim.effects import Cogging, CurrentAmplifier, Encoder, TwinEffects
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.recording import result_to_log
from maglev_oc.sim.scenarios import Scenario, SetpointSequence, Sinusoids, excitation_scenario
from maglev_oc.sim.twin import RigTwin
from maglev_oc.units import MM_TO_M

__all__ = [
    "COMPILED_RUN",
    "EQUILIBRIUM_GAPS",
    "FIXED_GAPS",
    "LOG_RATE_HZ",
    "TWIN_TRUTH",
    "ConstantCurrent",
    "EquilibriumMeasurement",
    "equilibrium_current_runs",
    "excitation_log",
    "fixed_gap_logs",
    "identification_effects",
    "verification_effects",
]

LOG_RATE_HZ = 1000.0
"""Logging rate of the twin experiments [Hz] (the loop runs at 5 kHz)."""
COMPILED_RUN = 10.0
"""[s] Excitation runs this long or longer run as generated C (module docstring): compiling a
loop costs about what 10 s of twin time cost in the virtual machine (0.2 s of CPU; 20 ms per
simulated second in the VM, 1-2 ms in C)."""

TWIN_TRUTH = LumpedConstants(
    DEFAULT_CONSTANTS.C1 * 1.03,
    DEFAULT_CONSTANTS.C2 * 0.98,
    DEFAULT_CONSTANTS.C3 * 1.03,
    DEFAULT_CONSTANTS.C4 * 1.15,
    source="twin truth: Table III (eps = 0.01) times (1.03, 0.98, 1.03, 1.15)",
)
"""The twin's true constants in the identification experiments: the papers' values perturbed,
so that a fit that stays at its initial guess (the papers' values) is visibly wrong."""

FIXED_GAPS = tuple(round(g, 4) * MM_TO_M for g in np.arange(10.0, 27.51, 2.5))
"""Gaps of the parabola experiments: 10-27.5 mm in 2.5 mm steps (000 Sec. V-A)."""
EQUILIBRIUM_GAPS = tuple(float(g) * MM_TO_M for g in range(10, 26))
"""Gaps of the equilibrium-current experiments: 10-25 mm in 1 mm steps (000 Sec. V-B)."""


def identification_effects() -> TwinEffects:
    """Encoders (10 um, 2 um noise) and amplifiers (1 kHz, 7/9 A); nothing else."""
    return TwinEffects(encoder=Encoder(), amplifier=CurrentAmplifier())


def verification_effects() -> TwinEffects:
    """:func:`identification_effects` plus the rig's cogging (1.5 N at 15 mm, (15 mm / x1)^3,
    000 eq. (9)), which vanishes at x3 = 0 and peaks at x3 = 3 t1 / 2."""
    return dataclasses.replace(identification_effects(), cogging=Cogging())


def _run(twin: RigTwin, controller, scenario: Scenario, seed: int, backend: str = "vm"):
    result = ClosedLoop(twin, controller, backend=backend).run(scenario, seed=seed)
    if not result.success:
        raise SolverError(f"twin experiment {scenario.name!r} failed: {result.message}")
    return result


def excitation_log(
    truth: StageModel,
    *,
    duration: float = 60.0,
    seed: int = 0,
    effects: TwinEffects | None = None,
    controller_model: StageModel | None = None,
    gap_offset: float = 20 * MM_TO_M,
    locked_position: float | None = None,
    design_gap: float | None = None,
) -> Log:
    """A sum-of-sines identification run (000 Sec. IV) logged at 1 kHz.

    Parameters
    ----------
    truth : StageModel
        The twin's plant.
    duration : float
        [s] (papers' style: 60 s).
    seed : int
        Phases of the sines and the encoder noise.
    effects : TwinEffects
        Default :func:`identification_effects`.
    controller_model : StageModel
        What the PIDs are designed on (default: ``truth``).
    gap_offset : float
        [m] Centre of the gap reference.
    locked_position : float, optional
        [m] Lock the mover horizontally there (vertical-only run); the horizontal reference is
        then that position (no horizontal sines).
    design_gap : float, optional
        [m] Gap the PIDs are placed at (default ``gap_offset``).
    """
    effects = identification_effects() if effects is None else effects
    base = excitation_scenario(duration, seed=seed, gap_offset=gap_offset)
    if locked_position is not None:
        effects = effects.locked(position=locked_position)
        ref = base.reference
        assert isinstance(ref, Sinusoids)
        ref = dataclasses.replace(ref, horizontal=(), horizontal_offset=locked_position)
        base = dataclasses.replace(
            base,
            name="excitation_vertical",
            title=f"Vertical sum of sines, mover locked at x3 = {locked_position * 1e3:g} mm",
            reference=ref,
            x0=(gap_offset, 0.0, locked_position, 0.0),
        )
    design = gap_offset if design_gap is None else design_gap
    controller = paper_pid(truth if controller_model is None else controller_model, design_gap=design)
    backend = "c" if duration >= COMPILED_RUN and c_compiler() is not None else "vm"
    result = _run(RigTwin(truth, effects), controller, base, seed, backend)
    name = "excitation" if locked_position is None else f"excitation_x3_{locked_position * 1e3:.3f}mm"
    log = result_to_log(result, rate_hz=LOG_RATE_HZ, metadata={"experiment": name, "seed": str(seed)})
    return dataclasses.replace(log, source=f"twin:{name}:seed{seed}")


# --- constant currents (open loop) ----------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ConstantCurrent:
    """An ExpressionController that commands a constant (i_q, i_d) [A] whatever it measures."""

    current: tuple[float, float]
    sample_time: float = 2e-4
    name: str = "constant current"
    n_state: int = 1
    diag_names: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        c, y, r = ca.SX.sym("c", 1), ca.SX.sym("y", 2), ca.SX.sym("r", 6)
        u = ca.DM(list(self.current))
        step = ca.Function(
            "constant_step", [c, y, r], [u, c, ca.SX(0, 1)], ["c", "y", "r"], ["u", "c_next", "diag"]
        )
        object.__setattr__(self, "step", step)

    def initial_state(self, y0, r0, u0=(0.0, 0.0)) -> np.ndarray:
        return np.zeros(1)


def fixed_gap_logs(
    truth: StageModel,
    gaps: Sequence[float] = FIXED_GAPS,
    *,
    current: float = -0.5,
    start: float = -50 * MM_TO_M,
    stop: float = 50 * MM_TO_M,
    effects: TwinEffects | None = None,
    seed: int = 0,
) -> list[Log]:
    """The horizontal verification runs (000 Sec. V-A): gap locked at each of ``gaps``, mover at
    rest at ``start``, u1 = ``current`` (u2 = 0); logged until the mover passes ``stop``."""
    effects = identification_effects() if effects is None else effects
    controller = ConstantCurrent((current, 0.0))
    logs = []
    for k, gap in enumerate(gaps):
        twin = RigTwin(truth, effects.locked(gap=gap))
        L1 = float(truth.coefficients([gap])[0, 0])
        accel = abs(L1 * current)
        duration = 1.15 * math.sqrt(2 * (stop - start) / accel)
        # stop early enough for the stoppers (60 mm) to be out of reach
        scenario = Scenario(
            "fixed_gap",
            f"u1 = {current:g} A at a locked gap of {gap * 1e3:g} mm",
            (gap, 0.0, start, 0.0),
            SetpointSequence((0.0,), ((gap, start),)),
            duration,
        )
        result = ClosedLoop(twin, controller).run(scenario, seed=seed + k)
        log = result_to_log(
            result, rate_hz=LOG_RATE_HZ, metadata={"experiment": "fixed_gap", "gap_m": f"{gap:g}"}
        )
        inside = np.flatnonzero(log.x[2] > stop)
        end = int(inside[0]) if inside.size else log.n
        log = log.index_slice(0, end)
        logs.append(dataclasses.replace(log, source=f"twin:fixed_gap_{gap * 1e3:g}mm"))
    return logs


# --- equilibrium currents ---------------------------------------------------------------------
@dataclass(frozen=True)
class EquilibriumMeasurement:
    """Measured equilibrium currents: the mean commanded i_d at rest at each gap.

    Attributes
    ----------
    gap : (k,) array [m] set-points
    position : float [m] where the mover was locked
    current : (k,) array [A] mean u2 over the last ``window`` seconds of each hold
    current_std : (k,) array [A]
    measured_gap : (k,) array [m] mean encoder reading over the same window
    """

    gap: np.ndarray
    position: float
    current: np.ndarray
    current_std: np.ndarray
    measured_gap: np.ndarray


def equilibrium_current_runs(
    truth: StageModel,
    gaps: Sequence[float] = EQUILIBRIUM_GAPS,
    *,
    position: float = 0.0,
    effects: TwinEffects | None = None,
    controller_model: StageModel | None = None,
    hold: float = 1.5,
    window: float = 0.5,
    seed: int = 0,
) -> EquilibriumMeasurement:
    """The vertical verification runs (000 Sec. V-B): mover locked at ``position``, u1 = 0 in
    effect (horizontal reference at the lock), the vertical PID holding each gap for ``hold``
    seconds; the current is averaged over the last ``window`` seconds of each hold.

    The PIDs are placed at each set-point (one short run per gap), as one would retune them
    on the rig: a PID placed at 20 mm loses its margin near 10 mm where the open-loop pole is
    twice as fast.
    """
    effects = (identification_effects() if effects is None else effects).locked(position=position)
    twin = RigTwin(truth, effects)
    ctrl_model = truth if controller_model is None else controller_model
    current, spread, measured = [], [], []
    for k, gap in enumerate(gaps):
        controller = paper_pid(ctrl_model, design_gap=gap)
        scenario = Scenario(
            "equilibrium",
            f"hold {gap * 1e3:g} mm at x3 = {position * 1e3:g} mm",
            (gap, 0.0, position, 0.0),
            SetpointSequence((0.0,), ((gap, position),)),
            hold,
        )
        result = _run(twin, controller, scenario, seed + k)
        tail = result.t >= hold - window
        current.append(float(np.mean(result.u[1, tail])))
        spread.append(float(np.std(result.u[1, tail])))
        measured.append(float(np.mean(result.y[0, tail])))
    return EquilibriumMeasurement(
        np.asarray(gaps, dtype=float),
        float(position),
        np.array(current),
        np.array(spread),
        np.array(measured),
    )
