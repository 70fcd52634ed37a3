"""An effect that acts on both axes must not make either axis's held-out error worse
(``SelectionSettings.max_axis_loss``; selection module doc, test 6).

A guide waviness moves the gap, so it acts on the attraction (vertical) and, through the slope of
the guide, on the thrust direction (horizontal) with one amplitude. On the independent generator's
small-excursion log of a detent (experiments_10: a horizontal force of the position alone, seen
over 1.2 of its periods and so not separable as cogging), a 15 mm waviness took the horizontal
residual: pooled held-out gain +15.7 % horizontally, -6.6 % vertically, z 3.03. The vertical data
do not show the gap change its horizontal force implies; it was the one false claim of the 56
experiments. Candidates with no effect on an axis move its held-out error by about 0.1 %
(the same log's vertical cogging candidates: -0.08 % and -0.01 %).
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.diagnosis.selection import SMOOTH_POSITION, Judgement, SelectionSettings
from tests._diagnosis_cases import _judgement as injected_judgement
from tests._diagnosis_cases import _verdict
from tests.diagnosis_support import diagnose_path
from tests.independent import write_log
from tests.independent.effects import CableCarrier, DetentForce
from tests.independent.sets import under_experiment
from tests.independent.simulate import Scenario, simulate


def _judgement(quarter, pooled) -> Judgement:
    """A candidate that passes tests 1-5 (z 5, Wald 10x its threshold, 0.01 m/s^2 on both axes),
    with the given per-axis held-out gains over the quarter and pooled over the four quarters."""
    j = injected_judgement(z=5.0, wald=100.0, gain_axes=quarter)
    return dataclasses.replace(j, pooled_gain_axes=np.asarray(pooled, dtype=float))


def _verdict_of(j, axes=(0, 1), settings=None):
    cand = SimpleNamespace(axis="both" if len(axes) == 2 else "horizontal", plausible=lambda physical: None)
    settings = settings or SelectionSettings()
    return _verdict(j, cand, np.array(axes), SimpleNamespace(compensation=1.0), settings, None)


def test_the_false_waviness_of_a_detent_is_not_specific():
    verdict, reason = _verdict_of(_judgement((-0.0665, 0.187), (-0.0658, 0.157)))
    assert verdict == "not specific"
    # the axis it worsens and by how much (pooled), and what it explains on the other
    assert "held-out vertical error 6.6% worse" in reason and "15.7% of the horizontal one" in reason


def test_the_loss_is_held_to_max_axis_loss_on_the_pooled_gain():
    s = SelectionSettings()
    assert s.max_axis_loss == pytest.approx(4 * s.min_gain)  # the module doc's reason
    just_under, just_over = -0.9 * s.max_axis_loss, -1.1 * s.max_axis_loss
    assert _verdict_of(_judgement((0.05, 0.05), (just_under, 0.05)))[0] == "passes"
    assert _verdict_of(_judgement((0.05, 0.05), (just_over, 0.05)))[0] == "not specific"
    # either axis: the horizontal one worsened with the vertical explained
    verdict, reason = _verdict_of(_judgement((0.05, 0.05), (0.05, just_over)))
    assert verdict == "not specific" and "horizontal error" in reason and "of the vertical one" in reason
    # the pooled gain decides, not the quarter's (the quarter alone is the noisier estimate)
    lost = -2 * s.max_axis_loss
    assert _verdict_of(_judgement((lost, 0.05), (0.001, 0.05)))[0] == "passes"
    assert _verdict_of(_judgement((0.02, 0.05), (lost, 0.05)))[0] == "not specific"
    # without cross-fitted parts the quarter's gains are the pooled ones
    no_parts = dataclasses.replace(_judgement((lost, 0.05), (0.0, 0.0)), pooled_gain_axes=None)
    assert _verdict_of(no_parts)[0] == "not specific"
    # the setting is used: a looser bound lets the same loss pass, a tighter one refuses less
    loose = SelectionSettings(max_axis_loss=3 * s.max_axis_loss)
    assert _verdict_of(_judgement((0.05, 0.05), (lost, 0.05)), settings=loose)[0] == "passes"
    tight = SelectionSettings(max_axis_loss=0.1 * s.max_axis_loss)
    assert _verdict_of(_judgement((0.05, 0.05), (just_under, 0.05)), settings=tight)[0] == "not specific"


def test_a_loss_small_beside_what_it_explains_on_the_other_axis_is_allowed():
    # Set 24110 of the independent generator on 1 um encoders (guides tilted by 2.5 mrad with 5 um
    # of waviness at 66 mm, a cable carrier, a -2.7 degree commutation offset): beside the other two
    # the tilt explained 96.3 % of the vertical error and made the horizontal one, 0.005 m/s^2 RMS
    # there, 5.7 % worse (the waviness's slope pushes along the track, which the tilt's one slope
    # does not). A loss of up to axis_loss_share of the gain on the other axis passes; the false
    # waviness of the detent (6.6 % lost for 15.7 %) stays refused.
    s = SelectionSettings()
    assert s.axis_loss_share * 0.157 < 0.066  # the detent's false waviness above stays refused
    assert _verdict_of(_judgement((0.96, -0.05), (0.963, -0.057)))[0] == "passes"
    share = s.axis_loss_share * 0.5
    assert _verdict_of(_judgement((0.5, 0.0), (0.5, -0.9 * share)))[0] == "passes"
    verdict, reason = _verdict_of(_judgement((0.5, 0.0), (0.5, -1.1 * share)))
    assert verdict == "not specific" and "horizontal error 5.5% worse" in reason
    # the bound is the larger of the two: max_axis_loss still allows its loss beside a small gain
    assert _verdict_of(_judgement((0.05, 0.05), (-0.9 * s.max_axis_loss, 0.05)))[0] == "passes"
    none = SelectionSettings(axis_loss_share=0.0)
    assert _verdict_of(_judgement((0.96, -0.05), (0.963, -0.057)), settings=none)[0] == "not specific"


def test_an_effect_on_one_axis_is_not_held_to_the_other():
    # a horizontal candidate's gain on the vertical axis is NaN, and only its own axis counts
    j = _judgement((np.nan, 0.05), (np.nan, 0.05))
    assert _verdict_of(j, axes=(1,))[0] == "passes"


# --- on the independent generator's logs --------------------------------------------------------------
@pytest.mark.slow
def test_a_detent_over_a_small_excursion_is_not_named_a_guide_waviness(generated):
    # experiments_10: a 2 N detent (19 mm slot pitch) logged over 1.2 of its periods. The detent is
    # not separable from a smooth dependence on the position there (SelectionSettings.min_periods);
    # a 15 mm guide waviness, whose attraction the vertical data do not show, took its residual
    path, truth = generated("experiments", "experiments_10")
    d = diagnose_path(path)
    assert [t["kind"] for t in truth["effects"]] == ["detent_force"]
    assert d.effects == []  # before the rule: guide_waviness_15mm, +15.7 % horizontal, -6.6 % vertical
    judged = {n: j for st in d.selection.steps for n, j in st.judgements.items()} | d.selection.last
    waviness = [j for n, j in judged.items() if n.startswith("guide_waviness")]
    assert waviness and all(j.verdict != "accepted" for j in waviness)
    (cogging,) = [n for n in d.not_separable if n.name == "cogging_horizontal_19mm"]
    # the experiment that separates it is a longer travel (1.25 periods), not the candidate's own
    # (runs at two gaps, which separate it from the base constants, which is not what failed)
    assert cogging.experiment.startswith("a run over 24 mm of travel or more (1.25 periods of 19.")


@pytest.mark.slow
def test_a_true_two_axis_effect_is_judged_on_converged_constants(generated):
    # eleven_03: a 0.02 rad commutation offset. Around the base fit's constants (which absorbed
    # part of it) its vertical prediction made the held-out error 15 % worse; once the references
    # converge, 0.7 % better. Held to the rule in the first selection it was refused there, a
    # constant force chosen instead, and the offset found in the second round from other
    # constants, sized at 0.044 rad
    path, truth = generated("eleven", "eleven_03")
    d = diagnose_path(path)
    assert [e.name for e in d.effects] == ["commutation_offset"]
    true_angle = truth["effects"][0]["parameters"]["angle"]
    assert d.effects[0].parameters["angle"].value == pytest.approx(true_angle, rel=0.3)  # the 30 %


@pytest.mark.slow
def test_a_detent_over_a_small_excursion_is_not_taken_by_effects_the_position_alone_shows(tmp_path):
    # Drawn pair 40103 of the independent generator under the small-travel experiment
    # (bench/diagnose_rigs.py --drawn-pairs 12 --experiment small_travel --seed 40100): a 1.6 N
    # detent at 15 mm over the slot pitch, seen over 1.1 of its periods on 24 mm of travel, beside a
    # cable carrier. The 19 mm detent explained 72 % of the held-out horizontal error (z 28) and is
    # rightly not separable from a smooth dependence on the position there; before
    # pipeline._position_shown a current sensor offset (its force along the track a smooth function
    # of the position over 0.2 of its 114 mm period; 0.7 % worse vertically) and a 14.5 mm guide
    # waviness (1.0 % worse vertically) were claimed in its place, both false. Judged beside that
    # dependence they explain nothing more, and the dependence is reported by its signature
    scenario = Scenario(
        name="detent_and_carrier",
        seed=40103,
        effects=(
            DetentForce(peak_force=1.59, phase=5.856, harmonic2_ratio=0.295, harmonic2_phase=3.822),
            CableCarrier(stiffness=6.04, neutral_position=-0.0114, constant_force=-0.193),
        ),
    )
    csv, _ = write_log(simulate(under_experiment(scenario, "small_travel")), tmp_path, stem="pair_40103")
    d = diagnose_path(csv)
    assert d.effects == []
    (cogging,) = [n for n in d.not_separable if n.name == "cogging_horizontal_19mm"]
    assert SMOOTH_POSITION in cogging.confounded_with
    assert any(u.axis == "horizontal" and u.depends_on == "position" for u in d.unexplained)
    dropped = {j.name: j for j in d.rejected if j.verdict == "not specific"}
    # the waviness judged beside the dependence explains nothing more; the sensor offset, kept over
    # a tilt of the guides it was not separable from and explaining nothing of the vertical error,
    # is listed with the tilt since selection._not_shown_beyond (before, beside the dependence too)
    assert "dependence on the position" in dropped["guide_waviness_14mm"].reason
    (offset,) = [n for n in d.not_separable if n.name == "current_sensor_offset"]
    assert (
        offset.confounded_with == ("horizontal_guides_not_level",) and "neither is claimed" in offset.reason
    )
