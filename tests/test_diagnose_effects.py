"""Every effect of the independent generator alone at two sizes, and pairs of effects: found first,
sized within 30 %, nothing else claimed (the diagnosis issue's acceptance tests; see
``tests/test_diagnose.py`` for the logs and the scoring)."""

from __future__ import annotations

import json
import math

import pytest

from maglev_oc.diagnosis import pipeline
from maglev_oc.diagnosis.magnetics import END_WIDTHS
from maglev_oc.diagnosis.selection import SMOOTH_POSITION, SelectionSettings
from tests.diagnosis_support import diagnose_path, relative_errors
from tests.independent.scoring import SIZE_TOLERANCE, score, sizes
from tests.independent.sets import named_set

LIMITS_READ = {"field_shape_large", "field_shape_small"}
"""The logs of :func:`diagnosed_here` whose detection limits a test here reads (the others are
diagnosed without them)."""


@pytest.fixture(scope="module")
def diagnosed_here(generated):
    """The default diagnosis of a generated log by (set, stem), once per module: the large field
    shape is diagnosed by two tests here (the session fixture ``diagnosed`` would put this long file
    on the worker of the files that share it)."""
    cache: dict[tuple[str, str], tuple] = {}

    def get(set_name: str, stem: str):
        if (set_name, stem) not in cache:
            path, truth = generated(set_name, stem)
            limits = truth["name"] in LIMITS_READ
            cache[(set_name, stem)] = (diagnose_path(path, limits=limits), truth)
        return cache[(set_name, stem)]

    return get


# --- each effect alone, two sizes ----------------------------------------------------------------
def _single_stems() -> list[tuple[str, str]]:
    return [(stem, scenario.name) for stem, scenario in named_set("single")]


QUICK = {"guide_friction_horizontal_small", "normal_cogging_large", "cable_carrier_small"}
FIELD_SHAPE = pytest.mark.xfail(
    strict=True,
    reason="below what this log can show: the attraction's part is absorbed by the constants (see "
    "test_field_shape_...), and the thrust's part of the small one is too weak (z 0.6 over the held-out "
    "quarter); the log's own detection limit, 9.3 % of the attraction at its smallest gap against the "
    "true 2 %, says so (test_a_field_shape_below_the_logs_limit_is_reported_as_such)",
)


EVERY_RUN_SIZE = {"normal_cogging": "large", "field_shape": "large"}
"""The size of each effect checked on every run (CI): the small one, which tests the detection,
except where the small one is the quick subset's (normal cogging) or a known miss (the field
shape); the other size is in the extended tier (``-m extended``; pyproject.toml)."""


def _marks(name: str) -> list:
    marks = [] if name in QUICK else [pytest.mark.slow]
    effect, size = name.rsplit("_", 1)
    if size != EVERY_RUN_SIZE.get(effect, "small"):
        marks.append(pytest.mark.extended)
    return marks + ([FIELD_SHAPE] if name == "field_shape_small" else [])


@pytest.mark.parametrize(
    ("stem", "name"),
    [pytest.param(stem, name, marks=_marks(name), id=name) for stem, name in _single_stems()],
)
def test_each_effect_alone_is_found_first_and_sized(diagnosed_here, stem, name):
    d, truth = diagnosed_here("single", stem)
    s = score(stem, truth, d.to_dict()["effects"])
    assert s.no_false_claim, s.claimed
    assert s.true_first, (s.claimed, s.notes)
    assert s.size_right, s.notes  # within 30 % of the truth (the bound)
    true = truth["effects"][0]
    if true["kind"] in ("normal_cogging", "detent_force"):
        # the size the report quotes at the papers' 15 mm gap, extrapolated from the logged gaps
        # with the field harmonic's decay: the truth's peak carried to 15 mm by its own decay law
        found = d.to_dict()["effects"][0]["parameters"]
        decay = true["derived"]["decay_length_fundamental_m"]
        at_15 = true["parameters"]["peak_force"] * math.exp(
            -(0.015 - true["parameters"]["reference_gap"]) / decay
        )
        assert found["amplitude_15mm"] == pytest.approx(at_15, rel=0.3), (found, at_15)


EVERY_RUN_PAIRS = {"pairs_01", "pairs_02"}
"""Pairs checked on every run (CI; pairs_03 has its own test below); the others are in the extended
tier (``-m extended``)."""

KNOWN_PAIR_FAILURES = {
    "pairs_05": pytest.mark.xfail(
        strict=True,
        reason="the amplifier lag next to vertical friction is judged on the horizontal axis alone (on the "
        "vertical one its column is the friction's viscous part), and there it is sized right (1.14 +- 0.17 "
        "ms against 1.16 beyond the hold, z 8.9) but moves the prediction by 1.6e-3 m/s^2 RMS, under one "
        "encoder count's 2.25e-3: too small",
    ),
}


@pytest.mark.slow
@pytest.mark.parametrize(
    "stem",
    [
        pytest.param(
            stem,
            marks=([KNOWN_PAIR_FAILURES[stem]] if stem in KNOWN_PAIR_FAILURES else [])
            + ([] if stem in EVERY_RUN_PAIRS else [pytest.mark.extended]),
            id=stem,
        )
        for stem, _ in named_set("pairs")
        if stem != "pairs_03"  # its own test below
    ],
)
def test_two_effects_together_are_both_found(generated, stem):
    _all_found(generated, "pairs", stem)


def _all_found(generated, set_name: str, stem: str) -> None:
    """Every true effect of the log found, first among the claims, nothing false, each sized within
    30 % (the issue's criteria, tests/independent/scoring.py)."""
    path, truth = generated(set_name, stem)
    s = score(stem, truth, diagnose_path(path).to_dict()["effects"])
    assert s.true_first, s.claimed
    assert s.no_false_claim, s.claimed
    assert s.size_right, (s.claimed, s.notes)


KNOWN_TRIPLE_FAILURES = {
    "triples_02": pytest.mark.xfail(
        strict=True,
        reason="the vertical friction beside horizontal friction, detent and ripple: 0.36 +- 0.5 N against "
        "0.6 N, within its standard error but not the 30 %",
    ),
    "triples_08": pytest.mark.xfail(
        strict=True, reason="the field's shape beside large end effects and friction: not claimed"
    ),
}


@pytest.mark.slow
@pytest.mark.extended
@pytest.mark.parametrize(
    "stem",
    [
        pytest.param(
            stem, marks=[KNOWN_TRIPLE_FAILURES[stem]] if stem in KNOWN_TRIPLE_FAILURES else [], id=stem
        )
        for stem, _ in named_set("triples")
        if stem != "triples_07"  # below
    ],
)
def test_three_or_four_effects_together_are_all_found(generated, stem):
    # bench/README "Three or four effects together": 8/8/6. triples_03 (a commutation offset
    # beside 1 N of friction) and triples_04 (a misalignment beside vertical friction) passed
    # only once sticking guides held every force but the friction's and the gap dependences'.
    _all_found(generated, "triples", stem)


@pytest.mark.slow
@pytest.mark.extended
def test_a_tilt_beside_friction_is_found_in_the_frictions_entry(generated):
    # triples_07: 1 N of horizontal friction, guides tilted by 5 mrad (0.078 N along the track) and
    # a thrust ripple. The tilt's force is what friction 8 % larger one way gives, and no run of the
    # stage tells the two apart (pipeline._merged_friction_by_direction): it is found and sized in
    # the friction's entry, and the tilt is not claimed but listed as not separable from it
    path, truth = generated("triples", "triples_07")
    out = diagnose_path(path).to_dict()
    s = score("triples_07", truth, out["effects"])
    assert s.claimed == ["guide_friction_horizontal", "thrust_ripple"]
    assert s.notes == ["tilted_base not claimed"]  # friction and ripple sized within 30 %
    force = next(e for e in truth["effects"] if e["kind"] == "tilted_base")["derived"]["horizontal_force_N"]
    assert out["effects"][0]["parameters"]["force_along_track"] == pytest.approx(force, rel=0.3)
    assert "horizontal_guides_not_level" in [n["name"] for n in out["not_separable"]]


@pytest.mark.slow
@pytest.mark.extended
def test_a_periodic_force_over_too_few_periods_is_not_claimed(generated):
    # pairs_03: a 4 mrad misalignment with 8 um waviness at 60 mm, and a 5 % end effect at +-50 mm
    # (2.6 % at +-40 mm). The travel (about 70 mm) covers 1.2 pole pitches: the end effect's
    # smooth fall of the thrust towards the ends fits a 57 mm detent as well as a bowl. Such a
    # force is not separable from a smooth dependence on the position
    # (SelectionSettings.min_periods = 1.25): judged so, never claimed. The end effect itself is
    # claimed beside the misalignment (its z 1.5 over the held-out quarter, 3.8 with the
    # cross-fitted training parts).
    path, truth = generated("pairs", "pairs_03")
    d = diagnose_path(path)
    s = score("pairs_03", truth, d.to_dict()["effects"])
    assert s.true_first and s.no_false_claim, s.claimed
    assert s.size_right, s.notes  # both within 30 % of the truth (the bound)
    assert [e.name for e in d.effects] == ["guide_misalignment", "end_effects"]
    assert d.effects[0].parameters["slope"].value == pytest.approx(0.004, rel=0.3)
    judged = [st.judgements["cogging_horizontal_57mm"] for st in d.selection.steps]
    assert any(j.verdict == "not separable" and SMOOTH_POSITION in j.confounded_with for j in judged)
    assert any("fewer than 1.25" in j.reason for j in judged)


@pytest.mark.slow
@pytest.mark.extended
def test_without_the_periods_rule_the_same_log_names_a_detent(generated, monkeypatch):
    # the failure the rule above fixes: with SelectionSettings.min_periods = 0, pairs_03's end
    # effect is named a 57 mm detent (extended tier: more diagnoses of that log, which only show
    # the rules are what make the difference). Two more rules now refuse it too: chosen beside the
    # misalignment, the detent has a guide waviness at its own period as rival
    # (pipeline._chosen_pitches), which explains as much in its place; and beside the misalignment
    # and the end effects a waviness longer than the travel is scanned for
    # (pipeline._waviness_beyond_travel: on this log a period is found, and the selection repeated
    # with that waviness in the pool does not take the detent). And a force at a motor pitch seen
    # over fewer than pipeline.SHORT_PERIODS (2) of its periods is judged beside the unexplained
    # dependence on the position, which explains what the detent did (dropped as not specific).
    # Without all four, it is named
    path, _ = generated("pairs", "pairs_03")
    off = diagnose_path(path, settings=SelectionSettings(min_periods=0.0))
    assert "cogging_horizontal_57mm" not in [e.name for e in off.effects]
    monkeypatch.setattr(pipeline, "_chosen_pitches", lambda library, sel: [])
    off = diagnose_path(path, settings=SelectionSettings(min_periods=0.0))
    assert "cogging_horizontal_57mm" not in [e.name for e in off.effects]
    monkeypatch.setattr(pipeline, "_waviness_beyond_travel", lambda *args: [])
    off = diagnose_path(path, settings=SelectionSettings(min_periods=0.0))
    assert "cogging_horizontal_57mm" not in [e.name for e in off.effects]
    assert any(r.name == "cogging_horizontal_57mm" and r.verdict == "not specific" for r in off.rejected)
    monkeypatch.setattr(pipeline, "SHORT_PERIODS", 0.0)
    off = diagnose_path(path, settings=SelectionSettings(min_periods=0.0))
    assert "cogging_horizontal_57mm" in [e.name for e in off.effects]


def test_every_candidate_judged_not_separable_is_listed_with_what_would_separate_it(diagnosed_here):
    # SPEC 3's not_separable: each candidate whose last judgement was "not separable", with what it
    # is confounded with and the experiment that would separate it, and no other. The large field
    # shape's log of the single set has one (a gap sensor offset, confounded with the constants;
    # bench/README's runs of the sets list it on that log alone)
    d, _ = diagnosed_here("single", "single_22")
    refused = {n for n, j in d.selection.last.items() if j.verdict == "not separable"}
    assert refused
    assert {n.name for n in d.not_separable} == refused
    for n in d.not_separable:
        assert n.confounded_with and n.experiment, n
    # the log showed them (it could not tell them apart): they have no detection limit, which is
    # for the effects the log did not show (maglev_oc.diagnosis.limits)
    assert not refused & {x.name for x in d.detection_limits}
    # and the result records the selection's settings it was judged by (the defaults here)
    from dataclasses import asdict

    from maglev_oc.diagnosis.selection import SelectionSettings

    assert d.settings["selection"] == asdict(SelectionSettings())


@pytest.mark.slow
@pytest.mark.extended
def test_a_field_shape_below_the_logs_limit_is_reported_as_such(diagnosed_here):
    # The small field shape (the field 1 % stronger at 14.5 mm, the attraction 2 %) is not found
    # (FIELD_SHAPE above). What the diagnosis must then say is that this log could not have shown
    # it: nothing claimed in its place, and a detection limit for the field's gap dependence above
    # the true size (measured 9.3 %: the thrust's part moves the prediction by less than the
    # selection's smallest size at any change the physics allows below that). A limit below the
    # truth would tell the user the log rules out an effect it did not see.
    stem = next(s for s, sc in named_set("single") if sc.name == "field_shape_small")
    d, truth = diagnosed_here("single", stem)
    assert d.effects == []
    limits = {lim.name: lim for lim in d.detection_limits}
    limit = limits["magnet_field_gap_dependence"]
    assert limit.parameter == "attraction_change_at_smallest_gap"
    true = truth["effects"][0]["derived"]["attraction_factor_at_14.5_mm"] - 1.0  # its largest, 2 %
    assert limit.value > true


@pytest.mark.slow
def test_a_field_shapes_attraction_is_absorbed_by_the_constants_and_its_thrust_is_found(diagnosed_here):
    # A field weaker/stronger with the gap (B times exp(-k1 d - k2 d^2)) multiplies the attraction
    # by a smooth function of the gap. On a closed-loop log the levitation current follows the
    # gap (it is the equilibrium current plus small transients), so C3 l3(g) i_d(g) and
    # C4 l4(g) i_d(g)^2 span the same smooth functions of the gap: the base fit absorbs the
    # attraction's part into C3, C4 (the experiment that shows it is the papers' equilibrium
    # currents over 10-25 mm, 000 Sec. V-B, where the gap is swept with the current held). The
    # thrust's part, where the stage pushes at small gaps, is what is found: with the
    # cross-fitted training parts its z is 5.3 (1.6 over the held-out quarter alone).
    stem = next(s for s, sc in named_set("single") if sc.name == "field_shape_large")
    d, truth = diagnosed_here("single", stem)  # shared with the test of the single effects
    assert [e.name for e in d.effects] == ["magnet_field_gap_dependence"]
    j = d.selection.steps[0].judgements["magnet_field_gap_dependence"]
    assert j.z >= SelectionSettings().min_z > j.z_holdout
    err = relative_errors(d, truth)
    assert abs(err["C4"]) > 0.2  # the attraction's part went into C4 (measured +136 %)


def _eleven_scored(generated, name: str):
    """(diagnosis, score) of the eleven set's log whose scenario is ``name``."""
    stem = next(s for s, sc in named_set("eleven") if sc.name == name)
    path, truth = generated("eleven", stem)
    d = diagnose_path(path)
    return d, score(stem, truth, d.to_dict()["effects"])


@pytest.mark.slow
def test_a_strong_field_shape_is_found_where_the_stage_pushes_at_small_gaps(generated):
    # The benchmark's large field shape (eleven_10: the field +2.8 % at 14.5 mm, -1.2 % at
    # 24.5 mm). Its thrust part moves the held-out prediction by 1.5e-3 m/s^2 RMS, under the
    # 2.25e-3 m/s^2 of one encoder count, and by about 3e-3 in the held-out half-second where it
    # is largest; its Wald statistic is 17 times its threshold (measured), so it is sized where it
    # is largest (SelectionSettings' strong path) and claimed, alone and first.
    d, s = _eleven_scored(generated, "field_shape")
    assert s.true_first and s.no_false_claim, s.claimed
    assert s.size_right, s.notes  # the attraction's change at the smallest gap within 30 %
    j = d.selection.steps[0].judgements["magnet_field_gap_dependence"]
    settings = SelectionSettings()
    assert j.contribution_rms.max() < settings.min_effect <= j.contribution_peak.max()
    assert j.wald >= settings.strong_wald * j.wald_threshold


@pytest.mark.slow
def test_the_end_effects_are_diagnosed_at_their_scanned_width(generated):
    # eleven_01: the large end effect alone, falling over 20 mm (12 % of the thrust and 8 % of the
    # attraction lost at +-50 mm). The first selection fits it at the library's 15 mm; the scan
    # finds 18.9 mm (the scanned width nearest 20 mm) and the selection is repeated there, so the
    # result reports that width, and the size within 30 % (the bound; measured 0.3 %).
    d, s = _eleven_scored(generated, "end_effect")
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes)
    (effect,) = d.effects
    assert effect.parameters["width"].value == pytest.approx(END_WIDTHS[5], rel=1e-12)


@pytest.mark.slow
def test_end_effects_that_are_not_exponential_are_found_at_their_scanned_width(tmp_path):
    # The fringing as a raised cosine (the generator's EndEffect.profile = "cosine"): 10 % of the
    # thrust and 6 % of the attraction lost at +-50 mm, none further in than 20 mm from the
    # centre, 7.5 % of the thrust at the logged ends (bench/diagnose_rigs.py --variants,
    # end_effect_cosine). The library's exponential at 15 mm does not fit it: its first judgement
    # failed (on another seed of the same variant, "not specific": a smooth function of the gap
    # explained more) and nothing was claimed. Its held-out gain shows the data have it, so its
    # width is scanned although it was not chosen, and at the scanned width it is found, alone,
    # and sized within 30 % (the bound).
    from tests.independent import effects as E
    from tests.independent import write_log
    from tests.independent.simulate import Scenario, simulate

    effect = E.EndEffect(thrust_loss=0.10, attraction_loss=0.06, width=0.01, profile="cosine")
    path, truth_path = write_log(
        simulate(Scenario(name="end_effect_cosine", seed=817, effects=(effect,))), tmp_path, stem="variant"
    )
    d = diagnose_path(path)
    s = score("variant", json.loads(truth_path.read_text()), d.to_dict()["effects"])
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes)
    assert [e.name for e in d.effects] == ["end_effects"]
    # a width other than the library's (the scan's narrowest widths fit a fall confined to the ends)
    assert d.effects[0].parameters["width"].value < END_WIDTHS[4]


def _drawn_pair(
    tmp_path,
    seed: int,
    kinds: tuple[str, ...],
    rig="default",
    extra: tuple = (),
    payload: tuple = (0.0, False),
    duration: float = 60.0,
):
    """The log ``bench/diagnose_rigs.py --drawn-pairs`` writes for ``seed`` with these kinds (each
    effect drawn from its own generator, seeded by the log's seed and the kind's index), on ``rig``
    (a ``Rig``, or the name of one of ``tests.independent.rigs.RIGS``, as ``--rig`` takes it), with
    the effects ``extra`` added after them (as ``--shake`` adds the base's vibration) and
    ``payload`` (kg, declared in the log or not: ``--payload``, ``--undeclared``), diagnosed with
    the defaults and scored: (effects, diagnosis, score); ``duration`` [s] as ``--duration`` sets it."""
    import numpy as np

    from tests.independent import write_log
    from tests.independent.draws import KINDS, draw
    from tests.independent.rigs import RIGS
    from tests.independent.simulate import Rig, Scenario, simulate

    effects = tuple(draw(k, np.random.default_rng([seed, KINDS.index(k)])) for k in kinds)
    on = rig if isinstance(rig, Rig) else Rig(**RIGS[rig])
    scenario = Scenario(
        name="+".join(kinds),
        seed=seed,
        effects=(*effects, *extra),
        rig=on,
        payload=payload[0],
        declare_payload=payload[1],
        duration=duration,
    )
    path, truth_path = write_log(simulate(scenario), tmp_path, stem="pair")
    d = diagnose_path(path)
    return effects, d, score("pair", json.loads(truth_path.read_text()), d.to_dict()["effects"])


def _drawn_pair_finds(
    tmp_path,
    seed: int,
    kinds: tuple[str, ...],
    names: list[str],
    sized: bool = True,
    rig="default",
    extra: tuple = (),
    payload: tuple = (0.0, False),
):
    """:func:`_drawn_pair` (on ``rig``, with ``extra`` and ``payload``), asserting the true effect
    first, no false claim, every size within 30 % (the issue's bound) when ``sized``, and exactly
    the effects ``names``: (effects, diagnosis)."""
    effects, d, s = _drawn_pair(tmp_path, seed, kinds, rig, extra, payload)
    assert s.true_first and s.no_false_claim and (s.size_right or not sized), (s.claimed, s.notes)
    assert sorted(e.name for e in d.effects) == sorted(names)
    return effects, d


def _off(d, name: str, parameter: str, truth: float) -> float:
    """The relative error of a claimed effect's parameter against its true value (the issue's size
    bound is :data:`~tests.independent.scoring.SIZE_TOLERANCE`, 30 %)."""
    return abs(next(e for e in d.effects if e.name == name).parameters[parameter].value / truth - 1)


@pytest.mark.slow
@pytest.mark.extended
def test_a_spring_and_a_misalignment_on_a_pid_rig_are_not_the_current_sensors_errors(tmp_path):
    # A random pair on the papers' PID loops (bench/diagnose_rigs.py --drawn-pairs --rig pid, seed
    # 15307): guides that change the gap by -2.4 um/mm along the track (4.2 um of waviness at 49 mm)
    # and a cable carrier's 8.8 N/m spring, over 66 mm of travel. A current sensor offset moves both
    # axes with one pair of coefficients and explained 63 % of the held-out error at the first step
    # against 55 and 49 % for each true effect alone: a 30 mA offset and a 0.9 % gain mismatch were
    # claimed, 64 % of the horizontal residual left unexplained. Without the sensors' errors the
    # other candidates explain 94.8 % against 79.6 % (pipeline._tie_shown): the two true effects,
    # sized within 30 % (the bound; measured slope -2.3 for -2.36 mrad, 8.7 for 8.78 N/m).
    # Since the selection tries two effects over its step's best (selection._pair_over_best), the
    # spring and the slope are chosen together at the first step, and beside them the offset
    # explains nothing that passes: not claimed, and no longer listed as refused.
    _, d, s = _drawn_pair(tmp_path, 15307, ("guide_misalignment", "cable_carrier"), "pid")
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes)
    assert sorted(e.name for e in d.effects) == ["cable_carrier_force", "guide_misalignment"]
    offset = d.selection.last["current_sensor_offset"]
    assert offset.verdict not in ("passes", "accepted"), offset


@pytest.mark.slow
def test_a_commutation_offset_that_only_the_thrust_shows_is_found_from_the_thrust(tmp_path):
    # A random pair on a rig logging its amplifiers' measured currents with 10 mA of noise
    # (bench/diagnose_rigs.py --rig measured --drawn-pairs, seed 20511): a -1.2 degree commutation
    # offset, whose thrust (i_d sin d, i_d about 1.7 A) rivals the commanded i_q (-0.02 to 0.08 A),
    # and end effects of 8 % of the thrust and 5 % of the attraction at +-50 mm (a raised cosine
    # 27 mm long). Fitted on both axes the offset had the true angle from the thrust but its free
    # vertical coefficient, weighed by i_q alone, made the vertical held-out error 2.3 % worse: refused
    # as not specific, nothing claimed, C1 left at 0.56 (true 14.7) with its warning, the horizontal
    # residual reported unexplained. Its form fitted on the thrust alone is the offset found there.
    effects, d, s = _drawn_pair(tmp_path, 20511, ("end_effect", "commutation_offset"), "measured")
    assert s.true_first and s.no_false_claim, (s.claimed, s.notes)
    assert sorted(e.name for e in d.effects) == ["commutation_offset", "end_effects"]
    offset = next(e for e in d.effects if e.name == "commutation_offset").parameters["angle"]
    true_angle = effects[1].angle
    # within 30 % (the bound; measured -0.02100 rad for -0.02103)
    assert abs(offset.value / true_angle - 1) < 0.3
    assert not d.warnings
    assert abs(relative_errors(d, json.loads((tmp_path / "pair.truth.json").read_text()))["C1"]) < 0.05


@pytest.mark.slow
def test_the_thrust_form_of_the_offset_does_not_leave_its_attraction_to_another_effect(tmp_path):
    # The same rig, seed 21060: a 1.6 degree offset beside 1.1 N of normal cogging. With the thrust
    # form of the offset chosen whenever the full form was not significantly better (a first form of
    # the change above), the attraction that i_q makes was left out and a guide misalignment took it:
    # a false claim. The thrust form stands in only where the full form is not specific.
    kinds, names = ("normal_cogging", "commutation_offset"), ["cogging_vertical_19mm", "commutation_offset"]
    _, d = _drawn_pair_finds(tmp_path, 21060, kinds, names, rig="measured")
    assert "commutation_offset_horizontal" not in d.selection.last


@pytest.mark.slow
def test_end_effects_beside_a_commutation_offset_lose_a_share_of_the_thrust_both_currents_make(tmp_path):
    # A random pair on a vibrating base (bench/diagnose_rigs.py --drawn-pairs 12 --shake small
    # --seed 22400, pair 22407): a 3.2 degree commutation offset, whose thrust d i_d (i_d about
    # 1.7 A) outweighs i_q's, and end effects of 11 % of the thrust and 7 % of the attraction at
    # +50 mm (a cosine 18 mm long; the stator's other end far off). Their thrust share was a share
    # of i_q's thrust alone: beside the offset it made the horizontal held-out error 59 % worse, and
    # the end effects were not claimed (the vertical residual reported unexplained). As shares of
    # what i_q + d i_d makes (LibraryContext.force_terms), both found, sized within 30 % (the issue's
    # bound; measured 3.2 degrees, and 7.6 % of the thrust at the logged high end, 34 mm).
    from tests.independent.effects import BaseVibration

    kinds, names = ("end_effect", "commutation_offset"), ["commutation_offset", "end_effects"]
    _, d = _drawn_pair_finds(tmp_path, 22407, kinds, names, extra=(BaseVibration.small(),))
    assert d.unexplained == []


@pytest.mark.slow
def test_the_offsets_thrust_is_not_counted_twice_on_the_thrust_side(tmp_path):
    # A random pair on the rig logging its amplifiers' measured currents with 10 mA of noise
    # (bench/diagnose_rigs.py --rig measured --drawn-pairs 16 --pairs-with commutation_offset --seed
    # 21000, pair 21030): a 2.5 degree commutation offset and end effects of 9 % of the thrust at
    # +-50 mm. With the end effects' thrust a share of i_q + d i_d (the test above) and the felt
    # currents of the thrust side left in the magnets' frame, the offset's thrust was counted twice
    # there and a 0.6 % thrust ripple the log does not have was claimed (z 5.1 on the thrust
    # current). The felt currents are turned into the amplifiers' frame (felt_currents' angle).
    kinds, names = ("end_effect", "commutation_offset"), ["commutation_offset", "end_effects"]
    _drawn_pair_finds(tmp_path, 21030, kinds, names, rig="measured")


@pytest.mark.slow
@pytest.mark.extended
def test_tilted_guides_a_cable_carrier_and_a_commutation_offset_on_fine_encoders(tmp_path):
    # Three effects on a rig with 1 um encoders (bench/diagnose_rigs.py --rig enc1um --drawn-pairs 12
    # --per-log 3 --seed 24100, set 24110): guides tilted by -2.5 mrad with 5 um of waviness at
    # 66 mm, a 10.2 N/m cable carrier and a -2.7 degree commutation offset (i_d about 2 A against
    # 0.1-0.2 A of i_q). Only the tilt was claimed, C1 refitted at 1.14 (92 % below the model's)
    # and three residuals unexplained. Three things refused the other two:
    # - the tilt's gap changed the thrust of the logged i_q alone, not of i_q + d i_d: beside the
    #   spring and the offset it made the horizontal error 26 % worse (LibraryContext.gap_sensitivity);
    # - then the waviness's push along the track, which the tilt's one slope leaves out, 5.7 %
    #   worse while it explained 96.3 % of the vertical error (SelectionSettings.axis_loss_share);
    # - beside the tilt the spring's line was refused as the first terms of a smooth function of
    #   the position, whose further orders explained the waviness's 0.026 N: 0.2 % of what the
    #   0.8 N line explains (SelectionSettings.max_bow_share).
    # All three are found, sized within 30 % (the bound).
    kinds = ("guide_misalignment", "cable_carrier", "commutation_offset")
    names = ["cable_carrier_force", "commutation_offset", "guide_misalignment"]
    _, d = _drawn_pair_finds(tmp_path, 24110, kinds, names, rig="enc1um")
    assert d.constants_final["C1"].value == pytest.approx(14.2, rel=0.3)  # identify's plausible change


@pytest.mark.slow
@pytest.mark.extended
def test_a_spring_that_explains_no_more_than_a_tilt_gives_way_to_it(tmp_path):
    # Three effects on a 10 kHz loop logged at 1 kHz (bench/diagnose_rigs.py --rig ctrl10k
    # --drawn-pairs 12 --per-log 3 --seed 24600, set 24602): guides tilted 2.1 mrad against the
    # stator with 7 um of waviness at 70 mm, a 4.2 % thrust ripple and a base tilted 12 mrad
    # (0.19 N along the track). A cable carrier was chosen before the waviness, its spring
    # (0.06 N/m) taking the waviness's slope, and beat the base's tilt by 0.36 % of the error (the
    # parsimony penalty is 0.2 % a parameter); beside the waviness its spring explained nothing more
    # than the tilt's constant force, and a cable carrier the rig does not have was claimed in its
    # place. The tilt, its simpler form (Candidate.simpler), now takes its place.
    kinds = ("guide_misalignment", "thrust_ripple", "tilted_base")
    names = ["guide_misalignment", "horizontal_guides_not_level", "thrust_ripple"]
    _, d = _drawn_pair_finds(tmp_path, 24602, kinds, names, rig="ctrl10k")
    assert "fewer parameters" in d.selection.last["cable_carrier_force"].reason


@pytest.mark.slow
@pytest.mark.extended
def test_a_lead_of_filtered_currents_is_not_a_friction_of_the_guides(tmp_path):
    # A random pair on the rig logging its amplifiers' currents through a 300 Hz sensor filter, 0.53 ms
    # late (bench/diagnose_rigs.py --rig filtered --drawn-pairs 12 --seed 24200, pair 24206): a normal
    # cogging force and a 4.4 % thrust ripple. The forces lead the logged currents by 0.64 +- 0.04 ms
    # on both axes, which the amplifiers' lag refuses (negative); over an oscillation a lead is a
    # damping, and a vertical guide friction (0.9 % of the held-out error) was claimed on guides that
    # have none. Beside it the lead was no longer judged on the vertical axis, so it was not reported.
    # The lead as judged before the friction was chosen is reported, and the friction judged beside
    # it is dropped.
    from maglev_oc.diagnosis.unexplained import TIMING

    kinds, names = ("normal_cogging", "thrust_ripple"), ["cogging_vertical_19mm", "thrust_ripple"]
    _, d = _drawn_pair_finds(tmp_path, 24206, kinds, names, rig="filtered")
    (late,) = [u for u in d.unexplained if u.depends_on == TIMING]
    assert "guide_friction_vertical" in {j.name for j in d.rejected}
    # the filter's 1 / (2 pi 300 Hz) = 0.53 ms, within the lead's +-0.1 ms (two of its standard errors)
    assert "lead the logged currents by 0.5" in late.description


@pytest.mark.slow
def test_end_effects_not_chosen_are_scanned_about_the_references_that_judge_them(tmp_path):
    # A drawn pair on measured currents (bench/diagnose_rigs.py --rig measured --drawn-pairs 12
    # --seed 25600, pair 25600): a 1.8 degree commutation offset and a stator end 10 mm beyond the
    # logged travel (9.4 % of the thrust and the currents' normal force lost there, 27 mm wide),
    # 0.5 N of vertical force at that end. The base fit's C1 was 1.24 (the offset not yet in the
    # model); the end effects' profile, scanned about it, came out a rounded fall 19 mm wide, which
    # the next selection (C1 at 13.6) refused as growing towards the other end by 0.93 +- 0.1 %;
    # the offset alone was claimed and 96 % of the vertical error reported unexplained. Scanned about
    # the next selection's references, the end effects are found.
    kinds, names = ("end_effect", "commutation_offset"), ["commutation_offset", "end_effects"]
    _, d = _drawn_pair_finds(tmp_path, 25600, kinds, names, rig="measured")
    assert not d.unexplained, d.unexplained


@pytest.mark.slow
@pytest.mark.extended
def test_the_ripple_beside_an_offset_ripples_the_current_of_the_offset_fitted_beside_it(tmp_path):
    # Three effects on the papers' PID loops (bench/diagnose_rigs.py --rig pid --drawn-pairs 12
    # --per-log 3 --seed 25900, set 25911): a cable carrier, a 2.4 % thrust ripple and a commutation
    # offset of -1.28 degrees. Chosen first, the offset was -1.72 degrees as the thrust saw it; the
    # selection was repeated with the ripple of i_q + d i_d at that d, a third too large, and d i_d
    # (a steady 0.04 A of the vertical current) rippled by the rest went to a 0.003 N detent. The
    # ripple now ripples the current of the offset as the final fit has it (-1.27 degrees).
    kinds = ("cable_carrier", "thrust_ripple", "commutation_offset")
    names = ["cable_carrier_force", "commutation_offset", "thrust_ripple"]
    _drawn_pair_finds(tmp_path, 25911, kinds, names, rig="pid")


@pytest.mark.slow
@pytest.mark.extended
def test_the_thrust_form_of_the_offset_keeps_the_attraction_its_angle_makes(tmp_path):
    # Three effects on a rig whose current sensors are filtered at 300 Hz (bench/diagnose_rigs.py
    # --rig filtered --drawn-pairs 12 --per-log 3 --seed 27100, set 27101): a 1.6 N detent, guides
    # sloping by -2.4 mrad, a -2.5 degree commutation offset. The full form of the offset was not
    # specific and its form fitted on the thrust alone was chosen; that form left out the
    # attraction C3 l3 d i_q, and the i_q that cancels the detent (rippling at the slot pitch) made
    # a normal force of -d C3/C1 = -0.09 times the detent, claimed as a 0.036 N normal cogging. The
    # thrust form keeps the attraction at the thrust's angle: the three true effects, sized within
    # 30 % (the bound; measured -0.0432 rad for -0.0432, slope -2.43 for -2.44 mrad).
    kinds = ("detent_force", "guide_misalignment", "commutation_offset")
    names = ["cogging_horizontal_19mm", "commutation_offset", "guide_misalignment"]
    _, d = _drawn_pair_finds(tmp_path, 27101, kinds, names, rig="filtered")
    assert "commutation_offset_horizontal" in d.selection.selected


@pytest.mark.slow
@pytest.mark.extended
def test_a_slope_the_vertical_fixes_is_not_confounded_with_a_spring_on_precise_encoders(tmp_path):
    # Three effects on 1 um encoders (bench/diagnose_rigs.py --rig enc1um --drawn-pairs 12 --per-log 3
    # --seed 26800, set 26810): vertical guide friction, guides sloping by -4.5 mrad, a 9.2 N/m cable
    # carrier. Beside the carrier the horizontal residual was 0.003 m/s^2, the vertical 0.14 (the
    # slope and the friction in it): weighed so, the slope's push along the track, nearly a constant
    # force, was confounded with the carrier's at a variance inflation of 669, and the slope and the
    # friction were not claimed. Judged again with the vertical axis weighed more
    # (selection.AXIS_EMPHASES), the three are found, sized within 30 % (the bound; measured
    # -3.7 mrad, 0.87 N for 0.79 N, 9.10 N/m).
    kinds = ("guide_friction_vertical", "guide_misalignment", "cable_carrier")
    names = ["cable_carrier_force", "guide_friction_vertical", "guide_misalignment"]
    _drawn_pair_finds(tmp_path, 26810, kinds, names, rig="enc1um")


@pytest.mark.slow
def test_sticking_guides_hold_an_offsets_thrust_in_the_share_they_hold_the_motors(tmp_path):
    # Three effects logged at 500 Hz (bench/diagnose_rigs.py --rig log500 --drawn-pairs 12 --per-log 3
    # --seed 27200, set 27206): 0.83 N of horizontal guide friction, guides sloping by 4.1 mrad, a
    # 2.8 degree commutation offset. The offset's thrust d i_d (about 1.2 N, which the loop cancels
    # with i_q) was held on the stuck samples with the holding share of the selection before (0.55)
    # while the friction held 0.75 of i_q's: C1 came out at 9.9 for the true 13.7, with its warning,
    # and 64 % of the horizontal held-out error was reported as an unexplained dependence on the
    # gap. Held in one share with the motor's (library._held_beside): the three effects, sized within
    # 30 % (the bound), no warning, nothing unexplained.
    kinds = ("guide_friction_horizontal", "guide_misalignment", "commutation_offset")
    names = ["commutation_offset", "guide_friction_horizontal", "guide_misalignment"]
    _, d = _drawn_pair_finds(tmp_path, 27206, kinds, names, rig="log500")
    assert not d.warnings and not d.unexplained
    # identify's plausible change (30 %) with room to spare: measured 12.7 for 13.7
    assert d.constants_final["C1"].value == pytest.approx(13.7, rel=0.15)


@pytest.mark.slow
def test_a_cogging_force_is_found_beside_a_larger_dependence_on_the_position_nothing_names(tmp_path):
    # Three effects (bench/diagnose_rigs.py --drawn-pairs 12 --per-log 3 --pairs-with end_effect
    # --seed 26100, set 26139): a normal cogging force of 2.45 N peak at 15 mm over the slot pitch,
    # end effects whose fall from the one stator end near the travel (10 % of the attraction there, a
    # raised cosine 104 mm long) spans the whole 70 mm travel, and a field shape. No fall-off the end
    # effects scan is that wide, so the position dependence is reported as unexplained; a smooth
    # function of the position explained 81.7 % of the held-out vertical error, the cogging 35.5 %,
    # and the cogging was refused as not specific: nothing was claimed. Judged beside the
    # unexplained dependence (pipeline._shown_beside_unexplained) it passes: claimed and sized
    # within 30 % (the bound; measured 2.09 N), the dependence still reported.
    kinds = ("normal_cogging", "end_effect", "field_shape")
    _, d = _drawn_pair_finds(tmp_path, 26139, kinds, ["cogging_vertical_19mm"], sized=False)
    truth = json.loads((tmp_path / "pair.truth.json").read_text())
    cogging = next(e for e in truth["effects"] if e["kind"] == "normal_cogging")
    true_size, found = sizes(cogging, d.to_dict()["effects"][0])
    assert found == pytest.approx(true_size, rel=0.3)
    assert any(u.axis == "vertical" and u.depends_on == "position" for u in d.unexplained)


@pytest.mark.slow
@pytest.mark.extended
def test_a_force_judged_beside_an_unexplained_dependence_is_held_to_the_end_effects_shape(tmp_path):
    # A random pair (bench/diagnose_rigs.py --drawn-pairs 16 --pairs-with end_effect normal_cogging
    # detent_force --seed 9000, pair 9415): a detent and end effects. The misfit of the end effects'
    # fall-off is reported as a vertical dependence on the position; judged beside it, a 38 mm
    # normal cogging the stage does not have passed and was claimed, until it was held to the end
    # effects' shape as the selection's choices are (its size moves with the assumed fall-off as
    # much as it is large). The two true effects, sized within 30 % (the bound).
    _drawn_pair_finds(
        tmp_path, 9415, ("detent_force", "end_effect"), ["cogging_horizontal_19mm", "end_effects"]
    )


@pytest.mark.slow
@pytest.mark.extended
def test_a_slope_of_the_guides_is_not_dropped_for_what_was_chosen_after_it(tmp_path):
    # Two effects of a drawn set with a declared 0.6 kg payload (bench/diagnose_rigs.py --rig measured
    # --drawn-pairs 12 --per-log 3 --payload 0.6 --seed 29300, set 29300, which the default rig
    # misdiagnoses the same way): guides sloping by 2.5 mrad with a 5.7 um waviness at 78 mm, and a
    # 1.2 degree commutation offset. The slope was chosen beside the offset; end effects of 0.1-0.2 %
    # and a spring along the track were chosen after it, on the waviness the slope leaves, and beside
    # them the backward pass found the slope collinear with the constants and dropped it: a tilt of
    # the guides claimed, the offset's vertical angle at 0.28 rad (14 times the truth). Dropped in its
    # place (selection._later_in_its_place): the two true effects, sized within 30 % (the issue's
    # bound; measured -2.50 mrad for -2.47, 0.0206 rad for 0.0206).
    kinds, names = ("guide_misalignment", "commutation_offset"), ["commutation_offset", "guide_misalignment"]
    _, d = _drawn_pair_finds(tmp_path, 29300, kinds, names, payload=(0.6, True))
    offset = next(e for e in d.effects if e.name == "commutation_offset").parameters
    # the vertical angle is the thrust's within 3 standard errors (0.28 rad when the slope was dropped)
    gap = abs(offset["angle_vertical"].value - offset["angle_horizontal"].value)
    assert gap < 3 * math.hypot(offset["angle_vertical"].stderr, offset["angle_horizontal"].stderr)


@pytest.mark.slow
@pytest.mark.extended
def test_a_tilt_is_not_dropped_for_end_effects_that_took_its_steady_thrust(tmp_path):
    # A drawn set on measured currents through the sensors' 300 Hz filter (bench/diagnose_rigs.py
    # --rig filtered --drawn-pairs 12 --per-log 3 --seed 29900, set 29901): guides sloping by 2.0 mrad
    # with a 3.2 um waviness, a base tilted by 6.7 mrad (0.105 N along the track) and a field shape.
    # The tilt, chosen beside the slope, explained nothing more beside end effects chosen after it
    # (their thrust's fall, on the steady thrust that holds the tilt); it was dropped as not
    # significant, the end effects then as implausible, and the tilt was not claimed. The later
    # choice is dropped in its place (selection._later_in_its_place): the slope and the tilt, each
    # within 30 % (the bound; measured -2.13 mrad and 0.1035 N); the field shape, 1.5 % of
    # the field at 14.5 mm, is not found.
    kinds = ("guide_misalignment", "field_shape", "tilted_base")
    names = ["guide_misalignment", "horizontal_guides_not_level"]
    effects, d = _drawn_pair_finds(tmp_path, 29901, kinds, names, sized=False, rig="filtered")
    assert _off(d, "guide_misalignment", "slope", effects[0].slope) < SIZE_TOLERANCE
    assert _off(d, "horizontal_guides_not_level", "tilt", effects[2].angle) < SIZE_TOLERANCE


@pytest.mark.slow
@pytest.mark.extended
def test_a_spring_and_end_effects_are_not_a_current_sensor_offset_with_a_payload(tmp_path):
    # A drawn set on measured currents with a declared 0.6 kg payload (bench/diagnose_rigs.py --rig
    # measured --drawn-pairs 12 --per-log 3 --payload 0.6 --seed 29300, set 29308): end effects of 9 %
    # of the thrust and 6 % of the attraction at +-50 mm, a 10.8 N/m cable carrier and a 4 % thrust
    # ripple at the slot pitch. The current sensors' offset explained 52 % of the held-out error at
    # the first step (61 % of the vertical, 43 % of the horizontal), the carrier 49 % (98 % of the
    # horizontal); the end effects (88 % of the vertical) were refused because a smooth function of
    # the position on both axes, the carrier with it, explained more. The offset, a tilt, end effects
    # and a gain mismatch were claimed. The carrier and the end effects are tried as a pair beside
    # the offset (selection._pair_over_best with the candidates a rival refused): the three true
    # effects, the spring and the ripple sized within 30 % (the bound; measured 10.7 N/m and
    # 3.8 %); the end effects' size, 4.7 % of the thrust at the ends for 8.4 % at 40 mm, is not.
    kinds = ("end_effect", "cable_carrier", "thrust_ripple")
    names = ["cable_carrier_force", "end_effects", "thrust_ripple"]
    effects, d = _drawn_pair_finds(
        tmp_path, 29308, kinds, names, sized=False, rig="measured", payload=(0.6, True)
    )
    assert _off(d, "cable_carrier_force", "stiffness", effects[1].stiffness) < SIZE_TOLERANCE
    assert _off(d, "thrust_ripple", "amplitude", effects[2].ratio) < SIZE_TOLERANCE


@pytest.mark.slow
@pytest.mark.extended
def test_a_spring_and_a_slope_beside_shared_large_effects_are_not_a_current_sensor_offset(tmp_path):
    # A drawn set of four effects (bench/diagnose_rigs.py --drawn-pairs 12 --per-log 4 --seed 30100,
    # set 30103): vertical guide friction of 1.1 N, a -3.1 degree commutation offset, guides sloping
    # by 3.0 mrad with a 6.1 um waviness at 74 mm, and a 8.4 N/m cable carrier. Beside the friction
    # and the offset a current sensor offset was chosen, and the carrier dropped in its place. Without
    # it the other candidates chose the four true effects, held-out error 0.026 / 0.019 m/s^2 against
    # 0.052 / 0.036, but against the base model's 0.28 / 0.12 (which the friction and the offset
    # make) that was 98.5 % explained against 94.0 %, short of rival_margin. Held against the fit of
    # the effects both chose (pipeline._tie_shown; 92.0 % against 67.6 % of its 0.077 / 0.085): the
    # four true effects, the spring and the slope sized within 30 % (the bound; measured
    # 8.2 N/m, 3.2 mrad).
    kinds = ("guide_friction_vertical", "guide_misalignment", "cable_carrier", "commutation_offset")
    names = ["cable_carrier_force", "commutation_offset", "guide_friction_vertical", "guide_misalignment"]
    effects, d = _drawn_pair_finds(tmp_path, 30103, kinds, names, sized=False)
    assert _off(d, "cable_carrier_force", "stiffness", effects[2].stiffness) < SIZE_TOLERANCE
    assert _off(d, "guide_misalignment", "slope", effects[1].slope) < SIZE_TOLERANCE


@pytest.mark.slow
@pytest.mark.extended
def test_end_effects_misfit_is_not_a_ripple_whose_slot_part_is_not_told_from_none(tmp_path):
    # A drawn pair on the noisy rig (observer at 2.8 kHz) with a declared 0.5 kg payload
    # (bench/diagnose_rigs.py --rig obs2800 --drawn-pairs 12 --payload 0.5 --seed 28600, pair
    # 28604): end effects of 10 % of the thrust and 9 % of the attraction at +-50 mm falling over
    # 23 mm, a 3.1 degree commutation offset. Beside the two, a thrust ripple of 1.2 +- 0.8 % over
    # the slot pitch and 0.6 +- 0.8 % over the pole pitch was claimed, significant only jointly
    # over 1.2 pole pitches of travel. A slot part within currents.SLOT_RIPPLE_Z standard errors of
    # none is refused there: the two true effects, sized within 30 % (the bound).
    _drawn_pair_finds(
        tmp_path,
        28604,
        ("end_effect", "commutation_offset"),
        ["commutation_offset", "end_effects"],
        rig="obs2800",
        payload=(0.5, True),
    )


@pytest.mark.slow
@pytest.mark.extended
def test_a_slope_of_the_guides_that_only_the_end_effects_fall_off_sizes_is_not_claimed(tmp_path, monkeypatch):
    # A drawn set of four effects on measured currents (bench/diagnose_rigs.py --rig measured
    # --drawn-pairs 12 --per-log 4 --seed 31600, set 31600): end effects falling as a Gaussian over
    # 32 mm from +-50 mm (10 % of the thrust at +-40 mm, 2 % at the centre), a 5.6 N/m cable
    # carrier, a 0.89 ms amplifier lag (not in measured currents) and a base tilted by 11.5 mrad.
    # Beside the carrier and the end effects, guides sloping by 1.0 mrad were claimed (0.3 % of the
    # held-out error): the fall-off's misfit. Refitted with each fall-off the end effects' scan
    # allows, that slope ran from 0.33 to 4.3 mrad; the true slopes of 25 benched logs with end
    # effects moved by at most 0.23 times their size (pipeline.SHAPE_SIZES). Not separable from
    # the end effects' shape: the carrier and the end effects, the spring within 30 % (the issue's
    # bound; measured 5.59 N/m for 5.62). Since 2026-12-06 (o) the slope is first refused as not one
    # slope along the travel (pipeline._not_one_slope: -9.5, 2.8 and 0.44 mrad on the low, high and
    # central halves); without that rule the end effects' shape still refuses it.
    kinds = ("end_effect", "cable_carrier", "amplifier_dynamics", "tilted_base")
    names = ["cable_carrier_force", "end_effects"]
    effects, d = _drawn_pair_finds(tmp_path, 31600, kinds, names, sized=False, rig="measured")
    assert _off(d, "cable_carrier_force", "stiffness", effects[1].stiffness) < SIZE_TOLERANCE
    (bent,) = [j for j in d.rejected if j.name == "guide_misalignment"]
    assert "is not one slope" in bent.reason
    monkeypatch.setattr(pipeline, "_not_one_slope", lambda *a: [])
    effects, d = _drawn_pair_finds(tmp_path, 31600, kinds, names, sized=False, rig="measured")
    slope = next(n for n in d.not_separable if n.name == "guide_misalignment")
    assert slope.confounded_with == ("end_effects",), slope


@pytest.mark.slow
def test_effects_that_the_log_shows_only_together_are_found_together(tmp_path):
    # A drawn set on a rig logging at 500 Hz with the magnets warming by 15 K (bench/diagnose_rigs.py
    # --rig log500 --drawn-pairs 12 --per-log 3 --warm large --seed 32000, set 32008): a normal
    # cogging of 1.3 N peak at 15 mm, end effects of 12 % of the thrust at +-50 mm falling as a
    # Gaussian over 35 mm, a 0.9 ms amplifier lag, and the field 1.1 % lower after 60 s. Each alone
    # explained 10-20 % of the held-out error at z 0.6-2.0 and nothing was claimed, the log said to
    # be explained to its noise. Pairs of such candidates, each judged beside the other
    # (selection._pairs_of_the_unseen): the cogging, the end effects and the warming, the cogging
    # and the warming within 30 % (the bound; measured 0.27 N for 0.31 at the 19.3 mm gap it
    # is sized at, a 1.13 % fall of the field for 1.14).
    from tests.independent.effects import MagnetWarming

    kinds = ("normal_cogging", "end_effect", "amplifier_dynamics")
    _, d, s = _drawn_pair(tmp_path, 32008, kinds, "log500", extra=(MagnetWarming.large(),))
    assert s.true_first and s.no_false_claim, (s.claimed, s.notes)
    assert sorted(e.name for e in d.effects) == ["cogging_vertical_19mm", "end_effects", "magnet_field_drift"]
    for kind in ("normal_cogging", "magnet_warming"):
        truth, claimed = s.sizes[kind]
        assert abs(claimed / truth - 1) < SIZE_TOLERANCE, (kind, truth, claimed)


@pytest.mark.slow
@pytest.mark.extended
def test_a_tilt_that_guides_sloping_against_the_stator_explain_as_well_is_not_claimed(tmp_path):
    # A drawn set on measured currents through the sensors' filter, the magnets warming a little
    # (bench/diagnose_rigs.py --rig filtered --drawn-pairs 12 --per-log 3 --warm small --seed 32100,
    # set 32105): guides sloping by -2.3 mrad against the stator, a normal cogging of 2.5 N peak at
    # 15 mm, end effects of 6 % at +-50 mm. A 4.0 mrad tilt of the guides was claimed first: its
    # constant force along the track is the slope's, and the end effects' unequal losses at the two
    # ends took the line the slope makes in the attraction. Neither is claimed now; both are listed
    # as not separable, with the gauge-block check that tells them apart, and the cogging is sized
    # within 30 % (the bound; measured 2.5 N at 15 mm).
    from tests.independent.effects import MagnetWarming

    kinds = ("normal_cogging", "end_effect", "guide_misalignment")
    _, d, s = _drawn_pair(tmp_path, 32105, kinds, "filtered", extra=(MagnetWarming.small(),))
    assert s.true_first and s.no_false_claim, (s.claimed, s.notes)
    assert "horizontal_guides_not_level" not in s.claimed
    apart = {n.name: n for n in d.not_separable}
    assert apart["horizontal_guides_not_level"].confounded_with == ("guide_misalignment",)
    assert apart["guide_misalignment"].confounded_with == ("horizontal_guides_not_level",)
    assert "gauge-block" in apart["horizontal_guides_not_level"].experiment
    truth, claimed = s.sizes["normal_cogging"]
    assert abs(claimed / truth - 1) < SIZE_TOLERANCE, (truth, claimed)


@pytest.mark.slow
def test_guides_sloping_against_the_stator_that_the_vertical_axis_shows_take_a_tilts_place(tmp_path):
    # A drawn set on a rig logging at 500 Hz with the magnets warming by 15 K (bench/diagnose_rigs.py
    # --rig log500 --drawn-pairs 12 --per-log 3 --warm large --seed 32000, set 32011): end effects,
    # guides sloping against the stator, a thrust ripple. A tilt of the guides was claimed with
    # exactly the slope's force along the track, the slope refused (Wald 6.5 against 15.1) beside
    # a vertical residual the warming had not yet taken. Beside the rest the slope explains as
    # much along the track and 28 % of the vertical error, and takes the tilt's place
    # (selection.told_apart_on_the_other_axis), sized within 30 % (the bound).
    from tests.independent.effects import MagnetWarming

    kinds = ("end_effect", "guide_misalignment", "thrust_ripple")
    _, d, s = _drawn_pair(tmp_path, 32011, kinds, "log500", extra=(MagnetWarming.large(),))
    assert s.true_first and s.no_false_claim, (s.claimed, s.notes)
    names = [e.name for e in d.effects]
    assert "guide_misalignment" in names and "horizontal_guides_not_level" not in names
    truth, claimed = s.sizes["guide_misalignment"]
    assert abs(claimed / truth - 1) < SIZE_TOLERANCE, (truth, claimed)


@pytest.mark.slow
@pytest.mark.extended
def test_a_payload_nobody_declared_beside_forces_that_take_c1_is_read_from_the_vertical_constants(tmp_path):
    # A drawn set on 1 um encoders carrying 0.8 kg nobody declared (bench/diagnose_rigs.py --rig enc1um
    # --drawn-pairs 12 --per-log 3 --payload 0.8 --undeclared --seed 30200, set 30200): guides sloping
    # by 2.6 mrad, a 9.8 N/m cable carrier, a -1.8 degree commutation offset. C1 came out at 3.5
    # beside the base model; the offset and the carrier together explained 99.8 % of the held-out
    # horizontal error with C1 at 9.7, the loaded stage's, but were not proposed (32 % from the
    # model's 14.2). Nothing was claimed and the payload not read. With the payload that C2 and C3
    # read as one more C1 the pair may reach (selection._carried_vertically): the three effects,
    # sized within 30 % (the bound), and the payload read within 3 of its standard errors
    # (measured 0.77 +- 0.05 kg).
    kinds = ("guide_misalignment", "cable_carrier", "commutation_offset")
    names = ["cable_carrier_force", "commutation_offset", "guide_misalignment"]
    _, d = _drawn_pair_finds(tmp_path, 30200, kinds, names, rig="enc1um", payload=(0.8, False))
    mass = d.moving_mass
    assert mass is not None and mass.carried
    assert abs(mass.added.value - 0.8) < 3 * mass.added.stderr
    assert not d.warnings


@pytest.mark.slow
def test_stuck_vertical_guides_carry_the_weight_of_a_payload_nobody_declared(tmp_path):
    # A random pair on measured currents through the sensors' 300 Hz filter, carrying 1 kg nobody
    # declared (bench/diagnose_rigs.py --rig filtered --drawn-pairs 12 --payload 1.0 --undeclared
    # --seed 28900, pair 28907): vertical guide friction (0.70 N Coulomb, 0.77 N breakaway) and a
    # 3.2 % thrust ripple. The payload is read (0.87 kg) and the log diagnosed carrying it, but the
    # friction held a stuck axis at an acceleration of 0, not at the unloaded stage's -m G / M_v:
    # 2 m/s^2 left on every stuck sample, a holding share of 0.01, a viscous part of -150 N s/m held
    # at its bound and the Coulomb force 0.93 N. Held at rest as the regression reads it
    # (LibraryContext.at_rest): both effects, sized within 30 % (the bound; 0.60 N).
    kinds, names = ("guide_friction_vertical", "thrust_ripple"), ["guide_friction_vertical", "thrust_ripple"]
    _, d = _drawn_pair_finds(tmp_path, 28907, kinds, names, rig="filtered", payload=(1.0, False))
    assert d.moving_mass is not None and d.moving_mass.carried
    friction = next(e for e in d.effects if e.name == "guide_friction_vertical")
    assert friction.parameters["holding"].value > 0.5  # measured 0.86; 0.01 held at 0


@pytest.mark.slow
def test_a_declared_payloads_weight_pulls_along_sloping_guides(tmp_path):
    # A random pair with a 0.8 kg payload declared in the log (bench/diagnose_rigs.py --drawn-pairs 12
    # --payload 0.8 --seed 27900, pair 27904): guides sloping by 4.2 mrad and a 0.29 ms amplifier lag.
    # The guides' pull along the track was the horizontal mover's weight alone; the payload's,
    # 0.8 kg x G x 4.2 mrad = 0.033 N, was claimed as a tilted base of 0.038 N. With the weight the
    # guides carry (LibraryContext.weight_carried): the two true effects, sized within 30 % (the
    # issue's bound).
    kinds, names = (
        ("guide_misalignment", "amplifier_dynamics"),
        ["current_amplifier_lag", "guide_misalignment"],
    )
    _drawn_pair_finds(tmp_path, 27904, kinds, names, payload=(0.8, True))


@pytest.mark.slow
@pytest.mark.extended
def test_a_tilt_within_what_a_read_payloads_error_pulls_along_sloping_guides_is_not_claimed(tmp_path):
    # The same draws with the 0.8 kg left out of the log (--payload 0.8 --undeclared, pair 27904):
    # guides sloping by 4.2 mrad and a 0.29 ms amplifier lag. The payload is read as 0.69 +- 0.05 kg
    # and the log diagnosed carrying it; the 0.11 kg it misses pulls along the sloping guides, and
    # was claimed as a 0.0052 N tilt. Within 3 standard errors of the reading's pull it is not
    # separable from the reading's error (pipeline._pulled_by_the_read_payload), and weighing the
    # payload is the experiment. The two true effects, sized within 30 % (the bound).
    kinds = ("guide_misalignment", "amplifier_dynamics")
    names = ["current_amplifier_lag", "guide_misalignment"]
    _, d = _drawn_pair_finds(tmp_path, 27904, kinds, names, payload=(0.8, False))
    assert d.moving_mass is not None and d.moving_mass.carried
    tilt = next(n for n in d.not_separable if n.name == "horizontal_guides_not_level")
    assert tilt.confounded_with == ("guide_misalignment",) and "payload_kg" in tilt.experiment


@pytest.mark.slow
def test_a_payload_nobody_declared_is_read_and_the_log_diagnosed_carrying_it(tmp_path):
    # The same draws with the payload left out of the log (--payload 0.8 --undeclared, pair 27900):
    # guides sloping by 2.4 mrad and a 4.1 N/m cable carrier. Sized with the model's masses, the
    # spring came out 2.72 N/m, M_h / (M_h + 0.8) of the truth. The constants read movers
    # 0.78 +- 0.05 kg heavier (identification.masses), and the log is diagnosed again as carrying
    # that: both effects sized within 30 % (measured 4.05 N/m), the reading said.
    kinds, names = ("guide_misalignment", "cable_carrier"), ["cable_carrier_force", "guide_misalignment"]
    _, d = _drawn_pair_finds(tmp_path, 27900, kinds, names, payload=(0.8, False))
    mass = d.moving_mass
    assert mass is not None and mass.carried
    # within 3 standard errors of the 0.8 kg (the reading's error is the spread of rigs' constants)
    assert abs(mass.added.value - 0.8) < 3 * mass.added.stderr
    assert d.settings["payload_read_kg"] == mass.added.value
    assert "diagnosed again as carrying" in d.report()


@pytest.mark.slow
@pytest.mark.extended
def test_a_bowl_over_the_travel_is_no_waviness_of_straight_guides(tmp_path):
    # Three effects on the default rig (bench/diagnose_rigs.py --drawn-pairs 12 --per-log 3
    # --pairs-with end_effect commutation_offset guide_friction_vertical tilted_base cable_carrier
    # thrust_ripple --seed 26100, set 26107): end effects 35 mm wide from stator ends 10 mm beyond a
    # +-40 mm travel (1.8 % of the thrust and attraction lost at the centre, 6.3 % at the ends), a
    # 8.7 N/m cable carrier and a 2.7 degree commutation offset. The bowl, too wide for the end
    # effects' profiles, peaked the residual's spectrum at 76 mm (1.05 periods of the travel) and went
    # to a guide waviness, whose push along the track took the carrier's spring: a waviness and a
    # tilted base claimed on straight, level guides. Without a chosen misalignment a period the travel
    # covers fewer than min_periods times is no waviness (pipeline._a_periodicity).
    kinds = ("end_effect", "cable_carrier", "commutation_offset")
    names = ["cable_carrier_force", "commutation_offset", "end_effects"]
    _drawn_pair_finds(tmp_path, 26107, kinds, names, sized=False)


@pytest.mark.slow
@pytest.mark.extended
def test_a_tilt_chosen_early_gives_way_to_the_spring_the_rest_shows(tmp_path):
    # Three effects on the papers' PID loops (bench/diagnose_rigs.py --rig pid --drawn-pairs 12
    # --per-log 3 --seed 25900, set 25905): a 7.1 N/m cable carrier, a 1.5 degree commutation offset
    # and large end effects at one stator end (7.8 % of the thrust, 7.2 % of the attraction). Before
    # the offset and the end effects were chosen, the spring's line was "not specific" against a
    # smooth function of the gap (which the offset's thrust of i_d is, on these loops), so a tilt of
    # the guides was chosen; a current sensor offset then took the spring's line, and a tilt and a
    # sensor offset were claimed for a cable carrier. The backward pass puts the spring in the tilt's
    # place when beside the rest it explains more than its extra parameter costs.
    kinds = ("end_effect", "cable_carrier", "commutation_offset")
    names = ["cable_carrier_force", "commutation_offset", "end_effects"]
    _drawn_pair_finds(tmp_path, 25905, kinds, names, sized=False, rig="pid")


@pytest.mark.slow
@pytest.mark.extended
def test_the_normal_coggings_push_along_sloping_guides_is_no_detent(tmp_path):
    # A drawn pair on warming magnets (bench/diagnose_rigs.py --drawn-pairs 12 --warm small --seed
    # 26700, pair 26703): guides sloping by -4.0 mrad and a normal cogging of 2.4 N peak at 15 mm.
    # Along the sloping guides the cogging pushes the platform by -slope times itself, a force along
    # the track at the cogging's period and phase that grows as the gap closes: a detent of 0.0023 N
    # was claimed at the phase of the 0.54 N cogging (-2.32 and -2.34 rad), which the stage does not
    # have. It is refused as the cogging's push (pipeline._pushed_along_the_guides).
    from tests.independent.effects import MagnetWarming

    kinds = ("normal_cogging", "guide_misalignment")
    names = ["cogging_vertical_19mm", "guide_misalignment", "magnet_field_drift"]
    _, d = _drawn_pair_finds(tmp_path, 26703, kinds, names, extra=(MagnetWarming.small(),))
    (j,) = [j for j in d.rejected if j.name == "cogging_horizontal_19mm"]
    assert "push along the guides" in j.reason


@pytest.mark.slow
@pytest.mark.extended
def test_a_lag_is_not_dropped_beside_a_dependence_on_the_velocity_it_delays(tmp_path):
    # Three effects on a rig with 20 um encoders (bench/diagnose_rigs.py --rig enc20um --drawn-pairs
    # 12 --per-log 3 --seed 21700, set 21707): a 218 Hz amplifier with 0.24 ms of delay (0.96 ms in
    # all), a 1.5 N detent and a base tilted 7.1 mrad. The lag was chosen (1.17 ms beyond the hold,
    # z 9.7), then dropped as "explained as well by a dependence on the gap rate" beside a polynomial
    # of the gap rate, which in closed loop is the lag's own column more flexibly shaped; the
    # residual was reported unexplained. The velocities a delay acts on are its own
    # (unexplained.delayed_rates); the residual left beside it is read against its fit, not as damping.
    kinds = ("detent_force", "amplifier_dynamics", "tilted_base")
    names = ["cogging_horizontal_19mm", "current_amplifier_lag", "horizontal_guides_not_level"]
    _, d = _drawn_pair_finds(tmp_path, 21707, kinds, names, rig="enc20um")
    assert all("damping" not in u.description for u in d.unexplained), d.unexplained


@pytest.mark.slow
@pytest.mark.extended
def test_a_spring_and_a_wavy_misalignment_are_chosen_together_over_a_sensor_offset_on_both_axes(tmp_path):
    # A random pair on a rig logging its amplifiers' measured currents with 10 mA of noise
    # (bench/diagnose_rigs.py --drawn-pairs 12 --rig measured --seed 18300, pair 18310): guides
    # sloping 4.8 mrad against the stator with 4.9 um of waviness at 74 mm, and a cable carrier's
    # 11.3 N/m spring. One effect at a time, a current sensor offset, whose forces turn along the
    # track on both axes, explained 61.6 % of the held-out error at the first step against 46.9 %
    # and 36.9 % for each true effect alone, and was claimed alone: a false claim, both true effects
    # missed. Together the two explain more than the offset by far (pooled held-out gains 0.97 and
    # 0.95 per axis against 0.48 and 0.72) and the offset does not pass beside them
    # (selection._pair_over_best); the waviness is then found beside the spring
    # (pipeline._waviness_beyond_travel). Both sized within 30 % (the bound; measured
    # 11 N/m, 4.8 mrad, and 5.6 um at 73.7 mm for the waviness).
    effects, d, s = _drawn_pair(tmp_path, 18310, ("guide_misalignment", "cable_carrier"), "measured")
    assert effects[1].stiffness == pytest.approx(11.277, abs=1e-3)  # the bench's log
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes)
    assert sorted(e.name for e in d.effects) == ["cable_carrier_force", "guide_misalignment"]
    # chosen together, each with the pair's confidence: the share of 30 block-bootstrap resamples in
    # which the pair explains more than the offset; 0.96 against 0.60 of the held-out error is a
    # margin no resample reversed (measured 1.0 for both; 0.0 for the second when its resamples
    # were fitted with the first counted twice)
    confidence = {st.chosen: st.confidence for st in d.selection.steps}
    assert confidence["cable_carrier_force"] == confidence["guide_misalignment"] >= 0.9, confidence
    # the waviness at its own period, not at a motor pitch (5 %: under a quarter of the way to the
    # pole pitch, 57 mm, 23 % off)
    slope = next(e for e in d.effects if e.name == "guide_misalignment").parameters
    assert slope["waviness_period"].value == pytest.approx(effects[0].waviness_wavelength, rel=0.05)


@pytest.mark.slow
@pytest.mark.extended
def test_a_pair_standing_in_for_a_misalignment_and_its_next_effect_is_not_chosen_over_them(tmp_path):
    # A random pair on the noisy rig (observers at 2.8 kHz, the logged currents as noisy as
    # ../shared/logs/independent_clean.csv's; bench/diagnose_rigs.py --drawn-pairs 12 --rig obs2800
    # --seed 18400): end effects and guides sloping against the stator. The slope is the best effect
    # alone; end effects with a tilt of the guides explain more than it does, and beside those two
    # the slope fell short of passing (8.5 % at z 2.4): a pair chosen over the step's best alone
    # claimed the tilt, a false claim, and missed the slope. Held against the best with another
    # effect (selection._pair_over_best), the slope and the end effects explain more: both true
    # effects, nothing else.
    _, d, s = _drawn_pair(tmp_path, 18400, ("end_effect", "guide_misalignment"), "obs2800")
    assert s.true_first and s.no_false_claim, (s.claimed, s.notes)
    assert sorted(e.name for e in d.effects) == ["end_effects", "guide_misalignment"]


@pytest.mark.slow
def test_a_ripple_beside_a_commutation_offset_ripples_the_thrust_of_the_levitation_current(tmp_path):
    # A random pair on the papers' PID loops (bench/diagnose_rigs.py --drawn-pairs 12 --rig pid
    # --seed 18500, pair 18502): the thrust per ampere rippling by 3.4 % over the slot pitch and
    # 1.7 % over the pole pitch, and a commutation offset of -1.2 degrees. The current that makes
    # thrust is then i_q + d i_d, and i_d, the levitation current, is 1.7 A against at most 0.14 A of
    # i_q: rippling i_q alone, the ripple of d i_d was left over and claimed as a 0.0095 +- 0.004 N
    # detent at the slot pitch (a false claim), the pole pitch's ripple sized at 1.2 %. The selection
    # repeated with the ripple of i_q + d i_d (pipeline._ripple_beside_commutation): the two true
    # effects and nothing else, the ripples at 3.4 % and 1.7 % (within 30 %, the bound).
    effects, d, s = _drawn_pair(tmp_path, 18502, ("thrust_ripple", "commutation_offset"), "pid")
    assert effects[0].ratio == pytest.approx(0.03378, abs=1e-5)  # the bench's log
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes)
    assert sorted(e.name for e in d.effects) == ["commutation_offset", "thrust_ripple"]
    ripple = next(e for e in d.effects if e.name == "thrust_ripple").parameters
    assert ripple["amplitude_pole_pitch"].value == pytest.approx(effects[0].ratio2, rel=0.3)


def _end_effects_16106(tmp_path, *more, seed: int = 16106):
    """The end effects of ``bench/diagnose_rigs.py --drawn 8 --kinds end_effect --seed 15700``'s
    draw 16106 (a raised cosine: 9.3 % of the thrust and 8.8 % of the attraction lost at +-50 mm,
    zero 80 mm further in), with ``more`` effects, on the generator's own rig (the log's ``seed``),
    diagnosed with the defaults and scored: (diagnosis, score)."""
    import numpy as np

    from tests.independent import write_log
    from tests.independent.draws import draw
    from tests.independent.simulate import Rig, Scenario, simulate

    ends = draw("end_effect", np.random.default_rng(16106))
    assert ends.profile == "cosine" and ends.thrust_loss == pytest.approx(0.0931, abs=1e-4)
    scenario = Scenario(name="end_effect", seed=seed, effects=(ends, *more), rig=Rig())
    path, truth_path = write_log(simulate(scenario), tmp_path, stem="ends")
    d = diagnose_path(path)
    return d, score("ends", json.loads(truth_path.read_text()), d.to_dict()["effects"])


@pytest.mark.slow
@pytest.mark.extended
def test_a_slow_sine_that_the_end_effects_shape_moves_is_not_claimed_beside_them(tmp_path):
    # Fitted with the exponential and rounded fall-offs, the raised cosine left a vertical misfit
    # along the travel that a 0.034 N normal cogging at 38 mm took (z 5.3): a false claim. Refitted
    # beside each fall-off the logged travel allows, that cogging ran from 0.034 to 0.12 N
    # (pipeline._told_by_the_end_effects_shape): not separable from the end effects' shape, and
    # listed so; the end effects alone are claimed.
    d, s = _end_effects_16106(tmp_path)
    assert s.true_first and s.no_false_claim, (s.claimed, s.notes)
    assert [e.name for e in d.effects] == ["end_effects"]
    shaped = {n.name: n for n in d.not_separable}["cogging_vertical_38mm"]
    assert shaped.confounded_with == ("end_effects",) and "fall-off" in shaped.reason


@pytest.mark.slow
def test_a_true_slow_cogging_beside_the_same_end_effects_is_still_claimed(tmp_path):
    # The other side of the rule above: 0.6 N of normal cogging at 38 mm (0.27 N at the 19.5 mm gap)
    # beside the same end effects. Its size beside each fall-off ran from 0.23 to 0.44 N, half that
    # range 0.45 times its size: claimed, with the end effects, and sized within 30 % of its peak at
    # the reference gap (the bound). (Not on every seed: on 16306 the cosine's misfit makes
    # the cogging's two halves of the travel differ, and it is refused as not specific, as before.)
    from tests.independent.effects import NormalCogging

    cogging = NormalCogging(peak_force=0.6, period=0.0381, harmonic2_ratio=0.0, phase=2.0)
    d, s = _end_effects_16106(tmp_path, cogging, seed=16302)
    assert sorted(e.name for e in d.effects) == ["cogging_vertical_38mm", "end_effects"], s.claimed
    found = {e.name: e for e in d.effects}["cogging_vertical_38mm"].parameters["amplitude_15mm"].value
    assert found == pytest.approx(0.6, rel=0.3)


@pytest.mark.slow
@pytest.mark.extended
def test_cogging_beside_end_effects_is_not_refused_for_a_stand_in_that_needs_another_motor(tmp_path):
    # A random pair (the drawn pairs' generator, seed 9030): normal cogging (1.25 N at 15 mm, 0.3 N
    # at the 19.5 mm gap) and end effects falling as a raised cosine (5.8 % of the thrust, 4.8 % of
    # the attraction at +-50 mm). Nothing was claimed: a constant vertical force, not separable from
    # C2, explained 47 % of the held-out error with C2 at 47.5 (the model's 797, true 776), the
    # loop's gap-following currents standing in for every vertical force once the attraction's gap
    # dependence is free, and the cogging (34.5 %) was refused as not separable from it. A fit that
    # needs a motor no stage of this design is (beyond identify's plausible change, 30 %) is no
    # rival (selection.another_motor, as for the generic rivals): both effects found, sized within
    # 30 % (the bound).
    _, d, s = _drawn_pair(tmp_path, 9030, ("normal_cogging", "end_effect"))
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes)
    assert sorted(e.name for e in d.effects) == ["cogging_vertical_19mm", "end_effects"]


@pytest.mark.slow
def test_end_effects_at_one_stator_end_beside_cogging_are_found_at_that_end(tmp_path):
    # A random pair (seed 9448): normal cogging (1.96 N at 15 mm) and end effects at one stator end
    # only, 12 mm beyond the logged high end (exponential over 21 mm, 7.7 % of the thrust and 3.4 %
    # of the attraction; the other stator end 260 mm beyond the low one). Fitted with both ends at
    # every scanned profile they were a fall at the high end and a growth at the low one (the
    # scan's widths straddle the true one), implausible, and a vertical dependence on the position
    # was reported unexplained. The fall at the high end alone keeps 99.9 % of what both ends
    # explain there (refit.ONE_END_SHARE): both found, the thrust's loss at the logged ends sized
    # within 30 % (the bound; measured 1.37 % for 1.23 %).
    _, d = _drawn_pair_finds(
        tmp_path, 9448, ("normal_cogging", "end_effect"), ["cogging_vertical_19mm", "end_effects"]
    )
    ends = {e.name: e for e in d.effects}["end_effects"]
    assert ends.parameters["forces_lost_at_low_end_alone"].value == 0.0
    assert "at the high end alone" in ends.finding, ends.finding


@pytest.mark.slow
@pytest.mark.extended
def test_end_effects_beside_sticking_vertical_guides_stand_beside_a_gap_dependence_of_another_motor(
    tmp_path,
):
    # A random pair (seed 15403): vertical guide friction (1.6 N, breakaway 2.0 N at 1 mm/s) and end
    # effects (9.6 % of the thrust, 8.7 % of the attraction lost at +-50 mm, 17.5 mm wide). Both were
    # chosen; then the end effects were dropped as "explained as well" by a vertical dependence on
    # the gap reported unexplained (77 % of the held-out error), and only the friction was claimed.
    # That dependence explained it with C2 at 451 (the model's 797), C3 at 1.4 (31) and C4 at
    # -0.016: a fit no stage of this design is, where the end effects' own has C2 at 840 and C3 at
    # 33.3 (selection.another_motor, as for the selection's rivals). Both found, sized within 30 % (the
    # issue's bound), on the generator's rig (and on the noisy, 2 kHz and 10 kHz rigs, bench/README
    # (xxxiv)).
    _drawn_pair_finds(
        tmp_path,
        15403,
        ("guide_friction_vertical", "end_effect"),
        ["end_effects", "guide_friction_vertical"],
    )


@pytest.mark.slow
@pytest.mark.extended
def test_vertical_friction_is_not_refused_beside_a_gap_dependence_of_another_motor(tmp_path):
    # A random pair (bench/diagnose_rigs.py --drawn-pairs 10 --pairs-with end_effect
    # guide_friction_vertical guide_friction_horizontal --seed 9000): vertical guide friction
    # (Coulomb 1.61 N, viscous 11.3 N s/m) and end effects of the thrust alone (10 % at +-50 mm, a
    # 32 mm Gaussian; 5.4 % at the logged ends relative to the centre). The friction was refused as
    # "not specific": beside a smooth function of the gap it explained -3 % of the held-out error.
    # That function's fit had C2 = 438, C3 = 0.24 and C4 = -0.006 (a stage whose attraction does not
    # depend on the current; the friction's own fit 816, 29.2, 0.059, the truth 818, 29.9, 0.071),
    # and the end effects were claimed with the forces rising at the ends, 1.5 N RMS of vertical
    # residual left unexplained. Held to another_motor (selection._beyond_the_misfit), the friction
    # is found; sized as the guides hold them (library.sized_as_held), the end effects as a fall of
    # the thrust of 3.8-5.0 % (1.1-1.9 % unheld). Both within 30 % (the bound), nothing
    # left unexplained.
    effects, d, s = _drawn_pair(tmp_path, 9112, ("guide_friction_vertical", "end_effect"))
    assert effects[0].coulomb_force == pytest.approx(1.612, abs=1e-3)  # the bench's log
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes)
    assert sorted(e.name for e in d.effects) == ["end_effects", "guide_friction_vertical"]
    ends = next(e for e in d.effects if e.name == "end_effects").parameters
    assert min(ends[f"thrust_loss_at_{end}_end"].value for end in ("low", "high")) > 0
    assert not d.unexplained, [u.description for u in d.unexplained]


@pytest.mark.slow
@pytest.mark.extended
def test_end_effects_beside_sticking_vertical_guides_are_sized_as_the_guides_hold_them(tmp_path):
    # A random pair (the same bench run as pair 9112's above, seed 9330): vertical guide friction
    # (Coulomb 1.10 N, breakaway 2.05 N) and end effects losing 6.6 % of the thrust and 6.5 % of the
    # attraction at +-50 mm (a 23 mm Gaussian; 3.4 % at the logged ends relative to the centre).
    # Both were claimed, the end effects at 1.0-1.4 %: fitted unheld, the stuck samples, where the
    # guides hold their force, counted as showing none. Sized as the guides hold them
    # (library.sized_as_held): 2.8-3.2 %, within 30 % (the bound); the log of the same end
    # effects alone gives 3.2-3.6 %.
    effects, d, s = _drawn_pair(tmp_path, 9330, ("guide_friction_vertical", "end_effect"))
    assert effects[1].thrust_loss == pytest.approx(0.0661, abs=1e-4), effects[1]  # the bench's log
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes)
    assert sorted(e.name for e in d.effects) == ["end_effects", "guide_friction_vertical"]


@pytest.mark.slow
def test_a_large_commutation_offset_beside_normal_cogging_is_sized_from_the_thrust_it_makes(tmp_path):
    # A random pair (bench/diagnose_rigs.py --drawn-pairs, seed 9018): normal cogging (1.66 N at
    # 15 mm) and a -2.5 degree commutation offset. With 1.7 A of levitation current the offset's
    # thrust, i_d sin d, rivals the commanded i_q, and the base fit's C1 came out 1.6 against the
    # true 14.5. One angle for both axes, fitted around that C1, was -5.7 degrees (2.3 times the
    # truth) and a smooth function of the gap was left over as unexplained (97.7 % of the
    # horizontal held-out error). Each axis's angle as its own product with its constant is linear
    # whatever the references: both effects found, the angle within 30 % (the bound;
    # measured 0.2 %), nothing unexplained.
    effects, d, s = _drawn_pair(tmp_path, 9018, ("normal_cogging", "commutation_offset"))
    assert effects[1].angle == pytest.approx(-0.04383, abs=1e-5)  # the bench's log
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes)
    assert sorted(e.name for e in d.effects) == ["cogging_vertical_19mm", "commutation_offset"]
    assert not d.unexplained, [u.description for u in d.unexplained]


@pytest.mark.slow
@pytest.mark.extended
def test_end_effects_beside_a_misalignment_are_not_also_a_ripple_over_the_pole_pitch(tmp_path):
    # A random pair (bench/diagnose_rigs.py --drawn-pairs, seed 9105): end effects falling as a
    # Gaussian over 19 mm (7 % of the thrust and of the attraction at +-50 mm) and a 4.9 mrad guide
    # slope. Beside the two, the exponential end effects' misfit was claimed as a third effect, a
    # 4.2 % thrust ripple over the 57 mm pole pitch with 0.25 % over the slot pitch, over a travel
    # of 1.4 pole pitches. Such a ripple is not told from a smooth change of the thrust along the
    # travel (currents.POLE_RIPPLE_PERIODS): the two true effects, sized within 30 % (the issue's
    # bound), and nothing else.
    effects, d, s = _drawn_pair(tmp_path, 9105, ("end_effect", "guide_misalignment"))
    assert effects[0].profile == "gaussian" and effects[1].slope == pytest.approx(0.0049, abs=1e-4)
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes)
    assert sorted(e.name for e in d.effects) == ["end_effects", "guide_misalignment"]


@pytest.mark.slow
@pytest.mark.extended
def test_a_commutation_offset_is_judged_separable_by_the_angle_both_axes_share(tmp_path):
    # A random pair (bench/diagnose_rigs.py --drawn-pairs, seed 9128): a 3.1 degree commutation
    # offset and end effects at one end. The loop cancels i_d's steady thrust with a steady i_q,
    # so the thrust's coefficient alone is collinear with C1 (variance inflation 107-114): judged
    # coefficient by coefficient the offset was "not separable", and a guide misalignment took its
    # steady horizontal force (a false claim). Judged along the angle both axes share it is
    # claimed, within 30 % of the truth (the bound; measured 0.1 %), and nothing false.
    effects, d, s = _drawn_pair(tmp_path, 9128, ("end_effect", "commutation_offset"))
    assert effects[1].angle == pytest.approx(0.0546, abs=1e-4)  # the bench's log
    assert s.no_false_claim, s.claimed
    assert "commutation_offset" in [e.name for e in d.effects]
    angle = next(e for e in d.effects if e.name == "commutation_offset").parameters["angle"]
    assert angle.value == pytest.approx(effects[1].angle, rel=0.3)


@pytest.mark.slow
def test_a_guide_waviness_near_twice_the_slot_pitch_is_named_with_the_misalignment(tmp_path):
    # A guide tilted the other way (-3 mrad) with 6 um of waviness at 40 mm, a shape the sets never
    # use (bench/diagnose_rigs.py --variants). 40 mm is within 5 % of twice the slot pitch, where
    # the library has a vertical cogging but no horizontal force: the waviness's horizontal peak
    # (39 mm) was set aside as a motor period, and its vertical part went to a false 38 mm normal
    # cogging beside the misalignment. Set aside only on the axes a force there can explain, the
    # waviness joins the misalignment, sized within 30 % (stable over four copies of the log that
    # differ in their last bits, bench/diagnose_stability.py's way).
    from tests.independent import effects as E
    from tests.independent import write_log
    from tests.independent.simulate import Scenario, simulate

    effect = E.GuideMisalignment(
        slope=-3e-3, waviness_amplitude=6e-6, waviness_wavelength=0.04, waviness_phase=2.0
    )
    scenario = Scenario(name="misalignment_negative_wavy", seed=808, effects=(effect,))
    path, _ = write_log(simulate(scenario), tmp_path, stem="variant")
    d = diagnose_path(path)
    assert [e.name for e in d.effects] == ["guide_misalignment"]
    p = d.effects[0].parameters
    assert p["slope"].value == pytest.approx(-3e-3, rel=0.3)
    assert p["waviness_amplitude"].value == pytest.approx(6e-6, rel=0.3)
    assert p["waviness_period"].value == pytest.approx(0.04, rel=0.1)  # the scan's +-25 % around a peak


@pytest.mark.slow
@pytest.mark.extended
def test_a_commutation_offset_as_precise_as_the_thrust_constant_is_claimed(tmp_path):
    # A commutation offset of -2.4 degrees drawn at random (tests/independent/draws.py, seed 2000 of
    # bench/diagnose_rigs.py --drawn). The levitation current is nearly constant, so i_d's thrust
    # is nearly a constant force that the loop cancels with a constant i_q; the offset is then
    # known as a ratio to the thrust constant, and its estimate correlates with C1's by 0.993
    # (variance inflation 76). Estimated to 0.15 %, it was refused as confounded with C1 while the
    # correlation limit (0.99) was stricter than the variance inflation's (100); with the two in
    # agreement it is claimed, within 30 % of the truth (the size tolerance; it is within 1 %).
    # Extended tier (8 s): every run checks the two limits' agreement in test_statistics_properties.
    import numpy as np

    from tests.independent import write_log
    from tests.independent.draws import draw
    from tests.independent.simulate import Scenario, simulate

    effect = draw("commutation_offset", np.random.default_rng(2000))
    assert effect.angle == pytest.approx(-0.0411, abs=1e-4)  # the draw is the log described above
    scenario = Scenario(name="commutation_offset", seed=2000, effects=(effect,))
    path, _ = write_log(simulate(scenario), tmp_path, stem="drawn")
    d = diagnose_path(path)
    assert [e.name for e in d.effects] == ["commutation_offset"]
    assert d.effects[0].parameters["angle"].value == pytest.approx(effect.angle, rel=0.3)
    assert not d.not_separable


@pytest.mark.slow
def test_no_amplifier_lag_is_claimed_from_the_vertical_axis_of_sticking_guides(tmp_path):
    # A random pair (bench/diagnose_rigs.py --drawn-pairs, seed 9122): vertical guide friction
    # (0.83 N Coulomb, 1.58 N breakaway, its viscous part fitted negative and so held at zero)
    # and a 5.8 N/m cable carrier. A 0.84 ms amplifier lag was claimed third, all of its evidence
    # from the vertical axis (3 % held out, 0.1 % horizontally), where the regulator makes the
    # currents' rate follow the velocity: its column there is the friction's viscous part, and
    # with it the Coulomb force came out 1.10 N (32 % off). Judged on the horizontal axis alone it
    # is not significant: the two true effects, each within 30 % (the bound), and no lag.
    kinds, names = (
        ("guide_friction_vertical", "cable_carrier"),
        ["cable_carrier_force", "guide_friction_vertical"],
    )
    effects, d = _drawn_pair_finds(tmp_path, 9122, kinds, names)
    assert effects[0].coulomb_force == pytest.approx(0.8313, abs=1e-4)  # the bench's log
    lag = d.selection.last["current_amplifier_lag"]
    assert "judged on the horizontal axis alone" in lag.reason, lag.reason


@pytest.mark.slow
@pytest.mark.extended
def test_the_force_of_a_guide_waviness_is_not_claimed_as_a_cable_carrier(tmp_path):
    # A random pair (bench/diagnose_rigs.py --drawn-pairs, seed 9201): vertical guide friction
    # and a -2.1 mrad guide slope with 3.7 um of waviness at 69 mm. Over the 100 mm travel the
    # waviness's horizontal force is a bow; its linear part was claimed as a 0.32 N/m spring
    # (a cable carrier), which a line in the position is by construction as good as the generic
    # rival of its size. Beside it the next orders of a smooth function of the position explained
    # about half as much again (z 2.4), so the spring is refused; the two true effects are found.
    # What the waviness leaves is a force on both axes along the travel, a quarter period apart,
    # which the current sensors' errors would give too: they are listed as not separable from the
    # tilted guides, with the waviness named in the reason, and the residual is still reported as
    # unexplained, depending on the position (pipeline._stands_for_residual).
    kinds = ("guide_friction_vertical", "guide_misalignment")
    effects, d = _drawn_pair_finds(tmp_path, 9201, kinds, list(kinds), sized=False)
    assert effects[1].waviness_amplitude == pytest.approx(3.69e-6, abs=1e-8)  # the bench's log
    cable = d.selection.last["cable_carrier_force"]
    assert cable.verdict == "not specific" and "position" in cable.reason, cable.reason
    sensors = {n.name: n for n in d.not_separable if n.name.startswith("current_sensor")}
    assert set(sensors) == {"current_sensor_offset", "current_sensor_gain_mismatch"}, d.not_separable
    for n in sensors.values():
        assert n.confounded_with == ("guide_misalignment",) and "waviness" in n.reason, n
    assert any("horizontal position" in u.description for u in d.unexplained), d.unexplained


@pytest.mark.slow
def test_a_spring_beside_end_effects_is_judged_once_they_are_chosen(tmp_path):
    # A random pair (bench/diagnose_rigs.py --drawn-pairs, seed 9020): a 5.2 N/m cable carrier
    # and end effects that fall as a raised cosine (10 % of the thrust). The spring is chosen
    # first, when the end effects are still in the residual: judged by the position's further
    # orders there it was refused, and a constant force (a tilt) took its place. Judged once the
    # end effects are chosen beside it, both true effects are claimed and nothing else.
    names = ["cable_carrier_force", "end_effects"]
    effects, _ = _drawn_pair_finds(tmp_path, 9020, ("end_effect", "cable_carrier"), names, sized=False)
    assert effects[0].profile == "cosine" and effects[1].stiffness == pytest.approx(5.242, abs=1e-3)


@pytest.mark.slow
def test_friction_whose_viscous_part_turns_negative_beside_a_later_effect_keeps_it_at_zero(tmp_path):
    # A random pair (bench/diagnose_rigs.py --drawn-pairs, seed 9304): vertical guide friction
    # (1.43 N Coulomb, 2.81 N breakaway) and a guide misalignment. The friction was chosen with its
    # viscous part free; once the misalignment was chosen beside it, the free viscous coefficient
    # came out at -17 N s/m, and the backward pass dropped the friction as implausible, leaving a
    # 1.6 N vertical residual "unexplained". As in the forward steps, its form with the viscous
    # part held at zero now stands in: both effects found, each within 30 % (the bound).
    kinds = ("guide_friction_vertical", "guide_misalignment")
    effects, d = _drawn_pair_finds(tmp_path, 9304, kinds, list(kinds))
    assert effects[0].coulomb_force == pytest.approx(1.4284, abs=1e-4)  # the bench's log
    assert (
        d.effects[[e.name for e in d.effects].index("guide_friction_vertical")].parameters["viscous"].value
        == 0
    )


@pytest.mark.slow
@pytest.mark.extended
def test_a_spring_beside_a_wavy_guide_is_judged_after_the_waviness_is_searched_for(tmp_path):
    # A random pair (bench/diagnose_rigs.py --drawn-pairs, seed 9332): a guide misalignment with
    # waviness and a cable carrier. Judged by the position's further orders in the first
    # selection, the spring was refused (the waviness, not yet found, was 9.8 % of the remainder
    # at z 5.0); the residual then hid the waviness from its search and a false 38 mm vertical
    # cogging was claimed. Judged in the kept selection, beside the waviness found meanwhile, all
    # three are found (the waviness with the misalignment) and nothing else.
    names = ["cable_carrier_force", "guide_misalignment"]
    effects, _ = _drawn_pair_finds(
        tmp_path, 9332, ("guide_misalignment", "cable_carrier"), names, sized=False
    )
    assert effects[1].stiffness == pytest.approx(10.521, abs=1e-3)  # the bench's log
    assert effects[0].waviness_amplitude == pytest.approx(5.99e-6, abs=1e-8)


@pytest.mark.slow
def test_a_one_sided_fall_at_a_stator_end_is_neither_cogging_nor_waviness(tmp_path):
    # A random pair (bench/diagnose_rigs.py --drawn-pairs, seed 9321): thrust and attraction falling
    # over the last 46 mm before the stator's end at +50 mm (a raised-cosine profile) and an
    # amplifier lag. With exponential end effects only, the misfit, one-sided, was claimed as a
    # 38 mm normal cogging (fitted on each half of the travel: 37 % and 152 % of its size), then,
    # with cogging held to the same size all along the stator, as a 38 mm guide waviness (59 %
    # and 155 %), then the end effects alone, 31 % too large. With the rounded profile scanned
    # beside the exponential, the end effects are fitted in that shape, and both effects are found
    # and sized within 30 % (the bound).
    effects, d = _drawn_pair_finds(
        tmp_path, 9321, ("end_effect", "amplifier_dynamics"), ["end_effects", "current_amplifier_lag"]
    )
    assert effects[0].end_position_plus == pytest.approx(0.05)  # the bench's log
    (end,) = [e for e in d.effects if e.name == "end_effects"]
    assert "stay flat near the ends" in end.finding  # the rounded profile
