"""Plausible log signals and a CSV writer shared by the log-layer property tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tests.test_logs import META

N = 600


def _signals(n: int = N, dt: float = 1e-3) -> dict[str, np.ndarray]:
    """A plausible run: gap around 20 mm, a few mm of motion, currents of a few A."""
    t = np.arange(n) * dt
    return {
        "t": t,
        "x1": 0.020 + 0.002 * np.sin(2 * np.pi * 1.3 * t),
        "x3": 0.010 * np.sin(2 * np.pi * 0.7 * t + 0.4),
        "u1": 0.8 * np.sin(2 * np.pi * 2.1 * t),
        "u2": 1.5 + 0.4 * np.cos(2 * np.pi * 0.9 * t),
    }


def _write_csv(path: Path, columns: dict[str, np.ndarray]) -> Path:
    table = np.column_stack(list(columns.values()))
    rows = (",".join(repr(float(v)) for v in row) for row in table)
    path.write_text("\n".join([*META, ",".join(columns), *rows]) + "\n")
    return path
