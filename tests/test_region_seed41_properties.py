"""Region properties from the survivors of the seed-41 mutation run, each a property of a result a
user sees, not of one line:

* the microstepper's largest level says "undecided" (success False, level 0, no half-width) when
  no level above zero could be certified, every bisection pass having spent its box budget; the
  message still gives the bracket and the constraint that fails;
* every Procedure 2 result is a result by the convention (a ``message`` string) that names its
  binding constraint, also when the stoppers' exact level is the certificate (12 mm);
* a sweep's ``message`` says how many runs, on which plants and reference, and how many left F;
* the empirical robust level's default seed is 0: without ``seed`` it draws the same plants and
  starts, and finds the same numbers, as with ``seed=0`` (and not those of seed 1);
* a sampled-plant twin's state takes the effect scales as (3,), (1, 3) or (3, 1) alike (as its
  constants take any shape of 4 values), and refuses scales of another length instead of shifting
  the constants' rows;
* ``run_plants`` refuses a 1-D ``x0`` (documented (4, n)) with an InputError naming it, whatever
  the shape of the constants, never an IndexError from deep inside;
* the study's timings name its steps in the order they ran (the rows of the report's timing
  table), the conservativeness slices among them;
* the study's quantisation Monte Carlo really adds encoder noise: the same starts on the same
  quantising twin without noise end elsewhere.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.errors import InputError
from maglev_oc.region import robust
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.microstepper import AXES, MICROSTEPPER_CONSTRAINTS, MicrostepperRegion
from maglev_oc.region.montecarlo import BatchSimulator, regulator_state
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.region.study import operating_region_study
from maglev_oc.region.sweep import PlantBatchSimulator, PlantSet, SampledPlantTwin, SweepSpec, run_sweep
from maglev_oc.results import check_result
from tests.test_microstepper_region import PLATFORM
from tests.test_region_study import TINY

MM = 1e-3


# --- the microstepper's region when nothing can be certified -------------------------------------
def test_a_microstepper_level_that_no_pass_could_certify_is_undecided(monkeypatch):
    """Every branch-and-bound pass after the set-point's own check (level 1e-12) runs out of its
    budget (planted: "undecided" after one box): the bisection certifies nothing, and the result
    says so, success False and status "undecided", with level 0 and zero half-widths; the upper
    end of the bracket and its constraint are still those of the refutation."""
    region = MicrostepperRegion(PLATFORM)
    setpoint = (0.0, 0.0, 0.025)
    certify = region.certify
    levels = []

    def out_of_budget(sp, level, *, max_boxes=1_000_000):
        levels.append(level)
        if len(levels) == 1:  # the set-point's own check (at 1e-12), done for real
            return certify(sp, level, max_boxes=max_boxes)
        return "undecided", 1, "", None

    monkeypatch.setattr(region, "certify", out_of_budget)
    res = region.largest_level(setpoint)
    check_result(res)
    assert levels[0] == 1e-12 and len(levels) > 2  # the check, the refuted level, the bisection
    assert (res.success, res.status, res.level) == (False, "undecided", 0.0)
    assert res.half_widths == dict.fromkeys(AXES, 0.0)
    assert res.binding in (*MICROSTEPPER_CONSTRAINTS, *AXES) and res.refuted_level > 0
    assert res.message.startswith("certified V <= 0;") and res.binding in res.message


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


# --- the study: its timings and its quantisation Monte Carlo --------------------------------------
CONFIG = dataclasses.replace(
    TINY, samples=2, slice_points=3, quantization_samples=4, map_points=0, horizon=0.05, robust_runs=0
)
"""tests/test_region_study.py's TINY smaller still (one set-point, 0.05 s runs, no robust part):
about 0.4 s."""
STEPS = [
    "build solvers",
    "procedure 2 (Lyapunov P)",
    "SDP enlargement (incl. re-certification)",
    "feasibility maps",
    "build Monte Carlo (FL)",
    "Monte Carlo inside the certified sets",
    "Monte Carlo on slices (conservativeness)",
    "Monte Carlo with encoder quantisation",
    "total",
]
"""The steps such a study runs, in order, as the report's timing table names them."""


@pytest.fixture(scope="module")
def recorded_study(model):
    """The study, with every batch of runs it simulates recorded: (simulator, x0, c0, reference,
    outcome)."""
    calls = []
    original = BatchSimulator.run

    def recording(self, x0, c0, reference, noise=None, twin_states=None):
        out = original(self, x0, c0, reference, noise, twin_states)
        calls.append((self, np.array(x0), np.array(c0), np.array(reference), out))
        return out

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(BatchSimulator, "run", recording)
        study = operating_region_study(model, CONFIG)
    return study, calls, original


def test_the_studys_timings_name_its_steps_in_the_order_they_ran(recorded_study):
    study, _, _ = recorded_study
    check_result(study)
    assert list(study.timings) == STEPS
    assert all(v >= 0 for v in study.timings.values())
    assert study.slices["Lyapunov P"], "the slices step ran"


def test_the_quantisation_monte_carlo_adds_encoder_noise(recorded_study):
    """The quantisation check is the one batch run on a twin with an encoder; the same starts on
    that simulator without noise (its default, zero) end elsewhere: final gap or position apart by
    more than 1e-8 m (measured: ~1e-6 m, the noise's 2 um; rounding of cm-sized states is ~1e-17 m),
    while the check's outcome is that of its own run."""
    study, calls, original = recorded_study
    quantising = [c for c in calls if c[0].twin.effects.encoder is not None]
    assert len(quantising) == 1
    sim, x0, c0, reference, out = quantising[0]
    assert study.quantization is not None and study.quantization.outcome is out
    assert study.quantization.n == x0.shape[1] == CONFIG.quantization_samples
    quiet = original(sim, x0, c0, reference)
    moved = np.abs(out.final_twin[[0, 2]] - quiet.final_twin[[0, 2]])
    assert np.all(np.isfinite(moved)) and moved.max() > 1e-8, moved
    assert math.isfinite(study.quantization.max_current)
