"""Properties of ``maglev_oc.identification`` behind the survivors of the seed-48 mutation run:

* comparing equilibrium currents at the gap where the magnets alone carry the mover (a measured and
  a predicted current of exactly 0 A) gives no percentage and no NumPy RuntimeWarning;
* ``ParameterLayout.unit(name)`` gives each estimated parameter's unit;
* ``MultisineShape`` accepts the documented closed range of tilt, [0, 3], both ends included;
* ``ExperimentDesigner.papers_budget``'s default is the papers' excitation at its own default seed;
* the D-optimal grid search never credits a design whose predicted covariance of C2..C4 is singular
  with information (its per-axis criterion is -inf, as the joint ``Prediction.log_det`` counts it);
* an equation-error fit refuses an unknown key in ``initial`` naming the key and the estimated names;
* the eps-trend explanation's verdict names exactly the moving constants whose direction with guide
  friction is the papers' ("all of them" only when every one is).

Two survivors are equivalent (see /tmp/s_p/equiv48_B.txt of the run): the dtype of the layout's
initial vector (every initial value is already a float) and the clip of the naive variances (the
diagonal of s^2 H^-1 with H positive definite, or of a pseudo-inverse of a Gram matrix).

Everything here is built directly or with stand-ins for the twin; the file takes well under a
second (after about 4 s of imports).
"""

from __future__ import annotations

import math
import re
import warnings
from types import SimpleNamespace

import numpy as np
import pytest

import maglev_oc.identification.design as design
from maglev_oc.errors import InputError
from maglev_oc.identification.design import CurrentBudget, MultisineShape, papers_reference
from maglev_oc.identification.eps_trend import (
    FLAT_BAND,
    RIG_FRICTION,
    TABLE2_NAMES,
    EpsTrend,
    _explanation,
    _papers,
)
from maglev_oc.identification.equation_error import EquationError
from maglev_oc.identification.layout import ParameterLayout
from maglev_oc.identification.verification import compare_equilibrium_currents
from maglev_oc.model.equilibrium import equilibrium_currents
from maglev_oc.regression.base import CONSTANT_NAMES
from maglev_oc.regression.terms import constant_force
from tests.test_identify_properties import _synthetic


# --- equilibrium currents: a zero measured current ----------------------------------------------------
def _magnets_alone_model(model, gap: float):
    """``model`` with C2 set so that L2(gap) = g: the permanent magnets alone hold the mover at
    ``gap`` and the predicted equilibrium current there is exactly 0 A (the discriminant is L3^2
    and -L3 - |L3| = 0 for L3 < 0). C2 is nudged by ulps until the float result is exactly zero."""
    l2 = float(model.coefficients([gap])[1, 0])
    c2 = model.constants.C2 * model.params.gravity / l2
    for _ in range(50):
        m = model.with_constants(model.constants.replace(C2=c2))
        if float(equilibrium_currents(m, [gap]).current[0]) == 0.0:
            return m
        l2 = float(m.coefficients([gap])[1, 0])
        c2 = float(np.nextafter(c2, math.inf if l2 < model.params.gravity else -math.inf))
    pytest.fail("no C2 gives an exactly zero equilibrium current")


def test_a_zero_measured_current_gives_no_percentage_and_no_warning(model):
    gap = 20e-3
    alone = _magnets_alone_model(model, gap)
    gaps = np.array([gap, 15e-3, 25e-3])
    measured = np.array([0.0, 0.0, 1.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # 0 A / 0 A or x / 0 A must not reach the user as a warning
        cmp = compare_equilibrium_currents(alone, gaps, measured)
    assert cmp.predicted[0] == 0.0 and cmp.error[0] == 0.0
    # below small_current (0.3 A) no percentage is given, whatever the prediction
    assert np.isnan(cmp.error_pct[0]) and np.isnan(cmp.error_pct[1])
    # 1e-12 relative: the same formula, 100 |error| / |measured|, in another order
    assert cmp.error_pct[2] == pytest.approx(100 * abs(cmp.predicted[2] - 1.0), rel=1e-12)


# --- ParameterLayout.unit -----------------------------------------------------------------------------
def test_the_layout_gives_each_parameters_unit(model):
    layout = ParameterLayout(
        model, estimate=(*CONSTANT_NAMES, "gap_offset"), terms=(constant_force(model.params, "vertical"),)
    )
    # the units of LumpedConstants' docstring (L_i = C_i x shape function of the gap) and the gap's
    expected = {
        "C1": "m/(s^2 A)",
        "C2": "m/(s^2 T^2)",
        "C3": "m/(s^2 A T)",
        "C4": "m/(s^2 A^2)",
        "gap_offset": "m",
    }
    for name, unit in expected.items():
        assert layout.unit(name) == unit, name
    # a term's parameter has no unit of the constants' table: it is given as blank, not as another's
    term_names = [n for n in layout.names if n not in expected]
    assert term_names and all(layout.unit(n) == "" for n in term_names)


# --- MultisineShape: tilt in [0, 3] ------------------------------------------------------------------
@pytest.mark.parametrize("tilt", [0.0, 1.0, 2.0, 3.0])
def test_a_multisine_accepts_every_tilt_of_the_closed_range(tilt):
    shape = MultisineShape(tilt=tilt)
    assert shape.tilt == tilt and shape.to_dict()["tilt"] == tilt


@pytest.mark.parametrize("tilt", [-1e-9, math.nextafter(3.0, math.inf), 3.5, math.inf, math.nan])
def test_a_multisine_refuses_a_tilt_outside_the_closed_range(tilt):
    with pytest.raises(InputError, match=r"tilt must be in \[0, 3\]"):
        MultisineShape(tilt=tilt)


# --- papers_budget's default -----------------------------------------------------------------------
def test_the_papers_budget_defaults_to_the_papers_excitation_at_its_default_seed():
    seen = []

    def predict(ref):
        seen.append(ref)
        return SimpleNamespace(success=True, message="", peak_current=np.array([1.25, 2.5]))

    duration = 8.0
    stand_in = SimpleNamespace(predict=predict)  # the designer's twin replaced: only the reference matters
    budget, _ = design.ExperimentDesigner.papers_budget(stand_in, duration)
    assert budget == CurrentBudget(vertical=2.5, horizontal=1.25)  # peaks are (i_q, i_d)
    default = papers_reference(duration)
    assert not np.array_equal(papers_reference(duration, seed=1).values, default.values)  # seeds differ
    assert np.array_equal(seen[0].t, default.t) and np.array_equal(seen[0].values, default.values)


# --- D-optimal: a singular covariance is no information ----------------------------------------------
def test_the_doptimal_search_never_credits_a_singular_design_with_information(model, monkeypatch):
    nominal = np.array(model.constants.as_array())
    good, degenerate = MultisineShape(tilt=0.0), MultisineShape(tilt=1.0)

    def relative_cov(c1_rel_var: float, vertical_rel: np.ndarray) -> np.ndarray:
        rel = np.zeros((4, 4))
        rel[0, 0] = c1_rel_var
        rel[1:, 1:] = vertical_rel
        return rel * np.outer(nominal, nominal)

    # good: 1 % on every constant; degenerate: C2..C4 perfectly correlated (rank 1 of 3: two
    # directions without a finite figure), C1 worse than good's so the horizontal choice is clear
    covs = {
        good: relative_cov(1e-4, 1e-4 * np.eye(3)),
        degenerate: relative_cov(4e-4, 1e-4 * np.ones((3, 3))),
    }

    def log_det(cov):  # Prediction.log_det's convention (ExperimentDesigner.predict)
        sign, ld = np.linalg.slogdet(cov / np.outer(nominal, nominal))
        return -float(ld) if sign > 0 else -math.inf

    def prediction(vertical, horizontal):
        cov = covs[horizontal].copy()
        cov[1:, 1:] = covs[vertical][1:, 1:]
        return SimpleNamespace(nominal=nominal, covariance=cov, log_det=log_det(cov))

    class Designer:
        def fit_to_budget(self, make, budget, **kwargs):
            vertical, horizontal = make(1e-3, 1e-3)
            return (vertical, horizontal), prediction(vertical, horizontal)

    monkeypatch.setattr(
        design,
        "multisine_reference",
        lambda duration, *, vertical, horizontal, gap_amplitude, position_amplitude: (vertical, horizontal),
    )
    ref, pred, rows, chosen = design._doptimal(Designer(), 40.0, CurrentBudget(), [degenerate, good])
    by_tilt = {r["shape"]["tilt"]: r for r in rows}
    assert by_tilt[1.0]["log_det"] == -math.inf
    assert by_tilt[1.0]["log_det_C2_C4"] == -math.inf  # no information, as the joint criterion says
    assert math.isfinite(by_tilt[0.0]["log_det_C2_C4"])
    assert chosen == {"vertical": good.to_dict(), "horizontal": good.to_dict()}
    assert ref == (good, good) and math.isfinite(pred.log_det)


# --- equation error: an unknown initial value ------------------------------------------------------
@pytest.mark.parametrize(
    ("estimate", "initial", "unknown"),
    [(("C2", "C3", "C4"), {"C1": 14.0}, "C1"), (CONSTANT_NAMES, {"C2": 790.0, "offset": 1e-4}, "offset")],
)
def test_an_equation_error_fit_refuses_an_unknown_initial_value_by_name(model, estimate, initial, unknown):
    log = _synthetic("both.csv", vertical=True, horizontal=True, duration=2.0)
    problem = EquationError(log, model, estimate=estimate)
    with pytest.raises(InputError) as info:
        problem.fit(initial=initial)
    msg = str(info.value)
    assert repr(unknown) in msg and "initial" in msg
    assert all(n in msg for n in problem.names), msg  # the names it could have used


# --- eps trend: the verdict names the agreeing constants ----------------------------------------------
def _flipped(trend: EpsTrend, names) -> EpsTrend:
    """``trend`` with the estimates of ``names`` in reverse eps order: their direction reversed."""
    values = np.array(trend.values)
    for k in names:
        i = trend.names.index(k)
        values[i] = values[i, ::-1]
    return EpsTrend("test: " + trend.source, trend.names, trend.eps, values)


@pytest.mark.parametrize(
    ("flip3", "flip2", "verdict"),
    [
        ((), (), "all of them"),
        (("C1",), (), "Table III C3, Table III C4, Table II C3, Table II C4"),
        (("C3",), ("C4",), "Table III C1, Table III C4, Table II C3"),
        (("C1", "C3", "C4"), ("C3", "C4"), "none of them"),
    ],
)
def test_the_eps_trend_verdict_names_the_constants_that_follow_the_papers(model, flip3, flip2, verdict):
    p3, p2 = _papers("table3", CONSTANT_NAMES), _papers("table2", TABLE2_NAMES)
    fields = dict(
        papers_table3=p3,
        papers_table2=p2,
        default_table3=p3,
        default_table2=p2,
        friction_table3=_flipped(p3, flip3),
        friction_table2=_flipped(p2, flip2),
        limit_default_table3=p3,
        zero_phase_table3=p3,
        band=FLAT_BAND,
        damping_rate=0.0,  # no damping paragraph: only the verdict is read here
        papers_damping=0.0,
    )
    text = _explanation(model, RIG_FRICTION, 1e-3, 1e-3, **fields)
    m = re.search(r"the papers' direction for (.*?)\. C2, pinned", text)
    assert m, text
    assert m.group(1) == verdict
