"""Monte Carlo on the sampled twin (maglev_oc.region.montecarlo): zero violations inside the
certified set, agreement with the engine, and the certificate's edge seen on the twin."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.numerics import c_compiler
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.montecarlo import (
    BatchSimulator,
    check_error_states,
    fl_slice,
    regulator_state,
    uniform_in_ellipsoid,
)
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.results import check_result
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.scenarios import paper_scenarios
from maglev_oc.sim.twin import RigTwin

REF = Reference.setpoint(0.02)


@pytest.fixture(scope="module")
def loop():
    return RegulatorLoop()


@pytest.fixture(scope="module")
def cert(model, loop):
    return Procedure2(FeasibleSet(model), loop).run(REF)


@pytest.fixture(scope="module")
def sim(model):
    # 0.4 s covers the transient peak of |u| (the worst starts peak within 0.15 s); the virtual
    # machine instead of the JIT keeps the test independent of a C compiler
    return BatchSimulator(RigTwin(model), FeedbackLinearizingRegulator(model), duration=0.4, compile=False)


def test_no_violation_inside_the_certified_set(sim, loop, cert):
    rng = np.random.default_rng(0)
    z = uniform_in_ellipsoid(cert.P, cert.level, 60, rng)
    assert np.all(np.einsum("in,ij,jn->n", z, cert.P, z) <= cert.level * (1 + 1e-12))
    chk = check_error_states(sim, loop, REF, cert.P, cert.level, z)
    assert chk.violations == 0
    assert np.all(chk.final_ratio < 0.5)  # every run is well inside again after 0.4 s
    check_result(chk)
    check_result(chk.outcome)
    assert chk.success and chk.status == "no_violations" and chk.outcome.status == "completed"


def test_the_certified_edge_is_real_on_the_twin(sim, loop, cert):
    """From the certified boundary point nearest to infeasibility the sampled loop comes within a few
    percent of the 9 A limit; 5 % further out along the same ray it exceeds it."""
    w = cert.witness
    scale = math.sqrt(cert.level / (w @ cert.P @ w))
    z = np.column_stack([w * scale * 0.999, w * 1.05])
    chk = check_error_states(sim, loop, REF, cert.P, cert.level, z)
    assert not chk.violating[0] and chk.outcome.max_current[0] > 8.8
    assert chk.violating[1] and chk.outcome.max_current[1] > 9.0
    assert not chk.success and chk.status == "violations" and "1 left F" in chk.message


def test_batch_matches_the_engine(model):
    """The reduced horizon Function reproduces ClosedLoop.run's extremes for the papers' large step."""
    ctrl = FeedbackLinearizingRegulator(model)
    twin = RigTwin(model)
    bsim = BatchSimulator(twin, ctrl, duration=0.3, compile=False, threads=1)
    n = bsim.n_steps
    # the engine records x[k] before step k; run it one sample longer to see x[n]
    sc = dataclasses.replace(paper_scenarios()["large_step"], duration=(n + 1) * twin.sample_time)
    res = ClosedLoop(twin, ctrl).run(sc)
    x0 = np.array(sc.x0)[:, None]
    _, ref = sc.sample(twin.sample_time)
    out = bsim.run(x0, regulator_state(x0, np.zeros((6, 1))), ref[:, :n])
    # identical arithmetic (the same CasADi step): agreement to rounding
    np.testing.assert_allclose(out.min_gap[0], res.x[0, 1 : n + 1].min(), rtol=1e-12)
    np.testing.assert_allclose(out.max_current[0], np.hypot(*res.u[:, :n]).max(), rtol=1e-12)
    np.testing.assert_allclose(out.min_margin[0], res.diagnostic("margin")[:n].min(), rtol=1e-12)
    np.testing.assert_allclose(out.final_twin[:4, 0], res.x[:, n], rtol=1e-9, atol=1e-15)


def test_slice_certified_starts_are_safe(sim, loop, cert):
    s = fl_slice(sim, loop, REF, cert.P, cert.level, ("e1", "e2"), (-0.008, 0.008), (-0.01, 0.01), n=5)
    # the grid asked for: n points per axis from end to end of each range
    np.testing.assert_allclose(s.x, np.linspace(-0.008, 0.008, 5), rtol=0, atol=0)
    np.testing.assert_allclose(s.y, np.linspace(-0.01, 0.01, 5), rtol=0, atol=0)
    assert s.certified.shape == (5, 5)
    assert s.unsafe_certified == 0
    assert s.certified.sum() > 0 and 0 < s.coverage <= 1
    check_result(s)
    assert s.success and s.status == "sound"
    # a slice reaching past the stoppers, judged against a set 1000 times too large: unsafe starts
    # are "certified", and the verdict says so
    far = fl_slice(sim, loop, REF, cert.P, cert.level, ("e1", "e2"), (-0.015, 0.015), (-0.01, 0.01), n=5)
    wide = far.with_certificate(cert.P, 1000 * cert.level)
    assert wide.unsafe_certified > 0 and not wide.success and wide.status == "unsound"


@pytest.mark.skipif(c_compiler() is None, reason="no C compiler")
def test_horizon_is_compiled_when_a_compiler_exists(model, sim):
    """The step runs as generated C in a C loop (it once fell back silently), and gives the virtual
    machine's outcome run for run, on threads and over another horizon from the same build."""
    short = BatchSimulator(sim.twin, sim.controller, duration=0.002, compile=True, threads=2)
    assert short.compiled
    rng = np.random.default_rng(3)
    n = 7  # odd: the threads' shares differ in size
    x0 = np.vstack([0.02 + rng.uniform(-0.004, 0.004, n), rng.uniform(-0.2, 0.2, n), np.zeros((2, n))])
    c0 = regulator_state(x0, np.zeros((6, n)))
    ref = np.array([0.02, 0, 0, 0.01, 0, 0])
    native = short.with_duration(0.4)
    a, b = native.run(x0, c0, ref), sim.run(x0, c0, ref)
    for name in ("min_margin", "max_current", "min_gap", "max_gap", "max_abs_position", "final_twin"):
        # the same expression graph, evaluated in C and in the virtual machine: equal to rounding
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=1e-9, atol=1e-12, err_msg=name)
    assert short.n_steps == 10 and native.n_steps == sim.n_steps


def test_validation(sim):
    with pytest.raises(ValueError, match="x0"):
        sim.run(np.zeros(4), np.zeros((10, 1)), np.zeros(6))
    with pytest.raises(ValueError, match="duration"):
        BatchSimulator(sim.twin, sim.controller, duration=0)
