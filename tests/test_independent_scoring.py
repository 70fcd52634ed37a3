"""The scorer of the diagnosis issue (``tests/independent/scoring.py``) on hand-made truths and
answers: what it counts as found, missed and false, and which size of an end effect it compares."""

from __future__ import annotations

import pytest

from tests.independent.effects import EndEffect
from tests.independent.scoring import SIZE_TOLERANCE, score, sizes

LAG = {"kind": "amplifier_dynamics", "axis": "both", "parameters": {"bandwidth": 150.0, "delay": 2e-4}}
LAG_CLAIM = {"name": "current_amplifier_lag", "parameters": {"time_constant": 1.26e-3}}


def _truth(*effects: dict, currents: str = "commanded") -> dict:
    return {"effects": list(effects), "rig": {"logged_currents": currents}}


def test_an_amplifier_lag_counts_only_where_the_logged_currents_are_the_commands():
    # commanded currents: the lag is in the log, missed when not claimed, found (and sized:
    # 1/(2 pi 150) + 0.2 ms = 1.261 ms) when claimed
    missed = score("log", _truth(LAG), [])
    assert not missed.size_right and missed.notes == ["amplifier_dynamics not claimed"]
    found = score("log", _truth(LAG), [LAG_CLAIM])
    assert found.true_first and found.no_false_claim and found.size_right
    # measured currents: nothing in the log shows the lag, so not claiming it is the right answer
    # (a clean log's score) and claiming it is a false claim
    right = score("log", _truth(LAG, currents="measured"), [])
    assert (right.truth, right.true_first, right.no_false_claim, right.size_right) == ([], True, True, True)
    wrong = score("log", _truth(LAG, currents="measured"), [LAG_CLAIM])
    assert not wrong.no_false_claim and not wrong.true_first
    # a truth without a rig (a hand-written one) counts the lag as the commanded case does
    assert not score("log", {"effects": [LAG]}, []).size_right


def _ends(claimed: dict, **truth) -> tuple[float, float]:
    t = EndEffect(**truth).parameters()
    c = {"low_end_position": -0.02557, "high_end_position": 0.03404, **claimed}
    return sizes({"kind": "end_effect", "parameters": t}, {"parameters": c})


def test_end_effects_are_compared_by_their_ends_mean_unless_the_ends_differ_in_sign():
    # both stator ends 10-16 mm beyond the logged ends (the default +-50 mm): both ends lose
    # thrust relative to the centre, and the mean is compared, as before
    claimed = {"thrust_loss_at_ends": 0.02, "thrust_loss_at_low_end": 0.5, "thrust_loss_at_high_end": 0.5}
    true, said = _ends(claimed, thrust_loss=0.05)
    t = EndEffect(thrust_loss=0.05)
    centre = t.loss((0.03404 - 0.02557) / 2)
    assert true == pytest.approx(0.05 * ((t.loss(-0.02557) + t.loss(0.03404)) / 2 - centre), rel=1e-12)
    assert said == 0.02
    # drawn pair 37003's end effects (one stator end at +50 mm, cosine fall over 24.7 mm, the other
    # 300 mm away): +2.97 % at the high end, -1.67 % at the low end; the high end is compared, and
    # the diagnosis's own numbers there (+3.46 %, a mean of 1.28 %) are within the tolerance while
    # the mean (0.65 % true) is not
    one_sided = dict(
        thrust_loss=0.05217, end_position_plus=0.05, end_position_minus=-0.3, width=0.02471, profile="cosine"
    )
    said_37003 = {
        "thrust_loss_at_ends": 0.0128,
        "thrust_loss_at_low_end": -0.009,
        "thrust_loss_at_high_end": 0.0346,
    }
    true, said = _ends(said_37003, **one_sided)
    assert (true, said) == (pytest.approx(0.0297, abs=1e-4), 0.0346)
    assert abs(said - true) <= SIZE_TOLERANCE * true
    mean, _ = _ends({"thrust_loss_at_ends": 0.0128}, **one_sided)  # no ends of its own: the mean
    assert mean == pytest.approx(0.0065, abs=1e-4)
    # mirrored (the stator end near the low end of the travel): the low end is compared
    mirrored = dict(one_sided, end_position_plus=0.3, end_position_minus=-0.042)
    true, said = _ends(said_37003, **mirrored)
    assert true > 0 and said == -0.009
