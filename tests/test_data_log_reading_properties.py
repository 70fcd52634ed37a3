"""Properties of reading logs (``maglev_oc.data``): what is refused and what the refusal says,
checked against files written here line by line:

- the plausibility limits (gap, horizontal position, currents) are limits on the magnitude: a
  value in millimetres or milliamperes is refused whatever its sign, naming line and column, and
  the largest plausible values of either sign are read;
- time must increase strictly, in a file and in a :class:`Log`; the sample-rate metadata may be
  1 % off the time column and a time stamp 10 % of a step off the grid;
- every CSV refusal is a LogError naming the file and carrying the line (as an attribute and in
  its words): a bad cell, a short row, a metadata value outside its choices, a position in
  millimetres, a binary file;
- a .mat log's vectors have one length, a numeric metadata field keeps every digit, and a
  variable or metadata field of the wrong type is named with its type;
- a :class:`Log` made with a current that is not finite names the row by its log column.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from maglev_oc.data.logs import MAX_AIR_GAP, MAX_CURRENT, MAX_HORIZONTAL_POSITION, Log, LogError, read_log
from tests._log_files import _signals, _write_csv
from tests.test_logs import META, _bad, _csv_text, _line

N = 600


# --- plausibility limits are on the magnitude ---------------------------------------------------
@pytest.mark.parametrize(
    ("column", "value", "limit"),
    [
        ("x1", 20.0, MAX_AIR_GAP),  # a 20 mm gap written in millimetres
        ("x3", 60.0, MAX_HORIZONTAL_POSITION),  # +60 mm
        ("x3", -60.0, MAX_HORIZONTAL_POSITION),  # -60 mm: the travel is symmetric (+-50 mm)
        ("u1", -1500.0, MAX_CURRENT),  # -1.5 A in milliamperes
        ("u2", 1500.0, MAX_CURRENT),
        ("u2", -1500.0, MAX_CURRENT),
    ],
)
def test_a_value_beyond_its_limit_is_refused_whatever_its_sign(tmp_path: Path, column, value, limit):
    """SPEC 2: values that look like millimetres or milliamperes are refused; the limits are on
    |value| (x3 and the currents take both signs), and the message names line and column."""
    assert abs(value) > limit  # the case is beyond the documented limit
    cols = _signals()
    row = 37
    cols[column] = cols[column].copy()
    cols[column][row] = value
    path = _write_csv(tmp_path / "units.csv", cols)
    with pytest.raises(LogError) as info:
        read_log(path)
    assert info.value.column == column
    assert info.value.line == len(META) + 2 + row
    assert str(info.value).startswith(str(path))


def test_values_just_inside_the_limits_are_read(tmp_path: Path):
    """The other side of the same limits: the largest plausible magnitudes of either sign pass."""
    cols = _signals()
    cols["x3"] = cols["x3"].copy()
    cols["x3"][10] = -0.99 * MAX_HORIZONTAL_POSITION
    cols["u1"] = cols["u1"].copy()
    cols["u1"][11] = -0.99 * MAX_CURRENT
    log = read_log(_write_csv(tmp_path / "edge.csv", cols))
    assert log.x[2, 10] == cols["x3"][10] and log.u[0, 11] == cols["u1"][11]


# --- time must increase strictly -----------------------------------------------------------------
def test_a_repeated_time_stamp_is_refused_by_the_log_and_by_the_reader(tmp_path: Path):
    """Time strictly increasing (SPEC 2; :class:`Log` docstring): a step of exactly zero is as
    wrong as a negative one (the rates are differences divided by the step)."""
    cols = _signals()
    t = cols["t"].copy()
    t[100] = t[99]
    x = np.vstack([cols["x1"], np.full(N, np.nan), cols["x3"], np.full(N, np.nan)])
    u = np.vstack([cols["u1"], cols["u2"]])
    with pytest.raises(ValueError, match=r"t\[100\]"):
        Log(t, x, u)
    cols["t"] = t
    path = _write_csv(tmp_path / "repeat.csv", cols)
    with pytest.raises(LogError) as info:
        read_log(path)
    assert info.value.column == "t" and info.value.line == len(META) + 2 + 100


# --- .mat specifics ------------------------------------------------------------------------------
def test_mat_vectors_of_different_lengths_are_refused(tmp_path: Path):
    """Every column of a log is one sample per time: a shorter vector is refused naming it."""
    cols = _signals()
    payload = {name: cols[name] for name in ("t", "x1", "x3", "u1", "u2")}
    payload["u1"] = payload["u1"][:-3]
    scipy.io.savemat(tmp_path / "short.mat", payload)
    with pytest.raises(LogError) as info:
        read_log(tmp_path / "short.mat")
    assert info.value.column == "u1" and "597" in str(info.value)


def test_mat_numeric_metadata_keeps_every_digit(tmp_path: Path):
    """mat_reader docstring: numbers in the metadata struct are written with 17 significant
    digits, which round-trips any float64 exactly."""
    cols = _signals()
    value = 0.1 + 0.2  # 0.30000000000000004: needs all 17 digits
    payload = {name: cols[name] for name in ("t", "x1", "x3", "u1", "u2")}
    payload["metadata"] = {"sample_rate_hz": 1000.0, "gain": value}
    scipy.io.savemat(tmp_path / "meta.mat", payload)
    log = read_log(tmp_path / "meta.mat")
    assert float(log.metadata["gain"]) == value


# --- the log layer's sampling checks -----------------------------------------------------------
def test_jitter_is_measured_in_steps(tmp_path):
    """A time stamp 20 % of a step off the uniform grid (0.2 ms at 1 kHz: steps of 1.2 and 0.8
    ms, no gap by GAP_FACTOR 1.5) is refused naming its line and column; one 5 % off (half of
    JITTER_TOLERANCE = 10 %) is read. The tolerance scales with the step: at 100 Hz the same 20 %
    is refused too."""
    for dt, meta in ((1e-3, META), (1e-2, ("# sample_rate_hz: 100", "# units: SI"))):
        for shift, refused in ((0.2, True), (0.05, False)):

            def edit(rows, shift=shift, dt=dt):
                rows[300][0] = repr(300 * dt + shift * dt)

            text = _csv_text(meta=meta, n=600, dt=dt, edit=edit)
            if refused:
                err = _bad(tmp_path, text)
                assert "irregular sampling" in str(err)
                assert f"line {_line(300, meta)}, column 1 ('t')" in str(err)
            else:
                path = tmp_path / "ok.csv"
                path.write_text(text)
                assert read_log(path).t.size == 600


@pytest.mark.parametrize(
    ("stated", "refused"), [("1020", True), ("980", True), ("1005", False), ("995", False)]
)
def test_sample_rate_tolerance_is_one_percent(tmp_path, stated, refused):
    """``sample_rate_hz`` 2 % off the 1 kHz of the time column is refused at its metadata line;
    0.5 % off is read (SAMPLE_RATE_TOLERANCE = 1 %)."""
    meta = (f"# sample_rate_hz: {stated}", "# units: SI")
    text = _csv_text(meta=meta)
    if refused:
        err = _bad(tmp_path, text)
        assert "line 1 (metadata 'sample_rate_hz')" in str(err) and "disagrees" in str(err)
    else:
        path = tmp_path / "ok.csv"
        path.write_text(text)
        assert read_log(path).metadata["sample_rate_hz"] == stated


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
