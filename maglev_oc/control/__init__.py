"""Controllers of the stage and their design.

* :mod:`.base` — what every controller offers the simulation engine (the two protocols);
* :mod:`.gains` — the papers' pole placement, printed gains and omega0;
* :mod:`.output_regulator` — internal models and observers shared by the output regulators;
* :mod:`.fl_regulator` — the papers' feedback-linearizing output regulator;
* :mod:`.linear_regulator`, :mod:`.lqr` — linear regulators scheduled on the set-point gap;
* :mod:`.pid` — the papers' PID excitation regulators;
* :mod:`.nmpc` — nonlinear MPC (real-time iteration, converged mode);
* :mod:`.codegen` — C export of the NMPC's real-time iteration;
* :mod:`.registry` — controllers by short name.

The everyday names are importable from here (each loaded on first use).
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "ExpressionController": "base",
    "OnlineController": "base",
    "OMEGA0": "gains",
    "PAPER_K_H": "gains",
    "PAPER_K_V": "gains",
    "FeedbackLinearizingRegulator": "fl_regulator",
    "ScheduledLinearRegulator": "linear_regulator",
    "paper_linear_regulator": "linear_regulator",
    "lqr_regulator": "lqr",
    "PidRegulator": "pid",
    "paper_pid": "pid",
    "NMPCSettings": "nmpc",
    "NMPCStep": "nmpc",
    "NMPCWeights": "nmpc",
    "NonlinearMPC": "nmpc",
    "CONTROLLERS": "registry",
    "build_controller": "registry",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
