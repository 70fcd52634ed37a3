"""The log layer (SPEC 2): reading, validating, writing; one test per kind of bad log."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io
from numpy.testing import assert_allclose, assert_array_equal

from maglev_oc.data.logs import (
    Log,
    LogError,
    check_excitation,
    inputs_to_phase_currents,
    phase_currents_to_inputs,
    read_log,
    write_log,
    write_log_arrays,
)
from maglev_oc.errors import InputError
from maglev_oc.model.parameters import StageParameters

TAU = StageParameters().pole_pitch
META = ("# sample_rate_hz: 1000", "# units: SI")  # the header is on line 3, data from line 4


def _signals(n: int = 600, dt: float = 1e-3) -> dict[str, np.ndarray]:
    """A plausible run: gap around 20 mm, a few mm of motion, currents of a few A."""
    t = np.arange(n) * dt
    return {
        "t": t,
        "x1": 0.020 + 0.002 * np.sin(2 * np.pi * 1.3 * t),
        "x2": 0.002 * 2 * np.pi * 1.3 * np.cos(2 * np.pi * 1.3 * t),
        "x3": 0.010 * np.sin(2 * np.pi * 0.7 * t + 0.4),
        "u1": 0.8 * np.sin(2 * np.pi * 2.1 * t),
        "u2": 1.5 + 0.4 * np.cos(2 * np.pi * 0.9 * t),
    }


def _csv_text(
    names: tuple[str, ...] = ("t", "x1", "x3", "u1", "u2"),
    meta: tuple[str, ...] = META,
    n: int = 600,
    dt: float = 1e-3,
    edit=None,
) -> str:
    """CSV text; ``edit(rows)`` may change the cells (list of lists of str) before joining.

    Columns not in :func:`_signals` hold 0.0.
    Data row i is on line len(meta) + 2 + i.
    """
    sig = _signals(n, dt)
    rows = [[repr(float(sig[name][i])) if name in sig else "0.0" for name in names] for i in range(n)]
    if edit is not None:
        edit(rows)
    return "\n".join([*meta, ",".join(names), *(",".join(row) for row in rows)]) + "\n"


def _line(i: int, meta: tuple[str, ...] = META) -> int:
    """The editor line of data row i."""
    return len(meta) + 2 + i


def _bad(tmp_path: Path, text: str, name: str = "run.csv", **kw) -> LogError:
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(LogError) as info:
        read_log(path, **kw)
    message = str(info.value)
    assert message.startswith(str(path)), message  # every message names the file
    return info.value


# --- good logs ----------------------------------------------------------------------------------
def test_reads_a_csv_with_metadata_and_marks_missing_rates(tmp_path: Path):
    path = tmp_path / "run.csv"
    path.write_text(_csv_text())
    log = read_log(path)
    sig = _signals()
    assert log.n == 600
    assert log.x.shape == (4, 600) and log.u.shape == (2, 600)
    assert_array_equal(log.x[0], sig["x1"])  # repr() is exact: no tolerance
    assert_array_equal(log.u[1], sig["u2"])
    assert log.states_measured == (True, False, True, False)
    assert np.all(np.isnan(log.x[1])) and np.all(np.isnan(log.x[3]))
    assert dict(log.metadata) == {"sample_rate_hz": "1000", "units": "SI"}
    assert log.source == str(path)
    assert not log.currents_measured
    assert any("x2, x4 not in the log" in note for note in log.notes)
    assert_allclose(log.sample_time, 1e-3, rtol=1e-9)  # arange(n) * 1e-3: rounding only
    assert_allclose(log.duration, 0.599, rtol=1e-12)


def test_currents_measured_comes_from_the_metadata(tmp_path: Path):
    path = tmp_path / "run.csv"
    path.write_text(_csv_text(meta=(*META, "# currents: measured")))
    assert read_log(path).currents_measured


def test_other_columns_are_ignored_with_a_note(tmp_path: Path):
    def add_text(rows):
        for row in rows:
            row[5] = "closed loop"  # a text column that is not ours must not matter

    names = ("t", "x1", "x3", "u1", "u2", "mode")
    path = tmp_path / "run.csv"
    path.write_text(_csv_text(names, edit=add_text))
    log = read_log(path)
    assert any("column 6 ('mode')" in note and "ignored" in note for note in log.notes)


def test_csv_round_trip_is_exact(tmp_path: Path):
    sig = _signals()
    x = np.vstack([sig["x1"], sig["x2"], sig["x3"], np.full(600, np.nan)])
    u = np.vstack([sig["u1"], sig["u2"]])
    path = write_log_arrays(
        tmp_path / "out.csv", sig["t"], x, u, metadata={"rig": "Quanser 2-DOF"}, currents_measured=True
    )
    text = path.read_text()
    assert text.startswith("# units: SI\n# sample_rate_hz: 1000\n")
    log = read_log(path)
    # '%.17g' round-trips float64 exactly: no tolerance
    assert_array_equal(log.t, sig["t"])
    assert_array_equal(log.x, x)  # NaN rows compare equal in assert_array_equal
    assert_array_equal(log.u, u)
    assert log.currents_measured
    assert log.metadata["rig"] == "Quanser 2-DOF"
    # and again: writing what was read gives the same file
    write_log(tmp_path / "again.csv", log)
    assert (tmp_path / "again.csv").read_text() == text


def test_mat_round_trip_is_exact(tmp_path: Path):
    sig = _signals()
    x = np.vstack([sig["x1"], np.full(600, np.nan), sig["x3"], sig["x2"]])
    u = np.vstack([sig["u1"], sig["u2"]])
    path = write_log_arrays(tmp_path / "out.mat", sig["t"], x, u, metadata={"rig": "A"})
    log = read_log(path)
    assert_array_equal(log.t, sig["t"])
    assert_array_equal(log.x, x)
    assert_array_equal(log.u, u)
    assert log.states_measured == (True, False, True, True)
    assert log.metadata["rig"] == "A" and log.metadata["units"] == "SI"


def test_reads_a_mat_file_saved_by_other_tools(tmp_path: Path):
    # column vectors (n, 1), a numeric metadata field, and an extra variable
    sig = _signals()
    payload = {name: sig[name].reshape(-1, 1) for name in ("t", "x1", "x3", "u1", "u2")}
    payload["metadata"] = {"sample_rate_hz": 1000.0, "units": "SI"}
    payload["comment"] = "bench run"
    scipy.io.savemat(tmp_path / "run.mat", payload)
    log = read_log(tmp_path / "run.mat")
    assert_array_equal(log.x[2], sig["x3"])
    assert log.metadata["sample_rate_hz"] == "1000"
    assert any("'comment'" in note for note in log.notes)


def test_reading_leaves_the_file_unchanged(tmp_path: Path):
    csv = tmp_path / "run.csv"
    csv.write_text(_csv_text())
    mat = write_log(tmp_path / "run.mat", read_log(csv))
    for path in (csv, mat):
        before = (path.read_bytes(), path.stat().st_mtime_ns)
        read_log(path)
        assert (path.read_bytes(), path.stat().st_mtime_ns) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.csv", "run.mat"]  # no stray files


def test_write_is_atomic_and_refuses_what_it_cannot_write(tmp_path: Path):
    sig = _signals()
    x = np.vstack([sig["x1"], sig["x2"], sig["x3"], sig["x2"]])
    u = np.vstack([sig["u1"], sig["u2"]])
    target = tmp_path / "out.csv"
    target.write_text("previous")
    with pytest.raises(ValueError, match="'bad key:'"):
        write_log_arrays(target, sig["t"], x, u, metadata={"bad key:": "v"})
    assert target.read_text() == "previous"  # a failed write leaves the old file
    with pytest.raises(ValueError, match=r"'sample rate'.*MATLAB"):
        write_log_arrays(tmp_path / "out.mat", sig["t"], x, u, metadata={"sample rate": "1"})
    with pytest.raises(ValueError, match=r"'\.h5'"):
        write_log_arrays(tmp_path / "out.h5", sig["t"], x, u)


# --- phase currents -----------------------------------------------------------------------------
def test_phase_transform_closed_form():
    # Eq. (2) of 001 at x3 = 0: (ia, ib, ic) = (1, -1/2, -1/2) is pure i_d = 1; half a pole
    # pitch further the same currents are pure i_q = -1 (theta = pi/2).
    phases = np.array([[1.0, 1.0], [-0.5, -0.5], [-0.5, -0.5]])
    u = phase_currents_to_inputs(*phases, x3=np.array([0.0, TAU / 2]), pole_pitch=TAU)
    assert_allclose(u, [[0.0, -1.0], [1.0, 0.0]], atol=1e-15)  # cos/sin of pi/2, 2 pi/3: ulps


def test_phase_currents_round_trip_through_a_file(tmp_path: Path):
    sig = _signals()
    u = np.vstack([sig["u1"], sig["u2"]])
    phases = inputs_to_phase_currents(u, sig["x3"], TAU)
    assert_allclose(phases.sum(axis=0), 0.0, atol=1e-14)  # balanced: the three cosines cancel
    cols = {"t": sig["t"], "x1": sig["x1"], "x3": sig["x3"], "ia": phases[0], "ib": phases[1]}
    cols["ic"] = phases[2]
    path = tmp_path / "phases.csv"
    rows = np.column_stack(list(cols.values()))
    path.write_text(
        "\n".join([*META, ",".join(cols), *(",".join(map(repr, r.tolist())) for r in rows)]) + "\n"
    )
    log = read_log(path)
    # forward then inverse transform of a few-ampere current: float rounding, about 1e-15 A
    assert_allclose(log.u, u, rtol=0, atol=1e-12)
    assert any("from ia, ib, ic" in note and f"tau = {TAU:g} m" in note for note in log.notes)


def test_logged_inputs_win_and_a_disagreement_gets_a_note(tmp_path: Path):
    sig = _signals()
    u = np.vstack([sig["u1"], sig["u2"]])
    phases = inputs_to_phase_currents(u, sig["x3"], TAU)
    names = ("t", "x1", "x3", "u1", "u2", "ia", "ib", "ic")
    table = np.column_stack([sig["t"], sig["x1"], sig["x3"], u[0], u[1], *phases])
    body = "\n".join(",".join(map(repr, r.tolist())) for r in table)
    path = tmp_path / "both.csv"
    path.write_text("\n".join([*META, ",".join(names), body]) + "\n")
    assert not any("differs" in note for note in read_log(path).notes)  # consistent: no note
    # the same file read with another pole pitch: the transform no longer matches the logged u
    wrong = StageParameters(pole_pitch=0.050, magnet_width=0.025)
    log = read_log(path, params=wrong)
    assert_array_equal(log.u, u)  # the logged u1, u2 are used
    notes = [note for note in log.notes if "differs" in note]
    assert len(notes) == 2 and "tolerance 0.01 A" in notes[0] and "line " in notes[0]


# --- one test per kind of bad log ------------------------------------------------------------
def test_missing_required_columns(tmp_path: Path):
    err = _bad(tmp_path, _csv_text(("t", "x1", "u1", "u2")))
    assert "missing required column(s) x3" in str(err)
    assert "columns found: t, x1, u1, u2" in str(err)
    assert err.line == 3 and err.column == "x3"


def test_missing_phase_current(tmp_path: Path):
    err = _bad(tmp_path, _csv_text(("t", "x1", "x3", "ia", "ib")))
    assert "ia, ib, ic" in str(err) and "missing ic" in str(err)


def test_non_numeric_cell(tmp_path: Path):
    def spoil(rows):
        rows[17][2] = "0.01a"

    err = _bad(tmp_path, _csv_text(edit=spoil))
    assert f"line {_line(17)}, column 3 ('x3')" in str(err) and "'0.01a'" in str(err)
    assert (err.line, err.column) == (_line(17), "x3")


def test_empty_cell(tmp_path: Path):
    def spoil(rows):
        rows[3][4] = ""

    err = _bad(tmp_path, _csv_text(edit=spoil))
    assert f"line {_line(3)}, column 5 ('u2')" in str(err) and "empty cell" in str(err)


def test_row_with_an_extra_cell(tmp_path: Path):
    def spoil(rows):
        rows[40].append("1.0")

    err = _bad(tmp_path, _csv_text(edit=spoil))
    assert f"line {_line(40)}" in str(err) and "6 cells" in str(err) and "(line 3) has 5" in str(err)


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_nan_or_inf(tmp_path: Path, value: str):
    def spoil(rows):
        rows[250][1] = value

    err = _bad(tmp_path, _csv_text(edit=spoil))
    assert f"line {_line(250)}, column 2 ('x1')" in str(err) and value.lstrip("-") in str(err)


def test_time_not_increasing(tmp_path: Path):
    def spoil(rows):
        rows[100][0] = rows[99][0]

    err = _bad(tmp_path, _csv_text(edit=spoil))
    assert f"line {_line(100)}, column 1 ('t')" in str(err)
    assert "does not increase" in str(err) and f"line {_line(99)}" in str(err)


def test_gap_in_time(tmp_path: Path):
    def drop(rows):
        del rows[300:305]  # 5 samples missing: a step of 6 ms in a 1 ms log

    err = _bad(tmp_path, _csv_text(edit=drop, meta=()))
    assert f"line {_line(300, ())}" in str(err) and "gap in time" in str(err)
    assert "0.006 s" in str(err) and "6 x the median step 0.001 s" in str(err)


def test_one_missing_sample_is_a_gap_in_time(tmp_path: Path):
    """The smallest gap a log can have, one sample dropped (a step of twice the median), is named as a
    gap at its line, not as irregular sampling: 2 x is beyond GAP_FACTOR (1.5), and a step of 1.4 x
    with the grid kept (the next stamp on time) is jitter, not a gap."""

    def drop_one(rows):
        del rows[300]

    err = _bad(tmp_path, _csv_text(edit=drop_one, meta=()))
    assert f"line {_line(300, ())}" in str(err) and "gap in time" in str(err)
    assert "2 x the median step 0.001 s" in str(err) and "1 such gap(s)" in str(err)

    def late(rows):
        rows[300][0] = repr(300e-3 + 0.4e-3)

    err = _bad(tmp_path, _csv_text(edit=late, meta=()))
    assert "irregular sampling" in str(err) and "gap in time" not in str(err)


def test_sample_rate_in_metadata_disagrees(tmp_path: Path):
    err = _bad(tmp_path, _csv_text(meta=("# units: SI", "# sample_rate_hz: 5000")))
    assert "line 2 (metadata 'sample_rate_hz')" in str(err)
    assert "5000" in str(err) and "1000 Hz" in str(err) and err.line == 2


def test_gap_in_millimetres(tmp_path: Path):
    def to_mm(rows):
        for row in rows:
            row[1] = repr(float(row[1]) * 1000)

    err = _bad(tmp_path, _csv_text(edit=to_mm))
    assert f"line {_line(0)}, column 2 ('x1')" in str(err) and "millimetres" in str(err)


def test_horizontal_position_in_millimetres(tmp_path: Path):
    def to_mm(rows):
        for row in rows:
            row[2] = repr(float(row[2]) * 1000)

    err = _bad(tmp_path, _csv_text(edit=to_mm))
    # x3 = 10 mm sin(...) first exceeds 0.5 (in mm) at the first sample: sin(0.4) * 10 = 3.9
    assert "column 3 ('x3')" in str(err) and "millimetres" in str(err)


def test_currents_in_milliamperes(tmp_path: Path):
    def to_ma(rows):
        for row in rows:
            row[4] = repr(float(row[4]) * 1000)

    err = _bad(tmp_path, _csv_text(edit=to_ma))
    assert "column 5 ('u2')" in str(err) and "milliamperes" in str(err)


def test_time_in_milliseconds(tmp_path: Path):
    err = _bad(tmp_path, _csv_text(meta=(), dt=1.0))
    assert "milliseconds" in str(err) and err.column == "t"


def test_too_few_samples(tmp_path: Path):
    err = _bad(tmp_path, _csv_text(n=600), min_samples=1000)
    assert "too short" in str(err) and "600 samples" in str(err) and "min_samples = 1000" in str(err)


def test_too_short_in_time(tmp_path: Path):
    err = _bad(tmp_path, _csv_text(n=300))  # 0.299 s < the default 0.5 s
    assert "too short" in str(err) and "0.299 s" in str(err) and "min_duration = 0.5 s" in str(err)
    path = tmp_path / "short.csv"
    path.write_text(_csv_text(n=300))
    assert read_log(path, min_duration=0.2).n == 300


def test_duplicate_column_names(tmp_path: Path):
    err = _bad(tmp_path, _csv_text(("t", "x1", "x3", "u1", "u2", "x1")))
    assert "duplicate" in str(err) and "'x1' in columns 2, 6" in str(err) and err.line == 3


def test_empty_file(tmp_path: Path):
    err = _bad(tmp_path, "")
    assert "empty file" in str(err)
    err = _bad(tmp_path, "# units: SI\n\n")
    assert "empty file" in str(err)


def test_header_only(tmp_path: Path):
    err = _bad(tmp_path, "# units: SI\nt,x1,x3,u1,u2\n")
    assert "header only" in str(err) and err.line == 2


def test_header_written_as_a_comment(tmp_path: Path):
    text = _csv_text(meta=("# units: SI",)).replace("\nt,x1", "\n# t,x1")
    err = _bad(tmp_path, text)
    assert "no header line" in str(err) and "line 2 looks like the header" in str(err)


def test_units_other_than_si(tmp_path: Path):
    err = _bad(tmp_path, _csv_text(meta=("# units: mm",)))
    assert "line 1" in str(err) and "'mm'" in str(err)


def test_conflicting_metadata(tmp_path: Path):
    err = _bad(tmp_path, _csv_text(meta=("# rig: A", "# rig: B")))
    assert err.line == 2 and "'A' (line 1)" in str(err)


def test_blank_and_space_only_lines_keep_line_numbers_right(tmp_path: Path):
    def spoil(rows):
        rows[10] = ["   "]  # a line of spaces in the data (becomes an empty line)
        rows[20][1] = "x"

    text = _csv_text(edit=spoil).replace("\n   \n", "\n   \n\n")  # and one more blank line
    err = _bad(tmp_path, text)
    assert f"line {_line(20) + 1}, column 2" in str(err)  # +1: the extra blank line


def _write_v73(path: Path, variables: dict, metadata: dict | None = None) -> None:
    """A file laid out as MATLAB's save(..., '-v7.3') lays it out (written without MATLAB): a
    512-byte user block holding the 128-byte MAT header, then HDF5 with each variable stored
    transposed (MATLAB is column-major) and tagged with its MATLAB_class; a struct is a group and
    a string is uint16 characters."""
    h5py = pytest.importorskip("h5py")
    with h5py.File(path, "w", userblock_size=512) as f:
        for name, value in variables.items():
            if isinstance(value, str):
                d = f.create_dataset(name, data=np.array([[ord(c)] for c in value], dtype=np.uint16))
                d.attrs["MATLAB_class"] = np.bytes_("char")
            else:
                d = f.create_dataset(name, data=np.atleast_2d(np.asarray(value, dtype=float)))
                d.attrs["MATLAB_class"] = np.bytes_("double")
        if metadata is not None:
            g = f.create_group("metadata")
            g.attrs["MATLAB_class"] = np.bytes_("struct")
            for key, text in metadata.items():
                d = g.create_dataset(key, data=np.array([[ord(c)] for c in text], dtype=np.uint16))
                d.attrs["MATLAB_class"] = np.bytes_("char")
        f.create_group("#refs#")  # MATLAB's bookkeeping, to be left out
    header = (
        b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 ."
    )
    with path.open("r+b") as fh:
        fh.write(header.ljust(116) + b"\x00" * 8 + b"\x00\x02IM")


def test_matlab_v73_reads_like_v7(tmp_path: Path):
    # MATLAB stores an n x 1 column as HDF5 shape (1, n): row vectors (1, n) here, so the reader
    # must transpose back; the same log saved as v7 reads to the same arrays and metadata
    sig = _signals()
    names = ("t", "x1", "x2", "x3", "u1", "u2")
    meta = {"units": "SI (m, A, s)", "currents": "measured", "sample_rate_hz": "1000"}
    _write_v73(tmp_path / "new.mat", {n: sig[n].reshape(1, -1) for n in names} | {"note": "bench"}, meta)
    scipy.io.savemat(tmp_path / "old.mat", {n: sig[n] for n in names} | {"metadata": meta})
    new, old = read_log(tmp_path / "new.mat"), read_log(tmp_path / "old.mat")
    for a in ("t", "x", "u"):
        assert_array_equal(getattr(new, a), getattr(old, a))
    assert new.metadata == old.metadata and new.metadata["units"] == "SI (m, A, s)"
    assert any("'note'" in n for n in new.notes)  # an extra variable is named, not read


def test_matlab_v73_errors_name_the_variable(tmp_path: Path):
    sig = _signals()
    columns = {n: sig[n].reshape(1, -1) for n in ("t", "x1", "x3", "u1", "u2")}
    _write_v73(tmp_path / "mm.mat", columns | {"x1": sig["x1"].reshape(1, -1) * 1000})
    with pytest.raises(LogError, match=r"variable 'x1', element 1: .*millimetres"):
        read_log(tmp_path / "mm.mat")
    _write_v73(tmp_path / "text.mat", columns | {"u2": "1.5"})
    with pytest.raises(LogError, match=r"variable 'u2'.*not numeric"):
        read_log(tmp_path / "text.mat")
    # a v7.3 header with no HDF5 behind it
    header = (
        b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 ."
    )
    (tmp_path / "cut.mat").write_bytes(header.ljust(116) + b"\x00" * 8 + b"\x00\x02IM" + b"\x00" * 512)
    with pytest.raises(LogError, match=r"cut.mat.*not a readable MATLAB 7.3"):
        read_log(tmp_path / "cut.mat")


def test_mat_errors_name_variable_and_element(tmp_path: Path):
    sig = _signals()
    payload = {name: sig[name] for name in ("t", "x1", "x3", "u1", "u2")}
    payload["x1"] = payload["x1"] * 1000
    scipy.io.savemat(tmp_path / "mm.mat", payload)
    with pytest.raises(LogError, match=r"variable 'x1', element 1: .*millimetres"):
        read_log(tmp_path / "mm.mat")
    payload = {name: sig[name] for name in ("t", "x1", "u1", "u2")}
    scipy.io.savemat(tmp_path / "missing.mat", payload)
    with pytest.raises(LogError, match=r"missing required column.*x3"):
        read_log(tmp_path / "missing.mat")


# --- the Log object, excitation -----------------------------------------------------------------
def test_log_validates_when_made_and_is_read_only():
    sig = _signals()
    x = np.vstack([sig["x1"], sig["x2"], sig["x3"], np.full(600, np.nan)])
    u = np.vstack([sig["u1"], sig["u2"]])
    log = Log(sig["t"], x, u)
    with pytest.raises(ValueError, match="read-only"):
        log.x[0, 0] = 1.0
    with pytest.raises(ValueError, match=r"Log.x: expected shape \(4, 600\)"):
        Log(sig["t"], x[:3], u)
    partly = x.copy()
    partly[3, 5] = 0.0  # x4 neither all NaN nor all finite
    with pytest.raises(ValueError, match=r"row 3 \(x4\)"):
        Log(sig["t"], partly, u)
    with pytest.raises(ValueError, match=r"t\[1\]"):
        Log(sig["t"][::-1], x, u)


def test_slices_for_held_out_data(tmp_path: Path):
    path = tmp_path / "run.csv"
    path.write_text(_csv_text())
    log = read_log(path)
    first = log.time_slice(0.0, 0.3)
    rest = log.time_slice(0.3, 1.0)
    assert first.n + rest.n == log.n and first.t[-1] < rest.t[0]
    assert first.source == log.source and "time_slice" in first.notes[-1]
    tail = log.index_slice(-100)
    assert_array_equal(tail.u, log.u[:, -100:])
    with pytest.raises(ValueError, match="need at least 2"):
        log.index_slice(5, 6)


def test_check_excitation(tmp_path: Path):
    def hold(rows):
        for row in rows:
            row[2] = "0.0"  # x3 held: the vertical-only runs of 000 Table II
            row[3] = "0.0"  # and i_q = 0

    path = tmp_path / "vertical.csv"
    path.write_text(_csv_text(edit=hold))
    log = read_log(path)
    with pytest.raises(LogError, match=r"x3 std 0 m <= resolution 1e-05 m; u1 std 0 A"):
        check_excitation(log)
    result = check_excitation(log, axis="vertical")
    # a 2 mm sine has standard deviation 2 mm / sqrt(2); 600 samples over 0.78 periods: 5 %
    assert_allclose(result.std["x1"], 2e-3 / np.sqrt(2), rtol=0.05)
    assert result.checked == ("x1", "u2")
    with pytest.raises(ValueError, match="axis"):
        check_excitation(log, axis="x")


def test_quantization_alone_is_no_excitation():
    # a held position toggling between two encoder counts: std at most half a count
    n = 1000
    t = np.arange(n) * 1e-3
    x1 = 0.02 + 10e-6 * (np.arange(n) % 2)
    x = np.vstack([x1, np.full(n, np.nan), np.sin(t) * 0.01, np.full(n, np.nan)])
    log = Log(t, x, np.vstack([np.sin(t), np.cos(t)]))
    with pytest.raises(LogError, match="x1 std 5e-06 m"):
        check_excitation(log)


@pytest.mark.slow
def test_a_60s_5khz_log_reads_whole(tmp_path: Path):
    n = 300_000
    sig = _signals(n, 2e-4)
    x = np.vstack([sig["x1"], sig["x2"], sig["x3"], sig["x2"]])
    path = write_log_arrays(tmp_path / "big.csv", sig["t"], x, np.vstack([sig["u1"], sig["u2"]]))
    log = read_log(path)  # its speed: bench/log_io.py
    assert log.n == n
    assert np.array_equal(log.x[2], sig["x3"]) and np.array_equal(log.u[1], sig["u2"])  # %.17g round-trips


def test_currents_moved_earlier_are_the_logged_ones_a_whole_sample_later(tmp_path: Path):
    """``Log.currents_advanced``: the currents of a log logged late, put back against the positions
    (``maglev-oc diagnose --currents-late``). A whole sample is exact; half a sample is the mean of
    the two neighbours (linear interpolation); the positions and times are kept, less the samples at
    the end that have no current that late; nothing to move, the same log."""
    path = tmp_path / "run.csv"
    path.write_text(_csv_text())
    log = read_log(path)
    moved = log.currents_advanced(1e-3)
    assert moved.n == log.n - 1
    assert_array_equal(moved.u, log.u[:, 1:])
    assert_array_equal(moved.x[[0, 2]], log.x[[0, 2], :-1])
    assert_array_equal(moved.t, log.t[:-1])
    assert "earlier against the positions" in moved.notes[-1]
    half = log.currents_advanced(0.5e-3)
    assert_allclose(half.u, 0.5 * (log.u[:, :-1] + log.u[:, 1:]), rtol=0, atol=1e-12)
    assert log.currents_advanced(0.0) is log


@pytest.mark.parametrize("delay", [-1e-3, float("nan"), 0.06])
def test_currents_moved_by_a_negative_or_too_long_delay_are_refused(tmp_path: Path, delay):
    path = tmp_path / "run.csv"
    path.write_text(_csv_text())  # 0.6 s: a tenth is 0.06 s
    with pytest.raises(InputError, match="currents late by") as info:
        read_log(path).currents_advanced(delay)
    assert str(path) in str(info.value)
