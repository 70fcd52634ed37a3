"""Constrained Gauss-Newton for equality-constrained least squares: min |r(w)|^2 s.t. c(w) = 0.

Each iteration solves the sparse KKT system of the linearized problem,

    [J_r' J_r   J_c'] [dw]   [-J_r' r]
    [J_c        0   ] [ l] = [-c     ]

with SuperLU (Levenberg-Marquardt damping of J_r' J_r if the matrix is singular) and takes the
step with a backtracking line search on the l1 merit 0.5 |r|^2 + rho |c|_1 (Nocedal & Wright,
Numerical Optimization, 2nd ed., Sec. 18.3; rho from the multipliers). The multiple-shooting
output-error fit (:mod:`.output_error`) is its one user; the solver knows nothing of it.

Status words of :class:`GaussNewtonOutcome`: ``"converged"``, ``"iteration_limit"``,
``"kkt_singular"``, ``"line_search_failed"``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

__all__ = ["GaussNewtonOutcome", "constrained_gauss_newton", "constrained_inverse_rows"]

Linearization = tuple[np.ndarray, np.ndarray, sp.spmatrix, sp.spmatrix]
"""(r, c, J_r, J_c) at a point; Jacobians with respect to the scaled variables."""


@dataclass(frozen=True, eq=False)
class GaussNewtonOutcome:
    """Where the iteration stopped and the linearization there."""

    w: np.ndarray  # the variables (unscaled)
    r: np.ndarray
    c: np.ndarray
    Jr: sp.spmatrix
    Jc: sp.spmatrix
    status: str
    message: str
    iterations: int
    timings: dict[str, float] = field(default_factory=dict)  # [s] "linearize", "kkt_solves"

    @property
    def success(self) -> bool:
        return self.status == "converged"


def _kkt(H: sp.spmatrix, Jc: sp.spmatrix) -> sp.csc_matrix:
    return sp.bmat([[H, Jc.T], [Jc, None]], format="csc")


def _factor(H: sp.spmatrix, Jc: sp.spmatrix):
    """LU of the KKT matrix; damped (Levenberg-Marquardt) if the reduced Hessian is singular: H +
    1e-6 max(max diag H, 1) I, so a direction the data do not determine takes a step of at most
    1e6 times its gradient over that scale, and the determined ones move by a relative 1e-6.
    Raises RuntimeError if even the damped one is."""
    try:
        return splu(_kkt(H, Jc))
    except RuntimeError:
        damp = 1e-6 * max(float(H.diagonal().max()), 1.0) * sp.identity(H.shape[0], format="csc")
        return splu(_kkt(H + damp, Jc))


def constrained_gauss_newton(
    linearize: Callable[[np.ndarray], Linearization],
    w0: np.ndarray,
    scale: np.ndarray,
    *,
    max_iterations: int = 30,
    tolerance: float = 1e-9,
    constraint_tolerance: float = 1e-6,
) -> GaussNewtonOutcome:
    """Solve from ``w0``; ``linearize(w)`` gives (r, c, J_r, J_c) with the Jacobians taken with
    respect to w / ``scale`` (so a step in them is multiplied by ``scale``).

    Stops when the scaled step is below ``tolerance`` (or a full step below 1000 ``tolerance``)
    with every |c| below ``constraint_tolerance``.
    """
    w = np.asarray(w0, dtype=float).copy()
    times = {"linearize": 0.0, "kkt_solves": 0.0}

    def lin(at: np.ndarray) -> Linearization:
        t = time.perf_counter()
        out = linearize(at)
        times["linearize"] += time.perf_counter() - t
        return out

    def merit(r, c, rho):
        return 0.5 * float(r @ r) + rho * float(np.sum(np.abs(c)))

    r, c, Jr, Jc = lin(w)
    status, message, iterations, rho = "iteration_limit", "maximum iterations reached", 0, 1.0
    for it in range(1, max_iterations + 1):
        iterations = it
        ts = time.perf_counter()
        H = (Jr.T @ Jr).tocsc()
        g = Jr.T @ r
        try:
            lu = _factor(H, Jc)
        except RuntimeError as err:
            status, message = "kkt_singular", f"KKT matrix singular: {err}"
            break
        sol = lu.solve(np.concatenate([-g, -c]))
        step, lam = sol[: H.shape[0]], sol[H.shape[0] :]
        times["kkt_solves"] += time.perf_counter() - ts
        rho = max(rho, 2.0 * float(np.max(np.abs(lam)))) if lam.size else rho
        m0 = merit(r, c, rho)
        slope = float(g @ step) - rho * float(np.sum(np.abs(c)))  # Nocedal & Wright eq. (18.29)
        alpha = 1.0
        while alpha > 1e-4:
            w_try = w + alpha * step * scale
            r_t, c_t, Jr_t, Jc_t = lin(w_try)
            if np.all(np.isfinite(r_t)) and merit(r_t, c_t, rho) <= m0 + 1e-4 * alpha * min(slope, 0.0):
                break
            alpha *= 0.5
        else:
            status, message = "line_search_failed", "line search failed"
            break
        w, r, c, Jr, Jc = w_try, r_t, c_t, Jr_t, Jc_t
        c_max = float(np.max(np.abs(c))) if c.size else 0.0
        largest = float(np.max(np.abs(step)))
        if c_max < constraint_tolerance and alpha * largest < tolerance:
            status, message = "converged", f"converged: scaled step below {tolerance:g}, continuity met"
            break
        if c_max < constraint_tolerance and alpha == 1.0 and largest < 1e3 * tolerance:
            status, message = "converged", f"converged: scaled step {largest:.2g}, continuity met"
            break
    return GaussNewtonOutcome(w, r, c, Jr, Jc, status, message, iterations, times)


def constrained_inverse_rows(Jr: sp.spmatrix, Jc: sp.spmatrix, q: int) -> np.ndarray:
    """The first ``q`` rows of the variable block of the inverse KKT matrix, shape (q, n_var):
    the sensitivity of the first q (scaled) variables to the gradient, from which their
    covariance follows. Raises RuntimeError if the KKT matrix is singular."""
    H = (Jr.T @ Jr).tocsc()
    lu = splu(_kkt(H, Jc))
    E = np.zeros((H.shape[0] + Jc.shape[0], q))
    E[np.arange(q), np.arange(q)] = 1.0
    return lu.solve(E)[: H.shape[0]].T
