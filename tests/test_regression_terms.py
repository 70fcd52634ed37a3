"""The one term type (identify and diagnose): its contract, linearity, features and the provided physics."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.errors import InputError
from maglev_oc.identification.layout import ParameterLayout
from maglev_oc.regression.terms import (
    AccelerationTerm,
    cogging_term,
    constant_acceleration,
    constant_force,
    guide_friction,
    is_linear_in_parameters,
    periodic_force,
    viscous_friction,
)


def _fn(n_p: int = 1) -> ca.Function:
    x, u, p = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("p", n_p)
    return ca.Function("f", [x, u, p], [ca.vertcat(p[0] * x[1], 0)])


def test_contract_fields():
    term = AccelerationTerm(
        name="drag",
        explanation="Air drag on the mover.",
        axis="vertical",
        parameter_names=("c",),
        initial=(0.0,),
        scale=(1.0,),
        lower=(-math.inf,),
        upper=(math.inf,),
        function=_fn(),
    )
    # the positional order the identify API has always had, then the physics for reports
    assert list(term.__dataclass_fields__)[:9] == [
        "name",
        "explanation",
        "axis",
        "parameter_names",
        "initial",
        "scale",
        "lower",
        "upper",
        "function",
    ]
    assert term.qualified_names == ("drag.c",)
    assert term.is_linear()
    # a 3-input function (x, u, p) is taken as not depending on the current rates
    assert term.function.n_in() == 4 and not term.depends_on_inputs()
    feats = np.asarray(term.features([0.02, 0.3, 0, 0], [0, 0], [0, 0]))
    assert_allclose(feats, [[0.3], [0.0]])
    with pytest.raises(AttributeError):
        term.name = "other"  # frozen


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"axis": "sideways"}, "axis"),
        ({"initial": (0.0, 1.0)}, "initial has 2 values"),
        ({"scale": (0.0,)}, "scale positive"),
        ({"lower": (1.0,)}, "lower <= initial"),
        ({"function": _fn(2)}, r"\(x \(4\), u \(2\), p \(1\)\)"),
        ({"function": None}, "casadi.Function"),
        ({"parameter_names": ()}, "at least one parameter"),
        ({"name": ""}, "non-empty"),
    ],
)
def test_invalid_terms_are_refused_when_made(changes, match):
    base = dict(
        name="t",
        explanation="e.",
        axis="both",
        parameter_names=("a",),
        initial=(0.0,),
        scale=(1.0,),
        lower=(-1.0,),
        upper=(1.0,),
        function=_fn(),
    )
    base.update(changes)
    with pytest.raises(ValueError, match=match):
        AccelerationTerm(**base)


def test_linearity_detection():
    x, u, p = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("p", 2)
    lin = ca.Function("l", [x, u, p], [ca.vertcat(p[0] * ca.sin(x[2]), p[1] * u[0])])
    non = ca.Function("n", [x, u, p], [ca.vertcat(ca.exp(p[0]) * x[1], p[1])])
    assert is_linear_in_parameters(lin)
    assert not is_linear_in_parameters(non)


def test_provided_terms(model):
    cog = cogging_term(model.params)
    assert cog.axis == "vertical" and cog.is_linear()
    # at x3 = t1/2 the sine part is at its peak: x2' += -a_s (ref/x1)^3 / M_v
    x = [15e-3, 0, model.params.slot_pitch / 2, 0]
    acc = np.asarray(cog.function(x, [0, 0], [0, 0], [1.5, 0.0])).ravel()
    assert acc[0] == pytest.approx(-1.5 / model.params.mass_vertical)
    assert acc[1] == 0.0
    for term in (constant_acceleration("horizontal"), viscous_friction("vertical")):
        assert term.is_linear()
    with pytest.raises(ValueError, match="axis"):
        constant_acceleration("both")
    layout = ParameterLayout(model, ("C1", "C2"), (cog, viscous_friction("horizontal")))
    assert layout.names == ("C1", "C2", "cogging.sin_peak", "cogging.cos_peak", "viscous_horizontal.rate")
    assert layout.linear
    assert layout.fixed() == {"C3": model.constants.C3, "C4": model.constants.C4}
    with pytest.raises(ValueError, match="duplicate"):
        ParameterLayout(model, ("C1",), (cog, cog))
    with pytest.raises(ValueError, match="nothing to estimate"):
        ParameterLayout(model, (), ())
    assert not ParameterLayout(model, ("C1", "gap_offset")).linear


def test_defaults_and_physical_units(model):
    x, u, p = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("p", 2)
    fn = ca.Function("f", [x, u, p], [ca.vertcat(p[0], p[1])])
    term = AccelerationTerm("t", "e.", "both", ("a", "b"), function=fn)
    assert term.initial == (0.0, 0.0) and term.scale == (1.0, 1.0)
    assert term.lower == (-math.inf, -math.inf) and term.upper == (math.inf, math.inf)
    # no conversion given: the parameters themselves with their standard errors
    est = term.physical_parameters(np.array([1.0, 2.0]), np.diag([0.04, 0.09]))
    assert est["a"].value == 1.0 and est["b"].stderr == pytest.approx(0.3)


def test_friction_force_and_periodic_terms_in_newtons(model):
    params = model.params
    fr = guide_friction(params, "horizontal")
    assert fr.linear and not fr.depends_on_inputs() and len(fr.variants) == 2
    # far above the reversal speed tanh = 1: acc = -(F_c + c v) / M_h
    acc = np.asarray(fr.function([0.02, 0, 0, 0.1], [0, 0], [0, 0], [1.0, 2.0])).ravel()
    assert acc[1] == pytest.approx(-(1.0 + 2.0 * 0.1) / params.mass_horizontal, rel=1e-9)
    est = fr.physical_parameters(np.array([1.0, 2.0]), np.diag([0.01, 0.04]))
    assert (est["coulomb"].unit, est["viscous"].unit) == ("N", "N s/m")
    # a vertical force towards the stator closes the gap: x2' decreases by F / M_v
    cf = constant_force(params, "vertical")
    acc = np.asarray(cf.function([0.02, 0, 0, 0], [0, 0], [0, 0], [2.0])).ravel()
    assert acc[0] == pytest.approx(-2.0 / params.mass_vertical)
    # periodic: amplitude and phase from (sin, cos) by the delta method
    pf = periodic_force(params, "horizontal", 0.019)
    est = pf.physical_parameters(np.array([3.0, 4.0]), np.diag([0.01, 0.01]))
    assert est["amplitude"].value == pytest.approx(5.0) and est["amplitude"].stderr == pytest.approx(0.1)
    assert est["period"].value == 0.019
    # growing as the gap closes: (g_ref / x1)^n, stated at the reference gap it was given
    grow = periodic_force(params, "vertical", 0.019, gap_exponent=2.0, reference_gap=0.015)
    assert grow.physical_parameters(np.array([3.0, 4.0]), np.eye(2))["at_gap"].value == 0.015
    at_ref = np.asarray(grow.function([0.015, 0, 0.019 / 4, 0], [0, 0], [0, 0], [1.0, 0.0])).ravel()
    closer = np.asarray(grow.function([0.0075, 0, 0.019 / 4, 0], [0, 0], [0, 0], [1.0, 0.0])).ravel()
    assert at_ref[0] == pytest.approx(-1.0 / params.mass_vertical)  # sin(pi/2) = 1 N towards the stator
    assert closer[0] == pytest.approx(4 * at_ref[0])  # half the gap, exponent 2
    for bad in (dict(period=0.0), dict(period=-0.019), dict(reference_gap=0.0), dict(gap_exponent=-1.0)):
        kw = {"period": 0.019, **bad}
        with pytest.raises(InputError):
            periodic_force(params, "vertical", kw.pop("period"), **kw)


def test_guide_friction_on_an_axis_it_does_not_have_is_refused_naming_it():
    """The friction term exists on the two axes only: another name is refused with an error that
    names the axes it may be and the one given (a message-less error tells a user nothing)."""
    from maglev_oc.model.parameters import StageParameters
    from maglev_oc.regression.terms import guide_friction

    with pytest.raises(InputError, match=r"axis must be 'vertical' or 'horizontal', got 'diagonal'"):
        guide_friction(StageParameters(), "diagonal")
    for axis in ("vertical", "horizontal"):
        assert guide_friction(StageParameters(), axis).axis == axis
