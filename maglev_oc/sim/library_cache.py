"""Compiled shared libraries kept between runs, under a digest of everything they are built from.

The simulations compile their closed loops to C (:mod:`maglev_oc.sim.native`,
:mod:`maglev_oc.sim.compiled_nmpc`). The same source compiled the same way is the same library, so
a library is kept in a cache directory under a digest of its source, the compiler flags, the
compiler and CasADi's version, and a later run (a report written again, another worker of a test
run) loads it instead of compiling it again: gcc is about a tenth of the test suite's CPU time,
half of it the same loops compiled again.

A library enters the cache whole or not at all (written beside it, then renamed), so processes
building the same library at once each find either nothing or the whole file. The directory is
created private to the user. A cache that cannot be written is no error: the library just is not
kept.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
from pathlib import Path

import casadi as ca

from maglev_oc.numerics import c_compiler

__all__ = ["cache_key", "keep", "user_cache"]


def user_cache() -> Path:
    """``$MAGLEV_OC_CACHE``, else ``$XDG_CACHE_HOME/maglev_oc``, else ``~/.cache/maglev_oc``."""
    if os.environ.get("MAGLEV_OC_CACHE"):
        return Path(os.environ["MAGLEV_OC_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "maglev_oc"


def cache_key(source: str, flags) -> str:
    """The digest a library of ``source`` compiled with ``flags`` is kept under: it also covers the
    compiler and CasADi's version (whose headers and solvers the source includes and links)."""
    parts = [source, *flags, str(c_compiler()), ca.__version__]
    return hashlib.sha1("\0".join(parts).encode()).hexdigest()


def keep(library: Path, kept: Path) -> bool:
    """Copy the compiled ``library`` to ``kept`` in the cache, whole or not at all; False (and
    nothing written) when the cache cannot be written."""
    partial = kept.with_suffix(f".{os.getpid()}.part")
    try:
        kept.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        shutil.copyfile(library, partial)
        os.replace(partial, kept)
    except OSError:
        with contextlib.suppress(OSError):
            partial.unlink(missing_ok=True)
        return False
    return True
