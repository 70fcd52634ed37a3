"""Procedure 2's closed-form witnesses on the stoppers touch the stopper they are named for.

When a stopper binds and no refutation supplied a witness, :meth:`Procedure2._travel_witness`
gives the state of least V on that stopper's half-space, with the orbit's phase at which the
reference comes nearest to it. Checked independently: the gap (or position) of the loop at the
witness, computed from the loop's offsets and output rows, equals the stopper, V there equals the
stoppers' level of :func:`_travel_levels`, and no phase of a dense grid brings that
level set nearer the stopper. A sinusoid on both axes with phases that put the extremes off the
cell edges, so that a wrong sign, row or phase shows.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.procedure2 import Procedure2, _travel_levels

REFERENCES = [
    Reference(0.014, -0.01, 0.003, 0.02, 0.4, 1.1),
    Reference(0.024, 0.015, 0.002, 0.01, 2.5, 4.0),
]
NAMES = ("gap_low", "gap_high", "position_low", "position_high")


@pytest.mark.parametrize("ref", REFERENCES, ids=["near-low", "near-high"])
@pytest.mark.parametrize("name", NAMES)
def test_the_travel_witness_lies_on_its_stopper_at_the_stoppers_level(model, ref, name):
    """V(witness) = the stopper's level (rounding of z' P z with |P| ~ 1e6..1e9: 1e-9 relative);
    at the witness's phase the loop's gap or position is the stopper itself (1e-12 m: rounding
    of ~1e-2 m values); the phase lies in [0, 2 pi); and the same direction at any other phase of
    a 2000-point grid does not cross the stopper (the witness phase is the orbit's extreme)."""
    loop = RegulatorLoop()
    feasible = FeasibleSet(model)
    P = loop.lyapunov_matrix()
    level = _travel_levels(feasible, loop, ref, P)[name]
    assert level > 0
    z, phase = Procedure2._travel_witness(SimpleNamespace(loop=loop), ref, P, name, level)
    assert z @ P @ z == pytest.approx(level, rel=1e-9)
    assert 0.0 <= phase < 2 * math.pi
    row = 0 if name.startswith("gap") else 1
    stopper = (feasible.gap_range if row == 0 else feasible.position_range)[0 if name.endswith("low") else 1]
    at = loop.offsets(ref, phase)[row, 0] + loop.output[row] @ z
    assert at == pytest.approx(stopper, abs=1e-12)
    grid = np.linspace(0, 2 * math.pi, 2000, endpoint=False)
    along = loop.offsets(ref, grid)[row] + loop.output[row] @ z
    if name.endswith("low"):
        assert np.all(along >= stopper - 1e-12)
    else:
        assert np.all(along <= stopper + 1e-12)
