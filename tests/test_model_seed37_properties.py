"""Properties of the stage model that the seed-37 mutation run found untested.

Each test checks what a user of ``maglev_oc/model/`` relies on, not one line:

- a platform's state equation (:meth:`PlatformModel.dynamics`) takes any array-like of real
  numbers for the states and inputs: an integer, boolean or single-precision array, and an
  object array of Python numbers (what ``np.array`` makes of a row mixing floats and
  :class:`fractions.Fraction` values, or a table's mixed columns), give the same x' as the
  float64 array of the same values;
- a stage file with a JSON value of the wrong type is refused with a message that says, in
  JSON's words, what was found there ("an object", "a list", "a string", "true/false",
  "null"), so the user can find the mistake in the file without knowing Python's type names.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from maglev_oc.errors import InputError
from maglev_oc.model.parameters import DEFAULT_CONSTANTS, StageParameters
from maglev_oc.model.platform import PlatformModel, microstepper
from maglev_oc.model.stagefile import Provenance, StageFile


# --- the platform's state equation -------------------------------------------------------------
@pytest.fixture(scope="module")
def stepper() -> PlatformModel:
    """The microstepper: states (x, x', y, y', gap, gap'), inputs (i_qA, i_dA, i_qB, i_dB)."""
    return PlatformModel(microstepper())


def test_the_state_equation_reads_any_real_array_as_its_values(stepper):
    """States and inputs given as integers, booleans, float32 and object arrays hold the same
    numbers as the float64 arrays they are compared with (every value chosen exactly
    representable in each type: 0, 1, 2, 1/4, 1/2, -3/4, 0.03125 m of gap), so x' must be the
    same bit for bit: the CasADi function sees the same doubles. The gap row is 1 or 2 m for
    the integer states, a large gap at which the field is still defined (any gap > 0)."""
    u = np.array([[1.0, 0.5], [0.25, -0.75], [2.0, 0.0], [-1.0, 1.0]])  # two columns
    ints = np.array([0, 1, 0, -1, 2, 0])
    want = stepper.dynamics(ints.astype(float), u)
    assert want.shape == (6, 2) and np.all(np.isfinite(want))
    for given in (ints, ints.astype(np.int8), ints.tolist()):
        np.testing.assert_array_equal(stepper.dynamics(given, u), want)
    flags = np.array([False, True, False, True, True, False])
    np.testing.assert_array_equal(stepper.dynamics(flags, u), stepper.dynamics(flags.astype(float), u))
    exact = np.array([0.25, -0.5, 0.0, 0.75, 0.03125, 0.0])
    np.testing.assert_array_equal(
        stepper.dynamics(exact.astype(np.float32), u.astype(np.float32)), stepper.dynamics(exact, u)
    )


def test_the_state_equation_reads_an_object_array_of_numbers(stepper):
    """An object array (a row of Fractions and floats, as exact arithmetic or a table with
    mixed columns gives it) is read as the numbers it holds, not refused: the same x' as the
    float64 state, bit for bit (each Fraction is a dyadic rational, exactly a double)."""
    u = np.array([1.0, 0.5, 2.0, -1.0])
    exact = [Fraction(1, 4), Fraction(-1, 2), 0.0, Fraction(3, 4), Fraction(1, 32), 0.0]
    state = np.array(exact, dtype=object)
    assert state.dtype == object
    want = stepper.dynamics(np.array([0.25, -0.5, 0.0, 0.75, 0.03125, 0.0]), u)
    np.testing.assert_array_equal(stepper.dynamics(state, u), want)
    np.testing.assert_array_equal(
        stepper.dynamics(np.array([0.25, -0.5, 0, 0.75, 0.03125, 0], object), u), want
    )


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
