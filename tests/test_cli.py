"""The maglev-oc command: tables, reports, and clear errors."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

from maglev_oc.cli import main


def test_model_table(capsys):
    assert main(["model", "--gaps", "10", "15", "20", "25"]) == 0
    out = capsys.readouterr().out
    rows = [line.split() for line in out.splitlines() if line.strip()[:1].isdigit()]
    currents = [float(r[1]) for r in rows[:4]]
    assert [round(c, 1) for c in currents] == [5.3, 3.3, 1.5, -0.2]  # SPEC 1


def test_model_with_bad_params_file(tmp_path, capsys):
    bad = tmp_path / "stage.json"
    bad.write_text(json.dumps({"stage": {"mass_vertical": -4.35}}))
    assert main(["model", "--params", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "mass_vertical" in err and "Traceback" not in err
    assert main(["model", "--params", str(tmp_path / "missing.json")]) == 2


def test_report_writes_model_pdf(tmp_path, capsys):
    assert main(["report", "--out", str(tmp_path), "--only", "model"]) == 0
    pdf = tmp_path / "model.pdf"
    assert pdf.read_bytes()[:5] == b"%PDF-"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp files left
    assert main(["report", "--out", str(tmp_path), "--only", "nosuch"]) == 2


def test_every_subpackage_is_packaged():
    # pyproject lists packages explicitly (analyses/ is mapped into maglev_oc.analyses); a
    # subpackage missing from the list would be absent from a wheel install.
    root = Path(__file__).resolve().parents[1]
    listed = set(tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {
        ".".join(p.parent.relative_to(root).parts)
        for p in (root / "maglev_oc").rglob("__init__.py")
        if "__pycache__" not in p.parts
    }
    found.add("maglev_oc.analyses")
    assert found == listed


def test_simulate_shorter_than_the_tracking_window_is_scored_from_its_start(tmp_path, capsys):
    # the sinusoid is scored from t = 4 s (its start-up transient); a 2 s run used to crash on an
    # empty window: now it is scored from its start, and evaluate() gives NaN on an empty window
    import dataclasses
    import math

    from maglev_oc.control.registry import build_controller
    from maglev_oc.model.stage import StageModel
    from maglev_oc.sim.engine import ClosedLoop
    from maglev_oc.sim.metrics import evaluate
    from maglev_oc.sim.scenarios import paper_scenarios
    from maglev_oc.sim.twin import RigTwin

    out = str(tmp_path / "s.csv")
    assert main(["simulate", "--scenario", "sinusoid", "--duration", "2", "--out", out]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if "mean |error|" in x)
    assert "nan" not in line
    model = StageModel()
    sc = dataclasses.replace(paper_scenarios()["sinusoid"], duration=1.0)
    assert sc.evaluate_from > sc.duration
    m = evaluate(ClosedLoop(RigTwin(model), build_controller("fl", model)).run(sc), sc)
    assert math.isnan(m.mean_error.vertical) and math.isnan(m.peak_error.horizontal)
    assert m.peak_current > 0  # the figures that do not need the window are still there


def test_simulate_writes_a_readable_log(tmp_path, capsys):
    from maglev_oc.data.logs import read_log

    out = tmp_path / "run.csv"
    code = main(
        [
            "simulate",
            "--controller",
            "fl",
            "--scenario",
            "small_step",
            "--twin",
            "ideal",
            "--duration",
            "1.0",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    log = read_log(out)
    assert log.n == 1000  # 1 s at the default 1 kHz logging rate
    assert abs(log.x[0, 0] - 0.026) < 1e-12  # starts at the scenario's 26 mm
    assert "twin_effects" not in log.metadata  # a log does not say what is in it


def test_a_bug_is_not_reported_as_the_users_mistake(monkeypatch, capsys):
    # Only MaglevError (bad input, solver failures named as such) and OSError mean exit 2; any
    # other exception is a bug of maglev_oc: exit 1, one line saying so, no traceback.
    import maglev_oc.cli as cli
    from maglev_oc.errors import LogError

    def broken(_args):
        raise ValueError("an internal invariant failed")

    def bad_input(_args):
        raise LogError("run.csv", "line 3, column x1: not a number")

    monkeypatch.setattr(cli, "cmd_model", broken)
    assert main(["model"]) == 1
    err = capsys.readouterr().err
    assert "internal error" in err and "an internal invariant failed" in err and "Traceback" not in err

    monkeypatch.setattr(cli, "cmd_model", bad_input)
    assert main(["model"]) == 2
    err = capsys.readouterr().err
    assert "run.csv" in err and "line 3" in err and "internal" not in err


def test_an_interrupt_inside_a_c_extension_is_an_interrupt(monkeypatch, capsys):
    # Ctrl-C while CasADi converts to NumPy surfaces as "SystemError: ... returned a result with
    # an exception set", the KeyboardInterrupt as its cause: exit 130, not "internal error"
    import maglev_oc.cli as cli

    def interrupted(_args):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as stop:
            raise SystemError("<function DM.__array__> returned a result with an exception set") from stop

    monkeypatch.setattr(cli, "cmd_model", interrupted)
    assert main(["model"]) == cli.EXIT_INTERRUPTED
    err = capsys.readouterr().err
    assert "interrupted" in err and "internal error" not in err

    def broken(_args):
        raise SystemError("a real bug")

    monkeypatch.setattr(cli, "cmd_model", broken)
    assert main(["model"]) == cli.EXIT_INTERNAL
