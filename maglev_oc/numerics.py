"""Numerical building blocks written once: the RK4 step, CasADi's JIT, the C compiler.

* :func:`rk4_step` — one classical Runge-Kutta step of any right-hand side, symbolically
  (CasADi expressions) or numerically (numpy arrays): the same four stages for the rig twin,
  the NMPC's transcription, the output-error fit's shooting segments and the diagnosis's
  short-horizon simulations.
* :func:`c_compiler` — the C compiler on this machine (``$CC``, gcc, cc, clang) or None.
* :func:`jit` — a CasADi Function compiled by CasADi's JIT with that compiler, or the Function
  itself when there is none (the caller need not know).
* :class:`NumpyCall` — a CasADi Function called on NumPy arrays through CasADi's buffer
  interface: no DM in between (the DM-to-NumPy copy goes element by element through Python and
  costs 5-10x the evaluation itself on mapped designs).
* :class:`ColumnMap` — a Function of column inputs evaluated on many columns at once, through one
  mapped :class:`NumpyCall` built once (a ``map(n)`` built and called with DMs per batch of
  varying size costs 2-3x as much).
* :func:`one_blas_thread` — runs a function with one BLAS thread, for work made of many small
  matrix products (the regression's block Grams).
* :func:`without_hugepage_advice` — runs a function with NumPy's advice of huge pages off, for
  work that allocates and frees many large arrays (the diagnosis's designs).
"""

from __future__ import annotations

import functools
import os
import shutil
from collections.abc import Callable, Sequence
from typing import Any

import casadi as ca
import numpy as np
from threadpoolctl import threadpool_limits

__all__ = [
    "BLAS_THREAD_VARIABLES",
    "ColumnMap",
    "NumpyCall",
    "c_compiler",
    "jit",
    "one_blas_thread",
    "rk4_step",
    "without_hugepage_advice",
]

BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
"""What sets the BLAS thread count of a process that has not yet loaded NumPy."""


def one_blas_thread(fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn`` run with one BLAS thread, unless the user set a count (:data:`BLAS_THREAD_VARIABLES`).

    For work made of many small products (a diagnosis accumulates ~800 block Grams of 80 columns
    by 1000 rows): OpenBLAS's threads gain nothing on such sizes and, on a machine whose cores
    are busy, spin against each other. Measured on the 2-core machine at load 6-8: 900 such
    Grams 6.3 s of CPU with OpenBLAS's default 2 threads, 0.19 s with one; a whole diagnosis of
    a 60 s log 11.3 s CPU / 34 s wall against 4.6 s / 18 s. The previous limit is restored on
    return (threadpoolctl's scoped limit)."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        if any(os.environ.get(k) for k in BLAS_THREAD_VARIABLES):
            return fn(*args, **kwargs)
        with threadpool_limits(limits=1, user_api="blas"):
            return fn(*args, **kwargs)

    return wrapper


HUGEPAGE_VARIABLE = "NUMPY_MADVISE_HUGEPAGE"
"""NumPy's own switch of its huge-page advice, read when NumPy loads; set, it is left alone."""


def _hugepage_switch() -> Callable[[bool], bool] | None:
    """NumPy's setter of its huge-page advice (it returns the previous setting), or None."""
    core = getattr(np, "_core", None) or getattr(np, "core", None)
    return getattr(getattr(core, "multiarray", None), "_set_madvise_hugepage", None)


def without_hugepage_advice(fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn`` run with NumPy's huge-page advice off (the previous setting restored on return),
    unless the user chose it (:data:`HUGEPAGE_VARIABLE`).

    NumPy advises the kernel to back every large array with 2 MB pages (``madvise``). Where
    transparent huge pages are "madvise" with direct compaction on fault (this 2-core machine's
    kernel), a process that allocates and frees hundreds of arrays of tens of megabytes, as a
    diagnosis does (a design's columns, their held-out and cross-fitted copies), waits on the
    compaction at many first touches and gets no huge page (AnonHugePages stayed 0): a fresh
    copy of 23 MB of held-out columns took 120-170 ms against 3-6 ms into memory already
    touched. Measured on 12 logs (2026-12-01): the same results to every digit, 158.5 -> 138.7 s
    of diagnosis in all. Where huge pages are granted cheaply the advice saves page faults, but
    a diagnosis spends little of its time on them."""
    switch = _hugepage_switch()

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        if switch is None or os.environ.get(HUGEPAGE_VARIABLE):
            return fn(*args, **kwargs)
        before = switch(False)
        try:
            return fn(*args, **kwargs)
        finally:
            switch(before)

    return wrapper


def rk4_step(
    f: Callable[..., Any],
    x: Any,
    h: Any,
    *args: Any,
    args_mid: Sequence[Any] | None = None,
    args_end: Sequence[Any] | None = None,
) -> Any:
    """x + h/6 (k1 + 2 k2 + 2 k3 + k4) with k_i = f(x_i, *args_i).

    ``args`` are held over the step (a zero-order hold); ``args_mid`` and ``args_end``, when given,
    replace them at the half step and at the end (e.g. a current interpolated linearly between
    samples). Works on CasADi SX/MX/DM and on numpy arrays alike.
    """
    a0 = tuple(args)
    am = a0 if args_mid is None else tuple(args_mid)
    a1 = am if args_end is None else tuple(args_end)
    k1 = f(x, *a0)
    k2 = f(x + h / 2 * k1, *am)
    k3 = f(x + h / 2 * k2, *am)
    k4 = f(x + h * k3, *a1)
    return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def c_compiler() -> str | None:
    """Path of a C compiler: ``$CC`` if set and found, else gcc, cc or clang; None if none."""
    for name in (os.environ.get("CC"), "gcc", "cc", "clang"):
        if name:
            path = shutil.which(name)
            if path:
                return path
    return None


def jit(fun: ca.Function, *, flags: Sequence[str] = ("-O3",), symbolic: str = "SX") -> ca.Function:
    """``fun`` compiled by CasADi's JIT (shell compiler, ``flags``), or ``fun`` unchanged when no C
    compiler is available or compilation fails. ``symbolic``: "SX" (flattens an SX Function) or "MX"
    (keeps maps and calls as they are, for large mapped Functions). Compiling takes about half a
    second once; calls get 2-4x faster."""
    compiler = c_compiler()
    if compiler is None:
        return fun
    sym = ca.SX.sym if symbolic == "SX" else ca.MX.sym
    ins = [sym(fun.name_in(k), fun.sparsity_in(k)) for k in range(fun.n_in())]
    opts = {"jit": True, "compiler": "shell", "jit_options": {"flags": list(flags), "verbose": False}}
    try:
        # call() returns a list whatever the number of outputs (fun(*ins) gives a bare
        # expression for one output, which ca.Function refuses)
        return ca.Function(fun.name() + "_jit", ins, fun.call(ins), fun.name_in(), fun.name_out(), opts)
    except RuntimeError:
        return fun


class NumpyCall:
    """``fn`` evaluated on NumPy arrays, returning NumPy arrays, with no DM round trip.

    Inputs are taken at the shapes of ``fn``'s inputs (anything NumPy broadcasts to them, and a
    1-D array for a column);
    outputs come back dense at the shapes of ``fn``'s outputs (sparse outputs are densified once,
    here). One instance holds one evaluation buffer: it is not for concurrent calls from threads.
    """

    def __init__(self, fn: ca.Function):
        if not all(fn.sparsity_out(k).is_dense() for k in range(fn.n_out())):
            ins = fn.mx_in()
            outs = [ca.densify(o) for o in fn.call(ins)]
            fn = ca.Function(fn.name() + "_dense", ins, outs, fn.name_in(), fn.name_out())
        self.fn = fn
        self._in = [fn.size_in(k) for k in range(fn.n_in())]
        self._out = [fn.size_out(k) for k in range(fn.n_out())]
        self._buffer, self._eval = fn.buffer()

    def __call__(self, *args: Any) -> tuple[np.ndarray, ...]:
        if len(args) != len(self._in):
            raise TypeError(f"{self.fn.name()}: {len(self._in)} inputs expected, got {len(args)}")
        # CasADi reads column-major memory: the C-ordered transpose of each array is exactly that
        held = []
        for k, (a, shape) in enumerate(zip(args, self._in, strict=True)):
            a = np.asarray(a, dtype=float)
            if a.ndim == 1 and shape[1] == 1:  # a vector for a column input
                a = a[:, None]
            col = np.ascontiguousarray(np.broadcast_to(a, shape).T)
            held.append(col)
            self._buffer.set_arg(k, memoryview(col))
        outs = [np.empty(shape[::-1]) for shape in self._out]
        for k, o in enumerate(outs):
            self._buffer.set_res(k, memoryview(o))
        self._eval()
        if self._buffer.ret() != 0:
            raise RuntimeError(f"{self.fn.name()}: evaluation failed (CasADi returned {self._buffer.ret()})")
        return tuple(o.T for o in outs)


class ColumnMap:
    """``fn`` (column inputs and outputs) evaluated column by column on arrays of n columns.

    Each input is ``(rows, n)``, or ``(rows, 1)`` held for every column; the outputs come back
    ``(rows, n)``. The columns go through one ``fn.map(chunk)`` called as a :class:`NumpyCall`
    (built once; the last chunk padded with copies of its last column, whose values are dropped),
    so each column's value is exactly ``fn``'s on it, whatever n is. One instance holds one
    evaluation buffer: it is not for concurrent calls from threads.
    """

    def __init__(self, fn: ca.Function, chunk: int = 256):
        if chunk < 1:
            raise ValueError(f"chunk must be a positive number of columns, got {chunk!r}")
        for k in range(fn.n_in()):
            if fn.size2_in(k) != 1:
                raise ValueError(f"{fn.name()}: input {k} is not a column ({fn.size_in(k)})")
        self.fn = fn
        self.chunk = int(chunk)
        self._call = NumpyCall(fn.map(self.chunk))

    def __call__(self, *args: Any) -> tuple[np.ndarray, ...]:
        arrays = [np.asarray(a, dtype=float) for a in args]
        arrays = [a[:, None] if a.ndim == 1 else a for a in arrays]
        n = max(a.shape[1] for a in arrays)
        if any(a.shape[1] not in (1, n) for a in arrays):
            shapes = [a.shape for a in arrays]
            raise ValueError(f"{self.fn.name()}: inputs must have 1 or {n} columns, got {shapes}")
        parts: list[tuple[np.ndarray, ...]] = []
        for k0 in range(0, n, self.chunk):
            m = min(self.chunk, n - k0)
            block = []
            for a in arrays:
                if a.shape[1] == 1:
                    block.append(a)
                    continue
                b = a[:, k0 : k0 + m]
                if m < self.chunk:
                    b = np.concatenate([b, np.repeat(b[:, -1:], self.chunk - m, axis=1)], axis=1)
                block.append(b)
            parts.append(tuple(o[:, :m] for o in self._call(*block)))
        if not parts:
            return tuple(np.empty((self.fn.size1_out(k), 0)) for k in range(self.fn.n_out()))
        return tuple(np.concatenate(outs, axis=1) for outs in zip(*parts, strict=True))
