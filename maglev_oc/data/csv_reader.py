"""Reading a log's CSV text into a :class:`~maglev_oc.data.validation.RawLog` (SPEC 2).

The format: any number of metadata lines ``# key: value``, then one header line of
comma-separated column names, then one numeric row per sample. Blank lines are skipped; line
numbers in messages are the editor's (1-based, counting the metadata lines). The rows are read by
numpy straight from the file, in one pass and without holding the text (a 3 M-row log needs the
array, not ten copies of its text); only when that fails does a slow pass find the bad cell.
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from maglev_oc.data.log import KNOWN_COLUMNS
from maglev_oc.data.validation import RawLog, check_required_columns
from maglev_oc.errors import LogError

__all__ = ["read_csv"]

_NUMBER = re.compile(
    r"\s*[+-]?(?:\d+\.?\d*(?:[eE][+-]?\d+)?|\.\d+(?:[eE][+-]?\d+)?|nan|inf(?:inity)?)\s*",
    re.IGNORECASE,
)


@dataclass
class _Preamble:
    """The metadata lines and the header line of a CSV log."""

    metadata: dict[str, str] = field(default_factory=dict)
    meta_line: dict[str, int] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    header: str | None = None
    header_line: int = 0
    commented_header: int | None = None  # a line that looks like the header behind a '#'
    body_start: int = 0  # offset of the first character after the header line


def read_csv(path: Path, source: str) -> RawLog:
    """The columns, metadata and locations of a CSV log; LogError for anything malformed.

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
    pre = _read_preamble(path, source)
    names = _header_names(pre, source)
    index = {name: j for j, name in enumerate(names)}

    def label(name: str) -> str:
        return f"column {index[name] + 1} ({name!r})"

    used = [name for name in names if name in KNOWN_COLUMNS]
    ignored = [name for name in names if name not in KNOWN_COLUMNS]
    notes = pre.notes
    if ignored:
        notes.append("ignored column(s) " + ", ".join(label(name) for name in ignored) + ": not in SPEC 2")
    body = _Body(path, pre.body_start, pre.header_line + 1, source)
    table = _load_table(body, names, used, pre.header_line)

    def where(k: int, name: str | None = None) -> tuple[str, int | None]:
        line = body.line_of(k)
        return (f"line {line}, {label(name)}" if name else f"line {line}"), line

    columns = {name: table[:, j] for j, name in enumerate(used)}
    metadata_where = {key: f"line {pre.meta_line[key]} (metadata {key!r})" for key in pre.metadata}
    return RawLog(source, columns, pre.metadata, metadata_where, notes, where)


def _decode_line(data: bytes, source: str, lineno: int) -> str:
    try:
        return data.decode("utf-8-sig" if lineno == 1 else "utf-8")
    except UnicodeDecodeError as err:
        raise LogError(
            source,
            f"byte {err.start} of line {lineno} is not UTF-8 text; is this a binary file "
            "(use .mat for MATLAB)?",
        ) from None


def _sniff_text(head: bytes, source: str) -> None:
    """LogError if the file's first bytes are not text (NUL bytes, or not UTF-8)."""
    nul = head.find(b"\x00")
    if nul >= 0:
        raise LogError(source, f"byte {nul} is NUL: a binary file, not a CSV log (use .mat for MATLAB)")
    cut = head.rfind(b"\n") + 1 if len(head) == 1 << 16 else len(head)  # whole lines only
    try:
        head[:cut].decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise LogError(
            source, f"byte {err.start} is not UTF-8 text; is this a binary file (use .mat for MATLAB)?"
        ) from None


def _read_preamble(path: Path, source: str) -> _Preamble:
    """The ``# key: value`` lines up to the header line (the first non-blank, non-comment line)."""
    pre = _Preamble()
    with path.open("rb") as f:
        _sniff_text(f.read(1 << 16), source)
        f.seek(0)
        for lineno, data in enumerate(iter(f.readline, b""), start=1):
            if b"\r" in data.rstrip(b"\r\n"):
                raise LogError(
                    source,
                    "lines end in a bare carriage return (classic Mac); save the file with "
                    "'\\n' line endings",
                    where=f"line {lineno}",
                    line=lineno,
                )
            stripped = _decode_line(data, source, lineno).strip()
            if not stripped:
                continue
            if not stripped.startswith("#"):
                pre.header, pre.header_line, pre.body_start = stripped, lineno, f.tell()
                return pre
            _metadata_line(pre, stripped[1:].strip(), lineno, source)
    raise LogError(
        source,
        "empty file: no header line and no data (expected '# key: value' lines, a header such "
        "as 't,x1,x3,u1,u2', then numeric rows)",
    )


def _metadata_line(pre: _Preamble, body: str, lineno: int, source: str) -> None:
    key, sep, value = body.partition(":")
    key, value = key.strip(), value.strip()
    if not sep or not key:
        if "," in body and {"t", "x1"} <= {c.strip() for c in body.split(",")}:
            pre.commented_header = lineno
        pre.notes.append(f"line {lineno}: comment without 'key: value' ignored")
        return
    if key in pre.metadata and pre.metadata[key] != value:
        raise LogError(
            source,
            f"metadata {key!r} is given twice with different values: {pre.metadata[key]!r} "
            f"(line {pre.meta_line[key]}) and {value!r}",
            where=f"line {lineno}",
            line=lineno,
        )
    pre.metadata[key], pre.meta_line[key] = value, lineno


def _header_names(pre: _Preamble, source: str) -> list[str]:
    """The column names of the header line, after checking they are names, distinct and complete."""
    header, header_line = pre.header, pre.header_line
    assert header is not None  # _read_preamble raises otherwise
    hdr = f"line {header_line}"
    if "," not in header:
        for delimiter, word in ((";", "';'"), ("\t", "tabs"), ("|", "'|'")):
            if header.count(delimiter) >= 2:
                raise LogError(
                    source,
                    f"the file uses {word} as delimiter; logs are comma-separated (header "
                    f"{header.strip()[:60]!r}): replace {word} by ',' (and any decimal commas by points)",
                    where=hdr,
                    line=header_line,
                )
    # names are matched without regard to case or surrounding spaces ("T, X1, X3, U1, U2")
    names = [name.strip() for name in header.split(",")]
    names = [name.lower() if name.lower() in KNOWN_COLUMNS else name for name in names]
    if all(_NUMBER.fullmatch(name) for name in names):
        hint = (
            f"; line {pre.commented_header} looks like the header written as a comment: remove its '#'"
            if pre.commented_header
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
    check_required_columns(names, source, where=hdr, line=header_line)
    return names


class _Body:
    """The data rows of a CSV file, read from disk on demand (never held as text)."""

    _CHUNK = 1 << 22

    def __init__(self, path: Path, offset: int, first_line: int, source: str) -> None:
        self.path, self.offset, self.first_line, self.source = path, offset, first_line, source
        self.n_lines = self.n_commas = 0
        self.n_rows: int | None = None  # set once parsed
        with path.open("rb") as f:  # one pass over the bytes: lines and commas
            f.seek(offset)
            last = b""
            for chunk in iter(lambda: f.read(self._CHUNK), b""):
                self.n_lines += chunk.count(b"\n")
                self.n_commas += chunk.count(b",")
                last = chunk[-1:]
            if last not in (b"\n", b""):
                self.n_lines += 1  # a last line without its newline
        self._line_numbers: list[int] | None = None

    def text_lines(self, *, blank_spaces: bool = False):
        """The rows as text lines (a generator); ``blank_spaces`` empties lines of only spaces."""
        with self.path.open("r", encoding="utf-8", newline=None) as f:
            f.seek(self.offset)
            for line in f:
                yield "\n" if blank_spaces and not line.strip() else line

    def line_of(self, k: int) -> int:
        """The editor line of data row ``k`` (blank lines skipped: found by a second pass, only
        when the rows are fewer than the lines and a message needs a line)."""
        if self.n_rows == self.n_lines:
            return self.first_line + k
        if self._line_numbers is None:
            self._line_numbers = [
                self.first_line + i for i, line in enumerate(self.text_lines()) if line.strip()
            ]
        return self._line_numbers[k]


def _load_table(body: _Body, names: list[str], used: list[str], header_line: int) -> np.ndarray:
    """The used columns as an (n, len(used)) array; LogError at the first bad cell or row."""
    source = body.source
    index = {name: j for j, name in enumerate(names)}
    usecols = [index[name] for name in used]

    def parse(lines) -> np.ndarray:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # an empty or odd file must not pass with a warning
            return np.loadtxt(lines, delimiter=",", comments=None, usecols=usecols, ndmin=2, dtype=float)

    try:
        try:
            table = parse(body.text_lines())
        except (ValueError, UserWarning):
            table = parse(body.text_lines(blank_spaces=True))  # lines of only spaces are blank
    except (ValueError, UserWarning) as err:
        if not any(line.strip() for line in body.text_lines()):
            table = np.zeros((0, len(used)))  # nothing but blank lines: header only, below
        else:
            _locate_bad_cell(body, names, used, header_line)
            raise LogError(
                source, f"could not read the data rows: {err}", where=f"line {header_line}"
            ) from None
    except UnicodeDecodeError:
        raise LogError(source, "the data rows are not UTF-8 text; is this a binary file?") from None
    if table.shape[0] == 0:
        raise LogError(
            source,
            "header only: no data rows after the header",
            where=f"line {header_line}",
            line=header_line,
        )
    body.n_rows = table.shape[0]
    if body.n_commas != table.shape[0] * (len(names) - 1):
        _locate_bad_cell(body, names, used, header_line)
    return table


def _locate_bad_cell(body: _Body, names: list[str], used: list[str], header_line: int) -> None:
    """Slow pass over the rows, only after the fast parse failed: raise at the first bad cell."""
    source = body.source
    wanted = [(j, name) for j, name in enumerate(names) if name in used]
    for i, line in enumerate(body.text_lines()):
        line = line.rstrip("\n")
        if not line.strip():
            continue
        lineno = body.first_line + i
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
