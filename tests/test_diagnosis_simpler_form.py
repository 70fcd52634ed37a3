"""A chosen effect gives way to its simpler form (``Candidate.simpler``) when, beside the rest of
the selection, that form explains as much of the held-out error within the parsimony penalty of the
parameters it lacks (the selection's backward pass, ``selection._simpler_in_place``)."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np

from maglev_oc.diagnosis.selection import Judgement, SelectionSettings, _richer_in_place, _simpler_in_place
from tests._diagnosis_cases import _judgement as injected_judgement


def _named(j: Judgement, name: str, gain: float, verdict: str = "passes") -> Judgement:
    return dataclasses.replace(j, name=name, verdict=verdict, gain_axes=np.array([np.nan, gain]))


BASE = injected_judgement(z=5.0, wald=100.0)


def _library() -> dict:
    """A spring along the track whose simpler form is the tilt's constant force, the tilt, and a
    candidate that is neither's form (the names, parameters and ``simpler`` links the two
    functions read)."""

    def term(*names):
        return SimpleNamespace(parameter_names=names)

    return {
        "cable_carrier_force": SimpleNamespace(
            simpler="horizontal_guides_not_level", term=term("stiffness", "force_at_zero"), nuisance=()
        ),
        "horizontal_guides_not_level": SimpleNamespace(simpler=None, term=term("force"), nuisance=()),
        "thrust_ripple": SimpleNamespace(simpler=None, term=term("a", "b"), nuisance=()),
    }


def beside(gain: float, verdict: str = "passes"):
    """A judge that finds every candidate with this held-out gain and verdict."""
    return lambda name, others: _named(BASE, name, gain, verdict)


def test_a_spring_gives_way_to_a_tilt_that_explains_as_much_beside_the_rest():
    # A spring along the track at zero stiffness is the tilt's constant force (guides.cable_candidate):
    # beside the rest of a selection the tilt takes its place when it explains as much of the held-out
    # error within the parsimony penalty of the one parameter it lacks (set 24602: 0.06 N/m of spring
    # that explained nothing more than the constant), and not when the spring explains more.
    s, by_name = SelectionSettings(), _library()
    spring = _named(BASE, "cable_carrier_force", 0.50)

    others = ["base", "guide_misalignment"]
    assert _simpler_in_place(spring, by_name, others, beside(0.50 - 0.9 * s.parameter_penalty), s).name == (
        "horizontal_guides_not_level"
    )
    assert _simpler_in_place(spring, by_name, others, beside(0.50 - 1.1 * s.parameter_penalty), s) is None
    # one that does not pass beside the rest, or is chosen already, does not take the place
    assert _simpler_in_place(spring, by_name, others, beside(0.50, "not significant"), s) is None
    chosen = [*others, "horizontal_guides_not_level"]
    assert _simpler_in_place(spring, by_name, chosen, beside(0.50), s) is None
    # a candidate without a simpler form is left alone
    tilt = _named(BASE, "horizontal_guides_not_level", 0.50)
    assert _simpler_in_place(tilt, by_name, others, beside(0.60), s) is None


def test_a_tilt_gives_way_to_a_spring_that_explains_more_than_its_parameter_costs():
    # The other way round (selection._richer_in_place): a tilt chosen early, when the spring's line
    # was judged against a smooth function of the gap that the effects not yet chosen made (set
    # 25905 on the papers' PID loops: a 7.1 N/m cable carrier beside large end effects and a
    # commutation offset; a current sensor offset took the spring's line), gives way to the spring
    # when beside the rest it explains more than the tilt by more than the penalty of its extra
    # parameter, and not within it.
    s, by_name = SelectionSettings(), _library()
    tilt = _named(BASE, "horizontal_guides_not_level", 0.30)

    others = ["base", "commutation_offset"]
    richer = _richer_in_place(tilt, by_name, others, beside(0.30 + 1.1 * s.parameter_penalty), s)
    assert richer.name == "cable_carrier_force"
    assert _richer_in_place(tilt, by_name, others, beside(0.30 + 0.9 * s.parameter_penalty), s) is None
    assert _richer_in_place(tilt, by_name, others, beside(0.60, "not specific"), s) is None
    assert _richer_in_place(tilt, by_name, [*others, "cable_carrier_force"], beside(0.60), s) is None
    # a candidate that is no simpler form of another is left alone
    spring = _named(BASE, "cable_carrier_force", 0.30)
    assert _richer_in_place(spring, by_name, others, beside(0.60), s) is None
