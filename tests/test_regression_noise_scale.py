"""The logged currents' error level from the fit's consistency across two bands
(maglev_oc.regression.noise_scale) and its use by the diagnosis.

The errors-in-variables correction takes the currents' error from their noise floor at 0.3-0.45 of
the sample rate. A fast velocity observer (2800 rad/s: 446 Hz) puts applied command content in that
band, the correction comes out too large and C1 high: +4.5 % on the independent generator's clean
log of such a rig, where issue 19 asks for 1 %. The level that makes the constants fitted on 2 Hz
and on 10 Hz agree gives C1 within 0.45 % on every rig setting of bench/diagnose_rigs.py.
"""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import chi2

from maglev_oc.data.logs import Log
from maglev_oc.data.reading import read_log
from maglev_oc.diagnosis.pipeline import diagnose
from maglev_oc.errors import InputError
from maglev_oc.regression import noise_scale as NS
from maglev_oc.regression.data import prepare
from maglev_oc.regression.design import build_design
from maglev_oc.regression.solve import fit_subset
from tests.independent import write_log
from tests.independent.simulate import Rig, Scenario, simulate

NOISY = Rig(observer_bandwidth=2800.0)
"""The generator's rig with currents as noisy as the shared clean log's (bench/diagnose_rigs.py)."""


# --- the search, on fits whose dependence on the scale is known -----------------------------------------
class _Linear:
    """Stands in for fit_subset: each design's coefficients move linearly with the noise scale and
    the two designs' lines cross at ``at``; the narrow one's covariance is diag(se^2), the wide
    one's 100 times it (the differences are scaled by the narrow fit's standard errors)."""

    def __init__(self, at, slopes, se, offset=None):
        self.at, self.slopes, self.se = at, slopes, np.asarray(se, dtype=float)
        self.offset = offset or {}

    def __call__(self, design, groups, *, covariance=True, noise_scale=1.0):
        slope = np.asarray(self.slopes[design.name], dtype=float)
        coef = np.array([1.0, 2.0]) + slope * (noise_scale - self.at)
        coef = coef + np.asarray(self.offset.get(design.name, 0.0), dtype=float)
        se = self.se * (10.0 if design.name == "wide" else 1.0)
        return SimpleNamespace(index=np.array([0, 1]), coef=coef, covariance=np.diag(se**2))


def _designs():
    return tuple(
        SimpleNamespace(name=name, names=("C1", "C4"), indices=lambda groups: np.array([0, 1]))
        for name in ("wide", "narrow")
    )


def _misfit(fake, s):
    d = (np.array(fake.slopes["wide"]) - np.array(fake.slopes["narrow"])) * (s - fake.at) / fake.se
    return float(d @ d)


@pytest.mark.parametrize("at", [0.0, 0.37, 0.83, 1.6, NS.MAX_SCALE])
def test_the_scale_is_where_the_bands_agree(monkeypatch, at):
    # the lines cross at ``at``: found to the search's tolerance (1e-4, with the grid's 0.05 steps
    # bracketing it), and taken (they agree there, and the range is narrow) unless it is 0: a range
    # that reaches no error at all in the logged currents does not tell their level
    fake = _Linear(at, {"wide": [4.0, 0.1], "narrow": [1.0, 0.05]}, [0.01, 0.001])
    monkeypatch.setattr(NS, "fit_subset", fake)
    out = NS.band_consistent_scale(*_designs(), ["base"])
    assert out.best == pytest.approx(at, abs=1e-3)
    if at > 0:
        assert out.calibrated and out.scale == out.best and out.interval[0] > 0
    else:
        assert not out.calibrated and out.interval[0] == 0.0 and "down to no error" in out.message
    assert out.misfit_best == pytest.approx(_misfit(fake, out.best), rel=1e-9)
    assert out.misfit_one == pytest.approx(_misfit(fake, 1.0), rel=1e-9)
    assert out.parameters == ("C1", "C4")


def test_a_crossing_beyond_the_largest_scale_is_held_at_it(monkeypatch):
    fake = _Linear(3.5, {"wide": [4.0, 0.1], "narrow": [1.0, 0.05]}, [0.01, 0.001])
    monkeypatch.setattr(NS, "fit_subset", fake)
    out = NS.band_consistent_scale(*_designs(), ["base"])
    assert out.best == pytest.approx(NS.MAX_SCALE, abs=1e-3)


@pytest.mark.parametrize("margin, taken", [(0.98, True), (1.02, False)])
def test_the_scale_is_taken_where_the_bands_agree_and_not_where_they_agree_nowhere(
    monkeypatch, margin, taken
):
    # C1's lines cross at 0.6, C4's are offset so that they cross elsewhere: the least disagreement
    # of the two is (off / se4)^2 a1^2 / (a1^2 + a2^2), with a1, a2 the differences' slopes over
    # their standard errors (least squares in s). Placed 2 % either side of the chi-square 95 %
    # point with one degree of freedom (two parameters compared, less the scale: 3.84, scipy),
    # the best scale is taken or the floor's estimate stands
    se = np.array([0.01, 0.001])
    a1, a2 = 3.0 / se[0], 0.05 / se[1]
    off = np.sqrt(margin * chi2.ppf(0.95, 1) * (a1**2 + a2**2)) / a1 * se[1]
    fake = _Linear(0.6, {"wide": [4.0, 0.1], "narrow": [1.0, 0.05]}, se, offset={"wide": [0.0, off]})
    monkeypatch.setattr(NS, "fit_subset", fake)
    out = NS.band_consistent_scale(*_designs(), ["base"])
    assert out.misfit_best == pytest.approx(margin * chi2.ppf(0.95, 1), rel=1e-4)
    assert out.agreement == pytest.approx(chi2.ppf(0.95, 1), rel=1e-12)
    assert out.calibrated is taken
    assert out.scale == (out.best if taken else 1.0)
    assert ("agree at no level" in out.message) is not taken


@pytest.mark.parametrize("at", [0.37, 0.83, 1.6])
def test_the_scales_range_is_where_the_disagreement_is_within_3_84_of_the_least(monkeypatch, at):
    # one effective parameter (C4's standard error huge): the disagreement is (3 (s - at) / se)^2,
    # within chi-square(1)'s 95 % point (3.84) of its least (0) for |s - at| <= 1.96 se / 3; the
    # range is that interval on the search's 0.05 grid (its outermost grid points inside), and 1
    # lies in it only when it is that close to the crossing
    se = np.array([0.02, 1e6])
    fake = _Linear(at, {"wide": [4.0, 0.0], "narrow": [1.0, 0.0]}, se)
    monkeypatch.setattr(NS, "fit_subset", fake)
    out = NS.band_consistent_scale(*_designs(), ["base"])
    half = np.sqrt(chi2.ppf(0.95, 1)) * se[0] / 3.0
    lo, hi = out.interval
    assert at - half <= lo <= at - half + 0.05 and at + half - 0.05 <= hi <= at + half
    assert out.calibrated and out.scale == pytest.approx(at, abs=1e-3)
    assert out.to_dict()["interval"] == [lo, hi]


# --- the solver's scale and the prepared data's ----------------------------------------------------------
@pytest.fixture(scope="module")
def noisy_clean(tmp_path_factory):
    """(path, true constants) of a 60 s clean log of the noisy rig (seed 731)."""
    run = simulate(Scenario(name="clean", seed=731, effects=(), rig=NOISY))
    path, truth = write_log(run, tmp_path_factory.mktemp("noisy_clean"), stem="clean")
    return path, json.loads(truth.read_text())["plant"]["constants_true"]


def _base_designs(path, model):
    designs = []
    for band in (10.0, NS.LOW_BAND):
        data = prepare([read_log(path)], bandwidth=band)
        fit, hold = data.masks(0.25)
        designs.append(build_design(data, model, fit=fit, holdout=hold))
    return designs


def test_the_solvers_noise_scale_multiplies_the_estimated_errors(noisy_clean, model):
    wide, _ = _base_designs(noisy_clean[0], model)
    plain = fit_subset(wide, ["base"], compensate=False)
    np.testing.assert_allclose(fit_subset(wide, ["base"], noise_scale=0.0).coef, plain.coef, rtol=1e-12)
    # the same as a design whose estimate is 0.7 times as large: the prepared data's own scaling
    scaled = build_design(
        wide.prepared.with_noise_scale(0.7), model, fit=wide.fit, holdout=wide.holdout, weights=wide.weights
    )
    np.testing.assert_allclose(scaled.noise, 0.7 * wide.noise, rtol=1e-12)
    a, b = fit_subset(wide, ["base"], noise_scale=0.7), fit_subset(scaled, ["base"])
    np.testing.assert_allclose(a.coef, b.coef, rtol=1e-10)
    np.testing.assert_allclose(a.covariance, b.covariance, rtol=1e-8)
    assert scaled.prepared.settings["current_noise_scale"] == 0.7
    assert scaled.prepared.same_samples(wide.prepared) and not wide.prepared.same_samples(
        prepare([read_log(noisy_clean[0])], bandwidth=10.0)
    )
    for bad in (-0.1, np.nan, np.inf):
        with pytest.raises(InputError, match="noise"):
            fit_subset(wide, ["base"], noise_scale=bad)
        with pytest.raises(InputError, match="noise scale"):
            wide.prepared.with_noise_scale(bad)


def test_on_the_noisy_rig_the_bands_give_c1_within_one_percent(noisy_clean, model):
    # issue 19: the constants the diagnosis starts from within 1 % (C1..C3) of the truth on a clean
    # log of a loop faster than its logging; the floor's estimate (scale 1) makes C1 3.5-4.5 % high
    # on this rig (measured +4.1 % here), the bands agree at 0.71 (C1 -0.2 %)
    path, truth = noisy_clean
    wide, narrow = _base_designs(path, model)
    out = NS.band_consistent_scale(wide, narrow, ["base"])
    assert out.calibrated and 0.5 < out.scale < 0.95
    at_one = fit_subset(wide, ["base"]).coef
    at_scale = fit_subset(wide, ["base"], noise_scale=out.scale).coef
    names = wide.names
    assert at_one[names.index("C1")] / truth["C1"] - 1 > 0.03
    for k, name in enumerate(names):
        if name != "C4":
            assert at_scale[k] / truth[name] - 1 == pytest.approx(0.0, abs=0.01), name


@pytest.mark.slow
def test_the_diagnosis_starts_from_the_calibrated_constants(noisy_clean):
    path, truth = noisy_clean
    d = diagnose([read_log(path)], limits=False)
    scale = d.settings["current_noise_scale"]
    assert 0.5 < scale["scale"] < 0.95 and scale["parameters"] == ["C1", "C2", "C3", "C4"]
    assert d.data.settings["current_noise_scale"] == scale["scale"]
    assert not d.effects
    for name in ("C1", "C2", "C3"):  # issue 19's bound
        assert d.constants_base[name].value / truth[name] - 1 == pytest.approx(0.0, abs=0.01), name
    # C4 within 10 %, the bound for it
    assert d.constants_base["C4"].value / truth["C4"] - 1 == pytest.approx(0.0, abs=0.1)


def test_a_gain_below_minus_100_percent_is_printed_as_its_bound():
    # a candidate whose columns the logged currents' errors dominate makes the held-out error many
    # times larger (-9e4 % was printed in the verdict table); the words keep the bound only
    from maglev_oc.diagnosis.selection import percent

    assert percent(0.0123) == "1.2%"
    assert percent(-1.0) == "-100.0%"
    assert percent(-915.5) == "< -100 %"


@pytest.mark.slow
def test_with_an_effect_found_the_claims_are_the_floors_and_the_refit_is_calibrated(tmp_path, monkeypatch):
    # the bands' agreement takes every band-dependent misfit for the currents' errors, so the
    # selection runs on the floor's estimate (calibrating before it added false claims on the noisy
    # rig's pairs: bench/README); once the claims are made, the kept selection is refitted at the
    # level where the bands agree with the chosen effects in the model. A large cable carrier on the
    # noisy rig (seed 733): the same claim as with the scale held at 1, the scale taken (measured
    # 0.79), and C1 beside it within 1 % of the truth (measured +0.29 %; at 1, +2.85 %)
    from maglev_oc.diagnosis import pipeline as P
    from tests.independent.sets import SINGLE_EFFECTS

    effect = SINGLE_EFFECTS["cable_carrier"]("large")
    run = simulate(Scenario(name="carrier", seed=733, effects=(effect,), rig=NOISY))
    path, truth = write_log(run, tmp_path, stem="carrier")
    c1 = json.loads(truth.read_text())["plant"]["constants_true"]["C1"]
    log = read_log(path)
    d = diagnose([log], limits=False)
    monkeypatch.setattr(P, "_band_scale", lambda stage, run: NS.NoiseScale.not_calibrated("held at 1"))
    at_one = diagnose([log], limits=False)
    assert [e.name for e in d.effects] == [e.name for e in at_one.effects] == ["cable_carrier_force"]
    scale = d.settings["current_noise_scale"]
    assert 0.5 < scale["scale"] < 0.95 and scale["interval"][0] > 0
    assert d.data.settings["current_noise_scale"] == scale["scale"]
    assert d.constants_final["C1"].value / c1 - 1 == pytest.approx(0.0, abs=0.01)
    assert abs(at_one.constants_final["C1"].value / c1 - 1) > 0.02


def test_beside_effects_only_the_kept_selection_is_refitted_at_the_scale(monkeypatch):
    """diagnose with effects chosen and nothing unexplained: the scale is looked for with them in
    the model (``_band_scale``), and when taken the stage handed to the result is the same
    selection refitted at it (``_at_scale``), never a new selection; with something unexplained,
    or no scale taken, the floor's stage as it is. Recorders stand in for the passes."""
    import contextlib

    from maglev_oc.diagnosis import pipeline as P

    floor = object()
    monkeypatch.setattr(P, "_prepare", lambda *a: (floor, None, None))
    monkeypatch.setattr(P, "refuse_convention_slips", lambda data, model: None)  # no samples to check
    monkeypatch.setattr(P, "reusing_columns", lambda data: contextlib.nullcontext())
    monkeypatch.setattr(P, "_finished", lambda stage, run, bandwidth, scale: (stage, scale))
    monkeypatch.setattr(P, "_at_scale", lambda stage, s: ("refitted", stage, s))
    taken = NS.NoiseScale(0.8, 0.8, 0.1, 20.0, ("C1",), "taken", (0.7, 0.9), 3.84)
    refused = NS.NoiseScale(1.0, 0.0, 0.1, 20.0, ("C1",), "refused", (0.0, 0.3), 3.84)
    for unexplained, band, expect in (
        ([], taken, "refitted"),
        ([], refused, "as is"),
        (["x"], taken, "as is"),
    ):
        passes = []
        stage = SimpleNamespace(
            sel=SimpleNamespace(selected=["cable_carrier_force"]), unexplained=unexplained
        )
        monkeypatch.setattr(
            P, "_selected", lambda run, data, st=stage, passes=passes: passes.append(data) or st
        )
        monkeypatch.setattr(P, "_band_scale", lambda st, run, band=band: band)
        out, scale = P.diagnose([SimpleNamespace(payload=0.0)])
        assert passes == [floor]  # one selection, on the floor's estimate
        if expect == "refitted":
            assert out == ("refitted", stage, 0.8) and scale is taken
        else:
            assert out is stage and not scale.calibrated


def test_identify_s_equation_error_uses_the_same_rule(noisy_clean, model):
    # one regression layer: the identification's equation-error fit (8 Hz band) calibrates the same
    # way, C1 within 1 % (measured +0.3 %; with the floor's estimate +4 %, kept by calibrate_noise=False)
    from maglev_oc.identification.equation_error import EquationError

    path, truth = noisy_clean
    log = read_log(path)
    fit = EquationError(log, model).fit()
    scale = fit.settings["current_noise_scale"]
    assert 0.5 < scale["scale"] < 0.95
    assert fit.values["C1"] / truth["C1"] - 1 == pytest.approx(0.0, abs=0.01)
    plain = EquationError(log, model, calibrate_noise=False).fit()
    assert plain.settings["current_noise_scale"] is None
    assert plain.values["C1"] / truth["C1"] - 1 > 0.03
    # logs too short for the 2 Hz band are fitted on the floor's estimate, and say why: 0.6 s is
    # shorter than its differentiator's window (0.76 s), 1.2 s leaves too few samples in its fit
    for n, why in ((600, "no 2 Hz fit to compare with"), (1200, "too few samples for a 2 Hz fit")):
        short = Log(log.t[:n], log.x[:, :n], log.u[:, :n], metadata=dict(log.metadata), source="short.csv")
        out = EquationError(short, model).fit()
        assert out.settings["current_noise_scale"]["scale"] == 1.0
        assert why in out.settings["current_noise_scale"]["message"]


def test_a_shifted_gap_reading_estimated_as_an_offset_leaves_the_calibrated_constants(noisy_clean, model):
    """The gap readings shifted by 1 mm and the offset estimated with C1 (the other constants at
    the truth, where the offset is sharply determined) is the same problem reparametrized: the
    offset comes out -1 mm and C1 within 0.15 % of the unshifted fit's (measured 0.04 %). The
    2 Hz fit the scale compares with is linearized where the wide fit converged; linearized at
    zero offset instead, 1 mm away, it moves the scale from 0.66 to 0.62 and C1 by 0.67 %."""
    import dataclasses

    from maglev_oc.identification.equation_error import EquationError

    path, truth = noisy_clean
    log = read_log(path)
    known = model.with_constants(dataclasses.replace(model.constants, **truth))
    x = log.x.copy()
    x[0] += 1e-3
    shifted = Log(log.t, x, log.u, metadata=dict(log.metadata), source="shifted.csv")
    estimate = ("C1", "gap_offset")
    plain, moved = (EquationError(g, known, estimate=estimate).fit() for g in (log, shifted))
    assert moved.settings["current_noise_scale"]["scale"] < 0.9  # calibrated (1 is the floor's estimate)
    assert moved.values["gap_offset"] == pytest.approx(-1e-3, abs=2e-5)
    assert moved.values["C1"] / plain.values["C1"] - 1 == pytest.approx(0.0, abs=1.5e-3)


def test_the_report_states_the_scale_in_one_line_and_in_a_note_when_calibrated():
    from maglev_oc.reporting.diagnosis_report import _compact_noise_scale, _noise_scale_notes

    taken = NS.NoiseScale(0.713, 0.713, 0.48, 40.43, ("C1",), "m", (0.6, 0.85), 3.84).to_dict()
    nowhere = NS.NoiseScale(1.0, 0.52, 12.1, 30.2, ("C1", "C2"), "m", (0.45, 0.6), 3.84).to_dict()
    from_zero = NS.NoiseScale(1.0, 0.1, 0.4, 9.0, ("C1", "C2"), "m", (0.0, 0.5), 3.84).to_dict()
    kept = NS.NoiseScale.not_calibrated("effects were found").to_dict()
    assert kept["best"] is None and kept["scale"] == 1.0
    line = _compact_noise_scale({"a": 1, "current_noise_scale": taken})
    assert line == {
        "a": 1,
        "current_noise_scale": "0.713 (bands agree at 0.713: misfit 0.48, against 40.43 at 1)",
    }
    assert _compact_noise_scale({"current_noise_scale": nowhere})["current_noise_scale"] == (
        "1 (bands agree at no level; least at 0.52: misfit 12.10, against 30.20 at 1)"
    )
    # they agree (0.4 within 3.84), but down to no error at all: not taken, and not "at no level"
    assert _compact_noise_scale({"current_noise_scale": from_zero})["current_noise_scale"] == (
        "1 (bands agree, in a range from 0 (not taken), at 0.1: misfit 0.40, against 9.00 at 1)"
    )
    assert _compact_noise_scale({"current_noise_scale": kept})["current_noise_scale"].startswith(
        "1 (the floor"
    )
    diag = SimpleNamespace(settings={"current_noise_scale": taken})
    (note,) = _noise_scale_notes(diag)
    assert "0.71 (95 % range 0.60-0.85) times their noise floor's estimate" in note and "40.4 at 1" in note
    assert _noise_scale_notes(SimpleNamespace(settings={"current_noise_scale": nowhere})) == []
    assert _noise_scale_notes(SimpleNamespace(settings={"current_noise_scale": kept})) == []


def test_the_diagnosis_calibrates_only_when_the_base_model_explains_the_log(monkeypatch):
    """diagnose: the scale is looked for only when the first pass chose nothing and left nothing
    unexplained; a calibrated pass that then finds something is not kept (the first pass is run
    again on the floor's estimate). The passes are stood in for by recorders."""
    import contextlib

    from maglev_oc.diagnosis import pipeline as P

    for selected, unexplained in ((["guide_friction_horizontal"], []), ([], ["horizontal: position"])):
        stage = SimpleNamespace(sel=SimpleNamespace(selected=selected), unexplained=unexplained)
        out = P._noise_scale(stage, None)
        assert not out.calibrated and "effects were found" in out.message

    class Data:
        def with_noise_scale(self, s):
            return ("scaled", s)

    floor = Data()
    taken = NS.NoiseScale(0.7, 0.7, 0.1, 20.0, ("C1",), "taken")
    monkeypatch.setattr(P, "_prepare", lambda *a: (floor, None, None))
    monkeypatch.setattr(P, "refuse_convention_slips", lambda data, model: None)  # no samples to check
    monkeypatch.setattr(P, "reusing_columns", lambda data: contextlib.nullcontext())
    monkeypatch.setattr(P, "_noise_scale", lambda stage, run: taken)
    monkeypatch.setattr(P, "_finished", lambda stage, run, bandwidth, scale: (stage.data, scale))
    for found_when_scaled in (False, True):
        passes = []

        def selected(run, data, found=found_when_scaled, passes=passes):
            passes.append(data)
            chosen = ["constant_vertical_force"] if found and data != floor else []
            return SimpleNamespace(data=data, sel=SimpleNamespace(selected=chosen), unexplained=[])

        monkeypatch.setattr(P, "_selected", selected)
        data, scale = P.diagnose([SimpleNamespace(payload=0.0)])
        if found_when_scaled:  # not kept: the floor's estimate, the first pass again
            assert passes == [floor, ("scaled", 0.7), floor] and data is floor
            assert not scale.calibrated and "calibrated on" in scale.message
        else:
            assert passes == [floor, ("scaled", 0.7)] and data == ("scaled", 0.7) and scale is taken
