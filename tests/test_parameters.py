"""Table I parameters, the lumped constants and their JSON form."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.errors import InputError
from maglev_oc.model.parameters import (
    DEFAULT_CONSTANTS,
    MU0,
    PAPER_CONSTANTS,
    LumpedConstants,
    StageParameters,
    load_json,
    paper_constants,
    save_json,
)


def test_defaults_are_table_one_in_si():
    p = StageParameters()
    assert p.slot_width == pytest.approx(12.7e-3)
    assert p.slot_pitch == pytest.approx(19.05e-3)
    assert p.pole_pitch == pytest.approx(57.15e-3)
    assert p.mass_vertical == pytest.approx(4.350)
    assert p.turns_per_phase == 900
    for name, unit, doc in StageParameters.describe():
        assert unit and doc, name


def test_winding_factor_is_one_for_this_winding():
    # SPEC 1: "The winding factor from 002's formula is k_w1 = 1 for this winding."
    assert StageParameters().winding_factor == pytest.approx(1.0, abs=1e-12)


def test_physical_constants_follow_002_formulas():
    # Hand evaluation of 002's formulas (SPEC 1 readings 3 and 4) with Table I values.
    p = StageParameters()
    c = p.physical_constants()
    assert_allclose(c.C2, 0.05 * 4 * 0.05715 / (4 * 4.350 * MU0), rtol=1e-12)
    assert_allclose(c.C3, 3 * math.sqrt(2) * 0.05 * 4 * 900 / (4.350 * 9), rtol=1e-12)
    assert_allclose(c.C4, 18 * 0.05 * 4 * 900**2 * MU0 / (4.350 * 0.05715 * 9), rtol=1e-12)
    a = math.pi / 0.05715
    c1 = (
        12
        * math.sqrt(2)
        * 900
        * 4
        * 0.05
        * 875400
        * MU0
        * math.sinh(a * 5e-3)
        * math.sin(math.pi * 28.58 / (2 * 57.15))
        / (1.594 * math.pi * 3)
    )
    assert_allclose(c.C1, c1, rtol=1e-12)


def test_paper_tables_by_name():
    assert DEFAULT_CONSTANTS.as_array() == [14.20, 796.99, 31.04, 0.07]  # SPEC 1 default
    assert paper_constants("table3_eps0.05").C1 == 16.23
    assert paper_constants("table2_eps0.001").C4 == 0.11
    assert paper_constants("cogging_x3_3t1_2").C2 == 769.99
    assert len([k for k in PAPER_CONSTANTS if k.startswith("table")]) == 6
    with pytest.raises(ValueError, match="unknown constant set"):
        paper_constants("table4")


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("mass_vertical", 0.0, "mass_vertical"),
        ("mass_horizontal", -1.0, "mass_horizontal"),
        ("slot_width", 12.7, "slot_width.*millimetres"),
        ("magnet_height", 5.0, "magnet_height.*millimetres"),
        ("pole_pitch", float("nan"), "pole_pitch"),
        ("turns_per_phase", 900.5, "turns_per_phase.*whole"),
        ("gravity", "9.81", "gravity.*number"),
    ],
)
def test_invalid_parameters_name_the_field(field, value, message):
    with pytest.raises(ValueError, match=message):
        StageParameters(**{field: value})


def test_invalid_constants():
    with pytest.raises(ValueError, match="C4"):
        LumpedConstants(14.2, 797.0, 31.0, -0.07)


def test_json_round_trip(tmp_path):
    p = StageParameters(mass_vertical=4.5)
    c = LumpedConstants(14.0, 800.0, 30.0, 0.08, source="test")
    path = save_json(tmp_path / "stage.json", p, c)
    p2, c2 = load_json(path)
    assert p2 == p
    assert c2 == c


def test_json_unknown_key_is_named(tmp_path):
    path = tmp_path / "stage.json"
    path.write_text(json.dumps({"stage": {"mass_vertcal": 4.3}}))
    with pytest.raises(ValueError, match="mass_vertcal"):
        load_json(path)
    path.write_text(json.dumps({"stage": {}, "extras": 1}))
    with pytest.raises(ValueError, match="extras"):
        load_json(path)


def test_json_in_millimetres_is_refused(tmp_path):
    path = tmp_path / "stage.json"
    path.write_text(json.dumps({"stage": {"slot_pitch": 19.05}}))
    with pytest.raises(ValueError, match=r"slot_pitch.*millimetres"):
        load_json(path)


def test_json_syntax_error_gives_line(tmp_path):
    path = tmp_path / "stage.json"
    path.write_text('{"stage": {\n  "mass_vertical": 4.3,\n}}')
    with pytest.raises(ValueError, match="line 3"):
        load_json(path)


def test_physical_constants_scale_with_winding_factor_and_masses():
    # 002 eqs. (5)-(8): C1 and C3 carry k_w once, C4 twice, C2 not at all; C1 divides by M_h,
    # C2..C4 by M_v. Table I's full-pitch winding has k_w = 1, which hides a wrong power of k_w,
    # so a short-pitched coil (two slots instead of three) makes it show.
    base = StageParameters()
    short = dataclasses.replace(base, coil_pitch=2 * base.slot_pitch)
    kw = short.winding_factor
    assert abs(kw - 1) > 0.05
    c0, c1 = base.physical_constants(), short.physical_constants()
    assert_allclose(c1.C1 / c0.C1, kw, rtol=1e-12)
    assert_allclose(c1.C2 / c0.C2, 1.0, rtol=1e-12)
    assert_allclose(c1.C3 / c0.C3, kw, rtol=1e-12)
    assert_allclose(c1.C4 / c0.C4, kw**2, rtol=1e-12)
    heavy = dataclasses.replace(
        base, mass_horizontal=2 * base.mass_horizontal, mass_vertical=3 * base.mass_vertical
    )
    c2 = heavy.physical_constants()
    assert_allclose(
        np.array(c2.as_array()) / np.array(c0.as_array()), [1 / 2, 1 / 3, 1 / 3, 1 / 3], rtol=1e-12
    )


def test_an_unknown_stage_field_is_named_with_where_it_came_from():
    # errors name the file (``where``) and the field, for the stage as for the constants
    with pytest.raises(InputError, match=r"rig\.json.*\bmagnet_heigth\b|\bmagnet_heigth\b.*rig\.json"):
        StageParameters.from_dict({"magnet_heigth": 5e-3}, where="rig.json")
