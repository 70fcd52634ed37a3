"""The adapted, certified Procedure 2 (maglev_oc.region.procedure2)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.ellipsoid import ellipsoid_image, max_rectangle
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.procedure2 import Procedure2, _UpperBounds
from maglev_oc.results import PerAxis, check_result


@pytest.fixture(scope="module")
def proc(model):
    return Procedure2(FeasibleSet(model), RegulatorLoop())


@pytest.fixture(scope="module")
def at20(proc):
    return proc.run(Reference.setpoint(0.02))


def test_certified_below_the_upper_bound_and_tight(at20):
    assert at20.success
    assert at20.level <= at20.level_upper
    # the ladder's first rung is 0.995 of the upper bound: the certificate is within 0.5 % here
    assert at20.tightness >= 0.99
    assert at20.binding == "headroom"  # the 9 A limit binds at 20 mm, not the stoppers


def test_papers_gains_certified_sizes_at_20mm(at20):
    """Sizes at 20 mm with the Lyapunov equation's P (this implementation's reference values;
    rtol 1 %: c is certified within 0.5 % of the IPOPT bound and the sizes go as sqrt(c))."""
    s = at20.initial_conditions.semi_axes
    np.testing.assert_allclose(
        [s["e1"], s["e1_rate"], s["e2"], s["e2_rate"]], [6.06e-3, 0.372, 8.02e-3, 0.414], rtol=0.01
    )


def test_witness_is_on_the_boundary_and_least_V(proc, at20):
    """IPOPT's point: V = upper bound, the constraint is zero, and it is the least-V preimage of its
    (e1, v1, v2) (the 10-D minimum equals the 3-D reduction)."""
    z = at20.witness
    np.testing.assert_allclose(z @ at20.P @ z, at20.level_upper, rtol=1e-9)
    fn = proc.feasible.loop_function(proc.loop, at20.reference)
    h = np.asarray(fn(z, at20.witness_phase)).ravel()
    assert abs(h[1]) < 1e-6  # [A^2], IPOPT tol 1e-10 on a scaled problem
    img = ellipsoid_image(proc.loop, at20.P)
    M = proc.loop.output[[0, 2, 3]]
    np.testing.assert_allclose(img.Pinv_Mt @ np.linalg.solve(img.S, M @ z), z, rtol=1e-6, atol=1e-12)
    # just inside the certified set the constraints hold, just outside the witness they fail
    inside = z * math.sqrt(at20.level / at20.level_upper) * 0.999
    assert np.all(np.asarray(fn(inside, at20.witness_phase)) >= 0)
    assert np.asarray(fn(z * 1.001, at20.witness_phase)).ravel()[1] < 0


def test_dense_sampling_finds_no_infeasible_point_inside(proc, at20):
    """Independent check of the branch and bound: 20000 points of the certified ellipsoid, most near
    its boundary, are all feasible."""
    rng = np.random.default_rng(1)
    g = rng.standard_normal((10, 20000))
    g /= np.linalg.norm(g, axis=0)
    g *= rng.uniform(0.9, 1.0, 20000) ** 0.1
    L = np.linalg.cholesky(at20.P)
    z = math.sqrt(at20.level) * np.linalg.solve(L.T, g)
    fn = proc.feasible.loop_function(proc.loop, at20.reference)
    h = np.asarray(fn.map(z.shape[1])(z, np.zeros((1, z.shape[1]))))
    assert np.all(h >= 0)


def test_stoppers_give_the_exact_level(proc):
    """At 25 mm the upper stopper (30 mm) binds: level = (5 mm)^2 / (m' P^-1 m) exactly."""
    res = proc.run(Reference.setpoint(0.025))
    Pinv = np.linalg.inv(res.P)
    np.testing.assert_allclose(res.level, 0.005**2 / Pinv[0, 0], rtol=1e-12)
    assert res.binding == "gap_high"
    np.testing.assert_allclose(res.witness[0], 0.005, rtol=1e-9)


def test_sinusoid_covers_every_phase(proc):
    """The ellipse reference: r_v reaches 25 mm, so the upper stopper binds at (5 mm)^2/spread^2."""
    res = proc.run(Reference.paper_sinusoid())
    assert res.success and res.binding == "gap_high"
    np.testing.assert_allclose(res.level, 0.005**2 / np.linalg.inv(res.P)[0, 0], rtol=1e-9)


def test_refutes_a_level_that_is_too_large(proc, at20):
    out = proc.certifier.certify(at20.reference, at20.P, 1.5 * at20.level_upper)
    assert out.status == "refuted"
    assert out.witness_level <= 1.5 * at20.level_upper
    assert out.binding == "headroom"
    check_result(out)
    assert not out.success


def test_results_follow_the_convention(at20):
    """Procedure2Result and its parts: success, status word, message, timings [s], to_dict, report."""
    check_result(at20)
    assert at20.status == "certified" and set(at20.timings) == {"nlp", "certify", "total"}
    for part in (*at20.attempts, *at20.minima):
        check_result(part)
    assert at20.attempts[-1].status == "certified" and all(m.status == "found" for m in at20.minima)
    rect = at20.initial_conditions.rectangle
    assert isinstance(rect, PerAxis) and at20.to_dict()["initial_conditions"]["rectangle"] == rect.to_dict()


def test_with_no_infeasible_point_known_no_witness_is_invented(proc, at20):
    """When neither the stoppers (switched off: infinite levels) nor IPOPT nor the branch and
    bound found a point that breaks a constraint, the result says nothing was certified or
    refuted: no witness state, an infinite upper bound. (A witness is a state at which the
    binding constraint fails; only a stopper's is computed in closed form.)"""
    travel = dict.fromkeys(("gap_low", "gap_high", "position_low", "position_high"), math.inf)
    nothing = {"margin": math.inf, "headroom": math.inf}
    bounds = _UpperBounds(nothing, dict.fromkeys(nothing, (None, 0.0)), 1.0)
    res = proc._result(at20.reference, at20.P, travel, bounds, 0.0, (), ())
    assert not res.success and res.status == "not_certified"
    assert res.witness is None and res.level_upper == math.inf
    assert res.binding in nothing  # the first named of the undecided constraints, not a stopper


def test_rejects_a_non_lyapunov_matrix(proc):
    with pytest.raises(ValueError, match="Lyapunov"):
        proc.run(Reference.setpoint(0.02), np.eye(10))


def test_max_rectangle_closed_form():
    """For a diagonal P2 the largest-area box has half-sides sqrt(c / (2 p_ii))."""
    a, b = max_rectangle(np.diag([4.0, 1.0]), 2.0)
    np.testing.assert_allclose([a, b], [0.5, 1.0], rtol=1e-12)


@pytest.mark.parametrize("gap", [0.030, 0.0305, 0.0075])
def test_a_reference_on_or_beyond_a_stopper_is_answered_not_raised(proc, gap):
    """A set-point on a stopper (30 mm, 8 mm is the other) or beyond it has no level set around it
    inside F: the result says so (status ``infeasible_reference``, level 0, the stopper named)
    instead of the branch and bound refusing a level of 0 from deep inside; 0.1 mm inside, a
    positive level is certified (the stopper's exact level, which is (room / spread)^2 > 0)."""
    res = proc.run(Reference.setpoint(gap))
    check_result(res)
    assert (res.success, res.status, res.level) == (False, "infeasible_reference", 0.0)
    assert res.binding == ("gap_high" if gap > 0.02 else "gap_low") and res.binding in res.message
    inside = proc.run(Reference.setpoint(0.0299 if gap > 0.02 else 0.0081))
    assert inside.success and inside.level > 0
