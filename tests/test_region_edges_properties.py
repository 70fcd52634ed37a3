"""Edges of the region code that its main tests do not reach: the certificate's search limits and
what a bad input or a degenerate matrix gives (issue 21: the survivors of a mutation run at
31d4cd9, seed 33, each turned into a property).

* The linear regulator's stability level grows 4x from the stoppers' level and stops once it
  passes 4x that level (the stoppers bind there anyway, ``level = min(stability, travel)``), and
  its bisection stops as soon as the bracket is within 1 %.
* A matrix with a non-positive diagonal is no Lyapunov candidate: the decrease test says "not
  certified" (an infinite margin) instead of taking square roots of negative numbers.
* Gains of the wrong size are refused with the name of the option that carries them.
* The large step's maps judge the current against the limit in force, and none when there is none.
* The robust ladder bisects between its certified rung and the rung above.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_oc.control.linear_regulator import paper_linear_regulator
from maglev_oc.errors import InputError
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.microstepper import MicrostepperRegion
from maglev_oc.region.roa import LinearizedLoop, RoaCertifier, certify_roa
from maglev_oc.region.robust_certificate import RobustCertifier
from tests.test_microstepper_region import PLATFORM


@pytest.fixture(scope="module")
def linear(model):
    return paper_linear_regulator(model)


def test_near_a_stopper_the_stability_search_stops_at_four_times_the_stoppers_level(model, linear):
    """At 29.9 mm the upper stopper (30 mm) is 0.1 mm away: its level is tiny, every level up to
    4x it is certified stable, and the search stops there after two steps (the stoppers' level,
    then 4x it), as its docstring says; the certified level is the stoppers'."""
    res = certify_roa(model, linear, Reference.setpoint(0.0299))
    assert res.level_stability == pytest.approx(4 * res.level_travel, rel=1e-12)
    assert res.bisections == 2
    assert res.level == res.level_travel


def test_the_bisection_stops_once_the_bracket_is_within_one_percent(model, linear):
    """At the papers' 20 mm the stability level binds; the bisection stops when the bracket
    closes to 1 %, long before its 40 allowed steps (measured 14), and the level 1 % above is
    not certified (the bracket's other end)."""
    res = certify_roa(model, linear, Reference.setpoint(0.02))
    assert res.level_stability < res.level_travel
    assert res.bisections < 20
    cert = RoaCertifier(LinearizedLoop(model, linear, Reference.setpoint(0.02)))
    above = 1.01 * res.level_stability
    assert cert.decrease_margin(res.P, cert.jacobian_box(res.P, above)) >= 0


def test_with_no_step_allowed_nothing_is_certified_and_no_step_is_counted(model, linear):
    """``iterations=0``: no level is tried, nothing is certified, and the result says 0 steps."""
    res = certify_roa(model, linear, Reference.setpoint(0.02), iterations=0)
    assert not res.success and res.status == "not_certified"
    assert res.bisections == 0 and res.level == 0.0


@pytest.mark.parametrize("entry", [0.0, -1.0])
def test_a_matrix_with_a_non_positive_diagonal_certifies_nothing(model, linear, entry):
    """The decrease margin of a P with a zero or negative diagonal entry is +inf (not certified),
    without a RuntimeWarning (the suite turns those from maglev_oc into errors)."""
    loop = LinearizedLoop(model, linear, Reference.setpoint(0.02))
    cert = RoaCertifier(loop)
    P = loop.lyapunov_matrix()
    box = cert.jacobian_box(P, 1e-6)
    assert math.isfinite(cert.decrease_margin(P, box))  # the real P: a finite margin
    bad = P.copy()
    bad[3, 3] = entry
    assert cert.decrease_margin(bad, box) == math.inf


@pytest.mark.parametrize("option", ["K_h", "K_v"])
def test_the_microstepper_names_the_gains_it_refuses(option):
    with pytest.raises(InputError, match=rf"^{option} must be 5 finite gains"):
        MicrostepperRegion(PLATFORM, **{option: np.ones(4)})


@pytest.mark.parametrize(("given", "kind"), [("20 mm", "str"), (None, "NoneType"), (0.02, "float")])
def test_the_robust_certifier_names_what_it_got_instead_of_a_nominal_certificate(model, given, kind):
    certifier = RobustCertifier(FeasibleSet(model), RegulatorLoop(), max_boxes=1000, ladder=(1.0,))
    with pytest.raises(TypeError, match=rf"^nominal must be a Procedure2Result, got {kind}$"):
        certifier.run(given, None)


def test_a_missing_row_of_the_robust_study_names_the_plant_sets_it_has():
    """Asking a sampled robustness study for a row it does not hold raises KeyError with the
    set-point and plant set asked for and the plant sets the study has, in table order."""
    from maglev_oc.region.study import RobustStudy
    from maglev_oc.region.sweep import PlantSet

    box = PlantSet.box([14.0, 2.0, 2.0, 0.1], [16.0, 3.0, 3.0, 0.2])
    study = RobustStudy(np.eye(4), "assumed", True, (0.9, 0.99), box, {}, (), (), 10, 5)
    with pytest.raises(KeyError) as err:
        study.row("20 mm", "0.95")
    assert err.value.args[0] == "no row ('20 mm', '0.95'); plant sets: ('nominal', '0.9', '0.99', 'box')"


@pytest.fixture(scope="module")
def start_target_maps(model):
    """The large step's start x target maps (FL and linear regulators) on 2 x 2 pairs, 3 s each (the
    study's horizon), judged against no current limit and against 4.5 A (the pairs peak at 3.2-6.4 A:
    some over it, some not)."""
    import dataclasses

    from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
    from maglev_oc.region.study import _Run, _start_target_maps
    from maglev_oc.sim.twin import RigTwin
    from tests.test_region_study import TINY

    loop = RegulatorLoop()
    config = dataclasses.replace(TINY, linear_horizon=3.0)
    starts, targets = np.array([0.022, 0.026]), np.array([0.018, 0.020])
    out = {}
    for limit in (None, 4.5):
        run = _Run(
            model, config, FeasibleSet(model, current_limit=limit), loop, np.random.default_rng(0), print, {}
        )
        fl = FeedbackLinearizingRegulator(model, loop.K_h, loop.K_v, omega0=loop.omega0)
        sim = run.simulator(RigTwin(model), fl, 3.0)
        out[limit] = _start_target_maps(run, sim, [paper_linear_regulator(model)], starts, targets)
    return out


def test_the_start_target_maps_judge_the_current_against_the_limit_in_force(start_target_maps):
    """The same runs judged twice: with no limit no pair is "over the current limit" (code 1); with
    4.5 A exactly the pairs that converged and peaked above 4.5 A are, every other pair keeping
    its outcome. Not vacuous: each controller has pairs on both sides of the limit."""
    free, limited = start_target_maps[None], start_target_maps[4.5]
    assert free.keys() == limited.keys() and len(free) == 2
    for name in free:
        a, b = free[name]["outcome"], limited[name]["outcome"]
        assert a.shape == (2, 2) and not np.any(a == 1), (name, a)
        over = limited[name]["max_current"] > 4.5
        assert np.any(b == 1) and np.any(b == 0), (name, b)
        np.testing.assert_array_equal(b == 1, (a == 0) & over)
        np.testing.assert_array_equal(a, np.where(b == 1, 0, b))


def test_the_robust_ladder_refines_between_the_certified_rung_and_the_one_above(model, monkeypatch):
    """With a branch and bound that certifies exactly the levels below 0.8 c_nom and refutes the
    others (a stand-in: the real one rarely fails a rung and passes a lower one on this stage),
    the ladder (1, 0.6, 0.3) certifies 0.6 and bisects [0.6, 1] three times (REFINE_STEPS):
    0.8 refuted, 0.7 and 0.75 certified. The certified level is 0.75 c_nom, the least refuted
    level 0.8 c_nom, and every attempt is in the order made."""
    from maglev_oc.region.procedure2 import Procedure2
    from maglev_oc.region.robust_certificate import REFINE_STEPS, RobustSearch
    from maglev_oc.region.sweep import PlantSet

    feasible, loop = FeasibleSet(model), RegulatorLoop()
    nominal = Procedure2(feasible, loop).run(Reference.setpoint(0.02))
    c_nom = nominal.level

    def search(self, reference, P, level, plants, geo, t0):
        ok = level < 0.8 * c_nom * (1 - 1e-12)
        status = "certified" if ok else "refuted"
        return RobustSearch(ok, status, status, level, 1, None, 0.0, None, -1.0 if ok else 1.0)

    monkeypatch.setattr(RobustCertifier, "_search", search)
    certifier = RobustCertifier(feasible, loop, max_boxes=1000, ladder=(1.0, 0.6, 0.3))
    res = certifier.run(nominal, PlantSet.point(model.constants.as_array()))
    assert REFINE_STEPS == 3
    assert [a.level / c_nom for a in res.attempts] == pytest.approx([1.0, 0.6, 0.8, 0.7, 0.75])
    assert res.status == "certified" and res.level == pytest.approx(0.75 * c_nom)
    assert res.level_upper == pytest.approx(0.8 * c_nom)


def test_the_linearized_loop_cannot_be_changed_after_it_is_built(model, linear):
    """The loop's matrices are shared by every certificate built on it (the Jacobian boxes, the
    Lyapunov matrix, the stoppers' levels): each is read-only, so a caller that writes into one
    gets an error instead of silently changing the loop under a certificate already issued."""
    loop = LinearizedLoop(model, linear, Reference.setpoint(0.02))
    for name in ("A", "output", "z_eq", "u_eq", "K_h", "K_v"):
        value = getattr(loop, name)
        assert not value.flags.writeable, name
        with pytest.raises(ValueError, match="read-only"):
            value.flat[0] = 1.0


def test_the_certified_study_checks_its_largest_set_with_the_configs_seed(model, monkeypatch):
    """The certified robust study (``region.study._certified``): per set-point the robust levels are
    certified confidence level by confidence level and stop at the first not certified; the
    Monte Carlo check then runs ``config.certify_runs`` runs, drawn with the study's seed (a study
    is reproducible from its config), inside the largest set certified at the first confidence
    level, with that certificate's plants, P and level; its counts are the study's. The costly
    parts (the robust SDP, Procedure 2, the branch and bound) and the sweep are stand-ins whose
    answers are scripted, so what is checked is the study's own bookkeeping."""
    import dataclasses
    from types import SimpleNamespace

    from maglev_oc.region import study as study_module
    from maglev_oc.region import sweep as sweep_module
    from maglev_oc.region.study import CONFIDENCE_LEVELS, _certified
    from tests.test_region_study import TINY

    # certified levels per set-point, one per confidence level in order (None: not certified)
    script = {0.018: (2.0, None, 1.0, 0.5), 0.02: (3.0, 2.5, 2.0, 1.5), 0.022: (1.0, 0.5, 0.2, None)}
    assert len(CONFIDENCE_LEVELS) == 4
    calls: list[tuple[float, object]] = []

    class Nominal:
        def __init__(self, feasible, loop):
            pass

        def run(self, reference, P):
            return SimpleNamespace(success=True, reference=reference)

    class Certifier:
        def __init__(self, feasible, loop, max_boxes, ladder):
            pass

        def run(self, nominal, plants):
            gap = nominal.reference.gap
            k = sum(1 for g, _ in calls if g == gap)
            calls.append((gap, plants))
            level = script[gap][k]
            ok = level is not None
            return SimpleNamespace(success=ok, level=level if ok else 0.0, P=np.eye(10) * (1 + k))

    @dataclasses.dataclass(frozen=True)
    class Spec:
        plants: object = None
        P: tuple = ()
        level: float = 0.0

    sweeps = []

    def run_sweep(spec, n, *, seed=0, progress=True):
        sweeps.append((spec, n, seed))
        return SimpleNamespace(violations=3, n=n)

    monkeypatch.setattr(study_module, "Procedure2", Nominal)
    monkeypatch.setattr(study_module, "RobustCertifier", Certifier)
    monkeypatch.setattr(study_module, "robust_lyapunov_matrix", lambda c, lyap, plants: (np.eye(10), "ok"))
    monkeypatch.setattr(sweep_module, "run_sweep", run_sweep)
    config = dataclasses.replace(TINY, seed=41, certify_runs=17, certify_boxes=10)
    refs = [SimpleNamespace(reference=Reference.setpoint(g), lyapunov=None) for g in script]
    specs = {f"{g * 1e3:g} mm": Spec() for g in script}
    covariance = np.diag([0.05, 0.01, 0.01, 1e-3]) ** 2

    def certified(config):
        calls.clear()
        sweeps.clear()
        run = SimpleNamespace(config=config, model=model, feasible=None, loop=None)
        return _certified(run, refs, covariance, specs)

    out = certified(config)
    # certificates per set-point: up to and including the first not certified
    assert [len(r.certificates) for r in out.rows] == [2, 4, 4]
    assert [r.certificates[-1].success for r in out.rows] == [False, True, False]
    # one check, in the largest set certified at the first level (20 mm: 3.0), with the study's seed
    assert len(sweeps) == 1
    spec, n, seed = sweeps[0]
    assert (n, seed) == (17, 41)
    assert out.checked == ("20 mm", CONFIDENCE_LEVELS[0])
    assert spec.level == 3.0 and np.array_equal(np.array(spec.P), np.eye(10))
    assert spec.plants is next(p for g, p in calls if g == 0.02)  # the first level's plant set
    assert (out.runs, out.violations) == (17, 3)
    # no runs asked for: no check
    out = certified(dataclasses.replace(config, certify_runs=0))
    assert sweeps == [] and out.checked is None and (out.runs, out.violations) == (0, 0)


@pytest.mark.parametrize("cover", [1, 0, -3])
def test_a_cover_of_fewer_than_two_boxes_is_refused_by_name(model, linear, cover):
    """``RoaCertifier(cover=...)``: the Jacobian box is the union over a cover of the level set's
    angles, which needs two pieces at least; fewer is a clear error that names the option and the
    value given."""
    loop = LinearizedLoop(model, linear, Reference.setpoint(0.02))
    with pytest.raises(InputError, match=rf"cover must be >= 2, got {cover}"):
        RoaCertifier(loop, cover=cover)
