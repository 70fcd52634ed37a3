"""The parametric twin (maglev_oc.sim.parametric_twin): another plant of one build runs exactly
as the RigTwin built for that plant, and a plant it cannot be is refused."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.control.linear_regulator import paper_linear_regulator
from maglev_oc.errors import InputError
from maglev_oc.numerics import c_compiler
from maglev_oc.sim.effects import CommutationOffset, GuideFriction, TwinEffects
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.parametric_twin import TUNABLE, ParametricTwin
from maglev_oc.sim.scenarios import Scenario, SetpointSequence
from maglev_oc.sim.twin import RigTwin

# a 4 mm step with a horizontal move: the plants' constants, amplifier lag, commutation offset,
# friction and cogging all act within 0.4 s
STEP = Scenario(
    "step", "22 -> 18 mm", (0.022, 0.0, 0.0, 0.0), SetpointSequence((0.0,), ((0.018, 0.01),)), 0.4
)


def _plants(model):
    """(true plant, effects): the rig twin and three others differing in every tunable size."""
    rig = TwinEffects.rig()
    c = model.constants
    return [
        (model, rig),
        (
            model.with_constants(c.replace(C2=1.05 * c.C2, C4=1.3 * c.C4)),
            dataclasses.replace(rig, amplifier=dataclasses.replace(rig.amplifier, bandwidth_hz=14.0)),
        ),
        (
            model.with_constants(c.replace(C1=0.97 * c.C1, C3=0.9 * c.C3)),
            TwinEffects.rig(commutation=CommutationOffset(-0.3)),
        ),
        (
            model,
            TwinEffects.rig(
                friction_vertical=GuideFriction(coulomb=1.0, viscous=2.0),
                cogging=dataclasses.replace(rig.cogging, peak_at_reference=3.0),
            ),
        ),
    ]


@pytest.mark.parametrize("backend", ["vm", "c"])
def test_a_plant_of_one_build_runs_as_its_own_rig_twin(model, backend):
    # Bit for bit (not to a tolerance): the same operations with a state row where the RigTwin
    # has a number, so a calibration on the parametric twin finds what one on RigTwins finds.
    if backend == "c" and c_compiler() is None:
        pytest.skip("no C compiler")
    template = ParametricTwin(model, TwinEffects.rig())
    assert template.n_state == RigTwin(model, TwinEffects.rig()).n_state + len(TUNABLE)
    for ctrl in (FeedbackLinearizingRegulator(model), paper_linear_regulator(model, feedforward=False)):
        shared = ClosedLoop(template, ctrl, backend=backend, cflags=("-O1",))  # the calibration's
        for plant, effects in _plants(model):
            own = ClosedLoop(RigTwin(plant, effects), ctrl, backend=backend, cflags=("-O1",)).run(STEP)
            run = shared.on(template.at(plant, effects)).run(STEP)
            for name in ("x", "y", "u", "current", "diag", "flags"):
                np.testing.assert_array_equal(getattr(run, name), getattr(own, name), err_msg=name)
            assert run.status == own.status and run.effects == own.effects


def test_what_a_build_cannot_be_is_refused(model):
    template = ParametricTwin(model, TwinEffects.rig())
    with pytest.raises(InputError, match="more than the tunable"):
        template.at(model, TwinEffects.rig(input_delay_samples=2))
    with pytest.raises(InputError, match="above 0 N"):
        template.at(model, TwinEffects.rig(friction_vertical=GuideFriction(coulomb=0.0, viscous=2.0)))
    with pytest.raises(InputError, match="amplifiers"):
        ParametricTwin(model, TwinEffects.ideal())
    loop = ClosedLoop(template, FeedbackLinearizingRegulator(model))
    with pytest.raises(InputError, match="share"):
        loop.on(RigTwin(model, TwinEffects.rig()))
