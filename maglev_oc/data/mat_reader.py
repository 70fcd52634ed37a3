"""Reading a MATLAB ``.mat`` log into a :class:`~maglev_oc.data.validation.RawLog` (SPEC 2):
v5/v7 files with ``scipy.io.loadmat``, v7.3 files (HDF5, what MATLAB writes with ``-v7.3`` and
Simulink/QUARC's large logs) with ``h5py``.

The same names as the CSV columns, as top-level vectors, and optionally a struct ``metadata``
of strings (numbers are accepted and written with 17 significant digits). Locations in messages
are the variable and the 1-based element.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.io

from maglev_oc.data.log import KNOWN_COLUMNS
from maglev_oc.data.validation import RawLog, check_required_columns
from maglev_oc.errors import LogError

__all__ = ["read_mat"]

_NO_H5PY = (
    "MATLAB 7.3 MAT-file (HDF5): reading it needs h5py (pip install h5py), or save it as v7 in "
    "MATLAB with save(name, ..., '-v7')"
)


def read_mat(path: Path, source: str) -> RawLog:
    """The columns, metadata and locations of a .mat log; LogError for anything malformed.

    Parameters
    ----------
    path : Path
        The file (opened for reading only).
    source : str
        The name used in messages.

    Returns
    -------
    RawLog
    """
    variables = _load_variables(path, source)
    metadata: dict[str, str] = {}
    if "metadata" in variables:
        meta = variables.pop("metadata")
        metadata = meta if isinstance(meta, dict) else _mat_metadata(meta, source)
    names = list(variables)
    check_required_columns(names, source, where=None, line=None)
    columns = _vectors(variables, source)
    notes: list[str] = []
    ignored = [name for name in names if name not in KNOWN_COLUMNS]
    if ignored:
        notes.append("ignored variable(s) " + ", ".join(map(repr, ignored)) + ": not in SPEC 2")
    if columns["t"].size == 0:
        raise LogError(source, "no samples (the vectors are empty)", where=_label("t"), column="t")

    def where(k: int, name: str | None = None) -> tuple[str, int | None]:
        return (f"{_label(name)}, element {k + 1}" if name else f"element {k + 1}"), None

    metadata_where = {key: f"metadata.{key}" for key in metadata}
    return RawLog(source, columns, metadata, metadata_where, notes, where)


def _label(name: str) -> str:
    return f"variable {name!r}"


def _load_variables(path: Path, source: str) -> dict[str, object]:
    """The file's top-level variables (MATLAB's own ``__header__`` etc. left out)."""
    with path.open("rb") as fh:
        head = fh.read(128)
    if head.startswith(b"MATLAB 7.3"):
        return _load_v73(path, source)
    try:
        data = scipy.io.loadmat(path, squeeze_me=False, chars_as_strings=True, appendmat=False)
    except NotImplementedError:  # an HDF5 body behind another header
        return _load_v73(path, source)
    except (ValueError, TypeError, OSError) as err:
        raise LogError(source, f"not a readable MATLAB .mat file ({err})") from None
    variables = {k: v for k, v in data.items() if not k.startswith("__")}
    if not variables:
        raise LogError(source, "empty file: no variables")
    return variables


def _load_v73(path: Path, source: str) -> dict[str, object]:
    """The top-level variables of a v7.3 file: numeric arrays as MATLAB shapes them (HDF5 stores
    them transposed), the struct ``metadata`` as a dict of str. MATLAB's bookkeeping (``#refs#``,
    ``#subsystem#``) is left out."""
    try:
        import h5py
    except ImportError:
        raise LogError(source, _NO_H5PY) from None
    try:
        with h5py.File(path, "r") as f:
            variables = {}
            for name, item in f.items():
                if name.startswith("#"):
                    continue
                kind = _matlab_class(item)
                if name == "metadata" and kind == "struct" and isinstance(item, h5py.Group):
                    variables[name] = _v73_struct_strings(item, source)
                elif isinstance(item, h5py.Dataset) and kind not in ("char", "cell", "struct"):
                    variables[name] = _v73_array(item)
                else:
                    variables[name] = np.array([kind or "unknown"])  # refused by name if it is a column
    except OSError as err:
        raise LogError(source, f"not a readable MATLAB 7.3 (HDF5) file ({err})") from None
    if not variables:
        raise LogError(source, "empty file: no variables")
    return variables


def _matlab_class(item) -> str:
    kind = item.attrs.get("MATLAB_class", b"")
    return kind.decode() if isinstance(kind, bytes) else str(kind)


def _v73_array(dataset) -> np.ndarray:
    if dataset.attrs.get("MATLAB_empty", 0):
        return np.zeros((0, 0))
    return np.asarray(dataset[()]).T  # HDF5 keeps MATLAB's column-major order: transpose back


def _v73_struct_strings(group, source: str) -> dict[str, str]:
    """A v7.3 struct of strings (uint16 characters) or scalars -> dict of str."""
    out: dict[str, str] = {}
    for key, item in group.items():
        kind = _matlab_class(item)
        data = None if not hasattr(item, "shape") else _v73_array(item)
        if kind == "char" and data is not None:
            out[key] = "".join(map(chr, data.ravel(order="F"))) if data.size else ""
        elif data is not None and data.dtype.kind in "biuf" and data.size == 1:
            out[key] = f"{float(data.ravel()[0]):.17g}"
        else:
            raise _not_text(source, key)
    return out


def _vectors(variables: dict[str, object], source: str) -> dict[str, np.ndarray]:
    """The known variables as float vectors of one length; LogError for anything else."""
    columns: dict[str, np.ndarray] = {}
    length_of: str | None = None
    for name, value in variables.items():
        if name not in KNOWN_COLUMNS:
            continue
        if not isinstance(value, np.ndarray) or value.dtype.kind not in "biuf":
            complex_ = isinstance(value, np.ndarray) and value.dtype.kind == "c"
            raise LogError(
                source,
                f"{'complex' if complex_ else 'not numeric'} (dtype {getattr(value, 'dtype', '?')}); "
                "expected a real numeric vector",
                where=_label(name),
                column=name,
            )
        if value.ndim > 2 or min(value.shape, default=0) > 1:
            raise LogError(
                source, f"has shape {value.shape}; expected a vector", where=_label(name), column=name
            )
        vector = value.astype(float).ravel()
        if length_of is not None and vector.size != columns[length_of].size:
            raise LogError(
                source,
                f"has {vector.size} elements but {length_of!r} has {columns[length_of].size}",
                where=_label(name),
                column=name,
            )
        length_of = length_of or name
        columns[name] = vector
    return columns


def _mat_metadata(value: object, source: str) -> dict[str, str]:
    """A MATLAB struct of strings (or numbers) -> dict of str."""
    arr = np.asarray(value)
    if arr.dtype.names is None or arr.size != 1:
        raise LogError(
            source, "expected a 1x1 struct of strings", where="variable 'metadata'", column="metadata"
        )
    record = arr.ravel()[0]
    out: dict[str, str] = {}
    for key in arr.dtype.names:
        item = np.asarray(record[key])
        if item.dtype.kind == "U":
            out[key] = str(item.ravel()[0]) if item.size else ""
        elif item.dtype.kind in "biuf" and item.size == 1:
            out[key] = f"{float(item.ravel()[0]):.17g}"
        else:
            raise _not_text(source, key)
    return out


def _not_text(source: str, key: str) -> LogError:
    return LogError(
        source,
        f"field {key!r} is neither a string nor a number",
        where="variable 'metadata'",
        column="metadata",
    )
