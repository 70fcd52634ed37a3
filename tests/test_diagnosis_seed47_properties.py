"""A property behind a diagnosis survivor of the seed-47 mutation sample (bench/README, "Mutation
testing"): the JSON gives every judged candidate's gain and z under the same keys. The sample's other
properties sit beside the fixtures they use: the cogging library and every candidate's units in
tests/test_diagnosis_library.py, an uncontested choice's confidence in
tests/test_diagnose_synthetic.py and tests/test_diagnose_ripple_properties.py."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

from tests.diagnosis_support import stub_diagnosis


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
