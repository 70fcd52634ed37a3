"""``delayed_inputs`` (``maglev_oc.regression.data``) shifts the logged currents later by any delay:
the currents read that much earlier (by index for whole samples, the mean of the two neighbours
for half a sample), held at their first value before the log starts.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_oc.data.logs import Log
from maglev_oc.regression.data import delayed_inputs


# --- delayed currents ------------------------------------------------------------------------------------
def _log(seconds: float = 3.0) -> Log:
    """A 1 kHz log whose currents are two sines of different frequencies (every sample distinct)."""
    t = np.arange(round(seconds * 1000)) * 1e-3
    x = np.vstack([0.02 + 1e-3 * np.sin(t), np.zeros_like(t), 0.01 * np.cos(t), np.zeros_like(t)])
    u = np.vstack([3.0 * np.sin(2 * math.pi * 0.7 * t) + 1.0, -2.0 * np.cos(2 * math.pi * 1.3 * t)])
    return Log(t, x, u, source="sines")


@pytest.mark.parametrize("samples", [1, 7, 1000, 2000])
def test_currents_delayed_by_whole_samples_are_the_earlier_samples_held_at_the_start(samples):
    """u_delayed[k] = u[k - d] with d = delay / 1 ms, and u[0] for k < d (held at the start). Linear
    interpolation at a time that is a sample up to rounding of t - delay (a few 1e-16 s) is that sample
    to 1e-12 A (the currents change by at most 0.02 A per ms)."""
    log = _log()
    delay = samples * 1e-3
    u = np.asarray(log.u)
    expected = np.hstack([np.repeat(u[:, :1], samples, axis=1), u[:, :-samples]])
    np.testing.assert_allclose(delayed_inputs(log, delay), expected, rtol=0, atol=1e-12)


def test_currents_delayed_by_half_a_sample_are_the_mean_of_the_neighbours():
    """Linear interpolation halfway: (u[k - 3] + u[k - 2]) / 2 for a 2.5 ms delay; held before."""
    log = _log()
    u = np.asarray(log.u)
    got = delayed_inputs(log, 2.5e-3)
    np.testing.assert_allclose(got[:, 3:], 0.5 * (u[:, :-3] + u[:, 1:-2]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(got[:, :2], u[:, :1].repeat(2, axis=1), rtol=0, atol=0)
    np.testing.assert_array_equal(delayed_inputs(log, 0.0), u)
