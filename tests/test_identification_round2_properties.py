"""Numbers of ``maglev_oc.identification`` that a user relies on, as properties (issue 21, second
hand-injection round: bench/README.md, "Second hand-injected round").

Small plausible bugs were injected by hand into the identification package, one at a time, and the
quick identification tests run against each; these are the properties the bugs that slipped
through broke, each checked against a computation made here independently of the code under test
(numpy, a textbook identity, a closed form), with the origin of every tolerance beside it.

* Verification: the parabola/NPFSI comparison refuses NPFSI runs at different eps (its discrepancy
  is "at one eps"); the fixed-gap NPFSI run uses the gamma and Q0 it is given (against the
  estimator run by hand on x4' = -L1 u1).
* NPFSI is the discretized recursion its docstring writes (plain numpy, one sample at a time: the
  new theta in the error update, the forward difference of the velocity, beta, gamma^-2 Q), and
  ``npfsi`` on a log uses the Q it is given.
* Constrained Gauss-Newton (the output-error solver) calls a point converged only where the
  constraints hold, whatever the step tolerance (the unit circle, closed-form answer).
* Output error: the fit does not depend on the order of its logs (values, HAC and plain errors);
  ``fit_output_error`` passes ``hac_band`` on; the plain covariance is s^2 times the theta block
  of the inverse KKT matrix with s^2 = r'r / (residuals - (variables - constraints)), dense numpy.
* ``identify`` reports only the methods it was asked for (output error alone: no equation-error
  fit, which would otherwise become the answer when output error fails); the coverage study's
  standard errors are the HAC ones (error_pct / z = 100 s / truth, an identity).
* Experiment design: the residual floor is white equation error of variance S fs / 2 (Parseval),
  entering the predicted covariance as sigma^2 H^-1; a PRBS reference plays a whole period of an
  m-sequence (two-valued periodic autocorrelation of the bits read back from the set-points).
* The eps trend's damping rate is the friction runs' C1 slope less the default runs', and the
  papers' damping follows from Table III's C1 (13.97 -> 16.23).

About 8 s on one core: two output-error fits of two 1 s logs, an NPFSI run on the 6 s twin log of
``conftest.py``, a 6 s coverage run, an identify of 1 s, the rest numpy.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp

from maglev_oc.data.log import Log
from maglev_oc.errors import InputError
from maglev_oc.estimation.differentiate import HighGainDifferentiator, differentiate_log
from maglev_oc.identification import eps_trend
from maglev_oc.identification.constrained_gn import GaussNewtonOutcome, constrained_gauss_newton
from maglev_oc.identification.design import (
    ExperimentDesigner,
    prbs_reference,
)
from maglev_oc.identification.eps_trend import EpsTrend
from maglev_oc.identification.equation_error import EquationError
from maglev_oc.identification.experiments import TWIN_TRUTH
from maglev_oc.identification.layout import CONSTANT_NAMES
from maglev_oc.identification.npfsi import PAPER_EPSILONS, NpfsiEstimator, npfsi, stage_regression
from maglev_oc.identification.output_error import MultipleShooting, fit_output_error
from maglev_oc.identification.pipeline import identify
from maglev_oc.identification.study import _Clock as StudyClock
from maglev_oc.identification.study import _coverage
from maglev_oc.identification.verification import compare_parabola_npfsi, npfsi_fixed_gap
from maglev_oc.regression.covariance import frequencies_for
from maglev_oc.regression.design import build_design


# --- verification --------------------------------------------------------------------------------------
def test_the_parabola_npfsi_comparison_refuses_runs_at_different_eps():
    par = [SimpleNamespace(gap=0.02, L1=10.0), SimpleNamespace(gap=0.025, L1=8.0)]
    same = [SimpleNamespace(eps=0.01, values={"L1": 11.0}), SimpleNamespace(eps=0.01, values={"L1": 6.0})]
    assert compare_parabola_npfsi(par, same).eps == 0.01
    mixed = [SimpleNamespace(eps=0.01, values={"L1": 11.0}), SimpleNamespace(eps=0.05, values={"L1": 6.0})]
    with pytest.raises(InputError, match="eps"):
        compare_parabola_npfsi(par, mixed)


def _fixed_gap_log(L1=7.3, u1=-0.5, n=600, seed=0):
    """000 eq. (5) sampled at 1 kHz with 10 um quantization: x3 = -50 mm - L1 u1 t^2 / 2."""
    t = np.arange(n) * 1e-3
    x3 = -0.05 - 0.5 * L1 * u1 * t**2 + np.random.default_rng(seed).normal(0, 2e-6, n)
    x = np.full((4, n), np.nan)
    x[0], x[2] = 0.02, np.round(x3 / 1e-5) * 1e-5
    return Log(t, x, np.vstack([np.full(n, u1), np.zeros(n)]), source="fixed_gap.csv")


@pytest.mark.parametrize("gamma, q0", [(1.1, None), (1.5, None), (1.1, 50.0), (2.0, 0.02)])
def test_the_fixed_gap_npfsi_run_uses_the_gamma_and_q0_it_is_given(gamma, q0):
    # x4' = -L1 u1 (000 eq. (4)): the regressor is -u1, the data the observer's x4; run here by hand
    # through the estimator with the same settings. Exact to round-off (rtol 1e-12: the same
    # recursion on the same numbers); the settings change the answer (the test has teeth).
    log = _fixed_gap_log()
    Q0 = None if q0 is None else np.array([[q0]])
    run = npfsi_fixed_gap(log, eps=0.01, gamma=gamma, Q0=Q0, theta0=5.0)
    assert run.gamma == gamma
    der = differentiate_log(log, HighGainDifferentiator(log.sample_time))
    n = log.n
    by_hand = NpfsiEstimator(0.01, gamma, None, Q0).run(
        -log.u[0].reshape(n, 1, 1), np.zeros((n, 1)), der.velocity[1].reshape(n, 1), 1e-3, [5.0]
    )
    np.testing.assert_allclose(run.trajectory, by_hand.trajectory, rtol=1e-12)
    np.testing.assert_allclose(run.Q0, by_hand.Q0, rtol=1e-12)
    default = npfsi_fixed_gap(log, eps=0.01, theta0=5.0)
    if (gamma, q0) != (1.1, None):
        assert abs(run.trajectory[0, n // 10] - default.trajectory[0, n // 10]) > 1e-6


# --- the NPFSI recursion ---------------------------------------------------------------------------------
def _documented_recursion(A, b, y, h, theta0, eps, gamma, Q, Q0):
    """npfsi.py's discretization as its docstring writes it, in plain numpy (one sample at a time):
    (S + beta A'A) theta+ = S theta + A' [(1 - phi) e + beta (dy - b)],
    e+ = phi e + eps (1 - phi) (dy - A theta+ - b),  S+ = S + h (A'A - Q / gamma^2)."""
    n, m, _ = A.shape
    phi = np.exp(-h / eps)
    beta = h - eps * (1 - phi)
    dy = np.zeros((n, m))
    dy[:-1] = np.diff(y, axis=0) / h
    theta, e, S = np.array(theta0, dtype=float), np.zeros(m), np.array(Q0, dtype=float)
    out = [theta]
    for k in range(n - 1):
        a = A[k]
        ata = a.T @ a
        theta = np.linalg.solve(S + beta * ata, S @ theta + a.T @ ((1 - phi) * e + beta * (dy[k] - b[k])))
        e = phi * e + eps * (1 - phi) * (dy[k] - a @ theta - b[k])
        S = S + h * (ata - (ata if Q is None else Q) / gamma**2)
        out.append(theta)
    return np.array(out).T


@pytest.mark.parametrize("eps, gamma, use_q", [(0.001, 1.1, False), (0.01, 1.5, True), (0.05, 1.1, True)])
def test_npfsi_is_the_recursion_its_docstring_writes(eps, gamma, use_q):
    # two rows, two parameters, a noisy velocity and an offset; the estimator (CasADi, in chunks)
    # against the documented recursion in numpy: the same arithmetic, so 1e-9 relative covers the
    # round-off of 800 steps of a 2 x 2 solve
    rng = np.random.default_rng(4)
    n, h = 800, 1e-3
    t = np.arange(n) * h
    A = np.zeros((n, 2, 2))
    A[:, 0, 0] = np.sin(2 * np.pi * 2.3 * t)
    A[:, 1, 1] = 1.0 + 0.4 * np.cos(2 * np.pi * 1.1 * t)
    A[:, 1, 0] = 0.3 * np.sin(2 * np.pi * 0.7 * t)
    b = np.column_stack([0.1 * np.ones(n), -0.2 * np.cos(2 * np.pi * 0.5 * t)])
    acc = np.einsum("nij,j->ni", A, [2.0, -1.5]) + b
    y = np.vstack([np.zeros(2), np.cumsum(acc[:-1], axis=0) * h]) + rng.normal(0, 1e-4, (n, 2))
    Q = np.array([[0.6, 0.1], [0.1, 0.9]]) if use_q else None
    Q0 = np.diag([0.01, 0.02])
    run = NpfsiEstimator(eps, gamma, Q, Q0).run(A, b, y, h, [1.0, 1.0])
    expected = _documented_recursion(A, b, y, h, [1.0, 1.0], eps, gamma, Q, Q0)
    np.testing.assert_allclose(run.trajectory, expected, rtol=1e-9, atol=1e-12)
    assert np.max(np.abs(expected[:, -1] - expected[:, n // 4])) > 1e-3  # it moves: the test has teeth


def test_npfsi_on_a_log_uses_the_q_it_is_given(model, twin_log):
    # the stage's regression (000 eq. (2)) run by hand through the estimator with the same Q
    Q = np.diag([2.0, 3.0])
    run = npfsi(twin_log, model, estimate=("C1", "C3"), eps=0.01, Q=Q)
    A, b, y, _ = stage_regression(twin_log, model, ("C1", "C3"), HighGainDifferentiator(twin_log.sample_time))
    c = model.constants
    by_hand = NpfsiEstimator(0.01, Q=Q).run(A, b, y, twin_log.sample_time, [c.C1, c.C3])
    np.testing.assert_allclose(run.Q, Q, rtol=0)
    np.testing.assert_allclose(run.trajectory, by_hand.trajectory, rtol=1e-12)
    default = npfsi(twin_log, model, estimate=("C1", "C3"), eps=0.01)
    assert abs(run.values["C3"] - default.values["C3"]) > 1e-6 * abs(default.values["C3"])


# --- constrained Gauss-Newton ----------------------------------------------------------------------------
DATA = np.array([2.0, 0.5])


def _circle(w):
    """r = w - DATA, c = |w|^2 - 1: the closest point of the unit circle to DATA."""
    r = w - DATA
    c = np.array([w @ w - 1.0])
    return r, c, sp.identity(2, format="csr"), sp.csr_matrix(2 * w[None, :])


@pytest.mark.parametrize("tolerance", [1.0, 0.1, 1e-3, 1e-9])
def test_constrained_gauss_newton_converges_only_where_the_constraints_hold(tolerance):
    out = constrained_gauss_newton(_circle, np.array([0.3, 0.2]), np.ones(2), tolerance=tolerance)
    assert out.status == "converged", out.message
    # the documented default constraint tolerance, 1e-6
    assert np.max(np.abs(out.c)) < 1e-6
    # closed form DATA / |DATA| at the default tolerance: the last full step was below 1000 x 1e-9
    # and Gauss-Newton converges linearly here, so 1e-5 is ample (measured 1e-12); a loose
    # tolerance stops earlier by design (a step below 1000 x tolerance) and is not checked
    if tolerance == 1e-9:
        np.testing.assert_allclose(out.w, DATA / np.linalg.norm(DATA), atol=1e-5)


@pytest.mark.parametrize("start", [(0.3, 0.2), (5.0, -3.0)])
def test_constrained_gauss_newton_keeps_an_exact_penalty_when_the_multipliers_are_large(start):
    # the closest point of the unit circle to data 4.1 away: the constraint's multiplier is about
    # 3 (|data| - 1), the full Gauss-Newton steps overshoot the circle and the line search on the
    # l1 merit 0.5 |r|^2 + rho |c|_1 must shorten them. That merit is exact only for rho above the
    # largest multiplier (Nocedal & Wright, Theorem 17.3); the solver takes twice it. With rho at a
    # fifth of it the search accepted steps away from the circle and failed there (|c| 0.4-0.8).
    # Converged within the default 30 iterations (measured 15 and 20) to data / |data| (1e-5, as above;
    # measured 6e-7: Gauss-Newton converges linearly here and stops on a step below 1e-6)
    data = np.array([4.0, 1.0])

    def far(w):
        return w - data, np.array([w @ w - 1.0]), sp.identity(2, format="csr"), sp.csr_matrix(2 * w[None, :])

    out = constrained_gauss_newton(far, np.array(start), np.ones(2))
    assert out.status == "converged", out.message
    np.testing.assert_allclose(out.w, data / np.linalg.norm(data), atol=1e-5)


@pytest.mark.parametrize("start", [0.5, -0.3, 0.05, 1.0])
def test_constrained_gauss_newton_stops_on_a_shortened_step_only_when_the_step_taken_is_small(start):
    # a large-residual problem where Gauss-Newton overshoots: r = (k x, y^2 + p) on the line y = x,
    # p = 0.75 k^2. At the minimizer x = 0 the Gauss-Newton curvature is k^2 and the true one k^2 +
    # 2p = 2.5 k^2, so every full step lands at -1.5 x, the merit rejects it and the halved step
    # lands at -x/4: convergence is linear through shortened steps, and the error left is 1/5 of
    # the step taken. The shortcut "a step below 1000 x tolerance" is documented for a *full*
    # step (quadratic convergence); taking it on a halved one stopped at |x| 2e-8 to 8e-8.
    # Default tolerance 1e-9 on the step taken, so |x| < 2e-10 in exact arithmetic; 1e-8 leaves
    # room for the merit's rounding (measured 1.2e-10 to 4.5e-10, in 14-17 iterations).
    k = 0.1
    p = 0.75 * k * k

    def overshoot(w):
        x, y = w
        Jr = sp.csr_matrix(np.array([[k, 0.0], [0.0, 2.0 * y]]))
        return np.array([k * x, y * y + p]), np.array([y - x]), Jr, sp.csr_matrix(np.array([[-1.0, 1.0]]))

    out = constrained_gauss_newton(overshoot, np.array([start, start]), np.ones(2))
    assert out.status == "converged", out.message
    assert np.max(np.abs(out.w)) < 1e-8


# --- what identify and the study report ----------------------------------------------------------------
def test_identify_reports_only_the_methods_it_was_asked_for(model, two_logs):
    # output error alone: the equation-error fit it starts from is not reported (nor taken as the
    # answer should the output-error fit fail); a 1 s log, so min_duration is lowered for the test
    out = identify(two_logs[0], model, methods=("output_error",), min_duration=0.5)
    assert out.equation_error is None and out.npfsi == ()
    assert out.output_error is not None and out.best is (
        out.output_error if out.output_error.success else None
    )


def test_the_coverage_standard_errors_are_the_hac_ones_in_percent_of_the_truth(model, truth_model):
    # identity: error_pct / z = 100 (v - t) / t / ((v - t) / s) = 100 s / t with s the HAC standard
    # error that z uses (1e-9: round-off of the divisions)
    cov = _coverage(StudyClock(), model, truth_model, 1, 6.0)
    np.testing.assert_allclose(cov.stderr_pct, cov.error_pct / cov.z, rtol=1e-9)


# --- experiment design ----------------------------------------------------------------------------------
def test_the_residual_floor_is_white_equation_error_of_its_density(model, twin_log):
    # white noise of one-sided density S sampled at fs has variance S fs / 2 (Parseval); under white
    # equation error of variance sigma^2 a least-squares estimate's covariance is sigma^2 H^-1,
    # H = sum over both axes of X X' (the filtered design columns on the fitted samples). The floor's
    # share of the predicted covariance is recomputed so; 1e-6 relative covers the cancellation of
    # the encoders' part in the difference
    floor = 1e-6
    extra = ExperimentDesigner(model, residual_floor=floor).covariance(twin_log) - ExperimentDesigner(
        model, residual_floor=0.0
    ).covariance(twin_log)
    prep = EquationError(twin_log, model).prepared
    design = build_design(prep, model, estimate=CONSTANT_NAMES, weights=np.ones(2))
    x = design.columns * design.fit[None, None, :]
    H = np.einsum("pan,qan->pq", x, x)
    np.testing.assert_allclose(extra, floor / prep.sample_time / 2 * np.linalg.inv(H), rtol=1e-6)


def _is_maximum_length(bits: np.ndarray) -> bool:
    """Periodic autocorrelation N at lag 0 and -1 at every other lag (the m-sequence's signature)."""
    n = bits.size
    return all(int(np.dot(bits, np.roll(bits, k))) == (n if k == 0 else -1) for k in range(n))


@pytest.mark.parametrize("duration", [10.0, 17.0])
def test_a_prbs_reference_plays_a_whole_period_of_its_sequence(duration):
    # documented: "the order is the largest whose period fits the run, so the sequence is played
    # whole". The bits are read back from the set-point at the end of each bit (the smoothing
    # filter, critically damped at 9.4 rad/s, has covered 68 % of a full step by then, so the sign
    # is the bit's); the first 2^k - 1 of them form an m-sequence for the largest such k that fits.
    ref = prbs_reference(duration)
    for row, offset, bit_time in ((0, 0.02, 0.25), (3, 0.0, 0.5)):
        ends = np.round((np.arange(1, int(duration / bit_time)) * bit_time - 1e-3) * 1000).astype(int)
        bits = np.sign(ref.values[row, ends] - offset).astype(int)
        k = int(np.floor(np.log2(bits.size + 1)))
        assert _is_maximum_length(bits[: 2**k - 1]), (row, k)


# --- the eps trend ---------------------------------------------------------------------------------------
def _trend(names, change):
    """An EpsTrend over the papers' eps whose constants change by ``change`` (relative) each."""
    eps = PAPER_EPSILONS
    values = np.array([[1.0, 1.0 + c / 2, 1.0 + c] for c in change])
    return EpsTrend("t", names, eps, values)


def test_the_damping_rate_is_the_friction_runs_c1_slope_less_the_default_runs(model, monkeypatch):
    # EpsTrendStudy.damping_rate: "read from the C1 slopes (friction minus default)"; papers_damping:
    # the papers' C1 slope (Table III of 000: 13.97 -> 16.23 from eps = 0.001 to 0.05) less our
    # default's, times M_h. The twin runs are replaced by trends of known slopes (the study's own
    # arithmetic is what is checked; its runs are checked in tests/test_eps_trend.py). 1e-9: round-off.
    t2 = ("C2", "C3", "C4")
    d3, d2 = _trend(CONSTANT_NAMES, (-0.04, 0.002, -0.02, -0.3)), _trend(t2, (0.002, -0.02, -0.3))
    f3, f2 = _trend(CONSTANT_NAMES, (0.06, 0.002, 0.03, 0.2)), _trend(t2, (0.002, 0.03, 0.2))
    log = SimpleNamespace(sample_time=1e-3)

    def runs(model, friction, **kw):
        return (d3, d2, log, True) if friction == (None, None) else (f3, f2, log, True)

    monkeypatch.setattr(eps_trend, "_twin_trend", runs)
    monkeypatch.setattr(eps_trend, "_npfsi_trend", lambda *a, **k: (d3, True))
    monkeypatch.setattr(eps_trend, "_limit", lambda *a: d3)
    study = eps_trend.eps_trend_study(model)
    span = PAPER_EPSILONS[-1] - PAPER_EPSILONS[0]
    assert study.damping_rate == pytest.approx((0.06 - -0.04) / span, rel=1e-9)
    papers_slope = (16.23 / 13.97 - 1) / span
    expected = model.params.mass_horizontal * (papers_slope - -0.04 / span)
    assert study.papers_damping == pytest.approx(expected, rel=1e-3)  # the table's 4 digits


# --- output error ----------------------------------------------------------------------------------------
TRUTH = dict(zip(CONSTANT_NAMES, TWIN_TRUTH.as_array(), strict=True))


@pytest.fixture(scope="module")
def two_logs(twin_log):
    """Two 1 s pieces of the 6 s twin log (1001 samples: 20 segments of 50 samples each)."""
    return twin_log.index_slice(0, 1001), twin_log.index_slice(3000, 4001)


@pytest.fixture(scope="module")
def oe_fits(model, two_logs):
    """The output-error fit of two logs in both orders at a 7.5 Hz HAC band (7 frequencies of a 1 s
    log, where the default 0.25 Hz gives the minimum 4), started at the truth."""
    a, b = two_logs
    ab = MultipleShooting([a, b], model).fit(initial=TRUTH, hac_band=7.5)
    ba = fit_output_error([b, a], model, initial=TRUTH, hac_band=7.5)
    return ab, ba


def test_the_output_error_fit_does_not_depend_on_the_order_of_its_logs(oe_fits):
    # values, HAC and plain standard errors are sums over the logs; 1e-6 relative: the solver's
    # tolerance on the scaled step (1e-9) and round-off of sums in another order
    ab, ba = oe_fits
    assert ab.success and ba.success
    for k in CONSTANT_NAMES:
        assert ba.values[k] == pytest.approx(ab.values[k], rel=1e-6)
        assert ba.stderr[k] == pytest.approx(ab.stderr[k], rel=1e-6)
        assert ba.stderr_naive[k] == pytest.approx(ab.stderr_naive[k], rel=1e-6)


def test_the_output_error_hac_band_sets_the_frequencies_it_averages(oe_fits):
    # fit_output_error passes hac_band on: each log's covariance averages frequencies_for(n, T, band)
    # Fourier frequencies of its J x M fitted samples (7.5 Hz: away from a tie of band n T with an
    # integer, where the floor would depend on the last bit of a log's sample time)
    _, ba = oe_fits
    assert ba.settings["hac_band_hz"] == 7.5
    assert ba.hac_frequencies == 2 * frequencies_for(1000, 1e-3, 7.5)
    assert ba.hac_frequencies > 2 * frequencies_for(1000, 1e-3, 0.25)


def test_fit_output_error_passes_the_window_on(model, two_logs, oe_fits):
    """``window_duration`` reaches the problem: 50 ms windows (one segment each, no continuity)
    give the fit MultipleShooting gives with them (1e-9: the same computation), recorded in the
    settings, and another fit than the default 0.2 s windows (continuity moves the estimates)."""
    a, _ = two_logs
    short = fit_output_error(a, model, initial=TRUTH, window_duration=0.05)
    same = MultipleShooting(a, model, window_duration=0.05).fit(initial=TRUTH)
    default = fit_output_error(a, model, initial=TRUTH)
    assert short.settings["window_duration_s"] == 0.05 and default.settings["window_duration_s"] == 0.2
    for k in CONSTANT_NAMES:
        assert short.values[k] == pytest.approx(same.values[k], rel=1e-9)
    assert max(abs(short.values[k] / default.values[k] - 1) for k in CONSTANT_NAMES) > 1e-6


def test_the_plain_output_error_covariance_is_s2_times_the_inverse_kkt_block(model, two_logs):
    # the constrained least-squares covariance (theta block of the inverse KKT matrix) times the
    # residual variance s^2 = r'r / (residuals - (variables - constraints)), recomputed with dense
    # numpy at the fit's starting point; 1e-6 relative: a dense against a sparse LU of the same
    # matrix, which is badly scaled (2-norm condition 4e16, the node states beside the scaled
    # constants): they agree to 1e-9-2e-8 depending on the machine's BLAS. A covariance not scaled
    # by s^2 (0.62 here), or with the degrees of freedom off by the 60 constraints (3 % of 1976),
    # is off by far more
    ms = MultipleShooting(two_logs[0], model)
    theta, nodes, _ = ms._start(TRUTH)
    w = ms._pack(theta, nodes)
    r, c, Jr, Jc = ms._linearize(w)
    gn = GaussNewtonOutcome(w, r, c, Jr, Jc, "converged", "", 1)
    scale = np.array(ms.layout.scale)
    _, naive, *_ = ms._covariance(gn, scale, 0.25)
    Jr, Jc = Jr.toarray(), Jc.toarray()
    nv, nc, q = Jr.shape[1], Jc.shape[0], scale.size
    kkt = np.block([[Jr.T @ Jr, Jc.T], [Jc, np.zeros((nc, nc))]])
    s2 = float(r @ r) / (r.size - (nv - nc))
    expected = s2 * np.linalg.inv(kkt)[:q, :q] * np.outer(scale, scale)
    np.testing.assert_allclose(naive, expected, rtol=1e-6)


def test_the_output_error_counts_its_residuals(oe_fits):
    # every fitted sample gives two output residuals (gap and position), and the reduced chi-square
    # is the chi-square over the residuals less the free variables: n_residuals is what the report
    # and the JSON print as "# residuals" and what the degrees of freedom start from
    for fit in oe_fits:
        assert fit.n_residuals == 2 * fit.n_samples, (fit.n_residuals, fit.n_samples)
        dof = fit.chi_square / fit.reduced_chi_square
        assert 0 < fit.n_residuals - dof < 0.1 * fit.n_residuals


def test_the_starting_nodes_reproduce_the_logged_gap_through_the_offset(model, two_logs):
    """The output map is y = (x1 - gap_offset, x3): the node states a fit starts from carry the
    logged gap plus the starting offset, so that at every node the model's output is the reading
    (1e-15 m: one addition and one subtraction of the same number). With a 0.2 mm offset a node
    state on the wrong side of the reading would be 0.4 mm off."""
    ms = MultipleShooting(two_logs[0], model, estimate=(*CONSTANT_NAMES, "gap_offset"))
    start = {k: getattr(TWIN_TRUTH, k) for k in CONSTANT_NAMES} | {"gap_offset": 2e-4}
    theta, nodes, _ = ms._start(start)
    offset = theta[ms.layout.names.index("gap_offset")]
    assert offset == pytest.approx(2e-4, rel=1e-12)
    for sg, S in zip(ms.segments, nodes, strict=True):
        assert np.max(np.abs((S[0] - offset) - sg.nodes0[0])) < 1e-15
        assert np.array_equal(S[1:], sg.nodes0[1:])
