"""The result convention (``maglev_oc.results``) on identification's results, which the convention's
checks had not reached: an equation-error fit, a designed experiment and its predictions (NPFSI's
runs are checked in test_identify_npfsi.py).

``check_result`` asks that the JSON say what the object says (success, status, message, timings),
that it be JSON (no NaN), and that the text report name the status. On top, for each: its JSON
carries the numbers a script reads from it under their own names, equal to the object's.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from maglev_oc.identification.design import MultisineShape, design_experiment
from maglev_oc.identification.equation_error import EquationError
from maglev_oc.results import check_result

SMALL_GRID = (MultisineShape((0.1, 3.0), 6, 0.5),)
"""One multisine shape: a D-optimal design of a single candidate (about 1 s on the twin)."""


@pytest.fixture(scope="module")
def fit(model, twin_log):
    return EquationError(twin_log, model).fit()


def test_a_fit_follows_the_convention_and_its_json_carries_its_estimates(fit):
    """Each parameter's value, standard error and initial guess in the JSON are the fit's own
    (a script reading ``parameters.C1.value`` gets what ``fit.values['C1']`` says), the covariance is
    the object's, and the report prints each estimate."""
    check_result(fit)
    d = json.loads(json.dumps(fit.to_dict()))
    assert d["method"] == fit.method and d["success"] is True
    assert set(d["parameters"]) == set(fit.names)
    for k in fit.names:
        p = d["parameters"][k]
        assert p["value"] == pytest.approx(fit.values[k], rel=1e-15)
        assert p["stderr"] == pytest.approx(fit.stderr[k], rel=1e-15)
        assert p["initial"] == pytest.approx(fit.initial[k], rel=1e-15)
    np.testing.assert_allclose(np.array(d["covariance"]), fit.covariance, rtol=1e-15)
    assert d["n_samples"] == fit.n_samples and d["n_residuals"] == fit.n_residuals
    text = fit.report()
    for k in fit.names:
        assert k in text


def test_a_design_and_its_predictions_follow_the_convention(model):
    """A designed experiment, its prediction and the papers' baseline: each a result by the
    convention, and the design's JSON carries the prediction's numbers as the prediction's own
    JSON does (one source of truth for the workflow's next step)."""
    design = design_experiment("doptimal", 20.0, model=model, grid=SMALL_GRID)
    check_result(design)
    check_result(design.prediction)
    assert design.baseline is not None
    check_result(design.baseline)
    d = json.loads(json.dumps(design.to_dict()))
    assert d["kind"] == design.kind == "doptimal"
    pred = json.loads(json.dumps(design.prediction.to_dict()))
    assert d["predicted"] == pred
    p = design.prediction
    assert pred["log_det_relative_information"] == pytest.approx(p.log_det, rel=1e-15)
    assert pred["rms_current_A"] == pytest.approx(p.rms_current, rel=1e-15)
    assert [pred["peak_current_A"]["i_q"], pred["peak_current_A"]["i_d"]] == pytest.approx(p.peak_current)
    assert pred["gap_range_m"] == pytest.approx(p.gap_range) and pred["position_range_m"] == pytest.approx(
        p.position_range
    )
    assert pred["stderr"] == pytest.approx(p.stderr, rel=1e-15)
    for k, n in zip(p.names, p.nominal, strict=True):
        assert pred["relative_stderr"][k] == pytest.approx(p.stderr[k] / abs(n), rel=1e-15)
