"""Properties of the identification study's experiments on the twin (``maglev_oc.identification
.study`` and ``experiments``, the coverage study and the twin check), checked against twin runs
and fits repeated here:

- the coverage counts a z on the bound as within, reports z with both standard errors (the HAC
  ones in percent of the truth) and records the length of its runs;
- the study delays the currents by the amplifier's lag and half a loop period, adds repeated
  steps' times, centres the vertical runs on the vertical gap, runs its fixed-gap and equilibrium
  runs with the effects and positions it was given (PIDs placed on the controller model), and its
  cogging curves cover every gap with the twin's true cogging;
- long excitation runs work without a C compiler;
- the twin check plays the plant it is given, summarises its fits by mean and sample deviation,
  and a failed run says so with its seeds.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import maglev_oc.identification.design as design
from maglev_oc.identification import study
from maglev_oc.identification.design import (
    REFERENCE_RATE_HZ,
    SampledReference,
    check_on_twin,
    papers_reference,
)
from maglev_oc.identification.equation_error import EquationError
from maglev_oc.identification.experiments import (
    COMPILED_RUN,
    FIXED_GAPS,
    LOG_RATE_HZ,
    TWIN_TRUTH,
    excitation_log,
    fixed_gap_logs,
    identification_effects,
    verification_effects,
)
from maglev_oc.identification.layout import CONSTANT_NAMES
from maglev_oc.identification.study import COMMAND_TO_CURRENT_DELAY, Coverage, _coverage
from maglev_oc.identification.study import _Clock as StudyClock
from maglev_oc.identification.study import _Clock as _StudyClock
from maglev_oc.model.hardware import RIG_SAMPLE_TIME, STOPPER_GAP
from maglev_oc.model.stage import StageModel
from maglev_oc.results import check_result
from maglev_oc.sim.effects import CurrentAmplifier
from maglev_oc.sim.scenarios import excitation_scenario
from maglev_oc.sim.twin import RigTwin
from tests._identification_cases import _prediction


# --- the coverage study ----------------------------------------------------------------------------------
def test_the_coverage_counts_a_z_on_the_bound_as_within():
    z = np.array([[2.0, 1.0], [3.0, -2.0], [-0.5, 2.5], [1.0, -1.0]])
    cov = Coverage(("C1", "C2"), (1, 2, 3, 4), 6.0, z, z, np.zeros_like(z), np.ones_like(z))
    np.testing.assert_allclose(cov.fraction_within(2.0), [0.75, 0.75])
    np.testing.assert_allclose(cov.fraction_within(1.0), [0.5, 0.5])


def test_the_coverage_runs_report_z_with_both_standard_errors(model, truth_model):
    # one 6 s run: the study's z and z_naive are the fit's errors over its HAC and its plain
    # standard errors (the fit redone here on the same seed-100 log: the same numbers to round-off)
    cov = _coverage(_StudyClock(), model, truth_model, 1, 6.0)
    log = excitation_log(truth_model, duration=6.0, seed=cov.seeds[0], controller_model=model)
    fit = EquationError(log, model).fit()
    truth = dict(zip(CONSTANT_NAMES, truth_model.constants.as_array(), strict=True))
    err = np.array([fit.values[k] - truth[k] for k in CONSTANT_NAMES])
    np.testing.assert_allclose(cov.z[0], err / [fit.stderr[k] for k in CONSTANT_NAMES], rtol=1e-9)
    np.testing.assert_allclose(cov.z_naive[0], err / [fit.stderr_naive[k] for k in CONSTANT_NAMES], rtol=1e-9)
    assert not np.allclose(cov.z[0], cov.z_naive[0], rtol=0.05)  # the two errors differ here


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


def test_the_coverage_standard_errors_are_the_hac_ones_in_percent_of_the_truth(model, truth_model):
    # identity: error_pct / z = 100 (v - t) / t / ((v - t) / s) = 100 s / t with s the HAC standard
    # error that z uses (1e-9: round-off of the divisions)
    cov = _coverage(StudyClock(), model, truth_model, 1, 6.0)
    np.testing.assert_allclose(cov.stderr_pct, cov.error_pct / cov.z, rtol=1e-9)


# --- study -----------------------------------------------------------------------------------------
def test_the_study_delays_the_currents_by_the_amplifiers_lag_and_half_a_loop_period():
    # the twin's amplifier is first order at 1 kHz: time constant 1 / (2 pi 1000) = 0.159 ms (not
    # 1 / 1000 s); a zero-order hold of the 5 kHz loop delays by half its 0.2 ms period
    lag = CurrentAmplifier().time_constant
    assert lag == pytest.approx(1 / (2 * np.pi * 1000.0), rel=1e-12)
    assert COMMAND_TO_CURRENT_DELAY == pytest.approx(lag + RIG_SAMPLE_TIME / 2, rel=1e-12)


# --- the identification study ------------------------------------------------------------------------------
def test_the_coverage_records_the_length_of_its_runs(model, truth_model):
    """Coverage.duration is how long each coverage run is (the report prints 'k x duration s'): one run of
    5 s, seed 100, whose z-scores are those of an equation-error fit on a 5 s twin run of that seed made here
    (same arithmetic: equal to round-off, 1e-9)."""
    cov = study._coverage(study._Clock(), model, truth_model, 1, 5.0)
    assert cov.duration == 5.0 and f"{cov.duration:g}" == "5"
    assert cov.seeds == (100,) and cov.z.shape == (1, len(CONSTANT_NAMES))
    log = excitation_log(truth_model, duration=5.0, seed=100, controller_model=model)
    tv = dict(zip(CONSTANT_NAMES, truth_model.constants.as_array(), strict=True))
    z = EquationError(log, model).fit().z_scores(tv)
    np.testing.assert_allclose(cov.z[0], [z[k] for k in CONSTANT_NAMES], rtol=1e-9, atol=1e-12)


def test_the_vertical_runs_are_centred_on_the_vertical_gap(model, truth_model):
    """The vertical-only runs excite about VERTICAL_GAP (16 mm, where the cogging acts): the logged gap
    follows the papers' sum-of-sines reference centred there. Tolerance 0.5 mm on the mean gap against the
    reference's mean: the PIDs' tracking error (measured 0.3 mm RMS, its mean 4 um), well below the 4 mm to
    the default 20 mm centre."""
    out = study._vertical_runs(study._Clock(), model, truth_model, verification_effects(), 5.0, 1)
    for key, offset in (("vertical_log", 1), ("cogging_log", 2)):
        log = out[key]
        scenario = excitation_scenario(5.0, seed=1 + offset, gap_offset=study.VERTICAL_GAP)
        ref = scenario.reference.sample(log.t)[0]
        assert abs(np.mean(log.x[0]) - np.mean(ref)) < 0.5e-3, key


# --- the identification study's clock ----------------------------------------------------------------------
def test_a_repeated_step_reports_the_sum_of_its_runs_times(monkeypatch):
    """_Clock docstring: wall times by step name, repeated steps add up (the study simulates its vertical
    runs and runs NPFSI in several calls under one name). perf_counter is replaced by a clock that
    advances 1, 2, 4 s per call, so the sums are exact."""
    ticks = iter([0.0, 1.0, 10.0, 12.0, 20.0, 24.0])
    monkeypatch.setattr(study.time, "perf_counter", lambda: next(ticks))
    clock = study._Clock()
    assert clock("simulate", lambda: "a") == "a"
    clock("simulate", lambda: None)
    clock("fit", lambda: None)
    clock.add("fit", 0.5)
    assert clock.times == {"simulate": 3.0, "fit": 4.5}


# --- the study's fixed-gap runs ------------------------------------------------------------------------
def test_the_studys_fixed_gap_runs_use_the_effects_it_was_given(model, truth_model):
    """run_study passes its verification effects (the rig's cogging, 000 eq. (9)) to every experiment
    after the excitation fits. The fixed-gap step's parabolas are fitted to the runs simulated with those
    effects: each parabola's position trace is the run's (bit for bit: the same simulation, seeded by the
    study's seed). The effects are not lost: at 10 mm the cogging (1.5 N x (15/10)^3, 5 N) moves the
    mover beyond the 10 um encoder's resolution, so the run differs from one without it."""
    seed = 1
    veff = verification_effects()
    out = study._fixed_gaps(study._Clock(), model, truth_model, veff, seed)
    runs = fixed_gap_logs(truth_model, FIXED_GAPS, effects=veff, seed=seed)
    assert len(out["parabolas"]) == len(runs) == len(FIXED_GAPS)
    for parabola, run, gap in zip(out["parabolas"], runs, FIXED_GAPS, strict=True):
        assert parabola.gap == gap
        np.testing.assert_array_equal(parabola.x3, run.x[2])
    plain = fixed_gap_logs(truth_model, FIXED_GAPS[:1], effects=identification_effects(), seed=seed)[0]
    first = out["parabolas"][0].x3
    assert first.size != plain.n or not np.array_equal(first, plain.x[2])


class _Stop(Exception):
    pass


def test_the_studys_equilibrium_runs_are_at_x3_0_and_on_the_cogging_position(model, truth_model, monkeypatch):
    """The study's two equilibrium-current runs are simulated at x3 = 0 and at 1.5 slot pitches
    (28.6 mm, where the slot-pitch cogging of eq. (9) is at its extreme; the papers compare the two
    to show the cogging's share of the holding current). The simulator is replaced by a recorder
    that stops the study after the second call, so only the positions asked for are checked."""
    positions = []

    def record(truth, gaps, **kw):
        positions.append(kw.get("position", "not given"))
        if len(positions) == 2:
            raise _Stop
        return None

    monkeypatch.setattr(study, "equilibrium_current_runs", record)
    with pytest.raises(_Stop):
        study._equilibrium(study._Clock(), model, truth_model, verification_effects(), model, None)
    assert positions == [0.0, pytest.approx(1.5 * model.params.slot_pitch, rel=1e-12)]


def _reference(gap: float, n: int = 200, name: str = "reference", description: str = "") -> SampledReference:
    """A constant set-point (gap [m], position 0) sampled at the reference rate."""
    values = np.zeros((6, n))
    values[0] = gap
    return SampledReference(np.arange(n) / REFERENCE_RATE_HZ, values, name, description)


# --- a failed twin check -------------------------------------------------------------------
def test_a_twin_check_whose_run_fails_says_so_with_its_seeds(model):
    assert 5e-3 < STOPPER_GAP[0]  # the reference starts inside the lower stopper
    seeds = (3, 5)
    check = check_on_twin(_reference(5e-3, name="into_stopper"), _prediction(model), model=model, seeds=seeds)
    check_result(check)
    assert check.success is False
    assert check.status == "failed"
    assert "stopper" in check.message
    assert check.seeds == seeds
    assert check.reference == "into_stopper"
    assert check.to_dict()["seeds"] == list(seeds)


def test_a_twin_check_over_seeds_is_the_mean_and_sample_deviation_of_its_fits(model, monkeypatch):
    fits = []

    class Recording(design.EquationError):
        def fit(self, *args, **kwargs):
            fits.append(super().fit(*args, **kwargs))
            return fits[-1]

    monkeypatch.setattr(design, "EquationError", Recording)
    prediction = _prediction(model)  # C1..C4 with 10 % standard errors
    check = check_on_twin(papers_reference(8.0), prediction, model=model, seeds=(1, 2))
    check_result(check)
    assert check.success and check.seeds == (1, 2) and len(fits) == 2
    truth = dict(zip(CONSTANT_NAMES, model.with_constants(TWIN_TRUTH).constants.as_array(), strict=True))
    for n in CONSTANT_NAMES:
        est = np.array([f.values[n] for f in fits])
        se = np.array([f.stderr[n] for f in fits])
        assert est[0] != est[1]  # two seeds, two estimates: the spread is not trivially zero
        assert check.spread[n] == pytest.approx(abs(est[0] - est[1]) / np.sqrt(2), rel=1e-12)
        assert check.achieved[n] == pytest.approx(se.mean(), rel=1e-12)
        assert check.error[n] == pytest.approx(np.mean(np.abs(est - truth[n])), rel=1e-12)
        assert check.predicted[n] == prediction.stderr[n]
    # one seed: no spread to speak of
    single = check_on_twin(papers_reference(8.0), prediction, model=model, seeds=(1,))
    assert all(np.isnan(single.spread[n]) for n in CONSTANT_NAMES)
    assert single.error["C1"] == pytest.approx(abs(fits[2].values["C1"] - truth["C1"]), rel=1e-12)


def test_the_equilibrium_runs_place_their_pids_on_the_controller_model(model, monkeypatch):
    """``controller_model``: the model the vertical PIDs are placed on (the nominal one the rig
    engineer has), the truth being the plant; by default the truth itself. Every PID of the runs,
    one per gap, is placed on that model at that gap (seed-45 survivor: the option ignored). The
    measured currents are the plant's either way, to the PID's integral action: within 1 % of each
    other at 15 mm."""
    from maglev_oc.identification import experiments

    placed = []
    real = experiments.paper_pid

    def recording(m, **kw):
        placed.append((m, kw["design_gap"]))
        return real(m, **kw)

    monkeypatch.setattr(experiments, "paper_pid", recording)
    truth = model.with_constants(TWIN_TRUTH)
    gaps = (0.015, 0.02)
    nominal = experiments.equilibrium_current_runs(truth, gaps, controller_model=model, hold=0.6, window=0.2)
    assert [(m is model, g) for m, g in placed] == [(True, 0.015), (True, 0.02)]
    placed.clear()
    own = experiments.equilibrium_current_runs(truth, gaps, hold=0.6, window=0.2)
    assert [(m is truth, g) for m, g in placed] == [(True, 0.015), (True, 0.02)]
    assert nominal.current[0] == pytest.approx(own.current[0], rel=0.01)


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
