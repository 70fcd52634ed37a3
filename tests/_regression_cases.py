"""A prepared horizontal sweep with viscous friction and a log moving on both axes, shared by the
regression and diagnosis option tests. The fixture is registered in ``tests/conftest.py``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_oc.data.logs import Log
from maglev_oc.regression.data import prepare
from tests.test_statistics_properties import RATE_FRICTION, _log


@pytest.fixture(scope="module")
def friction_data(model):
    """The 30 s horizontal sweep with viscous friction planted, prepared at a 10 Hz band."""
    return prepare([_log(model, friction=RATE_FRICTION)], bandwidth=10.0)


def _both_axes_log(seconds: float = 8.0, rate: float = 1000.0, seed: int = 0) -> Log:
    """A log moving on both axes: gap and position sums of two sines (periods of seconds, well inside
    a 10 Hz band), currents around equilibrium with a little white noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * rate)) / rate
    x = np.full((4, t.size), np.nan)
    x[0] = 0.020 + 1.0e-3 * np.sin(2 * math.pi * 0.4 * t) + 0.4e-3 * np.sin(2 * math.pi * 1.1 * t + 1.0)
    x[2] = 0.030 * np.sin(2 * math.pi * 0.23 * t) + 0.008 * np.sin(2 * math.pi * 0.9 * t + 0.3)
    u = np.vstack([0.5 * np.sin(2 * math.pi * 0.3 * t), 1.5 + 0.2 * np.sin(2 * math.pi * 0.7 * t)])
    u = u + 1e-3 * rng.standard_normal(u.shape)
    return Log(t, x, u, source=f"both axes seed {seed}")
