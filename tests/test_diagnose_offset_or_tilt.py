"""A commutation offset's thrust, C1 l1 d i_d, is nearly a constant force along the track where the
levitation current i_d is steady: a tilt of the guides makes the same. Its attraction, C3 l3 d i_q,
is what the tilt has not. Where the two are not separable along the track and the vertical axis
shows nothing of the offset, neither is claimed (``selection._not_shown_beyond``)."""

from __future__ import annotations

import math

import pytest

from maglev_oc.diagnosis import selection
from maglev_oc.diagnosis.currents import _commutation_text
from maglev_oc.results import Estimate
from tests.diagnosis_support import diagnose_path
from tests.independent import write_log
from tests.independent.effects import GuideFriction, TiltedBase
from tests.independent.rigs import RIGS
from tests.independent.sets import under_experiment
from tests.independent.simulate import Rig, Scenario, simulate

OFFSET = "commutation_offset"


@pytest.mark.slow
def test_a_tilt_beside_friction_is_not_claimed_as_a_commutation_offset(tmp_path, monkeypatch):
    # Drawn pair 41102 of the independent generator (bench/diagnose_rigs.py --drawn-pairs 12 --rig
    # obs2800 --experiment steps --seed 41100): 1.17 N of horizontal Coulomb friction (LuGre) and
    # guides tilted by 6.2 mrad, a 0.097 N force along the track; no commutation offset. Before the
    # rule a -0.22 +- 0.02 degree offset was claimed (23.2 % of the held-out horizontal error against
    # the tilt's 22.5 % in its place; its attraction -0.12 +- 0.07 degrees, nothing of the vertical
    # error) and the tilt listed as not separable from it
    scenario = Scenario(
        name="guide_friction_horizontal+tilted_base",
        seed=41102,
        effects=(
            GuideFriction(
                axis_="horizontal",
                coulomb_force=1.1741225588836282,
                static_force=1.6966274684329294,
                stribeck_velocity=0.008936438148875353,
                viscous_coefficient=1.5040312401625324,
            ),
            TiltedBase(angle=0.0061876944010758475),
        ),
        rig=Rig(**RIGS["obs2800"]),
    )
    csv, _ = write_log(simulate(under_experiment(scenario, "steps")), tmp_path, stem="pair_41102")
    d = diagnose_path(csv)
    claimed = [e.name for e in d.effects]
    assert claimed == ["guide_friction_horizontal"]
    (friction,) = d.effects  # the true friction, sized within the 30 %
    assert friction.parameters["coulomb"].value == pytest.approx(1.1741, rel=0.3)
    (offset,) = [n for n in d.not_separable if n.name == OFFSET]
    assert "neither is claimed" in offset.reason and "vertical error" in offset.reason
    # without the rule, the same log claims the offset: the rule, not another, refuses it
    monkeypatch.setattr(selection, "_not_shown_beyond", lambda *a: None)
    assert OFFSET in [e.name for e in diagnose_path(csv).effects]


def _angles(h: float, v: float, sh: float = 0.008, sv: float = 0.04) -> dict:
    deg = math.pi / 180
    return {
        "angle": Estimate(h * deg, sh * deg, "rad"),
        "angle_horizontal": Estimate(h * deg, sh * deg, "rad"),
        "angle_vertical": Estimate(v * deg, sv * deg, "rad"),
    }


def test_angles_that_differ_name_both_axes_as_the_one_another_effect_moved():
    # Drawn pair 42204 (a -1.51 degree offset, a 0.135 N tilt of the guides): the thrust gave -1.81
    # +- 0.008 degrees, the attraction the true -1.51 +- 0.04; the tilt moved the thrust's angle, so
    # the text may not say it is the vertical axis's
    text = _commutation_text(_angles(-1.81, -1.51))
    assert "tilt of the guides" in text and "a vertical one into the attraction's" in text
    # within 3 standard errors of each other (0.12 degrees here) the angle alone is reported
    assert _commutation_text(_angles(-1.55, -1.51)).endswith("degrees.")
