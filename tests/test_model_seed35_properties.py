"""Properties of the stage model that the seed-35 mutation run found untested (issue 21).

Each test checks what a user of ``maglev_oc/model/`` relies on, not one line:

- a stage file of a newer version is refused saying which version this maglev_oc reads, and
  only an older one is told to be written again (a newer one cannot be, by this version);
- the constructors of a stage file and of the microstepper refuse bad input with an
  :class:`~maglev_oc.errors.InputError` naming the field and what is wrong (a covariance
  that is not symmetric, not positive semidefinite or with a negative variance; the wrong
  number of masses), not with a TypeError from inside;
- a stage file holds its own read-only copy of the covariance it was given (a list or an
  array the caller changes later), and writes and reads it back;
- the constants' ``source`` says which constants the file gave and which came from the
  defaults, for every subset of C1..C4;
- the papers' named constant sets are Tables II and III of paper 000 (Table II's C1 from
  Table III at the same eps), built afresh;
- ``save_json`` writes one value a line (a file a user reads and edits by hand, like every
  JSON maglev_oc writes) that reads back to the same parameters and constants;
- the 2-DOF platform built for other parameters and constants is the StageModel of those
  (the arguments are honoured, the motor attracts towards its stator);
- the microstepper's transformation, called by its documented input names (gap, v), gives
  currents that realise the requested accelerations on the platform model.
"""

from __future__ import annotations

import itertools
import json
import math
import re

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.errors import InputError
from maglev_oc.model.allocation import MicrostepperTransformation
from maglev_oc.model.parameters import (
    DEFAULT_CONSTANTS,
    PAPER_CONSTANTS,
    LumpedConstants,
    StageParameters,
    _paper_sets,
    load_json,
    save_json,
)
from maglev_oc.model.platform import PlatformModel, microstepper, two_dof_platform
from maglev_oc.model.stage import StageModel
from maglev_oc.model.stagefile import VERSION, Provenance, StageFile, tool_version

NAMES = ("C1", "C2", "C3", "C4")


def _provenance() -> dict[str, Provenance]:
    return {p: Provenance.now((), "test") for p in ("geometry", "constants", "effects")}


def _stage(covariance=None) -> StageFile:
    return StageFile(StageParameters(), DEFAULT_CONSTANTS, covariance, {}, (), _provenance())


# --- versions ---------------------------------------------------------------------------------
@pytest.mark.parametrize("version", [VERSION - 1, VERSION + 1, VERSION + 7])
def test_other_versions_are_refused_with_the_hint_only_for_older_files(version):
    """The whole message: the file, the field, the version found and the one read; the advice
    to write the file again only for an older file (a newer one needs a newer maglev_oc)."""
    doc = _stage().to_dict()
    doc["version"] = version
    message = (
        f"stage.json: version: version {version} is not supported: {tool_version()} reads stage "
        f"files of version {VERSION} only"
    )
    if version < VERSION:
        message += " (write it again with this version)"
    with pytest.raises(InputError) as err:
        StageFile.from_dict(doc, source="stage.json")
    assert str(err.value) == message


# --- the constructors name what is wrong ------------------------------------------------------
GOOD = np.diag([1e-4, 4.0, 1.0, 1e-4])


def _num(value: float) -> str:
    """The number as the message writes it: a plain float's repr (never numpy's
    ``np.float64(...)``, which the messages printed before 2026-11-24)."""
    return rf"(?<!\(){re.escape(repr(value))}(?!\))"


def _edited(i: int, j: int, value: float) -> np.ndarray:
    cov = GOOD.copy()
    cov[i, j] = value
    return cov


@pytest.mark.parametrize(
    "covariance, message",
    [
        (
            _edited(1, 0, 0.5),
            rf"StageFile\.covariance\[1\]\[0\]: {_num(0.5)} differs from "
            rf"\[0\]\[1\] = {_num(0.0)}: not symmetric",
        ),
        (_edited(2, 2, -1.0), rf"StageFile\.covariance\[2\]\[2\]: a variance must be >= 0, got {_num(-1.0)}"),
        (
            np.array([[1, 2, 0, 0], [2, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=float),
            r"StageFile\.covariance: not positive semidefinite \(correlation eigenvalue -1 < 0\)",
        ),
        (np.eye(3), r"StageFile\.covariance: expected 4 x 4 \(C1\.\.C4\), got 3 x 3"),
    ],
    ids=["asymmetric", "negative variance", "not psd", "3 x 3"],
)
def test_a_stage_made_in_code_with_a_bad_covariance_names_the_entry(covariance, message):
    with pytest.raises(InputError, match=rf"^{message}$"):
        _stage(covariance)


@pytest.mark.parametrize("masses", [(1.0, 2.0), (1.0, 2.0, 3.0, 4.0)])
def test_the_microstepper_needs_three_masses_and_says_so(masses):
    with pytest.raises(
        InputError, match=rf"^microstepper: three masses \(x, y, gap\) needed, got {len(masses)}$"
    ):
        microstepper(masses=masses)


# --- the stage file's covariance is its own -----------------------------------------------------
def test_a_stage_file_holds_its_own_read_only_covariance(tmp_path):
    """Given as a list or as an array the caller changes afterwards: the stage keeps the values
    it was given (bit for bit), refuses writes, and the file round trip gives them back."""
    rng = np.random.default_rng(35)
    m = rng.normal(size=(4, 4))
    given = m @ m.T  # symmetric PSD
    want = given.copy()
    from_list = _stage(given.tolist())
    from_array = _stage(given)
    given[0, 0] = given[1, 2] = given[2, 1] = 123.0  # the caller reuses its array
    for stage in (from_list, from_array):
        assert isinstance(stage.covariance, np.ndarray) and stage.covariance.dtype == float
        np.testing.assert_array_equal(stage.covariance, want)
        with pytest.raises(ValueError):
            stage.covariance[0, 0] = 0.0
        assert [stage.stderr[k] for k in NAMES] == [math.sqrt(want[i, i]) for i in range(4)]
        path = stage.write(tmp_path / "stage.json")
        np.testing.assert_array_equal(StageFile.read(path).covariance, want)


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


# --- the 2-DOF platform -----------------------------------------------------------------------
def test_the_two_dof_platform_is_the_stage_model_of_its_arguments():
    """Other masses, geometry and constants than the defaults: the platform's dynamics are the
    StageModel's of the same arguments to rounding (rtol 1e-12 of the largest acceleration, as
    tests/test_platform.py for the defaults): gravity, masses and the attraction towards the
    stator with these numbers."""
    params = StageParameters(mass_vertical=3.9, mass_horizontal=1.4, slot_width=12.5e-3)
    constants = LumpedConstants(15.0, 780.0, 32.0, 0.09)
    platform = two_dof_platform(params, constants)
    assert [m.name for m in platform.motors] == ["PMLSM"]
    pm, stage = PlatformModel(platform), StageModel(params, constants)
    rng = np.random.default_rng(35)
    n = 100
    x = np.vstack(
        [
            rng.uniform(0.008, 0.03, n),
            rng.normal(0, 0.05, n),
            rng.uniform(-0.05, 0.05, n),
            rng.normal(0, 0.05, n),
        ]
    )
    u = rng.uniform(-9, 9, (2, n))
    a, b = pm.dynamics(x, u), stage.dynamics(x, u)
    assert np.max(np.abs(a - b)) <= 1e-12 * np.max(np.abs(b))


# --- the microstepper's transformation ------------------------------------------------------------
def test_the_microstepper_transformation_by_its_named_inputs_realises_v():
    """function(gap=..., v=...) -> {u, R}: the currents give the platform the accelerations v
    (x'', y'', gap'') on :class:`PlatformModel` (rtol 1e-9: the minimum-norm allocation
    solves a quadratic for i_d, whose root carries round-off of the size of k3^2 / k4)."""
    platform = microstepper()
    fl, pm = MicrostepperTransformation(platform), PlatformModel(platform)
    rng = np.random.default_rng(35)
    for _ in range(10):
        gap = rng.uniform(0.02, 0.03)
        v = rng.uniform(-2.0, 2.0, 3)
        out = fl.function(gap=gap, v=v)
        assert set(out) == {"u", "R"} and float(out["R"]) > 0
        u = np.asarray(out["u"]).ravel()
        assert_allclose(u, fl.allocate(gap, v).currents, rtol=0, atol=0)
        x = np.array([rng.uniform(-0.05, 0.05), 0.0, rng.uniform(-0.05, 0.05), 0.0, gap, 0.0])
        acc = pm.dynamics(x, u)[1::2].ravel()
        assert_allclose(acc, v, rtol=1e-9, atol=1e-9 * platform.gravity[2])
