"""The experiment design's feasibility check (``identification.design.FeasibleSet``) flags a
planted violation of each of its limits and nothing at the limits themselves: set-point ranges,
the simulated gap and position, the amplifiers' peak and continuous currents, a failed run.
Numpy only, well under a second (the run is a plain record of states and currents)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.identification.design import FeasibleSet, SampledReference

N = 200
FS = FeasibleSet()


def _reference(gap=0.02, position=0.0):
    t = np.arange(N) * 1e-3
    v = np.zeros((6, N))
    v[0] = 0.02
    v[3] = 0.0
    v[0, N // 2] = gap
    v[3, N // 2] = position
    return SampledReference(t, v)


def _run(gap=0.02, position=0.0, peak=None, rms=1.0, success=True):
    """States at rest at 20 mm except one sample; currents of magnitude ``rms`` everywhere but one
    sample at ``peak`` (default the same)."""
    x = np.zeros((4, N))
    x[0] = 0.02
    x[0, N // 3] = gap
    x[2, N // 3] = position
    mag = np.full(N, rms)
    mag[N // 4] = rms if peak is None else peak
    u = np.vstack([np.zeros(N), mag])  # all in i_d: |i| is exactly mag
    return SimpleNamespace(success=success, x=x, u=u, message="diverged")


def _flags(ref=None, run=None):
    return FS.violations(ref or _reference(), run or _run())


def test_a_feasible_reference_and_run_are_not_flagged_even_at_the_limits():
    assert _flags() == []
    at_limits = _reference(gap=FS.gap[1], position=FS.position[0])
    run = _run(gap=FS.true_gap[0], position=FS.true_position[1], peak=FS.peak_current)
    assert FS.violations(at_limits, run) == []
    assert _flags(run=_run(rms=FS.continuous_current)) == []


@pytest.mark.parametrize(
    "reference, run, needle",
    [
        (dict(gap=FeasibleSet().gap[1] + 1e-6), {}, "gap set-point"),
        (dict(gap=FeasibleSet().gap[0] - 1e-6), {}, "gap set-point"),
        (dict(position=FeasibleSet().position[1] + 1e-6), {}, "position set-point"),
        (dict(position=FeasibleSet().position[0] - 1e-6), {}, "position set-point"),
        ({}, dict(gap=FeasibleSet().true_gap[1] + 1e-6), "simulated gap"),
        ({}, dict(gap=FeasibleSet().true_gap[0] - 1e-6), "simulated gap"),
        ({}, dict(position=FeasibleSet().true_position[1] + 1e-6), "simulated position"),
        ({}, dict(position=FeasibleSet().true_position[0] - 1e-6), "simulated position"),
        ({}, dict(peak=FeasibleSet().peak_current + 1e-3), "peak current"),
        ({}, dict(rms=FeasibleSet().continuous_current + 1e-3), "RMS current"),
    ],
)
def test_each_limit_flags_a_planted_violation(reference, run, needle):
    """One sample 1 um (or 1 mA) beyond one limit: exactly that limit is named."""
    flags = _flags(_reference(**reference), _run(**run))
    assert len(flags) == 1 and flags[0].startswith(needle), flags


def test_a_failed_run_is_named_and_its_states_not_judged():
    flags = _flags(run=_run(gap=1.0, success=False))
    assert flags == ["run failed: diverged"]
    both = FS.violations(_reference(gap=0.05), _run(success=False))
    assert len(both) == 2 and both[0].startswith("gap set-point") and both[1].startswith("run failed")


@pytest.mark.parametrize(("compiler", "backend"), [(None, "vm"), ("/usr/bin/cc", "c")])
def test_the_design_twin_runs_on_a_backend_the_closed_loop_accepts(monkeypatch, compiler, backend):
    """Generated C where a compiler is found, else CasADi's virtual machine: either way a name
    ``ClosedLoop`` accepts (a machine without gcc must still design experiments)."""
    import maglev_oc.identification.design as design
    from maglev_oc.sim.engine import ClosedLoop

    monkeypatch.setattr(design, "c_compiler", lambda: compiler)
    assert design._twin_backend() == backend and backend in ClosedLoop.BACKENDS
