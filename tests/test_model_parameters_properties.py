"""Properties of the stage's parameters and constants (``maglev_oc.model.parameters`` and
``StageModel.with_constants``), checked against the papers' tables and files written here:

- the constructors refuse what cannot be a stage (a magnet wider than its pole pitch, a lumped
  constant that is not positive); a geometry field carries its unit, description and default;
- the papers' sets are Tables II and III; ``save_json`` writes one value a line and reads back,
  and the constants' source says which came from the file;
- ``with_constants`` changes the constants only: the field model and the shape functions are
  those of the model it came from.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import re

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.model.parameters import (
    DEFAULT_CONSTANTS,
    PAPER_CONSTANTS,
    LumpedConstants,
    StageParameters,
    _field,
    _paper_sets,
    load_json,
    save_json,
)
from maglev_oc.model.stage import StageModel


# --- constructors refuse what cannot be a stage ---------------------------------------------------
def test_a_magnet_wider_than_its_pole_pitch_is_refused():
    """tau_p <= tau: wider magnets would overlap their neighbours (Table I: 28.58 of 57.15 mm)."""
    p = StageParameters()
    with pytest.raises(ValueError, match="magnet_width"):
        StageParameters(magnet_width=1.01 * p.pole_pitch)
    with pytest.raises(ValueError, match="slot_width"):
        StageParameters(slot_width=p.slot_pitch)
    assert StageParameters(magnet_width=p.pole_pitch).magnet_width == p.pole_pitch


@pytest.mark.parametrize("name", ["C1", "C2", "C3", "C4"])
@pytest.mark.parametrize("value", [0.0, -1.0, math.inf, math.nan])
def test_each_lumped_constant_must_be_positive(name, value):
    """C_i > 0 (SPEC 1, C3 > 0 with the sign in L3): C_i = 0 would make L_i = 0 and the feedback
    transformation divide by zero (u1 = -v1 / L1; u2 = ... / (2 L4))."""
    with pytest.raises(ValueError, match=name):
        DEFAULT_CONSTANTS.replace(**{name: value})


GAPS = np.linspace(5e-3, 35e-3, 13)  # the papers' field-fit range [m]


# --- the stage model ---------------------------------------------------------------------------
def test_with_constants_keeps_the_field_model_and_the_shape_functions(model):
    """A model made by ``with_constants`` has the field model of the one it came from and the
    same shape functions bit for bit (they do not depend on C); its L are the new C times them
    (rtol 1e-14: one product of doubles)."""
    other = next(c for c in PAPER_CONSTANTS.values() if c != model.constants)
    poly = StageModel(model.params, model.constants, "polynomial")
    for base in (model, poly):
        new = base.with_constants(other)
        assert new.field_model == base.field_model and new.constants == other
        assert_allclose(
            np.asarray(new.shape.map(GAPS.size)(GAPS[None, :])),
            np.asarray(base.shape.map(GAPS.size)(GAPS[None, :])),
            rtol=0,
            atol=0,
        )
        shapes = np.asarray(base.shape.map(GAPS.size)(GAPS[None, :]))
        assert_allclose(new.coefficients(GAPS), np.asarray(other.as_array())[:, None] * shapes, rtol=1e-14)
    # the two field models differ inside the fit by more than rounding (3.8e-6 relative, measured
    # in tests/test_model_field_properties.py), so a dropped field model is seen
    b_poly = np.asarray(poly.with_constants(other).pm_field.map(GAPS.size)(GAPS[None, :])).ravel()
    b_closed = np.asarray(model.pm_field.map(GAPS.size)(GAPS[None, :])).ravel()
    assert np.max(np.abs(b_poly / b_closed - 1)) > 1e-8


NAMES = ("C1", "C2", "C3", "C4")


# --- the constants' source says where each came from ---------------------------------------------
@pytest.mark.parametrize(
    "given",
    [g for n in range(4) for g in itertools.combinations(NAMES, n)],
    ids=lambda g: "+".join(g) or "none",
)
def test_constants_source_says_which_came_from_the_file(tmp_path, given):
    values = {"C1": 15.0, "C2": 800.0, "C3": 32.0, "C4": 0.09}
    path = tmp_path / "stage.json"
    path.write_text(json.dumps({"constants": {k: values[k] for k in given}}))
    _, c = load_json(path)
    missing = [k for k in NAMES if k not in given]
    said = f"{path}: constants ({', '.join(given) or 'none'}); {', '.join(missing)}"
    assert c.source == f"{said} from {DEFAULT_CONSTANTS.source}"
    assert c.as_array() == [values[k] if k in given else getattr(DEFAULT_CONSTANTS, k) for k in NAMES]


# --- the papers' sets ----------------------------------------------------------------------------
# Tables II and III of paper 000 as printed: eps -> (C2, C3, C4) and eps -> (C1, C2, C3, C4)
TABLE_II = {0.001: (790.97, 30.47, 0.11), 0.01: (791.00, 30.90, 0.12), 0.05: (788.98, 32.44, 0.18)}


TABLE_III = {
    0.001: (13.97, 796.93, 30.33, 0.06),
    0.01: (14.20, 796.99, 31.04, 0.07),
    0.05: (16.23, 795.01, 33.44, 0.15),
}


def test_the_papers_sets_are_tables_two_and_three():
    sets = _paper_sets()  # built afresh, as at import
    assert sets == PAPER_CONSTANTS
    for eps, c in TABLE_III.items():
        assert sets[f"table3_eps{eps:g}"].as_array() == list(c)
    for eps, (c2, c3, c4) in TABLE_II.items():
        s = sets[f"table2_eps{eps:g}"]
        assert s.as_array() == [TABLE_III[eps][0], c2, c3, c4]
        assert "C1 from Table III" in s.source
    assert sets["cogging_x3_3t1_2"].as_array() == [14.20, 769.99, 31.04, 0.07]
    assert DEFAULT_CONSTANTS == sets["table3_eps0.01"]


# --- the older stage/constants JSON --------------------------------------------------------------
def test_save_json_writes_one_value_a_line_and_reads_back(tmp_path):
    params = StageParameters(mass_vertical=3.9, slot_width=12.5e-3)
    constants = LumpedConstants(14.0, 790.0, 30.5, 0.08, source="a fit")
    path = save_json(tmp_path / "stage.json", params, constants)
    text = path.read_text()
    lines = text.splitlines()
    keys = [re.findall(r'"(\w+)":', line) for line in lines]
    assert all(len(k) <= 1 for k in keys)  # never two keys on one line
    found = [k[0] for k in keys if k]
    assert sorted(found) == sorted(["stage", "constants", *params.to_dict(), *constants.to_dict()])
    assert load_json(path) == (params, constants)


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
