"""The reference a region is certified for (``maglev_oc.region.closed_loop.Reference``) as what
it claims to be: r_v = gap + a_v sin(omega t + phi_v), r_h = position + a_h sin(omega t + phi_h)
and their first two time derivatives, checked against the closed form and against central
differences in time (independent of how the module writes the exosystem). Numpy, milliseconds."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.region.closed_loop import Reference


@pytest.mark.parametrize(
    "ref",
    [
        Reference.paper_sinusoid(),
        # both axes moving, distinct phases and a frequency other than omega0, so that a factor
        # swapped between the axes, or omega where omega^2 belongs, shows
        Reference(0.018, -0.01, 3e-3, 20e-3, 0.4, -1.1, 3.7),
    ],
)
def test_signals_are_the_sinusoids_and_their_time_derivatives(ref):
    """(r_v, r_v', r_v'', r_h, r_h', r_h'') at phase phi = omega t: the values are the closed form
    (1e-15 m: rounding of millimetre-sized sums), and each derivative is the central difference
    of the signal before it in time (step 1e-5 s: truncation omega^2 h^2 / 6 ~ 2e-9 relative,
    rounding 1e-16 / 1e-5 ~ 1e-11 m/s; 1e-7 relative to the amplitude x omega^k covers both)."""
    phase = np.linspace(0.0, 2 * math.pi, 17)
    om = ref.omega
    sig = ref.signals(phase)
    assert sig.shape == (6, phase.size)
    assert_allclose(sig[0], ref.gap + ref.gap_amplitude * np.sin(phase + ref.gap_phase), rtol=0, atol=1e-15)
    assert_allclose(
        sig[3], ref.position + ref.position_amplitude * np.sin(phase + ref.position_phase), rtol=0, atol=1e-15
    )
    h = 1e-5  # [s]
    ahead, behind = ref.signals(phase + om * h), ref.signals(phase - om * h)
    for axis, amplitude in ((0, ref.gap_amplitude), (3, ref.position_amplitude)):
        for k in (1, 2):
            rate = (ahead[axis + k - 1] - behind[axis + k - 1]) / (2 * h)
            assert_allclose(sig[axis + k], rate, rtol=0, atol=1e-7 * amplitude * om**k)


def test_a_setpoint_has_no_motion():
    """A set-point's signals are its gap and position with zero rates and accelerations."""
    sig = Reference.setpoint(0.021, 0.013).signals(np.array([0.0, 1.0, 4.0]))
    assert_allclose(sig[[0, 3]], [[0.021] * 3, [0.013] * 3], rtol=0, atol=0)
    assert not np.any(sig[[1, 2, 4, 5]])
