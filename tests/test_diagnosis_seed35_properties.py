"""Properties of ``maglev_oc.diagnosis`` written against the survivors of the seed-35 mutation-testing run
at b484c31 (issue 21): each test states a property of a result a user sees, not the mutated token.

* The current-amplifier lag candidate is the first-order change of the model's accelerations when the
  currents act late by T: acc(u - T du) - acc(u) = -(d acc / d u) du T, with d acc / d u the model's
  own Jacobian (CasADi, exact), for currents and rates of either sign on both axes.
* The guide misalignment candidate judges its slope against its physical bound (0.05 rad): a slope
  within it (either sign) is plausible, one beyond it is refused with a reason naming the bound.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from maglev_oc.diagnosis.candidate import LibraryContext
from maglev_oc.diagnosis.currents import lag_candidate
from maglev_oc.diagnosis.guides import misalignment_candidate
from maglev_oc.regression.data import prepare


@pytest.fixture(scope="module")
def ctx(model, twin_log) -> LibraryContext:
    """The candidates' context on the twin's 6 s excitation, with the papers' constants as references."""
    return LibraryContext(model, prepare([twin_log], bandwidth=10.0))


def test_the_lag_candidate_is_the_models_first_order_change_under_late_currents(ctx, model):
    """For a lag T the forces see u(t - T) = u - T du to first order, so the term must equal
    -J_u(x, u) du T with J_u the Jacobian of the model's (x2', x4') in the currents (d/du of
    model.f, computed by CasADi here, not by the candidate's own formula). Both are linear in T and
    du, so they agree to round-off: 1e-12 relative to the largest component. States and currents
    drawn over the rig's gaps, positions and +-8 A, rates up to 2 kA/s, both signs."""
    x, u = ca.SX.sym("x", 4), ca.SX.sym("u", 2)
    jac = ca.Function("J", [x, u], [ca.jacobian(model.f(x, u)[[1, 3]], u)])
    term = lag_candidate(ctx).term.function
    rng = np.random.default_rng(35)
    for _ in range(20):
        xs = np.array(
            [rng.uniform(0.01, 0.028), rng.normal(0, 0.05), rng.uniform(-0.05, 0.05), rng.normal(0, 0.1)]
        )
        us = rng.uniform(-8.0, 8.0, 2)
        dus = rng.uniform(-2000.0, 2000.0, 2)
        T = rng.uniform(1e-4, 2e-3)
        expected = -np.asarray(jac(xs, us)) @ dus * T
        got = np.asarray(term(xs, us, dus, [T])).ravel()
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    # and it is the change of the accelerations for a small lag (first order: relative error ~ T/tau,
    # tau the currents' time scale |u| / |du| = 4 ms here, so 1e-6 s leaves < 1e-3)
    xs, us, dus, T = np.array([0.018, 0.0, 0.02, 0.0]), np.array([3.0, -2.0]), np.array([400.0, -300.0]), 1e-6
    change = (np.asarray(model.f(xs, us - T * dus)) - np.asarray(model.f(xs, us))).ravel()[[1, 3]]
    np.testing.assert_allclose(np.asarray(term(xs, us, dus, [T])).ravel(), change, rtol=1e-3)


@pytest.mark.parametrize(("slope", "plausible"), [(0.01, True), (-0.049, True), (0.06, False), (-0.2, False)])
def test_a_guide_slope_is_judged_against_its_physical_bound(ctx, slope, plausible):
    """misalignment_candidate: the slope's physical bound is 0.05 rad (a guide tilted 3 degrees off the
    stator is no misalignment). The physical parameters of a fitted slope pass the candidate's check
    within the bound, of either sign, and fail it beyond, with a reason that names the bound."""
    cand = misalignment_candidate(ctx)
    params = cand.term.physical_parameters(np.array([slope]), np.array([[1e-8]]), {})
    assert params["slope"].value == slope
    reason = cand.plausible(params)
    if plausible:
        assert reason is None
    else:
        assert reason and "0.05" in reason and "slope" in reason
