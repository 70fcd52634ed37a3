"""Properties of the constrained Gauss-Newton solver (``maglev_oc.identification.constrained_gn``),
checked on small problems with closed-form answers (the closest point of the unit circle):

- a point is converged only where the constraints hold, strictly below the constraint tolerance,
  whatever the step tolerance; a shortened step stops it only when the step taken is small;
- an exact penalty is kept when the multipliers are large; redundant constraints stop the solver
  at its start with the documented status; a singular Hessian is damped by a millionth of its
  scale.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
import scipy.sparse as sp

from maglev_oc.identification import constrained_gn
from maglev_oc.identification.constrained_gn import constrained_gauss_newton
from tests._identification_cases import _circle

# --- constrained Gauss-Newton ----------------------------------------------------------------------------
DATA = np.array([2.0, 0.5])


@pytest.mark.parametrize("tolerance", [1.0, 0.1, 1e-3, 1e-9])
def test_constrained_gauss_newton_converges_only_where_the_constraints_hold(tolerance):
    out = constrained_gauss_newton(_circle, np.array([0.3, 0.2]), np.ones(2), tolerance=tolerance)
    assert out.status == "converged", out.message
    # the documented default constraint tolerance, 1e-6
    assert np.max(np.abs(out.c)) < 1e-6
    # closed form DATA / |DATA| at the default tolerance: the last full step was below 1000 x 1e-9
    # and Gauss-Newton converges linearly here, so 1e-5 is ample (measured 1e-12); a loose
    # tolerance stops earlier by design (a step below 1000 x tolerance) and is not checked
    if tolerance == 1e-9:
        np.testing.assert_allclose(out.w, DATA / np.linalg.norm(DATA), atol=1e-5)


@pytest.mark.parametrize("start", [(0.3, 0.2), (5.0, -3.0)])
def test_constrained_gauss_newton_keeps_an_exact_penalty_when_the_multipliers_are_large(start):
    # the closest point of the unit circle to data 4.1 away: the constraint's multiplier is about
    # 3 (|data| - 1), the full Gauss-Newton steps overshoot the circle and the line search on the
    # l1 merit 0.5 |r|^2 + rho |c|_1 must shorten them. That merit is exact only for rho above the
    # largest multiplier (Nocedal & Wright, Theorem 17.3); the solver takes twice it. With rho at a
    # fifth of it the search accepted steps away from the circle and failed there (|c| 0.4-0.8).
    # Converged within the default 30 iterations (measured 15 and 20) to data / |data| (1e-5, as above;
    # measured 6e-7: Gauss-Newton converges linearly here and stops on a step below 1e-6)
    data = np.array([4.0, 1.0])

    def far(w):
        return w - data, np.array([w @ w - 1.0]), sp.identity(2, format="csr"), sp.csr_matrix(2 * w[None, :])

    out = constrained_gauss_newton(far, np.array(start), np.ones(2))
    assert out.status == "converged", out.message
    np.testing.assert_allclose(out.w, data / np.linalg.norm(data), atol=1e-5)


@pytest.mark.parametrize("start", [0.5, -0.3, 0.05, 1.0])
def test_constrained_gauss_newton_stops_on_a_shortened_step_only_when_the_step_taken_is_small(start):
    # a large-residual problem where Gauss-Newton overshoots: r = (k x, y^2 + p) on the line y = x,
    # p = 0.75 k^2. At the minimizer x = 0 the Gauss-Newton curvature is k^2 and the true one k^2 +
    # 2p = 2.5 k^2, so every full step lands at -1.5 x, the merit rejects it and the halved step
    # lands at -x/4: convergence is linear through shortened steps, and the error left is 1/5 of
    # the step taken. The shortcut "a step below 1000 x tolerance" is documented for a *full*
    # step (quadratic convergence); taking it on a halved one stopped at |x| 2e-8 to 8e-8.
    # Default tolerance 1e-9 on the step taken, so |x| < 2e-10 in exact arithmetic; 1e-8 leaves
    # room for the merit's rounding (measured 1.2e-10 to 4.5e-10, in 14-17 iterations).
    k = 0.1
    p = 0.75 * k * k

    def overshoot(w):
        x, y = w
        Jr = sp.csr_matrix(np.array([[k, 0.0], [0.0, 2.0 * y]]))
        return np.array([k * x, y * y + p]), np.array([y - x]), Jr, sp.csr_matrix(np.array([[-1.0, 1.0]]))

    out = constrained_gauss_newton(overshoot, np.array([start, start]), np.ones(2))
    assert out.status == "converged", out.message
    assert np.max(np.abs(out.w)) < 1e-8


# --- constrained Gauss-Newton ----------------------------------------------------------------------------
def _documented_statuses() -> set[str]:
    """The status words the module docstring lists (``"..."`` after "Status words")."""
    doc = constrained_gn.__doc__
    return set(re.findall(r'``"([a-z_]+)"``', doc[doc.index("Status words") :]))


def test_redundant_constraints_stop_at_the_start_with_the_documented_status():
    """min |A w - b|^2 s.t. w0 + w1 = 1, the constraint stated twice: the KKT matrix [H J'; J 0] has two
    equal rows of J, so it is singular whatever damping is added to H. The solver must say so with its
    documented word and leave w at the start; stated once, the same problem converges to the KKT
    solution (numpy, dense)."""
    A = np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])
    b = np.array([1.0, 2, 3, 4])
    row = np.array([[1.0, 1.0, 0.0]])

    def linearize(times: int):
        def lin(w):
            c = np.full(times, w[0] + w[1] - 1.0)
            return A @ w - b, c, sp.csr_matrix(A), sp.csr_matrix(np.repeat(row, times, axis=0))

        return lin

    assert "kkt_singular" in _documented_statuses()
    out = constrained_gauss_newton(linearize(2), np.zeros(3), np.ones(3))
    assert out.status == "kkt_singular" and not out.success
    assert "singular" in out.message
    np.testing.assert_array_equal(out.w, np.zeros(3))
    once = constrained_gauss_newton(linearize(1), np.zeros(3), np.ones(3))
    assert once.success and once.status in _documented_statuses()
    kkt = np.block([[A.T @ A, row.T], [row, np.zeros((1, 1))]])
    expected = np.linalg.solve(kkt, np.concatenate([A.T @ b, [1.0]]))[:3]
    np.testing.assert_allclose(once.w, expected, rtol=0, atol=1e-9)  # the solver's step tolerance


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


# --- the Gauss-Newton step where the Hessian is singular -------------------------------------------------
@pytest.mark.parametrize("scale", [0.5, 40.0])
def test_a_singular_hessian_is_damped_by_a_millionth_of_its_scale(scale):
    """``constrained_gn._factor``'s docstring: a singular H is damped by 1e-6 max(max diag H, 1).
    H = diag(scale, 0) without constraints: the undetermined second
    direction steps by g / damp, the first by g / (scale + damp); round-off only (1e-12)."""
    import numpy as np
    import scipy.sparse as sp

    from maglev_oc.identification.constrained_gn import _factor

    H = sp.csc_matrix(np.diag([scale, 0.0]))
    Jc = sp.csc_matrix((0, 2))
    damp = 1e-6 * max(scale, 1.0)
    step = _factor(H, Jc).solve(np.array([1.0, 1.0]))
    np.testing.assert_allclose(step, [1.0 / (scale + damp), 1.0 / damp], rtol=1e-12)


def test_with_no_iteration_allowed_the_start_is_returned_and_no_iteration_counted():
    """``max_iterations=0``: the solver takes no step, says it hit its limit, and counts 0
    iterations (the start is not an iteration)."""
    start = np.array([0.3, 0.2])
    out = constrained_gauss_newton(_circle, start, np.ones(2), max_iterations=0)
    assert out.status == "iteration_limit" and out.iterations == 0
    np.testing.assert_array_equal(out.w, start)
