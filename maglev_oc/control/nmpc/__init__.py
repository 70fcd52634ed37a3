"""Nonlinear model predictive control of the stage: multiple shooting, RK4, real-time iteration.

The optimal control problem (OCP) solved at every sample k, on the controller's own
:class:`~maglev_oc.model.stage.StageModel` with constant acceleration disturbances d = (d_v, d_h):

    min   sum_{j<N} h_j [ |x_j - xr_j|_Q^2 + |u_j - ur_j|_R^2 ]  +  |x_N - xr_N|_P(r_v,N)^2
    s.t.  x_0 = x^(k)                           (observer estimate, initial-value embedding)
          x_{j+1} = RK4(x_j, u_j, d; h_j)        (one RK4 step per shooting interval)
          current polytope:  |u_1|, |u_2| <= r,  |u_1 +- u_2| <= sqrt(2) r,   r = I_max cos(pi/8)
          gap and horizontal bounds on x_j, j >= 2

with f(x, u, d) = f(x, u) + (0, d_v, 0, d_h) (SPEC 1; 001 Sec. V models the friction and
misalignment the same way, as constant Delta_1, Delta_2 on x4', x2').

One concept per module:

* :mod:`.settings` — :class:`NMPCSettings` and :class:`NMPCWeights` (the weights' rationale);
* :mod:`.grid` — the shooting grid of the 5 kHz loop, the reference preview, the warm-start shift;
* :mod:`.layout` — where things sit in the decision vector, the constraint rows, the memory;
* :mod:`.transcription` — the OCP by multiple shooting (RK4), the Gauss-Newton QP data;
* :mod:`.terminal` — the terminal cost (DARE) and the local LQR the NMPC reduces to;
* :mod:`.riccati` — the unconstrained shortcut (Riccati recursion of the LQ problem);
* :mod:`.rti` — the real-time iteration as one CasADi Function, its QP solver and checks;
* :mod:`.converged` — IPOPT to convergence every sample (a reference, not real time);
* :mod:`.status` — the diagnostics row and :class:`NMPCStep`, an update in words;
* :mod:`.controller` — :class:`NonlinearMPC`, the online controller of the simulation engine.

The state and disturbance estimate (offset-free tracking) is
:class:`~maglev_oc.estimation.extended_high_gain.ExtendedHighGainObserver`; the C export of the
RTI step is :mod:`maglev_oc.control.codegen`.
"""

from maglev_oc.control.nmpc.controller import NonlinearMPC
from maglev_oc.control.nmpc.grid import ShootingGrid, shift_matrix
from maglev_oc.control.nmpc.settings import (
    DEFAULT_DISTURBANCE_BANDWIDTH,
    DEFAULT_DISTURBANCE_LIMIT,
    DEFAULT_GAP_BOUNDS,
    DEFAULT_HORIZON,
    DEFAULT_INTERVAL,
    DEFAULT_POSITION_BOUNDS,
    MODES,
    QP_SOLVERS,
    NMPCSettings,
    NMPCWeights,
)
from maglev_oc.control.nmpc.status import DIAG_NAMES, STATUSES, NMPCStep, step_status
from maglev_oc.control.nmpc.terminal import LocalLQR, TerminalCostTable

__all__ = [
    "DEFAULT_DISTURBANCE_BANDWIDTH",
    "DEFAULT_DISTURBANCE_LIMIT",
    "DEFAULT_GAP_BOUNDS",
    "DEFAULT_HORIZON",
    "DEFAULT_INTERVAL",
    "DEFAULT_POSITION_BOUNDS",
    "DIAG_NAMES",
    "MODES",
    "QP_SOLVERS",
    "STATUSES",
    "LocalLQR",
    "NMPCSettings",
    "NMPCStep",
    "NMPCWeights",
    "NonlinearMPC",
    "ShootingGrid",
    "TerminalCostTable",
    "shift_matrix",
    "step_status",
]
