"""Closed-loop simulation of a controller on the rig twin.

For an :class:`~maglev_oc.control.base.ExpressionController` the controller and the twin are
fused into one CasADi step Function and the whole run is a single ``mapaccum`` call (no Python
per sample). An :class:`~maglev_oc.control.base.OnlineController` (NMPC) is stepped from a Python
loop around the same twin Functions, and each of its calls is timed.

Per sample k (controller and twin share the sample time):

    y[k] = measure(s[k], w[k]);  (u[k], c[k+1], diag[k]) = controller(c[k], y[k], r[k]);
    s[k+1] = twin.step(s[k], u[k])
"""

from __future__ import annotations

import copy
import time
from collections.abc import Mapping
from dataclasses import dataclass

import casadi as ca
import numpy as np

from maglev_oc.control.base import ExpressionController, OnlineController
from maglev_oc.errors import InputError
from maglev_oc.model.equilibrium import equilibrium_currents
from maglev_oc.numerics import jit
from maglev_oc.results import Result
from maglev_oc.sim.scenarios import Scenario
from maglev_oc.sim.twin import RigTwin

__all__ = ["CHUNK", "ClosedLoop", "SimulationResult", "run_outcome", "simulate"]


def run_outcome(t: np.ndarray, x: np.ndarray, stopper: np.ndarray) -> tuple[bool, str, str]:
    """(success, status, message) of a closed-loop run from its time grid (n,), true states
    (n_x, n) and stopper flags (n,): ``"diverged"`` at the first non-finite state,
    ``"stopper_hit"`` at the first stopper contact, else ``"completed"``."""
    finite = np.all(np.isfinite(x), axis=0)
    if not np.all(finite):
        k = int(np.argmin(finite))
        return False, "diverged", f"state became non-finite at t = {t[k]:.4f} s"
    if np.any(stopper > 0):
        k = int(np.argmax(stopper > 0))
        return False, "stopper_hit", f"unstable: hit a mechanical stopper at t = {t[k]:.3f} s"
    dt = t[1] - t[0] if t.size > 1 else 0.0
    return True, "completed", f"completed {t.size} samples ({t.size * dt:.4g} s) without instability"


@dataclass(frozen=True)
class SimulationResult(Result):
    """One closed-loop run. Signals are (n_rows, n_samples); all share the time grid ``t``.

    ``success`` is False when the run went unstable; ``status`` is ``"completed"``,
    ``"diverged"`` (a non-finite state) or ``"stopper_hit"``, and the ``message`` says when.
    ``events`` counts flagged samples (controller clipping, amplifier current limiting, thermal
    foldback, stopper hits). ``timings["total"]`` is the simulation's wall time [s].
    """

    controller: str
    scenario: str
    effects: tuple[str, ...]
    t: np.ndarray  # (n,) [s]
    x: np.ndarray  # (4, n) true mechanical state at t[k]
    y: np.ndarray  # (2, n) encoder readings [m]
    u: np.ndarray  # (2, n) current commands (i_q, i_d) [A]
    current: np.ndarray  # (2, n) applied d-q currents [A] (after amplifier)
    reference: np.ndarray  # (6, n)
    diag: np.ndarray  # (n_diag, n)
    diag_names: tuple[str, ...]
    flags: np.ndarray  # (3, n) twin flags, RigTwin.FLAG_NAMES
    events: dict[str, int]
    success: bool
    status: str
    message: str
    timings: Mapping[str, float]  # [s] {"total": simulation wall time}
    step_times: np.ndarray | None = None  # (n,) [s] per-call time of an online controller
    sample_time: float = 0.0
    evaluate_from: float = 0.0

    def diagnostic(self, name: str) -> np.ndarray:
        """A diagnostic row by name, e.g. ``'margin'``; NaNs if the controller has none."""
        if name in self.diag_names:
            return self.diag[self.diag_names.index(name)]
        return np.full(self.t.shape, np.nan)

    @property
    def error(self) -> np.ndarray:
        """True tracking error (x1 - r_v, x3 - r_h), (2, n) [m]."""
        return np.vstack([self.x[0] - self.reference[0], self.x[2] - self.reference[3]])


CHUNK = 1_000
"""Samples per ``mapaccum`` call. Runs are simulated chunk by chunk: CasADi's mapaccum build
time grows at least linearly with its length (0.05 s for 10^3 steps, 0.45 s for 10^4, 4 s for
10^5) and every ClosedLoop builds its own, while a loop over 0.2 s chunks costs little (a 60 s
run: 2.1 s with 10^3, 2.6 s with 10^4; a 1.5 s run: 0.13 s against 0.6 s)."""


class ClosedLoop:
    """A twin and a controller joined once; :meth:`run` simulates scenarios with them.

    The fused step Function and its runner are built once per instance, so repeated runs
    (scenarios, seeds, Monte Carlo) pay the build cost once. ``backend``:

    * ``"vm"`` (default): chunked ``mapaccum`` in CasADi's virtual machine, no compiler needed;
    * ``"jit"``: the same chunk compiled by CasADi's JIT (about 0.5 s once, 2x faster; the
      virtual machine when no C compiler is found, :func:`maglev_oc.numerics.jit`);
    * ``"c"``: the step generated as C with a C loop around it (:mod:`maglev_oc.sim.native`;
      about 1 s of gcc once, then several times faster again: no per-step bookkeeping).

    Parameters
    ----------
    twin : RigTwin
        The plant: model, effects, sample time, encoders and amplifiers.
    controller : ExpressionController or OnlineController
        A symbolic control law (fused into the step) or one that runs in Python per sample
        (NMPC); the latter always runs in the virtual machine's loop.
    backend : {"vm", "jit", "c"}
    cflags : tuple of str
        Compiler flags of the ``"c"`` backend. ``-O3`` (default) for loops run many times;
        ``-O1`` compiles in about two thirds of the time for loops run once or twice (same
        results: no flag here changes the floating-point semantics).
    """

    BACKENDS = ("vm", "jit", "c")

    def __init__(
        self,
        twin: RigTwin,
        controller: ExpressionController | OnlineController,
        *,
        backend: str = "vm",
        cflags: tuple[str, ...] = ("-O3",),
    ) -> None:
        if abs(controller.sample_time - twin.sample_time) > 1e-12:
            raise InputError(
                f"controller sample time {controller.sample_time} s differs from the twin's "
                f"{twin.sample_time} s"
            )
        self.twin = twin
        self.controller = controller
        self.expression = isinstance(controller, ExpressionController)
        if not self.expression and not isinstance(controller, OnlineController):
            raise TypeError(f"{type(controller).__name__} is not a controller (see control.base)")
        if backend not in self.BACKENDS:
            raise InputError(f"backend must be one of {self.BACKENDS}, got {backend!r}")
        self.backend = backend
        self.cflags = tuple(cflags)
        self._chunk: ca.Function | None = None
        self._native = None
        if self.expression:
            self.step_function = self._fused_step()

    def _fused_step(self) -> ca.Function:
        """``step_function``: (z = (twin state, controller state), r (6), w (2)) ->
        (z_next, out) with out = (y (2), u (2), diag, flags (3), twin state). Public so that
        batch analyses (Monte Carlo) can ``map``/``mapaccum`` it themselves."""
        twin, ctrl = self.twin, self.controller
        ns, nc = twin.n_state, ctrl.n_state
        zs = ca.SX.sym("z", ns + nc)
        r = ca.SX.sym("r", 6)
        w = ca.SX.sym("w", 2)
        s, c = zs[:ns], zs[ns:]
        y = twin.measure(s, w)
        u, c_next, diag = ctrl.step(c, y, r)
        s_next, flags = twin.step(s, u)
        out = ca.vertcat(y, u, diag, flags, s)
        # cse: the controller and the RK4 stages share many subexpressions (sinh, atan, log of
        # the gap): common-subexpression elimination removes about a fifth of the operations
        return ca.Function("closed_loop", [zs, r, w], [ca.vertcat(s_next, c_next), out], {"cse": True})

    def _chunk_function(self) -> ca.Function:
        if self._chunk is None:
            chunk = self.step_function.mapaccum("closed_loop_chunk", CHUNK)
            if self.backend == "jit":
                chunk = jit(chunk, symbolic="MX")  # unchanged without a C compiler
            self._chunk = chunk
        return self._chunk

    def _native_loop(self):
        if self._native is None:
            from maglev_oc.sim.native import NativeLoop

            self._native = NativeLoop(self.step_function, flags=self.cflags)
        return self._native

    def on(self, twin: RigTwin) -> ClosedLoop:
        """This loop, its fused step and its compiled C (built now if not yet) on ``twin``: a twin
        with this one's ``step`` and ``measure`` Functions, another plant of a
        :class:`~maglev_oc.sim.parametric_twin.ParametricTwin`. Nothing is built again; runs
        start from ``twin``'s initial state and holding current.

        Raises
        ------
        InputError
            ``twin`` does not share this loop's twin Functions.
        """
        if twin.step is not self.twin.step or twin.measure is not self.twin.measure:
            raise InputError("ClosedLoop.on: the twin must share this loop's twin step and measure Functions")
        if self.expression:
            self._native_loop() if self.backend == "c" else self._chunk_function()
        other = copy.copy(self)
        other.twin = twin
        return other

    def _run_expression(self, z0: np.ndarray, ref: np.ndarray, noise: np.ndarray) -> np.ndarray:
        if self.backend == "c":
            out, _ = self._native_loop()(z0, ref, noise)
            return out
        chunk = self._chunk_function()
        n = ref.shape[1]
        n_pad = -(-n // CHUNK) * CHUNK
        ref_p = np.concatenate([ref, np.repeat(ref[:, -1:], n_pad - n, axis=1)], axis=1)
        noise_p = np.concatenate([noise, np.zeros((2, n_pad - n))], axis=1)
        outs = []
        z = np.asarray(z0, dtype=float)
        for k0 in range(0, n_pad, CHUNK):
            zs, out = chunk(z, ref_p[:, k0 : k0 + CHUNK], noise_p[:, k0 : k0 + CHUNK])
            outs.append(np.asarray(out))
            z = np.asarray(zs[:, -1]).ravel()
            if not np.all(np.isfinite(z)):
                break
        out = np.concatenate(outs, axis=1)
        if out.shape[1] < n_pad:  # stopped early: pad with NaN
            out = np.concatenate([out, np.full((out.shape[0], n_pad - out.shape[1]), np.nan)], axis=1)
        return out[:, :n]

    # ------------------------------------------------------------------------------------
    def run(self, scenario: Scenario, *, seed: int = 0, x0=None) -> SimulationResult:
        """Simulate ``scenario``.

        Parameters
        ----------
        scenario : Scenario
        seed : int
            Seed of the encoder noise (used when the twin has an encoder).
        x0 : (4,) array, optional
            Another starting mechanical state [m, m/s, m, m/s] (default ``scenario.x0``); the run
            starts at rest with the current that holds the plant at that gap.

        Returns
        -------
        SimulationResult
        """
        twin, ctrl = self.twin, self.controller
        t, ref = scenario.sample(twin.sample_time)
        n = t.size
        x_init = np.asarray(scenario.x0 if x0 is None else x0, dtype=float)
        u_init = _holding_current(twin, x_init[0])
        s0 = twin.initial_state(x_init, u_init)
        noise = np.random.default_rng(seed).standard_normal((2, n))
        y0 = np.asarray(twin.measure(s0, noise[:, 0])).ravel()
        t0 = time.perf_counter()
        if self.expression:
            c0 = ctrl.initial_state(y0, ref[:, 0], u_init)
            out = self._run_expression(np.concatenate([s0, c0]), ref, noise)
            step_times = None
        else:
            out, step_times = self._run_online(s0, y0, ref, noise, u_init)
        wall = time.perf_counter() - t0
        return self._result(scenario, t, ref, out, wall, step_times)

    def _run_online(self, s0, y0, ref, noise, u_init):
        twin, ctrl = self.twin, self.controller
        n = ref.shape[1]
        nd = len(ctrl.diag_names)
        out = np.full((2 + 2 + nd + 3 + twin.n_state, n), np.nan)
        step_times = np.full(n, np.nan)
        ctrl.reset(y0, ref[:, 0], u_init)
        s = np.asarray(s0, dtype=float)
        measure, step = twin.measure, twin.step
        for k in range(n):
            y = np.asarray(measure(s, noise[:, k])).ravel()
            tc = time.perf_counter()
            u, diag = ctrl.control(k, y, ref)
            step_times[k] = time.perf_counter() - tc
            s_next, flags = step(s, u)
            row = (y, u, diag, flags, s)
            out[:, k] = np.concatenate([np.asarray(v, dtype=float).ravel() for v in row])
            s = np.asarray(s_next).ravel()
            if not np.all(np.isfinite(s)):
                break
        return out, step_times

    def _result(self, scenario, t, ref, out, wall, step_times) -> SimulationResult:
        twin, ctrl = self.twin, self.controller
        nd = len(ctrl.diag_names)
        y, u = out[0:2], out[2:4]
        diag = out[4 : 4 + nd]
        flags = out[4 + nd : 7 + nd]
        states = out[7 + nd :]
        x = twin.mechanical(states)
        events = {
            "clipped": int(np.nansum(diag[ctrl.diag_names.index("clipped")]))
            if "clipped" in ctrl.diag_names
            else 0,
        }
        for k, name in enumerate(twin.FLAG_NAMES):
            events[name] = int(np.nansum(flags[k]))
        success, status, message = run_outcome(t, x, flags[twin.FLAG_NAMES.index("stopper_hit")])
        return SimulationResult(
            controller=ctrl.name,
            scenario=scenario.name,
            effects=tuple(twin.effects.enabled()),
            t=t,
            x=x,
            y=y,
            u=u,
            current=twin.currents(states),
            reference=ref,
            diag=diag,
            diag_names=tuple(ctrl.diag_names),
            flags=flags,
            events=events,
            success=success,
            status=status,
            message=message,
            timings={"total": wall},
            step_times=step_times,
            sample_time=twin.sample_time,
            evaluate_from=scenario.evaluate_from,
        )


def _holding_current(twin: RigTwin, gap: float) -> np.ndarray:
    """Current that holds the true plant at ``gap`` (the run starts at rest, levitated);
    zero if no equilibrium exists there."""
    curve = equilibrium_currents(twin.model, [gap])
    return np.array([0.0, float(curve.current[0]) if curve.exists[0] else 0.0])


def simulate(
    twin: RigTwin,
    controller: ExpressionController | OnlineController,
    scenario: Scenario,
    *,
    seed: int = 0,
) -> SimulationResult:
    """One-off simulation; for several runs build a :class:`ClosedLoop` once and reuse it.

    Parameters
    ----------
    twin : RigTwin
    controller : ExpressionController or OnlineController
    scenario : Scenario
    seed : int
        Seed of the encoder noise.

    Returns
    -------
    SimulationResult
    """
    return ClosedLoop(twin, controller).run(scenario, seed=seed)
