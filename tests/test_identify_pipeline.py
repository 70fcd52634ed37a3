"""``maglev-oc identify`` and the checks in front of it: every bad log gets its clear error."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from maglev_oc.cli import main
from maglev_oc.data.logs import Log, LogError, write_log
from maglev_oc.identification.experiments import TWIN_TRUTH, excitation_log
from maglev_oc.identification.pipeline import MIN_DURATION, check_identifiable, identify, load_logs


@pytest.fixture(scope="module")
def good_log(model) -> Log:
    """7 s of the papers' excitation on the twin."""
    return excitation_log(model.with_constants(TWIN_TRUTH), duration=7.0, seed=2, controller_model=model)


@pytest.fixture()
def good_csv(tmp_path: Path, good_log: Log) -> Path:
    return write_log(tmp_path / "run.csv", good_log)


def _rewrite(src: Path, dst: Path, edit) -> Path:
    lines = src.read_text().splitlines()
    header = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    names = lines[header].split(",")
    rows = [line.split(",") for line in lines[header + 1 :]]
    names, rows = edit(names, rows)
    text = "\n".join([*lines[:header], ",".join(names), *(",".join(r) for r in rows)]) + "\n"
    dst.write_text(text)
    return dst


def _cli_error(capsys, path: Path, tmp_path: Path) -> str:
    code = main(["identify", str(path), "--json", str(tmp_path / "out.json")])
    err = capsys.readouterr().err
    assert code == 2
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out.json").exists()  # nothing written on error
    return err


def test_missing_column(tmp_path, good_csv, capsys):
    def drop_u2(names, rows):
        j = names.index("u2")
        return [n for k, n in enumerate(names) if k != j], [
            [c for k, c in enumerate(r) if k != j] for r in rows
        ]

    bad = _rewrite(good_csv, tmp_path / "no_u2.csv", drop_u2)
    with pytest.raises(LogError, match=r"missing required column.*u2"):
        load_logs([bad])
    err = _cli_error(capsys, bad, tmp_path)
    assert "no_u2.csv" in err and "u2" in err


def test_nan_cell(tmp_path, good_csv, capsys):
    def spoil(names, rows):
        rows[500][names.index("x1")] = "nan"
        return names, rows

    bad = _rewrite(good_csv, tmp_path / "nan.csv", spoil)
    with pytest.raises(LogError, match="nan") as info:
        load_logs([bad])
    assert info.value.column == "x1" and info.value.line is not None
    assert "nan.csv" in _cli_error(capsys, bad, tmp_path)


def test_gap_in_millimetres(tmp_path, good_csv, capsys):
    def to_mm(names, rows):
        j = names.index("x1")
        for r in rows:
            r[j] = repr(float(r[j]) * 1000)
        return names, rows

    bad = _rewrite(good_csv, tmp_path / "mm.csv", to_mm)
    with pytest.raises(LogError, match="millimetres"):
        load_logs([bad])
    assert "millimetres" in _cli_error(capsys, bad, tmp_path)


def test_time_not_increasing(tmp_path, good_csv, capsys):
    def swap(names, rows):
        j = names.index("t")
        rows[1000][j], rows[1001][j] = rows[1001][j], rows[1000][j]
        return names, rows

    bad = _rewrite(good_csv, tmp_path / "time.csv", swap)
    with pytest.raises(LogError, match="time does not increase"):
        load_logs([bad])
    assert "time does not increase" in _cli_error(capsys, bad, tmp_path)


def test_too_short_for_identification(tmp_path, good_log, capsys, model):
    # A 2 s log is a valid log (read_log accepts it) but too short to identify from.
    short = write_log(tmp_path / "short.csv", good_log.index_slice(0, 2000))
    logs = load_logs([short])
    with pytest.raises(LogError, match="too short for identification") as info:
        identify(logs, model)
    assert "short.csv" in str(info.value) and f"{MIN_DURATION:g} s" in str(info.value)
    err = _cli_error(capsys, short, tmp_path)
    assert "short.csv" in err and "too short for identification" in err


def test_no_excitation(tmp_path, capsys, model):
    # A rig held still for 8 s: nothing to identify from; the message names the file and the
    # signals that do not move.
    t = np.arange(8000) * 1e-3
    x = np.full((4, t.size), np.nan)
    x[0] = 0.02 + 1e-5 * (np.arange(t.size) % 2)  # toggling one count: std 5 um < 10 um
    x[2] = 0.0
    u = np.vstack([np.zeros(t.size), np.full(t.size, 1.4)])
    still = write_log(tmp_path / "still.csv", Log(t, x, u))
    logs = load_logs([still])
    with pytest.raises(LogError, match="no excitation") as info:
        identify(logs, model)
    msg = str(info.value)
    assert "still.csv" in msg and "x1" in msg and "u2" in msg
    err = _cli_error(capsys, still, tmp_path)
    assert "still.csv" in err and "no excitation" in err


def test_vertical_only_log_identifies_the_vertical_constants(good_log, model):
    # A log that moves only vertically may be used for C2..C4 but not for C1 alone.
    x = good_log.x.copy()
    x[2] = 0.0
    u = good_log.u.copy()
    u[0] = 0.0
    vertical = Log(good_log.t, x, u, source="vertical.csv")
    check_identifiable([vertical], ("C2", "C3", "C4"))
    with pytest.raises(LogError, match=r"vertical.csv.*no excitation.*horizontal"):
        check_identifiable([vertical], ("C1",))
    # with another log that moves horizontally, C1..C4 together are fine
    check_identifiable([vertical, good_log], ("C1", "C2", "C3", "C4"))


def test_cli_writes_json(tmp_path, good_csv, capsys):
    # The output-error fit is covered in test_identify_output_error.py and by the slow test
    # below; here the two fast methods keep the test short.
    out = tmp_path / "ident.json"
    args = ["identify", str(good_csv), "--json", str(out), "--eps", "0.01"]
    code = main([*args, "--methods", "equation_error", "npfsi"])
    assert code == 0, capsys.readouterr().err
    data = json.loads(out.read_text())
    assert data["equation_error"]["success"] and data["output_error"] is None
    c = data["identified_constants"]
    for k, v in zip(("C1", "C2", "C3"), TWIN_TRUTH.as_array(), strict=False):
        assert c[k] == pytest.approx(v, rel=0.01)
    assert [r["eps"] for r in data["npfsi"]] == [0.01]
    assert "C4" in data["equation_error"]["parameters"]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    printed = capsys.readouterr().out
    assert "[[Variables]]" in printed and "wrote" in printed


def test_report_pdf(tmp_path, good_log, model):
    from maglev_oc.reporting.identification_plots import write_outcome_report

    outcome = identify(good_log, model, methods=("equation_error", "npfsi"), npfsi_eps=(0.01,))
    report = write_outcome_report(tmp_path / "ident.pdf", outcome, [good_log])
    assert report.path.read_bytes()[:5] == b"%PDF-"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    # the table prints the fit's values to 6 digits and its standard errors to 3
    table = report.section("Least-squares estimates")
    fit = outcome.equation_error
    assert table.column("parameter") == fit.names
    for k in fit.names:
        row = table.row(k)
        assert float(row[2]) == pytest.approx(fit.values[k], rel=1e-5)
        assert float(row[3]) == pytest.approx(fit.stderr[k], rel=1e-2)
    assert table.column("output error") == ("—",) * len(fit.names)  # not run
    npfsi = report.section("NPFSI (000")
    assert npfsi.column("eps") == ("0.01",)
    assert "Fit report: equation_error" in report.headings


def test_methods_are_validated(good_log, model):
    with pytest.raises(ValueError, match="methods"):
        identify(good_log, model, methods=("least_squares",))
    outcome = identify(good_log, model, methods=("equation_error",))
    assert outcome.output_error is None and outcome.npfsi == ()
    assert outcome.best is outcome.equation_error


@pytest.mark.slow
def test_cli_all_methods(tmp_path, good_csv, capsys):
    out, pdf = tmp_path / "all.json", tmp_path / "all.pdf"
    assert main(["identify", str(good_csv), "--json", str(out), "--report", str(pdf)]) == 0, (
        capsys.readouterr().err
    )
    assert pdf.read_bytes()[:5] == b"%PDF-"
    data = json.loads(out.read_text())
    assert data["output_error"]["success"]
    assert [r["eps"] for r in data["npfsi"]] == [0.001, 0.01, 0.05]
    assert data["identified_constants"]["source"].startswith("identified (equation_error)")


def test_npfsi_estimates_the_constants_asked_for(good_log, model):
    # identify's estimate reaches NPFSI: asked for C1 and C2, each run estimates those two (the
    # others held at the model's values), as the least-squares fits do
    outcome = identify(
        good_log, model, estimate=("C1", "C2"), methods=("equation_error", "npfsi"), npfsi_eps=(0.01,)
    )
    assert outcome.equation_error.names[:2] == ("C1", "C2") and "C3" not in outcome.equation_error.names
    assert [run.names for run in outcome.npfsi] == [("C1", "C2")]
