"""Region properties from the survivors of the seed-42 mutation run. Each test checks something a
user sees, not one line of code:

* the SDP's inner polygon for a periodic reference is proved over exactly one period: the same
  orbit started half a period later gives the same polygon for the same number of interval
  evaluations;
* an SDP candidate whose P fails the floating-point Lyapunov re-check says so. It is not
  certified, keeps its half-width E in its fields and its message, and is not sent to
  Procedure 2;
* the microstepper's branch and bound searches the whole box around the level set. A level that
  holds a state where R < 0 is never certified, also when that state lies on the side of
  positive gap error and velocities;
* a study with the large step names the large step's steps in its timings, in the order they ran.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.region import sdp
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.microstepper import MicrostepperRegion
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.region.sdp import PolygonBuilder, enlarge
from maglev_oc.region.study import operating_region_study
from maglev_oc.results import check_result
from tests.test_microstepper_region import PLATFORM, _violations
from tests.test_region_seed41_properties import CONFIG, STEPS


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


# --- the microstepper's branch and bound covers the whole box -----------------------------------------
def test_no_level_above_a_failing_point_on_the_positive_side_is_certified():
    """R >= 0 alone (no current limit, no stoppers) off-centre at (40, -40, 22) mm: IPOPT's least
    violation of R >= 0 (the "margin" case of tests/test_microstepper_region.py) lies where the gap
    error and the velocities are positive, in the upper corner of the box the search covers. The
    state is checked with the controller's own Function, not the interval code. It lies inside
    {V <= 1.01 V_there}, so that level must never come out certified. With 100 000 boxes the
    search goes deep enough to find it (refuted after about 110 000 boxes, measured). Running out
    of budget ("undecided") would also be sound; only "certified" is wrong."""
    region = MicrostepperRegion(PLATFORM, current_limit=None, stoppers=False)
    setpoint = (0.04, -0.04, 0.022)
    found, binding, ell = region.refute(setpoint)
    assert binding == "margin"
    z = region.state_of(ell)
    assert z @ region.P @ z == pytest.approx(found, rel=1e-9)  # rounding of the quadratic form
    assert _violations(region, setpoint, 1.0001 * z[:, None])["margin"] == 1
    status, _, _, _ = region.certify(setpoint, 1.01 * found, max_boxes=100_000)
    assert status != "certified"


# --- the study's timings with the large step ---------------------------------------------------------
def test_a_study_with_the_large_step_names_its_steps_in_its_timings(model):
    """The seed-41 file's small study (tests/test_region_seed41_properties.py) with the large step
    turned on, for one start and one target and 0.05 s runs (about 2 s). Its timings name the
    steps in the order they ran, as the report's timing table prints them: the steps of the study
    without the large step, then the large step's FL certificates, the linear regulators' certified
    regions and the start x target map, then the total. Each step takes a time of zero or more and
    no more than the total."""
    config = dataclasses.replace(
        CONFIG, linear=True, map_starts_mm=(26.0,), map_targets_mm=(18.0,), linear_horizon=0.05
    )
    study = operating_region_study(model, config)
    check_result(study)
    large = [
        "large step: FL certificates",
        "large step: certified regions of attraction",
        "large step: sampled start x target map",
    ]
    assert list(study.timings) == [*STEPS[:-1], *large, "total"]
    assert all(0 <= v <= study.timings["total"] for v in study.timings.values())
    # the steps the names stand for ran: three linear regulators, one start x target map each
    assert len(study.large_step.linear) == 3
    assert all(m["outcome"].shape == (1, 1) for m in study.large_step.maps.values())
    # four different controllers, as the papers compare them: the FL regulator, the linear regulator
    # with and without its feedforward, and the LQR (a map per controller, each under its own name)
    assert len(study.large_step.maps) == 4 and "FL regulator" in study.large_step.maps
    assert sum("no feedforward" in name for name in study.large_step.maps) == 1


def test_each_critical_radius_is_labelled_with_the_reference_it_probes(model):
    """The seed-41 file's small study with a robust part of 4 runs per probe (about 1 s): each
    bisection for the radius where runs first leave F carries the name of the certificate it grows
    (the report's bracket table finds its row by that name), there is one per certificate, and
    the bracket is ordered (safe below broken)."""
    config = dataclasses.replace(CONFIG, robust_runs=4, robust_probe_runs=4, certify_boxes=0)
    study = operating_region_study(model, config)
    check_result(study)
    rb = study.robust
    assert rb is not None and rb.certificates
    assert sorted(c.reference for c in rb.radii) == sorted(rb.certificates)
    assert all(0 <= c.safe_radius < c.broken_radius for c in rb.radii)


def test_a_certified_robust_row_certifies_the_p_its_sdp_chose(model):
    """The seed-41 file's small study with a certified robust part (2000 boxes per level, no
    Monte Carlo; about 1.2 s): a set-point whose robust SDP found a P (its message says so) has
    its nominal certificate made for that P, not for the Lyapunov equation's P of the nominal
    loop, which the SDP replaced because the confidence set's plants mismatch it."""
    config = dataclasses.replace(
        CONFIG, robust_runs=4, robust_probe_runs=0, certify_boxes=2000, certify_runs=0
    )
    study = operating_region_study(model, config)
    check_result(study)
    rows = study.robust.certified.rows
    assert rows
    for row in rows:
        assert row.nominal is not None and "P from the robust SDP" in row.sdp_message, row.sdp_message
        assert not np.allclose(row.nominal.P, RegulatorLoop().lyapunov_matrix(), rtol=1e-6)
