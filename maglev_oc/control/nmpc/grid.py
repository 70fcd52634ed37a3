"""The NMPC's time grid: shooting intervals, the reference at the nodes, the warm-start shift.

Shooting grid and the 5 kHz loop
    The controller runs every sample Ts = 200 us and re-solves every sample. The first shooting
    interval is exactly one sample (h_0 = Ts): u_0 is the current held by the zero-order hold
    until the next solve, so the plan's first piece is what the rig applies. The other N - 1
    intervals are uniform, h = 5 ms = 25 Ts by default. The open-loop unstable pole (30-64
    rad/s over 10-30 mm) and the closed loop of the default weights (poles of magnitude 55-110
    rad/s, damping 0.75-0.96, over 10-29 mm; the papers' regulators: 9-15 rad/s) give h |lambda|
    <= 0.55, where one RK4 step is accurate to (h lambda)^5 / 120 < 5e-4 and a time constant
    (9-18 ms) spans 2-4 intervals. N = 20 previews Ts + 95 ms (N = 40: 195 ms), five to ten
    closed-loop time constants and one sixth of the ellipse's period; beyond it the terminal
    cost is the infinite-horizon LQR value. Shorter intervals would cost more intervals for the
    same preview; longer ones would leave the unstable and closed-loop modes under-resolved.
    With a short first interval the first input is, near an equilibrium,
    u_0 = -(Ts R + B0' P B0)^-1 B0' P A0 dx: the LQR law of the sampled problem (checked in
    tests/test_nmpc.py), close to the continuous-time LQR of (Q, R). The stage cost is integrated
    (weighted by h_j), so the weights do not depend on the grid.

Reference preview
    The nodes read the reference array at their own times (``preview=True``, the default): the
    plan sees a set-point step up to Ts + (N - 1) h before it happens and leaves the old
    set-point early (by ~50 ms with the defaults), which metrics that time the settling from the
    step instant count against it. ``preview=False`` makes the controller causal like the
    papers' regulators: every node extrapolates the current reference sample with its velocity
    and acceleration (on the ellipse, which is smooth, the tracking errors are the same to
    within a few um).

Warm start by shifting
    After a sample the new grid starts at the old node 1 and every later node lies a fraction
    a = Ts / h into the old interval; the plan is shifted by linear interpolation between old
    nodes (the last node and input are held).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.control.base import N_REFERENCE
from maglev_oc.control.nmpc.layout import NU, NX, STAGE_SIZE, u_index, x_index
from maglev_oc.errors import InputError

__all__ = ["ShootingGrid", "extrapolated_reference", "node_references", "shift_matrix"]

_AXIS_ROWS = (0, 3)
"""First row (position) of each axis's (position, velocity, acceleration) in a reference sample."""


@dataclass(frozen=True)
class ShootingGrid:
    """The multiple-shooting grid: a first interval of one sample, then N - 1 of ``interval_samples``.

    Parameters
    ----------
    sample_time : float
        Controller period Ts [s], also the first interval.
    interval_samples : int
        Samples per regular interval (h = interval_samples Ts).
    horizon : int
        Number of intervals N >= 2.

    Attributes
    ----------
    node_offsets : (N + 1,) int
        Node j lies ``node_offsets[j]`` samples after the current one (0, 1, 1 + m, 1 + 2m, ...);
        the reference preview is read there.
    intervals : (N,) float
        h_j [s].
    """

    sample_time: float
    interval_samples: int
    horizon: int
    node_offsets: np.ndarray = field(init=False, repr=False)
    intervals: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not (self.sample_time > 0 and math.isfinite(self.sample_time)):
            raise InputError(f"sample_time must be positive [s], got {self.sample_time!r}")
        if not (isinstance(self.interval_samples, int) and self.interval_samples >= 1):
            raise InputError(f"interval_samples must be a positive integer, got {self.interval_samples!r}")
        if not (isinstance(self.horizon, int) and self.horizon >= 2):
            raise InputError(f"horizon must be an integer >= 2, got {self.horizon!r}")
        offsets = np.concatenate([[0], 1 + self.interval_samples * np.arange(self.horizon)])
        h = np.full(self.horizon, self.interval_samples * self.sample_time)
        h[0] = self.sample_time
        object.__setattr__(self, "node_offsets", offsets.astype(int))
        object.__setattr__(self, "intervals", h)

    @property
    def interval(self) -> float:
        """The regular interval h [s]."""
        return self.interval_samples * self.sample_time

    @property
    def preview(self) -> float:
        """Time covered by the horizon [s]."""
        return float(self.intervals.sum())

    def shift_fraction(self) -> float:
        """How far into an old interval a new node lies after one sample (Ts / h)."""
        return 1.0 / self.interval_samples


def shift_matrix(grid: ShootingGrid) -> np.ndarray:
    """The warm start after one sample (see the module docstring).

    Parameters
    ----------
    grid : ShootingGrid

    Returns
    -------
    (STAGE_SIZE N, STAGE_SIZE N) array
        S with z_next = S z.
    """
    n = grid.horizon
    nz = STAGE_SIZE * n
    a = grid.shift_fraction()
    s = np.zeros((nz, nz))
    eye_u, eye_x = np.eye(NU), np.eye(NX)
    # new u_0 (over [Ts, 2 Ts]) lies inside old interval 1
    s[0:NU, u_index(1) : u_index(1) + NU] = eye_u
    for j in range(1, n + 1):
        r = x_index(j)
        if j < n:  # new node j sits a fraction a into old interval j
            s[r : r + NX, x_index(j) : x_index(j) + NX] += (1 - a) * eye_x
            s[r : r + NX, x_index(j + 1) : x_index(j + 1) + NX] += a * eye_x
        else:
            s[r : r + NX, r : r + NX] = eye_x
        if j < n:
            ru = u_index(j)
            if j + 1 < n:
                s[ru : ru + NU, u_index(j) : u_index(j) + NU] += (1 - a) * eye_u
                s[ru : ru + NU, u_index(j + 1) : u_index(j + 1) + NU] += a * eye_u
            else:
                s[ru : ru + NU, ru : ru + NU] = eye_u
    return s


def node_references(grid: ShootingGrid, k: int, reference: np.ndarray, *, preview: bool) -> np.ndarray:
    """The reference at the shooting nodes from sample ``k`` on.

    With ``preview`` the nodes read the reference array at their own times; nodes beyond its
    last sample extrapolate it with its last velocity and acceleration (a set-point is held; a
    sinusoid ending mid-motion is continued instead of being seen to stop, which would make the
    plan brake before the run ends). Without ``preview`` every node extrapolates the current
    sample that way (a causal controller: a step is seen when it happens, a sinusoid is
    continued by its local Taylor expansion).

    Parameters
    ----------
    grid : ShootingGrid
    k : int
        Current sample.
    reference : (6, n) array
        The sampled reference (r_v, r_v', r_v'', r_h, r_h', r_h'') [m, m/s, m/s^2].
    preview : bool

    Returns
    -------
    (6, N + 1) array
        The reference at nodes 0..N.
    """
    last = reference.shape[1] - 1
    if not preview:
        return _extrapolate(reference[:, min(k, last)], grid.node_offsets * grid.sample_time)
    idx = k + grid.node_offsets
    if idx[-1] <= last:
        return reference[:, idx]
    out = reference[:, np.minimum(idx, last)].copy()
    beyond = idx > last
    out[:, beyond] = _extrapolate(reference[:, last], (idx[beyond] - last) * grid.sample_time)
    return out


def _extrapolate(r: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """The reference sample r (6,) continued with constant acceleration over times dt: (6, n)."""
    out = np.empty((N_REFERENCE, dt.size))
    for row in _AXIS_ROWS:
        p, v, a = r[row], r[row + 1], r[row + 2]
        out[row] = p + v * dt + 0.5 * a * dt**2
        out[row + 1] = v + a * dt
        out[row + 2] = a
    return out


def extrapolated_reference(r, dt: np.ndarray):
    """:func:`_extrapolate` for a CasADi reference sample r (6): (6, dt.size), symbolic.

    The causal NMPC's node references are ``extrapolated_reference(r, grid.node_offsets * Ts)``
    (:func:`node_references` without preview); the exported NMPC's preparation predicts the next
    sample's reference as ``extrapolated_reference(r, [Ts])``.
    """
    dt = ca.DM(np.asarray(dt, dtype=float)).T
    ones = ca.DM.ones(1, dt.numel())
    rows = []
    for row in _AXIS_ROWS:
        p, v, a = r[row], r[row + 1], r[row + 2]
        rows += [p + v * dt + 0.5 * a * dt**2, v + a * dt, a * ones]
    return ca.vertcat(*rows)
