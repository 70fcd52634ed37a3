"""Region properties from the survivors of the seed-35 mutation run at b484c31 (issue 21), each a
property of a result a user sees, not of one line:

* F's stoppers are validated each on its own: a malformed position range is refused by name even
  when the gap range is dropped (None), and the other way round.
* A slice of error states judges its runs against its own ``current_limit``: a start is safe
  exactly when its run's peak current stays within that limit (the other constraints of F hold
  with room to spare on the slice used), and with no limit every start is safe.
"""

from __future__ import annotations

import numpy as np
import pytest

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.errors import InputError
from maglev_oc.region.closed_loop import N_ERROR, Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.montecarlo import BatchSimulator, fl_slice
from maglev_oc.sim.twin import RigTwin


# --- the feasible set F -------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("dropped", "checked", "bad"),
    [
        ("gap_range", "position_range", (0.05, -0.05)),  # low above high
        ("gap_range", "position_range", (-0.8, 0.8)),  # beyond 0.5 m: not metres
        ("position_range", "gap_range", (0.03, 0.01)),
        ("position_range", "gap_range", (0.01, 0.9)),
    ],
)
def test_each_stopper_range_is_checked_whichever_other_is_dropped(model, dropped, checked, bad):
    """FeasibleSet's docstring: each of gap_range and position_range is (low, high) in metres or
    None (no stopper). Dropping one does not exempt the other from the check."""
    with pytest.raises(InputError, match=checked):
        FeasibleSet(model, **{dropped: None, checked: bad})
    # the same set with a well-formed range is accepted, stored as floats
    good = (0.01, 0.03) if checked == "gap_range" else (-0.05, 0.05)
    feasible = FeasibleSet(model, **{dropped: None, checked: good})
    assert getattr(feasible, checked) == good and getattr(feasible, dropped) is None


# --- slices of error states --------------------------------------------------------------------------
REF = Reference.setpoint(0.02)


@pytest.fixture(scope="module")
def slice_runs(model):
    """The FL regulator on the nominal twin over 0.05 s (the current's transient peak comes within
    the first few ms for these small starts), the virtual machine (no C compiler needed)."""
    sim = BatchSimulator(RigTwin(model), FeedbackLinearizingRegulator(model), duration=0.05, compile=False)
    return sim, RegulatorLoop()


def test_a_slice_judges_its_starts_against_its_own_current_limit(slice_runs):
    """fl_slice's ``current_limit`` is the |u| limit of F its runs are judged against. Over a slice of
    gap errors of +-1 mm (the gap stays 19-21 mm, 9 mm or more from either stopper, and R > 0 all along) the
    runs' peak currents differ from start to start; with a limit halfway between the smallest and
    largest peak, safe is exactly peak <= limit (a mix of both), and without a limit all are safe.
    The peaks do not depend on the limit (the regulator does not see it): the same to round-off."""
    sim, loop = slice_runs
    P, level = np.eye(N_ERROR), 1.0  # any certificate: only the safe labels are checked here
    args = (sim, loop, REF, P, level, ("e1", "e1_rate"), (-1e-3, 1e-3), (-0.01, 0.01))
    free = fl_slice(*args, n=5, current_limit=None)
    assert free.safe.all()
    peaks = free.max_current
    assert peaks.max() - peaks.min() > 0.1  # [A] room for a limit between them
    limit = 0.5 * (peaks.min() + peaks.max())
    judged = fl_slice(*args, n=5, current_limit=limit)
    np.testing.assert_allclose(judged.max_current, peaks, rtol=1e-12)
    np.testing.assert_array_equal(judged.safe, peaks <= limit)
    assert judged.safe.any() and not judged.safe.all()
