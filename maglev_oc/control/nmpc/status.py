"""What one NMPC update did: the numeric diagnostics row, and its translation into a result.

Inside the CasADi Function (and in the generated C) the diagnostics are numbers, one row of
:data:`DIAG_NAMES` per sample; the simulation engine stores them as such. At the Python
boundary :class:`NMPCStep` says the same in words: ``success``, a ``status`` from
:data:`STATUSES` and a ``message`` (the convention of :mod:`maglev_oc.results`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from maglev_oc.results import PerAxis, Result

__all__ = ["DIAG_NAMES", "STATUSES", "NMPCStep", "step_status"]

DIAG_NAMES = ("solver_ok", "qp_iterations", "cost", "d_v", "d_h", "active_constraints", "qp_status")
"""Diagnostics per sample: ``solver_ok`` 1 if the solution passed the checks (else the fallback
was applied); ``qp_iterations`` of the QP solver (0: the unconstrained Riccati step was feasible
and no QP was solved; IPOPT's iterations in converged mode); ``cost`` of the applied plan [-];
``d_v``, ``d_h`` the disturbance estimates [m/s^2]; ``active_constraints`` the number of
inequalities active in the solution (-1 when it failed); ``qp_status`` -1 no QP solved, 0 the
solver reported success, 1 it reported a failure (iteration limit, infeasibility). The generated
C leaves qp_iterations at -1 and qp_status at NaN on QP samples (no solver statistics there)."""

_COL = {name: i for i, name in enumerate(DIAG_NAMES)}

STATUSES: Mapping[str, str] = MappingProxyType(
    {
        "unconstrained": "the unconstrained (Riccati) step satisfied every bound; no QP was solved",
        "qp_solved": "the QP solver converged and its solution passed the checks",
        "qp_accepted": "the QP solver reported a failure but its solution passed the checks",
        "qp_unreported": "the QP solution passed the checks; the solver's statistics were not available",
        "converged": "IPOPT converged",
        "fallback": "no solution passed the checks (the solver failed or ran out of its iteration "
        "budget); the real-time iteration applied the unconstrained (Riccati) step, its currents "
        "projected onto the limits, the converged mode the shifted previous plan",
    }
)
"""The status words of :class:`NMPCStep` and what each means."""


def step_status(diag, mode: str = "rti") -> str:
    """The status word (:data:`STATUSES`) of one diagnostics row.

    Parameters
    ----------
    diag : (7,) array
        One row of :data:`DIAG_NAMES`.
    mode : {"rti", "converged"}
        The mode of the controller that wrote it.

    Returns
    -------
    str
    """
    diag = np.asarray(diag, dtype=float)
    if diag[_COL["solver_ok"]] != 1:
        return "fallback"
    if mode == "converged":
        return "converged"
    qp_status = diag[_COL["qp_status"]]
    if math.isnan(qp_status):
        return "qp_unreported"
    return {-1.0: "unconstrained", 0.0: "qp_solved"}.get(float(qp_status), "qp_accepted")


@dataclass(frozen=True)
class NMPCStep(Result):
    """One NMPC update, for analyses and tests (the engine calls ``NonlinearMPC.control``).

    Attributes
    ----------
    success : bool
        The solution passed the checks (finite, dynamics residual and constraint violation
        below tolerance); otherwise the fallback was applied.
    status : str
        A word of :data:`STATUSES`.
    message : str
    timings : mapping
        ``{"step": wall time of the update [s]}``.
    u : (2,) array
        The current applied (i_q, i_d) [A].
    memory_next : array
        The controller memory after the update (:class:`~.layout.MemoryLayout`).
    qp_iterations : int
        Iterations of the QP solver (IPOPT in converged mode); 0 when no QP was solved, -1 when
        not reported.
    cost : float
        Cost of the applied plan [-] (NaN if not finite).
    disturbance : PerAxis
        Disturbance estimate (d_v, d_h) [m/s^2] used by this update.
    active_constraints : int
        Inequalities active in the solution (-1 when it failed).
    diag : (7,) array
        The numeric row (:data:`DIAG_NAMES`), as the generated C and the engine see it.
    """

    success: bool
    status: str
    message: str
    u: np.ndarray = field(repr=False)
    memory_next: np.ndarray = field(repr=False)
    qp_iterations: int
    cost: float
    disturbance: PerAxis
    active_constraints: int
    diag: np.ndarray = field(repr=False)
    timings: Mapping[str, float] = field(default_factory=dict)

    @classmethod
    def from_diag(
        cls, u, memory_next, diag, *, mode: str = "rti", timings: Mapping[str, float] | None = None
    ) -> NMPCStep:
        """The result of an update from its outputs and numeric diagnostics row.

        Parameters
        ----------
        u : (2,) array
            Applied current [A].
        memory_next : array
            Memory after the update.
        diag : (7,) array
            Row of :data:`DIAG_NAMES`.
        mode : {"rti", "converged"}
        timings : mapping, optional
            Wall times [s] by step name.

        Returns
        -------
        NMPCStep
        """
        diag = np.asarray(diag, dtype=float).ravel()
        status = step_status(diag, mode)
        return cls(
            success=status != "fallback",
            status=status,
            message=STATUSES[status],
            u=np.asarray(u, dtype=float).ravel(),
            memory_next=np.asarray(memory_next, dtype=float).ravel(),
            qp_iterations=_count(diag[_COL["qp_iterations"]]),
            cost=float(diag[_COL["cost"]]),
            disturbance=PerAxis(float(diag[_COL["d_v"]]), float(diag[_COL["d_h"]])),
            active_constraints=_count(diag[_COL["active_constraints"]]),
            diag=diag,
            timings=dict(timings or {}),
        )


def _count(value: float) -> int:
    """A count from the numeric row; -1 where it is not reported (NaN)."""
    return int(value) if math.isfinite(value) else -1
