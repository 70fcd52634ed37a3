"""Region properties from the second hand-injection round (issue 21: "tests that would catch a
wrong answer"). Small plausible bugs were injected one at a time into ``maglev_oc.region`` (all
but the branch and bound and the boundary minimizer, covered before) and the region's quick tests
run against each; these properties are what a correct implementation satisfies whatever its
code, each checked against an independent computation, for the bugs nothing caught.

* The steady state of the exosystem solves the loop: along the orbit, omega d/dphi z_ss(phi) =
  A_cl z_ss - B r'' (finite differences in the phase), at the internal model's frequency and off
  it, and the loop started on the orbit at any phase stays on it on the sampled twin (its start
  and its end judged at their own phases).
* A run into the left position stopper records its distance like one into the right.
* ``is_lyapunov`` is the eigenvalue test it documents: a P whose A'P + PA has a positive
  eigenvalue 1e-8 of its scale is refused (and by Procedure 2), and the decay rate it accepts
  ends at half the least generalised eigenvalue of (Q, P).
* Procedure 2's tightness is level / level_upper (<= 1), and no level above the stoppers' exact
  level is tried when they cap the certificate.
* The critical radius brackets the radius where runs first leave F (a planted threshold), and
  its tails are the chi-square tails of r^2 (closed forms for 1 and 2 degrees of freedom).
* The robust certificate refines between the first certified rung and the one above it (the
  bracket closes to 1/2^REFINE_STEPS of the rungs' gap against a planted threshold); a ladder
  that does not decrease is refused.
* The cover of the unit ball on which the region-of-attraction certificate encloses the
  Jacobian has no holes (every point of the ball, the shell included, is in a box of the cover).
* A slice's coverage is |certified and safe| / |safe|, recomputed from its own starts.
* The study: a basin run is labelled by the first outcome that applies in the documented order;
  a sinusoid's runs are spread evenly over 8 phases and all of them run; the worst start is the
  witness scaled along its ray onto V = 0.999 level; the enlargement is each size's own ratio;
  the verdict names a certified slice start that is unsafe; the least current on R = 0 is the
  least over the gap range; the highest certified confidence needs every lower one; the FL map
  succeeds only within F, a linear regulator's map whenever it converged (planted runs).
* The microstepper's half-widths are sqrt(level (P^-1)_jj), reached inside its certified set.
* The SDP: the construction level is the largest inside the polygon and the gap band (one of
  them reached); the P it returns keeps the decay rate asked; its weights act in their
  direction; ``enlarge`` keeps the certified candidate with the largest score.
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.control.linear_regulator import paper_linear_regulator
from maglev_oc.errors import InputError
from maglev_oc.region import robust as robust_module
from maglev_oc.region import sdp as sdp_module
from maglev_oc.region import study as study_module
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.ellipsoid import initial_condition_set, max_rectangle
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.microstepper import MicrostepperRegion
from maglev_oc.region.montecarlo import (
    BatchOutcome,
    BatchSimulator,
    check_error_states,
    fl_slice,
    regulator_state,
)
from maglev_oc.region.procedure2 import Procedure2, Procedure2Result
from maglev_oc.region.roa import LinearizedLoop, RoaCertifier
from maglev_oc.region.robust import critical_radius
from maglev_oc.region.robust_certificate import REFINE_STEPS, RobustCertifier, RobustSearch
from maglev_oc.region.sdp import InnerPolygon, SdpCandidate, construction_level, solve_sdp
from maglev_oc.region.study import BASIN_OUTCOMES
from maglev_oc.region.sweep import PlantSet, SweepSpec
from maglev_oc.sim.twin import RigTwin


@pytest.fixture(scope="module")
def loop():
    return RegulatorLoop()


@pytest.fixture(scope="module")
def sim(model):
    # the ideal twin under the FL regulator; the virtual machine (no C compiler needed)
    return BatchSimulator(RigTwin(model), FeedbackLinearizingRegulator(model), duration=0.3, compile=False)


@pytest.fixture(scope="module")
def proc(model, loop):
    return Procedure2(FeasibleSet(model), loop)


# --- the loop in error coordinates ---------------------------------------------------------------
@pytest.mark.parametrize("omega", [None, 2.0])
def test_the_steady_state_solves_the_loop_along_the_orbit(loop, omega):
    """z_ss(phi) = Pi w(phi) is a trajectory of z' = A_cl z - B r'' (module docstring of
    closed_loop): omega dz_ss/dphi (central differences, step 1e-5 rad: error ~1e-10 of the
    amplitude) equals A_cl z_ss - B_v r_v'' - B_h r_h''. At the internal model's frequency (the
    papers' ellipse) and at 2 rad/s, where e_ss is not zero. Tolerance 1e-6 of the largest term."""
    ref = Reference.paper_sinusoid()
    if omega is not None:
        ref = dataclasses.replace(ref, omega=omega)
    phases = np.linspace(0.0, 2 * math.pi, 13)
    h = 1e-5
    dz = (loop.steady_state(ref, phases + h) - loop.steady_state(ref, phases - h)) / (2 * h) * ref.omega
    z = loop.steady_state(ref, phases)
    sig = ref.signals(phases)
    rhs = loop.A @ z - np.outer(loop.B_v, sig[2]) - np.outer(loop.B_h, sig[5])
    scale = np.max(np.abs(loop.A @ z))
    np.testing.assert_allclose(dz, rhs, rtol=0, atol=1e-6 * scale)


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


@pytest.mark.parametrize("phase", [0.0, math.pi / 3, 4.0])
def test_the_sampled_loop_started_on_the_orbit_stays_on_it(loop, sim, phase):
    """z~ = 0 is the steady state of the sinusoid at every phase: started there (the physical state
    at that phase, the internal models at their steady state), the sampled twin follows the orbit,
    and at the end of the horizon (0.3 s, 1.4 rad further on the orbit) z~ is still about 0. The
    sampled loop is not the continuous one (5 kHz, the amplifier): V at the end was measured
    3e-5 to 5e-5; the bound 1e-3 (level 1e-3, final ratio < 1) is 20 x that, while a start or an
    end judged at the wrong phase is 1e4 x off."""
    ref = Reference.paper_sinusoid()
    chk = check_error_states(sim, loop, ref, loop.lyapunov_matrix(), 1e-3, np.zeros((10, 1)), phase=phase)
    assert chk.violations == 0
    assert chk.start_ratio[0] == 0.0
    assert chk.final_ratio[0] < 1.0


def test_a_run_into_the_left_stopper_records_its_distance(model, sim):
    """``max_abs_position`` is the largest |x3|: a start at -59 mm moving left at 0.5 m/s reaches the
    left stopper (-60 mm, hardware.STOPPER_POSITION) within 0.05 s and records 60 mm, as a run into
    the right one does."""
    x0 = np.array([[0.02, 0.02], [0.0, 0.0], [-0.059, 0.059], [-0.5, 0.5]])
    out = sim.with_duration(0.05).run(
        x0, regulator_state(x0, np.zeros((6, 2))), np.array([0.02, 0, 0, 0, 0, 0])
    )
    assert list(out.stopper_hit) == [True, True]
    np.testing.assert_allclose(out.max_abs_position, [0.060, 0.060], rtol=0, atol=1e-9)


def test_a_slice_counts_its_coverage_among_the_safe_starts(model, loop, sim):
    """``coverage`` = |certified and safe| / |safe| (SliceCheck docstring), recomputed from the
    slice's own starts: certified where V(start) <= level, safe where the run stayed in F. A slice
    from stopper to stopper on the gap (the outer starts hit a stopper) at a level that certifies
    part of it, so every count is neither empty nor full."""
    ref = Reference.setpoint(0.02)
    P = loop.lyapunov_matrix()
    sl = fl_slice(sim, loop, ref, P, 0.5, ("e1", "e2"), (-0.0125, 0.0125), (-0.03, 0.03), n=9)
    v = np.einsum("in,ij,jn->n", sl.starts, P, sl.starts).reshape(sl.safe.shape)
    certified = v <= 0.5
    np.testing.assert_array_equal(sl.certified, certified)
    safe = sl.safe
    assert 0 < safe.sum() < safe.size and 0 < certified.sum() < certified.size
    assert (certified & safe).sum() < certified.sum() or (certified & safe).sum() < safe.sum()
    assert sl.coverage == pytest.approx((certified & safe).sum() / safe.sum(), rel=1e-12)
    assert sl.unsafe_certified == int((certified & ~safe).sum())


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


# --- the robust analyses -------------------------------------------------------------------------
def _radius_probe(monkeypatch, threshold):
    """run_sweep replaced by a planted verdict: runs leave F exactly when the plant set's radius
    (read from its shape, r^2 cov) exceeds ``threshold``."""
    probed = []

    def fake(spec, runs, **_):
        cov0 = np.asarray(spec.plants.shape)[0, 0]
        r = math.sqrt(cov0 / fake.unit)
        probed.append(r)
        return dataclasses.make_dataclass("S", ["violations"])(int(r > threshold))

    monkeypatch.setattr(robust_module, "run_sweep", fake)
    return fake, probed


@pytest.mark.parametrize("threshold", [0.3, 3.7, 41.0])
def test_the_critical_radius_brackets_where_runs_first_leave_f(model, monkeypatch, threshold):
    """A planted threshold r* (violations exactly above it): the bracket [safe, broken] contains r*
    and is no wider than ``rel_tol`` of its upper end, whatever side of 1 (the bisection's start) r*
    lies on."""
    cov = np.diag([1e-6, 1.0, 4e-6, 1e-8])
    fake, probed = _radius_probe(monkeypatch, threshold)
    fake.unit = cov[0, 0]
    spec = SweepSpec(PlantSet.point(model.constants), Reference.setpoint(0.02), start=(0.02, 0, 0, 0))
    res = critical_radius("planted", spec, cov, runs=10, rel_tol=0.05)
    assert res.safe_radius <= threshold < res.broken_radius
    assert res.broken_radius - res.safe_radius <= 0.05 * res.broken_radius * (1 + 1e-12)
    assert res.dof == 4 and probed


def test_the_tails_are_chi_square_tails_of_the_squared_radius():
    """P(chi2_k > r^2) in closed form: erfc(r / sqrt 2) for 1 degree of freedom (|N(0, 1)| > r),
    exp(-r^2 / 2) for 2; an unbroken bracket has a zero tail."""
    for r in (0.5, 1.0, 2.0, 3.0):
        one = robust_module.CriticalRadius("x", r, 2 * r, 1, 10)
        assert one.safe_tail == pytest.approx(math.erfc(r / math.sqrt(2)), rel=1e-9)
        assert one.broken_tail == pytest.approx(math.erfc(2 * r / math.sqrt(2)), rel=1e-9)
        two = robust_module.CriticalRadius("x", r, math.inf, 2, 10)
        assert two.safe_tail == pytest.approx(math.exp(-(r**2) / 2), rel=1e-9)
        assert two.broken_tail == 0.0


def _nominal(loop, level: float) -> Procedure2Result:
    """A nominal certificate at ``level`` for the Lyapunov P at 20 mm, without running Procedure 2."""
    P = loop.lyapunov_matrix()
    ics = initial_condition_set(P, level)
    ref = Reference.setpoint(0.02)
    return Procedure2Result(
        True, "certified", "planted", ref, P, level, level, 1.0, "margin", None, 0.0, {}, ics, (), ()
    )


@pytest.mark.parametrize("threshold", [0.55, 0.93, 0.31])
def test_the_robust_level_is_refined_to_the_planted_threshold(model, loop, monkeypatch, threshold):
    """A planted condition (b): certified exactly at levels <= threshold x c_nom, refuted above. The
    ladder certifies the first rung below the threshold, then REFINE_STEPS bisections between it and
    the rung above close the bracket [level, level_upper] around the threshold to 1/2^REFINE_STEPS
    of the rungs' gap."""
    certifier = RobustCertifier(FeasibleSet(model), loop, max_boxes=1000)
    c_nom = 7.0
    cut = threshold * c_nom

    def search(reference, P, level, plants, geo, t0):
        ok = level <= cut
        status = "certified" if ok else "refuted"
        z = None if ok else np.zeros(10)
        plant = None if ok else np.asarray(model.constants.as_array())
        return RobustSearch(ok, status, status, level, 1, z, 0.0, plant, 1.0 if not ok else math.nan)

    monkeypatch.setattr(certifier, "_search", search)
    res = certifier.run(_nominal(loop, c_nom), PlantSet.point(model.constants))
    ladder = np.asarray(certifier.ladder) * c_nom
    below = ladder[ladder <= cut].max()
    above = ladder[ladder > cut].min()
    assert res.level <= cut < res.level_upper
    assert res.level_upper - res.level <= (above - below) / 2**REFINE_STEPS * (1 + 1e-12)
    assert res.witness_plant is not None


@pytest.mark.parametrize("ladder", [(0.5, 0.9), (1.0, 0.5, 0.5), (0.3, 0.2, 0.25)])
def test_a_ladder_that_does_not_decrease_is_refused(model, loop, ladder):
    """``ladder``: "decreasing fractions in (0, 1]" (the first certified rung is the largest)."""
    with pytest.raises(InputError, match="ladder must be decreasing"):
        RobustCertifier(FeasibleSet(model), loop, ladder=ladder)


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


# --- the study --------------------------------------------------------------------------------
def test_a_basin_run_is_labelled_by_the_first_outcome_that_applies():
    """BASIN_OUTCOMES: "the first that applies in this order: diverged, hit a stopper, not settled,
    met R < 0, commanded more than the current limit; else converged", on every combination of
    the five flags."""
    flags = np.array(list(itertools.product([False, True], repeat=5))).T  # (5, 32)
    finite, stopper, settled, over, negative = ~flags[0], flags[1], ~flags[2], flags[3], flags[4]
    code = study_module._outcome_codes(finite, stopper, settled, over, negative)
    for k in range(flags.shape[1]):
        order = (
            ("diverged", not finite[k]),
            ("stopper", stopper[k]),
            ("not settled", not settled[k]),
            ("R < 0", negative[k]),
            ("over the current limit", over[k]),
            ("converged", True),
        )
        expected = next(name for name, applies in order if applies)
        assert BASIN_OUTCOMES[code[k]] == expected, flags[:, k]


@pytest.mark.parametrize("n", [0, 1, 7, 8, 13, 420, 421])
def test_a_sinusoid_spreads_every_run_over_eight_phases(n):
    """The runs of a sinusoid's check are spread over 8 phases of the orbit, evenly (counts differ
    by at most 1) and all of them (the counts add up to n); a set-point runs all at phase 0."""
    groups = study_module._phases(Reference.paper_sinusoid(), n)
    counts = [c for _, c in groups]
    assert sum(counts) == n
    if n:
        assert len(groups) == 8 and max(counts) - min(counts) <= 1
        np.testing.assert_allclose([p for p, _ in groups], 2 * math.pi * np.arange(8) / 8)
    assert study_module._phases(Reference.setpoint(0.02), n) == [(0.0, n)]


def test_the_worst_start_is_the_witness_scaled_onto_the_certified_boundary(loop, monkeypatch):
    """The run "from the certified boundary nearest F's edge": the witness (V = level_upper, outside)
    scaled back along its own ray to V = 0.999 level, at the witness's phase."""
    seen = {}

    def fake(sim, loop_, reference, P, level, z, *, phase, current_limit):
        seen.update(z=z[:, 0], phase=phase, level=level)
        return "run"

    monkeypatch.setattr(study_module, "check_error_states", fake)
    w = np.linspace(1.0, 2.0, 10) * 1e-3
    nominal = dataclasses.replace(_nominal(loop, 0.4), witness=w, witness_phase=1.25, level_upper=0.9)
    assert w @ nominal.P @ w > 0.4  # the witness lies outside the certified set
    assert study_module._worst_start(None, loop, nominal.reference, nominal, 9.0) == "run"
    z = seen["z"]
    assert z @ nominal.P @ z == pytest.approx(0.999 * 0.4, rel=1e-12)
    cos = z @ w / (np.linalg.norm(z) * np.linalg.norm(w))
    assert cos == pytest.approx(1.0, abs=1e-12)
    assert seen["phase"] == 1.25 and seen["level"] == 0.4


def test_the_enlargement_is_the_ratio_of_each_size(loop):
    """Enlargement: the SDP's certified rectangle and semi-axes over the Lyapunov P's, each side
    over its own side (two certificates whose e1 and e2 grow by different factors)."""
    P0 = loop.lyapunov_matrix()
    P1 = P0.copy()
    P1[5:, 5:] *= 0.25  # the horizontal axis 2 x larger at the same level
    ok = {"success": True}
    lyap = dataclasses.replace(_nominal(loop, 0.4), **ok)
    sdp_cert = dataclasses.replace(
        _nominal(loop, 0.9), P=P1, initial_conditions=initial_condition_set(P1, 0.9)
    )
    sdp = type("Sdp", (), {"certified": sdp_cert})()
    enl = study_module._enlargement(lyap, sdp)
    (a0, b0), (a1, b1) = lyap.initial_conditions.rectangle, sdp_cert.initial_conditions.rectangle
    assert enl.e1 == pytest.approx(a1 / a0, rel=1e-12) and enl.e2 == pytest.approx(b1 / b0, rel=1e-12)
    assert enl.e2 > 1.5 * enl.e1  # the two sides did grow differently
    assert enl.area == pytest.approx(a1 * b1 / (a0 * b0), rel=1e-12)
    s0, s1 = lyap.initial_conditions.semi_axes, sdp_cert.initial_conditions.semi_axes
    assert enl.semi_axes == pytest.approx({k: s1[k] / s0[k] for k in s0}, rel=1e-12)


def _study_parts(certified=True, bad=0, unsafe=0):
    ref = type("R", (), {"lyapunov": type("L", (), {"success": certified})(), "checks": {}})()
    ref.checks = {"x": type("C", (), {"n": 5, "violations": bad})()}
    slices = {"Lyapunov P": (type("S", (), {"unsafe_certified": unsafe})(),)}
    return [ref], slices


def test_the_study_verdict_names_every_contradiction():
    """OperatingRegionStudy.status: "violations" when a run inside a certified set left F *or* a
    certified slice start was unsafe; "not_certified" when a reference has no certificate;
    otherwise "certified"."""
    assert study_module._verdict(*_study_parts())[:2] == (True, "certified")
    assert study_module._verdict(*_study_parts(bad=1))[:2] == (False, "violations")
    assert study_module._verdict(*_study_parts(unsafe=1))[:2] == (False, "violations")
    assert study_module._verdict(*_study_parts(certified=False))[:2] == (False, "not_certified")


def test_the_least_current_on_r_zero_is_the_least_over_the_gap_range(model):
    """|u| >= |i_d| = |L3 / (2 L4)| on R = 0: the study reports the least of it over the stoppers'
    gap range and where. Checked on a grid 10 x finer (the reported value is a grid minimum: within
    1e-3 of the finer one, the function being smooth on a 0.1 mm grid) and at its own gap."""
    feasible = FeasibleSet(model)
    current, gap = study_module._r_zero_current(model, feasible)
    gaps = np.linspace(*feasible.gap_range, 2201)
    _, _, L3, L4 = model.coefficients(gaps)
    fine = np.abs(L3 / (2 * L4))
    assert current <= fine.min() * (1 + 1e-3)
    _, _, l3, l4 = model.coefficients(np.array([gap]))
    assert current == pytest.approx(abs(l3[0] / (2 * l4[0])), rel=1e-12)
    assert feasible.gap_range[0] <= gap <= feasible.gap_range[1]


def test_the_highest_certified_confidence_needs_every_lower_one():
    """CertifiedRobustStudy.highest_certified: the highest level certified "with every lower one":
    a failure at 0.9 stops the count there even if 0.95 was certified."""
    cert = [type("C", (), {"success": ok})() for ok in (True, False, True)]
    row = study_module.CertifiedRobustRow("20 mm", None, "", tuple(cert))
    st = study_module.CertifiedRobustStudy((0.5, 0.9, 0.95, 0.99), 0.9, 1000, (1.0,), (row,), None, 0, 0)
    assert st.highest_certified(row) == 0.5
    none = study_module.CertifiedRobustRow("20 mm", None, "", (cert[1],))
    assert st.highest_certified(none) is None


class _PlantedSim:
    """A simulator whose runs end as planted, one per start: converged, over the current limit,
    R < 0, converged (the start x target map's outcomes, BASIN_OUTCOMES 0, 1, 2, 0)."""

    def __init__(self, name):
        self.controller = type("Ctrl", (), {"name": name, "n_state": 10})()
        self.references = []

    def with_duration(self, duration):
        return self

    def run(self, x0, c0, reference):
        self.references.append(np.array(reference, dtype=float))
        n = x0.shape[1]
        final = np.zeros((4, n))
        final[0], final[2] = reference[0], reference[3]  # every run settles on its target
        return BatchOutcome.of(
            {"total": 0.0},
            min_margin=np.array([1.0, 1.0, -0.5, 1.0]),
            max_current=np.array([5.0, 12.0, 5.0, 5.0]),
            stopper_hit=np.zeros(n, bool),
            min_gap=np.full(n, 0.01),
            max_gap=np.full(n, 0.02),
            max_abs_position=np.full(n, 0.02),
            final_twin=final,
            final_controller=np.zeros((10, n)),
            finite=np.ones(n, bool),
        )


def test_the_fl_map_succeeds_only_within_f_and_the_linear_ones_when_converged(model):
    """The start x target maps: "success (converged without a stopper; for the FL regulator also
    without leaving F)". Planted runs: the FL map's success is outcome 0 only, a linear
    regulator's every converged outcome (0, 1, 2: the ideal twin does not limit the current)."""
    run = type("Run", (), {})()
    run.model, run.limit = model, 9.0
    run.config = type("Cfg", (), {"linear_horizon": 1.0})()
    run.simulator = lambda twin, ctrl, duration: _PlantedSim(ctrl.name)
    starts, targets = np.array([0.01, 0.012, 0.014, 0.016]), np.array([0.018, 0.02])
    linear = type("Lin", (), {"name": "linear regulator"})()
    fl_sim = _PlantedSim("FL")
    maps = study_module._start_target_maps(run, fl_sim, [linear], starts, targets)
    # every run is the set-point (target gap, 20 mm), as Reference.setpoint lays it out (values,
    # velocities and accelerations of gap and position): at rest there
    assert len(fl_sim.references) == targets.size
    for g, ref in zip(targets, fl_sim.references, strict=True):
        setpoint = Reference.setpoint(g, study_module.LARGE_STEP_TARGET[1]).signals(0.0)[:, 0]
        np.testing.assert_array_equal(ref, setpoint)
    np.testing.assert_array_equal(maps["FL"]["outcome"], [[0, 1, 2, 0]] * 2)
    np.testing.assert_array_equal(maps["FL"]["success"], [[True, False, False, True]] * 2)
    np.testing.assert_array_equal(maps["linear regulator"]["success"], [[True, True, True, True]] * 2)


# --- the microstepper and the SDP ---------------------------------------------------------------
def test_the_microstepper_half_widths_are_reached_inside_its_certified_set():
    """``half_widths``: the largest error of each axis inside {V <= level}, sqrt(level (P^-1)_jj),
    reached at the point P^-1 e_j scaled to V = level (computed here from P's inverse). A cheap
    case: 20 A at 10 mm, no stoppers (its refutation is 45.4, seed37's test)."""
    region = MicrostepperRegion(current_limit=20.0, stoppers=False)
    # a loose bracket (any certified level has these half-widths) keeps the test to about a second
    res = region.largest_level((0.0, 0.0, 0.010), rel_tol=0.5, max_boxes=20_000)
    assert res.success
    p_inv = np.linalg.inv(region.P)
    for axis, j in (("x", 0), ("y", 5), ("gap", 10)):
        z = p_inv[:, j] * math.sqrt(res.level / p_inv[j, j])
        assert z @ region.P @ z == pytest.approx(res.level, rel=1e-9)
        assert res.half_widths[axis] == pytest.approx(z[j], rel=1e-9)


def test_the_construction_level_is_the_largest_inside_the_polygon_and_the_gap_band(loop):
    """construction_level: the largest c <= 1 with {V <= c} inside [-E, E] x Poly: on {V <= c} the
    linear function m'z ranges over +-sqrt(c m'P^-1 m) (computed here from P's inverse), so at
    the level every face and |e1| <= E hold and one of them is reached. A square polygon
    |dv1|, |dv2| <= b and two bands E, one binding, one not."""
    P = loop.lyapunov_matrix()
    p_inv = np.linalg.inv(P)
    normals = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    for E, b in ((1e-4, 50.0), (5e-3, 0.5)):
        poly = InnerPolygon(True, "proved", "planted", E, np.zeros((2, 4)), normals, np.full(4, b), 0)
        c = construction_level(loop, P, poly, E)
        reach_e1 = math.sqrt(c * p_inv[0, 0])
        rows = normals @ loop.output[2:4]
        reach_faces = np.sqrt(c * np.einsum("ij,jk,ik->i", rows, p_inv, rows))
        assert reach_e1 <= E * (1 + 1e-9) and np.all(reach_faces <= b * (1 + 1e-9))
        reached = max(reach_e1 / E, np.max(reach_faces) / b)
        assert c == pytest.approx(1.0) or reached == pytest.approx(1.0, rel=1e-9)


def _square(halfwidth: float, b: float) -> InnerPolygon:
    """A planted inner polygon |dv1|, |dv2| <= b [m/s^2] over the gap band |e1| <= halfwidth [m]."""
    normals = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    return InnerPolygon(True, "proved", "planted", halfwidth, np.zeros((2, 4)), normals, np.full(4, b), 0)


def test_the_sdp_keeps_its_decay_rate_and_follows_its_weights(model, loop):
    """solve_sdp: "A Q + Q A' + 2 decay Q <= 0": the P it returns is a Lyapunov matrix with 0.9 of
    the decay rate asked (10 % for the solver's accuracy; measured to hold at 0.999). Weighting
    log a2 four times log a1 gives a larger e2 half-side than the other way round (measured
    0.011935 against 0.011912 m, 2e-3 apart, far above Clarabel's 1e-8)."""
    ref, feasible = Reference.setpoint(0.02), FeasibleSet(model)
    sides = {}
    for weights in ((4.0, 1.0), (1.0, 4.0)):
        status, Q, _ = solve_sdp(loop, ref, _square(4e-3, 20.0), feasible, 0.5, weights)
        assert status == "optimal"
        P = np.linalg.inv(Q)
        P = 0.5 * (P + P.T)
        assert loop.is_lyapunov(P, 0.9 * 0.5)
        sides[weights] = max_rectangle(P[np.ix_([0, 5], [0, 5])], 1.0)
    assert sides[(1.0, 4.0)][1] > sides[(4.0, 1.0)][1] * (1 + 1e-3)
    assert sides[(4.0, 1.0)][0] >= sides[(1.0, 4.0)][0] * (1 - 1e-6)


def test_the_enlargement_keeps_the_candidate_with_the_largest_score(model, loop, monkeypatch):
    """enlarge: ``best`` is the certified candidate with the largest score, whichever half-width it
    was found at (planted candidates, the best in the middle, an uncertified one larger still)."""
    scores = iter([(True, 1.0), (True, 3.0), (False, 9.0), (True, 2.0)])

    def fake(procedure, builder, reference, E, decay, weights, direction, clock):
        ok, score = next(scores)
        cert = type("Cert", (), {"success": ok, "level": 1.0, "message": "planted"})()
        return SdpCandidate.of(E, _square(E, 1.0), "optimal", rectangle=(score, 1.0), certified=cert)

    monkeypatch.setattr(sdp_module, "_candidate", fake)
    procedure = type("Proc", (), {"feasible": FeasibleSet(model), "loop": loop})()
    res = sdp_module.enlarge(procedure, Reference.setpoint(0.02), builder=object())
    assert res.success and res.best.score == 3.0
    assert res.best is res.candidates[1]
