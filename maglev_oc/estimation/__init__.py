"""State estimation: high-gain observers and differentiators.

* :mod:`.high_gain` — the papers' high-gain observer of one axis (position, velocity);
* :mod:`.extended_high_gain` — the same extended by a disturbance state (the NMPC's estimator);
* :mod:`.differentiate` — velocity and acceleration from logged positions (identification).

The everyday names are importable from here (each loaded on first use).
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "DEFAULT_EPSILON": "high_gain",
    "HighGainObserver": "high_gain",
    "ExtendedHighGainObserver": "extended_high_gain",
    "Derivatives": "differentiate",
    "HighGainDifferentiator": "differentiate",
    "SavitzkyGolay": "differentiate",
    "differentiate_log": "differentiate",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
