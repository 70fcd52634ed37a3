"""Properties of what a stage file holds (``maglev_oc.model.stagefile``): its constants' standard
errors and covariance, its effects and its model, checked against matrices and files built here:

- the standard errors are the square roots of the covariance's diagonal (in the constants'
  units), read as written from a file (null: unknown), and a negative one is refused by name;
- an identification's covariance lands on the constants it belongs to, and a stage made in code
  with a bad covariance names the entry; the stage keeps its own read-only copy of the covariance;
- the compensation sums only the effects that can be fed forward, and the model is that of the
  file's geometry and constants;
- another version of the format is refused, with the hint to write it again only for an older one.
"""

from __future__ import annotations

import math
import re
from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.errors import InputError
from maglev_oc.expressions import function_to_data
from maglev_oc.model.parameters import DEFAULT_CONSTANTS, LumpedConstants, StageParameters
from maglev_oc.model.stagefile import VERSION, Provenance, StageEffect, StageFile, tool_version
from maglev_oc.results import Estimate


# --- the stage file -------------------------------------------------------------------------------
def _provenance() -> dict[str, Provenance]:
    return {part: Provenance.now((), "test") for part in ("geometry", "constants", "effects")}


def test_stage_file_standard_errors_are_square_roots_of_the_variances(tmp_path):
    """stderr_k = sqrt(cov_kk), in the constants' units (not their squares), also after a write
    and read; a stage file's covariance of diag(s^2) gives back s exactly up to sqrt's round-off."""
    s = np.array([0.1, 2.0, 0.3, 0.004])
    cov = np.diag(s**2)
    cov[1, 2] = cov[2, 1] = 0.5 * s[1] * s[2]  # correlation 0.5 leaves the variances alone
    stage = StageFile(StageParameters(), DEFAULT_CONSTANTS, cov, {}, (), _provenance())
    back = StageFile.read(stage.write(tmp_path / "stage.json"))
    for f in (stage, back):
        assert_allclose([f.stderr[k] for k in ("C1", "C2", "C3", "C4")], s, rtol=1e-15)


def test_identification_covariance_lands_on_its_constants():
    """An identification that fits C2..C4 only (C1 held fixed): its 3 x 3 covariance goes to the
    rows and columns of C2..C4 of the stage file, C1's row and column are zero."""
    cov3 = np.array([[4.0, 0.3, 0.1], [0.3, 0.25, 0.02], [0.1, 0.02, 0.01]])
    best = SimpleNamespace(
        names=("C2", "C3", "C4"),
        covariance=cov3,
        stderr={k: math.sqrt(cov3[i, i]) for i, k in enumerate(("C2", "C3", "C4"))},
        method="output_error",
    )
    outcome = SimpleNamespace(best=best, constants=lambda: DEFAULT_CONSTANTS, sources=("run.csv",))
    geometry = Provenance.now((), "Table I")
    stage = StageFile.from_identification(outcome, _model_stub(), geometry)
    assert_allclose(stage.covariance[1:, 1:], cov3, rtol=0, atol=0)
    assert np.all(stage.covariance[0] == 0) and np.all(stage.covariance[:, 0] == 0)
    assert stage.stderr["C2"] == 2.0 and stage.stderr["C1"] == 0.0


def _model_stub():
    return SimpleNamespace(params=StageParameters())


def _effect(name: str, force: float, compensable: bool) -> StageEffect:
    """A constant horizontal acceleration ``force`` [m/s^2]; current-dependent when not compensable."""
    x, i = ca.SX.sym("x", 4), ca.SX.sym("i", 2)
    acc = ca.vertcat(0, force + (0 if compensable else 0.1 * i[0]))
    comp = function_to_data(ca.Function("g", [x], [ca.vertcat(0, force + 0 * x[0])], ["x"], ["acc"]))
    return StageEffect(
        name,
        "horizontal",
        "test",
        "test",
        {"force": Estimate(force, math.nan, "m/s^2")},
        function_to_data(ca.Function("f", [x, i], [acc], ["x", "i"], ["acc"])),
        comp if compensable else None,
    )


def test_compensation_sums_only_the_compensable_effects():
    """StageFile.compensation: the effects a controller can feed forward (those with a state-only
    part); the plant's effects are all of them."""
    effects = (_effect("cable_carrier_force", 0.3, True), _effect("guide_misalignment", 0.05, False))
    stage = StageFile(StageParameters(), DEFAULT_CONSTANTS, None, {}, effects, _provenance())
    x = np.array([0.02, 0.0, 0.01, 0.0])
    assert_allclose(np.asarray(stage.compensation()(x)).ravel(), [0.0, 0.3], rtol=1e-15)
    assert_allclose(np.asarray(stage.plant_effects()(x, [2.0, 0.0])).ravel(), [0.0, 0.55], rtol=1e-15)
    only_current = StageFile(StageParameters(), DEFAULT_CONSTANTS, None, {}, effects[1:], _provenance())
    assert only_current.compensation() is None


def test_stage_file_model_uses_its_geometry_and_constants():
    """StageFile.model(): a StageModel of the file's own geometry and constants."""
    constants = LumpedConstants(15.0, 800.0, 30.0, 0.08, source="test")
    geometry = StageParameters(gravity=9.80)
    stage = StageFile(geometry, constants, None, {}, (), _provenance())
    model = stage.model()
    assert model.constants == constants and model.params == geometry


NAMES = ("C1", "C2", "C3", "C4")


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
