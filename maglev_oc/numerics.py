"""Numerical building blocks written once: the RK4 step, CasADi's JIT, the C compiler.

* :func:`rk4_step` — one classical Runge-Kutta step of any right-hand side, symbolically
  (CasADi expressions) or numerically (numpy arrays): the same four stages for the rig twin,
  the NMPC's transcription, the output-error fit's shooting segments and the diagnosis's
  short-horizon simulations.
* :func:`c_compiler` — the C compiler on this machine (``$CC``, gcc, cc, clang) or None.
* :func:`jit` — a CasADi Function compiled by CasADi's JIT with that compiler, or the Function
  itself when there is none (the caller need not know).
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable, Sequence
from typing import Any

import casadi as ca

__all__ = ["c_compiler", "jit", "rk4_step"]


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
