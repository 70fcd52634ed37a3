"""A candidate listed as not separable from an effect that was chosen and then dropped says so
(``pipeline._beside_dropped``): it was judged beside an effect the diagnosis no longer claims."""

from __future__ import annotations

from types import SimpleNamespace

from maglev_oc.diagnosis.pipeline import _beside_dropped
from maglev_oc.diagnosis.result import NotSeparable

TILT, OFFSET, CARRIER = "horizontal_guides_not_level", "current_sensor_offset", "cable_carrier_force"


def _listed(name: str, *confounded: str) -> NotSeparable:
    return NotSeparable(name, confounded, "a run elsewhere", 0.4, f"not separable from {confounded}", {})


def test_an_entry_confounded_with_a_dropped_effect_says_it_was_dropped_and_the_rest_are_untouched():
    # drawn pair 40103 (a detent and a cable carrier over a small travel): the tilt was listed as
    # confounded with a current sensor offset that was then dropped as not specific
    dropped = SimpleNamespace(name=OFFSET, verdict="not specific")
    sel = SimpleNamespace(selected=[CARRIER])
    tilt, other = _listed(TILT, OFFSET), _listed("guide_misalignment", CARRIER)
    out = _beside_dropped([tilt, other], [dropped], sel)
    assert [n.name for n in out] == [TILT, "guide_misalignment"]
    assert out[0].reason.startswith(tilt.reason)
    assert "Dropped afterwards: current sensor offset (not specific); neither is claimed" in out[0].reason
    assert out[0].confounded_with == (OFFSET,)
    assert out[1] is other  # confounded with an effect still claimed: as it was


def test_a_rejected_candidate_that_is_still_chosen_is_not_called_dropped():
    # a form refused at one step and chosen at a later one is claimed: nothing to say
    refused_then_chosen = SimpleNamespace(name=CARRIER, verdict="implausible")
    entry = _listed(TILT, CARRIER)
    assert _beside_dropped([entry], [refused_then_chosen], SimpleNamespace(selected=[CARRIER])) == [entry]
