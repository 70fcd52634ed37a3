"""Properties of the feasible set F and the closed loop it is evaluated on (``maglev_oc.region
.feasibility``, ``closed_loop``), checked against F evaluated pointwise, finite differences and
closed forms:

- the stoppers are strict, each range is checked whichever other is dropped, and stoppers at a gap
  of zero or below are refused;
- F on the closed loop is F at the loop's physical state, its gap rows the distances to the
  stoppers, and every boundary point of a feasibility map satisfies the other constraints;
- the steady state solves the loop along the orbit; the papers' sinusoid is its closed form with
  its derivatives; the default phases make the physical and error states each other's inverse.
"""

from __future__ import annotations

import dataclasses
import math

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.control.gains import OMEGA0
from maglev_oc.errors import InputError
from maglev_oc.region.closed_loop import N_ERROR, Reference, RegulatorLoop
from maglev_oc.region.feasibility import CONSTRAINT_NAMES, FeasibleSet, feasibility_map


# --- the feasible set F -------------------------------------------------------------------------
def test_a_setpoint_on_a_stopper_is_refused_and_one_just_inside_is_held(model):
    """The stoppers bound F strictly (``check_setpoint``: "strictly between the stoppers"). Without
    a current limit only R >= 0 and the stoppers remain, and R > 0 at rest over 8-30 mm: at a
    stopper the set-point is refused by the stopper check alone; 0.1 mm inside it is held."""
    feasible = FeasibleSet(model, current_limit=None)
    (g_lo, g_hi), (p_lo, p_hi) = feasible.gap_range, feasible.position_range
    for gap, position in ((g_lo, 0.0), (g_hi, 0.0), (0.02, p_lo), (0.02, p_hi)):
        with pytest.raises(InputError, match="strictly between the stoppers"):
            feasible.check_setpoint(gap, position)
    for gap, position in ((g_lo + 1e-4, 0.0), (g_hi - 1e-4, 0.0), (0.02, p_lo + 1e-4), (0.02, p_hi - 1e-4)):
        feasible.check_setpoint(gap, position)


@pytest.mark.parametrize("low", [0.0, -1e-3])
def test_stoppers_at_a_gap_of_zero_or_below_are_refused(model, low):
    """A gap is positive (the field model is not defined at a closed gap): a lower stopper at or
    below 0 m is an input error, not a feasible set."""
    with pytest.raises(InputError, match="gap_range"):
        FeasibleSet(model, gap_range=(low, 0.03))


def _every_state_compensation() -> ca.Function:
    """A smooth effect x (4) -> (x2', x4') [m/s^2] that depends on every state, the way friction
    (velocities) and cogging or a cable carrier (position) do; coefficients of the size of the
    rig's effects (a few m/s^2 over the states' ranges)."""
    x = ca.SX.sym("x", 4)
    d_vertical = -20.0 * x[1] + 30.0 * x[2] - 2.0 * ca.tanh(x[3] / 0.01)
    d_horizontal = -15.0 * x[3] + 40.0 * x[2] + 100.0 * (x[0] - 0.02)
    return ca.Function("effect", [x], [ca.vertcat(d_vertical, d_horizontal)])


def test_the_loops_constraints_are_F_at_the_loops_physical_state(model):
    """The closed loop's constraints at (z~, phi) are F at the physical state of that z~: gap and
    position from :meth:`RegulatorLoop.physical_state`, v = (K_h z_h, K_v z_v) with z = z~ + z_ss
    (002 (23)-(24)), and the compensation at (x1, x2, x3, x4). Computed independently with
    numpy and :meth:`FeasibleSet.evaluate`; the two differ by rounding only (relative 1e-9 covers
    the few hundred operations of each side, ~1e-13 each, with room)."""
    loop = RegulatorLoop()
    ref = Reference.paper_sinusoid()
    feasible = FeasibleSet(model, compensation=_every_state_compensation())
    fn = feasible.loop_function(loop, ref)
    rng = np.random.default_rng(7)
    scale = np.array([2e-3, 0.05, 1e-4, 1e-3, 1e-3, 5e-3, 0.1, 1e-4, 1e-3, 1e-3])
    for phase in (0.3, 2.0, 4.5):
        zt = rng.uniform(-1, 1, (N_ERROR, 40)) * scale[:, None]
        x, _ = loop.physical_state(zt, ref, phase)
        z = zt + loop.steady_state(ref, phase)
        v1, v2 = loop.K_h @ z[5:], loop.K_v @ z[:5]
        want = feasible.evaluate(x[0], v1, v2, x2=x[1], x3=x[2], x4=x[3])
        got = np.asarray(fn.map(zt.shape[1])(zt, np.full((1, zt.shape[1]), phase)))
        np.testing.assert_allclose(got[:2], want, rtol=1e-9, atol=1e-9)
        (g_lo, g_hi), (p_lo, p_hi) = feasible.gap_range, feasible.position_range
        stoppers = np.vstack([x[0] - g_lo, g_hi - x[0], x[2] - p_lo, p_hi - x[2]])
        np.testing.assert_allclose(got[2:], stoppers, rtol=0, atol=1e-15)


def test_every_boundary_point_of_a_map_satisfies_the_other_constraints(model):
    """``FeasibilityMap.boundary[name]`` holds the points where ``name`` is zero *and every other
    constraint holds* (its docstring): the boundary of F, not of each constraint alone. On a slice
    through 20 mm where the stoppers' lines (e1 = -12 and +10 mm) cross the current boundary,
    every kept point has the other constraints >= 0 (to the 1e-9 relative tolerance the map
    itself uses) and lies on its own constraint's zero: Newton stops once its step is below 1e-12
    (CasADi's default step tolerance), and the headroom's slope along the line reaches 1.5e7 A^2
    per unit of xi_v3 on this slice (finite differences), so a root is exact to 1.5e-5 A^2 at
    worst (measured: 1.2e-8); 2e-5 is 2.5e-7 of the constraint's scale (81 A^2)."""
    feasible = FeasibleSet(model)
    loop = RegulatorLoop()
    ref = Reference.setpoint(0.02)
    fm = feasibility_map(feasible, loop, ref, ("e1", "xi_v3"), (-0.014, 0.012), (-0.1, 0.1), n=41)
    fn = feasible.loop_function(loop, ref)
    kept = 0
    for j, name in enumerate(CONSTRAINT_NAMES):
        pts = fm.boundary[name]
        if pts.shape[1] == 0:
            continue
        z = np.zeros((N_ERROR, pts.shape[1]))
        z[0], z[4] = pts
        h = np.asarray(fn.map(pts.shape[1])(z, np.zeros((1, pts.shape[1]))))
        others = np.delete(h, j, axis=0)
        assert np.all(others >= -1e-9 * np.maximum(1, np.abs(others))), name
        np.testing.assert_allclose(h[j], 0.0, atol=2e-5)
        kept += pts.shape[1]
    # the stoppers' lines do cross infeasible parts of the slice: the filter has work to do
    assert not fm.feasible[:, 0].all() or not fm.feasible[:, -1].all()
    assert kept > 20


# --- the loop in error coordinates ---------------------------------------------------------------
@pytest.mark.parametrize("omega", [None, 2.0])
def test_the_steady_state_solves_the_loop_along_the_orbit(loop, omega):
    """z_ss(phi) = Pi w(phi) is a trajectory of z' = A_cl z - B r'' (module docstring of
    closed_loop): omega dz_ss/dphi (central differences, step 1e-5 rad: error ~1e-10 of the
    amplitude) equals A_cl z_ss - B_v r_v'' - B_h r_h''. At the internal model's frequency (the
    papers' ellipse) and at 2 rad/s, where e_ss is not zero. Tolerance 1e-6 of the largest term."""
    ref = Reference.paper_sinusoid()
    if omega is not None:
        ref = dataclasses.replace(ref, omega=omega)
    phases = np.linspace(0.0, 2 * math.pi, 13)
    h = 1e-5
    dz = (loop.steady_state(ref, phases + h) - loop.steady_state(ref, phases - h)) / (2 * h) * ref.omega
    z = loop.steady_state(ref, phases)
    sig = ref.signals(phases)
    rhs = loop.A @ z - np.outer(loop.B_v, sig[2]) - np.outer(loop.B_h, sig[5])
    scale = np.max(np.abs(loop.A @ z))
    np.testing.assert_allclose(dz, rhs, rtol=0, atol=1e-6 * scale)


@pytest.mark.parametrize("reference", [Reference.setpoint(0.02), Reference(0.02, 0.01, 0.004, 0.02, 0.3)])
def test_the_loops_gap_constraints_are_the_distances_to_the_stoppers(model, reference):
    """With stoppers at (lo, hi), F's closed-loop rows gap_low and gap_high are x1 - lo and hi - x1
    at the gap x1 = reference gap at the phase + e1, on both sides of each stopper (negative
    beyond it); with no stoppers they are a constant satisfied value. Exact up to the sum's
    round-off (a few eps of the gap)."""
    loop = RegulatorLoop()
    lo, hi = 0.011, 0.029
    rows = [CONSTRAINT_NAMES.index("gap_low"), CONSTRAINT_NAMES.index("gap_high")]
    with_stoppers = FeasibleSet(model, gap_range=(lo, hi)).loop_function(loop, reference)
    without = FeasibleSet(model, gap_range=None).loop_function(loop, reference)
    rng = np.random.default_rng(34)
    for phase in (0.0, 1.1, 4.0):
        centre = reference.gap + reference.gap_amplitude * np.sin(phase + reference.gap_phase)
        for e1 in (-0.012, -0.005, 0.0, 0.004, 0.011):
            z = 1e-4 * rng.standard_normal(10)
            z[0] = e1
            h = np.asarray(with_stoppers(z, phase)).ravel()
            x1 = centre + e1
            np.testing.assert_allclose(h[rows], [x1 - lo, hi - x1], rtol=0, atol=1e-15)
            free = np.asarray(without(z, phase)).ravel()
            assert np.all(free[rows] > 0)
            np.testing.assert_allclose(free[:2], h[:2], rtol=1e-12)  # the other rows do not care


# --- the feasible set F -------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("dropped", "checked", "bad"),
    [
        ("gap_range", "position_range", (0.05, -0.05)),  # low above high
        ("gap_range", "position_range", (-0.8, 0.8)),  # beyond 0.5 m: not metres
        ("position_range", "gap_range", (0.03, 0.01)),
        ("position_range", "gap_range", (0.01, 0.9)),
    ],
)
def test_each_stopper_range_is_checked_whichever_other_is_dropped(model, dropped, checked, bad):
    """FeasibleSet's docstring: each of gap_range and position_range is (low, high) in metres or
    None (no stopper). Dropping one does not exempt the other from the check."""
    with pytest.raises(InputError, match=checked):
        FeasibleSet(model, **{dropped: None, checked: bad})
    # the same set with a well-formed range is accepted, stored as floats
    good = (0.01, 0.03) if checked == "gap_range" else (-0.05, 0.05)
    feasible = FeasibleSet(model, **{dropped: None, checked: good})
    assert getattr(feasible, checked) == good and getattr(feasible, dropped) is None


MM = 1e-3


# --- the papers' reference -----------------------------------------------------------------------
def test_the_papers_sinusoid_is_its_closed_form_with_its_derivatives():
    """r_v = 20 + 5 cos(w0 t) mm and r_h = 30 sin(w0 t) mm with their first and second time
    derivatives, at quarter periods and at arbitrary times over three periods (1e-12 in SI units:
    values up to 0.7 m/s^2, rounding ~1e-16 of that)."""
    ref = Reference.paper_sinusoid()
    w = OMEGA0
    period = 2 * math.pi / w
    t = np.concatenate([np.arange(5) * period / 4, np.random.default_rng(2).uniform(0, 3 * period, 9)])
    got = ref.signals(w * t)
    want = np.vstack(
        [
            20 * MM + 5 * MM * np.cos(w * t),
            -5 * MM * w * np.sin(w * t),
            -5 * MM * w**2 * np.cos(w * t),
            30 * MM * np.sin(w * t),
            30 * MM * w * np.cos(w * t),
            -30 * MM * w**2 * np.sin(w * t),
        ]
    )
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


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
