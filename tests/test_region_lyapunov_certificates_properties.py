"""Properties of the Lyapunov certificates (Procedure 2 and the region of attraction of the
linearized loop), checked against closed forms, generalised eigenvalues and dense sampling:

- a Lyapunov matrix solves its equation; one whose V grows slightly is refused, as is one that is
  not symmetric (relative to its scale), with what is wrong; the decay rate accepted ends where
  the generalised eigenvalue says;
- each stopper's level touches that stopper over the whole orbit, no level above the stoppers is
  tried when they cap the certificate, and the tightness is the certified share of the upper
  bound;
- every Procedure 2 result names its binding constraint and says "certified" in its status and
  message; a certified region of attraction says so with its level;
- the Jacobian cover of the ball has no holes, and a linear loop is built at either end of its
  schedule and refused beyond.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from maglev_oc.control.gains import PAPER_GAINS, axis_poles
from maglev_oc.control.linear_regulator import paper_linear_regulator
from maglev_oc.errors import InputError
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.ellipsoid import checked_p
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.procedure2 import Procedure2, _travel_levels
from maglev_oc.region.roa import LinearizedLoop, RoaCertifier, certify_roa
from maglev_oc.results import check_result


# --- Procedure 2 -----------------------------------------------------------------------------------
def test_each_stoppers_level_touches_that_stopper_over_the_whole_orbit(model):
    """The stoppers' levels of Procedure 2 are exact (closed form): on {V <= c} the gap ranges over
    x1_ss(phi) +- sqrt(c e1' P^-1 e1), so at c = level(gap_low) the least gap over all phases is the
    lower stopper, and likewise for the upper stopper and the position's. Checked against numpy on
    a sinusoid near the lower stopper (12 +- 3 mm) and beside the left one, where every stopper is
    at a different distance; phases sampled at 100001 points (the orbit's extreme is then found
    to amp (dphi)^2 / 2 ~ 6e-14 m); equality to 1e-12 m (rounding of ~1e-2 m values, with room)."""
    loop = RegulatorLoop()
    ref = Reference(0.012, -0.02, 0.003, 0.03, 0.4, 1.1)
    P = loop.lyapunov_matrix()
    feasible = FeasibleSet(model)
    levels = _travel_levels(feasible, loop, ref, P)
    phase = np.linspace(0, 2 * math.pi, 100001)
    off = loop.offsets(ref, phase)
    Pinv = np.linalg.inv(P)
    for row, k, (lo, hi) in ((0, 0, feasible.gap_range), (1, 5, feasible.position_range)):
        spread = math.sqrt(Pinv[k, k])
        names = ("gap_low", "gap_high") if row == 0 else ("position_low", "position_high")
        least = off[row].min() - math.sqrt(levels[names[0]]) * spread
        largest = off[row].max() + math.sqrt(levels[names[1]]) * spread
        assert least == pytest.approx(lo, abs=1e-12)
        assert largest == pytest.approx(hi, abs=1e-12)


@pytest.fixture(scope="module")
def proc(model, loop):
    return Procedure2(FeasibleSet(model), loop)


@pytest.mark.parametrize("eps", [1e-9, 1e-8])
def test_a_p_whose_v_grows_slightly_is_not_a_lyapunov_matrix(loop, proc, eps):
    """P solving A'P + PA = -Q with one diagonal entry of Q slightly negative (-eps of its
    acceleration-scaled value) is positive definite but V grows along one direction: A'P + PA has
    a positive eigenvalue (about 14 eps after the diagonal scaling ``is_lyapunov`` documents, far
    above round-off, 1e-12). It is not a Lyapunov matrix, and Procedure 2 refuses it."""
    q = np.diag(1.0 / loop.state_scale() ** 2)
    q[0, 0] *= -eps
    P = loop.lyapunov_matrix(q)
    assert np.linalg.eigvalsh(P).min() > 0
    assert np.linalg.eigvalsh(loop.A.T @ P + P @ loop.A).max() > 0  # the independent test
    assert not loop.is_lyapunov(P)
    with pytest.raises(InputError, match="not a Lyapunov matrix"):
        proc.run(Reference.setpoint(0.02), P)


def test_the_decay_rate_accepted_ends_where_the_generalised_eigenvalue_says(loop):
    """A'P + PA + 2 a P <= 0 exactly for a <= lambda_min(Q, P) / 2 (Q = -(A'P + PA)): accepted at
    0.99 of that rate, refused at 1.01 (1 % either side of a simple eigenvalue)."""
    from scipy.linalg import eigh

    P = loop.lyapunov_matrix()
    Q = -(loop.A.T @ P + P @ loop.A)
    rate = float(eigh(0.5 * (Q + Q.T), P, eigvals_only=True)[0]) / 2
    assert rate > 0
    assert loop.is_lyapunov(P, 0.99 * rate)
    assert not loop.is_lyapunov(P, 1.01 * rate)


# --- Procedure 2 ---------------------------------------------------------------------------------
def test_tightness_is_the_certified_share_of_the_upper_bound(proc):
    """``tightness`` = level / level_upper (the Procedure2Result docstring): at 20 mm the current
    limit binds and the two differ (11.33 against 11.39); the ratio is at most 1."""
    res = proc.run(Reference.setpoint(0.02))
    assert 0 < res.level < res.level_upper
    assert res.tightness == pytest.approx(res.level / res.level_upper, rel=1e-12)
    assert res.tightness <= 1


def test_no_level_above_the_stoppers_is_tried_when_they_cap_the_certificate(proc):
    """At 12 mm the lower stopper's exact level is below every nonlinear bound: the ladder starts at
    the stoppers' level ("no higher than the stoppers allow"), so every branch and bound is run at
    or below it (round-off 1e-12), and the certificate is that level."""
    res = proc.run(Reference.setpoint(0.012))
    cap = min(res.levels[k][0] for k in ("gap_low", "gap_high", "position_low", "position_high"))
    assert res.binding == "gap_low" and res.level == cap
    assert min(res.levels[k][1] for k in ("margin", "headroom")) > cap
    assert res.attempts and max(a.level for a in res.attempts) <= cap * (1 + 1e-12)


# --- the linear regulators' region of attraction -----------------------------------------------
def test_the_jacobian_cover_of_the_ball_has_no_holes(model):
    """The enclosure of dg/dl on the certified set is the union of the enclosures on the boxes of
    a cover of the unit ball (l = sqrt(c) chol(S) zeta, |zeta| <= 1): every sampled zeta of the
    ball, the shell 0.9 <= |zeta| <= 1 included and every octant, lies in a box of the cover.
    A box missing from the cover drops the Jacobian there from the proof."""
    loop_l = LinearizedLoop(model, paper_linear_regulator(model), Reference.setpoint(0.02))
    cert = RoaCertifier(loop_l)
    lo, hi = cert._lo, cert._hi
    rng = np.random.default_rng(3)
    u = rng.standard_normal((3, 4000))
    u /= np.linalg.norm(u, axis=0)
    u *= rng.uniform(0.9, 1.0, u.shape[1]) ** (1 / 3)
    inside = np.all((lo[:, :, None] <= u[:, None, :]) & (u[:, None, :] <= hi[:, :, None]), axis=0)
    assert np.all(inside.any(axis=0))


EPS = np.finfo(float).eps


@pytest.mark.parametrize("gap", [0.012, 0.02, 0.027])
def test_the_linearized_loops_lyapunov_matrix_solves_its_equation(model, gap):
    """A'P + PA + Q = 0 with Q = diag(1/state_scale^2), P symmetric positive definite. Tolerance:
    a backward-stable solver leaves a residual of a few n eps ||A|| ||P|| (n = 10 states); 1e3 eps
    is far above that and far below a P off by any factor (its residual is of the order of ||Q||)."""
    loop = LinearizedLoop(model, paper_linear_regulator(model), Reference.setpoint(gap))
    P = loop.lyapunov_matrix()
    Q = np.diag(1.0 / loop.state_scale() ** 2)
    residual = loop.A.T @ P + P @ loop.A + Q
    scale = np.linalg.norm(loop.A, 2) * np.linalg.norm(P, 2)
    assert np.linalg.norm(residual, 2) <= 1e3 * EPS * scale
    assert np.linalg.norm(Q, 2) > 1e6 * EPS * scale  # the bound is not vacuous against a wrong P
    np.testing.assert_array_equal(P, P.T)
    assert np.linalg.eigvalsh(P)[0] > 0


def test_a_lyapunov_matrix_is_refused_with_what_is_wrong_with_it():
    """P defines the certified ellipsoid {e' P e <= c}: a P that is not symmetric (to 1e-10
    relative) is a user's mistake (a transposed factor, a typo), refused saying "symmetric"; a
    symmetric P comes back unchanged (its symmetrisation is the identity)."""
    rng = np.random.default_rng(36)
    a = rng.normal(size=(10, 10))
    with pytest.raises(InputError, match="P must be symmetric"):
        checked_p(a @ a.T + np.triu(np.full((10, 10), 1e-3), 1))
    with pytest.raises(InputError, match="P must be a finite 10 x 10 matrix, got shape \\(9, 9\\)"):
        checked_p(np.eye(9))
    p = a @ a.T
    np.testing.assert_array_equal(checked_p(p), 0.5 * (p + p.T))


MM = 1e-3


# --- the linear regulator's loop on the whole schedule -------------------------------------------
def test_a_linear_loop_is_built_at_either_end_of_the_schedule_and_refused_beyond(model):
    """Schedule 12, 16, 20 mm: at 12 and 20 mm the loop's poles are the printed gains' FL poles
    (the design of paper_linear_regulator; relative 1e-6 as in tests/test_region_roa.py, the
    eigenvalues of a 10 x 10 matrix with poles up to ~100 rad/s); 1e-9 m below 12 mm or above
    20 mm (far above the rounding of 1e-2 m, 2e-18 m) the set-point is refused by its gap."""
    gaps = (12 * MM, 16 * MM, 20 * MM)
    linear = paper_linear_regulator(model, gaps=gaps)
    expect = np.sort_complex(
        np.concatenate([axis_poles(PAPER_GAINS["K_v"].printed), axis_poles(PAPER_GAINS["K_h"].printed)])
    )
    for gap in (gaps[0], gaps[-1]):
        lp = LinearizedLoop(model, linear, Reference.setpoint(gap, 0.01))
        np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(lp.A)), expect, rtol=1e-6)
    for gap in (gaps[0] - 1e-9, gaps[-1] + 1e-9):
        with pytest.raises(InputError, match=rf"set-point gap {re.escape(repr(gap))} m outside"):
            LinearizedLoop(model, linear, Reference.setpoint(gap))


# --- Procedure 2's message -----------------------------------------------------------------------
@pytest.mark.parametrize(("gap", "binding"), [(0.012, "gap_low"), (0.020, "headroom")])
def test_every_procedure2_result_names_its_binding_constraint(model, gap, binding):
    """At 12 mm the lower stopper's exact level is the certificate, at 20 mm the current limit
    binds (both as in tests/test_region_round2_properties.py): either way the result follows the
    convention (a message string) and the message names the constraint; at 12 mm it says the
    level is the stoppers' exact one. Two IPOPT starts keep it to 0.3 s."""
    res = Procedure2(FeasibleSet(model), RegulatorLoop(), starts=2).run(Reference.setpoint(gap))
    check_result(res)
    assert res.success and res.binding == binding
    assert isinstance(res.message, str) and f"({binding})" in res.message
    if gap == 0.012:
        assert "stoppers' exact level" in res.message


def test_procedure_2_says_certified_in_its_status_word_and_its_message(model):
    """The result convention: a certified level is status "certified" (the word reports and the
    CLI's exit status read), with a message that says what bounds it; a reference inside a
    stopper is "infeasible_reference", not certified."""
    from maglev_oc.region.closed_loop import RegulatorLoop
    from maglev_oc.region.feasibility import FeasibleSet
    from maglev_oc.region.procedure2 import Procedure2
    from maglev_oc.results import check_result

    proc = Procedure2(FeasibleSet(model), RegulatorLoop())
    res = proc.run(Reference.setpoint(0.02))
    check_result(res)
    assert (res.success, res.status) == (True, "certified") and res.level > 0
    assert res.message.startswith("certified")
    stuck = proc.run(Reference.setpoint(0.005))  # below the lower stopper (8 mm)
    assert (stuck.success, stuck.status) == (False, "infeasible_reference")


@pytest.mark.parametrize("scale", [1.0, 1e-12])
def test_the_lyapunov_matrix_symmetry_check_is_relative(scale):
    """A P whose off-diagonal pairs differ by 1e-6 of its entries is refused at any scale (1e-6 is
    far above the 1e-10 relative rounding the check allows and far below any real asymmetry), and
    the exactly symmetric P is accepted at any scale. At scale 1e-12 the asymmetry is 1e-18 in
    absolute terms, below any absolute tolerance: a check with one would accept it."""
    a = np.random.default_rng(50).standard_normal((10, 10))
    p = (a @ a.T + 10 * np.eye(10)) * scale
    skew = np.triu(np.full((10, 10), 1e-6 * scale), 1)
    with pytest.raises(InputError, match="symmetric"):
        checked_p(p + skew)
    np.testing.assert_array_equal(checked_p(p), p)


SETPOINT = Reference.setpoint(0.02)


def test_a_certified_region_of_attraction_says_so_with_its_level(model):
    """The linear regulator at 20 mm: certified, and the message gives the certified level and the
    three it is the least of (4 significant digits, as printed)."""
    res = certify_roa(model, paper_linear_regulator(model), SETPOINT)
    assert res.success and res.level > 0
    assert res.message.startswith(f"certified level {res.level:.4g} (stability ")
