"""Properties of the refit (``maglev_oc.diagnosis.refit``), checked against fits rebuilt here from
the public pieces (``build_design``, ``fit_subset``):

- ``moved`` is the largest relative change; a refit keeps the model's constant where the fit is
  not positive, not finite or its axis is locked, and the constants of an axis that does not move
  are unknown;
- the model-form spread is half the range over the variants, over designs weighted as the
  diagnosis weights them, added in quadrature with the calibration (which leaves angles and
  lengths alone);
- ``converged_references`` rebuilds the library from each refit and says its model is the refit
  with the effects.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

import maglev_oc.diagnosis.refit as refit
from maglev_oc.diagnosis.candidate import LibraryContext
from maglev_oc.diagnosis.library import candidate_library
from maglev_oc.diagnosis.magnetics import EndProfile, end_effects_candidate
from maglev_oc.diagnosis.refit import (
    CALIBRATION,
    constants_of,
    converged_references,
    fitted_model,
    moved,
    with_model_form_spread,
)
from maglev_oc.diagnosis.selection import fitted_constants
from maglev_oc.model.parameters import LumpedConstants
from maglev_oc.regression.base import CONSTANT_AXIS, CONSTANT_NAMES
from maglev_oc.regression.data import prepare
from maglev_oc.regression.design import build_design
from maglev_oc.regression.solve import fit_subset
from maglev_oc.results import AXES, Estimate
from tests.test_statistics_properties import RATE_FRICTION, _log


def test_moved_is_the_largest_relative_change(model):
    c = model.constants
    other = model.with_constants(c.replace(C3=1.05 * c.C3))
    assert moved(other, model) == pytest.approx(0.05, rel=1e-9)
    both = model.with_constants(c.replace(C1=0.99 * c.C1, C3=1.05 * c.C3))
    assert moved(both, model) == pytest.approx(0.05, rel=1e-9)


def test_fitted_model_keeps_the_models_constant_where_the_fit_is_not_usable(model):
    c = model.constants
    values = {"C1": 1.1 * c.C1, "C2": -5.0, "C3": 0.0, "C4": 1.2 * c.C4}
    fit = SimpleNamespace(value=lambda name: values[name])
    out = fitted_model(model, fit, np.array([True, True]), "test").constants
    assert (out.C1, out.C2, out.C3, out.C4) == pytest.approx((1.1 * c.C1, c.C2, c.C3, 1.2 * c.C4))
    # horizontal axis locked: C1 (horizontal) keeps the model's value
    out = fitted_model(model, fit, np.array([True, False]), "test").constants
    assert out.C1 == pytest.approx(c.C1)


def test_the_calibration_is_added_to_every_parameter_but_angles_and_lengths():
    params = {
        "force": Estimate(2.0, 0.03, "N"),
        "phase": Estimate(1.0, 0.02, "rad"),
        "period": Estimate(0.019, 1e-4, "m"),
    }
    cand = SimpleNamespace(term=SimpleNamespace(variants=()))  # no variants: no spread
    out = with_model_form_spread(params, None, None, [], cand, None, None, None)
    assert out["force"].stderr == pytest.approx(math.hypot(0.03, CALIBRATION * 2.0), rel=1e-12)
    assert out["phase"].stderr == pytest.approx(0.02, rel=1e-12)
    assert out["period"].stderr == pytest.approx(1e-4, rel=1e-12)


def test_the_model_form_spread_is_half_the_range_over_the_variants_added_in_quadrature(model, two_effects):
    # guide friction's variants reverse over half and twice its 2 mm/s (the planted friction
    # reverses over 5 mm/s, so they differ): each refitted here beside the cogging (a design of the
    # variant's term), the Coulomb force's standard error is then sqrt(se^2 + (half the range of
    # the three values)^2 + (1 % of the value)^2). The same fits: rel 1e-9
    design, lib = two_effects
    cand, other = lib["guide_friction_horizontal"], lib["cogging_horizontal_19mm"]
    data, fit_mask, hold = design.prepared, design.fit, design.holdout
    values = []
    for fn in (cand.term.function, *cand.term.variants):
        terms = [cand.term.with_function(fn), other.term]
        d = build_design(data, model, terms=terms, fit=fit_mask, holdout=hold, weights=design.weights)
        coef, cov = fit_subset(d, list(d.groups)).group(d, cand.name)
        physical = cand.term.physical_parameters(coef, cov, {})
        values.append(physical["coulomb"].value)
        if fn is cand.term.function:
            params = physical
    out = with_model_form_spread(params, data, model, [cand, other], cand, fit_mask, hold, design.weights)
    spread = 0.5 * (max(values) - min(values))
    c = params["coulomb"]
    assert spread > c.stderr  # the variants do differ
    expected = math.sqrt(c.stderr**2 + spread**2 + (CALIBRATION * c.value) ** 2)
    assert out["coulomb"].stderr == pytest.approx(expected, rel=1e-9)


def test_the_constants_of_an_axis_that_does_not_move_are_unknown_even_when_the_fit_holds_them(
    model, horizontal_all
):
    """C2..C4 are in the fit (every constant estimated, as the diagnosis does) but the vertical axis
    did not move: they are reported unknown (NaN value and error), not the fit's 0 ± 0 of a dead
    column; C1 is the fit's."""
    data, design = horizontal_all
    assert not data.moving[0] and data.moving[1]
    fit = fit_subset(design, ["base", "viscous_horizontal"])
    assert fit.names[:4] == ("C1", "C2", "C3", "C4")
    c = constants_of(design, fit, model)
    assert c["C1"].value == fit.value("C1")
    for name in ("C2", "C3", "C4"):
        assert math.isnan(c[name].value) and math.isnan(c[name].stderr), (name, c[name])


def _fit(values: dict[str, float]) -> SimpleNamespace:
    return SimpleNamespace(value=lambda name: values[name])


@pytest.mark.parametrize("bad", [0.0, -0.0, -3.0, math.nan, math.inf])
def test_a_refit_keeps_the_models_constant_where_the_fit_is_not_positive(model, bad):
    """C2 fitted to ``bad`` keeps the model's C2 (a fitted 0 is what a column that vanishes on the
    fitted rows gives: no information, not a zero constant); every positive fit of a moving
    axis is adopted exactly, and a locked axis's constant is the model's whatever its fit."""
    c0 = dict(zip(CONSTANT_NAMES, model.constants.as_array(), strict=True))
    fitted = {name: 1.25 * c0[name] for name in CONSTANT_NAMES}
    fitted["C2"] = bad
    out = fitted_model(model, _fit(fitted), np.array([True, True]), "test")
    got = dict(zip(CONSTANT_NAMES, out.constants.as_array(), strict=True))
    assert got["C2"] == c0["C2"]
    for name in ("C1", "C3", "C4"):
        assert got[name] == fitted[name]
    locked = np.array([AXES[a] == "vertical" for a in range(2)])  # horizontal axis held
    out = fitted_model(model, _fit(fitted), locked, "test")
    got = dict(zip(CONSTANT_NAMES, out.constants.as_array(), strict=True))
    for name in CONSTANT_NAMES:
        moving = CONSTANT_AXIS[name] == "vertical" and name != "C2"
        assert got[name] == (fitted[name] if moving else c0[name]), name


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


# --- the references iterated to convergence --------------------------------------------------------------
def test_converged_references_rebuilds_the_library_from_each_refit(model, monkeypatch):
    """Guide friction on the synthetic horizontal log, started from a C1 10 % low (so that several
    rounds run): handed the library of the starting model, the result is the one it gets building
    that library itself, and every library it builds is of a refitted model (none of the starting
    one, one per round after the first)."""
    data = prepare([_log(model, friction=RATE_FRICTION)], bandwidth=10.0)
    train, hold = data.masks(0.25)
    c = model.constants
    start = model.with_constants(LumpedConstants(0.9 * c.C1, c.C2, c.C3, c.C4, source="start"))
    first = candidate_library(start, data, None)
    built_for = []
    widths = []
    asked = []

    def spy(fitted, data, held=None, *, end_profile, only=None, commutation_angle=0.0):
        built_for.append(fitted.constants.C1)
        widths.append(end_profile)
        asked.append(only)
        return candidate_library(
            fitted, data, held, end_profile=end_profile, only=only, commutation_angle=commutation_angle
        )

    monkeypatch.setattr(refit, "candidate_library", spy)
    args = (model, start, data, ["guide_friction_horizontal"], train, hold, np.array([0.0, 1.0]))
    built = refit.converged_references(*args)
    rounds = len(built_for)
    assert rounds >= 2 and built_for[0] == start.constants.C1
    built_for.clear()
    handed = refit.converged_references(*args, library=first)
    assert len(built_for) == rounds - 1
    assert start.constants.C1 not in built_for
    # a round builds the chosen candidates only (library.candidate_library's ``only``)
    assert asked and all(list(a) == ["guide_friction_horizontal"] for a in asked)
    # the same fits of the same columns: rounding only
    np.testing.assert_allclose(handed.constants.as_array(), built.constants.as_array(), rtol=1e-12)
    # each rebuilt library has the end effects' fall-off handed in (the scanned one), not the default
    widths.clear()
    scanned = EndProfile(0.02, "rounded")
    refit.converged_references(*args, end_profile=scanned)
    assert widths and set(widths) == {scanned}
