"""Branch and bound with interval arithmetic: the certificate of Procedure 2 for the nonlinear
constraints of F (module docstring of :mod:`maglev_oc.region.procedure2`).

The nonlinear constraints (R >= 0, |u| <= I) are checked on l = sqrt(c) chol(S) zeta + l_ss(phi),
|zeta| <= 1, phi in [0, 2 pi): a box of (zeta, phi) is accepted when the interval enclosure of
every constraint (:mod:`maglev_oc.region.interval`) is >= 0, refined otherwise, and the level is
refuted as soon as a point of a box inside the ball is infeasible.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.numerics import ColumnMap
from maglev_oc.region.closed_loop import LOOP_VARIABLES, Reference, RegulatorLoop
from maglev_oc.region.ellipsoid import ellipsoid_image
from maglev_oc.region.feasibility import NONLINEAR, FeasibleSet, compensated_constraints
from maglev_oc.region.interval import IntervalFunction
from maglev_oc.results import Result

__all__ = ["BoxSearch", "LevelCertifier", "bisect_widest", "cube_grid", "initial_boxes", "meets_unit_ball"]


@dataclass(frozen=True)
class BoxSearch(Result):
    """Outcome of one branch and bound on {V <= c}: ``status`` ``"certified"``, ``"refuted"``
    (an infeasible point was found: ``witness``) or ``"undecided"`` (box budget spent)."""

    success: bool
    status: str
    message: str
    level: float
    witness: np.ndarray | None  # (d + 1,) zeta (d) and phase of an infeasible point, if refuted
    witness_level: float  # V at the witness (c |zeta|^2)
    binding: str  # constraint violated at the witness ('' otherwise)
    boxes: int  # boxes evaluated
    timings: Mapping[str, float] = field(default_factory=dict)  # [s] {"total": ...}

    @classmethod
    def of(
        cls,
        status: str,
        level: float,
        boxes: int,
        t0: float,
        *,
        witness: np.ndarray | None = None,
        witness_level: float = math.inf,
        binding: str = "",
    ) -> BoxSearch:
        """The outcome with its message; ``t0`` is the search's start (``time.perf_counter``)."""
        message = {
            "certified": f"every box of {{V <= {level:.4g}}} proved feasible ({boxes} boxes)",
            "refuted": f"{binding} < 0 at V = {witness_level:.4g} ({boxes} boxes)",
            "undecided": f"box budget spent after {boxes} boxes",
        }[status]
        timings = {"total": time.perf_counter() - t0}
        return cls(
            status == "certified", status, message, level, witness, witness_level, binding, boxes, timings
        )


class LevelCertifier:
    """Branch and bound over the image of Omega_c (module docstring), built once per
    (feasible set, loop) and reused for any P, c and reference.

    Parameters
    ----------
    feasible : FeasibleSet
    loop : RegulatorLoop
    max_boxes : int
        Budget of box evaluations per level before giving up ('undecided').
    """

    def __init__(self, feasible: FeasibleSet, loop: RegulatorLoop, *, max_boxes: int = 400_000) -> None:
        if max_boxes < 100:
            raise InputError(f"max_boxes must be >= 100, got {max_boxes!r}")
        self.feasible = feasible
        self.loop = loop
        self.max_boxes = int(max_boxes)
        # l = (x1, v1, v2) and, with a compensation, the states it depends on (feasible.loop_variables)
        self.rows = tuple(feasible.loop_variables)
        self.dims = len(self.rows)
        zeta = ca.SX.sym("zeta", self.dims)
        phi = ca.SX.sym("phi")
        lmat = ca.SX.sym("L", self.dims, self.dims)  # sqrt(c) chol(S)
        off = ca.SX.sym("F", len(LOOP_VARIABLES), 3)
        basis = ca.vertcat(1, ca.sin(phi), ca.cos(phi))
        ell = ca.mtimes(lmat, zeta)
        offs = ca.mtimes(off, basis)
        value = {name: offs[k] for k, name in enumerate(LOOP_VARIABLES)}
        for k, name in enumerate(self.rows):
            value[name] = value[name] + ell[k]
        x = ca.vertcat(value["x1"], value["x2"], value["x3"], value["x4"])
        v = ca.vertcat(value["v1"], value["v2"])
        margin, headroom = compensated_constraints(
            feasible.model, x, v, feasible.current_limit, feasible.compensation
        )
        h = ca.vertcat(margin, headroom)
        self._fn = ca.Function("h_zeta", [zeta, phi, ca.vec(lmat), ca.vec(off)], [h])
        self._ifn = IntervalFunction(self._fn)
        self._columns = ColumnMap(self._fn)  # the constraints at many points, one map built once

    def certify(self, reference: Reference, P, level: float, *, phase_cells: int = 24) -> BoxSearch:
        """Branch and bound for the nonlinear constraints on {V <= level}.

        Parameters
        ----------
        reference : Reference
        P : (10, 10) array
        level : float
            c, positive and finite.
        phase_cells : int
            Initial cells over the phase [0, 2 pi) for a sinusoid.

        Returns
        -------
        BoxSearch
        """
        t0 = time.perf_counter()
        if not (level > 0 and math.isfinite(level)):
            raise InputError(f"level must be positive and finite, got {level!r}")
        img = ellipsoid_image(self.loop, P, self.rows)
        lmat = math.sqrt(level) * img.chol
        par_l = lmat.ravel(order="F")[:, None]
        par_f = self.loop.offset_coefficients(reference).ravel(order="F")[:, None]
        periodic = not reference.is_setpoint
        d = self.dims
        lo, hi = initial_boxes(periodic, phase_cells, d)
        scale = np.append(np.ones(d), 1.0 / math.pi)  # phase widths count per pi
        boxes = 0
        while lo.shape[1] > 0:
            # boxes outside the unit ball hold no point of the ellipsoid's image
            keep, near = meets_unit_ball(lo[:d], hi[:d])
            lo, hi, near = lo[:, keep], hi[:, keep], near[:, keep]
            n = lo.shape[1]
            if n == 0:
                break
            boxes += n
            hlo, _ = self._ifn([lo[:d], lo[d:], par_l, par_f], [hi[:d], hi[d:], par_l, par_f])
            ok = np.all(hlo[0] >= 0, axis=0)
            lo, hi, near = lo[:, ~ok], hi[:, ~ok], near[:, ~ok]
            if lo.shape[1] == 0:
                break
            # a point of each undecided box inside the ball: refute if infeasible there
            phase_mid = 0.5 * (lo[d] + hi[d])
            vals = self._columns(near, phase_mid[None, :], par_l, par_f)[0]
            bad = np.any(vals < 0, axis=0)
            if np.any(bad):
                r2 = np.where(bad, np.sum(near**2, axis=0), np.inf)
                k = int(np.argmin(r2))
                j = int(np.argmin(vals[:, k]))
                witness = np.concatenate([near[:, k], [phase_mid[k]]])
                return BoxSearch.of(
                    "refuted",
                    level,
                    boxes,
                    t0,
                    witness=witness,
                    witness_level=level * float(r2[k]),
                    binding=NONLINEAR[j],
                )
            if boxes > self.max_boxes:
                return BoxSearch.of("undecided", level, boxes, t0)
            lo, hi = _bisect_boxes(lo, hi, scale, periodic)
        return BoxSearch.of("certified", level, boxes, t0)

    def zeta_to_state(self, P, level: float, zeta) -> np.ndarray:
        """The z~ of least V whose l equals sqrt(level) chol(S) zeta (V there = level |zeta|^2)."""
        img = ellipsoid_image(self.loop, P, self.rows)
        ell = math.sqrt(level) * img.chol @ np.asarray(zeta, dtype=float)
        return img.Pinv_Mt @ np.linalg.solve(img.S, ell)


def initial_boxes(periodic: bool, phase_cells: int, dims: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) (dims + 1, k): a 4^dims grid over the cube [-1, 1]^dims of zeta, times
    ``phase_cells`` cells over [0, 2 pi) for a sinusoid (the phase pinned at 0 for a set-point)."""
    lo, hi = cube_grid(4, dims)
    if periodic:
        pe = np.linspace(0, 2 * math.pi, phase_cells + 1)
        k = np.arange(phase_cells)
        lo = np.vstack([np.repeat(lo, phase_cells, axis=1), np.tile(pe[k], lo.shape[1])])
        hi = np.vstack([np.repeat(hi, phase_cells, axis=1), np.tile(pe[k + 1], hi.shape[1])])
    else:
        lo = np.vstack([lo, np.zeros(lo.shape[1])])
        hi = np.vstack([hi, np.zeros(hi.shape[1])])
    return lo, hi


def cube_grid(cells: int, dims: int) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) (dims, cells^dims): the cube [-1, 1]^dims cut into cells^dims equal boxes, which
    tile it (every point of the cube in one box, up to their shared faces). Every branch and bound
    starts from such a grid; a grid that left part of the cube out would leave that part of
    {V <= c} unexamined and its certificate unsound."""
    if cells < 1 or dims < 1:
        raise InputError(f"cube_grid: cells and dims must be >= 1, got {cells!r}, {dims!r}")
    edges = np.linspace(-1.0, 1.0, cells + 1)
    g = np.array(np.meshgrid(*[range(cells)] * dims, indexing="ij")).reshape(dims, -1)
    return edges[g], edges[g + 1]


def _bisect_boxes(lo: np.ndarray, hi: np.ndarray, scale: np.ndarray, periodic: bool):
    """Every box halved along its widest (scaled) side; the phase only for a sinusoid."""
    if not periodic:
        scale = scale.copy()
        scale[-1] = 0.0
    return bisect_widest(lo, hi, scale)


def meets_unit_ball(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which boxes (lo, hi) (d, k) hold a point of the closed unit ball (k,), and each box's point
    nearest the origin (d, k), coordinate by coordinate the bound nearer 0 or 0 itself: a box meets
    the ball exactly when that point lies in it. A box kept by its centre or a corner instead would
    leave holes in the cover, and a certificate would skip the part of {V <= c} in them."""
    near = np.clip(0.0, lo, hi)
    return np.sum(near**2, axis=0) <= 1.0, near


def bisect_widest(lo: np.ndarray, hi: np.ndarray, scale: np.ndarray | None = None):
    """Boxes (lo, hi) (d, k), every one halved along its widest side (widths times ``scale``, a
    zero scale never splits that side): (lo, hi) (d, 2k), the lower halves first. The inputs are
    left as they were."""
    width = hi - lo if scale is None else (hi - lo) * scale[:, None]
    dim = np.argmax(width, axis=0)
    cols = np.arange(lo.shape[1])
    mid = 0.5 * (lo[dim, cols] + hi[dim, cols])
    hi1, lo2 = hi.copy(), lo.copy()
    hi1[dim, cols] = mid
    lo2[dim, cols] = mid
    return np.hstack([lo, lo2]), np.hstack([hi1, hi])
