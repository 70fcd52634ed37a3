"""Properties of ``maglev_oc.identification`` written against the survivors of the seed-35 mutation-testing
run at b484c31 (issue 21): each test states a property the code should have, not the mutated token.

* constrained Gauss-Newton: redundant constraints (a singular KKT matrix even when damped) stop the
  solver at its start with the documented status word ``kkt_singular``, not a success; the same
  problem with the constraint stated once is solved;
* the eps-trend study's logs: the Table II log is the locked-mover run of seed + 1 (the study's seeds),
  reproducible from the seed; with guide friction, the Table III log is the run of the identification
  effects with that friction (and not the frictionless one);
* the identification study's clock: a step run several times reports the sum of its runs' times;
* multiple shooting refuses an input delay of 10 ms or more by name, as equation error does;
* a PRBS reference's description states the bit times it holds its levels for (vertical/horizontal):
  the set-points' accelerations jump only at multiples of each stated bit time;
* multiple shooting's gap offset is true gap - reading: a constant added to the gap reading moves the
  fitted offset by minus that constant.
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest
import scipy.sparse as sp

from maglev_oc.errors import InputError
from maglev_oc.identification import constrained_gn, eps_trend, study
from maglev_oc.identification.constrained_gn import constrained_gauss_newton
from maglev_oc.identification.design import RAMP_TIME, prbs_reference
from maglev_oc.identification.equation_error import EquationError
from maglev_oc.identification.experiments import excitation_log, identification_effects, verification_effects
from maglev_oc.identification.layout import GAP_OFFSET
from maglev_oc.identification.output_error import MultipleShooting


# --- constrained Gauss-Newton ----------------------------------------------------------------------------
def _documented_statuses() -> set[str]:
    """The status words the module docstring lists (``"..."`` after "Status words")."""
    doc = constrained_gn.__doc__
    return set(re.findall(r'``"([a-z_]+)"``', doc[doc.index("Status words") :]))


def test_redundant_constraints_stop_at_the_start_with_the_documented_status():
    """min |A w - b|^2 s.t. w0 + w1 = 1, the constraint stated twice: the KKT matrix [H J'; J 0] has two
    equal rows of J, so it is singular whatever damping is added to H. The solver must say so with its
    documented word and leave w at the start; stated once, the same problem converges to the KKT
    solution (numpy, dense)."""
    A = np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])
    b = np.array([1.0, 2, 3, 4])
    row = np.array([[1.0, 1.0, 0.0]])

    def linearize(times: int):
        def lin(w):
            c = np.full(times, w[0] + w[1] - 1.0)
            return A @ w - b, c, sp.csr_matrix(A), sp.csr_matrix(np.repeat(row, times, axis=0))

        return lin

    assert "kkt_singular" in _documented_statuses()
    out = constrained_gauss_newton(linearize(2), np.zeros(3), np.ones(3))
    assert out.status == "kkt_singular" and not out.success
    assert "singular" in out.message
    np.testing.assert_array_equal(out.w, np.zeros(3))
    once = constrained_gauss_newton(linearize(1), np.zeros(3), np.ones(3))
    assert once.success and once.status in _documented_statuses()
    kkt = np.block([[A.T @ A, row.T], [row, np.zeros((1, 1))]])
    expected = np.linalg.solve(kkt, np.concatenate([A.T @ b, [1.0]]))[:3]
    np.testing.assert_allclose(once.w, expected, rtol=0, atol=1e-9)  # the solver's step tolerance


# --- the eps-trend study's logs --------------------------------------------------------------------------
def test_the_table2_log_is_the_locked_run_of_the_next_seed_and_reproducible(model, truth_model):
    """_logs docstring: the Table II log (mover locked at x3 = 0, gap about 16 mm) uses seed + 1, as the
    identification study does. It is the same run as excitation_log with that seed (bit for bit: the same
    simulation), and the same again on a second call."""
    seed, duration = 3, 1.5
    _, t2 = eps_trend._logs(
        truth_model, model, identification_effects(), verification_effects(), duration, duration, seed
    )
    expected = excitation_log(
        truth_model,
        duration=duration,
        seed=seed + 1,
        controller_model=model,
        effects=verification_effects(),
        gap_offset=study.VERTICAL_GAP,
        locked_position=0.0,
    )
    np.testing.assert_array_equal(t2.x, expected.x)
    np.testing.assert_array_equal(t2.u, expected.u)
    assert t2.source == expected.source
    _, again = eps_trend._logs(
        truth_model, model, identification_effects(), verification_effects(), duration, duration, seed
    )
    np.testing.assert_array_equal(again.x, t2.x)


def test_the_friction_trend_runs_the_table3_log_with_that_friction(model, truth_model):
    """_twin_trend: NPFSI on the study's twin runs with the given guide friction added to the study's
    effects. Its Table III log is the identification effects' run with that friction, bit for bit, and
    differs from the run without it (the friction is not lost on the way)."""
    friction = eps_trend.RIG_FRICTION
    seed, duration = 3, 2.0
    _, _, log, _ = eps_trend._twin_trend(
        model, friction, duration=duration, vertical_duration=duration, seed=seed
    )
    with_friction = dataclasses.replace(
        identification_effects(), friction_horizontal=friction[0], friction_vertical=friction[1]
    )
    common = {"duration": duration, "seed": seed, "controller_model": model}
    expected = excitation_log(truth_model, effects=with_friction, **common)
    np.testing.assert_array_equal(log.x, expected.x)
    np.testing.assert_array_equal(log.u, expected.u)
    plain = excitation_log(truth_model, effects=identification_effects(), **common)
    assert not np.array_equal(log.x, plain.x)


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


# --- multiple shooting -------------------------------------------------------------------------------------
@pytest.mark.parametrize("delay", [0.01, 0.02, -1e-9, math.nan])
def test_multiple_shooting_refuses_the_input_delays_equation_error_refuses(model, twin_log, delay):
    """Both fits take input_delay in [0, 0.01) s (their messages say so): 10 ms is outside, as in
    EquationError."""
    with pytest.raises(InputError, match="input_delay"):
        EquationError(twin_log, model, input_delay=delay)
    with pytest.raises(InputError, match="input_delay"):
        MultipleShooting(twin_log, model, input_delay=delay)


def test_a_shift_of_the_gap_reading_moves_the_fitted_gap_offset_by_minus_the_shift(truth_model, twin_log):
    """gap_offset = true gap - reading (the fits' convention): adding 100 um to every gap reading of a
    log is the same plant seen by an encoder 100 um off, so the multiple-shooting fit of the offset
    (the other constants the twin's) moves by -100 um. The two problems are the same after the shift,
    so the estimates differ by the shift to the solver's tolerance; 1 % of the offset's standard error
    (0.3 um on 2 s) is far above that and far below the shift."""
    log = twin_log.index_slice(0, 2000)
    shift = 1e-4
    x = np.array(log.x)
    x[0] += shift
    shifted = dataclasses.replace(log, x=x)
    fits = [
        MultipleShooting(g, truth_model, estimate=(GAP_OFFSET,)).fit(initial={GAP_OFFSET: 0.0})
        for g in (log, shifted)
    ]
    assert all(f.success for f in fits)
    tol = 0.01 * fits[0].stderr[GAP_OFFSET]
    assert tol < 0.01 * shift
    assert fits[1].values[GAP_OFFSET] - fits[0].values[GAP_OFFSET] == pytest.approx(-shift, abs=tol)


# --- PRBS references ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("bit_time", [(0.25, 0.5), (0.5, 0.2)])
def test_a_prbs_references_description_states_its_bit_times(bit_time):
    """The description "bits of A/B s" gives the vertical and horizontal bit times. The smoothing filter
    is critically damped and of second order, so each step of the levels makes the set-point's
    acceleration jump; after the ramp (RAMP_TIME) every jump lies on a multiple of the stated bit time of
    its axis (to 1.5 samples of 1 ms), and the closest two are one bit apart."""
    ref = prbs_reference(8.0, bit_time=bit_time)
    m = re.search(r"bits of ([0-9.]+)/([0-9.]+) s", ref.description)
    assert m is not None, ref.description
    stated = (float(m.group(1)), float(m.group(2)))
    assert stated == pytest.approx(bit_time, rel=1e-12)
    dt = ref.t[1] - ref.t[0]
    for row, bit in ((2, stated[0]), (5, stated[1])):
        jump = np.abs(np.diff(ref.values[row]))
        at = ref.t[1:][jump > 0.3 * jump.max()]
        at = at[at >= RAMP_TIME]
        assert at.size >= 4
        k = at / bit
        np.testing.assert_allclose(k, np.round(k), rtol=0, atol=1.5 * dt / bit)
        assert np.diff(at).min() == pytest.approx(bit, abs=1.5 * dt)
