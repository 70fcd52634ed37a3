"""Logs of runs on the stage: reading, validating and writing them (SPEC 2).

A log is one run: time, the four states and the two inputs, in SI units,

    t [s];  x = (x1 air gap [m], x2 its rate [m/s], x3 horizontal position [m], x4 its rate [m/s]);
    u = (u1 = i_q [A], u2 = i_d [A]),

held by :class:`Log` with the shapes ``t (n,)``, ``x (4, n)``, ``u (2, n)``. A log that did not
carry the velocities has NaN rows for x2 and x4 (:attr:`Log.states_measured` says which rows
are data); :mod:`maglev_oc.estimation.differentiate` estimates them from x1, x3.

File formats
------------
CSV: any number of metadata lines ``# key: value`` (for example ``# sample_rate_hz: 5000``,
``# units: SI``, ``# currents: measured``), then one header line of comma-separated column
names, then one numeric row per sample. MATLAB ``.mat`` (v5/v7, what ``scipy.io.loadmat``
reads): the same names as top-level vectors and, optionally, a struct ``metadata`` of strings.

Columns: ``t, x1, x3, u1, u2`` are required; ``x2, x4`` are optional; the phase currents
``ia, ib, ic`` [A] may replace ``u1, u2``: then ``(i_q, i_d)`` come from the transform of
eq. (2) of paper 001 (002 Sec. 3) at the logged mover position x3 (:func:`phase_currents_to_inputs`).
If both are present the logged u1, u2 are used and a note records how far they are from the
transform when that exceeds ``transform_tolerance``. Any other column is ignored with a note.
The currents are taken to be the commanded ones unless the metadata says ``currents: measured``.

Validation
----------
Every problem raises :class:`LogError` (a ``ValueError``) whose message names the file, the line
(1-based, counting the metadata lines, as an editor shows it) or the MATLAB variable and element,
the column, and what is wrong: missing columns, duplicate names, non-numeric cells, NaN or inf,
time not strictly increasing, gaps in time (a step above 1.5x the median), a metadata sample rate
the time column contradicts, values that look like millimetres (gap above 0.1 m, |x3| above
0.5 m) or milliamperes (above 100 A), and logs too short to identify anything from. Nothing is
guessed, converted or repaired silently, and the input file is only ever opened for reading.
:func:`check_excitation` refuses logs on which an input or output does not move.
"""

from __future__ import annotations

import dataclasses
import io
import math
import os
import re
import types
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import scipy.io

from maglev_oc.errors import LogError
from maglev_oc.fileio import atomic_path
from maglev_oc.model.hardware import ENCODER_RESOLUTION, PEAK_CURRENT_LIMIT
from maglev_oc.model.parameters import StageParameters

REQUIRED_COLUMNS = ("t", "x1", "x3", "u1", "u2")
"""Columns every log must have (u1, u2 may be replaced by the phase currents ia, ib, ic)."""
STATE_COLUMNS = ("x1", "x2", "x3", "x4")
INPUT_COLUMNS = ("u1", "u2")
PHASE_COLUMNS = ("ia", "ib", "ic")
KNOWN_COLUMNS = ("t", *STATE_COLUMNS, *INPUT_COLUMNS, *PHASE_COLUMNS)

CURRENT_RESOLUTION = 1e-3
"""Resolution of a logged current [A], about 1 mA."""

MAX_AIR_GAP = 0.1
"""[m] The air gap of the stage is 0..40 mm; a value above 0.1 m is a gap in millimetres."""
MAX_HORIZONTAL_POSITION = 0.5
"""[m] Horizontal travel is about +-50 mm (SPEC 4); |x3| above 0.5 m is millimetres."""
MAX_CURRENT = 100.0
"""[A] The amplifiers give 9 A peak (``PEAK_CURRENT_LIMIT``); a current above 100 A is in
milliamperes."""
MAX_SAMPLE_TIME = 0.05
"""[s] The control loop runs at 5 kHz; a median step above 50 ms (20 Hz, too coarse for the
closed-loop dynamics at up to 9 Hz) means the time column is in milliseconds or the log is
decimated beyond use."""
GAP_FACTOR = 1.5
"""A time step larger than this multiple of the median step is a gap (samples missing)."""
SAMPLE_RATE_TOLERANCE = 0.01
"""Relative disagreement allowed between ``sample_rate_hz`` in the metadata and the data."""
TRANSFORM_TOLERANCE = 0.01
"""[A] Logged u1, u2 differing from the transform of ia, ib, ic by more than this get a note:
10x the current resolution, so rounding never triggers it, while a wrong pole pitch, phase
order or sign (errors of the order of the currents themselves) always does."""

_NUMBER = re.compile(
    r"\s*[+-]?(?:\d+\.?\d*(?:[eE][+-]?\d+)?|\.\d+(?:[eE][+-]?\d+)?|nan|inf(?:inity)?)\s*",
    re.IGNORECASE,
)
_MATLAB_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,62}")


# --- the Log ------------------------------------------------------------------------------------
def _readonly(value: object, name: str, shape: tuple[int, ...] | None = None) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float, copy=True)
    except (TypeError, ValueError):
        raise ValueError(f"Log.{name}: expected a numeric array, got {type(value).__name__}") from None
    if shape is not None and arr.shape != shape:
        raise ValueError(f"Log.{name}: expected shape {shape}, got {arr.shape}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Log:
    """One run of the stage, SI units, validated when made.

    Parameters
    ----------
    t : (n,) array
        Time [s], finite and strictly increasing, n >= 2.
    x : (4, n) array
        States: air gap x1 [m], its rate x2 [m/s], horizontal position x3 [m], its rate x4 [m/s].
        x1 and x3 are finite; x2 and x4 are either finite or all NaN (not measured).
    u : (2, n) array
        Inputs u1 = i_q [A], u2 = i_d [A], finite.
    metadata : mapping of str to str
        The ``# key: value`` lines of the file (stored read-only).
    source : str
        Where the log came from (a path).
    notes : tuple of str
        What reading did beyond copying numbers: ignored columns, conversions, slicing.
    currents_measured : bool
        True when the currents were measured (metadata ``currents: measured``); otherwise they
        are the commanded values (SPEC 2).

    The arrays are copies and read-only. Invalid values raise ``ValueError`` naming the field.
    """

    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    metadata: Mapping[str, str] = field(default_factory=dict)
    source: str = ""
    notes: tuple[str, ...] = ()
    currents_measured: bool = False

    def __post_init__(self) -> None:
        t = _readonly(self.t, "t")
        if t.ndim != 1:
            raise ValueError(f"Log.t: expected a 1-D array (n,), got shape {t.shape}")
        n = t.size
        if n < 2:
            raise ValueError(f"Log.t: need at least 2 samples, got {n}")
        x = _readonly(self.x, "x", (4, n))
        u = _readonly(self.u, "u", (2, n))
        if not np.all(np.isfinite(t)):
            k = int(np.flatnonzero(~np.isfinite(t))[0])
            raise ValueError(f"Log.t: sample {k} is {float(t[k])!r}; time must be finite")
        steps = np.diff(t)
        if np.any(steps <= 0):
            k = int(np.flatnonzero(steps <= 0)[0]) + 1
            raise ValueError(
                f"Log.t: time must increase strictly; t[{k}] = {float(t[k])!r} s after "
                f"t[{k - 1}] = {float(t[k - 1])!r} s"
            )
        for row, name in enumerate(STATE_COLUMNS):
            finite = np.isfinite(x[row])
            if name in ("x2", "x4") and not np.any(finite) and np.all(np.isnan(x[row])):
                continue  # not measured
            if not np.all(finite):
                k = int(np.flatnonzero(~finite)[0])
                raise ValueError(
                    f"Log.x: row {row} ({name}) has {float(x[row, k])!r} at sample {k}; x1, x3 must be "
                    "finite and x2, x4 either finite or all NaN"
                )
        if not np.all(np.isfinite(u)):
            row, k = (int(i[0]) for i in np.nonzero(~np.isfinite(u)))
            raise ValueError(f"Log.u: row {row} (u{row + 1}) has {float(u[row, k])!r} at sample {k}")
        metadata = dict(self.metadata)
        for key, value in metadata.items():
            if not isinstance(key, str) or not isinstance(value, str):
                raise ValueError(f"Log.metadata: keys and values must be str, got {key!r}: {value!r}")
        notes = tuple(self.notes)
        if not all(isinstance(note, str) for note in notes):
            raise ValueError(f"Log.notes: expected a tuple of str, got {self.notes!r}")
        if not isinstance(self.currents_measured, (bool, np.bool_)):
            raise ValueError(f"Log.currents_measured: expected a bool, got {self.currents_measured!r}")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "u", u)
        object.__setattr__(self, "metadata", types.MappingProxyType(metadata))
        object.__setattr__(self, "source", str(self.source))
        object.__setattr__(self, "notes", notes)
        object.__setattr__(self, "currents_measured", bool(self.currents_measured))

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.t.size)

    @property
    def sample_time(self) -> float:
        """Median time step [s]."""
        return float(np.median(np.diff(self.t)))

    @property
    def duration(self) -> float:
        """t[-1] - t[0] [s]."""
        return float(self.t[-1] - self.t[0])

    @property
    def states_measured(self) -> tuple[bool, bool, bool, bool]:
        """For x1..x4, whether the row holds data (False: x2 or x4 was not in the log, NaN row)."""
        return tuple(bool(np.all(np.isfinite(row))) for row in self.x)  # type: ignore[return-value]

    def index_slice(self, start: int | None = None, stop: int | None = None) -> Log:
        """Samples ``start:stop`` (Python slice semantics) as a new Log with a note saying so."""
        rows = range(self.n)[slice(start, stop)]
        if len(rows) < 2:
            raise ValueError(
                f"Log.index_slice: samples [{start}:{stop}] of a {self.n}-sample log leave "
                f"{len(rows)} sample(s); need at least 2"
            )
        sel = slice(rows.start, rows.stop)
        note = f"samples {rows.start}..{rows.stop - 1} of {self.n} (index_slice)"
        return dataclasses.replace(
            self, t=self.t[sel], x=self.x[:, sel], u=self.u[:, sel], notes=(*self.notes, note)
        )

    def time_slice(self, t_start: float, t_stop: float) -> Log:
        """Samples with ``t_start <= t < t_stop`` [s] as a new Log (e.g. a held-out part)."""
        if not t_start < t_stop:
            raise ValueError(f"Log.time_slice: need t_start < t_stop, got {t_start!r}, {t_stop!r}")
        start = int(np.searchsorted(self.t, t_start, side="left"))
        stop = int(np.searchsorted(self.t, t_stop, side="left"))
        if stop - start < 2:
            raise ValueError(
                f"Log.time_slice: [{t_start!r}, {t_stop!r}) s holds {stop - start} sample(s) of a log "
                f"spanning [{float(self.t[0])!r}, {float(self.t[-1])!r}] s; need at least 2"
            )
        note = f"t in [{t_start!r}, {t_stop!r}) s (time_slice)"
        return dataclasses.replace(
            self,
            t=self.t[start:stop],
            x=self.x[:, start:stop],
            u=self.u[:, start:stop],
            notes=(*self.notes, note),
        )

    def columns(self) -> dict[str, np.ndarray]:
        """The log as named columns (the file's names): t, x1, [x2], x3, [x4], u1, u2."""
        out = {"t": self.t}
        for row, name in enumerate(STATE_COLUMNS):
            if self.states_measured[row]:
                out[name] = self.x[row]
        out["u1"], out["u2"] = self.u[0], self.u[1]
        return out


# --- the dq transform -------------------------------------------------------------------------
def phase_currents_to_inputs(
    ia: np.ndarray, ib: np.ndarray, ic: np.ndarray, x3: np.ndarray, pole_pitch: float
) -> np.ndarray:
    """Inputs ``u = (i_q, i_d)`` [A], shape (2, n), from the phase currents at mover position x3.

    Eq. (2) of paper 001 (002 Sec. 3), with theta = pi x3 / tau:

        i_d =  2/3 [cos(theta) ia + cos(theta - 2 pi/3) ib + cos(theta + 2 pi/3) ic]
        i_q = -2/3 [sin(theta) ia + sin(theta - 2 pi/3) ib + sin(theta + 2 pi/3) ic]

    Parameters
    ----------
    ia, ib, ic : (n,) arrays
        Phase currents [A].
    x3 : (n,) array
        Horizontal mover position [m].
    pole_pitch : float
        tau [m] (``StageParameters().pole_pitch`` = 57.15 mm).
    """
    theta = np.pi * np.asarray(x3, dtype=float) / pole_pitch
    shifts = (0.0, -2 * np.pi / 3, 2 * np.pi / 3)
    phases = (np.asarray(ia, dtype=float), np.asarray(ib, dtype=float), np.asarray(ic, dtype=float))
    i_d = 2 / 3 * sum(np.cos(theta + s) * i for s, i in zip(shifts, phases, strict=True))
    i_q = -2 / 3 * sum(np.sin(theta + s) * i for s, i in zip(shifts, phases, strict=True))
    return np.vstack([i_q, i_d])


def inputs_to_phase_currents(u: np.ndarray, x3: np.ndarray, pole_pitch: float) -> np.ndarray:
    """Balanced phase currents ``(ia, ib, ic)`` [A], shape (3, n), that give ``u = (i_q, i_d)``.

    The inverse of :func:`phase_currents_to_inputs` for currents that sum to zero (the star-
    connected stator): i_k = cos(theta_k) i_d - sin(theta_k) i_q with theta_k = pi x3 / tau,
    theta - 2 pi/3, theta + 2 pi/3. This is what the controller sends to the amplifiers (002 Fig. 8).
    """
    u = np.asarray(u, dtype=float)
    if u.ndim != 2 or u.shape[0] != 2:
        raise ValueError(f"u: expected shape (2, n) = (i_q, i_d), got {u.shape}")
    theta = np.pi * np.asarray(x3, dtype=float) / pole_pitch
    i_q, i_d = u
    shifts = (0.0, -2 * np.pi / 3, 2 * np.pi / 3)
    return np.vstack([np.cos(theta + s) * i_d - np.sin(theta + s) * i_q for s in shifts])


# --- reading ------------------------------------------------------------------------------------
@dataclass
class _Raw:
    """What a reader found, before the checks common to both formats."""

    columns: dict[str, np.ndarray]
    metadata: dict[str, str]
    metadata_where: dict[str, str]
    notes: list[str]
    where: Callable[[int, str | None], tuple[str, int | None]]  # (sample, column) -> (place, line)


def read_log(
    path: str | os.PathLike,
    *,
    params: StageParameters | None = None,
    min_samples: int = 100,
    min_duration: float = 0.5,
    transform_tolerance: float = TRANSFORM_TOLERANCE,
) -> Log:
    """Read and validate a log (CSV or MATLAB .mat, by suffix; SPEC 2).

    Parameters
    ----------
    path : path-like
        ``.mat`` is read with ``scipy.io.loadmat``; any other suffix as CSV text.
    params : StageParameters, optional
        Supplies the pole pitch tau [m] for the phase-current transform (default Table I).
    min_samples : int
        Fewest samples accepted (default 100).
    min_duration : float
        Shortest duration accepted [s] (default 0.5 s).
    transform_tolerance : float
        [A] When u1, u2 and ia, ib, ic are both present, a larger disagreement gets a note.

    Returns
    -------
    Log
        ``source`` is ``str(path)``; ``notes`` says what was ignored or converted.

    Raises
    ------
    LogError
        The file is not a valid log; the message names the file, line/element and column.
    FileNotFoundError
        No such file.
    """
    if isinstance(min_samples, bool) or not isinstance(min_samples, int) or min_samples < 2:
        raise ValueError(f"min_samples must be an integer >= 2, got {min_samples!r}")
    if not (min_duration >= 0 and math.isfinite(min_duration)):
        raise ValueError(f"min_duration must be >= 0 [s], got {min_duration!r}")
    if not (transform_tolerance > 0):
        raise ValueError(f"transform_tolerance must be positive [A], got {transform_tolerance!r}")
    params = StageParameters() if params is None else params
    path = Path(path)
    source = str(path)
    if not path.is_file():
        raise FileNotFoundError(f"{source}: no such file")
    raw = _read_mat(path, source) if path.suffix.lower() == ".mat" else _read_csv(path, source)
    return _validated(raw, source, params, min_samples, min_duration, transform_tolerance)


def _read_csv(path: Path, source: str) -> _Raw:
    data = path.read_bytes()
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise LogError(
            source, f"byte {err.start} is not UTF-8 text; is this a binary file (use .mat for MATLAB)?"
        ) from None
    if "\r" in text:
        text = text.replace("\r\n", "\n").replace("\r", "\n")

    metadata: dict[str, str] = {}
    meta_line: dict[str, int] = {}
    notes: list[str] = []
    header: str | None = None
    header_line = 0
    commented_header: int | None = None
    pos = lineno = 0
    while pos < len(text):
        end = text.find("\n", pos)
        end = len(text) if end < 0 else end
        line, pos, lineno = text[pos:end], end + 1, lineno + 1
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            body = stripped[1:].strip()
            key, sep, value = body.partition(":")
            key, value = key.strip(), value.strip()
            if not sep or not key:
                if "," in body and {"t", "x1"} <= {c.strip() for c in body.split(",")}:
                    commented_header = lineno
                notes.append(f"line {lineno}: comment without 'key: value' ignored")
                continue
            if key in metadata and metadata[key] != value:
                raise LogError(
                    source,
                    f"metadata {key!r} is given twice with different values: {metadata[key]!r} "
                    f"(line {meta_line[key]}) and {value!r}",
                    where=f"line {lineno}",
                    line=lineno,
                )
            metadata[key], meta_line[key] = value, lineno
            continue
        header, header_line = line, lineno
        break
    if header is None:
        raise LogError(
            source,
            "empty file: no header line and no data (expected '# key: value' lines, a header such "
            "as 't,x1,x3,u1,u2', then numeric rows)",
        )

    names = [name.strip() for name in header.split(",")]
    index = {name: j for j, name in enumerate(names)}

    def label(name: str) -> str:
        return f"column {index[name] + 1} ({name!r})"

    hdr = f"line {header_line}"
    if all(_NUMBER.fullmatch(name) for name in names):
        hint = (
            f"; line {commented_header} looks like the header written as a comment: remove its '#'"
            if commented_header
            else ""
        )
        raise LogError(
            source,
            f"no header line: {header.strip()[:60]!r} is numbers, expected column names such as "
            f"t, x1, x3, u1, u2{hint}",
            where=hdr,
            line=header_line,
        )
    for j, name in enumerate(names):
        if not name:
            raise LogError(
                source, "empty column name in the header", where=f"{hdr}, column {j + 1}", line=header_line
            )
    seen: dict[str, list[int]] = {}
    for j, name in enumerate(names):
        seen.setdefault(name, []).append(j + 1)
    duplicates = {name: cols for name, cols in seen.items() if len(cols) > 1}
    if duplicates:
        listed = "; ".join(f"{name!r} in columns {', '.join(map(str, c))}" for name, c in duplicates.items())
        raise LogError(
            source,
            f"duplicate column names in the header: {listed}",
            where=hdr,
            line=header_line,
            column=next(iter(duplicates)),
        )
    _check_required(names, source, where=hdr, line=header_line)
    used = [name for name in names if name in KNOWN_COLUMNS]
    ignored = [name for name in names if name not in KNOWN_COLUMNS]
    if ignored:
        notes.append("ignored column(s) " + ", ".join(label(name) for name in ignored) + ": not in SPEC 2")

    body = text[pos:]
    if "\n " in body or "\n\t" in body or body[:1] in (" ", "\t"):
        # lines holding only spaces would be rows to numpy; make them empty (line count unchanged)
        body = re.sub(r"(?m)^[ \t]+$", "", body)
    if not re.search(r"\S", body):
        raise LogError(source, "header only: no data rows after the header", where=hdr, line=header_line)

    first_data_line = header_line + 1
    line_numbers: list[int] = []  # filled on first use when blank lines break "row k = line k"
    contiguous = not body.startswith("\n") and "\n\n" not in body.rstrip("\n")

    def line_of(k: int) -> int:
        if contiguous:
            return first_data_line + k
        if not line_numbers:
            line_numbers.extend(first_data_line + i for i, s in enumerate(body.split("\n")) if s.strip())
        return line_numbers[k]

    usecols = [index[name] for name in used]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # an empty or odd file must not pass with a warning
            table = np.loadtxt(
                io.StringIO(body), delimiter=",", comments=None, usecols=usecols, ndmin=2, dtype=float
            )
    except (ValueError, UserWarning) as err:
        _locate_bad_cell(body, names, used, first_data_line, source, header_line)
        raise LogError(source, f"could not read the data rows: {err}", where=hdr) from None
    n_rows = table.shape[0]
    if body.count(",") != n_rows * (len(names) - 1):
        _locate_bad_cell(body, names, used, first_data_line, source, header_line)

    def where(k: int, name: str | None = None) -> tuple[str, int | None]:
        line = line_of(k)
        return (f"line {line}, {label(name)}" if name else f"line {line}"), line

    columns = {name: table[:, j] for j, name in enumerate(used)}
    metadata_where = {key: f"line {meta_line[key]} (metadata {key!r})" for key in metadata}
    return _Raw(columns, metadata, metadata_where, notes, where)


def _locate_bad_cell(
    body: str, names: list[str], used: list[str], first_line: int, source: str, header_line: int
) -> None:
    """Slow pass over the rows, only after the fast parse failed: raise at the first bad cell."""
    wanted = [(j, name) for j, name in enumerate(names) if name in used]
    for i, line in enumerate(body.split("\n")):
        if not line.strip():
            continue
        lineno = first_line + i
        cells = line.split(",")
        if len(cells) != len(names):
            raise LogError(
                source,
                f"row has {len(cells)} cells, the header (line {header_line}) has {len(names)} names",
                where=f"line {lineno}",
                line=lineno,
            )
        for j, name in wanted:
            if not _NUMBER.fullmatch(cells[j]):
                text = cells[j].strip()
                what = "an empty cell" if not text else f"{text[:40]!r}"
                raise LogError(
                    source,
                    f"{what} is not a number",
                    where=f"line {lineno}, column {j + 1} ({name!r})",
                    line=lineno,
                    column=name,
                )


def _read_mat(path: Path, source: str) -> _Raw:
    with path.open("rb") as fh:
        head = fh.read(128)
    v73 = (
        "MATLAB 7.3 MAT-file is an HDF5 file, which this reader does not take; save it as v7 "
        "in MATLAB with save(name, ..., '-v7')"
    )
    if head.startswith(b"MATLAB 7.3"):
        raise LogError(source, v73)
    try:
        data = scipy.io.loadmat(path, squeeze_me=False, chars_as_strings=True, appendmat=False)
    except NotImplementedError:
        raise LogError(source, v73) from None
    except (ValueError, TypeError, OSError) as err:
        raise LogError(source, f"not a readable MATLAB .mat file ({err})") from None
    variables = {k: v for k, v in data.items() if not k.startswith("__")}
    if not variables:
        raise LogError(source, "empty file: no variables")

    def label(name: str) -> str:
        return f"variable {name!r}"

    notes: list[str] = []
    metadata: dict[str, str] = {}
    if "metadata" in variables:
        metadata = _mat_metadata(variables.pop("metadata"), source)
    names = list(variables)
    _check_required(names, source, where=None, line=None)
    columns: dict[str, np.ndarray] = {}
    length_of: str | None = None
    for name in names:
        if name not in KNOWN_COLUMNS:
            continue
        value = variables[name]
        if not isinstance(value, np.ndarray) or value.dtype.kind not in "biuf":
            complex_ = isinstance(value, np.ndarray) and value.dtype.kind == "c"
            raise LogError(
                source,
                f"{'complex' if complex_ else 'not numeric'} (dtype {getattr(value, 'dtype', '?')}); "
                "expected a real numeric vector",
                where=label(name),
                column=name,
            )
        if value.ndim > 2 or min(value.shape, default=0) > 1:
            raise LogError(
                source, f"has shape {value.shape}; expected a vector", where=label(name), column=name
            )
        vector = value.astype(float).ravel()
        if length_of is not None and vector.size != columns[length_of].size:
            raise LogError(
                source,
                f"has {vector.size} elements but {length_of!r} has {columns[length_of].size}",
                where=label(name),
                column=name,
            )
        length_of = length_of or name
        columns[name] = vector
    ignored = [name for name in names if name not in KNOWN_COLUMNS]
    if ignored:
        notes.append("ignored variable(s) " + ", ".join(map(repr, ignored)) + ": not in SPEC 2")
    if columns["t"].size == 0:
        raise LogError(source, "no samples (the vectors are empty)", where=label("t"), column="t")

    def where(k: int, name: str | None = None) -> tuple[str, int | None]:
        return (f"{label(name)}, element {k + 1}" if name else f"element {k + 1}"), None

    metadata_where = {key: f"metadata.{key}" for key in metadata}
    return _Raw(columns, metadata, metadata_where, notes, where)


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
            raise LogError(
                source,
                f"field {key!r} is neither a string nor a number",
                where="variable 'metadata'",
                column="metadata",
            )
    return out


def _check_required(names: list[str], source: str, *, where: str | None, line: int | None) -> None:
    present = set(names)
    partial = [c for c in PHASE_COLUMNS if c in present]
    if partial and len(partial) < len(PHASE_COLUMNS):
        missing = [c for c in PHASE_COLUMNS if c not in present]
        raise LogError(
            source,
            f"phase currents need all of ia, ib, ic; found {', '.join(partial)}, missing "
            f"{', '.join(missing)} (columns found: {', '.join(names)})",
            where=where,
            line=line,
            column=missing[0],
        )
    has_phases = len(partial) == len(PHASE_COLUMNS)
    missing = [c for c in ("t", "x1", "x3") if c not in present]
    if not has_phases:
        missing += [c for c in INPUT_COLUMNS if c not in present]
    if missing:
        alternative = "" if has_phases else " (u1, u2 may be replaced by phase currents ia, ib, ic)"
        raise LogError(
            source,
            f"missing required column(s) {', '.join(missing)}{alternative}; columns found: "
            f"{', '.join(names) if names else 'none'}",
            where=where,
            line=line,
            column=missing[0],
        )


def _validated(
    raw: _Raw,
    source: str,
    params: StageParameters,
    min_samples: int,
    min_duration: float,
    transform_tolerance: float,
) -> Log:
    """The checks common to CSV and .mat, then the Log."""
    cols = raw.columns
    notes = list(raw.notes)

    def fail(k: int, name: str | None, problem: str) -> LogError:
        place, line = raw.where(k, name)
        return LogError(source, problem, where=place, line=line, column=name)

    # NaN / inf: the first bad sample, and the first column bad there
    names = list(cols)
    finite = np.vstack([np.isfinite(cols[name]) for name in names])
    if not finite.all():
        bad_rows = ~finite.all(axis=0)
        k = int(np.argmax(bad_rows))
        name = names[int(np.argmax(~finite[:, k]))]
        raise fail(k, name, f"{float(cols[name][k])!r} value; every cell must be a finite number")

    t = cols["t"]
    n = t.size
    if n >= 2:
        steps = np.diff(t)
        if np.any(steps <= 0):
            k = int(np.argmax(steps <= 0)) + 1
            previous = raw.where(k - 1, None)[0]
            raise fail(
                k,
                "t",
                f"time does not increase: t = {float(t[k])!r} s here after t = {float(t[k - 1])!r} s "
                f"({previous})",
            )
    duration = float(t[-1] - t[0])
    if n < min_samples or duration < min_duration:
        raise LogError(
            source,
            f"too short: {n} samples over {duration:.6g} s; need at least min_samples = {min_samples} "
            f"samples and min_duration = {min_duration:g} s to identify anything",
        )
    steps = np.diff(t)
    median = float(np.median(steps))
    if median > MAX_SAMPLE_TIME:
        raise LogError(
            source,
            f"the median time step is {median:.6g} s ({1 / median:.4g} Hz): is t in milliseconds? "
            f"Logs are in seconds, and steps above {MAX_SAMPLE_TIME:g} s are too coarse for the stage",
            column="t",
        )
    if np.any(steps > GAP_FACTOR * median):
        gaps = np.flatnonzero(steps > GAP_FACTOR * median)
        k = int(gaps[0]) + 1
        previous = raw.where(k - 1, None)[0]
        raise fail(
            k,
            "t",
            f"gap in time: t jumps by {steps[k - 1]:.6g} s from {float(t[k - 1])!r} s ({previous}) to "
            f"{float(t[k])!r} s, {steps[k - 1] / median:.3g} x the median step {median:.6g} s "
            f"(more than {GAP_FACTOR:g} x means samples are missing; {gaps.size} such gap(s) in all)",
        )

    meta = raw.metadata
    if "sample_rate_hz" in meta:
        stated_text = meta["sample_rate_hz"]
        try:
            stated = float(stated_text)
        except ValueError:
            stated = math.nan
        if not (stated > 0 and math.isfinite(stated)):
            raise LogError(
                source,
                f"sample_rate_hz {stated_text!r} is not a positive number",
                where=raw.metadata_where["sample_rate_hz"],
                line=_line_number(raw.metadata_where["sample_rate_hz"]),
            )
        measured = 1.0 / median
        if abs(measured - stated) > SAMPLE_RATE_TOLERANCE * stated:
            raise LogError(
                source,
                f"sample_rate_hz = {stated_text} disagrees with the time column, whose median step "
                f"{median:.6g} s is {measured:.6g} Hz (tolerance {SAMPLE_RATE_TOLERANCE:.0%})",
                where=raw.metadata_where["sample_rate_hz"],
                line=_line_number(raw.metadata_where["sample_rate_hz"]),
                column="t",
            )
    if "units" in meta and meta["units"].strip().lower() != "si":
        raise LogError(
            source,
            f"units {meta['units']!r}: only SI logs are read (m, m/s, A, s); convert the file",
            where=raw.metadata_where["units"],
            line=_line_number(raw.metadata_where["units"]),
        )
    currents = meta.get("currents", "commanded").strip().lower()
    if currents not in ("measured", "commanded"):
        raise LogError(
            source,
            f"currents {meta['currents']!r}: expected 'measured' or 'commanded'",
            where=raw.metadata_where["currents"],
            line=_line_number(raw.metadata_where["currents"]),
        )

    limits = [("x1", MAX_AIR_GAP, "air gap", "m", "0..40 mm", "millimetres", "metres")]
    limits.append(
        ("x3", MAX_HORIZONTAL_POSITION, "horizontal position", "m", "+-50 mm", "millimetres", "metres")
    )
    for name in (*INPUT_COLUMNS, *PHASE_COLUMNS):
        span = f"+-{PEAK_CURRENT_LIMIT:g} A"
        limits.append((name, MAX_CURRENT, "current", "A", span, "milliamperes", "amperes"))
    for name, limit, what, unit, span, small, si in limits:
        if name not in cols:
            continue
        big = np.abs(cols[name]) > limit
        if np.any(big):
            k = int(np.argmax(big))
            raise fail(
                k,
                name,
                f"{what} {float(cols[name][k])!r} {unit} is beyond {limit:g} {unit} (the stage spans "
                f"{span}): the column looks like {small}; logs are in {si} (SI)",
            )

    x = np.full((4, n), np.nan)
    for row, name in enumerate(STATE_COLUMNS):
        if name in cols:
            x[row] = cols[name]
    missing_rates = [name for name in ("x2", "x4") if name not in cols]
    if missing_rates:
        notes.append(f"{', '.join(missing_rates)} not in the log: NaN row(s)")

    tau = params.pole_pitch
    if all(name in cols for name in PHASE_COLUMNS):
        from_phases = phase_currents_to_inputs(cols["ia"], cols["ib"], cols["ic"], cols["x3"], tau)
        u = from_phases.copy()
        logged = [name for name in INPUT_COLUMNS if name in cols]
        for name in logged:
            u[INPUT_COLUMNS.index(name)] = cols[name]
        converted = [name for name in INPUT_COLUMNS if name not in cols]
        if converted:
            notes.append(
                f"{' and '.join(converted)} from ia, ib, ic by eq. (2) of paper 001 with tau = {tau:g} m"
            )
        for name in logged:
            row = INPUT_COLUMNS.index(name)
            diff = np.abs(cols[name] - from_phases[row])
            k = int(np.argmax(diff))
            if diff[k] > transform_tolerance:
                notes.append(
                    f"logged {name} differs from the transform of ia, ib, ic (tau = {tau:g} m) by up to "
                    f"{diff[k]:.4g} A ({raw.where(k, None)[0]}); tolerance {transform_tolerance:g} A; the "
                    f"logged {name} is used"
                )
        zero_sequence = np.abs(cols["ia"] + cols["ib"] + cols["ic"])
        if zero_sequence.max() > transform_tolerance:
            k = int(np.argmax(zero_sequence))
            notes.append(
                f"ia + ib + ic reaches {zero_sequence[k]:.4g} A ({raw.where(k, None)[0]}); the dq transform "
                "ignores this zero-sequence part"
            )
    else:
        u = np.vstack([cols["u1"], cols["u2"]])

    return Log(
        t=t,
        x=x,
        u=u,
        metadata=dict(meta),
        source=source,
        notes=tuple(notes),
        currents_measured=currents == "measured",
    )


def _line_number(where: str) -> int | None:
    match = re.match(r"line (\d+)", where)
    return int(match.group(1)) if match else None


# --- excitation ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class Excitation:
    """How much the signals that identification needs move.

    Attributes
    ----------
    std : mapping
        Standard deviation of x1, x3 [m] and u1, u2 [A].
    resolution : mapping
        The resolution each was compared with (same units).
    checked : tuple of str
        The signals that had to vary (the others are reported but not required).
    """

    std: Mapping[str, float]
    resolution: Mapping[str, float]
    checked: tuple[str, ...]


def check_excitation(
    log: Log,
    *,
    axis: Literal["vertical", "horizontal", "both"] = "both",
    position_resolution: float = ENCODER_RESOLUTION,
    current_resolution: float = CURRENT_RESOLUTION,
) -> Excitation:
    """Refuse a log on which a needed input or output is constant to within its resolution.

    A signal whose standard deviation is at most its resolution (encoder 10 um, current 1 mA)
    is constant as far as the data can tell: a held value toggling between two quantization
    levels has a standard deviation of at most half a step. Equation-error identification of
    the terms it multiplies is then impossible.

    Parameters
    ----------
    log : Log
    axis : {"vertical", "horizontal", "both"}
        Which dynamics are to be identified: vertical needs x1 and u2 (i_d) to vary, horizontal
        x3 and u1 (i_q); "both" all four (the vertical-only runs of 000 Table II hold x3 fixed).
    position_resolution : float
        [m] Default 10 um (the encoders).
    current_resolution : float
        [A] Default 1 mA.

    Returns
    -------
    Excitation

    Raises
    ------
    LogError
        Listing every constant signal with its standard deviation.
    """
    needed = {"vertical": ("x1", "u2"), "horizontal": ("x3", "u1"), "both": ("x1", "x3", "u1", "u2")}
    if axis not in needed:
        raise ValueError(f"axis must be 'vertical', 'horizontal' or 'both', got {axis!r}")
    for name, value in (
        ("position_resolution", position_resolution),
        ("current_resolution", current_resolution),
    ):
        if not (value > 0 and math.isfinite(value)):
            raise ValueError(f"{name} must be positive, got {value!r}")
    signals = {"x1": log.x[0], "x3": log.x[2], "u1": log.u[0], "u2": log.u[1]}
    resolution = {"x1": position_resolution, "x3": position_resolution}
    resolution |= {"u1": current_resolution, "u2": current_resolution}
    std = {name: float(np.std(value)) for name, value in signals.items()}
    flat = [name for name in needed[axis] if std[name] <= resolution[name]]
    if flat:
        units = {"x1": "m", "x3": "m", "u1": "A", "u2": "A"}
        listed = "; ".join(
            f"{name} std {std[name]:.3g} {units[name]} <= resolution {resolution[name]:g} {units[name]}"
            for name in flat
        )
        raise LogError(
            log.source or "<log>",
            f"no excitation: {listed}; identification needs these signals to vary "
            f"(e.g. the sum-of-sines references of 000 Sec. IV)",
            where=f"column(s) {', '.join(flat)}",
            column=flat[0],
        )
    return Excitation(types.MappingProxyType(std), types.MappingProxyType(resolution), needed[axis])


# --- writing ------------------------------------------------------------------------------------
def write_log(path: str | os.PathLike, log: Log) -> Path:
    """Write ``log`` atomically: MATLAB v5 when the suffix is ``.mat``, else CSV (``.csv``/``.txt``).

    CSV: ``# key: value`` lines (``units: SI``, ``sample_rate_hz`` from the median step, ``currents``
    and the log's other metadata), the header, then the rows in ``%.17g``, which
    :func:`read_log` turns back into the same float64 values. x2/x4 are written only when
    measured. ``.mat``: the columns as column vectors and a ``metadata`` struct of strings.
    ``notes`` are not written (they describe how this Log was made, not the data).

    Returns the path. Raises ``ValueError`` for an unknown suffix or metadata that the format
    cannot hold (newlines, ':' in a CSV key, a key that is not a MATLAB name for .mat).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".txt", ".mat"):
        raise ValueError(f"{path}: unknown log suffix {path.suffix!r}; use .csv, .txt or .mat")
    meta = {"units": "SI", "sample_rate_hz": f"{1.0 / log.sample_time:.10g}"}
    meta["currents"] = "measured" if log.currents_measured else "commanded"
    meta |= {k: v for k, v in log.metadata.items() if k not in meta}
    for key, value in meta.items():
        if not key.strip() or ":" in key or "\n" in key or "\n" in value or key.strip() != key:
            raise ValueError(f"{path}: metadata {key!r}: {value!r} cannot be written as '# key: value'")
    columns = log.columns()
    if suffix == ".mat":
        for key in meta:
            if not _MATLAB_NAME.fullmatch(key):
                raise ValueError(f"{path}: metadata key {key!r} is not a MATLAB field name")
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
    """Write arrays as a log: ``t`` (n,) [s], ``x`` (4, n) (NaN rows for unmeasured x2/x4), ``u`` (2, n) [A].

    The arrays are validated as for :class:`Log`; see :func:`write_log` for the formats.
    """
    log = Log(t, x, u, metadata=dict(metadata or {}), source=str(path), currents_measured=currents_measured)
    return write_log(path, log)
