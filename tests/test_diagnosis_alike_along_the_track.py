"""A tilt of the guides and guides sloping against the stator push alike along the track; only what
the slope does to the magnetic gap, on the vertical axis, tells them apart
(``selection.told_apart_on_the_other_axis``). The numbers are those measured on the independent
generator's logs (the function's docstring)."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np

from maglev_oc.diagnosis.selection import (
    ALIKE_ALONG_THE_TRACK,
    SelectionSettings,
    alike_along_the_track,
    told_apart_on_the_other_axis,
)
from tests._diagnosis_cases import _judgement

SETTINGS = SelectionSettings()
TILT, SLOPE = ALIKE_ALONG_THE_TRACK[0]
BY_NAME = {TILT: SimpleNamespace(axis="horizontal"), SLOPE: SimpleNamespace(axis="both")}
MOVING = np.array([True, True])
NAN = float("nan")


def _judged(name: str, pooled: tuple[float, float], verdict: str = "passes"):
    j = _judgement(z=10.0, wald=1e3, gain_axes=pooled)
    return dataclasses.replace(
        j, name=name, verdict=verdict, pooled_gain_axes=np.asarray(pooled, dtype=float)
    )


def test_a_tilt_is_not_told_from_a_slope_that_explains_nothing_on_the_vertical_axis():
    # Set 32105 (a -2.3 mrad slope, cogging, end effects, warming): beside the rest the slope in the
    # tilt's place explained 72.05 % of the held-out horizontal error against 72.07 %, and -3.0 %
    # of the vertical (the end effects' unequal losses took its line in the attraction)
    tilt, slope = _judged(TILT, (NAN, 0.7207)), _judged(SLOPE, (-0.0298, 0.7205))
    alike = told_apart_on_the_other_axis(tilt, slope, BY_NAME, MOVING, SETTINGS)
    assert alike is not None and not alike.takes_place
    assert alike.alt is slope and alike.two_axis == SLOPE
    assert alike.other == -0.0298 and alike.along == (0.7205, 0.7207)


def test_a_slope_that_the_vertical_axis_shows_takes_the_tilts_place():
    # the same set in the first round of the backward pass: the slope explained 22.3 % of the
    # vertical error, which a tilt does not touch
    tilt, slope = _judged(TILT, (NAN, 0.7196)), _judged(SLOPE, (0.2229, 0.7191))
    alike = told_apart_on_the_other_axis(tilt, slope, BY_NAME, MOVING, SETTINGS)
    assert alike is not None and alike.takes_place


def test_a_chosen_slope_stays_where_the_vertical_axis_shows_it_and_not_where_it_does_not():
    # pair 32204 (a slope beside end effects): the chosen slope explained 8.5 % of the vertical error
    # beside a waviness and the end effects, the tilt in its place as much along the track
    tilt = _judged(TILT, (NAN, 0.7767))
    assert (
        told_apart_on_the_other_axis(_judged(SLOPE, (0.0853, 0.7767)), tilt, BY_NAME, MOVING, SETTINGS)
        is None
    )
    # one that explains no more than the parsimony penalty there is not told from the tilt
    flat = _judged(SLOPE, (SETTINGS.parameter_penalty, 0.7767))
    alike = told_apart_on_the_other_axis(flat, tilt, BY_NAME, MOVING, SETTINGS)
    assert alike is not None and not alike.takes_place and alike.alt is tilt


def test_told_apart_along_the_track_or_when_the_other_does_not_pass():
    tilt = _judged(TILT, (NAN, 0.72))
    # more than the parsimony penalty apart on the shared axis: the track tells them apart
    apart = _judged(SLOPE, (0.0, 0.72 - 1.01 * SETTINGS.parameter_penalty))
    assert told_apart_on_the_other_axis(tilt, apart, BY_NAME, MOVING, SETTINGS) is None
    within = _judged(SLOPE, (0.0, 0.72 - 0.99 * SETTINGS.parameter_penalty))
    assert told_apart_on_the_other_axis(tilt, within, BY_NAME, MOVING, SETTINGS) is not None
    # pairs 32235-32420 (a tilt beside end effects): the slope in its place lost 54 % to 3350 % of
    # the vertical error and did not pass
    lost = _judged(SLOPE, (-0.54, 0.6859), verdict="not specific")
    assert told_apart_on_the_other_axis(tilt, lost, BY_NAME, MOVING, SETTINGS) is None


def test_each_of_the_pair_names_the_other_and_nothing_else_has_one():
    assert alike_along_the_track(TILT, BY_NAME) == SLOPE
    assert alike_along_the_track(SLOPE, BY_NAME) == TILT
    assert alike_along_the_track("cable_carrier_force", BY_NAME) is None
    assert alike_along_the_track(TILT, {TILT: BY_NAME[TILT]}) is None  # the library lacks the slope


def test_the_constants_carry_the_force_of_a_tilt_listed_as_not_separable_from_a_slope_and_say_so():
    # pair 32687 (a 3.7 mrad slope, end effects): neither claimed, C1 refitted 30 % low without the
    # force along the track the two share, 0.4 % with it (pipeline._with_shared_force)
    from maglev_oc.diagnosis.result import NotSeparable
    from maglev_oc.diagnosis.selection import shared_along_the_track
    from maglev_oc.reporting.diagnosis_report import _shared_force_notes

    tilt, slope = (
        NotSeparable(a, (b,), "a gauge-block check", 0.67, "", {}) for a, b in ((TILT, SLOPE), (SLOPE, TILT))
    )
    assert shared_along_the_track([slope, tilt]) == [(TILT, SLOPE)]
    assert shared_along_the_track([slope]) == []  # the tilt not listed: nothing to carry
    other = NotSeparable(TILT, ("C1", "C2"), "", 0.67, "", {})  # not separable from the constants
    assert shared_along_the_track([other]) == []
    (note,) = _shared_force_notes(SimpleNamespace(not_separable=[tilt, slope]))
    assert "horizontal guides off level" in note and "neither is claimed" in note, note
    assert _shared_force_notes(SimpleNamespace(not_separable=[other])) == []


def test_the_report_sizes_a_candidate_not_separable_from_an_effect_and_not_one_confounded_with_constants():
    # the words page of maglev-oc diagnose: the tilt of set 32105 is the same force along the track
    # either way, so its size means something; a constant force traded with C2, C3 means nothing
    from maglev_oc.diagnosis.result import NotSeparable
    from maglev_oc.regression.terms import Estimate
    from maglev_oc.reporting.diagnosis_report import _beside_effects

    force = {"force": Estimate(0.063, 0.0008, "N"), "rms_force_horizontal": Estimate(0.063, 0.0, "N")}
    tilt = NotSeparable(TILT, (SLOPE,), "a gauge-block check", 0.36, "", force)
    assert _beside_effects(tilt) == " Fitted in its place: force 0.063 ± 0.0008\u00a0N."
    for confounded in (("C2", "C3"), ("C1..C4",), ("a smooth dependence on the position",), ()):
        assert _beside_effects(NotSeparable("constant_vertical_force", confounded, "", 0.5, "", force)) == ""


def test_small_angles_and_lengths_are_given_in_thousandths_and_large_ones_and_ratios_are_not():
    # a guide tilt of 4 mrad printed as 0.004 rad reads as nothing on the report's words page;
    # a commutation phase of 1.3 rad is an angle of its own size; a ratio stays in per cent
    from maglev_oc.regression.terms import Estimate
    from maglev_oc.reporting.diagnosis_report import _sizes

    assert _sizes({"tilt": Estimate(0.004, 0.0002, "rad")}) == "tilt 4 ± 0.2\u00a0mrad"
    assert (
        _sizes({"gap_change_over_travel": Estimate(-3e-4, 2e-5, "m")})
        == "gap change over travel -0.3 ± 0.02\u00a0mm"
    )
    assert _sizes({"phase": Estimate(1.3, 0.05, "rad")}) == "phase 1.3 ± 0.05\u00a0rad"
    assert _sizes({"mismatch": Estimate(0.021, 0.001, "1")}) == "mismatch 2.1 ± 0.1\u00a0%"


def test_the_errors_after_say_they_carry_the_force_of_a_pair_not_told_apart():
    # with neither of the pair claimed the "after" figures come from the model the constants are
    # fitted with, the shared force in it (pipeline._shared_terms): the report and the JSON's error
    # metric say what lowered them, where "nothing to add" stood beside a 42 % drop on pair 32687
    from maglev_oc.diagnosis.result import ERROR_METRIC, NotSeparable, _after_carries
    from maglev_oc.reporting.diagnosis_report import outcome_rows
    from maglev_oc.results import PerAxis

    tilt, slope = (
        NotSeparable(a, (b,), "a gauge-block check", 0.67, "", {}) for a, b in ((TILT, SLOPE), (SLOPE, TILT))
    )
    errors = {
        "error_before": PerAxis(0.099, 0.0624),
        "error_after": PerAxis(0.099, 0.0363),
        "output_error_before": PerAxis(70e-6, 38e-6),
        "output_error_after": PerAxis(70e-6, 6.6e-6),
    }
    rows = outcome_rows(SimpleNamespace(effects=[], not_separable=[tilt, slope], **errors), None)
    acceleration, position = (verdict for _, _, verdict in rows)
    assert acceleration.startswith("lowered by 0.0 % (vertical) and 42 % (horizontal) with the force")
    assert "horizontal guides off level or" in acceleration and acceleration.endswith("(not separable)")
    assert position.startswith("lowered by 0.0 % (vertical) and 83 % (horizontal) with the force")
    assert f"after: with the effects and the force along the track of {TILT} or {SLOPE}" in _after_carries(
        [tilt, slope]
    )
    # nothing carried: the metric as SPEC 3 has it, and no drop claimed
    assert _after_carries([slope]) == ""
    (row, _) = outcome_rows(SimpleNamespace(effects=[], not_separable=[slope], **errors), None)
    assert row[2] == "nothing to add" and ERROR_METRIC.endswith("does not move in the logs)")
