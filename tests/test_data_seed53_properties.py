"""What the log layer tells a user about a bad file, and how it writes one (issue 21; survivors of the
mutation run of seed 53 on data/): every refusal is a LogError naming the file, with the line a
CSV error is on as an attribute as well as in the words; a metadata value outside its choices is
refused, not a crash; a millimetre column names the quantity; a MATLAB variable that is not
numeric names its type; .mat logs are written compressed."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from maglev_oc.data.logs import read_log, write_log
from maglev_oc.errors import LogError

N = 600
DT = 1e-3


def _rows(n: int = N) -> list[list[str]]:
    t = np.arange(n) * DT
    x1 = 0.02 + 1e-3 * np.sin(2 * np.pi * t)
    x3 = 0.01 * np.sin(2 * np.pi * 0.5 * t)
    u1 = 0.5 * np.cos(2 * np.pi * t)
    u2 = 1.5 + 0.1 * np.sin(2 * np.pi * t)
    return [[repr(float(v)) for v in row] for row in zip(t, x1, x3, u1, u2, strict=True)]


def _write(tmp_path: Path, rows, meta=("# sample_rate_hz: 1000",), name="run.csv") -> Path:
    path = tmp_path / name
    path.write_text("\n".join([*meta, "t,x1,x3,u1,u2", *(",".join(r) for r in rows)]) + "\n")
    return path


def _refused(path: Path) -> LogError:
    with pytest.raises(LogError) as info:
        read_log(path)
    assert str(info.value).startswith(str(path)), str(info.value)  # every message names the file
    return info.value


def test_a_bad_cell_and_a_short_row_carry_their_line(tmp_path):
    """The error's ``line`` is the file's line (metadata and header counted), for a cell that is not
    a number and for a row with too few cells alike: what an editor or a script jumps to."""
    rows = _rows()
    rows[10][2] = "1.0.0"
    err = _refused(_write(tmp_path, rows))
    assert err.line == 13 and "line 13" in str(err)  # 1 metadata line + header + 11th row
    rows = _rows()
    rows[20] = rows[20][:3]
    err = _refused(_write(tmp_path, rows, name="short.csv"))
    assert err.line == 23 and "line 23" in str(err)


def test_a_binary_file_given_as_csv_names_the_file(tmp_path):
    path = tmp_path / "run.csv"
    path.write_bytes(b"t,x1,x3,u1,u2\n0,\xff\xfe,1,2,3\n" * 8)  # Latin-1 bytes, no NUL
    err = _refused(path)
    assert "not UTF-8 text" in str(err)


def test_a_currents_metadata_outside_its_choices_is_refused_at_its_line(tmp_path):
    """``# currents:`` is 'measured' or 'commanded'; anything else (a user's 'averaged') is a
    LogError that quotes the value, not a crash."""
    err = _refused(_write(tmp_path, _rows(), meta=("# sample_rate_hz: 1000", "# currents: averaged")))
    assert "currents 'averaged'" in str(err) and "expected 'measured' or 'commanded'" in str(err)
    assert err.line == 2 and "line 2 (metadata 'currents')" in str(err)


def test_a_position_in_millimetres_names_the_quantity(tmp_path):
    rows = _rows()
    for r in rows:
        r[2] = repr(float(r[2]) * 1e3 + 100.0)  # x3 in mm, off-centre
    err = _refused(_write(tmp_path, rows))
    assert re.search(r"\): horizontal position 1\d\d\.\d+ m is beyond", str(err)), str(err)
    assert "looks like millimetres" in str(err) and err.column == "x3"


def test_a_mat_variable_that_is_not_numeric_names_its_type(tmp_path):
    t = np.arange(N) * DT
    path = tmp_path / "run.mat"
    scipy.io.savemat(
        path,
        {"t": t, "x1": 0.02 + 0 * t, "x3": 0 * t, "u1": 0 * t, "u2": 1.5 + 0 * t + 0j},
        oned_as="column",
    )
    err = _refused(path)
    assert "complex" in str(err) and "complex128" in str(err) and "u2" in str(err)


def test_mat_logs_are_written_compressed(tmp_path):
    """A .mat log is written with zlib compression (scipy's do_compression): a slowly varying
    60 s log at 1 kHz takes less than half of its raw 8-byte doubles. Read back, it is the same log."""
    n = 60_000
    t = np.arange(n) * DT
    rows = np.vstack([t, 0.02 + 0 * t, np.round(np.sin(t) * 1e3) / 1e5, 0 * t, 1.5 + 0 * t])
    csv = tmp_path / "run.csv"
    csv.write_text(
        "# sample_rate_hz: 1000\nt,x1,x3,u1,u2\n" + "\n".join(",".join(map(repr, r)) for r in rows.T.tolist())
    )
    log = read_log(csv)
    out = tmp_path / "run.mat"
    write_log(out, log)
    assert out.stat().st_size < 0.5 * rows.size * 8
    again = read_log(out)
    np.testing.assert_array_equal(again.x, log.x)
    np.testing.assert_array_equal(again.u, log.u)


@pytest.mark.parametrize(("row", "name"), [(0, "u1"), (1, "u2")])
def test_a_log_built_with_a_bad_current_names_the_row_as_its_column(row, name):
    """Log(...) refuses a current that is not finite, naming the row by its log column (u1 = i_q,
    u2 = i_d) and the sample."""
    from maglev_oc.data.log import Log
    from maglev_oc.errors import InputError

    t = np.arange(N) * DT
    x = np.vstack([0.02 + 0 * t, np.full(N, np.nan), 0 * t, np.full(N, np.nan)])
    u = np.vstack([0 * t, 1.5 + 0 * t])
    u[row, 7] = np.inf
    with pytest.raises(InputError, match=rf"Log.u: row {row} \({name}\) has inf at sample 7"):
        Log(t, x, u)


def test_a_mat_metadata_field_that_is_neither_text_nor_a_number_is_named(tmp_path):
    """A .mat log's ``metadata`` struct holds strings or single numbers; a field holding a vector is
    refused naming the field and where it is."""
    t = np.arange(N) * DT
    path = tmp_path / "run.mat"
    scipy.io.savemat(
        path,
        {
            "t": t,
            "x1": 0.02 + 1e-3 * np.sin(t),
            "x3": 1e-2 * np.sin(t),
            "u1": 0.1 * np.cos(t),
            "u2": 1.5 + 0 * t,
            "metadata": {"sample_rate_hz": "1000", "gains": np.array([1.0, 2.0])},
        },
        oned_as="column",
    )
    err = _refused(path)
    assert "field 'gains' is neither a string nor a number" in str(err) and err.column == "metadata"
