"""A survivor of the seed-46 mutation sample of ``maglev_oc.region`` (bench/README, "Mutation
testing"): ``RegulatorLoop.physical_state`` and ``error_state`` default to the same phase (0), so
that the one is the other's inverse when neither is given a phase, on a sinusoidal reference
(where the phase matters; a set-point is the same at every phase)."""

from __future__ import annotations

import math

import numpy as np
from numpy.testing import assert_allclose

from maglev_oc.region.closed_loop import Reference, RegulatorLoop


def test_the_default_phases_make_the_states_inverse():
    loop = RegulatorLoop()
    ref = Reference(0.02, 0.0, 3e-3, 0.01, 0.4, 1.1)  # both axes move with the phase
    rng = np.random.default_rng(46)
    x = np.array([0.02, 0.0, 0.0, 0.0])[:, None] + rng.normal(0.0, [[1e-3], [1e-2], [5e-3], [2e-2]], (4, 5))
    xi = rng.normal(0.0, 1e-4, (6, 5))
    back, xi_back = loop.physical_state(loop.error_state(x, xi, ref), ref)
    assert_allclose(back, x, rtol=0, atol=1e-15)  # the same floats through an add and a subtract
    assert_allclose(xi_back, xi, rtol=0, atol=1e-15)
    # the premise: another phase gives another state (the test would not see a wrong default)
    other, _ = loop.physical_state(loop.error_state(x, xi, ref), ref, math.pi / 3)
    assert np.max(np.abs(other - x)) > 1e-4
