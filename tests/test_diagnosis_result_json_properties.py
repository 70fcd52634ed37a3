"""Properties of a diagnosis's result as a user reads it (its JSON, its text and its stage file),
checked against stub diagnoses whose numbers are known:

- ``to_dict`` follows the result convention and round-trips through JSON; it counts the held-out
  and fitted samples, keeps each number's sign, carries the validation before and after, names
  every metric's SI unit and every judged candidate's gain and z under the same keys, and each
  effect's numbers under the contract's names;
- the text gives each moving axis's error before -> after and says the outcome in words; a
  per-axis number of an axis that does not move is unknown;
- the stage file holds the refitted constants of the moving axis and the model's elsewhere.
"""

from __future__ import annotations

import dataclasses
import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.diagnosis.result import Diagnosis, NotSeparable
from maglev_oc.diagnosis.selection import EIV_REASON, THRUST_SIDE, Judgement, Ranked, Selection
from maglev_oc.results import Estimate, PerAxis, check_result
from maglev_oc.validation import Validation
from tests.diagnosis_support import stub_diagnosis


# --- the result's JSON and text ------------------------------------------------------------------------
def _judgement(name: str, gain: float, verdict: str = "passes", reason: str = ""):
    """A judgement's fields as the result reads them; its ``dominated_by_current_errors`` is the
    real property's rule (:class:`Judgement`), applied to this verdict and reason."""
    j = SimpleNamespace(
        name=name, verdict=verdict, reason=reason, gain=gain, z=3.0 * gain, wald=1.0, vif=1.0, side=""
    )
    j.dominated_by_current_errors = Judgement.dominated_by_current_errors.fget(j)
    return j


def _stub_diagnosis(**changes) -> Diagnosis:
    """A Diagnosis built by hand (no fit): every number distinct, so that a number read from the
    wrong field shows; 300 training and 100 held-out samples of 500 (the rest filtered out)."""
    train = np.zeros(500, dtype=bool)
    train[:300] = True
    hold = np.zeros(500, dtype=bool)
    hold[350:450] = True
    steps = [
        SimpleNamespace(
            chosen="b",
            confidence=0.9,
            judgements={n: _judgement(n, g) for n, g in (("a", 0.02), ("b", 0.31), ("c", 0.11))},
        )
    ]
    selection = SimpleNamespace(
        steps=steps,
        ranking=[Ranked("b", 0.31, "passes"), Ranked("c", 0.11, "passes"), Ranked("a", 0.02, "passes")],
    )
    per = PerAxis.of
    fields = dict(
        success=True,
        status="nothing_found",
        message="m",
        sources=("log.csv",),
        constants_base={},
        constants_final={},
        effects=[],
        not_separable=[NotSeparable("wave", ("C1",), "run it", 0.07, "r", {})],
        rejected=[],
        unexplained=[],
        error_before=per([0.0123, float("nan")]),
        error_after=per([0.00456, float("nan")]),
        output_error_before=per([1e-5, float("nan")]),
        output_error_after=per([2e-6, float("nan")]),
        selection=selection,
        trace=None,
        residual_before=np.zeros((2, 500)),
        residual_after=np.zeros((2, 500)),
        data=None,
        train=train,
        holdout=hold,
        settings={"holdout_fraction": 0.25},
    )
    fields.update(changes)
    return Diagnosis(**fields)


def test_the_json_counts_the_held_out_and_fitted_samples_and_keeps_each_numbers_sign():
    """``holdout.samples`` and ``fit_samples`` are the two masks' counts (100 and 300, from the masks
    here); a not-separable candidate's held-out gain keeps its sign; the selection's candidates are
    listed best gain first; an axis that does not move is null, not NaN (JSON has no NaN)."""
    d = _stub_diagnosis()
    out = d.to_dict()
    assert out["holdout"] == {"fraction": 0.25, "samples": 100, "fit_samples": 300}
    assert out["not_separable"][0]["holdout_gain"] == 0.07
    gains = [c["holdout_gain"] for c in out["selection_steps"][0]["candidates"]]
    assert gains == sorted(gains, reverse=True) == [0.31, 0.11, 0.02]
    assert out["error_before"] == {"vertical": 0.0123, "horizontal": None}
    assert out["error_after"] == {"vertical": 0.00456, "horizontal": None}
    json.dumps(out, allow_nan=False)


def test_a_fit_dominated_by_the_currents_errors_has_no_gain_in_the_json_and_ranks_last():
    """A candidate refused because its columns are the logged currents' errors (a nearly singular
    fit: noisy single_20 of the independent generator gave gains of -4.7e15 to -3.7e18 for four
    vertical candidates) has a null gain, z and Wald statistic in the ranking, the steps and the
    refused list, and ranks after every candidate with a measured gain, however negative (-2.0
    here: a fit that triples the error is a measurement); the others keep their numbers."""
    eiv = _judgement("friction", -4.7e15, "not significant", f"{EIV_REASON} (not identifiable)")
    worse = _judgement("offset", -2.0, "not significant", "held-out error rises")
    good = _judgement("lag", 0.0073, "not significant", "z = 1.9")
    first = {j.name: j for j in (eiv, worse, good)}
    # the ranking is the real Selection's, over these judgements
    selection = Selection(steps=[], base=None, final=None, last=first)
    assert selection.ranking[-1].name == "friction" and math.isnan(selection.ranking[-1].gain)
    steps = [SimpleNamespace(chosen="lag", confidence=0.5, judgements=first)]
    d = _stub_diagnosis(
        selection=SimpleNamespace(steps=steps, ranking=selection.ranking), rejected=[eiv, worse]
    )
    out = d.to_dict()
    json.dumps(out, allow_nan=False)
    assert out["candidate_ranking"] == [
        {"name": "lag", "holdout_gain": 0.0073, "verdict": "not significant"},
        {"name": "offset", "holdout_gain": -2.0, "verdict": "not significant"},
        {"name": "friction", "holdout_gain": None, "verdict": "not significant"},
    ]
    listed = out["selection_steps"][0]["candidates"]
    assert [c["name"] for c in listed] == ["lag", "offset", "friction"]
    assert (listed[-1]["holdout_gain"], listed[-1]["z"], listed[-1]["wald"]) == (None, None, None)
    assert listed[1]["holdout_gain"] == -2.0 and listed[1]["z"] == pytest.approx(-6.0)
    refused = {r["name"]: r for r in out["rejected"]}
    assert refused["friction"]["holdout_gain"] is None and refused["friction"]["z"] is None
    assert refused["friction"]["reason"].startswith(EIV_REASON)
    assert refused["offset"]["holdout_gain"] == -2.0


def test_the_reports_errors_are_before_and_after_on_the_moving_axes():
    """The text's held-out error line of a moving axis reads before -> after (4 significant digits,
    as the numbers were given); an axis that does not move has no line."""
    text = _stub_diagnosis().report()
    assert "held-out error vertical: 0.0123 -> 0.00456 m/s^2" in text
    assert "horizontal" not in text.split("held-out error", 1)[1]


# --- the stage file -------------------------------------------------------------------------------------
def test_the_stage_file_holds_the_fitted_constants_of_the_moving_axis_and_the_models_elsewhere(model):
    """A diagnosis of a horizontal log (C1 refitted 7 % above the model's, C2..C4 unknown): the stage
    file's C1 is the refitted value with its standard error and C2..C4 the model's (no error: the
    log says nothing of them). With all four refitted, its covariance is the C1..C4 block of the
    final fit's, picked by name from a fit whose columns are in another order (symmetrised)."""
    from maglev_oc.diagnosis.stage_file import diagnosis_stage_file
    from maglev_oc.model.stagefile import Provenance

    c = model.constants
    nan = Estimate(float("nan"), float("nan"), "")
    final = {"C1": Estimate(1.07 * c.C1, 0.01 * c.C1, "")} | {k: nan for k in ("C2", "C3", "C4")}
    geometry = Provenance.now(("test",), "test")
    sf = diagnosis_stage_file(_stub_diagnosis(constants_final=final), model, geometry)
    assert sf.constants.C1 == 1.07 * c.C1
    assert (sf.constants.C2, sf.constants.C3, sf.constants.C4) == (c.C2, c.C3, c.C4)
    assert sf.covariance is None and sf.stderr["C1"] == 0.01 * c.C1
    assert all(math.isnan(sf.stderr[k]) for k in ("C2", "C3", "C4"))

    names = ("q", "C3", "C1", "C4", "C2")
    rng = np.random.default_rng(0)
    a = rng.standard_normal((5, 5))
    cov = a @ a.T
    values = {"C1": 1.07 * c.C1, "C2": 0.98 * c.C2, "C3": 1.01 * c.C3, "C4": 0.9 * c.C4}
    final = {k: Estimate(v, 0.01 * v, "") for k, v in values.items()}
    fit = SimpleNamespace(names=names, covariance=cov)
    sf = diagnosis_stage_file(
        _stub_diagnosis(constants_final=final, selection=SimpleNamespace(final=fit)), model, geometry
    )
    assert [getattr(sf.constants, k) for k in values] == list(values.values())
    k = [names.index(n) for n in ("C1", "C2", "C3", "C4")]
    np.testing.assert_allclose(sf.covariance, cov[np.ix_(k, k)], rtol=1e-15)


def test_a_per_axis_number_of_an_axis_that_does_not_move_is_unknown():
    """The errors before and after are per axis, NaN (null in the JSON) where the axis did not move."""
    from maglev_oc.diagnosis.pipeline import _per_axis

    got = _per_axis(np.array([0.2, 0.3]), np.array([False, True]))
    assert math.isnan(got.vertical) and got.horizontal == 0.3
    got = _per_axis(np.array([0.2, 0.3]), np.array([True, False]))
    assert got.vertical == 0.2 and math.isnan(got.horizontal)


def test_the_outcome_says_what_was_found_in_words():
    # status and message of each outcome (SPEC 3's words); the unexplained-only one must say that
    # no named effect was found and part of the residual is unexplained (seed 65: its words could
    # be changed with every test passing)
    from types import SimpleNamespace as NS

    from maglev_oc.diagnosis.pipeline import _outcome

    sel = NS(base=NS(compensated=True))
    data = NS(current_noise=np.array([1e-4, 1e-4]))
    status, success, message = _outcome([], [], [NS()], sel, data)
    assert (status, success) == ("unexplained_only", True)
    assert message == "no named effect found, but part of the residual is unexplained"
    status, _, message = _outcome([], [], [], sel, data)
    assert status == "nothing_found" and message.startswith("no missing effect found")
    _, success, message = _outcome([], [], [], NS(base=NS(compensated=False)), data)
    assert not success and "errors-in-variables compensation failed" in message


@pytest.mark.parametrize(
    ("success", "status", "message"),
    [(True, "nothing_found", "no missing effect found"), (False, "unexplained_only", "a residual at 60 mm")],
)
def test_a_diagnosis_to_dict_carries_its_outcome_and_round_trips_through_json(success, status, message):
    """The dict the CLI writes has the convention's success, status and message with the
    diagnosis's values (both outcomes, so a constant cannot pass), and the logs, holdout sizes,
    settings and timings; it is plain JSON (dumped and loaded, it is equal)."""
    d = stub_diagnosis(
        success, status, message, sources=("a.csv", "b.csv"), ranking=[("cogging", 0.12, "passes")]
    )
    check_result(d)
    out = d.to_dict()
    assert out["success"] is success and out["status"] == status and out["message"] == message
    assert out["logs"] == ["a.csv", "b.csv"]
    assert out["holdout"] == {"fraction": 0.25, "samples": 1, "fit_samples": 2}
    assert out["settings"] == {"holdout_fraction": 0.25} and out["timings"] == {"total": 1.5}
    assert out["error_before"] == {"vertical": 0.5, "horizontal": 0.25}
    assert out["candidate_ranking"] == [{"name": "cogging", "holdout_gain": 0.12, "verdict": "passes"}]
    assert out["warnings"] == []
    assert json.loads(json.dumps(out)) == out
    # a warning on the refitted constants is in the JSON and on the text report's second line
    warned = dataclasses.replace(d, warnings=("C1 refitted beside the effects is 2.342",))
    assert warned.to_dict()["warnings"] == ["C1 refitted beside the effects is 2.342"]
    assert warned.report().splitlines()[1] == "  WARNING: C1 refitted beside the effects is 2.342"
    # and on the PDF's first page: a scorecard row with the constant's clause
    from maglev_oc.reporting.diagnosis_report import _finding_rows

    warned = dataclasses.replace(d, warnings=("C1 refitted beside the effects is 2.342: the rest",))
    rows = [r for r in _finding_rows(warned) if r[0] == "warning: a refitted constant"]
    assert [r[1] for r in rows] == ["C1 refitted beside the effects is 2.342"]


# --- the JSON's validation block ------------------------------------------------------------------------
def _validation(model: str, rms: tuple[float, float], status: str) -> Validation:
    """A validation result as :func:`maglev_oc.validation.validate` returns it, with known residuals."""
    residuals = np.vstack([np.full(8, rms[0]), np.full(8, rms[1])])
    return Validation(
        model=model,
        data="held-out",
        horizon=0.05,
        spacing=0.05,
        residuals=residuals,
        inputs=np.zeros((2, 8)),
        whiteness={},
        independence={},
        fits=(),
        success=status == "valid",
        status=status,
        message=f"{model}: {status}",
        timings={"total": 0.25},
    )


def test_the_json_carries_the_validation_of_the_base_model_and_of_the_model_with_the_effects():
    """README (SPEC 3): the JSON holds the errors "before and after"; its validation block is keyed
    the same way, ``before`` the base model's and ``after`` the model's with the effects. The two
    validations here differ in every field a reader looks at (model, status, residual RMS 2e-6 vs
    1e-6 m), so each key must hold its own validation's dict exactly; without a validation both keys
    are there and null. The block is plain JSON (dumped and loaded it is equal)."""
    before = _validation("base model (C1..C4 refitted, no effects)", (2e-6, 4e-6), "invalid")
    after = _validation("model with the effects (cogging)", (1e-6, 1e-6), "valid")
    d = stub_diagnosis(validation_before=before, validation_after=after)
    check_result(d)
    block = d.to_dict()["validation"]
    assert set(block) == {"before", "after"}
    assert block["before"] == before.to_dict() and block["after"] == after.to_dict()
    assert block["before"]["status"] == "invalid" and block["after"]["status"] == "valid"
    assert block["after"]["residual_rms_m"] == pytest.approx({"vertical": 1e-6, "horizontal": 1e-6})
    assert json.loads(json.dumps(block)) == block
    assert stub_diagnosis().to_dict()["validation"] == {"before": None, "after": None}


def test_the_metrics_name_their_si_units():
    d = stub_diagnosis().to_dict()
    assert d["output_error_metric"].endswith("held-out block, per axis, in m")
    assert "m/s^2" in d["error_metric"]


def test_every_judged_candidate_reports_its_gain_and_z_under_the_same_keys():
    # effects and rejected candidates are judged by the same numbers; the JSON gives them the
    # same names (a reader of the SPEC 3 contract looks up "holdout_gain" and "z" in both)
    # and what the held-out test predicted: the accelerations, or the logged thrust current
    judged = _judgement("thrust_ripple", 0.004, "not significant", "r")
    judged.z, judged.side = 1.3, THRUST_SIDE
    d = dataclasses.replace(stub_diagnosis(), rejected=[judged])
    (entry,) = d.to_dict()["rejected"]
    assert entry == {
        "name": "thrust_ripple",
        "verdict": "not significant",
        "reason": "r",
        "holdout_gain": 0.004,
        "z": 1.3,
        "judged_on": THRUST_SIDE,
    }


def test_the_json_of_a_diagnosis_carries_each_effects_numbers_under_the_contracts_names(generated):
    """SPEC 3: every found effect's entry names its numbers as the contract does (and as the
    report and tests/independent/scoring read them): parameters and their details, confidence,
    holdout_gain, z, contribution_rms and force_rms_N per axis, with the values of the result."""
    from tests.diagnosis_support import diagnose_path
    from tests.independent.sets import named_set

    stem = next(s for s, sc in named_set("single") if sc.name == "normal_cogging_large")
    d = diagnose_path(generated("single", stem)[0])
    out = d.to_dict()
    assert len(out["effects"]) == len(d.effects) >= 1
    for e, j in zip(d.effects, out["effects"], strict=True):
        assert j["name"] == e.name and j["axis"] == e.axis
        assert j["parameters"] == {k: v.value for k, v in e.parameters.items()}
        assert j["parameter_details"] == {k: v.to_dict() for k, v in e.parameters.items()}
        assert (j["confidence"], j["holdout_gain"], j["z"]) == (e.confidence, e.gain, e.z)
        assert j["contribution_rms"] == e.contribution_rms.to_dict()
        assert j["force_rms_N"] == e.force_rms.to_dict()
        assert set(j["contribution_rms"]) == set(j["force_rms_N"]) == {"vertical", "horizontal"}
