"""Properties of the gain design (``maglev_oc.control.gains`` and ``lqr``), checked against
textbook computations made here:

- the LQR gains are optimal for their own axis's weights and ``omega0``: K = -R^-1 B' P with P
  the cost matrix of K itself (a Lyapunov equation, not the Riccati equation the design solves),
  with Bryson's R = 1 / current_max^2; maxima that are not positive are refused;
- the papers' gain check calls a gain vector stable only with every pole in the open left half
  plane, and compares it to the recomputed gains;
- the per-axis augmented system refuses a zero or non-finite input gain and carries any other
  into B.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.linalg import solve_continuous_lyapunov

from maglev_oc.control.gains import augmented_axis, check_paper_gains, place_axis
from maglev_oc.control.lqr import DEFAULT_WEIGHTS, AxisWeights, lqr_regulator
from maglev_oc.errors import InputError
from tests._control_cases import _bryson

GAP = 0.020  # [m] a scheduled gap (8 mm + 24 x 0.5 mm)


def test_lqr_gains_are_optimal_for_their_own_axis_and_frequency(model):
    """For w = K z the cost of K is z0' P z0 with (A + B K)' P + P (A + B K) + Q + K' R K = 0; K is
    optimal exactly when K = -R^-1 B' P (the stationarity condition). Checked with the axis's own
    weights and the omega0 given (2 pi, not the default), at three scheduled gaps. The Lyapunov
    solve of this 5 x 5 system (Q spanning 1e1..1e11) is accurate to about 1e-7 relative."""
    omega0 = 2.0 * np.pi
    reg = lqr_regulator(model, omega0=omega0)
    lin = reg.schedule
    for j in (0, len(lin.gap) // 2, len(lin.gap) - 1):
        axes = (
            ("vertical", reg.gains_v[:, j], lin.stiffness_v[j], lin.gain_v[j]),
            ("horizontal", reg.gains_h[:, j], 0.0, lin.gain_h[j]),
        )
        for axis, k, stiffness, gain in axes:
            a, b = augmented_axis(omega0, stiffness, gain)
            q, r = _bryson(DEFAULT_WEIGHTS[axis])
            closed = a + b @ k[None, :]
            assert np.all(np.linalg.eigvals(closed).real < 0), axis
            p = solve_continuous_lyapunov(closed.T, -(q + k[:, None] @ r @ k[None, :]))
            stationary = -np.linalg.solve(r, b.T @ p).ravel()
            assert_allclose(k, stationary, rtol=1e-5, err_msg=f"{axis} at {lin.gap[j]}")


@pytest.mark.parametrize("field", ["error", "error_rate", "current"])
@pytest.mark.parametrize("value", [0.0, -1.0, float("nan")])
def test_lqr_refuses_maxima_that_are_not_positive(field, value):
    """Bryson's rule divides by the maxima: a zero or negative one is refused when the weights are
    made (before any design uses them), naming the entry."""
    w = DEFAULT_WEIGHTS["vertical"]
    kwargs = {
        "error": w.error,
        "error_rate": w.error_rate,
        "internal_model": w.internal_model,
        "current": w.current,
    }
    kwargs[field] = value
    with pytest.raises(ValueError, match=f"positive and finite: {field} = "):
        AxisWeights(**kwargs)


# --- the paper gains' check ------------------------------------------------------------------------
def test_paper_gain_check_needs_every_pole_stable_and_compares_to_the_recomputed_gains():
    omega0 = 30.0  # [rad/s] the printed K_h leaves two poles in the right half plane here
    for check in check_paper_gains(omega0):
        printed = np.asarray(check.paper.printed, dtype=float)
        a, b = augmented_axis(omega0)
        stable = bool(np.all(np.linalg.eigvals(a + b @ printed[None, :]).real < 0))
        assert check.success is stable and check.status == ("stable" if stable else "unstable")
        computed = place_axis(check.paper.poles, omega0)
        assert_allclose(check.rel_difference, np.abs(printed - computed) / np.abs(computed), rtol=1e-12)
    assert [c.success for c in check_paper_gains(omega0)] == [False, True, True]


# --- LQR with a current maximum other than 1 A ------------------------------------------------------
def test_lqr_weighs_the_current_by_its_squared_maximum(model):
    """Bryson's rule R = 1 / current_max^2, visible only when current_max != 1 A (the defaults'
    1 A hides R = 1 / current_max): K = -R^-1 B' P with P the cost of K itself (Lyapunov), as in
    test_control_injected_properties (1e-5 relative, its tolerance)."""
    from scipy.linalg import solve_continuous_lyapunov

    from maglev_oc.control.lqr import AxisWeights
    from tests._control_cases import _bryson

    weights = {
        "vertical": AxisWeights(2e-2, 0.5, (3e-6, 1e-4, 1e-3), 0.4),
        "horizontal": AxisWeights(2e-2, 0.2, (3e-5, 1e-4, 1e-3), 2.5),
    }
    reg = lqr_regulator(model, weights, gaps=[0.015, GAP])  # the interpolant needs two
    lin = reg.schedule
    for axis, k, stiffness, gain in (
        ("vertical", reg.gains_v[:, 1], lin.stiffness_v[1], lin.gain_v[1]),
        ("horizontal", reg.gains_h[:, 1], 0.0, lin.gain_h[1]),
    ):
        a, b = augmented_axis(reg.omega0, stiffness, gain)
        q, r = _bryson(weights[axis])
        p = solve_continuous_lyapunov((a + b @ k[None, :]).T, -(q + k[:, None] @ r @ k[None, :]))
        assert_allclose(k, -np.linalg.solve(r, b.T @ p).ravel(), rtol=1e-5, err_msg=axis)


@pytest.mark.parametrize("gain", [0.0, -0.0, math.inf, -math.inf, math.nan])
def test_an_augmented_axis_refuses_a_zero_or_non_finite_input_gain(gain):
    """The input gain divides the pole placement (B = (0, g, 0, 0, 0)'): zero makes the axis
    uncontrollable and inf or nan propagates into every gain, so each is refused by name."""
    with pytest.raises(InputError, match="input_gain must be finite and nonzero"):
        augmented_axis(input_gain=gain)


def test_an_augmented_axis_carries_its_input_gain_into_b():
    """Any finite nonzero gain, either sign, is accepted and is B's only nonzero entry (e')."""
    for gain in (1e-3, -2.5, 40.0):
        _, b = augmented_axis(input_gain=gain)
        assert b.ravel().tolist() == [0.0, gain, 0.0, 0.0, 0.0]
