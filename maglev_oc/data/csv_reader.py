"""Reading a log's CSV text into a :class:`~maglev_oc.data.validation.RawLog` (SPEC 2).

The format: any number of metadata lines ``# key: value``, then one header line of
comma-separated column names, then one numeric row per sample. Blank lines are skipped; line
numbers in messages are the editor's (1-based, counting the metadata lines). The rows are read by
numpy in one pass; only when that fails does a slow pass find the first bad cell to name it.
"""

from __future__ import annotations

import io
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
    text = _decode(path.read_bytes(), source)
    pre = _read_preamble(text, source)
    names = _header_names(pre, source)
    index = {name: j for j, name in enumerate(names)}

    def label(name: str) -> str:
        return f"column {index[name] + 1} ({name!r})"

    used = [name for name in names if name in KNOWN_COLUMNS]
    ignored = [name for name in names if name not in KNOWN_COLUMNS]
    notes = pre.notes
    if ignored:
        notes.append("ignored column(s) " + ", ".join(label(name) for name in ignored) + ": not in SPEC 2")
    body = _data_body(text[pre.body_start :], source, pre.header_line)
    first_data_line = pre.header_line + 1
    table = _load_table(body, names, used, first_data_line, source, pre.header_line)
    line_of = _line_locator(body, first_data_line)

    def where(k: int, name: str | None = None) -> tuple[str, int | None]:
        line = line_of(k)
        return (f"line {line}, {label(name)}" if name else f"line {line}"), line

    columns = {name: table[:, j] for j, name in enumerate(used)}
    metadata_where = {key: f"line {pre.meta_line[key]} (metadata {key!r})" for key in pre.metadata}
    return RawLog(source, columns, pre.metadata, metadata_where, notes, where)


def _decode(data: bytes, source: str) -> str:
    """UTF-8 text (a byte-order mark dropped) with every line ending made '\\n'."""
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise LogError(
            source, f"byte {err.start} is not UTF-8 text; is this a binary file (use .mat for MATLAB)?"
        ) from None
    if "\r" in text:
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    return text


def _read_preamble(text: str, source: str) -> _Preamble:
    """The ``# key: value`` lines up to the header line (the first non-blank, non-comment line)."""
    pre = _Preamble()
    pos = lineno = 0
    while pos < len(text):
        end = text.find("\n", pos)
        end = len(text) if end < 0 else end
        line, pos, lineno = text[pos:end], end + 1, lineno + 1
        stripped = line.strip()
        if not stripped:
            continue
        if not stripped.startswith("#"):
            pre.header, pre.header_line, pre.body_start = line, lineno, pos
            return pre
        body = stripped[1:].strip()
        key, sep, value = body.partition(":")
        key, value = key.strip(), value.strip()
        if not sep or not key:
            if "," in body and {"t", "x1"} <= {c.strip() for c in body.split(",")}:
                pre.commented_header = lineno
            pre.notes.append(f"line {lineno}: comment without 'key: value' ignored")
            continue
        if key in pre.metadata and pre.metadata[key] != value:
            raise LogError(
                source,
                f"metadata {key!r} is given twice with different values: {pre.metadata[key]!r} "
                f"(line {pre.meta_line[key]}) and {value!r}",
                where=f"line {lineno}",
                line=lineno,
            )
        pre.metadata[key], pre.meta_line[key] = value, lineno
    raise LogError(
        source,
        "empty file: no header line and no data (expected '# key: value' lines, a header such "
        "as 't,x1,x3,u1,u2', then numeric rows)",
    )


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


def _data_body(body: str, source: str, header_line: int) -> str:
    """The text after the header, lines of only spaces emptied; LogError if it holds no rows."""
    if "\n " in body or "\n\t" in body or body[:1] in (" ", "\t"):
        # lines holding only spaces would be rows to numpy; make them empty (line count unchanged)
        body = re.sub(r"(?m)^[ \t]+$", "", body)
    if not re.search(r"\S", body):
        raise LogError(
            source,
            "header only: no data rows after the header",
            where=f"line {header_line}",
            line=header_line,
        )
    return body


def _line_locator(body: str, first_data_line: int):
    """k -> the editor line of data row k (blank lines skipped)."""
    contiguous = not body.startswith("\n") and "\n\n" not in body.rstrip("\n")
    line_numbers: list[int] = []  # filled on first use when blank lines break "row k = line k"

    def line_of(k: int) -> int:
        if contiguous:
            return first_data_line + k
        if not line_numbers:
            line_numbers.extend(first_data_line + i for i, s in enumerate(body.split("\n")) if s.strip())
        return line_numbers[k]

    return line_of


def _load_table(
    body: str, names: list[str], used: list[str], first_data_line: int, source: str, header_line: int
) -> np.ndarray:
    """The used columns as an (n, len(used)) array; LogError at the first bad cell or row."""
    index = {name: j for j, name in enumerate(names)}
    usecols = [index[name] for name in used]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # an empty or odd file must not pass with a warning
            table = np.loadtxt(
                io.StringIO(body), delimiter=",", comments=None, usecols=usecols, ndmin=2, dtype=float
            )
    except (ValueError, UserWarning) as err:
        _locate_bad_cell(body, names, used, first_data_line, source, header_line)
        raise LogError(source, f"could not read the data rows: {err}", where=f"line {header_line}") from None
    n_rows = table.shape[0]
    if body.count(",") != n_rows * (len(names) - 1):
        _locate_bad_cell(body, names, used, first_data_line, source, header_line)
    return table


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
