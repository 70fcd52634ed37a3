"""Short-horizon predictions of a diagnosed model: the output error before and after.

The window simulator is :func:`maglev_oc.validation.simulate_windows`, which the validation's
prediction residuals and long-horizon fits use too.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from maglev_oc.regression.data import PreparedLogs
from maglev_oc.results import PerAxis
from maglev_oc.validation import simulate_windows, window_starts

__all__ = ["output_error"]


def output_error(
    data: PreparedLogs,
    holdout: np.ndarray,
    model,
    effects: Sequence[tuple] = (),
    *,
    horizon: float = 0.05,
    every: float = 0.25,
) -> PerAxis:
    """RMS position error [m] per axis of the model simulated over ``horizon`` from the
    estimated state at window starts (every ``every`` s) in the held-out block, with the logged
    currents. Short windows because the gap is open-loop unstable (30-64 1/s): 50 ms lets an
    initial velocity error grow by at most e^3. ``effects`` are (Candidate, coefficients)."""
    ts = data.sample_time
    h = max(1, round(horizon / ts))
    starts = window_starts(data, holdout, h, max(1, round(every / ts)))
    if starts.size == 0:
        return PerAxis(float("nan"), float("nan"))
    terms = [(cand.term, coef) for cand, coef in effects]
    traj, meas = simulate_windows(data, starts, h, model, terms)
    errs = (traj[[0, 2]] - meas[[0, 2]]).reshape(2, -1)
    rms = np.where(data.moving, np.sqrt(np.mean(errs**2, axis=1)), np.nan)
    return PerAxis.of(rms)
