"""Properties from the survivors of the seed-59 mutation run (region/, identification/,
diagnosis/), each a behaviour a user relies on, not a mutant's line:

* the report's table of certified sets gives every semi-axis in millimetres;
* a study's set-point gaps are accepted up to 40 mm exactly, not beyond;
* the twin check plays the plant it is given;
* single shooting starts, by default, from the smoothed state at the log's first sample;
* constants taken from an NPFSI run say so (the estimator and its epsilon);
* a richer form of an effect is still tried after a form as rich as the one chosen;
* the end effects' profile is scanned when the held-out data show them although not chosen;
* the JSON of a diagnosis carries each effect's numbers under the contract's names.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.errors import InputError
from maglev_oc.model.stage import StageModel


# --- region -------------------------------------------------------------------------------------
def test_the_table_of_certified_sets_gives_every_semi_axis_in_millimetres():
    """certificate_rows: (reference, P, level, upper, tightness, binding, e1 [mm], e1' [mm/s],
    e2 [mm], e2' [mm/s], rectangle [mm]) from a certificate's semi-axes and rectangle in metres."""
    from maglev_oc.region.closed_loop import Reference
    from maglev_oc.region.study import certificate_rows

    semi = {"e1": 1.5e-3, "e1_rate": 2.5e-2, "e2": 7.0e-3, "e2_rate": 4.0e-2}
    cert = SimpleNamespace(
        level=0.8,
        level_upper=0.9,
        tightness=0.1,
        binding="travel",
        initial_conditions=SimpleNamespace(semi_axes=semi, rectangle=(1.25e-3, 6.5e-3)),
    )
    ref = SimpleNamespace(reference=Reference.setpoint(0.02), lyapunov=cert, sdp=None)
    (row,) = certificate_rows(SimpleNamespace(references=[ref]))
    assert row[1:6] == ("Lyapunov eq.", 0.8, 0.9, 0.1, "travel")
    np.testing.assert_allclose(row[6:10], [1.5, 25.0, 7.0, 40.0], rtol=1e-12)
    assert row[10] == "1.25 x 6.50"


def test_a_studys_set_point_gaps_are_accepted_up_to_40_mm_exactly():
    from maglev_oc.region.study import StudyConfig

    StudyConfig(setpoints_mm=(5.0, 40.0), slice_setpoints_mm=(40.0,))
    for bad in (math.nextafter(40.0, 41.0), math.nextafter(5.0, 0.0)):
        with pytest.raises(InputError, match=r"set-point gaps are in millimetres in \[5, 40\]"):
            StudyConfig(setpoints_mm=(bad,))
        with pytest.raises(InputError, match=r"set-point gaps are in millimetres in \[5, 40\]"):
            StudyConfig(slice_setpoints_mm=(bad,))


# --- identification -----------------------------------------------------------------------------
def test_the_twin_check_plays_the_plant_it_is_given(monkeypatch):
    """check_on_twin(truth=...): the rig twin is built on that plant (C1 5 % above the default
    truth here), not on TWIN_TRUTH."""
    from maglev_oc.identification import design as D

    built = []
    original = D.RigTwin

    def recording(model, *args, **kw):
        built.append(model)
        return original(model, *args, **kw)

    monkeypatch.setattr(D, "RigTwin", recording)
    model = StageModel()
    c = model.constants
    truth = model.with_constants(c.replace(C1=1.05 * D.TWIN_TRUTH.C1, source="test"))
    design = D.design_experiment("prbs", 10.0)
    D.check_on_twin(design.reference, design.prediction, model=model, truth=truth)
    assert built and built[-1].constants.C1 == truth.constants.C1


def test_single_shooting_starts_from_the_smoothed_state_at_the_first_sample(generated):
    from maglev_oc.data.reading import read_log
    from maglev_oc.estimation.differentiate import SavitzkyGolay, differentiate_log
    from maglev_oc.identification.output_error import simulate_open_loop
    from tests.independent.sets import named_set

    stem = next(s for s, sc in named_set("single") if sc.name == "normal_cogging_large")
    # from 20 s on, where both axes move (the log starts at rest on the horizontal axis)
    whole = read_log(generated("single", stem)[0])
    log = whole.index_slice(round(20.0 / whole.sample_time))
    der = differentiate_log(log, SavitzkyGolay(log.sample_time))
    assert np.all(np.abs(der.velocity[:, :2]) > 1e-4)
    out = simulate_open_loop(log, StageModel(), 0.01)
    expected = [der.position[0, 0], der.velocity[0, 0], der.position[1, 0], der.velocity[1, 0]]
    np.testing.assert_array_equal(out[:, 0], expected)


def test_constants_from_an_npfsi_run_say_where_they_come_from():
    from tests.test_identify_properties import _npfsi_result

    run = _npfsi_result([[14.0, 14.5], [800.0, 790.0]], names=("C1", "C2"))
    c = run.constants(StageModel().constants)
    assert (c.C1, c.C2) == (14.5, 790.0)
    assert c.source == "NPFSI, eps = 0.01"


# --- diagnosis ----------------------------------------------------------------------------------
def test_a_richer_form_is_tried_after_a_form_as_rich_as_the_chosen_one(monkeypatch):
    """selection._form_of_effect over guide friction's four forms (1, 2, 2 and 3 reported
    parameters): the viscous form improves on the Coulomb-only one, the Stribeck form without
    viscous part (as rich as the chosen) is skipped, and the full form, which improves on the
    viscous one, must still be tried and chosen. The held-out test is stubbed (as in
    tests/test_diagnose_stribeck.py): significant for exactly those two steps."""
    from maglev_oc.diagnosis import selection as S
    from maglev_oc.diagnosis.candidate import LibraryContext
    from maglev_oc.diagnosis.guides import friction_candidates
    from tests.test_diagnose_stribeck import _judged

    n = 200
    x = np.vstack([np.linspace(0.012, 0.018, n), np.zeros(n), np.linspace(-0.05, 0.05, n), np.zeros(n)])
    ctx = LibraryContext(StageModel(), SimpleNamespace(x=x, valid=np.ones(n, dtype=bool), settings={}))
    by_name = {c.name: c for c in friction_candidates(ctx)}
    base = "guide_friction_horizontal"
    forms = [
        _judged(f"{base}_without_viscous", 0.40),
        _judged(base, 0.41),
        _judged(f"{base}_with_stribeck_without_viscous", 0.405),
        _judged(f"{base}_with_stribeck", 0.42),
    ]
    significant = {(f"{base}_without_viscous", base), (base, f"{base}_with_stribeck")}
    tried = []

    def significance(design, r0, r1, axes):
        tried.append((r0, r1))
        return (0.01, 5.0) if (r0, r1) in significant else (0.0, 0.0)

    monkeypatch.setattr(S, "holdout_significance", significance)
    held_out = SimpleNamespace(around=lambda fit, counted: SimpleNamespace(residual=fit))
    design = SimpleNamespace(moving=np.array([True, True]))
    chosen = S._form_of_effect(design, forms[0], forms, by_name, held_out, None, S.SelectionSettings())
    assert chosen.name == f"{base}_with_stribeck"
    assert tried == [(f"{base}_without_viscous", base), (base, f"{base}_with_stribeck")]


def test_the_end_effects_profile_is_scanned_when_the_data_show_them_although_not_chosen(monkeypatch):
    """pipeline._end_profile: chosen, the end effects are scanned beside the effects chosen
    before them; not chosen, they are scanned (beside every chosen effect) only when their last
    judgement's pooled held-out gain reaches min_gain, whatever test they failed."""
    from maglev_oc.diagnosis import pipeline
    from maglev_oc.diagnosis.selection import SelectionSettings

    calls = []

    def scan(fitted, data, before, *args, **kw):
        calls.append([t.name for t in before])
        return "scanned"

    monkeypatch.setattr(pipeline, "best_end_profile", scan)
    settings = SelectionSettings()
    session = SimpleNamespace(data=None, train=None, hold=None, weights=None, settings=settings)
    library = [
        SimpleNamespace(name=n, reported_name=n, term=SimpleNamespace(name=n))
        for n in ("cable_carrier_force", "end_effects", "thrust_ripple")
    ]

    def sel(selected, gain):
        judged = SimpleNamespace(own_pooled_gain=gain)
        return SimpleNamespace(selected=selected, last={"end_effects": judged})

    both = ["cable_carrier_force", "thrust_ripple"]
    assert pipeline._end_profile(session, None, library, sel(["cable_carrier_force", "end_effects"], 0), {})
    assert calls[-1] == ["cable_carrier_force"]  # the effects chosen before them
    assert pipeline._end_profile(session, None, library, sel(both, settings.min_gain), {}) == "scanned"
    assert calls[-1] == both  # beside every chosen effect
    calls.clear()
    below = math.nextafter(settings.min_gain, 0.0)
    assert pipeline._end_profile(session, None, library, sel(both, below), {}) is None
    assert calls == []


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


def test_the_designers_noise_covariance_is_the_differentiators_second_derivative_of_white_noise():
    """ExperimentDesigner.covariance with no residual floor: white encoder noise of variance s^2
    reaches the equation error through the Savitzky-Golay second derivative, so the covariance is
    s^2 H^-1 (sum over axes of G G') H^-1, G the columns filtered by that derivative. Its taps are
    computed here from their definition (the least-squares polynomial of the filter's order over
    its window, twice its t^2 coefficient at the centre), not by scipy; 1e-9 relative (rounding).
    A residual floor adds its own white part on top."""
    from maglev_oc.identification import design as D
    from maglev_oc.identification.equation_error import EquationError
    from maglev_oc.identification.experiments import LOG_RATE_HZ
    from maglev_oc.regression.base import CONSTANT_NAMES
    from maglev_oc.regression.design import build_design
    from maglev_oc.sim.recording import result_to_log

    model = StageModel()
    designer = D.ExperimentDesigner(model, residual_floor=0.0)
    log = result_to_log(designer.simulate(D.papers_reference(10.0)), rate_hz=LOG_RATE_HZ)
    cov = designer.covariance(log)

    prep = EquationError(log, model, estimate=CONSTANT_NAMES).prepared
    design = build_design(prep, model, estimate=CONSTANT_NAMES, weights=np.ones(2))
    x = design.columns * design.fit[None, None, :]  # the fitted samples' columns
    sg = prep.differentiator
    half = sg.acceleration_window // 2
    tau = np.arange(-half, half + 1) * sg.sample_time
    vandermonde = tau[:, None] ** np.arange(sg.polyorder + 1)[None, :]
    taps = 2.0 * np.linalg.pinv(vandermonde)[2]  # y''(centre) = sum_k taps_k y(centre + tau_k)
    assert taps @ (0.5 * tau**2) == pytest.approx(1.0, rel=1e-9)  # the second derivative of t^2 / 2
    H = sum(x[:, a, :] @ x[:, a, :].T for a in range(2))
    G = [np.array([np.convolve(row, taps, mode="full") for row in x[:, a, :]]) for a in range(2)]
    M = designer.noise_variance * sum(g @ g.T for g in G)
    Hi = np.linalg.inv(H)
    np.testing.assert_allclose(cov, Hi @ M @ Hi, rtol=1e-9, atol=0.0)
    # a residual floor (a white equation error of variance floor * fs / 2) adds floor fs / 2 H^-1
    floor = 1e-4
    with_floor = D.ExperimentDesigner(model, residual_floor=floor).covariance(log)
    added = floor / (2 * sg.sample_time) * Hi
    np.testing.assert_allclose(with_floor - cov, added, rtol=1e-6, atol=1e-9 * np.max(np.abs(added)))
