"""The SDP enlargement's failures are reported as failures (maglev_oc.region.sdp): an inner
polygon that cannot be proved is not a polygon, and a search in which no polygon can be proved
certifies nothing."""

from __future__ import annotations

import pytest

from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.region.sdp import PolygonBuilder, enlarge
from maglev_oc.results import check_result

REF = Reference.setpoint(0.02)


@pytest.fixture(scope="module")
def builder(model):
    return PolygonBuilder(FeasibleSet(model), RegulatorLoop())


def _refused(poly, words):
    check_result(poly)
    assert not poly.success and poly.status == "not_proved" and words in poly.message
    # no faces either: normals n' dv <= b, each a 2-vector, none of them
    assert poly.vertices.shape == (2, 0) and poly.normals.shape == (0, 2) and poly.offsets.shape == (0,)


def test_a_polygon_reaching_a_closed_gap_is_not_proved(builder):
    # |e1| <= 25 mm around 20 mm reaches gaps below 0: the model (and F) is not defined there
    _refused(builder.build(REF, 0.025), "<= 0")
    with pytest.raises(ValueError, match="halfwidth"):
        builder.build(REF, 0.0)


def test_a_polygon_whose_slices_are_not_convex_is_not_proved(model):
    # the slices of F are convex only while the root at R = 0 needs more current than the limit
    # (-L3 / (2 L4) >= I, about 18 A over 8-30 mm): with a 30 A limit that premise fails
    wide = PolygonBuilder(FeasibleSet(model, current_limit=30.0), RegulatorLoop())
    _refused(wide.build(REF, 2e-3), "convex")


def test_when_no_polygon_can_be_proved_nothing_is_certified(model, builder):
    proc = Procedure2(FeasibleSet(model), RegulatorLoop())
    res = enlarge(proc, REF, fractions=(3.0,), builder=builder)  # E = 3x the room to the stopper
    check_result(res)
    assert not res.success and res.status == "not_certified" and res.best is None and res.certified is None
    (cand,) = res.candidates
    assert not cand.success and cand.solver_status == "no polygon" and cand.certified is None
