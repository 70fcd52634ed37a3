"""Logs whose currents are as noisy as the shared log's: what the diagnosis must not read into them.

A generic probe that stands in for the constants rivals nothing and explains nothing. The diagnosis
compares every candidate with generic smooth functions of one state variable (the rivals,
:func:`maglev_oc.diagnosis.selection._rival_gains`) and reports as unexplained what such a probe
finds beyond the chosen effects (:mod:`maglev_oc.diagnosis.unexplained`). A smooth function of the
gap on the vertical axis is nearly C2's own column (the attraction is a smooth function of the
gap): fitted beside C1..C4 it takes over the weight from C3 and C4, and where the logged currents
are noisy it removes most of the equation error their errors cause. Held to the candidates'
separability test from the constants (variance inflation at most ``max_vif``) it no longer does.
Nor may a probe's constant beside a constant force stop the errors-in-variables compensation, nor
a trend along the travel pass for end effects.

The logs come from the independent generator with observers 2.8x faster than its default
(``bench/diagnose_rigs.py``'s ``obs2800`` rig): their commanded currents are as noisy as those of
``../shared/logs/independent_clean.csv`` (noise floor above 200 Hz and sample-to-sample jitter
within 3 %, bench/README), 20x noisier than the generator's default.
"""

from __future__ import annotations

import json
import math
import re
from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.data.reading import read_log
from maglev_oc.diagnosis.probes import smooth_probes
from maglev_oc.diagnosis.selection import (
    ALIKE_ALONG_THE_TRACK,
    Rival,
    Rivals,
    SelectionSettings,
    _HeldOutGrams,
    _rival_gains,
    stands_in_for_the_constants,
)
from maglev_oc.regression.data import prepare
from maglev_oc.regression.design import build_design
from maglev_oc.regression.solve import fit_subset
from tests.diagnosis_support import diagnose_path, relative_errors
from tests.independent import write_log
from tests.independent.rigs import RIGS
from tests.independent.scoring import score
from tests.independent.sets import SINGLE_EFFECTS
from tests.independent.simulate import Rig, Scenario, simulate
from tests.test_diagnose_effects import _drawn_pair, _drawn_pair_finds

NOISY = Rig(**RIGS["obs2800"])
"""The generator's rig with currents as noisy as the shared clean log's (module doc; the bench's
``--rig obs2800``)."""

MAX_VIF = SelectionSettings().max_vif


@pytest.fixture(scope="module")
def noisy_cogged(model, tmp_path_factory):
    """(design with the smooth probes beside C1..C4, probes by (axis, variable) -> group name) of the
    60 s log of the noisy rig with a large normal cogging force (the log of the last test), a
    quarter held out."""
    scenario = Scenario(
        name="cogging", seed=702, effects=(SINGLE_EFFECTS["normal_cogging"]("large"),), rig=NOISY
    )
    path, _ = write_log(simulate(scenario), tmp_path_factory.mktemp("noisy"), stem="cogging")
    data = prepare([read_log(path)], bandwidth=10.0)
    fit, hold = data.masks(0.25)
    probes = smooth_probes(data)
    design = build_design(data, model, terms=list(probes.values()), fit=fit, holdout=hold)
    return design, {k: t.name for k, t in probes.items()}


def _inflation_by_inverse(design, columns) -> float:
    """The variance inflation of one column beside the base constants, from the inverse of the
    compensated Gram (G^-1)_jj G_jj: the textbook single-column formula, not the canonical
    correlation the code computes."""
    cols = np.concatenate([design.indices(["base"]), [columns]])
    g = design.gram.sum(axis=0)[np.ix_(cols, cols)] - design.noise.sum(axis=0)[np.ix_(cols, cols)]
    return float(np.linalg.inv(g)[-1, -1] * g[-1, -1])


def test_only_the_gap_on_the_vertical_axis_stands_in_for_the_constants(noisy_cogged):
    # every probe's first column judged beside C1..C4: the vertical function of the gap is confounded
    # (its inflation beyond twice max_vif: 540 here, 400-47 000 on the bench's clean logs), every
    # other probe is not (under 2; at most 1.3 on those logs): the attraction's own
    # shape is a function of the gap, nothing else in the base model is a function of one state
    # alone. The decision agrees with the single-column formula on both sides of the threshold
    design, probes = noisy_cogged
    for (axis, var), group in probes.items():
        first = int(design.groups[group][0])
        vif = _inflation_by_inverse(design, first)
        confounded = axis == "vertical" and var == "gap"
        assert (vif > 2 * MAX_VIF) if confounded else (vif < 2.0), (axis, var, vif)
        assert stands_in_for_the_constants(design, [first], MAX_VIF) is confounded
        # the threshold is the argument's, not a constant of the code
        assert stands_in_for_the_constants(design, [first], 0.5 * vif) is True
        assert stands_in_for_the_constants(design, [first], 2.0 * vif) is False


def test_the_confounded_probe_is_no_rival_although_it_explains_the_most(noisy_cogged):
    # unconstrained, the vertical function of the gap is the best vertical rival at every size and
    # explains a large share of the held-out error (the noisy currents' share, taken by dropping C3
    # and C4); held to max_vif, the best rival is another variable's and explains far less
    design, probes = noisy_cogged
    base = fit_subset(design, ["base"], covariance=False)
    around = _HeldOutGrams(design).around(base)
    mse0 = np.maximum(np.mean(around.residual**2, axis=1), 1e-30)
    sizes = {("vertical", k) for k in (1, 2, 4)}
    free = _rival_gains(design, ["base"], mse0, probes, sizes, around)
    held = _rival_gains(design, ["base"], mse0, probes, sizes, around, MAX_VIF)
    for key in sizes:
        top, kept = free.by_size[key][0], held.by_size[key][0]
        assert top.variable == "gap" and top.gain > 0.05, (key, top)
        assert kept.variable != "gap" and kept.gain < 0.5 * top.gain, (key, kept)
    # and what it took was the constants' job: C3 falls by more than half beside it
    gap = list(design.groups[probes[("vertical", "gap")]])
    beside = fit_subset(design, ["base"], covariance=False, extra=gap)
    assert beside.value("C3") < 0.5 * base.value("C3")


def test_a_rival_on_both_axes_takes_every_split_of_its_coefficients_the_probes_allow(noisy_cogged):
    # an effect on both axes with k coefficients is rivalled by k probe columns split any way
    # between the vertical probe (4 columns) and the horizontal one (5, with its constant). At
    # k = 6 the splits that put 0 or 1 on the vertical axis need more columns than the horizontal
    # probe has, and only the later ones exist: the best rival is the best of those, recomputed
    # here fit by fit (the same fits and mean squares: equal to rounding)
    design, probes = noisy_cogged
    base = fit_subset(design, ["base"], covariance=False)
    around = _HeldOutGrams(design).around(base)
    mse0 = np.maximum(np.mean(around.residual**2, axis=1), 1e-30)
    k = 6
    got = _rival_gains(design, ["base"], mse0, probes, {("both", k)}, around).by_size[("both", k)][0]
    best = (-np.inf, "")
    for var in sorted({v for _, v in probes}):
        for kv in range(k + 1):
            cv = list(design.groups[probes[("vertical", var)]])[:kv]
            h = list(design.groups[probes[("horizontal", var)]])
            ch = (h[-1:] + h[:-1])[: k - kv]  # the horizontal constant first, as a rival takes them
            if len(cv) < kv or len(ch) < k - kv:
                continue
            ms = around.mean_squares(fit_subset(design, ["base"], covariance=False, extra=(*cv, *ch)))
            gain = float(np.mean(1.0 - ms / mse0))
            if gain > best[0]:
                best = (gain, var)
    assert np.isfinite(best[0])
    assert got.variable == best[1] and got.gain == pytest.approx(best[0], rel=1e-9)


def test_a_split_that_stands_in_for_the_constants_does_not_end_the_search(noisy_cogged, monkeypatch):
    # the splits of a both-axes rival are judged one by one: one that stands in for the constants
    # is skipped and the later ones still rival. Here every split with no vertical column is made
    # to stand in (a recorder in place of the variance-inflation test): the best rival is the best
    # of the others, recomputed fit by fit
    import maglev_oc.diagnosis.selection as selection

    design, probes = noisy_cogged
    vertical = {
        int(c) for (axis, _), name in probes.items() if axis == "vertical" for c in design.groups[name]
    }

    def horizontal_only(design, columns, max_vif):
        return not any(int(c) in vertical for c in columns)

    monkeypatch.setattr(selection, "stands_in_for_the_constants", horizontal_only)
    base = fit_subset(design, ["base"], covariance=False)
    around = _HeldOutGrams(design).around(base)
    mse0 = np.maximum(np.mean(around.residual**2, axis=1), 1e-30)
    k = 3
    rivals = selection._rival_gains(design, ["base"], mse0, probes, {("both", k)}, around, MAX_VIF)
    got = rivals.by_size[("both", k)][0]
    best = (-np.inf, "")
    for var in sorted({v for _, v in probes}):
        for kv in range(1, k + 1):  # kv = 0 stands in
            cv = list(design.groups[probes[("vertical", var)]])[:kv]
            h = list(design.groups[probes[("horizontal", var)]])
            ch = (h[-1:] + h[:-1])[: k - kv]
            ms = around.mean_squares(fit_subset(design, ["base"], covariance=False, extra=(*cv, *ch)))
            gain = float(np.mean(1.0 - ms / mse0))
            if gain > best[0]:
                best = (gain, var)
    assert got.variable == best[1] and got.gain == pytest.approx(best[0], rel=1e-9)


@pytest.mark.parametrize(
    ("effect", "seed", "name"),
    [
        ("normal_cogging", 702, "cogging_vertical_19mm"),
        # the same check on a second kind (the extended tier: every run makes it on the cogging)
        pytest.param("cable_carrier", 703, "cable_carrier_force", marks=pytest.mark.extended),
    ],
)
def test_a_large_effect_on_the_noisy_rig_is_found_alone_and_sized(tmp_path, effect, seed, name):
    # the large normal cogging force went unclaimed on this rig ("a smooth function of the gap
    # explains more": 97 % of the held-out error against the cogging's 88 %). The large cable
    # carrier was chosen, then dropped beside a horizontal probe whose constant duplicated the
    # carrier's (singular normal equations read as "dominated by the errors of the logged
    # currents", regression.solve._spanned), and its residual reported as unexplained. Each is
    # found alone, sized within 30 % (the bound), with nothing unexplained (the logs of
    # bench/diagnose_rigs.py --rigs obs2800)
    scenario = Scenario(name=effect, seed=seed, effects=(SINGLE_EFFECTS[effect]("large"),), rig=NOISY)
    path, truth_path = write_log(simulate(scenario), tmp_path, stem=effect)
    d = diagnose_path(path)
    s = score(effect, json.loads(truth_path.read_text()), d.to_dict()["effects"])
    assert [e.name for e in d.effects] == [name]
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes, s.sizes)
    assert not d.unexplained


@pytest.mark.extended
def test_a_probe_collinear_with_a_chosen_effect_still_rivals_that_effects_shape(tmp_path):
    # random pair 9118 (bench/diagnose_rigs.py --drawn-pairs, the generator's default rig): Gaussian
    # end effects and an amplifier lag. The end effects' attraction part is a smooth function of the
    # position, and so is the vertical position probe: judged against the whole fit rather than the
    # constants alone, that probe counted as confounded, and a 46 mm guide waviness the position
    # rival had refused (9.4 % of the held-out error against 0.7 %) was claimed. Both true effects
    # are found and sized within 30 % (the bound), and nothing else
    _drawn_pair_finds(
        tmp_path, 9118, ("end_effect", "amplifier_dynamics"), ["end_effects", "current_amplifier_lag"]
    )


def test_a_trend_along_the_travel_on_the_noisy_rig_is_not_claimed_as_end_effects(tmp_path):
    # random pair 9002 on the noisy rig (bench/diagnose_rigs.py --drawn-pairs 24 --seed 9000 --rig
    # obs2800): a guide misalignment (slope 3.8 mrad) and a tilted base. The end effects took the
    # trend along the travel as +1.8 % attraction lost at one end and -1.7 % at the other, falls at
    # the ends of 0.0 and 0.1 standard errors (magnetics.END_FALL_Z): no false claim
    _, d, s = _drawn_pair(tmp_path, 9002, ("guide_misalignment", "tilted_base"), NOISY)
    assert s.no_false_claim, (s.claimed, s.notes)
    assert "end_effects" not in [e.name for e in d.effects]


@pytest.mark.extended
def test_a_spring_whose_constant_a_chosen_force_repeats_is_judged_on_its_stiffness(tmp_path):
    # random pair 9227 on the noisy rig (--drawn-pairs 40 --seed 9200 --rig obs2800): a cable
    # carrier (8.5 N/m) and a commutation offset. A constant force along the track was chosen first;
    # beside it the carrier's constant is spanned and held at 0, and counting that coefficient made
    # the carrier's Wald 0 and its variance inflation infinite: the constant force was claimed (a
    # false claim) and the carrier's position dependence reported unexplained. Judged on the
    # coefficient the fit estimates, the carrier is accepted and the constant force, nested in it,
    # dropped: both true effects found, the carrier sized within 30 % (the bound)
    _, d, s = _drawn_pair(tmp_path, 9227, ("cable_carrier", "commutation_offset"), NOISY)
    assert sorted(e.name for e in d.effects) == ["cable_carrier_force", "commutation_offset"]
    assert s.true_first and s.no_false_claim, (s.claimed, s.notes)
    assert s.sizes["cable_carrier"][1] == pytest.approx(s.sizes["cable_carrier"][0], rel=0.3)
    assert not d.unexplained


def test_a_probe_that_stands_in_for_the_constants_is_not_reported_unexplained(model, noisy_cogged):
    # the noisy cogging log's residual searched beside the base model alone (no effect named, no
    # spatial period given): with no limit on the variance inflation the vertical function of the
    # gap is reported first (it stands in for C2..C4, first test); held to max_vif it is not reported
    import dataclasses

    from maglev_oc.diagnosis.unexplained import find_unexplained

    design, _ = noisy_cogged

    def found(settings):
        out = find_unexplained(
            design.prepared, model, [], design.fit, design.holdout, design.weights, (), settings
        )
        return [(u.axis, u.depends_on) for u in out]

    settings = SelectionSettings()
    assert found(dataclasses.replace(settings, max_vif=np.inf))[0] == ("vertical", "gap")
    assert ("vertical", "gap") not in found(settings)


# --- a rival that is another motor -------------------------------------------------------------------

PAPERS = {"C1": 14.2, "C2": 796.99, "C3": 31.04, "C4": 0.07}


def _fit(values: dict, sd: dict):
    """A stand-in of a candidate's fit: its constants and their standard errors."""
    names = tuple(values)
    return SimpleNamespace(
        names=names, value=values.__getitem__, covariance=np.diag([sd[n] ** 2 for n in names])
    )


def _offset_and_its_rivals():
    # noisy pair 9903's numbers (the test below): the commutation offset's fit has C1 at 14.9 +-
    # 1.04; the best rival of its size (a constant and a linear function of the gap on the
    # horizontal axis) has C1 at 9.4 (34 % below the papers' 14.2, 4.6 standard errors from 14.9),
    # the next (the position) 14.5
    own = _fit(
        {"C1": 14.9, "C2": 779.0, "C3": 30.2, "C4": 0.072}, {"C1": 1.04, "C2": 0.26, "C3": 0.05, "C4": 0.002}
    )
    vertical = {"C2": 778.7, "C3": 30.1, "C4": 0.073}
    ranked = (
        Rival(0.374, "gap", {"C1": 9.4, **vertical}),
        Rival(0.151, "position", {"C1": 14.5, **vertical}),
    )
    return own, ranked


def test_a_rival_that_needs_another_motor_does_not_rival_a_candidate_that_keeps_the_stages():
    own, ranked = _offset_and_its_rivals()
    key = ("both", 2)
    assert Rivals({key: ranked}, PAPERS).best(key, own, "both") is ranked[1]
    # held to nothing (no reference), the best rival counts, as before
    assert Rivals({key: ranked}, None).best(key, own, "both") is ranked[0]
    # beyond 30 % but not 2 standard errors from the candidate's (a C1 as uncertain as +-3): a rival
    assert Rivals({key: ranked}, PAPERS).best(key, _fit({"C1": 14.9}, {"C1": 3.0}), "horizontal") is ranked[0]
    # the candidate's own fit no stage of this design either (C1 at 5): every rival counts
    assert Rivals({key: ranked}, PAPERS).best(key, _fit({"C1": 5.0}, {"C1": 0.1}), "horizontal") is ranked[0]
    # a vertical candidate is held to the vertical constants only: the rival's C1 does not matter
    vertical = _fit({"C2": 779.0, "C3": 30.2, "C4": 0.072}, {"C2": 0.26, "C3": 0.05, "C4": 0.002})
    assert Rivals({key: ranked}, PAPERS).best(key, vertical, "vertical") is ranked[0]
    # no credible rival at all: none
    assert Rivals({key: ranked[:1]}, PAPERS).best(key, own, "both") is None
    assert Rivals({}, PAPERS).best(key, own, "both") is None


@pytest.mark.slow
@pytest.mark.parametrize(
    ("seed", "stiffness"),
    [
        # random pair 9903 on the noisy rig (--drawn-pairs 24 --seed 9900 --rig obs2800): a cable
        # carrier (4.3 N/m) and a -2.4 degree commutation offset. The offset makes the levitation
        # current push along the track and the loop cancels it with i_q, so the base fit's C1 was
        # 0.12 (true 14.75). The offset (C1 back at 14.9) was refused as "not specific": a constant
        # and a linear function of the gap on the horizontal axis explained 37 % of the held-out
        # error against its 23 %, with C1 at 9.4. The carrier was refused the same way, a 0.03 N
        # constant force claimed in their place (a false claim) and C1 left at 0.51. A rival that
        # needs a motor no stage of this design has rivals nothing (selection.Rivals.best)
        (9903, 4.260),
        # random pair 9922 of the same run: a 7.4 N/m carrier and a -2.4 degree offset. C1 was 0.25
        # beside the base model and 5.1 beside the offset alone, which explained 7.7 % of the
        # held-out horizontal error (the carrier 3.8 %): neither passed, nothing was claimed, and C1
        # was warned of (98 % below the model's). Together they explain 53 % with C1 at 16.6 (true
        # 14.7); proposed as a pair and each judged beside the other
        # (selection._pairs_restoring_thrust), both are found
        (9922, 7.385),
    ],
)
def test_a_commutation_offset_and_a_cable_carrier_the_loop_cancels_are_both_found(tmp_path, seed, stiffness):
    # both true effects found and sized within 30 % (the bound; measured 0 % and 3 % on
    # 9903, 0.5 % and 0.1 % on 9922), nothing else claimed, nothing warned of
    effects, d, s = _drawn_pair(tmp_path, seed, ("cable_carrier", "commutation_offset"), NOISY)
    assert effects[0].stiffness == pytest.approx(stiffness, abs=1e-3)  # the bench's log
    assert sorted(e.name for e in d.effects) == ["cable_carrier_force", "commutation_offset"]
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes, s.sizes)
    assert not d.warnings


@pytest.mark.slow
def test_the_pair_proposed_is_the_one_that_brings_the_motor_back(model, tmp_path):
    # pair 9922's library design beside the base model alone (C1 at 0.25): the pair proposed is the
    # carrier and the offset; none without a reference, none when C1 is plausible, none when the
    # pair's gain is under min_gain; without the offset in the pool, whatever is proposed brings C1
    # within identify's plausible change of the model's or halfway there on a log scale
    # (selection._restores; every pair without it leaves C1 under 6.6)
    import dataclasses

    from maglev_oc.diagnosis.library import candidate_library
    from maglev_oc.diagnosis.pipeline import fitted_model
    from maglev_oc.diagnosis.selection import _pairs_restoring_thrust, _restores
    from tests.independent.draws import KINDS, draw

    kinds = ("cable_carrier", "commutation_offset")
    effects = tuple(draw(k, np.random.default_rng([9922, KINDS.index(k)])) for k in kinds)
    scenario = Scenario(name="pair", seed=9922, effects=effects, rig=NOISY)
    path, _ = write_log(simulate(scenario), tmp_path, stem="pair")
    data = prepare([read_log(path)], bandwidth=10.0)
    fit, hold = data.masks(0.25)
    base = fit_subset(build_design(data, model, fit=fit, holdout=hold), ["base"])
    fitted = fitted_model(model, base, data.moving, "test")
    library = [c for c in candidate_library(fitted, data, {}) if c.fallback_for is None]
    design = build_design(data, fitted, terms=[c.term for c in library], fit=fit, holdout=hold)
    by_name = {c.name: c for c in library}
    cur = fit_subset(design, ["base"])
    reference = {"C1": 14.2, "C2": 796.99, "C3": 31.04, "C4": 0.07}
    settings = SelectionSettings()
    pool = list(by_name)

    def proposed(pool=pool, reference=reference, settings=settings):
        return _pairs_restoring_thrust(design, ["base"], cur, pool, by_name, reference, settings)

    assert cur.value("C1") < 0.1 * reference["C1"]
    assert sorted(proposed()[0]) == ["cable_carrier_force", "commutation_offset"]
    assert proposed(reference=None) == []
    assert proposed(reference={**reference, "C1": cur.value("C1")}) == []
    assert proposed(settings=dataclasses.replace(settings, min_gain=0.9)) == []
    # nothing left on the horizontal axis (a log the spring and C1 fit exactly: the interrupt test's
    # sines of tests/test_bad_input.py), or no held-out part there: nothing proposed, and no division
    # by that zero (a RuntimeWarning printed to the user, an error here)
    for nothing in (0.0, math.nan):
        emptied = dataclasses.replace(cur, holdout_rms=np.array([cur.holdout_rms[0], nothing]))
        assert _pairs_restoring_thrust(design, ["base"], emptied, pool, by_name, reference, settings) == []
    for without in proposed(pool=[n for n in pool if n != "commutation_offset"]):
        c1 = fit_subset(design, ["base", *without], covariance=False).value("C1")
        assert _restores(c1, cur.value("C1"), reference["C1"]), c1


def _noisy_named(tmp_path, set_name: str, seed_offset: int, name: str):
    """Log ``name`` of the independent named set at ``seed_offset`` on the noisy rig, as
    ``bench/diagnose_score.py --sets SET --rig obs2800 --seed-offset N`` writes it, diagnosed with
    the defaults and scored: (diagnosis, score)."""
    import dataclasses

    from tests.independent.sets import named_set

    scenario = dict(named_set(set_name, seed_offset=seed_offset))[name]
    # the set's own rig (its gains) with the noisy rig's observer
    scenario = dataclasses.replace(
        scenario, rig=dataclasses.replace(scenario.rig, observer_bandwidth=NOISY.observer_bandwidth)
    )
    path, truth_path = write_log(simulate(scenario), tmp_path, stem=name)
    d = diagnose_path(path)
    return d, score(name, json.loads(truth_path.read_text()), d.to_dict()["effects"])


@pytest.mark.slow
@pytest.mark.extended
def test_three_forces_along_the_track_are_found_in_the_form_of_the_pair_the_data_support(tmp_path):
    # noisy triples_06 of the independent set at seed offset 2000 (bench/diagnose_score.py --sets
    # triples --rig obs2800 --seed-offset 2000): horizontal guide friction (0.3 N Coulomb, 0.4 N
    # breakaway), a 0.8 N detent and a 4 N/m cable carrier along the track, and a 1 N normal
    # cogging. Beside the cogging, C1 was 1.67 (true 13.7) and no candidate passed alone; the pair
    # that brought C1 back and explained the most (55.1 %) was the friction with its Stribeck rise
    # and the detent, but beside the detent the rise was 0.042 +- 0.023 N (implausible), so
    # nothing along the track was claimed and C1 was warned of. The Coulomb-only form of the same
    # pair (54.6 %) passes; the carrier then passes on its own (selection._pairs_restoring_thrust)
    d, s = _noisy_named(tmp_path, "triples", 2000, "triples_06")
    assert sorted(e.name for e in d.effects) == [
        "cable_carrier_force",
        "cogging_horizontal_19mm",
        "cogging_vertical_19mm",
        "guide_friction_horizontal",
    ]
    # every size within 30 % (the bound; measured 0.2 % on the friction, 1.5 % on the
    # cogging, 5.2 % on the detent, 1.6 % on the carrier), nothing warned of: C1 is back
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes, s.sizes)
    assert not d.warnings


@pytest.mark.slow
@pytest.mark.extended
def test_a_guide_waviness_at_the_pole_pitch_is_not_claimed_as_a_detent(tmp_path):
    # random pair 10018 on the noisy rig (--drawn-pairs 24 --seed 10010 --rig obs2800): guides
    # tilted by 3.14 mrad with 4.7 um of waviness at 57.35 mm, and a thrust ripple (2.5 % at 19 mm,
    # 1.7 % at 57 mm). Claimed were the misalignment, the ripple and a 0.018 N detent at the pole
    # pitch (57.15 mm), the waviness's push along its sloping guides (a false claim); the residual
    # beside them showed no period to search. Beside a misalignment a waviness at a chosen motor-pitch
    # force's own period now joins the search (pipeline._chosen_pitches), and the detent is held
    # to it (selection._residual_periods)
    effects, d, s = _drawn_pair(tmp_path, 10018, ("guide_misalignment", "thrust_ripple"), NOISY)
    assert effects[0].slope == pytest.approx(3.1417e-3, abs=1e-6)  # the bench's log
    assert sorted(e.name for e in d.effects) == ["guide_misalignment", "thrust_ripple"]
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes, s.sizes)
    # the waviness found with the slope: within 30 % of its amplitude (the bound; measured
    # 5.1 um, +9 %) at the pole pitch, 0.02 of a cycle from its true period over the travel
    slope = d.effects[[e.name for e in d.effects].index("guide_misalignment")].parameters
    assert slope["waviness_amplitude"].value == pytest.approx(effects[0].waviness_amplitude, rel=0.3)
    assert slope["waviness_period"].value == pytest.approx(0.05715, abs=1e-3)


@pytest.mark.slow
def test_a_commutation_offset_beside_a_tilted_base_is_found_as_a_pair(tmp_path):
    # noisy pairs_04 of the independent set at seed offset 3000 (bench/diagnose_score.py --sets
    # pairs --rig obs2800 --seed-offset 3000): a 1.1 degree commutation offset and guides tilted by
    # 15 mrad. C1 was 9.99 against the papers' 14.2 (-29.7 %, inside identify's 30 %), no candidate
    # passed alone (the tilt 32.8 % of the held-out error at z 2.4; the offset lost to a smooth
    # function of the gap), so the pair step did not run and nothing was claimed. It now runs from
    # a change of C1 beyond the spread of stages of this design (selection.RIG_SPREAD, 20 %)
    d, s = _noisy_named(tmp_path, "pairs", 3000, "pairs_04")
    assert sorted(e.name for e in d.effects) == ["commutation_offset", "horizontal_guides_not_level"]
    # both sizes within 30 % (the bound; measured +0.9 % on the offset's angle, +0.6 % on
    # the tilt's force), nothing warned of: C1 is back
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes, s.sizes)
    assert not d.warnings


@pytest.mark.slow
@pytest.mark.extended
def test_a_guide_waviness_longer_than_the_travel_is_not_claimed_as_a_spring_and_end_effects(tmp_path):
    # random pair 10075 on the noisy rig (--drawn-pairs 24 --seed 10070 --rig obs2800): guides
    # tilted by 4.5 mrad with 7.3 um of waviness at 77 mm over 60 mm of travel, and a 1.1 N detent
    # at the slot pitch. A cable carrier and end effects were claimed beside the misalignment and
    # the detent: over the travel the waviness is a bow, and its residual shows no period. Beside a
    # misalignment and such forces a waviness is now scanned for in a joint fit, from the travel to
    # three travels (pipeline._waviness_beyond_travel), and the selection judges it against them
    effects, d, s = _drawn_pair(tmp_path, 10075, ("detent_force", "guide_misalignment"), NOISY)
    assert effects[1].slope == pytest.approx(-4.4557e-3, abs=1e-6)  # the bench's log
    assert sorted(e.name for e in d.effects) == ["cogging_horizontal_19mm", "guide_misalignment"]
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes, s.sizes)
    # the bow found as a waviness longer than the travel (its period is not resolved over 60 mm:
    # measured 109.9 mm), its size within a factor of two of the truth's 7.3 um (measured 11.1 um: a
    # longer period, a larger amplitude for the same bow)
    guides = d.effects[[e.name for e in d.effects].index("guide_misalignment")].parameters
    assert guides["waviness_period"].value > 0.06
    assert 0.5 < guides["waviness_amplitude"].value / effects[1].waviness_amplitude < 2.0


@pytest.mark.slow
@pytest.mark.extended
def test_a_spring_beside_tilted_guides_keeps_the_slope_a_long_waviness_could_stand_for(tmp_path):
    # random pair 10085 on the noisy rig (--drawn-pairs 24 --seed 10070 --rig obs2800): guides
    # tilted by 2.9 mrad with 6.2 um of waviness at 56 mm, and a 6 N/m cable carrier. Beside the
    # misalignment and the carrier, the scan for a waviness longer than the travel was least at its
    # longest period (three travels): a line of the gap, the slope's own shape. Taken as a waviness
    # it replaced the slope (the misalignment no longer claimed); such a scan now adds nothing
    effects, d, s = _drawn_pair(tmp_path, 10085, ("guide_misalignment", "cable_carrier"), NOISY)
    assert effects[0].slope == pytest.approx(-2.8818e-3, abs=1e-6)  # the bench's log
    assert sorted(e.name for e in d.effects) == ["cable_carrier_force", "guide_misalignment"]
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes, s.sizes)


@pytest.mark.slow
@pytest.mark.extended
def test_a_vertical_friction_that_only_holds_the_models_misfit_is_not_claimed_and_what_it_hid_is_found(
    tmp_path,
):
    # random pair 10116 on the noisy rig (--drawn-pairs 24 --seed 10100 --rig obs2800): end effects
    # (a raised cosine over 61 mm from ends at +-50 mm, 11 % of the thrust and 4.5 % of the magnets'
    # attraction lost at them) and a 4.8 N/m cable carrier. A vertical friction of 0.083 +- 0.036 N
    # holding 1.30 of the force was claimed beside the carrier: holding the axis at standstill it
    # took up the model's misfit in the gap there (65 % of the held-out vertical error alone; -0.1 %
    # beside a smooth function of the gap). Such a friction is now judged beside that function
    # (selection._beyond_the_misfit) and dropped. The end effects, judged beside the friction while
    # it was chosen, are judged again without it once it is dropped (selection.select's forward
    # steps after the backward pass): found, where before the misfit was reported nowhere
    effects, d, s = _drawn_pair(tmp_path, 10116, ("end_effect", "cable_carrier"), NOISY)
    assert effects[1].stiffness == pytest.approx(4.786, abs=1e-3)  # the bench's log
    assert sorted(e.name for e in d.effects) == ["cable_carrier_force", "end_effects"]
    assert s.true_first and s.no_false_claim, (s.claimed, s.notes)
    # both within 30 % (the bound, as the bench scores them): the carrier measured
    # 4.8 +- 0.09 N/m (+0.3 %); the thrust lost at the logged ends relative to the centre 5.4 and
    # 6.9 % against the generator's 5.7 and 6.2 %, the attraction 2.2 and 2.7 % against 2.3 and 2.5 %
    assert s.size_right, s.notes
    carrier = next(e for e in d.effects if e.name == "cable_carrier_force")
    assert carrier.parameters["stiffness"].value == pytest.approx(effects[1].stiffness, rel=0.3)
    assert not d.unexplained, d.unexplained


@pytest.mark.slow
def test_a_friction_holding_its_axis_is_kept_beside_the_misfit_it_leaves_in_that_axiss_state(generated):
    # experiments_37 (soft gains; 2 N of vertical guide friction with pre-sliding, LuGre): the
    # friction explains 99.99 % of the vertical error's square (0.45 m/s^2 RMS without it, 0.005
    # with it), and beside it a smooth function of the gap explains 49 % of what is left (z 4.6
    # pooled over the quarter and the cross-fitted parts, 1.8 on the quarter): the friction model's
    # misfit where it holds the axis. Judged again beside that unexplained probe, as an effect is
    # beside a dependence on another variable than its own, the friction was dropped as not
    # specific; its axis's state is its own variable (pipeline._explained_by_unexplained), and it
    # was judged beside such a function already (selection._beyond_the_misfit)
    path, truth = generated("experiments", "experiments_37")
    assert truth["name"] == "soft_gains_guide_friction_vertical"
    d = diagnose_path(path)
    assert [e.name for e in d.effects] == ["guide_friction_vertical"]
    (u,) = [u for u in d.unexplained if u.axis == "vertical"]
    assert u.depends_on == "gap"  # what is left is reported, not named


@pytest.mark.slow
def test_a_ripple_seen_on_the_thrust_current_is_not_dropped_for_a_dependence_of_the_accelerations(tmp_path):
    # random pair 10023 on the noisy rig (--drawn-pairs 24 --seed 10010 --rig obs2800): vertical
    # guide friction and a thrust ripple. The ripple is seen predicting the logged thrust current
    # (z 5.6); beside the friction a dependence on the vertical rate is left unexplained (the
    # friction model's misfit, 24 % of the vertical error, z 3.6 once the probes are judged over
    # the cross-fitted parts). Judged again on the accelerations beside that dependence, the ripple
    # was dropped as not specific (z 1.8 on the quarter); its evidence is the thrust current, which
    # that dependence does not rival (pipeline._explained_by_unexplained's on_thrust)
    effects, d, s = _drawn_pair(tmp_path, 10023, ("guide_friction_vertical", "thrust_ripple"), NOISY)
    assert effects[1].ratio == pytest.approx(0.04994, abs=1e-5)  # the bench's log
    assert sorted(e.name for e in d.effects) == ["guide_friction_vertical", "thrust_ripple"]
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes)


@pytest.mark.slow
def test_a_guide_waviness_that_does_not_pass_leaves_no_cogging_in_its_place(tmp_path):
    # random pair 9960 on the noisy rig (--drawn-pairs 24 --seed 9950 --rig obs2800): guides tilted
    # by 3.5 mrad with 6.2 um of waviness at 51 mm, and a field shape. The first selection chose the
    # misalignment and a 0.035 N normal cogging at 38.1 mm; beside them the residual still showed a
    # period of 48.8 mm, 0.38 of a cycle from 38.1 mm over the 65 mm travel. The waviness at that
    # period lost on the horizontal axis what it gained vertically and did not pass (z 1.7), and the
    # cogging was claimed (a false claim). A force at a motor pitch is now unresolved from the pool's
    # waviness too (selection._residual_periods): not separable, named with the waviness
    from tests.independent.draws import KINDS, draw

    kinds = ("guide_misalignment", "field_shape")
    effects = tuple(draw(k, np.random.default_rng([9960, KINDS.index(k)])) for k in kinds)
    assert effects[0].slope == pytest.approx(3.468e-3, abs=1e-6)  # the bench's log
    scenario = Scenario(name="+".join(kinds), seed=9960, effects=effects, rig=NOISY)
    path, truth_path = write_log(simulate(scenario), tmp_path, stem="pair")
    d = diagnose_path(path)
    s = score("pair", json.loads(truth_path.read_text()), d.to_dict()["effects"])
    assert [e.name for e in d.effects] == ["guide_misalignment"]
    assert s.true_first and s.no_false_claim, (s.claimed, s.notes)
    # the misalignment's slope within 30 % (the bound; measured 3.38 mrad, -2.5 %)
    assert d.effects[0].parameters["slope"].value == pytest.approx(effects[0].slope, rel=0.3)
    stand_in = {n.name: n for n in d.not_separable}["cogging_vertical_38mm"]
    assert any(c.startswith("guide_waviness_") for c in stand_in.confounded_with)
    # the experiment that would separate them names the waviness in words, with its period
    words = stand_in.experiment
    assert re.search(r"from that of guide waviness \(\d+ mm period\)", words), words
    # one of them at its own period (pipeline._chosen_pitches): no travel between the stoppers
    # tells them apart (was "a run over 65325889673 mm of travel"), so its own experiment is named
    assert words.startswith("no run between the stoppers (120 mm)"), words
    own = "runs at two gaps separate a force that grows as the gap closes from guide waviness"
    assert words.endswith(own), words


@pytest.mark.slow
def test_a_tilt_is_not_claimed_for_sloping_guides_beside_a_vertical_trend_no_effect_explains(tmp_path):
    # Drawn pair 32687 on 20 um encoders (bench/diagnose_rigs.py --rig enc20um --drawn-pairs 12
    # --pairs-with end_effect normal_cogging detent_force thrust_ripple guide_misalignment --seed
    # 32600): guides sloping by 3.7 mrad against the stator (-0.099 N along the track) and end
    # effects at one stator end falling as a raised cosine over 68 mm of the 74 mm travel. A tilt of
    # the guides, -6.4 mrad with exactly the slope's force, was claimed: the slope alone made the
    # held-out vertical error worse (the end effects are not in it), and beside the tilt the end
    # effects' losses grew towards the other end (the slope's line in the attraction). Beside the
    # vertical dependence on the position that no effect explains, the two explain as much along the
    # track and the slope nothing on the vertical axis beyond it (pipeline._alike_beside_unexplained):
    # neither is claimed, both are listed as not separable with the gauge-block check, and the
    # dependence is reported with the end effect among its causes.
    kinds = ("end_effect", "guide_misalignment")
    effects, d, s = _drawn_pair(tmp_path, 32687, kinds, "enc20um")
    assert effects[1].slope == pytest.approx(3.660e-3, abs=1e-6)  # the bench's log
    assert s.no_false_claim, (s.claimed, s.notes)
    assert "horizontal_guides_not_level" not in s.claimed
    apart = {n.name: n for n in d.not_separable}
    assert apart["horizontal_guides_not_level"].confounded_with == ("guide_misalignment",)
    assert apart["guide_misalignment"].confounded_with == ("horizontal_guides_not_level",)
    assert "gauge-block" in apart["guide_misalignment"].experiment
    vertical = [u for u in d.unexplained if u.axis == "vertical" and u.depends_on == "position"]
    assert vertical and "end effect" in vertical[0].description, d.unexplained
    # the constants are fitted beside the force along the track the two share (pipeline.
    # _with_shared_force): C1 within 5 % of the truth, as beside a claimed effect on a log whose end
    # effects are not in the model (the issue asks 1 % on clean logs; measured -0.4 %, -30 % and a
    # warning without that force)
    assert not d.warnings, d.warnings
    assert abs(relative_errors(d, json.loads((tmp_path / "pair.truth.json").read_text()))["C1"]) < 0.05
    # and the "after" figures come from that model, the force in it (pipeline._shared_terms): the
    # force, 0.099 N on the 1.59 kg mover, is 0.062 m/s^2, about the whole held-out horizontal error
    # before (measured 0.0624 -> 0.0363 m/s^2, 38 -> 6.6 um; unchanged without the force, the
    # constants not those reported)
    assert d.error_after.horizontal < 0.8 * d.error_before.horizontal
    assert d.output_error_after.horizontal < 0.5 * d.output_error_before.horizontal
    assert "not separable on this log" in d.validation_after.model


@pytest.mark.slow
@pytest.mark.extended
def test_sloping_guides_are_not_claimed_for_a_tilt_where_the_vertical_axis_alone_does_not_size_them(tmp_path):
    # Drawn pair 33250 on currents through the sensors' filter (bench/diagnose_rigs.py --rig filtered
    # --drawn-pairs 12 --pairs-with end_effect tilted_base guide_misalignment normal_cogging --seed
    # 33100): a 7.0 mrad tilt of the guides and end effects falling as a raised cosine over the whole
    # travel. Guides sloping by -4.05 mrad against the stator were claimed in the tilt's place: beside
    # the end effects they explained 2.1 % of the held-out vertical error, above the parsimony
    # penalty, but fitted beside the tilt, which takes the force along the track, the vertical axis
    # sized the slope at 1.2 +- 1.4 mrad (0.29 of it): the end effects' misfit, not the slope's gap
    # change (selection.sized_alike_on_the_other_axis). Neither is claimed now, both are listed as
    # not separable, the end effects are claimed, and C1 is within 5 % of the truth (the force
    # along the track carried, pipeline._with_shared_force; measured -0.9 %).
    _, d, s = _drawn_pair(tmp_path, 33250, ("end_effect", "tilted_base"), "filtered")
    assert s.no_false_claim, (s.claimed, s.notes)
    assert [e.name for e in d.effects] == ["end_effects"]
    apart = {n.name: n for n in d.not_separable}
    assert apart["guide_misalignment"].confounded_with == ("horizontal_guides_not_level",)
    assert "that axis alone sizes them at" in apart["guide_misalignment"].reason
    assert abs(relative_errors(d, json.loads((tmp_path / "pair.truth.json").read_text()))["C1"]) < 0.05


@pytest.mark.slow
@pytest.mark.parametrize(
    ("seed", "kinds"),
    [(32235, ("end_effect", "tilted_base")), (32204, ("end_effect", "guide_misalignment"))],
)
def test_the_vertical_axis_alone_sizes_a_true_slope_at_its_size_and_rules_it_out_beside_a_true_tilt(
    tmp_path, monkeypatch, seed, kinds
):
    # Drawn pairs of bench/diagnose_rigs.py --drawn-pairs 12 --pairs-with end_effect tilted_base
    # guide_misalignment --seed 32200 (default rig). Fitted beside the chosen effects and the tilt,
    # which takes the force along the track, the vertical axis alone sizes guides sloping against
    # the stator (selection.other_axis_size): where the slope is true (pair 32204, -2.2 mrad) at its
    # size on both axes, within 3 standard errors (measured 1.00 +- 0.02); where a tilt is (pair
    # 32235, 4.4 mrad), at nothing, further than OTHER_AXIS_RULES_OUT standard errors from its
    # size (measured -0.06 +- 0.02: 50). What decides whether a slope is chosen over a tilt
    # (sized_alike_on_the_other_axis) and whether a tilt stays beside a vertical dependence no
    # effect explains (pipeline._alike_beside_unexplained).
    from maglev_oc.diagnosis import pipeline
    from maglev_oc.diagnosis.selection import OTHER_AXIS_RULES_OUT, other_axis_size

    sizes = []
    separate = pipeline._separate_unexplained

    def sized(session, fitted, library, design, sel, tr):
        name = next(n for n in sel.selected if n in ALIKE_ALONG_THE_TRACK[0])
        sizes.append(other_axis_size(design, ["base", *[n for n in sel.selected if n != name]], name))
        return separate(session, fitted, library, design, sel, tr)

    monkeypatch.setattr(pipeline, "_separate_unexplained", sized)
    *_, s = _drawn_pair(tmp_path, seed, kinds)
    assert s.true_first and s.no_false_claim, (s.claimed, s.notes)
    (ratio, stderr), *_ = sizes
    if "guide_misalignment" in kinds:
        assert abs(ratio - 1) < 3 * stderr, (ratio, stderr)
    else:
        assert abs(ratio - 1) > OTHER_AXIS_RULES_OUT * stderr, (ratio, stderr)


@pytest.mark.slow
def test_a_true_tilt_stays_claimed_beside_a_vertical_dependence_where_the_vertical_axis_rules_a_slope_out(
    tmp_path, monkeypatch
):
    # Set 32004 of bench/diagnose_rigs.py --rig log500 --drawn-pairs 12 --per-log 3 --warm large
    # --seed 32000: end effects, a field shape and guides tilted by -7.5 mrad, the magnets warming,
    # logged at 500 Hz. Beside the vertical dependence on the position that no effect explains,
    # the tilt and guides sloping against the stator explain alike along the track
    # (pipeline._alike_beside_unexplained), but the vertical axis alone sizes the slope at -0.01 +-
    # 0.013 of its size on both axes, 80 standard errors from it (OTHER_AXIS_RULES_OUT is 10): no
    # slope is in that axis's residual, so the tilt stays claimed. With the rule taken out the tilt
    # went to not_separable beside the slope (49bb1b9). The log is the bench's bit for bit under
    # glibc's generic libm (tests/conftest.py; 8bc3ceab... by md5), which this test checks by its
    # unexplained dependence, the case it needs.
    from maglev_oc.diagnosis import pipeline
    from maglev_oc.diagnosis.selection import ALIKE_ALONG_THE_TRACK, other_axis_size
    from tests.independent.effects import MagnetWarming

    tilt = ALIKE_ALONG_THE_TRACK[0][0]
    sizes = []
    size = other_axis_size

    def measured(design, rest, name):
        out = size(design, rest, name)
        sizes.append(out)
        return out

    monkeypatch.setattr(pipeline, "other_axis_size", measured)
    kinds = ("end_effect", "field_shape", "tilted_base")
    effects, d, s = _drawn_pair(tmp_path, 32004, kinds, "log500", extra=(MagnetWarming.large(),))
    assert effects[2].angle == pytest.approx(-7.458e-3, abs=1e-6)  # the bench's draw
    assert any(u.axis == "vertical" and u.depends_on == "position" for u in d.unexplained), d.unexplained
    assert s.no_false_claim, (s.claimed, s.notes)
    assert tilt in s.claimed
    assert tilt not in {n.name for n in d.not_separable}
    (ratio, stderr), *_ = sizes  # the rule was reached: the case this log is for
    assert abs(ratio - 1.0) > pipeline.OTHER_AXIS_RULES_OUT * stderr, (ratio, stderr)


@pytest.mark.slow
def test_sticking_guides_and_a_commutation_offset_that_each_leave_c1_far_off_are_found_together(tmp_path):
    # Set 31806 of bench/diagnose_rigs.py --rig enc1um --drawn-pairs 12 --per-log 4 --duration 30
    # --seed 31800: horizontal guide friction of 0.99 N (breakaway 1.38 N, twice the platform's
    # inertial force, so the guides hold it a fifth of the time), a -2.4 degree commutation offset,
    # end effects and a 0.5 ms amplifier lag. The loop cancels the offset's share of i_d with i_q,
    # so the base fit gave C1 0.33 (true 14.6). Each of friction and offset alone explained nothing
    # there; the two together brought C1 to 5.3 (26 % of the way on a log scale), short of the
    # plausible 30 % that selection._pairs_restoring_thrust asked, and beside the friction only the
    # offset passed (z 11), not the friction beside it. Nothing was claimed, C1 stayed 0.33 with a
    # warning. Now a pair may restore C1 halfway (selection.RESTORED_SHARE) and the member that
    # passes beside the other is chosen alone (selection._lone_of_the_pair); converged around it,
    # the two pass together. Sizes within 30 % (the bound; measured Coulomb 0.97 N for
    # 0.99, -0.0420 rad for -0.0423) and C1 within 10 % (measured -4 %: the end effects and lag are
    # not in the model).
    kinds = ("guide_friction_horizontal", "end_effect", "commutation_offset", "amplifier_dynamics")
    effects, d, s = _drawn_pair(tmp_path, 31806, kinds, "enc1um", duration=30.0)
    assert effects[2].angle == pytest.approx(-0.0423175, abs=1e-6)  # the bench's draw
    assert s.true_first and s.no_false_claim, (s.claimed, s.notes)
    found = {e.name: e for e in d.effects}
    assert {"guide_friction_horizontal", "commutation_offset"} <= set(found), s.claimed
    assert found["commutation_offset"].parameters["angle"].value == pytest.approx(effects[2].angle, rel=0.3)
    assert found["guide_friction_horizontal"].parameters["coulomb"].value == pytest.approx(
        effects[0].coulomb_force, rel=0.3
    )
    assert not d.warnings, d.warnings
    assert abs(relative_errors(d, json.loads((tmp_path / "pair.truth.json").read_text()))["C1"]) < 0.1
