"""The NMPC's terminal cost and the LQR it reduces to near an equilibrium.

Beyond node N the cost-to-go is that of the infinite-horizon LQR of the sampled linearization:
at the equilibrium of each tabulated gap the shooting step over one regular interval h is
linearized exactly (the same CasADi Function the OCP uses) and the DARE with stage weights
(h Q, h R) is solved. P is interpolated linearly in the gap of the terminal reference.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np
from scipy.linalg import solve_discrete_are

from maglev_oc.control.nmpc.grid import ShootingGrid
from maglev_oc.control.nmpc.layout import NX
from maglev_oc.control.nmpc.settings import NMPCWeights
from maglev_oc.model.equilibrium import equilibrium
from maglev_oc.model.stage import StageModel

__all__ = ["TERMINAL_GAPS", "LocalLQR", "TerminalCostTable", "local_lqr", "terminal_cost_table"]

TERMINAL_GAPS = np.linspace(10e-3, 30e-3, 21)
"""Gaps [m] at which the terminal weight P is tabulated (1 mm apart; linear in between)."""


@dataclass(frozen=True)
class TerminalCostTable:
    """Terminal weights P(gap) (4, 4) from the DARE of the RK4-discretized linearization.

    With this P the cost-to-go beyond node N equals that of the infinite-horizon LQR of the
    sampled linearization (module docstring).

    Attributes
    ----------
    gaps : (n,) array
        Tabulated gaps [m].
    P : (n, 4, 4) array
        Terminal weights (SI units, the cost's).
    gains : (n, 2, 4) array
        LQR gains of the regular interval, u - u_eq = -K (x - x_eq) [A/m, A s/m].
    """

    gaps: np.ndarray
    P: np.ndarray
    gains: np.ndarray

    def expression(self, gap):
        """P at ``gap`` (CasADi SX or MX scalar), linear between the tabulated gaps, clamped outside."""
        g = ca.fmin(ca.fmax(gap, float(self.gaps[0])), float(self.gaps[-1]))
        out = ca.SX.zeros(NX, NX) if isinstance(gap, ca.SX) else ca.MX.zeros(NX, NX)
        for c in range(NX):
            for r in range(c, NX):
                vals = self.P[:, r, c]
                if np.all(vals == 0):
                    continue
                e = ca.pw_lin(g, list(self.gaps), list(vals))
                out[r, c] = e
                if r != c:
                    out[c, r] = e
        return out

    def at(self, gap: float) -> np.ndarray:
        """P at a gap, linear between the tabulated gaps, clamped outside.

        Parameters
        ----------
        gap : float
            [m].

        Returns
        -------
        (4, 4) array
        """
        g = float(np.clip(gap, self.gaps[0], self.gaps[-1]))
        return np.array([[np.interp(g, self.gaps, self.P[:, r, c]) for c in range(NX)] for r in range(NX)])


@dataclass(frozen=True)
class LocalLQR:
    """The LQR of the sampled linearization at an equilibrium, as the NMPC sees it.

    Attributes
    ----------
    x_eq : (4,) array
        Equilibrium state [m, m/s, m, m/s].
    u_eq : (2,) array
        Equilibrium current [A].
    gain_first : (2, 4) array
        Law of the shortened first interval, u - u_eq = -K0 (x - x_eq), with
        K0 = (Ts R + B0' P B0)^-1 B0' P A0 [A/m, A s/m].
    gain : (2, 4) array
        The regular-interval DARE gain.
    P : (4, 4) array
        The terminal weight at the equilibrium's gap.
    """

    x_eq: np.ndarray
    u_eq: np.ndarray
    gain_first: np.ndarray
    gain: np.ndarray
    P: np.ndarray


def terminal_cost_table(
    model: StageModel,
    rk4_lin: ca.Function,
    weights: NMPCWeights,
    interval: float,
    gaps: np.ndarray = TERMINAL_GAPS,
) -> TerminalCostTable:
    """Solve the DARE at the equilibrium of every gap.

    Parameters
    ----------
    model : StageModel
        The controller's model.
    rk4_lin : casadi.Function
        (x, u, d, h) -> (x_next, A, B): the linearized shooting step.
    weights : NMPCWeights
    interval : float
        The regular shooting interval h [s].
    gaps : (n,) array
        Gaps [m] to tabulate.

    Returns
    -------
    TerminalCostTable
    """
    q = weights.state_weight * interval
    rr = weights.input_weight * interval
    ps, ks = [], []
    for gap in gaps:
        op = equilibrium(model, float(gap), current_limit=math.inf)
        _, a, b = rk4_lin(op.x, op.u, [0, 0], interval)
        a, b = np.asarray(a), np.asarray(b)
        p = solve_discrete_are(a, b, q, rr)
        p = 0.5 * (p + p.T)
        ps.append(p)
        ks.append(np.linalg.solve(rr + b.T @ p @ b, b.T @ p @ a))
    return TerminalCostTable(np.array(gaps, dtype=float), np.array(ps), np.array(ks))


def local_lqr(
    model: StageModel,
    rk4_lin: ca.Function,
    weights: NMPCWeights,
    grid: ShootingGrid,
    terminal: TerminalCostTable,
    gap: float,
    position: float = 0.0,
) -> LocalLQR:
    """The linear-quadratic law the NMPC reduces to near the equilibrium at ``gap``.

    Parameters
    ----------
    model, rk4_lin, weights
        As for :func:`terminal_cost_table`.
    grid : ShootingGrid
    terminal : TerminalCostTable
    gap : float
        Equilibrium gap [m].
    position : float
        Equilibrium horizontal position [m].

    Returns
    -------
    LocalLQR
    """
    op = equilibrium(model, gap, position, current_limit=math.inf)
    p = terminal.at(gap)
    ts, h = grid.sample_time, grid.interval
    _, a0, b0 = (np.asarray(v) for v in rk4_lin(op.x, op.u, [0, 0], ts))
    _, a, b = (np.asarray(v) for v in rk4_lin(op.x, op.u, [0, 0], h))
    rr = weights.input_weight
    k0 = np.linalg.solve(ts * rr + b0.T @ p @ b0, b0.T @ p @ a0)
    k = np.linalg.solve(h * rr + b.T @ p @ b, b.T @ p @ a)
    return LocalLQR(op.x, op.u, k0, k, p)
