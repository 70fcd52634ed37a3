"""C objects compiled once per test session, shared by the pytest-xdist workers.

The export and NMPC tests compile the same generated C several times (the NMPC's 1.3 MB source
takes 8-14 s of gcc CPU at -O1 each time). :class:`ObjectCache` keeps each object under a digest
of what the compiler sees and how it is asked to compile it: the compiler, its flags (the ``-I``
directories aside, since what they provide is in the preprocessed text) and the preprocessed
source (``-E -P``: every header the file includes, expanded). The same input compiled the same way
is the same object, so a test that reuses one checks what a fresh compilation would give, warnings
as errors included (a compilation that failed is not kept). Two workers asking for the same object
at once take turns on a lock file: one compiles, the other finds the object. A new object appears
whole (written beside, then renamed).

The directory lives under the session's base temporary directory (:func:`session_shared_dir`):
the workers of one run share it, nothing is left in the user's home, and the next run starts
empty, as a fresh clone does. Tests about compilation itself (``tests/test_compiled_nmpc.py``)
keep their own directories.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import subprocess
from collections.abc import Sequence
from pathlib import Path

import pytest

__all__ = [
    "GENERATED_CFLAGS",
    "ObjectCache",
    "cflags_for",
    "object_cache",
    "session_shared_dir",
    "shared_compile_cache",
]

GENERATED_CFLAGS = ("-O0",)
"""gcc's optimization for CasADi's generated sources in the tests (the NMPC's is 1.3-1.4 MB): -O0
compiles it in 4.7 s of CPU against 12.3 s at -O1 (measured 2026-11-24 on the qrqp export), and
the values are the same: IEEE arithmetic, the same operations in the same order at every -O
level (no -ffast-math, and -std=c99 contracts no multiply-add). The tests run a few hundred
steps of it, where the slower code costs well under a second. The hand-written interfaces and
drivers, where the warnings of the optimizer's flow analysis (-Wmaybe-uninitialized) matter,
stay at -O1; users compile with what the export's README says (-O2)."""


def cflags_for(source: str | os.PathLike, flags: Sequence[str] = ("-O1",)) -> tuple[str, ...]:
    """The optimization flags the tests compile ``source`` with: :data:`GENERATED_CFLAGS` for a
    CasADi-generated file (``*_generated.c``), ``flags`` for the others."""
    return GENERATED_CFLAGS if Path(source).name.endswith("_generated.c") else tuple(flags)


def session_shared_dir(tmp_path_factory, name: str) -> Path:
    """``name`` under the run's base temporary directory: with pytest-xdist, the directory above
    the workers' own (``pytest-N/popen-gwK``), so one per run shared by its workers; without it,
    in the session's own."""
    base = tmp_path_factory.getbasetemp()
    root = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base
    path = root / name
    path.mkdir(mode=0o700, exist_ok=True)
    return path


class ObjectCache:
    """Compiles C sources to objects once per key (module docstring).

    Parameters
    ----------
    directory : Path
        Where the objects are kept.
    """

    def __init__(self, directory: Path):
        self.directory = Path(directory)
        self.compiled = 0
        """Sources this instance compiled (the others came from the directory)."""

    def compile(self, command: Sequence[str], source: Path, output: Path) -> bool:
        """``command + ["-c", source, "-o", output]``, or a copy of the object it gave before.

        ``command`` is the compiler and its flags. Raises ``CalledProcessError`` as
        ``subprocess.run(..., check=True)`` does when the compiler fails. Returns whether the
        object came from the cache.
        """
        command = [str(c) for c in command]
        pre = subprocess.run([*command, "-E", "-P", str(source)], check=True, capture_output=True)
        flags = [c for c in command[1:] if not c.startswith("-I")]
        digest = hashlib.sha256()
        for part in (shutil.which(command[0]) or command[0], *flags):
            digest.update(part.encode() + b"\0")
        digest.update(pre.stdout)
        kept = self.directory / f"{Path(source).stem}_{digest.hexdigest()[:24]}.o"
        with open(kept.with_suffix(".lock"), "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file is closed
            if kept.is_file():
                shutil.copyfile(kept, output)
                return True
            subprocess.run([*command, "-c", str(source), "-o", str(output)], check=True, capture_output=True)
            partial = kept.with_suffix(f".{os.getpid()}.part")
            shutil.copyfile(output, partial)
            os.replace(partial, kept)
            self.compiled += 1
        return False


@pytest.fixture(scope="session")
def object_cache(tmp_path_factory) -> ObjectCache:
    """The run's shared :class:`ObjectCache`."""
    return ObjectCache(session_shared_dir(tmp_path_factory, "objects"))


@pytest.fixture(scope="session", autouse=True)
def shared_compile_cache(tmp_path_factory):
    """``$MAGLEV_OC_CACHE`` (:func:`maglev_oc.sim.library_cache.user_cache`, where the reports
    keep the compiled NMPC and closed loops) in the run's shared directory: the workers build each
    library once, and the user's own cache is neither read nor written by the tests."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("MAGLEV_OC_CACHE", str(session_shared_dir(tmp_path_factory, "maglev_oc_cache")))
        yield
