"""Properties of the SDP's inner polygons (``maglev_oc.region.sdp.PolygonBuilder``), checked against
the reference's own orbit, planted enclosures and F's edge:

- a vertex is proved only if every constraint holds on all its cells, and a vertex on the edge of
  the closed set is proved at once;
- a sinusoid's polygon covers the whole gap orbit widened by E, and one whose widened orbit
  reaches a closed gap is refused;
- a polygon is claimed only with the origin strictly inside, and the sampled radius is capped at
  the current limit's diameter.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from maglev_oc.model.hardware import PEAK_CURRENT_LIMIT
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet, constraints_from_coefficients
from maglev_oc.region.sdp import PolygonBuilder
from maglev_oc.results import check_result


# --- the SDP enlargement ------------------------------------------------------------------------
def test_a_polygon_vertex_is_proved_only_if_every_constraint_holds_on_its_cells(model):
    """The inner polygon's proof accepts a cell of (e1, phase) only when *every* constraint's
    enclosure is >= 0 there. At 20 mm with |e1| <= 2 mm, dv = (0, -45.2) m/s^2 keeps R > 0 (R / (4
    L4) > 50 m/s^2) and fits the 9 A limit except in a sliver near e1 = +2 mm (the headroom falls
    with the gap and is zero at 21.9 mm for v2 = -45.16, numpy below): it must not be proved,
    however thin the sliver. dv = (0, -10) m/s^2 (headroom > 0 on the whole range) must be."""
    loop = RegulatorLoop()
    ref = Reference.setpoint(0.02)
    builder = PolygonBuilder(FeasibleSet(model), loop)
    verts = np.array([[0.0, 0.0], [-10.0, -45.2]])
    gaps = 0.02 + np.linspace(-2e-3, 2e-3, 401)
    coef = model.coefficients(gaps)[:, :, None]
    h = constraints_from_coefficients(coef, 0.0, verts[1][None, :], model.params.gravity, 9.0)
    assert np.all(h[0] > 50) and np.all(h[1][:, 0] > 0)
    assert h[1][-1, 1] < 0 and np.mean(h[1][:, 1] < 0) < 0.05  # infeasible on under 5 % of the range
    fpar = loop.offset_coefficients(ref).ravel(order="F")[:, None]
    proved, _ = builder._prove_vertices(verts, 2e-3, False, fpar, 20_000)
    assert proved.tolist() == [True, False]


MM = 1e-3


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


def test_a_polygon_is_claimed_only_with_the_origin_strictly_inside(builder, monkeypatch):
    """At the 20 mm set-point with E = 1 mm the polygon is proved, and every face has b > 0 (the
    origin strictly inside). When F's sampled radius is zero over a half-plane of directions (the
    origin on F's edge, as at a set-point that needs all the current), the builder refuses, saying
    so, rather than claiming a polygon with the origin on its boundary."""
    ref = Reference.setpoint(0.02)
    poly = builder.build(ref, 1e-3)
    assert poly.success, poly.message
    assert np.all(poly.offsets > 0)
    sampled = builder._sampled_radii

    def on_the_edge(F, dirs, halfwidth, periodic):
        r = sampled(F, dirs, halfwidth, periodic)
        theta = np.arctan2(dirs[1], dirs[0])
        return np.where(np.cos(theta) > math.cos(math.radians(80)), 0.0, r)

    monkeypatch.setattr(builder, "_sampled_radii", on_the_edge)
    edge = builder.build(ref, 1e-3)
    assert not edge.success and edge.status == "not_proved"
    assert "origin" in edge.message


SETPOINT = Reference.setpoint(0.02)


HALFWIDTH = 1e-3  # E [m]


def _radii(model, current_limit):
    loop = RegulatorLoop()
    kwargs = {} if current_limit == "default" else {"current_limit": current_limit}
    builder = PolygonBuilder(FeasibleSet(model, **kwargs), loop)
    F = loop.offset_coefficients(SETPOINT)
    L1, _, L3, _ = model.coefficients([F[0, 0]])[:, 0]
    lim = builder.feasible.current_limit or PEAK_CURRENT_LIMIT  # the builder's scale
    th = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    dirs = np.vstack([np.cos(th), np.sin(th)]) * np.array([[L1 * lim], [abs(L3) * lim]])
    return th, builder._sampled_radii(F, dirs, HALFWIDTH, False)


def test_the_sampled_radius_is_capped_at_the_current_limits_diameter(model):
    """With the 9 A limit every radius is inside (0, 2) (measured 0.67-1.19). Without a limit F is
    bounded by R >= 0 alone (dv2 below a parabola in dv1): the directions of weaker attraction
    (dv2 < 0) are unbounded and their radius is the cap, 2 (to the bisection's 2 * 2^-40), while
    straight up the radius stays finite (measured 1.415)."""
    _, bounded = _radii(model, "default")
    assert np.all(bounded > 0) and np.all(bounded < 1.5)
    th, free = _radii(model, None)
    down = int(np.argmin(np.abs(th - 1.5 * np.pi)))
    assert free[down] == pytest.approx(2.0, abs=4 * 2.0**-40)
    up = int(np.argmin(np.abs(th - 0.5 * np.pi)))
    assert free[up] < 1.9


def test_a_vertex_on_the_edge_of_the_closed_set_is_proved_at_once(model, monkeypatch):
    """An interval enclosure [0, 1] of every constraint on every cell (a stand-in for a vertex on
    R = 0): proved on the first 16 cells of the set-point's gap range, none subdivided."""
    loop = RegulatorLoop()
    builder = PolygonBuilder(FeasibleSet(model), loop)

    def touching(lo, hi):
        n = lo[0].shape[1]
        return [np.zeros((2, n))], [np.ones((2, n))]

    monkeypatch.setattr(builder, "_ifn", touching)
    fpar = loop.offset_coefficients(SETPOINT).ravel(order="F")[:, None]
    proved, used = builder._prove_vertices(np.array([[1.0], [0.0]]), HALFWIDTH, False, fpar, 1000)
    assert proved.tolist() == [True] and used == 16
