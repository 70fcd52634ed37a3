"""The SDP enlargement with a proved inner polytope (maglev_oc.region.sdp)."""

from __future__ import annotations

import numpy as np
import pytest

from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.region.sdp import PolygonBuilder, enlarge
from maglev_oc.results import PerAxis, check_result


@pytest.fixture(scope="module")
def proc(model):
    return Procedure2(FeasibleSet(model), RegulatorLoop())


@pytest.fixture(scope="module")
def builder(proc):
    return PolygonBuilder(proc.feasible, proc.loop)


def test_polygon_vertices_are_feasible_on_the_whole_gap_range(proc, builder):
    """Independent pointwise check of the interval proof on a dense gap grid."""
    ref = Reference.setpoint(0.02)
    poly = builder.build(ref, 5e-3)
    assert poly.success
    check_result(poly)
    assert poly.status == "proved"
    gaps = np.linspace(0.015, 0.025, 801)
    for v in poly.vertices.T:
        h = proc.feasible.evaluate(gaps, v[0], v[1])
        assert np.all(h >= 0)
    # the origin (the set-point's own acceleration) is strictly inside every face
    assert np.all(poly.offsets > 0)


def test_sdp_enlarges_the_certified_rectangle(proc, builder):
    """At 20 mm the SDP's certified rectangle is several times the Lyapunov equation's
    (reference run: x8.2 in area; asserted >= 4 to leave room for solver differences)."""
    ref = Reference.setpoint(0.02)
    base = proc.run(ref)
    res = enlarge(proc, ref, fractions=(0.75,), builder=builder)
    assert res.success
    best = res.best
    check_result(res)
    check_result(best)
    assert res.status == best.status == "certified" and isinstance(best.rectangle, PerAxis)
    assert proc.loop.is_lyapunov(best.P, 0.05)
    assert best.construction_level >= 1 - 1e-6  # the polytope holds the SDP's level set
    assert best.certified.level >= best.construction_level * (1 - 1e-6)  # exact F allows at least as much
    a0, b0 = base.initial_conditions.rectangle
    a1, b1 = best.rectangle
    assert a1 * b1 >= 4 * a0 * b0


def test_sdp_aimed_at_the_papers_large_step_certifies_it(proc, builder):
    """The large step (26, 0, 0, 0) -> (18 mm, 20 mm) is inside a certified set of the FL regulator
    (reference run: 1.15 times its initial error)."""
    ref = Reference.setpoint(0.018, 0.020)
    z0 = proc.loop.error_state([0.026, 0, 0, 0], np.zeros(6), ref)[:, 0]
    res = enlarge(proc, ref, fractions=(0.75,), builder=builder, direction=z0)
    assert res.success
    assert res.best.reach >= 1.0
    assert z0 @ res.best.P @ z0 <= res.best.certified.level


def test_validation(proc):
    with pytest.raises(ValueError, match="decay"):
        enlarge(proc, Reference.setpoint(0.02), decay=-1)


def test_a_reference_at_the_stoppers_is_infeasible(proc):
    """A sinusoid whose gap orbit reaches the upper stopper (30 mm) leaves no room: the result says so."""
    ref = Reference(0.027, gap_amplitude=0.004)
    res = enlarge(proc, ref)
    check_result(res)
    assert not res.success and res.status == "infeasible" and res.certified is None


def test_a_solver_stopped_before_optimality_gives_no_matrix(proc, builder, monkeypatch):
    """Clarabel stopped after 3 iterations leaves cvxpy values in the variables (status
    "user_limit"), but they are not a solution: solve_sdp returns no Q and says why, and enlarge
    certifies nothing from it (a Q read from an unfinished solve would be a certificate built on
    an arbitrary matrix)."""
    import cvxpy as cp

    from maglev_oc.region.sdp import solve_sdp

    solve = cp.Problem.solve
    monkeypatch.setattr(cp.Problem, "solve", lambda self, **kw: solve(self, **kw, max_iter=3))
    ref = Reference.setpoint(0.02)
    poly = builder.build(ref, 5e-3)
    status, Q, _ = solve_sdp(proc.loop, ref, poly, proc.feasible, 0.05, (1.0, 1.0))
    assert status not in ("optimal", "optimal_inaccurate") and Q is None, status
    res = enlarge(proc, ref, fractions=(0.75,), builder=builder)
    check_result(res)
    assert not res.success and res.certified is None


def test_an_inaccurate_optimum_keeps_its_matrix_and_says_so(proc, builder, monkeypatch):
    """Clarabel's "optimal_inaccurate" (it reached its looser tolerances) is a solution whose
    accuracy the certificate re-checks downstream: solve_sdp returns its Q with that status, not
    nothing. The same solve marked so after the fact gives the optimal solve's Q exactly."""
    import cvxpy as cp

    from maglev_oc.region.sdp import solve_sdp

    ref = Reference.setpoint(0.02)
    poly = builder.build(ref, 5e-3)
    status, Q, _ = solve_sdp(proc.loop, ref, poly, proc.feasible, 0.05, (1.0, 1.0))
    assert status == "optimal" and Q is not None
    solve = cp.Problem.solve

    def inaccurate(self, **kw):
        out = solve(self, **kw)
        self._status = "optimal_inaccurate"
        return out

    monkeypatch.setattr(cp.Problem, "solve", inaccurate)
    status2, Q2, _ = solve_sdp(proc.loop, ref, poly, proc.feasible, 0.05, (1.0, 1.0))
    assert status2 == "optimal_inaccurate"
    np.testing.assert_array_equal(Q2, Q)
