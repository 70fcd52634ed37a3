"""Properties of the NPFSI estimator (``maglev_oc.identification.npfsi``), checked against its
recursion written out in numpy and its closed form:

- NPFSI is the discretized recursion its docstring writes, ``sigma_final`` is that recursion's
  closed form, and the estimate is the state after the last sample;
- the default Sigma(0) is a millisecond of the mean information, and a run on a log uses the Q it
  is given, which the report names; a Q or Q0 that is not a finite symmetric matrix is refused
  under the caller's name, a symmetric semidefinite Q accepted;
- the settling time is relative to the final value, and constants taken from a run say where they
  come from.
"""

from __future__ import annotations

import numpy as np
import pytest

from maglev_oc.errors import InputError
from maglev_oc.estimation.differentiate import HighGainDifferentiator
from maglev_oc.identification.npfsi import DEFAULT_Q0_SECONDS, NpfsiEstimator, npfsi, stage_regression
from maglev_oc.model.stage import StageModel


# --- NPFSI ---------------------------------------------------------------------------------------------
def _npfsi_data(n=3000, h=1e-3, seed=0):
    """A (n, 1, 2) regressor of two sines, b = 0 and velocities integrating A theta exactly."""
    t = np.arange(n) * h
    rng = np.random.default_rng(seed)
    A = np.stack(
        [np.sin(2 * np.pi * 3.1 * t + rng.uniform()), 1.0 + 0.5 * np.cos(2 * np.pi * 1.7 * t)], axis=1
    )
    A = A[:, None, :]
    theta = np.array([2.0, -1.5])
    acc = A[:, 0, :] @ theta
    y = np.concatenate([[0.0], np.cumsum(acc[:-1]) * h])[:, None]
    return A, np.zeros((n, 1)), y, h, theta


def test_npfsi_default_sigma0_is_a_millisecond_of_the_mean_information():
    A, b, y, h, _ = _npfsi_data()
    res = NpfsiEstimator(0.01).run(A, b, y, h, [1.0, 1.0])
    info = np.einsum("nij,nik->jk", A, A) / A.shape[0]  # mean A'A, independently
    np.testing.assert_allclose(res.Q0, DEFAULT_Q0_SECONDS * np.diag(np.diag(info)), rtol=1e-12)
    assert DEFAULT_Q0_SECONDS == 1e-3


def test_npfsi_settling_time_is_relative_to_the_final_value():
    # started at a tenth of the truth: a band relative to the start would be ten times narrower
    A, b, y, h, theta = _npfsi_data()
    res = NpfsiEstimator(0.01).run(A, b, y, h, 0.1 * theta, names=("a", "b"))
    for k, name in enumerate(res.names):
        band = 0.01
        ts = res.settling_time(name, band)
        traj, final = res.trajectory[k], res.trajectory[k, -1]
        after = res.t >= ts
        assert np.all(np.abs(traj[after] - final) <= band * abs(final))
        i = int(np.flatnonzero(after)[0])
        assert i > 0 and abs(traj[i - 1] - final) > band * abs(final)  # it left the band just before


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


# --- NPFSI: Sigma at the end ------------------------------------------------------------------------------
@pytest.mark.parametrize("given_q", [False, True])
def test_npfsi_sigma_final_is_the_closed_form_of_its_recursion(given_q):
    """Sigma' = A'A - gamma^-2 Q, stepped as Sigma_{k+1} = Sigma_k + h (A_k'A_k - gamma^-2 Q) over the n - 1
    steps of n samples, from Sigma(0) = Q0 (default 1 ms times the diagonal of the mean A'A; Q default A'A).
    Tolerance 1e-11 relative: round-off of sums of 60 terms."""
    rng = np.random.default_rng(34)
    n, m, p, h, gamma = 60, 2, 3, 1e-3, 1.1
    A = rng.normal(size=(n, m, p))
    b = rng.normal(size=(n, m))
    y = 0.01 * rng.normal(size=(n, m))
    Q = np.diag([0.5, 1.0, 2.0]) if given_q else None
    run = NpfsiEstimator(0.01, gamma, Q=Q).run(A, b, y, h, np.zeros(p))
    ata = np.einsum("nij,nik->njk", A, A)
    q0 = DEFAULT_Q0_SECONDS * np.diag(np.diag(ata.mean(axis=0)))
    if given_q:
        expected = q0 + h * ata[:-1].sum(axis=0) - h * (n - 1) * Q / gamma**2
    else:
        expected = q0 + h * (1 - gamma**-2) * ata[:-1].sum(axis=0)
    assert run.sigma_final.shape == (p, p)
    np.testing.assert_allclose(run.sigma_final, expected, rtol=1e-11, atol=0)
    np.testing.assert_allclose(run.Q0, q0, rtol=1e-12)
    assert run.success == bool(np.linalg.eigvalsh(expected).min() > 0)


# --- NPFSI's report ------------------------------------------------------------------------------------
def _scalar_data(h: float = 1e-3, duration: float = 1.0):
    """v' = 2.5 a(t), a = sin(3t) + 0.5 cos(7t), exact velocity samples (as tests/test_identify_npfsi.py)."""
    t = np.arange(0, duration, h)
    a = np.sin(3 * t) + 0.5 * np.cos(7 * t)
    v = 2.5 * ((1 - np.cos(3 * t)) / 3 + 0.5 * np.sin(7 * t) / 7)
    return a.reshape(-1, 1, 1), np.zeros((t.size, 1)), v.reshape(-1, 1)


@pytest.mark.parametrize(
    ("Q", "words"), [(None, "Q = A'A (002 sidebar)"), (np.array([[0.5]]), "Q = given matrix")]
)
def test_the_npfsi_report_says_which_q_was_used(Q, words):
    """The report's first line names Q: A'A (the papers' choice, Sigma' = (1 - gamma^-2) A'A) when the
    estimator was made without one, "given matrix" when a Q was passed; never the other."""
    A, b, v = _scalar_data()
    run = NpfsiEstimator(0.01, Q=Q).run(A, b, v, 1e-3, [1.0], names=("theta",))
    head = run.report().splitlines()[0]
    assert head.endswith(f"{words}]]"), head
    other = "given matrix" if Q is None else "A'A"
    assert other not in head


# --- NPFSI's matrices ----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("kw", "message"),
    [
        ({"Q": np.array([[1.0, 0.5], [0.0, 1.0]])}, "Q must be symmetric"),
        ({"Q": np.ones((2, 3))}, "Q must be a finite square matrix, got shape (2, 3)"),
        ({"Q": np.array([[np.nan]])}, "Q must be a finite square matrix, got shape (1, 1)"),
        ({"Q0": np.array([[1.0, 0.5], [0.0, 1.0]])}, "Q0 must be symmetric"),
        ({"Q0": np.ones((2, 3))}, "Q0 must be a finite square matrix, got shape (2, 3)"),
    ],
)
def test_npfsi_names_the_matrix_it_refuses_as_the_caller_wrote_it(kw, message):
    """000's Sigma' = A'A - gamma^-2 Q needs a symmetric Q, Sigma(0) = Q0 a symmetric one; a matrix
    that is not is refused, and the message names the keyword the caller passed (Q or Q0, case as
    written), so the caller knows which of the two to fix."""
    with pytest.raises(InputError) as err:
        NpfsiEstimator(0.01, **kw)
    assert str(err.value) == message


def test_npfsi_accepts_a_symmetric_semidefinite_q():
    """Q need not be definite (the papers' default A'A is singular on data that miss a direction)."""
    q = np.array([[1.0, 1.0], [1.0, 1.0]])
    np.testing.assert_array_equal(NpfsiEstimator(0.01, Q=q).Q, q)


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


def test_constants_from_an_npfsi_run_say_where_they_come_from():
    from tests.test_identify_properties import _npfsi_result

    run = _npfsi_result([[14.0, 14.5], [800.0, 790.0]], names=("C1", "C2"))
    c = run.constants(StageModel().constants)
    assert (c.C1, c.C2) == (14.5, 790.0)
    assert c.source == "NPFSI, eps = 0.01"
