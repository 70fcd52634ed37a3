"""Region properties from the survivors of the seed-39 mutation run, each a property of a result a
user sees, not of one line:

* the branch and bound over (zeta, phase) halves every box along its widest side with the
  phase's width counted per pi (the phase runs over [0, 2 pi), zeta over [-1, 1]: a phase cell
  as long as a zeta side in those units is as wide), and never along the phase for a set-point
  (the phase pinned at 0): zeta widths 0.2 and a phase width of 0.5 rad (0.16 per pi) split a
  zeta side. Checked against the split recomputed from the widths; exact (tolerance 0: the
  halves are the same midpoints, 0.5 (lo + hi), and the other sides are copied);
* an inner polygon for a sinusoid covers the whole gap orbit widened by the half-width E:
  gaps [r_v - a_v - E, r_v + a_v + E] with r_v, a_v the reference's own gap and amplitude.
  The proved polygon's message names that range (to the 0.001 mm it prints), and a range
  whose low end reaches a closed gap is refused as such (to the 3 digits it prints);
* a robust certificate's initial-condition set is {z~' P z~ <= level} of its own P and level:
  each semi-axis s_i has s_i^2 P_ii = level (relative 1e-12: one square root and its square)
  and the rectangle's worst corner lies on that boundary (relative 1e-9, the bisection
  tolerance of ``max_rectangle`` with margin); a certificate whose nominal failed has level 0
  and a set of zero sizes.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from maglev_oc.region.branch_and_bound import _bisect_boxes
from maglev_oc.region.closed_loop import DE1, DE2, E1, E2, Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.region.robust_certificate import RobustCertifier
from maglev_oc.region.sdp import PolygonBuilder
from maglev_oc.region.sweep import PlantSet
from maglev_oc.results import check_result

MM = 1e-3


# --- the branch and bound's bisection ------------------------------------------------------------
def _expected_split(lo, hi, periodic):
    """Each box's two halves along its widest side, the phase (last row) counted per pi and
    never split for a set-point; recomputed box by box."""
    d = lo.shape[0] - 1
    weight = np.append(np.ones(d), 1.0 / math.pi if periodic else 0.0)
    halves = []
    for k in range(lo.shape[1]):
        j = int(np.argmax((hi[:, k] - lo[:, k]) * weight))
        mid = 0.5 * (lo[j, k] + hi[j, k])
        a_lo, a_hi, b_lo, b_hi = lo[:, k].copy(), hi[:, k].copy(), lo[:, k].copy(), hi[:, k].copy()
        a_hi[j], b_lo[j] = mid, mid
        halves.append((j, a_lo, a_hi, b_lo, b_hi))
    return halves


def _random_boxes(rng, n, periodic):
    d = 3
    zlo = rng.uniform(-1.0, 0.5, (d, n))
    zw = rng.uniform(0.05, 0.5, (d, n))
    if periodic:
        plo, pw = rng.uniform(0.0, 5.0, n), rng.uniform(0.05, 1.2, n)
    else:
        plo, pw = np.zeros(n), np.zeros(n)
    return np.vstack([zlo, plo]), np.vstack([zlo + zw, plo + pw])


@pytest.mark.parametrize("periodic", [True, False], ids=["sinusoid", "set-point"])
def test_boxes_are_halved_along_the_widest_side_with_the_phase_counted_per_pi(periodic):
    rng = np.random.default_rng(39)
    lo, hi = _random_boxes(rng, 200, periodic)
    if periodic:
        # the brief's case: zeta sides 0.2 and a phase cell of 0.5 rad (0.16 per pi): a zeta side
        lo[:, 0], hi[:, 0] = [0.0, 0.0, 0.0, 1.0], [0.2, 0.2, 0.2, 1.5]
    expected = _expected_split(lo, hi, periodic)
    scale = np.append(np.ones(3), 1.0 / math.pi)
    got_lo, got_hi = _bisect_boxes(lo.copy(), hi.copy(), scale.copy(), periodic)
    n = lo.shape[1]
    assert got_lo.shape == got_hi.shape == (4, 2 * n)
    if periodic:
        assert expected[0][0] < 3  # a zeta side, not the phase
    split = []
    for k, (j, a_lo, a_hi, b_lo, b_hi) in enumerate(expected):
        np.testing.assert_array_equal(got_lo[:, k], a_lo)
        np.testing.assert_array_equal(got_hi[:, k], a_hi)
        np.testing.assert_array_equal(got_lo[:, n + k], b_lo)
        np.testing.assert_array_equal(got_hi[:, n + k], b_hi)
        split.append(j)
    # both kinds of split are exercised for a sinusoid; the phase never for a set-point
    assert (3 in split) == periodic and any(j < 3 for j in split)


# --- the inner polygon's gap range -----------------------------------------------------------------
@pytest.fixture(scope="module")
def builder(model):
    return PolygonBuilder(FeasibleSet(model), RegulatorLoop())


def test_a_sinusoids_polygon_covers_the_whole_gap_orbit_widened_by_e(builder):
    """The papers' sinusoid (r_v = 20 + 5 cos mm) with E = 1 mm: gaps 14 to 26 mm."""
    ref, E = Reference.paper_sinusoid(), 1 * MM
    poly = builder.build(ref, E)
    check_result(poly)
    assert poly.success and poly.status == "proved", poly.message
    m = re.search(r"on gap \[([-\d.]+), ([-\d.]+)\] mm", poly.message)
    assert m, poly.message
    lo_mm, hi_mm = float(m.group(1)), float(m.group(2))
    want_lo = (ref.gap - ref.gap_amplitude - E) / MM
    want_hi = (ref.gap + ref.gap_amplitude + E) / MM
    assert lo_mm == pytest.approx(want_lo, abs=1e-3) and hi_mm == pytest.approx(want_hi, abs=1e-3)


def test_a_sinusoid_whose_widened_orbit_reaches_a_closed_gap_is_refused(builder):
    """E = 16 mm around 20 +- 5 mm reaches a gap of -1 mm (at the orbit's lowest point), though
    the orbit's highest point minus E (9 mm) does not."""
    ref, E = Reference.paper_sinusoid(), 16 * MM
    poly = builder.build(ref, E)
    check_result(poly)
    assert not poly.success and poly.status == "not_proved"
    m = re.search(r"gap range reaches ([-\d.e+]+) mm <= 0", poly.message)
    assert m, poly.message
    assert float(m.group(1)) == pytest.approx((ref.gap - ref.gap_amplitude - E) / MM, rel=5e-3)


# --- the robust certificate's initial-condition set ------------------------------------------------
@pytest.fixture(scope="module")
def loop():
    return RegulatorLoop()


@pytest.fixture(scope="module")
def certifier(model, loop):
    return RobustCertifier(FeasibleSet(model), loop, max_boxes=100_000, ladder=(1.0, 0.6, 0.3))


def _on_boundary(P, level, ics):
    for name, i in (("e1", E1), ("e1_rate", DE1), ("e2", E2), ("e2_rate", DE2)):
        assert ics.semi_axes[name] ** 2 * P[i, i] == pytest.approx(level, rel=1e-12, abs=0.0)
    a1, a2 = ics.rectangle.vertical, ics.rectangle.horizontal
    assert a1 > 0 and a2 > 0
    corners = []
    for s in (1.0, -1.0):
        z = np.zeros(P.shape[0])
        z[E1], z[E2] = a1, s * a2
        corners.append(z @ P @ z)
    worst = max(corners)  # the largest rectangle touches the ellipse at a corner
    assert worst == pytest.approx(level, rel=1e-9)


def test_a_robust_certificates_initial_conditions_are_its_own_level_set(model, loop, certifier):
    """Theta = {C_nom} at a 20 mm set-point: certified at the nominal level (the cheapest
    certified robust certificate, as in test_region_robust_certificate)."""
    nominal = Procedure2(FeasibleSet(model), loop).run(Reference.setpoint(0.02))
    res = certifier.run(nominal, PlantSet.point(np.asarray(model.constants.as_array())))
    check_result(res)
    assert res.status == "certified" and res.level > 0
    _on_boundary(res.P, res.level, res.initial_conditions)


def test_a_certificate_whose_nominal_failed_has_an_empty_initial_condition_set(model, loop, certifier):
    """A sinusoid reaching the upper stopper: no nominal level, so level 0 and zero sizes."""
    nominal = Procedure2(FeasibleSet(model), loop).run(Reference(0.027, gap_amplitude=0.004))
    assert not nominal.success
    res = certifier.run(nominal, PlantSet.point(np.asarray(model.constants.as_array())))
    check_result(res)
    assert res.status == "not_certified" and res.level == 0.0
    ics = res.initial_conditions
    assert set(ics.semi_axes) == {"e1", "e1_rate", "e2", "e2_rate"}
    assert all(v == 0.0 for v in ics.semi_axes.values())
    assert ics.rectangle.vertical == 0.0 and ics.rectangle.horizontal == 0.0
