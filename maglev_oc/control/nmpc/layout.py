"""Where things sit in the NMPC's vectors: the decision vector, the constraint rows, the memory.

Three sizes of the transcription happen to be six; each has its own name here:

* :data:`STAGE_SIZE` = NX + NU: the entries of the decision vector per shooting interval. The
  decision vector is z = (u_0, x_1, u_1, ..., x_{N-1}, u_{N-1}, x_N): x_0 is not a variable (it
  is the estimate), so z has STAGE_SIZE N entries.
* :data:`STAGE_ROWS` = NX + N_POLYTOPE_ROWS: the constraint rows per interval, the dynamics
  (NX) then the current polytope (2), so A has STAGE_ROWS N rows.
* :class:`MemoryLayout`: the controller memory is the observer state (4), the disturbance
  estimate (2) and the plan z; the plan starts at entry 6.

(The reference sample has six rows too, :data:`~maglev_oc.control.base.N_REFERENCE`.)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from maglev_oc.estimation.extended_high_gain import N_DISTURBANCE, N_OBSERVER_STATE
from maglev_oc.model.stage import N_INPUTS, N_STATES

__all__ = [
    "NU",
    "NX",
    "N_POLYTOPE_ROWS",
    "STAGE_ROWS",
    "STAGE_SIZE",
    "MemoryLayout",
    "u_index",
    "x_index",
]

NX = N_STATES
"""States (x1, x2, x3, x4) = (gap, gap rate, position, position rate) [m, m/s, m, m/s]."""
NU = N_INPUTS
"""Inputs (i_q, i_d) [A]."""
N_POLYTOPE_ROWS = 2
"""Rows D u of the current octagon per interval: i_q + i_d and i_q - i_d."""
STAGE_SIZE = NX + NU
"""Entries of the decision vector z per shooting interval (u_j, x_{j+1})."""
STAGE_ROWS = NX + N_POLYTOPE_ROWS
"""Constraint rows per shooting interval: dynamics (NX), then the current polytope."""


def x_index(j: int) -> int:
    """First entry of x_j in z (j = 1..N)."""
    return NU + (j - 1) * STAGE_SIZE


def u_index(j: int) -> int:
    """First entry of u_j in z (j = 0..N-1)."""
    return 0 if j == 0 else NU + (j - 1) * STAGE_SIZE + NX


@dataclass(frozen=True)
class MemoryLayout:
    """The controller memory: observer state, disturbance estimate, then the plan z.

    Parameters
    ----------
    nz : int
        Entries of the decision vector z (STAGE_SIZE N).

    Attributes
    ----------
    observer : slice
        (p_v, q_v, p_h, q_h) [m, m/s]: the extended high-gain observer's position and velocity.
    disturbance : slice
        (d_v, d_h) [m/s^2].
    plan : slice
        The (shifted) plan z, to the end of the memory.
    size : int
        Entries of the memory.
    """

    nz: int
    observer: ClassVar[slice] = slice(0, N_OBSERVER_STATE)
    disturbance: ClassVar[slice] = slice(N_OBSERVER_STATE, N_OBSERVER_STATE + N_DISTURBANCE)
    plan_start: ClassVar[int] = N_OBSERVER_STATE + N_DISTURBANCE

    @property
    def plan(self) -> slice:
        return slice(self.plan_start, self.plan_start + self.nz)

    @property
    def size(self) -> int:
        return self.plan_start + self.nz
