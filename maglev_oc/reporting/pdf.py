"""Multi-page PDF reports written whole or not at all, without pyplot's global state.

Figures are plain ``matplotlib.figure.Figure`` objects (Agg-free, no window system needed).
:class:`PdfReport` also keeps a plain record of what it wrote (:class:`ReportContents`: the
headings, paragraphs, table rows as printed, figure titles and how much of each page is used),
so that tests can check what a report says, and that it reads well, without reading the PDF back.

A page is either a figure of its own (:meth:`PdfReport.add_figure`), flowing text
(:meth:`PdfReport.add_text`), a table (:meth:`PdfReport.add_table`), or a page of stacked blocks
(:meth:`PdfReport.add_page` with :class:`Text`, :class:`Table` and :class:`Plot`). Tables are laid
out with each column as wide as its longest line, measured with the renderer after drawing: a
clipped cell or content that runs off the page is an error (:class:`LayoutError`), not a page a
reader has to puzzle over.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import os
import textwrap
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

import matplotlib
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure
from matplotlib.table import Table as _MplTable

from maglev_oc.fileio import atomic_path
from maglev_oc.reporting.style import RC

__all__ = [
    "FIGURE_SIZE",
    "PAGE_SIZE",
    "FigureSection",
    "LayoutError",
    "PdfReport",
    "Plot",
    "ReportContents",
    "Section",
    "Table",
    "TableSection",
    "Text",
    "TextSection",
    "block_height",
    "caption",
    "check_tables",
    "grid",
    "new_figure",
    "page_room",
    "split_table",
]

PAGE_SIZE = (8.27, 11.69)  # A4 portrait [in]
FIGURE_SIZE = (8.27, 5.8)  # half page landscape-ish [in]
MIN_FILL = 0.5  # a page below this share used is near-empty (section openers excepted)


class LayoutError(ValueError):
    """A page that would print clipped or cut off."""


def new_figure(size: tuple[float, float] = FIGURE_SIZE) -> Figure:
    """A figure in the reports' style when made inside a :class:`PdfReport` block."""
    return Figure(figsize=size, layout="constrained")


# --- what a report wrote ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class TextSection:
    """Paragraphs under a heading, as handed to the report (before wrapping)."""

    heading: str
    paragraphs: tuple[str, ...]
    pages: int

    def text(self) -> str:
        return "\n".join((self.heading, *self.paragraphs))


@dataclass(frozen=True)
class TableSection:
    """A table as printed: every cell the string that appears on the page."""

    heading: str
    columns: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    notes: tuple[str, ...]
    pages: int

    def column(self, name: str) -> tuple[str, ...]:
        """The cells of the first column headed ``name``."""
        if name not in self.columns:
            raise KeyError(f"no column {name!r} in {self.heading!r}; columns: {self.columns}")
        k = self.columns.index(name)
        return tuple(row[k] for row in self.rows)

    def row(self, first_cell: str) -> tuple[str, ...]:
        """The only row whose first cell is ``first_cell``."""
        found = [row for row in self.rows if row and row[0] == first_cell]
        if len(found) != 1:
            raise KeyError(f"{len(found)} rows start with {first_cell!r} in {self.heading!r}")
        return found[0]

    def text(self) -> str:
        return "\n".join((self.heading, *self.columns, *(c for r in self.rows for c in r), *self.notes))


@dataclass(frozen=True)
class FigureSection:
    """A figure, known by its title: the suptitle, else the first axes' title, else the first text
    placed on the figure (for a :class:`Plot` block, what its ``draw`` returned)."""

    heading: str
    pages: int = 1

    def text(self) -> str:
        return self.heading


Section = TextSection | TableSection | FigureSection


@dataclass(frozen=True)
class Page:
    """One printed page: its heading, the share of its height used (0-1), and whether it opens a
    part of the report (an opener may be short)."""

    heading: str
    fill: float
    opener: bool = False


@dataclass(frozen=True)
class ReportContents:
    """What a :class:`PdfReport` wrote, section by section, in page order."""

    path: Path
    title: str
    sections: tuple[Section, ...]
    pages: tuple[Page, ...] = ()

    @property
    def n_pages(self) -> int:
        return sum(s.pages for s in self.sections)

    @property
    def headings(self) -> tuple[str, ...]:
        return tuple(s.heading for s in self.sections)

    def section(self, heading: str) -> Section:
        """The only section whose heading starts with ``heading``."""
        found = [s for s in self.sections if s.heading.startswith(heading)]
        if len(found) != 1:
            raise KeyError(f"{len(found)} sections start with {heading!r}; headings: {self.headings}")
        return found[0]

    def sparse_pages(self, minimum: float = MIN_FILL) -> list[tuple[int, Page]]:
        """(page number from 1, page) of every page less than ``minimum`` used, openers excepted."""
        return [(k, p) for k, p in enumerate(self.pages, 1) if p.fill < minimum and not p.opener]

    def text(self) -> str:
        """Every heading, paragraph, cell, note and figure title, one per line."""
        return "\n".join((self.title, *(s.text() for s in self.sections)))


# --- blocks of a page ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Text:
    """Paragraphs; a line starting with spaces or "•" keeps its indent when wrapped."""

    paragraphs: Sequence[str]
    font_size: float = 9.0
    width: int = 104  # characters per line


@dataclass(frozen=True)
class Table:
    """A table; ``heading`` may be empty (the page's heading names it)."""

    heading: str
    columns: Sequence[str]
    rows: Sequence[Sequence[object]]
    notes: Sequence[str] = ()
    font_size: float = 8.0


@dataclass(frozen=True)
class Plot:
    """A figure drawn into a band of the page: ``draw(fig, (left, bottom, width, height))`` in page
    fractions returns its title."""

    draw: Callable[[Figure, tuple[float, float, float, float]], str]
    height: float  # [page fraction]


_INCH = 1.0 / PAGE_SIZE[1]  # page-height fraction per inch
_EM = 0.6 / 72 / PAGE_SIZE[0]  # page-width fraction per character per point of font size (DejaVu Sans)
_TABLE_WIDTH = 0.9
_TOP, _BOTTOM = 0.955, 0.03
_LEFT = 0.06


def wrap_cells(rows: Sequence[Sequence[object]], widths: Sequence[int]) -> list[tuple[str, ...]]:
    """Each cell's text re-wrapped to its column's width in characters (for tables whose columns
    should stay narrow enough to print at a readable size)."""
    return [
        tuple(
            "\n".join(textwrap.wrap(" ".join(str(cell).split()), w))
            for cell, w in zip(row, widths, strict=True)
        )
        for row in rows
    ]


def grid(fig: Figure, rect, nrows: int, ncols: int, *, bottom: float = 0.05, top: float = 0.02, **kw):
    """A grid of axes inside ``rect`` (page fractions), ``bottom`` and ``top`` left free, room for
    the y labels on the left."""
    r_bottom, r_height = rect[1], rect[3]
    kw.setdefault("left", 0.11)
    kw.setdefault("right", 0.97)
    return fig.add_gridspec(nrows, ncols, bottom=r_bottom + bottom, top=r_bottom + r_height - top, **kw)


def caption(fig: Figure, rect, title: str, text: str = "") -> str:
    """A bold title (and a grey caption under it) at the top of ``rect``; returns the title."""
    top = rect[1] + rect[3]
    fig.text(_LEFT, top, title, fontsize=10.5, weight="bold", va="top")
    if text:
        fig.text(_LEFT, top - 0.019, textwrap.fill(text, 125), fontsize=8, va="top", color="0.25")
    return title


# --- the report ------------------------------------------------------------------------------------------
class PdfReport:
    """Collect pages; the file appears at ``path`` only when the ``with`` block succeeds."""

    def __init__(self, path: str | os.PathLike, title: str, subtitle: str = "") -> None:
        self.path = Path(path)
        self.title = title
        self.subtitle = subtitle
        self._atomic = atomic_path(self.path)
        self._pdf: PdfPages | None = None
        self._style = matplotlib.rc_context(RC)
        self.n_pages = 0
        self._sections: list[Section] = []
        self._pages: list[Page] = []

    def __enter__(self) -> PdfReport:
        self._style.__enter__()
        tmp = self._atomic.__enter__()
        self._pdf = PdfPages(tmp, metadata={"Title": self.title, "Creator": "maglev_oc"})
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool:
        assert self._pdf is not None
        try:
            self._pdf.close()
            return bool(self._atomic.__exit__(exc_type, exc, tb))
        finally:
            self._style.__exit__(exc_type, exc, tb)

    @property
    def contents(self) -> ReportContents:
        """What has been written so far (all of it once the ``with`` block has ended)."""
        return ReportContents(self.path, self.title, tuple(self._sections), tuple(self._pages))

    # --------------------------------------------------------------------------------------
    def add_figure(self, fig: Figure) -> None:
        """A figure as a page of its own (its own size; a figure fills its page)."""
        title = _figure_title(fig)
        self._save(fig, title, 1.0)
        self._sections.append(FigureSection(title))

    def add_text(
        self, heading: str, paragraphs: Sequence[str], *, first_page: bool = False, opener: bool = False
    ) -> None:
        """Pages of wrapped text (as many as it takes); ``first_page`` adds the report title and
        date above the first; ``opener`` marks the first page as opening a part (it may be short)."""
        line_height, gap = 0.0165, 0.014
        first = self.n_pages
        fig = Figure(figsize=PAGE_SIZE)
        y = self._heading(fig, heading, first_page)
        for para in paragraphs:
            lines = []
            for raw in para.split("\n"):
                lines.extend(textwrap.wrap(raw, 95) or [""])
            while lines:
                fit = int((y - _BOTTOM) / line_height)
                chunk, lines = lines[:fit], lines[fit:]
                if chunk:
                    fig.text(0.08, y, "\n".join(chunk), fontsize=9.5, va="top")
                    y -= line_height * len(chunk) + gap
                if lines:  # continue on a new page
                    self._save(fig, heading, _TOP - y, opener=opener and self.n_pages == first)
                    fig = Figure(figsize=PAGE_SIZE)
                    y = self._heading(fig, f"{heading} (continued)", False)
        self._save(fig, heading, _TOP - y, opener=opener and self.n_pages == first)
        self._sections.append(TextSection(heading, tuple(paragraphs), self.n_pages - first))

    def add_table(
        self,
        heading: str,
        columns: Sequence[str],
        rows: Sequence[Sequence[object]],
        *,
        notes: Sequence[str] = (),
        font_size: float = 8.5,
    ) -> None:
        """A table on pages of its own; long tables continue on further pages (the header
        repeated, the notes under the last part)."""
        cells = [[_fmt(v) for v in r] for r in rows]
        first = self.n_pages
        chunks = _paginate(cells, columns, font_size, bool(notes))
        for k, chunk in enumerate(chunks):
            title = heading if k == 0 else f"{heading} (continued)"
            last = k == len(chunks) - 1
            block = Table("", columns, chunk, notes if last else (), font_size)
            fig = Figure(figsize=PAGE_SIZE)
            y = self._heading(fig, title, False)
            y, _ = _draw_table(fig, y, block)
            self._check_bottom(y, title)
            self._save(fig, title, _TOP - y)
        printed = tuple(tuple(r) for r in cells)
        self._sections.append(
            TableSection(heading, tuple(columns), printed, tuple(notes), self.n_pages - first)
        )

    def add_page(
        self, heading: str, blocks: Sequence[Text | Table | Plot], *, first_page: bool = False
    ) -> None:
        """One page of stacked blocks, recorded as :meth:`add_text`, :meth:`add_table` and
        :meth:`add_figure` record theirs (the page counted once, on its first section). Content
        that would run off the page is a :class:`LayoutError`."""
        fig = Figure(figsize=PAGE_SIZE)
        y = self._heading(fig, heading, first_page)
        sections: list[Section] = []
        for block in blocks:
            if isinstance(block, Text):
                y = _draw_text(fig, y, block)
                sections.append(TextSection(heading, tuple(block.paragraphs), 0))
            elif isinstance(block, Table):
                y, printed = _draw_table(fig, y, block)
                sections.append(printed if printed.heading else dataclasses.replace(printed, heading=heading))
            else:
                title = block.draw(fig, (0.0, y - block.height, 1.0, block.height))
                sections.append(FigureSection(title, 0))
                y -= block.height + 0.01
            self._check_bottom(y, heading)
        self._save(fig, heading, _TOP - y)
        sections[0] = dataclasses.replace(sections[0], pages=1)
        self._sections.extend(sections)

    # --------------------------------------------------------------------------------------
    def _heading(self, fig: Figure, heading: str, first_page: bool) -> float:
        y = _TOP
        if first_page:
            fig.text(_LEFT, y, self.title, fontsize=17, weight="bold", va="top")
            stamp = _dt.date.today().isoformat()
            sub = f"{self.subtitle} — {stamp}" if self.subtitle else stamp
            fig.text(_LEFT, y - 0.035, sub, fontsize=9.5, color="0.35", va="top")
            y -= 0.065
        fig.text(_LEFT, y, heading, fontsize=13, weight="bold", va="top")
        return y - 0.032

    def _check_bottom(self, y: float, heading: str) -> None:
        if y < _BOTTOM - 0.015:
            raise LayoutError(
                f"{self.path.name}: page {heading!r} runs {(_BOTTOM - y) * 100:.1f} % of a page too long"
            )

    def _save(self, fig: Figure, heading: str, fill: float, *, opener: bool = False) -> None:
        assert self._pdf is not None, "use PdfReport inside a with block"
        check_tables(fig, f"{self.path.name}: page {self.n_pages + 1} ({heading!r})")
        self._pdf.savefig(fig)
        self.n_pages += 1
        self._pages.append(Page(heading, min(1.0, max(0.0, fill)), opener))


# --- layout ----------------------------------------------------------------------------------------------
def page_room(first_page: bool = False) -> float:
    """The page fraction :meth:`PdfReport.add_page` has for blocks under its heading."""
    return _TOP - 0.032 - (0.065 if first_page else 0.0) - (_BOTTOM - 0.015)


def split_table(table: Table) -> list[Table]:
    """``table`` as consecutive tables that each fit a page under its heading (the header repeated,
    the heading on the first, the notes under the last), for blocks of :meth:`PdfReport.add_page`:
    a table taller than a page cannot be placed whole. One table when it fits."""
    cells = [[_fmt(v) for v in r] for r in table.rows]
    chunks = _paginate(cells, table.columns, table.font_size, bool(table.notes))
    last = len(chunks) - 1
    return [
        Table(
            table.heading if k == 0 else "",
            table.columns,
            chunk,
            table.notes if k == last else (),
            table.font_size,
        )
        for k, chunk in enumerate(chunks)
    ]


def block_height(block: Text | Table | Plot) -> float:
    """The page fraction ``block`` takes in :meth:`PdfReport.add_page`, measured on a scratch figure
    (to share blocks out over pages before drawing them)."""
    if isinstance(block, Plot):
        return block.height + 0.01
    fig = Figure(figsize=PAGE_SIZE)
    y = _draw_text(fig, _TOP, block) if isinstance(block, Text) else _draw_table(fig, _TOP, block)[0]
    return _TOP - y


def _draw_text(fig: Figure, top: float, t: Text) -> float:
    line = t.font_size * 1.25 / 72 * _INCH
    y = top
    for para in t.paragraphs:
        lines = []
        for raw in para.split("\n"):
            indent = " " * (len(raw) - len(raw.lstrip(" •")))
            lines += textwrap.wrap(raw, t.width, subsequent_indent=indent) or [""]
        fig.text(_LEFT, y, "\n".join(lines), fontsize=t.font_size, va="top", linespacing=1.25)
        y -= len(lines) * line + 0.008
    return y - 0.005


def _lines(text: object) -> list[str]:
    return str(text).split("\n")


def _table_size(columns: Sequence[str], rows: Sequence[Sequence[str]], font_size: float):
    """(font size, column widths, row heights) in page fractions: each column as wide as its
    longest line (bold headers count wider), the font shrunk where the table would not fit."""

    def longest(j: int) -> float:
        header = max(len(x) * 1.1 for x in _lines(columns[j]))
        return max(header, *(len(x) for r in rows for x in _lines(r[j])))

    chars = [longest(j) + 2.5 for j in range(len(columns))]
    size = min(font_size, _TABLE_WIDTH / (sum(chars) * _EM))
    widths = [c * size * _EM for c in chars]
    line = size * 1.3 / 72 * _INCH
    heights = [max(len(_lines(c)) for c in row) * line + 0.007 for row in [list(columns), *rows]]
    return size, widths, heights


def _paginate(rows: list[list[str]], columns: Sequence[str], font_size: float, notes: bool):
    """Rows split so that each part fits a page under its heading (room for notes on the last)."""
    _, _, heights = _table_size(columns, rows or [[""] * len(columns)], font_size)
    room = _TOP - 0.032 - _BOTTOM - 0.03 - heights[0] - (0.08 if notes else 0.0)
    chunks, chunk, used = [], [], 0.0
    for row, h in zip(rows, heights[1:], strict=True):
        if chunk and used + h > room:
            chunks.append(chunk)
            chunk, used = [], 0.0
        chunk.append(row)
        used += h
    chunks.append(chunk)
    return chunks


def _draw_table(fig: Figure, top: float, t: Table) -> tuple[float, TableSection]:
    """Draw ``t`` from ``top`` down; returns the y below it and what it printed."""
    rows = [[_fmt(c) for c in r] for r in t.rows]
    if any(len(r) != len(t.columns) for r in rows):
        raise LayoutError(f"table {t.heading!r}: a row's length differs from its {len(t.columns)} columns")
    shown = rows or [["—"] * len(t.columns)]
    size, widths, heights = _table_size(t.columns, shown, t.font_size)
    width, height = sum(widths), sum(heights)
    y = top
    if t.heading:
        fig.text(_LEFT, y, t.heading, fontsize=10.5, weight="bold", va="top")
        y -= 0.024
    ax = fig.add_axes((0.5 - width / 2, y - height, width, height))
    ax.axis("off")
    table = _MplTable(ax, bbox=(0, 0, 1, 1))
    for r, row in enumerate([list(t.columns), *shown]):
        for j, text in enumerate(row):
            cell = table.add_cell(
                r,
                j,
                widths[j] / width,
                heights[r] / height,
                text=text,
                loc="left" if (j == 0 and r > 0) else "center",
                facecolor="0.9" if r == 0 else "white",
                edgecolor="0.6",
            )
            cell.set_text_props(fontsize=size, weight="bold" if r == 0 else "normal")
            cell.set_linewidth(0.5)
            if j == 0 and r > 0:  # left-aligned: a one-character margin, not a tenth of a wide column
                cell.PAD = min(cell.PAD, size * _EM / widths[j])
    table.auto_set_font_size(False)
    ax.add_table(table)
    y -= height + 0.01
    if t.notes:
        text = "\n".join(line for n in t.notes for line in (textwrap.wrap(n, 122) or [""]))
        fig.text(_LEFT, y, text, fontsize=8, va="top", linespacing=1.3)
        y -= (text.count("\n") + 1) * 8 * 1.3 / 72 * _INCH + 0.006
    printed = TableSection(t.heading, tuple(t.columns), tuple(tuple(r) for r in rows), tuple(t.notes), 0)
    return y - 0.012, printed


def check_tables(fig: Figure, where: str = "figure") -> None:
    """Every table cell's text inside its cell, measured by the renderer (a clipped header or value
    is a :class:`LayoutError`)."""
    tables = [t for ax in fig.axes for t in ax.tables]
    if not tables:
        return
    canvas = FigureCanvasAgg(fig)
    renderer = canvas.get_renderer()
    if fig.get_layout_engine() is None:
        # the cells and their text placed as Table.draw and Cell.draw place them, without painting
        # them: the same boxes to the bit as after drawing the tables' axes (checked on every page
        # of the controllers, model and microstepper reports), a third of the report's time less
        for table in tables:
            table._update_positions(renderer)
            for cell in table.get_celld().values():
                cell._set_text_position(renderer)
    else:  # a layout engine places every axes at draw time
        fig.draw(renderer)
    for table in tables:
        for (r, c), cell in table.get_celld().items():
            text = cell.get_text()
            if not text.get_text():
                continue
            box, ink = cell.get_window_extent(renderer), text.get_window_extent(renderer)
            if ink.x0 < box.x0 - 0.5 or ink.x1 > box.x1 + 0.5 or ink.height > box.height + 0.5:
                kind = "header" if r == 0 else "cell"
                raise LayoutError(
                    f"{where}: {kind} {text.get_text()!r} (row {r}, column {c}) is clipped: "
                    f"{ink.width:.0f} x {ink.height:.0f} px of text in a "
                    f"{box.width:.0f} x {box.height:.0f} px cell"
                )


def _figure_title(fig: Figure) -> str:
    if fig.get_suptitle():
        return fig.get_suptitle()
    titles = [ax.get_title() for ax in fig.axes if ax.get_title()]
    if titles:
        return titles[0]
    return fig.texts[0].get_text() if fig.texts else ""


def _fmt(value: object) -> str:
    if isinstance(value, float):
        if value != value:  # NaN
            return "—"
        if value == 0 or 1e-3 <= abs(value) < 1e5:
            return f"{value:.4g}"
        return f"{value:.3e}"
    return str(value)
