"""``diagnose`` end to end on a synthetic log whose answer is exact (``tests/test_regression.py``'s
horizontal sweep at a held gap, the current computed from the acceleration the plant must
produce): guide friction planted with known Coulomb and viscous parts is the one effect claimed,
with its sign and size; the reported errors before and after are the held-out RMS of the
reported residuals; the force is the acceleration times the mass; a clean log claims nothing.
About 5 s of CPU (two diagnoses of 30 s logs, one axis)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_oc.diagnosis.pipeline import diagnose
from maglev_oc.validation import Validation
from tests.diagnosis_support import check_confidence
from tests.test_regression import RATE, _synthetic
from tests.test_statistics_properties import _log

COULOMB = 0.5  # [N]
VISCOUS = 2.0  # [N s/m]
"""The planted friction: 0.5 N is a third of the horizontal weight share the library allows as
plausible (a quarter of M g = 3.9 N), and 2 N s/m gives 0.06 N at the sweep's RMS speed."""


@pytest.fixture(scope="module")
def with_friction(model):
    m = model.params.mass_horizontal
    v = np.gradient(_synthetic(model, seconds=30.0, seed=3).x[2], 1.0 / RATE)  # the plant's speed
    log = _log(model, friction=VISCOUS / m, force=lambda x3: -(COULOMB / m) * np.sign(v))
    return diagnose([log], model)


@pytest.fixture(scope="module")
def clean(model):
    return diagnose([_log(model, friction=0.0)], model)


def test_planted_friction_is_the_one_effect_with_its_sign_and_size(with_friction):
    """The Coulomb part within 3 standard errors and 10 % of 0.5 N (measured 0.514 +- 0.013),
    the viscous part within 3 standard errors of 2 N s/m (measured 1.75 +- 0.21: beside a
    Coulomb force the viscous part is the weaker signal), both positive."""
    d = with_friction
    assert [e.name for e in d.effects] == ["guide_friction_horizontal"]
    p = d.effects[0].parameters
    for name, truth in (("coulomb", COULOMB), ("viscous", VISCOUS)):
        assert p[name].value > 0 and p[name].stderr > 0
        assert abs(p[name].value - truth) < 3 * p[name].stderr, (name, p[name])
    assert p["coulomb"].value == pytest.approx(COULOMB, rel=0.1)
    assert d.unexplained == [] and d.not_separable == []


def test_reported_errors_are_the_held_out_rms_of_the_reported_residuals(with_friction, clean, model):
    """error_before / error_after: the RMS over the held-out quarter (the last, as
    ``masks(0.25)`` holds it out) of residual_before / residual_after, NaN on the locked axis,
    and the same numbers in the JSON; the friction's removal lowers it tenfold (the planted
    friction is 90 % of the base model's held-out error), a clean log's not at all."""
    for d in (with_friction, clean):
        hold = d.data.masks(0.25)[1]
        before = np.sqrt(np.mean(d.residual_before[1, hold] ** 2))
        after = np.sqrt(np.mean(d.residual_after[1, hold] ** 2))
        # Gram sums against the residuals themselves: 1e-9
        assert d.error_before.horizontal == pytest.approx(before, rel=1e-9)
        assert d.error_after.horizontal == pytest.approx(after, rel=1e-9)
        assert math.isnan(d.error_before.vertical) and math.isnan(d.error_after.vertical)
        j = d.to_dict()
        assert j["error_before"] == {"vertical": None, "horizontal": d.error_before.horizontal}
        assert j["error_after"] == {"vertical": None, "horizontal": d.error_after.horizontal}
    assert with_friction.error_after.horizontal < 0.2 * with_friction.error_before.horizontal
    assert clean.effects == [] and clean.error_after.horizontal == clean.error_before.horizontal


def test_an_effects_force_is_its_acceleration_times_the_mass(with_friction, model):
    """force_rms = contribution_rms x M_h on the axis the effect acts on, zero on the other; the
    parameter rms_force_horizontal is that force; and the contribution is the RMS of the
    Coulomb and viscous forces' acceleration over the held-out speeds (within 15 %: the
    reported one is filtered to the fit's 10 Hz band, which smooths the Coulomb force's
    reversals, and the fitted sizes are within a few % of the planted ones)."""
    e = with_friction.effects[0]
    m = model.params.mass_horizontal
    assert e.force_rms.horizontal == pytest.approx(e.contribution_rms.horizontal * m, rel=1e-12)
    assert e.force_rms.vertical == 0.0 and e.contribution_rms.vertical == 0.0
    assert e.parameters["rms_force_horizontal"].value == e.force_rms.horizontal
    d = with_friction
    hold = d.data.masks(0.25)[1]
    v = d.data.x[3, hold]
    planted = np.sqrt(np.mean(((COULOMB * np.sign(v) + VISCOUS * v) / m) ** 2))
    assert e.contribution_rms.horizontal == pytest.approx(planted, rel=0.15)


def test_the_stage_file_carries_the_refitted_constant_and_a_compensation_that_opposes_friction(
    with_friction, model
):
    """The stage file of the diagnosis: C1 (the moving axis's constant) refitted with its
    standard error, C2..C4 the model's (their axis did not move, so no covariance); the effect's
    acceleration is the fitted term's, and its compensable part is the friction force itself
    (the holding share, a nuisance, left out): at a speed far above the friction's reversal
    speed it is -(Coulomb sign(v) + viscous v) / M_h with the reported sizes, opposing the
    motion, which a feedforward cancels by adding the opposite (within 1 %: the smoothed sign at
    20x the reversal speed)."""
    from maglev_oc.diagnosis.stage_file import diagnosis_stage_file
    from maglev_oc.model.stagefile import Provenance

    d = with_friction
    sf = diagnosis_stage_file(d, model, Provenance.now((), "test"))
    c = sf.constants
    assert c.C1 == d.constants_final["C1"].value and c.C1 != model.constants.C1
    assert (c.C2, c.C3, c.C4) == (model.constants.C2, model.constants.C3, model.constants.C4)
    assert sf.covariance is None and sf.stderr["C1"] == d.constants_final["C1"].stderr > 0
    assert all(math.isnan(sf.stderr[k]) for k in ("C2", "C3", "C4"))  # unknown, not zero
    (effect,) = sf.effects
    e = d.effects[0]
    assert effect.name == e.name == "guide_friction_horizontal"
    m = model.params.mass_horizontal
    p = e.parameters
    for v in (0.1, -0.1):  # [m/s]
        x = np.array([0.02, 0.0, 0.01, v])
        i = np.array([0.3, 1.2])
        whole = effect.acceleration_function(x, i).full().ravel()
        term = e.candidate.term.acceleration(e.coefficients)(x, i, np.zeros(2)).full().ravel()
        np.testing.assert_allclose(whole, term, rtol=1e-12, atol=1e-15)
        comp = effect.compensation_function(x).full().ravel()
        expected = -(p["coulomb"].value * np.sign(v) + p["viscous"].value * v) / m
        assert comp[0] == 0.0
        assert comp[1] == pytest.approx(expected, rel=0.01)


def test_both_models_are_validated_on_the_held_out_block(with_friction):
    """The diagnosis validates the base model and the model with the effects, both on the held
    out block, and the friction it found makes the second follow the measured position better
    (fit over the shortest windows, measured 95.4 % before and 99.9 % after)."""
    d = with_friction
    before, after = d.validation_before, d.validation_after
    assert before is not None and after is not None
    assert before.model == "base model (C1..C4 refitted, no effects)"
    assert "guide_friction_horizontal" in after.model
    assert after.fits[0].fit["horizontal"] > before.fits[0].fit["horizontal"]


def test_a_choice_no_other_candidate_contested_has_full_confidence(with_friction):
    # the confidence of a choice is the share of bootstrap resamples in which it ranks first among
    # the candidates that pass at its step; with none beside it that share is 1 (not 0: no
    # resample is drawn), and it is a share whatever the contest
    check_confidence(with_friction)


def test_a_diagnosis_with_effects_validates_the_model_with_them(with_friction):
    """The friction found: the result carries the validation of the model with it (named in its
    description) beside the base model's, the JSON too, and with the friction the held-out
    horizontal prediction errs less than without it."""
    d = with_friction
    assert [e.name for e in d.effects] == ["guide_friction_horizontal"]
    after, before = d.validation_after, d.validation_before
    assert isinstance(after, Validation) and isinstance(before, Validation)
    assert "guide_friction_horizontal" in after.model
    j = d.to_dict()["validation"]
    assert j["after"] is not None and j["after"]["model"] == after.model
    assert j["after"]["residual_rms_m"] == after.to_dict()["residual_rms_m"]
    rms = [v.to_dict()["residual_rms_m"]["horizontal"] for v in (before, after)]
    assert rms[1] < rms[0]


def test_a_report_with_nothing_found_and_no_closed_loop_study_is_written(clean, tmp_path):
    """``diagnose --report --no-control`` on a log where nothing is found: no figure of the effects
    (there are none) and no study; it drew an effects figure of zero rows and stopped with an
    internal error (a measured-current log of the independent generator, 2026-12-04)."""
    from maglev_oc.reporting.diagnosis_report import write_diagnosis_report

    assert clean.effects == []
    pdf = tmp_path / "nothing.pdf"
    write_diagnosis_report(pdf, clean, study=None)
    assert pdf.read_bytes().startswith(b"%PDF") and pdf.stat().st_size > 10_000
