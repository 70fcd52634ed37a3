"""Properties of ``maglev_oc.region`` from the survivors of the seed-45 mutation run: a sweep's
specification refuses starts drawn in a certified set {z~' P z~ <= level} for a controller other
than the FL regulator (those error coordinates are the FL loop's), and says so; the same set for
the FL loop, and a fixed start for any controller, are accepted; Procedure 2's status word is
"certified" when it certifies a level."""

from __future__ import annotations

import numpy as np
import pytest

from maglev_oc.errors import InputError
from maglev_oc.region.closed_loop import Reference
from maglev_oc.region.sweep import PlantSet, SweepSpec


@pytest.mark.parametrize("controller", ["lqr", "linear"])
def test_a_certified_set_of_starts_is_for_the_fl_loop_only(model, controller):
    plants = PlantSet.point(model.constants)
    ref = Reference.setpoint(0.02)
    P = tuple(map(tuple, np.eye(10)))
    with pytest.raises(InputError, match=r"certified set .* are for the FL loop"):
        SweepSpec(plants, ref, controller=controller, P=P, level=1.0)
    assert SweepSpec(plants, ref, controller="fl", P=P, level=1.0).controller == "fl"
    start = SweepSpec(plants, ref, controller=controller, start=(0.02, 0.0, 0.0, 0.0))
    assert start.controller == controller and start.P is None


def test_procedure_2_says_certified_in_its_status_word_and_its_message(model):
    """The result convention: a certified level is status "certified" (the word reports and the
    CLI's exit status read), with a message that says what bounds it; a reference inside a
    stopper is "infeasible_reference", not certified."""
    from maglev_oc.region.closed_loop import RegulatorLoop
    from maglev_oc.region.feasibility import FeasibleSet
    from maglev_oc.region.procedure2 import Procedure2
    from maglev_oc.results import check_result

    proc = Procedure2(FeasibleSet(model), RegulatorLoop())
    res = proc.run(Reference.setpoint(0.02))
    check_result(res)
    assert (res.success, res.status) == (True, "certified") and res.level > 0
    assert res.message.startswith("certified")
    stuck = proc.run(Reference.setpoint(0.005))  # below the lower stopper (8 mm)
    assert (stuck.success, stuck.status) == (False, "infeasible_reference")
