"""Turn simulation results into logs in the SPEC 2 format (what a user records on the rig)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from maglev_oc.data.logs import Log
from maglev_oc.errors import InputError
from maglev_oc.sim.engine import SimulationResult

__all__ = ["result_to_log"]


def result_to_log(
    result: SimulationResult,
    *,
    rate_hz: float | None = None,
    metadata: Mapping[str, str] | None = None,
    describe_twin: bool = False,
) -> Log:
    """A log of what the rig would record: encoder readings and commanded currents.

    Parameters
    ----------
    result : SimulationResult
    rate_hz : float, optional
        Logging rate [Hz]; the run is decimated to it (default: every controller sample).
        It must divide the controller rate.
    metadata : mapping, optional
        Extra ``# key: value`` lines.
    describe_twin : bool
        Write which twin effects were on (``twin_effects``). Off by default: a log handed to
        identification or diagnosis should not say what is in it.

    Returns
    -------
    Log
        Velocities are not logged (the rig has no velocity sensor); the positions are the
        encoder readings, quantized and noisy when the twin's encoder is on. A run that blew up
        is kept up to its first non-finite sample.
    """
    fs = 1.0 / result.sample_time
    step = 1
    if rate_hz is not None:
        ratio = fs / rate_hz
        step = round(ratio)
        if step < 1 or abs(ratio - step) > 1e-9:
            raise InputError(f"rate_hz = {rate_hz} must divide the controller rate {fs:g} Hz")
    k = np.arange(0, result.t.size, step)
    finite = np.all(np.isfinite(result.y[:, k]), axis=0) & np.all(np.isfinite(result.u[:, k]), axis=0)
    if not np.all(finite):  # a run that blew up: keep the part before it
        k = k[: int(np.argmin(finite))]
    x = np.full((4, k.size), np.nan)
    x[0] = result.y[0, k]
    x[2] = result.y[1, k]
    meta = {
        "source": "maglev_oc rig twin",
        "controller": result.controller,
        "scenario": result.scenario,
        "sample_rate_hz": f"{fs / step:.10g}",
    }
    if describe_twin:
        meta["twin_effects"] = " ".join(result.effects) or "none"
    meta |= dict(metadata or {})
    return Log(result.t[k], x, result.u[:, k], metadata=meta, source=f"simulation:{result.scenario}")
