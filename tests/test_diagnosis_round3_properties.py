"""Properties of ``maglev_oc.diagnosis`` (and the regression layer under it) that a third round of
hand-injected bugs found unguarded (issue 21: "tests that would catch a wrong answer"), on the
modules the first two rounds did not reach: the residual's trace, the unexplained probes, the
refit, the candidates' physical sizes, the stage file, the result's JSON and text, the pipeline's
small helpers, the long-run covariance and the terms. Each is a property a correct implementation
must satisfy, checked against an independent computation (numpy's least squares, a closed form,
a planted effect of known size), not against the text of one line; every tolerance's origin is
written beside it.

The residual's trace:

* the spatial spectrum's share at a period is the R^2 gain of a sine and a cosine of the position
  over a constant (numpy's lstsq), whatever the residual's mean; a period longer than the travel
  (up to 1.5 travels) is found at its period.

The result, the stage file and the pipeline's helpers:

* the JSON counts the held-out and the fitted samples from their masks, keeps a gain's sign, lists
  a step's candidates best first and writes null for an axis that does not move; the text reads
  each moving axis's error before -> after;
* the stage file holds the refitted constants of the moving axis and the model's elsewhere, and
  the C1..C4 block of the final fit's covariance picked by name;
* a slope and a waviness found together are one misalignment whose contribution is the RMS of
  their sum (two orthogonal signals, numpy).

Feedback, refit and physical sizes:

* the regulator feeds forward a friction's Coulomb and viscous parts (closed form), not the share
  its guides hold while sticking, which the twin keeps; an improvement is before / after;
* the constants of an axis that does not move are unknown even when the fit holds them;
* a guide slope's gap change is over the logged travel (1st-99th percentiles, numpy) and is what
  the term's vertical acceleration sees there; the waviness period is refined on both sides of the
  periodogram's guess (a planted waviness recovered exactly);
* a gap offset, a guide slope and a commutation angle beyond the library's bounds are refused on
  either side, within them accepted.

Regression layer:

* the fit's chi-square is the weighted residual sum of squares of its rows with the
  errors-in-variables part removed (numpy), and the plain covariance chi^2 / (rows - p) H^-1;
* an ordinary least-squares fit's long-run covariance is the sandwich of the plain scores (no
  errors-in-variables correction; numpy's FFT);
* sticking guides hold at most the whole force, never reverse it, alike in either direction with
  the Gaussian fall-off exp(-(v / v_s)^2) (closed form);
* a linear physical quantity's standard error is |k| times the parameter's.
"""

from __future__ import annotations

import dataclasses
import json
import math
from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest

from maglev_oc.diagnosis.candidate import LibraryContext
from maglev_oc.diagnosis.guides import friction_candidates
from maglev_oc.diagnosis.refit import constants_of
from maglev_oc.diagnosis.result import Diagnosis, Effect, NotSeparable
from maglev_oc.diagnosis.trace import trace
from maglev_oc.model.parameters import StageParameters
from maglev_oc.regression.data import prepare
from maglev_oc.regression.design import build_design
from maglev_oc.regression.solve import fit_subset
from maglev_oc.results import Estimate, PerAxis
from tests.test_diagnosis_trace import sweep_signals
from tests.test_statistics_properties import RATE_FRICTION, _friction_candidate, _log, _rows

TS = 1e-3  # [s] the logs' 1 kHz


# --- the residual's trace ----------------------------------------------------------------------------
def _sweep():
    """(x (4, n), du (2, n)): 6 s of a stage sweeping +-30 mm at 0.17 Hz with a 2 mm wobble."""
    return sweep_signals(6000, position_hz=0.17)


def test_the_spectrums_share_is_the_r2_gain_of_a_sinusoid_over_a_constant_whatever_the_mean():
    """A residual with a large mean (10x its sinusoid: a constant the base model lacks) plus a
    sinusoid of 23 mm and noise: at every fifth period of the grid the share is 1 - RSS / TSS of
    numpy's least squares on [1, sin, cos] of the position, TSS about the mean (the share is of
    the residual's variance; within 1e-6: the phases are computed in single precision, 1e-5 rad at
    63 rad, a relative error of the share of that order)."""
    x, du = _sweep()
    rng = np.random.default_rng(1)
    n = x.shape[1]
    r = np.vstack(
        [
            0.5 + 0.05 * np.sin(2 * math.pi * x[2] / 0.023) + 0.05 * rng.standard_normal(n),
            -0.3 + 0.02 * np.cos(2 * math.pi * x[2] / 0.011) + 0.05 * rng.standard_normal(n),
        ]
    )
    tr = trace(x, du, r, StageParameters(), TS)
    for j in range(0, tr.periods.size, 5):
        k = 2 * math.pi / tr.periods[j]
        a = np.column_stack([np.ones(n), np.sin(k * x[2]), np.cos(k * x[2])])
        for axis in range(2):
            coef, *_ = np.linalg.lstsq(a, r[axis], rcond=None)
            rss = float(np.sum((r[axis] - a @ coef) ** 2))
            tss = float(np.sum((r[axis] - r[axis].mean()) ** 2))
            assert tr.spectrum[axis, j] == pytest.approx(1 - rss / tss, abs=1e-6), (axis, tr.periods[j])


def test_a_period_longer_than_the_travel_is_found_at_its_period():
    """A residual that is a sinusoid of the position over 1.3 times the logged travel (83 mm on a
    64 mm sweep: less than a cycle, what a long guide wave looks like) and a little noise: the
    horizontal spectrum has a peak reported there (within 2 %, the 300-period grid's spacing over a
    factor of 24; the grid reaches 1.5 travels)."""
    x, du = _sweep()
    rng = np.random.default_rng(2)
    span = float(np.ptp(x[2]))
    lam = 1.3 * span
    n = x.shape[1]
    r = np.vstack([0.01 * rng.standard_normal(n), 0.05 * np.sin(2 * math.pi * x[2] / lam + 0.3)])
    r[1] += 0.01 * rng.standard_normal(n)
    tr = trace(x, du, r, StageParameters(), TS)
    found = [p for axis, p, _ in tr.peaks if axis == "horizontal"]
    assert found and min(abs(p / lam - 1) for p in found) < 0.02, found


# --- the result's JSON and text ------------------------------------------------------------------------
def _judgement(name: str, gain: float, verdict: str = "passes"):
    return SimpleNamespace(name=name, verdict=verdict, reason="", gain=gain, z=3.0 * gain, wald=1.0, vif=1.0)


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
    selection = SimpleNamespace(steps=steps, ranking=[("b", 0.31), ("c", 0.11), ("a", 0.02)])
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


def test_the_reports_errors_are_before_and_after_on_the_moving_axes():
    """The text's held-out error line of a moving axis reads before -> after (4 significant digits,
    as the numbers were given); an axis that does not move has no line."""
    text = _stub_diagnosis().report()
    assert "held-out error vertical: 0.0123 -> 0.00456 m/s^2" in text
    assert "horizontal" not in text.split("held-out error", 1)[1]


# --- feedback: what a controller may feed forward ----------------------------------------------------
def _ctx(model, n: int = 400) -> LibraryContext:
    """A LibraryContext of a stand-in log: gaps 16-24 mm, positions -30..40 mm (its valid samples)."""
    t = np.linspace(0.0, 1.0, n)
    x = np.vstack([0.02 + 0.004 * np.sin(7 * t), 0.01 * np.cos(7 * t), 0.005 + 0.035 * np.sin(5 * t), 0 * t])
    return LibraryContext(model, SimpleNamespace(x=x, valid=np.ones(n, dtype=bool), settings={}))


def _effect(cand, coefficients) -> Effect:
    nan = PerAxis.of([float("nan")] * 2)
    return Effect(
        cand.name, "", "", cand.axis, {}, 1.0, 0.1, 5.0, nan, nan, "", "", np.asarray(coefficients), cand
    )


def test_the_compensation_leaves_out_the_share_the_guides_hold_and_the_twin_keeps_it(model):
    """Horizontal guide friction (Coulomb 2 N, viscous 5 N s/m, 60 % held while sticking) at a speed
    of 1 mm/s (stuck: exp(-(v / 2 mm/s)^2) = 0.78): what the regulator feeds forward is the Coulomb
    and viscous force alone, -(F_c tanh(v / v_r) + c v) / M_h (closed form), the held share being
    no force a controller can cancel; the twin of the identified plant has the whole friction, the
    held share of the model's own acceleration added (-h a_model exp(-(v / v_s)^2), from the
    model's f). The stage file carries the same two functions (1e-12: the same arithmetic)."""
    from maglev_oc.diagnosis.feedback import _effects_acceleration, improvement
    from maglev_oc.regression.terms import REVERSAL_SPEED

    ctx = _ctx(model)
    (friction,) = [c for c in friction_candidates(ctx) if c.name == "guide_friction_horizontal"]
    fc, c, h = 2.0, 5.0, 0.6
    e = _effect(friction, [fc, c, h])
    v = 1e-3
    x = np.array([0.02, 0.0, 0.01, v])
    u = np.array([0.3, 1.2])
    mh = model.params.mass_horizontal
    own = -(fc * math.tanh(v / REVERSAL_SPEED) + c * v) / mh
    a_model = float(np.asarray(ca.DM(model.f(x, u))).ravel()[3])
    held = -h * a_model * math.exp(-((v / REVERSAL_SPEED) ** 2))
    comp = np.asarray(_effects_acceleration([e], with_inputs=False)(x)).ravel()
    twin = np.asarray(_effects_acceleration([e], with_inputs=True)(x, u)).ravel()
    np.testing.assert_allclose(comp, [0.0, own], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(twin, [0.0, own + held], rtol=1e-12, atol=1e-15)
    # a ratio of errors above 1 is an improvement: before / after, per axis
    study = SimpleNamespace(
        before=SimpleNamespace(mean_error=PerAxis.of([2e-6, 9e-6])),
        after=SimpleNamespace(mean_error=PerAxis.of([1e-6, 3e-6])),
    )
    np.testing.assert_allclose(improvement(study), [2.0, 3.0], rtol=1e-12)


# --- the refit ----------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def horizontal_all(model):
    """(data, design): the horizontal sweep with viscous friction (gap held: the vertical axis does
    not move), all four constants estimated beside the friction, a quarter held out."""
    data = prepare([_log(model, friction=RATE_FRICTION)], bandwidth=10.0)
    train, hold = data.masks(0.25)
    return data, build_design(data, model, terms=[_friction_candidate().term], fit=train, holdout=hold)


def test_the_constants_of_an_axis_that_does_not_move_are_unknown_even_when_the_fit_holds_them(
    model, horizontal_all
):
    """C2..C4 are in the fit (every constant estimated, as the diagnosis does) but the vertical axis
    did not move: they are reported unknown (NaN value and error), not the fit's 0 ± 0 of a dead
    column; C1 is the fit's."""
    data, design = horizontal_all
    assert not data.moving[0] and data.moving[1]
    fit = fit_subset(design, ["base", "viscous_horizontal"])
    assert fit.names[:4] == ("C1", "C2", "C3", "C4")
    c = constants_of(design, fit, model)
    assert c["C1"].value == fit.value("C1")
    for name in ("C2", "C3", "C4"):
        assert math.isnan(c[name].value) and math.isnan(c[name].stderr), (name, c[name])


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


# --- physical sizes of the guides' and the currents' candidates --------------------------------------
def test_a_guide_slopes_gap_change_is_over_the_logged_travel(model):
    """A guide slope of 2 mrad on a log whose positions run -30..40 mm (not centred on zero): the
    gap error it reports over the travel is the slope times the travel between the 1st and 99th
    percentiles of the logged positions (numpy here), with the slope's standard error scaled alike;
    the same change is what the term's vertical acceleration sees, through the model's gap
    sensitivity, between those two positions (1e-9: the same arithmetic in another order)."""
    from maglev_oc.diagnosis.guides import misalignment_candidate

    ctx = _ctx(model)
    cand = misalignment_candidate(ctx)
    slope = 2e-3
    p = cand.term.physical_parameters(np.array([slope]), np.array([[1e-8]]), {})
    lo, hi = np.percentile(ctx.fitted_states[2], [1, 99])
    assert p["gap_change_over_travel"].value == pytest.approx(slope * (hi - lo), rel=1e-12)
    assert p["gap_change_over_travel"].stderr == pytest.approx(1e-4 * (hi - lo), rel=1e-12)
    u = np.array([0.3, 1.2])

    def vertical(x3):
        x = np.array([0.02, 0.0, x3, 0.0])
        return float(cand.term.acceleration([slope])(x, u, np.zeros(2)).full()[0, 0])

    sensitivity = float(ctx.gap_sensitivity(ca.DM([0.02, 0.0, 0.0, 0.0]), u)[0])
    assert vertical(hi) - vertical(lo) == pytest.approx(
        sensitivity * p["gap_change_over_travel"].value, rel=1e-9
    )


@pytest.mark.parametrize("factor", [0.85, 1.2])
def test_the_waviness_period_is_refined_on_both_sides_of_the_periodograms_guess(
    model, horizontal_all, factor
):
    """A residual that is exactly a guide waviness (0.1 mm at 40 mm, its own acceleration through
    the log's filter, no noise) and a periodogram guess 15 % too long or 20 % too short: the scan
    (+-25 % of the guess, 41 periods) returns the planted period, a point of its grid (1e-9: the
    grid's own rounding)."""
    from maglev_oc.diagnosis.guides import refine_waviness_period, waviness_candidate

    data, design = horizontal_all
    true_period = 0.040
    guess = true_period / factor
    term = waviness_candidate(model, data, true_period).term
    acc = term.acceleration([1e-4, 0.5e-4]).map(data.n)(data.x, data.u, data.du)
    residual = data.filter(np.asarray(acc))
    found = refine_waviness_period(model, data, residual, np.ones(2), design.fit, guess)
    assert found == pytest.approx(true_period, rel=1e-9)


def _bounded(model, name):
    """The candidate ``name`` of the stand-in log's context (:func:`_ctx`)."""
    from maglev_oc.diagnosis.currents import commutation_candidate
    from maglev_oc.diagnosis.guides import gap_offset_candidate, misalignment_candidate

    ctx = _ctx(model)
    return {
        "gap_sensor_offset": gap_offset_candidate(ctx),
        "guide_misalignment": misalignment_candidate(ctx),
        "commutation_offset": commutation_candidate(ctx),
    }[name]


@pytest.mark.parametrize(
    "name, parameter, bound",
    [
        ("gap_sensor_offset", "offset", 2e-3),  # a tenth of the papers' 20 mm gap
        ("guide_misalignment", "slope", 0.05),  # 50 mrad: 5 mm over a 100 mm travel
        ("commutation_offset", "angle", 0.35),  # 20 degrees, where the first-order mixing still holds
    ],
)
def test_a_geometry_or_commutation_error_beyond_its_physical_bound_is_refused_on_either_side(
    model, name, parameter, bound
):
    """Each candidate's parameter (the commutation offset's two axes' angles alike), fitted 5 %
    inside its bound (either sign), is plausible, and 5 % beyond it is refused with a reason naming
    the bound (the library's stated bounds)."""
    cand = _bounded(model, name)
    n = len(cand.term.parameter_names)
    for sign in (1.0, -1.0):
        for factor, ok in ((0.95, True), (1.05, False)):
            q = np.full(n, sign * factor * bound)
            p = cand.term.physical_parameters(q, 1e-14 * np.eye(n), {})
            assert p[parameter].value == pytest.approx(q[0], rel=1e-12)
            reason = cand.plausible(p)
            assert (reason is None) == ok, (name, sign, factor, reason)
            if not ok:  # the reason names what is beyond its bound, in words
                words = {"gap_sensor_offset": "gap offset", "guide_misalignment": "guide slope"}
                assert reason.startswith(words.get(name, reason.split(" of ")[0])), reason
                assert f"beyond the physical bound {bound:g}" in reason, reason


# --- the pipeline's small helpers ----------------------------------------------------------------------
def test_a_slope_and_a_waviness_found_together_are_one_misalignment_with_their_joint_rms():
    """A guide slope and a waviness found together are reported as one misalignment whose held-out
    contribution per axis is the RMS of the two accelerations added: two orthogonal signals here (a
    line in the position and a cosine of it over whole periods, odd and even), numpy computing the
    RMS of their sum (within 1e-3: the sampled cosine's mean over the grid), with the waviness's
    amplitude and period among the misalignment's parameters and the waviness no longer reported
    on its own."""
    from maglev_oc.diagnosis.pipeline import _merged_guide_geometry

    x3 = np.linspace(-0.03, 0.03, 20001)
    line, wave = x3 / np.sqrt(np.mean(x3**2)), np.cos(2 * math.pi * x3 / 0.02) * math.sqrt(2)
    slope_rms, wave_rms = np.array([0.03, 0.01]), np.array([0.04, 0.02])
    joint = np.sqrt(np.mean((np.outer(slope_rms, line) + np.outer(wave_rms, wave)) ** 2, axis=1))

    masses = np.array([4.35, 1.6])  # [kg] per axis: an effect's RMS force is its acceleration times these

    def effect(name, rms, params):
        return dataclasses.replace(
            _effect(SimpleNamespace(name=name, axis="both"), [0.0]),
            parameters=params,
            finding=name,
            contribution_rms=PerAxis.of(rms),
            force_rms=PerAxis.of(np.asarray(rms) * masses),
        )

    amplitude, period = Estimate(1e-4, 1e-5, "m"), Estimate(0.02, 0.0, "m")
    forces = {
        f"rms_force_{a}": Estimate(f, float("nan"), "N")
        for a, f in zip(("vertical", "horizontal"), slope_rms * masses, strict=True)
    }
    slope = effect("guide_misalignment", slope_rms, {"slope": Estimate(1e-3, 1e-4, "rad"), **forces})
    wavy = effect("guide_waviness_20mm", wave_rms, {"amplitude": amplitude, "period": period})
    other = effect("cable_carrier_force", [0.0, 0.005], {})
    merged = _merged_guide_geometry([slope, other, wavy])
    assert [e.name for e in merged] == ["guide_misalignment", "cable_carrier_force"]
    np.testing.assert_allclose(np.asarray(merged[0].contribution_rms), joint, rtol=1e-3)
    assert merged[0].parameters["waviness_amplitude"] == amplitude
    assert merged[0].parameters["waviness_period"] == period
    assert merged[0].parameters["slope"] == slope.parameters["slope"]
    # the merged force is the merged acceleration times the mass, in the effect and in its parameters
    # (the slope's alone was kept before: force_rms_N no longer matched contribution_rms)
    force = np.asarray(merged[0].contribution_rms) * masses
    np.testing.assert_allclose(np.asarray(merged[0].force_rms), force, rtol=1e-12)
    for a, axis in enumerate(("vertical", "horizontal")):
        assert merged[0].parameters[f"rms_force_{axis}"].value == pytest.approx(force[a], rel=1e-12)


def test_a_per_axis_number_of_an_axis_that_does_not_move_is_unknown():
    """The errors before and after are per axis, NaN (null in the JSON) where the axis did not move."""
    from maglev_oc.diagnosis.pipeline import _per_axis

    got = _per_axis(np.array([0.2, 0.3]), np.array([False, True]))
    assert math.isnan(got.vertical) and got.horizontal == 0.3
    got = _per_axis(np.array([0.2, 0.3]), np.array([True, False]))
    assert got.vertical == 0.2 and math.isnan(got.horizontal)


# --- the regression layer -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def twin_design(model, twin_log):
    """The twin's log (its logged currents carry amplifier noise) with C1..C4, a quarter held out."""
    data = prepare([twin_log], bandwidth=10.0)
    fit_mask, hold = data.masks(0.25)
    return build_design(data, model, fit=fit_mask, holdout=hold)


def test_the_fits_chi_square_is_the_weighted_residual_sum_of_squares_with_compensation(twin_design):
    """On the twin's log (noisy logged currents: the fit removes an errors-in-variables part, so its
    coefficients are not the plain least-squares ones) the fit's chi-square is the weighted residual
    sum of squares of its fitted rows, recomputed with numpy from the columns and the coefficients,
    and the plain covariance is chi^2 / (rows - parameters) times the compensated normal matrix's
    inverse (rtol 1e-9: sums of 10^4 squares in another order)."""
    design = twin_design
    fit = fit_subset(design, ["base"])
    assert fit.compensation == 1.0 and np.any(design.noise != 0)
    x, y = _rows(design, fit.index, design.fit)
    rss = float(np.sum((y - x @ fit.coef) ** 2))
    assert fit.chi_square == pytest.approx(rss, rel=1e-9)
    idx = fit.index
    h = design.gram[:, idx][:, :, idx].sum(axis=0) - design.noise[:, idx][:, :, idx].sum(axis=0)
    np.testing.assert_allclose(fit.naive, rss / (y.size - idx.size) * np.linalg.inv(h), rtol=1e-9)


def test_an_ordinary_least_squares_fits_long_run_covariance_has_no_errors_in_variables_part(twin_design):
    """compensate=False on the same log: the sandwich H^-1 S H^-1 of the plain scores, H = X'X and the
    scores sum_a w_a^2 x_a r_a with no errors-in-variables correction (nothing was removed), S the
    mean over j = 1..m of Re(D_j D_j^*) of their DFT (numpy's FFT, m = max(4, floor(0.25 Hz x
    duration))); rtol 1e-7, an FFT against the code's tabulated DFT (as in the second round's test
    of the compensated fit)."""
    design = twin_design
    fit = fit_subset(design, ["base"], compensate=False)
    assert fit.compensation == 0.0
    idx = fit.index
    x = design.columns[idx][:, :, design.fit]
    r = design.target[:, design.fit] - np.einsum("p,pan->an", fit.coef, x)
    scores = np.einsum("pan,an->pn", x, r * design.weights[:, None] ** 2)
    m = max(4, math.floor(0.25 * scores.shape[1] * design.prepared.sample_time))
    f = np.fft.fft(scores, axis=1)[:, 1 : m + 1]
    meat = (f @ f.conj().T).real / m
    hinv = np.linalg.inv(design.gram[:, idx][:, :, idx].sum(axis=0))
    np.testing.assert_allclose(fit.covariance, hinv @ meat @ hinv, rtol=1e-7, atol=0)


def test_sticking_guides_hold_at_most_the_whole_force_and_never_reverse_it(model):
    """held_by_guides multiplies a term's acceleration by 1 - h exp(-(v / v_s)^2): at rest with a
    share of 0.6 the force is 40 % of itself, at v = v_s 1 - 0.6 / e, at +-2 v_s 1 - 0.6 e^-4 in
    either direction (closed form); a share fitted
    beyond 1 holds the whole force (the guides cannot push back harder than they are pushed: static
    friction only opposes) and a negative one holds nothing (1e-12: the same arithmetic)."""
    from maglev_oc.regression.terms import REVERSAL_SPEED, constant_force, held_by_guides

    term = constant_force(model.params, "horizontal")

    def acc(share, v):
        held = held_by_guides(term, {"horizontal": share})
        x = np.array([0.02, 0.0, 0.0, v])
        return float(held.acceleration([1.0])(x, np.zeros(2), np.zeros(2)).full()[1, 0])

    free = 1.0 / model.params.mass_horizontal
    assert acc(0.6, 0.0) == pytest.approx(0.4 * free, rel=1e-12)
    assert acc(0.6, REVERSAL_SPEED) == pytest.approx((1 - 0.6 / math.e) * free, rel=1e-12)
    for v in (2 * REVERSAL_SPEED, -2 * REVERSAL_SPEED):  # either direction alike
        assert acc(0.6, v) == pytest.approx((1 - 0.6 * math.exp(-4)) * free, rel=1e-12)
    assert acc(1.5, 0.0) == pytest.approx(0.0, abs=1e-15)
    assert acc(-0.5, 0.0) == pytest.approx(free, rel=1e-12)


def test_a_linear_physical_quantitys_standard_error_is_not_negative_for_a_negative_scale():
    """linear_physical: value p k and standard error sqrt(var p) |k| (a standard error is a spread,
    of either sign of the scale)."""
    from maglev_oc.regression.terms import linear_physical

    out = linear_physical([("force", "N", -2.0), ("length", "m", 1e-3)])(
        np.array([0.5, 3.0]), np.diag([0.04, 0.09]), {}
    )
    assert (out["force"].value, out["force"].stderr, out["force"].unit) == (-1.0, 0.4, "N")
    assert out["length"].value == pytest.approx(3e-3) and out["length"].stderr == pytest.approx(3e-4)


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
