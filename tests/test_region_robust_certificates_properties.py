"""Properties of the robust analyses (the robust certificate, the critical radius and the empirical
robust level), checked against planted thresholds, chi-square tails in closed form and sampled
plants:

- the worst plant is in the set and attains the sup of dV/dt; a robust certificate's ratio is its
  level over the nominal one at any scale; its initial conditions are its own level set (empty
  when the nominal failed); the robust level is refined to a planted threshold; a ladder that does
  not decrease is refused; an undecided certificate says so;
- the critical radius brackets where runs first leave F, and its tails are chi-square tails of
  the squared radius;
- the empirical robust level defaults to seed 0.
"""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from maglev_oc.errors import InputError
from maglev_oc.region import robust
from maglev_oc.region import robust as robust_module
from maglev_oc.region.closed_loop import DE1, DE2, E1, E2, N_ERROR, Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.region.robust import critical_radius
from maglev_oc.region.robust_certificate import (
    REFINE_STEPS,
    RobustCertifier,
    RobustSearch,
    certificate_words,
    certify_robust,
)
from maglev_oc.region.sweep import PlantSet, SweepSpec
from maglev_oc.results import check_result
from tests._region_cases import _nominal


# --- the robust certificate ---------------------------------------------------------------------
def test_the_worst_plant_is_in_the_set_and_attains_the_sup_of_dv_dt(model):
    """``RobustCertifier.rate`` returns sup over Theta of dV/dt and the plant attaining it. The
    plant is a member of Theta, its own dV/dt (the rate for the one-point set {C}) equals the
    sup, and no plant sampled from Theta has a larger dV/dt. Box of +-5 % around the nominal
    constants; 20 sampled plants per state; dV/dt is linear in C, so the sup is attained at
    a vertex and equalities hold to rounding (1e-9 relative of the terms, ~1e2-1e4)."""
    loop = RegulatorLoop()
    feasible = FeasibleSet(model)
    cert = RobustCertifier(feasible, loop, max_boxes=1000)
    c = np.asarray(model.constants.as_array(), dtype=float)
    box = PlantSet.box(0.95 * c, 1.05 * c)
    P = loop.lyapunov_matrix()
    ref = Reference.paper_sinusoid()
    rng = np.random.default_rng(5)
    scale = np.array([2e-3, 0.05, 1e-4, 1e-3, 1e-3, 5e-3, 0.1, 1e-4, 1e-3, 1e-3])
    zt = rng.uniform(-1, 1, (N_ERROR, 6)) * scale[:, None]
    phase = rng.uniform(0, 2 * math.pi, 6)
    sup, worst = cert.rate(P, ref, box, zt, phase)
    # in the box: |C - C0| <= half-width, to the rounding of C0 +- half-width (1e-12 relative)
    assert np.all(np.abs(worst - c[:, None]) <= 0.05 * c[:, None] * (1 + 1e-9))
    plants = box.sample(20, rng)
    for k in range(zt.shape[1]):
        own, _ = cert.rate(P, ref, PlantSet.point(worst[:, k]), zt[:, k], phase[k])
        assert own[0] == pytest.approx(sup[k], rel=1e-9, abs=1e-9 * abs(sup[k]) + 1e-12)
        sampled = [cert.rate(P, ref, PlantSet.point(p), zt[:, k], phase[k])[0][0] for p in plants.T]
        assert max(sampled) <= sup[k] + 1e-9 * abs(sup[k])


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


EPS = np.finfo(float).eps


def test_a_robust_certificates_ratio_is_its_level_over_the_nominal_one_at_any_scale(model):
    """For the nominal plant alone the robust level is the nominal one: ratio 1. V = z'Pz scaled by
    1e-6 gives the same sets with levels 1e-6 as large (both below 1 here), and the same ratio,
    which is always level / nominal_level (to round-off: one division)."""
    feasible, loop = FeasibleSet(model), RegulatorLoop()
    reference = Reference.setpoint(0.02)
    nominal = Procedure2(feasible, loop).run(reference)
    plants = PlantSet.point(model.constants.as_array())
    small = certify_robust(feasible, loop, reference, plants, P=1e-6 * nominal.P)
    assert small.status == "certified"
    assert 0 < small.nominal_level < 1
    # the same set up to Procedure 2's search, which stops on a bracket of about 1 % (1.1 % measured)
    assert small.nominal_level == pytest.approx(1e-6 * nominal.level, rel=0.03)
    assert small.ratio == pytest.approx(small.level / small.nominal_level, rel=4 * EPS)
    assert small.ratio == pytest.approx(1.0, rel=1e-12)


@pytest.fixture(scope="module")
def certifier(model, loop):
    return RobustCertifier(FeasibleSet(model), loop, max_boxes=100_000, ladder=(1.0, 0.6, 0.3))


def _on_boundary(P, level, ics):
    for name, i in (("e1", E1), ("e1_rate", DE1), ("e2", E2), ("e2_rate", DE2)):
        assert ics.semi_axes[name] ** 2 * P[i, i] == pytest.approx(level, rel=1e-12, abs=0.0)
    a1, a2 = ics.rectangle.vertical, ics.rectangle.horizontal
    assert a1 > 0 and a2 > 0
    corners = []
    for s in (1.0, -1.0):
        z = np.zeros(P.shape[0])
        z[E1], z[E2] = a1, s * a2
        corners.append(z @ P @ z)
    worst = max(corners)  # the largest rectangle touches the ellipse at a corner
    assert worst == pytest.approx(level, rel=1e-9)


def test_a_robust_certificates_initial_conditions_are_its_own_level_set(model, loop, certifier):
    """Theta = {C_nom} at a 20 mm set-point: certified at the nominal level (the cheapest
    certified robust certificate, as in test_region_robust_certificate)."""
    nominal = Procedure2(FeasibleSet(model), loop).run(Reference.setpoint(0.02))
    res = certifier.run(nominal, PlantSet.point(np.asarray(model.constants.as_array())))
    check_result(res)
    assert res.status == "certified" and res.level > 0
    _on_boundary(res.P, res.level, res.initial_conditions)


def test_a_certificate_whose_nominal_failed_has_an_empty_initial_condition_set(model, loop, certifier):
    """A sinusoid reaching the upper stopper: no nominal level, so level 0 and zero sizes."""
    nominal = Procedure2(FeasibleSet(model), loop).run(Reference(0.027, gap_amplitude=0.004))
    assert not nominal.success
    res = certifier.run(nominal, PlantSet.point(np.asarray(model.constants.as_array())))
    check_result(res)
    assert res.status == "not_certified" and res.level == 0.0
    ics = res.initial_conditions
    assert set(ics.semi_axes) == {"e1", "e1_rate", "e2", "e2_rate"}
    assert all(v == 0.0 for v in ics.semi_axes.values())
    assert ics.rectangle.vertical == 0.0 and ics.rectangle.horizontal == 0.0


def test_the_empirical_robust_level_defaults_to_seed_0(model):
    """Starts in {z~' P z~ <= 1} (the Lyapunov P, well inside the 20 mm certificate's 11.3) on
    plants within 1 % of the nominal ones: no violation, one round. Without ``seed`` the round draws
    the plants and starts of seed 0, bit for bit, and so finds the same numbers; seed 1 draws others."""
    P = RegulatorLoop().lyapunov_matrix()
    C = np.asarray(model.constants.as_array())
    spec = SweepSpec(
        PlantSet.point(C), Reference.setpoint(0.02), P=tuple(map(tuple, P)), level=1.0, duration=0.3
    )
    box = PlantSet.box(0.99 * C, 1.01 * C)

    def level(**kwargs):
        return robust.empirical_robust_level("20 mm", spec, box, runs=4, task_size=4, **kwargs)

    default, zero, one = level(), level(seed=0), level(seed=1)
    assert default.check.seed == 0 and default.rounds == zero.rounds == 1
    assert default.level == zero.level
    for name in ("constants", "start_ratio", "min_margin", "max_current"):
        assert_array_equal(getattr(default.check, name), getattr(zero.check, name), err_msg=name)
    assert not np.array_equal(one.check.constants, zero.check.constants)


def test_an_undecided_robust_certificate_says_so():
    """No rung certified and none refuted: the words a user reads are "undecided within the budget"."""
    c = SimpleNamespace(status="not_certified", message="", nominal_level=1e-3, witness_plant=None)
    assert certificate_words(c) == "undecided within the budget"
