"""Region properties from the survivors of the seed-51 mutation run, each a property of what a user
gets back, not of one line:

* the inner polygon's sampled radius along a direction is the distance to F's edge, found by
  bisection on [0, 2] in the directions' units (each direction asks for the current limit at
  t = 1, so the limit's ellipse, of diameter 2, bounds a radius from any point inside it); without
  a current limit F is unbounded towards weaker attraction, and the radius there is the cap, 2;
* F is closed (R >= 0, |u| <= I): a vertex whose interval enclosure touches 0 from above is proved
  at once, not subdivided until its budget runs out;
* a certified region of attraction says so in its message, with its level;
* an undecided robust certificate says "undecided within the budget";
* the region study's run from the certified boundary point nearest F's edge is judged against the
  study's F, current limit included (as are its Monte Carlo runs inside the set).
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.control.linear_regulator import paper_linear_regulator
from maglev_oc.model.hardware import PEAK_CURRENT_LIMIT
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.montecarlo import check_error_states
from maglev_oc.region.roa import certify_roa
from maglev_oc.region.robust_certificate import certificate_words
from maglev_oc.region.sdp import PolygonBuilder
from maglev_oc.region.study import operating_region_study
from tests.test_region_study_properties import TINY

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


def test_a_certified_region_of_attraction_says_so_with_its_level(model):
    """The linear regulator at 20 mm: certified, and the message gives the certified level and the
    three it is the least of (4 significant digits, as printed)."""
    res = certify_roa(model, paper_linear_regulator(model), SETPOINT)
    assert res.success and res.level > 0
    assert res.message.startswith(f"certified level {res.level:.4g} (stability ")


def test_an_undecided_robust_certificate_says_so():
    """No rung certified and none refuted: the words a user reads are "undecided within the budget"."""
    c = SimpleNamespace(status="not_certified", message="", nominal_level=1e-3, witness_plant=None)
    assert certificate_words(c) == "undecided within the budget"


def test_the_worst_start_is_judged_against_the_studys_current_limit(model, monkeypatch):
    """Every run of the study's Monte Carlo, the worst start included, is judged with the study's
    current limit (the default F's 9 A): recorded at each call; the worst start did run."""
    limits = []

    def recording(*args, **kwargs):
        limits.append(kwargs.get("current_limit", "default"))
        return check_error_states(*args, **kwargs)

    monkeypatch.setattr("maglev_oc.region.study.check_error_states", recording)
    st = operating_region_study(model, dataclasses.replace(TINY, robust_runs=0))
    assert st.references[0].worst_start  # the run from the boundary point was made
    assert limits and set(limits) == {FeasibleSet(model).current_limit}
