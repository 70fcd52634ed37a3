"""Region properties from the survivors of the seed-50 mutation run, each a property of what a user
hands in or gets back, not of one line:

* an uncertainty ellipsoid of the plant's constants is refused unless its shape is a 4 x 4
  matrix, one per constant (a 3 x 3 covariance of C1..C3 alone says nothing about C4);
* a Lyapunov matrix's symmetry check does not depend on its units: P and 1e-12 P are refused or
  accepted alike (a P in other units, e.g. gaps in mm, is the same certificate);
* the SDP's inner polygon is claimed only with the origin dv = 0 strictly inside it: the SDP's
  faces n' dv <= b need b > 0, or the certified set would have to sit on F's edge.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_oc.errors import InputError
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.ellipsoid import checked_p
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.sdp import PolygonBuilder
from maglev_oc.region.sweep import PlantSet

CENTER = (14.8, 100.0, -2.0, 0.13)  # C1..C4 of the papers' scale; only positivity matters here


def test_an_uncertainty_ellipsoid_needs_one_row_and_column_per_constant():
    """A symmetric, finite, positive definite 3 x 3 shape is refused with a message naming the 4 x 4
    shape it needs; the same matrix bordered to 4 x 4 (C4 held) is accepted."""
    s3 = np.diag([0.1, 1.0, 0.01])
    with pytest.raises(InputError, match="4 x 4"):
        PlantSet("ellipsoid", (14.8, 100.0, 2.0, 0.13), shape=tuple(map(tuple, s3)))
    s4 = np.zeros((4, 4))
    s4[:3, :3] = s3
    assert PlantSet("ellipsoid", (14.8, 100.0, 2.0, 0.13), shape=tuple(map(tuple, s4))).kind == "ellipsoid"


@pytest.mark.parametrize("scale", [1.0, 1e-12])
def test_the_lyapunov_matrix_symmetry_check_is_relative(scale):
    """A P whose off-diagonal pairs differ by 1e-6 of its entries is refused at any scale (1e-6 is
    far above the 1e-10 relative rounding the check allows and far below any real asymmetry), and
    the exactly symmetric P is accepted at any scale. At scale 1e-12 the asymmetry is 1e-18 in
    absolute terms, below any absolute tolerance: a check with one would accept it."""
    a = np.random.default_rng(50).standard_normal((10, 10))
    p = (a @ a.T + 10 * np.eye(10)) * scale
    skew = np.triu(np.full((10, 10), 1e-6 * scale), 1)
    with pytest.raises(InputError, match="symmetric"):
        checked_p(p + skew)
    np.testing.assert_array_equal(checked_p(p), p)


@pytest.fixture(scope="module")
def builder(model):
    return PolygonBuilder(FeasibleSet(model), RegulatorLoop())


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
