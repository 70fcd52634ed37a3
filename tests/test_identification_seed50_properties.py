"""Identification properties from the survivors of the seed-50 mutation run, each a property of an
option a user passes:

* ``fit_output_error(initial=...)`` starts the solver from the given constants: no equation-error
  fit is run for a start, and with no iteration allowed the answer is the start itself (a start
  that is silently replaced makes a user's warm start, e.g. from yesterday's fit, do nothing);
* ``ExperimentDesigner.predict`` predicts C1..C4 alone unless asked for the constant vertical
  force: the default's covariance is the 4 x 4 of the constants, and it is not the constants' block
  of the prediction with the force (estimating the force as well costs the constants precision);
* constrained Gauss-Newton calls an iterate converged only with every |c| strictly below the
  constraint tolerance, as its documentation says: an iterate exactly at it is not converged.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from maglev_oc.identification import output_error
from maglev_oc.identification.constrained_gn import constrained_gauss_newton
from maglev_oc.identification.design import EFFECT, ExperimentDesigner, multisine_reference
from maglev_oc.identification.experiments import TWIN_TRUTH
from maglev_oc.identification.layout import CONSTANT_NAMES

TRUTH = dict(zip(CONSTANT_NAMES, TWIN_TRUTH.as_array(), strict=True))


def test_the_output_error_fit_starts_from_the_given_constants(model, twin_log, monkeypatch):
    """1 s of the twin log, started at the true constants with no iteration allowed: the values are
    the start, exactly, and the equation-error fit that would otherwise give the start is never
    called."""

    def refused(*args, **kwargs):
        raise AssertionError("an equation-error start was fitted although one was given")

    monkeypatch.setattr(output_error, "fit_equation_error", refused)
    fit = output_error.fit_output_error(twin_log.index_slice(0, 1000), model, initial=TRUTH, max_iterations=0)
    assert [fit.values[c] for c in CONSTANT_NAMES] == [TRUTH[c] for c in CONSTANT_NAMES]


def test_a_prediction_leaves_the_vertical_force_out_unless_asked(model):
    """A 5 s multisine on the nominal twin: by default the prediction names C1..C4 with a 4 x 4
    covariance; asked for the force, 5 names and a 5 x 5 covariance whose constants' block is
    larger on C2's diagonal (the force and C2 both set the vertical force's mean; 1 %: far above the
    rounding of two solves of the same normal equations, far below the effect measured, x1.3 or
    more)."""
    designer = ExperimentDesigner(model)
    ref = multisine_reference(5.0)
    run = designer.simulate(ref)
    plain = designer.predict(ref, run=run)
    both = designer.predict(ref, effect=True, run=run)
    assert plain.names == CONSTANT_NAMES and plain.covariance.shape == (4, 4)
    assert both.names == (*CONSTANT_NAMES, EFFECT) and both.covariance.shape == (5, 5)
    c2 = CONSTANT_NAMES.index("C2")
    assert both.covariance[c2, c2] > 2.0 * plain.covariance[c2, c2]
    assert np.all(np.isfinite(plain.covariance))


def _circle(w):
    """r = w - (2, 0.5), c = |w|^2 - 1: the closest point of the unit circle to (2, 0.5)."""
    return (
        w - np.array([2.0, 0.5]),
        np.array([w @ w - 1.0]),
        sp.identity(2, format="csr"),
        sp.csr_matrix(2 * w),
    )


def test_an_iterate_exactly_at_the_constraint_tolerance_is_not_converged():
    """With a step tolerance of 1 the constraint alone decides. The third iterate's |c| (the solver
    run with a tolerance nothing meets) taken as the tolerance itself: the third iterate is not
    converged (|c| is not below it), the fourth is (the iterates are the same floats in both runs,
    the solver being deterministic; |c| falls at every iterate from this start)."""
    w0 = np.array([0.3, 0.2])
    third = constrained_gauss_newton(
        _circle, w0, np.ones(2), max_iterations=3, tolerance=1.0, constraint_tolerance=1e-300
    )
    assert third.iterations == 3 and third.c[0] != 0.0
    at = constrained_gauss_newton(
        _circle, w0, np.ones(2), tolerance=1.0, constraint_tolerance=abs(third.c[0])
    )
    assert at.status == "converged" and at.iterations == 4
    assert abs(at.c[0]) < abs(third.c[0])
