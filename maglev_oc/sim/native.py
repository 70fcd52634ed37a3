"""The fused closed-loop step compiled to C with its own loop (CasADi code generation + gcc).

CasADi's ``mapaccum`` costs about half a microsecond per iteration of bookkeeping even around
a trivial function, which caps a simulation at ~2e6 steps/s before any work is done. Here the
step Function is generated as C, a ten-line driver loops over the samples in C, and the shared
library is called once per run through ctypes with numpy buffers. Build once (about a second of
gcc, or a library of the same source found in the cache: :mod:`maglev_oc.sim.library_cache`), then
every run costs only the arithmetic.

:class:`NativeLoop` records every sample of one run; :class:`NativeBatch` runs many initial
states through the same step and keeps only each one's final state (Monte Carlo), on threads
(ctypes releases the GIL during the call).
"""

from __future__ import annotations

import ctypes
import math
import os
import subprocess
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import casadi as ca
import numpy as np

from maglev_oc.errors import InputError, SolverError
from maglev_oc.numerics import c_compiler
from maglev_oc.sim.library_cache import cache_key, keep, user_cache

__all__ = ["NativeBatch", "NativeLoop"]

_DRIVER = r"""
#include <stdlib.h>
#include <string.h>

int {name}_run(const double* z0, const double* r, const double* w, double* out, double* zf, long n) {{
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  {name}_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  const double** arg = (const double**) malloc(sizeof(double*) * (sz_arg > 3 ? sz_arg : 3));
  double** res = (double**) malloc(sizeof(double*) * (sz_res > 2 ? sz_res : 2));
  casadi_int* iw = (casadi_int*) malloc(sizeof(casadi_int) * (sz_iw > 0 ? sz_iw : 1));
  double* work = (double*) malloc(sizeof(double) * (sz_w > 0 ? sz_w : 1));
  double* za = (double*) malloc(sizeof(double) * {nz});
  double* zb = (double*) malloc(sizeof(double) * {nz});
  memcpy(za, z0, sizeof(double) * {nz});
  int flag = 0;
  for (long k = 0; k < n; ++k) {{
    arg[0] = za; arg[1] = r + {nr} * k; arg[2] = w + {nw} * k;
    res[0] = zb; res[1] = out + {nout} * k;
    if ({name}(arg, res, iw, work, 0)) {{ flag = 1; break; }}
    double* t = za; za = zb; zb = t;
  }}
  memcpy(zf, za, sizeof(double) * {nz});
  free(arg); free(res); free(iw); free(work); free(za); free(zb);
  return flag;
}}
"""


class NativeLoop:
    """``step`` (z, r, w) -> (z_next, out), all dense column vectors, run in a C loop.

    Call with z0 (nz,), r (nr, n), w (nw, n); returns out (nout, n) and the final z.

    Parameters
    ----------
    step : casadi.Function
        (z, r, w) -> (z_next, out), dense columns (the fused closed-loop step of the engine).
    flags : tuple of str
        Compiler flags (default ``-O3``).
    cache : path-like or bool
        Where the compiled library is kept and looked for (:mod:`maglev_oc.sim.library_cache`):
        True (default) the user's cache (:func:`~maglev_oc.sim.library_cache.user_cache`), a
        directory, or False to compile every time.

    Attributes
    ----------
    cached : bool
        The library came from the cache (it was not compiled).

    Raises
    ------
    SolverError
        No C compiler, or compiling the generated code failed.
    """

    def __init__(
        self, step: ca.Function, *, flags: tuple[str, ...] = ("-O3",), cache: str | os.PathLike | bool = True
    ) -> None:
        if step.n_in() != 3 or step.n_out() != 2:
            raise InputError("step must map (z, r, w) -> (z_next, out)")
        for k in range(3):
            if not step.sparsity_in(k).is_dense() or step.size2_in(k) != 1:
                raise InputError(f"input {k} of step must be a dense column")
        self.nz, self.nr, self.nw = (step.size1_in(k) for k in range(3))
        self.nout = step.size1_out(1)
        name = "cl_step"
        driver = _DRIVER.format(name=name, nz=self.nz, nr=self.nr, nw=self.nw, nout=self.nout)
        self._dir, self._lib, self.cached = _compile(step, name, driver, flags, _cache_dir(cache))
        run = getattr(self._lib, f"{name}_run")
        dbl = np.ctypeslib.ndpointer(dtype=np.float64, flags="C_CONTIGUOUS")
        run.argtypes = [dbl, dbl, dbl, dbl, dbl, ctypes.c_long]
        run.restype = ctypes.c_int
        self._run = run

    def __call__(self, z0: np.ndarray, r: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n = r.shape[1]
        z0 = np.ascontiguousarray(z0, dtype=float).ravel()
        # column-major per sample: transpose to (n, rows) so each sample's vector is contiguous
        rt = np.ascontiguousarray(np.asarray(r, dtype=float).T)
        wt = np.ascontiguousarray(np.asarray(w, dtype=float).T)
        out = np.empty((n, self.nout))
        zf = np.empty(self.nz)
        if self._run(z0, rt, wt, out, zf, n) != 0:
            raise RuntimeError("the generated closed-loop step reported an error")
        return out.T, zf


def _cache_dir(cache: str | os.PathLike | bool) -> Path | None:
    if cache is True:
        return user_cache()
    if cache is False or cache is None:
        return None
    return Path(cache)


def _compile(step: ca.Function, name: str, driver: str, flags: tuple[str, ...], cache: Path | None):
    """(temporary directory, loaded library, whether it came from the cache) of ``step``
    generated as C under ``name`` with ``driver`` appended, compiled by the system C compiler, or
    loaded from ``cache`` where the same source was compiled with the same flags before
    (:mod:`maglev_oc.sim.library_cache`)."""
    cc = c_compiler()
    if cc is None:
        raise SolverError("no C compiler ($CC, gcc, cc, clang) on PATH: use the CasADi virtual machine")
    tmp = tempfile.TemporaryDirectory(prefix="maglev_oc_native_")
    ins = [step.sx_in(k) for k in range(step.n_in())]
    fn = ca.Function(name, ins, step.call(ins), {"cse": True})
    src = Path(tmp.name) / f"{name}.c"
    cg = ca.CodeGenerator(f"{name}.c", {"with_header": False})
    cg.add(fn)
    cg.generate(str(Path(tmp.name)) + "/")
    text = src.read_text(encoding="utf-8") + driver
    kept = Path(cache) / "native" / f"{name}_{cache_key(text, flags)[:24]}.so" if cache is not None else None
    if kept is not None and kept.is_file():
        try:
            return tmp, ctypes.CDLL(str(kept)), True
        except OSError:  # not a library this machine loads: compiled again below, and replaced
            pass
    src.write_text(text, encoding="utf-8")
    lib = Path(tmp.name) / f"{name}.so"
    done = subprocess.run(
        [cc, *flags, "-shared", "-fPIC", str(src), "-o", str(lib), "-lm"],
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        raise SolverError(f"compiling the closed loop failed: {done.stderr[-2000:]}")
    if kept is not None:
        keep(lib, kept)
    return tmp, ctypes.CDLL(str(lib)), False


_BATCH_DRIVER = r"""
#include <stdlib.h>
#include <string.h>

int {name}_batch(const double* z0, const double* r, const double* w, double* zf, long n_steps,
                 long first, long last) {{
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  {name}_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  const double** arg = (const double**) malloc(sizeof(double*) * (sz_arg > 3 ? sz_arg : 3));
  double** res = (double**) malloc(sizeof(double*) * (sz_res > 1 ? sz_res : 1));
  casadi_int* iw = (casadi_int*) malloc(sizeof(casadi_int) * (sz_iw > 0 ? sz_iw : 1));
  double* work = (double*) malloc(sizeof(double) * (sz_w > 0 ? sz_w : 1));
  double* za = (double*) malloc(sizeof(double) * {nz});
  double* zb = (double*) malloc(sizeof(double) * {nz});
  int flag = 0;
  for (long j = first; j < last && !flag; ++j) {{
    memcpy(za, z0 + {nz} * j, sizeof(double) * {nz});
    for (long k = 0; k < n_steps; ++k) {{
      arg[0] = za; arg[1] = r + {nr} * k; arg[2] = w + {nw} * k;
      res[0] = zb;
      if ({name}(arg, res, iw, work, 0)) {{ flag = 1; break; }}
      double* t = za; za = zb; zb = t;
    }}
    memcpy(zf + {nz} * j, za, sizeof(double) * {nz});
  }}
  free(arg); free(res); free(iw); free(work); free(za); free(zb);
  return flag;
}}
"""


class NativeBatch:
    """``step`` (z, r, w) -> z_next run from many initial states over one shared input sequence,
    in a C loop; only each run's final state is kept.

    Call with z0 (nz, n), r (nr, n_steps), w (nw, n_steps); returns the final states (nz, n).
    The runs are split over ``threads`` threads. The number of steps is the call's, so one
    build serves every horizon.

    Parameters
    ----------
    step : casadi.Function
        (z, r, w) -> z_next, dense columns.
    flags, cache
        As :class:`NativeLoop`'s (and ``cached`` likewise says whether the library came from the
        cache).

    Raises
    ------
    SolverError
        No C compiler, or compiling the generated code failed.
    """

    def __init__(
        self, step: ca.Function, *, flags: tuple[str, ...] = ("-O3",), cache: str | os.PathLike | bool = True
    ) -> None:
        if step.n_in() != 3 or step.n_out() != 1:
            raise InputError("step must map (z, r, w) -> z_next")
        for k in range(3):
            if not step.sparsity_in(k).is_dense() or step.size2_in(k) != 1:
                raise InputError(f"input {k} of step must be a dense column")
        if step.size1_out(0) != step.size1_in(0):
            raise InputError("step must return a state of the size it takes")
        self.nz, self.nr, self.nw = (step.size1_in(k) for k in range(3))
        name = "batch_step"
        driver = _BATCH_DRIVER.format(name=name, nz=self.nz, nr=self.nr, nw=self.nw)
        self._dir, self._lib, self.cached = _compile(step, name, driver, flags, _cache_dir(cache))
        run = getattr(self._lib, f"{name}_batch")
        dbl = np.ctypeslib.ndpointer(dtype=np.float64, flags="C_CONTIGUOUS")
        run.argtypes = [dbl, dbl, dbl, dbl, ctypes.c_long, ctypes.c_long, ctypes.c_long]
        run.restype = ctypes.c_int
        self._run = run

    def __call__(self, z0: np.ndarray, r: np.ndarray, w: np.ndarray, *, threads: int = 1) -> np.ndarray:
        z0 = np.asarray(z0, dtype=float)
        r, w = np.asarray(r, dtype=float), np.asarray(w, dtype=float)
        if z0.ndim != 2 or z0.shape[0] != self.nz:
            raise InputError(f"z0 must have shape ({self.nz}, n), got {z0.shape}")
        n_steps = r.shape[1]
        if r.shape != (self.nr, n_steps) or w.shape != (self.nw, n_steps):
            raise InputError(f"r and w must be ({self.nr}, n) and ({self.nw}, n), got {r.shape}, {w.shape}")
        n = z0.shape[1]
        zt = np.ascontiguousarray(z0.T)  # each run's state contiguous
        rt, wt = np.ascontiguousarray(r.T), np.ascontiguousarray(w.T)
        zf = np.empty_like(zt)
        size = max(1, math.ceil(n / max(1, threads)))
        parts = [(j, min(j + size, n)) for j in range(0, n, size)]

        def part(bounds: tuple[int, int]) -> int:
            return self._run(zt, rt, wt, zf, n_steps, *bounds)

        if len(parts) <= 1:
            flags = [part(p) for p in parts]
        else:
            with ThreadPoolExecutor(len(parts)) as pool:
                flags = list(pool.map(part, parts))
        if any(flags):
            raise RuntimeError("the generated closed-loop step reported an error")
        return zf.T
