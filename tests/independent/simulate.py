"""Run one closed-loop scenario of the rig in software and collect its log and its truth.

A :class:`Scenario` is a seed, a duration, the plant's true constants (drawn from the seed a few
per cent off the papers' unless given), a tuple of effects, a reference specification and the
rig settings (:class:`Rig`). :func:`simulate` runs it in the C core and returns a :class:`Run`
with the 1 kHz log (every fifth 5 kHz control sample: encoder readings and the commanded
currents at those instants), the true states at the same instants, and the truth dict that
:func:`~tests.independent.logio.write_log` writes next to the CSV.

Random streams: ``SeedSequence(seed).spawn(3)`` gives independent generators for the constants,
the reference and the encoder noise, so the same seed always gives the same log, and the noise
of a shorter run is the beginning of the noise of a longer one.
"""

from __future__ import annotations

import ctypes
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import core
from .controller import (
    K_H,
    K_V,
    OBSERVER_BANDWIDTH,
    OMEGA0,
    PID_POLES,
    internal_model_matrices,
    observer_matrices,
    pid_design,
)
from .effects import Effect
from .physics import GEOMETRY, PAPERS_CONSTANTS, G, StageGeometry, field_prefactor
from .reference import ReferenceSpec


class SimulationError(RuntimeError):
    """The closed loop left the stage's range (lost levitation) or produced non-finite values."""


@dataclass(frozen=True)
class Rig:
    """Settings of the real-time loop, the sensors and the amplifiers (SI units).

    Attributes
    ----------
    control_rate : float
        [Hz] sampling rate of the controller (5 kHz, 002 Sec. 4).
    log_every : int
        The log keeps every ``log_every``-th control sample (5 -> 1 kHz).
    plant_substeps : int
        RK4 steps of the plant per control period (5 -> 25 kHz).
    encoder_resolution : float
        [m] quantization of both encoders (10 um).
    encoder_noise : float
        [m] standard deviation of Gaussian noise added to the position before quantization.
    current_limit : float
        [A] the controller clips each commanded current at +-this (the LCAMs' 9 A peak).
    amplifier_peak : float
        [A] the amplifiers cannot deliver a phase-current amplitude sqrt(i_d^2 + i_q^2) above this.
    amplifier_continuous : float
        [A] continuous rating (7 A); only reported (the RMS current of the run is in the truth).
    observer_bandwidth : float
        [rad/s] double pole of the high-gain observers.
    omega0 : float
        [rad/s] internal-model frequency.
    K_h, K_v : tuple of float
        Regulator gains on (e, e', xi1, xi2, xi3).
    controller_constants : tuple of float
        (C1, C2, C3, C4) the controller's feedback transformation uses (the papers').
    gap_limits : (float, float)
        [m] the run is aborted (SimulationError) if the gap leaves this range.
    stopper_gap : float or None
        [m] the stopper the platform rests on when the magnets do not hold it: the gap cannot open
        beyond it (the plate stops there, inelastic). None: no stopper (the default). A run that
        begins at the stopper's gap begins resting on it (a lift-off).
    top_stopper_gap : float or None
        [m] the stop at the smallest gap (the platform against the stator's cover): the gap cannot
        close below it (inelastic). None: none (the default).
    end_stops : (float, float) or None
        [m] the horizontal travel's end stops (low, high): x3 is held within them (inelastic).
        None: none (the default).
    x3_limit : float
        [m] ... or if |x3| exceeds this.
    logged_currents : str
        ``"commanded"`` (the controller's commands at the logging instants) or ``"measured"`` (what
        the amplifiers' current sensors read there: their output current in the commanded frame,
        after any lag, plus ``current_sensor_noise``; the log's metadata then say ``currents:
        measured``).
    current_sensor_noise : float
        [A] standard deviation of the white noise on each measured current (``"measured"`` only).
    current_sensor_bandwidth : float
        [Hz] the bandwidth of a first-order filter on the current sensors (an amplifier's current
        monitor, or the anti-aliasing filter before its converter), ``"measured"`` only; 0: none
        (the default). A filter at bandwidth f delays the measured currents by about 1 / (2 pi f).
    controller : str
        ``"fl"`` (the papers' FL output regulator) or ``"pid"`` (the two independent PID regulators
        of the papers' identification runs, :func:`~tests.independent.controller.pid_design`, with
        triple poles at ``-pid_poles`` rad/s (vertical, horizontal) on the linearization at
        ``operating_gap`` [m]).
    """

    control_rate: float = 5000.0
    log_every: int = 5
    plant_substeps: int = 5
    encoder_resolution: float = 10e-6
    encoder_noise: float = 2e-6
    current_limit: float = 9.0
    amplifier_peak: float = 9.0
    amplifier_continuous: float = 7.0
    observer_bandwidth: float = OBSERVER_BANDWIDTH
    omega0: float = OMEGA0
    K_h: tuple[float, ...] = K_H
    K_v: tuple[float, ...] = K_V
    controller_constants: tuple[float, float, float, float] = PAPERS_CONSTANTS
    gap_limits: tuple[float, float] = (0.006, 0.034)
    x3_limit: float = 0.08
    stopper_gap: float | None = None
    top_stopper_gap: float | None = None
    end_stops: tuple[float, float] | None = None
    logged_currents: str = "commanded"
    current_sensor_noise: float = 0.0
    current_sensor_bandwidth: float = 0.0
    controller: str = "fl"
    pid_poles: tuple[float, float] = PID_POLES
    operating_gap: float = 0.0195

    def __post_init__(self) -> None:
        if self.logged_currents not in ("commanded", "measured"):
            raise ValueError(
                f"Rig.logged_currents must be 'commanded' or 'measured', got {self.logged_currents!r}"
            )
        if self.controller not in ("fl", "pid"):
            raise ValueError(f"Rig.controller must be 'fl' or 'pid', got {self.controller!r}")
        if not self.current_sensor_noise >= 0 or (
            self.current_sensor_noise and self.logged_currents != "measured"
        ):
            raise ValueError(
                "Rig.current_sensor_noise: a standard deviation >= 0 [A], of measured currents only"
            )
        if not self.current_sensor_bandwidth >= 0 or (
            self.current_sensor_bandwidth and self.logged_currents != "measured"
        ):
            raise ValueError("Rig.current_sensor_bandwidth: a bandwidth >= 0 [Hz], of measured currents only")

    @property
    def control_period(self) -> float:
        """[s]"""
        return 1.0 / self.control_rate

    @property
    def plant_step(self) -> float:
        """[s]"""
        return self.control_period / self.plant_substeps

    @property
    def log_rate(self) -> float:
        """[Hz]"""
        return self.control_rate / self.log_every

    def as_dict(self) -> dict[str, Any]:
        """The settings for the truth file."""
        return {
            "control_rate_hz": self.control_rate,
            "log_rate_hz": self.log_rate,
            "log_decimation": f"every {self.log_every}th control sample; currents are the "
            + (
                "commanded values at the logging instants, not averages"
                if self.logged_currents == "commanded"
                else "amplifiers' measured output currents at the logging instants (commanded frame), "
                f"with white sensor noise of {self.current_sensor_noise:g} A"
                + (
                    f", through a first-order filter of bandwidth {self.current_sensor_bandwidth:g} Hz"
                    if self.current_sensor_bandwidth
                    else ""
                )
            ),
            "logged_currents": self.logged_currents,
            "plant_integrator": f"classical RK4, {self.plant_substeps} steps per control period "
            f"({self.control_rate * self.plant_substeps:g} Hz)",
            "encoder_resolution_m": self.encoder_resolution,
            "encoder_noise_std_m": self.encoder_noise,
            "encoder_model": "reading = q * round((x + n) / q), n ~ N(0, sigma^2): noise before quantization",
            "current_hold": "zero-order hold over each control period",
            "stopper_gap_m": self.stopper_gap,
            # (said only when there: the truth of the logs without them stays as it was)
            **({"top_stopper_gap_m": self.top_stopper_gap} if self.top_stopper_gap is not None else {}),
            **({"end_stops_m": list(self.end_stops)} if self.end_stops is not None else {}),
            "controller_current_clip_a": self.current_limit,
            "amplifier_peak_a": self.amplifier_peak,
            "amplifier_continuous_a": self.amplifier_continuous,
            "amplifier_default": "ideal (current equals command) unless an amplifier_dynamics effect "
            "is present",
        }

    def controller_dict(self) -> dict[str, Any]:
        """The controller's settings for the truth file."""
        if self.controller == "pid":
            design = pid_design(self.operating_gap, self.pid_poles, self.controller_constants)
            return {
                "law": "two independent PID regulators: u2 = i_eq - (kp e1 + kd e1' + ki int e1) / b_v, "
                "u1 = -(kp e2 + kd e2' + ki int e2) / b_h, designed on the model linearized at the "
                "operating gap (triple poles at -pid_poles)",
                "constants": dict(zip(("C1", "C2", "C3", "C4"), self.controller_constants, strict=True)),
                "operating_gap_m": self.operating_gap,
                "pid_poles_rad_per_s": list(self.pid_poles),
                "gains_vertical_kp_kd_ki": list(design["vertical"]),
                "gains_horizontal_kp_kd_ki": list(design["horizontal"]),
                "b_v": design["b_v"],
                "b_h": design["b_h"],
                "i_eq_a": design["i_eq"],
                "observer": "high-gain observer per axis (as the FL regulator's)",
                "observer_bandwidth_rad_per_s": self.observer_bandwidth,
            }
        return {
            "law": "papers' FL output regulator: u1 = -v1/L1(y1), u2 = (-L3 - sqrt(R))/(2 L4), "
            "R = L3^2 - 4 L4 (L4 u1^2 + L2 - G + v2) clipped at 0; v = K (e, e', xi), xi' = phi xi + N e",
            "constants": dict(zip(("C1", "C2", "C3", "C4"), self.controller_constants, strict=True)),
            "K_h": list(self.K_h),
            "K_v": list(self.K_v),
            "omega0_rad_per_s": self.omega0,
            "observer": "high-gain observer per axis, p' = q + 2 w (y - p), q' = v + w^2 (y - p), "
            "exact ZOH discretization, one-sample prediction",
            "observer_bandwidth_rad_per_s": self.observer_bandwidth,
            "measured_gap_used": "the gap encoder reading y1",
        }


@dataclass(frozen=True)
class Scenario:
    """One run to simulate.

    Attributes
    ----------
    name : str
        Name (used for the file stem unless one is given to :func:`write_log`).
    seed : int
        Seed of the constants, the reference and the noise.
    duration : float
        [s] length of the run (60 s).
    effects : tuple of Effect
        Unmodelled effects present in the plant (at most one per kind and axis).
    constants : tuple of float or None
        The plant's true (C1, C2, C3, C4); None draws them from the seed, each off the papers'
        by a relative amount uniform in ``constant_spread`` with a random sign.
    constant_spread : (float, float)
        Range of the relative deviation of the drawn constants (1 % to 4 %).
    reference : ReferenceSpec
        How the references are drawn.
    rig : Rig
        Loop, sensor and amplifier settings.
    description : str
        Free text for the truth file.
    payload : float
        [kg] A mass carried on the platform: it moves with both axes, so every force the stage
        feels accelerates M_h + payload and M_v + payload (gravity still G). 0: none.
    declare_payload : bool
        Write the payload into the log's metadata (``# payload_kg: ...``), as a user who weighed
        it would; False leaves the log silent about it (the truth file always says it).
    """

    name: str
    seed: int
    duration: float = 60.0
    effects: tuple[Effect, ...] = ()
    constants: tuple[float, float, float, float] | None = None
    constant_spread: tuple[float, float] = (0.01, 0.04)
    reference: ReferenceSpec = field(default_factory=ReferenceSpec)
    rig: Rig = field(default_factory=Rig)
    description: str = ""
    payload: float = 0.0
    declare_payload: bool = False

    def __post_init__(self) -> None:
        if not (math.isfinite(self.payload) and self.payload >= 0.0):
            raise ValueError(f"Scenario.payload must be a mass >= 0 [kg], got {self.payload!r}")


@dataclass
class Run:
    """Result of :func:`simulate`.

    Attributes
    ----------
    scenario : Scenario
    t : ndarray (n,)
        [s] logging instants.
    x1, x3 : ndarray (n,)
        [m] encoder readings at the logging instants (the logged positions).
    u1, u2 : ndarray (n,)
        [A] commanded i_q, i_d at the logging instants (the logged currents).
    states : dict of str to ndarray (n,)
        True values at the logging instants: ``x1 x2 x3 x4`` (plant), ``iq id`` (actual currents),
        ``gap`` (true magnetic gap), ``F_fric_h F_fric_v`` [N], ``v1 v2``, ``xhat2 xhat4``
        (observer velocities), ``r_v r_h`` (references).
    truth : dict
        Everything the truth file holds.
    elapsed : float
        [s] wall time of the C loop.
    """

    scenario: Scenario
    t: np.ndarray
    x1: np.ndarray
    x3: np.ndarray
    u1: np.ndarray
    u2: np.ndarray
    states: dict[str, np.ndarray]
    truth: dict[str, Any]
    elapsed: float


def draw_constants(rng: np.random.Generator, spread: tuple[float, float]) -> tuple[float, ...]:
    """Papers' constants each times (1 + s d), d uniform in ``spread``, s a random sign."""
    d = rng.uniform(spread[0], spread[1], 4) * rng.choice([-1.0, 1.0], 4)
    return tuple(float(c * (1.0 + x)) for c, x in zip(PAPERS_CONSTANTS, d, strict=True))


def build_params(
    scenario: Scenario,
    constants: tuple[float, ...],
    geo: StageGeometry = GEOMETRY,
) -> core.Params:
    """Fill the C core's parameter struct for ``scenario`` with true ``constants``."""
    rig = scenario.rig
    p = core.Params()
    p.C1, p.C2, p.C3, p.C4 = constants
    p.Mh, p.Mv, p.G = geo.M_h, geo.M_v, G
    p.load = scenario.payload
    p.b0, p.t1, p.hm, p.tau, p.mu_rec = geo.b0, geo.t1, geo.hm, geo.tau, geo.mu_rec
    p.Bpre = field_prefactor(geo)
    p.Cn1, p.Cn2, p.Cn3, p.Cn4 = rig.controller_constants
    p.Kh[:] = list(rig.K_h)
    p.Kv[:] = list(rig.K_v)
    T = rig.control_period
    Ao, Bo = observer_matrices(T, rig.observer_bandwidth)
    Ai, Bi = internal_model_matrices(T, rig.omega0)
    p.Ao[:] = Ao.ravel().tolist()
    p.Bo[:] = Bo.ravel().tolist()
    p.Ai[:] = Ai.ravel().tolist()
    p.Bi[:] = Bi.tolist()
    p.i_max, p.Tc = rig.current_limit, T
    p.n_sub, p.record_every = rig.plant_substeps, rig.log_every
    p.q = rig.encoder_resolution
    p.gap_min, p.gap_max = rig.gap_limits
    p.x3_max = rig.x3_limit
    p.stop_gap = rig.stopper_gap or 0.0
    p.top_gap = rig.top_stopper_gap or 0.0
    if rig.end_stops is not None:
        p.x3_stop_on = 1
        p.x3_stop_lo, p.x3_stop_hi = rig.end_stops
    p.com_cos, p.com_sin = 1.0, 0.0
    p.amp_peak = rig.amplifier_peak
    if rig.current_sensor_bandwidth:
        p.sensor_tau = 1.0 / (2.0 * math.pi * rig.current_sensor_bandwidth)
    if rig.controller == "pid":
        design = pid_design(rig.operating_gap, rig.pid_poles, rig.controller_constants)
        p.pid_on = 1
        p.pid_v[:] = list(design["vertical"])
        p.pid_h[:] = list(design["horizontal"])
        p.pid_bv, p.pid_bh, p.pid_ieq = design["b_v"], design["b_h"], design["i_eq"]
    ctx = effect_context(scenario)
    keys = [e.key() for e in scenario.effects]
    if len(set(keys)) != len(keys):
        raise ValueError(f"scenario {scenario.name!r}: an effect kind appears twice: {keys}")
    for eff in scenario.effects:
        eff.apply(p, ctx)
    return p


def effect_context(scenario: Scenario, geo: StageGeometry = GEOMETRY) -> dict[str, float]:
    """Rig values the effects need: plant step [s], the masses moved [kg] (with the payload)."""
    m = scenario.payload
    return {"plant_step": scenario.rig.plant_step, "M_h": geo.M_h + m, "M_v": geo.M_v + m}


def simulate(scenario: Scenario) -> Run:
    """Simulate ``scenario`` and return its :class:`Run`.

    Raises
    ------
    SimulationError
        If the stage leaves ``rig.gap_limits`` / ``rig.x3_limit`` or the state stops being finite.
    """
    rig = scenario.rig
    if rig.plant_substeps < 1 or rig.log_every < 1:
        raise ValueError("plant_substeps and log_every must be >= 1")
    seq = np.random.SeedSequence(scenario.seed)
    # later streams (measured currents' noise, the base's vibration) leave the first three as they were
    rng_c, rng_r, rng_n, rng_i, rng_b = (np.random.default_rng(s) for s in seq.spawn(5))
    constants = (
        scenario.constants
        if scenario.constants is not None
        else draw_constants(rng_c, scenario.constant_spread)
    )
    ref_v, ref_h = scenario.reference.draw(rng_r, scenario.duration)

    n_ctrl = round(scenario.duration * rig.control_rate)
    if n_ctrl < 2 * rig.log_every:
        raise ValueError(f"duration {scenario.duration} s is too short")
    tk = np.arange(n_ctrl) / rig.control_rate
    rv, drv = ref_v.evaluate(tk)
    rh, drh = ref_h.evaluate(tk)
    ref = np.ascontiguousarray(np.column_stack([rv, drv, rh, drh]))
    noise = np.ascontiguousarray(rng_n.standard_normal((n_ctrl, 2)) * rig.encoder_noise)
    gap0 = rv[0] if rig.stopper_gap is None else min(rv[0], rig.stopper_gap)
    s0 = np.array([gap0, 0.0, rh[0], 0.0, 0.0, 0.0])
    n_rec = -(-n_ctrl // rig.log_every)
    rec = np.zeros((n_rec, core.NREC))
    info = np.zeros(5, dtype=np.int32)
    ucmd = np.zeros((n_ctrl, 2))
    shaking = [e for e in scenario.effects if hasattr(e, "signal")]
    base_acc = np.zeros((n_ctrl, 2))
    if shaking:
        base_acc = np.ascontiguousarray(shaking[0].signal(rng_b, n_ctrl, rig.control_rate))

    params = build_params(scenario, constants)
    lib = core.load()
    t0 = time.perf_counter()
    status = lib.simulate(ctypes.byref(params), n_ctrl, ref, noise, s0, rec, info, ucmd, base_acc)
    elapsed = time.perf_counter() - t0
    if status != 0:
        k = int(info[1])
        what = (
            "left the stage's range (lost levitation or hit a stop)" if status == 1 else "became non-finite"
        )
        raise SimulationError(
            f"scenario {scenario.name!r} (seed {scenario.seed}): the closed loop {what} at "
            f"t = {k / rig.control_rate:.4f} s"
        )

    cols = {name: rec[:, i].copy() for i, name in enumerate(core.REC_COLUMNS)}
    idx = np.arange(n_rec) * rig.log_every
    cols["r_v"] = rv[idx]
    cols["r_h"] = rh[idx]
    t_log = np.arange(n_rec) / rig.log_rate

    ctx = effect_context(scenario)
    i_mag = np.hypot(ucmd[:, 0], ucmd[:, 1])
    truth: dict[str, Any] = {
        "name": scenario.name,
        "seed": scenario.seed,
        "description": scenario.description,
        "generator": "tests/independent of maglev_oc: own physics, controller and integrator; "
        "does not import maglev_oc",
        "duration_s": scenario.duration,
        "plant": {
            "model": "SPEC 1 two-DOF model with the closed-form field B(y) (sigma_m = H_c), true lumped "
            "constants below, plus the listed effects",
            "constants_true": dict(zip(("C1", "C2", "C3", "C4"), constants, strict=True)),
            "constants_papers": dict(zip(("C1", "C2", "C3", "C4"), PAPERS_CONSTANTS, strict=True)),
            "constants_relative_to_papers": {
                f"C{i + 1}": c / cp - 1.0
                for i, (c, cp) in enumerate(zip(constants, PAPERS_CONSTANTS, strict=True))
            },
            "G_m_per_s2": G,
            "geometry": GEOMETRY.as_dict(),
            "payload_kg": scenario.payload,
            "payload_declared": scenario.declare_payload,
            "sign_conventions": "x1 gap as the vertical encoder reads it (gravity opens it); x3 horizontal; "
            "F_x along +x3 on M_h; F_n attraction towards the stator on M_v",
        },
        "effects": [e.truth(ctx) for e in scenario.effects],
        "rig": rig.as_dict(),
        "controller": rig.controller_dict(),
        "reference": {
            "formula": "r = r0 + w(t) sum a_i sin(2 pi f_i t + phi_i) + smoothed steps; w quintic ramp 0->1",
            "vertical": ref_v.as_dict(),
            "horizontal": ref_h.as_dict(),
        },
        "log": {
            "columns": {
                "t": "s",
                "x1": "m, vertical encoder reading (gap)",
                "x3": "m, horizontal encoder reading",
                "u1": f"A, {rig.logged_currents} i_q",
                "u2": f"A, {rig.logged_currents} i_d",
            },
            "sample_rate_hz": rig.log_rate,
        },
        "run": {
            "samples_with_R_clipped": int(info[2]),
            "samples_with_current_clipped": int(info[3]),
            "plant_steps_with_amplifier_at_peak": int(info[4]),
            "max_abs_i_q_a": float(np.max(np.abs(ucmd[:, 0]))),
            "max_abs_i_d_a": float(np.max(np.abs(ucmd[:, 1]))),
            "rms_current_magnitude_a": float(math.sqrt(np.mean(i_mag**2))),
            "tracking_error_rms_m": {
                "vertical": float(np.sqrt(np.mean((cols["x1"] - cols["r_v"]) ** 2))),
                "horizontal": float(np.sqrt(np.mean((cols["x3"] - cols["r_h"]) ** 2))),
            },
            "tracking_error_max_m": {
                "vertical": float(np.max(np.abs(cols["x1"] - cols["r_v"]))),
                "horizontal": float(np.max(np.abs(cols["x3"] - cols["r_h"]))),
            },
            "true_gap_range_m": [float(np.min(cols["gap"])), float(np.max(cols["gap"]))],
        },
    }
    logged = (cols["u1"], cols["u2"])
    if rig.logged_currents == "measured":
        noise_i = rng_i.standard_normal((2, n_rec)) * rig.current_sensor_noise
        logged = (cols["iq_amp"] + noise_i[0], cols["id_amp"] + noise_i[1])
    return Run(
        scenario=scenario,
        t=t_log,
        x1=cols["y1"],
        x3=cols["y3"],
        u1=logged[0],
        u2=logged[1],
        states=cols,
        truth=truth,
        elapsed=elapsed,
    )
