"""Turn simulation results into logs in the SPEC 2 format (what a user records on the rig), and
the 3-DOF microstepper's runs into a CSV of their own (SPEC 2 holds two axes)."""

from __future__ import annotations

import io
from collections.abc import Mapping
from typing import Any

import numpy as np

from maglev_oc.data.logs import Log
from maglev_oc.errors import InputError
from maglev_oc.sim.engine import SimulationResult

__all__ = ["MICROSTEPPER_COLUMNS", "microstepper_csv", "result_to_log"]

MICROSTEPPER_COLUMNS = ("t", "x", "y", "gap", "i_qA", "i_dA", "i_qB", "i_dB")
"""Columns of a microstepper run's CSV: time [s], encoder readings [m], commanded pair currents [A]."""


def _recorded(result: Any, rate_hz: float | None, describe_twin: bool) -> tuple[np.ndarray, float, dict]:
    """(sample indices, logging rate [Hz], metadata) of what the rig records of ``result``: every
    ``fs / rate_hz``-th controller sample, up to the first non-finite one (a run that blew up)."""
    fs = 1.0 / result.sample_time
    step = 1
    if rate_hz is not None:
        ratio = fs / rate_hz
        step = round(ratio)
        if step < 1 or abs(ratio - step) > 1e-9:
            raise InputError(f"rate_hz = {rate_hz} must divide the controller rate {fs:g} Hz")
    k = np.arange(0, result.t.size, step)
    finite = np.all(np.isfinite(result.y[:, k]), axis=0) & np.all(np.isfinite(result.u[:, k]), axis=0)
    if not np.all(finite):
        k = k[: int(np.argmin(finite))]
    meta = {
        "source": "maglev_oc rig twin",
        "controller": result.controller,
        "scenario": result.scenario,
        "sample_rate_hz": f"{fs / step:.10g}",
    }
    if describe_twin:
        meta["twin_effects"] = " ".join(result.effects) or "none"
    return k, fs / step, meta


def microstepper_csv(result: Any, rate_hz: float, *, describe_twin: bool = False) -> tuple[str, int, float]:
    """(CSV text, rows, logging rate [Hz]) of a microstepper run: the encoder readings and the
    commanded currents (:data:`MICROSTEPPER_COLUMNS`) decimated to ``rate_hz``, with ``# key:
    value`` lines saying the format and units."""
    k, rate, meta = _recorded(result, rate_hz, describe_twin)
    meta = {
        "format": "maglev_oc 3-DOF microstepper run (not a SPEC 2 log: SPEC 2 holds two axes)",
        "columns": "t [s]; x, y, gap: encoder readings [m]; i_qA, i_dA, i_qB, i_dB: commanded pair "
        "currents [A] (pair A drives x, pair B drives y)",
        "units": "SI",
        **meta,
    }
    buf = io.StringIO()
    buf.write("".join(f"# {key}: {value}\n" for key, value in meta.items()))
    rows = np.vstack([result.t[k], result.y[:, k], result.u[:, k]]).T
    np.savetxt(buf, rows, fmt="%.17g", delimiter=",", header=",".join(MICROSTEPPER_COLUMNS), comments="")
    return buf.getvalue(), int(k.size), rate


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
    k, _, meta = _recorded(result, rate_hz, describe_twin)
    x = np.full((4, k.size), np.nan)
    x[0] = result.y[0, k]
    x[2] = result.y[1, k]
    meta |= dict(metadata or {})
    return Log(result.t[k], x, result.u[:, k], metadata=meta, source=f"simulation:{result.scenario}")
