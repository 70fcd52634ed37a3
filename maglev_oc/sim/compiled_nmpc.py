"""The causal NMPC as an expression controller, its real-time iteration running as generated C.

A :class:`~maglev_oc.control.nmpc.NonlinearMPC` is an online controller: the engine steps it from
Python, about 0.2-0.5 ms a sample, most of it Python and conversions. Without reference preview
(``preview=False``, the comparison's causal NMPC) its whole update depends only on its memory,
the reading and the current reference sample, which the shooting nodes extrapolate with constant
acceleration (:func:`maglev_oc.control.nmpc.grid.node_references`). That extrapolation is written
here as CasADi expressions, so the update is one Function ``step(c, y, r)``: an
:class:`~maglev_oc.control.base.ExpressionController`, which the engine fuses with the twin and
runs in its C loop (:mod:`maglev_oc.sim.native`). Same controller, same arithmetic: the runs equal
the Python-stepped ones to round-off.

The RTI step is generated and compiled once by :mod:`maglev_oc.control.codegen` (its HPIPM
patches included) into a shared library that the closed loop's generated C calls by name. The
library's symbols carry a digest of the generated source, so that two different NMPCs can be
loaded in one process without one binding to the other's code. Without a C compiler (or with a
QP solver whose C is not generated) the step calls the RTI Function itself, in CasADi's virtual
machine.

Given a ``cache`` directory, the compiled library is kept there under a digest of everything it is
built from (the generated source, the flags, the compiler, CasADi's version, whose HPIPM it links)
and reused by later runs: the same source compiled the same way is the same library. The
directory is created private to the user; :func:`user_cache` is the usual place.
"""

from __future__ import annotations

import ctypes
import dataclasses
import hashlib
import os
import tempfile
import time
from pathlib import Path

import casadi as ca
import numpy as np

from maglev_oc.control.base import N_MEASUREMENTS, N_REFERENCE
from maglev_oc.control.codegen import CODEGEN_SOLVERS, FUNCTION_NAME, compile_shared, generate_c
from maglev_oc.control.nmpc import NonlinearMPC
from maglev_oc.errors import InputError
from maglev_oc.numerics import c_compiler
from maglev_oc.sim.library_cache import cache_key, keep, user_cache

__all__ = ["COMPILE_FLAGS", "CompiledNMPC", "user_cache"]  # user_cache: maglev_oc.sim.library_cache's

COMPILE_FLAGS = ("-O1",)
"""gcc flags of the RTI step's library. The generated source is about 1.3 MB: -O1 compiles in
about a third of -O2's time and runs within 25 % of it, which over the comparison's 6e5 samples
is the faster total (measured on the 2-core test machine: 11 s + 5.0 s against 27 s + 4.1 s for
one 25 s run)."""


class CompiledNMPC:
    """A causal RTI :class:`NonlinearMPC` as an expression controller (module docstring).

    Parameters
    ----------
    controller : NonlinearMPC
        In mode "rti", without reference preview.
    cflags : sequence of str
        Compiler flags of the RTI step's library.
    backend : {"c", "vm"}, optional
        "c" (default where a C compiler is found and the QP solver's C is generated) or "vm".
    cache : path-like, optional
        Directory of compiled libraries to reuse and add to (module docstring); none by default.

    Attributes
    ----------
    name, sample_time, diag_names
        The controller's.
    n_state : int
        Entries of the NMPC's memory.
    step : casadi.Function
        (memory, y (2), r (6)) -> (u (2) [A], memory_next, diag (7)).
    backend : str
        "c" (the generated library) or "vm" (the RTI Function in CasADi's virtual machine).
    build_time : float
        [s] generating and compiling the library (0 in the virtual machine).
    cached : bool
        The library came from the cache (it was not compiled).
    """

    def __init__(
        self,
        controller: NonlinearMPC,
        *,
        cflags: tuple[str, ...] = COMPILE_FLAGS,
        backend: str | None = None,
        cache: str | os.PathLike | None = None,
    ) -> None:
        if not isinstance(controller, NonlinearMPC):
            raise TypeError(f"controller must be a NonlinearMPC, got {type(controller).__name__}")
        if controller.mode != "rti" or controller.preview:
            raise InputError(
                "only a causal RTI NMPC (mode 'rti', preview=False) is an expression controller; got "
                f"mode {controller.mode!r}, preview={controller.preview}"
            )
        self.controller = controller
        self.name = controller.name
        self.sample_time = controller.sample_time
        self.diag_names = controller.diag_names
        self.n_state = controller.n_memory
        can_compile = c_compiler() is not None and controller.qp_solver in CODEGEN_SOLVERS
        if backend is None:
            backend = "c" if can_compile else "vm"
        if backend not in ("c", "vm") or (backend == "c" and not can_compile):
            raise InputError(
                f"backend must be 'vm' or, with a C compiler and a QP solver of {CODEGEN_SOLVERS}, 'c'; "
                f"got {backend!r}"
            )
        self.backend = backend
        self.cached = False
        t0 = time.perf_counter()
        rti = self._compiled(controller, cflags, cache) if backend == "c" else controller.rti_step
        self.build_time = time.perf_counter() - t0 if backend == "c" else 0.0
        c = ca.MX.sym("memory", self.n_state)
        y = ca.MX.sym("y", N_MEASUREMENTS)
        r = ca.MX.sym("r", N_REFERENCE)
        u, c_next, diag = rti(c, y, _node_references(r, controller))
        self.step = ca.Function(
            "nmpc_step", [c, y, r], [u, c_next, diag], ["c", "y", "r"], ["u", "c_next", "diag"]
        )

    def _compiled(self, controller: NonlinearMPC, cflags, cache) -> ca.Function:
        """The RTI step as a ``casadi.external`` of its generated library, loaded globally so that
        the closed loop's generated C finds it by name."""
        self._directory = tempfile.TemporaryDirectory(prefix="maglev_oc_nmpc_")
        code = generate_c(controller, self._directory.name)
        text = code.source.read_text(encoding="utf-8")
        name = f"{FUNCTION_NAME}_{hashlib.sha1(text.encode()).hexdigest()[:12]}"
        # every symbol of the library starts with the function's name (its _work, _incref, ...)
        code.source.write_text(text.replace(FUNCTION_NAME, name), encoding="utf-8")
        code = dataclasses.replace(code, function=name)
        kept = Path(cache) / f"nmpc_rti_{cache_key(text, cflags)[:24]}.so" if cache is not None else None
        if kept is not None and kept.is_file():
            library, self.cached = kept, True
        else:
            library = compile_shared(code, cflags=tuple(cflags))
            if kept is not None:
                keep(library, kept)  # whole or not at all, also with reports running at once
        self._library = library
        ctypes.CDLL(str(library), mode=ctypes.RTLD_GLOBAL)
        return ca.external(name, str(library))

    def initial_state(self, y0, r0, u0=None) -> np.ndarray:
        """The NMPC's memory at start (:meth:`NonlinearMPC.initial_memory`)."""
        return self.controller.initial_memory(y0, r0, u0)

    @property
    def library(self) -> Path | None:
        """Where the compiled RTI step is (None in the virtual machine)."""
        return self._library if self.backend == "c" else None


def _node_references(r: ca.MX, controller: NonlinearMPC) -> ca.MX:
    """The reference sample r (6) at the shooting nodes, (6, N + 1): constant acceleration from
    now on, as :func:`~maglev_oc.control.nmpc.grid.node_references` without preview."""
    dt = ca.DM(controller.grid.node_offsets * controller.sample_time).T
    ones = ca.DM.ones(1, dt.numel())
    rows = []
    for row in (0, 3):
        p, v, a = r[row], r[row + 1], r[row + 2]
        rows += [p + v * dt + 0.5 * a * dt**2, v + a * dt, a * ones]
    return ca.vertcat(*rows)
