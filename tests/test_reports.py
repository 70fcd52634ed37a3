"""What the reports say, read from PdfReport's record of what it printed (not only that a PDF
appeared): the numbers on the page are the ones the computation produced."""

from __future__ import annotations

import pytest

from maglev_oc.control.gains import PAPER_GAINS


@pytest.fixture(scope="module")
def model_report(shared_model_report):
    """The model report's contents, written once per session (tests/report_support.py)."""
    return shared_model_report[1]


def test_model_report_is_whole_and_in_order(model_report):
    c = model_report
    assert c.path.read_bytes()[:5] == b"%PDF-"
    assert not [p for p in c.path.parent.iterdir() if p.name.startswith(".")]  # no temp file left
    assert c.headings[0].startswith("Scorecard")
    assert c.n_pages == len(c.pages) >= 5  # every page recorded (a page holds several sections)
    assert all(h for h in c.headings)  # every figure is titled


def test_model_report_prints_the_spec_equilibrium_currents(model_report):
    # SPEC 1: about +5.3 A at 10 mm, +3.3 at 15, +1.5 at 20 and -0.2 at 25 mm; 0.05 A as the
    # model tests hold them (the printed value is rounded to 3-4 digits, well inside that).
    table = model_report.section("Equilibrium currents")
    current = dict(zip(table.column("gap [mm]"), table.column("i_d [A]"), strict=True))
    for gap, expected in (("10", 5.3), ("15", 3.3), ("20", 1.5), ("25", -0.2)):
        assert float(current[gap]) == pytest.approx(expected, abs=0.05), gap
    # the amplifier column follows the LCAM limits (7 A continuous, 9 A peak; 002 Sec. 4)
    for i_d, status in zip(table.column("i_d [A]"), table.column("amplifier"), strict=True):
        if status != "no equilibrium":
            limit = {"ok": (0.0, 7.0), "> 7 A continuous": (7.0, 9.0), "> 9 A peak": (9.0, 1e9)}
            low, high = limit[status]
            assert low <= abs(float(i_d)) <= high, (i_d, status)


def test_model_report_prints_the_papers_gains_beside_the_computed_ones(model_report):
    table = model_report.section("Printed and computed gains")
    names = [n for n in table.column("gains") if n]
    assert names == [n.replace("_retuned", " retuned") for n in PAPER_GAINS]  # plain words, not identifiers
    printed = [float(x) for x in table.column("printed")]
    computed = [float(x) for x in table.column("ours")]
    expected = [v for g in PAPER_GAINS.values() for v in g.printed]
    assert printed == pytest.approx(expected, abs=0.5)  # printed to integers
    # the papers' printed integers are the pole-placement gains truncated or rounded (within 1 or
    # 0.1 %); K_v_retuned's poles are printed only to 0.1 in 002, and a 0.05 shift of five poles
    # near -10 moves the gains by several per cent (measured 5.6 %, in k4; bound 7 %)
    rows = iter(zip(printed, computed, strict=True))
    for name in PAPER_GAINS:
        rel = 0.07 if name == "K_v_retuned" else 1e-3
        for _ in range(5):
            p, c = next(rows)
            assert p == pytest.approx(c, rel=rel, abs=1.0), name
