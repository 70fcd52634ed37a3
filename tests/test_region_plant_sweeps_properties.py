"""Properties of the sweeps over sampled plants (``maglev_oc.region.sweep``), checked against sample
statistics and runs planted or repeated here:

- plants are uniform in an uncertainty ellipsoid of any rank, which needs one row and column per
  constant;
- a sweep judges its runs against its own current limit, each task draws its own effect scales,
  and its message counts its runs and those that left F; certified sets of starts are for the FL
  loop only;
- a sampled twin takes the effect scales in any shape of three, and ``run_plants`` refuses a
  one-dimensional start with an input error.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.errors import InputError
from maglev_oc.model.equilibrium import equilibrium_currents
from maglev_oc.model.parameters import DEFAULT_CONSTANTS
from maglev_oc.region.closed_loop import Reference
from maglev_oc.region.montecarlo import regulator_state
from maglev_oc.region.sweep import PlantBatchSimulator, PlantSet, SampledPlantTwin, SweepSpec, run_sweep
from maglev_oc.results import check_result
from maglev_oc.sim.effects import TwinEffects


# --- sampled plants -------------------------------------------------------------------------------
@pytest.mark.parametrize("rank", [1, 2, 3, 4])
def test_plants_are_uniform_in_an_ellipsoid_of_any_rank(model, rank):
    """``PlantSet.sample`` is uniform in the ellipsoid, which has the covariance's rank k as its
    dimension (the other constants held at the centre): the share of plants within half the
    radius is 0.5^k. 4000 draws: the binomial standard deviation is at most 0.008, 5 of them
    (0.04) allowed."""
    c = np.asarray(model.constants.as_array(), dtype=float)
    rel = np.array([0.02, 0.03, 0.01, 0.1])
    rel[rank:] = 0.0  # constants held fixed
    plants = PlantSet.confidence(c, np.diag((rel * c) ** 2), 0.9)
    C = plants.sample(4000, np.random.default_rng(11))
    d = (C - c[:, None]) / c[:, None]
    s = np.asarray(plants.shape) / np.outer(c, c)
    r2 = np.einsum("in,ij,jn->n", d, np.linalg.pinv(s), d)
    assert r2.max() <= 1 + 1e-9
    assert np.mean(r2 <= 0.25) == pytest.approx(0.5**rank, abs=0.04)


def test_a_sweep_judges_its_runs_against_its_own_current_limit(model):
    """A sweep's violations use the spec's ``current_limit``: from rest at the 20 mm set-point on
    the nominal plant the FL regulator commands the equilibrium current |u_eq| and nothing more
    (zero error, zero v; 000 eq. (7)), so every run violates a limit 0.05 A below |u_eq| and none
    violates one 0.05 A above it, or no limit at all. 0.05 A is far above the loop's rounding
    (the commanded current is exact to ~1e-12 A at rest) and the amplifier is ideal."""
    C = model.constants.as_array()
    u_eq = abs(float(equilibrium_currents(model, [0.02]).current[0]))
    spec = SweepSpec(PlantSet.point(C), Reference.setpoint(0.02), start=(0.02, 0.0, 0.0, 0.0), duration=0.02)
    for limit, violations in ((u_eq - 0.05, 3), (u_eq + 0.05, 0), (None, 0)):
        res = run_sweep(dataclasses.replace(spec, current_limit=limit), 3, progress=False)
        assert res.violations == violations, limit
        np.testing.assert_allclose(res.max_current, u_eq, rtol=1e-6)


# --- the sweep's effect scales ---------------------------------------------------------------------------
def test_each_task_of_a_sweep_draws_its_own_effect_scales():
    """6 runs in tasks of 3 at one fixed start: each task's three runs get their own scales,
    not the first task's again (on a continuous uniform draw a repeat has probability 0), and
    the sweep is reproducible (the same seed, the same scales bit for bit). The scales lie in
    their ranges (a range (1, 1) is exactly 1)."""
    spec = SweepSpec(
        PlantSet.point(DEFAULT_CONSTANTS.as_array()), Reference.setpoint(0.02), start=(0.02, 0.0, 0.0, 0.0),
        duration=0.01, effects=TwinEffects.rig(), effect_ranges=((0.5, 2.0), (0.0, 3.0), (1.0, 1.0)),
    )  # fmt: skip
    a = run_sweep(spec, 6, seed=5, task_size=3, progress=False)
    k = a.effect_scales
    assert k.shape == (3, 6)
    assert (
        np.all((k[0] >= 0.5) & (k[0] <= 2.0))
        and np.all((k[1] >= 0.0) & (k[1] <= 3.0))
        and np.all(k[2] == 1.0)
    )
    assert not np.any(np.isin(k[:2, 3:], k[:2, :3]))  # no scale of task 1 is one of task 0's
    np.testing.assert_array_equal(run_sweep(spec, 6, seed=5, task_size=3, progress=False).effect_scales, k)


# --- sweeps --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def start_spec(model):
    """The nominal plant from one start 1 mm below 20 mm, 0.3 s (long enough for a planted plant
    with C2 x 1.5 to hit the upper stopper: tests/test_region_sweep.py)."""
    return SweepSpec(
        PlantSet.point(model.constants), Reference.setpoint(0.02), start=(0.021, 0, 0, 0), duration=0.3
    )


def test_a_sweeps_message_counts_its_runs_and_those_that_left_f(model, start_spec):
    far = np.asarray(model.constants.as_array()) * np.array([1.0, 1.5, 1.0, 1.0])
    for spec, bad in ((start_spec, 0), (start_spec.with_plants(PlantSet.point(far)), 3)):
        res = run_sweep(spec, 3, task_size=2, progress=False)
        check_result(res)
        assert res.violations == bad
        want = f"3 runs ({spec.plants.label}; {spec.reference.label}): {bad} left F"
        assert res.message == want


# --- sampled-plant twins --------------------------------------------------------------------------
def test_a_sampled_twin_takes_the_effect_scales_in_any_shape_of_three(model):
    """``scales`` (3,) as documented; (1, 3) and (3, 1) give the same state (as ``constants`` of
    any shape of 4 values do, _constants_array); 2 or 4 values are refused as bad input naming
    ``scales``, never a state whose constants sit one row off."""
    twin = SampledPlantTwin(model)
    x = np.array([0.018, 0.01, 0.004, -0.02])
    k = np.array([2.0, 0.5, 3.0])
    flat = twin.initial_state(x, scales=k)
    assert flat.shape == (twin.n_state,)
    assert_array_equal(flat[-7:-4], k)
    for shape in ((1, 3), (3, 1)):
        assert_array_equal(twin.initial_state(x, scales=k.reshape(shape)), flat, err_msg=str(shape))
    for bad in (k[:2], np.append(k, 1.0)):
        with pytest.raises(InputError, match="scales"):
            twin.initial_state(x, scales=bad)


def test_run_plants_refuses_a_one_dimensional_start_with_an_input_error(model):
    """``x0`` is documented (4, n): a (4,) start is refused as bad input before any run, whether the
    constants come as (4,) or as the (4, 1) of one run, and the message names x0 and its shape (it
    blamed the right (4, 1) constants)."""
    sim = PlantBatchSimulator(
        SampledPlantTwin(model), FeedbackLinearizingRegulator(model), duration=0.01, threads=1, compile=False
    )
    x0 = np.array([0.021, 0.0, 0.0, 0.0])
    c0 = regulator_state(x0[:, None], np.zeros((6, 1)))
    C = np.asarray(model.constants.as_array())
    for constants in (C, C[:, None]):
        with pytest.raises(InputError, match=r"x0 must have shape \(4, n\).*\(4,\)"):
            sim.run_plants(x0, c0, Reference.setpoint(0.02).signals(0.0)[:, 0], constants)


@pytest.mark.parametrize("controller", ["lqr", "linear"])
def test_a_certified_set_of_starts_is_for_the_fl_loop_only(model, controller):
    plants = PlantSet.point(model.constants)
    ref = Reference.setpoint(0.02)
    P = tuple(map(tuple, np.eye(10)))
    with pytest.raises(InputError, match=r"certified set .* are for the FL loop"):
        SweepSpec(plants, ref, controller=controller, P=P, level=1.0)
    assert SweepSpec(plants, ref, controller="fl", P=P, level=1.0).controller == "fl"
    start = SweepSpec(plants, ref, controller=controller, start=(0.02, 0.0, 0.0, 0.0))
    assert start.controller == controller and start.P is None


def test_an_uncertainty_ellipsoid_needs_one_row_and_column_per_constant():
    """A symmetric, finite, positive definite 3 x 3 shape is refused with a message naming the 4 x 4
    shape it needs; the same matrix bordered to 4 x 4 (C4 held) is accepted."""
    s3 = np.diag([0.1, 1.0, 0.01])
    with pytest.raises(InputError, match="4 x 4"):
        PlantSet("ellipsoid", (14.8, 100.0, 2.0, 0.13), shape=tuple(map(tuple, s3)))
    s4 = np.zeros((4, 4))
    s4[:3, :3] = s3
    assert PlantSet("ellipsoid", (14.8, 100.0, 2.0, 0.13), shape=tuple(map(tuple, s4))).kind == "ellipsoid"
