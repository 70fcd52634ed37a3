"""Multi-page PDF reports written whole or not at all, without pyplot's global state.

Figures are plain ``matplotlib.figure.Figure`` objects (Agg-free, no window system needed).
"""

from __future__ import annotations

import datetime as _dt
import os
import textwrap
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType

from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure

from maglev_oc.fileio import atomic_path

__all__ = ["FIGURE_SIZE", "PAGE_SIZE", "PdfReport", "new_figure"]

PAGE_SIZE = (8.27, 11.69)  # A4 portrait [in]
FIGURE_SIZE = (8.27, 5.8)  # half page landscape-ish [in]


def new_figure(size: tuple[float, float] = FIGURE_SIZE) -> Figure:
    return Figure(figsize=size, layout="constrained")


class PdfReport:
    """Collect pages; the file appears at ``path`` only when the ``with`` block succeeds."""

    def __init__(self, path: str | os.PathLike, title: str, subtitle: str = "") -> None:
        self.path = Path(path)
        self.title = title
        self.subtitle = subtitle
        self._atomic = atomic_path(self.path)
        self._pdf: PdfPages | None = None
        self.n_pages = 0

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

    # --------------------------------------------------------------------------------------
    def add_figure(self, fig: Figure) -> None:
        assert self._pdf is not None, "use PdfReport inside a with block"
        self._pdf.savefig(fig)
        self.n_pages += 1

    def add_text(self, heading: str, paragraphs: Sequence[str], *, first_page: bool = False) -> None:
        """Pages of wrapped text (as many as it takes); ``first_page`` adds the report title and
        date above the first."""
        line_height, gap, bottom = 0.0165, 0.014, 0.04
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
                    self.add_figure(fig)
                    fig = Figure(figsize=PAGE_SIZE)
                    fig.text(0.08, 0.95, f"{heading} (continued)", fontsize=13, weight="bold", va="top")
                    y = 0.95 - 0.035
        self.add_figure(fig)

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
            self.add_figure(fig)


def _fmt(value: object) -> str:
    if isinstance(value, float):
        if value != value:  # NaN
            return "—"
        if value == 0 or 1e-3 <= abs(value) < 1e5:
            return f"{value:.4g}"
        return f"{value:.3e}"
    return str(value)
