"""Properties behind the diagnosis survivors of the seed-47 mutation sample (bench/README, "Mutation
testing"): the cogging library's periods and harmonics as documented, every candidate's sentence
giving each size a unit, the JSON giving every judged candidate's gain and z under the same keys,
and the confidence of a choice no other candidate contested."""

from __future__ import annotations

import dataclasses
import re
from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.diagnosis.library import candidate_library
from maglev_oc.model.stage import StageModel
from tests.diagnosis_support import stub_diagnosis
from tests.test_diagnose_ripple_properties import rippled  # noqa: F401 (the module fixture)
from tests.test_diagnose_synthetic import with_friction  # noqa: F401 (the module fixture)
from tests.test_diagnosis_library import plant  # noqa: F401 (the module fixture)


def test_the_cogging_candidates_are_the_documented_periods_and_harmonics(plant):  # noqa: F811
    # magnetics.py and the library's module doc: normal cogging at the slot pitch t1 (with its
    # second harmonic) and at 2 t1 (000 eq. (9)); detent at t1 (with its second harmonic) and at
    # the pole pitch tau (the mover's ends: its fundamental). Each harmonic is a sine and a cosine.
    p = StageModel().params
    t1, tau = p.slot_pitch, p.pole_pitch
    library = {c.name: c for c in candidate_library(StageModel(), plant.data) if c.family == "periodic"}
    expected = {
        f"cogging_vertical_{t1 * 1e3:.0f}mm": 2,
        f"cogging_vertical_{2 * t1 * 1e3:.0f}mm": 1,
        f"cogging_horizontal_{t1 * 1e3:.0f}mm": 2,
        f"cogging_horizontal_{tau * 1e3:.0f}mm": 1,
    }
    assert set(expected) <= set(library)
    for name, harmonics in expected.items():
        assert library[name].term.n_parameters == 2 * harmonics, name


_ESTIMATE = re.compile(r"± (\S+) (\S+)")


def test_every_candidate_gives_each_size_a_unit(plant):  # noqa: F811
    # the sentence a user reads: every "value ± error" is followed by its unit (%, N, mm, ...),
    # never by the bare "1" of a ratio that was not scaled to per cent, nor by the next word
    constants = {k: getattr(plant.model.constants, k) for k in ("C1", "C2", "C3", "C4")}
    units = {"%", "N", "N/m", "N s/m", "mm", "um", "m", "rad", "degrees", "ms", "s", "A", "mrad"}
    for cand in candidate_library(StageModel(), plant.data):
        n = cand.term.n_parameters
        physical = cand.term.physical_parameters(np.full(n, 2e-3), 1e-10 * np.eye(n), constants)
        sentence = cand.describe(physical)
        found = _ESTIMATE.findall(sentence)
        assert found, (cand.name, sentence)
        for _, unit in found:
            assert unit.rstrip(",.;:)") in units, (cand.name, unit, sentence)


def test_every_judged_candidate_reports_its_gain_and_z_under_the_same_keys():
    # effects and rejected candidates are judged by the same numbers; the JSON gives them the
    # same names (a reader of the SPEC 3 contract looks up "holdout_gain" and "z" in both)
    judged = SimpleNamespace(name="thrust_ripple", verdict="not significant", reason="r", gain=0.004, z=1.3)
    d = dataclasses.replace(stub_diagnosis(), rejected=[judged])
    (entry,) = d.to_dict()["rejected"]
    assert entry == {
        "name": "thrust_ripple",
        "verdict": "not significant",
        "reason": "r",
        "holdout_gain": 0.004,
        "z": 1.3,
    }


def test_a_choice_no_other_candidate_contested_has_full_confidence(with_friction):  # noqa: F811
    # the confidence of a choice is the share of bootstrap resamples in which it ranks first among
    # the candidates that pass at its step; with none beside it that share is 1 (not 0: no
    # resample is drawn), and it is a share whatever the contest
    _check_confidence(with_friction)


def test_a_planted_ripples_confidence_is_a_share(rippled):  # noqa: F811
    _check_confidence(rippled[-1])


def _check_confidence(d):
    assert d.effects
    for step, effect in zip(d.selection.steps, d.effects, strict=False):
        passing = [n for n, j in step.judgements.items() if j.verdict in ("passes", "accepted")]
        assert 0.0 < step.confidence <= 1.0
        if passing == [step.chosen]:
            assert step.confidence == 1.0 and effect.confidence == 1.0
    assert d.to_dict()["effects"][0]["confidence"] == pytest.approx(d.effects[0].confidence)
