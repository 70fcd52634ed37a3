"""Current sensors that read off zero (``currents.sensor_offset_candidate``) or differ in gain
(``currents.sensor_gain_candidate``), errors of real drives that neither the library nor the
independent generator had:

- each candidate's column is what the independent generator's C core (``tests/independent``, its
  own implementation of 002's transform, with an offset or a gain per phase) does with such errors,
  to first order;
- on logs of the generator with the errors in, they are found first and sized, and nothing else is
  claimed. Before the candidates, offsets were claimed as a 38 mm normal cogging, a guide
  misalignment, or a guide waviness beside a cable carrier, and gain mismatches as guide waviness
  at 52-57 mm (bench/README, *A current sensor that reads off zero*);
- beside guides found tilted against the stator it is not separable from their waviness, which
  does the same along the travel (``Candidate.confounded_beside``).
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from maglev_oc.data.reading import read_log
from maglev_oc.diagnosis.candidate import LibraryContext
from maglev_oc.diagnosis.currents import (
    SENSOR_OFFSET_BOUND_A,
    sensor_gain_candidate,
    sensor_offset_candidate,
)
from maglev_oc.regression.data import prepare
from maglev_oc.results import Estimate
from tests.diagnosis_support import diagnose_path
from tests.independent import core
from tests.independent import effects as E
from tests.independent.logio import write_log
from tests.independent.physics import model_functions
from tests.independent.scoring import score
from tests.independent.simulate import Rig, Scenario, build_params, simulate


def _core_and_column(model, cand, effect, reference, q, seed: int):
    """At 40 random gaps, positions and currents, with the papers' constants in both codes: the
    independent C core's accelerations (vertical, horizontal) with ``effect`` minus those with
    ``reference`` (40, 2), the candidate's column at coefficients ``q`` (40, 2) and the gaps."""
    c = tuple(getattr(model.constants, k) for k in ("C1", "C2", "C3", "C4"))
    with_it = build_params(Scenario(name="e", seed=0, effects=(effect,)), c)
    without = build_params(Scenario(name="e", seed=0, effects=reference), c)
    rng = np.random.default_rng(seed)
    change, column, gaps = [], [], []
    for _ in range(40):
        gap, x3 = rng.uniform(0.014, 0.026), rng.uniform(-0.05, 0.05)
        iq, id_ = rng.uniform(-3, 3), rng.uniform(-2, 5)
        state = np.array([gap, 0.0, x3, 0.0, 0.0, 0.0])
        d1, _ = core.eval_rhs(with_it, state, iq, id_)
        d0, _ = core.eval_rhs(without, state, iq, id_)
        change.append((d1 - d0)[[1, 3]])
        column.append(np.asarray(cand.term.function([gap, 0.0, x3, 0.0], [iq, id_], [0.0, 0.0], q)).ravel())
        gaps.append(gap)
    return np.array(change), np.array(column), np.array(gaps)


def _context(model, generated) -> LibraryContext:
    path, _ = generated("clean", "clean_01")
    return LibraryContext(model, prepare([read_log(path)], bandwidth=10.0))


def test_the_column_is_what_the_generators_phase_offsets_do(model, generated):
    """At the papers' constants in both codes, the generator's accelerations with the offsets of the
    large size (80, 0, -50 mA) minus those without are the candidate's column at (A, B), the
    offsets' first harmonic in the dq frame (``phase_harmonic``, which this checks against the C
    core's own transform). The candidate is first order in the offset: it leaves out L4 |di|^2 (at
    most 0.074 x 0.076^2 = 4.3e-4 m/s^2, against 0.4 m/s^2 of the first-order part), the tolerance
    on the vertical axis; the horizontal force is linear in the current, so there it is exact to
    rounding."""
    cand = sensor_offset_candidate(_context(model, generated))
    effect = E.CurrentSensorOffset.large()
    q = E.phase_harmonic((effect.offset_a, effect.offset_b, effect.offset_c), 1)
    change, column, gaps = _core_and_column(model, cand, effect, (), q, seed=3)
    c = tuple(getattr(model.constants, k) for k in ("C1", "C2", "C3", "C4"))
    l4 = np.array([model_functions(g, c)[3] for g in gaps])
    assert np.all(np.abs(column[:, 0] - change[:, 0]) <= 1.01 * l4 * math.hypot(*q) ** 2)
    np.testing.assert_allclose(column[:, 1], change[:, 1], rtol=1e-9, atol=1e-12)


def test_the_column_is_what_the_generators_phase_gains_do(model, generated):
    """The same for gain errors of 3, 0 and -2 per mille: the generator's accelerations with them
    minus those with their common part alone (which scales both currents: the constants' share) are
    the candidate's column at the errors' second harmonic in the dq frame. First order in the
    errors: what is left is of the errors' size relative to the change (3e-3), so 1 % of the
    largest change is the tolerance."""
    cand = sensor_gain_candidate(_context(model, generated))
    errors = (3e-3, 0.0, -2e-3)
    common = sum(errors) / 3
    change, column, _ = _core_and_column(
        model,
        cand,
        E.CurrentSensorGain(*errors),
        (E.CurrentSensorGain(common, common, common),),
        E.phase_harmonic(errors, 2),
        seed=4,
    )
    np.testing.assert_allclose(column, change, atol=0.01 * np.max(np.abs(change)))


def test_an_offset_beyond_what_a_current_sensor_reads_at_zero_is_not_physical(model, generated):
    cand = sensor_offset_candidate(_context(model, generated))
    angle = Estimate(0.2, 0.01, "rad")
    for share, ok in ((0.9, True), (1.1, False)):
        offset = Estimate(share * SENSOR_OFFSET_BOUND_A, 0.01, "A")
        reason = cand.plausible({"offset": offset, "angle": angle})
        assert (reason is None) is ok, reason


NOISY = {"observer_bandwidth": 2800.0}
"""The rig whose logged currents are as noisy as ``../shared/logs/independent_clean.csv``'s."""


@pytest.mark.slow
@pytest.mark.parametrize(
    ("kind", "size", "rig", "seed", "name"),
    [
        pytest.param(
            E.CurrentSensorOffset, "small", NOISY, 7001, "current_sensor_offset", id="offset-small-noisy"
        ),
        pytest.param(
            E.CurrentSensorGain, "small", NOISY, 7001, "current_sensor_gain_mismatch", id="gain-small-noisy"
        ),
        pytest.param(
            E.CurrentSensorOffset,
            "large",
            {},
            7002,
            "current_sensor_offset",
            id="offset-large",
            marks=pytest.mark.extended,
        ),
        pytest.param(
            E.CurrentSensorGain,
            "large",
            {},
            7002,
            "current_sensor_gain_mismatch",
            id="gain-large",
            marks=pytest.mark.extended,
        ),
    ],
)
def test_errors_of_the_current_sensors_are_found_first_and_sized(tmp_path, kind, size, rig, seed, name):
    """24 mA of offset in the dq frame (30 and -10 mA on two phases) and a 1.2 % gain mismatch
    (+1 and -1 %) on the rig whose logged currents are as noisy as the shared clean log's, 76 mA and
    2.9 % on the default rig: found first, nothing else claimed, the size within the issue's 30 %
    (measured: within 1.2 % on the logs of bench/README)."""
    effect = getattr(kind, size)()
    scenario = Scenario(name=f"{kind.kind}_{size}", seed=seed, effects=(effect,))
    scenario = dataclasses.replace(scenario, rig=dataclasses.replace(Rig(), **rig))
    csv, truth_path = write_log(simulate(scenario), tmp_path, kind.kind)
    truth = json.loads(truth_path.read_text())
    effects = diagnose_path(csv).to_dict()["effects"]
    s = score(kind.kind, truth, effects)
    assert s.true_first and s.no_false_claim, s.claimed
    assert s.size_right, s.notes
    assert effects[0]["name"] == name


@pytest.mark.slow
def test_beside_tilted_guides_an_offset_is_not_separable_from_their_waviness(generated):
    """experiments_06 of the independent set: 4 mrad guides with 8 um of waviness at 60 mm, set-point
    steps. Judged beside the misalignment the offset's force, turning once over two pole pitches
    on both axes a quarter period apart, fits what the misalignment's model leaves of the waviness:
    0.5 mA at z 3.9 (0.4 % of the held-out error) was claimed before the rule. Now the
    misalignment alone is claimed and the offset is listed as not separable from it."""
    path, _ = generated("experiments", "experiments_06")
    d = diagnose_path(path).to_dict()
    assert [e["name"] for e in d["effects"]] == ["guide_misalignment"]
    (entry,) = [n for n in d["not_separable"] if n["name"] == "current_sensor_offset"]
    assert entry["confounded_with"] == ["guide_misalignment"]
    assert "commands at zero" in entry["experiment"]


@pytest.mark.slow
@pytest.mark.extended
def test_beside_end_effects_a_gain_mismatch_that_their_fall_off_moves_is_not_claimed(tmp_path):
    """Sensor pair 7103 of bench/diagnose_rigs.py --sensor-pairs: 76 mA of sensor offset (the large
    size) and the large end effects. Over the 62 mm travel a mismatch's forces over each pole pitch
    take what the end effects' assumed fall-off misses: a 0.093 +- 0.01 % mismatch was claimed, which
    ran from 0.037 % to 0.23 % over the fall-offs the travel allows. Held to the end effects' shape
    (pipeline.SHAPE_SIZES) it is not separable from them; the offset and the end effects are claimed,
    the offset within the issue's 30 %."""
    from tests.independent.sets import SINGLE_EFFECTS

    effects = (E.CurrentSensorOffset.large(), SINGLE_EFFECTS["end_effect"]("large"))
    scenario = Scenario(name="current_sensor_offset+end_effect", seed=7103, effects=effects, rig=Rig())
    csv, truth_path = write_log(simulate(scenario), tmp_path, "sensor_pair_7103")
    d = diagnose_path(csv).to_dict()
    s = score("sensor_pair_7103", json.loads(truth_path.read_text()), d["effects"])
    assert s.true_first and s.no_false_claim, s.claimed
    assert sorted(e["name"] for e in d["effects"]) == ["current_sensor_offset", "end_effects"]
    (entry,) = [n for n in d["not_separable"] if n["name"] == "current_sensor_gain_mismatch"]
    assert entry["confounded_with"] == ["end_effects"]
    truth, claimed = s.sizes["current_sensor_offset"]
    assert abs(claimed / truth - 1) < 0.3, (truth, claimed)


def _large_gain_beside_drawn_end_effects(seed: int, tmp_path):
    """The diagnosis (SPEC 3 dict) and score of the large gain mismatch beside end effects drawn as
    the generator draws them for ``seed``, on its default rig."""
    from tests.independent.draws import KINDS, draw

    ends = draw("end_effect", np.random.default_rng([seed, KINDS.index("end_effect")]))
    scenario = Scenario(name="gain+ends", seed=seed, effects=(E.CurrentSensorGain.large(), ends), rig=Rig())
    csv, truth_path = write_log(simulate(scenario), tmp_path, f"gain_ends_{seed}")
    d = diagnose_path(csv).to_dict()
    return d, score(f"gain_ends_{seed}", json.loads(truth_path.read_text()), d["effects"])


@pytest.mark.slow
@pytest.mark.extended
def test_beside_end_effects_no_model_fits_a_slow_sine_seen_over_a_travel_of_few_periods_is_not_claimed(
    tmp_path,
):
    """The large gain mismatch (2.9 %) beside drawn end effects of a raised-cosine profile (8.4 % of
    the attraction at +-50 mm falling over 20 mm; seed 7705): the end effects' scanned fall-offs do
    not fit them and a smooth function of the position explains more, reported as unexplained
    (0.63 N RMS). A 0.31 N normal cogging at 38 mm, seen over 1.5 periods of the 58 mm travel, was
    claimed beside it; beside that dependence it explains 0.3 % of the held-out error
    (pipeline.SHORT_PERIODS). The mismatch alone is claimed, within the issue's 30 %."""
    d, s = _large_gain_beside_drawn_end_effects(7705, tmp_path)
    assert s.true_first and s.no_false_claim, s.claimed
    assert [e["name"] for e in d["effects"]] == ["current_sensor_gain_mismatch"]
    assert any(u["depends_on"] == "position" for u in d["unexplained"])
    truth, claimed = s.sizes["current_sensor_gain"]
    assert abs(claimed / truth - 1) < 0.3, (truth, claimed)


@pytest.mark.slow
@pytest.mark.extended
def test_beside_a_gain_mismatch_and_end_effects_at_one_stator_end_a_sine_their_fall_off_moves_is_not_claimed(
    tmp_path,
):
    """The large gain mismatch (2.9 %) beside drawn end effects at one stator end (6.3 % of the
    thrust at +50 mm, falling over 11.6 mm; the other end 300 mm away; seed 7707). The end effects
    alone are fitted at the scanned 11.9 mm; beside the mismatch's first-order model at 18.9 mm, and
    a 0.017 N normal cogging at 38 mm, seen over 1.6 periods of the 61 mm travel, took what the two
    leave (1.6 % of the held-out error). Over the fall-offs the travel allows its size ran from
    0.018 to 0.048 N, half that range 0.89 times its size (pipeline.SHAPE_SPREAD, 0.75): not separable
    from the end effects' shape. The mismatch and the end effects are claimed, each within the
    issue's 30 %."""
    d, s = _large_gain_beside_drawn_end_effects(7707, tmp_path)
    assert s.true_first and s.no_false_claim, s.claimed
    assert sorted(e["name"] for e in d["effects"]) == ["current_sensor_gain_mismatch", "end_effects"]
    assert [n["name"] for n in d["not_separable"]] == ["cogging_vertical_38mm"]
    for kind in ("current_sensor_gain", "end_effect"):
        truth, claimed = s.sizes[kind]
        assert abs(claimed / truth - 1) < 0.3, (kind, truth, claimed)
