"""Options of ``maglev_oc.data`` passed by name, each test failing when its option is ignored (the
default used instead) or inverted:

- ``check_excitation(position_resolution, current_resolution)``: a signal is flat exactly when its
  standard deviation is at most its own resolution, each resolution deciding its own signals;
- the CSV reader's ``text_lines(blank_spaces)``: lines of only spaces or tabs among the data are
  blank lines, and the log keeps every other row exactly.
"""

from __future__ import annotations

import numpy as np
import pytest

from maglev_oc.data.csv_reader import _Body
from maglev_oc.data.logs import Log, LogError, check_excitation, read_log
from tests._log_files import _signals

GAP = 0.020  # [m] a scheduled gap (8 mm + 24 x 0.5 mm)


N = 600


@pytest.mark.parametrize("name", ["x1", "x3", "u1", "u2"])
def test_each_resolution_option_decides_its_own_signals(name):
    """check_excitation: a signal is constant when its std is at most its resolution; the
    position resolution applies to x1 and x3, the current resolution to u1 and u2. Setting the
    one resolution just above the signal's std (and leaving the other at its default) must make
    exactly that signal flat."""
    cols = _signals()
    x = np.vstack([cols["x1"], np.full(N, np.nan), cols["x3"], np.full(N, np.nan)])
    log = Log(cols["t"], x, np.vstack([cols["u1"], cols["u2"]]))
    base = check_excitation(log)
    std = base.std[name]
    assert std == pytest.approx(float(np.std(cols[name])), rel=1e-12)
    sharing = ("x1", "x3") if name in ("x1", "x3") else ("u1", "u2")
    option = "position_resolution" if name in ("x1", "x3") else "current_resolution"
    below = 0.999 * min(base.std[other] for other in sharing)  # every signal still moves
    assert check_excitation(log, **{option: below}).resolution[name] == below
    with pytest.raises(LogError) as info:
        check_excitation(log, **{option: 1.001 * std})
    assert info.value.column in sharing
    assert f"{name} std" in str(info.value)
    for bad in (0.0, -1e-5, float("nan")):
        with pytest.raises(ValueError, match=option):
            check_excitation(log, **{option: bad})


# --- data: lines of only spaces ----------------------------------------------------------------
def test_lines_of_only_spaces_in_the_data_are_blank_lines(tmp_path):
    """A CSV whose data holds a line of spaces and a line of a tab is read as if those lines were
    empty: every other row, exactly (repr() round-trips a float), in order."""
    n = 300
    t = np.arange(n) * 1e-3
    x1 = GAP + 1e-4 * np.sin(2 * np.pi * 3 * t)
    x3 = 1e-3 * np.cos(2 * np.pi * 2 * t)
    u1 = 0.1 * np.sin(2 * np.pi * 5 * t)
    u2 = 1.5 + 0.05 * np.cos(2 * np.pi * 4 * t)
    rows = [",".join(repr(float(v)) for v in row) for row in zip(t, x1, x3, u1, u2, strict=True)]
    rows.insert(100, "    ")
    rows.insert(201, "\t ")
    path = tmp_path / "run.csv"
    path.write_text("# units: SI\nt,x1,x3,u1,u2\n" + "\n".join(rows) + "\n")
    log = read_log(path, min_samples=10, min_duration=0.1)
    assert log.n == n
    np.testing.assert_array_equal(log.t, t)
    np.testing.assert_array_equal(log.x[0], x1)
    np.testing.assert_array_equal(log.u[1], u2)


def test_text_lines_empties_lines_of_only_whitespace_when_asked(tmp_path):
    """``_Body.text_lines``: the lines as they are by default (a bad line's message quotes it),
    and with ``blank_spaces`` a line of only spaces or tabs becomes an empty line (numpy's
    loadtxt skips empty lines, not lines of spaces); lines with data are never changed."""
    path = tmp_path / "body.csv"
    lines = ["0.0,1.0\n", "   \n", "2.0,3.0\n", "\t \n", " 4.0,5.0\n"]
    path.write_text("".join(lines))
    body = _Body(path, 0, 1, str(path))
    assert list(body.text_lines()) == lines
    assert list(body.text_lines(blank_spaces=True)) == [lines[0], "\n", lines[2], "\n", lines[4]]
