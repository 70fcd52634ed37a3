"""Options of ``maglev_oc.identification`` passed by name, each test failing when its option is
ignored (the default used instead) or inverted:

- constrained Gauss-Newton stops at the first iterate within ``constraint_tolerance``;
- ``gap_sweep_reference(sweep_period)`` is the raised cosine's period (closed form);
  ``MultisineShape.tilt`` makes the tones' amplitudes fall as f^-tilt (read off the DFT); the
  design's ``continuous_current`` bounds the run's RMS current.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.identification.constrained_gn import constrained_gauss_newton
from maglev_oc.identification.design import (
    REFERENCE_RATE_HZ,
    MultisineShape,
    SampledReference,
    gap_sweep_reference,
    multisine_reference,
)
from maglev_oc.identification.design import FeasibleSet as DesignFeasibleSet
from tests._identification_cases import _circle

# --- constrained Gauss-Newton ----------------------------------------------------------------------------
DATA = np.array([2.0, 0.5])


@pytest.mark.parametrize("constraint_tolerance", [0.5, 0.1, 1e-3])
def test_gauss_newton_stops_at_the_first_iterate_within_the_constraint_tolerance(constraint_tolerance):
    """With a step tolerance of 1 every full step counts as small, so the constraint alone decides:
    the solver must stop at the first iterate with |c| < constraint_tolerance, not later (the default
    1e-6 takes 9 iterations from this start) and not earlier (one iterate before, |c| >= it)."""
    w0 = np.array([0.3, 0.2])
    out = constrained_gauss_newton(
        _circle, w0, np.ones(2), tolerance=1.0, constraint_tolerance=constraint_tolerance
    )
    assert out.status == "converged", out.message
    assert abs(out.c[0]) < constraint_tolerance
    assert out.iterations >= 2  # from |c| = 0.87 no tolerance here is met by the start
    before = constrained_gauss_newton(
        _circle, w0, np.ones(2), max_iterations=out.iterations - 1, tolerance=1.0, constraint_tolerance=1e-300
    )
    assert before.iterations == out.iterations - 1  # the same iterates (the tolerances never stopped it)
    assert abs(before.c[0]) >= constraint_tolerance
    default = constrained_gauss_newton(_circle, w0, np.ones(2), tolerance=1.0)
    assert abs(default.c[0]) < 1e-6 and default.iterations > out.iterations


# --- experiment design ---------------------------------------------------------------------------------
@pytest.mark.parametrize(("sweep_period", "periods"), [(20.0, 3), (60.0, 1), (30.0, 2)])
def test_gap_sweep_period_is_the_raised_cosines_period(sweep_period, periods):
    """Without ripple and horizontal multisine the gap set-point is the raised cosine alone,
    mid - half cos(2 pi t / T) with T = ``sweep_period`` (a divisor of the run here, so exact), its
    derivatives analytic; the gap is at its smallest (the low end) once per period."""
    lo, hi, duration = 10e-3, 25e-3, 60.0
    ref = gap_sweep_reference(duration, gaps=(lo, hi), sweep_period=sweep_period, ripple=0.0, horizontal=None)
    t = ref.t
    w = 2 * math.pi / sweep_period
    mid, half = (lo + hi) / 2, (hi - lo) / 2
    # 1e-15 m: rounding of the sampled cosine
    assert_allclose(ref.values[0], mid - half * np.cos(w * t), rtol=0, atol=1e-15)
    assert_allclose(ref.values[1], half * w * np.sin(w * t), rtol=0, atol=1e-15)
    assert_allclose(ref.values[2], half * w**2 * np.cos(w * t), rtol=0, atol=1e-15)
    at_low = np.flatnonzero(np.abs(ref.values[0] - lo) < 1e-12)
    assert at_low.size == periods and f"({periods} x {sweep_period:g} s)" in ref.description


@pytest.mark.parametrize("tilt", [0.0, 1.0, 2.0])
def test_multisine_tilt_makes_the_amplitudes_fall_as_a_power_of_the_frequency(tilt):
    """Horizontal tones of amplitude a_k ~ f_k^-tilt: read off the DFT of one whole period after the
    2 s ramp (a 20 s period of a 40 s run: every tone an integer number of cycles, so each lands in
    its own bin and the ratio is exact to round-off, 1e-6 here). Tilt 2 is the documented "equal
    accelerations": the acceleration row's tones are all of one size."""
    shape = MultisineShape(band=(0.2, 4.0), tones=6, tilt=tilt)
    ref = multisine_reference(40.0, vertical=None, horizontal=shape)
    n = round(20.0 * REFERENCE_RATE_HZ)
    last = slice(ref.t.size - n, ref.t.size)
    h = shape.harmonics(20.0)
    pos = np.abs(np.fft.rfft(ref.values[3, last]))[h]
    acc = np.abs(np.fft.rfft(ref.values[5, last]))[h]
    assert_allclose(pos / pos[0], (h / h[0]) ** (-tilt), rtol=1e-6)
    # r'' = -w^2 r tone by tone: the acceleration's tones fall as f^(2 - tilt)
    assert_allclose(acc / acc[0], (h / h[0]) ** (2 - tilt), rtol=1e-6)


def test_design_continuous_current_bounds_the_rms_current():
    """A run with |i| = 5 A throughout (i = (3, 4) A) has an RMS current of exactly 5 A: a
    continuous rating of 4.9 A flags it, 5.1 A and the default 7 A do not (the peak, 5 A, is
    within every peak limit here)."""
    n = 200
    t = np.arange(n) / REFERENCE_RATE_HZ
    ref = SampledReference(t, np.vstack([np.full(n, 0.02), np.zeros((5, n))]))
    run = SimpleNamespace(
        success=True,
        x=np.vstack([np.full(n, 0.02), np.zeros(n), np.zeros(n), np.zeros(n)]),
        u=np.vstack([np.full(n, 3.0), np.full(n, 4.0)]),
    )

    def rms_flags(**kw):
        return [v for v in DesignFeasibleSet(**kw).violations(ref, run) if "RMS current" in v]

    assert rms_flags(continuous_current=4.9, peak_current=9.0)
    assert not rms_flags(continuous_current=5.1, peak_current=9.0)
    assert not rms_flags()
