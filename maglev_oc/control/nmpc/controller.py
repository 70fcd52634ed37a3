"""The NMPC as an online controller of the simulation engine: memory, reset, one update a sample."""

from __future__ import annotations

import dataclasses
import functools
import time
import warnings

import casadi as ca
import numpy as np

from maglev_oc.control.base import N_MEASUREMENTS
from maglev_oc.control.nmpc.converged import ConvergedSolver
from maglev_oc.control.nmpc.grid import node_references, shift_matrix
from maglev_oc.control.nmpc.layout import NU, NX, MemoryLayout, u_index, x_index
from maglev_oc.control.nmpc.rti import (
    PreparedLayout,
    python_entry,
    qp_solver_function,
    read_qp_statistics,
    rti_feedback_function,
    rti_parts,
    rti_prepare_function,
    rti_step_function,
)
from maglev_oc.control.nmpc.settings import NMPCSettings
from maglev_oc.control.nmpc.status import DIAG_NAMES, NMPCStep
from maglev_oc.control.nmpc.terminal import LocalLQR, TerminalCostTable
from maglev_oc.control.nmpc.transcription import Transcription
from maglev_oc.estimation.extended_high_gain import N_DISTURBANCE, ExtendedHighGainObserver
from maglev_oc.model.stage import StageModel

__all__ = ["NonlinearMPC"]


class NonlinearMPC:
    """Nonlinear MPC of the stage (an :class:`~maglev_oc.control.base.OnlineController`).

    Parameters
    ----------
    model : StageModel
        The controller's model (its constants may differ from the plant's).
    settings : NMPCSettings, optional
        Horizon, grid, weights, mode, QP solver, bounds, observer, ... (default
        :class:`NMPCSettings`).
    **options
        Fields of :class:`NMPCSettings` that replace those of ``settings``, e.g.
        ``NonlinearMPC(model, horizon=40, mode="converged")``; an unknown name raises TypeError.

    Attributes
    ----------
    rti_step : casadi.Function
        The whole RTI update, (memory, y (2), ref (6, N + 1)) -> (u (2), memory_next, diag (7)),
        as exported to C by :mod:`maglev_oc.control.codegen`.
    rti_prepare, rti_feedback : casadi.Function
        The same update split at the reading (:func:`~.rti.rti_prepare_function`,
        :func:`~.rti.rti_feedback_function`): (memory, ref) -> prepared, then (memory, prepared,
        y) -> (u, memory_next, diag); the QP linearized at the predicted initial state (initial
        value embedding), where :attr:`rti_step` linearizes at the estimate itself.
    n_prepared : int
        Entries of the prepared vector.
    grid : ShootingGrid
    shift : (6N, 6N) array
        The warm-start shift.
    diag_names : tuple of str
        :data:`~.status.DIAG_NAMES`, the rows of the diagnostics :meth:`control` returns.
    """

    def __init__(self, model: StageModel, settings: NMPCSettings | None = None, **options) -> None:
        if not isinstance(model, StageModel):
            raise TypeError(f"model must be a StageModel, got {type(model).__name__}")
        if settings is None:
            settings = NMPCSettings(**options)
        elif options:
            settings = dataclasses.replace(settings, **options)
        s = settings
        self.model = model
        self.settings = s
        self.sample_time = float(s.sample_time)
        self.grid = s.grid
        self.weights = s.weights
        self.mode = s.mode
        self.qp_solver = s.qp_solver
        self.qp_options = s.qp_options
        self.unconstrained_shortcut = s.unconstrained_shortcut
        self.preview = s.preview
        self.current_limit = float(s.current_limit)
        self.compiled = s.compile
        self.name = s.controller_name
        self.diag_names = DIAG_NAMES
        self._ocp = Transcription(
            model, self.grid, s.weights, s.current_limit, s.gap_bounds, s.position_bounds, s.effects
        )
        self._observer = ExtendedHighGainObserver(
            model,
            self.sample_time,
            s.observer_epsilon,
            s.disturbance_bandwidth,
            s.disturbance_limit,
            effects=s.effects,
        )
        self.shift = shift_matrix(self.grid)
        self.nz = self._ocp.nz
        self.na = self._ocp.na
        self._layout = MemoryLayout(self.nz)
        self.n_memory = self._layout.size
        parts = rti_parts(self._ocp, self._observer, self.shift)
        self.rti_step, self._rti_qp = self._rti_step(parts)
        self._parts = parts
        self.n_prepared = PreparedLayout.of(parts.qp_data).size
        # the controller's own copy (JIT-compiled parts if asked), with its own QP solver instance
        # so that the solver statistics read after each call are those of that call
        step, self._step_qp = self._rti_step(parts.compiled() if self.compiled else parts)
        self._step = python_entry(step, self.n_memory, self.grid.horizon)
        self._converged = (
            ConvergedSolver(self._ocp, self._observer, self.shift) if s.mode == "converged" else None
        )
        self._memory: np.ndarray | ca.DM | None = None
        self._u_last = np.zeros(NU)

    def _rti_step(self, parts) -> tuple[ca.Function, ca.Function]:
        """The RTI step Function and the QP solver (conic) inside it."""
        s = self.settings
        qp = qp_solver_function(s.qp_solver, s.qp_options, self.grid.horizon, parts.qp_data)
        step = rti_step_function(
            parts, qp, self._observer, horizon=self.grid.horizon, shortcut=s.unconstrained_shortcut
        )
        return step, qp

    @functools.cached_property
    def rti_prepare(self) -> ca.Function:
        """(memory, ref (6, N + 1)) -> prepared (built on first use: the export's)."""
        return rti_prepare_function(self._parts, self._observer, horizon=self.grid.horizon)

    @functools.cached_property
    def rti_feedback(self) -> ca.Function:
        """(memory, prepared, y (2)) -> (u (2), memory_next, diag (7)) (built on first use)."""
        s = self.settings
        qp = qp_solver_function(s.qp_solver, s.qp_options, self.grid.horizon, self._parts.qp_data)
        return rti_feedback_function(self._parts, qp, self._observer, horizon=self.grid.horizon)

    # ------------------------------------------------------------------------------------
    @property
    def terminal_cost(self) -> TerminalCostTable:
        """The terminal weights P(gap) of the OCP."""
        return self._ocp.terminal

    @property
    def node_offsets(self) -> np.ndarray:
        """Samples from the current one to each shooting node, (N + 1,)."""
        return self.grid.node_offsets

    def local_lqr(self, gap: float, position: float = 0.0) -> LocalLQR:
        """The LQR the NMPC coincides with near an equilibrium.

        Parameters
        ----------
        gap : float
            Equilibrium gap [m].
        position : float
            Equilibrium horizontal position [m].

        Returns
        -------
        LocalLQR
        """
        return self._ocp.local_lqr(gap, position)

    # ------------------------------------------------------------------------------------
    def initial_memory(self, y0, r0=None, u0=None) -> np.ndarray:
        """Controller memory at start.

        Parameters
        ----------
        y0 : (2,) array
            First encoder reading [m]; the observer starts there at rest.
        r0 : (6,) array, optional
            First reference sample (unused: the plan starts where the stage is).
        u0 : (2,) array, optional
            The current already flowing [A] (default zero), held by the whole plan.

        Returns
        -------
        array
            The memory (:class:`~.layout.MemoryLayout`): no disturbance, the plan holding the
            current position.
        """
        y0 = np.asarray(y0, dtype=float).reshape(N_MEASUREMENTS)
        u0 = np.zeros(NU) if u0 is None else np.asarray(u0, dtype=float).reshape(NU)
        at_rest = [y0[0], 0.0, y0[1], 0.0]  # the observer and every node: the reading, no velocity
        z = np.zeros(self.nz)
        for j in range(self.grid.horizon):
            z[u_index(j) : u_index(j) + NU] = u0
        for j in range(1, self.grid.horizon + 1):
            z[x_index(j) : x_index(j) + NX] = at_rest
        return np.concatenate([at_rest, np.zeros(N_DISTURBANCE), z])

    def reset(self, y0, r0, u0) -> None:
        """Prepare a run.

        Parameters
        ----------
        y0 : (2,) array
            First encoder reading [m].
        r0 : (6,) array
            First reference sample.
        u0 : (2,) array
            The current already flowing [A], also the last current applied.
        """
        self._memory = self.initial_memory(y0, r0, u0)
        self._u_last = np.asarray(u0, dtype=float).reshape(NU).copy()
        if self._converged is not None:
            self._converged.reset()

    def node_references(self, k: int, reference: np.ndarray) -> np.ndarray:
        """The reference at the shooting nodes from sample ``k`` on.

        Parameters
        ----------
        k : int
            Current sample.
        reference : (6, n) array
            The whole sampled reference.

        Returns
        -------
        (6, N + 1) array
            :func:`~.grid.node_references` with this controller's ``preview``.
        """
        return node_references(self.grid, k, reference, preview=self.preview)

    def control(self, k: int, y, reference: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One update (the engine's call).

        Parameters
        ----------
        k : int
            Sample index.
        y : (2,) array
            Encoder reading (gap, horizontal position) [m].
        reference : (6, n) array
            The whole sampled reference (for the preview).

        Returns
        -------
        u : (2,) array
            Current command (i_q, i_d) [A].
        diag : (7,) array
            Row of :data:`~.status.DIAG_NAMES` (:meth:`NMPCStep.from_diag` says it in words).
        """
        if self._memory is None:
            raise RuntimeError("NonlinearMPC.control() called before reset()")
        ref = self.node_references(k, reference)
        if self.mode == "rti":
            return self._control_rti(y, ref)
        u, self._memory, diag = self._converged.step(self._memory, y, ref)
        self._u_last = u
        return u, diag

    def _control_rti(self, y, ref) -> tuple[np.ndarray, np.ndarray]:
        yr = np.concatenate([np.asarray(y, dtype=float).ravel(), ref.ravel(order="F")])
        try:
            out, mem = self._step(self._memory, yr)
        except RuntimeError as err:  # defensive: the Function is built not to raise
            warnings.warn(
                f"NMPC step raised ({err}); applying the previous current", RuntimeWarning, stacklevel=2
            )
            return self._u_last.copy(), np.array([0.0, 0.0, np.nan, *self.disturbance, -1.0, np.nan])
        self._memory = mem
        out = np.array(out.nonzeros())
        u, diag = out[0:NU], out[NU:]
        if diag[DIAG_NAMES.index("qp_iterations")] < 0:
            read_qp_statistics(diag, self._step_qp)
        self._u_last = u
        return u, diag

    def step_rti(self, memory: np.ndarray, y, ref) -> NMPCStep:
        """One evaluation of :attr:`rti_step` on explicit inputs, the controller's own memory
        untouched (for analyses and tests).

        Parameters
        ----------
        memory : array
            Controller memory (:meth:`initial_memory`).
        y : (2,) array
            Encoder reading [m].
        ref : (6, N + 1) array
            Reference at the nodes.

        Returns
        -------
        NMPCStep
            The applied current, the next memory and what the update did.
        """
        t0 = time.perf_counter()
        u, mem, diag = self.rti_step(memory, y, ref)
        diag = diag.full().ravel()
        if diag[DIAG_NAMES.index("qp_iterations")] < 0:
            read_qp_statistics(diag, self._rti_qp)
        wall = time.perf_counter() - t0
        return NMPCStep.from_diag(u.full().ravel(), mem.full().ravel(), diag, timings={"step": wall})

    # ------------------------------------------------------------------------------------
    @property
    def memory(self) -> np.ndarray:
        """The controller memory (:class:`~.layout.MemoryLayout`): observer (p_v, q_v, p_h, q_h),
        disturbance (d_v, d_h), the shifted plan z (6N)."""
        if self._memory is None:
            raise RuntimeError("no memory before reset()")
        if isinstance(self._memory, ca.DM):
            return np.array(self._memory.nonzeros())
        return self._memory.copy()

    @property
    def disturbance(self) -> np.ndarray:
        """Current disturbance estimate (d_v, d_h) [m/s^2]."""
        return self.memory[self._layout.disturbance]

    def plan(self) -> tuple[np.ndarray, np.ndarray]:
        """The shifted plan as (states (4, N), inputs (2, N)) for nodes 1..N and 0..N-1."""
        z = self.memory[self._layout.plan]
        xs = np.array([z[x_index(j) : x_index(j) + NX] for j in range(1, self.grid.horizon + 1)]).T
        us = np.array([z[u_index(j) : u_index(j) + NU] for j in range(self.grid.horizon)]).T
        return xs, us
