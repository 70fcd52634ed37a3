"""Progress of long runs on the terminal: shown on stderr when it is a terminal, silent otherwise
(pipes, log files, CI), so output captured by a script never carries progress bars."""

from __future__ import annotations

import sys
from collections.abc import Iterable

__all__ = ["progress", "shown"]


def shown() -> bool:
    """Whether progress is shown: stderr is a terminal."""
    return sys.stderr.isatty()


def progress(iterable: Iterable | None = None, *, total: int | None = None, desc: str = "", unit: str = "it"):
    """A tqdm bar on stderr (disabled when :func:`shown` is False); use as tqdm: iterate, or
    ``update()`` / ``set_description()`` by hand."""
    from tqdm import tqdm

    return tqdm(
        iterable, total=total, desc=desc, unit=unit, disable=not shown(), leave=False, file=sys.stderr
    )
