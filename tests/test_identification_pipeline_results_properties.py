"""Properties of ``identify``, its parameter layout and its results and reports, checked against
validations and accelerations recomputed here with the identified constants:

- ``check_identifiable`` refuses a log just shorter than ``min_duration`` and an axis with one flat
  signal; ``load_logs`` refuses an empty list;
- ``identify`` reports only the methods asked for, and validates on the validation logs, with the
  fitted gap offset and on the currents shifted by the input delay;
- the layout bounds the constants below by zero and the gap offset on both sides, refuses a name
  asked twice, gives each parameter's unit, and its accelerations are the model's plus each term
  on its own parameters;
- a fit's relative errors and z-scores are against the truth and the HAC errors; its report gives
  each relative standard error in percent and its JSON each parameter's unit; a method without a
  title reports its name; an NPFSI-only outcome succeeds only if every run stayed well posed;
  the eps-trend report gives each change in percent beside its direction.
"""

from __future__ import annotations

import dataclasses
import json
import re

import numpy as np
import pytest

from maglev_oc.data.log import Log
from maglev_oc.data.logs import LogError
from maglev_oc.errors import InputError
from maglev_oc.identification.eps_trend import FLAT_BAND, EpsTrend, EpsTrendStudy
from maglev_oc.identification.equation_error import EquationError
from maglev_oc.identification.layout import CONSTANT_NAMES, GAP_OFFSET, UNITS, ParameterLayout
from maglev_oc.identification.npfsi import PAPER_EPSILONS
from maglev_oc.identification.pipeline import (
    VALIDATION_BANDWIDTH,
    IdentificationOutcome,
    check_identifiable,
    identify,
    load_logs,
)
from maglev_oc.model.parameters import PAPER_CONSTANTS
from maglev_oc.regression.base import GAP_OFFSET_BOUND
from maglev_oc.regression.data import prepare
from maglev_oc.regression.terms import constant_force, guide_friction
from maglev_oc.validation import validate
from tests.test_identification_outputs import make_fit, make_npfsi


# --- identify and its checks ---------------------------------------------------------------------------
def test_identify_validates_on_the_validation_logs(model, twin_log):
    # recomputed by hand as validate(prepare(held-out logs), their valid samples, fitted constants);
    # 1e-9 relative: the same arithmetic on the same samples (round-off only)
    held = Log(
        twin_log.t[1000:] - twin_log.t[1000],
        twin_log.x[:, 1000:],
        twin_log.u[:, 1000:],
        source="held.csv",
    )
    out = identify(twin_log, model, methods=("equation_error",), validation_logs=[held])
    data = prepare([held], bandwidth=VALIDATION_BANDWIDTH)
    expected = validate(data, data.valid, model.with_constants(out.constants()), [])
    assert out.validation.inputs.shape == expected.inputs.shape
    np.testing.assert_allclose(out.validation.residuals, expected.residuals, rtol=1e-9, atol=1e-12)
    assert "held.csv" in out.validation.data
    # and it says what was validated: the identified constants, by the method that fitted them
    assert out.validation.model == f"identified constants ({out.best.method})"


def _moving_log(duration: float) -> Log:
    t = np.arange(0, duration, 1e-3)
    s = np.sin(2 * np.pi * 0.5 * t)
    x = np.full((4, t.size), np.nan)
    x[0], x[2] = 0.02 + 1e-3 * s, 0.03 * s
    return Log(t, x, np.vstack([0.5 * s, 1.5 + 0.5 * s]), source="run.csv")


def test_check_identifiable_refuses_a_log_just_shorter_than_min_duration():
    check_identifiable([_moving_log(5.5)], ("C1", "C2"), min_duration=5.0)
    with pytest.raises(LogError, match="too short"):
        check_identifiable([_moving_log(4.5)], ("C1", "C2"), min_duration=5.0)


def test_identify_validates_with_the_fitted_gap_offset(model, twin_log):
    # the gap readings 0.5 mm short of the true gap: a fitted offset of a few tenths of a mm, and the
    # validation simulates the model at the reading plus it (recomputed by hand, 1e-9 relative:
    # the same arithmetic); without the offset the residuals are different (the test has teeth)
    x = np.array(twin_log.x, dtype=float)
    x[0] -= 5e-4
    log = dataclasses.replace(twin_log, x=x, source="short.csv")
    out = identify(log, model, methods=("equation_error",), estimate=(*CONSTANT_NAMES, GAP_OFFSET))
    offset = out.equation_error.values[GAP_OFFSET]
    # correlated with C2..C4 on 6 s of data (0.38 mm found): only that it is far from zero matters here
    assert 1e-4 < offset < 1e-3
    data = prepare([log], bandwidth=VALIDATION_BANDWIDTH)
    fitted = model.with_constants(out.constants())
    expected = validate(data, data.valid, fitted, [], gap_offset=offset)
    np.testing.assert_allclose(out.validation.residuals, expected.residuals, rtol=1e-9, atol=1e-12)
    without = validate(data, data.valid, fitted, [], gap_offset=0.0)
    assert not np.allclose(without.residuals, expected.residuals, rtol=1e-6, atol=0)


# --- what identify and the study report ----------------------------------------------------------------
def test_identify_reports_only_the_methods_it_was_asked_for(model, two_logs):
    # output error alone: the equation-error fit it starts from is not reported (nor taken as the
    # answer should the output-error fit fail); a 1 s log, so min_duration is lowered for the test
    out = identify(two_logs[0], model, methods=("output_error",), min_duration=0.5)
    assert out.equation_error is None and out.npfsi == ()
    assert out.output_error is not None and out.best is (
        out.output_error if out.output_error.success else None
    )


# --- result ----------------------------------------------------------------------------------------
def test_relative_errors_and_z_scores_are_against_the_truth_and_the_hac_errors():
    fit = make_fit()
    truth = {"C1": 14.0, "C2": 812.5, "gap_offset": 0.0, "friction.c": 0.01, "C3": 31.0}
    rel = fit.relative_errors(truth)
    # exact arithmetic on the same floats: equality to 1e-15 relative (one rounding)
    assert set(rel) == {"C1", "C2", "friction.c"}  # truth 0 has no relative error; C3 not estimated
    for k in rel:
        assert rel[k] == pytest.approx((fit.values[k] - truth[k]) / truth[k], rel=1e-15)
    z = fit.z_scores(truth)
    assert set(z) == {"C1", "C2", "gap_offset", "friction.c"}
    for k in z:
        assert z[k] == pytest.approx((fit.values[k] - truth[k]) / fit.stderr[k], rel=1e-15)
    # the estimate 14.2346 against 14: +1.676 %, not the -1.649 % of dividing by the estimate
    assert rel["C1"] == pytest.approx(0.23456789 / 14.0, rel=1e-12)


# --- layout ----------------------------------------------------------------------------------------
def test_layout_bounds_constants_below_by_zero_and_the_gap_offset_on_both_sides(model):
    lay = ParameterLayout(model, estimate=("C1", "C3", GAP_OFFSET))
    assert lay.names == ("C1", "C3", GAP_OFFSET)
    assert lay.lower == (0.0, 0.0, -GAP_OFFSET_BOUND)
    assert lay.upper == (np.inf, np.inf, GAP_OFFSET_BOUND)
    assert lay.initial == (model.constants.C1, model.constants.C3, 0.0)


def test_layout_refuses_a_name_asked_twice(model):
    with pytest.raises(InputError, match="duplicate"):
        ParameterLayout(model, estimate=("C2", "C2"))


# --- pipeline --------------------------------------------------------------------------------------
def test_an_npfsi_only_outcome_succeeds_only_if_every_run_stayed_well_posed(model):
    ok = (make_npfsi(eps=0.001), make_npfsi(eps=0.01), make_npfsi(eps=0.05))
    base = model.constants
    good = IdentificationOutcome(None, None, ok, base, ("C1", "C2"), ("run_a.csv",))
    assert (good.status, good.success) == ("npfsi_only", True)
    for k in range(3):
        runs = tuple(make_npfsi(eps=r.eps, success=j != k) for j, r in enumerate(ok))
        bad = IdentificationOutcome(None, None, runs, base, ("C1", "C2"), ("run_a.csv",))
        assert (bad.status, bad.success) == ("failed", False)


# --- check_identifiable ------------------------------------------------------------------------------------
def _log(source: str, *, x1: bool, u2: bool, x3: bool, u1: bool, duration: float = 6.0) -> Log:
    """A log whose chosen signals move (0.5 Hz sines far above the resolutions) and the others do not."""
    t = np.arange(0, duration, 1e-3)
    s = np.sin(2 * np.pi * 0.5 * t)
    x = np.full((4, t.size), np.nan)
    x[0] = 0.02 + (1e-3 * s if x1 else 0.0)
    x[2] = 0.03 * s if x3 else 0.0 * t
    u = np.vstack([0.5 * s if u1 else 0.0 * t, 1.5 + (0.5 * s if u2 else 0.0 * t)])
    return Log(t, x, u, source=source)


@pytest.mark.parametrize(
    ("flat", "estimate", "column"),
    [("u2", ("C2", "C3"), "u2"), ("x1", ("C2", "C3"), "x1"), ("u1", ("C1",), "u1"), ("x3", ("C1",), "x3")],
)
def test_an_axis_with_one_flat_signal_is_not_excited(flat, estimate, column):
    """An axis is excited only when its position and its current both move (x1 and u2 vertically, x3 and u1
    horizontally: the constants multiply their products). A log with one of them flat moves on no needed
    axis and is refused by name, even when another log moves on every signal."""
    good = _log("good.csv", x1=True, u2=True, x3=True, u1=True)
    moving = {k: k != flat for k in ("x1", "u2", "x3", "u1")}
    half = _log("half.csv", **moving)
    check_identifiable([good], estimate)
    with pytest.raises(LogError, match="no excitation") as info:
        check_identifiable([good, half], estimate)
    assert info.value.source == "half.csv"
    assert info.value.column == column
    with pytest.raises(LogError, match="no excitation"):
        check_identifiable([half], estimate)


# --- identify: validation with the input delay -------------------------------------------------------------
def test_identify_validates_on_the_currents_shifted_by_the_input_delay(model, twin_log):
    """identify(input_delay=d) fits the model to the currents delayed by d, and validates the fit on the same
    delayed currents. Recomputed here with the shift done by hand (d = 2 ms = 2 samples at 1 kHz, held at
    the start). Tolerance 1e-9 relative: the validation's numbers from the same arithmetic, up to the
    round-off of the library's interpolation at t - d (about 1e-16 of the currents)."""
    d = 0.002
    out = identify(twin_log, model, methods=("equation_error",), input_delay=d)
    assert out.validation is not None
    u = np.asarray(twin_log.u, dtype=float)
    shifted = np.hstack([np.repeat(u[:, :1], 2, axis=1), u[:, :-2]])
    fit = out.equation_error
    fitted = model.with_constants(out.constants())

    def by_hand(currents):
        data = prepare([dataclasses.replace(twin_log, u=currents)], bandwidth=VALIDATION_BANDWIDTH)
        return validate(data, data.valid, fitted, [], gap_offset=fit.values.get(GAP_OFFSET, 0.0))

    expected = by_hand(shifted)
    np.testing.assert_allclose(out.validation.inputs, expected.inputs, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(out.validation.residuals, expected.residuals, rtol=1e-9, atol=1e-12)
    got, want = out.validation.fit_table(), expected.fit_table()
    for axis in want:
        for horizon, value in want[axis].items():
            assert got[axis][horizon] == pytest.approx(value, rel=1e-9, abs=1e-9), (axis, horizon)
    # the delay matters here: the unshifted currents give other residuals
    assert not np.allclose(by_hand(u).residuals, expected.residuals, rtol=1e-6, atol=0)


# --- the eps-trend study's report ----------------------------------------------------------------------
def _papers(table: str, names: tuple[str, ...]) -> EpsTrend:
    values = [[getattr(PAPER_CONSTANTS[f"{table}_eps{e:g}"], k) for e in PAPER_EPSILONS] for k in names]
    return EpsTrend(f"paper 000, {table}", names, PAPER_EPSILONS, np.array(values))


def _ours(names: tuple[str, ...], first: list[float], last: list[float]) -> EpsTrend:
    mid = [(a + b) / 2 for a, b in zip(first, last, strict=True)]
    return EpsTrend("a run", names, PAPER_EPSILONS, np.array([first, mid, last]).T)


def _study() -> EpsTrendStudy:
    t3, t2 = CONSTANT_NAMES, ("C2", "C3", "C4")
    default3 = _ours(t3, [14.0, 800.0, 30.0, 0.08], [13.44, 800.0, 29.1, 0.0804])
    default2 = _ours(t2, [790.0, 30.0, 0.1], [790.0, 29.4, 0.1015])
    return EpsTrendStudy(
        success=True,
        status="partly_reproduced",
        message="made by hand",
        papers_table2=_papers("table2", t2),
        papers_table3=_papers("table3", t3),
        default_table2=default2,
        default_table3=default3,
        friction_table2=_ours(t2, [790.0, 30.0, 0.1], [787.0, 32.1, 0.2]),
        friction_table3=_ours(t3, [14.0, 800.0, 30.0, 0.08], [16.1, 798.0, 33.0, 0.16]),
        zero_phase_table3=default3,
        limit_default_table3=default3,
        limit_friction_table3=default3,
        truth={k: 1.0 for k in t3},
        friction={"horizontal": {"coulomb": 1.0, "viscous": 10.0}},
        observer_lag=0.003,
        damping_rate=1.0,
        papers_damping=10.0,
        band=FLAT_BAND,
        explanation="none",
        timings={"total": 1.0},
    )


def test_the_eps_trend_report_gives_each_change_in_percent_beside_its_direction():
    """Each row of the report gives each constant's change from eps = 0.001 to 0.05, v(0.05) / v(0.001)
    - 1, in percent with its sign and two decimals, then its direction (flat within 1 %). The papers'
    rows, worked out by hand from 000's tables: Table III C1 13.97 -> 16.23 (+16.18 %), C2 796.93 ->
    795.01 (-0.24 %, flat), C3 30.33 -> 33.44 (+10.25 %), C4 0.06 -> 0.15 (+150.00 %); Table II C2
    790.97 -> 788.98 (-0.25 %), C3 30.47 -> 32.44 (+6.47 %), C4 0.11 -> 0.18 (+63.64 %). Our default
    rows here: C1 14 -> 13.44 (-4.00 %), C2 unchanged (+0.00 %, flat)."""
    lines = _study().report().splitlines()
    t3, t2 = (
        lines.index("  table3: relative change from eps = 0.001 to 0.05"),
        lines.index("  table2: relative change from eps = 0.001 to 0.05"),
    )
    assert (
        lines[t3 + 1]
        == "    papers    C1 +16.18 % (up), C2 -0.24 % (flat), C3 +10.25 % (up), C4 +150.00 % (up)"
    )
    assert (
        lines[t3 + 2]
        == "    default   C1 -4.00 % (down), C2 +0.00 % (flat), C3 -3.00 % (down), C4 +0.50 % (flat)"
    )
    assert lines[t2 + 1] == "    papers    C2 -0.25 % (flat), C3 +6.47 % (up), C4 +63.64 % (up)"
    assert lines[t2 + 2] == "    default   C2 +0.00 % (flat), C3 -2.00 % (down), C4 +1.50 % (up)"
    assert lines[t2 + 3] == "    friction  C2 -0.38 % (flat), C3 +7.00 % (up), C4 +100.00 % (up)"


# --- a fit's report and JSON ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def force_fit(model, twin_log):
    """Equation error on the twin's excitation, C1..C4 and a constant vertical force (a term's
    parameter, which has no entry among the constants' units)."""
    fit = EquationError(twin_log, model, terms=(constant_force(model.params, "vertical"),)).fit()
    assert fit.success, fit.message
    return fit


VARIABLE = re.compile(
    r"^    (?P<name>\S+)\s*:\s+(?P<value>\S+) \+/- (?P<stderr>\S+)\s+\((?P<rel>\S+)%\)\s+"
    r"\(init = (?P<init>\S+)\)(?:  \[(?P<unit>.+)\])?$"
)


def _variables(report: str) -> dict[str, dict[str, str]]:
    lines = report.splitlines()
    start = lines.index("[[Variables]]") + 1
    out = {}
    for line in lines[start:]:
        m = VARIABLE.match(line)
        if m is None:
            break
        out[m["name"]] = m.groupdict()
    return out


def test_a_fits_report_gives_each_relative_standard_error_in_percent(force_fit):
    """Each variable's line: the value, its standard error, the error relative to the value in
    percent, 100 |s / v|, to the 3 significant digits shown (the constants' are 0.01-1 %, the
    force's about 100 %: the twin has no constant force to find), and the unit of C1..C4 in brackets.
    Value and error are the fit's to the 7 and 4 digits printed."""
    rows = _variables(force_fit.report())
    assert list(rows) == list(force_fit.names)
    for k, row in rows.items():
        v, s = force_fit.values[k], force_fit.stderr[k]
        assert float(row["value"]) == pytest.approx(v, rel=5e-7)
        assert float(row["stderr"]) == pytest.approx(s, rel=5e-4)
        assert float(row["rel"]) == float(f"{100 * abs(s / v):.3g}"), (k, row["rel"])
        assert float(row["init"]) == force_fit.initial[k]
        assert row["unit"] == (UNITS[k] if k in CONSTANT_NAMES else None)


def test_a_fits_json_gives_each_parameter_the_unit_the_result_states(force_fit):
    """The JSON a script reads: every parameter's entry carries ``unit``, the unit of the result's own
    ``estimates`` and of the report's brackets: C1..C4 their units (C1 m/(s^2 A)). The term's force is
    in N (constant_force's parameter); the result does not state it today, and the file then says ""
    (no unit), never a placeholder: "" or "N" is right, anything else is not."""
    d = json.loads(json.dumps(force_fit.to_dict(), allow_nan=False))
    rows = _variables(force_fit.report())
    assert list(d["parameters"]) == list(force_fit.names)
    for k, entry in d["parameters"].items():
        assert entry["unit"] == force_fit.estimates[k].unit == (rows[k]["unit"] or ""), k
    for k in CONSTANT_NAMES:
        assert d["parameters"][k]["unit"] == UNITS[k] != ""
    assert d["parameters"]["C1"]["unit"] == "m/(s^2 A)"
    assert d["parameters"]["constant_force_vertical.force"]["unit"] in ("", "N")


# --- the layout's accelerations with terms ---------------------------------------------------
def test_layout_accelerations_are_the_models_plus_each_term_on_its_own_parameters(model):
    friction = guide_friction(model.params, "horizontal")
    force = constant_force(model.params, "vertical")
    assert (friction.n_parameters, force.n_parameters) == (2, 1)
    layout = ParameterLayout(model, ("C2", "C3", "gap_offset"), (friction, force))
    assert layout.names[:3] == ("C2", "C3", "gap_offset")
    rng = np.random.default_rng(39)
    for _ in range(5):
        c2, c3 = model.constants.C2 * rng.uniform(0.8, 1.2), model.constants.C3 * rng.uniform(0.8, 1.2)
        offset = rng.uniform(-1e-3, 1e-3)
        p_friction = rng.uniform([1.0, 5.0], [5.0, 50.0])
        p_force = rng.uniform(-3.0, 3.0, 1)
        theta = np.concatenate([[c2, c3, offset], p_friction, p_force])
        x = np.array([rng.uniform(12e-3, 22e-3), rng.uniform(-0.05, 0.05), rng.uniform(-0.03, 0.03), 0.0])
        x[3] = rng.uniform(0.002, 0.1) * rng.choice([-1.0, 1.0])
        u = rng.uniform(-3.0, 3.0, 2)
        fitted = model.with_constants(model.constants.replace(C2=c2, C3=c3))

        def expected(x_true, fitted=fitted, u=u, p_friction=p_friction, p_force=p_force):
            base = fitted.dynamics(x_true, u)[[1, 3], 0]
            du = np.zeros(2)
            extra = (
                np.asarray(friction.function(x_true, u, du, p_friction)).ravel()
                + np.asarray(force.function(x_true, u, du, p_force)).ravel()
            )
            return base + extra

        got_true = np.asarray(layout.acceleration_true(x, u, theta)).ravel()
        np.testing.assert_allclose(got_true, expected(x), rtol=1e-9, atol=1e-12)
        shifted = x.copy()
        shifted[0] += offset
        got_reading = np.asarray(layout.acceleration_reading(x, u, theta)).ravel()
        np.testing.assert_allclose(got_reading, expected(shifted), rtol=1e-9, atol=1e-12)


# --- load_logs: nothing to load --------------------------------------------------------------------------
@pytest.mark.parametrize("paths", [[], ()])
def test_load_logs_refuses_an_empty_list_saying_no_files_were_given(paths):
    """An empty selection (a shell glob that matched nothing) is refused when the logs are loaded, the
    message saying that no log files were given."""
    with pytest.raises(InputError, match="no log files given"):
        load_logs(paths)


# --- ParameterLayout.unit -----------------------------------------------------------------------------
def test_the_layout_gives_each_parameters_unit(model):
    layout = ParameterLayout(
        model, estimate=(*CONSTANT_NAMES, "gap_offset"), terms=(constant_force(model.params, "vertical"),)
    )
    # the units of LumpedConstants' docstring (L_i = C_i x shape function of the gap) and the gap's
    expected = {
        "C1": "m/(s^2 A)",
        "C2": "m/(s^2 T^2)",
        "C3": "m/(s^2 A T)",
        "C4": "m/(s^2 A^2)",
        "gap_offset": "m",
    }
    for name, unit in expected.items():
        assert layout.unit(name) == unit, name
    # a term's parameter has no unit of the constants' table: it is given as blank, not as another's
    term_names = [n for n in layout.names if n not in expected]
    assert term_names and all(layout.unit(n) == "" for n in term_names)


# --- a report's title -----------------------------------------------------------------------------------
def test_a_fit_of_a_method_without_a_title_reports_the_methods_name():
    assert make_fit(method="output_error").report().startswith("[[Fit: output error")
    assert make_fit(method="my_own_fit").report().startswith("[[Fit: my_own_fit]]")
