"""Properties of ``maglev_oc.diagnosis`` written against the survivors of the seed-41 mutation-testing run
(issue 21): each test states a property of a result a user sees, not the mutated token.

* The model-form spread of an effect is the spread of its estimates over designs weighted as the
  diagnosis weights its data (the ``weights`` it is given), not over designs each weighted by its own
  residual: recomputed here with the public pieces (``build_design``, ``fit_subset``) for the end
  effects, whose parameters act on both axes, so the axes' relative weight changes their fit.
* The model that ``converged_references`` returns says where its constants came from: "diagnose:
  refit with the effects" (what the command line prints beside a model's constants and a stage file
  writes as their source).
* The compensation study's two runs are labelled "FL, base model fitted" and "FL, effects
  compensated", in its results, their metrics, and the legend of the report's compensation plot.
* Every candidate's ``separate_by`` (SPEC ``not_separable[].experiment``) continues the report's
  sentence "What would separate it: ...": a clause in lower case, no word shouted in capitals, no
  full stop of its own; the amplifier lag's names current steps measured with a current probe.
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest
from matplotlib.figure import Figure

from maglev_oc.diagnosis.candidate import LibraryContext
from maglev_oc.diagnosis.feedback import compensation_study
from maglev_oc.diagnosis.library import candidate_library, waviness_candidate
from maglev_oc.diagnosis.magnetics import end_effects_candidate
from maglev_oc.diagnosis.refit import CALIBRATION, converged_references, with_model_form_spread
from maglev_oc.diagnosis.result import NotSeparable
from maglev_oc.diagnosis.selection import fitted_constants
from maglev_oc.regression.data import prepare
from maglev_oc.regression.design import build_design
from maglev_oc.regression.solve import fit_subset
from maglev_oc.reporting.diagnosis_plots import compensation_plot
from maglev_oc.sim.scenarios import paper_scenarios
from tests.diagnosis_support import stub_diagnosis
from tests.test_diagnosis_seed39_properties import _force_found
from tests.test_statistics_properties import RATE_FRICTION, _log


# --- the model-form spread ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def twin_data(twin_log):
    """The twin's 6 s excitation (both axes move) prepared for the fits, a quarter held out."""
    data = prepare([twin_log], bandwidth=10.0)
    assert np.all(data.moving)
    return data, *data.masks(0.25)


def _end_effects_fit(data, model, cand, fn, train, hold, weights):
    """The end effects' physical parameters from a design of their ``fn`` form and ``weights``."""
    d = build_design(
        data, model, terms=[cand.term.with_function(fn)], fit=train, holdout=hold, weights=weights
    )
    fit = fit_subset(d, list(d.groups))
    coef, cov = fit.group(d, cand.name)
    return cand.term.physical_parameters(coef, cov, fitted_constants(fit))


def test_the_model_form_spread_is_taken_over_designs_weighted_as_the_diagnosis_weights_them(model, twin_data):
    """End effects (thrust and attraction losses, on both axes) with weights (1, 10): unlike each
    design's own 1 / RMS residual (about (61, 62) on this log), they change the joint fit. The spread
    of each loss over the three fall-off widths, each refitted here on designs with those weights, is
    what the standard error carries: sqrt(se^2 + spread^2 + (1 % of the value)^2), rel 1e-9 (the same
    fits). With each design's own weights five of the six spreads differ by 20-115 % (checked: the
    weights do matter here)."""
    data, train, hold = twin_data
    cand = end_effects_candidate(LibraryContext(model, data))
    weights = np.array([1.0, 10.0])
    forms = [cand.term.function, *cand.term.variants]
    assert len(forms) == 3
    weighted = [_end_effects_fit(data, model, cand, fn, train, hold, weights) for fn in forms]
    own = [_end_effects_fit(data, model, cand, fn, train, hold, None) for fn in forms]
    params = weighted[0]
    out = with_model_form_spread(params, data, model, [cand], cand, train, hold, weights)
    losses = [k for k in params if "_loss_" in k]
    assert len(losses) == 6
    differs = 0
    for k in losses:
        spread = 0.5 * np.ptp([p[k].value for p in weighted])
        own_spread = 0.5 * np.ptp([p[k].value for p in own])
        v = params[k]
        expected = math.sqrt(v.stderr**2 + spread**2 + (CALIBRATION * v.value) ** 2)
        assert out[k].value == v.value and out[k].unit == v.unit
        assert out[k].stderr == pytest.approx(expected, rel=1e-9), k
        differs += abs(own_spread / spread - 1) > 0.05
    assert differs >= 3  # the check above could fail: other weights give other spreads


# --- the refitted model's note --------------------------------------------------------------------------
def test_the_converged_model_says_it_is_the_refit_with_the_effects(model):
    """Guide friction chosen on the synthetic horizontal log: the model returned carries the source
    "diagnose: refit with the effects" (a string, also in its constants' dictionary), and its C1 is the
    joint fit's (moved from the papers' by the planted friction, so it is a refitted model)."""
    data = prepare([_log(model, friction=RATE_FRICTION)], bandwidth=10.0)
    train, hold = data.masks(0.25)
    got = converged_references(
        model, model, data, ["guide_friction_horizontal"], train, hold, np.array([0.0, 1.0])
    )
    assert got.constants.source == "diagnose: refit with the effects"
    assert got.constants.to_dict()["source"] == "diagnose: refit with the effects"
    assert got.constants.C1 != model.constants.C1
    assert (got.constants.C2, got.constants.C3, got.constants.C4) == (
        model.constants.C2,
        model.constants.C3,
        model.constants.C4,
    )  # the vertical axis is locked on this log: its constants are the model's


# --- the compensation study's labels --------------------------------------------------------------------
def test_the_compensation_studys_runs_are_labelled_before_and_after(model):
    """A found constant force, 1 s of the papers' sinusoid: the run without compensation is the "FL,
    base model fitted" regulator's and the other the "FL, effects compensated" one's, in the results,
    their metrics and the legend of the report's compensation plot (before, then after)."""
    scenario = dataclasses.replace(paper_scenarios()["sinusoid"], duration=1.0)
    study = compensation_study(_force_found(model), model, scenario=scenario)
    names = ("FL, base model fitted", "FL, effects compensated")
    assert (study.result_before.controller, study.result_after.controller) == names
    assert (study.before.controller, study.after.controller) == names
    fig = Figure(figsize=(6, 5))
    compensation_plot(study)(fig, (0.0, 0.0, 1.0, 1.0))
    assert [t.get_text() for t in fig.legends[0].get_texts()] == list(names)


# --- what separates a candidate -------------------------------------------------------------------------
def test_every_candidates_experiment_continues_the_reports_sentence(model):
    """The library on the synthetic horizontal log (every candidate, a waviness too): each
    ``separate_by`` starts in lower case, has no word of two or more capitals (none is an acronym;
    "C2..C4", "L1", "000 Sec. V-A" are not words of capitals) and no full stop at its end; the
    report's line for a not-separable amplifier lag reads as one sentence naming current steps
    measured with a current probe."""
    data = prepare([_log(model, friction=0.0)], bandwidth=10.0)
    library = [*candidate_library(model, data), waviness_candidate(model, data, 0.06)]
    assert len(library) > 15
    for cand in library:
        text = cand.separate_by
        assert text[:1].islower(), (cand.name, text)
        assert re.search(r"\b[A-Z]{2,}\b", text) is None, (cand.name, text)
        assert not text.rstrip().endswith("."), (cand.name, text)
    lag = next(c for c in library if c.name == "current_amplifier_lag")
    assert "current steps at several amplitudes, measured with a current probe" in lag.separate_by
    sep = NotSeparable(lag.name, ("C1",), lag.separate_by, 0.01, "confounded", {})
    diag = dataclasses.replace(stub_diagnosis(), not_separable=[sep])
    line = next(s for s in diag.report().splitlines() if "not separable" in s)
    assert line.endswith(f"(confounded with C1): {lag.separate_by}")
    assert "with C1): current steps at several amplitudes" in line
