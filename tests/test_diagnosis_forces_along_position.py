"""A residual the library cannot name is reported, not hidden: the motor's forces falling towards one
end of the stator over the whole logged travel (an end effect whose near end is just beyond the
travel, its far end off it), from the independent generator (``tests/independent``).

Drawn pair 9813 of ``bench/diagnose_rigs.py --drawn-pairs`` with its end effect alone: a raised
cosine 34.5 mm wide from a stator end at +50 mm (the other at -300 mm), so the thrust is 7.5 %
lower at +40 mm than at -40 mm and the attraction 2 %. The end effects' own profiles, anchored at
the logged ends, fit it only as a growth at one end and a fall at the other, which they refuse;
the vertical residual it leaves (0.12 m/s^2 RMS held out, six times a clean log's) was, before,
taken up by three candidates not separable on the log (a 40 N constant vertical force beside a
halved C1: not physical), and the log was reported with nothing unexplained. About 10 s of CPU.
"""

from __future__ import annotations

import re

import pytest

from maglev_oc.diagnosis.guides import level_candidates
from maglev_oc.diagnosis.pipeline import _stands_for_residual
from maglev_oc.diagnosis.result import NotSeparable
from maglev_oc.diagnosis.selection import SMOOTH_POSITION, SelectionSettings
from maglev_oc.diagnosis.unexplained import BOTH_ENDS, along_the_stator
from maglev_oc.reporting.diagnosis_report import _finding_paragraphs
from maglev_oc.results import Estimate
from tests._diagnosis_cases import _ctx
from tests.diagnosis_support import diagnose_path
from tests.independent import write_log
from tests.independent.effects import EndEffect
from tests.independent.simulate import Scenario, simulate

ONE_SIDED = EndEffect(
    thrust_loss=0.0770,
    attraction_loss=0.0216,
    width=0.0345,
    end_position_plus=0.05,
    end_position_minus=-0.3,
    profile="cosine",
)


@pytest.fixture(scope="module")
def diagnosed(tmp_path_factory):
    run = simulate(Scenario(name="one_sided", seed=9813, effects=(ONE_SIDED,)))
    path, _ = write_log(run, tmp_path_factory.mktemp("one_sided"), stem="one_sided")
    return diagnose_path(path)


@pytest.mark.slow
def test_forces_falling_along_the_whole_travel_are_reported_as_unexplained(diagnosed):
    d = diagnosed
    assert d.effects == []  # nothing named in its place (no false claim)
    settings = SelectionSettings()
    vertical = [u for u in d.unexplained if u.axis == "vertical"]
    assert vertical, d.unexplained
    (u,) = vertical
    assert u.depends_on == "position"
    assert "in proportion to the magnets' attraction" in u.description
    # it is most of the vertical residual: the held-out error falls by more than half (measured
    # 97 %), and its size is the residual's order (measured 0.12 m/s^2, 50 times the smallest
    # size the selection reports)
    assert u.gain > 0.5
    assert u.size > 20 * settings.min_effect
    assert u.z >= settings.min_z
    # and it says how each force differs at the logged ends from the centre of the travel: the
    # change between the ends it quotes is the generator's own profile's within 30 % (the issue's
    # bound on sizes; measured -2.0 % for the true -1.9 %, and -7.2 % for the true -7.0 % of the
    # currents' forces)
    at = r"([-+]\d+\.\d) % at (-?\d+) mm and ([-+]\d+\.\d) % at (-?\d+) mm"
    m = re.search(rf"attraction is {at}, the currents' normal force {at}", u.description)
    assert m, u.description
    a_lo, lo, a_hi, hi, w_lo, _, w_hi, _ = (float(g) for g in m.groups())
    fall = ONE_SIDED.loss(hi * 1e-3) - ONE_SIDED.loss(lo * 1e-3)
    assert a_hi - a_lo == pytest.approx(-100 * ONE_SIDED.attraction_loss * fall, rel=0.3)
    assert w_hi - w_lo == pytest.approx(-100 * ONE_SIDED.thrust_loss * fall, rel=0.3)
    # and names what gives that shape: the generator's stator end is beyond the high logged end
    assert f"Falling towards the high end ({hi:.0f} mm): what a stator end near that end" in u.description


@pytest.mark.parametrize(
    ("low", "high", "said"),
    [
        (-1.0, -3.0, "Lower at both ends"),  # the smaller a third of the larger: both ends fall
        (-0.2, -3.0, "Falling towards the high end (40 mm)"),  # the low end's fall under BOTH_ENDS
        (1.0, -3.0, "Falling towards the high end (40 mm)"),
        (-3.0, 1.0, "Falling towards the low end (-40 mm)"),
        (2.0, 3.0, "Higher at both ends"),
        (3.0, -1.0, "Rising towards the low end (-40 mm)"),
        (0.0, 0.0, ""),
    ],
)
def test_forces_changing_along_the_travel_are_said_in_the_words_of_what_gives_that_shape(low, high, said):
    """The forces' change at the logged ends (relative to the centre), in words: lower at both ends
    is what end effects give; falling towards one end, a stator end beyond it or the true gap to the
    stator wider there; rising towards one, no end effect (they lower the forces), and no cause on the
    mover (the magnets ride on it: 000 Sec. II)."""
    text = along_the_stator(low, high, -0.04, 0.04)
    assert text.startswith(f" {said}") if said else text == ""
    assert ("end effect" in text) == (said != "")
    assert ("nearer the mover" in text) == said.startswith(("Higher", "Rising"))
    assert "magnets" not in text
    assert BOTH_ENDS == 0.25  # the threshold the first two rows straddle


def test_a_candidate_not_separable_takes_part_of_the_residual_only_where_its_fit_is_physical(model):
    # the constant vertical force of the one-sided log (40 N "if it were separable", beside a halved
    # C1) against one within a quarter of the stage's weight, the plausibility bound
    # (candidate.MAX_FORCE_SHARE: 0.25 M_v g = 10.7 N); a periodic force seen over too few periods
    # never takes part (it stands for a smooth dependence on the position)
    (cand,) = [c for c in level_candidates(_ctx(model)) if c.name == "constant_vertical_force"]

    def judged(force: float, confounded=("C2",)) -> NotSeparable:
        return NotSeparable(cand.name, confounded, "", 0.4, "", {"force": Estimate(force, 0.9, "N")})

    assert not _stands_for_residual(judged(40.4), cand)
    assert _stands_for_residual(judged(2.0), cand)
    assert not _stands_for_residual(judged(2.0, (SMOOTH_POSITION,)), cand)


@pytest.mark.slow
def test_the_report_does_not_say_the_model_explains_the_log(diagnosed):
    # the report's words said "the papers' model, refitted, explains the log to its noise" when
    # nothing was named, whatever was left unexplained
    paragraphs = _finding_paragraphs(diagnosed)
    assert paragraphs[0].startswith("No effect of the library found")
    assert "does not explain the log to its noise" in paragraphs[0]
    # the candidates judged and refused are in the report's words with their reason (the issue's
    # "rejected ... candidates with the reason"; they were in the JSON only): here the end effects,
    # whose fit grows at one end
    rejected = [p for p in paragraphs if p.startswith("Judged and not claimed (implausible): end effects")]
    assert len(rejected) == 1 and "one end up, the other down" in rejected[0]
    assert "not claimed: end_effects (implausible)" in diagnosed.report()
