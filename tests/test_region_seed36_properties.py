"""Region properties from the survivors of the seed-36 mutation run, each a property of a result a
user sees, not of one line:

* the microstepper's certified level follows the result convention of every maglev_oc result
  (:mod:`maglev_oc.results`): its ``timings`` carry the call's wall time under ``"total"``, the key
  ``maglev-oc region --microstepper`` prints and the other results use (simulations, the
  feasibility and SDP certificates, the region study), whether the set-point is certified or
  found infeasible; and ``success`` is a Python bool (``res.success is True`` held for every result
  but this one, whose certified case returned numpy's ``np.True_``).
"""

from __future__ import annotations

import time

import pytest

from maglev_oc.model.platform import microstepper
from maglev_oc.region.microstepper import MicrostepperRegion
from maglev_oc.results import check_result

PLATFORM = microstepper()


@pytest.mark.parametrize(
    ("limit", "setpoint", "status"),
    [
        # 3 mm below the 35 mm stopper: the stopper binds; a coarse bracket (rel_tol 0.5) and a
        # small box budget keep it to a fraction of a second (measured 0.25 s)
        (None, (0.0, 0.0, 0.032), "certified"),
        # 0.5 A cannot hold the mover at 25 mm (the equilibrium needs more): refused at once
        (0.5, (0.0, 0.0, 0.025), "infeasible_setpoint"),
    ],
    ids=["certified", "infeasible"],
)
def test_the_microstepper_level_reports_its_total_wall_time(limit, setpoint, status):
    """``timings == {"total": t}`` with 0 < t <= the wall time measured around the call (the
    result's clock starts after the call begins and stops before it returns)."""
    kwargs = {} if limit is None else {"current_limit": limit}
    region = MicrostepperRegion(PLATFORM, **kwargs)
    t0 = time.perf_counter()
    res = region.largest_level(setpoint, rel_tol=0.5, max_boxes=20_000)
    wall = time.perf_counter() - t0
    assert res.status == status, res.message
    assert set(res.timings) == {"total"}
    assert 0 < res.timings["total"] <= wall
    assert "timings [s]: total " in res.report()
    check_result(res)  # success a Python bool (it was numpy's np.True_ when certified), the rest
