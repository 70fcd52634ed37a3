"""Monte Carlo sweeps over sampled plants (maglev_oc.region.sweep) and `region --robust`."""

from __future__ import annotations

import dataclasses
import json
import sys

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from maglev_oc.cli import main
from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.errors import InputError
from maglev_oc.model.stage import StageModel
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.montecarlo import BatchSimulator, check_error_states
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.region.sweep import PlantSet, SampledPlantTwin, SweepSpec, dask_client, run_sweep
from maglev_oc.sim.effects import TwinEffects
from maglev_oc.sim.twin import RigTwin

FIELDS = (
    "violating",
    "constants",
    "effect_scales",
    "start_ratio",
    "min_margin",
    "max_current",
    "stopper_hit",
    "min_gap",
)


@pytest.fixture(scope="module")
def model():
    return StageModel()


@pytest.fixture(scope="module")
def spec20(model):
    """Starts in the nominal certificate at 20 mm (Lyapunov P), on the nominal plant."""
    ref = Reference.setpoint(0.020)
    cert = Procedure2(FeasibleSet(model), RegulatorLoop()).run(ref)
    assert cert.success
    C = model.constants.as_array()
    return SweepSpec(PlantSet.point(C), ref, P=tuple(map(tuple, cert.P)), level=cert.level)


def _same(a, b):
    for k in FIELDS:
        assert_array_equal(getattr(a, k), getattr(b, k), err_msg=k)


def test_one_worker_and_a_local_cluster_of_two_give_bit_identical_numbers(model, spec20):
    C = np.asarray(model.constants.as_array())
    spec = spec20.with_plants(PlantSet.box(0.8 * C, 1.2 * C))  # wide enough for some violations
    local = run_sweep(spec, 300, seed=4, task_size=100)
    with dask_client(workers=2) as client:
        dask = run_sweep(spec, 300, seed=4, task_size=100, client=client)
    assert "2 workers" in dask.workers and local.workers == "this process"
    _same(local, dask)
    assert local.violations == dask.violations > 0


def test_a_planted_plant_far_outside_the_set_is_flagged(model, spec20):
    # C2 x 1.5 pulls the mover onto the upper stopper from every start (C2 x 0.5 stays feasible:
    # the internal model absorbs the missing attraction within 9 A)
    C = np.asarray(model.constants.as_array())
    far = C * np.array([1.0, 1.5, 1.0, 1.0])
    ellipsoid = PlantSet.confidence(C, np.diag((0.02 * C) ** 2), 0.99)
    assert not ellipsoid.contains(far[:, None])[0]
    res = run_sweep(spec20.with_plants(PlantSet.point(far)), 100, seed=0, task_size=50)
    assert res.status == "violations" and res.violations == 100
    assert np.all(res.stopper_hit)
    inside = run_sweep(spec20.with_plants(ellipsoid), 100, seed=0, task_size=50)
    assert np.all(ellipsoid.contains(inside.constants)) and inside.violations == 0


def test_a_zero_size_set_reproduces_the_nominal_monte_carlo(model, spec20):
    zero = PlantSet.confidence(model.constants, np.zeros((4, 4)), 0.95)
    res = run_sweep(spec20.with_plants(zero), 200, seed=3, task_size=200)
    assert_allclose(res.constants, np.repeat(np.asarray(model.constants.as_array())[:, None], 200, 1))
    # the same starts through the nominal Monte Carlo (RigTwin, montecarlo.check_error_states)
    _, z = spec20.draw(200, np.random.SeedSequence(3).spawn(1)[0])
    sim = BatchSimulator(RigTwin(model), FeedbackLinearizingRegulator(model), duration=1.0)
    chk = check_error_states(sim, RegulatorLoop(), spec20.reference, np.asarray(spec20.P), spec20.level, z)
    assert_array_equal(res.violating, chk.violating)
    # L_theta(y, C) and L(y) are the same products C_i l_i(y): equal to rounding
    assert_allclose(res.min_margin, chk.outcome.min_margin, rtol=1e-12)
    assert_allclose(res.max_current, chk.outcome.max_current, rtol=1e-12)
    assert_allclose(res.start_ratio, chk.start_ratio, rtol=1e-12)


def _steps(twin, states, u) -> np.ndarray:
    return np.column_stack([np.asarray(twin.step(s, u)[0]).ravel() for s in states.T])


def test_effect_scales_are_the_twin_with_scaled_effects(model):
    """A scale row is the same twin with that effect's numbers scaled, built independently as a
    RigTwin with scaled dataclasses: ones = the rig twin exactly; (2, 0.5, 3) = guides with 2x
    and 0.5x Coulomb level and viscous coefficient (same pre-sliding distance) and 3x cogging
    (to 1e-12 relative: the same arithmetic in another order); zeros = no friction, no cogging."""
    rig = TwinEffects.rig(misalignment=None)  # binding friction scales with the level too: left out
    sampled = SampledPlantTwin(model, rig)
    rng = np.random.default_rng(5)
    x = np.vstack(
        [0.012 + 0.012 * rng.random(8), 0.05 * rng.standard_normal(8), 0.05 * rng.standard_normal((2, 8))]
    )
    x[3] *= 2.0
    u = np.array([0.7, -1.3])

    def states(twin, scales, friction):
        out = []
        for k in range(x.shape[1]):
            s = twin.initial_state(x[:, k], u)
            s[7:9] = friction[:, k]
            out.append(s if scales is None else np.concatenate([s[:-7], scales, s[-4:]]))
        return np.column_stack(out)

    fr = 0.05 * rng.standard_normal((2, 8))
    base = _steps(RigTwin(model, rig), states(RigTwin(model, rig), None, fr), u)
    ones = _steps(sampled, states(sampled, np.ones(3), fr), u)
    assert_array_equal(ones[: base.shape[0]], base)

    def scaled(f, k):
        return dataclasses.replace(f, coulomb=k * f.coulomb, viscous=k * f.viscous)

    c = rig.cogging
    bigger = dataclasses.replace(
        rig,
        friction_vertical=scaled(rig.friction_vertical, 2.0),
        friction_horizontal=scaled(rig.friction_horizontal, 0.5),
        cogging=dataclasses.replace(
            c, peak_at_reference=3 * c.peak_at_reference, horizontal_peak=3 * c.horizontal_peak
        ),
    )
    # the Dahl state of k-times guides is k times the state: start them there
    fr_k = fr * np.array([[2.0], [0.5]])
    want = _steps(RigTwin(model, bigger), states(RigTwin(model, bigger), None, fr_k), u)
    got = _steps(sampled, states(sampled, np.array([2.0, 0.5, 3.0]), fr_k), u)
    assert_allclose(got[: want.shape[0]], want, rtol=1e-12, atol=1e-15)
    assert np.max(np.abs(got[:4] - ones[:4])) > 0  # and they do move the plant

    none = dataclasses.replace(rig, friction_vertical=None, friction_horizontal=None, cogging=None)
    zero_fr = np.zeros((2, 8))
    want = _steps(RigTwin(model, none), states(RigTwin(model, none), None, zero_fr), u)
    got = _steps(sampled, states(sampled, np.zeros(3), zero_fr), u)
    assert_allclose(got[: want.shape[0]], want, rtol=1e-12, atol=1e-15)


def test_sweeps_draw_effect_scales_in_their_ranges_beside_the_same_plants(model, spec20):
    C = np.asarray(model.constants.as_array())
    plants = PlantSet.box(0.98 * C, 1.02 * C)
    spec = dataclasses.replace(
        spec20, plants=plants, effects=TwinEffects.rig(), effect_ranges=((0.5, 2.0), (0.0, 3.0), (1.0, 1.0))
    )
    a = run_sweep(spec, 120, seed=7, task_size=60, progress=False)
    b = run_sweep(spec, 120, seed=7, task_size=60, progress=False)
    _same(a, b)
    k = a.effect_scales
    assert k.shape == (3, 120) and np.all(k[0] >= 0.5) and np.all(k[0] <= 2.0) and np.all(k[1] <= 3.0)
    assert np.all(k[2] == 1.0) and np.ptp(k[0]) > 1.0  # spread over the range
    # the plants and starts come from their own streams: the same with or without effect ranges
    plain = run_sweep(
        dataclasses.replace(spec, effect_ranges=None), 120, seed=7, task_size=60, progress=False
    )
    assert_array_equal(plain.constants, a.constants) and np.all(plain.effect_scales == 1.0)
    # inside the 20 mm certificate, the rig's friction and cogging up to 3x still leave F alone
    assert a.violations == 0
    with pytest.raises(InputError, match="effect_ranges"):
        dataclasses.replace(spec, effect_ranges=((1.0, 0.5), (0, 1), (0, 1)))


def test_the_empirical_robust_level_sweeps_the_twin_it_was_given(model, spec20):
    """empirical_robust_level shrinks the level of ``spec`` over another plant set and keeps every
    other setting: a spec with the rig's effects at scales up to 3x is swept with them (the effect
    scales of its runs span their ranges), not on the ideal twin."""
    from maglev_oc.region.robust import empirical_robust_level

    C = np.asarray(model.constants.as_array())
    spec = dataclasses.replace(
        spec20, effects=TwinEffects.rig(), effect_ranges=((0.5, 2.0), (0.0, 3.0), (1.0, 1.0))
    )
    out = empirical_robust_level("20 mm", spec, PlantSet.box(0.99 * C, 1.01 * C), runs=40, task_size=40)
    swept = out.check  # the last sweep
    assert swept.spec.effects == spec.effects and swept.spec.effect_ranges == spec.effect_ranges
    k = swept.effect_scales
    assert np.all(k[0] >= 0.5) and np.all(k[0] <= 2.0) and np.ptp(k[1]) > 1.0
    assert swept.spec.level == out.level and swept.spec.plants.label == out.plants


def test_the_empirical_level_ends_below_every_violating_start_it_saw(monkeypatch, spec20):
    """Each round's level lies below the V/c of every violating run of the round before (0.95 x
    the least ratio), so no start seen to violate stays inside; runs that did not violate do not
    move it; seeds advance by round. A stub sweep plants the violations (ratios of start V to the
    level swept), so the rule is checked exactly, to round-off."""
    from types import SimpleNamespace

    from maglev_oc.region import robust

    planted = [np.array([0.9, 0.5, 0.7, 0.2]), np.array([0.8, 0.99, 0.95]), np.array([0.5])]
    violating = [np.array([True, True, False, False]), np.array([False, True, True]), np.array([False])]
    seen = []

    def sweep(spec, runs, *, seed, task_size, client):
        k = len(seen)
        seen.append((spec.level, seed))
        return SimpleNamespace(
            violations=int(violating[k].sum()), start_ratio=planted[k], violating=violating[k], spec=spec
        )

    monkeypatch.setattr(robust, "run_sweep", sweep)
    out = robust.empirical_robust_level("20 mm", spec20, spec20.plants, runs=4, seed=7)
    level0 = spec20.level
    levels = [s[0] for s in seen]
    assert [s[1] for s in seen] == [7, 8, 9]
    assert levels[1] == pytest.approx(level0 * 0.95 * 0.5, rel=1e-12)  # the least violating ratio
    assert levels[2] == pytest.approx(levels[1] * 0.95 * 0.95, rel=1e-12)
    # the property itself: every start that violated lies above the final level
    for k in range(2):
        v_starts = planted[k][violating[k]] * levels[k]
        assert np.all(v_starts > out.level)
    assert out.level == levels[2] and out.rounds == 3 and out.ratio == pytest.approx(levels[2] / level0)


def test_seeds_change_the_samples_and_repeat_them(model, spec20):
    C = np.asarray(model.constants.as_array())
    spec = spec20.with_plants(PlantSet.box(0.95 * C, 1.05 * C))
    a, b, c = (run_sweep(spec, 40, seed=s, task_size=20) for s in (0, 0, 1))
    _same(a, b)
    assert not np.any(a.constants == c.constants)
    assert not np.any(a.start_ratio == c.start_ratio)
    # the task stream does not depend on how many runs follow: the first task is the same
    longer = run_sweep(spec, 60, seed=0, task_size=20)
    assert_array_equal(longer.constants[:, :40], a.constants)


def test_confidence_sets_scale_with_the_chi_square_quantile(model):
    C = np.asarray(model.constants.as_array())
    cov = np.diag((0.02 * C) ** 2)
    rng = np.random.default_rng(0)
    small, large = (PlantSet.confidence(C, cov, p).sample(4000, rng) for p in (0.5, 0.99))
    r = [np.sqrt(np.sum(((s - C[:, None]) / (0.02 * C[:, None])) ** 2, axis=0)).max() for s in (small, large)]
    # chi2(4) quantiles 3.357 and 13.28: radii 1.832 and 3.644 sigma (max of 4000 uniform draws: within 1 %)
    assert_allclose(r, [1.832, 3.644], rtol=0.01)


def test_missing_dask_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "dask.distributed", None)
    with pytest.raises(InputError, match=r"maglev_oc\[sweeps\]"):
        with dask_client(workers=2):
            pass
    with dask_client(workers=1) as client:  # one worker needs no Dask
        assert client is None


@pytest.mark.parametrize(
    ("kw", "field"),
    [
        (dict(n=0), "n"),
        (dict(n=2.0), "n"),
        (dict(task_size=0), "task_size"),
        (dict(seed=-1), "seed"),
        (dict(seed=1.5), "seed"),
    ],
)
def test_run_sweep_refuses_counts_and_seeds_that_are_not_non_negative_integers(spec20, kw, field):
    """Each argument is checked before any run: a negative integer seed (which SeedSequence
    would refuse with its own message) and a float one are refused by name, like n and task_size."""
    args = {"n": 10, **kw}
    with pytest.raises(InputError, match=rf"^{field} must be a (positive|non-negative) integer, got"):
        run_sweep(spec20, args.pop("n"), **args)


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--robust", "--box", "C9=1:2"], "--box"),
        (["--robust", "--box", "C2=800:700"], "LO <= HI"),
        (["--robust", "--confidence", "1.5"], "--confidence"),
        (["--robust", "--confidence", "0.9", "--box", "C2=700:800"], "contradict"),
        (["--workers", "2"], "only apply with --robust"),
        (["--robust", "--workers", "0"], "--workers"),
        (["--robust", "--samples", "0"], "--samples"),
    ],
)
def test_region_robust_rejects_bad_options(args, needle, capsys):
    assert main(["region", "--gaps", "20", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0]


def test_region_robust_writes_its_table(tmp_path, capsys):
    out = tmp_path / "robust.json"
    code = main(["region", "--robust", "--gaps", "20", "--samples", "200", "--seed", "1", "--json", str(out)])
    assert code == 0
    doc = json.loads(out.read_text())
    (row,) = doc["setpoints"]
    assert row["runs"] == 200 and row["nominal_violations"] == 0
    assert "ASSUMED" in doc["plants_source"] and "not a certificate" in doc["note"]
    assert "sampled, not certified" in capsys.readouterr().out


def test_region_robust_takes_the_covariance_of_a_stage_file(tmp_path, capsys):
    # --params with a stage file that has a covariance: the plants are drawn from it, and the
    # output says so (not ASSUMED). A covariance 100x smaller than the assumed one keeps every
    # run of the nominal set feasible, like the nominal plant.
    from maglev_oc.model.parameters import StageParameters
    from maglev_oc.model.stage import StageModel
    from maglev_oc.model.stagefile import Provenance, StageFile
    from maglev_oc.region.robust import assumed_covariance

    model = StageModel()
    cov = assumed_covariance(model.constants) * 1e-4
    stage = StageFile(
        StageParameters(),
        model.constants,
        cov,
        {},
        (),
        {
            "geometry": Provenance.now((), "Table I of paper 000"),
            "constants": Provenance.now(("run.csv",), "output_error"),
            "effects": Provenance.now((), "none"),
        },
    )
    path = tmp_path / "stage.json"
    stage.write(path)
    out = tmp_path / "robust.json"
    argv = ["region", "--robust", "--params", str(path), "--gaps", "20", "--samples", "100"]
    assert main([*argv, "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["plants_source"] == f"covariance of {path}"
    (row,) = doc["setpoints"]
    assert row["runs"] == 100 and row["nominal_violations"] == 0
    capsys.readouterr()
