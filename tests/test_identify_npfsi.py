"""The reduced-order NPFSI estimator (000 eq. (3), 002 sidebar): closed-form cases, its
discretization under refinement, settings, and its behaviour on twin logs beside NLS."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.estimation.differentiate import SavitzkyGolay
from maglev_oc.identification.equation_error import fit_equation_error
from maglev_oc.identification.experiments import TWIN_TRUTH, excitation_log
from maglev_oc.identification.layout import CONSTANT_NAMES
from maglev_oc.identification.npfsi import NpfsiEstimator, npfsi
from maglev_oc.results import check_result

TRUTH = dict(zip(CONSTANT_NAMES, TWIN_TRUTH.as_array(), strict=True))


def _scalar_data(h: float, duration: float = 4.0, theta: float = 2.5):
    """v' = theta a(t), a = sin(3t) + 0.5 cos(7t): exact velocity samples."""
    t = np.arange(0, duration, h)
    a = np.sin(3 * t) + 0.5 * np.cos(7 * t)
    v = theta * ((1 - np.cos(3 * t)) / 3 + 0.5 * np.sin(7 * t) / 7)
    return t, a.reshape(-1, 1, 1), np.zeros((t.size, 1)), v.reshape(-1, 1)


def test_exact_data_converge_to_the_parameter():
    # With noise-free velocities the estimator converges to theta for every eps (its
    # stationary point is the truth); eps = h = 1 ms (stiff) stays stable.
    for eps in (1e-3, 1e-2, 5e-2):
        t, A, b, v = _scalar_data(1e-3)
        run = NpfsiEstimator(eps).run(A, b, v, 1e-3, [1.0], names=("theta",))
        assert run.success
        assert run.values["theta"] == pytest.approx(2.5, rel=2e-3), eps
        assert run.trajectory.shape == (1, t.size)


def test_discretization_converges_under_refinement():
    # The same continuous data sampled at h, h/2, h/4: the estimate after 1 s converges at
    # first order or better (the data are held over a sample), and the exact treatment of the
    # error filter keeps h = eps accurate.
    out = []
    for h in (2e-3, 1e-3, 5e-4, 2.5e-4):
        _t, A, b, v = _scalar_data(h, duration=1.0)
        run = NpfsiEstimator(5e-3, gamma=1.1, Q0=np.array([[1e-3]])).run(A, b, v, h, [1.0])
        out.append(run.trajectory[0, -1])
    diffs = np.abs(np.diff(out))
    assert diffs[1] < 0.6 * diffs[0] and diffs[2] < 0.6 * diffs[1], diffs


def test_settings_are_validated():
    with pytest.raises(ValueError, match="eps"):
        NpfsiEstimator(0.0)
    with pytest.raises(ValueError, match="gamma"):
        NpfsiEstimator(0.01, gamma=0.9)
    with pytest.raises(ValueError, match="positive definite"):
        NpfsiEstimator(0.01, Q0=-np.eye(2))
    with pytest.raises(ValueError, match="symmetric"):
        NpfsiEstimator(0.01, Q=np.array([[1.0, 2.0], [0.0, 1.0]]))
    _t, A, b, v = _scalar_data(1e-3)
    with pytest.raises(ValueError, match="theta0"):
        NpfsiEstimator(0.01).run(A, b, v, 1e-3, [1.0, 2.0])
    with pytest.raises(ValueError, match=r"\(1, 1\)"):
        NpfsiEstimator(0.01, Q0=np.eye(2)).run(A, b, v, 1e-3, [1.0])


def test_a_large_q_makes_sigma_indefinite_and_says_so():
    # 000's Sigma' = A'A - gamma^-2 Q with a constant Q much larger than the information: Sigma
    # loses positive definiteness; the result says so instead of returning a silent number.
    _t, A, b, v = _scalar_data(1e-3)
    run = NpfsiEstimator(0.01, gamma=1.1, Q=np.array([[50.0]])).run(A, b, v, 1e-3, [1.0])
    assert not run.success
    assert "positive definite" in run.message or "diverged" in run.message


@pytest.fixture(scope="module")
def twin_log(model):
    return excitation_log(model.with_constants(TWIN_TRUTH), duration=20.0, seed=3, controller_model=model)


def test_npfsi_agrees_with_nls_given_zero_phase_velocities(model, twin_log):
    # Cross-check NLS vs NPFSI on the same log: with zero-phase velocities the estimator's
    # limit is the least-squares solution of the (low-passed) equation error.
    ee = fit_equation_error(twin_log, model)
    run = npfsi(twin_log, model, eps=0.01, differentiator=SavitzkyGolay(twin_log.sample_time))
    assert run.success and run.velocity_method == "savitzky_golay"
    for k in ("C1", "C2", "C3"):
        assert run.values[k] == pytest.approx(ee.values[k], rel=0.003), k
    assert run.values["C4"] == pytest.approx(ee.values["C4"], rel=0.05)


def test_papers_observer_velocities_give_an_eps_dependent_bias(model, twin_log):
    # With the papers' high-gain observer velocities (eps_obs = 2 ms, sampled at 1 kHz, 2.1 %
    # low and lagging) C1 comes out low, more so for larger eps (000 Table III also moves with eps).
    runs = [npfsi(twin_log, model, eps=e) for e in (0.001, 0.05)]
    bias = [r.values["C1"] / TRUTH["C1"] - 1 for r in runs]
    assert -0.05 < bias[0] < -0.01
    assert bias[1] < bias[0] - 0.02
    for r in runs:
        assert r.values["C2"] == pytest.approx(TRUTH["C2"], rel=0.01)
        check_result(r)
    text = runs[0].report(truth=TRUTH)
    assert "eps = 0.001" in text and "C4" in text


def test_partial_estimate_holds_the_others(model, twin_log):
    run = npfsi(twin_log, model, estimate=("C2",), eps=0.01, theta0={"C2": 700.0})
    assert run.names == ("C2",)
    assert run.theta0["C2"] == 700.0
    assert run.values["C2"] == pytest.approx(TRUTH["C2"], rel=0.03)
    with pytest.raises(ValueError, match="not estimated"):
        npfsi(twin_log, model, estimate=("C2",), theta0={"C3": 1.0})
    assert_allclose(run.t[0], 0.0)


def test_the_trajectorys_time_starts_at_the_logs_first_sample(model, twin_log):
    """The estimate's time axis is the log's, counted from its first sample: a log recorded from
    t = 5 s gives the same trajectory on the same axis (0 .. 20 s) as one from 0."""
    import dataclasses

    later = dataclasses.replace(twin_log, t=twin_log.t + 5.0)
    a, b = (npfsi(log, model, estimate=("C2",), eps=0.01) for log in (twin_log, later))
    assert b.t[0] == 0.0
    np.testing.assert_allclose(b.t, twin_log.t - twin_log.t[0], rtol=0, atol=1e-9)  # 5 s + t: rounding
    # the same estimate: the shifted time's rounding moves the sample time by ~1e-15 relative
    np.testing.assert_allclose(a.trajectory, b.trajectory, rtol=1e-9)
