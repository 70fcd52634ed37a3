"""The converged solve (``mode="converged"``): the NMPC's NLP solved by IPOPT every sample.

The same OCP as the RTI (:mod:`.transcription`), with the exact Hessian, solved to convergence
and warm-started by the same shift and by the previous multipliers: a reference for the RTI,
not real time. A failed solve never raises: the shifted previous plan (or the feedforward
current of the reference), projected on the current octagon, is applied and ``solver_ok`` is 0.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from maglev_oc.control.base import N_MEASUREMENTS, N_REFERENCE
from maglev_oc.control.nmpc.layout import N_POLYTOPE_ROWS, NU, NX, STAGE_ROWS, MemoryLayout
from maglev_oc.control.nmpc.transcription import OCTAGON, Transcription
from maglev_oc.estimation.extended_high_gain import N_DISTURBANCE, N_OBSERVER_STATE, ExtendedHighGainObserver

__all__ = ["IPOPT_OPTIONS", "ConvergedSolver"]

IPOPT_OPTIONS = {
    "tol": 1e-10,
    "acceptable_tol": 1e-8,
    "max_iter": 200,
    "warm_start_init_point": "yes",
    "mu_strategy": "adaptive",
}
"""IPOPT's options in the converged mode (besides silencing its output)."""


class ConvergedSolver:
    """IPOPT on the NMPC's NLP, warm-started from one sample to the next.

    Parameters
    ----------
    ocp : Transcription
    observer : ExtendedHighGainObserver
    shift : (6N, 6N) array
        The warm-start shift (:func:`~.grid.shift_matrix`).
    """

    def __init__(self, ocp: Transcription, observer: ExtendedHighGainObserver, shift: np.ndarray) -> None:
        self._ocp = ocp
        self._shift = shift
        self._layout = MemoryLayout(ocp.nz)
        self._cost = ocp.objective_function()
        self._nlp = self._build_nlp()
        lim = math.sqrt(2) * ocp.radius
        self._lbg = np.tile(np.r_[np.zeros(NX), -lim, -lim], ocp.N)
        self._ubg = np.tile(np.r_[np.zeros(NX), lim, lim], ocp.N)
        self._lbz, self._ubz = ocp.bounds()
        obs = ca.SX.sym("obs", N_OBSERVER_STATE)
        d = ca.SX.sym("d", N_DISTURBANCE)
        y = ca.SX.sym("y", N_MEASUREMENTS)
        u = ca.SX.sym("u", NU)
        o_n, d_n = observer.update(obs, d, y, u)
        self._estimator = ca.Function("nmpc_estimator", [obs, d, y, u], [o_n, d_n])
        self.reset()

    def _build_nlp(self) -> ca.Function:
        ocp = self._ocp
        n, nz = ocp.N, ocp.nz
        z = ca.SX.sym("z", nz)
        x0 = ca.SX.sym("x0", NX)
        d = ca.SX.sym("d", N_DISTURBANCE)
        ref = ca.SX.sym("ref", N_REFERENCE, n + 1)
        xs, us = ocp.stage_states(z, x0)
        g = []
        for j in range(n):
            g.append(ocp.rk4(xs[j], us[j], d, float(ocp.grid.intervals[j])) - xs[j + 1])
            g.append(ca.mtimes(ca.DM(OCTAGON), us[j]))
        p = ca.vertcat(x0, d, ca.vec(ref))
        nlp = {"x": z, "p": p, "f": self._cost(z, d, ref), "g": ca.vertcat(*g)}
        opts = {
            "print_time": False,
            "error_on_fail": False,
            "ipopt": {"print_level": 0, "sb": "yes", **IPOPT_OPTIONS},
        }
        return ca.nlpsol("nmpc_nlp", "ipopt", nlp, opts)

    def reset(self) -> None:
        """Forget the multipliers (the next solve starts from the plan alone)."""
        self._lam_g: np.ndarray | None = None
        self._lam_x: np.ndarray | None = None

    def step(self, memory: np.ndarray, y, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One converged update.

        Parameters
        ----------
        memory : array
            Controller memory (:class:`~.layout.MemoryLayout`).
        y : (2,) array
            Encoder reading [m].
        ref : (6, N + 1) array
            Reference at the nodes.

        Returns
        -------
        u : (2,) array
            Applied current [A].
        memory_next : array
        diag : (7,) array
            Row of :data:`~.status.DIAG_NAMES` (``qp_iterations`` are IPOPT's).
        """
        y = np.asarray(y, dtype=float).ravel()
        lay = self._layout
        obs, d, zb = memory[lay.observer], memory[lay.disturbance], memory[lay.plan]
        x0 = np.array([y[0], obs[1], y[1], obs[3]])
        p = np.concatenate([x0, d, ref.ravel(order="F")])
        ok, z, iters = self._solve(zb, p)
        if ok:
            u = z[0:NU].copy()
        else:
            z = zb
            self._lam_g = None
            u = np.asarray(self._fallback(zb, d, ref)).ravel()
        cost = float(self._cost(z, d, ref)) if np.all(np.isfinite(z)) else np.nan
        obs_n, d_n = self._estimator(obs, d, y, u)
        memory_next = np.concatenate([np.asarray(obs_n).ravel(), np.asarray(d_n).ravel(), self._shift @ z])
        active = -1.0
        if ok:
            per_stage = self._lam_g.reshape(-1, STAGE_ROWS)[:, NX : NX + N_POLYTOPE_ROWS]
            lam = np.concatenate([self._lam_x, per_stage.ravel()])
            active = float(np.sum(np.abs(lam) > 1e-9))
        return u, memory_next, np.array([float(ok), iters, cost, *d, active, 0.0 if ok else 1.0])

    def _solve(self, zb: np.ndarray, p: np.ndarray) -> tuple[bool, np.ndarray | None, int]:
        """(ok, z, iterations) of IPOPT from the plan ``zb`` with parameters ``p``; the
        multipliers are kept for the next solve when it succeeds."""
        if not np.all(np.isfinite(p)):
            return False, None, 0
        args = {"x0": zb, "p": p, "lbx": self._lbz, "ubx": self._ubz, "lbg": self._lbg, "ubg": self._ubg}
        if self._lam_g is not None:
            args["lam_g0"] = self._lam_g
            args["lam_x0"] = self._lam_x
        sol = self._nlp(**args)
        stats = self._nlp.stats()
        z = sol["x"].full().ravel()
        ok = bool(stats["success"]) and bool(np.all(np.isfinite(z)))
        if ok:
            self._lam_g = sol["lam_g"].full().ravel()
            self._lam_x = sol["lam_x"].full().ravel()
        return ok, z, stats.get("iter_count", 0)

    def _fallback(self, zb, d, ref):
        """The plan's first input if finite, else the reference's feedforward, in the octagon."""
        u = (
            zb[0:NU]
            if np.all(np.isfinite(zb[0:NU]))
            else np.asarray(self._ocp.feedforward(ref[:, 0], d)).ravel()
        )
        r = self._ocp.radius
        m = max(abs(u[0]), abs(u[1]), abs(u[0] + u[1]) / math.sqrt(2), abs(u[0] - u[1]) / math.sqrt(2))
        return u / max(1.0, m / r)
