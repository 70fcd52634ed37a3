"""The 3-DOF microstepper in closed loop on its twin, and the paper's figures of a run (002 Sec. 8).

Per sample k (controller and twin share the 5 kHz sample time), as the 2-DOF engine
(:mod:`~maglev_oc.sim.engine`):

    y[k] = twin.measure(s[k], w[k]);  (u[k], c[k+1], diag[k]) = controller.step(c[k], y[k], r[k]);
    s[k+1] = twin.step(s[k], u[k])

fused into one CasADi Function and run with ``mapaccum`` (chunks of
:data:`~maglev_oc.sim.engine.CHUNK` samples, no Python per sample), or as generated C
(:class:`~maglev_oc.sim.native.NativeLoop`). :func:`simulate_microstepper` is the one-off call,
:class:`MicrostepperLoop` builds once for many runs, :func:`evaluate_microstepper` gives the
paper's figures: settling of the measured error below 0.1 mm and 10 um per set-point and axis,
overshoot, mean absolute tracking error per axis.

The twin is :mod:`~maglev_oc.sim.microstepper_twin`, the scenarios
:mod:`~maglev_oc.sim.microstepper_scenarios`, the controller :mod:`~maglev_oc.control.microstepper`.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass

import casadi as ca
import numpy as np

from maglev_oc.control.microstepper import N_MEASUREMENTS, N_REFERENCE, MicrostepperRegulator
from maglev_oc.errors import InputError
from maglev_oc.numerics import jit
from maglev_oc.results import Result
from maglev_oc.sim.engine import CHUNK, run_outcome
from maglev_oc.sim.metrics import BANDS, MIN_STEP
from maglev_oc.sim.microstepper_scenarios import MicrostepperScenario, MicrostepperSetpoints
from maglev_oc.sim.microstepper_twin import MicrostepperTwin

__all__ = [
    "MicrostepperLoop",
    "MicrostepperMetrics",
    "MicrostepperResult",
    "SetpointMetrics",
    "evaluate_microstepper",
    "simulate_microstepper",
]

_BAND_ROUNDING = 1e-9
"""Relative slack on the settling bands: a reading one 10 um count off the set-point gives an
error of 10 um up to rounding (1e-17 m), which is inside the 10 um band, not outside it."""


# --- closed loop -------------------------------------------------------------------------------
@dataclass(frozen=True)
class MicrostepperResult(Result):
    """One closed-loop run of the microstepper. Signals are (rows, n) on the time grid ``t``.

    ``status``: ``"completed"``, ``"diverged"`` (a non-finite state) or ``"stopper_hit"``.
    ``events`` counts flagged samples: ``clipped`` (R < 0 in the controller), ``saturated``
    (the controller saw a pair over the limit), and the twin's :attr:`MicrostepperTwin.FLAG_NAMES`.
    """

    controller: str
    scenario: str
    effects: tuple[str, ...]
    t: np.ndarray  # (n,) [s]
    x: np.ndarray  # (6, n) true state (x, x', y, y', gap, gap') [m, m/s]
    y: np.ndarray  # (3, n) encoder readings (x, y, gap) [m]
    u: np.ndarray  # (4, n) current commands (i_qA, i_dA, i_qB, i_dB) [A]
    current: np.ndarray  # (4, n) applied currents [A] (after the amplifiers)
    reference: np.ndarray  # (9, n)
    diag: np.ndarray  # (n_diag, n)
    diag_names: tuple[str, ...]
    flags: np.ndarray  # (3, n) MicrostepperTwin.FLAG_NAMES
    events: dict[str, int]
    success: bool
    status: str
    message: str
    timings: Mapping[str, float]  # [s] {"total": wall time of the simulation}
    sample_time: float = 0.0
    evaluate_from: float = 0.0

    def diagnostic(self, name: str) -> np.ndarray:
        """A controller diagnostic row by name (e.g. ``"v_ach_x"``)."""
        return self.diag[self.diag_names.index(name)]

    @property
    def error(self) -> np.ndarray:
        """True tracking error (3, n) [m] per axis (x, y, gap)."""
        return self.x[0::2] - self.reference[0::3]

    @property
    def measured_error(self) -> np.ndarray:
        """Encoder reading minus reference (3, n) [m]: the error the paper reports."""
        return self.y - self.reference[0::3]


class MicrostepperLoop:
    """A microstepper twin and an expression controller joined once; :meth:`run` simulates.

    The fused step (controller + twin) and its runner are built once per instance.

    Parameters
    ----------
    twin : MicrostepperTwin
    controller : MicrostepperRegulator
        Or any controller with its interface (step, n_state, diag_names, initial_state).
    backend : {"vm", "jit", "c"}
        ``mapaccum`` in CasADi's virtual machine, the same compiled by CasADi's JIT, or the step
        as generated C with a C loop (:class:`~maglev_oc.sim.native.NativeLoop`).
    """

    BACKENDS = ("vm", "jit", "c")

    def __init__(
        self, twin: MicrostepperTwin, controller: MicrostepperRegulator, *, backend: str = "vm"
    ) -> None:
        if abs(controller.sample_time - twin.sample_time) > 1e-12:
            raise InputError(
                f"controller sample time {controller.sample_time} s differs from the twin's "
                f"{twin.sample_time} s"
            )
        if backend not in self.BACKENDS:
            raise InputError(f"backend must be one of {self.BACKENDS}, got {backend!r}")
        self.twin, self.controller, self.backend = twin, controller, backend
        t0 = time.perf_counter()
        self.step_function = self._fused_step()
        self._runner = self._build_runner()
        self.build_time = time.perf_counter() - t0  # [s]

    def _fused_step(self) -> ca.Function:
        """(z = (twin state, controller state), r (9), w (3)) -> (z_next, out), out = (y (3),
        u (4), diag, flags (3), twin state)."""
        twin, ctrl = self.twin, self.controller
        ns, nc = twin.n_state, ctrl.n_state
        z = ca.SX.sym("z", ns + nc)
        r = ca.SX.sym("r", N_REFERENCE)
        w = ca.SX.sym("w", N_MEASUREMENTS)
        s, c = z[:ns], z[ns:]
        y = twin.measure(s, w)
        u, c_next, diag = ctrl.step(c, y, r)
        s_next, flags = twin.step(s, u)
        out = ca.vertcat(y, u, diag, flags, s)
        return ca.Function("microstepper_loop", [z, r, w], [ca.vertcat(s_next, c_next), out], {"cse": True})

    def _build_runner(self):
        if self.backend == "c":
            from maglev_oc.sim.native import NativeLoop

            return NativeLoop(self.step_function)
        chunk = self.step_function.mapaccum("microstepper_chunk", CHUNK)
        return jit(chunk, symbolic="MX") if self.backend == "jit" else chunk

    def _simulate(self, z0: np.ndarray, ref: np.ndarray, noise: np.ndarray) -> np.ndarray:
        if self.backend == "c":
            out, _ = self._runner(z0, ref, noise)
            return out
        n = ref.shape[1]
        n_pad = -(-n // CHUNK) * CHUNK
        ref_p = np.concatenate([ref, np.repeat(ref[:, -1:], n_pad - n, axis=1)], axis=1)
        noise_p = np.concatenate([noise, np.zeros((N_MEASUREMENTS, n_pad - n))], axis=1)
        outs, z = [], np.asarray(z0, dtype=float)
        for k0 in range(0, n_pad, CHUNK):
            zs, out = self._runner(z, ref_p[:, k0 : k0 + CHUNK], noise_p[:, k0 : k0 + CHUNK])
            outs.append(np.asarray(out))
            z = np.asarray(zs[:, -1]).ravel()
            if not np.all(np.isfinite(z)):
                break
        out = np.concatenate(outs, axis=1)
        if out.shape[1] < n_pad:  # diverged: the rest is NaN
            out = np.concatenate([out, np.full((out.shape[0], n_pad - out.shape[1]), np.nan)], axis=1)
        return out[:, :n]

    def run(
        self,
        scenario: MicrostepperScenario,
        *,
        seed: int = 0,
        start: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> MicrostepperResult:
        """Simulate ``scenario`` from rest at ``scenario.q0`` with the holding currents flowing, or
        from ``start``.

        Parameters
        ----------
        scenario : MicrostepperScenario
        seed : int
            Seed of the encoder noise.
        start : (q0 (6,), xi (9,)), optional
            The mechanical state (x, x', y, y', gap, gap') [m, m/s] and the controller's internal
            models (three per axis, x, y, gap) to start from (the observers start at the first
            reading and the true rates; the currents flowing are the holding currents of the gap).

        Returns
        -------
        MicrostepperResult
        """
        twin, ctrl = self.twin, self.controller
        t, ref = scenario.sample(twin.sample_time)
        q0 = np.zeros(6)
        q0[0::2] = scenario.q0
        if start is not None:
            q0 = np.asarray(start[0], dtype=float).reshape(6)
        u0 = twin.holding_currents(q0[4])
        s0 = twin.initial_state(q0, u0)
        noise = np.random.default_rng(seed).standard_normal((N_MEASUREMENTS, t.size))
        y0 = np.asarray(twin.measure(s0, noise[:, 0])).ravel()
        c0 = ctrl.initial_state(y0, ref[:, 0], u0)
        if start is not None:
            c0[1:6:2] = q0[1::2]
            c0[6:15] = np.asarray(start[1], dtype=float).reshape(9)
        t0 = time.perf_counter()
        out = self._simulate(np.concatenate([s0, c0]), ref, noise)
        wall = time.perf_counter() - t0
        return self._result(scenario, t, ref, out, wall)

    def _result(self, scenario, t, ref, out, wall) -> MicrostepperResult:
        twin, ctrl = self.twin, self.controller
        nd = len(ctrl.diag_names)
        diag, flags, states = out[7 : 7 + nd], out[7 + nd : 10 + nd], out[10 + nd :]
        x = states[0:6]
        names = ctrl.diag_names
        events = {
            "clipped": int(np.nansum(diag[names.index("clipped")])) if "clipped" in names else 0,
            "saturated": int(
                np.nansum(np.max(diag[[names.index("saturated_A"), names.index("saturated_B")]], 0))
            )
            if "saturated_A" in names
            else 0,
        }
        events |= {name: int(np.nansum(flags[k])) for k, name in enumerate(twin.FLAG_NAMES)}
        success, status, message = run_outcome(t, x, flags[twin.FLAG_NAMES.index("stopper_hit")])
        return MicrostepperResult(
            controller=ctrl.name,
            scenario=scenario.name,
            effects=tuple(twin.effects.enabled()),
            t=t,
            x=x,
            y=out[0:3],
            u=out[3:7],
            current=states[6:10],
            reference=ref,
            diag=diag,
            diag_names=tuple(names),
            flags=flags,
            events=events,
            success=success,
            status=status,
            message=message,
            timings={"total": wall},
            sample_time=twin.sample_time,
            evaluate_from=scenario.evaluate_from,
        )


def simulate_microstepper(
    controller: MicrostepperRegulator,
    scenario: MicrostepperScenario,
    seed: int = 0,
    *,
    twin: MicrostepperTwin | None = None,
) -> MicrostepperResult:
    """One-off closed-loop run; for several runs build a :class:`MicrostepperLoop` once.

    Parameters
    ----------
    controller : MicrostepperRegulator
    scenario : MicrostepperScenario
    seed : int
        Seed of the encoder noise.
    twin : MicrostepperTwin, optional
        Default: the rig twin of the controller's platform.

    Returns
    -------
    MicrostepperResult
    """
    twin = MicrostepperTwin(controller.platform) if twin is None else twin
    return MicrostepperLoop(twin, controller).run(scenario, seed=seed)


# --- metrics -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class SetpointMetrics:
    """One set-point change; arrays per axis (x, y, gap)."""

    time: float  # [s] when the set-point changed
    size: np.ndarray  # (3,) [m] signed step
    settling_01mm: np.ndarray  # (3,) [s], NaN if not settled before the next change
    settling_10um: np.ndarray  # (3,) [s]
    overshoot_pct: np.ndarray  # (3,) [%], NaN for steps under MIN_STEP


@dataclass(frozen=True)
class MicrostepperMetrics(Result):
    """The paper's figures of one run (002 Sec. 8), measured errors (readings minus reference)."""

    controller: str
    scenario: str
    success: bool
    status: str
    message: str
    steps: tuple[SetpointMetrics, ...]
    mean_error: np.ndarray  # (3,) [m] mean |measured error| per axis after evaluate_from
    peak_error: np.ndarray  # (3,) [m]
    peak_current: float  # [A] largest commanded pair magnitude
    saturated: int  # samples with a pair over the limit
    clipped: int  # samples with R < 0
    timings: Mapping[str, float]

    def worst_settling(self, band: str = "01mm") -> np.ndarray:
        """Longest settling time [s] per axis over the steps, to "01mm" or "10um"; NaN where a
        step never settled."""
        if not self.steps:
            return np.full(3, np.nan)
        vals = np.array([getattr(s, f"settling_{band}") for s in self.steps])
        return np.where(np.any(np.isnan(vals), axis=0), np.nan, np.max(vals, axis=0))

    def max_overshoot(self) -> np.ndarray:
        """Largest overshoot [%] per axis over the scored steps (NaN if none scored)."""
        if not self.steps:
            return np.full(3, np.nan)
        vals = np.array([s.overshoot_pct for s in self.steps])
        scored = ~np.isnan(vals)
        return np.array([np.max(vals[scored[:, j], j]) if scored[:, j].any() else np.nan for j in range(3)])


def evaluate_microstepper(result: MicrostepperResult, scenario: MicrostepperScenario) -> MicrostepperMetrics:
    """The paper's figures of ``result`` (a run of ``scenario``).

    Settling to a band (0.1 mm, 10 um): time from the set-point change until the measured error
    enters the band for good (NaN if it does not before the next change). Overshoot: largest
    excursion past the new set-point in % of the step (steps under 0.5 mm not scored).

    Parameters
    ----------
    result : MicrostepperResult
    scenario : MicrostepperScenario

    Returns
    -------
    MicrostepperMetrics
    """
    t, err = result.t, result.measured_error
    steps = ()
    if isinstance(scenario.reference, MicrostepperSetpoints):
        steps = _setpoint_metrics(t, err, scenario, result.sample_time)
    window = t >= scenario.evaluate_from
    e_win = np.abs(err[:, window])
    mag = np.hypot(result.u[0::2], result.u[1::2])
    return MicrostepperMetrics(
        controller=result.controller,
        scenario=result.scenario,
        success=result.success,
        status=result.status,
        message=result.message,
        steps=steps,
        mean_error=np.nanmean(e_win, axis=1),
        peak_error=np.nanmax(e_win, axis=1),
        peak_current=float(np.nanmax(mag)),
        saturated=result.events.get("saturated", 0),
        clipped=result.events.get("clipped", 0),
        timings=dict(result.timings),
    )


def _settling(t: np.ndarray, err: np.ndarray, band: float) -> float:
    outside = np.nonzero(~(np.abs(err) <= band * (1 + _BAND_ROUNDING)))[0]  # NaN counts as outside
    if outside.size == 0:
        return 0.0
    if outside[-1] >= t.size - 1:
        return float("nan")
    return float(t[outside[-1] + 1] - t[0])


def _setpoint_metrics(t, err, scenario: MicrostepperScenario, sample_time: float) -> tuple:
    ref = scenario.reference
    times = [*ref.times, t[-1] + sample_time]
    sp = np.asarray(ref.setpoints)
    prev = np.asarray(scenario.q0, dtype=float)
    steps = []
    for k in range(len(ref.times)):
        seg = (t >= times[k]) & (t < times[k + 1])
        size, prev = sp[k] - prev, sp[k]
        if not np.any(seg):
            continue
        e = err[:, seg]
        s01 = np.array([_settling(t[seg], e[j], BANDS[0]) for j in range(3)])
        s10 = np.array([_settling(t[seg], e[j], BANDS[1]) for j in range(3)])
        past = np.nanmax(np.sign(size)[:, None] * e, axis=1)
        over = np.where(
            np.abs(size) < MIN_STEP, np.nan, np.maximum(past, 0) / np.maximum(np.abs(size), MIN_STEP) * 100
        )
        steps.append(SetpointMetrics(float(times[k]), size, s01, s10, over))
    return tuple(steps)
