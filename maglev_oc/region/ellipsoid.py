"""Level sets {z~' P z~ <= c} of the error coordinates seen through what matters: their image
under the linear functions the feasible set depends on, and the initial conditions they contain.

On {V <= c} each linear function m'z~ ranges exactly over |m'z~| <= sqrt(c m' P^-1 m'), and the
triple l = (e1, v1, v2) over the 3-D ellipsoid {l' S^-1 l <= c}, S = M P^-1 M' (the image of an
ellipsoid under a linear map); see :mod:`maglev_oc.region.procedure2`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.region.closed_loop import DE1, DE2, E1, E2, N_ERROR, RegulatorLoop
from maglev_oc.results import PerAxis

__all__ = [
    "EllipsoidImage",
    "InitialConditionSet",
    "checked_p",
    "ellipsoid_image",
    "initial_condition_set",
    "max_rectangle",
]


@dataclass(frozen=True)
class EllipsoidImage:
    """What Omega_c = {z~' P z~ <= c} looks like through the functions F depends on.

    S (d, d) = M P^-1 M' for l (default (e1, v1, v2)); chol (d, d) lower factor of S; ``spread`` (4,) =
    sqrt(m' P^-1 m) for m = rows (e1, e2, v1, v2): on Omega_c each ranges over +- sqrt(c) spread.
    """

    S: np.ndarray
    chol: np.ndarray
    spread: np.ndarray
    Pinv_Mt: np.ndarray  # (10, d) P^-1 M'


def ellipsoid_image(loop: RegulatorLoop, P: np.ndarray, rows=("x1", "v1", "v2")) -> EllipsoidImage:
    """What {V <= c} looks like through l (default (e1, v1, v2)) and the four linear functions F
    depends on.

    Parameters
    ----------
    loop : RegulatorLoop
    P : (10, 10) array
        Symmetric positive definite.
    rows : sequence of str
        The loop variables (:data:`~maglev_oc.region.closed_loop.LOOP_VARIABLES`) making up l;
        a compensated effect adds the states it depends on
        (:attr:`~maglev_oc.region.feasibility.FeasibleSet.loop_variables`).

    Returns
    -------
    EllipsoidImage
    """
    P = checked_p(P)
    M = loop.rows(tuple(rows))
    pinv_mt = np.linalg.solve(P, M.T)
    S = M @ pinv_mt
    S = 0.5 * (S + S.T)
    spread = np.sqrt(np.einsum("ij,ji->i", loop.output, np.linalg.solve(P, loop.output.T)))
    return EllipsoidImage(S, np.linalg.cholesky(S), spread, pinv_mt)


def checked_p(P) -> np.ndarray:
    """``P`` as a finite, symmetric 10 x 10 float array (symmetrised); ValueError otherwise."""
    P = np.asarray(P, dtype=float)
    if P.shape != (N_ERROR, N_ERROR) or not np.all(np.isfinite(P)):
        raise InputError(f"P must be a finite 10 x 10 matrix, got shape {P.shape}")
    if not np.allclose(P, P.T, rtol=1e-10, atol=0):
        raise InputError("P must be symmetric")
    return 0.5 * (P + P.T)


@dataclass(frozen=True)
class InitialConditionSet:
    """The certified set {z~' P z~ <= c} seen through the initial conditions users set.

    Semi-axes: the largest deviation of each of e1 [m], e1' [m/s], e2 [m], e2' [m/s] from the
    reference's steady state with every other state at its steady-state value (for a
    set-point: at rest, internal models empty). ``rectangle`` (a1, a2) [m]: the largest-area
    box |e1| <= a1, |e2| <= a2 (rates and internal models at steady state) inside the set.
    """

    semi_axes: dict[str, float]  # e1, e1_rate, e2, e2_rate
    rectangle: PerAxis  # (a1 on e1, vertical; a2 on e2, horizontal)


def initial_condition_set(P, level: float) -> InitialConditionSet:
    """The set {z~' P z~ <= level} seen through the initial conditions users set.

    Parameters
    ----------
    P : (10, 10) array
    level : float
        c (0 gives the empty set's zero sizes).

    Returns
    -------
    InitialConditionSet
    """
    P = checked_p(P)
    semi = {
        name: math.sqrt(level / P[i, i])
        for name, i in (("e1", E1), ("e1_rate", DE1), ("e2", E2), ("e2_rate", DE2))
    }
    return InitialConditionSet(semi, PerAxis.of(max_rectangle(P[np.ix_([E1, E2], [E1, E2])], level)))


def max_rectangle(P2, level: float) -> tuple[float, float]:
    """Half-sides (a, b) of the largest-area axis-aligned box centred at 0 inside the ellipse
    {y' P2 y <= level} (2 x 2): corners (a, +-b) must satisfy a^2 p11 + b^2 p22 + 2|a b p12| <= level.

    Parameters
    ----------
    P2 : (2, 2) array
        Symmetric positive definite.
    level : float

    Returns
    -------
    (float, float)
        a, b in the units of y.
    """
    p11, p22, p12 = P2[0, 0], P2[1, 1], abs(P2[0, 1])
    # with a = r cos t / sqrt(p11), b = r sin t / sqrt(p22): r^2 (1 + k sin 2t) = level,
    # k = p12 / sqrt(p11 p22); area ~ sin 2t / (1 + k sin 2t) is largest at t = pi/4.
    k = p12 / math.sqrt(p11 * p22)
    r = math.sqrt(level / (1 + k))
    return r / math.sqrt(2 * p11), r / math.sqrt(2 * p22)
