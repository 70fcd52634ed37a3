"""Properties of the stage model that the seed-36 mutation run found untested.

Each test checks what a user of ``maglev_oc/model/`` relies on, not one line:

- a stage file's standard errors (``constants.stderr``, given when there is no covariance) are
  read as written when they are >= 0, a ``null`` entry as unknown (NaN), and a negative one is
  refused with an :class:`~maglev_oc.errors.InputError` naming the file, the field and the
  value (a standard error is a square root: it cannot be negative);
- the geometry's fields are made by one helper (``_field``) that attaches the unit and the
  description :meth:`StageParameters.describe` lists and passes on the field's default, so
  ``StageParameters()`` is Table I. The helper runs at import, before mutmut switches a mutant
  on; the test makes fields with it afresh (as tests/test_model_seed35_properties.py builds the
  papers' tables afresh), so a mutant of it is seen.
"""

from __future__ import annotations

import dataclasses
import math

import pytest

from maglev_oc.errors import InputError
from maglev_oc.model.parameters import DEFAULT_CONSTANTS, StageParameters, _field
from maglev_oc.model.stagefile import Provenance, StageFile

NAMES = ("C1", "C2", "C3", "C4")


def _document(stderr: dict) -> dict:
    """A valid stage file's JSON with these standard errors and no covariance."""
    provenance = {p: Provenance.now((), "test") for p in ("geometry", "constants", "effects")}
    doc = StageFile(StageParameters(), DEFAULT_CONSTANTS, None, {}, (), provenance).to_dict()
    doc["constants"]["stderr"] = stderr
    return doc


def test_stage_file_standard_errors_are_read_null_as_unknown(tmp_path):
    """Zero and positive standard errors are kept as written (bit for bit: they are copied, not
    computed); a null entry and a constant left out are unknown, NaN. The same after a write and
    a read (the file's own round trip)."""
    given = {"C1": 0.25, "C2": 0.0, "C3": None}
    stage = StageFile.from_dict(_document(given), source="stage.json")
    assert stage.stderr["C1"] == 0.25 and stage.stderr["C2"] == 0.0
    assert math.isnan(stage.stderr["C3"]) and math.isnan(stage.stderr["C4"])
    again = StageFile.read(stage.write(tmp_path / "stage.json"))
    assert [again.stderr[k] for k in ("C1", "C2")] == [0.25, 0.0]
    assert math.isnan(again.stderr["C3"]) and math.isnan(again.stderr["C4"])


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("value", [-1e-9, -2.0])
def test_a_negative_standard_error_in_a_stage_file_is_refused_by_name(name, value):
    """The whole message: the file, the field path (constants.stderr.<name>) and the number as
    written; the smallest negative value too (no tolerance: a standard error is >= 0 exactly)."""
    stderr = {k: 0.1 for k in NAMES}
    stderr[name] = value
    with pytest.raises(InputError) as err:
        StageFile.from_dict(_document(stderr), source="stage.json")
    assert str(err.value) == (
        f"stage.json: constants.stderr.{name}: a standard error must be >= 0, got {value!r}"
    )


# --- the geometry's fields --------------------------------------------------------------------
def test_a_geometry_field_carries_its_unit_doc_and_default():
    """A frozen dataclass built afresh the way StageParameters is: made without arguments it
    holds the defaults given (a plain default and a default factory), and every field's metadata
    is exactly its unit and description. StageParameters itself: every field has a default
    (``StageParameters()`` is Table I) and describe() gives each field's unit and description."""
    probe = dataclasses.make_dataclass(
        "Probe",
        [
            ("width", float, _field("m", "a width", default=12.7e-3)),
            ("turns", int, _field("-", "a count", default=900)),
            ("masses", list, _field("kg", "masses", default_factory=lambda: [1.0, 2.0])),
        ],
        frozen=True,
    )
    made = probe()
    assert (made.width, made.turns, made.masses) == (12.7e-3, 900, [1.0, 2.0])
    assert [dict(f.metadata) for f in dataclasses.fields(probe)] == [
        {"unit": "m", "doc": "a width"},
        {"unit": "-", "doc": "a count"},
        {"unit": "kg", "doc": "masses"},
    ]
    for f in dataclasses.fields(StageParameters):
        assert f.default is not dataclasses.MISSING, f.name
        assert set(f.metadata) == {"unit", "doc"} and f.metadata["unit"] and f.metadata["doc"], f.name
    assert StageParameters.describe()[0] == ("slot_width", "m", "stator slot width b0 (Table I, 000)")
    assert StageParameters().slot_width == 12.7e-3
