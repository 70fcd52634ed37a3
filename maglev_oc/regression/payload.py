"""A payload the log declares: the forces of the stage move a heavier platform.

The lumped constants are forces per moving mass (SPEC 1: C1 over the horizontal mover's M_h,
C2..C4 over the vertical one's M_v), and so is every extra term of the regression layer. A log
that declares a payload of m kg (metadata ``payload_kg``, :data:`~maglev_oc.data.log.PAYLOAD_KEY`)
was recorded with every force accelerating M + m instead of M, gravity still G:

.. math::

    \\ddot x_1 = G + s_v (a_1 - G), \\qquad \\ddot x_3 = s_h a_3, \\qquad s = M / (M + m),

with ``a`` the acceleration the model (and its terms) give the unloaded stage. Fits read such a log
in the unloaded stage's units: the equation-error target is the measured acceleration mapped back
(:func:`unloaded`), and every simulation of a loaded log maps the model's acceleration forward
(:func:`loaded`). The constants and effects found are then the stage's own, and a log with a
declared load change beside one without separates what a single log cannot: a constant vertical
force (a hanging cable's weight, a preload) acts on the platform as its weight does, and the
magnets' scale absorbs it on one log (a 3 N force of the independent generator moved C2..C4 by
-4 to -7 % and left nothing else), while with two loads the force stays and the weight changes.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import casadi as ca
import numpy as np

from maglev_oc.data.logs import Log
from maglev_oc.errors import InputError
from maglev_oc.model.parameters import StageParameters

__all__ = ["declared", "factors", "load_factors", "loaded", "payload_note", "unloaded"]


def factors(params: StageParameters, payload: float) -> np.ndarray:
    """(2,) M / (M + m): (vertical, horizontal) for a payload of ``payload`` kg."""
    m = float(payload)
    return np.array(
        [
            params.mass_vertical / (params.mass_vertical + m),
            params.mass_horizontal / (params.mass_horizontal + m),
        ]
    )


def load_factors(
    logs: Sequence[Log], segment: np.ndarray, params: StageParameters | None
) -> np.ndarray | None:
    """(2, n) each sample's :func:`factors` (``segment``: its log's index), or None when no log
    carries a payload. ``params`` gives the masses; None with a payload is an error."""
    if not any(log.payload for log in logs):
        return None
    if params is None:
        raise InputError(
            "logs that declare a payload (payload_kg) need the stage's masses: give the model "
            f"({', '.join(log.source for log in logs if log.payload)})"
        )
    table = np.column_stack([factors(params, log.payload) for log in logs])
    return table[:, np.asarray(segment, dtype=int)]


def unloaded(acc: np.ndarray, factor: np.ndarray | None, gravity: float) -> np.ndarray:
    """The measured accelerations (2, n) (x2', x4') as the unloaded stage would have had them
    under the same forces: ``G + (a_1 - G) / s_v`` and ``a_3 / s_h``."""
    if factor is None:
        return acc
    out = np.array(acc, dtype=float)
    out[0] = gravity + (out[0] - gravity) / factor[0]
    out[1] = out[1] / factor[1]
    return out


def loaded(acc, factor, gravity: float):
    """The accelerations ``acc`` (2,) (x2', x4') of the unloaded stage (CasADi or NumPy) as the
    loaded one has them: ``G + s_v (a_1 - G)`` and ``s_h a_3``, with ``factor`` (s_v, s_h)."""
    return ca.vertcat(gravity + factor[0] * (acc[0] - gravity), factor[1] * acc[1])


def payload_note(log: Log, params: StageParameters) -> str:
    """What reading a log that declares a payload does, in words."""
    s = factors(params, log.payload)
    moved = (params.mass_vertical + log.payload, params.mass_horizontal + log.payload)
    return (
        f"{log.source}: a payload of {log.payload:g} kg declared (payload_kg): its forces move "
        f"{moved[0]:.3g} kg vertically and {moved[1]:.3g} kg horizontally, read as the unloaded "
        f"stage's (accelerations x {1 / s[0]:.3f} and x {1 / s[1]:.3f})"
    )


def declared(sources: Sequence[str], masses: Sequence[float]) -> tuple[str, ...]:
    """One sentence per log of ``sources`` whose payload in ``masses`` (kg, in the same order) is
    not 0: what ``identify`` and ``diagnose`` tell their user of it."""
    return tuple(
        f"{os.path.basename(src)}: a payload of {m:g} kg declared (payload_kg), its forces read as the "
        "unloaded stage's"
        for src, m in zip(sources, masses, strict=True)
        if m
    )
