"""Properties of ``maglev_oc.diagnosis`` written against the survivors of the seed-39 mutation-testing run
(issue 21): each test states a property of a result a user sees, not the mutated token.

* The held-out evidence of a change of residuals is judged only on the axes given: on no axis at all
  there is no evidence, (gain, z) = (0, 0), the same as replacing the residuals by themselves on
  any axis (an identity: exactly 0 and 0), whatever the residuals on the axes not judged.
* A candidate whose joint fit with the base parameters is singular (its column never excited:
  zero, singular in any arithmetic) cannot be told from the base constants at all: its variance
  inflation is infinite and the partner the user reads in ``confounded_with`` is "the base
  constants".
* With no twin given, the compensation study runs the controllers on a twin of the identified
  plant: the refitted constants AND every found effect. Recomputed here with a twin built from the
  same constants and the effect's acceleration written out by hand (a constant horizontal force,
  (0, F / M_h)), the closed-loop runs (seed 0, 1 s) agree to 1e-9 relative (the same arithmetic
  but for F * (1 / M_h) against F / M_h: a few ulps carried over a stable loop; they agree exactly
  here), while a twin without the effect is off by far more (the 2 N force moves the stage by
  about a millimetre; more than 0.1 mm is asked).
"""

from __future__ import annotations

import dataclasses
import math

import casadi as ca
import numpy as np
import pytest

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.diagnosis.candidate import Candidate
from maglev_oc.diagnosis.feedback import compensation_study
from maglev_oc.diagnosis.result import Effect
from maglev_oc.diagnosis.selection import SelectionSettings, _separability, holdout_significance
from maglev_oc.regression.terms import constant_force
from maglev_oc.results import Estimate, PerAxis
from maglev_oc.sim.effects import Encoder, TwinEffects
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.scenarios import paper_scenarios
from maglev_oc.sim.twin import RigTwin
from tests.diagnosis_support import stub_diagnosis
from tests.test_diagnosis_round2_properties import _fake_fit
from tests.test_diagnosis_seed37_properties import two_periodic  # noqa: F401  (a fixture)

FORCE = 2.0
"""[N] the found constant horizontal force of the compensation study's diagnosis."""


# --- held-out evidence on no axis ------------------------------------------------------------------------
def test_held_out_evidence_on_no_axis_is_none(two_periodic):  # noqa: F811
    """On no axis there is nothing to judge: (gain, z) is (0, 0), exactly what replacing the
    held-out residuals by themselves gives on a judged axis (no change: no gain, no evidence),
    although here the replacement residual differs from the first on every sample."""
    _, _, d = two_periodic
    n = int(d.holdout.sum())
    rng = np.random.default_rng(39)
    r0 = rng.standard_normal((2, n))
    r1 = 0.1 * rng.standard_normal((2, n))
    assert holdout_significance(d, r0, r0, np.array([1])) == (0.0, 0.0)
    assert holdout_significance(d, r0, r1, np.array([], dtype=int)) == (0.0, 0.0)
    # on a judged axis the same replacement is strong evidence: the zero above is the empty axis set's
    gain, z = holdout_significance(d, r0, r1, np.array([1]))
    assert gain == pytest.approx(1 - np.mean(r1[1] ** 2) / np.mean(r0[1] ** 2), rel=1e-12)
    assert gain > 0.9 and z > 3


# --- a candidate that is a base column -------------------------------------------------------------------
def test_a_candidate_whose_joint_fit_is_singular_is_confounded_with_the_base_constants():
    """A candidate the log never excites (its column zero) has a singular joint fit: its estimate
    is not determined beside the base parameters, its variance inflation is infinite and the user
    reads "the base constants" as what it cannot be told from. (A candidate column that copies a
    base column is singular too, but whether LAPACK meets an exact zero pivot or one at rounding
    level depends on the BLAS kernel; the zero column is singular in any arithmetic.)"""
    rng = np.random.default_rng(39)
    x = np.zeros((60, 3))
    x[:32, 0] = rng.choice([-1.0, 1.0], 32)
    x[:, 1] = rng.choice([-1.0, 0.0, 1.0], 60)
    assert np.linalg.matrix_rank(x.T @ x) == 2
    design, cand, fit = _fake_fit(x, [2])
    vif, partners = _separability(design, cand, fit, SelectionSettings())
    assert vif == math.inf
    assert partners == ("the base constants",)


# --- the compensation study's default plant --------------------------------------------------------------
def _force_found(model):
    """A stub diagnosis with the papers' constants (before and after) and one found effect: a
    constant horizontal force of ``FORCE`` N."""
    term = constant_force(model.params, "horizontal")
    cand = Candidate(term, "constant", "position", "a held position", lambda e: None, lambda e: "")
    nan = PerAxis(math.nan, math.nan)
    effect = Effect(
        term.name,
        "",
        "",
        "horizontal",
        {"force": Estimate(FORCE, 0.1, "N")},
        1.0,
        0.1,
        5.0,
        nan,
        nan,
        "",
        "",
        np.array([FORCE]),
        cand,
    )
    c = {k: Estimate(getattr(model.constants, k), 0.0, "") for k in ("C1", "C2", "C3", "C4")}
    return dataclasses.replace(stub_diagnosis(), constants_base=c, constants_final=c, effects=[effect])


def test_the_compensation_studys_default_plant_carries_the_found_effects(model):
    """The default plant, rebuilt here: the identified constants, 10 um encoders, and the found
    force written out as its acceleration (0, F / M_h). The study's runs (seed 0) are those of
    this twin; a twin with the constants alone gives visibly different runs."""
    diag = _force_found(model)
    scenario = dataclasses.replace(paper_scenarios()["sinusoid"], duration=1.0)
    study = compensation_study(diag, model, scenario=scenario)
    assert study.plant.startswith("twin of the identified plant")
    assert study.compensated == (diag.effects[0].name,)

    x, i = ca.SX.sym("x", 4), ca.SX.sym("i", 2)
    acc = ca.vertcat(0, FORCE / model.params.mass_horizontal)
    push = ca.Function("push", [x, i], [acc], ["x", "i"], ["acc"])
    with_force = RigTwin(model, TwinEffects(encoder=Encoder(), extra=push))
    without = RigTwin(model, TwinEffects(encoder=Encoder()))
    base = FeedbackLinearizingRegulator(model, name="FL, base model fitted")  # the papers' constants
    expected = ClosedLoop(with_force, base).run(scenario)
    plain = ClosedLoop(without, base).run(scenario)
    assert study.result_before.success and expected.success
    scale = np.max(np.abs(expected.x[2]))
    np.testing.assert_allclose(study.result_before.x, expected.x, rtol=1e-9, atol=1e-9 * scale)
    assert np.max(np.abs(plain.x[2] - expected.x[2])) > 1e-4
