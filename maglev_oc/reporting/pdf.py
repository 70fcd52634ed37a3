"""Multi-page PDF reports written whole or not at all, without pyplot's global state.

Figures are plain ``matplotlib.figure.Figure`` objects (Agg-free, no window system needed).
:class:`PdfReport` also keeps a plain record of what it wrote (:class:`ReportContents`: the
headings, paragraphs, table rows as printed and figure titles), so that tests can check what a
report says without reading the PDF back.
"""

from __future__ import annotations

import datetime as _dt
import os
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure

from maglev_oc.fileio import atomic_path

__all__ = [
    "FIGURE_SIZE",
    "PAGE_SIZE",
    "FigureSection",
    "PdfReport",
    "ReportContents",
    "Section",
    "TableSection",
    "TextSection",
    "new_figure",
]

PAGE_SIZE = (8.27, 11.69)  # A4 portrait [in]
FIGURE_SIZE = (8.27, 5.8)  # half page landscape-ish [in]


def new_figure(size: tuple[float, float] = FIGURE_SIZE) -> Figure:
    return Figure(figsize=size, layout="constrained")


@dataclass(frozen=True)
class TextSection:
    """Paragraphs under a heading, as handed to :meth:`PdfReport.add_text` (before wrapping)."""

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
    """A figure page, known by its title: the suptitle, else the first axes' title, else the
    first text placed on the figure."""

    heading: str
    pages: int = 1

    def text(self) -> str:
        return self.heading


Section = TextSection | TableSection | FigureSection


@dataclass(frozen=True)
class ReportContents:
    """What a :class:`PdfReport` wrote, section by section, in page order."""

    path: Path
    title: str
    sections: tuple[Section, ...]

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

    def text(self) -> str:
        """Every heading, paragraph, cell, note and figure title, one per line."""
        return "\n".join((self.title, *(s.text() for s in self.sections)))


class PdfReport:
    """Collect pages; the file appears at ``path`` only when the ``with`` block succeeds."""

    def __init__(self, path: str | os.PathLike, title: str, subtitle: str = "") -> None:
        self.path = Path(path)
        self.title = title
        self.subtitle = subtitle
        self._atomic = atomic_path(self.path)
        self._pdf: PdfPages | None = None
        self.n_pages = 0
        self._sections: list[Section] = []

    def __enter__(self) -> PdfReport:
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
        self._pdf.close()
        return bool(self._atomic.__exit__(exc_type, exc, tb))

    @property
    def contents(self) -> ReportContents:
        """What has been written so far (all of it once the ``with`` block has ended)."""
        return ReportContents(self.path, self.title, tuple(self._sections))

    # --------------------------------------------------------------------------------------
    def add_figure(self, fig: Figure) -> None:
        self._save(fig)
        self._sections.append(FigureSection(_figure_title(fig)))

    def _save(self, fig: Figure) -> None:
        assert self._pdf is not None, "use PdfReport inside a with block"
        self._pdf.savefig(fig)
        self.n_pages += 1

    def add_text(self, heading: str, paragraphs: Sequence[str], *, first_page: bool = False) -> None:
        """Pages of wrapped text (as many as it takes); ``first_page`` adds the report title and
        date above the first."""
        line_height, gap, bottom = 0.0165, 0.014, 0.04
        first = self.n_pages
        fig = Figure(figsize=PAGE_SIZE)
        y = 0.95
        if first_page:
            fig.text(0.08, y, self.title, fontsize=17, weight="bold", va="top")
            y -= 0.035
            stamp = _dt.date.today().isoformat()
            sub = f"{self.subtitle} — {stamp}" if self.subtitle else stamp
            fig.text(0.08, y, sub, fontsize=9.5, color="0.35", va="top")
            y -= 0.04
        fig.text(0.08, y, heading, fontsize=13, weight="bold", va="top")
        y -= 0.035
        for para in paragraphs:
            lines = []
            for raw in para.split("\n"):
                lines.extend(textwrap.wrap(raw, 95) or [""])
            while lines:
                fit = int((y - bottom) / line_height)
                chunk, lines = lines[:fit], lines[fit:]
                if chunk:
                    fig.text(0.08, y, "\n".join(chunk), fontsize=9.5, va="top", family="DejaVu Sans")
                    y -= line_height * len(chunk) + gap
                if lines:  # continue on a new page
                    self._save(fig)
                    fig = Figure(figsize=PAGE_SIZE)
                    fig.text(0.08, 0.95, f"{heading} (continued)", fontsize=13, weight="bold", va="top")
                    y = 0.95 - 0.035
        self._save(fig)
        self._sections.append(TextSection(heading, tuple(paragraphs), self.n_pages - first))

    def add_table(
        self,
        heading: str,
        columns: Sequence[str],
        rows: Sequence[Sequence[object]],
        *,
        notes: Sequence[str] = (),
        col_widths: Sequence[float] | None = None,
        font_size: float = 8.5,
    ) -> None:
        """A page with a table; long tables continue on further pages."""
        per_page = 38  # lines of text per page
        rows = [[_fmt(v) for v in r] for r in rows]
        heights = [max(str(v).count("\n") + 1 for v in r) if r else 1 for r in rows]
        chunks, chunk, used = [], [], 0
        for r, h in zip(rows, heights, strict=True):
            if chunk and used + h > per_page:
                chunks.append(chunk)
                chunk, used = [], 0
            chunk.append(r)
            used += h
        chunks.append(chunk)
        for k, chunk in enumerate(chunks):
            fig = Figure(figsize=PAGE_SIZE)
            title = heading if k == 0 else f"{heading} (continued)"
            fig.text(0.06, 0.95, title, fontsize=13, weight="bold", va="top")
            lines = [max(str(v).count("\n") + 1 for v in r) for r in chunk]
            height = min(0.022 * (sum(lines) + 1), 0.82)
            ax = fig.add_axes((0.04, 0.92 - height, 0.92, height))
            ax.axis("off")
            cells = chunk or [["—"] * len(columns)]
            table = ax.table(
                cellText=cells,
                colLabels=list(columns),
                loc="upper center",
                cellLoc="center",
                colWidths=col_widths,
            )
            table.auto_set_font_size(False)
            table.set_fontsize(font_size)
            table.scale(1.0, 1.25)
            header_lines = max(str(c).count("\n") + 1 for c in columns)
            for (r, _), cell in table.get_celld().items():
                if r == 0:
                    cell.set_text_props(weight="bold")
                    cell.set_facecolor("0.9")
                    cell.set_height(cell.get_height() * header_lines)
                elif r - 1 < len(lines) and lines[r - 1] > 1:
                    cell.set_height(cell.get_height() * lines[r - 1])
            if k == len(chunks) - 1 and notes:
                text = "\n".join(line for n in notes for line in (textwrap.wrap(n, 100) or [""]))
                fig.text(0.06, 0.88 - height, text, fontsize=8.5, va="top")
            self._save(fig)
        printed = tuple(tuple(r) for r in rows)
        self._sections.append(TableSection(heading, tuple(columns), printed, tuple(notes), len(chunks)))


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
