"""What the controllers' designs promise, checked against independent computations.

* axis poles: the eigenvalues of A + B K, in the documented order;
* the papers' linear regulator: designed on the model it is given (its equilibria are its
  feed-forward, its gains place the printed gains' poles on that model's linearization at every
  scheduled gap), with the internal-model frequency it is given;
* the PID baseline: each axis's characteristic polynomial s^3 + b kd s^2 + (b kp - a) s + b ki
  (e'' = a e + b du, du = -(kp e + kd e' + ki int e)) has the requested poles, with a = 0 on the
  horizontal double integrator and a = dx2'/dx1 vertically.
"""

from __future__ import annotations

import numpy as np
import pytest

from maglev_oc.control.gains import PAPER_K_H, PAPER_K_V, augmented_axis, axis_poles
from maglev_oc.control.linear_regulator import paper_linear_regulator
from maglev_oc.control.pid import DEFAULT_POLES, paper_pid
from maglev_oc.model.equilibrium import equilibrium_currents


def test_axis_poles_are_the_eigenvalues_in_order():
    for k in (PAPER_K_H, PAPER_K_V):
        a, b = augmented_axis(2.0, 30.0, -1.5)
        p = axis_poles(k, 2.0, 30.0, -1.5)
        ev = np.linalg.eigvals(a + b @ np.asarray(k)[None, :])
        np.testing.assert_allclose(np.sort_complex(p), np.sort_complex(ev), rtol=1e-12)
        # sorted by real part, descending (the slowest first), then imaginary part
        assert np.all(np.diff(p.real) <= 1e-12)


@pytest.mark.parametrize("omega0", [1.5 * np.pi, 2.0])
def test_the_linear_regulator_is_designed_on_the_model_and_frequency_it_is_given(model, omega0):
    other = model.with_constants(model.constants.replace(C2=model.constants.C2 * 1.1))
    reg = paper_linear_regulator(other, omega0=omega0)
    assert reg.model is other and reg.omega0 == omega0
    lin = reg.schedule
    # its feed-forward is the given model's equilibrium current at every scheduled gap
    np.testing.assert_allclose(lin.u2_eq, equilibrium_currents(other, lin.gap).current, rtol=1e-12)
    # the printed gains' FL poles, placed on that model's linearization at each gap
    np.testing.assert_allclose(reg.design["poles_v"], axis_poles(PAPER_K_V, omega0), rtol=1e-12)
    np.testing.assert_allclose(reg.design["poles_h"], axis_poles(PAPER_K_H, omega0), rtol=1e-12)
    assert reg.design["feedforward"] is True
    for j in (0, len(lin.gap) // 2, len(lin.gap) - 1):
        kh, kv = reg.gains_at(lin.gap[j])
        pv = axis_poles(kv, omega0, lin.stiffness_v[j], lin.gain_v[j])
        ph = axis_poles(kh, omega0, 0.0, lin.gain_h[j])
        np.testing.assert_allclose(np.sort_complex(pv), np.sort_complex(reg.design["poles_v"]), rtol=1e-6)
        np.testing.assert_allclose(np.sort_complex(ph), np.sort_complex(reg.design["poles_h"]), rtol=1e-6)
    # without feed-forward the internal model supplies the current: none is added
    plain = paper_linear_regulator(other, feedforward=False, omega0=omega0)
    assert np.all(plain.schedule.u2_eq == 0) and plain.design["feedforward"] is False


def _pid_polynomial(gains, stiffness: float, input_gain: float) -> np.ndarray:
    b = input_gain
    return np.array([1.0, b * gains.kd, b * gains.kp - stiffness, b * gains.ki])


def test_the_pid_places_the_requested_poles_on_each_axis(model):
    # compared as polynomials: the default poles are triple (-30, -30, -30), whose computed roots
    # scatter by eps^(1/3) ~ 1e-5
    pid = paper_pid(model)
    from maglev_oc.control.linear_regulator import axis_linearizations

    lin = axis_linearizations(model, [pid.design["design_gap"]])
    vertical = _pid_polynomial(pid.vertical, float(lin.stiffness_v[0]), float(lin.gain_v[0]))
    horizontal = _pid_polynomial(pid.horizontal, 0.0, float(lin.gain_h[0]))
    np.testing.assert_allclose(vertical, np.real(np.poly(DEFAULT_POLES["vertical"])), rtol=1e-12)
    np.testing.assert_allclose(horizontal, np.real(np.poly(DEFAULT_POLES["horizontal"])), rtol=1e-12)
    assert float(lin.stiffness_v[0]) > 0  # the vertical axis is open-loop unstable: a matters there
