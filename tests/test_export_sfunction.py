"""The Simulink block of an export (``sfun_<prefix>.c``), compiled and run without MATLAB.

Simulink's ``simstruc.h`` is replaced by a stand-in written here with only the types and macros
the generated S-function uses (the SimStruct a small struct the harness fills as Simulink
would: it reads the sizes the block asks for in mdlInitializeSizes, allocates the ports and the
DWork vectors, then calls the methods). Where the real build includes ``cg_sfun.h`` (Simulink
Coder's function table), the stand-in exposes the block's static methods to ctypes. The
S-function is compiled with the export (C99, warnings as errors) into one shared library, and
the methods are called in Simulink's order -- mdlInitializeSizes, mdlInitializeSampleTimes,
mdlStart, mdlOutputs every sample, mdlTerminate -- on the readings and references of a recorded
closed-loop run. The block's outputs are the export's own ``<prefix>_step`` bit for bit: the same
compiled code on the same numbers.
"""

from __future__ import annotations

import ctypes
import dataclasses
import json
import subprocess

import numpy as np
import pytest

from maglev_oc.control.export import export_controller
from maglev_oc.control.registry import build_controller
from maglev_oc.numerics import c_compiler
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.scenarios import paper_scenarios
from maglev_oc.sim.twin import RigTwin
from tests.compile_support import cflags_for

pytestmark = pytest.mark.skipif(c_compiler() is None, reason="no C compiler to build the export")

MAX_PORTS = 4
SS_DOUBLE, SS_INT32 = 0, 6  # Simulink's DTypeId values

SIMSTRUC_H = f"""\
/* Stand-in for Simulink's simstruc.h: only what the generated S-function uses. */
#ifndef SIMSTRUC_STANDIN_H
#define SIMSTRUC_STANDIN_H
#ifndef S_FUNCTION_NAME
#error "define S_FUNCTION_NAME before including simstruc.h"
#endif

typedef double real_T;
typedef int int_T;
typedef unsigned int uint_T;
typedef int int32_T;

#define SS_MAX_PORTS {MAX_PORTS}
typedef struct SimStruct_tag {{
  int_T n_params, n_params_given, n_cont_states, n_disc_states;
  int_T n_inputs, input_width[SS_MAX_PORTS], input_contiguous[SS_MAX_PORTS];
  int_T input_feedthrough[SS_MAX_PORTS];
  int_T n_outputs, output_width[SS_MAX_PORTS];
  int_T n_sample_times;
  real_T sample_time[SS_MAX_PORTS], offset_time[SS_MAX_PORTS];
  int_T n_dwork, dwork_width[SS_MAX_PORTS], dwork_type[SS_MAX_PORTS];
  void* dwork[SS_MAX_PORTS];
  void* input[SS_MAX_PORTS];
  void* output[SS_MAX_PORTS];
  uint_T options;
  const char* error;
}} SimStruct;

#define SS_DOUBLE {SS_DOUBLE}
#define SS_INT32 {SS_INT32}
#define SS_OPTION_EXCEPTION_FREE_CODE 0x1u

#define ssSetNumSFcnParams(S, n) ((S)->n_params = (n))
#define ssGetNumSFcnParams(S) ((S)->n_params)
#define ssGetSFcnParamsCount(S) ((S)->n_params_given)
#define ssSetNumContStates(S, n) ((S)->n_cont_states = (n))
#define ssSetNumDiscStates(S, n) ((S)->n_disc_states = (n))
#define ssSetNumInputPorts(S, n) ((n) <= SS_MAX_PORTS ? ((S)->n_inputs = (n), 1) : 0)
#define ssSetInputPortWidth(S, i, w) ((S)->input_width[i] = (w))
#define ssSetInputPortRequiredContiguous(S, i, v) ((S)->input_contiguous[i] = (v))
#define ssSetInputPortDirectFeedThrough(S, i, v) ((S)->input_feedthrough[i] = (v))
#define ssSetNumOutputPorts(S, n) ((n) <= SS_MAX_PORTS ? ((S)->n_outputs = (n), 1) : 0)
#define ssSetOutputPortWidth(S, i, w) ((S)->output_width[i] = (w))
#define ssSetNumSampleTimes(S, n) ((S)->n_sample_times = (n))
#define ssSetSampleTime(S, i, t) ((S)->sample_time[i] = (t))
#define ssSetOffsetTime(S, i, t) ((S)->offset_time[i] = (t))
#define ssSetNumDWork(S, n) ((S)->n_dwork = (n))
#define ssSetDWorkWidth(S, i, w) ((S)->dwork_width[i] = (w))
#define ssSetDWorkDataType(S, i, t) ((S)->dwork_type[i] = (t))
#define ssGetDWork(S, i) ((S)->dwork[i])
#define ssSetOptions(S, o) ((S)->options = (o))
#define ssGetInputPortRealSignal(S, i) ((const real_T*)(S)->input[i])
#define ssGetOutputPortRealSignal(S, i) ((real_T*)(S)->output[i])
#define ssSetErrorStatus(S, msg) ((S)->error = (msg))

#endif
"""

# included at the end of the S-function, where its static methods are in scope (as in simulink.c)
CG_SFUN_H = """\
/* Stand-in for Simulink Coder's cg_sfun.h: the block's methods, for the test harness. */
size_t harness_simstruct_size(void) { return sizeof(SimStruct); }
void harness_mdlInitializeSizes(SimStruct* S) { mdlInitializeSizes(S); }
void harness_mdlInitializeSampleTimes(SimStruct* S) { mdlInitializeSampleTimes(S); }
void harness_mdlStart(SimStruct* S) { mdlStart(S); }
void harness_mdlOutputs(SimStruct* S, int_T tid) { mdlOutputs(S, tid); }
void harness_mdlTerminate(SimStruct* S) { mdlTerminate(S); }
#ifdef MDL_UPDATE
void harness_mdlUpdate(SimStruct* S, int_T tid) { mdlUpdate(S, tid); }
#endif
"""

_PORTS = ctypes.c_int * MAX_PORTS


class SimStruct(ctypes.Structure):
    """The stand-in SimStruct as ctypes sees it (its size is checked against C's)."""

    _fields_ = [
        ("n_params", ctypes.c_int),
        ("n_params_given", ctypes.c_int),
        ("n_cont_states", ctypes.c_int),
        ("n_disc_states", ctypes.c_int),
        ("n_inputs", ctypes.c_int),
        ("input_width", _PORTS),
        ("input_contiguous", _PORTS),
        ("input_feedthrough", _PORTS),
        ("n_outputs", ctypes.c_int),
        ("output_width", _PORTS),
        ("n_sample_times", ctypes.c_int),
        ("sample_time", ctypes.c_double * MAX_PORTS),
        ("offset_time", ctypes.c_double * MAX_PORTS),
        ("n_dwork", ctypes.c_int),
        ("dwork_width", _PORTS),
        ("dwork_type", _PORTS),
        ("dwork", ctypes.c_void_p * MAX_PORTS),
        ("input", ctypes.c_void_p * MAX_PORTS),
        ("output", ctypes.c_void_p * MAX_PORTS),
        ("options", ctypes.c_uint),
        ("error", ctypes.c_char_p),
    ]


def _build(export, tmp_path, object_cache) -> ctypes.CDLL:
    """The export and its S-function in one shared library; the S-function calls nothing but the
    export's interface (no allocation: Simulink owns its memory). An object the session compiled
    before from the same preprocessed source with the same flags is reused
    (tests/compile_support.py)."""
    (tmp_path / "simstruc.h").write_text(SIMSTRUC_H)
    (tmp_path / "cg_sfun.h").write_text(CG_SFUN_H)
    cc = c_compiler()
    objects = []
    sfun, _ = export.simulink
    for src in (*export.sources, sfun):
        obj = tmp_path / (src.stem + ".o")
        # -std=c99 -Wall -Werror on every file; the interface and the block also -Wextra -pedantic
        # (CasADi's generated code has unused parameters by design)
        extra = [] if src.name.endswith("_generated.c") else ["-Wextra", "-pedantic"]
        cmd = [cc, "-std=c99", "-Wall", "-Werror", *extra, *cflags_for(src), "-fPIC"]
        cmd += [f"-I{tmp_path}", f"-I{export.directory}"]
        object_cache.compile(cmd, src, obj)
        objects.append(obj)
    out = subprocess.run(["nm", "-u", str(objects[-1])], check=True, capture_output=True, text=True).stdout
    undefined = {line.split()[-1] for line in out.splitlines() if line.strip()}
    interface = {f"{export.prefix}_{name}" for name in ("init", "step", "prepare", "feedback")}
    assert undefined <= {*interface, "memcpy", "memset"}, undefined
    lib = tmp_path / f"libsfun_{export.prefix}.so"
    link = [cc, "-shared", *map(str, objects), "-o", str(lib), "-lm"]
    subprocess.run(link, check=True, capture_output=True)
    return ctypes.CDLL(str(lib))


class _Simulink:
    """What Simulink does with a block: sizes, allocation, sample time, start, outputs, end."""

    def __init__(self, lib: ctypes.CDLL):
        self.lib = lib
        for name in ("mdlInitializeSizes", "mdlInitializeSampleTimes", "mdlStart", "mdlTerminate"):
            getattr(lib, f"harness_{name}").argtypes = [ctypes.POINTER(SimStruct)]
        lib.harness_mdlOutputs.argtypes = [ctypes.POINTER(SimStruct), ctypes.c_int]
        # mdlUpdate if the block has one (the NMPC's: its preparation of the next sample)
        self.update = getattr(lib, "harness_mdlUpdate", None)
        if self.update is not None:
            self.update.argtypes = [ctypes.POINTER(SimStruct), ctypes.c_int]
        lib.harness_simstruct_size.restype = ctypes.c_size_t
        assert lib.harness_simstruct_size() == ctypes.sizeof(SimStruct)
        self.S = SimStruct()
        self.p = ctypes.pointer(self.S)

    def initialize(self) -> None:
        """mdlInitializeSizes, then the ports and DWork vectors as the block asked for them."""
        S = self.S
        self.lib.harness_mdlInitializeSizes(self.p)
        assert S.error is None
        self.inputs = [np.zeros(S.input_width[i]) for i in range(S.n_inputs)]
        self.outputs = [np.zeros(S.output_width[i]) for i in range(S.n_outputs)]
        itemsize = {SS_DOUBLE: 8, SS_INT32: 4}
        self.dwork = [
            np.zeros(S.dwork_width[i] * itemsize[S.dwork_type[i]], dtype=np.uint8) for i in range(S.n_dwork)
        ]
        for i, v in enumerate(self.inputs):
            S.input[i] = v.ctypes.data
        for i, v in enumerate(self.outputs):
            S.output[i] = v.ctypes.data
        for i, v in enumerate(self.dwork):
            S.dwork[i] = v.ctypes.data
        self.lib.harness_mdlInitializeSampleTimes(self.p)

    def run(self, y: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """mdlStart, mdlOutputs (then mdlUpdate, if the block has one) at every sample of (y, r),
        mdlTerminate -> (u, diag) per sample."""
        self.lib.harness_mdlStart(self.p)
        u, diag = [], []
        for k in range(y.shape[1]):
            self.inputs[0][:] = y[:, k]
            self.inputs[1][:] = r[:, k]
            self.lib.harness_mdlOutputs(self.p, 0)
            assert self.S.error is None, self.S.error
            u.append(self.outputs[0].copy())
            diag.append(self.outputs[1].copy())
            if self.update is not None:
                self.update(self.p, 0)
                assert self.S.error is None, self.S.error
        self.lib.harness_mdlTerminate(self.p)
        return np.array(u).T, np.array(diag).T


def _direct(lib: ctypes.CDLL, export, y: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The export's own init (u0 = 0) and step on the same (y, r) -> (u, diag) per sample."""
    size = getattr(lib, f"{export.prefix}_mem_size")
    size.restype = ctypes.c_size_t
    mem = np.zeros(size(), dtype=np.uint8)
    dbl = np.ctypeslib.ndpointer(dtype=np.float64, flags="C_CONTIGUOUS")
    init, step = getattr(lib, f"{export.prefix}_init"), getattr(lib, f"{export.prefix}_step")
    init.argtypes = step.argtypes = [ctypes.c_void_p, dbl, dbl, dbl]
    y, r = np.ascontiguousarray(y.T), np.ascontiguousarray(r.T)
    assert init(mem.ctypes.data, y[0], r[0], np.zeros(2)) == 0
    u, diag, n_diag = [], [], len(export.diag_names)
    for k in range(y.shape[0]):
        out = np.zeros(2)
        assert step(mem.ctypes.data, y[k], r[k], out) == 0
        u.append(out)
        # the diagnostics follow c and c_next in the memory struct
        diag.append(mem[16 * export.n_state :].view(np.float64)[:n_diag].copy())
    return np.array(u).T, np.array(diag).T


def _python_step(ctrl):
    """(c, y, r) -> (u, c_next) of the Python controller the export was made from: its step, or
    for the NMPC the preparation for r then the feedback (the export's step)."""
    import casadi as ca

    from maglev_oc.control.nmpc.grid import extrapolated_reference

    nmpc = getattr(ctrl, "controller", None)
    if nmpc is None:

        def step(c, y, r):
            u, c_next, _ = ctrl.step(c, y, r)
            return np.asarray(u).ravel(), np.asarray(c_next).ravel()

        return step
    rs = ca.SX.sym("r", 6)
    offsets = nmpc.grid.node_offsets * nmpc.sample_time
    nodes = ca.Function("nodes", [rs], [extrapolated_reference(rs, offsets)])

    def split(c, y, r):
        u, c_next, _ = nmpc.rti_feedback(c, nmpc.rti_prepare(c, nodes(r)), y)
        return np.asarray(u).ravel(), np.asarray(c_next).ravel()

    return split


def _controller(name: str, model):
    if name == "nmpc":
        from maglev_oc.control.nmpc import NonlinearMPC
        from maglev_oc.sim.compiled_nmpc import CompiledNMPC

        nmpc = NonlinearMPC(model, preview=False, qp_solver="qrqp")
        return CompiledNMPC(nmpc, backend="vm"), "large_step", 0.1
    return build_controller(name, model), "setpoint_steps", 1.5


@pytest.mark.parametrize("name", ["fl", "pid", pytest.param("nmpc", marks=pytest.mark.slow)])
def test_simulink_block_gives_the_exported_step_bit_for_bit(model, tmp_path, object_cache, name):
    # fl/pid: the set-point steps through t = 1 s (7500 samples); nmpc: the large step's first
    # 0.1 s, where the current constraints are active and the QP solver runs
    ctrl, scenario, seconds = _controller(name, model)
    export = export_controller(ctrl, tmp_path / "export")
    lib = _build(export, tmp_path, object_cache)
    sc = dataclasses.replace(paper_scenarios()[scenario], duration=seconds)
    res = ClosedLoop(RigTwin(model), ctrl).run(sc)
    y, r = res.y, res.reference

    block = _Simulink(lib)
    block.initialize()
    S = block.S
    # the block as a user sees it in Simulink: no parameters, y (2) and r (6) in with direct
    # feedthrough, u (2) and diag out, the export's sample time, its memory in a DWork vector
    assert (S.n_params, S.n_cont_states, S.n_disc_states) == (0, 0, 0)
    assert (S.n_inputs, list(S.input_width[:2]), list(S.input_feedthrough[:2])) == (2, [2, 6], [1, 1])
    assert list(S.input_contiguous[:2]) == [1, 1]
    assert (S.n_outputs, list(S.output_width[:2])) == (2, [2, len(ctrl.diag_names)])
    assert (S.n_sample_times, S.sample_time[0], S.offset_time[0]) == (1, ctrl.sample_time, 0.0)
    assert S.dwork_type[0] == SS_DOUBLE  # the struct's doubles, pointers and integers are aligned
    assert S.dwork_width[0] * 8 >= export.memory_bytes

    u, diag = block.run(y, r)
    u_direct, diag_direct = _direct(lib, export, y, r)
    np.testing.assert_array_equal(u, u_direct)
    np.testing.assert_array_equal(diag, diag_direct)
    # and the export is the Python controller (to round-off, tests/test_export.py), started the same
    # way; for the NMPC its preparation and feedback Functions, which the export's step is, with
    # the QP solved by another method on the constrained samples (the first 54 here: the export's
    # dual active-set method, Python's qrqp, both exact on the QP's active set, measured 1.5e-13 A
    # apart): 1e-6 A there, the QPs' exactness bar (tests/test_export.py, QP_TOLERANCE_A)
    step = _python_step(ctrl)
    c = np.asarray(ctrl.initial_state(y[:, 0], r[:, 0], np.zeros(2)), dtype=float).ravel()
    tolerance = 1e-6 if name == "nmpc" else 1e-9
    for k in range(60):
        uk, c = step(c, y[:, k], r[:, k])
        np.testing.assert_allclose(u[:, k], uk, rtol=0, atol=tolerance)
    if name == "nmpc":
        # the block prepared every sample but the first in mdlUpdate, off the output path (the
        # first: the block starts the controller in that sample's mdlOutputs, whose feedback then
        # prepares; later the set-point's predicted reference is the reference)
        assert block.update is not None
        late = block.dwork[0][export.memory_bytes - 8 : export.memory_bytes].view(np.int64)[0]
        assert late == 1
    else:
        assert block.update is None

    # a restart of the model (its memory left as the last run left it, or garbage) starts over
    for v in block.dwork:
        v[:] = 0xFF  # NaN doubles, -1 flags
    again, _ = block.run(y[:, :200], r[:, :200])
    np.testing.assert_array_equal(again, u[:, :200])


def test_simulink_files_are_listed_and_the_build_script_names_every_source(model, tmp_path):
    export = export_controller(build_controller("pid", model), tmp_path / "pid")
    manifest = json.loads((export.directory / "export.json").read_text())
    assert manifest["simulink"] == [p.name for p in export.simulink]
    assert all(p.is_file() for p in export.simulink)
    script = export.simulink[1].read_text()
    for src in (export.simulink[0], *export.sources):
        assert f"'{src.name}'" in script
    sfun = export.simulink[0].read_text()
    assert f"#define S_FUNCTION_NAME sfun_{export.prefix}\n" in sfun
    assert '#ifdef MATLAB_MEX_FILE\n#include "simulink.c"\n#else\n#include "cg_sfun.h"\n#endif' in sfun
    assert (
        f"S-function modules `{export.prefix} {export.prefix}_generated`"
        in (export.directory / "README.md").read_text()
    )
