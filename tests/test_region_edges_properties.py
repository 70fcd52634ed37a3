"""Edges of the region code that its main tests do not reach: the certificate's search limits and
what a bad input or a degenerate matrix gives (issue 21: the survivors of a mutation run at
31d4cd9, seed 33, each turned into a property).

* The linear regulator's stability level grows 4x from the stoppers' level and stops once it
  passes 4x that level (the stoppers bind there anyway, ``level = min(stability, travel)``), and
  its bisection stops as soon as the bracket is within 1 %.
* A matrix with a non-positive diagonal is no Lyapunov candidate: the decrease test says "not
  certified" (an infinite margin) instead of taking square roots of negative numbers.
* Gains of the wrong size are refused with the name of the option that carries them.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_oc.control.linear_regulator import paper_linear_regulator
from maglev_oc.errors import InputError
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.microstepper import MicrostepperRegion
from maglev_oc.region.roa import LinearizedLoop, RoaCertifier, certify_roa
from maglev_oc.region.robust_certificate import RobustCertifier
from tests.test_microstepper_region import PLATFORM


@pytest.fixture(scope="module")
def linear(model):
    return paper_linear_regulator(model)


def test_near_a_stopper_the_stability_search_stops_at_four_times_the_stoppers_level(model, linear):
    """At 29.9 mm the upper stopper (30 mm) is 0.1 mm away: its level is tiny, every level up to
    4x it is certified stable, and the search stops there after two steps (the stoppers' level,
    then 4x it), as its docstring says; the certified level is the stoppers'."""
    res = certify_roa(model, linear, Reference.setpoint(0.0299))
    assert res.level_stability == pytest.approx(4 * res.level_travel, rel=1e-12)
    assert res.bisections == 2
    assert res.level == res.level_travel


def test_the_bisection_stops_once_the_bracket_is_within_one_percent(model, linear):
    """At the papers' 20 mm the stability level binds; the bisection stops when the bracket
    closes to 1 %, long before its 40 allowed steps (measured 14), and the level 1 % above is
    not certified (the bracket's other end)."""
    res = certify_roa(model, linear, Reference.setpoint(0.02))
    assert res.level_stability < res.level_travel
    assert res.bisections < 20
    cert = RoaCertifier(LinearizedLoop(model, linear, Reference.setpoint(0.02)))
    above = 1.01 * res.level_stability
    assert cert.decrease_margin(res.P, cert.jacobian_box(res.P, above)) >= 0


def test_with_no_step_allowed_nothing_is_certified_and_no_step_is_counted(model, linear):
    """``iterations=0``: no level is tried, nothing is certified, and the result says 0 steps."""
    res = certify_roa(model, linear, Reference.setpoint(0.02), iterations=0)
    assert not res.success and res.status == "not_certified"
    assert res.bisections == 0 and res.level == 0.0


@pytest.mark.parametrize("entry", [0.0, -1.0])
def test_a_matrix_with_a_non_positive_diagonal_certifies_nothing(model, linear, entry):
    """The decrease margin of a P with a zero or negative diagonal entry is +inf (not certified),
    without a RuntimeWarning (the suite turns those from maglev_oc into errors)."""
    loop = LinearizedLoop(model, linear, Reference.setpoint(0.02))
    cert = RoaCertifier(loop)
    P = loop.lyapunov_matrix()
    box = cert.jacobian_box(P, 1e-6)
    assert math.isfinite(cert.decrease_margin(P, box))  # the real P: a finite margin
    bad = P.copy()
    bad[3, 3] = entry
    assert cert.decrease_margin(bad, box) == math.inf


@pytest.mark.parametrize("option", ["K_h", "K_v"])
def test_the_microstepper_names_the_gains_it_refuses(option):
    with pytest.raises(InputError, match=rf"^{option} must be 5 finite gains"):
        MicrostepperRegion(PLATFORM, **{option: np.ones(4)})


@pytest.mark.parametrize(("given", "kind"), [("20 mm", "str"), (None, "NoneType"), (0.02, "float")])
def test_the_robust_certifier_names_what_it_got_instead_of_a_nominal_certificate(model, given, kind):
    certifier = RobustCertifier(FeasibleSet(model), RegulatorLoop(), max_boxes=1000, ladder=(1.0,))
    with pytest.raises(TypeError, match=rf"^nominal must be a Procedure2Result, got {kind}$"):
        certifier.run(given, None)


def test_a_missing_row_of_the_robust_study_names_the_plant_sets_it_has():
    """Asking a sampled robustness study for a row it does not hold raises KeyError with the
    set-point and plant set asked for and the plant sets the study has, in table order."""
    from maglev_oc.region.study import RobustStudy
    from maglev_oc.region.sweep import PlantSet

    box = PlantSet.box([14.0, 2.0, 2.0, 0.1], [16.0, 3.0, 3.0, 0.2])
    study = RobustStudy(np.eye(4), "assumed", True, (0.9, 0.99), box, {}, (), (), 10, 5)
    with pytest.raises(KeyError) as err:
        study.row("20 mm", "0.95")
    assert err.value.args[0] == "no row ('20 mm', '0.95'); plant sets: ('nominal', '0.9', '0.99', 'box')"
