"""Write a :class:`~tests.independent.simulate.Run` as a SPEC 2 CSV log plus its truth file.

The CSV has ``# key: value`` metadata lines, one header line ``t,x1,x3,u1,u2`` and one row per
1 kHz sample: ``t`` [s] to 0.1 ms, positions [m] to 1 um (the encoder readings are exact
multiples of 10 um, so nothing is rounded away), currents [A] to 1 uA. The metadata say nothing
about the effects present: those are only in ``<stem>.truth.json``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from .simulate import Run

DESCRIPTION = (
    "2-DOF PMLSM maglev stage, closed-loop log (FL output regulator at {loop:g} kHz, logged at {log:g} kHz)"
)
"""The description line, with the rig's loop and logging rates (nothing else: the rates are stated in
words only, as a user's logger would; ``control_rate_hz`` is not a metadata key here)."""


def csv_text(run: Run) -> str:
    """The CSV file's text for ``run``."""
    head = [
        "# description: "
        + DESCRIPTION.format(loop=run.scenario.rig.control_rate / 1e3, log=run.scenario.rig.log_rate / 1e3),
        f"# sample_rate_hz: {run.scenario.rig.log_rate:g}",
        "# units: SI",
        f"# currents: {run.scenario.rig.logged_currents}",
        *([f"# payload_kg: {run.scenario.payload:g}"] if run.scenario.declare_payload else []),
        "t,x1,x3,u1,u2",
    ]
    # + 0.0 turns -0.0 into 0.0; currents below 0.5 uA print as 0
    u1 = np.where(np.abs(run.u1) < 5e-7, 0.0, run.u1)
    u2 = np.where(np.abs(run.u2) < 5e-7, 0.0, run.u2)
    data = np.column_stack([run.t, run.x1 + 0.0, run.x3 + 0.0, u1, u2])
    # one %-format over all rows: np.savetxt's text to the byte (it formats row by row), in a
    # quarter of its time (0.12 s against 0.45 s for 60 s at 1 kHz)
    row = "%.4f,%.6f,%.6f,%.6f,%.6f\n"
    return "\n".join(head) + "\n" + (row * len(data)) % tuple(data.ravel().tolist())


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def write_log(run: Run, out_dir: str | os.PathLike[str], stem: str | None = None) -> tuple[Path, Path]:
    """Write ``<stem>.csv`` and ``<stem>.truth.json`` into ``out_dir`` (created if needed).

    ``stem`` defaults to the scenario's name. Returns (csv path, truth path).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    stem = stem or run.scenario.name
    csv_path = out / f"{stem}.csv"
    truth_path = out / f"{stem}.truth.json"
    _atomic_write(csv_path, csv_text(run))
    truth: dict[str, Any] = dict(run.truth)
    truth["log"] = dict(truth["log"], file=csv_path.name)
    _atomic_write(truth_path, json.dumps(truth, indent=2) + "\n")
    return csv_path, truth_path
