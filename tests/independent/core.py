"""Build and load the C simulation core (``core.c``) with gcc and ctypes.

The layout of the ``Params`` struct is written here once (:data:`FIELDS`) and generated into
the C source before compiling, so the two sides cannot disagree. The shared library is cached
in ``$MAGLEV_INDEPENDENT_CACHE`` (default ``~/.cache/maglev_independent``) under a name keyed
by the SHA-256 of the generated source and the compiler flags: it is compiled once per change.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

_HERE = Path(__file__).resolve().parent
SOURCE = _HERE / "core.c"
CFLAGS = ("-O2", "-std=c99", "-fPIC", "-shared", "-ffp-contract=off", "-fno-fast-math")
"""No fused multiply-add and no fast-math: a seed must give bit-identical logs on re-run."""

NREC = 19
"""Columns of the record array written by ``simulate`` in core.c."""

REC_COLUMNS = (
    "x1", "x2", "x3", "x4", "y1", "y3", "u1", "u2", "iq", "id", "gap",
    "F_fric_h", "F_fric_v", "v1", "v2", "xhat2", "xhat4", "iq_amp", "id_amp",
)  # fmt: skip
"""Names of the record columns (see ``simulate`` in core.c)."""

GENERIC_LIBM = "glibc.cpu.hwcaps=-AVX2,-FMA,-FMA4"
"""``GLIBC_TUNABLES`` under which glibc gives a process its generic ``exp``, ``sin``, ``cos``, ...: on
x86-64 CPUs with FMA and AVX2 it otherwise picks variants that differ in the last bit now and then,
which a loop that sticks and slips amplifies into another log (experiments_37 of the independent
sets). glibc reads it when a process starts; ``tests/conftest.py`` sets it for the test workers."""


def _started_with_tunables() -> bool:
    """Whether this process started with ``GLIBC_TUNABLES`` set (glibc reads it then, and only
    then): the environment it started with, not ``os.environ``, which the process may have set since
    (``tests/conftest.py`` does, for the workers it starts)."""
    try:
        start = Path("/proc/self/environ").read_bytes().split(b"\0")
    except OSError:
        return "GLIBC_TUNABLES" in os.environ
    return any(v.startswith(b"GLIBC_TUNABLES=") for v in start)


def with_generic_libm() -> None:
    """Start this command again under :data:`GENERIC_LIBM` unless it already runs under it (or the
    user set ``GLIBC_TUNABLES`` to something else, which is kept): the logs a command generates are
    then the test suite's. For command-line entry points, before any log is generated."""
    if not sys.platform.startswith("linux") or _started_with_tunables():
        return
    env = {**os.environ, "GLIBC_TUNABLES": os.environ.get("GLIBC_TUNABLES", GENERIC_LIBM)}
    sys.stdout.flush()
    os.execve(sys.executable, [sys.executable, *sys.orig_argv[1:]], env)


_D = ctypes.c_double
_I = ctypes.c_int

FIELDS: list[tuple[str, object]] = [
    # true plant constants and geometry
    ("C1", _D), ("C2", _D), ("C3", _D), ("C4", _D), ("Mh", _D), ("Mv", _D), ("G", _D),
    ("b0", _D), ("t1", _D), ("hm", _D), ("tau", _D), ("mu_rec", _D), ("Bpre", _D),
    # controller
    ("Cn1", _D), ("Cn2", _D), ("Cn3", _D), ("Cn4", _D), ("Kh", _D * 5), ("Kv", _D * 5),
    ("Ao", _D * 4), ("Bo", _D * 4), ("Ai", _D * 9), ("Bi", _D * 3), ("i_max", _D), ("Tc", _D),
    # rig
    ("n_sub", _I), ("record_every", _I), ("q", _D), ("gap_min", _D), ("gap_max", _D), ("x3_max", _D),
    # the stopper the platform rests on when the magnets do not hold it (the largest gap) [m], 0: none
    ("stop_gap", _D),
    # the stop at the smallest gap [m] (0: none), the horizontal travel's end stops [m] (when on)
    ("top_gap", _D), ("x3_stop_on", _I), ("x3_stop_lo", _D), ("x3_stop_hi", _D),
    # effects: guide friction (LuGre), horizontal and vertical
    ("fh_on", _I), ("fh_Fc", _D), ("fh_Fs", _D), ("fh_vs", _D), ("fh_s0", _D), ("fh_s1", _D), ("fh_s2", _D),
    ("fv_on", _I), ("fv_Fc", _D), ("fv_Fs", _D), ("fv_vs", _D), ("fv_s0", _D), ("fv_s1", _D), ("fv_s2", _D),
    # the friction's level along the track (horizontal) and its difference between the directions
    ("fh_slope", _D), ("fh_asym", _D), ("fv_asym", _D),
    # the friction's level changing first-order over the run as the guides warm: share, time constant
    ("fh_warm", _D), ("fh_warm_tau", _D), ("fv_warm", _D), ("fv_warm_tau", _D),
    # normal cogging, longitudinal cogging (detent)
    ("cn_on", _I), ("cn_amp", _D * 3), ("cn_period", _D * 3), ("cn_phase", _D * 3), ("cn_decay", _D * 3),
    ("cn_gref", _D),
    ("cl_on", _I), ("cl_amp", _D * 3), ("cl_period", _D * 3), ("cl_phase", _D * 3), ("cl_decay", _D * 3),
    ("cl_gref", _D),
    # end effects
    ("ee_on", _I), ("ee_fT", _D), ("ee_fA", _D), ("ee_xp", _D), ("ee_xm", _D), ("ee_w", _D),
    ("ee_profile", _I),
    # guide misalignment
    ("mis_on", _I), ("mis_slope", _D), ("mis_amp", _D), ("mis_len", _D), ("mis_phase", _D),
    # cable carrier, tilted base
    ("cab_on", _I), ("cab_k", _D), ("cab_x0", _D), ("cab_F0", _D), ("tilt_F", _D),
    # a payload on the platform [kg]; a vertical force along +x1: constant [N], spring [N/m] about x1 [m]
    ("load", _D), ("vf_on", _I), ("vf_F", _D), ("vf_k", _D), ("vf_x0", _D),
    # thrust ripple
    ("tr_on", _I), ("tr_amp", _D * 2), ("tr_period", _D * 2), ("tr_phase", _D * 2),
    # commutation error, amplifier
    ("com_cos", _D), ("com_sin", _D), ("amp_tau", _D), ("amp_delay_sub", _I), ("amp_peak", _D),
    # a first-order filter on the amplifiers' current sensors (time constant [s]; 0: none)
    ("sensor_tau", _D),
    # field shape
    ("fs_on", _I), ("fs_k1", _D), ("fs_k2", _D), ("fs_gref", _D), ("fs_thrust", _I),
    # saturation of the iron by the stator current
    ("sat_on", _I), ("sat_current", _D),
    # phase current sensors' offsets, gap sensor's zero
    ("cso_on", _I), ("cso_offset", _D * 3), ("gap_zero", _D), ("csg_on", _I), ("csg_error", _D * 3),
    # the gap sensor's zero drifting as the frame warms: the drift [m] and its time constant [s]
    ("gz_drift", _D), ("gz_drift_tau", _D),
    # the base vibrating (its acceleration is an array of simulate's)
    ("vib_on", _I),
    # the magnets warming over the run: temperature coefficient of the field [1/K], final rise [K],
    # thermal time constant [s], the time the warming had run when the log began [s]
    ("heat_on", _I), ("heat_coef", _D), ("heat_rise", _D), ("heat_tau", _D), ("heat_t0", _D),
    # the papers' two PID regulators instead of the FL regulator: gains (kp, kd, ki) per axis,
    # the inputs' gains b and the equilibrium current they were designed at
    ("pid_on", _I), ("pid_v", _D * 3), ("pid_h", _D * 3), ("pid_bv", _D), ("pid_bh", _D), ("pid_ieq", _D),
]  # fmt: skip
"""The ``Params`` struct: (name, ctypes type) in declaration order."""


class Params(ctypes.Structure):
    """ctypes mirror of the C ``Params`` struct (all zeros when created)."""

    _fields_ = FIELDS  # type: ignore[assignment]


def _c_declaration(name: str, ctype: object) -> str:
    if isinstance(ctype, type) and issubclass(ctype, ctypes.Array):
        base = "double" if ctype._type_ is _D else "int"
        return f"    {base} {name}[{ctype._length_}];"
    return f"    {'double' if ctype is _D else 'int'} {name};"


def generated_source() -> str:
    """The C source with the ``Params`` body filled in from :data:`FIELDS`."""
    body = "\n".join(_c_declaration(n, t) for n, t in FIELDS)
    return SOURCE.read_text().replace("/*@FIELDS@*/", body)


def cache_dir() -> Path:
    """Where compiled cores are kept (``$MAGLEV_INDEPENDENT_CACHE`` or ``~/.cache/maglev_independent``)."""
    env = os.environ.get("MAGLEV_INDEPENDENT_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "maglev_independent"


_LIB: ctypes.CDLL | None = None


def _compile(src: str, target: Path) -> None:
    gcc = shutil.which(os.environ.get("CC", "gcc")) or shutil.which("gcc")
    if gcc is None:
        raise RuntimeError(
            "tests/independent needs a C compiler: 'gcc' was not found on PATH (set CC to another "
            "compiler, e.g. CC=clang). The project already requires one for its CasADi code generation."
        )
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
        c_path = Path(tmp) / "core.c"
        c_path.write_text(src)
        so_tmp = Path(tmp) / target.name
        proc = subprocess.run(
            [gcc, *CFLAGS, "-o", str(so_tmp), str(c_path), "-lm"], capture_output=True, text=True
        )
        if proc.returncode != 0:
            raise RuntimeError(f"compiling {SOURCE} with {gcc} failed:\n{proc.stderr}")
        os.replace(so_tmp, target)  # atomic: concurrent builders never see a half-written library


def load() -> ctypes.CDLL:
    """Compile (once per source change) and load the core; returns the ctypes library."""
    global _LIB
    if _LIB is not None:
        return _LIB
    src = generated_source()
    key = hashlib.sha256((src + " ".join(CFLAGS)).encode()).hexdigest()[:16]
    target = cache_dir() / f"core_{key}.so"
    if not target.exists():
        _compile(src, target)
    lib = ctypes.CDLL(str(target))
    lib.params_size.restype = _I
    if lib.params_size() != ctypes.sizeof(Params):
        raise RuntimeError(
            f"{target}: Params layout mismatch ({lib.params_size()} vs {ctypes.sizeof(Params)})"
        )
    dp = np.ctypeslib.ndpointer(dtype=np.float64, flags="C_CONTIGUOUS")
    ip = np.ctypeslib.ndpointer(dtype=np.int32, flags="C_CONTIGUOUS")
    pp = ctypes.POINTER(Params)
    lib.simulate.argtypes = [pp, _I, dp, dp, dp, dp, ip, dp, dp]
    lib.simulate.restype = _I
    lib.eval_rhs.argtypes = [pp, dp, _D, _D, _D, dp, dp]
    lib.eval_rhs.restype = None
    lib.eval_control.argtypes = [pp, _D, _D, _D, dp]
    lib.eval_control.restype = _I
    _LIB = lib
    return lib


def eval_rhs(
    params: Params, state: np.ndarray, iq: float, id_: float, t: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Plant right-hand side at ``state`` (6,) for amplifier currents (i_q, i_d) [A] at time ``t`` [s]
    into the run (what warms over it: ``MagnetWarming``, ``GuideFriction.warming_change``).

    Returns the derivative (6,) and the auxiliary values (true gap [m], actual i_q, i_d [A],
    horizontal and vertical friction forces [N], magnetic normal force [N]).
    """
    lib = load()
    ds = np.zeros(6)
    aux = np.zeros(6)
    lib.eval_rhs(ctypes.byref(params), np.ascontiguousarray(state, dtype=float), iq, id_, t, ds, aux)
    return ds, aux


def eval_control(params: Params, y1: float, v1: float, v2: float) -> tuple[float, float, bool]:
    """The controller's feedback transformation: (u1, u2) [A] for gap reading ``y1`` [m] and (v1, v2)."""
    lib = load()
    u = np.zeros(2)
    clipped = lib.eval_control(ctypes.byref(params), y1, v1, v2, u)
    return float(u[0]), float(u[1]), bool(clipped)
