"""The FL loop in error coordinates (maglev_oc.region.closed_loop)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_oc.control.gains import PAPER_GAINS, axis_poles
from maglev_oc.region.closed_loop import Reference, RegulatorLoop


@pytest.fixture(scope="module")
def loop():
    return RegulatorLoop()


def test_closed_loop_poles_are_the_papers(loop):
    """A_cl is block-diagonal with the augmented axes closed by the printed gains (001/002)."""
    ev = np.sort_complex(np.linalg.eigvals(loop.A))
    expect = np.sort_complex(
        np.concatenate([axis_poles(PAPER_GAINS["K_v"].printed), axis_poles(PAPER_GAINS["K_h"].printed)])
    )
    np.testing.assert_allclose(ev, expect, rtol=1e-9)  # the same matrices: rounding only


def test_steady_state_of_the_sinusoid(loop):
    """For omega = omega0 the internal model cancels the error and K Pi w = r'' (regulator equations)."""
    ref = Reference.paper_sinusoid()
    phase = np.linspace(0, 2 * math.pi, 13)
    zss = loop.steady_state(ref, phase)
    np.testing.assert_allclose(zss[[0, 1, 5, 6]], 0, atol=1e-15)
    off = loop.offsets(ref, phase)
    sig = ref.signals(phase)
    np.testing.assert_allclose(off[2], sig[5], rtol=1e-9, atol=1e-12)  # v1 = r_h''
    np.testing.assert_allclose(off[3], sig[2], rtol=1e-9, atol=1e-12)  # v2 = r_v''
    F = loop.offset_coefficients(ref)
    basis = np.vstack([np.ones_like(phase), np.sin(phase), np.cos(phase)])
    np.testing.assert_allclose(F @ basis, off, atol=1e-12)


def test_error_state_round_trip(loop):
    rng = np.random.default_rng(0)
    ref = Reference.paper_sinusoid()
    z = rng.standard_normal((10, 5)) * 1e-3
    x, xi = loop.physical_state(z, ref, 0.7)
    np.testing.assert_allclose(loop.error_state(x, xi, ref, 0.7), z, atol=1e-15)


def test_lyapunov_matrix(loop):
    """The Lyapunov equation's P guarantees a decay rate of 0.333 1/s for V (largest eigenvalue of
    P^-1/2 (A'P + PA) P^-1/2 is -0.666): the test brackets it."""
    P = loop.lyapunov_matrix()
    assert loop.is_lyapunov(P)
    assert loop.is_lyapunov(P, decay=0.33)
    assert not loop.is_lyapunov(P, decay=0.34)
    assert not loop.is_lyapunov(np.eye(10))


def test_validation():
    with pytest.raises(ValueError, match="metres"):
        Reference.setpoint(20.0)
    with pytest.raises(ValueError, match="amplitudes"):
        Reference(0.02, gap_amplitude=-1e-3)
    with pytest.raises(TypeError):
        Reference(0.02, gain=3)  # unknown keyword
    with pytest.raises(ValueError, match="5 finite gains"):
        RegulatorLoop(K_h=[1, 2, 3])
    with pytest.raises(ValueError, match="Hurwitz"):
        RegulatorLoop(K_h=np.ones(5))


@pytest.mark.parametrize(
    "fastest_growing, stable", [(0.5, False), (1e-3, False), (-1e-3, True), (-0.5, True)]
)
def test_gains_are_refused_exactly_when_a_closed_loop_pole_is_not_in_the_left_half_plane(
    fastest_growing, stable
):
    # gains placed (scipy.signal.place_poles on the augmented horizontal axis) so that its
    # rightmost closed-loop pole is at ``fastest_growing`` [1/s], the others at -4..-7: A_cl is
    # Hurwitz exactly when that pole is negative (a check at another bound, 1 1/s, let 0.5 pass)
    from scipy.signal import place_poles

    from maglev_oc.region.closed_loop import augmented_axis

    a, b = augmented_axis(RegulatorLoop().omega0)
    gains = -place_poles(a, b, [fastest_growing, -4.0, -5.0, -6.0, -7.0]).gain_matrix[0]
    np.testing.assert_allclose(
        np.max(np.linalg.eigvals(a + b @ gains[None, :]).real), fastest_growing, atol=1e-6
    )
    if stable:
        RegulatorLoop(K_h=gains)
    else:
        with pytest.raises(ValueError, match="Hurwitz"):
            RegulatorLoop(K_h=gains)
