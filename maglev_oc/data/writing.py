"""Writing a log atomically: CSV text that reads back to the same float64 values, or MATLAB v5."""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import scipy.io

from maglev_oc.data.log import Log
from maglev_oc.errors import InputError
from maglev_oc.fileio import atomic_path

__all__ = ["write_log", "write_log_arrays"]

_MATLAB_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,62}")


def write_log(path: str | os.PathLike, log: Log) -> Path:
    """Write ``log`` atomically: MATLAB v5 when the suffix is ``.mat``, else CSV (``.csv``/``.txt``).

    CSV: ``# key: value`` lines (``units: SI``, ``sample_rate_hz`` from the median step, ``currents``
    and the log's other metadata), the header, then the rows in ``%.17g``, which
    :func:`read_log` turns back into the same float64 values. x2/x4 are written only when
    measured. ``.mat``: the columns as column vectors and a ``metadata`` struct of strings.
    ``notes`` are not written (they describe how this Log was made, not the data).

    Parameters
    ----------
    path : path-like
        ``.mat``, ``.csv`` or ``.txt``.
    log : Log

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValueError
        An unknown suffix, or metadata that the format cannot hold (newlines, ':' in a CSV key,
        a key that is not a MATLAB name for .mat).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".txt", ".mat"):
        raise InputError(f"{path}: unknown log suffix {path.suffix!r}; use .csv, .txt or .mat")
    meta = {"units": "SI", "sample_rate_hz": f"{1.0 / log.sample_time:.10g}"}
    meta["currents"] = "measured" if log.currents_measured else "commanded"
    meta |= {k: v for k, v in log.metadata.items() if k not in meta}
    for key, value in meta.items():
        if not key.strip() or ":" in key or "\n" in key or "\n" in value or key.strip() != key:
            raise InputError(f"{path}: metadata {key!r}: {value!r} cannot be written as '# key: value'")
    columns = log.columns()
    if suffix == ".mat":
        for key in meta:
            if not _MATLAB_NAME.fullmatch(key):
                raise InputError(f"{path}: metadata key {key!r} is not a MATLAB field name")
        payload: dict[str, object] = {name: np.asarray(v) for name, v in columns.items()}
        payload["metadata"] = dict(meta)
        with atomic_path(path) as tmp, tmp.open("wb") as fh:
            scipy.io.savemat(fh, payload, oned_as="column", do_compression=True)
        return path
    names = list(columns)
    table = np.column_stack([columns[name] for name in names])
    row = ",".join(["%.17g"] * len(names)) + "\n"
    parts = [f"# {key}: {value}\n" for key, value in meta.items()]
    parts.append(",".join(names) + "\n")
    parts.append((row * table.shape[0]) % tuple(table.ravel().tolist()))
    with atomic_path(path) as tmp:
        tmp.write_text("".join(parts), encoding="utf-8")
    return path


def write_log_arrays(
    path: str | os.PathLike,
    t: np.ndarray,
    x: np.ndarray,
    u: np.ndarray,
    *,
    metadata: Mapping[str, str] | None = None,
    currents_measured: bool = False,
) -> Path:
    """Write arrays as a log; they are validated as for :class:`Log` (see :func:`write_log` for the formats).

    Parameters
    ----------
    path : path-like
    t : (n,) array
        Time [s].
    x : (4, n) array
        States [m, m/s, m, m/s]; NaN rows for unmeasured x2/x4.
    u : (2, n) array
        Inputs (i_q, i_d) [A].
    metadata : mapping of str to str, optional
    currents_measured : bool
        Whether the currents were measured (else commanded).

    Returns
    -------
    Path
    """
    log = Log(t, x, u, metadata=dict(metadata or {}), source=str(path), currents_measured=currents_measured)
    return write_log(path, log)
