"""Options of ``maglev_oc.control`` passed by name, each test failing when its option is ignored
(the default used instead) or inverted:

- ``observer_epsilon``: ``RegulatorCore`` discretizes the papers' high-gain observer exactly (a
  double pole at -1/eps, checked against a matrix exponential), and every controller that takes
  the option (FL, scheduled linear, PID, microstepper, NMPC) updates its velocity estimates with
  that observer;
- ``NMPCSettings(position_bounds)``: the plan's positions stay inside them, and in the QP they
  bound x3, as ``gap_bounds`` bound x1, at nodes 2..N exactly;
- ``compile_shared(output)`` writes the library there, and ``build_harness(output,
  harness_source, library)`` compiles that harness into that executable linked to that library
  (a one-line C source stands in for the generated NMPC).
"""

from __future__ import annotations

import ctypes
import dataclasses
import math
import subprocess
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.linalg import expm

from maglev_oc.control.codegen import GeneratedCode, build_harness, compile_shared
from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.control.linear_regulator import paper_linear_regulator
from maglev_oc.control.microstepper import MicrostepperRegulator
from maglev_oc.control.nmpc import NMPCSettings, NonlinearMPC
from maglev_oc.control.nmpc.layout import x_index
from maglev_oc.control.nmpc.transcription import Transcription
from maglev_oc.control.output_regulator import RegulatorCore
from maglev_oc.control.pid import paper_pid
from maglev_oc.errors import SolverError
from maglev_oc.estimation.high_gain import DEFAULT_EPSILON, HighGainObserver
from maglev_oc.model.equilibrium import equilibrium_currents
from maglev_oc.model.platform import microstepper
from maglev_oc.numerics import c_compiler

GAP = 0.020  # [m] a scheduled gap (8 mm + 24 x 0.5 mm)


EPS = 1e-3  # [s] an observer time constant half the default: poles at -1000 instead of -500 rad/s


# --- control: the observers' epsilon -------------------------------------------------------------
def test_regulator_core_observer_has_its_double_pole_at_minus_one_over_epsilon():
    """RegulatorCore(observer_epsilon) uses the papers' observer with alpha = (2, 1) and that eps:
    its next_state is the exact ZOH discretization of A = [[-2/eps, 1], [-1/eps^2, 0]],
    B = [[2/eps, 0], [1/eps^2, 1]] on (y, a) (a 4 x 4 expm here; 1e-9 relative), whose
    eigenvalue exp(-Ts/eps) is double (the characteristic polynomial (z - exp(-Ts/eps))^2:
    trace and determinant, 1e-12)."""
    ts = 2e-4
    core = RegulatorCore(ts, observer_epsilon=EPS)
    m = np.zeros((4, 4))
    m[:2, :2] = [[-2 / EPS, 1.0], [-1 / EPS**2, 0.0]]
    m[:2, 2:] = [[2 / EPS, 0.0], [1 / EPS**2, 1.0]]
    e = expm(m * ts)
    ad, bd = e[:2, :2], e[:2, 2:]
    lam = math.exp(-ts / EPS)
    assert_allclose([np.trace(ad), np.linalg.det(ad)], [2 * lam, lam**2], rtol=1e-12)
    c, y, r = ca.SX.sym("c", 10), ca.SX.sym("y", 2), ca.SX.sym("r", 6)
    av, ah = ca.SX.sym("av"), ca.SX.sym("ah")
    f = ca.Function("f", [c, y, r, av, ah], [core.next_state(c, y, r, av, ah)])
    rng = np.random.default_rng(3)
    cv = np.r_[GAP, 0.01, 0.002, -0.02, rng.normal(size=6) * 1e-5]
    yv, rv = np.array([GAP + 2e-5, 0.002 - 3e-5]), np.r_[GAP, 0, 0, 0.001, 0, 0]
    out = np.asarray(f(cv, yv, rv, 0.7, -1.3)).ravel()
    assert_allclose(out[0:2], ad @ cv[0:2] + bd @ [yv[0], 0.7], rtol=1e-9)
    assert_allclose(out[2:4], ad @ cv[2:4] + bd @ [yv[1], -1.3], rtol=1e-9)


def _observer_check(ctrl, c, y, acc, n_axes):
    """c_next's observer rows against HighGainObserver(Ts, EPS) fed ``acc`` per axis."""
    u, c_next, diag = (np.asarray(v, dtype=float).ravel() for v in ctrl.step(c, y, _reference_of(ctrl)))
    obs = HighGainObserver(ctrl.sample_time, EPS)
    a = acc(u, diag)
    for j in range(n_axes):
        expected = obs.step(c[2 * j : 2 * j + 2], y[j], a[j])
        # the same ZOH matrices and arithmetic up to order: rounding only (1e-9 relative)
        assert_allclose(c_next[2 * j : 2 * j + 2], expected, rtol=1e-9, atol=1e-12)


def _reference_of(ctrl) -> np.ndarray:
    """At rest at the 20 mm gap, every other axis at 0 (the microstepper's rows are x, y, gap)."""
    if isinstance(ctrl, MicrostepperRegulator):
        r = np.zeros(9)
        r[6] = GAP
        return r
    r = np.zeros(6)
    r[0] = GAP
    return r


@pytest.mark.parametrize("kind", ["fl", "linear", "pid", "microstepper"])
def test_each_regulator_updates_its_velocities_with_the_epsilon_given(model, kind):
    """A regulator built with observer_epsilon = 1 ms updates its (position, velocity) estimates
    with that observer, fed the acceleration it expects: v (FL), a21 e1 + b22 du2 and b41 du1 on
    the reference gap's linearization (linear), none (PID), the realised v_ach (microstepper).
    The readings are two encoder counts off the estimates, so the velocity update depends on eps
    (1/eps^2 Ts: 200 1/s at 1 ms, 50 1/s at the default 2 ms)."""
    assert DEFAULT_EPSILON != EPS
    if kind == "microstepper":
        ctrl = MicrostepperRegulator(microstepper(), observer_epsilon=EPS)
        y = np.array([1e-3 + 2e-5, -2e-3 - 2e-5, GAP + 2e-5])
        c = ctrl.initial_state(y - np.array([2e-5, -2e-5, 2e-5]))
        c[1], c[3], c[5] = 0.01, -0.02, 0.005
        _observer_check(ctrl, c, y, lambda u, d: d[7:10], 3)
        return
    if kind == "fl":
        ctrl = FeedbackLinearizingRegulator(model, observer_epsilon=EPS)
        acc = lambda u, d: (d[3], d[2])  # noqa: E731  (v2 vertical, v1 horizontal)
    elif kind == "linear":
        ctrl = dataclasses.replace(paper_linear_regulator(model), observer_epsilon=EPS)
        k = int(np.argmin(np.abs(ctrl.schedule.gap - GAP)))
        assert ctrl.schedule.gap[k] == pytest.approx(GAP, abs=1e-12)  # the table's own row
        s = ctrl.schedule
        # e1 = y1 - r_v = 2e-5 m below
        acc = lambda u, d: (s.stiffness_v[k] * 2e-5 + s.gain_v[k] * d[2], s.gain_h[k] * d[1])  # noqa: E731
    else:
        ctrl = dataclasses.replace(paper_pid(model), observer_epsilon=EPS)
        acc = lambda u, d: (0.0, 0.0)  # noqa: E731
    y = np.array([GAP + 2e-5, 1e-3])
    c = ctrl.initial_state(np.array([GAP, 1e-3 + 2e-5]), None)
    c[1], c[3] = 0.01, -0.02
    _observer_check(ctrl, c, y, acc, 2)


def test_the_nmpc_updates_its_velocities_with_the_epsilon_given(model):
    """NMPCSettings(observer_epsilon): from the observer at rest two counts off the readings (no
    disturbance estimate yet), the next (p, q) per axis are HighGainObserver(Ts, eps)'s, fed the
    model's acceleration at the measured positions, the observer's velocities and the current
    the step applies (1e-9 relative; the QP only chooses u)."""
    ctrl = NonlinearMPC(model, horizon=5, observer_epsilon=EPS)
    y0 = np.array([GAP, 0.0])
    y = y0 + np.array([2e-5, -2e-5])  # two encoder counts
    memory = ctrl.initial_memory(y0, None, [0.0, float(equilibrium_currents(model, [GAP]).current[0])])
    ref = np.zeros((6, ctrl.grid.horizon + 1))
    ref[0] = GAP
    step = ctrl.step_rti(memory, y, ref)
    x_hat = np.array([y[0], 0.0, y[1], 0.0])
    acc = np.asarray(model.dynamics(x_hat, step.u)).ravel()
    obs = HighGainObserver(ctrl.sample_time, EPS)
    nxt = np.asarray(step.memory_next)[:4]
    assert_allclose(nxt[0:2], obs.step(np.array([y0[0], 0.0]), y[0], acc[1]), rtol=1e-9, atol=1e-12)
    assert_allclose(nxt[2:4], obs.step(np.array([y0[1], 0.0]), y[1], acc[3]), rtol=1e-9, atol=1e-12)


def test_the_nmpc_plan_stays_inside_its_position_bounds(model):
    """NMPCSettings(position_bounds): with the reference 10 mm off to either side and bounds of
    +-2 mm, every planned x3 (nodes 1..N of the shifted plan, all bounded in the QP) is inside
    them (1e-9 m: the QP's feasibility tolerance on a bound scaled to mm); with the default
    bounds the plan goes past 2 mm, so the bound is what holds it."""
    i_eq = float(equilibrium_currents(model, [GAP]).current[0])
    bound = 2e-3
    for sign in (1.0, -1.0):
        ref = np.zeros((6, 400))
        ref[0], ref[3] = GAP, sign * 10e-3
        planned = {}
        for label, options in (("bounded", {"position_bounds": (-bound, bound)}), ("free", {})):
            ctrl = NonlinearMPC(model, horizon=5, **options)
            ctrl.reset(np.array([GAP, 0.0]), ref[:, 0], np.array([0.0, i_eq]))
            for k in range(20):
                y = np.array([GAP, ctrl.plan()[0][2, 0] if k else 0.0])
                ctrl.control(k, y, ref)
            planned[label] = ctrl.plan()[0][2]
        assert np.all(np.abs(planned["bounded"]) <= bound + 1e-9)
        assert np.max(sign * planned["free"]) > bound


def test_the_nmpc_bounds_x1_and_x3_at_nodes_two_to_n(model):
    """The QP's simple bounds (NMPCSettings docstring): gap_bounds on x1 and position_bounds on
    x3 at nodes 2..N, exactly the numbers given; node 1 (one sample ahead, fixed by the current
    state) and the velocities unbounded."""
    s = NMPCSettings(horizon=6, gap_bounds=(4e-3, 31e-3), position_bounds=(-7e-3, 9e-3))
    ocp = Transcription(model, s.grid, s.weights, s.current_limit, s.gap_bounds, s.position_bounds)
    lb, ub = ocp.bounds()
    for j in range(1, s.horizon + 1):
        k = x_index(j)
        if j == 1:
            assert np.all(np.isinf(lb[k : k + 4])) and np.all(np.isinf(ub[k : k + 4]))
            continue
        assert (lb[k], ub[k]) == (4e-3, 31e-3)
        assert (lb[k + 2], ub[k + 2]) == (-7e-3, 9e-3)
        assert np.isinf([lb[k + 1], ub[k + 1], lb[k + 3], ub[k + 3]]).all()


# --- control: building C ---------------------------------------------------------------------------
needs_cc = pytest.mark.skipif(c_compiler() is None, reason="no C compiler")


def _tiny_code(directory: Path, factor: int) -> GeneratedCode:
    """A stand-in for the generated NMPC: one C function, scale(x) = factor x."""
    directory.mkdir(parents=True, exist_ok=True)
    source = directory / "nmpc_rti_step.c"
    source.write_text(f"double scale(double x) {{ return {factor} * x; }}\n")
    header = directory / "nmpc_rti_step.h"
    header.write_text("double scale(double x);\n")
    return GeneratedCode(source, header, "scale", "qrqp", 1)


@needs_cc
def test_compile_shared_writes_the_library_where_asked(tmp_path):
    """compile_shared(output): the library is at ``output`` and nowhere else (default: the source
    with .so); loaded with ctypes, it computes the source's function."""
    code = _tiny_code(tmp_path / "src", 2)
    (tmp_path / "lib").mkdir()
    out = compile_shared(code, tmp_path / "lib" / "libscale.so", cflags=("-O0",))
    assert out == tmp_path / "lib" / "libscale.so" and out.is_file()
    assert not code.source.with_suffix(".so").exists()
    lib = ctypes.CDLL(str(out))
    lib.scale.restype, lib.scale.argtypes = ctypes.c_double, [ctypes.c_double]
    assert lib.scale(21.0) == 42.0
    default = compile_shared(code, cflags=("-O0",))
    assert default == code.source.with_suffix(".so") and default.is_file()


@needs_cc
def test_build_harness_compiles_that_harness_into_that_executable(tmp_path):
    """build_harness(output, harness_source, library): the executable at ``output`` is the given
    harness (it prints what it computes), linked to the library when one is given: the library
    made from factor 2 is used even after the source changes to factor 3, which a build from
    the source picks up."""
    code = _tiny_code(tmp_path / "src", 2)
    harness = tmp_path / "my_harness.c"
    harness.write_text(
        '#include <stdio.h>\n#include "nmpc_rti_step.h"\n'
        'int main(void) { printf("%g\\n", scale(21.0)); return 0; }\n'
    )
    library = compile_shared(code, tmp_path / "libscale.so", cflags=("-O0",))
    code.source.write_text("double scale(double x) { return 3 * x; }\n")
    exe = build_harness(
        code, tmp_path / "bin_linked", harness_source=harness, cflags=("-O0",), library=library
    )
    assert exe == tmp_path / "bin_linked" and exe.is_file()
    assert not (code.source.parent / "harness").exists()
    run = lambda path: subprocess.run([str(path)], capture_output=True, text=True, check=True).stdout  # noqa: E731
    assert run(exe).strip() == "42"
    own = build_harness(code, tmp_path / "bin_own", harness_source=harness, cflags=("-O0",))
    assert run(own).strip() == "63"
    with pytest.raises(FileNotFoundError, match="harness source not found"):
        build_harness(code, harness_source=tmp_path / "absent.c")
    with pytest.raises(SolverError, match="C compilation failed"):
        bad = tmp_path / "bad.c"
        bad.write_text("int main(void) { return undefined_symbol; }\n")
        build_harness(code, tmp_path / "bin_bad", harness_source=bad, cflags=("-O0",))
