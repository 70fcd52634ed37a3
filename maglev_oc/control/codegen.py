"""C export of the NMPC real-time iteration, and the replay of recorded problem instances.

:attr:`NonlinearMPC.rti_step <maglev_oc.control.nmpc.NonlinearMPC.rti_step>` (observer,
linearization, QP, check, fallback, shift: one CasADi Function) is turned into C by CasADi's
code generator, compiled with ``gcc -O3`` into a shared library (loadable with
``casadi.external``) or linked with the harness of ``bench/nmpc_c/harness.c``, which replays
instances recorded from a closed-loop Python run and times each call. The closed-loop
recording itself is :func:`maglev_oc.sim.nmpc_instances.record_instances` (simulation sits
downstream of control); this module defines the instances (:class:`RecordedInstances`,
:func:`instance_row`) and their file format.

QP solvers and code generation (CasADi 3.8.2)
    * ``qrqp`` generates self-contained C (no library, no ``malloc``): the default.
    * ``hpipm`` generates C that calls libhpipm/libblasfeo shipped in the CasADi wheel (linked
      with an rpath). Its generated code has two defects that :func:`generate_c` patches, each
      checked by string match so that a changed CasADi fails loudly instead of silently:
      the IPM arguments are copied from a struct in which five fields of this HPIPM version
      (dual_gap_max, lam0_min, t0_min, t0_init, update_fact_exit) are left uninitialized (the
      copy is replaced by HPIPM's own ``d_ocp_qp_ipm_arg_set_default`` for the same mode plus
      the two options the NMPC sets, the iteration limit and the initial barrier mu0), and a
      solver status other than 0 makes the whole generated function return an error before the
      fallback runs (that early return is removed: the solution check inside the step decides).
      It also calls ``malloc`` five times per solve.
    * ``osqp`` is not supported here (its generated code needs the OSQP sources).

Instance file format (little endian), shared with the harness:
``b"NMPCREC1"``, int32 n_instances, n_in, n_out, int32 nnz_in[n_in], int32 nnz_out[n_out], then
float64 rows of the concatenated inputs (memory, y, ref column-major) of each call; the
harness writes the outputs (u, memory_next, diag) in the same layout.
"""

from __future__ import annotations

import os
import struct
import subprocess
import tempfile
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca
import numpy as np

from maglev_oc.control.nmpc import NonlinearMPC
from maglev_oc.errors import InputError, SolverError
from maglev_oc.numerics import c_compiler
from maglev_oc.results import Result

__all__ = [
    "CODEGEN_SOLVERS",
    "DEFAULT_CFLAGS",
    "FUNCTION_NAME",
    "REPO_HARNESS",
    "GeneratedCode",
    "HarnessTiming",
    "RecordedInstances",
    "build_harness",
    "compile_shared",
    "evaluate_instances",
    "generate_c",
    "instance_row",
    "read_outputs",
    "run_harness",
    "write_instances",
]

FUNCTION_NAME = "nmpc_rti_step"
"""Name of the generated C function (and of ``NonlinearMPC.rti_step``)."""
_MAGIC = b"NMPCREC1"
CODEGEN_SOLVERS = ("qrqp", "hpipm")
"""QP solvers whose generated code compiles here (module docstring)."""
DEFAULT_CFLAGS = ("-O3",)
"""Compiler flags of :func:`compile_shared` and :func:`build_harness`."""
REPO_HARNESS = Path(__file__).resolve().parents[2] / "bench" / "nmpc_c" / "harness.c"
"""The harness source in a source checkout (not shipped in the wheel)."""

_HPIPM_ARG_COPY = "memcpy(&myarg, &p->hpipm_options, sizeof(struct d_ocp_qp_ipm_arg));"
_HPIPM_ARG_DEFAULT = (
    "d_ocp_qp_ipm_arg_set_default((enum hpipm_mode) p->hpipm_options.mode, &myarg);\n"
    "    d_ocp_qp_ipm_arg_set_iter_max((int*) &p->hpipm_options.iter_max, &myarg);\n"
    "    d_ocp_qp_ipm_arg_set_mu0(&p->hpipm_options.mu0, &myarg);"
)
_HPIPM_EARLY_RETURN = "  if (d.return_status!=0) {\n    return -1;\n  }\n"


def _casadi_directory() -> Path:
    """Where the CasADi wheel keeps its headers (include/) and libraries (libhpipm, libblasfeo)."""
    return Path(ca.__file__).resolve().parent


@dataclass(frozen=True)
class GeneratedCode:
    """C source and header of the RTI step, and what it needs to compile.

    Attributes
    ----------
    source, header : Path
        ``nmpc_rti_step.c`` and ``.h``.
    function : str
        Name of the C function (:data:`FUNCTION_NAME`).
    qp_solver : str
        The QP solver inside (one of :data:`CODEGEN_SOLVERS`).
    horizon : int
        N.
    """

    source: Path
    header: Path
    function: str
    qp_solver: str
    horizon: int

    @property
    def include_dirs(self) -> tuple[Path, ...]:
        """Directories to pass with -I: the generated code's and CasADi's headers."""
        return (self.source.parent, _casadi_directory() / "include")

    @property
    def link_flags(self) -> tuple[str, ...]:
        """Linker flags (HPIPM and BLASFEO from the CasADi wheel for ``hpipm``)."""
        if self.qp_solver == "hpipm":
            lib = _casadi_directory()
            return (f"-L{lib}", "-lhpipm", "-lblasfeo", f"-Wl,-rpath,{lib}", "-lm")
        return ("-lm",)


def generate_c(controller: NonlinearMPC, directory: str | os.PathLike) -> GeneratedCode:
    """Write ``nmpc_rti_step.c`` and ``.h`` for ``controller.rti_step`` into ``directory``.

    Parameters
    ----------
    controller : NonlinearMPC
        With a QP solver of :data:`CODEGEN_SOLVERS`.
    directory : path-like
        Created if missing.

    Returns
    -------
    GeneratedCode
    """
    if not isinstance(controller, NonlinearMPC):
        raise TypeError(f"controller must be a NonlinearMPC, got {type(controller).__name__}")
    if controller.qp_solver not in CODEGEN_SOLVERS:
        raise InputError(f"C export supports the QP solvers {CODEGEN_SOLVERS}, got {controller.qp_solver!r}")
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
    text = source.read_text(encoding="utf-8")
    for needle in (_HPIPM_ARG_COPY, _HPIPM_EARLY_RETURN):
        if text.count(needle) != 1:
            raise RuntimeError(
                f"{source}: the HPIPM code generated by CasADi {ca.__version__} does not have the "
                f"expected form (looked for {needle.strip()[:40]!r}); the patch of "
                "maglev_oc.control.codegen must be revisited"
            )
    text = text.replace(_HPIPM_ARG_COPY, _HPIPM_ARG_DEFAULT).replace(_HPIPM_EARLY_RETURN, "")
    source.write_text(text, encoding="utf-8")


def _compiler() -> str:
    cc = c_compiler()
    if cc is None:
        raise SolverError("no C compiler found (set $CC or install gcc)")
    return cc


def _compile(args: list[str]) -> None:
    proc = subprocess.run(args, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise SolverError(f"C compilation failed ({' '.join(args[:3])} ...):\n{proc.stderr[-4000:]}")


def compile_shared(
    code: GeneratedCode, output: str | os.PathLike | None = None, *, cflags=DEFAULT_CFLAGS
) -> Path:
    """Compile the generated code into a shared library.

    Parameters
    ----------
    code : GeneratedCode
    output : path-like, optional
        The library (default: the source with suffix .so).
    cflags : sequence of str

    Returns
    -------
    Path
        The library, for ``casadi.external(code.function, path)``.

    Raises
    ------
    SolverError
        Without a C compiler, or when compilation fails.
    """
    cc = _compiler()
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
    library: str | os.PathLike | None = None,
) -> Path:
    """Compile ``bench/nmpc_c/harness.c`` with the generated code into an executable.

    Parameters
    ----------
    code : GeneratedCode
    output : path-like, optional
        The executable (default: ``harness`` beside the source).
    harness_source : path-like
        The harness (in a source checkout: :data:`REPO_HARNESS`).
    cflags : sequence of str
    library : path-like, optional
        The shared library :func:`compile_shared` made of the same ``code``: the harness is
        linked against it (found at run time by its path) instead of compiling the generated
        source a second time, which is nearly all of the build (the 1.3 MB source: 8 s of gcc at
        -O1). The step then runs as the library's position-independent code, as it does under
        ``casadi.external``; for timings that compare with a rig's static build, leave it out.

    Returns
    -------
    Path
        The executable, for :func:`run_harness`.

    Raises
    ------
    SolverError
        Without a C compiler, or when compilation fails.
    """
    cc = _compiler()
    harness_source = Path(harness_source)
    if not harness_source.is_file():
        raise FileNotFoundError(f"harness source not found: {harness_source}")
    output = Path(output) if output is not None else code.source.parent / "harness"
    includes = [f"-I{d}" for d in code.include_dirs]
    if library is None:
        step = [str(code.source)]
    else:
        library = Path(library).resolve()
        if not library.is_file():
            raise FileNotFoundError(f"shared library not found: {library}")
        step = [str(library), f"-Wl,-rpath,{library.parent}"]
    _compile([cc, *cflags, str(harness_source), *step, "-o", str(output), *includes, *code.link_flags])
    return output


# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RecordedInstances:
    """Inputs of the RTI Function, one row per call.

    Attributes
    ----------
    inputs : (n, sum(nnz_in)) array
        The concatenated inputs (memory, y, ref column-major) of each call.
    nnz_in, nnz_out : tuple of int
        Entries of each input and output of the Function.
    """

    inputs: np.ndarray
    nnz_in: tuple[int, ...]
    nnz_out: tuple[int, ...]

    @classmethod
    def of(cls, controller: NonlinearMPC, rows) -> RecordedInstances:
        """Rows of :func:`instance_row` as the instances of ``controller.rti_step``."""
        f = controller.rti_step
        nnz_in = tuple(int(f.nnz_in(i)) for i in range(f.n_in()))
        nnz_out = tuple(int(f.nnz_out(i)) for i in range(f.n_out()))
        return cls(np.array(rows), nnz_in, nnz_out)

    def __len__(self) -> int:
        return self.inputs.shape[0]

    def split(self, k: int) -> list[np.ndarray]:
        """The inputs of call k, one array per Function input."""
        return np.split(self.inputs[k], np.cumsum(self.nnz_in)[:-1])


def instance_row(controller: NonlinearMPC, k: int, y, reference: np.ndarray) -> np.ndarray:
    """The inputs of the RTI call ``controller.control(k, y, reference)`` is about to make.

    Parameters
    ----------
    controller : NonlinearMPC
        An RTI controller after ``reset`` (its memory is read).
    k : int
        Sample index.
    y : (2,) array
        Encoder reading [m].
    reference : (6, n) array
        The whole sampled reference.

    Returns
    -------
    array
        (memory, y, node references column-major): one row of :class:`RecordedInstances`.
    """
    ref = controller.node_references(k, reference)
    return np.concatenate([controller.memory, np.asarray(y, dtype=float).ravel(), ref.ravel(order="F")])


def write_instances(path: str | os.PathLike, instances: RecordedInstances) -> Path:
    """Write the instance file read by the harness (format in the module docstring).

    Parameters
    ----------
    path : path-like
    instances : RecordedInstances

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    with open(path, "wb") as fh:
        _write_header(fh, len(instances), instances.nnz_in, instances.nnz_out)
        fh.write(np.ascontiguousarray(instances.inputs, dtype="<f8").tobytes())
    return path


def _write_header(fh, n: int, nnz_in, nnz_out) -> None:
    fh.write(_MAGIC)
    fh.write(struct.pack("<3i", n, len(nnz_in), len(nnz_out)))
    fh.write(struct.pack(f"<{len(nnz_in)}i", *nnz_in))
    fh.write(struct.pack(f"<{len(nnz_out)}i", *nnz_out))


def read_outputs(path: str | os.PathLike) -> list[np.ndarray]:
    """Outputs written by the harness.

    Parameters
    ----------
    path : path-like
        The harness's output file (the instance format, rows of outputs).

    Returns
    -------
    list of (n, nnz) arrays
        One per Function output (u, memory_next, diag).
    """
    path = Path(path)
    data = path.read_bytes()
    if data[:8] != _MAGIC:
        raise InputError(f"{path}: not an NMPCREC1 file")
    n, n_in, n_out = struct.unpack_from("<3i", data, 8)
    off = 20 + 4 * n_in  # the header's nnz_in are the instances', not needed here
    nnz_out = struct.unpack_from(f"<{n_out}i", data, off)
    off += 4 * n_out
    width = sum(nnz_out)
    values = np.frombuffer(data, dtype="<f8", offset=off)
    if values.size != n * width:
        raise InputError(f"{path}: expected {n} rows of {width} values, found {values.size} values")
    return np.split(values.reshape(n, width).copy(), np.cumsum(nnz_out)[:-1], axis=1)


def evaluate_instances(function: ca.Function, instances: RecordedInstances) -> list[np.ndarray]:
    """Outputs of ``function`` on every instance.

    Parameters
    ----------
    function : casadi.Function
        The Python RTI step or a ``casadi.external`` of the generated C.
    instances : RecordedInstances

    Returns
    -------
    list of (n, nnz) arrays
        One per output, the layout of :func:`read_outputs`.
    """
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
class HarnessTiming(Result):
    """Step times of the generated C over the replayed instances.

    Attributes
    ----------
    success : bool
        Every call returned 0.
    status : str
        "replayed" or "failed_calls".
    message : str
    instances : int
        Instances in the file.
    calls : int
        Calls timed (instances times passes).
    failed_calls : int
        Calls that returned an error.
    median, p99, worst : float
        Time per call [s].
    timings : mapping
        ``{"harness": wall time of the whole run [s]}``.
    """

    success: bool
    status: str
    message: str
    instances: int
    calls: int
    failed_calls: int
    median: float
    p99: float
    worst: float
    timings: Mapping[str, float] = field(default_factory=dict)


def run_harness(
    executable: str | os.PathLike,
    instances_path: str | os.PathLike,
    outputs_path: str | os.PathLike | None = None,
    *,
    repeat: int = 3,
    timeout: float = 600.0,
) -> HarnessTiming:
    """Run the harness and parse its report.

    Parameters
    ----------
    executable : path-like
        From :func:`build_harness`.
    instances_path : path-like
        From :func:`write_instances`.
    outputs_path : path-like, optional
        Where the harness writes the outputs (a temporary file if not given).
    repeat : int
        Timed passes over the instances.
    timeout : float
        [s].

    Returns
    -------
    HarnessTiming

    Raises
    ------
    SolverError
        If the harness exits with an error.
    """
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(outputs_path) if outputs_path is not None else Path(tmp) / "outputs.bin"
        args = [str(executable), str(instances_path), str(out), str(int(repeat))]
        proc = subprocess.run(args, capture_output=True, text=True, timeout=timeout, check=False)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SolverError(f"harness failed ({proc.returncode}): {proc.stderr.strip()}")
    report = {}
    for line in proc.stdout.splitlines():
        key, _, value = line.partition(":")
        report[key.strip()] = float(value)
    failed = int(report["failed_calls"])
    calls = int(report["calls_timed"])
    return HarnessTiming(
        success=failed == 0,
        status="replayed" if failed == 0 else "failed_calls",
        message=f"{calls} calls timed, {failed} returned an error",
        instances=int(report["instances"]),
        calls=calls,
        failed_calls=failed,
        median=report["median_us"] * 1e-6,
        p99=report["p99_us"] * 1e-6,
        worst=report["worst_us"] * 1e-6,
        timings={"harness": wall},
    )
