"""Properties of the Monte Carlo runs (``maglev_oc.region.montecarlo``), checked against the loop's
own steady state, slices recomputed from their starts and the simulation engine:

- the sampled loop started on the orbit stays on it, and a run into the left stopper records its
  distance like one into the right;
- a slice counts its coverage among the safe starts and judges its starts against its own current
  limit;
- a simulator whose C batch fails to build runs in CasADi with the same results.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import maglev_oc.region.montecarlo as montecarlo
from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.errors import SolverError
from maglev_oc.numerics import c_compiler
from maglev_oc.region.closed_loop import N_ERROR, Reference, RegulatorLoop
from maglev_oc.region.montecarlo import BatchSimulator, check_error_states, fl_slice, regulator_state
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.scenarios import paper_scenarios
from maglev_oc.sim.twin import RigTwin


@pytest.fixture(scope="module")
def sim(model):
    # the ideal twin under the FL regulator; the virtual machine (no C compiler needed)
    return BatchSimulator(RigTwin(model), FeedbackLinearizingRegulator(model), duration=0.3, compile=False)


@pytest.mark.parametrize("phase", [0.0, math.pi / 3, 4.0])
def test_the_sampled_loop_started_on_the_orbit_stays_on_it(loop, sim, phase):
    """z~ = 0 is the steady state of the sinusoid at every phase: started there (the physical state
    at that phase, the internal models at their steady state), the sampled twin follows the orbit,
    and at the end of the horizon (0.3 s, 1.4 rad further on the orbit) z~ is still about 0. The
    sampled loop is not the continuous one (5 kHz, the amplifier): V at the end was measured
    3e-5 to 5e-5; the bound 1e-3 (level 1e-3, final ratio < 1) is 20 x that, while a start or an
    end judged at the wrong phase is 1e4 x off."""
    ref = Reference.paper_sinusoid()
    chk = check_error_states(sim, loop, ref, loop.lyapunov_matrix(), 1e-3, np.zeros((10, 1)), phase=phase)
    assert chk.violations == 0
    assert chk.start_ratio[0] == 0.0
    assert chk.final_ratio[0] < 1.0


def test_a_run_into_the_left_stopper_records_its_distance(model, sim):
    """``max_abs_position`` is the largest |x3|: a start at -59 mm moving left at 0.5 m/s reaches the
    left stopper (-60 mm, hardware.STOPPER_POSITION) within 0.05 s and records 60 mm, as a run into
    the right one does."""
    x0 = np.array([[0.02, 0.02], [0.0, 0.0], [-0.059, 0.059], [-0.5, 0.5]])
    out = sim.with_duration(0.05).run(
        x0, regulator_state(x0, np.zeros((6, 2))), np.array([0.02, 0, 0, 0, 0, 0])
    )
    assert list(out.stopper_hit) == [True, True]
    np.testing.assert_allclose(out.max_abs_position, [0.060, 0.060], rtol=0, atol=1e-9)


def test_a_slice_counts_its_coverage_among_the_safe_starts(model, loop, sim):
    """``coverage`` = |certified and safe| / |safe| (SliceCheck docstring), recomputed from the
    slice's own starts: certified where V(start) <= level, safe where the run stayed in F. A slice
    from stopper to stopper on the gap (the outer starts hit a stopper) at a level that certifies
    part of it, so every count is neither empty nor full."""
    ref = Reference.setpoint(0.02)
    P = loop.lyapunov_matrix()
    sl = fl_slice(sim, loop, ref, P, 0.5, ("e1", "e2"), (-0.0125, 0.0125), (-0.03, 0.03), n=9)
    v = np.einsum("in,ij,jn->n", sl.starts, P, sl.starts).reshape(sl.safe.shape)
    certified = v <= 0.5
    np.testing.assert_array_equal(sl.certified, certified)
    safe = sl.safe
    assert 0 < safe.sum() < safe.size and 0 < certified.sum() < certified.size
    assert (certified & safe).sum() < certified.sum() or (certified & safe).sum() < safe.sum()
    assert sl.coverage == pytest.approx((certified & safe).sum() / safe.sum(), rel=1e-12)
    assert sl.unsafe_certified == int((certified & ~safe).sum())


# --- slices of error states --------------------------------------------------------------------------
REF = Reference.setpoint(0.02)


@pytest.fixture(scope="module")
def slice_runs(model):
    """The FL regulator on the nominal twin over 0.05 s (the current's transient peak comes within
    the first few ms for these small starts), the virtual machine (no C compiler needed)."""
    sim = BatchSimulator(RigTwin(model), FeedbackLinearizingRegulator(model), duration=0.05, compile=False)
    return sim, RegulatorLoop()


def test_a_slice_judges_its_starts_against_its_own_current_limit(slice_runs):
    """fl_slice's ``current_limit`` is the |u| limit of F its runs are judged against. Over a slice of
    gap errors of +-1 mm (the gap stays 19-21 mm, 9 mm or more from either stopper, and R > 0 all along) the
    runs' peak currents differ from start to start; with a limit halfway between the smallest and
    largest peak, safe is exactly peak <= limit (a mix of both), and without a limit all are safe.
    The peaks do not depend on the limit (the regulator does not see it): the same to round-off."""
    sim, loop = slice_runs
    P, level = np.eye(N_ERROR), 1.0  # any certificate: only the safe labels are checked here
    args = (sim, loop, REF, P, level, ("e1", "e1_rate"), (-1e-3, 1e-3), (-0.01, 0.01))
    free = fl_slice(*args, n=5, current_limit=None)
    assert free.safe.all()
    peaks = free.max_current
    assert peaks.max() - peaks.min() > 0.1  # [A] room for a limit between them
    limit = 0.5 * (peaks.min() + peaks.max())
    judged = fl_slice(*args, n=5, current_limit=limit)
    np.testing.assert_allclose(judged.max_current, peaks, rtol=1e-12)
    np.testing.assert_array_equal(judged.safe, peaks <= limit)
    assert judged.safe.any() and not judged.safe.all()


# --- the Monte Carlo simulator without its compiled batch -----------------------------------------
def test_a_simulator_whose_c_batch_fails_to_build_runs_in_casadi_with_the_same_results(model, monkeypatch):
    """NativeBatch raising SolverError (a compilation that failed), with a compiler on the PATH as
    far as the simulator can tell: ``compiled`` is False and the runs are those of the compiled
    batch (when this machine has a compiler; 1e-9 relative, 1e-12 absolute: the same graph in C and
    in the virtual machine, as in tests/test_region_montecarlo.py) and of the engine run sample by
    sample from the papers' large step (1e-12: identical arithmetic)."""
    ctrl, twin = FeedbackLinearizingRegulator(model), RigTwin(model)
    duration = 0.05
    sc = paper_scenarios()["large_step"]
    rng = np.random.default_rng(5)
    n = 5  # the large step first, then starts around 20 mm
    x0 = np.vstack([0.02 + rng.uniform(-0.004, 0.004, n), rng.uniform(-0.2, 0.2, n), np.zeros((2, n))])
    x0[:, 0] = sc.x0
    c0 = regulator_state(x0, np.zeros((6, n)))
    compiled = None
    if c_compiler() is not None:
        native = BatchSimulator(twin, ctrl, duration=duration, compile=True, threads=1)
        assert native.compiled is True
        compiled = native.run(x0, c0, sc.sample(twin.sample_time)[1][:, : native.n_steps])

    def fails(step, **kwargs):
        raise SolverError("compiling the closed loop failed: (planted)")

    monkeypatch.setattr(montecarlo, "NativeBatch", fails)
    monkeypatch.setattr(montecarlo, "c_compiler", lambda: "/usr/bin/cc")
    sim = BatchSimulator(twin, ctrl, duration=duration, compile=True, threads=1)
    assert sim.compiled is False
    ref = sc.sample(twin.sample_time)[1][:, : sim.n_steps]
    out = sim.run(x0, c0, ref)
    assert out.status == "completed"
    names = ("min_margin", "max_current", "min_gap", "max_gap", "max_abs_position", "final_twin")
    if compiled is not None:
        for name in names:
            np.testing.assert_allclose(
                getattr(out, name), getattr(compiled, name), rtol=1e-9, atol=1e-12, err_msg=name
            )
    # the engine records x[k] before step k: one sample longer to see x[n]
    k = sim.n_steps
    res = ClosedLoop(twin, ctrl).run(dataclasses.replace(sc, duration=(k + 1) * twin.sample_time))
    np.testing.assert_allclose(out.min_gap[0], res.x[0, 1 : k + 1].min(), rtol=1e-12)
    np.testing.assert_allclose(out.max_current[0], np.hypot(*res.u[:, :k]).max(), rtol=1e-12)
    np.testing.assert_allclose(out.final_twin[:4, 0], res.x[:, k], rtol=1e-9, atol=1e-15)
