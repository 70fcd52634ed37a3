"""Region properties from the survivors of the seed-36 mutation run, each a property of a result a
user sees, not of one line:

* the microstepper's certified level follows the result convention of every maglev_oc result
  (:mod:`maglev_oc.results`): its ``timings`` carry the call's wall time under ``"total"``, the key
  ``maglev-oc region --microstepper`` prints and the other results use (simulations, the
  feasibility and SDP certificates, the region study), whether the set-point is certified or
  found infeasible; and ``success`` is a Python bool (``res.success is True`` held for every result
  but this one, whose certified case returned numpy's ``np.True_``);
* a Lyapunov matrix handed to the region code is refused with a message that says what is wrong
  with it (not square 10 x 10 and finite, or not symmetric), and a symmetric one is taken as is.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from maglev_oc.errors import InputError
from maglev_oc.model.platform import microstepper
from maglev_oc.region.ellipsoid import checked_p
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
    if status == "infeasible_setpoint":
        # the set-point itself (V = 0) breaks a constraint: nothing is certified, and the least
        # refuted level is 0, a number a table can print (not a missing value)
        assert res.level == 0.0 and res.refuted_level == 0.0 and res.binding


def test_a_lyapunov_matrix_is_refused_with_what_is_wrong_with_it():
    """P defines the certified ellipsoid {e' P e <= c}: a P that is not symmetric (to 1e-10
    relative) is a user's mistake (a transposed factor, a typo), refused saying "symmetric"; a
    symmetric P comes back unchanged (its symmetrisation is the identity)."""
    rng = np.random.default_rng(36)
    a = rng.normal(size=(10, 10))
    with pytest.raises(InputError, match="P must be symmetric"):
        checked_p(a @ a.T + np.triu(np.full((10, 10), 1e-3), 1))
    with pytest.raises(InputError, match="P must be a finite 10 x 10 matrix, got shape \\(9, 9\\)"):
        checked_p(np.eye(9))
    p = a @ a.T
    np.testing.assert_array_equal(checked_p(p), 0.5 * (p + p.T))
