"""Properties of the SDP enlargement (``maglev_oc.region.sdp`` and the certified sets it builds),
checked against closed forms of the ellipsoids, planted candidates and dense sampling:

- the largest rectangle fits the ellipse and no sampled one is larger; the reach along a
  direction is where the certified set ends; the construction level is the largest inside the
  polygon and the gap band;
- the SDP keeps its decay rate and follows its weights, and its ellipsoid keeps the whole
  horizontal orbit inside the position range;
- the enlargement keeps the candidate with the largest score, reports a P failing the Lyapunov
  recheck with its half-width, says when no candidate could be certified, and times itself at the
  stoppers; a half-period shift of the reference proves the same polygon for the same work.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.control.gains import OMEGA0
from maglev_oc.region import sdp
from maglev_oc.region import sdp as sdp_module
from maglev_oc.region.closed_loop import E2, Reference, RegulatorLoop
from maglev_oc.region.ellipsoid import max_rectangle
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.region.sdp import (
    InnerPolygon,
    PolygonBuilder,
    SdpCandidate,
    construction_level,
    enlarge,
    solve_sdp,
)
from maglev_oc.results import check_result


# --- ellipsoid geometry ---------------------------------------------------------------------------
@pytest.mark.parametrize("p12", [-1.5, -0.4, 0.0, 0.9, 1.9])
def test_the_largest_rectangle_fits_the_ellipse_and_no_sampled_one_is_larger(p12):
    """``max_rectangle``: its corners (+-a, +-b) lie in {y' P2 y <= c} (one on the boundary, to
    rounding: 1e-12 relative), and no box of another aspect ratio scaled onto the ellipse has a
    larger area. The others are sampled densely: 20001 angles; the area is flat at the optimum, so
    the grid's best is within (pi/20000)^2 ~ 2.5e-8 relative of the true maximum (1e-7 allowed)."""
    P2 = np.array([[4.0, p12], [p12, 1.0]])  # positive definite: p12^2 < 4
    level = 0.7
    a, b = max_rectangle(P2, level)
    corners = np.array([[a, b], [a, -b], [-a, b], [-a, -b]])
    values = np.einsum("ki,ij,kj->k", corners, P2, corners)
    assert values.max() == pytest.approx(level, rel=1e-12)
    t = np.linspace(0, math.pi / 2, 20001)
    c, s = np.cos(t), np.sin(t)
    size = np.sqrt(level / (c**2 * P2[0, 0] + s**2 * P2[1, 1] + 2 * np.abs(c * s * P2[0, 1])))
    assert a * b >= (size**2 * c * s).max() * (1 - 1e-7)


def test_the_reach_along_a_direction_is_where_the_certified_set_ends(model):
    """``enlarge(direction=d)``: ``best.reach`` is the largest t with t d in the certified set
    {V <= c}, i.e. (t d)' P (t d) = c exactly (to rounding, 1e-9 relative); for the papers' large
    step 26 -> (18, 20) mm it is above 1 (the start is covered)."""
    loop = RegulatorLoop()
    feasible = FeasibleSet(model)
    proc = Procedure2(feasible, loop, starts=4)
    ref = Reference.setpoint(0.018, 0.020)
    z0 = loop.error_state([0.026, 0, 0, 0], np.zeros(6), ref)[:, 0]
    res = enlarge(proc, ref, fractions=(0.75,), builder=PolygonBuilder(feasible, loop), direction=z0)
    best = res.best
    t = best.reach
    assert t > 1
    assert (t * z0) @ best.P @ (t * z0) == pytest.approx(best.certified.level, rel=1e-9)


def test_the_construction_level_is_the_largest_inside_the_polygon_and_the_gap_band(loop):
    """construction_level: the largest c <= 1 with {V <= c} inside [-E, E] x Poly: on {V <= c} the
    linear function m'z ranges over +-sqrt(c m'P^-1 m) (computed here from P's inverse), so at
    the level every face and |e1| <= E hold and one of them is reached. A square polygon
    |dv1|, |dv2| <= b and two bands E, one binding, one not."""
    P = loop.lyapunov_matrix()
    p_inv = np.linalg.inv(P)
    normals = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    for E, b in ((1e-4, 50.0), (5e-3, 0.5)):
        poly = InnerPolygon(True, "proved", "planted", E, np.zeros((2, 4)), normals, np.full(4, b), 0)
        c = construction_level(loop, P, poly, E)
        reach_e1 = math.sqrt(c * p_inv[0, 0])
        rows = normals @ loop.output[2:4]
        reach_faces = np.sqrt(c * np.einsum("ij,jk,ik->i", rows, p_inv, rows))
        assert reach_e1 <= E * (1 + 1e-9) and np.all(reach_faces <= b * (1 + 1e-9))
        reached = max(reach_e1 / E, np.max(reach_faces) / b)
        assert c == pytest.approx(1.0) or reached == pytest.approx(1.0, rel=1e-9)


def _square(halfwidth: float, b: float) -> InnerPolygon:
    """A planted inner polygon |dv1|, |dv2| <= b [m/s^2] over the gap band |e1| <= halfwidth [m]."""
    normals = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    return InnerPolygon(True, "proved", "planted", halfwidth, np.zeros((2, 4)), normals, np.full(4, b), 0)


def test_the_sdp_keeps_its_decay_rate_and_follows_its_weights(model, loop):
    """solve_sdp: "A Q + Q A' + 2 decay Q <= 0": the P it returns is a Lyapunov matrix with 0.9 of
    the decay rate asked (10 % for the solver's accuracy; measured to hold at 0.999). Weighting
    log a2 four times log a1 gives a larger e2 half-side than the other way round (measured
    0.011935 against 0.011912 m, 2e-3 apart, far above Clarabel's 1e-8)."""
    ref, feasible = Reference.setpoint(0.02), FeasibleSet(model)
    sides = {}
    for weights in ((4.0, 1.0), (1.0, 4.0)):
        status, Q, _ = solve_sdp(loop, ref, _square(4e-3, 20.0), feasible, 0.5, weights)
        assert status == "optimal"
        P = np.linalg.inv(Q)
        P = 0.5 * (P + P.T)
        assert loop.is_lyapunov(P, 0.9 * 0.5)
        sides[weights] = max_rectangle(P[np.ix_([0, 5], [0, 5])], 1.0)
    assert sides[(1.0, 4.0)][1] > sides[(4.0, 1.0)][1] * (1 + 1e-3)
    assert sides[(4.0, 1.0)][0] >= sides[(1.0, 4.0)][0] * (1 - 1e-6)


def test_the_enlargement_keeps_the_candidate_with_the_largest_score(model, loop, monkeypatch):
    """enlarge: ``best`` is the certified candidate with the largest score, whichever half-width it
    was found at (planted candidates, the best in the middle, an uncertified one larger still)."""
    scores = iter([(True, 1.0), (True, 3.0), (False, 9.0), (True, 2.0)])

    def fake(procedure, builder, reference, E, decay, weights, direction, clock):
        ok, score = next(scores)
        cert = type("Cert", (), {"success": ok, "level": 1.0, "message": "planted"})()
        return SdpCandidate.of(E, _square(E, 1.0), "optimal", rectangle=(score, 1.0), certified=cert)

    monkeypatch.setattr(sdp_module, "_candidate", fake)
    procedure = type("Proc", (), {"feasible": FeasibleSet(model), "loop": loop})()
    res = sdp_module.enlarge(procedure, Reference.setpoint(0.02), builder=object())
    assert res.success and res.best.score == 3.0
    assert res.best is res.candidates[1]


MM = 1e-3


# --- the SDP enlargement that certifies nothing ----------------------------------------------------
@pytest.mark.parametrize("fractions", [(3.0,), ()], ids=["no-polygon", "no-candidate"])
def test_an_enlargement_that_certifies_nothing_says_no_candidate_could_be_certified(model, fractions):
    """E = 3x the room to the stopper gives no provable polygon; no fractions at all give no
    candidate. Either way nothing is certified, and the message (printed by the report) says
    why in the words the other results use (lower case, no shouting)."""
    feasible, loop = FeasibleSet(model), RegulatorLoop()
    res = enlarge(
        Procedure2(feasible, loop), Reference.setpoint(0.02), fractions=fractions,
        builder=PolygonBuilder(feasible, loop),
    )  # fmt: skip
    check_result(res)
    assert not res.success and res.status == "not_certified" and res.best is None
    assert res.message == "no candidate P could be certified"
    assert "failure (not_certified): no candidate P could be certified" in res.report()


# --- the SDP's room to the position stoppers ------------------------------------------------------
@pytest.mark.parametrize(
    "position_phase",
    [0.0, math.pi / 2, 3 * math.pi / 4],
    ids=["sin-part", "cos-part", "both-parts"],
)
def test_the_sdps_ellipsoid_keeps_the_whole_horizontal_orbit_inside_the_position_range(
    model, loop, position_phase
):
    """r_h = -4 + 30 sin(w0 t + phase) mm (the papers' amplitude, r_v their 20 + 5 cos): at
    w0 the steady-state error is zero, so the position orbit is r_h itself, spanning -34 to 26 mm.
    With stoppers at -36 and 30 mm the room is 2 mm below and 4 mm above; the SDP's ellipsoid
    {z' Q^-1 z <= 1} reaches sqrt(Q_e2e2) in e2 and must fit: -4 mm - 30 mm - reach >= -36 mm and
    -4 + 30 + reach <= 30 mm, to 1e-6 relative of the room (Clarabel's feasibility tolerance,
    1e-8, on a constraint scaled to about 1, with margin). Without the stoppers the SDP reaches
    further in e2 (the range binds)."""
    ref = Reference(20 * MM, -4 * MM, 5 * MM, 30 * MM, math.pi / 2, position_phase, OMEGA0)
    limited = FeasibleSet(model, position_range=(-36 * MM, 30 * MM))
    free = FeasibleSet(model, position_range=None)
    poly = PolygonBuilder(limited, loop).build(ref, 2 * MM)
    assert poly.success, poly.message
    status, Q, _ = solve_sdp(loop, ref, poly, limited, 0.05, (1.0, 1.0))
    assert status == "optimal" and Q is not None, status
    reach = math.sqrt(Q[E2, E2])
    low = ref.position - ref.position_amplitude - reach
    high = ref.position + ref.position_amplitude + reach
    room = 2 * MM
    assert low >= -36 * MM - 1e-6 * room and high <= 30 * MM + 1e-6 * room
    _, Q_free, _ = solve_sdp(loop, ref, poly, free, 0.05, (1.0, 1.0))
    assert math.sqrt(Q_free[E2, E2]) > 1.1 * room


@pytest.fixture(scope="module")
def procedure(model):
    return Procedure2(FeasibleSet(model), RegulatorLoop())


@pytest.fixture(scope="module")
def builder(procedure):
    return PolygonBuilder(procedure.feasible, procedure.loop)


# --- the inner polygon of a periodic reference ----------------------------------------------------
def test_a_half_period_shift_of_the_reference_proves_the_same_polygon_for_the_same_work(builder):
    """Shifting both phases of the papers' sinusoid by pi gives the same orbit with the clock started
    half a period later. The proof covers one period, [0, 2 pi], in 24 phase cells, so the shift
    maps the cells onto each other. Both proofs bound the same boxes, prove the same vertices and
    spend the same number of interval evaluations (``cells``). A proof that looked at some phases
    twice would spend a different number for the two descriptions. The only difference between
    the two inputs is the rounding of sin/cos(phase + pi), about 1e-16 relative, so the vertices
    agree to 1e-12 relative and the counts agree to within a few splits (0.1 %: a box on a
    knife-edge may split on one machine's rounding and not on another's; a proof over [0, 3 pi]
    differed by 3.8 %). E = 0.5 mm is a width at which many boxes must be split (about 67 000
    cells), so a change in the phase cells shows up."""
    ref = Reference.paper_sinusoid()
    later = dataclasses.replace(
        ref, gap_phase=ref.gap_phase + math.pi, position_phase=ref.position_phase + math.pi
    )
    a, b = builder.build(ref, 0.5e-3), builder.build(later, 0.5e-3)
    for poly in (a, b):
        check_result(poly)
        assert poly.success and poly.status == "proved", poly.message
    assert_allclose(b.vertices, a.vertices, rtol=1e-12)
    assert b.cells == pytest.approx(a.cells, rel=1e-3)


# --- an SDP candidate whose P fails the Lyapunov re-check -------------------------------------------
def test_a_p_failing_the_lyapunov_recheck_is_reported_with_its_half_width(procedure, builder, monkeypatch):
    """The solver is replaced by one that reports "optimal" and returns Q = diag(d)^2, with d the
    loop's state scale. Its P is a scaled identity and not a Lyapunov matrix of the loop (checked
    here as a premise). The candidate for E = 0.75 x the room to the nearer stopper (10 mm at
    20 mm between the 8 and 30 mm stoppers, so E = 7.5 mm) says that the check failed. It is not
    certified, keeps E, has no P and no certificate, and Procedure 2 never runs on it (no
    certification time). The enlargement as a whole certifies nothing."""
    loop = procedure.loop
    q_bad = np.diag(loop.state_scale() ** 2)
    assert not loop.is_lyapunov(np.linalg.inv(q_bad), 0.05)
    monkeypatch.setattr(sdp, "solve_sdp", lambda *args, **kwargs: ("optimal", q_bad, 0.01))
    ref = Reference.setpoint(0.02)
    lo, hi = procedure.feasible.gap_range
    half_width = 0.75 * min(ref.gap - lo, hi - ref.gap)

    res = enlarge(procedure, ref, fractions=(0.75,), builder=builder)
    check_result(res)
    assert not res.success and res.status == "not_certified" and res.best is None
    assert res.timings["certify"] == 0.0  # Procedure 2 was not run on an unchecked P
    (cand,) = res.candidates
    check_result(cand)
    assert cand.polygon.success  # the failure is the re-check's, not the polygon's
    assert not cand.success and cand.status == "not_certified"
    assert cand.halfwidth == pytest.approx(half_width, rel=1e-12)  # the same E, up to rounding
    assert cand.solver_status == "optimal (Lyapunov check failed)"
    assert cand.message == f"E = {half_width * 1e3:.3g} mm: SDP optimal (Lyapunov check failed)"
    assert cand.P is None and cand.certified is None and cand.score == 0.0


# --- region.sdp ---------------------------------------------------------------------------------
def test_enlarge_at_the_stoppers_reports_the_time_it_took(model):
    """A reference whose gap orbit reaches the upper stopper (30 mm) is refused at once; its
    ``timings["total"]`` [s] is the time enlarge took: nonnegative and no more than the wall time
    measured around the call (the same clock, perf_counter, read outside enlarge's own readings)."""
    proc = Procedure2(FeasibleSet(model), RegulatorLoop())
    t0 = time.perf_counter()
    res = enlarge(proc, Reference(0.027, gap_amplitude=0.004))
    elapsed = time.perf_counter() - t0
    assert res.status == "infeasible" and not res.success
    assert 0.0 <= res.timings["total"] <= elapsed
