"""The constants and error bars a diagnosis reports after its joint refit
(``maglev_oc.diagnosis.refit``), on the synthetic horizontal logs of
``tests/test_statistics_properties.py`` (the gap held, so the vertical constants are not
identified there): a locked axis's constants are reported as unknown and kept at the model's,
a fitted constant is the fit's with its standard error, and the model-form spread and the
differentiator's calibration enter the standard errors in quadrature, each with its size. About
2 s of CPU."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from maglev_oc.diagnosis.refit import CALIBRATION, constants_of, fitted_model, moved, with_model_form_spread
from maglev_oc.model.parameters import LumpedConstants
from maglev_oc.regression.data import prepare
from maglev_oc.regression.design import build_design
from maglev_oc.regression.solve import fit_subset
from maglev_oc.regression.terms import term_function
from maglev_oc.results import Estimate
from tests.test_statistics_properties import RATE_FRICTION, _design, _friction_candidate, _log


@pytest.fixture(scope="module")
def design(model):
    return _design(model, _log(model, friction=RATE_FRICTION))


def test_constants_of_a_locked_axis_are_unknown_and_the_fitted_one_is_the_fits(design, model):
    fit = fit_subset(design, ["base", "viscous_horizontal"])
    c = constants_of(design, fit, model)
    assert list(c) == ["C1", "C2", "C3", "C4"]
    assert c["C1"].value == fit.value("C1") and c["C1"].stderr == fit.stderr("C1") > 0
    for name in ("C2", "C3", "C4"):  # the vertical axis does not move on these logs
        assert math.isnan(c[name].value) and math.isnan(c[name].stderr)
    # the synthetic current was computed with the model's C1: the fit returns it (to 1e-3, the
    # friction's and the noise's share)
    assert c["C1"].value == pytest.approx(model.constants.C1, rel=1e-3)


def test_fitted_model_takes_a_moving_axis_positive_constant_only(model):
    """The model after the fit of all four constants (as the diagnosis fits them): a constant of
    a moving axis is the fit's, one of an axis declared locked stays the model's whatever the fit
    says, and a non-positive value is refused (the model's kept)."""
    data = prepare([_log(model, friction=RATE_FRICTION)], bandwidth=10.0)
    train, hold = data.masks(0.25)
    d = build_design(data, model, terms=[_friction_candidate().term], fit=train, holdout=hold)
    fit = fit_subset(d, ["base", "viscous_horizontal"])
    assert fit.names[:4] == ("C1", "C2", "C3", "C4")
    # values the fit could have had: every constant 10 % above the model's
    c0 = np.asarray(model.constants.as_array(), dtype=float)
    shifted = dataclasses.replace(fit, coef=np.concatenate([1.1 * c0, fit.coef[4:]]))
    for moving in ([True, True], [False, True], [True, False]):
        m = fitted_model(model, shifted, np.array(moving), "test")
        got = np.asarray(m.constants.as_array(), dtype=float)
        # C1 is horizontal, C2..C4 vertical
        want = c0 * np.where([moving[1], moving[0], moving[0], moving[0]], 1.1, 1.0)
        np.testing.assert_allclose(got, want, rtol=1e-12)
    negative = dataclasses.replace(fit, coef=np.concatenate([-c0, fit.coef[4:]]))
    m = fitted_model(model, negative, np.array([True, True]), "test")
    np.testing.assert_array_equal(np.asarray(m.constants.as_array()), c0)


def test_moved_is_the_largest_relative_change_of_a_constant(model):
    c = model.constants
    other = model.with_constants(LumpedConstants(c.C1 * 1.03, c.C2 * 0.95, c.C3, c.C4 * 1.01))
    assert moved(other, model) == pytest.approx(0.05, rel=1e-9)
    assert moved(model, model) == 0.0


def test_model_form_spread_and_calibration_add_in_quadrature(model):
    """A candidate with one variant whose column is twice the main form's: the variant's fit
    returns half the coefficient, so the spread (half the range over the forms) is a quarter
    of the value; the reported standard error is sqrt(se^2 + spread^2 + (1 % of the value)^2)
    (CALIBRATION: the differentiator's), and an angle or a length gets no calibration part."""
    data = prepare([_log(model, friction=RATE_FRICTION)], bandwidth=10.0)
    train, hold = data.masks(0.25)
    cand = _friction_candidate()
    double = term_function("viscous_horizontal", lambda x, u, du, p: ca_put(-2 * p[0] * x[3]), 1)
    cand = dataclasses.replace(cand, term=dataclasses.replace(cand.term, variants=(double,)))
    value, se = RATE_FRICTION, 0.003
    out = with_model_form_spread(
        {"rate": Estimate(value, se, "1/s")}, data, model, [cand], cand, train, hold, None
    )
    # the variant's estimate is within 5e-3 of half the planted rate (the fit's noise, a few
    # 1e-5, and the friction's 5 % tolerance of recovery do not matter at this size)
    spread = 0.25 * value
    expected = math.sqrt(se**2 + spread**2 + (CALIBRATION * value) ** 2)
    assert out["rate"].stderr == pytest.approx(expected, rel=0.02)
    assert out["rate"].value == value and out["rate"].unit == "1/s"
    angle = with_model_form_spread(
        {"rate": Estimate(value, se, "rad")}, data, model, [cand], cand, train, hold, None
    )
    assert angle["rate"].stderr == pytest.approx(math.sqrt(se**2 + spread**2), rel=0.02)


def ca_put(expr):
    import casadi as ca

    return ca.vertcat(0, expr)


def test_the_refit_with_the_effects_does_not_see_the_held_out_block(model):
    """converged_references fits the constants with the chosen effects on the training samples
    only: changing the measured accelerations on the held-out block leaves its constants exactly
    as they were, while the same change on the training block moves them."""
    from maglev_oc.diagnosis.refit import converged_references

    data = prepare([_log(model, friction=RATE_FRICTION)], bandwidth=10.0)
    train, hold = data.masks(0.25)
    chosen = ["guide_friction_horizontal"]

    def refit(d):
        m = converged_references(model, model, d, chosen, train, hold, np.array([0.0, 1.0]))
        return np.asarray(m.constants.as_array(), dtype=float)

    ref = refit(data)
    for mask, same in ((hold, True), (train, False)):
        acc = data.acc.copy()
        acc[1, mask] *= 1.2
        got = refit(dataclasses.replace(data, acc=acc))
        assert np.array_equal(got, ref) == same
