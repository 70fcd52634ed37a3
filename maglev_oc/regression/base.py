"""Bookkeeping of the base model's parameters: names, units and the axis each acts on.

The base model (SPEC 1) has four lumped constants C1..C4 (C1 scales the thrust, C2..C4 the
normal force) and, optionally, ``gap_offset`` [m]: a mounting offset of the gap encoder, the true
gap being the reading plus the offset, so that the physics (L1..L4 and every term) sees the true
gap. Everything that needs to know which constant belongs to which axis reads it here.
"""

from __future__ import annotations

from maglev_oc.results import AXES

__all__ = [
    "AXIS_INDEX",
    "CONSTANT_AXIS",
    "CONSTANT_NAMES",
    "ESTIMABLE",
    "GAP_OFFSET",
    "GAP_OFFSET_BOUND",
    "GAP_OFFSET_SCALE",
    "UNITS",
]

AXIS_INDEX = {name: k for k, name in enumerate(AXES)}
"""Rows of every per-axis array: 0 = vertical (x2', the gap), 1 = horizontal (x4')."""
CONSTANT_NAMES = ("C1", "C2", "C3", "C4")
CONSTANT_AXIS = {"C1": "horizontal", "C2": "vertical", "C3": "vertical", "C4": "vertical"}
GAP_OFFSET = "gap_offset"
ESTIMABLE = (*CONSTANT_NAMES, GAP_OFFSET)
GAP_OFFSET_SCALE = 1e-4
"""[m] Typical encoder mounting offset (0.1 mm), for conditioning."""
GAP_OFFSET_BOUND = 5e-3
"""[m] An offset beyond 5 mm is a wrong setup, not a parameter."""
UNITS = {"C1": "m/(s^2 A)", "C2": "m/(s^2 T^2)", "C3": "m/(s^2 A T)", "C4": "m/(s^2 A^2)", GAP_OFFSET: "m"}
