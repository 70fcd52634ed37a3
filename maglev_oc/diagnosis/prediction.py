"""Short-horizon predictions of a diagnosed model: the output error before and after."""

from __future__ import annotations

from collections.abc import Sequence

import casadi as ca
import numpy as np

from maglev_oc.diagnosis.candidate import Candidate
from maglev_oc.model.stage import StageModel
from maglev_oc.numerics import rk4_step
from maglev_oc.regression.data import PreparedLogs
from maglev_oc.results import PerAxis

__all__ = ["output_error"]


def output_error(
    data: PreparedLogs,
    holdout: np.ndarray,
    model: StageModel,
    effects: Sequence[tuple[Candidate, np.ndarray]],
    *,
    horizon: float = 0.05,
    every: float = 0.25,
) -> PerAxis:
    """RMS position error [m] per axis of the model simulated over ``horizon`` from the
    estimated state at window starts (every ``every`` s) in the held-out block, with the logged
    currents. Short windows because the gap is open-loop unstable (30-64 1/s): 50 ms lets an
    initial velocity error grow by at most e^3."""
    ts = data.sample_time
    h = max(1, round(horizon / ts))
    x, u, du = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("du", 2)
    acc = model.f(x, u)[[1, 3]]
    for cand, coef in effects:
        acc = acc + cand.term.acceleration(coef)(x, u, du)
    f = ca.Function("f", [x, u, du], [ca.vertcat(x[1], acc[0], x[3], acc[1])])
    step = ca.Function("rk4", [x, u, du], [rk4_step(f, x, ts, u, du)])
    sim = step.mapaccum("window", h)
    hold = np.flatnonzero(holdout)
    stride = max(1, round(every / ts))
    starts = [
        k
        for k in hold[::stride]
        if k + h < data.n and holdout[k + h] and data.segment[k + h] == data.segment[k]
    ]
    if not starts:
        return PerAxis(float("nan"), float("nan"))
    x0 = data.x[:, starts]
    U = np.hstack([data.u[:, k : k + h] for k in starts])
    DU = np.hstack([data.du[:, k : k + h] for k in starts])
    traj = np.asarray(sim.map(len(starts))(x0, U, DU))
    meas = np.hstack([data.x[:, k + 1 : k + 1 + h] for k in starts])
    errs = traj[[0, 2]] - meas[[0, 2]]
    rms = np.where(data.moving, np.sqrt(np.mean(errs**2, axis=1)), np.nan)
    return PerAxis.of(rms)
