"""Independent log generator for the 2-DOF maglev positioning stage (a "rig in software").

This package is written from the papers' physics and from what is known about real
linear-guide PMLSM stages; it shares no code and no modelling choices with ``maglev_oc``
(it never imports it). It simulates the papers' feedback-linearizing output regulator running
at 5 kHz on quantized encoder readings against a plant whose true constants and unmodelled
effects are known, and writes 1 kHz logs in the project's CSV format (SPEC 2) together with a
``<name>.truth.json`` file that says what is in them.

Modules
-------
physics
    Table I constants, Carter coefficient, lambda~, the closed-form magnet field B(y), the
    model functions L1..L4 and the equilibrium current (numpy, used for checks and by the
    controller set-up; the fast loop is in C).
effects
    The unmodelled effects of a real stage (friction, cogging, end effects, misalignment, ...),
    each a dataclass with physical parameters in SI units and its equation in the docstring.
controller
    The papers' output regulator: gains, internal models, high-gain observers, discretized at
    the control rate.
reference
    Random sums of sines (and optional smoothed set-point steps) per seed.
core
    The C simulation core (compiled once with gcc into a cache, loaded with ctypes).
simulate
    :func:`simulate` runs one scenario and returns the log and the truth.
sets
    Named sets of scenarios (``clean``, ``eleven``, ``single``, ``pairs``).
rigs
    Named rig settings (faster observers, measured or filtered currents, other encoders and loop
    rates, PID loops) that ``bench/diagnose_rigs.py --rig`` and the tests reproducing its logs share.
generate
    Command line: ``python -m tests.independent.generate --set NAME --out DIR``.

Quick use
---------
>>> from tests.independent import Scenario, simulate, write_log
>>> run = simulate(Scenario(name="demo", seed=3, duration=10.0))   # doctest: +SKIP
>>> write_log(run, "out/")                                          # doctest: +SKIP
"""

from __future__ import annotations

from .effects import EFFECT_KINDS
from .logio import write_log
from .simulate import Rig, Run, Scenario, simulate

__all__ = ["EFFECT_KINDS", "Rig", "Run", "Scenario", "simulate", "write_log"]
