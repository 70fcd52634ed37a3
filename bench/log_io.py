"""Benchmark: reading logs, and the independent generator's speed (timings out of the tests).

    python bench/log_io.py

Reads a 60 s log at the rig's 5 kHz (300 000 rows, full-precision values) with ``read_log``, and
simulates one 60 s scenario with the independent generator (tests/independent: a 5 kHz FL loop
in its own C code, logged at 1 kHz).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
from common import best_of, fmt, machine

from maglev_oc.data.reading import read_log
from maglev_oc.data.writing import write_log_arrays


def _log_file(path: Path, n: int, dt: float) -> Path:
    t = np.arange(n) * dt
    x = np.vstack(
        [
            0.020 + 0.002 * np.sin(2 * np.pi * 1.3 * t),
            0.002 * 2 * np.pi * 1.3 * np.cos(2 * np.pi * 1.3 * t),
            0.010 * np.sin(2 * np.pi * 0.7 * t + 0.4),
            0.010 * 2 * np.pi * 0.7 * np.cos(2 * np.pi * 0.7 * t + 0.4),
        ]
    )
    u = np.vstack([0.8 * np.sin(2 * np.pi * 2.1 * t), 1.5 + 0.4 * np.cos(2 * np.pi * 0.9 * t)])
    return write_log_arrays(path, t, x, u)


def main() -> None:
    root = Path(__file__).resolve().parents[1]
    sys.path.insert(0, str(root))
    from tests.independent.simulate import Scenario, simulate

    print(f"machine: {machine()}")
    with tempfile.TemporaryDirectory() as tmp:
        path = _log_file(Path(tmp) / "big.csv", 300_000, 2e-4)
        best, median = best_of(lambda: read_log(path), repeat=3)
        size = path.stat().st_size / 1e6
        print(
            f"read_log, 60 s at 5 kHz (300 000 rows, {size:.0f} MB): best {fmt(best)}, median {fmt(median)}"
        )
    best, median = best_of(lambda: simulate(Scenario(name="speed", seed=1, duration=60.0)), repeat=3)
    label = "independent generator, 60 s scenario (5 kHz loop, 1 kHz log)"
    print(f"{label}: best {fmt(best)}, median {fmt(median)}")


if __name__ == "__main__":
    main()
