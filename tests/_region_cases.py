"""Cases shared by the region property tests: the papers' regulator loop and a planted nominal
certificate. The fixture is registered in ``tests/conftest.py``.
"""

from __future__ import annotations

import pytest

from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.ellipsoid import initial_condition_set
from maglev_oc.region.procedure2 import Procedure2Result


@pytest.fixture(scope="module")
def loop():
    return RegulatorLoop()


def _nominal(loop, level: float) -> Procedure2Result:
    """A nominal certificate at ``level`` for the Lyapunov P at 20 mm, without running Procedure 2."""
    P = loop.lyapunov_matrix()
    ics = initial_condition_set(P, level)
    ref = Reference.setpoint(0.02)
    return Procedure2Result(
        True, "certified", "planted", ref, P, level, level, 1.0, "margin", None, 0.0, {}, ics, (), ()
    )
