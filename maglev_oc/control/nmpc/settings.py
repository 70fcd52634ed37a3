"""What an NMPC is made of: its weights and settings, validated when they are made.

Weights (defaults, :class:`NMPCWeights`)
    Q = diag(1e6, 1e2, 1e6, 1e2), R = diag(1, 1) per second in SI units: 1 mm of position
    error costs as much as 1 A of current beyond the feedforward (position gains of the LQR
    ~1000-1500 A/m), 10 mm/s of velocity error as much as 0.1 mm of position. The LQR on the
    linearization then has its poles at magnitudes 55-110 rad/s (damping 0.75-0.96) over
    10-29 mm (the vertical pair can not be slower than the mirror of the unstable pole, 30-64
    rad/s): 4-7x faster than the papers' regulators, which matters against friction reversals
    (a 1.3 N Coulomb step on the 1.6 kg horizontal mover costs 0.8 m/s^2 / 6700 s^-2 = 0.1 mm
    of error before the disturbance estimate catches up), yet 5-10x below the observer (500
    rad/s) and 60x below the amplifier (6300 rad/s). Encoder quantization (10 um, and about
    5 mm/s of velocity noise through the observer) maps to ~0.01 A + 0.1 A of current noise.
    Large steps are shaped by the current polytope, not by the weights.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import casadi as ca
import numpy as np

from maglev_oc.control.nmpc.grid import ShootingGrid
from maglev_oc.errors import InputError
from maglev_oc.estimation.extended_high_gain import DEFAULT_DISTURBANCE_BANDWIDTH, DEFAULT_DISTURBANCE_LIMIT
from maglev_oc.estimation.high_gain import DEFAULT_EPSILON
from maglev_oc.model.hardware import PEAK_CURRENT_LIMIT, RIG_SAMPLE_TIME

__all__ = [
    "DEFAULT_DISTURBANCE_BANDWIDTH",
    "DEFAULT_DISTURBANCE_LIMIT",
    "DEFAULT_GAP_BOUNDS",
    "DEFAULT_HORIZON",
    "DEFAULT_INTERVAL",
    "DEFAULT_POSITION_BOUNDS",
    "MODES",
    "QP_SOLVERS",
    "NMPCSettings",
    "NMPCWeights",
]

MODES = ("rti", "converged")
"""One Gauss-Newton SQP step per sample (:mod:`.rti`) or IPOPT to convergence (:mod:`.converged`)."""
QP_SOLVERS = ("hpipm", "qrqp", "osqp")
"""Sparse QP solvers of the RTI (see :mod:`.rti`)."""
DEFAULT_INTERVAL = 5e-3
"""Shooting interval after the first (one-sample) interval [s]; see :mod:`.grid`."""
DEFAULT_HORIZON = 20
"""Shooting intervals N: Ts + 95 ms of preview with the default interval."""
DEFAULT_GAP_BOUNDS = (10e-3, 29e-3)
"""Gap bounds [m]: the 10 mm end is where the model's verified range ends (cogging > 1 N below
15 mm, 000 Sec. V-C) widened to the travel; the upper one keeps 1 mm from the 30 mm stopper."""
DEFAULT_POSITION_BOUNDS = (-55e-3, 55e-3)
"""Horizontal bounds [m]: the +-50 mm travel plus 5 mm, inside the +-60 mm stoppers."""


@dataclass(frozen=True)
class NMPCWeights:
    """Weights of the integrated tracking cost (per second of horizon, SI units).

    The stage cost is ``gap (x1 - r_v)^2 + gap_rate (x2 - r_v')^2 + position (x3 - r_h)^2 +
    position_rate (x4 - r_h')^2 + i_q (u1 - ur1)^2 + i_d (u2 - ur2)^2`` where ur is the
    feedforward current of the reference.

    Parameters
    ----------
    gap, position : float
        Position weights [1/(m^2 s)], non-negative.
    gap_rate, position_rate : float
        Velocity weights [s/m^2], non-negative.
    i_q, i_d : float
        Current weights [1/(A^2 s)], positive.
    """

    gap: float = 1e6
    gap_rate: float = 1e2
    position: float = 1e6
    position_rate: float = 1e2
    i_q: float = 1.0
    i_d: float = 1.0

    def __post_init__(self) -> None:
        for name in ("gap", "gap_rate", "position", "position_rate", "i_q", "i_d"):
            value = getattr(self, name)
            positive = name in ("i_q", "i_d")
            if (
                not (isinstance(value, (int, float)) and math.isfinite(value))
                or value < 0
                or (positive and value == 0)
            ):
                kind = "positive" if positive else "non-negative"
                raise InputError(f"NMPCWeights.{name} must be {kind} and finite, got {value!r}")

    @property
    def state_weight(self) -> np.ndarray:
        """Q (4, 4)."""
        return np.diag([self.gap, self.gap_rate, self.position, self.position_rate]).astype(float)

    @property
    def input_weight(self) -> np.ndarray:
        """R (2, 2)."""
        return np.diag([self.i_q, self.i_d]).astype(float)


@dataclass(frozen=True)
class NMPCSettings:
    """Everything that defines a :class:`~maglev_oc.control.nmpc.NonlinearMPC` but the model.

    Parameters
    ----------
    horizon : int
        Number of shooting intervals N (default 20; 40 works too).
    interval : float
        Regular shooting interval [s] (default 5 ms); a multiple of ``sample_time``.
    sample_time : float
        Controller period [s] (default 2e-4, 5 kHz); also the first shooting interval.
    weights : NMPCWeights, optional
        Tracking weights (default :class:`NMPCWeights`).
    mode : {"rti", "converged"}
        One Gauss-Newton SQP step per sample (real time) or IPOPT to convergence (reference).
    qp_solver : {"hpipm", "qrqp", "osqp"}
        Sparse QP solver of the RTI.
    current_limit : float
        Amplifier peak current [A]; the current vector is kept in the inscribed regular octagon
        (facets at 0.924 of the limit, vertices on the circle).
    gap_bounds, position_bounds : (float, float)
        State bounds [m] on x1 and x3 at nodes 2..N.
    observer_epsilon : float
        High-gain observer time constant [s].
    disturbance_bandwidth : float
        w_d [rad/s] of the disturbance estimate; 0 switches the disturbance estimate off.
    disturbance_limit : float
        |d| clip [m/s^2].
    qp_options : mapping
        Options merged into the QP solver's (e.g. ``{"hpipm": {"mode": "robust"}}``).
    preview : bool
        Read the future reference from the reference array (default), or extrapolate the current
        sample (causal, like the papers' regulators: set-point steps are not anticipated).
    unconstrained_shortcut : bool
        Take the Riccati step when it is feasible (default) or solve the QP every sample.
    compile : bool
        JIT-compile the three SX parts of the RTI step with the system C compiler (CasADi
        ``jit``, -O1: 10-25 s once; then 2.5-3x faster calls, 0.13 ms instead of 0.31-0.36 ms
        at N = 20 on the 2-core test machine). Without a C compiler the parts run in CasADi's
        VM. The C export (:mod:`maglev_oc.control.codegen`) does not use it.
    name : str, optional
        Default "NMPC" (the name the comparison plots know), "NMPC (converged, IPOPT)".
    effects : casadi.Function, optional
        (x (4), i (2)) -> (x2', x4') [m/s^2]: accelerations added to the model's in the
        prediction, the observer and the feedforward (the model augmented with found effects,
        e.g. ``StageFile.plant_effects()`` of a diagnosis). Default none.

    Attributes
    ----------
    grid : ShootingGrid
        The shooting grid: one sample, then N - 1 intervals of ``interval``.
    controller_name : str
        ``name``, or the default of the mode.

    Raises
    ------
    InputError
        (a ``ValueError``) naming the offending setting and value.
    TypeError
        For ``weights`` that are not :class:`NMPCWeights` (and, as for any dataclass, for an
        unknown keyword).
    """

    horizon: int = DEFAULT_HORIZON
    interval: float = DEFAULT_INTERVAL
    sample_time: float = RIG_SAMPLE_TIME
    weights: NMPCWeights | None = None
    mode: str = "rti"
    qp_solver: str = "hpipm"
    current_limit: float = PEAK_CURRENT_LIMIT
    gap_bounds: tuple[float, float] = DEFAULT_GAP_BOUNDS
    position_bounds: tuple[float, float] = DEFAULT_POSITION_BOUNDS
    observer_epsilon: float = DEFAULT_EPSILON
    disturbance_bandwidth: float = DEFAULT_DISTURBANCE_BANDWIDTH
    disturbance_limit: float = DEFAULT_DISTURBANCE_LIMIT
    qp_options: Mapping[str, Any] = field(default_factory=dict)
    preview: bool = True
    unconstrained_shortcut: bool = True
    compile: bool = False
    name: str | None = None
    effects: ca.Function | None = None
    grid: ShootingGrid = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._check_choices()
        self._check_timing()
        self._check_bounds()
        self._check_disturbance()
        self._check_effects()
        weights = NMPCWeights() if self.weights is None else self.weights
        if not isinstance(weights, NMPCWeights):
            raise TypeError(f"weights must be NMPCWeights, got {type(weights).__name__}")
        for key, value in (
            ("weights", weights),
            ("gap_bounds", tuple(self.gap_bounds)),
            ("position_bounds", tuple(self.position_bounds)),
            ("qp_options", MappingProxyType(dict(self.qp_options or {}))),
            ("preview", bool(self.preview)),
            ("unconstrained_shortcut", bool(self.unconstrained_shortcut)),
            ("compile", bool(self.compile)),
            (
                "grid",
                ShootingGrid(
                    float(self.sample_time), round(self.interval / self.sample_time), int(self.horizon)
                ),
            ),
        ):
            object.__setattr__(self, key, value)

    def _check_choices(self) -> None:
        if self.mode not in MODES:
            raise InputError(f"mode must be one of {MODES}, got {self.mode!r}")
        if self.qp_solver not in QP_SOLVERS:
            raise InputError(f"qp_solver must be one of {QP_SOLVERS}, got {self.qp_solver!r}")

    def _check_timing(self) -> None:
        ts = self.sample_time
        if not (ts > 0 and math.isfinite(ts)):
            raise InputError(f"sample_time must be positive [s], got {ts!r}")
        ratio = self.interval / ts
        if not (math.isfinite(ratio) and ratio >= 1 and abs(ratio - round(ratio)) < 1e-9):
            raise InputError(
                f"interval must be a positive multiple of sample_time {ts} s, got {self.interval!r}"
            )

    def _check_bounds(self) -> None:
        if not (math.isfinite(self.current_limit) and self.current_limit > 0):
            raise InputError(f"current_limit must be positive [A], got {self.current_limit!r}")
        for label, b in (("gap_bounds", self.gap_bounds), ("position_bounds", self.position_bounds)):
            if len(b) != 2 or not (b[0] < b[1]) or not all(math.isfinite(v) for v in b):
                raise InputError(f"{label} must be (lower, upper) with lower < upper [m], got {b!r}")
        if self.gap_bounds[1] > 0.1 or self.gap_bounds[0] <= 0:
            raise InputError(f"gap_bounds must be positive and in metres, got {self.gap_bounds!r}")

    def _check_effects(self) -> None:
        f = self.effects
        if f is None:
            return
        if not isinstance(f, ca.Function):
            raise InputError(
                f"effects must be a casadi.Function (x, i) -> (x2', x4'), got {type(f).__name__}"
            )
        shapes = [(f.size1_in(k), f.size2_in(k)) for k in range(f.n_in())]
        if shapes != [(4, 1), (2, 1)] or f.n_out() != 1 or (f.size1_out(0), f.size2_out(0)) != (2, 1):
            raise InputError(
                f"effects must map x (4) and i (2) to (x2', x4') (2), got inputs {shapes} "
                f"and {f.n_out()} output(s)"
            )

    def _check_disturbance(self) -> None:
        w_d, limit, eps = self.disturbance_bandwidth, self.disturbance_limit, self.observer_epsilon
        if not (w_d >= 0 and math.isfinite(w_d)):
            raise InputError(f"disturbance_bandwidth must be >= 0 [rad/s], got {w_d!r}")
        if not (limit > 0 and math.isfinite(limit)):
            raise InputError(f"disturbance_limit must be positive [m/s^2], got {limit!r}")
        if w_d * eps > 0.5:
            raise InputError(
                f"disturbance_bandwidth {w_d} rad/s is too close to the observer's "
                f"1/eps = {1 / eps:g} rad/s (keep w_d eps <= 0.5)"
            )

    @property
    def controller_name(self) -> str:
        """``name``, or the default of the mode."""
        return self.name or ("NMPC" if self.mode == "rti" else "NMPC (converged, IPOPT)")
