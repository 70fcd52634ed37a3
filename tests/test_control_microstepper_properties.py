"""Properties of the microstepper regulator and its current limiter, checked against closed forms
and the platform's own equations:

- the levitation-first limiter flags the pair whose thrust it cut, and an unreachable gap
  request sends i_d to the end of [-I, I] that comes closest;
- the regulator honours a given tracking time constant T_t: every axis's closed internal model
  has the characteristic polynomial (s + 1/T_t)^3;
- the amplifiers' saturation scales each pair's (i_q, i_d) onto the limit with its direction
  kept, and leaves pairs under the limit alone;
- the "margin" diagnostic is the room left in v_gap before R = 0.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
from numpy.testing import assert_allclose

from maglev_oc.control.gains import internal_model
from maglev_oc.control.microstepper import MicrostepperRegulator, saturated_currents
from maglev_oc.model.platform import microstepper

PLATFORM = microstepper()


PEAK = 9.0  # [A] the amplifiers' limit per pair (002 Sec. 4)


# --- the microstepper ---------------------------------------------------------------------------------
def test_microstepper_limiter_flags_each_pair_it_cuts():
    """A thrust request on x alone cuts pair A only, on y alone pair B only; a cut pair sits at
    the limit (slack 1e-9) and the uncut one below it."""
    reg = MicrostepperRegulator(PLATFORM)
    for v, flags in (([400.0, 0.0, 0.0], [1, 0, 0]), ([0.0, 400.0, 0.0], [0, 1, 0])):
        u, limited = (np.asarray(a, dtype=float).ravel() for a in reg.limiter(0.025, v))
        assert_allclose(limited, flags)
        mags = np.hypot(u[0::2], u[1::2])
        cut = np.array(flags[:2], dtype=bool)
        assert_allclose(mags[cut], PEAK, rtol=1e-8)
        assert np.all(mags[~cut] < PEAK * (1 - 1e-6))


def test_microstepper_unreachable_gap_request_goes_to_the_closest_end():
    """Far more and far less normal force than the motors give: i_d at -I and at +I."""
    reg = MicrostepperRegulator(PLATFORM)
    ends = []
    for v_gap in (-1e4, 1e4):  # [m/s^2]
        u, limited = (np.asarray(a, dtype=float).ravel() for a in reg.limiter(0.025, [0.0, 0.0, v_gap]))
        assert limited[2] == 1
        assert u[1] == u[3]
        ends.append(u[1])
    assert_allclose(sorted(ends), [-PEAK, PEAK], rtol=1e-8)


def test_microstepper_honours_the_tracking_time_constant_given():
    tau = 0.2  # [s] not the dominant time constant of either gain vector (0.130 s, 0.106 s)
    reg = MicrostepperRegulator(PLATFORM, tracking_time_constant=tau)
    assert_allclose(reg.tracking_time_constants, [tau] * 3, rtol=0)
    phi, _, _ = internal_model(reg.omega0)
    for gains, gain_l in zip((reg.K_h, reg.K_h, reg.K_v), reg.tracking_gains, strict=True):
        closed = phi - gain_l[:, None] @ gains[None, 2:]
        assert_allclose(np.poly(closed), np.poly([-1 / tau] * 3), rtol=1e-6)


def test_saturation_scales_each_pair_to_the_limit_keeping_its_direction():
    rng = np.random.default_rng(4)
    u_sym = ca.SX.sym("u", 4)
    sat = ca.Function("sat", [u_sym], list(saturated_currents(u_sym, PEAK)))
    for _ in range(20):
        u = rng.uniform(-12.0, 12.0, 4)
        got, over = (np.asarray(a, dtype=float).ravel() for a in sat(u))
        for j in range(2):
            pair, out = u[2 * j : 2 * j + 2], got[2 * j : 2 * j + 2]
            mag = np.hypot(*pair)
            assert over[j] == float(mag > PEAK)
            want = pair * min(1.0, PEAK / mag)  # the same direction, Euclidean magnitude <= peak
            assert_allclose(out, want, rtol=1e-12, atol=1e-12)


def test_the_microsteppers_margin_is_the_room_left_in_v_gap():
    """The "margin" diagnostic is how much further v_gap could rise before R = 0 (R is affine in
    v_gap): with it added, R is zero (to 1e-9 of R's scale at v: rounding of an affine function),
    and it is positive exactly where R is (the allocation is defined), on sampled (gap, v)."""
    ctrl = MicrostepperRegulator(microstepper())
    margin = ctrl._margin_function()
    transform = ctrl.transformation.function
    rng = np.random.default_rng(26)
    signs = []
    for _ in range(40):
        gap = rng.uniform(0.015, 0.03)
        v = rng.uniform(-20.0, 20.0, 3)
        m = float(margin(gap, v))
        R = float(transform(gap, v)[1])
        R_at = float(transform(gap, v + np.array([0.0, 0.0, m]))[1])
        assert abs(R_at) <= 1e-9 * max(abs(R), 1.0)
        signs.append(np.sign(m) == np.sign(R))
    assert all(signs)
