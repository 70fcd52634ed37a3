"""The selection's backward pass finds an effect not separable beside the rest: the effect chosen
after it that confounds it is dropped in its place when, without both, the first explains more of
the held-out error (``selection._later_in_its_place``); else the first is dropped, as before. Kept
on an axis the later one does not act on that shows nothing of it, neither is claimed
(``selection._not_shown_beyond``)."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np

from maglev_oc.diagnosis.selection import SelectionSettings, _later_in_its_place, _not_shown_beyond
from tests._diagnosis_cases import _judgement as injected_judgement

BASE = injected_judgement(z=5.0, wald=100.0)
CONFOUNDED = dataclasses.replace(
    BASE,
    name="guide_misalignment",
    verdict="not separable",
    reason="confounded with the base constants on this log (variance inflation 291)",
)


def _library() -> dict:
    """A slope of the guides (one parameter), end effects (four) and a spring along the track (two):
    the names and parameters the function reads."""

    def cand(*names):
        return SimpleNamespace(term=SimpleNamespace(parameter_names=names), nuisance=())

    return {
        "guide_misalignment": cand("slope"),
        "end_effects": cand("a", "b", "c", "d"),
        "cable_carrier_force": cand("stiffness", "force_at_zero"),
    }


def judge(table: dict):
    """A judge of (name, others) from ``table``: name -> (others' set -> (gain, verdict)), the
    calls recorded in ``judge.calls``."""
    calls = []

    def judged(name, others):
        calls.append((name, tuple(others)))
        gain, verdict = table[name][frozenset(others)]
        return dataclasses.replace(
            BASE, name=name, verdict=verdict, gain=gain, gain_axes=np.array([gain, gain])
        )

    judged.calls = calls
    return judged


CURRENT = ["base", "commutation_offset", "guide_misalignment", "end_effects"]
REST = frozenset({"base", "commutation_offset"})


def test_a_later_effect_that_explains_less_is_dropped_in_the_place_of_the_one_it_confounds():
    # Set 29300 of the independent generator: the slope chosen beside a commutation offset explained
    # 67.6 % of the held-out error; end effects of 0.1-0.2 % chosen after it made it collinear with
    # the constants. Without them it passes, and it explains more than they do in its place.
    s = SelectionSettings()
    judged = judge(
        {
            "guide_misalignment": {REST: (0.676, "passes")},
            "end_effects": {REST: (0.44, "passes"), REST | {"guide_misalignment"}: (0.026, "passes")},
        }
    )
    out = _later_in_its_place("guide_misalignment", CONFOUNDED, CURRENT, _library(), judged, s)
    assert out is not None and out.name == "end_effects"
    assert out.verdict == "not separable" and out.confounded_with == ("guide_misalignment",)
    assert out.gain == 0.026  # its judgement beside the one kept
    assert "67.6%" in out.reason and "44.0%" in out.reason and "variance inflation 291" in out.reason


def test_the_first_is_dropped_when_the_later_one_explains_more_in_its_place():
    s, lib = SelectionSettings(), _library()
    # the later one explains more than the first beside the rest: the first goes (None), as before
    more = judge(
        {
            "guide_misalignment": {REST: (0.50, "passes")},
            "end_effects": {REST: (0.60, "passes")},
        }
    )
    assert _later_in_its_place("guide_misalignment", CONFOUNDED, CURRENT, lib, more, s) is None
    # within the parsimony penalty of the later one's three extra parameters the first is kept
    within = judge(
        {
            "guide_misalignment": {REST: (0.50, "passes")},
            "end_effects": {
                REST: (0.50 + 2.9 * s.parameter_penalty, "passes"),
                REST | {"guide_misalignment"}: (0.01, "passes"),
            },
        }
    )
    assert (
        _later_in_its_place("guide_misalignment", CONFOUNDED, CURRENT, lib, within, s).name == "end_effects"
    )
    beyond = judge(
        {
            "guide_misalignment": {REST: (0.50, "passes")},
            "end_effects": {REST: (0.50 + 3.1 * s.parameter_penalty, "passes")},
        }
    )
    assert _later_in_its_place("guide_misalignment", CONFOUNDED, CURRENT, lib, beyond, s) is None
    # a later one that does not pass in its place explains nothing the first does not: it goes
    refused = judge(
        {
            "guide_misalignment": {REST: (0.50, "passes")},
            "end_effects": {REST: (0.90, "implausible"), REST | {"guide_misalignment"}: (0.01, "passes")},
        }
    )
    assert (
        _later_in_its_place("guide_misalignment", CONFOUNDED, CURRENT, lib, refused, s).name == "end_effects"
    )


def test_nothing_is_dropped_in_its_place_unless_a_later_choice_is_what_confounds_it():
    s, lib = SelectionSettings(), _library()
    # without the later effect the first still does not pass: the constants confound it on their own
    still = judge({"guide_misalignment": {REST: (0.50, "not separable")}})
    assert _later_in_its_place("guide_misalignment", CONFOUNDED, CURRENT, lib, still, s) is None
    # the last chosen has no later effect; an implausible fit or a rival's shape is the effect's own
    # failing, not the later one's doing
    nothing = judge({})
    last = ["base", "commutation_offset", "end_effects", "guide_misalignment"]
    assert _later_in_its_place("guide_misalignment", CONFOUNDED, last, lib, nothing, s) is None
    for verdict in ("implausible", "not specific", "too small"):
        refused = dataclasses.replace(CONFOUNDED, verdict=verdict)
        assert _later_in_its_place("guide_misalignment", refused, CURRENT, lib, nothing, s) is None
    assert nothing.calls == []


def test_an_effect_that_explains_nothing_beside_a_later_one_is_the_same_case():
    # Set 29901 of the filtered-current rig: a tilt chosen beside the slope of the guides (57.9 % of
    # the held-out horizontal error) explained nothing more beside end effects chosen after it, whose
    # thrust's fall on the steady thrust that holds the tilt took its place; they explain less in it.
    s = SelectionSettings()
    rest = frozenset({"base", "guide_misalignment"})
    current = ["base", "guide_misalignment", "horizontal_guides_not_level", "end_effects"]
    lib = {**_library(), "horizontal_guides_not_level": _library()["guide_misalignment"]}
    judged = judge(
        {
            "horizontal_guides_not_level": {rest: (0.29, "passes")},
            "end_effects": {rest: (0.20, "passes"), rest | {"horizontal_guides_not_level"}: (0.03, "passes")},
        }
    )
    quiet = dataclasses.replace(
        CONFOUNDED, name="horizontal_guides_not_level", verdict="not significant", reason="falls by 0.5%"
    )
    out = _later_in_its_place("horizontal_guides_not_level", quiet, current, lib, judged, s)
    assert out.name == "end_effects" and out.verdict == "not separable"
    assert "horizontal guides off level was not significant (falls by 0.5%)" in out.reason


def test_the_latest_choice_is_tried_first():
    # two later effects: the most recent is the first whose removal is tried
    s = SelectionSettings()
    current = [*CURRENT, "cable_carrier_force"]
    rest = frozenset({"base", "commutation_offset", "end_effects"})
    judged = judge(
        {
            "guide_misalignment": {rest: (0.60, "passes")},
            "cable_carrier_force": {rest: (0.10, "passes"), rest | {"guide_misalignment"}: (0.02, "passes")},
        }
    )
    out = _later_in_its_place("guide_misalignment", CONFOUNDED, current, _library(), judged, s)
    assert out.name == "cable_carrier_force"
    assert judged.calls[0] == ("guide_misalignment", ("base", "commutation_offset", "end_effects"))


def _on_axes() -> dict:
    """A commutation offset (on both axes) and a tilt of the guides (along the track): the names,
    axes and parameters the functions read."""

    def cand(axis, *names):
        return SimpleNamespace(axis=axis, term=SimpleNamespace(parameter_names=names), nuisance=())

    return {
        "commutation_offset": cand("both", "angle_thrust", "angle_attraction"),
        "horizontal_guides_not_level": cand("horizontal", "tilt"),
        "guide_misalignment": cand("both", "slope"),
    }


def _tilt_after_offset(vertical_gain: float, later: str = "horizontal_guides_not_level"):
    """Pair 41102's backward pass: the offset kept over the later effect, not significant beside
    it; beside the rest the offset explains ``vertical_gain`` of the held-out vertical error (axis
    0) and 23.2 % of the horizontal (axis 1)."""
    rest = frozenset({"base"})
    current = ["base", "commutation_offset", later]
    calls = []

    def judged(name, others):
        calls.append((name, tuple(others)))
        assert name == "commutation_offset" and frozenset(others) == rest
        return dataclasses.replace(BASE, name=name, gain=0.232, gain_axes=np.array([vertical_gain, 0.232]))

    quiet = dataclasses.replace(
        BASE, name="commutation_offset", verdict="not significant", reason="falls by -1.2%"
    )
    kept_over = dataclasses.replace(
        BASE,
        name=later,
        verdict="not separable",
        reason="chosen before it",
        confounded_with=("commutation_offset",),
    )
    moving = np.array([True, True])
    out = _not_shown_beyond(
        "commutation_offset", quiet, kept_over, current, _on_axes(), judged, moving, SelectionSettings()
    )
    return out, calls


def test_an_effect_on_two_axes_kept_over_a_rival_on_one_must_show_on_the_other():
    # Pair 41102 of the noisy-observer rig: a -0.22 degree commutation offset kept over the tilt of
    # the guides it stands in for along the track (23.2 % against 22.5 % of the held-out horizontal
    # error), its attraction explaining nothing of the vertical error: neither is claimed
    out, calls = _tilt_after_offset(vertical_gain=-0.002)
    assert out is not None
    first, second = out
    assert (first.name, first.verdict, first.confounded_with) == (
        "commutation_offset",
        "not separable",
        ("horizontal_guides_not_level",),
    )
    assert (second.name, second.verdict, second.confounded_with) == (
        "horizontal_guides_not_level",
        "not separable",
        ("commutation_offset",),
    )
    assert "-0.2% of the held-out vertical error" in first.reason and "neither is claimed" in second.reason
    assert "beside horizontal guides off level, commutation angle offset was not significant" in first.reason
    assert calls == [("commutation_offset", ("base",))]  # judged beside the rest without the later one


def test_shown_on_its_other_axis_the_first_is_kept():
    # beyond the parsimony penalty (0.2 %) on the vertical axis the offset is what the log shows
    s = SelectionSettings()
    assert _tilt_after_offset(vertical_gain=s.parameter_penalty * 1.5)[0] is None
    assert _tilt_after_offset(vertical_gain=s.parameter_penalty * 0.5)[0] is not None
    # a later effect on both axes leaves no axis for the first alone: the rule does not apply
    assert _tilt_after_offset(vertical_gain=-0.002, later="guide_misalignment")[0] is None
