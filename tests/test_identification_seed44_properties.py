"""Properties of ``maglev_oc.identification`` from the survivors of the seed-44 and seed-45 mutation
runs:

* a twin check over several seeds summarises the fits it ran: the achieved standard error is the
  mean of the fits' standard errors, the spread the *sample* standard deviation of the estimates
  over the seeds (ddof = 1: with two seeds the population figure is 1/sqrt(2) of it, and a
  spread read against a predicted standard error must be the unbiased one), the error the mean
  |estimate - truth|. The fits are recorded as they are made and the figures recomputed from
  them (1e-12 relative: the same arithmetic in another order);
* an NPFSI run's estimate is its state after the last sample;
* a multisine's harmonics are distinct positive integers, or the call is refused;
* the equilibrium runs place their PIDs on the controller model they are given;
* (in tests/test_reports_identification_layout.py) every step of the identification study's
  clock is named (the report's timing table prints the names).
"""

from __future__ import annotations

import numpy as np
import pytest

import maglev_oc.identification.design as design
from maglev_oc.identification.design import check_on_twin, papers_reference
from maglev_oc.identification.experiments import TWIN_TRUTH
from maglev_oc.regression.base import CONSTANT_NAMES
from maglev_oc.results import check_result
from tests.test_identification_seed39_properties import _prediction


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


def test_an_npfsi_run_reports_the_estimate_at_the_end_of_the_log():
    """NpfsiResult.values are the estimator's state after the last sample (the trajectory's last
    column), exactly, on a two-parameter run still moving at its end (its last two samples
    differ), started at a tenth of the truth."""
    from maglev_oc.identification.npfsi import NpfsiEstimator

    h, n = 1e-3, 400
    t = np.arange(n) * h
    A = np.column_stack([np.sin(2 * np.pi * 3 * t), np.cos(2 * np.pi * 5 * t)])[:, None, :]
    theta = np.array([2.0, -1.5])
    y = np.concatenate([[0.0], np.cumsum(A[:-1, 0, :] @ theta) * h])[:, None]
    res = NpfsiEstimator(0.01).run(A, np.zeros((n, 1)), y, h, 0.1 * theta, names=("a", "b"))
    for k, name in enumerate(("a", "b")):
        assert res.values[name] == res.trajectory[k, -1]
        assert res.trajectory[k, -1] != res.trajectory[k, -2]


@pytest.mark.parametrize("harmonics", [[0, 2], [-1, 3], [1, 1]])
def test_a_multisine_refuses_harmonics_that_are_not_distinct_positive_integers(harmonics):
    """A harmonic 0 is a constant, not a sine of the period; a negative one is a positive one with
    its phase moved; a repeated one would add two amplitudes at one frequency: each refused by
    name, never a design built on it."""
    from maglev_oc.errors import InputError
    from maglev_oc.identification.design import multisine

    with pytest.raises(InputError, match="distinct positive integers"):
        multisine(harmonics, [1.0, 1.0])
    phases, crest = multisine([1, 2], [1.0, 1.0])  # the same call with valid harmonics
    assert phases.shape == (2,) and crest > 0


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
