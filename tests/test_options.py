"""Every public option does what it says (issue 21): for each option, a test that fails when the
option's effect is ignored (the default used instead) or inverted (a flag's meaning flipped, a
sign flipped, millimetres read as metres).

:data:`OPTION_TESTS` maps every option of ``maglev-oc`` ("subcommand --option"; "--debug" for the
option before the subcommand) to the test that checks its effect, here or in another test file;
:data:`LIBRARY_OPTION_TESTS` does the same for the main keyword options of the library functions
the commands call (the options that change what is computed; solver and numerical settings such
as tolerances, thread counts or segment lengths are left out). The meta-tests at the end walk
the argparse parser and the signatures, so a new option without a test, or a test renamed away,
fails here.

Most tests compare a run with the option to the run without it and assert the difference the
option must make, with a physical reason for the size: an equilibrium current from the closed
form, a stopper distance, the encoder's grid, the exact linearization of the FL regulator.
Commands run in-process (``main([...])``) on short runs; the whole file takes about 30 s.

Bugs found while writing these (an option silently dropped, bad values ending in an internal error)
are fixed; their tests close each section.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import importlib
import inspect
import json
import math
import os
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from numpy.testing import assert_allclose

import maglev_oc.cli as cli
from maglev_oc.cli import build_parser, main
from maglev_oc.data.logs import Log, read_log, write_log
from maglev_oc.model.hardware import ENCODER_RESOLUTION, STOPPER_GAP, STOPPER_POSITION
from maglev_oc.model.parameters import DEFAULT_CONSTANTS, PAPER_CONSTANTS, StageParameters, save_json
from maglev_oc.model.stage import StageModel
from maglev_oc.units import MM_TO_M

ROOT = Path(__file__).resolve().parents[1]
HERE = "tests/test_options.py"

DESIGN_PICKS = "test_design_experiment_kind_duration_and_seed_pick_the_reference"
EXPORT_NAMES = "test_cli_export_params_and_prefix_are_the_controller_and_its_names"
OPTION_TESTS: dict[str, str] = {
    "--debug": f"{HERE}::test_debug_shows_the_traceback_of_a_bug_only",
    "--version": f"{HERE}::test_version_names_the_package_and_casadi",
    # report
    "report --out": "tests/test_cli.py::test_report_writes_model_pdf",
    "report --only": f"{HERE}::test_report_only_runs_the_named_analyses",
    "report --params": f"{HERE}::test_report_params_is_the_model_the_analyses_get",
    "report --jobs": f"{HERE}::test_report_jobs_runs_analyses_at_once_and_a_failure_stops_none",
    # model
    "model --params": f"{HERE}::test_model_params_gives_the_files_equilibria",
    "model --constants": f"{HERE}::test_model_constants_names_a_paper_set",
    "model --gaps": "tests/test_cli.py::test_model_table",
    # simulate
    "simulate --controller": f"{HERE}::test_simulate_controller_runs_the_named_regulator",
    "simulate --scenario": "tests/test_cli.py::test_simulate_writes_a_readable_log",
    "simulate --twin": f"{HERE}::test_simulate_rig_twin_reads_through_the_encoder",
    "simulate --twin-constants": f"{HERE}::test_simulate_twin_constants_is_the_plant",
    "simulate --twin-params": f"{HERE}::test_simulate_twin_params_is_the_plant",
    "simulate --params": f"{HERE}::test_simulate_params_is_the_controllers_model",
    "simulate --duration": "tests/test_cli.py::test_simulate_writes_a_readable_log",
    "simulate --rate": f"{HERE}::test_simulate_rate_decimates_the_log",
    "simulate --seed": f"{HERE}::test_simulate_seed_sets_the_noise",
    "simulate --describe-twin": f"{HERE}::test_simulate_describe_twin_names_the_effects",
    "simulate --out": "tests/test_cli.py::test_simulate_writes_a_readable_log",
    "simulate --stage": f"{HERE}::test_simulate_stage_microstepper_writes_three_axes",
    "simulate --no-anti-windup": f"{HERE}::test_simulate_no_anti_windup_winds_up_into_the_stopper",
    # region
    "region --gaps": "tests/test_region_cli.py::test_region_writes_certificates",
    "region --position": f"{HERE}::test_region_position_moves_the_set_point",
    "region --sinusoid": f"{HERE}::test_region_sinusoid_adds_the_ellipse",
    "region --sdp": f"{HERE}::test_region_sdp_adds_a_larger_set",
    "region --current-limit": f"{HERE}::test_region_current_limit_shrinks_the_set",
    "region --no-current-limit": f"{HERE}::test_region_no_current_limit_drops_the_current_constraint",
    "region --no-stoppers": f"{HERE}::test_region_no_stoppers_drops_the_gap_stoppers",
    "region --samples": f"{HERE}::test_region_samples_runs_monte_carlo_inside",
    "region --json": "tests/test_region_cli.py::test_region_writes_certificates",
    "region --params": f"{HERE}::test_region_params_is_the_model",
    "region --without-effects": "tests/test_region_compensation.py::test_region_compensates_stage_effects",
    "region --stage": f"{HERE}::test_region_stage_microstepper_certifies_the_3dof_loop",
    "region --setpoint": f"{HERE}::test_region_setpoint_places_each_axis",
    "region --robust": "tests/test_region_sweep.py::test_region_robust_writes_its_table",
    "region --confidence": f"{HERE}::test_region_robust_confidence_scales_the_ellipsoid",
    "region --box": f"{HERE}::test_region_robust_box_is_the_plant_set",
    "region --seed": f"{HERE}::test_region_robust_seed_reaches_every_sweep",
    "region --workers": f"{HERE}::test_region_robust_workers_and_scheduler_choose_where_the_tasks_run",
    "region --scheduler": f"{HERE}::test_region_robust_workers_and_scheduler_choose_where_the_tasks_run",
    "region --certify-boxes": "tests/test_region_cli.py::test_region_robust_certify_boxes_is_the_budget",
    # diagnose
    "diagnose --json": "tests/test_diagnose.py::test_json_follows_the_spec_contract",
    "diagnose --report": f"{HERE}::test_diagnose_report_is_written_with_the_findings",
    "diagnose --params": f"{HERE}::test_diagnose_params_is_the_stage",
    "diagnose --holdout": f"{HERE}::test_diagnose_holdout_holds_out_that_share",
    "diagnose --no-control": f"{HERE}::test_diagnose_no_control_leaves_out_the_closed_loop_study",
    "diagnose --no-limits": f"{HERE}::test_diagnose_no_limits_leaves_out_what_the_log_could_not_have_shown",
    "diagnose --currents-late": "tests/test_diagnose_log_timing.py::"
    "test_the_command_line_moves_late_currents_back_and_then_nothing_is_left",
    # identify
    "identify --json": "tests/test_identify_pipeline.py::test_cli_writes_json",
    "identify --report": f"{HERE}::test_identify_report_is_written_with_the_fit",
    "identify --params": f"{HERE}::test_identify_params_gives_the_fixed_constants",
    "identify --estimate": f"{HERE}::test_identify_estimate_fits_only_those",
    "identify --methods": "tests/test_identify_pipeline.py::test_cli_writes_json",
    "identify --eps": "tests/test_identify_pipeline.py::test_cli_writes_json",
    "identify --input-delay": f"{HERE}::test_identify_input_delay_matches_a_late_amplifier",
    "identify --validate": f"{HERE}::test_identify_validate_checks_the_fit_on_held_out_logs",
    # design-experiment
    "design-experiment --kind": f"{HERE}::{DESIGN_PICKS}",
    "design-experiment --duration": f"{HERE}::{DESIGN_PICKS}",
    "design-experiment --seed": f"{HERE}::{DESIGN_PICKS}",
    "design-experiment --out": "tests/test_experiment_design.py::test_cli_writes_reference_mat_and_json",
    "design-experiment --params": f"{HERE}::test_design_experiment_params_is_the_model_designed_for",
    # export
    "export --out": "tests/test_export.py::test_cli_exports_and_refuses_unknown_controllers",
    "export --params": f"tests/test_export.py::{EXPORT_NAMES}",
    "export --prefix": f"tests/test_export.py::{EXPORT_NAMES}",
    "export --qp-iterations": f"{HERE}::test_export_qp_iterations_is_the_nmpc_solvers_budget",
    "export --qp-solver": "tests/test_export.py::test_cli_exports_the_nmpc_with_its_qp_solver_and_budget",
}
"""Every option of ``maglev-oc`` -> the test that fails when its effect is ignored or inverted."""

LIBRARY_OPTION_TESTS: dict[str, str] = {
    "maglev_oc.control.export.export_controller(qp_solver)": (
        "tests/test_export.py::test_exported_nmpc_gives_the_python_commands_on_constrained_samples"
    ),
    "maglev_oc.control.export.export_controller(qp_iterations)": (
        "tests/test_export.py::test_exported_nmpc_gives_the_python_commands_on_constrained_samples"
    ),
    "maglev_oc.identification.pipeline.identify(estimate)": f"{HERE}::test_identify_estimate_fits_only_those",
    "maglev_oc.identification.pipeline.identify(methods)": (
        "tests/test_identify_pipeline.py::test_methods_are_validated"
    ),
    "maglev_oc.identification.pipeline.identify(npfsi_eps)": (
        "tests/test_identify_pipeline.py::test_report_pdf"
    ),
    "maglev_oc.identification.pipeline.identify(input_delay)": (
        f"{HERE}::test_identify_input_delay_matches_a_late_amplifier"
    ),
    "maglev_oc.identification.pipeline.identify(terms)": f"{HERE}::test_identify_terms_are_fitted",
    "maglev_oc.diagnosis.pipeline.diagnose(holdout_fraction)": (
        f"{HERE}::test_diagnose_holdout_holds_out_that_share"
    ),
    "maglev_oc.diagnosis.pipeline.diagnose(limits)": (
        f"{HERE}::test_diagnose_no_limits_leaves_out_what_the_log_could_not_have_shown"
    ),
    "maglev_oc.diagnosis.pipeline.diagnose(exclude)": (
        "tests/test_diagnose.py::test_an_effect_outside_the_library_goes_to_unexplained"
    ),
    "maglev_oc.reporting.diagnosis_report.write_diagnosis_report(study)": (
        f"{HERE}::test_diagnose_no_control_leaves_out_the_closed_loop_study"
    ),
    "maglev_oc.region.feasibility.FeasibleSet(current_limit)": (
        f"{HERE}::test_region_current_limit_shrinks_the_set"
    ),
    "maglev_oc.region.feasibility.FeasibleSet(gap_range)": (
        f"{HERE}::test_region_no_stoppers_drops_the_gap_stoppers"
    ),
    "maglev_oc.region.feasibility.FeasibleSet(position_range)": (
        f"{HERE}::test_feasible_set_position_range_is_the_only_place_x3_enters"
    ),
    "maglev_oc.region.feasibility.FeasibleSet(compensation)": (
        "tests/test_region_compensation.py::test_constant_vertical_compensation_is_a_heavier_gravity"
    ),
    "maglev_oc.region.montecarlo.fl_batch_simulator(compensation)": (
        "tests/test_region_compensation.py::test_compensated_certificate_holds_on_the_twin_with_the_effect"
    ),
    "maglev_oc.region.sweep.SweepSpec(effects)": (
        "tests/test_region_sweep.py::test_sweeps_draw_effect_scales_in_their_ranges_beside_the_same_plants"
    ),
    "maglev_oc.region.sweep.SweepSpec(effect_ranges)": (
        "tests/test_region_sweep.py::test_effect_scales_are_the_twin_with_scaled_effects"
    ),
    "maglev_oc.region.robust_certificate.robust_lyapunov_matrix(direction)": (
        "tests/test_region_robust_certificate.py::test_robust_p_aimed_at_a_start_reaches_further_along_it"
    ),
    "maglev_oc.control.nmpc.NMPCSettings(effects)": (
        "tests/test_nmpc_effects.py::test_the_feedforward_current_makes_the_plant_with_the_effects_follow_the_reference"
    ),
    "maglev_oc.control.fl_regulator.FeedbackLinearizingRegulator(K_h)": (
        f"{HERE}::test_fl_gains_scale_the_outer_loop"
    ),
    "maglev_oc.control.fl_regulator.FeedbackLinearizingRegulator(K_v)": (
        f"{HERE}::test_fl_gains_scale_the_outer_loop"
    ),
    "maglev_oc.control.fl_regulator.FeedbackLinearizingRegulator(omega0)": (
        f"{HERE}::test_fl_omega0_is_the_frequency_tracked_without_error"
    ),
    "maglev_oc.control.fl_regulator.FeedbackLinearizingRegulator(compensation)": (
        "tests/test_control_options.py::test_disturbance_compensation_makes_the_plant_see_v"
    ),
    "maglev_oc.control.linear_regulator.paper_linear_regulator(feedforward)": (
        f"{HERE}::test_simulate_controller_runs_the_named_regulator"
    ),
    "maglev_oc.control.nmpc.NMPCSettings(preview)": (
        "tests/test_nmpc.py::test_reference_preview_extrapolates_past_the_end"
    ),
    "maglev_oc.sim.engine.ClosedLoop.run(seed)": f"{HERE}::test_simulate_seed_sets_the_noise",
    "maglev_oc.sim.recording.result_to_log(rate_hz)": f"{HERE}::test_simulate_rate_decimates_the_log",
    "maglev_oc.sim.recording.result_to_log(describe_twin)": (
        f"{HERE}::test_simulate_describe_twin_names_the_effects"
    ),
    "maglev_oc.model.loading.load_model(params_path)": (
        f"{HERE}::test_model_params_gives_the_files_equilibria"
    ),
    "maglev_oc.model.loading.load_model(constants)": f"{HERE}::test_model_constants_names_a_paper_set",
    "maglev_oc.model.summary.summarize_model(table_gaps)": "tests/test_cli.py::test_model_table",
    "maglev_oc.control.microstepper.MicrostepperRegulator(anti_windup)": (
        f"{HERE}::test_simulate_no_anti_windup_winds_up_into_the_stopper"
    ),
    "maglev_oc.control.microstepper.MicrostepperRegulator(levitation_first)": (
        "tests/test_microstepper_control.py::test_amplifier_scaling_of_the_currents_drops_the_platform"
    ),
    "maglev_oc.region.microstepper.MicrostepperRegion(current_limit)": (
        f"{HERE}::test_region_stage_microstepper_certifies_the_3dof_loop"
    ),
    "maglev_oc.region.microstepper.MicrostepperRegion(stoppers)": (
        "tests/test_microstepper_region.py::test_each_constraint_binds_in_some_case"
    ),
}
"""The main keyword options of the library behind the commands -> the test of their effect."""

WEAK_C3 = DEFAULT_CONSTANTS.replace(C3=0.8 * DEFAULT_CONSTANTS.C3, source="test: C3 20 % below Table III")
"""20 % less normal force per ampere of i_d: every equilibrium current is larger (1.50 -> 1.90 A at
20 mm), so a run on this model differs visibly from one on the papers' constants."""


# --- helpers --------------------------------------------------------------------------------------
def _ok(argv: list[str]) -> None:
    code = main(argv)
    assert code == 0, f"exit {code} for {argv}"


def _read(path: Path) -> Log:
    return read_log(path, min_samples=10, min_duration=0.01)  # short runs are fine here


def _simulate(folder: Path, *options: str, duration: float = 0.3, scenario: str = "small_step") -> Log:
    out = folder / f"run{len(list(folder.iterdir()))}.csv"
    _ok(["simulate", "--scenario", scenario, "--duration", str(duration), *options, "--out", str(out)])
    return _read(out)


def _equilibrium_current(model: StageModel, gap: float) -> float:
    """The physical root of 0 = G - L4 u2^2 - L3 u2 - L2 (x2' = 0 at rest with u1 = 0, SPEC 1)."""
    _, L2, L3, L4 = model.coefficients(gap)[:, 0]
    return float((-L3 - math.sqrt(L3**2 - 4 * L4 * (L2 - model.params.gravity))) / (2 * L4))


def _pdf_pages(path: Path) -> int:
    """Pages in a PDF written by matplotlib (its page objects are not compressed)."""
    return len(re.findall(rb"/Type\s*/Page[^s]", path.read_bytes()))


@pytest.fixture(scope="module")
def stage_file(tmp_path_factory) -> Path:
    """The papers' stage with :data:`WEAK_C3`."""
    return save_json(tmp_path_factory.mktemp("stage") / "weak_c3.json", StageParameters(), WEAK_C3)


@pytest.fixture(scope="module")
def light_stage_file(tmp_path_factory) -> Path:
    """The papers' stage and constants with g = 9.0 m/s^2 instead of 9.81 (a lever on the stage
    section of the file: the constants stay the papers')."""
    params = dataclasses.replace(StageParameters(), gravity=9.0)
    return save_json(tmp_path_factory.mktemp("stage") / "light.json", params, DEFAULT_CONSTANTS)


# --- the option before the subcommand ---------------------------------------------------------------
def test_debug_shows_the_traceback_of_a_bug_only(monkeypatch, capsys):
    def broken(_args):
        raise ValueError("an internal invariant failed")

    monkeypatch.setattr(cli, "cmd_model", broken)
    with pytest.raises(ValueError, match="internal invariant"):  # the traceback reaches the user
        main(["--debug", "model"])
    assert main(["model"]) == cli.EXIT_INTERNAL
    assert "Traceback" not in capsys.readouterr().err
    # --debug is about bugs: the user's mistakes still get their one line and exit 2
    monkeypatch.undo()
    assert main(["--debug", "model", "--gaps", "0"]) == cli.EXIT_USAGE
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_version_names_the_package_and_casadi(capsys):
    import tomllib

    import casadi

    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    out = capsys.readouterr().out
    project = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())["project"]
    assert out.startswith(f"maglev-oc {project['version']} ") and f"CasADi {casadi.__version__}" in out


# --- report -----------------------------------------------------------------------------------------
@pytest.fixture()
def fake_analyses(monkeypatch) -> list:
    """Two stand-in analyses recording what ``build`` was handed (the real ones take minutes; what
    --only and --params change is which analyses run and on which model)."""
    calls = []

    def analysis(name: str) -> SimpleNamespace:
        def build(out: Path, model: StageModel) -> None:
            calls.append((name, out, model.constants))
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text(f"{name}: C3 = {model.constants.C3!r}\n")

        return SimpleNamespace(REPORT=f"{name}.pdf", build=build)

    from maglev_oc.reporting import runner

    fakes = {n: analysis(n) for n in ("first", "second")}
    monkeypatch.setattr(runner, "analysis_modules", lambda package=runner.ANALYSES: fakes)
    return calls


def test_report_only_runs_the_named_analyses(tmp_path, fake_analyses):
    _ok(["report", "--out", str(tmp_path / "some"), "--only", "second", "--jobs", "1"])
    assert [name for name, _, _ in fake_analyses] == ["second"]
    assert sorted(p.name for p in (tmp_path / "some").iterdir()) == ["second.pdf"]
    fake_analyses.clear()
    _ok(["report", "--out", str(tmp_path / "all"), "--jobs", "1"])
    assert [name for name, _, _ in fake_analyses] == ["first", "second"]


def test_report_params_is_the_model_the_analyses_get(tmp_path, fake_analyses, stage_file):
    _ok(["report", "--out", str(tmp_path), "--only", "first", "--params", str(stage_file), "--jobs", "1"])
    _ok(["report", "--out", str(tmp_path / "papers"), "--only", "first", "--jobs", "1"])
    (_, out, with_file), (_, _, default) = fake_analyses
    assert with_file.C3 == WEAK_C3.C3 and default.C3 == DEFAULT_CONSTANTS.C3
    assert out == tmp_path / "first.pdf" and repr(WEAK_C3.C3) in out.read_text()


def test_report_params_reaches_the_region_robust_page_as_a_covariance(tmp_path, monkeypatch):
    # The operating-region report's robust page draws plants from the stage file's covariance:
    # `report --params` must hand the file (not only the model read from it) to that analysis.
    # The study itself is stubbed here (minutes); what reaches it is the point.
    import importlib

    from maglev_oc.model.stagefile import Provenance, StageFile
    from maglev_oc.reporting import runner

    region = importlib.import_module("maglev_oc.analyses.operating_region")
    seen = {}

    def study(model, config, *, covariance=None, covariance_source=""):
        seen.update(covariance=covariance, source=covariance_source, C2=model.constants.C2)
        raise RuntimeError("stop here")

    monkeypatch.setattr(region, "operating_region_study", study)
    model = StageModel()
    cov = np.diag([1e-4, 0.25, 4e-4, 1e-8])
    provenance = {k: Provenance.now((), "test") for k in ("geometry", "constants", "effects")}
    path = tmp_path / "stage.json"
    StageFile(StageParameters(), model.constants.replace(C2=780.0), cov, {}, (), provenance).write(path)
    (run,) = runner.run_reports(["operating_region"], tmp_path / "out", params=path, jobs=1)
    assert "stop here" in run.error  # the stubbed study ran, with
    assert_allclose(seen["covariance"], cov, rtol=0)  # the file's covariance, not the assumed one
    assert seen["source"] == "the stage file stage.json" and seen["C2"] == 780.0
    seen.clear()
    runner.run_reports(["operating_region"], tmp_path / "papers", jobs=1)
    assert seen["covariance"] is None and seen["source"] == ""  # no file: the page assumes one


def test_report_jobs_runs_analyses_at_once_and_a_failure_stops_none(tmp_path, stage_file, monkeypatch):
    from maglev_oc.numerics import BLAS_THREAD_VARIABLES
    from maglev_oc.reporting.runner import run_reports

    for k in BLAS_THREAD_VARIABLES:  # as on a user's shell: the runner then sets cores / workers
        monkeypatch.delenv(k, raising=False)

    names = ["slow", "slower", "broken"]
    kwargs = dict(params=stage_file, package="tests.fake_analyses")
    runs = run_reports(names, tmp_path / "two", jobs=2, **kwargs)
    assert [r.name for r in runs] == names and [r.success for r in runs] == [True, True, False]
    assert "failed on purpose" in runs[2].error and not (tmp_path / "two" / "broken.pdf").exists()
    texts = [dict(line.split(" = ") for line in r.path.read_text().splitlines()) for r in runs[:2]]
    assert all(t["C3"] == repr(WEAK_C3.C3) for t in texts)  # --params reaches every worker
    # two processes whose runs overlap in time: each analysis waited until the other had started
    assert texts[0]["pid"] != texts[1]["pid"]
    start, end = [float(t["started"]) for t in texts], [float(t["ended"]) for t in texts]
    assert max(start) < min(end)
    # each worker got its share of the cores as BLAS threads; this process's environment is as it was
    assert [t["blas"] for t in texts] == [str(max(1, len(os.sched_getaffinity(0)) // 2))] * 2
    assert not any(k in os.environ for k in BLAS_THREAD_VARIABLES)
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "3")  # a count the user set is kept
    runs = run_reports(names[:2], tmp_path / "user", jobs=2, **kwargs)
    assert [r.path.read_text().splitlines()[-1] for r in runs] == ["blas = 3"] * 2
    # one job: one after the other, in this process
    runs = run_reports(names[:2], tmp_path / "one", jobs=1, **kwargs)
    texts = [dict(line.split(" = ") for line in r.path.read_text().splitlines()) for r in runs]
    assert float(texts[1]["started"]) >= float(texts[0]["ended"])


def test_report_jobs_must_be_positive(capsys):
    assert main(["report", "--only", "model", "--jobs", "0"]) == cli.EXIT_USAGE
    assert "--jobs must be at least 1" in capsys.readouterr().err


# --- model ------------------------------------------------------------------------------------------
def _model_table(capsys) -> tuple[str, dict[float, float]]:
    """(the constants line, {gap [mm]: i_d [A]}) of ``maglev-oc model``'s output."""
    lines = capsys.readouterr().out.splitlines()
    rows = [line.split() for line in lines if line.strip()[:1].isdigit()]
    return lines[0], {float(r[0]): float(r[1]) for r in rows}


def test_model_params_gives_the_files_equilibria(capsys, stage_file):
    _ok(["model", "--params", str(stage_file), "--gaps", "15", "20", "25"])
    constants, table = _model_table(capsys)
    _ok(["model", "--gaps", "15", "20", "25"])
    _, papers = _model_table(capsys)
    assert f"C3={WEAK_C3.C3:g}" in constants
    weak = StageModel(StageParameters(), WEAK_C3)
    for gap, current in table.items():
        # the closed-form root with the file's constants, to the printed 3 decimals
        assert current == pytest.approx(_equilibrium_current(weak, gap * MM_TO_M), abs=5e-4)
        # and not the papers': 20 % less force per ampere moves i_d by 0.94, 0.40 and -0.054 A at
        # 15, 20 and 25 mm (near the zero-current gap, 24.3 mm, i_d is small and so is the change)
        assert abs(current - papers[gap]) > 0.04


def test_model_constants_names_a_paper_set(capsys, stage_file):
    eps05 = PAPER_CONSTANTS["table3_eps0.05"]
    _ok(["model", "--constants", "table3_eps0.05", "--gaps", "20"])
    constants, table = _model_table(capsys)
    assert f"C1={eps05.C1:g}" in constants and "eps = 0.05" in constants
    # 1.412 A at 20 mm (closed form with Table III at eps = 0.05) against 1.497 A with the default set
    expected = _equilibrium_current(StageModel(StageParameters(), eps05), 20 * MM_TO_M)
    assert table[20.0] == pytest.approx(expected, abs=5e-4)
    assert abs(expected - _equilibrium_current(StageModel(), 20 * MM_TO_M)) > 0.05
    # the named set replaces the constants of a --params file
    _ok(["model", "--params", str(stage_file), "--constants", "table3_eps0.05", "--gaps", "20"])
    assert _model_table(capsys) == (constants, table)


# --- simulate ---------------------------------------------------------------------------------------
def test_simulate_controller_runs_the_named_regulator(tmp_path, monkeypatch):
    import maglev_oc.control.registry as registry

    monkeypatch.setattr(registry, "c_compiler", lambda: None)  # NMPC without its 10-25 s C build
    logs = {
        name: _simulate(
            tmp_path, "--controller", name, "--twin", "ideal", duration=0.02, scenario="setpoint_steps"
        )
        for name in registry.CONTROLLERS
    }
    # each run names the controller that produced it, and their first commands all differ
    assert len({log.metadata["controller"] for log in logs.values()}) == len(registry.CONTROLLERS)
    first = np.array([log.u[:, 0] for log in logs.values()])
    gaps = np.abs(first[:, None, :] - first[None, :, :]).max(axis=2)
    assert np.all(gaps + np.eye(len(first)) > 0.01), gaps  # 10x the 1 mA current resolution; min 0.7 A
    # linear against linear-noff: the same gains and states at t = 0, so the first commands differ by
    # the feedforward alone, the equilibrium current of the first set-point (17.5 mm, 001 Sec. VI-A)
    with_ff, without = logs["linear"].u[:, 0], logs["linear-noff"].u[:, 0]
    assert with_ff[0] == without[0]  # i_q has no feedforward
    feedforward = _equilibrium_current(StageModel(), 17.5 * MM_TO_M)
    assert with_ff[1] - without[1] == pytest.approx(feedforward, rel=1e-9)


def test_simulate_rig_twin_reads_through_the_encoder(tmp_path):
    rig = _simulate(tmp_path, "--twin", "rig")
    ideal = _simulate(tmp_path, "--twin", "ideal")
    counts = {"rig": rig.x[[0, 2]] / ENCODER_RESOLUTION, "ideal": ideal.x[[0, 2]] / ENCODER_RESOLUTION}
    off_grid = {k: np.abs(c - np.round(c)) > 1e-6 for k, c in counts.items()}  # CSV keeps 17 digits
    assert not off_grid["rig"].any()  # every reading is a whole count of the 10 um encoder (000 Sec. II)
    assert off_grid["ideal"][0].mean() > 0.9  # the exact gap: almost never a whole count


def test_simulate_seed_sets_the_noise(tmp_path):
    one, again, two = (_simulate(tmp_path, "--seed", s) for s in ("1", "1", "2"))  # rig twin: noisy
    assert np.array_equal(one.x, again.x, equal_nan=True) and np.array_equal(one.u, again.u)
    assert not np.array_equal(one.x, two.x, equal_nan=True)
    # another noise draw, not another run: the readings differ by the odd count where the 2 um noise
    # crosses a quantization edge, never by more than 3 counts (measured: 1)
    assert np.nanmax(np.abs(one.x - two.x)) <= 3 * ENCODER_RESOLUTION + 1e-12


def test_simulate_rate_decimates_the_log(tmp_path):
    full = _simulate(tmp_path, "--twin", "ideal", duration=0.4)
    half = _simulate(tmp_path, "--twin", "ideal", "--rate", "500", duration=0.4)
    assert full.n == 400 and half.n == 200  # 0.4 s at 1 kHz (default) and at 500 Hz
    assert half.sample_time == pytest.approx(2e-3, rel=1e-12)
    # the ideal twin is deterministic: the 500 Hz log is every other sample of the 1 kHz one
    assert np.array_equal(half.x, full.x[:, ::2], equal_nan=True) and np.array_equal(half.u, full.u[:, ::2])


def test_simulate_describe_twin_names_the_effects(tmp_path):
    from maglev_oc.sim.effects import TwinEffects

    described = _simulate(tmp_path, "--describe-twin", duration=0.05)
    plain = _simulate(tmp_path, duration=0.05)
    assert described.metadata["twin_effects"].split() == TwinEffects.rig().enabled()
    assert "twin_effects" not in plain.metadata
    ideal = _simulate(tmp_path, "--twin", "ideal", "--describe-twin", duration=0.05)
    assert ideal.metadata["twin_effects"].split() == (TwinEffects.ideal().enabled() or ["none"])


@pytest.fixture(scope="module")
def settled(tmp_path_factory):
    """2 s of the small step (26 -> 24 mm) on the ideal twin with the FL regulator, by options;
    each run once. At 2 s the internal model has settled: the current left to settle is 3e-5 A
    (measured with the plant's C3 20 % off the controller's)."""
    folder = tmp_path_factory.mktemp("settled")
    runs: dict[tuple[str, ...], Log] = {}

    def run(*options: str) -> Log:
        if options not in runs:
            runs[options] = _simulate(folder, "--twin", "ideal", *options, duration=2.0)
        return runs[options]

    return run


SETTLED_CURRENT = 2e-3
"""[A] How close the final i_d is to the plant's equilibrium current after 2 s: 70x the 3e-5 A
measured, and 14x below the smallest shift the options below make at 24 mm (0.029 A)."""


def test_simulate_params_is_the_controllers_model(settled, stage_file):
    papers, weak = settled(), settled("--params", str(stage_file))
    # the controller uses the file's model: its first command differs (the feedback transformation
    # with 20 % less force per ampere asks for -1.91 A of i_d instead of -1.55 A) ...
    assert abs(weak.u[1, 0] - papers.u[1, 0]) > 0.1
    # ... and with no twin option the plant is that model too: the FL regulator then linearizes it
    # exactly, so the positions are those of the papers' run (002 Sec. 4: the closed loop is the
    # same linear error system for any constants): measured 1.3e-9 m apart; bound a tenth of a count
    assert_allclose(weak.x[[0, 2]], papers.x[[0, 2]], rtol=0, atol=0.1 * ENCODER_RESOLUTION)
    # while the plant holds 24 mm with its own, larger equilibrium current
    expected = _equilibrium_current(StageModel(StageParameters(), WEAK_C3), 24 * MM_TO_M)
    assert weak.u[1, -1] == pytest.approx(expected, abs=SETTLED_CURRENT)
    assert abs(papers.u[1, -1] - expected) > 10 * SETTLED_CURRENT  # 0.144 A against 0.115 A


def test_simulate_twin_params_is_the_plant(settled, stage_file):
    papers, plant = settled(), settled("--twin-params", str(stage_file))
    assert np.array_equal(plant.u[:, 0], papers.u[:, 0])  # the controller is unchanged
    assert np.max(np.abs(plant.x[0] - papers.x[0])) > 0.1e-3  # the mismatch shows: 0.56 mm
    expected = _equilibrium_current(StageModel(StageParameters(), WEAK_C3), 24 * MM_TO_M)
    assert plant.u[1, -1] == pytest.approx(expected, abs=SETTLED_CURRENT)
    assert abs(papers.u[1, -1] - expected) > 10 * SETTLED_CURRENT


def test_simulate_twin_constants_is_the_plant(settled):
    papers, plant = settled(), settled("--twin-constants", "table2_eps0.05")
    assert np.array_equal(plant.u[:, 0], papers.u[:, 0])  # the controller is unchanged
    table2 = StageModel(StageParameters(), PAPER_CONSTANTS["table2_eps0.05"])
    expected = _equilibrium_current(table2, 24 * MM_TO_M)  # 0.082 A against the papers' 0.115 A
    assert plant.u[1, -1] == pytest.approx(expected, abs=SETTLED_CURRENT)
    assert abs(papers.u[1, -1] - expected) > 10 * SETTLED_CURRENT


def test_simulate_twin_constants_keep_the_params_stage(settled, light_stage_file):
    # --twin-constants says "named constant set for the plant (default: the controller's)": only the
    # constants should change; the stage (here g = 9.0) is still the --params file's
    run = settled("--params", str(light_stage_file), "--twin-constants", "table2_eps0.05")
    light = dataclasses.replace(StageParameters(), gravity=9.0)
    expected = _equilibrium_current(StageModel(light, PAPER_CONSTANTS["table2_eps0.05"]), 24 * MM_TO_M)
    assert run.u[1, -1] == pytest.approx(expected, abs=SETTLED_CURRENT)


@pytest.mark.parametrize("duration", ["0", "-1"])
def test_simulate_refuses_a_duration_that_is_not_positive(tmp_path, capsys, duration):
    argv = ["simulate", "--twin", "ideal", "--scenario", "small_step", "--duration", duration]
    assert main([*argv, "--out", str(tmp_path / "run.csv")]) == cli.EXIT_USAGE
    assert "--duration" in capsys.readouterr().err


def test_simulate_refuses_a_zero_rate(tmp_path, capsys):
    argv = ["simulate", "--twin", "ideal", "--duration", "0.01", "--rate", "0"]
    assert main([*argv, "--out", str(tmp_path / "run.csv")]) == cli.EXIT_USAGE
    assert "internal error" not in capsys.readouterr().err


# --- the microstepper (--stage microstepper) ----------------------------------------------------------
def _microstepper_csv(path: Path) -> tuple[dict[str, str], list[str], np.ndarray]:
    """(the ``# key: value`` lines, the column names, the rows) of ``simulate --stage microstepper``'s CSV."""
    lines = path.read_text().splitlines()
    meta = dict(line[2:].split(": ", 1) for line in lines if line.startswith("# "))
    body = [line for line in lines if not line.startswith("#")]
    return meta, body[0].split(","), np.loadtxt(body[1:], delimiter=",", ndmin=2)


def test_simulate_stage_microstepper_writes_three_axes(tmp_path):
    from maglev_oc.errors import LogError

    out = tmp_path / "ms.csv"
    argv = ["simulate", "--stage", "microstepper", "--scenario", "setpoints", "--twin", "ideal"]
    _ok([*argv, "--duration", "0.05", "--out", str(out)])
    meta, columns, rows = _microstepper_csv(out)
    assert columns == ["t", "x", "y", "gap", "i_qA", "i_dA", "i_qB", "i_dB"]
    assert "not a SPEC 2 log" in meta["format"] and meta["controller"] == "microstepper FL regulator"
    assert rows.shape == (50, 8)  # 0.05 s at the default 1 kHz
    _, x, y, gap, i_qa, i_da, i_qb, i_db = rows.T
    # the scenario starts at rest at (0, 0, 25) mm; the ideal twin reads the positions exactly
    assert (x[0], y[0], gap[0]) == (0.0, 0.0, 25 * MM_TO_M)
    # the first set-point (-40, -40, 21) mm: both pairs push towards -x and -y (i_q = -m v / (2 K1 l1)
    # with v < 0), levitation first holds each pair at the 9 A limit, and the gap closes towards 21 mm
    assert np.all(i_qa[:10] > 0) and np.all(i_qb[:10] > 0)
    assert_allclose([np.hypot(i_qa[:10], i_da[:10]), np.hypot(i_qb[:10], i_db[:10])], 9.0, rtol=1e-6)
    assert x[-1] < -0.1 * MM_TO_M and y[-1] < -0.1 * MM_TO_M and gap[-1] < gap[0]
    # three axes do not fit a SPEC 2 log, and the file does not pass for one
    with pytest.raises(LogError):
        read_log(out)
    # the default stage is the 2-DOF one, and the microstepper's scenarios are not its own
    assert main(["simulate", "--scenario", "setpoints", "--out", str(tmp_path / "two.csv")]) == cli.EXIT_USAGE


def test_simulate_no_anti_windup_winds_up_into_the_stopper(tmp_path, capsys):
    # The 90 mm step on x and y (-45 -> 45 mm) saturates both pairs. Without back-calculation the
    # internal models wind up and x overshoots into its stopper at 60 mm after 0.10 s (measured;
    # test_microstepper_control.py holds the full runs); with it, x peaks at 57.8 mm, later.
    argv = ["simulate", "--stage", "microstepper", "--scenario", "saturation", "--duration", "0.3"]
    _ok([*argv, "--out", str(tmp_path / "aw.csv")])
    assert "FAILED" not in capsys.readouterr().out
    assert main([*argv, "--no-anti-windup", "--out", str(tmp_path / "plain.csv")]) == 1  # a failed run
    assert "hit a mechanical stopper" in capsys.readouterr().out
    (aw_meta, _, aw), (plain_meta, _, plain) = (
        _microstepper_csv(tmp_path / f) for f in ("aw.csv", "plain.csv")
    )
    assert aw_meta["controller"] == "microstepper FL regulator"
    assert plain_meta["controller"] == "microstepper FL regulator (no anti-windup)"
    # readings are 10 um counts with 2 um noise: the stopper at 60 mm reads 60 mm within a count
    assert plain[:, 1].max() >= STOPPER_POSITION[1] - ENCODER_RESOLUTION
    assert aw[:, 1].max() < STOPPER_POSITION[1] - 1e-3


def _region_json(folder: Path, *options: str) -> dict:
    out = folder / f"ms{len(list(folder.iterdir()))}.json"
    _ok(["region", "--stage", "microstepper", *options, "--json", str(out)])
    return json.loads(out.read_text())


def test_region_stage_microstepper_certifies_the_3dof_loop(tmp_path, capsys):
    from maglev_oc.region.microstepper import MicrostepperRegion

    doc = _region_json(tmp_path, "--setpoint", "0", "0", "32")
    assert "3-DOF microstepper" in capsys.readouterr().out
    # 3 mm under the 35 mm gap stopper the stopper binds (below 31 mm the 9 A limit does;
    # test_microstepper_region.py), the gap's half-width is that room, and the level is the library's
    assert doc["certified"] and doc["binding"] == "gap"
    assert doc["half_widths_mm"]["gap"] == pytest.approx(3.0, rel=1e-9)
    expected = MicrostepperRegion().largest_level((0.0, 0.0, 0.032))
    assert doc["level"] == pytest.approx(expected.level, rel=1e-12)
    # the limits the 2-DOF region takes reach the 3-DOF one: without the current limit the centre's
    # set is bounded by the gap stoppers alone (10 mm to 35 mm; with the 9 A limit pair B binds at a
    # 6.1 mm half-width, test_microstepper_region.py)
    free = _region_json(tmp_path, "--setpoint", "0", "0", "25", "--no-current-limit")
    assert free["binding"] == "gap" and free["half_widths_mm"]["gap"] == pytest.approx(10.0, rel=1e-9)
    assert "pair currents" not in free["constraints"]


def test_region_setpoint_places_each_axis(tmp_path):
    # Each coordinate of --setpoint X Y GAP [mm] moves its own axis towards its stopper: 5 mm from
    # the x (or y) stopper at 60 mm that axis's travel binds with a 5 mm half-width (the 9 A limit
    # alone allows 7.9 mm at 25 mm), and 3 mm under the gap stopper the gap binds (3 mm).
    for setpoint, axis, room in (
        (("55", "0", "25"), "x", 5.0),
        (("0", "55", "25"), "y", 5.0),
        (("0", "0", "32"), "gap", 3.0),
    ):
        doc = _region_json(tmp_path, "--setpoint", *setpoint)
        assert doc["setpoint_mm"] == [float(v) for v in setpoint]
        assert doc["binding"] == axis, setpoint
        assert doc["half_widths_mm"][axis] == pytest.approx(room, rel=1e-9)


@pytest.mark.parametrize(
    ("argv", "named"),
    [
        (["simulate", "--stage", "microstepper", "--controller", "lqr"], "--controller lqr"),
        (["simulate", "--stage", "microstepper", "--twin-constants", "table2_eps0.05"], "--twin-constants"),
        (["simulate", "--stage", "microstepper", "--scenario", "small_step"], "--scenario small_step"),
        (["simulate", "--no-anti-windup"], "--no-anti-windup"),
        (["simulate", "--scenario", "saturation"], "--scenario saturation"),
        (["region", "--stage", "microstepper", "--setpoint", "0", "0", "25", "--sdp"], "--sdp"),
        (["region", "--stage", "microstepper", "--setpoint", "0", "0", "25", "--gaps", "20"], "--gaps"),
        (["region", "--stage", "microstepper"], "--setpoint"),
        (["region", "--setpoint", "0", "0", "25"], "--setpoint"),
        (["region", "--stage", "microstepper", "--setpoint", "0", "0", "0.025"], "--setpoint"),
    ],
)
def test_options_of_the_other_stage_are_refused(tmp_path, capsys, argv, named):
    if argv[0] == "simulate":
        argv = [*argv, "--out", str(tmp_path / "run.csv")]
    assert main(argv) == cli.EXIT_USAGE
    err = capsys.readouterr().err
    assert named in err and len(err.strip().splitlines()) == 1
    assert not list(tmp_path.iterdir())  # nothing written


# --- controllers (library options) ----------------------------------------------------------------
def test_fl_gains_scale_the_outer_loop(model):
    from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
    from maglev_oc.control.gains import PAPER_K_H, PAPER_K_V

    papers = FeedbackLinearizingRegulator(model)
    scaled = FeedbackLinearizingRegulator(model, K_h=2 * PAPER_K_H, K_v=3 * PAPER_K_V)
    y = np.array([0.021, 0.004])  # 1 mm and 4 mm off the set-point below
    r = np.zeros(6)
    r[0] = 0.020
    c = papers.initial_state(y, None)
    c[1], c[3] = 0.01, -0.02  # the observers' velocities
    c[4:] = np.random.default_rng(0).uniform(-1e-4, 1e-4, c.size - 4)  # internal-model states
    v = [np.asarray(ctrl.step(c, y, r)[2]).ravel()[2:4] for ctrl in (papers, scaled)]
    # v1 = K_h z_h, v2 = K_v z_v (002 (23), (24)): linear in the gains, K_h horizontal, K_v vertical
    assert np.all(np.abs(v[0]) > 1e-3)
    assert_allclose(v[1], [2 * v[0][0], 3 * v[0][1]], rtol=1e-12)


def test_fl_omega0_is_the_frequency_tracked_without_error(model):
    from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
    from maglev_oc.control.gains import OMEGA0
    from maglev_oc.sim.effects import TwinEffects
    from maglev_oc.sim.engine import ClosedLoop
    from maglev_oc.sim.scenarios import paper_scenarios
    from maglev_oc.sim.twin import RigTwin

    # the papers' ellipse at 0.8 w0 instead of w0 = 1.5 pi, 10 s (amplitudes ramped in over 2 s)
    ellipse = paper_scenarios()["sinusoid"]
    w = 0.8 * OMEGA0
    ref = ellipse.reference
    ref = dataclasses.replace(
        ref,
        vertical=tuple((a, w, p) for a, _, p in ref.vertical),
        horizontal=tuple((a, w, p) for a, _, p in ref.horizontal),
    )
    scenario = dataclasses.replace(ellipse, reference=ref, duration=10.0)
    errors = {}
    for omega0 in (w, OMEGA0):
        loop = ClosedLoop(
            RigTwin(model, TwinEffects.ideal()), FeedbackLinearizingRegulator(model, omega0=omega0)
        )
        res = loop.run(scenario)
        late = res.t >= 8.0
        errors[omega0] = np.max(np.abs([res.y[0] - res.reference[0], res.y[1] - res.reference[3]])[:, late])
    # internal model principle (002 (21)-(22)): no steady error at the internal model's frequency;
    # measured 0.4 um (what is left of the FL loop's transient) tuned against 62 um detuned; bounds:
    # half an encoder count and two counts
    assert errors[w] < 0.5 * ENCODER_RESOLUTION
    assert errors[OMEGA0] > 2 * ENCODER_RESOLUTION


# --- region -----------------------------------------------------------------------------------------
def _region(folder: Path, *options: str) -> list[dict]:
    out = folder / f"region{len(list(folder.iterdir()))}.json"
    _ok(["region", "--gaps", "20", *options, "--json", str(out)])
    return json.loads(out.read_text())["certificates"]


@pytest.fixture(scope="module")
def at_20mm(tmp_path_factory) -> dict:
    """The certificate at the 20 mm set-point with every default: headroom binds, e1 6.06 mm."""
    (rec,) = _region(tmp_path_factory.mktemp("region"))
    assert rec["certified"] and rec["binding"] == "headroom"
    return rec


def test_region_position_moves_the_set_point(tmp_path, at_20mm):
    room = STOPPER_POSITION[1] - 55 * MM_TO_M  # 5 mm to the stopper at 60 mm
    for position, binding in (("55", "position_high"), ("-55", "position_low")):
        (rec,) = _region(tmp_path, "--position", position)
        assert rec["certified"] and f"{position} mm" in rec["reference"]
        assert rec["binding"] == binding  # the stopper on the set-point's side
        # a start at rest displaced along e2 alone stays between the stoppers; 8.0 mm at x3 = 0
        assert rec["semi_axes_SI"]["e2"] <= room
        assert at_20mm["semi_axes_SI"]["e2"] > room


def test_region_sinusoid_adds_the_ellipse(tmp_path, at_20mm):
    point, ellipse = _region(tmp_path, "--sinusoid")
    assert point == at_20mm and ellipse["reference"].startswith("sinusoid")
    assert ellipse["certified"]
    # the ellipse reaches 25 mm: the set leaves that reference 5 mm to the upper stopper at 30 mm
    assert ellipse["semi_axes_SI"]["e1"] <= STOPPER_GAP[1] - 25 * MM_TO_M
    assert ellipse["semi_axes_SI"]["e1"] < at_20mm["semi_axes_SI"]["e1"]


def test_region_sdp_adds_a_larger_set(tmp_path, at_20mm):
    lyapunov, sdp = _region(tmp_path, "--sdp")
    assert lyapunov == at_20mm and sdp["P"] == "SDP" and sdp["certified"]
    # the SDP certifies a rectangle of starts several times the Lyapunov equation's (x8.2 at 20 mm;
    # >= 4 as in test_region_sdp.py)
    assert np.prod(sdp["rectangle_m"]) >= 4 * np.prod(lyapunov["rectangle_m"])


def test_region_current_limit_shrinks_the_set(tmp_path, capsys, at_20mm):
    (rec,) = _region(tmp_path, "--current-limit", "5")
    assert "|u| <= 5 A" in capsys.readouterr().out
    # F with 5 A lies inside F with 9 A and the current binds at 9 A: every semi-axis shrinks
    assert rec["certified"] and rec["binding"] == "headroom"
    for k, v in rec["semi_axes_SI"].items():
        assert v < 0.8 * at_20mm["semi_axes_SI"][k], k  # measured 0.57 (level 3.74 against 11.33)


def test_region_no_current_limit_drops_the_current_constraint(tmp_path, capsys, at_20mm):
    (rec,) = _region(tmp_path, "--no-current-limit")
    assert "no current limit" in capsys.readouterr().out
    # the papers' set A (R >= 0 and the stoppers) contains F: the level can only grow, and the
    # current no longer binds (the upper gap stopper does)
    assert rec["certified"] and rec["binding"] == "gap_high"
    assert rec["level"] >= at_20mm["level"]


def test_region_no_stoppers_drops_the_gap_stoppers(tmp_path, capsys):
    (with_stoppers,) = _region(tmp_path, "--no-current-limit")
    (without,) = _region(tmp_path, "--no-current-limit", "--no-stoppers")
    assert "no gap stoppers" in capsys.readouterr().out
    # without the current limit the upper stopper binds; without the stoppers too, R >= 0 does
    # (002: the transformation's existence), at a level 1.66x higher (measured 18.99 against 11.45)
    assert with_stoppers["binding"] == "gap_high" and without["binding"] == "margin"
    assert without["level"] > 1.2 * with_stoppers["level"]


def test_region_samples_runs_monte_carlo_inside(tmp_path, capsys, at_20mm):
    (rec,) = _region(tmp_path, "--samples", "3")
    # three runs from inside the certified set, on the rig twin: none may leave F (the certificate)
    assert rec["monte_carlo"] == {"runs": 3, "violations": 0}
    assert "3/0" in capsys.readouterr().out
    assert at_20mm["monte_carlo"] == {"runs": 0, "violations": 0}


def test_region_params_is_the_model(tmp_path, stage_file, at_20mm):
    (rec,) = _region(tmp_path, "--params", str(stage_file))
    # 20 % less force per ampere: the equilibrium current at 20 mm is 1.90 A instead of 1.50 A and
    # each m/s^2 of v costs more current, so less headroom is left: the set must shrink
    assert rec["binding"] == at_20mm["binding"] == "headroom"
    assert rec["level"] < 0.8 * at_20mm["level"]  # measured 6.69 against 11.33


def test_region_refuses_a_limit_and_no_limit_together(tmp_path, capsys):
    argv = ["region", "--gaps", "20", "--current-limit", "5", "--no-current-limit"]
    assert main(argv) == cli.EXIT_USAGE
    assert "--current-limit" in capsys.readouterr().err


def test_feasible_set_position_range_is_the_only_place_x3_enters(model):
    from maglev_oc.region.closed_loop import Reference, RegulatorLoop
    from maglev_oc.region.feasibility import FeasibleSet
    from maglev_oc.region.procedure2 import Procedure2

    loop = RegulatorLoop()
    near_stopper = Reference.setpoint(0.020, 0.055)
    stopped = Procedure2(FeasibleSet(model), loop).run(near_stopper)
    free = Procedure2(FeasibleSet(model, position_range=None), loop).run(near_stopper)
    centre = Procedure2(FeasibleSet(model), loop).run(Reference.setpoint(0.020, 0.0))
    assert stopped.binding == "position_high"
    # x3 does not appear in the model (002 (3)): without the position stoppers the set at 55 mm is
    # the one at 0 mm (measured: the same level to the last digit; 1e-9 for a change of platform)
    assert free.binding == centre.binding == "headroom"
    assert free.level == pytest.approx(centre.level, rel=1e-9)


# --- region --robust ----------------------------------------------------------------------------------
@pytest.fixture
def sweeps(monkeypatch):
    """Every sweep ``region --robust`` runs and every Dask client it opens, recorded (the real
    functions still run): the plant set, the seed and where the tasks went."""
    import contextlib

    import maglev_oc.region.robust as robust
    import maglev_oc.region.sweep as sweep

    calls = SimpleNamespace(sweeps=[], clients=[])
    run, client = sweep.run_sweep, sweep.dask_client

    def recording_run(spec, n, **kw):
        calls.sweeps.append(SimpleNamespace(spec=spec, n=n, **kw))
        return run(spec, n, **kw)

    @contextlib.contextmanager
    def recording_client(scheduler=None, workers=1):
        with client(scheduler, workers) as c:
            n = None if c is None else len(c.scheduler_info()["workers"])
            calls.clients.append((scheduler, workers, n))
            yield c

    monkeypatch.setattr(sweep, "run_sweep", recording_run)
    monkeypatch.setattr(robust, "run_sweep", recording_run)
    monkeypatch.setattr(sweep, "dask_client", recording_client)
    return calls


def _robust(tmp_path: Path, *options: str) -> dict:
    # --certify-boxes 1000, the smallest budget: these tests check where the options send the
    # sweeps, which are the same with any budget (same specs, sizes and seeds; measured), while the
    # default 100000 boxes cost three quarters of each run (the budget itself:
    # tests/test_region_cli.py::test_region_robust_certify_boxes_is_the_budget)
    out = tmp_path / f"robust{len(list(tmp_path.glob('robust*.json')))}.json"
    argv = ["region", "--robust", "--gaps", "20", "--samples", "40", "--certify-boxes", "1000", *options]
    argv += ["--json", str(out)]
    assert main(argv) == 0
    return json.loads(out.read_text())


def _robust_plants(calls) -> set:
    """The plant sets the sweeps drew from, apart from the nominal point."""
    return {c.spec.plants for c in calls.sweeps if c.spec.plants.label != "the nominal plant"}


def test_region_robust_confidence_scales_the_ellipsoid(tmp_path, sweeps, model):
    from scipy.stats import chi2

    from maglev_oc.region.robust import assumed_covariance

    _robust(tmp_path, "--confidence", "0.5")
    (plants,) = _robust_plants(sweeps)
    # the assumed covariance (no stage file) times the chi-square quantile of 0.5 with 4 dof
    # (3.36, against 9.49 at the default 0.95): a level ignored or read as 1 - level fails
    assert plants.kind == "ellipsoid"
    assert_allclose(plants.shape, chi2.ppf(0.5, 4) * assumed_covariance(model.constants), rtol=1e-12)
    assert_allclose(plants.center, model.constants.as_array(), rtol=0)


def test_region_robust_box_is_the_plant_set(tmp_path, sweeps, model):
    _robust(tmp_path, "--box", "C2=700:800,C4=0.06:0.08")
    (plants,) = _robust_plants(sweeps)
    nominal = np.asarray(model.constants.as_array())
    assert plants.kind == "box"
    # the named constants span their ranges, LO below HI; the others stay at the nominal value
    assert_allclose(plants.lower, [nominal[0], 700.0, nominal[2], 0.06], rtol=0)
    assert_allclose(plants.upper, [nominal[0], 800.0, nominal[2], 0.08], rtol=0)


def test_region_robust_seed_reaches_every_sweep(tmp_path, sweeps):
    doc = _robust(tmp_path, "--seed", "7")
    assert doc["seed"] == 7
    assert sweeps.sweeps and {c.seed for c in sweeps.sweeps} == {7}  # nominal, robust and the level search
    sweeps.sweeps.clear()
    _robust(tmp_path)
    assert {c.seed for c in sweeps.sweeps} == {0}  # the default


def test_region_robust_workers_and_scheduler_choose_where_the_tasks_run(tmp_path, sweeps):
    # The numbers do not depend on where the tasks run (a seed per task: the bit-identity test of
    # tests/test_region_sweep.py), so the options are checked by where they send the work: one
    # worker stays in this process; --workers 2 starts a LocalCluster of two; --scheduler
    # connects to a running scheduler (here a threaded cluster in this process), whose
    # scheduler must then have run the sweep's tasks.
    distributed = pytest.importorskip("distributed")
    alone = _robust(tmp_path)
    assert sweeps.clients[-1] == (None, 1, None)  # no client: this process
    two = _robust(tmp_path, "--workers", "2")
    assert sweeps.clients[-1] == (None, 2, 2)  # a cluster with two workers
    with distributed.LocalCluster(n_workers=1, processes=False, dashboard_address=None) as cluster:
        remote = _robust(tmp_path, "--scheduler", cluster.scheduler_address)
        assert sweeps.clients[-1] == (cluster.scheduler_address, 1, 1)
        assert cluster.scheduler.transition_counter > 0  # the tasks ran there
    assert alone["setpoints"] == two["setpoints"] == remote["setpoints"]


def test_region_robust_refuses_an_unreachable_scheduler(capsys, monkeypatch):
    pytest.importorskip("distributed")
    import maglev_oc.region.sweep as sweep

    monkeypatch.setattr(sweep, "SCHEDULER_TIMEOUT_S", 1.0)  # port 9 refuses at once; Dask retries
    argv = ["region", "--robust", "--gaps", "20", "--samples", "10", "--scheduler", "tcp://127.0.0.1:9"]
    assert main(argv) == cli.EXIT_USAGE
    err = capsys.readouterr().err
    assert "cannot connect to the Dask scheduler 'tcp://127.0.0.1:9'" in err


# --- diagnose ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def twin_csv(tmp_path_factory, model) -> dict[str, Path]:
    """Twin runs of the papers' excitation (true constants TWIN_TRUTH, PIDs on the papers' model,
    encoder and amplifier on), as CSV: 10.5 s for the diagnosis (its shortest is 10 s), 6 s for
    identification, and 6 s whose currents reach the plant 10 loop samples (2 ms) late."""
    from maglev_oc.identification.experiments import TWIN_TRUTH, excitation_log, identification_effects

    folder = tmp_path_factory.mktemp("twin")
    truth = model.with_constants(TWIN_TRUTH)
    late = dataclasses.replace(identification_effects(), input_delay_samples=10)
    runs = {
        "diagnose": excitation_log(truth, duration=10.5, seed=2, controller_model=model),
        "identify": excitation_log(truth, duration=6.0, seed=2, controller_model=model),
        "late": excitation_log(truth, duration=6.0, seed=2, controller_model=model, effects=late),
    }
    return {name: write_log(folder / f"{name}.csv", log) for name, log in runs.items()}


@pytest.fixture(scope="module")
def diagnosed(tmp_path_factory, twin_csv) -> dict[str, tuple[dict, object]]:
    """``diagnose --report`` with the defaults, and with --holdout 0.4 --no-control --no-limits: (JSON,
    what the report says) each."""
    import maglev_oc.reporting.diagnosis_report as reporting

    folder = tmp_path_factory.mktemp("diagnose")
    written = []
    real = reporting.write_diagnosis_report

    def keep(*args, **kw):
        written.append(real(*args, **kw))
        return written[-1]

    out = {}
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(reporting, "write_diagnosis_report", keep)
        other = ["--holdout", "0.4", "--no-control", "--no-limits"]
        for name, options in (("default", []), ("options", other)):
            json_out, pdf = folder / f"{name}.json", folder / f"{name}.pdf"
            outputs = ["--json", str(json_out), "--report", str(pdf)]
            _ok(["diagnose", str(twin_csv["diagnose"]), *outputs, *options])
            out[name] = (json.loads(json_out.read_text()), written[-1])
    return out


def test_diagnose_holdout_holds_out_that_share(diagnosed, twin_csv):
    n = _read(twin_csv["diagnose"]).n
    default, options = diagnosed["default"][0]["holdout"], diagnosed["options"][0]["holdout"]
    assert (default["fraction"], options["fraction"]) == (0.25, 0.4)
    # the guard bands and filter edges do not depend on the share, so moving from 25 % to 40 %
    # moves exactly 15 % of the samples from the fit to the held-out block (1 for rounding)
    assert abs(options["samples"] - default["samples"] - 0.15 * n) <= 1
    assert abs(default["fit_samples"] - options["fit_samples"] - 0.15 * n) <= 1
    # and what they take is small: 40 % of the samples less 146 (a guard band and the filter's edge)
    assert 0.38 * n < options["samples"] <= 0.4 * n


def _words(text: str) -> str:
    """Text with its line breaks (wrapped table cells) and no-break spaces as single spaces."""
    return " ".join(text.split())


def test_diagnose_report_is_written_with_the_findings(diagnosed):
    from maglev_oc.reporting.diagnosis_plots import plain

    doc, contents = diagnosed["default"]
    assert contents.path.read_bytes()[:5] == b"%PDF-" and _pdf_pages(contents.path) == contents.n_pages
    assert contents.sparse_pages() == []
    scorecard = contents.sections[0]  # page 1: the scorecard table
    summary = _words(scorecard.text())
    for axis, before in doc["error_before"].items():
        after = doc["error_after"][axis]
        assert f"{axis} {before:.3g} → {after:.3g} m/s²" in summary  # the JSON's numbers
    assert f"({doc['holdout']['samples']} samples" in summary
    found = [_words(row[0]) for row in scorecard.rows]
    words = _words(contents.text())
    for effect in doc["effects"]:
        assert plain(effect["name"]) in found  # a scorecard row per effect, in plain words
        assert _words(effect["finding"]) in words  # and its finding on the pages after


def test_diagnose_no_control_leaves_out_the_closed_loop_study(diagnosed):
    (_, with_study), (_, without) = diagnosed["default"], diagnosed["options"]
    study_page = "FL regulator on "  # the compensation figure: before and after compensating

    def has_study(contents) -> tuple[bool, bool]:
        said = any(row[0].startswith("FL regulator") for row in contents.sections[0].rows)  # scorecard
        return said, any(h.startswith(study_page) for h in contents.headings)

    assert has_study(with_study) == (True, True)
    assert has_study(without) == (False, False)
    # (the pages are packed full, so leaving the study out need not save a page)
    assert _pdf_pages(without.path) == without.n_pages and without.sparse_pages() == []


def test_diagnose_no_limits_leaves_out_what_the_log_could_not_have_shown(diagnosed):
    (doc, with_limits), (doc_without, without) = diagnosed["default"], diagnosed["options"]
    assert doc["settings"]["detection_limits"] is True and doc["detection_limits"]
    assert doc_without["settings"]["detection_limits"] is False and doc_without["detection_limits"] == []
    # the report says they were not worked out, rather than leaving the reader to think none exist
    said = "could not have shown was not worked out (diagnose --no-limits)"
    assert said in _words(without.text()) and said not in _words(with_limits.text())
    rows = {_words(row[0]): _words(row[1]) for row in without.sections[0].rows}  # the scorecard
    assert rows["not shown by this log"] == "not worked out (diagnose --no-limits)"
    # the claims do not depend on them: the same effects by name (the held-out share differs)
    assert [e["name"] for e in doc["effects"]] == [e["name"] for e in doc_without["effects"]]


def test_diagnose_params_is_the_stage(tmp_path, twin_csv, light_stage_file, diagnosed):
    out = tmp_path / "light.json"
    _ok(["diagnose", str(twin_csv["diagnose"]), "--json", str(out), "--params", str(light_stage_file)])
    light = {k: v["value"] for k, v in json.loads(out.read_text())["constants_base"].items()}
    papers = {k: v["value"] for k, v in diagnosed["default"][0]["constants_base"].items()}
    # both fits explain the same measured vertical accelerations x2' = G - (C2 l2 + C3 l3 u2 +
    # C4 l4 |u|^2): with g 0.81 m/s^2 lower, the magnetic part must drop by 0.81 m/s^2 on average
    # over the log (measured 0.8097; 3 %: a constant is not exactly in the span of l2, l3 u2 and
    # l4 |u|^2, l2 alone varying by a factor 2.3 over the logged 16.4-23.1 mm)
    log = _read(twin_csv["diagnose"])
    shape = np.asarray(StageModel().shape.map(log.n)(log.x[0][None, :]))
    u1, u2 = log.u

    def magnetic(c):
        return c["C2"] * shape[1] + c["C3"] * shape[2] * u2 + c["C4"] * shape[3] * (u1**2 + u2**2)

    assert np.mean(magnetic(papers) - magnetic(light)) == pytest.approx(9.81 - 9.0, rel=0.03)
    assert light["C1"] == pytest.approx(papers["C1"], rel=1e-9)  # gravity is vertical only


# --- identify ---------------------------------------------------------------------------------------
def _identify(folder: Path, log: Path, *options: str) -> dict:
    out = folder / f"fit{len(list(folder.iterdir()))}.json"
    _ok(["identify", str(log), "--methods", "equation_error", *options, "--json", str(out)])
    return json.loads(out.read_text())


def test_identify_input_delay_matches_a_late_amplifier(tmp_path, twin_csv):
    from maglev_oc.identification.experiments import TWIN_TRUTH

    clean = _identify(tmp_path, twin_csv["identify"])["equation_error"]
    plain = _identify(tmp_path, twin_csv["late"])["equation_error"]
    delayed = _identify(tmp_path, twin_csv["late"], "--input-delay", "0.002")["equation_error"]
    assert delayed["settings"]["input_delay_s"] == 0.002
    # the currents shifted by the true 2 ms: the residual falls to the clean log's noise floor
    # (measured 0.0095 against 0.0097 m/s^2); ignored, it stays 3x higher; inverted (an advance)
    # the mismatch would be 4 ms and worse still
    floor = clean["residual_rms"]["vertical"]
    assert delayed["residual_rms"]["vertical"] == pytest.approx(floor, rel=0.2)
    assert plain["residual_rms"]["vertical"] > 2 * floor
    # and the constants the lag biased move back to the truth (C4: -3.5 % -> -0.9 %)
    for k in ("C3", "C4"):
        err = [abs(fit["parameters"][k]["value"] / getattr(TWIN_TRUTH, k) - 1) for fit in (plain, delayed)]
        assert err[1] < 0.5 * err[0], (k, err)


def test_identify_validate_checks_the_fit_on_held_out_logs(tmp_path, twin_csv, capsys):
    fitted = twin_csv["identify"]
    inside = _identify(tmp_path, fitted)["validation"]
    held = _identify(tmp_path, fitted, "--validate", str(twin_csv["late"]))["validation"]
    assert "in-sample" in inside["data"] and str(twin_csv["late"]) in held["data"]
    # the held-out log's currents reach the plant 2 ms late, which the fit knows nothing of: its
    # prediction residuals are larger than on the fitted log (measured 5.5 against 2.3 um
    # vertically, 3.0 against 1.3 um horizontally; ignored, --validate would give the in-sample
    # numbers)
    for axis in ("vertical", "horizontal"):
        assert held["residual_rms_m"][axis] > 1.2 * inside["residual_rms_m"][axis], axis
    # a held-out log that is also fitted is refused, naming it
    argv = ["identify", str(fitted), "--validate", str(fitted), "--json", str(tmp_path / "x.json")]
    assert main(argv) == cli.EXIT_USAGE
    assert "--validate" in capsys.readouterr().err and not (tmp_path / "x.json").exists()


def test_identify_input_delay_reaches_npfsi(tmp_path, capsys, twin_csv):
    argv = ["identify", str(twin_csv["late"]), "--methods", "npfsi", "--eps", "0.01"]
    fits = []
    for options in ([], ["--input-delay", "0.002"]):
        out = tmp_path / f"npfsi{len(fits)}.json"
        code = main([*argv, *options, "--json", str(out)])
        if code == cli.EXIT_USAGE:  # refusing the combination, naming the option, is fine too
            assert "--input-delay" in capsys.readouterr().err
            return
        fits.append(json.loads(out.read_text())["identified_constants"])
    assert fits[0] != fits[1]


def test_identify_estimate_fits_only_those(tmp_path, twin_csv):
    full = _identify(tmp_path, twin_csv["identify"])
    horizontal = _identify(tmp_path, twin_csv["identify"], "--estimate", "C1")
    vertical = _identify(tmp_path, twin_csv["identify"], "--estimate", "C2", "C3", "C4")
    assert list(horizontal["equation_error"]["parameters"]) == ["C1"]
    assert list(vertical["equation_error"]["parameters"]) == ["C2", "C3", "C4"]
    # x4' = -C1 l1(x1) u1 holds C1 alone and x2' holds C2..C4 alone (002 (3)): each subset's estimates
    # are the full fit's, to rounding; the rest stay at the papers' values
    fitted = {k: v["value"] for k, v in full["equation_error"]["parameters"].items()}
    for doc, names in ((horizontal, ("C1",)), (vertical, ("C2", "C3", "C4"))):
        got = doc["identified_constants"]
        for k in ("C1", "C2", "C3", "C4"):
            expected = fitted[k] if k in names else getattr(DEFAULT_CONSTANTS, k)
            assert got[k] == pytest.approx(expected, rel=1e-9)


def test_identify_params_gives_the_fixed_constants(tmp_path, twin_csv):
    guesses = DEFAULT_CONSTANTS.replace(C1=13.0, C2=760.0, source="test: other initial guesses")
    params = save_json(tmp_path / "guesses.json", StageParameters(), guesses)
    estimate = ("--estimate", "C2", "C3", "C4")
    doc = _identify(tmp_path, twin_csv["identify"], *estimate, "--params", str(params))
    papers = _identify(tmp_path, twin_csv["identify"], *estimate)
    # C1, not estimated, is held at the file's value; the estimated constants start from the file's
    assert doc["identified_constants"]["C1"] == 13.0
    assert papers["identified_constants"]["C1"] == DEFAULT_CONSTANTS.C1
    assert doc["equation_error"]["parameters"]["C2"]["initial"] == 760.0
    # x2' does not hold C1 (002 (3)) and the vertical fit is one linear solve, exact from any start:
    # the estimates are the papers' run's, to rounding
    for k in ("C2", "C3", "C4"):
        assert doc["identified_constants"][k] == pytest.approx(papers["identified_constants"][k], rel=1e-9)


def test_identify_report_is_written_with_the_fit(tmp_path, monkeypatch, twin_csv):
    import maglev_oc.reporting.identification_plots as plots

    written = []
    real = plots.write_outcome_report
    monkeypatch.setattr(plots, "write_outcome_report", lambda *a, **kw: written.append(real(*a, **kw)))
    without = _identify(tmp_path, twin_csv["identify"])
    assert not written and not list(tmp_path.glob("*.pdf"))
    pdf = tmp_path / "fit.pdf"
    doc = _identify(tmp_path, twin_csv["identify"], "--report", str(pdf))
    (contents,) = written
    assert contents.path == pdf and pdf.read_bytes()[:5] == b"%PDF-" and _pdf_pages(pdf) == contents.n_pages
    table = contents.section("Least-squares estimates")
    fit = doc["equation_error"]["parameters"]
    assert table.column("parameter") == tuple(fit)
    for k, p in fit.items():
        assert float(table.row(k)[2]) == pytest.approx(p["value"], rel=1e-5)  # printed to 6 digits
    assert doc["identified_constants"] == without["identified_constants"]  # the report computes nothing


def test_identify_terms_are_fitted(model, twin_csv):
    from maglev_oc.identification.pipeline import identify
    from maglev_oc.regression.terms import constant_acceleration

    log = _read(twin_csv["identify"])
    t = log.t - log.t[0]
    bias = 0.05  # [m/s^2] guides 5 mrad off level
    x = log.x.copy()
    x[2] += 0.5 * bias * t**2  # exact for the double integrator x3'' = ... + bias
    tilted = dataclasses.replace(log, x=x)
    term = constant_acceleration("horizontal")
    with_term = identify(tilted, model, methods=("equation_error",), terms=[term]).equation_error
    without = identify(tilted, model, methods=("equation_error",)).equation_error
    # measured 0.05003 +- 0.00007 m/s^2; 0.002 as on the 20 s log of test_identify_equation_error.py
    assert with_term.values["bias_horizontal.acceleration"] == pytest.approx(bias, abs=0.002)
    assert "bias_horizontal.acceleration" not in without.values
    assert with_term.residual_rms["horizontal"] < without.residual_rms["horizontal"]


# --- export ---------------------------------------------------------------------------------------
def test_export_qp_iterations_is_the_nmpc_solvers_budget(monkeypatch, capsys):
    # The budget reaches the exported NMPC's QP solver: the export's dual active-set solver by
    # default, qrqp's max_iter with --qp-solver qrqp (what a budget does to the loop: the budget
    # tests of tests/test_export.py and tests/test_nmpc.py). The NMPC, its compiled form and the
    # export are stand-ins that record what they are given (the export is tested in
    # tests/test_export.py).
    import maglev_oc.control.export as export
    import maglev_oc.control.nmpc as nmpc
    import maglev_oc.sim.compiled_nmpc as compiled

    built, exported = [], []

    def recording(model, **options):
        built.append(options)
        return SimpleNamespace()

    def exporting(ctrl, out, **options):
        exported.append(options)
        raise RuntimeError("exported")

    monkeypatch.setattr(nmpc, "NonlinearMPC", recording)
    monkeypatch.setattr(compiled, "CompiledNMPC", lambda ctrl, **_: ctrl)
    monkeypatch.setattr(export, "export_controller", exporting)
    for options, qp_options, export_options in (
        ([], None, {"qp_solver": "dual", "qp_iterations": None}),
        (["--qp-iterations", "3"], None, {"qp_solver": "dual", "qp_iterations": 3}),
        (["--qp-solver", "qrqp"], {"max_iter": cli.QP_ITERATION_BUDGET}, {"qp_solver": "qrqp"}),
        (["--qp-solver", "qrqp", "--qp-iterations", "3"], {"max_iter": 3}, {"qp_solver": "qrqp"}),
    ):
        assert main(["export", "nmpc", "--out", "/nonexistent/x", *options]) == cli.EXIT_INTERNAL
        assert built.pop().get("qp_options") == qp_options
        assert {k: v for k, v in exported.pop().items() if k != "prefix"} == export_options
    assert cli.QP_ITERATION_BUDGET >= 10 and export.DUAL_QP_BUDGET >= 10  # the large step needs 7
    for argv, needle in (
        (["nmpc", "--qp-iterations", "0"], "--qp-iterations must be in [1, 1000]"),
        (["pid", "--qp-iterations", "5"], "--qp-iterations and --qp-solver apply to the NMPC only"),
    ):
        assert main(["export", *argv, "--out", "/nonexistent/x"]) == cli.EXIT_USAGE
        assert needle in capsys.readouterr().err


# --- design-experiment ----------------------------------------------------------------------------
def _design(folder: Path, *options: str):
    from maglev_oc.identification.design import read_reference

    assert main(["design-experiment", *options, "--out", str(folder)]) == 0
    return json.loads((folder / "design.json").read_text()), read_reference(folder / "reference.csv")


def test_design_experiment_kind_duration_and_seed_pick_the_reference(tmp_path, model):
    from maglev_oc.identification.design import design_experiment

    doc, ref = _design(tmp_path / "a", "--kind", "prbs", "--duration", "12", "--seed", "3")
    want = design_experiment("prbs", 12.0, model=model, seed=3)
    assert doc["kind"] == "prbs" and doc["settings"]["seed"] == 3 and doc["settings"]["duration_s"] == 12
    # 12 s at 1 kHz; the file holds the library's reference (CSV with 17 significant digits)
    assert ref.t.size == 12000 and ref.t[-1] == pytest.approx(11.999, abs=1e-12)
    assert_allclose(ref.values, want.reference.values, rtol=1e-15, atol=1e-18)
    # another seed shifts the PRBS (a different reference); another kind is another shape
    other_seed = design_experiment("prbs", 12.0, model=model, seed=0).reference.values
    other_kind = design_experiment("multisine", 12.0, model=model, seed=3).reference.values
    for other in (other_seed, other_kind):
        assert np.max(np.abs(ref.values[0] - other[0])) > 1e-4  # > 0.1 mm of gap set-point


def test_design_experiment_params_is_the_model_designed_for(tmp_path, stage_file):
    # 20 % less force per ampere of i_d (WEAK_C3): the papers' excitation, whose peaks are the
    # budget every design gets, needs more i_d on that stage (1.90 against 1.50 A to hold 20 mm)
    weak, _ = _design(
        tmp_path / "weak", "--kind", "multisine", "--duration", "12", "--params", str(stage_file)
    )
    papers, _ = _design(tmp_path / "papers", "--kind", "multisine", "--duration", "12")
    assert weak["budget_A"]["i_d"] > 1.15 * papers["budget_A"]["i_d"]
    assert weak["budget_A"]["i_d"] == pytest.approx(papers["budget_A"]["i_d"] * 1.90 / 1.50, rel=0.1)


# --- the tables are complete and point at real tests ----------------------------------------------
def _cli_options() -> set[str]:
    """ "subcommand --option" for every option of every subcommand, "--option" for the top level."""

    def options(parser: argparse.ArgumentParser, prefix: str) -> set[str]:
        return {
            prefix + max(a.option_strings, key=len)
            for a in parser._actions
            if a.option_strings and not isinstance(a, argparse._HelpAction)
        }

    parser = build_parser()
    found = options(parser, "")
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found |= options(sub, f"{name} ")
    return found


def _test_functions(path: str) -> dict[str, ast.FunctionDef]:
    tree = ast.parse((ROOT / path).read_text())
    return {n.name: n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name.startswith("test_")}


def test_every_cli_option_has_a_test():
    options = _cli_options()
    assert len(options) > 30  # the walk found the subcommands
    missing = sorted(options - set(OPTION_TESTS))
    stale = sorted(set(OPTION_TESTS) - options)
    assert not missing, f"options without a test in OPTION_TESTS: {missing}"
    assert not stale, f"OPTION_TESTS names options maglev-oc does not have: {stale}"


def _resolve(dotted: str):
    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ModuleNotFoundError:
            continue
        for attr in parts[k:]:
            obj = getattr(obj, attr)
        return obj
    raise ImportError(dotted)


@pytest.mark.parametrize("key", sorted(LIBRARY_OPTION_TESTS))
def test_every_library_option_is_a_real_keyword(key):
    dotted, keyword = re.fullmatch(r"([\w.]+)\((\w+)\)", key).groups()
    assert keyword in inspect.signature(_resolve(dotted)).parameters, key


@pytest.mark.parametrize("table", [OPTION_TESTS, LIBRARY_OPTION_TESTS], ids=["cli", "library"])
def test_every_named_test_exists_and_is_expected_to_pass(table):
    files: dict[str, dict[str, ast.FunctionDef]] = {}
    for option, ref in table.items():
        path, _, name = ref.partition("::")
        if path not in files:
            files[path] = _test_functions(path)
        assert name in files[path], f"{option}: no test {name} in {path}"
        # an expected failure does not check the option: the named test must be one that passes
        decorators = [ast.unparse(d) for d in files[path][name].decorator_list]
        assert not any("xfail" in d for d in decorators), f"{option}: {ref} is marked xfail"
