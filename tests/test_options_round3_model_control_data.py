"""Options of ``maglev_oc.model``, ``maglev_oc.control`` and ``maglev_oc.data`` that no test passed
by name (issue 21, third round): each test fails when its option is ignored (the default used
instead) or, where that means something, inverted. Every option was checked by hand against both
bugs.

* ``gap_for_current(bracket)``: Brent's method searches only the bracket given: a current whose gap
  lies inside the default 5-35 mm but outside a 15-25 mm bracket is refused naming that bracket,
  one inside it is found there (the equilibrium current to brentq's 1e-12 m).
* ``fit_field_polynomial(degree)``: a degree-d fit has d + 1 coefficients, its reported maximum
  error is the one measured here against the closed form B(y) (evaluated with numpy from Table I),
  and the error falls as 3^-d: B's only singularity, y = -h_m, lies on the Bernstein ellipse
  rho = 3 of the scaled 5-35 mm interval (within a factor 2 from degree 3 to 7 and 7 to 12).
* ``Motor(gap_at_zero, position_at_zero)``: a mirrored, offset 2-DOF platform is the 2-DOF stage
  at gap y = gap_at_zero - n . q and position s = position_at_zero + t . q.
* The stage-file reader's optional fields: a geometry with one field keeps Table I for the rest,
  ``constants.stderr`` may be left out, partial or null per constant (NaN: unknown), an effect's
  parameter may have a null standard error but not a null value; a missing required field is
  refused naming that field.
* The high-gain observers' ``observer_epsilon``: ``RegulatorCore`` discretizes the papers'
  observer p' = q + (2/eps)(y - p), q' = a + (1/eps^2)(y - p) exactly (a double pole at -1/eps,
  so a double discrete eigenvalue exp(-Ts/eps)), and every controller that takes the option (FL,
  scheduled linear, PID, microstepper, NMPC) updates its velocity estimates with that observer.
* ``NMPCSettings(position_bounds)``: the plan's horizontal positions stay inside them even when
  the reference lies far outside; in the QP they bound x3, as ``gap_bounds`` bound x1, at nodes
  2..N exactly (node 1 is one sample ahead and free).
* ``codegen``: ``compile_shared(output)`` writes the library there (default beside the source),
  ``build_harness(output, harness_source, library)`` compiles that harness into that executable,
  linked to that library; a tiny C source stands in for the generated NMPC (no 8 s build).
* The CSV reader: lines of only spaces (or tabs) among the data are blank lines
  (``text_lines(blank_spaces)``, which leaves the lines as they are by default); the log keeps
  every other row, exactly.

Already covered elsewhere (checked, not repeated): ``load_model(params_path)``
(tests/test_options.py), ``check_excitation(position_resolution, current_resolution)``
(tests/test_data_injected_properties.py), ``run_harness(outputs_path)``
(tests/test_codegen_harness_properties.py, positionally).

The whole file takes about 1 s (3 s with the imports); the two C tests compile a one-line source.
"""

from __future__ import annotations

import ctypes
import dataclasses
import json
import math
import re
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
from maglev_oc.data.csv_reader import _Body
from maglev_oc.data.logs import read_log
from maglev_oc.errors import InputError, SolverError
from maglev_oc.estimation.high_gain import DEFAULT_EPSILON, HighGainObserver
from maglev_oc.expressions import function_to_data
from maglev_oc.model.equilibrium import NoEquilibriumError, equilibrium_currents, gap_for_current
from maglev_oc.model.magnetics import FIELD_FIT_RANGE, fit_field_polynomial
from maglev_oc.model.parameters import DEFAULT_CONSTANTS, MU0, StageParameters
from maglev_oc.model.platform import Motor, Platform, PlatformModel, microstepper
from maglev_oc.model.stagefile import Provenance, StageEffect, StageFile
from maglev_oc.numerics import c_compiler
from maglev_oc.results import Estimate

GAP = 0.020  # [m] an operating gap of the papers' runs (a scheduled gap of the linear regulators)
EPS = 1e-3  # [s] an observer time constant half the default: poles at -1000 instead of -500 rad/s


# --- model: equilibrium and field -------------------------------------------------------------
def test_gap_for_current_searches_only_its_bracket(model):
    """With bracket 15-25 mm, the 10 mm equilibrium current (inside the default 5-35 mm) has no
    gap in the bracket and is refused naming it; the 20 mm current is found at 20 mm (brentq's
    xtol 1e-12 m; 1e-9 m leaves room for the residual's rounding at a slope of 0.4 A/mm)."""
    i10, i20 = equilibrium_currents(model, [10e-3, GAP]).current
    assert 5e-3 < gap_for_current(model, float(i10)) < 35e-3  # the default bracket holds it
    with pytest.raises(NoEquilibriumError, match=r"no gap in \[15, 25\] mm"):
        gap_for_current(model, float(i10), bracket=(15e-3, 25e-3))
    assert_allclose(gap_for_current(model, float(i20), bracket=(15e-3, 25e-3)), GAP, rtol=0, atol=1e-9)
    # a bracket reaching past the default one finds a gap beyond 35 mm (the current there is
    # below i(35 mm), which the default refuses)
    i40 = float(equilibrium_currents(model, [40e-3]).current[0])
    with pytest.raises(NoEquilibriumError):
        gap_for_current(model, i40)
    assert_allclose(gap_for_current(model, i40, bracket=(30e-3, 45e-3)), 40e-3, rtol=0, atol=1e-9)


def _closed_form_field(p: StageParameters, y: np.ndarray) -> np.ndarray:
    """B(y) [T] of SPEC 1 written out with numpy (the magnetic-charge model's fundamental)."""
    a = math.pi / p.pole_pitch
    amp = 4 * MU0 * p.surface_charge / math.pi * math.sin(math.pi * p.magnet_width / (2 * p.pole_pitch))
    return amp * np.sinh(a * p.magnet_height) / np.sinh(a * (p.magnet_height + y))


def test_field_fit_degree_is_the_polynomials_degree():
    """A degree-d fit has d + 1 coefficients, its max_error is the largest deviation from the
    closed form on the dense grid (recomputed here with numpy; 1e-6 relative), and it falls as
    rho^-d with rho = 3: B ~ 1/sinh(a (h_m + y)) is analytic but for a pole at y = -h_m = -5 mm,
    which in the scaled gap s = (y - 20 mm) / 15 mm is at s = -5/3, on the Bernstein ellipse
    rho = 5/3 + sqrt((5/3)^2 - 1) = 3. Near-best (Chebyshev-node) fits converge at that rate:
    from degree 3 to 7 the error falls by 3^4 = 81 (measured 80.5), from 7 to 12 by 3^5 = 243
    (measured 243); a factor 2 either way is the bound asserted."""
    p = StageParameters()
    lo, hi = FIELD_FIT_RANGE
    s_pole = (-p.magnet_height - 0.5 * (lo + hi)) / (0.5 * (hi - lo))
    rho = abs(s_pole) + math.sqrt(s_pole**2 - 1)
    assert rho == pytest.approx(3.0, rel=1e-12)
    y = np.linspace(lo, hi, 3001)
    b = _closed_form_field(p, y)
    errors = {}
    for degree in (3, 7, 12):
        fit = fit_field_polynomial(p, degree=degree) if degree != 12 else fit_field_polynomial(p)
        assert len(fit.coefficients) == degree + 1
        errors[degree] = np.max(np.abs(np.asarray(fit(y), dtype=float) - b))
        assert_allclose(fit.max_error, errors[degree], rtol=1e-6)
    for low, high in ((3, 7), (7, 12)):
        assert 0.5 < errors[low] / errors[high] / rho ** (high - low) < 2.0


def test_a_motors_gap_and_position_at_zero_place_it(model):
    """Motor(gap_at_zero, position_at_zero): y = gap_at_zero - n . q and s = position_at_zero +
    t . q. A 2-DOF stage mirrored (stator on the +q1 side, gravity -G along q1) and offset (gap
    30 mm and position 10 mm at q = 0) is the 2-DOF stage at y and s: q1'' = -x2', q2'' = x4'
    of StageModel at the gap y (1e-12 relative: the same shape functions; the base model does
    not depend on s, which motor_forces reports)."""
    p = model.params
    motor = Motor("mirrored", (0.0, 1.0), (1.0, 0.0), (0, 1), gap_at_zero=0.030, position_at_zero=0.010)
    platform = Platform(("q1", "q2"), (p.mass_vertical, p.mass_horizontal), (-p.gravity, 0.0), (motor,), 2)
    pm = PlatformModel(platform)
    rng = np.random.default_rng(5)
    for _ in range(5):
        q = np.array([rng.uniform(0.005, 0.020), rng.uniform(-0.02, 0.02)])  # gaps 10-25 mm
        qd, u = rng.normal(0, 0.05, 2), rng.uniform(-5, 5, 2)
        x = np.array([q[0], qd[0], q[1], qd[1]])
        _, _, y, s = (float(v) for v in pm.motor_forces(x, u))
        assert_allclose([y, s], [0.030 - q[0], 0.010 + q[1]], rtol=1e-15)
        acc = np.asarray(pm.f(x, u)).ravel()
        stage = np.asarray(model.dynamics(np.array([y, -qd[0], s, qd[1]]), u)).ravel()
        assert_allclose([acc[1], acc[3]], [-stage[1], stage[3]], rtol=1e-12, atol=1e-12 * p.gravity)


# --- model: the stage file's optional and required fields ----------------------------------------
def _effect() -> StageEffect:
    x, i = ca.SX.sym("x", 4), ca.SX.sym("i", 2)
    acc = ca.vertcat(0, 0.1 - 2.0 * x[2] + 0 * i[0])
    return StageEffect(
        "cable_carrier_force",
        "horizontal",
        "A spring-like force along the track.",
        "stiffness -2",
        {"force": Estimate(0.1, 0.01, "N"), "stiffness": Estimate(-2.0, 0.5, "N/m")},
        function_to_data(ca.Function("f", [x, i], [acc], ["x", "i"], ["acc"])),
        None,
    )


def _document() -> dict:
    provenance = {part: Provenance.now((), "test") for part in ("geometry", "constants", "effects")}
    stage = StageFile(StageParameters(), DEFAULT_CONSTANTS, None, {}, (_effect(),), provenance)
    return json.loads(json.dumps(stage.to_dict()))


def test_stage_file_optional_fields_may_be_left_out_or_null():
    """Geometry fields are each optional (Table I for those left out); ``constants.stderr`` is
    optional, and so is each constant in it and its value (null: unknown, NaN); an effect's
    parameter may have a null standard error (NaN)."""
    doc = _document()
    doc["geometry"] = {"mass_vertical": 4.0}
    doc["constants"]["stderr"] = {"C1": 0.5, "C3": None}
    doc["effects"][0]["parameters"]["force"]["stderr"] = None
    stage = StageFile.from_dict(doc)
    assert stage.geometry == dataclasses.replace(StageParameters(), mass_vertical=4.0)
    assert stage.stderr["C1"] == 0.5
    assert all(math.isnan(stage.stderr[k]) for k in ("C2", "C3", "C4"))
    force = stage.effects[0].parameters["force"]
    assert force.value == 0.1 and math.isnan(force.stderr)
    assert stage.effects[0].parameters["stiffness"].stderr == 0.5
    del doc["constants"]["stderr"]
    assert all(math.isnan(v) for v in StageFile.from_dict(doc).stderr.values())


@pytest.mark.parametrize(
    "path",
    [
        "constants.source",
        "constants.covariance",
        "effects.0.parameters.force.unit",
        "effects.0.parameters.force.stderr",
        "effects.0.compensation",
        "provenance.effects.method",
    ],
)
def test_a_missing_required_stage_field_is_refused_naming_it(path):
    """Required fields (including those that may be null) must be present; the error names the
    field's path, whatever other fields are present."""
    doc = _document()
    *parents, last = path.split(".")
    obj = doc
    for key in parents:
        obj = obj[int(key)] if key.isdigit() else obj[key]
    del obj[last]
    shown = path.replace(".0.", "[0].")
    with pytest.raises(InputError, match=re.escape(f"{shown}: missing")):
        StageFile.from_dict(doc)


@pytest.mark.parametrize(
    ("path", "shown"),
    [("constants.C3", r"constants\.C3"), ("effects.0.parameters.force.value", r"\.force\.value")],
)
def test_a_required_number_may_not_be_null(path, shown):
    """Where a standard error may be null, a value may not: null is refused as not a number."""
    doc = _document()
    *parents, last = path.split(".")
    obj = doc
    for key in parents:
        obj = obj[int(key)] if key.isdigit() else obj[key]
    obj[last] = None
    with pytest.raises(InputError, match=rf"{shown}: expected a number, got null"):
        StageFile.from_dict(doc)


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


# --- data: lines of only spaces ----------------------------------------------------------------
def test_lines_of_only_spaces_in_the_data_are_blank_lines(tmp_path):
    """A CSV whose data holds a line of spaces and a line of a tab is read as if those lines were
    empty: every other row, exactly (repr() round-trips a float), in order."""
    n = 300
    t = np.arange(n) * 1e-3
    x1 = GAP + 1e-4 * np.sin(2 * np.pi * 3 * t)
    x3 = 1e-3 * np.cos(2 * np.pi * 2 * t)
    u1 = 0.1 * np.sin(2 * np.pi * 5 * t)
    u2 = 1.5 + 0.05 * np.cos(2 * np.pi * 4 * t)
    rows = [",".join(repr(float(v)) for v in row) for row in zip(t, x1, x3, u1, u2, strict=True)]
    rows.insert(100, "    ")
    rows.insert(201, "\t ")
    path = tmp_path / "run.csv"
    path.write_text("# units: SI\nt,x1,x3,u1,u2\n" + "\n".join(rows) + "\n")
    log = read_log(path, min_samples=10, min_duration=0.1)
    assert log.n == n
    np.testing.assert_array_equal(log.t, t)
    np.testing.assert_array_equal(log.x[0], x1)
    np.testing.assert_array_equal(log.u[1], u2)


def test_text_lines_empties_lines_of_only_whitespace_when_asked(tmp_path):
    """``_Body.text_lines``: the lines as they are by default (a bad line's message quotes it),
    and with ``blank_spaces`` a line of only spaces or tabs becomes an empty line (numpy's
    loadtxt skips empty lines, not lines of spaces); lines with data are never changed."""
    path = tmp_path / "body.csv"
    lines = ["0.0,1.0\n", "   \n", "2.0,3.0\n", "\t \n", " 4.0,5.0\n"]
    path.write_text("".join(lines))
    body = _Body(path, 0, 1, str(path))
    assert list(body.text_lines()) == lines
    assert list(body.text_lines(blank_spaces=True)) == [lines[0], "\n", lines[2], "\n", lines[4]]
