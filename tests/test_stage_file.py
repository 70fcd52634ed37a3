"""The stage file (issue 15, part 1): written and read back bit-identically, every malformed or
old file refused naming the file and the field, and what ``identify``/``diagnose --json`` write
accepted by ``--params`` as it is, the inputs untouched."""

from __future__ import annotations

import hashlib
import json
import math
import re
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from maglev_oc.cli import main
from maglev_oc.data.logs import write_log
from maglev_oc.errors import InputError
from maglev_oc.expressions import function_from_data, function_to_data
from maglev_oc.identification.experiments import TWIN_TRUTH, excitation_log
from maglev_oc.model.loading import load_model
from maglev_oc.model.parameters import DEFAULT_CONSTANTS, LumpedConstants, StageParameters
from maglev_oc.model.stagefile import FORMAT, VERSION, Provenance, StageEffect, StageFile, stage_effects
from maglev_oc.results import Estimate
from maglev_oc.sim.effects import TwinEffects


def _effect(force: float, stiffness: float, name: str = "cable_carrier_force") -> StageEffect:
    """A horizontal spring-like force (the cable carrier) with the given numbers inside its formula."""
    x, i = ca.SX.sym("x", 4), ca.SX.sym("i", 2)
    acc = ca.vertcat(0, force + stiffness * x[2] + 1e-3 * ca.sin(x[0]) * i[1])
    state = ca.vertcat(0, force + stiffness * x[2])
    return StageEffect(
        name,
        "horizontal",
        "A spring-like force along the track.",
        f"stiffness {stiffness!r}",
        {"force": Estimate(force, abs(stiffness), "N"), "stiffness": Estimate(stiffness, math.nan, "N/m")},
        function_to_data(ca.Function("f", [x, i], [acc], ["x", "i"], ["acc"])),
        function_to_data(ca.Function("g", [x], [state], ["x"], ["acc"])),
    )


def _provenance() -> dict[str, Provenance]:
    return {
        "geometry": Provenance.now((), "Table I of paper 000"),
        "constants": Provenance.now(("run.csv",), "output_error"),
        "effects": Provenance.now(("run.csv",), "diagnose"),
    }


def _stage(constants=DEFAULT_CONSTANTS, covariance=None, effects=()) -> StageFile:
    return StageFile(StageParameters(), constants, covariance, {}, tuple(effects), _provenance())


def _floats(value) -> list[str]:
    """Every number in a JSON value, as the exact bits (float.hex)."""
    if isinstance(value, dict):
        return [h for k in sorted(value) for h in _floats(value[k])]
    if isinstance(value, list):
        return [h for v in value for h in _floats(v)]
    if isinstance(value, float):
        return [value.hex()]
    return []


# --- round trip ------------------------------------------------------------------------------
positive = st.floats(min_value=1e-6, max_value=1e6, allow_nan=False, allow_infinity=False)
anything = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    c=st.tuples(positive, positive, positive, positive),
    a=st.lists(st.floats(min_value=-1e3, max_value=1e3), min_size=16, max_size=16),
    force=anything.filter(lambda v: abs(v) < 1e300),
    stiffness=anything.filter(lambda v: abs(v) < 1e300),
)
def test_round_trip_is_bit_identical(tmp_path, c, a, force, stiffness):
    root = np.reshape(a, (4, 4))
    covariance = root @ root.T  # symmetric positive semidefinite, random scale
    stage = _stage(LumpedConstants(*c, source="hypothesis"), covariance, [_effect(force, stiffness)])
    path = stage.write(tmp_path / "stage.json")
    back = StageFile.read(path)
    assert back.to_dict() == stage.to_dict()
    assert _floats(back.to_dict()) == _floats(stage.to_dict())  # same bits, -0.0 included
    assert [getattr(back.constants, k) for k in ("C1", "C2", "C3", "C4")] == list(c)
    assert np.array_equal(back.covariance, covariance)
    assert back.effects[0].parameters["force"].value == force
    # the effect's formula evaluates to the same bits as the one that was written
    rng = np.random.default_rng(0)
    for _ in range(3):
        x, i = rng.normal(size=4), rng.normal(size=2)
        assert np.array_equal(
            np.asarray(back.effects[0].acceleration_function(x, i)),
            np.asarray(stage.effects[0].acceleration_function(x, i)),
        )
    assert back.write(tmp_path / "again.json").read_bytes() == path.read_bytes()


def test_expression_codec_gives_the_same_function():
    x, u = ca.SX.sym("x", 4), ca.SX.sym("u", 2)
    expr = ca.vertcat(
        ca.tanh(x[3] / 0.01) * ca.exp(-x[0] / 0.02) + ca.fmax(u[0], 0.5) ** 2,
        ca.if_else(x[1] > 0, ca.atan2(x[2], x[0]), ca.sqrt(x[0] ** 2 + 1)),
    )
    f = ca.Function("f", [x, u], [expr], ["x", "u"], ["acc"])
    data = json.loads(json.dumps(function_to_data(f)))
    g = function_from_data(data, "g", "test")
    for seed in range(5):
        xs, us = np.random.default_rng(seed).normal(size=4), np.random.default_rng(seed + 9).normal(size=2)
        assert np.array_equal(np.asarray(f(xs, us)), np.asarray(g(xs, us)))
    assert function_to_data(g) == data


# --- malformed files ------------------------------------------------------------------------
def _good() -> dict:
    return _stage(covariance=np.diag([1e-4, 4.0, 1.0, 1e-4]), effects=[_effect(0.1, -0.2)]).to_dict()


def _set(path: str, value):
    """An edit setting the field at ``path`` (dots and [k]) to ``value`` (``...``: delete it)."""

    def edit(doc: dict) -> None:
        keys = [int(k) if k.isdigit() else k for k in path.replace("[", ".").replace("]", "").split(".")]
        obj = doc
        for k in keys[:-1]:
            obj = obj[k]
        if value is ...:
            del obj[keys[-1]]
        else:
            obj[keys[-1]] = value

    return edit


MALFORMED = [
    ("missing field", _set("constants.C2", ...), r"constants\.C2: missing"),
    ("missing section", _set("provenance", ...), r"provenance: missing"),
    ("wrong type", _set("geometry.slot_width", "12.7"), r"geometry\.slot_width: expected a number"),
    (
        "millimetres",
        _set("geometry.slot_width", 12.7),
        r"geometry: slot_width = 12\.7 m looks like millimetres",
    ),
    ("nan constant", _set("constants.C1", math.nan), r"constants\.C1: expected a finite number, got nan"),
    ("nan covariance", _set("constants.covariance[1][3]", math.nan), r"constants\.covariance\[1\]\[3\]: "),
    ("negative constant", _set("constants.C4", -0.07), r"constants\.C4: must be positive"),
    ("unknown field", _set("geometry.slot_depth", 0.01), r"geometry\.slot_depth: unknown field"),
    (
        "asymmetric",
        _set("constants.covariance[2][1]", 0.5),
        r"constants\.covariance\[2\]\[1\]: .*not symmetric",
    ),
    (
        "negative variance",
        _set("constants.covariance[3][3]", -1e-4),
        r"constants\.covariance\[3\]\[3\]: .*>= 0",
    ),
    (
        "not psd",
        _set("constants.covariance", [[1, 2, 0, 0], [2, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]),
        r"constants\.covariance: not positive semidefinite",
    ),
    (
        "wrong size",
        _set("constants.covariance", [[1, 0, 0], [0, 1, 0], [0, 0, 1]]),
        r"constants\.covariance: expected 4 rows",
    ),
    (
        "short row",
        _set("constants.covariance[2]", [0, 0, 1]),
        r"constants\.covariance\[2\]: expected 4 columns",
    ),
    ("unknown effect", _set("effects[0].name", "gremlins"), r"effects\[0\]\.name: unknown effect 'gremlins'"),
    ("bad axis", _set("effects[0].axis", "sideways"), r"effects\[0\]\.axis: expected vertical"),
    (
        "negative stderr",
        _set("effects[0].parameters.force.stderr", -1.0),
        r"effects\[0\]\.parameters\.force\.stderr: .*>= 0",
    ),
    (
        "effect calls code",
        _set("effects[0].acceleration.algorithm[0]", ["call", 0, "os.system"]),
        r"effects\[0\]\.acceleration\.algorithm\[0\]\[0\]: unknown operation 'call'",
    ),
    (
        "effect reads an unset cell",
        _set("effects[0].compensation.algorithm[0]", ["sin", 0, 5]),
        r"effects\[0\]\.compensation\.algorithm\[0\]\[2\]: .*out of range|read before it is set",
    ),
    (
        "bad date",
        _set("provenance.constants.date", "yesterday"),
        r"provenance\.constants\.date: not an ISO 8601",
    ),
    ("not a stage file", _set("format", "something.else"), r"format: expected 'maglev_oc\.stage'"),
    ("version as text", _set("version", "1"), r"version: expected an integer"),
]


@pytest.mark.parametrize("label, edit, message", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_malformed_file_names_the_file_and_the_field(tmp_path, label, edit, message):
    doc = _good()
    edit(doc)
    path = tmp_path / "stage.json"
    path.write_text(json.dumps(doc, indent=2))  # NaN written as NaN, as a careless tool would
    before = path.read_bytes()
    with pytest.raises(InputError, match=rf"^{re.escape(str(path))}: (?:{message})"):
        StageFile.read(path)
    with pytest.raises(InputError, match=re.escape(str(path))):
        load_model(path)
    assert path.read_bytes() == before


def test_bad_json_names_line_and_column(tmp_path):
    path = tmp_path / "stage.json"
    text = json.dumps(_good(), indent=2)
    path.write_text(text.replace('"version": 1,', '"version": 1,,', 1))
    with pytest.raises(InputError, match=rf"^{re.escape(str(path))}: line 3, column 16: not valid JSON"):
        StageFile.read(path)
    with pytest.raises(InputError, match=r"line 3, column 16"):
        load_model(path)


@pytest.mark.parametrize("old", [0, 2])
def test_other_versions_are_refused_saying_which_is_read(tmp_path, old):
    doc = _good()
    doc["version"] = old
    path = tmp_path / "stage.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(
        InputError, match=rf"stage\.json: version: version {old} is not supported.*version {VERSION}"
    ):
        StageFile.read(path)
    code = main(["model", "--params", str(path)])
    assert code == 2


def test_embedded_stage_file_errors_name_the_stage_key(tmp_path):
    doc = {"status": "converged", "stage": _good()}
    doc["stage"]["constants"]["covariance"][0][1] = 7.0
    path = tmp_path / "out.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(
        InputError, match=r"out\.json: stage\.constants\.covariance\[1\]\[0\]: .*not symmetric"
    ):
        load_model(path)


def test_the_older_stage_constants_json_is_still_read(tmp_path):
    path = tmp_path / "old.json"
    path.write_text(json.dumps({"constants": {"C2": 780.0}}))
    assert load_model(path).constants.C2 == 780.0
    assert stage_effects(path) == ()


# --- the commands' outputs as --params -------------------------------------------------------
def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def rig_log(tmp_path_factory, model) -> Path:
    """12 s of the papers' excitation on the rig twin (friction, cogging, ...): diagnose needs 10 s."""
    log = excitation_log(
        model.with_constants(TWIN_TRUTH),
        duration=12.0,
        seed=2,
        controller_model=model,
        effects=TwinEffects.rig(),
    )
    return write_log(tmp_path_factory.mktemp("stage") / "run.csv", log)


def _params_accepted(out: Path, tmp_path: Path, capsys) -> str:
    before = _sha(out)
    assert main(["model", "--params", str(out), "--gaps", "20"]) == 0
    sim = tmp_path / "sim.csv"
    assert (
        main(
            [
                "simulate",
                "--params",
                str(out),
                "--scenario",
                "small_step",
                "--duration",
                "0.5",
                "--out",
                str(sim),
            ]
        )
        == 0
    )
    assert sim.is_file()
    assert _sha(out) == before  # --params never modifies its file
    return capsys.readouterr().out


def test_identify_json_is_a_stage_file_for_params(rig_log, tmp_path, capsys):
    log_hash = _sha(rig_log)
    out = tmp_path / "id.json"
    assert main(["identify", str(rig_log), "--json", str(out), "--methods", "equation_error"]) == 0
    assert _sha(rig_log) == log_hash
    doc = json.loads(out.read_text())
    assert doc["stage"]["format"] == FORMAT and doc["stage"]["version"] == VERSION
    assert {"equation_error", "identified_constants", "status"} <= set(doc)  # what identify wrote before
    stage = StageFile.read(out)
    assert stage.covariance is not None and stage.effects == ()
    assert stage.provenance["constants"].sources == (str(rig_log),)
    assert stage.provenance["constants"].method == "equation_error"
    model = load_model(out)
    for k in ("C1", "C2", "C3", "C4"):  # bit-identical to what identify reported
        assert getattr(model.constants, k) == doc["identified_constants"][k]
    np.testing.assert_array_equal(
        np.sqrt(np.diag(stage.covariance)),
        [doc["equation_error"]["parameters"][k]["stderr"] for k in ("C1", "C2", "C3", "C4")],
    )
    printed = _params_accepted(out, tmp_path, capsys)
    assert f"C1={doc['identified_constants']['C1']:g}" in printed


def test_diagnose_json_is_a_stage_file_with_effects_for_params(rig_log, tmp_path, capsys, monkeypatch):
    out = tmp_path / "diag.json"
    assert main(["diagnose", str(rig_log), "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    stage = StageFile.read(out)
    # the SPEC 3 contract is unchanged beside the stage file, and the two agree
    assert [e["name"] for e in doc["effects"]] == [e.name for e in stage.effects]
    assert {"error_before", "error_after", "error_metric", "not_separable", "unexplained"} <= set(doc)
    assert stage.effects, "the rig twin's friction and cogging are found on 12 s"
    for e, spec in zip(stage.effects, doc["effects"], strict=True):
        assert {k: p.value for k, p in e.parameters.items()} == spec["parameters"]
    assert stage.provenance["effects"].sources == (str(rig_log),)
    # the constants' covariance is the final joint fit's (effects estimated beside them): its
    # diagonal gives the standard errors the diagnosis printed, and a robust region can use it
    assert stage.covariance is not None
    np.testing.assert_allclose(
        np.sqrt(np.diag(stage.covariance)),
        [doc["constants_final"][k]["stderr"] for k in ("C1", "C2", "C3", "C4")],
        rtol=1e-12,
    )
    assert np.all(np.linalg.eigvalsh(stage.covariance) > 0)
    assert stage_effects(out) == stage.effects
    assert stage.compensation() is not None and stage.plant_effects() is not None
    printed = _params_accepted(out, tmp_path, capsys)
    assert "FL regulator compensating" in printed
    # the NMPC predicts with every found effect (in the VM: no JIT build in a test)
    from maglev_oc import cli
    from maglev_oc.control import registry

    monkeypatch.setattr(registry, "c_compiler", lambda: None)
    nmpc = cli._controller_with_effects("nmpc", load_model(out), out)
    assert nmpc.settings.effects is not None and "effects in the model" in nmpc.name
    x, i = np.array([18e-3, 0.0, 0.01, 0.05]), np.array([0.5, 2.0])
    np.testing.assert_array_equal(nmpc.settings.effects(x, i), stage.plant_effects()(x, i))
    assert "NMPC predicting with" in capsys.readouterr().out
