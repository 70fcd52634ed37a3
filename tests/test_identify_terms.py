"""The AccelerationTerm contract (used by the diagnosis layer) and the provided terms."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from maglev_oc.identify.layout import ParameterLayout
from maglev_oc.identify.terms import (
    AccelerationTerm,
    cogging_term,
    constant_acceleration,
    is_linear_in_parameters,
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
    assert [f for f in term.__dataclass_fields__] == [
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
    acc = np.asarray(cog.function([15e-3, 0, model.params.slot_pitch / 2, 0], [0, 0], [1.5, 0.0])).ravel()
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
