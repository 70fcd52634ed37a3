"""The identification study behind reports/identification.pdf: the issue's numbers (slow)."""

from __future__ import annotations

import numpy as np
import pytest

from maglev_oc.identification.layout import CONSTANT_NAMES


@pytest.fixture(scope="module")
def study(model):
    from maglev_oc.identification.study import run_study

    return run_study(model, coverage_seeds=4)


@pytest.mark.slow
def test_nls_meets_the_requirement_and_covers_the_truth(study):
    truth = study.truth_values
    for fit in (study.equation_error, study.output_error):
        err = fit.relative_errors(truth)
        assert max(abs(err[k]) for k in ("C1", "C2", "C3")) < 0.01
        assert abs(err["C4"]) < 0.10
        assert max(abs(z) for z in fit.z_scores(truth).values()) < 3.0
    assert np.all(np.abs(study.coverage.z) < 4.0)


@pytest.mark.slow
def test_npfsi_bias_grows_with_eps_and_vanishes_with_zero_phase_velocities(study):
    truth = study.truth_values
    c1 = [r.values["C1"] / truth["C1"] - 1 for r in study.npfsi_observer]
    assert c1[2] < c1[0] < 0  # eps = 0.05 further off than 0.001, both low
    for run in study.npfsi_zero_phase[:2]:
        for k in ("C1", "C2", "C3"):
            assert run.values[k] == pytest.approx(truth[k], rel=0.005)
    assert {r.eps for r in study.table2} == {0.001, 0.01, 0.05}
    assert all(r.names == ("C2", "C3", "C4") for r in study.table2)


@pytest.mark.slow
def test_verification_in_the_papers_form(study):
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
def test_report_prints_the_study(tmp_path, study):
    from maglev_oc.analyses.identification import write_report

    from maglev_oc.identification.eps_trend import eps_trend_study

    trend = eps_trend_study(study.nominal)
    report = write_report(tmp_path / "identification.pdf", study, trend)
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
