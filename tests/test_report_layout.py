"""The page layout every report uses: a clipped table cell or content that runs off the page is an
error, and how much of each page is used is recorded, so that a near-empty page is found."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.figure import Figure

from maglev_oc.reporting.pdf import (
    PAGE_SIZE,
    LayoutError,
    PdfReport,
    Plot,
    Table,
    Text,
    block_height,
    check_tables,
    page_room,
    split_table,
)
from maglev_oc.reporting.style import CONTROLLER_COLOURS, controller_colour, thin


def _table_figure(widths):
    fig = Figure(figsize=PAGE_SIZE)
    ax = fig.add_axes((0.1, 0.5, 0.8, 0.1))
    ax.axis("off")
    table = ax.table(cellText=[["1.0", "2.0"]], colLabels=["settling 0.1 mm [s]", "b"], colWidths=widths)
    table.auto_set_font_size(False)
    table.set_fontsize(8.5)
    return fig


def test_a_clipped_header_is_found_by_measuring_it():
    # the fixed column widths the reports used to pass: 8 % of the page for a 19-character header
    with pytest.raises(LayoutError, match=r"header 'settling 0.1 mm \[s\]'.*clipped"):
        check_tables(_table_figure([0.08, 0.5]))
    check_tables(_table_figure([0.5, 0.5]))  # wide enough: no error


def test_tables_are_sized_to_their_text(tmp_path):
    long = "a column header that is long [unit]"
    with PdfReport(tmp_path / "r.pdf", "t") as pdf:
        pdf.add_table(
            "t", [long, "b", "c\nsecond line"], [[f"{k * 1.2345:.4f}", "x" * 30, k] for k in range(5)]
        )
        pdf.add_page("p", [Table("", ["h"] * 12, [["123456.789"] * 12])])  # shrinks the font to fit
    assert (tmp_path / "r.pdf").read_bytes()[:5] == b"%PDF-"
    assert pdf.contents.section("t").rows[1] == ("1.2345", "x" * 30, "1")


def test_a_long_table_continues_on_further_pages_with_its_notes_last(tmp_path):
    with PdfReport(tmp_path / "r.pdf", "t") as pdf:
        pdf.add_table("long", ["k", "value"], [[k, k * 2.0] for k in range(150)], notes=["the note"])
    c = pdf.contents
    assert c.section("long").pages == len(c.pages) >= 3
    assert [p.heading for p in c.pages[1:]] == ["long (continued)"] * (len(c.pages) - 1)
    assert len(c.section("long").rows) == 150


def test_a_table_too_tall_for_a_page_is_split_into_tables_that_each_fit_one(tmp_path):
    # a diagnosis report's verdict table (one row per candidate, reasons wrapped over lines) ran
    # 6.6 % of a page too long and the report failed: split, each part fits a page under its
    # heading with the header repeated, the rows in order, the heading on the first, the notes on
    # the last; a table that fits stays one
    rows = [[f"candidate {k}", "not significant", "reason\nwrapped\nover lines"] for k in range(60)]
    table = Table("verdicts", ("candidate", "verdict", "reason"), rows, notes=["the note"], font_size=7.5)
    assert block_height(table) > page_room()  # whole, it cannot be placed
    parts = split_table(table)
    assert len(parts) >= 2
    assert all(block_height(t) <= page_room() for t in parts)
    assert [r for t in parts for r in t.rows] == rows
    assert [t.heading for t in parts] == ["verdicts"] + [""] * (len(parts) - 1)
    assert [tuple(t.notes) for t in parts] == [()] * (len(parts) - 1) + [("the note",)]
    with PdfReport(tmp_path / "r.pdf", "t") as pdf:
        for k, t in enumerate(parts):
            pdf.add_page("verdicts" + (" (continued)" if k else ""), [t])
    assert len(pdf.contents.pages) == len(parts)
    short = Table("short", ("a", "b"), [["1", "2"]])
    assert split_table(short) == [short]


def test_content_that_runs_off_the_page_is_refused_and_nothing_is_written(tmp_path):
    out = tmp_path / "r.pdf"
    with pytest.raises(LayoutError, match=r"runs .* too long"), PdfReport(out, "t") as pdf:
        pdf.add_page("too much", [Text(["a line"] * 10), Plot(lambda fig, rect: "p", 0.9)])
    assert not out.exists() and not list(tmp_path.iterdir())


def test_page_fill_finds_near_empty_pages_except_openers(tmp_path):
    def plot(fig, rect):
        ax = fig.add_axes((0.1, rect[1] + 0.05, 0.8, rect[3] - 0.1))
        ax.plot([0, 1], [0, 1])
        return "a plot"

    with PdfReport(tmp_path / "r.pdf", "t") as pdf:
        pdf.add_text("short", ["one line"])  # near-empty
        pdf.add_text("opener", ["one line"], opener=True)  # short, but opens a part
        pdf.add_page("full", [Text(["text"]), Plot(plot, 0.8)])
        pdf.add_text("long", ["a sentence of words " * 40] * 6)  # a page and a bit
    c = pdf.contents
    fills = [round(p.fill, 2) for p in c.pages]
    assert len(c.pages) == c.n_pages == 5
    assert fills[0] < 0.1 and fills[2] > 0.85 and fills[3] > 0.85, fills
    sparse = [(k, p.heading) for k, p in c.sparse_pages()]
    assert (1, "short") in sparse and all(h != "opener" for _, h in sparse)
    assert [h for _, h in sparse if h.startswith("long")] == (["long"] if fills[4] < 0.5 else [])


def test_every_controller_has_one_colour_and_variants_keep_it():
    assert len(set(CONTROLLER_COLOURS.values())) == len(CONTROLLER_COLOURS)
    assert controller_colour("FL regulator, retuned K_v") == CONTROLLER_COLOURS["FL regulator"]
    assert controller_colour("linear regulator (no feedforward)") != CONTROLLER_COLOURS["linear regulator"]
    assert controller_colour("something else") not in CONTROLLER_COLOURS.values()


def test_thinning_keeps_every_peak():
    t = np.linspace(0, 1, 100_001)
    y = np.sin(40 * t) + (t == t[77_777]) * 5.0
    tt, yy = thin(t, y)
    assert tt.size <= 2.1 * 3000 and yy.max() == y.max() and yy.min() == y.min()
    assert tt[-1] == t[-1] and y[-1] in yy[-2:]  # the end of the trace is kept


def test_each_twin_is_stated_once_with_its_true_constants():
    from maglev_oc.identification.experiments import TWIN_TRUTH
    from maglev_oc.model.parameters import PAPER_CONSTANTS
    from maglev_oc.reporting.twins import TWINS, twin_sentence, twin_table
    from maglev_oc.sim.comparison import RIG_CONSTANTS

    # the sentences state the constants the studies actually simulate (4 significant digits)
    assert f"{PAPER_CONSTANTS[RIG_CONSTANTS].C1:.4g}" in twin_sentence("rig twin")
    assert "Table III at eps = 0.001" in twin_sentence("rig twin")
    assert f"{TWIN_TRUTH.C4:.3g}" in twin_sentence("identification twin")
    assert "cogging" not in twin_sentence("identification twin")  # encoders and amplifiers only
    assert "none" in twin_sentence("ideal twin")
    rows = twin_table().rows
    assert [r[0] for r in rows] == list(TWINS) and all("_" not in r[2] for r in rows)  # plain words
