"""The discrete high-gain observer."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.estimation.high_gain import HighGainObserver


def test_observer_poles_and_exact_discretization():
    obs = HighGainObserver(sample_time=2e-4, epsilon=2e-3)
    # alpha = (2, 1): double continuous pole at -1/eps -> discrete exp(-T/eps)
    assert_allclose(np.linalg.eigvals(obs.Ad), np.exp(-2e-4 / 2e-3) * np.ones(2), rtol=1e-6)


def test_observer_tracks_a_ramp_and_a_parabola():
    # A ramp is tracked (type-2 error dynamics); a parabola with acceleration a known to the
    # observer likewise. The samples are held (ZOH) while the true signal moves, which biases
    # the velocity by about (T/eps)^2 / 12 = 8.3e-4 relative: tolerance 1e-3.
    ts = 2e-4
    obs = HighGainObserver(ts, 2e-3)
    t = np.arange(5000) * ts
    est = obs.filter(0.01 + 0.05 * t)
    assert_allclose(est[1, -100:], 0.05, rtol=1e-3)
    acc = 3.0
    est = obs.filter(0.5 * acc * t**2, a=np.full_like(t, acc))
    # the estimate at k is based on y[k-1]: velocity lags by up to one sample, acc * ts
    assert_allclose(est[1, -100:], acc * t[-100:], rtol=1e-3, atol=acc * ts)


def test_observer_rejects_bad_settings():
    with pytest.raises(ValueError, match="epsilon"):
        HighGainObserver(2e-4, epsilon=0.0)
    with pytest.raises(ValueError, match="sample_time"):
        HighGainObserver(-1.0)


def test_step_keeps_the_shape_of_its_input():
    # a 1-D estimate must not broadcast against the (2, 1) input column into a (2, 2) array
    obs = HighGainObserver(2e-4)
    x1 = obs.step(np.array([0.02, 0.0]), 0.0201)
    x2 = obs.step(np.array([[0.02], [0.0]]), 0.0201)
    assert x1.shape == (2,) and x2.shape == (2, 1)
    assert_allclose(x1, x2.ravel(), rtol=0, atol=0)
