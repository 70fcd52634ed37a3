"""What the stage-file reader refuses and how it says so (``maglev_oc.model.stagefile``), checked
against documents edited here:

- a value of the wrong JSON type, a top level that is not an object and an object where a list
  belongs are named in JSON's words, with the file and the field path;
- an unknown effect is refused listing each known effect;
- a covariance with a nonzero entry beside a zero variance is refused naming the entry (it is not
  positive semidefinite), while one at rounding level, and zero rows of constants held fixed, are
  accepted.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from maglev_oc.errors import InputError
from maglev_oc.model.parameters import DEFAULT_CONSTANTS, StageParameters
from maglev_oc.model.stagefile import EFFECT_NAMES, Provenance, StageEffect, StageFile
from tests.test_stage_file import _good, _stage


# --- what a wrong JSON type is called --------------------------------------------------------
def _document() -> dict:
    """A valid stage file's JSON (Table I geometry, Table III constants)."""
    provenance = {p: Provenance.now((), "test") for p in ("geometry", "constants", "effects")}
    return StageFile(StageParameters(), DEFAULT_CONSTANTS, None, {}, (), provenance).to_dict()


@pytest.mark.parametrize(
    ("value", "words"),
    [
        ("14.2", "a string"),
        ({"value": 14.2}, "an object"),
        ([14.2], "a list"),
        (True, "true/false"),
        (False, "true/false"),
        (None, "null"),
    ],
    ids=["string", "object", "list", "true", "false", "null"],
)
def test_a_constant_of_the_wrong_json_type_is_named_in_json_words(value, words):
    """A constant must be a JSON number: a quoted number, an object, an array or a boolean there
    is refused with the file, the field path and JSON's name for what was found (the whole
    message, so Python's names, e.g. "str '14.2'" or "bool True", cannot stand in for it)."""
    doc = _document()
    doc["constants"]["C1"] = value
    with pytest.raises(InputError) as err:
        StageFile.from_dict(doc, source="stage.json")
    assert str(err.value) == f"stage.json: constants.C1: expected a number, got {words}"


@pytest.mark.parametrize(
    ("data", "words"), [([1.0], "a list"), ("stage", "a string"), (True, "true/false"), (None, "null")]
)
def test_a_stage_file_that_is_not_an_object_says_what_it_is(data, words):
    """The top level of a stage file is a JSON object; anything else is named in JSON's words."""
    with pytest.raises(InputError) as err:
        StageFile.from_dict(data, source="stage.json")
    assert str(err.value) == f"stage.json: (top level): expected an object, got {words}"


def test_a_list_field_given_an_object_says_it_got_an_object():
    """``effects`` is a JSON array: an object there is called "an object" (not Python's dict)."""
    doc = _document()
    doc["effects"] = {"name": "cogging"}
    with pytest.raises(InputError) as err:
        StageFile.from_dict(doc, source="stage.json")
    assert str(err.value) == "stage.json: effects: expected a list, got an object"


# --- model.stagefile ----------------------------------------------------------------------------
def _listed_effects(message: str) -> list[str]:
    head = "the diagnosis's effects are "
    assert head in message, message
    return message.split(head, 1)[1].split(", ")


def test_an_unknown_effect_is_refused_listing_each_known_effect(tmp_path):
    """The message lists every effect of the library, each on its own (comma separated), both when
    a StageEffect is made and when a stage file is read."""
    with pytest.raises(InputError, match="unknown effect 'gremlins'") as made:
        StageEffect("gremlins", "horizontal", "", "", {}, {}, None)
    assert _listed_effects(str(made.value)) == list(EFFECT_NAMES)
    doc = _good()
    doc["effects"][0]["name"] = "gremlins"
    path = tmp_path / "stage.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"effects\[0\]\.name: unknown effect 'gremlins'") as read:
        StageFile.read(path)
    assert _listed_effects(str(read.value)) == list(EFFECT_NAMES)


def _beside_zero(i: int, j: int, value: float) -> np.ndarray:
    """A diagonal covariance of the constants' scale with variance i zero and cov[i][j] = value."""
    cov = np.diag([1e-4, 4.0, 1.0, 1e-4])
    cov[i, i] = 0.0
    cov[i, j] = cov[j, i] = value
    return cov


# (i, j, value): a covariance beside a zero variance, above the check's rounding room
# (_PSD_TOL = 1e-9 of sqrt(the other variance x the largest), 2e-9 beside C3's variance 1 here);
# |cov_ij| <= sqrt(cov_ii cov_jj) = 0
BESIDE_ZERO = [(0, 1, 0.1), (1, 0, -0.5), (3, 2, 1e-6), (2, 3, 1e-7)]


@pytest.mark.parametrize("i, j, value", BESIDE_ZERO)
def test_a_covariance_beside_a_zero_variance_is_refused_naming_its_entry(i, j, value, tmp_path):
    """[[0, c], [c, v]] has the eigenvalue (v - sqrt(v^2 + 4 c^2)) / 2 < 0 for every c != 0: not
    positive semidefinite beyond rounding once c is above the check's room. The error names the
    entry, as the other covariance errors do, in a StageFile and in a file."""
    cov = _beside_zero(i, j, value)
    entry = rf"\[({i}\]\[{j}|{j}\]\[{i})\]"
    with pytest.raises(InputError, match=rf"^StageFile\.covariance{entry}: .*not positive semidefinite"):
        _stage(covariance=cov)
    doc = _good()
    doc["constants"]["covariance"] = cov.tolist()
    path = tmp_path / "stage.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=rf"constants\.covariance{entry}: .*not positive semidefinite"):
        StageFile.read(path)


@pytest.mark.parametrize("value", [1e-12, 1e-181, 1e-300])
def test_a_rounding_level_covariance_beside_a_zero_variance_is_accepted(value):
    """The other side of the room: beside a zero variance and one of 1, a covariance c gives the
    eigenvalue -c^2 (to first order), 1e-24 or less here, rounding against the matrix's scale 4 (a
    product A A' whose small entries' squares underflow keeps 4.7e-181 beside a zero variance:
    tests/test_stage_file.py's round trip found it)."""
    stage = _stage(covariance=_beside_zero(3, 2, value))
    assert stage.covariance[3, 2] == value


def test_zero_rows_of_constants_held_fixed_are_still_accepted():
    """The other side: a zero variance with zeros beside it (a constant held fixed) is a valid
    covariance, and the others' correlations are kept."""
    cov = _beside_zero(2, 0, 0.0)
    cov[1, 3] = cov[3, 1] = 0.9 * math.sqrt(4.0 * 1e-4)  # correlation 0.9: PSD
    stage = _stage(covariance=cov)
    assert np.array_equal(stage.covariance, cov)
    assert stage.stderr["C3"] == 0.0
