"""Properties of what identification hands a user (issue 21: tests that catch a wrong answer).

Each test states what a function promises (its docstring, SPEC, or an independent computation)
rather than the code's current numbers:

* the JSON of ``maglev-oc identify --json`` and ``to_dict``: the schema a user's script reads,
  and every number in it equal to the attribute of the result it came from;
* ``NpfsiResult.settling_time`` and ``report``; the correlation list of ``FitResult.report``;
* ``compare_equilibrium_currents`` against the model's own equilibrium (x2' = 0) and SPEC 1;
* ``EquationError``: sample windows, residuals of a partial estimate, covariance fields;
* ``MultipleShooting`` on several logs: every log checked and used; status and timings;
* ``check_identifiable``'s messages; NPFSI input checks; the Gauss-Newton's failure status;
* the twin experiments' seeds; ``ParameterLayout``'s type check.

Short twin logs (6 s, the shortest :data:`MIN_DURATION` allows, and 1 s runs) and module
fixtures keep the file at a few seconds.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import time

import numpy as np
import pytest
import scipy.sparse as sp
from numpy.testing import assert_allclose, assert_array_equal

from maglev_oc.cli import main
from maglev_oc.control.base import ExpressionController
from maglev_oc.control.pid import paper_pid
from maglev_oc.data.log import Log
from maglev_oc.data.logs import write_log
from maglev_oc.errors import InputError, LogError
from maglev_oc.identification.constrained_gn import constrained_gauss_newton
from maglev_oc.identification.equation_error import EquationError
from maglev_oc.identification.experiments import (
    ConstantCurrent,
    excitation_log,
    fixed_gap_logs,
)
from maglev_oc.identification.layout import ParameterLayout
from maglev_oc.identification.npfsi import DEFAULT_Q0_SECONDS, NpfsiEstimator, npfsi
from maglev_oc.identification.output_error import MultipleShooting
from maglev_oc.identification.pipeline import check_identifiable, identify, load_logs
from maglev_oc.identification.result import NpfsiResult
from maglev_oc.identification.verification import compare_equilibrium_currents
from maglev_oc.model.hardware import ENCODER_RESOLUTION
from maglev_oc.regression.base import CONSTANT_NAMES, UNITS
from maglev_oc.regression.data import delayed_inputs
from maglev_oc.regression.design import build_design
from maglev_oc.regression.terms import constant_acceleration
from maglev_oc.results import AXES, jsonable

EPS = (0.01, 0.05)  # two NPFSI runs: enough to see one run per eps, in order

# --- the schema a user's script reads (the current output of `identify --json`) -------------------
OUTCOME_KEYS = {
    "sources",
    "estimate",
    "base_constants",
    "identified_constants",
    "equation_error",
    "output_error",
    "npfsi",
    "success",
    "status",
    "message",
    "timings",
    "warnings",  # constants a stage of this geometry cannot have (IdentificationOutcome.warnings)
    "left_out",  # where a log's platform rests on its stopper (regression.stoppers)
    "moving_mass",  # the constants moved as a payload moves them (identification.masses), or null
    "payload_kg",  # the payload each log declares (# payload_kg; 0 for none), read as the unloaded stage's
    "validation",  # residual whiteness and fit % of the best fit (maglev_oc.validation)
}
CLI_KEYS = OUTCOME_KEYS | {"stage"}  # the file also holds the stage file it amounts to
FIT_KEYS = {
    "method",
    "parameters",
    "fixed",
    "covariance",
    "correlation",
    "residual_rms",
    "residual_unit",
    "n_samples",
    "n_residuals",
    "chi_square",
    "reduced_chi_square",
    "hac_frequencies",
    "success",
    "status",
    "message",
    "iterations",
    "timings",
    "sources",
    "settings",
}
PARAMETER_KEYS = {"value", "stderr", "stderr_naive", "initial", "unit"}
NPFSI_KEYS = {
    "method",
    "eps",
    "gamma",
    "Q",
    "Q0",
    "values",
    "theta0",
    "velocity_method",
    "success",
    "status",
    "message",
    "timings",
    "sources",
    "settings",
}
TIMINGS = {
    "equation_error": {"prepare", "solve", "covariance", "total"},
    "output_error": {"prepare", "initial_fit", "simulate_and_linearize", "kkt_solves", "covariance", "total"},
}
SETTINGS = {  # at least these (a renamed key is a missing key for the script that reads it)
    "equation_error": {
        "differentiator",
        "bandwidth_hz",
        "hac_band_hz",
        "polyorder",
        "velocity_window",
        "acceleration_window",
        "edge_samples",
        "input_delay_s",
        "axis_weights",
        "linear",
        "terms",
        "logging_error_variance_A2",
        "errors_in_variables_compensated",
    },
    "output_error": {
        "segment_duration_s",
        "segments",
        "integrator",
        "input_delay_s",
        "hac_band_hz",
        "residual_scale_m",
        "chi_square_units",
        "terms",
    },
}
NPFSI_SETTINGS = {"sample_time_s", "rows", "Q0_default_seconds"}
FIT_STATUS = {  # FitResult's docstring and constrained_gn's module doc
    "converged",
    "iteration_limit",
    "no_decrease",
    "singular",
    "kkt_singular",
    "line_search_failed",
    "covariance_singular",
}


# --- fixtures (truth_model and twin_log: tests/conftest.py) ------------------------------------------
@pytest.fixture(scope="module")
def csv_path(tmp_path_factory, twin_log):
    return write_log(tmp_path_factory.mktemp("ident") / "run.csv", twin_log)


@pytest.fixture(scope="module")
def timed_outcome(model, csv_path):
    """Every method on the CSV, in process (the same numbers the command line computes), and the
    wall time [s] the call took."""
    logs = load_logs([csv_path])
    start = time.perf_counter()
    out = identify(logs, model, npfsi_eps=EPS)
    return out, time.perf_counter() - start


@pytest.fixture(scope="module")
def outcome(timed_outcome):
    return timed_outcome[0]


@pytest.fixture(scope="module")
def cli_json(csv_path, tmp_path_factory) -> dict:
    out = tmp_path_factory.mktemp("cli") / "ident.json"
    code = main(["identify", str(csv_path), "--json", str(out), "--eps", *map(str, EPS)])
    assert code == 0
    return json.loads(out.read_text())


@pytest.fixture(scope="module")
def ee_problem(model, twin_log) -> EquationError:
    return EquationError(twin_log, model)


@pytest.fixture(scope="module")
def ee_fit(ee_problem):
    fit = ee_problem.fit()
    assert fit.success, fit.message
    return fit


@pytest.fixture(scope="module")
def halves(twin_log) -> tuple[Log, Log]:
    """The 6 s log as two logs of 3 s with their own names."""
    half = twin_log.n // 2
    a = dataclasses.replace(twin_log.index_slice(0, half), source="first.csv")
    b = dataclasses.replace(twin_log.index_slice(half, None), source="second.csv")
    return a, b


@pytest.fixture(scope="module")
def shooting(model, halves) -> MultipleShooting:
    return MultipleShooting(list(halves), model)


@pytest.fixture(scope="module")
def shooting_fit(shooting, ee_fit):
    return shooting.fit(initial=ee_fit)


def _slower(log: Log, source: str) -> Log:
    """The log at half its rate (every second sample), renamed."""
    return dataclasses.replace(log, t=log.t[::2], x=log.x[:, ::2], u=log.u[:, ::2], source=source)


# --- the JSON contract ----------------------------------------------------------------------------------
def test_identify_json_has_the_schema_a_script_reads(cli_json):
    assert set(cli_json) == CLI_KEYS
    assert cli_json["success"] is True and cli_json["status"] == "converged"
    assert cli_json["warnings"] == []  # the twin's constants are within a few per cent of the papers'
    assert cli_json["left_out"] == []  # the twin's runs levitate from their first sample
    assert cli_json["moving_mass"] is None  # the twin carries no payload
    assert cli_json["payload_kg"] == [0.0] * len(cli_json["sources"])  # and declares none
    for method in ("equation_error", "output_error"):
        fit = cli_json[method]
        assert set(fit) == FIT_KEYS, method
        assert fit["method"] == method
        assert list(fit["parameters"]) == list(CONSTANT_NAMES)  # covariance order
        for name, entry in fit["parameters"].items():
            assert set(entry) == PARAMETER_KEYS
            assert entry["unit"] == UNITS[name] != ""
            assert all(math.isfinite(entry[k]) for k in ("value", "stderr", "stderr_naive", "initial"))
        assert set(fit["timings"]) == TIMINGS[method]
        assert set(fit["settings"]) >= SETTINGS[method]
        assert fit["status"] in FIT_STATUS
        assert set(fit["residual_rms"]) == set(AXES)
        assert np.shape(fit["covariance"]) == np.shape(fit["correlation"]) == (4, 4)
    assert cli_json["equation_error"]["residual_unit"] == "m/s^2"
    assert cli_json["output_error"]["residual_unit"] == "m"
    assert [run["eps"] for run in cli_json["npfsi"]] == list(EPS)  # one run per eps, in order
    for run in cli_json["npfsi"]:
        assert set(run) == NPFSI_KEYS and run["method"] == "npfsi"
        assert set(run["values"]) == set(run["theta0"]) == set(CONSTANT_NAMES)
        assert set(run["settings"]) >= NPFSI_SETTINGS
        assert set(run["timings"]) == {"total"}
    assert set(cli_json["timings"]) == {"equation_error", "output_error", "npfsi", "validation", "total"}
    v = cli_json["validation"]  # no held-out log given: validated in-sample, and the file says so
    assert "in-sample" in v["data"] or "training" in v["data"], v["data"]
    assert set(v["whiteness"]) == set(v["input_independence"]) == set(AXES)
    json.dumps(cli_json, allow_nan=False)  # plain JSON, no NaN tokens


def test_identify_json_numbers_are_the_results_attributes(outcome, model):
    d = json.loads(json.dumps(outcome.to_dict(), allow_nan=False))
    for method in ("equation_error", "output_error"):
        fit, out = getattr(outcome, method), d[method]
        assert out["method"] == fit.method == method
        assert list(out["parameters"]) == list(fit.names)
        for k in fit.names:
            entry = out["parameters"][k]
            assert entry["value"] == fit.values[k]
            assert entry["stderr"] == fit.stderr[k]
            assert entry["stderr_naive"] == fit.stderr_naive[k]
            assert entry["initial"] == fit.initial[k]
            assert entry["unit"] == UNITS[k]
        assert_array_equal(out["covariance"], fit.covariance)
        assert_array_equal(out["correlation"], fit.correlation)
        assert out["residual_rms"] == dict(fit.residual_rms)
        for key in ("residual_unit", "n_samples", "n_residuals", "chi_square", "reduced_chi_square"):
            assert out[key] == getattr(fit, key), key
        for key in ("hac_frequencies", "success", "status", "message", "iterations"):
            assert out[key] == getattr(fit, key), key
        assert out["sources"] == list(fit.sources) == [str(outcome.sources[0])]
        assert out["timings"] == dict(fit.timings)
        assert out["settings"] == jsonable(dict(fit.settings))
        assert out["fixed"] == dict(fit.fixed) == {}
    # output error starts from the equation-error fit identify already has (not a second one)
    assert dict(outcome.output_error.initial) == dict(outcome.equation_error.values)
    assert outcome.output_error.timings["initial_fit"] == 0.0
    # the best fit (equation error, converged) gives the identified constants
    assert outcome.best is outcome.equation_error
    for k in CONSTANT_NAMES:
        assert d["identified_constants"][k] == outcome.equation_error.values[k]
        assert d["base_constants"][k] == getattr(model.constants, k)
    assert d["identified_constants"]["source"].startswith("identified (equation_error)")
    assert d["estimate"] == list(CONSTANT_NAMES)
    t = d["timings"]
    parts = ("equation_error", "output_error", "npfsi", "validation")
    assert t["total"] == pytest.approx(sum(t[k] for k in parts), rel=1e-12)


def test_each_stage_of_identify_is_timed_within_the_calls_own_wall_time(timed_outcome):
    """Every stage's wall time is positive, and they add up to no more than the call took (measured
    around it): a stage timed from the wrong origin, or a clock added instead of subtracted, is
    off by the machine's uptime."""
    outcome, wall = timed_outcome
    t = outcome.to_dict()["timings"]
    parts = ("equation_error", "output_error", "npfsi", "validation")
    assert all(0 < t[k] <= wall for k in parts), (t, wall)
    assert t["total"] <= wall


def _same_but_timings(a: dict, b: dict) -> bool:
    """Equal except wall times, anywhere in the nesting."""
    if isinstance(a, dict) and isinstance(b, dict):
        return set(a) == set(b) and all(k == "timings" or _same_but_timings(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same_but_timings(x, y) for x, y in zip(a, b, strict=True))
    return a == b


def test_cli_json_equals_to_dict_except_wall_times(outcome, cli_json):
    # Both fits are deterministic (one linear solve; Gauss-Newton from it), so the file the command
    # line wrote and the in-process result agree to the last bit except for the wall times.
    d = json.loads(json.dumps(outcome.to_dict()))
    cli_json = dict(cli_json)  # a module-scoped fixture: other tests read the stage
    stage = cli_json.pop("stage")  # the stage file: what identify found, read back by --params
    assert [stage["constants"][k] for k in CONSTANT_NAMES] == [
        d["identified_constants"][k] for k in CONSTANT_NAMES
    ]
    assert _same_but_timings(d, cli_json)
    for method in ("equation_error", "output_error"):
        assert set(d[method]["timings"]) == set(cli_json[method]["timings"])


def test_npfsi_json_round_trips_the_result(outcome, twin_log, model):
    d = json.loads(json.dumps(outcome.to_dict(), allow_nan=False))
    assert len(outcome.npfsi) == len(EPS)
    for run, out, eps in zip(outcome.npfsi, d["npfsi"], EPS, strict=True):
        assert run.success and run.status == "completed"
        assert out["eps"] == run.eps == eps
        assert out["gamma"] == run.gamma
        assert out["values"] == dict(run.values)
        # the values are the end of the trajectory, named in order
        assert_array_equal([run.values[k] for k in run.names], run.trajectory[:, -1])
        nominal = dict(zip(CONSTANT_NAMES, model.constants.as_array(), strict=True))
        assert out["theta0"] == dict(run.theta0) == nominal  # the model's constants
        assert out["Q"] is None and run.Q is None
        # Sigma(0): the default, DEFAULT_Q0_SECONDS times the diagonal of the mean A'A
        q0 = np.asarray(out["Q0"])
        assert_array_equal(q0, run.Q0)
        assert q0.shape == (4, 4) and np.all(np.diag(q0) > 0)
        assert_array_equal(q0 - np.diag(np.diag(q0)), 0.0)
        s = out["settings"]
        assert s["rows"] == 2  # the two velocity rows (x2', x4')
        assert s["sample_time_s"] == pytest.approx(twin_log.sample_time, rel=1e-9)
        assert s["Q0_default_seconds"] == DEFAULT_Q0_SECONDS
        assert out["sources"] == [str(outcome.sources[0])]
        assert out["status"] == run.status and out["success"] == run.success
        assert out["timings"] == dict(run.timings)


def test_a_failed_fit_is_still_plain_json(shooting, ee_fit):
    failed = shooting.fit(initial=ee_fit, max_iterations=1)
    assert not failed.success
    json.dumps(failed.to_dict(), allow_nan=False)


def test_identify_passes_its_options_to_every_method(model, twin_log):
    # input_delay shifts the currents for every method, NPFSI included (identify's docstring);
    # npfsi_gamma and npfsi_eps reach the estimator.
    out = identify(
        twin_log,
        model,
        methods=("equation_error", "npfsi"),
        npfsi_eps=(0.05,),
        npfsi_gamma=1.2,
        input_delay=0.002,
    )
    assert out.output_error is None and out.equation_error.settings["input_delay_s"] == 0.002
    (run,) = out.npfsi
    assert (run.eps, run.gamma) == (0.05, 1.2)
    shifted = dataclasses.replace(twin_log, u=delayed_inputs(twin_log, 0.002))
    by_hand = npfsi(shifted, model, eps=0.05, gamma=1.2)
    assert_array_equal(run.trajectory, by_hand.trajectory)
    assert not np.array_equal(run.trajectory, npfsi(twin_log, model, eps=0.05, gamma=1.2).trajectory)
    assert set(out.timings) == {"equation_error", "npfsi", "validation", "total"}


# --- NpfsiResult ----------------------------------------------------------------------------------------
def _npfsi_result(trajectory, names=None) -> NpfsiResult:
    """A result with a given trajectory; t starts at 2 s so that 'the first sample' is not 0."""
    traj = np.atleast_2d(np.asarray(trajectory, dtype=float))
    p, n = traj.shape
    names = tuple(names) if names else tuple(f"p{k}" for k in range(p))
    return NpfsiResult(
        names=names,
        t=2.0 + 0.5 * np.arange(n),
        trajectory=traj,
        values=dict(zip(names, traj[:, -1], strict=True)),
        eps=0.01,
        gamma=1.1,
        Q=None,
        Q0=np.eye(p),
        theta0=dict(zip(names, traj[:, 0], strict=True)),
        sigma_final=np.eye(p),
        velocity_method="given",
        success=True,
        status="completed",
        message="completed",
        timings={"total": 0.0},
    )


def test_settling_time_is_the_first_sample_when_never_outside_the_band():
    # t = 2.0, 2.5, ...: never outside -> the first sample's time, not 0 and not the last
    assert _npfsi_result([100.0] * 5).settling_time("p0") == 2.0
    assert _npfsi_result([100.5, 99.5, 100.9, 100.0]).settling_time("p0") == 2.0


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_settling_band_is_relative_to_the_final_value_and_inclusive(sign):
    # band * |final| = 0.01 * 100 = 1 exactly; |101 - 100| = |99 - 100| = 1 exactly: on the band
    # edge is within it ("stays within band"), so only the first sample (105) is outside.
    r = _npfsi_result(sign * np.array([105.0, 101.0, 99.0, 100.5, 100.0]))
    assert r.settling_time("p0") == 2.5  # the sample after the last one outside
    assert r.settling_time("p0", band=0.0099) == 3.5  # 101 and 99 now outside, 100.5 not
    assert r.settling_time("p0", band=0.004) == 4.0  # 100.5 outside too


def test_settling_time_follows_the_last_excursion():
    assert _npfsi_result([100, 100, 150, 100, 100]).settling_time("p0") == 3.5
    # outside at the second-to-last sample: settles at the last
    assert _npfsi_result([100, 100, 100, 150, 100]).settling_time("p0") == 4.0
    # each parameter by its own trajectory
    r = _npfsi_result([[100, 150, 100, 100], [5, 5, 5, 9]], names=("a", "b"))
    assert r.settling_time("a") == 3.0 and r.settling_time("b") == 3.5


def test_npfsi_report_compares_with_truth_only_for_the_keys_it_has():
    r = _npfsi_result([[1.0, 1.1], [3.0, 2.0], [1.0, 0.5]], names=("a", "b", "c"))
    text = r.report({"a": 1.0, "c": 0.0})
    lines = {k: next(line for line in text.splitlines() if line.startswith(f"    {k}:")) for k in "abc"}
    # a: 100 (1.1 - 1) / 1 = +10 %; b: no truth given; c: truth 0, no percentage
    assert "truth 1, error +10%" in lines["a"]
    assert "truth" not in lines["b"] and "truth" not in lines["c"]
    for k in ("a", "b", "c"):
        assert f"{r.values[k]:14.7g}  (init = {r.theta0[k]:.6g}, " in lines[k]  # final value, then start
        assert f"1 % band from t = {r.settling_time(k):.2f} s" in lines[k]
    assert "truth" not in r.report()  # no truth, no comparison
    assert "truth" not in r.report({"zzz": 1.0})


def test_fit_report_lists_correlations_from_one_tenth_up_in_order(ee_fit):
    # "[[Correlations]] (unreported correlations are < 0.100)": |c| = 0.1 is reported, 0.0999 is
    # not, and the list runs from the largest |c| down.
    c = np.eye(4)
    pairs = {(0, 1): 0.1, (0, 2): -0.0999, (0, 3): -0.7, (1, 2): 0.35, (1, 3): 0.0, (2, 3): -0.25}
    for (i, j), v in pairs.items():
        c[i, j] = c[j, i] = v
    text = dataclasses.replace(ee_fit, correlation=c).report()
    listed = text.split("[[Correlations]]")[1].splitlines()[1:]
    assert listed == [
        "    C(C1, C4) = -0.7000",
        "    C(C2, C3) = +0.3500",
        "    C(C3, C4) = -0.2500",
        "    C(C1, C2) = +0.1000",
    ]


# --- equilibrium currents -------------------------------------------------------------------------------
def test_compare_equilibrium_currents_every_field(model):
    gaps = np.array([0.010, 0.015, 0.020, 0.024, 0.025])
    measured = np.array([5.0, 3.5, 1.4, 0.3, -0.2])
    cmp = compare_equilibrium_currents(model, gaps, measured, small_current=0.3)
    assert_array_equal(cmp.gap, gaps)
    assert_array_equal(cmp.measured, measured)
    assert cmp.small_current == 0.3
    # predicted: the current that holds the gap, x2' = 0 at rest with u1 = 0 (the model's own
    # dynamics, not the closed form); f is O(10) m/s^2 per A, so 1e-9 is round-off.
    for g, i in zip(gaps, cmp.predicted, strict=True):
        acc = np.asarray(model.f([g, 0.0, 0.0, 0.0], [0.0, i])).ravel()
        assert abs(acc[1]) < 1e-9, (g, i, acc)
        assert abs(i) < 9.0  # the physical (small-magnitude) root, SPEC 1 note 5
    # SPEC 1: about +5.3 A at 10 mm, +3.3 at 15, +1.5 at 20, -0.2 at 25 (one decimal printed)
    assert_allclose(cmp.predicted[[0, 1, 2, 4]], [5.3, 3.3, 1.5, -0.2], atol=0.05)
    assert_array_equal(cmp.error, cmp.predicted - measured)  # predicted - measured, signed
    # percent: 100 |error| / |measured| where |measured| >= small_current (0.3 itself included)
    expected = np.where(np.abs(measured) >= 0.3, 100 * np.abs(cmp.error) / np.abs(measured), np.nan)
    assert_allclose(cmp.error_pct, expected, rtol=1e-15, equal_nan=True)
    assert np.isfinite(cmp.error_pct[3]) and np.isnan(cmp.error_pct[4])
    assert cmp.max_pct(0.015, 0.020) == pytest.approx(max(expected[1], expected[2]), rel=1e-15)
    with pytest.raises(InputError, match="shape"):
        compare_equilibrium_currents(model, gaps, measured[:3])


# --- EquationError ----------------------------------------------------------------------------------------
def test_sample_window_up_to_the_last_sample_is_the_whole_log(ee_problem, ee_fit, twin_log):
    n, edge = twin_log.n, ee_problem.prepared.edge
    assert_array_equal(ee_problem.fit((0, n)).vector(), ee_fit.vector())
    assert ee_fit.n_samples == n - 2 * edge  # everything but the filters' edges
    # a window inside the valid part fits exactly its samples (start included, stop excluded),
    # said three ways: (start, stop), a slice and a boolean mask
    mask = np.zeros(n, dtype=bool)
    mask[1000:4000] = True
    by_tuple = ee_problem.fit((1000, 4000))
    assert by_tuple.n_samples == 3000
    assert_array_equal(ee_problem.fit(slice(1000, 4000)).vector(), by_tuple.vector())
    assert_array_equal(ee_problem.fit(mask).vector(), by_tuple.vector())
    fitted = np.flatnonzero(np.isfinite(by_tuple.residuals[0][0]))
    assert (fitted[0], fitted[-1]) == (1000, 3999)


@pytest.mark.parametrize("window", [(0, 6001), (-1, 3000), (3000, 3000), (4000, 3000)])
def test_sample_window_outside_the_log_is_refused_naming_it(ee_problem, twin_log, window):
    assert twin_log.n == 6000
    with pytest.raises(InputError) as info:
        ee_problem.fit(window)
    msg = str(info.value)
    assert twin_log.source in msg and f"({window[0]}, {window[1]})" in msg and "6000" in msg


def test_sample_specs_of_every_log_are_checked(model, halves):
    a, b = halves
    problem = EquationError([a, b], model)
    assert problem.fit([(0, a.n), None]).n_samples > 0  # up to the last sample: accepted
    with pytest.raises(InputError, match="one entry per log"):
        problem.fit((0, a.n))
    with pytest.raises(InputError, match=r"first\.csv"):
        problem.fit([(0, a.n + 1), None])
    with pytest.raises(InputError, match=r"second\.csv"):
        problem.fit([None, (0, b.n + 1)])
    with pytest.raises(InputError, match=r"second\.csv"):
        problem.fit([None, np.ones(b.n + 1, dtype=bool)])


def test_residuals_of_a_partial_estimate_are_the_fits(model, twin_log):
    # C1 held at the model's value: residuals(fit) recomputes the fitted residuals from the
    # estimated set alone (same filtered columns, same arithmetic: equal to round-off).
    problem = EquationError(twin_log, model, estimate=("C2", "C3", "C4"))
    fit = problem.fit()
    assert fit.names == ("C2", "C3", "C4") and dict(fit.fixed) == {"C1": model.constants.C1}
    assert fit.to_dict()["fixed"] == {"C1": model.constants.C1}
    r = problem.residuals(fit)
    assert len(r) == len(fit.residuals) == 1
    used = np.isfinite(fit.residuals[0])
    assert np.all(np.isfinite(r[0][used]))  # every fitted sample is a valid one
    scale = np.nanmax(np.abs(fit.residuals[0]))
    assert_allclose(r[0][used], fit.residuals[0][used], rtol=0, atol=1e-9 * scale)
    by_name = problem.residuals({k: fit.values[k] for k in fit.names})
    assert_array_equal(by_name[0], r[0])
    assert_array_equal(problem.residuals(fit.vector())[0], r[0])
    with pytest.raises(InputError, match="C2"):
        problem.residuals({"C3": 1.0, "C4": 1.0})


def test_output_errors_per_sample_influences_are_on_the_scale_of_the_plain_covariance(
    model, twin_log, monkeypatch
):
    """The long-run covariance of output error sums, over frequencies, the spectra of each time
    sample's influence on the constants (both axes' residuals at that instant together). At lag 0
    those influences give the heteroskedasticity-robust sandwich sum_t s_t s_t', which estimates
    the same variance as the plain s^2 (J'J)^-1 when the residuals' size does not follow the
    Jacobian's: measured 0.96-1.44 of it on this log. Bounds: a factor 2 either way; an influence
    that counts one axis only, or averages the two axes instead of adding them (1/4), is outside."""
    import maglev_oc.identification.output_error as oe

    seen = {}
    original = oe.long_run_covariance

    def spy(influence, naive, sample_time, **kw):
        seen["influence"], seen["naive"] = influence, naive
        return original(influence, naive, sample_time, **kw)

    monkeypatch.setattr(oe, "long_run_covariance", spy)
    fit = oe.fit_output_error(twin_log, model)
    assert fit.success, fit.message
    sandwich = sum(d @ d.T for d in seen["influence"])
    ratio = np.diag(sandwich) / np.diag(seen["naive"])
    assert np.all((ratio > 0.5) & (ratio < 2.0)), dict(zip(fit.names, ratio, strict=True))
    # and the plain covariance is the one reported beside the long-run one
    assert_allclose(np.sqrt(np.diag(seen["naive"])), [fit.stderr_naive[k] for k in fit.names], rtol=1e-12)


@pytest.mark.parametrize("which", ["full", "partial", "output_error"])
def test_covariance_fields_are_consistent(model, twin_log, ee_fit, shooting_fit, which):
    if which == "partial":
        fit = EquationError(twin_log, model, estimate=("C1", "C3")).fit()
    else:
        fit = ee_fit if which == "full" else shooting_fit
    assert fit.success, fit.message
    se = np.array([fit.stderr[k] for k in fit.names])
    naive = np.array([fit.stderr_naive[k] for k in fit.names])
    cov = fit.covariance
    assert np.all(np.isfinite(cov)) and np.all(se > 0) and np.all(naive > 0)
    assert_allclose(cov, cov.T, rtol=0, atol=1e-12 * np.max(np.abs(cov)))  # symmetric to round-off
    assert_allclose(np.diag(cov), se**2, rtol=1e-12)
    assert_allclose(fit.correlation, cov / np.outer(se, se), rtol=1e-9, atol=1e-12)
    assert_allclose(np.diag(fit.correlation), 1.0, rtol=1e-12)
    # variance inflation = HAC variance / plain variance, per parameter (FitResult docstring)
    infl = np.array([fit.variance_inflation[k] for k in fit.names])
    assert np.all(np.isfinite(infl)) and np.all(infl > 0)
    assert_allclose(infl, (se / naive) ** 2, rtol=1e-10)
    # the counts and RMS describe the residuals the fit carries
    res = np.concatenate(fit.residuals, axis=1)
    used = np.all(np.isfinite(res), axis=0)
    assert fit.n_samples == int(used.sum())
    assert fit.n_residuals == 2 * fit.n_samples  # both axes
    for k, axis in enumerate(AXES):
        assert fit.residual_rms[axis] == pytest.approx(np.sqrt(np.mean(res[k, used] ** 2)), rel=1e-12)
    # chi-square: the weighted residuals' sum of squares; equation error weights each axis (settings),
    # output error divides by one encoder count. Reduced: per degree of freedom, n_residuals - p for
    # the equation error (lmfit's redchi). The linear solver forms chi-square from the normal
    # equations, which loses ~1e-10 relative to the direct sum (measured 1.5e-10).
    if fit.method == "equation_error":
        w = np.array([fit.settings["axis_weights"][a] for a in AXES])
        assert fit.reduced_chi_square == pytest.approx(
            fit.chi_square / (fit.n_residuals - len(fit.names)), rel=1e-12
        )
    else:
        w = np.full(2, 1 / fit.settings["residual_scale_m"])
    rms = np.array([fit.residual_rms[a] for a in AXES])
    assert fit.chi_square == pytest.approx(fit.n_samples * np.sum((w * rms) ** 2), rel=1e-8)


def test_plain_standard_errors_are_the_residual_variance_times_the_inverse_gram(model, twin_log):
    # Without the errors-in-variables correction the fit is weighted least squares on the
    # filtered columns: stderr_naive^2 = s^2 diag((X'WX)^-1), s^2 = weighted residual sum of
    # squares / (N - p), recomputed here from the fit's own residuals and weights.
    problem = EquationError(twin_log, model, logging_error=False)
    fit = problem.fit()
    w = np.array([fit.settings["axis_weights"][a] for a in AXES])
    res = fit.residuals[0]
    used = np.all(np.isfinite(res), axis=0)
    chi2 = float(np.sum((w[:, None] * res[:, used]) ** 2))
    s2 = chi2 / (2 * int(used.sum()) - len(fit.names))
    design = build_design(problem.prepared, model, estimate=problem.estimate, fit=used, weights=w)
    X = (design.columns[:, :, used] * w[None, :, None]).reshape(len(fit.names), -1)
    expected = np.sqrt(s2 * np.diag(np.linalg.inv(X @ X.T)))
    # measured agreement 8e-11 (chi-square from the normal equations); the Gram's condition is
    # 1.6e6 (C2..C4 correlated up to 0.97), so 1e-7 is round-off headroom, not a model error
    assert_allclose([fit.stderr_naive[k] for k in fit.names], expected, rtol=1e-7)


def test_input_delay_shifts_the_currents(model, twin_log, ee_fit):
    # input_delay = d fits the model to the currents delayed by d (regression.data.delayed_inputs,
    # linear interpolation): the same fit as on a log whose currents were shifted beforehand.
    delayed = EquationError(twin_log, model, input_delay=0.002).fit()
    assert delayed.success and delayed.settings["input_delay_s"] == 0.002
    assert ee_fit.settings["input_delay_s"] == 0.0
    shifted = dataclasses.replace(twin_log, u=delayed_inputs(twin_log, 0.002))
    by_hand = EquationError(shifted, model).fit()
    assert_allclose(delayed.vector(), by_hand.vector(), rtol=1e-12)  # same arithmetic
    assert not np.allclose(delayed.vector(), ee_fit.vector(), rtol=1e-6, atol=0)  # and not ignored
    for bad in (-1e-3, 0.01, math.nan):
        with pytest.raises(InputError, match="input_delay"):
            EquationError(twin_log, model, input_delay=bad)


# --- several logs ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("position", [1, 2])
@pytest.mark.parametrize("method", ["equation_error", "output_error"])
def test_a_log_at_another_rate_is_refused_wherever_it_is(model, twin_log, position, method):
    thirds = [
        dataclasses.replace(twin_log.index_slice(k * 2000, (k + 1) * 2000), source=f"log{k}.csv")
        for k in range(3)
    ]
    thirds[position] = _slower(thirds[position], f"slow{position}.csv")
    cls = EquationError if method == "equation_error" else MultipleShooting
    with pytest.raises(InputError, match="different rates") as info:
        cls(thirds, model)
    assert f"slow{position}.csv" in str(info.value)


def test_multiple_shooting_uses_every_log(shooting, shooting_fit, halves):
    fit = shooting_fit
    assert fit.success and fit.status == "converged", fit.message
    assert fit.method == "output_error"
    assert fit.sources == ("first.csv", "second.csv")
    M = shooting.M
    segments = [(log.n - 1) // M for log in halves]
    assert fit.settings["segments"] == segments
    assert fit.n_samples == sum(J * M for J in segments)
    assert len(fit.residuals) == 2
    for res, log, J in zip(fit.residuals, halves, segments, strict=True):
        assert res.shape == (2, log.n)
        assert np.all(np.isfinite(res[:, : J * M])) and np.all(np.isnan(res[:, J * M :]))
    res = np.concatenate(fit.residuals, axis=1)
    for k, axis in enumerate(AXES):
        assert fit.residual_rms[axis] == pytest.approx(np.sqrt(np.nanmean(res[k] ** 2)), rel=1e-12)
    # a few encoder counts: the fit follows both logs (10 um quantization + 2 um noise)
    assert max(fit.residual_rms.values()) < 2 * ENCODER_RESOLUTION


def test_multiple_shooting_status_and_timings(shooting, shooting_fit, ee_fit):
    t = shooting_fit.timings
    assert set(t) == TIMINGS["output_error"]
    assert all(isinstance(v, float) and v >= 0 for v in t.values())
    parts = sum(v for k, v in t.items() if k != "total")
    assert t["total"] >= parts - 1e-9  # the parts are disjoint stretches of the total
    assert t["prepare"] == shooting.prepare_time and t["initial_fit"] == 0.0  # initial given
    for step in ("prepare", "simulate_and_linearize", "kkt_solves", "covariance"):
        assert t[step] > 0, step  # each step did work (perf_counter resolves nanoseconds)
    assert shooting_fit.iterations >= 1
    # stopped early: a result that says so, not an exception or a half-set one
    early = shooting.fit(initial=ee_fit, max_iterations=1)
    assert early.status == "iteration_limit" and early.success is False
    assert "maximum iterations" in early.message
    assert early.iterations == 1
    assert set(early.timings) == TIMINGS["output_error"]
    assert np.all(np.isnan(early.correlation)) and all(math.isnan(v) for v in early.stderr.values())
    assert early.status in FIT_STATUS and shooting_fit.status in FIT_STATUS


# --- check_identifiable -------------------------------------------------------------------------------------
def _synthetic(source: str, *, vertical: bool, horizontal: bool, duration: float = 6.0) -> Log:
    """A log that moves on the chosen axes only (0.5 Hz sines well above the resolutions)."""
    t = np.arange(0, duration, 1e-3)
    s = np.sin(2 * np.pi * 0.5 * t)
    x = np.full((4, t.size), np.nan)
    x[0] = 0.02 + (1e-3 * s if vertical else 0.0)
    x[2] = 0.03 * s if horizontal else 0.0
    u = np.vstack([0.5 * s if horizontal else 0.0 * t, 1.5 + (0.5 * s if vertical else 0.0 * t)])
    return Log(t, x, u, source=source)


def test_no_log_moving_on_a_needed_axis_is_named():
    v1 = _synthetic("v1.csv", vertical=True, horizontal=False)
    v2 = _synthetic("v2.csv", vertical=True, horizontal=False)
    check_identifiable([v1, v2], ("C2", "C3", "C4"))
    with pytest.raises(LogError) as info:
        check_identifiable([v1, v2], CONSTANT_NAMES)
    msg = str(info.value)
    assert info.value.source == "v1.csv, v2.csv"
    assert re.search(r"no log moves horizontally \(x3 and u1 constant .*\) but C1 needs it", msg), msg
    h = _synthetic("h.csv", vertical=False, horizontal=True)
    with pytest.raises(LogError) as info:
        check_identifiable([h], ("C1", "C2", "gap_offset"))
    msg = str(info.value)
    assert info.value.source == "h.csv"
    wanted = r"no log moves vertically \(x1 and u2 constant .*\) but C2, gap_offset need it"
    assert re.search(wanted, msg), msg
    check_identifiable([v1, h], CONSTANT_NAMES)  # together they excite both axes
    # an axis needs both of its signals: x3 moving with u1 = 0 (pushed by hand) is no excitation
    x = v1.x.copy()
    x[2] = h.x[2]
    pushed = dataclasses.replace(v1, x=x, source="pushed.csv")
    with pytest.raises(LogError, match="no log moves horizontally"):
        check_identifiable([pushed], CONSTANT_NAMES)


def test_a_log_moving_on_no_needed_axis_is_refused_by_name_among_good_ones():
    v1 = _synthetic("v1.csv", vertical=True, horizontal=False)
    still = _synthetic("still.csv", vertical=False, horizontal=False)
    with pytest.raises(LogError, match="no excitation") as info:
        check_identifiable([v1, still], ("C2", "C3"))
    assert info.value.source == "still.csv"
    assert "vertical (x1 and u2 = i_d must vary for C2, C3)" in str(info.value)
    assert info.value.column == "x1"  # the first signal that does not move


def test_a_log_of_exactly_the_minimum_duration_is_accepted():
    # MIN_DURATION = 5 s: 5000 samples at 1 kHz cover exactly 5.0 s (t = 0 to 4.999 s, each sample
    # standing for its millisecond), as a 5 s recording at 1 kHz has them
    long_enough = _synthetic("five.csv", vertical=True, horizontal=True, duration=5.0005).index_slice(0, 5000)
    assert long_enough.recorded == pytest.approx(5.0, rel=1e-12) and long_enough.duration < 5.0
    check_identifiable([long_enough], CONSTANT_NAMES)
    short = dataclasses.replace(long_enough.index_slice(0, 4999), source="short.csv")  # 4.999 s
    with pytest.raises(LogError, match=r"too short for identification: 4.999 s \(4999 samples\)") as info:
        check_identifiable([long_enough, short], CONSTANT_NAMES)
    assert info.value.source == "short.csv" and "at least 5 s" in str(info.value)
    check_identifiable([short], CONSTANT_NAMES, min_duration=4.0)  # the option is used


def test_too_short_message_shows_a_duration_below_the_minimum():
    short = _synthetic("short.csv", vertical=True, horizontal=True, duration=4.9985)  # 4999 samples
    assert short.recorded < 5.0
    with pytest.raises(LogError) as info:
        check_identifiable([short], CONSTANT_NAMES)
    shown = float(re.search(r"identification: ([0-9.]+) s", str(info.value)).group(1))
    assert shown < 5.0, str(info.value)


# --- NPFSI input checks ----------------------------------------------------------------------------------
def _npfsi_data(n: int = 50):
    rng = np.random.default_rng(0)
    A = rng.standard_normal((n, 1, 2))
    b = rng.standard_normal((n, 1))
    y = rng.standard_normal((n, 1))
    return A, b, y


@pytest.mark.parametrize("bad", [math.nan, math.inf])
@pytest.mark.parametrize("which", [0, 1, 2])
def test_npfsi_refuses_non_finite_data_in_any_input(which, bad):
    data = list(_npfsi_data())
    est = NpfsiEstimator(0.01)
    assert est.run(*data, 1e-3, [1.0, 1.0]).success  # the clean data run
    data[which] = data[which].copy()
    data[which].flat[7] = bad
    with pytest.raises(InputError, match="must be finite"):
        est.run(*data, 1e-3, [1.0, 1.0])


def test_npfsi_initial_sigma_names_the_parameters_without_information():
    A, b, y = _npfsi_data()
    A[:, :, 1] = 0.0
    est = NpfsiEstimator(0.01)
    with pytest.raises(InputError, match="no information") as info:
        est.run(A, b, y, 1e-3, [1.0, 1.0], names=("alpha", "beta"))
    assert "'beta'" in str(info.value) and "alpha" not in str(info.value)
    A[:, :, 0] = 0.0
    with pytest.raises(InputError) as info:
        est.run(A, b, y, 1e-3, [1.0, 1.0], names=("alpha", "beta"))
    assert "'alpha'" in str(info.value) and "'beta'" in str(info.value)
    # with Sigma(0) given, the estimator runs (and keeps the given matrix)
    run = NpfsiEstimator(0.01, Q0=np.eye(2)).run(A, b, y, 1e-3, [1.0, 1.0], names=("alpha", "beta"))
    assert_array_equal(run.Q0, np.eye(2)) and run.settings["Q0_default_seconds"] is None


# --- constrained Gauss-Newton ----------------------------------------------------------------------------
def test_gauss_newton_reports_a_failed_line_search():
    # The Jacobian has the wrong sign, so every step goes uphill: the merit 0.5 (1 + alpha)^2
    # never decreases and the search gives up at the start, which it returns unchanged.
    def linearize(w):
        return (
            np.array([w[0]]),
            np.array([w[1]]),
            sp.csc_matrix([[-1.0, 0.0]]),
            sp.csc_matrix([[0.0, 1.0]]),
        )

    out = constrained_gauss_newton(linearize, np.array([1.0, 0.0]), np.ones(2))
    assert out.status == "line_search_failed" and out.success is False
    assert "line search" in out.message
    assert out.iterations == 1
    assert_array_equal(out.w, [1.0, 0.0])
    assert_array_equal(out.r, [1.0])  # the linearization where it stopped
    assert set(out.timings) == {"linearize", "kkt_solves"}


def test_gauss_newton_solves_a_constrained_least_squares_problem():
    # min |X w - y|^2 s.t. w0 + w1 + w2 = 1: one Gauss-Newton step is exact; the answer is the KKT
    # solution computed here directly. Scaled variables (scale 2) must not change it.
    rng = np.random.default_rng(1)
    X, y = rng.standard_normal((20, 3)), rng.standard_normal(20)
    C, d = np.ones((1, 3)), np.array([1.0])
    scale = np.full(3, 2.0)

    def linearize(w):
        return X @ w - y, C @ w - d, sp.csc_matrix(X * scale), sp.csc_matrix(C * scale)

    out = constrained_gauss_newton(linearize, np.zeros(3), scale)
    kkt = np.block([[X.T @ X, C.T], [C, np.zeros((1, 1))]])
    w_star = np.linalg.solve(kkt, np.concatenate([X.T @ y, d]))[:3]
    assert out.status == "converged" and out.success, out.message
    assert_allclose(out.w, w_star, rtol=1e-10, atol=1e-12)  # a 3x3 solve: round-off
    assert abs(out.c[0]) < 1e-12
    stopped = constrained_gauss_newton(linearize, np.zeros(3), scale, max_iterations=1)
    assert stopped.status == "iteration_limit" and not stopped.success
    assert "maximum iterations" in stopped.message


# --- twin experiments --------------------------------------------------------------------------------------
def test_excitation_log_seed_is_used(model, truth_model):
    def run(seed, **kw):
        return excitation_log(truth_model, duration=1.0, seed=seed, controller_model=model, **kw)

    a, again, other = run(1), run(1), run(2)
    for field in ("t", "x", "u"):
        assert_array_equal(getattr(a, field), getattr(again, field))  # same seed, same log
    assert not np.array_equal(a.x[0], other.x[0]) and not np.array_equal(a.u, other.u)
    assert a.metadata["seed"] == "1" and a.source == "twin:excitation:seed1"
    assert other.source.endswith("seed2")
    # locked horizontally: x3 stays at the lock to within one encoder count (10 um), the log says so
    locked = run(1, locked_position=0.01)
    assert np.max(np.abs(locked.x[2] - 0.01)) <= ENCODER_RESOLUTION * (1 + 1e-9)
    assert locked.metadata["scenario"] == "excitation_vertical"
    assert a.metadata["scenario"] == "excitation"
    assert locked.metadata["experiment"] == "excitation_x3_10.000mm"
    assert_array_equal(locked.x[2], run(1, locked_position=0.01).x[2])


def test_fixed_gap_runs_hold_a_constant_current_and_use_the_seed(truth_model):
    def run(seed):
        return fixed_gap_logs(truth_model, gaps=(0.015,), seed=seed)[0]

    a, again, other = run(3), run(3), run(4)
    assert_array_equal(a.x[0], again.x[0])
    assert_array_equal(a.x[2], again.x[2])
    assert not np.array_equal(a.x[0], other.x[0])  # another seed, other encoder noise
    assert_array_equal(a.u[0], -0.5)  # u1 = current (default -0.5 A), u2 = 0 throughout
    assert_array_equal(a.u[1], 0.0)
    assert np.max(np.abs(a.x[0] - 0.015)) <= ENCODER_RESOLUTION * (1 + 1e-9)  # gap locked
    assert a.x[2, 0] < -0.045 and a.x[2, -1] <= 0.05  # from rest near -50 mm, cut at +50 mm


def test_constant_current_follows_the_controller_protocol(model):
    cc = ConstantCurrent((0.7, -1.2))
    assert isinstance(cc, ExpressionController)
    pid = paper_pid(model)
    assert cc.step.name_in() == pid.step.name_in()
    assert cc.step.name_out() == pid.step.name_out()
    rng = np.random.default_rng(2)
    for _ in range(3):
        c = rng.standard_normal(1)
        u, c_next, diag = cc.step(c, rng.standard_normal(2), rng.standard_normal(6))
        assert_array_equal(np.asarray(u).ravel(), [0.7, -1.2])  # whatever it measures
        assert_array_equal(np.asarray(c_next).ravel(), c)
        assert np.asarray(diag).size == len(cc.diag_names) == 0


# --- ParameterLayout ----------------------------------------------------------------------------------------
@pytest.mark.parametrize(("bad", "type_name"), [("drag", "str"), (3, "int"), ({"name": "x"}, "dict")])
def test_a_non_term_is_refused_naming_its_type(model, twin_log, bad, type_name):
    term = constant_acceleration("vertical")
    assert ParameterLayout(model, ("C2",), (term,)).names[-1].startswith(term.name)  # a real one is fine
    for make in (
        lambda: ParameterLayout(model, ("C2",), (term, bad)),
        lambda: EquationError(twin_log, model, terms=(bad,)),
        lambda: MultipleShooting(twin_log, model, terms=(bad,)),
    ):
        with pytest.raises(TypeError, match=rf"AccelerationTerm, got {type_name}\b"):
            make()
    with pytest.raises(TypeError, match="StageModel, got str"):
        ParameterLayout("model", ("C2",))


def test_fit_report_gives_each_parameter_its_own_unit_and_none_to_a_parameter_without_one(ee_fit):
    """Each [[Variables]] line ends with the parameter's SI unit in brackets (regression.base
    UNITS, the units the fit's constants are defined in), and a parameter without a known unit
    (here C4 renamed) gets no bracket rather than a made-up unit."""
    from maglev_oc.regression.base import UNITS

    text = ee_fit.report()
    for k in ee_fit.names:
        line = next(ln for ln in text.splitlines() if ln.startswith(f"    {k}"))
        assert line.endswith(f"  [{UNITS[k]}]"), line
    rename = {k: ("k_unitless" if k == "C4" else k) for k in ee_fit.names}

    def moved(m):
        return {rename[k]: v for k, v in m.items()}

    other = dataclasses.replace(
        ee_fit,
        names=tuple(rename[k] for k in ee_fit.names),
        values=moved(ee_fit.values),
        stderr=moved(ee_fit.stderr),
        stderr_naive=moved(ee_fit.stderr_naive),
        initial=moved(ee_fit.initial),
    )
    line = next(ln for ln in other.report().splitlines() if ln.startswith("    k_unitless"))
    assert "[" not in line, line


@pytest.mark.parametrize("which", ["equation_error", "output_error"])
def test_a_fit_result_is_read_only_and_reports_without_timings(ee_fit, shooting_fit, which):
    # a FitResult is what a script, a report and the diagnosis read: its arrays cannot be changed
    # through it (the covariance and correlation a report prints, the residuals), and its report
    # reads even a result rebuilt without timings (a missing total prints as nan, not a crash)
    import dataclasses

    fit = ee_fit if which == "equation_error" else shooting_fit
    for held in (fit.covariance, fit.correlation, *fit.residuals):
        assert not held.flags.writeable
    with pytest.raises(ValueError, match="read-only"):
        fit.covariance[0, 0] = 0.0
    bare = dataclasses.replace(fit, timings={})
    assert "wall time          = nan s" in bare.report()
