"""reports/identification.pdf and reports/closing_the_loop.pdf (issue 14): every number of the
scorecards on page 1 recomputed from the study results by another route, and no near-empty page.

Quick tests score shortened studies (their numbers differ from the report's, the arithmetic is the
same); the slow ones write the reports from the full studies and check their pages.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.identification.layout import CONSTANT_NAMES
from maglev_oc.model.equilibrium import equilibrium_currents

# Tables II and III of paper 000 (Sec. V-B and V-D), eps = 0.001, 0.01, 0.05
TABLE_III = {"C1": (13.97, 14.20, 16.23), "C2": (796.93, 796.99, 795.01), "C3": (30.33, 31.04, 33.44)}
TABLE_III["C4"] = (0.06, 0.07, 0.15)
TABLE_II_EPS001 = {"C2": 791.00, "C3": 30.90, "C4": 0.12}
COGGING_C2_PAPER = 769.99  # 000 Sec. V-C: C2 at x3 = 3 t1/2, eps = 0.01
L1_PAPER = (3.8, 10.0)  # 002: NPFSI vs parabolas, mean and largest difference [%]


def _words(text: str) -> str:
    """Text with line breaks and no-break spaces as single spaces (cells are wrapped)."""
    return " ".join(str(text).split())


def _row(rows, start: str) -> list[str]:
    """The only row whose first cell starts with ``start`` (cells as single-spaced text)."""
    found = [[_words(c) for c in r] for r in rows if _words(r[0]).startswith(start)]
    assert len(found) == 1, (start, [_words(r[0]) for r in rows])
    return found[0]


def _pcts(cell: str) -> dict[str, float]:
    """{"C1": -3.39, ...} from '... C1 -3.39 %, C2 ...'."""
    return {k: float(v) for k, v in re.findall(r"(C\d) ([+-]?\d+(?:\.\d+)?) %", cell)}


def _numbers(cell: str) -> list[float]:
    return [float(x) for x in re.findall(r"[+-]?\d+(?:\.\d+)?", cell)]


# --- identification ----------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def small_identification(model):
    """The identification study and the eps-trend study with shorter runs (about 10 s instead of 50)."""
    from maglev_oc.identification.eps_trend import eps_trend_study
    from maglev_oc.identification.study import run_study

    st = run_study(model, duration=12.0, coverage_seeds=2, coverage_duration=8.0, vertical_duration=10.0)
    return st, eps_trend_study(model, duration=12.0, vertical_duration=10.0)


def _truth() -> dict[str, float]:
    from maglev_oc.identification.experiments import TWIN_TRUTH

    return dict(zip(("C1", "C2", "C3", "C4"), TWIN_TRUTH.as_array(), strict=True))


def check_identification_scorecard(st, trend, rows) -> None:
    """Every number of the identification scorecard against a recomputation from ``st`` (the
    identification study) and ``trend`` (the eps-trend study on the same runs)."""
    truth = _truth()

    row = _row(rows, "NPFSI finds C1..C4")
    assert _numbers(row[1]) == pytest.approx([v[1] for v in TABLE_III.values()])  # Table III, eps = 0.01
    run = next(r for r in st.npfsi_observer if r.eps == 0.01)
    for k, pct in _pcts(row[2]).items():
        assert pct == pytest.approx(100 * (run.values[k] - truth[k]) / truth[k], abs=0.006)  # 2 decimals
    assert set(_pcts(row[2])) == set(truth)

    row = _row(rows, "NPFSI finds C2..C4")
    assert _numbers(row[1]) == pytest.approx(list(TABLE_II_EPS001.values()))
    run = next(r for r in st.table2 if r.eps == 0.01)
    got = _pcts(row[2])
    assert set(got) == {"C2", "C3", "C4"}
    for k, pct in got.items():
        assert pct == pytest.approx(100 * (run.values[k] / truth[k] - 1), abs=0.006)

    row = _row(rows, "The estimates grow with eps")
    paper = _pcts(row[1])
    for k, pct in paper.items():  # printed to the unit (to 0.1 below 1 %)
        lo, _, hi = TABLE_III[k]
        assert pct == pytest.approx(100 * (hi / lo - 1), abs=0.51)
    plain_twin, rough = (_pcts(part) for part in row[2].split(";"))
    lo, hi = (next(r for r in st.npfsi_observer if r.eps == e) for e in (0.001, 0.05))
    for k, pct in plain_twin.items():  # the study's own runs: the trend study repeats them
        assert pct == pytest.approx(100 * (hi.values[k] / lo.values[k] - 1), abs=0.51)
    f3 = trend.friction_table3
    for k, pct in rough.items():
        values = f3.values[f3.names.index(k)]
        assert pct == pytest.approx(100 * (values[-1] / values[0] - 1), abs=0.51)
    assert set(paper) == set(plain_twin) == set(rough) == {"C1", "C3", "C4"}
    same = all(np.sign(paper[k]) == np.sign(plain_twin[k]) for k in paper)
    assert row[3].startswith("reproduced" if same else "differs")

    # with friction, every constant of both tables moves the papers' way (up, down, or flat within the
    # band), recomputed from the estimates
    def direction(values) -> str:
        change = values[-1] / values[0] - 1
        return "flat" if abs(change) < trend.band else ("up" if change > 0 else "down")

    agree = all(
        direction(getattr(trend, f"friction_{t}").values[i])
        == direction(getattr(trend, f"papers_{t}").values[i])
        for t in ("table2", "table3")
        for i in range(len(getattr(trend, f"papers_{t}").names))
    )
    if not same:
        said = "with guide friction (damping) every constant of both tables moves the papers' way" in row[3]
        assert said == agree

    row = _row(rows, "Parabolas and NPFSI agree")
    assert _numbers(row[1]) == pytest.approx(list(L1_PAPER))
    parabola = np.array([p.L1 for p in st.parabolas])
    npfsi = np.array([r.values["L1"] for r in st.fixed_gap_npfsi[0.01]])
    diff = 100 * np.abs(npfsi / parabola - 1)
    mean, largest = _numbers(row[2])[:2]
    assert (mean, largest) == pytest.approx((diff.mean(), diff.max()), abs=0.051)

    row = _row(rows, "Eq. (8) predicts equilibrium currents")
    eq = st.equilibrium_x0
    predicted = equilibrium_currents(st.table2_model, eq.gap).current
    band = (eq.gap >= 15e-3 - 1e-9) & (eq.gap <= 25e-3 + 1e-9) & (np.abs(eq.current) >= 0.3)
    worst = np.max(100 * np.abs(predicted - eq.current)[band] / np.abs(eq.current[band]))
    assert _numbers(row[2])[0] == pytest.approx(worst, abs=0.051)
    assert row[3] == ("reproduced" if worst < 5.0 else "differs: more than 5 %")

    row = _row(rows, "Below 15 mm they diverge")
    assert f"{100 * (COGGING_C2_PAPER / TABLE_II_EPS001['C2'] - 1):+.1f} %" in row[1]
    eq = st.equilibrium_cogging
    error = 1e3 * (equilibrium_currents(st.table2_model, eq.gap).current - eq.current)  # [mA]
    at = {round(g * 1e3): e for g, e in zip(eq.gap, error, strict=True)}
    printed = re.search(
        r"([+-]\d+) mA at 15 mm, ([+-]\d+) mA at 10 mm; cogging ([\d.]+) N at 15 mm \(twin ([\d.]+) N\); "
        r"C2 ([+-][\d.]+) %",
        row[2],
    )
    assert printed, row[2]
    e15, e10, xi15, true15, c2_pct = map(float, printed.groups())
    assert (e15, e10) == pytest.approx((at[15], at[10]), abs=0.51)
    # the procedure's force at 15 mm: M_v (C2 at 3 t1/2 - C2 at x3 = 0) L2(15 mm) / C2
    nominal = st.nominal
    l2 = float(nominal.coefficients([15e-3])[1, 0]) / nominal.constants.C2
    c2_cog, c2_ref = st.cogging_npfsi.values["C2"], next(r for r in st.table2 if r.eps == 0.01).values["C2"]
    assert xi15 == pytest.approx(abs(nominal.params.mass_vertical * (c2_cog - c2_ref) * l2), abs=0.006)
    assert true15 == pytest.approx(1.5, abs=0.006)  # the twin's cogging: 1.5 N at 15 mm
    assert c2_pct == pytest.approx(100 * (c2_cog / c2_ref - 1), abs=0.051)

    row = _row(rows, "Not in the papers: least squares")
    errors = [
        100 * abs(f.values[k] / truth[k] - 1) for f in (st.equation_error, st.output_error) for k in truth
    ]
    z = [
        abs(f.values[k] - truth[k]) / f.stderr[k] for f in (st.equation_error, st.output_error) for k in truth
    ]
    printed = re.search(
        r"errors ([\d.]+) % at most, within ([\d.]+) standard errors; \|z\| ≤ 2 for (\d+) of (\d+) "
        r"estimates on (\d+) more runs",
        row[2],
    )
    assert printed, row[2]
    worst, z_max, inside, total, runs = map(float, printed.groups())
    assert worst == pytest.approx(max(errors), abs=0.0051)
    assert z_max == pytest.approx(max(z), abs=0.051)
    cov = st.coverage
    assert (inside, total, runs) == (np.sum(np.abs(cov.z) <= 2), cov.z.size, cov.z.shape[0])


def test_identification_scorecard_numbers_are_the_studys(small_identification):
    from maglev_oc.analyses.identification import SCORECARD_COLUMNS, scorecard_rows

    st, trend = small_identification
    rows = scorecard_rows(st, trend)
    assert all(len(r) == len(SCORECARD_COLUMNS) for r in rows)
    check_identification_scorecard(st, trend, rows)


def test_the_table_ii_model_is_the_vertical_runs_eps_001_estimate_and_says_so(small_identification):
    # 000 Sec. V-C predicts the equilibrium currents and the cogging from Table II's constants (NPFSI
    # at eps = 0.01, x3 = 0): the study's model for that carries exactly that run's C2..C4, the
    # nominal C1 (the vertical runs do not move x3), and a source naming where they come from
    st, _ = small_identification
    run = next(r for r in st.table2 if r.eps == 0.01)
    c = st.table2_model.constants
    assert {k: getattr(c, k) for k in ("C2", "C3", "C4")} == {k: run.values[k] for k in ("C2", "C3", "C4")}
    assert c.C1 == st.nominal.constants.C1
    assert c.source == "Table II style: NPFSI eps = 0.01, x3 = 0"


def test_the_single_shooting_figure_is_the_first_second_with_the_true_constants(small_identification):
    """The figure "Why the output-error fit uses multiple shooting (first second of the log)"
    draws ``st.open_loop``: the true-constant model driven by the logged currents over the first
    second (1001 samples at 1 kHz), from the zero-phase state at the first sample. Recomputed here
    from the log and the truth; the gap runs away from the encoder within that second (000: the
    vertical pole is 33-64 1/s, a 1 mm error grows e-fold in under 30 ms)."""
    from maglev_oc.identification.output_error import simulate_open_loop

    st, _ = small_identification
    assert st.open_loop.shape == (4, round(1.0 / st.log.sample_time) + 1)
    assert_allclose(st.open_loop, simulate_open_loop(st.log, st.truth, 1.0), rtol=1e-12, equal_nan=True)
    done = np.isfinite(st.open_loop[0])
    assert not done.all() or np.max(np.abs(st.open_loop[0] - st.log.x[0, : done.size])) > 1e-3


def test_identification_scorecard_has_no_internal_names(small_identification):
    from maglev_oc.analyses.identification import scorecard_rows

    text = " ".join(c for r in scorecard_rows(*small_identification) for c in r)
    assert not re.search(r"\w_\w|mapaccum|table3_eps|\(\)", text), text


def test_the_timing_table_names_every_step_of_the_study(small_identification):
    """The report's timing table: one row per step of the study's clock, each named in words (a
    step timed under no name printed as "None"), its seconds as the clock measured them."""
    from maglev_oc.analyses.identification import timing_rows

    st, trend = small_identification
    assert st.timings and all(isinstance(k, str) and k.strip() and k != "None" for k in st.timings)
    rows = {r[0]: r[1] for r in timing_rows(st, trend)}
    for k, v in st.timings.items():
        assert rows[k] == f"{v:.2f}"


# --- closing the loop ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def short_diagnosis(model):
    """A diagnosis of 10.5 s of the identification twin's excitation, and the closed loop before
    and after (about 8 s)."""
    from maglev_oc.diagnosis.feedback import compensation_study
    from maglev_oc.diagnosis.pipeline import diagnose
    from maglev_oc.identification.experiments import TWIN_TRUTH, excitation_log

    log = excitation_log(model.with_constants(TWIN_TRUTH), duration=10.5, seed=2, controller_model=model)
    diag = diagnose([log], model)
    return diag, compensation_study(diag, model)


def check_outcome_rows(diag, study, rows) -> None:
    """The scorecard's error and closed-loop rows against a recomputation from the results."""
    row = _row(rows, "held-out acceleration error")
    cell = row[-2]
    for a, axis in enumerate(("vertical", "horizontal")):
        residuals = {"before": diag.residual_before[a], "after": diag.residual_after[a]}
        rms = {k: math.sqrt(np.nanmean(r[diag.holdout] ** 2)) for k, r in residuals.items()}
        printed = re.search(rf"{axis} ([\d.e-]+) → ([\d.e-]+) m/s²", cell)
        assert printed, cell
        assert float(printed[1]) == pytest.approx(rms["before"], rel=6e-3)  # 3 significant digits
        assert float(printed[2]) == pytest.approx(rms["after"], rel=6e-3)
    row = _row(rows, "FL regulator")
    from maglev_oc.sim.scenarios import paper_scenarios

    scenario = paper_scenarios()[study.scenario]
    for res, k in ((study.result_before, 1), (study.result_after, 2)):
        window = res.t >= scenario.evaluate_from
        for a, (axis, j) in enumerate((("vertical", 0), ("horizontal", 3))):
            mean = np.nanmean(np.abs(res.y[a, window] - res.reference[j, window])) * 1e6
            printed = re.search(rf"{axis} ([\d.]+) → ([\d.]+) µm", row[-2])
            assert float(printed[k]) == pytest.approx(mean, abs=0.051)


def test_diagnosis_scorecard_numbers_are_the_diagnosis(short_diagnosis):
    from maglev_oc.diagnosis.words import plain
    from maglev_oc.reporting.diagnosis_report import scorecard_table

    diag, study = short_diagnosis
    table = scorecard_table(diag, study)
    check_outcome_rows(diag, study, table.rows)
    names = [_words(r[0]) for r in table.rows]
    for e in diag.effects:  # one row per effect, in words, with its sizes
        row = _row(table.rows, plain(e.name))
        for k, v in e.parameters.items():
            if k in ("coulomb", "viscous", "amplitude", "force"):
                assert f"{v.value:.4g}" in row[1]
    assert not any("_" in n for n in names)


def test_effect_names_are_plain_words():
    from maglev_oc.diagnosis.words import plain

    assert plain("cogging_vertical_38mm") == "normal cogging (38 mm period)"
    assert plain("cogging_horizontal_19mm") == "cogging along the travel (19 mm period)"
    assert plain("constant_vertical_force") == "constant vertical force"
    assert plain("guide_friction_horizontal") == "horizontal guide friction"
    assert plain("guide_friction_vertical_with_stribeck") == "vertical guide friction with its Stribeck rise"
    assert (
        plain("guide_friction_horizontal_with_stribeck_without_viscous")
        == "horizontal guide friction with its Stribeck rise, without its viscous part"
    )
    assert plain("guide_waviness_22mm") == "guide waviness (22 mm period)"
    assert plain("something_new") == "something new"


# --- the reports as written (slow) ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def identification_report(model, tmp_path_factory, shared_eps_trend):
    """The identification study, the eps-trend study (shared with tests/test_eps_trend.py) and
    their report."""
    from maglev_oc.analyses.identification import write_report

    from maglev_oc.identification.study import run_study

    st, trend = run_study(model), shared_eps_trend
    return st, trend, write_report(tmp_path_factory.mktemp("ident") / "identification.pdf", st, trend)


@pytest.mark.slow
def test_identification_report_pages_are_used_and_page_1_is_the_scorecard(identification_report):
    st, trend, contents = identification_report
    assert contents.sparse_pages() == []
    assert contents.pages[0].heading.startswith("Scorecard")
    scorecard = contents.sections[0]
    assert scorecard.columns[0].startswith("claim")
    check_identification_scorecard(st, trend, scorecard.rows)
    assert contents.n_pages <= 12  # 21 before issue 14
    text = contents.text()
    assert not re.search(r"mapaccum|TwinEffects|table3_eps|vertical_force_offset", text)


@pytest.fixture(scope="module")
def closing_the_loop_report(model, tmp_path_factory):
    from maglev_oc.analyses.closing_the_loop import run_study, write_report

    st = run_study(model)
    return st, write_report(tmp_path_factory.mktemp("ctl") / "closing_the_loop.pdf", st)


@pytest.mark.slow
def test_closing_the_loop_report_pages_and_truth(closing_the_loop_report):
    from maglev_oc.reporting.twins import twin_sentence

    st, contents = closing_the_loop_report
    assert contents.sparse_pages() == []
    scorecard = contents.sections[0]
    assert scorecard.columns[1] == "true (twin)"
    check_outcome_rows(st.diagnosis, st.compensation, scorecard.rows)
    # the twin's truth, stated once in the shared words
    assert _words(twin_sentence("diagnosis twin")) in _words(contents.text())
    truth, diag = st.twin.model.constants, st.diagnosis
    row = _row(scorecard.rows, "C1..C4, refitted")
    assert _numbers(row[1]) == pytest.approx([truth.C1, truth.C2, truth.C3, truth.C4], rel=1e-3)
    worst = max(abs(diag.constants_final[k].value / getattr(truth, k) - 1) for k in ("C1", "C2", "C3", "C4"))
    assert row[3].startswith(f"found, within {100 * worst:.1f} %")
    effects = st.twin.effects
    level = st.model.params.mass_horizontal * st.model.params.gravity * effects.misalignment.level_tilt
    assert _numbers(_row(scorecard.rows, "horizontal guides off level")[1])[0] == pytest.approx(
        level, abs=5.1e-5
    )  # printed to 3 significant digits
    # beside the friction the tilt's force is found in the friction's entry (read two ways:
    # pipeline._merged_friction_by_direction), 0.0159 N for 0.0156, within the 30 %
    found_level = _numbers(_row(scorecard.rows, "horizontal guides off level")[2])[0]
    assert found_level == pytest.approx(level, rel=0.3)
    # the twin's binding (friction rising by 3 N/m |x3|) is reported by its signature, not named
    assert "changing along the track" in _row(scorecard.rows, "guide binding")[2]
    row = _row(scorecard.rows, "horizontal guide friction")
    assert _numbers(row[1])[:2] == pytest.approx([effects.friction_horizontal.coulomb, 1.0])
    found = next(e for e in diag.effects if e.name == "guide_friction_horizontal")
    coulomb = found.parameters["coulomb"]
    pct = 100 * (coulomb.value / effects.friction_horizontal.coulomb - 1)
    if abs(coulomb.value - effects.friction_horizontal.coulomb) > 2 * coulomb.stderr:
        assert f"Coulomb {pct:+.0f} %" in row[3]
    # the twin's normal cogging (000 eq. (9): period 2 t1 = 38 mm, logged over 1.3 periods) is
    # found, and sized within 30 % (the diagnosis issue's bound) at the gap it was logged at, where
    # the twin's law (reference_gap / gap)^exponent gives the truth (measured -13 %)
    cog = next(e for e in diag.effects if e.name == "cogging_vertical_38mm")
    c, at = effects.cogging, cog.parameters["at_gap"].value
    true_at = c.peak_at_reference * (c.reference_gap / at) ** c.exponent
    assert cog.parameters["amplitude"].value == pytest.approx(true_at, rel=0.3)
    # no internal identifiers anywhere
    assert not re.search(r"\w_\w", " ".join(_words(c) for r in scorecard.rows for c in r))


# --- the identification study behind the report: the numbers (slow; one study for the
# report and these, shared through the module fixture above) ---------------------------------------
@pytest.mark.slow
def test_nls_meets_the_requirement_and_covers_the_truth(identification_report):
    study = identification_report[0]
    truth = study.truth_values
    for fit in (study.equation_error, study.output_error):
        err = fit.relative_errors(truth)
        assert max(abs(err[k]) for k in ("C1", "C2", "C3")) < 0.01
        assert abs(err["C4"]) < 0.10
        assert max(abs(z) for z in fit.z_scores(truth).values()) < 3.0
    assert np.all(np.abs(study.coverage.z) < 4.0)


@pytest.mark.slow
def test_npfsi_bias_grows_with_eps_and_vanishes_with_zero_phase_velocities(identification_report):
    study = identification_report[0]
    truth = study.truth_values
    c1 = [r.values["C1"] / truth["C1"] - 1 for r in study.npfsi_observer]
    assert c1[2] < c1[0] < 0  # eps = 0.05 further off than 0.001, both low
    for run in study.npfsi_zero_phase[:2]:
        for k in ("C1", "C2", "C3"):
            assert run.values[k] == pytest.approx(truth[k], rel=0.005)
    assert {r.eps for r in study.table2} == {0.001, 0.01, 0.05}
    assert all(r.names == ("C2", "C3", "C4") for r in study.table2)


@pytest.mark.slow
def test_verification_in_the_papers_form(identification_report):
    study = identification_report[0]
    # parabola vs NPFSI: the papers' 3.8 % mean / 10 % max are the scale to compare with
    for comp in study.parabola_comparisons.values():
        assert comp.mean_pct < 6.0 and comp.max_pct < 10.0
    true_l1 = study.truth.coefficients(np.array([p.gap for p in study.parabolas]))[0]
    assert np.allclose([p.L1 for p in study.parabolas], true_l1, rtol=1e-3)
    # equilibrium currents at x3 = 0 within 5 % over 15-25 mm (papers)
    assert study.prediction_x0.max_pct(15e-3, 25e-3) < 5.0
    # with cogging (x3 = 3 t1/2) the current error grows as the gap closes below 15 mm
    e = study.prediction_cogging
    i10, i15 = (int(np.argmin(np.abs(e.gap - g))) for g in (10e-3, 15e-3))
    assert e.error[i10] > 1.8 * e.error[i15] > 0
    # the cogging procedure estimates its size where the run excited it (15 mm: 1.5 N)
    k15 = int(np.argmin(np.abs(study.cogging_gaps - 15e-3)))
    assert abs(study.cogging_xi_npfsi[k15]) == pytest.approx(abs(study.cogging_xi_true[k15]), rel=0.25)
    assert study.cogging_npfsi.values["C2"] < study.table2[1].values["C2"]


@pytest.mark.slow
def test_report_prints_the_study(identification_report):
    study, _, report = identification_report
    assert report.path.read_bytes()[:5] == b"%PDF-"
    table = report.section("Least squares")
    assert table.column("") == CONSTANT_NAMES
    truth = study.truth_values
    for k in CONSTANT_NAMES:
        row = table.row(k)
        assert float(row[1]) == pytest.approx(truth[k], rel=1e-4)  # printed to 5 digits
        for first, fit in ((3, study.equation_error), (7, study.output_error)):
            assert float(row[first]) == pytest.approx(fit.values[k], rel=1e-5)
            z = (fit.values[k] - truth[k]) / fit.stderr[k]
            assert float(row[first + 3]) == pytest.approx(z, abs=0.006)  # printed to 0.01


def test_a_small_drop_of_the_error_is_not_printed_as_zero():
    """The diagnose scorecard's drops: one decimal below 10 % (a claimed effect that lowers the
    held-out error by 0.5 % read "−0 %"), whole per cent above; no drop without a base error."""
    from maglev_oc.reporting.diagnosis_report import _drop

    assert _drop(1.0, 0.995) == "0.5 %"
    assert _drop(0.02, 0.01) == "50 %"
    assert _drop(1.0, 1.02) == "-2.0 %"
    assert _drop(0.0, 1.0) == "—"
