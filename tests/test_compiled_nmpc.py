"""The causal NMPC as an expression controller (sim.compiled_nmpc): the same controller as the
Python-stepped NonlinearMPC, run inside the engine's loop. Same operations in the same order on
the same inputs (the generated C of the RTI step matches the Python Function to 1e-9 on each call,
tests/test_nmpc.py), so the closed-loop runs agree to round-off; 1e-9 absolute (m, A) bounds that
accumulated round-off over the run with a wide margin."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.control.nmpc import NonlinearMPC
from maglev_oc.errors import InputError
from maglev_oc.numerics import c_compiler
from maglev_oc.sim.compiled_nmpc import CompiledNMPC
from maglev_oc.sim.effects import TwinEffects
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.scenarios import paper_scenarios
from maglev_oc.sim.twin import RigTwin

# -O0: the arithmetic is the same at any level without fast-math, and the 1.3 MB source compiles in
# a third of -O1's 9-13 s
CFLAGS = ("-O0",)


def _runs(model, backend, duration, cache=None):
    twin = RigTwin(model, TwinEffects.rig())  # encoder, delay, amplifier: every input path used
    scenario = dataclasses.replace(paper_scenarios()["large_step"], duration=duration)
    online = ClosedLoop(twin, NonlinearMPC(model, preview=False)).run(scenario)
    causal = CompiledNMPC(NonlinearMPC(model, preview=False), backend=backend, cache=cache, cflags=CFLAGS)
    assert not causal.cached
    return online, ClosedLoop(twin, causal, backend=backend).run(scenario)


def _assert_same(online, fused):
    assert online.success and fused.success
    assert_allclose(fused.x, online.x, rtol=0, atol=1e-9)
    assert_allclose(fused.u, online.u, rtol=0, atol=1e-9)
    # the QP is solved on the first samples of the step (the current polytope is active)
    ok = fused.diagnostic("solver_ok")
    assert np.all(ok == 1) and np.any(online.diagnostic("qp_iterations") > 0)


def test_the_virtual_machine_loop_is_the_python_stepped_nmpc(model):
    _assert_same(*_runs(model, "vm", 0.02))


@pytest.mark.slow
@pytest.mark.skipif(c_compiler() is None, reason="no C compiler")
def test_the_generated_c_loop_is_the_python_stepped_nmpc(model, tmp_path):
    online, fused = _runs(model, "c", 0.3, cache=tmp_path)
    _assert_same(online, fused)
    # a second NMPC with the same settings finds its library in the cache and runs the same
    again = CompiledNMPC(NonlinearMPC(model, preview=False), cache=tmp_path, cflags=CFLAGS)
    assert again.cached and again.library.parent == tmp_path
    twin = RigTwin(model, TwinEffects.rig())
    scenario = dataclasses.replace(paper_scenarios()["large_step"], duration=0.3)
    assert_allclose(ClosedLoop(twin, again, backend="c").run(scenario).u, fused.u, rtol=0, atol=0)


def test_only_a_causal_rti_nmpc_is_an_expression(model):
    with pytest.raises(InputError, match="preview"):
        CompiledNMPC(NonlinearMPC(model), backend="vm")
    with pytest.raises(TypeError, match="NonlinearMPC"):
        CompiledNMPC(object())
