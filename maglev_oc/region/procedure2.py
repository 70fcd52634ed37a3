"""Procedure 2 of Maggiore & Becerril (2004), adapted to the output regulator of 001/002, certified.

The papers (001 Sec. V, 002 Sec. 6) ask for "the largest set of feasible initial conditions x(0)
guaranteeing that (x(t), v(t)) in A for all t >= 0" and leave the adaptation of Procedure 2 to
their v undone. Procedure 2 as adapted here:

1. In error coordinates z~ (:mod:`maglev_oc.region.closed_loop`) the closed loop is z~' = A_cl z~
   *as long as* (x, v) stays in the feasible set F (:mod:`maglev_oc.region.feasibility`).
2. Take V = z~' P z~ with A_cl' P + P A_cl <= 0 (Lyapunov equation, or the SDP of
   :mod:`maglev_oc.region.sdp`). Every level set Omega_c = {V <= c} is invariant for the linear loop.
3. If Omega_c x {exosystem orbit} lies inside F, a solution starting in Omega_c stays in Omega_c
   (while it is in F it is a solution of the linear loop, whose V does not increase; it cannot
   reach the boundary of F without first leaving Omega_c), so the transformation exists and the
   currents fit for all t >= 0. The largest such c is c* = min V over the complement of F.

**Certificate.** F depends on z~ only through four linear functions (e1, e2, v1, v2) and the phase.
On Omega_c each linear function m'z~ ranges exactly over |m'z~| <= sqrt(c m' P^-1 m'), and the
triple l = (e1, v1, v2) ranges exactly over the 3-D ellipsoid {l' S^-1 l <= c}, S = M P^-1 M'
(the image of an ellipsoid under a linear map). So:

* the stopper constraints (linear in e1, e2) give their level in closed form;
* the nonlinear constraints (R >= 0, |u| <= I) are checked on l = sqrt(c) chol(S) zeta + l_ss(phi),
  |zeta| <= 1, phi in [0, 2 pi), by branch and bound with interval arithmetic on the CasADi graph
  (:mod:`maglev_oc.region.interval`): a box is accepted when the enclosure of every constraint is
  >= 0, refined otherwise. "Certified" means every box covering the ball was accepted: a sound
  lower bound on c*, up to floating-point rounding (handled by outward padding).

**Tightness.** Multistart IPOPT with exact derivatives minimises V on each constraint's boundary
(10-D, plus the phase): any point it returns is infeasible (or on the boundary) and bounds c* from
above. A branch-and-bound refutation also returns such a point. The report gives both bounds.

Assumptions of the certificate: the nominal plant equals the controller's model; the loop is the
continuous-time FL loop with exact velocities and an ideal amplifier (commands applied exactly
while within the limit); the reference is an exosystem trajectory (constant, or a pure sinusoid
at the exosystem's frequency, no ramp-in). The 5 kHz sampling, the high-gain observer and the
encoder quantisation are not covered; :mod:`maglev_oc.region.montecarlo` checks the sampled loop.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.region.boundary import BoundaryMinimizer, BoundaryMinimum
from maglev_oc.region.branch_and_bound import BoxSearch, LevelCertifier
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.ellipsoid import (
    InitialConditionSet,
    checked_p,
    ellipsoid_image,
    initial_condition_set,
)
from maglev_oc.region.feasibility import CONSTRAINT_NAMES, NONLINEAR, FeasibleSet
from maglev_oc.results import Result

__all__ = ["LADDER", "MAX_ATTEMPTS", "Procedure2", "Procedure2Result"]

LADDER = (0.995, 0.98, 0.95, 0.9, 0.8, 0.65, 0.5, 0.3, 0.15, 0.05, 0.01)
"""Fractions of the best upper bound at which a certificate is attempted, in this order."""
MAX_ATTEMPTS = 24
"""Branch-and-bound runs per reference and P before giving up."""


def _travel_levels(feasible: FeasibleSet, loop: RegulatorLoop, reference: Reference, P) -> dict[str, float]:
    """Exact min of V over each violated stopper half-space {x1 < g_lo}, ... (closed form).

    Parameters
    ----------
    feasible : FeasibleSet
        Supplies the stoppers [m] (a missing one gives an infinite level).
    loop : RegulatorLoop
    reference : Reference
    P : (10, 10) array

    Returns
    -------
    dict of str to float
        The level per stopper constraint (gap_low, gap_high, position_low, position_high).
    """
    img = ellipsoid_image(loop, P)
    F = loop.offset_coefficients(reference)
    out = {}
    for row, rng, names in (
        (0, feasible.gap_range, ("gap_low", "gap_high")),
        (1, feasible.position_range, ("position_low", "position_high")),
    ):
        if rng is None:
            out[names[0]] = out[names[1]] = math.inf
            continue
        amp = math.hypot(F[row, 1], F[row, 2])
        lo_room = F[row, 0] - amp - rng[0]
        hi_room = rng[1] - (F[row, 0] + amp)
        out[names[0]] = max(lo_room, 0.0) ** 2 / img.spread[row] ** 2
        out[names[1]] = max(hi_room, 0.0) ** 2 / img.spread[row] ** 2
    return out


@dataclass(frozen=True)
class Procedure2Result(Result):
    """The adapted Procedure 2 for one reference and one P (module docstring).

    ``level`` is the certified c (0 if nothing could be certified); c* lies in
    [level, level_upper]; ``tightness`` = level / level_upper. ``levels`` lists, per
    constraint of F, (certified lower bound, best upper bound) on min V over its violation.
    """

    success: bool
    status: str
    message: str
    reference: Reference
    P: np.ndarray
    level: float
    level_upper: float
    tightness: float
    binding: str
    witness: np.ndarray | None  # z~ (10,) of the best upper bound
    witness_phase: float
    levels: dict[str, tuple[float, float]]
    initial_conditions: InitialConditionSet
    attempts: tuple[BoxSearch, ...]
    minima: tuple[BoundaryMinimum, ...]
    timings: Mapping[str, float] = field(default_factory=dict)  # [s] nlp, certify, total


@dataclass
class _UpperBounds:
    """The best infeasible points known per nonlinear constraint, improved by refutations."""

    upper: dict[str, float]  # constraint -> least V found on its violation
    witness: dict[str, tuple[np.ndarray | None, float]]  # constraint -> (z~, phase) there
    best: float  # least of them (or a stand-in when IPOPT found no boundary point)

    @classmethod
    def of(cls, minima: tuple[BoundaryMinimum, ...], travel: dict[str, float]) -> _UpperBounds:
        upper = {m.constraint: m.level for m in minima}
        witness = {m.constraint: (m.state, m.phase) for m in minima}
        best = min(upper.values())
        if not math.isfinite(best):
            # no boundary point found by IPOPT: bound the search by the stoppers' level
            best = min(v for v in travel.values()) * 4 if math.isfinite(min(travel.values())) else 1.0
        return cls(upper, witness, best)

    def refuted(self, name: str, level: float, state: np.ndarray, phase: float) -> None:
        """A branch-and-bound refutation found an infeasible point of ``name`` at V = level."""
        self.best = level
        self.witness[name] = (state, phase)
        self.upper[name] = min(self.upper.get(name, math.inf), level)


class Procedure2:
    """The adapted Procedure 2 (module docstring). Build once; call :meth:`run` for each
    reference and P. Its solvers (IPOPT, interval graph) are built here, once.

    Parameters
    ----------
    feasible : FeasibleSet
    loop : RegulatorLoop
    starts : int
        IPOPT starts per constraint.
    max_boxes : int
        Branch-and-bound budget per attempted level.
    """

    def __init__(
        self, feasible: FeasibleSet, loop: RegulatorLoop, *, starts: int = 12, max_boxes: int = 400_000
    ) -> None:
        if starts < 1:
            raise InputError(f"starts must be >= 1, got {starts!r}")
        self.feasible = feasible
        self.loop = loop
        self.starts = int(starts)
        self.certifier = LevelCertifier(feasible, loop, max_boxes=max_boxes)
        self.minimizer = BoundaryMinimizer(feasible, loop)

    def run(self, reference: Reference, P=None, *, seed: int = 0) -> Procedure2Result:
        """Certify the largest level set of V = z~' P z~ inside F for ``reference`` (module docstring).

        Parameters
        ----------
        reference : Reference
        P : (10, 10) array, optional
            A Lyapunov matrix of the loop (default: the Lyapunov equation's,
            :meth:`RegulatorLoop.lyapunov_matrix`).
        seed : int
            Seed of the multistart rays.

        Returns
        -------
        Procedure2Result
            ``status`` ``"certified"``, ``"not_certified"`` (nothing within the branch-and-bound
            budget) or ``"infeasible_reference"`` (the reference itself reaches a stopper).
        """
        t0 = time.perf_counter()
        P = self.loop.lyapunov_matrix() if P is None else checked_p(P)
        if not self.loop.is_lyapunov(P):
            raise InputError("P is not a Lyapunov matrix of the loop (A' P + P A must be <= 0, P > 0)")
        timings: dict[str, float] = {}
        travel = _travel_levels(self.feasible, self.loop, reference, P)  # exact, closed form
        t1 = time.perf_counter()
        minima = tuple(
            self.minimizer.minimize(reference, P, name, starts=self.starts, seed=seed)
            for name in self.minimizer.constraints
        )
        timings["nlp"] = time.perf_counter() - t1
        bounds = _UpperBounds.of(minima, travel)
        t1 = time.perf_counter()
        if min(travel.values()) > 0:
            certified_nl, attempts = self._ladder(reference, P, min(travel.values()), bounds)
        else:  # the reference itself reaches a stopper: no level set around it fits
            certified_nl, attempts = 0.0, ()
        timings["certify"] = time.perf_counter() - t1
        result = self._result(reference, P, travel, bounds, certified_nl, attempts, minima)
        timings["total"] = time.perf_counter() - t0
        return dataclasses.replace(result, timings=timings)

    def _ladder(
        self, reference: Reference, P: np.ndarray, cap: float, bounds: _UpperBounds
    ) -> tuple[float, tuple[BoxSearch, ...]]:
        """Certify the nonlinear constraints on a ladder of levels below the best upper bound, but
        no higher than the stoppers allow (``cap``: the certified set is their minimum anyway).
        A refutation lowers the bound and the same rung is tried again below it."""
        attempts = []
        target = min(bounds.best, cap / LADDER[0]) if math.isfinite(cap) else bounds.best
        k = 0
        while k < len(LADDER) and len(attempts) < MAX_ATTEMPTS:
            lev = LADDER[k] * target
            res = self.certifier.certify(reference, P, lev)
            attempts.append(res)
            if res.status == "certified":
                return lev, tuple(attempts)
            if res.status == "refuted" and res.witness_level < bounds.best:
                zt = self.certifier.zeta_to_state(P, lev, res.witness[:-1])
                bounds.refuted(res.binding, res.witness_level, zt, float(res.witness[-1]))
                target = res.witness_level  # retry the same fraction of the better bound
                continue
            k += 1
        return 0.0, tuple(attempts)

    def _result(self, reference, P, travel, bounds, certified_nl, attempts, minima) -> Procedure2Result:
        """The certified level, the bounds per constraint, the binding one and its witness."""
        cap = min(travel.values())
        level = min(certified_nl, cap)
        levels: dict[str, tuple[float, float]] = {}
        for name in CONSTRAINT_NAMES:
            if name in travel:
                levels[name] = (travel[name], travel[name])
            elif name in bounds.upper or name in NONLINEAR:
                levels[name] = (certified_nl, bounds.upper.get(name, math.inf))
        all_upper = {k: v[1] for k, v in levels.items()}
        binding = min(all_upper, key=all_upper.get)
        level_upper = all_upper[binding]
        wz, wphi = bounds.witness.get(binding, (None, 0.0))
        if binding in travel and wz is None:
            wz, wphi = self._travel_witness(reference, P, binding, level_upper)
        success = bool(level > 0)
        status = "certified" if success else "not_certified"
        if cap <= 0:
            status = "infeasible_reference"
            message = f"the reference itself reaches a stopper ({binding}): no level set around it fits in F"
        elif success and level >= cap and certified_nl >= cap:
            message = f"certified up to the stoppers' exact level ({binding})"
        elif success:
            message = (
                f"certified c = {level:.4g}; the best infeasible point found has V = {level_upper:.4g} "
                f"({binding})"
            )
        else:
            message = "no level could be certified within the branch-and-bound budget"
        return Procedure2Result(
            success,
            status,
            message,
            reference,
            P,
            level,
            level_upper,
            level / level_upper if level_upper > 0 else 0.0,
            binding,
            wz,
            wphi,
            levels,
            initial_condition_set(P, level) if success else initial_condition_set(P, 0.0),
            attempts,
            minima,
        )

    def _travel_witness(self, reference: Reference, P, name: str, level: float):
        """The z~ on the stopper's half-space with the least V (closed form)."""
        row = 0 if name.startswith("gap") else 1
        m = self.loop.output[row]
        pinv_m = np.linalg.solve(P, m)
        sign = -1.0 if name.endswith("low") else 1.0
        F = self.loop.offset_coefficients(reference)
        phase = math.atan2(F[row, 1], F[row, 2]) if sign > 0 else math.atan2(-F[row, 1], -F[row, 2])
        return sign * math.sqrt(level) * pinv_m / math.sqrt(m @ pinv_m), phase % (2 * math.pi)
