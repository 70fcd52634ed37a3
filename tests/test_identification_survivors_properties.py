"""Properties of ``maglev_oc.identification`` that a wrong answer would break (issue 21: tests
written against the survivors of a mutation-testing run, each for the property the code should
have, not for the mutated token).

* output error: a too-short log is refused with the length two segments need; the residual RMS
  and the sample count of a fit over two logs pool both logs;
* experiment design: PRBS references are consistent (accelerations integrate to the rates); the
  gap sweep's description names its ripple in mm; a prediction's nominal values and its RMS
  current; the D-optimal design's reference is the one its settings describe;
* the study's vertical runs: the cogging curves cover every gap, the true cogging is the twin's;
* twin experiments run without a C compiler; the eps-trend study runs the twin it is given.

Each test is quick (a few short twin runs at most).
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from maglev_oc.errors import InputError
from maglev_oc.identification import study
from maglev_oc.identification.design import (
    EFFECT,
    CurrentBudget,
    ExperimentDesigner,
    MultisineShape,
    Prediction,
    design_experiment,
    gap_sweep_reference,
    multisine_reference,
    prbs_reference,
)
from maglev_oc.identification.eps_trend import eps_trend_study
from maglev_oc.identification.experiments import (
    COMPILED_RUN,
    LOG_RATE_HZ,
    TWIN_TRUTH,
    excitation_log,
    verification_effects,
)
from maglev_oc.identification.layout import CONSTANT_NAMES
from maglev_oc.identification.output_error import DEFAULT_SEGMENT, MultipleShooting
from maglev_oc.sim.twin import RigTwin

TRUTH = dict(zip(CONSTANT_NAMES, TWIN_TRUTH.as_array(), strict=True))


# --- output error ----------------------------------------------------------------------------------------
def test_a_too_short_log_is_refused_with_the_length_two_segments_need(model, twin_log):
    """The multiple-shooting fit needs two whole segments; a shorter log is refused with a message
    naming the length that is enough, and a log of exactly that length is accepted (one sample
    fewer is not). The length is 2 segments = 2 x 50 samples at 1 kHz = 0.1 s; the message prints
    it with ``:g`` (6 significant digits), hence the relative tolerance 1e-5."""
    dt = twin_log.sample_time
    m = round(DEFAULT_SEGMENT / dt)
    with pytest.raises(InputError) as info:
        MultipleShooting(twin_log.index_slice(0, 2 * m), model)
    found = re.search(r"a log of ([0-9.eE+-]+) s or more", str(info.value))
    assert found, str(info.value)
    needed = float(found.group(1))
    assert needed == pytest.approx(2 * DEFAULT_SEGMENT, rel=1e-5)
    samples = round(needed / dt) + 1  # a log spanning ``needed`` seconds
    ms = MultipleShooting(twin_log.index_slice(0, samples), model)
    assert [s.J for s in ms.segments] == [2]
    with pytest.raises(InputError, match="need at least 2"):
        MultipleShooting(twin_log.index_slice(0, samples - 1), model)


def test_the_residual_rms_over_two_logs_pools_both_logs(model, twin_log):
    """A fit over two logs reports one RMS per axis over the residuals of both logs and counts the
    samples of both: n_samples is the number of residual samples the result holds (NaN past the
    last segment excluded), and RMS^2 * n_samples is the sum of squares over both logs. The pooled
    RMS lies between the two logs' own (the logs are of different lengths and parts of the run, so
    their RMS differ). The solve's convergence does not matter here (two iterations from the
    truth); the tolerance 1e-9 is rounding of the sums."""
    a = twin_log.index_slice(0, 1500)
    b = twin_log.index_slice(3000, 4200)
    fit = MultipleShooting([a, b], model).fit(initial=TRUTH, max_iterations=2)
    assert len(fit.residuals) == 2
    used = [np.isfinite(r[0]) for r in fit.residuals]
    assert fit.n_samples == sum(int(u.sum()) for u in used)
    for i, axis in enumerate(("vertical", "horizontal")):
        sums = [float(np.sum(r[i, u] ** 2)) for r, u in zip(fit.residuals, used, strict=True)]
        assert fit.residual_rms[axis] ** 2 * fit.n_samples == pytest.approx(sum(sums), rel=1e-9)
        own = [math.sqrt(s / u.sum()) for s, u in zip(sums, used, strict=True)]
        assert min(own) < fit.residual_rms[axis] < max(own)


# --- experiment design: references --------------------------------------------------------------------
def test_prbs_reference_accelerations_and_rates_integrate_to_the_set_points():
    """A reference file's rows are a set-point, its rate and its acceleration: on both axes the
    trapezoidal integral of the acceleration is the rate and that of the rate is the set-point.
    Tolerance: the filtered PRBS's acceleration jumps at every bit (w^2 times the step), where the
    trapezoid errs by up to half a jump times a 1 ms sample; over 10 s that adds up to 0.6 % of
    the peak rate (measured), allowed 2 %; the rate is smooth (5e-6 of the range measured, 1e-4
    allowed)."""
    ref = prbs_reference(10.0)
    v = ref.values
    for row in (0, 3):
        rate = v[row + 1, 0] + cumulative_trapezoid(v[row + 2], ref.t, initial=0)
        assert np.max(np.abs(rate - v[row + 1])) < 0.02 * np.max(np.abs(v[row + 1]))
        point = v[row, 0] + cumulative_trapezoid(v[row + 1], ref.t, initial=0)
        assert np.max(np.abs(point - v[row])) < 1e-4 * np.ptp(v[row])


def test_gap_sweep_description_names_its_ripple_in_millimetres():
    """The gap sweep's description states its gap range and its ripple in mm (3 mm given in metres
    as 3e-3): what a reader of the design file sees of the reference."""
    ref = gap_sweep_reference(10.0, ripple=3e-3)
    assert "10-25 mm" in ref.description
    assert "with a 3 mm ripple" in ref.description


# --- experiment design: predictions ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def designer(model) -> ExperimentDesigner:
    return ExperimentDesigner(model)


@pytest.fixture(scope="module")
def short_prediction(designer):
    """(run, prediction with the constant vertical force) of a 5 s multisine on the nominal twin."""
    ref = multisine_reference(5.0)
    run = designer.simulate(ref)
    return run, designer.predict(ref, effect=True, run=run)


def test_prediction_nominal_values_are_the_models_constants_and_one_newton(model, short_prediction):
    """A prediction's relative standard errors are relative to the nominal values: C1..C4 at the
    model's constants, and the constant force, whose nominal value is 0 N, per newton (nominal
    1 N), so its relative standard error is its standard error in N. Exact: the same floats."""
    _, pred = short_prediction
    assert pred.names == (*CONSTANT_NAMES, EFFECT)
    assert list(pred.nominal[:4]) == [getattr(model.constants, c) for c in CONSTANT_NAMES]
    rel = pred.to_dict()["relative_stderr"]
    assert np.isfinite(pred.stderr[EFFECT]) and pred.stderr[EFFECT] > 0
    assert rel[EFFECT] == pred.stderr[EFFECT]
    for c in CONSTANT_NAMES:
        assert rel[c] == pytest.approx(pred.stderr[c] / abs(getattr(model.constants, c)), rel=1e-12)


def test_prediction_rms_current_combines_the_axes_rms(short_prediction):
    """The RMS of the current magnitude |i| = hypot(i_q, i_d) satisfies RMS(|i|)^2 = RMS(i_q)^2 +
    RMS(i_d)^2 (Pythagoras sample by sample), and lies below the peak magnitude. Tolerance 1e-12:
    rounding of the means."""
    run, pred = short_prediction
    assert run.success
    per_axis = float(np.nanmean(run.u[0] ** 2) + np.nanmean(run.u[1] ** 2))
    assert pred.rms_current**2 == pytest.approx(per_axis, rel=1e-12)
    assert pred.rms_current <= np.nanmax(np.hypot(run.u[0], run.u[1]))


class _StubDesigner:
    """Stands for :class:`ExperimentDesigner` in :func:`design_experiment`: every reference family
    is taken at fixed excursions (no simulation), every design predicts the same information and
    the papers' excitation less, so the design's choice is the D-optimal search's own."""

    V, H = 3e-3, 30e-3  # [m] the excursions ``fit_to_budget`` settles on

    @staticmethod
    def _prediction(log_det: float) -> Prediction:
        return Prediction(
            names=CONSTANT_NAMES,
            nominal=np.asarray(TWIN_TRUTH.as_array()),
            covariance=np.diag((0.01 * np.asarray(TWIN_TRUTH.as_array())) ** 2),
            log_det=log_det,
            peak_current=np.array([1.0, 3.0]),
            rms_current=1.0,
            gap_range=np.array([0.017, 0.023]),
            position_range=np.array([-0.03, 0.03]),
            violations=(),
        )

    def papers_budget(self, duration, *, seed=0):
        return CurrentBudget(vertical=3.0, horizontal=1.0), self._prediction(-1.0)

    def predict(self, reference, *, effect=False, budget=None, run=None):
        return self._prediction(-1.0)

    def fit_to_budget(self, make, budget, *, effect=False, iterations=4):
        return make(self.V, self.H), self._prediction(0.0)


def test_doptimal_reference_is_the_one_its_settings_describe(model):
    """The D-optimal design's settings name the multisine shape of each axis; the reference it
    hands out is the multisine of exactly those shapes (at the excursions the budget allowed). The
    grid holds one shape, not the default one, so both axes carry it. Exact: the same computation."""
    grid = (MultisineShape((0.1, 3.0), 6, 0.5),)
    design = design_experiment("doptimal", 10.0, model=model, designer=_StubDesigner(), grid=grid)

    def shape(axis):
        d = design.settings[axis]
        return MultisineShape(tuple(d["band_hz"]), d["tones"], d["tilt"])

    assert shape("vertical") == shape("horizontal") == grid[0]
    expected = multisine_reference(
        10.0,
        vertical=shape("vertical"),
        horizontal=shape("horizontal"),
        gap_amplitude=_StubDesigner.V,
        position_amplitude=_StubDesigner.H,
    )
    np.testing.assert_array_equal(design.reference.values, expected.values)


# --- the identification study's vertical runs -------------------------------------------------------------
PHASE = 0.4
"""[rad] A cogging phase off zero, so that the slot angle's sine at the cogging position is not +-1."""


@pytest.fixture(scope="module")
def vertical(model, truth_model):
    """The study's vertical-only runs (5 s each) on a twin whose cogging has phase :data:`PHASE`."""
    veff = verification_effects()
    veff = dataclasses.replace(veff, cogging=dataclasses.replace(veff.cogging, phase=PHASE))
    return veff, study._vertical_runs(study._Clock(), model, truth_model, veff, 5.0, 1)


def test_cogging_curves_cover_every_cogging_gap(vertical):
    """The cogging force of the NPFSI fits, of the equation-error fits and the true one are each
    given at every gap of the cogging grid, finite; the two estimates agree in sign with the truth
    at every gap (the cogging there is 0.3-4.7 N; the 5 s runs' estimates are within 20 % of it,
    measured, so the sign is certain)."""
    _, out = vertical
    gaps = out["cogging_gaps"]
    for key in ("cogging_xi_npfsi", "cogging_xi_equation_error", "cogging_xi_true"):
        xi = np.asarray(out[key])
        assert xi.shape == gaps.shape, key
        assert np.all(np.isfinite(xi)), key
    for key in ("cogging_xi_npfsi", "cogging_xi_equation_error"):
        assert np.all(np.sign(out[key]) == np.sign(out["cogging_xi_true"])), key


def test_true_cogging_is_the_twins_normal_force_at_the_cogging_position(model, truth_model, vertical):
    """The true cogging curve is the normal cogging force the twin applies with the mover at the
    cogging position (1.5 slot pitches) at rest: M_v times the drop of its vertical acceleration
    when the cogging is switched off (RigTwin.acceleration, zero current and friction). Tolerance
    1e-9 of the force: rounding of the two accelerations (about 10 m/s^2) against a 0.3-4.5 N force
    over a 2.5 kg mover."""
    veff, out = vertical
    pos = 1.5 * model.params.slot_pitch
    with_cog = RigTwin(truth_model, veff).acceleration
    without = RigTwin(truth_model, dataclasses.replace(veff, cogging=None)).acceleration
    m_v = truth_model.params.mass_vertical
    for gap, xi in zip(out["cogging_gaps"], out["cogging_xi_true"], strict=True):
        x = [gap, 0.0, pos, 0.0]
        drop = float(without(x, [0.0, 0.0], [0.0, 0.0])[0] - with_cog(x, [0.0, 0.0], [0.0, 0.0])[0])
        assert xi == pytest.approx(m_v * drop, rel=1e-9, abs=1e-9)


# --- twin experiments and the eps-trend study -------------------------------------------------------------
def test_a_long_excitation_run_works_without_a_c_compiler(monkeypatch, model, truth_model):
    """Runs of COMPILED_RUN seconds or more use generated C where a compiler is found; on a
    machine without one (no $CC, empty PATH) they run in CasADi's virtual machine and give the whole
    log (module docstring of ``identification.experiments``)."""
    monkeypatch.delenv("CC", raising=False)
    monkeypatch.setenv("PATH", "")
    log = excitation_log(truth_model, duration=COMPILED_RUN, seed=3, controller_model=model)
    assert log.n == round(COMPILED_RUN * LOG_RATE_HZ)
    assert np.all(np.isfinite(log.x[[0, 2]]))  # the encoders' gap and position


def test_eps_trend_study_runs_the_twin_of_the_given_truth(model):
    """The eps-trend study identifies the twin whose constants it is given: with C1 25 % above and
    C2 15 % below the default twin's, the Table III NPFSI estimates (study's effects, eps = 0.01)
    are within 5 % of the given constants (on 5 s runs: 3 % for C1, 0.1 % for C2 measured), far
    from the default twin's."""
    given = TWIN_TRUTH.replace(C1=TWIN_TRUTH.C1 * 1.25, C2=TWIN_TRUTH.C2 * 0.85)
    st = eps_trend_study(model, truth_constants=given, duration=5.0, vertical_duration=5.0)
    assert st.truth["C1"] == given.C1
    for c in ("C1", "C2"):
        estimate = st.default_table3.value(c, 0.01)
        assert estimate == pytest.approx(getattr(given, c), rel=0.05), c
