"""Small timing helpers shared by the benchmark scripts (not part of the package)."""

from __future__ import annotations

import platform
import statistics
import time
from collections.abc import Callable


def best_of(fun: Callable[[], object], repeat: int = 7, number: int = 1) -> tuple[float, float]:
    """(best, median) wall time of ``number`` calls, over ``repeat`` runs, per call [s]."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fun()
        times.append((time.perf_counter() - t0) / number)
    return min(times), statistics.median(times)


def machine() -> str:
    return f"{platform.processor() or platform.machine()}, Python {platform.python_version()}"


def fmt(seconds: float) -> str:
    if seconds < 1e-3:
        return f"{seconds * 1e6:.2f} us"
    if seconds < 1:
        return f"{seconds * 1e3:.2f} ms"
    return f"{seconds:.2f} s"
