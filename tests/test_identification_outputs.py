"""What identification's results *write*, read against the objects that write it.

The computations of :mod:`maglev_oc.identification` are tested elsewhere; here the text of each
``report()`` and the JSON of each ``to_dict()`` are parsed back and compared with the object: a user
reads the report, a script (the CLI's JSON, ``write_design``'s ``design.json``, the stage file)
reads the dict. Most objects are built directly from chosen, deliberately "unround" numbers (fast,
and every field is known); one equation-error fit on the twin log checks a real object too.

Numbers in reports are compared to within half a unit of their last printed digit (see
:func:`printed_close`): that is the most any correct rounding can move a value, so a looser test would
let a wrong digit through and a tighter one would fail on correct output. JSON numbers are compared
exactly (a JSON round trip of a float is exact).
"""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from maglev_oc.identification.design import (
    REFERENCE_COLUMNS,
    REFERENCE_RATE_HZ,
    CurrentBudget,
    ExperimentDesign,
    MultisineShape,
    Prediction,
    SampledReference,
    TwinCheck,
)
from maglev_oc.identification.eps_trend import EpsTrend, EpsTrendStudy
from maglev_oc.identification.equation_error import EquationError
from maglev_oc.identification.layout import CONSTANT_NAMES, UNITS
from maglev_oc.identification.npfsi import PAPER_EPSILONS
from maglev_oc.identification.pipeline import IdentificationOutcome
from maglev_oc.identification.result import METHOD_TITLES, FitResult, NpfsiResult
from maglev_oc.results import AXES
from tests.test_identify_properties import OUTCOME_KEYS

NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|[-+]?(?:nan|inf)"


# --- helpers --------------------------------------------------------------------------------------
def printed_close(text: str, value: float) -> bool:
    """Is ``text`` (a number as printed) ``value`` rounded to the digits ``text`` shows?

    The tolerance is half a unit of the last printed digit (plus 1e-12 relative for the binary
    representation): e.g. "14.23" matches 14.2345 but not 14.24 or 1423.45."""
    text = text.strip()
    if text.lower().lstrip("+-") in ("nan", "inf"):
        return str(value).lower().lstrip("+-") == text.lower().lstrip("+-") and (
            text.startswith("-") == (value < 0) or math.isnan(value)
        )
    m = re.fullmatch(r"([-+]?)(\d*)\.?(\d*)(?:[eE]([-+]?\d+))?", text)
    assert m, f"not a number: {text!r}"
    decimals = len(m.group(3))
    exponent = int(m.group(4) or 0)
    half_unit = 0.5 * 10.0 ** (exponent - decimals)
    return abs(float(text) - value) <= half_unit * (1 + 1e-9) + 1e-12 * abs(value)


def assert_printed(text: str, value: float, what: str) -> None:
    assert printed_close(text, value), f"{what}: printed {text!r}, the object has {value!r}"


def line_after(report: str, label: str) -> str:
    """The rest of the (only) report line that holds ``label``."""
    hits = [ln for ln in report.splitlines() if label in ln]
    assert len(hits) == 1, f"{label!r} on {len(hits)} lines of\n{report}"
    return hits[0].split(label, 1)[1]


def roundtrip(d: dict) -> dict:
    """``d`` as a reader of the JSON gets it (and proof that it is JSON: no NaN, no arrays)."""
    return json.loads(json.dumps(d, allow_nan=False))


def js(x: float) -> float | None:
    """How a float appears in the JSON: NaN and infinities are null."""
    return float(x) if math.isfinite(x) else None


# --- objects ------------------------------------------------------------------------------------
NAMES = ("C1", "C2", "gap_offset", "friction.c")
CORR = np.array(
    [
        [1.0, -0.8765, 0.05, 0.2345],
        [-0.8765, 1.0, 0.4321, -0.0999],
        [0.05, 0.4321, 1.0, -0.1001],
        [0.2345, -0.0999, -0.1001, 1.0],
    ]
)
SE = np.array([0.0123456, 3.456789, 2.345678e-6, 0.0104321])


def make_fit(**changes) -> FitResult:
    """A four-parameter fit with values chosen so that every printed digit matters: a constant
    in the tens, one in the hundreds, a gap offset in micrometres and a term parameter of value 0
    (no relative error printed)."""
    kw = dict(
        method="equation_error",
        names=NAMES,
        values=dict(zip(NAMES, (14.23456789, 801.2345678, 1.2345678e-4, 0.0), strict=True)),
        stderr=dict(zip(NAMES, SE, strict=True)),
        stderr_naive=dict(zip(NAMES, (0.00654321, 1.987654, 1.234567e-6, 0.00876543), strict=True)),
        initial=dict(zip(NAMES, (14.2, 796.99, 0.0, 0.123456789), strict=True)),
        fixed={"C3": 31.0412345, "C4": 0.0712345},
        covariance=CORR * np.outer(SE, SE),
        correlation=CORR,
        residual_rms={"vertical": 0.0123456789, "horizontal": 2.3456789e-4},
        residual_unit="m/s^2",
        residuals=(np.zeros((2, 5)),),
        n_samples=1234,
        n_residuals=2468,
        chi_square=2345.67891,
        reduced_chi_square=0.987654321,
        hac_frequencies=17,
        variance_inflation=dict(zip(NAMES, (2.1, 3.2, 1.1, 1.0), strict=True)),
        success=True,
        status="converged",
        message="relative decrease below tolerance",
        iterations=7,
        timings={"prepare": 0.12345, "solve": 0.56789, "covariance": 0.01234, "total": 0.70368},
        sources=("run_a.csv", "run_b.csv"),
        settings={"differentiator": "savitzky_golay", "weights": [1.0, 2.5], "segment_s": 0.5},
    )
    kw.update(changes)
    return FitResult(**kw)


def make_npfsi(eps: float = 0.01, values=(14.3456789, 790.123456), success: bool = True, **changes):
    names = ("C1", "C2")
    t = np.arange(400) * 0.0025
    final = np.array(values, dtype=float)
    theta0 = np.array([12.3456789, 700.987654])
    # exponential approach from theta0, then a step inside the 1 % band at 0.5 s
    with np.errstate(invalid="ignore"):  # a diverged run's inf - inf
        traj = final[:, None] + (theta0 - final)[:, None] * np.exp(-t / 0.05)[None, :]
    traj[:, t < 0.5] *= 1.03
    kw = dict(
        names=names,
        t=t,
        trajectory=traj,
        values=dict(zip(names, final, strict=True)),
        eps=eps,
        gamma=1.1,
        Q=None,
        Q0=np.diag([1.5, 2.5]),
        theta0=dict(zip(names, theta0, strict=True)),
        sigma_final=np.diag([3.0, 4.0]),
        velocity_method="high_gain_observer",
        success=success,
        status="completed" if success else "diverged",
        message="ran to the end" if success else "Sigma blew up",
        timings={"total": 0.4567891},
        sources=("run_a.csv",),
        settings={"gamma": 1.1},
    )
    kw.update(changes)
    return NpfsiResult(**kw)


def make_prediction(log_det: float = 12.3456789, violations=()) -> Prediction:
    return Prediction(
        names=CONSTANT_NAMES,
        nominal=np.array([14.2, 796.99, 31.04, 0.07]),
        covariance=np.diag([0.0123456, 4.56789, 0.0345678, 1.23456e-5]) ** 2,
        log_det=log_det,
        peak_current=np.array([1.23456, 4.56789]),
        rms_current=0.987654321,
        gap_range=np.array([0.0181234, 0.0219876]),
        position_range=np.array([-0.0123456, 0.0134567]),
        violations=tuple(violations),
        timings={"simulate": 0.25, "total": 0.5},
    )


def make_design() -> ExperimentDesign:
    t = np.arange(200) / REFERENCE_RATE_HZ
    gap = 0.02 + 0.001234 * np.sin(2 * np.pi * 0.5 * t)
    pos = 0.0056789 * np.cos(2 * np.pi * 0.3 * t) - 0.0012345
    values = np.vstack(
        [gap, np.gradient(gap, t), np.zeros_like(t), pos, np.gradient(pos, t), np.zeros_like(t)]
    )
    ref = SampledReference(t, values, "multisine", "two multisines, 0.2-4 Hz")
    baseline = Prediction(
        names=CONSTANT_NAMES,
        nominal=np.array([14.2, 796.99, 31.04, 0.07]),
        covariance=np.diag([0.0234567, 9.87654, 0.0456789, 2.34567e-5]) ** 2,
        log_det=10.5,
        peak_current=np.array([1.5, 4.0]),
        rms_current=1.1,
        gap_range=np.array([0.018, 0.022]),
        position_range=np.array([-0.01, 0.01]),
        violations=(),
    )
    return ExperimentDesign(
        kind="multisine",
        reference=ref,
        targets=CONSTANT_NAMES,
        purpose="all four constants",
        prediction=make_prediction(),
        budget=CurrentBudget(vertical=4.87654, horizontal=1.65432),
        baseline=baseline,
        settings={"duration_s": 20.0, "seed": 3, "vertical": MultisineShape().to_dict()},
        candidates=({"shape": "a", "feasible": True, "log_det": 1.25},),
        timings={"total": 1.5},
    )


def make_trend(source: str, changes: dict[str, float], eps=PAPER_EPSILONS) -> EpsTrend:
    names = tuple(changes)
    base = np.array([14.2, 796.99, 31.04, 0.07][: len(names)])
    ramp = np.linspace(0, 1, len(eps))
    values = base[:, None] * (1 + np.array(list(changes.values()))[:, None] * ramp[None, :])
    return EpsTrend(source, names, tuple(eps), values)


def make_study() -> EpsTrendStudy:
    t2 = {"C1": 0.1234, "C2": -0.0456}
    t3 = {"C1": 0.0789, "C2": 0.00345, "C3": -0.2345, "C4": 0.0567}
    return EpsTrendStudy(
        success=True,
        status="partly_reproduced",
        message="C4 of table3 moves the other way",
        papers_table2=make_trend("Table II", t2),
        papers_table3=make_trend("Table III", t3),
        default_table2=make_trend("default II", {"C1": 0.0012, "C2": -0.0023}),
        default_table3=make_trend("default III", {"C1": 0.0034, "C2": 0.0045, "C3": -0.0056, "C4": 0.0067}),
        friction_table2=make_trend("friction II", {"C1": 0.0987, "C2": -0.0321}),
        friction_table3=make_trend(
            "friction III", {"C1": 0.0654, "C2": 0.0078, "C3": -0.1234, "C4": -0.0345}
        ),
        zero_phase_table3=make_trend("zero phase", {"C1": 0.0001, "C2": -0.0002, "C3": 0.0003, "C4": 0.0}),
        limit_default_table3=make_trend("limit default", {"C1": 0.002, "C2": 0.003, "C3": 0.0, "C4": 0.0}),
        limit_friction_table3=make_trend("limit friction", {"C1": 0.06, "C2": 0.007, "C3": -0.1, "C4": 0.0}),
        truth={"C1": 14.1, "C2": 800.5, "C3": 30.9, "C4": 0.071},
        friction={
            "horizontal": {"coulomb": 0.35, "viscous": 2.5},
            "vertical": {"coulomb": 0.1, "viscous": 0.0},
        },
        observer_lag=0.0031234,
        damping_rate=1.23456,
        papers_damping=float("nan"),
        band=0.01,
        explanation="friction lags the velocity",
        timings={"runs": 12.3456, "total": 13.579},
    )


@pytest.fixture(scope="module")
def real_fit(model, twin_log):
    """The equation-error fit of C1..C4 on the 6 s twin log (a real object, about 1 s)."""
    return EquationError(twin_log, model).fit()


# --- FitResult -----------------------------------------------------------------------------------
VAR_LINE = re.compile(
    r"^    (?P<name>\S+?)\s*: +(?P<v>\S+) \+/- (?P<s>\S+)\s+(?:\((?P<rel>\S+)%\)\s+)?"
    r"\(init = (?P<init>[^)]+)\)(?P<rest>.*)$"
)


def _variables(report: str) -> dict[str, re.Match]:
    out = {}
    for ln in report.split("[[Variables]]", 1)[1].split("[[Correlations]]", 1)[0].splitlines():
        m = VAR_LINE.match(ln)
        if m:
            out[m["name"]] = m
    return out


def check_fit_report(fit: FitResult, truth=None) -> None:
    text = fit.report(truth)
    head = text.splitlines()[0]
    assert head == f"[[Fit: {METHOD_TITLES.get(fit.method, fit.method)}]]"
    assert line_after(text, "success            = ") == f"{fit.success} (status {fit.status}: {fit.message})"
    assert line_after(text, "logs               = ") == ", ".join(fit.sources)
    assert int(line_after(text, "# samples          = ")) == fit.n_samples
    assert int(line_after(text, "# residuals        = ")) == fit.n_residuals
    assert int(line_after(text, "# variables        = ")) == len(fit.names)
    assert int(line_after(text, "iterations         = ")) == fit.iterations
    assert_printed(line_after(text, "    chi-square         = "), fit.chi_square, "chi-square")
    assert_printed(line_after(text, "reduced chi-square = "), fit.reduced_chi_square, "reduced chi-square")
    for axis in AXES:
        value, unit = line_after(text, f"residual RMS {axis}").split("=", 1)[1].split()
        assert_printed(value, fit.residual_rms[axis], f"residual RMS {axis}")
        assert unit == fit.residual_unit
    wall = re.fullmatch(rf"({NUM}) s \((.*)\)", line_after(text, "wall time          = "))
    assert wall, text
    assert_printed(wall[1], fit.timings["total"], "wall time")
    steps = dict(item.rsplit(" ", 1) for item in wall[2].split(", "))
    assert set(steps) == set(fit.timings) - {"total"}
    for k, v in steps.items():
        assert_printed(v, fit.timings[k], f"timing {k}")

    found = _variables(text)
    assert list(found) == list(fit.names)
    for k, m in found.items():
        v, s = fit.values[k], fit.stderr[k]
        assert_printed(m["v"], v, f"{k} value")
        assert_printed(m["s"], s, f"{k} stderr")
        assert_printed(m["init"], fit.initial[k], f"{k} initial")
        if v != 0:
            assert_printed(m["rel"], 100 * abs(s / v), f"{k} relative stderr [%]")
        else:
            assert m["rel"] is None
        unit = re.search(r"  \[([^\]]+)\]$", m["rest"])
        assert (unit[1] if unit else "") == UNITS.get(k, ""), f"{k}: unit"
        cmp = re.search(rf"truth ({NUM}), error ({NUM})(%?), z ({NUM})", m["rest"])
        if truth is not None and k in truth and s > 0:
            t = truth[k]
            assert cmp, m.group(0)
            assert_printed(cmp[1], t, f"{k} truth")
            if t != 0:
                assert cmp[3] == "%"
                assert_printed(cmp[2], 100 * (v - t) / t, f"{k} error [%]")
            else:
                assert_printed(cmp[2], v - t, f"{k} error")
            assert_printed(cmp[4], (v - t) / s, f"{k} z")
        else:
            assert cmp is None
    if fit.fixed:
        fixed = dict(item.split(" = ") for item in line_after(text, "    fixed: ").split(", "))
        assert set(fixed) == set(fit.fixed)
        for k, v in fixed.items():
            assert_printed(v, fit.fixed[k], f"fixed {k}")
    naive = re.search(r"long-run covariance over (\d+) frequencies; .* ones are (.*)\)$", text, re.M)
    assert naive and int(naive[1]) == fit.hac_frequencies
    pairs = dict(item.rsplit(" ", 1) for item in naive[2].split(", "))
    assert list(pairs) == list(fit.names)
    for k, v in pairs.items():
        assert_printed(v, fit.stderr_naive[k], f"plain stderr {k}")


def test_fit_report_prints_the_fits_numbers_with_their_labels_and_units():
    """A user reads a fit's report: every number next to a label (counts, chi-square, residual RMS
    per axis in the fit's unit, wall times per step, each parameter's value, HAC standard error,
    relative error in %, initial guess and unit, the fixed constants, the plain standard errors)
    is the object's, to the printed digits (half a unit of the last digit: exact rounding)."""
    check_fit_report(make_fit())
    check_fit_report(make_fit(method="output_error", residual_unit="m"))


def test_fit_report_against_truth_prints_errors_and_z_scores():
    """With ``truth``, each parameter's line gives the truth, the error in % of the truth (or the
    absolute error for a truth of 0) and the z score (v - t) / stderr: what a study reads to judge
    the standard errors. Compared to the printed digits."""
    fit = make_fit()
    truth = {"C1": 14.1, "C2": 805.5, "gap_offset": 0.0, "friction.c": 0.01}
    check_fit_report(fit, truth)
    # the numbers themselves: C1 is 0.954 % high, 10.90 of its standard errors
    line = _variables(fit.report(truth))["C1"]["rest"]
    assert "error +0.954%" in line and "z +10.90" in line


def test_fit_report_lists_exactly_the_correlations_of_magnitude_0_1_and_above_largest_first():
    """The correlation block: each pair |C| >= 0.1 once, with its sign and value to 4 decimals,
    largest first; no pair below 0.1 (the heading says they are left out)."""
    fit = make_fit()
    text = fit.report()
    block = text.split("[[Correlations]] (unreported correlations are < 0.100)\n", 1)[1].splitlines()
    got = [re.fullmatch(rf"    C\((\S+), (\S+)\) = ({NUM})", ln) for ln in block]
    assert all(got), block
    expected = {
        (fit.names[i], fit.names[j]): fit.correlation[i, j]
        for i in range(len(fit.names))
        for j in range(i + 1, len(fit.names))
        if abs(fit.correlation[i, j]) >= 0.1
    }
    assert {(m[1], m[2]) for m in got} == set(expected)
    for m in got:
        assert_printed(m[3], expected[m[1], m[2]], f"C({m[1]}, {m[2]})")
    mags = [abs(float(m[3])) for m in got]
    assert mags == sorted(mags, reverse=True)


def test_fit_report_of_a_real_fit(real_fit):
    """The same reading on an equation-error fit of the twin log: the real object's numbers."""
    check_fit_report(real_fit)
    check_fit_report(real_fit, {"C1": 14.0, "C2": 800.0, "C3": 31.0, "C4": 0.07})


def check_fit_dict(fit: FitResult) -> None:
    d = roundtrip(fit.to_dict())
    assert d["method"] == fit.method
    assert list(d["parameters"]) == list(fit.names)  # in the covariance's order
    for k in fit.names:
        p = d["parameters"][k]
        assert p == {
            "value": js(fit.values[k]),
            "stderr": js(fit.stderr[k]),
            "stderr_naive": js(fit.stderr_naive[k]),
            "initial": js(fit.initial[k]),
            "unit": UNITS.get(k, ""),
        }
    assert d["fixed"] == {k: js(v) for k, v in fit.fixed.items()}
    assert d["covariance"] == [[js(x) for x in row] for row in fit.covariance]
    assert d["correlation"] == [[js(x) for x in row] for row in fit.correlation]
    assert d["residual_rms"] == {k: js(v) for k, v in fit.residual_rms.items()}
    for key in (
        "residual_unit",
        "n_samples",
        "n_residuals",
        "hac_frequencies",
        "success",
        "status",
        "message",
        "iterations",
    ):
        assert d[key] == getattr(fit, key), key
    assert d["chi_square"] == js(fit.chi_square)
    assert d["reduced_chi_square"] == js(fit.reduced_chi_square)
    assert d["timings"] == {k: js(v) for k, v in fit.timings.items()}
    assert d["sources"] == list(fit.sources)
    assert d["settings"] == roundtrip(dict(fit.settings))
    assert "residuals" not in d  # per-sample residuals stay out of the summary


def test_fit_json_holds_every_summary_field_of_the_object():
    """A script reads the fit's JSON (the CLI's ``identify`` output): each parameter's value,
    HAC and plain standard error, initial guess and unit under its name, in the order of the
    covariance; the fixed constants, covariance, correlation, residual RMS per axis with its unit,
    counts, chi-square, solver status, timings, sources and settings, all equal to the object's
    after a JSON round trip (exact: JSON keeps a float's digits)."""
    check_fit_dict(make_fit())


def test_fit_json_of_a_real_fit(real_fit):
    """The same on the twin fit."""
    check_fit_dict(real_fit)


def test_a_failed_fits_nan_become_null_and_the_rest_stays():
    """A failed fit has NaN standard errors and covariance: the JSON must still be JSON (null in
    their place) and keep the values and status a user needs to see why."""
    nan = float("nan")
    fit = make_fit(
        stderr=dict.fromkeys(NAMES, nan),
        covariance=np.full((4, 4), nan),
        correlation=np.full((4, 4), nan),
        reduced_chi_square=float("inf"),
        success=False,
        status="covariance_singular",
        message="J'J is singular",
    )
    check_fit_dict(fit)
    d = roundtrip(fit.to_dict())
    assert all(p["stderr"] is None for p in d["parameters"].values())
    assert d["reduced_chi_square"] is None and d["covariance"][0][0] is None
    assert d["parameters"]["C1"]["value"] == fit.values["C1"]


# --- NpfsiResult ---------------------------------------------------------------------------------
def check_npfsi_report(run: NpfsiResult, truth=None) -> None:
    text = run.report(truth)
    head = re.fullmatch(
        rf"\[\[NPFSI \(reduced order, 000 eq\. \(3\)\): eps = ({NUM}) s, gamma = ({NUM}), Q = (.*)\]\]",
        text.splitlines()[0],
    )
    assert head, text
    assert_printed(head[1], run.eps, "eps")
    assert_printed(head[2], run.gamma, "gamma")
    assert head[3] == ("A'A (002 sidebar)" if run.Q is None else "given matrix")
    assert line_after(text, "success            = ") == f"{run.success} (status {run.status}: {run.message})"
    assert line_after(text, "logs               = ") == ", ".join(run.sources)
    assert int(line_after(text, "# samples          = ")) == run.t.size
    assert line_after(text, "velocities         = ") == run.velocity_method
    wall = re.fullmatch(rf"({NUM}) s", line_after(text, "wall time          = "))
    assert wall
    assert_printed(wall[1], run.timings["total"], "wall time")
    rows = text.split("[[Variables]]\n", 1)[1].splitlines()
    assert len(rows) == len(run.names)
    for k, ln in zip(run.names, rows, strict=True):
        m = re.fullmatch(
            rf"    {re.escape(k)}\s*: +({NUM})  \(init = ({NUM}), 1 % band from t = ({NUM}) s\)(.*)", ln
        )
        assert m, ln
        assert_printed(m[1], run.values[k], f"{k} value")
        assert_printed(m[2], run.theta0[k], f"{k} initial")
        assert_printed(m[3], run.settling_time(k), f"{k} settling time")
        cmp = re.fullmatch(rf"  truth ({NUM}), error ({NUM})%", m[4])
        if truth is not None and truth.get(k, 0) != 0:
            assert cmp, ln
            assert_printed(cmp[1], truth[k], f"{k} truth")
            assert_printed(cmp[2], 100 * (run.values[k] - truth[k]) / truth[k], f"{k} error [%]")
        else:
            assert m[4] == ""


def test_npfsi_report_prints_the_runs_settings_and_estimates():
    """An NPFSI run's report: eps [s], gamma and Q in the title, the sample count, velocity
    method, wall time, and per parameter the final value, initial guess and the time it entered
    its 1 % band, each the object's to the printed digits; with ``truth``, the error in %."""
    run = make_npfsi()
    assert 0.3 < run.settling_time("C1") < 0.6  # the band is entered at the step, not at 0
    check_npfsi_report(run)
    check_npfsi_report(run, {"C1": 14.1, "C2": 0.0})
    check_npfsi_report(make_npfsi(eps=0.001, Q=np.eye(2)), {"C1": 14.1, "C2": 800.0})
    # a run built without timings (by a script, from a saved JSON) still reports, wall time unknown
    assert "wall time          = nan s" in make_npfsi(timings={}).report()


def test_npfsi_json_holds_the_runs_settings_and_estimates():
    """The JSON a script reads of an NPFSI run: method, eps, gamma, Q (null for A'A), Q0, final
    values and initial guesses by name, velocity method, status, timings, sources, settings; a
    diverged run's NaN values are null."""
    for run in (make_npfsi(), make_npfsi(eps=0.05, Q=np.diag([2.0, 3.0]))):
        d = roundtrip(run.to_dict())
        assert d["method"] == "npfsi"
        assert d["eps"] == run.eps and d["gamma"] == run.gamma
        assert d["Q"] == (None if run.Q is None else run.Q.tolist())
        assert d["Q0"] == run.Q0.tolist()
        assert d["values"] == dict(run.values) and list(d["values"]) == list(run.names)
        assert d["theta0"] == dict(run.theta0)
        for key in ("velocity_method", "success", "status", "message"):
            assert d[key] == getattr(run, key), key
        assert d["timings"] == dict(run.timings)
        assert d["sources"] == list(run.sources)
        assert d["settings"] == dict(run.settings)
    diverged = make_npfsi(values=(float("nan"), float("inf")), success=False)
    d = roundtrip(diverged.to_dict())
    assert d["values"] == {"C1": None, "C2": None} and d["status"] == "diverged"


# --- IdentificationOutcome ------------------------------------------------------------------------
def _constants_line(text: str) -> dict[str, str]:
    line = line_after(text, "[[Identified constants]] ")
    body, source = re.fullmatch(r"(.*?)  \((.*)\)", line).groups()
    out = dict(item.split(" = ") for item in body.split(", "))
    out["source"] = source
    return out


def _fit4(method: str, success: bool = True, scale: float = 1.0) -> FitResult:
    names = CONSTANT_NAMES
    vals = np.array([14.3456789, 801.234567, 31.1234567, 0.0712345]) * scale
    corr = np.eye(4)
    se = np.array([0.01, 2.0, 0.05, 1e-4])
    return make_fit(
        method=method,
        names=names,
        values=dict(zip(names, vals, strict=True)),
        stderr=dict(zip(names, se, strict=True)),
        stderr_naive=dict(zip(names, se / 2, strict=True)),
        initial=dict(zip(names, (14.2, 796.99, 31.04, 0.07), strict=True)),
        fixed={},
        covariance=np.diag(se**2),
        correlation=corr,
        variance_inflation=dict.fromkeys(names, 4.0),
        success=success,
        status="converged" if success else "iteration_limit",
        message="ok" if success else "50 iterations",
    )


@pytest.mark.parametrize("ee_success", [True, False])
def test_outcome_report_and_json_name_the_constants_of_the_best_fit(model, ee_success):
    """``maglev_oc identify`` prints the outcome's report and writes its JSON; the stage file and
    the user take ``identified_constants`` from them. Those must be the best fit's (equation error
    if it converged, else output error), printed to 6 digits and stored exactly, with the source
    naming the method; the JSON nests each fit's and run's own JSON and carries status, message,
    timings, estimate and sources."""
    ee, oe = _fit4("equation_error", success=ee_success), _fit4("output_error", scale=1.001)
    runs = (make_npfsi(eps=0.001), make_npfsi(eps=0.01))
    outcome = IdentificationOutcome(
        equation_error=ee,
        output_error=oe,
        npfsi=runs,
        base_constants=model.constants,
        estimate=CONSTANT_NAMES,
        sources=("run_a.csv", "run_b.csv"),
        timings={"equation_error": 0.5, "output_error": 2.25, "npfsi": 0.75, "total": 3.5},
    )
    best = ee if ee_success else oe
    assert outcome.best is best
    text = outcome.report()
    assert text.count("[[Fit: ") == 2 and text.count("[[NPFSI") == 2
    printed = _constants_line(text)
    assert list(printed)[:4] == list(CONSTANT_NAMES)
    for k in CONSTANT_NAMES:
        assert_printed(printed[k], best.values[k], f"identified {k}")
    assert printed["source"] == outcome.constants().source
    assert printed["source"].startswith(f"identified ({best.method})")

    d = roundtrip(outcome.to_dict())
    assert set(d) >= OUTCOME_KEYS
    for k in CONSTANT_NAMES:
        assert d["identified_constants"][k] == best.values[k]
        assert d["base_constants"][k] == getattr(model.constants, k)
    assert d["identified_constants"]["source"] == printed["source"]
    assert d["equation_error"] == roundtrip(ee.to_dict())
    assert d["output_error"] == roundtrip(oe.to_dict())
    assert d["npfsi"] == [roundtrip(r.to_dict()) for r in runs]
    assert d["success"] is True and d["status"] == "converged"
    assert d["message"] == f"{best.method}: {best.message}"
    assert d["timings"] == outcome.timings
    assert d["estimate"] == list(CONSTANT_NAMES) and d["sources"] == ["run_a.csv", "run_b.csv"]
    assert d["validation"] is None


def test_an_npfsi_only_outcome_reports_the_eps_0_01_run(model):
    """Without least-squares fits, the identified constants are NPFSI's at eps = 0.01 (the
    papers' choice), not the first run's; the status says ``npfsi_only`` and the message names
    each run's eps."""
    runs = (
        make_npfsi(eps=0.001, values=(11.0, 700.0)),
        make_npfsi(eps=0.01, values=(14.3456789, 790.123456)),
    )
    outcome = IdentificationOutcome(None, None, runs, model.constants, ("C1", "C2"), ("run_a.csv",))
    printed = _constants_line(outcome.report())
    for k in ("C1", "C2"):
        assert_printed(printed[k], runs[1].values[k], k)
    for k in ("C3", "C4"):
        assert_printed(printed[k], getattr(model.constants, k), k)
    d = roundtrip(outcome.to_dict())
    assert d["identified_constants"]["C1"] == runs[1].values["C1"]
    assert d["equation_error"] is None and d["output_error"] is None
    assert d["status"] == "npfsi_only" and d["success"] is True
    assert d["message"] == "NPFSI eps = 0.001: ran to the end; NPFSI eps = 0.01: ran to the end"


# --- designs ---------------------------------------------------------------------------------------
def test_prediction_json_carries_its_numbers_under_named_units():
    """A prediction's JSON (inside ``design.json``): standard errors and relative standard errors
    by parameter, peak currents under their current names (i_q is the horizontal, first entry),
    RMS current, ranges, violations; a singular information's -inf log det is null."""
    p = make_prediction()
    d = roundtrip(p.to_dict())
    se = np.sqrt(np.diag(p.covariance))
    assert d["stderr"] == dict(zip(p.names, se.tolist(), strict=True))
    assert d["relative_stderr"] == {k: s / abs(n) for k, s, n in zip(p.names, se, p.nominal, strict=True)}
    assert d["log_det_relative_information"] == p.log_det
    assert d["peak_current_A"] == {"i_q": p.peak_current[0], "i_d": p.peak_current[1]}
    assert d["rms_current_A"] == p.rms_current
    assert d["gap_range_m"] == p.gap_range.tolist() and d["position_range_m"] == p.position_range.tolist()
    assert d["violations"] == [] and d["status"] == "feasible" and d["timings"] == dict(p.timings)
    bad = make_prediction(log_det=-math.inf, violations=("peak i_d 9.5 A over 9 A",))
    d = roundtrip(bad.to_dict())
    assert d["log_det_relative_information"] is None
    assert d["violations"] == ["peak i_d 9.5 A over 9 A"] and d["status"] == "infeasible"
    assert d["success"] is False and d["message"] == "peak i_d 9.5 A over 9 A"


def test_design_json_is_what_the_rig_and_the_next_step_read():
    """``design.json`` (written by ``write_design``): the reference's name, description, duration,
    rate, columns and its gap / position ranges (rows 0 and 3 of the values), the budget with
    i_d vertical and i_q horizontal, the prediction's and the baseline's own JSON, the standard
    error ratios to the papers' excitation, settings, candidates and status."""
    des = make_design()
    d = roundtrip(des.to_dict())
    assert d["format"] == "maglev_oc experiment design 1" and d["kind"] == des.kind
    ref = d["reference"]
    assert ref["name"] == des.reference.name and ref["description"] == des.reference.description
    assert ref["duration_s"] == des.reference.duration and ref["sample_rate_hz"] == REFERENCE_RATE_HZ
    assert ref["columns"] == list(REFERENCE_COLUMNS)
    v = des.reference.values
    assert ref["gap_range_m"] == [v[0].min(), v[0].max()]
    assert ref["position_range_m"] == [v[3].min(), v[3].max()]
    assert d["targets"] == list(des.targets) and d["purpose"] == des.purpose
    assert d["budget_A"] == {"i_d": des.budget.vertical, "i_q": des.budget.horizontal}
    assert d["predicted"] == roundtrip(des.prediction.to_dict())
    assert d["papers_excitation_predicted"] == roundtrip(des.baseline.to_dict())
    ratio = {k: des.prediction.stderr[k] / des.baseline.stderr[k] for k in des.targets}
    assert d["stderr_ratio_to_papers"] == ratio
    assert d["settings"] == des.settings and d["candidates"] == list(des.candidates)
    assert (d["success"], d["status"], d["message"]) == (des.success, des.status, des.message)
    assert d["timings"] == dict(des.timings)


def test_design_report_prints_standard_errors_and_currents_against_the_budget():
    """``maglev_oc design-experiment`` prints the report: per parameter the predicted standard
    error and the papers' excitation's (3 digits), and the peak currents i_q and i_d [A] against
    the budget (horizontal / vertical), each the object's value to the printed digits."""
    des = make_design()
    text = des.report()
    assert text.splitlines()[0] == f"[[Experiment design: {des.kind}]] {des.reference.description}"
    assert line_after(text, "  targets: ") == f"{', '.join(des.targets)} — {des.purpose}"
    for k in des.prediction.names:
        m = re.fullmatch(rf"\s+({NUM})   papers' excitation ({NUM})", line_after(text, f"predicted SE {k} "))
        assert m, text
        assert_printed(m[1], des.prediction.stderr[k], f"SE {k}")
        assert_printed(m[2], des.baseline.stderr[k], f"papers' SE {k}")
    m = re.fullmatch(
        rf"  peak currents i_q ({NUM}) A, i_d ({NUM}) A \(budget ({NUM}) / ({NUM}) A\); (\w+): (.*)",
        text.splitlines()[-1],
    )
    assert m, text
    assert_printed(m[1], des.prediction.peak_current[0], "peak i_q")
    assert_printed(m[2], des.prediction.peak_current[1], "peak i_d")
    assert_printed(m[3], des.budget.horizontal, "budget i_q")
    assert_printed(m[4], des.budget.vertical, "budget i_d")
    assert (m[5], m[6]) == (des.status, des.message)


def test_twin_check_json_and_report_hold_predicted_and_achieved():
    """A twin check compares predicted with achieved standard errors: its JSON carries both by
    name, the spread (null for one seed, where it is NaN), the errors, peak currents and seeds;
    its report names the reference and the timings (3 significant digits)."""
    nan = float("nan")
    chk = TwinCheck(
        reference="doptimal",
        names=("C1", "C2"),
        predicted={"C1": 0.0123, "C2": 2.345},
        achieved={"C1": 0.0134, "C2": 2.567},
        spread={"C1": nan, "C2": nan},
        error={"C1": 0.0211, "C2": 1.234},
        peak_current=np.array([1.2345, 4.5678]),
        seeds=(0,),
        success=True,
        status="identified",
        message="1 run(s) identified",
        timings={"simulate": 1.23456, "identify": 0.345678, "total": 1.58024},
    )
    d = roundtrip(chk.to_dict())
    assert d["reference"] == "doptimal" and d["names"] == ["C1", "C2"]
    for key in ("predicted", "achieved", "error"):
        assert d[key] == getattr(chk, key), key
    assert d["spread"] == {"C1": None, "C2": None}
    assert d["peak_current"] == chk.peak_current.tolist() and d["seeds"] == [0]
    assert (d["success"], d["status"], d["message"]) == (True, "identified", "1 run(s) identified")
    text = chk.report()
    assert line_after(text, "reference              = ") == "doptimal"
    steps = dict(item.rsplit(" ", 1) for item in line_after(text, "timings [s]: ").split(", "))
    assert set(steps) == set(chk.timings)
    for k, v in steps.items():
        assert_printed(v, chk.timings[k], f"timing {k}")


def test_multisine_shape_json():
    """The shape a design's settings record: band [Hz], tone count and tilt, as given."""
    s = MultisineShape((0.15, 3.5), 6, 0.75)
    assert roundtrip(s.to_dict()) == {"band_hz": [0.15, 3.5], "tones": 6, "tilt": 0.75}


# --- EpsTrendStudy -----------------------------------------------------------------------------------
def test_eps_trend_report_prints_each_change_in_percent_with_its_direction():
    """The eps-trend report: for Tables III and II, the papers', default and friction rows, each
    constant's relative change from the smallest to the largest eps in % (2 decimals) with its
    direction (up/down/flat within the band); the explanation and the timings. Each number is
    the object's to the printed digits."""
    st = make_study()
    text = st.report()
    assert text.splitlines()[0] == f"EpsTrendStudy: {st.status}: {st.message}"
    lines = text.splitlines()
    for table in ("table3", "table2"):
        at = next(i for i, ln in enumerate(lines) if ln.startswith(f"  {table}: "))
        head = re.fullmatch(rf"  {table}: relative change from eps = ({NUM}) to ({NUM})", lines[at])
        assert head
        for row, ln in zip(("papers", "default", "friction"), lines[at + 1 : at + 4], strict=True):
            trend = getattr(st, f"{row}_{table}")
            assert_printed(head[1], trend.eps[0], "first eps")
            assert_printed(head[2], trend.eps[-1], "last eps")
            assert ln.startswith(f"    {row:<9s} ")
            cells = re.findall(rf"(\w+) ({NUM}) % \((\w+)\)", ln)
            assert [c[0] for c in cells] == list(trend.names)
            for name, pct, direction in cells:
                assert_printed(pct, 100 * trend.change[name], f"{row} {table} {name} change [%]")
                assert direction == trend.direction(st.band)[name]
    assert line_after(text, "  explanation: ") == st.explanation
    steps = dict(item.rsplit(" ", 1) for item in line_after(text, "  timings [s]: ").split(", "))
    assert set(steps) == set(st.timings)
    for k, v in steps.items():
        assert_printed(v, st.timings[k], f"timing {k}")


def test_eps_trend_json_holds_every_trend_and_the_verdicts():
    """The study's JSON: each trend (source, eps, values by constant, change by constant), the
    truth, friction, observer lag, damping rates, band, explanation, and the directions and
    agreement a reader checks against the papers; NaN (no papers' damping) is null."""
    st = make_study()
    d = roundtrip(st.to_dict())
    for field in (
        "papers_table2",
        "papers_table3",
        "default_table2",
        "default_table3",
        "friction_table2",
        "friction_table3",
        "zero_phase_table3",
        "limit_default_table3",
        "limit_friction_table3",
    ):
        tr = getattr(st, field)
        assert d[field] == {
            "source": tr.source,
            "eps": list(tr.eps),
            "values": {k: tr.values[i].tolist() for i, k in enumerate(tr.names)},
            "change": tr.change,
        }, field
    assert d["truth"] == dict(st.truth) and d["friction"] == roundtrip(dict(st.friction))
    for key in ("observer_lag", "damping_rate", "band", "explanation", "success", "status", "message"):
        assert d[key] == getattr(st, key), key
    assert d["papers_damping"] is None
    assert d["timings"] == dict(st.timings)
    assert d["directions"] == st.directions()
    assert set(d["directions"]) == {
        f"{r}_{t}" for r in ("papers", "default", "friction") for t in ("table2", "table3")
    } | {"zero_phase_table3"}
    assert d["directions"]["friction_table3"] == {"C1": "up", "C2": "flat", "C3": "down", "C4": "down"}
    assert d["agreement"] == st.agreement()
    assert d["agreement"]["table3"] == {"C1": True, "C2": True, "C3": True, "C4": False}
    assert d["agreement"]["table2"] == {"C1": True, "C2": True}


def test_a_fit_without_standard_errors_still_reports_its_error_against_the_truth():
    """A failed fit (singular covariance: NaN standard errors) is exactly when a user wants the
    estimate against the truth: the report keeps "truth ..., error ...%" and leaves out only the z
    score, which needs a standard error (it dropped both)."""
    fit = make_fit(stderr=dict.fromkeys(NAMES, float("nan")), success=False, status="covariance_singular")
    (line,) = [ln for ln in fit.report({"C1": 14.1}).splitlines() if ln.startswith("    C1")]
    assert "truth 14.1, error " in line and ", z " not in line
    err = float(re.search(r"error ([+-][\d.e+-]+)%", line).group(1))
    assert err == pytest.approx(100 * (fit.values["C1"] - 14.1) / 14.1, rel=1e-2)
