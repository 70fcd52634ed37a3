"""Writing output files whole or not at all."""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

from maglev_oc.errors import OutputError
from maglev_oc.interrupts import raise_if_interrupted

__all__ = ["atomic_path", "replace_directory", "write_text_atomic"]


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` only if the block succeeds.

    A reader never sees a half-written file and a failure leaves any previous file untouched.
    """
    path = Path(path)
    if path.is_dir():
        raise OutputError(f"{path}: is a directory; give a file name inside it")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=path.suffix)
    except OSError as err:
        raise OutputError(f"{path}: cannot write here ({err.strerror or err})") from None
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        raise_if_interrupted()  # nothing put in place after Ctrl-C, whatever swallowed it
        # mkstemp makes the file private (0600); give it the mode a plain open() would
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp_path, 0o666 & ~umask)
        try:
            os.replace(tmp_path, path)
        except OSError as err:
            raise OutputError(f"{path}: cannot write here ({err.strerror or err})") from None
    finally:
        tmp_path.unlink(missing_ok=True)


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` to ``path`` through a temporary file in the same folder and a rename."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def replace_directory(built: str | os.PathLike, path: str | os.PathLike) -> Path:
    """Move the finished directory ``built`` onto ``path`` (same file system), replacing an old
    ``path``: the old one is renamed aside first and removed only once the new one is in place
    (and put back if that fails). ``path`` is never a half-written directory: it is the old one,
    the new one, or for the instant between the two renames absent."""
    built, path = Path(built), Path(path)
    old = None
    raise_if_interrupted()
    try:
        if path.exists():
            old = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.old."))
            os.replace(path, old / path.name)
        os.replace(built, path)
    except OSError as err:
        if old is not None and not path.exists():
            os.replace(old / path.name, path)  # put the old one back
        raise OutputError(f"{path}: cannot write here ({err.strerror or err})") from None
    finally:
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    return path
