"""Controllers by name, for the command line and the reports."""

from __future__ import annotations

from collections.abc import Callable

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.control.linear_regulator import paper_linear_regulator
from maglev_oc.control.lqr import lqr_regulator
from maglev_oc.control.pid import paper_pid
from maglev_oc.errors import InputError
from maglev_oc.model.stage import StageModel
from maglev_oc.numerics import c_compiler

__all__ = ["CONTROLLERS", "build_controller", "nmpc_controller"]


def nmpc_controller(model: StageModel, **options):
    """The NMPC of the comparisons; ``options``: further :class:`NMPCSettings` fields (e.g.
    ``effects`` of a stage file)."""
    from maglev_oc.control.nmpc import NonlinearMPC  # imported only when asked for

    # causal (no reference preview), like the papers' regulators, so that settling times are
    # comparable; JIT-compiled when a C compiler exists (2-3x faster per step after a 10-25 s
    # build, which a comparison of several scenarios recovers many times over)
    return NonlinearMPC(model, preview=False, compile=c_compiler() is not None, **options)


CONTROLLERS: dict[str, tuple[str, Callable[[StageModel], object]]] = {
    "fl": ("feedback-linearizing output regulator (001/002), printed gains", FeedbackLinearizingRegulator),
    "linear": ("papers' linear output regulator, same poles, with feedforward", paper_linear_regulator),
    "linear-noff": (
        "papers' linear output regulator without equilibrium feedforward",
        lambda m: paper_linear_regulator(m, feedforward=False),
    ),
    "lqr": ("LQR with internal model on the Jacobian linearization", lqr_regulator),
    "pid": ("the papers' PID excitation regulators", paper_pid),
    "nmpc": ("nonlinear MPC, real-time iteration", nmpc_controller),
}
"""Short name -> (description, factory taking the controller's model)."""


def build_controller(name: str, model: StageModel):
    """A controller by its short name.

    Parameters
    ----------
    name : str
        A key of :data:`CONTROLLERS`.
    model : StageModel
        The controller's model.

    Returns
    -------
    ExpressionController or OnlineController

    Raises
    ------
    InputError
        (a ``ValueError``) for an unknown name; the message lists the known ones.
    """
    try:
        _, factory = CONTROLLERS[name]
    except KeyError:
        raise InputError(f"unknown controller {name!r}; known: {', '.join(CONTROLLERS)}") from None
    return factory(model)
