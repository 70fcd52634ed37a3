"""C export of the NMPC real-time iteration, and the replay of recorded problem instances.

:attr:`NonlinearMPC.rti_step <maglev_oc.control.nmpc.NonlinearMPC.rti_step>` (observer,
linearization, QP, check, fallback, shift: one CasADi Function) is turned into C by CasADi's
code generator, compiled with ``gcc -O3`` into a shared library (loadable with
``casadi.external``) or linked with the harness of ``bench/nmpc_c/harness.c``, which replays
instances recorded from a closed-loop Python run and times each call.

QP solvers and code generation (CasADi 3.8.2)
    * ``qrqp`` generates self-contained C (no library, no ``malloc``): the default.
    * ``hpipm`` generates C that calls libhpipm/libblasfeo shipped in the CasADi wheel (linked
      with an rpath). Its generated code has two defects that :func:`generate_c` patches, each
      checked by string match so that a changed CasADi fails loudly instead of silently:
      the IPM arguments are copied from a struct in which five fields of this HPIPM version
      (dual_gap_max, lam0_min, t0_min, t0_init, update_fact_exit) are left uninitialized (the
      copy is replaced by HPIPM's own ``d_ocp_qp_ipm_arg_set_default`` for the same mode plus
      the iteration limit), and a solver status other than 0 makes the whole generated
      function return an error before the fallback runs (that early return is removed: the
      solution check inside the step decides). It also calls ``malloc`` five times per solve.
    * ``osqp`` is not supported here (its generated code needs the OSQP sources).

Instance file format (little endian), shared with the harness:
``b"NMPCREC1"``, int32 n_instances, n_in, n_out, int32 nnz_in[n_in], int32 nnz_out[n_out], then
float64 rows of the concatenated inputs (memory, y, ref column-major) of each call; the
harness writes the outputs (u, memory_next, diag) in the same layout.
"""

from __future__ import annotations

import os
import shutil
import struct
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

from maglev_oc.control.nmpc import NonlinearMPC
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.scenarios import Scenario
from maglev_oc.sim.twin import RigTwin

FUNCTION_NAME = "nmpc_rti_step"
MAGIC = b"NMPCREC1"
CODEGEN_SOLVERS = ("qrqp", "hpipm")
DEFAULT_CFLAGS = ("-O3",)
REPO_HARNESS = Path(__file__).resolve().parents[2] / "bench" / "nmpc_c" / "harness.c"
"""The harness source in a source checkout (not shipped in the wheel)."""

_HPIPM_ARG_COPY = "memcpy(&myarg, &p->hpipm_options, sizeof(struct d_ocp_qp_ipm_arg));"
_HPIPM_ARG_DEFAULT = (
    "d_ocp_qp_ipm_arg_set_default((enum hpipm_mode) p->hpipm_options.mode, &myarg);\n"
    "    d_ocp_qp_ipm_arg_set_iter_max((int*) &p->hpipm_options.iter_max, &myarg);"
)
_HPIPM_EARLY_RETURN = "  if (d.return_status!=0) {\n    return -1;\n  }\n"


def casadi_directory() -> Path:
    """Where the CasADi wheel keeps its headers (include/) and libraries (libhpipm, libblasfeo)."""
    return Path(ca.__file__).resolve().parent


def c_compiler() -> str | None:
    """The C compiler to use ($CC, else gcc, else cc), or None if there is none."""
    for name in (os.environ.get("CC"), "gcc", "cc"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


@dataclass(frozen=True)
class GeneratedCode:
    """C source and header of the RTI step, and what it needs to compile."""

    source: Path
    header: Path
    function: str
    qp_solver: str
    horizon: int

    @property
    def include_dirs(self) -> tuple[Path, ...]:
        return (self.source.parent, casadi_directory() / "include")

    @property
    def link_flags(self) -> tuple[str, ...]:
        if self.qp_solver == "hpipm":
            lib = casadi_directory()
            return (f"-L{lib}", "-lhpipm", "-lblasfeo", f"-Wl,-rpath,{lib}", "-lm")
        return ("-lm",)


def generate_c(controller: NonlinearMPC, directory: str | os.PathLike) -> GeneratedCode:
    """Write ``nmpc_rti_step.c`` and ``.h`` for ``controller.rti_step`` into ``directory``."""
    if not isinstance(controller, NonlinearMPC):
        raise TypeError(f"controller must be a NonlinearMPC, got {type(controller).__name__}")
    if controller.qp_solver not in CODEGEN_SOLVERS:
        raise ValueError(f"C export supports the QP solvers {CODEGEN_SOLVERS}, got {controller.qp_solver!r}")
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    gen = ca.CodeGenerator(f"{FUNCTION_NAME}.c", {"with_header": True})
    gen.add(controller.rti_step)
    gen.generate(str(directory) + os.sep)
    source = directory / f"{FUNCTION_NAME}.c"
    header = directory / f"{FUNCTION_NAME}.h"
    if controller.qp_solver == "hpipm":
        _patch_hpipm(source)
    return GeneratedCode(source, header, FUNCTION_NAME, controller.qp_solver, controller.grid.horizon)


def _patch_hpipm(source: Path) -> None:
    text = source.read_text()
    for needle in (_HPIPM_ARG_COPY, _HPIPM_EARLY_RETURN):
        if text.count(needle) != 1:
            raise RuntimeError(
                f"{source}: the HPIPM code generated by CasADi {ca.__version__} does not have the "
                f"expected form (looked for {needle.strip()[:40]!r}); the patch of "
                "maglev_oc.control.codegen must be revisited"
            )
    text = text.replace(_HPIPM_ARG_COPY, _HPIPM_ARG_DEFAULT).replace(_HPIPM_EARLY_RETURN, "")
    source.write_text(text)


def _compile(args: list[str]) -> None:
    proc = subprocess.run(args, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"C compilation failed ({' '.join(args[:3])} ...):\n{proc.stderr[-4000:]}")


def compile_shared(
    code: GeneratedCode, output: str | os.PathLike | None = None, *, cflags=DEFAULT_CFLAGS
) -> Path:
    """Compile the generated code into a shared library (``casadi.external(code.function, path)``)."""
    cc = c_compiler()
    if cc is None:
        raise RuntimeError("no C compiler found (set $CC or install gcc)")
    output = Path(output) if output is not None else code.source.with_suffix(".so")
    includes = [f"-I{d}" for d in code.include_dirs]
    _compile(
        [cc, *cflags, "-fPIC", "-shared", str(code.source), "-o", str(output), *includes, *code.link_flags]
    )
    return output


def build_harness(
    code: GeneratedCode,
    output: str | os.PathLike | None = None,
    *,
    harness_source: str | os.PathLike = REPO_HARNESS,
    cflags=DEFAULT_CFLAGS,
) -> Path:
    """Compile ``bench/nmpc_c/harness.c`` with the generated code into an executable."""
    cc = c_compiler()
    if cc is None:
        raise RuntimeError("no C compiler found (set $CC or install gcc)")
    harness_source = Path(harness_source)
    if not harness_source.is_file():
        raise FileNotFoundError(f"harness source not found: {harness_source}")
    output = Path(output) if output is not None else code.source.parent / "harness"
    includes = [f"-I{d}" for d in code.include_dirs]
    _compile(
        [cc, *cflags, str(harness_source), str(code.source), "-o", str(output), *includes, *code.link_flags]
    )
    return output


# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RecordedInstances:
    """Inputs of the RTI Function, one row per call: (n, sum(nnz_in)) with nnz_in per input."""

    inputs: np.ndarray
    nnz_in: tuple[int, ...]
    nnz_out: tuple[int, ...]

    def __len__(self) -> int:
        return self.inputs.shape[0]

    def split(self, k: int) -> list[np.ndarray]:
        """The inputs of call k, one array per Function input."""
        return np.split(self.inputs[k], np.cumsum(self.nnz_in)[:-1])


class _Recorder:
    """An OnlineController that forwards to an RTI NonlinearMPC and records its step inputs."""

    def __init__(self, controller: NonlinearMPC, every: int, limit: int) -> None:
        self.controller = controller
        self.name = controller.name
        self.sample_time = controller.sample_time
        self.diag_names = controller.diag_names
        self.every = every
        self.limit = limit
        self.rows: list[np.ndarray] = []

    def reset(self, y0, r0, u0) -> None:
        self.controller.reset(y0, r0, u0)

    def control(self, k, y, reference):
        c = self.controller
        if k % self.every == 0 and len(self.rows) < self.limit:
            ref = c.node_references(k, reference)
            self.rows.append(
                np.concatenate([c.memory, np.asarray(y, dtype=float).ravel(), ref.ravel(order="F")])
            )
        return c.control(k, y, reference)


def record_instances(
    controller: NonlinearMPC,
    twin: RigTwin,
    scenario: Scenario,
    *,
    every: int = 1,
    limit: int = 100_000,
    seed: int = 0,
) -> RecordedInstances:
    """Run ``scenario`` in closed loop and record the inputs of every ``every``-th RTI call."""
    if controller.mode != "rti":
        raise ValueError(f"instances are recorded from an RTI controller, got mode {controller.mode!r}")
    if not (isinstance(every, int) and every >= 1):
        raise ValueError(f"every must be a positive integer, got {every!r}")
    rec = _Recorder(controller, every, limit)
    ClosedLoop(twin, rec).run(scenario, seed=seed)
    f = controller.rti_step
    nnz_in = tuple(int(f.nnz_in(i)) for i in range(f.n_in()))
    nnz_out = tuple(int(f.nnz_out(i)) for i in range(f.n_out()))
    return RecordedInstances(np.array(rec.rows), nnz_in, nnz_out)


def write_instances(path: str | os.PathLike, instances: RecordedInstances) -> Path:
    """Write the instance file read by the harness (format in the module docstring)."""
    path = Path(path)
    with open(path, "wb") as fh:
        _write_header(fh, len(instances), instances.nnz_in, instances.nnz_out)
        fh.write(np.ascontiguousarray(instances.inputs, dtype="<f8").tobytes())
    return path


def _write_header(fh, n: int, nnz_in, nnz_out) -> None:
    fh.write(MAGIC)
    fh.write(struct.pack("<3i", n, len(nnz_in), len(nnz_out)))
    fh.write(struct.pack(f"<{len(nnz_in)}i", *nnz_in))
    fh.write(struct.pack(f"<{len(nnz_out)}i", *nnz_out))


def _read(path: str | os.PathLike, which: str) -> tuple[np.ndarray, tuple[int, ...], tuple[int, ...]]:
    path = Path(path)
    data = path.read_bytes()
    if data[:8] != MAGIC:
        raise ValueError(f"{path}: not an NMPCREC1 file")
    n, n_in, n_out = struct.unpack_from("<3i", data, 8)
    off = 20
    nnz_in = struct.unpack_from(f"<{n_in}i", data, off)
    off += 4 * n_in
    nnz_out = struct.unpack_from(f"<{n_out}i", data, off)
    off += 4 * n_out
    width = sum(nnz_in) if which == "in" else sum(nnz_out)
    values = np.frombuffer(data, dtype="<f8", offset=off)
    if values.size != n * width:
        raise ValueError(f"{path}: expected {n} rows of {width} values, found {values.size} values")
    return values.reshape(n, width).copy(), tuple(nnz_in), tuple(nnz_out)


def read_instances(path: str | os.PathLike) -> RecordedInstances:
    rows, nnz_in, nnz_out = _read(path, "in")
    return RecordedInstances(rows, nnz_in, nnz_out)


def read_outputs(path: str | os.PathLike) -> list[np.ndarray]:
    """Outputs written by the harness: one (n, nnz) array per Function output."""
    rows, _, nnz_out = _read(path, "out")
    return np.split(rows, np.cumsum(nnz_out)[:-1], axis=1)


def evaluate_instances(function: ca.Function, instances: RecordedInstances) -> list[np.ndarray]:
    """Outputs of ``function`` (the Python RTI step or a ``casadi.external``) on every instance,
    one (n, nnz) array per output, with the same layout as :func:`read_outputs`."""
    n = len(instances)
    outs = [np.empty((n, function.nnz_out(i))) for i in range(function.n_out())]
    sp_in = [function.sparsity_in(i) for i in range(function.n_in())]
    for k in range(n):
        args = [ca.DM(sp, v) for sp, v in zip(sp_in, instances.split(k), strict=True)]
        res = function.call(args)
        for i, r in enumerate(res):
            outs[i][k] = np.asarray(r.nonzeros())
    return outs


@dataclass(frozen=True)
class HarnessTiming:
    """Step times of the generated C over the replayed instances [s]."""

    instances: int
    calls: int
    failed_calls: int
    median: float
    p99: float
    worst: float


def run_harness(
    executable: str | os.PathLike,
    instances_path: str | os.PathLike,
    outputs_path: str | os.PathLike | None = None,
    *,
    repeat: int = 3,
    timeout: float = 600.0,
) -> HarnessTiming:
    """Run the harness and parse its report (outputs go to a temporary file unless a path is given)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(outputs_path) if outputs_path is not None else Path(tmp) / "outputs.bin"
        args = [str(executable), str(instances_path), str(out), str(int(repeat))]
        proc = subprocess.run(args, capture_output=True, text=True, timeout=timeout, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"harness failed ({proc.returncode}): {proc.stderr.strip()}")
    report = {}
    for line in proc.stdout.splitlines():
        key, _, value = line.partition(":")
        report[key.strip()] = float(value)
    return HarnessTiming(
        instances=int(report["instances"]),
        calls=int(report["calls_timed"]),
        failed_calls=int(report["failed_calls"]),
        median=report["median_us"] * 1e-6,
        p99=report["p99_us"] * 1e-6,
        worst=report["worst_us"] * 1e-6,
    )
