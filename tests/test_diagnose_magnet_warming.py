"""Magnets that warm during the run: the forces drift over the log, and a term may change over it.

A stage's coils dissipate i^2 R and the magnets warm with them; a neodymium magnet's field falls
by about 0.12 % per kelvin, and every force the magnets make follows (``tests.independent.effects
.MagnetWarming``). Before the diagnosis had a term that changes over the log, such a drift (9 K,
1.1 % of the field, over 60 s) was no function of the state it could describe: the constant
vertical force, the attraction's gap dependence and a gap sensor's offset each took half of the
held-out error and were not separable, nothing was claimed, and a 150 Hz amplifier lag beside it
was not found on 3 of 3 logs (the held-out last quarter's error was the drift's). Logs from
``tests/independent`` (no code shared with ``maglev_oc.sim``).
"""

from __future__ import annotations

import dataclasses
import json
import re

import casadi as ca
import numpy as np
import pytest

from maglev_oc.data.reading import read_log
from maglev_oc.diagnosis.pipeline import diagnose
from maglev_oc.errors import InputError
from maglev_oc.identification.layout import ParameterLayout
from maglev_oc.regression.data import prepare
from maglev_oc.regression.design import build_design
from maglev_oc.regression.terms import AccelerationTerm, held_by_guides, when_symbol
from maglev_oc.validation import simulate_windows
from tests.independent import core
from tests.independent.effects import AmplifierDynamics, GapSensorZero, GuideFriction, MagnetWarming
from tests.independent.logio import write_log
from tests.independent.physics import PAPERS_CONSTANTS, G, model_functions
from tests.independent.scoring import score
from tests.independent.simulate import Scenario, build_params, simulate
from tests.test_regression import _synthetic


def _drift(axis: int = 1) -> AccelerationTerm:
    """q s on one axis: the simplest term in time."""
    x, u, du, s, q = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("du", 2), ca.SX.sym("s"), ca.SX.sym("q")
    acc = ca.vertcat(q * s, 0) if axis == 0 else ca.vertcat(0, q * s)
    fn = ca.Function("drift", [x, u, du, s, q], [acc])
    return AccelerationTerm(
        "drift",
        "a force growing over the log",
        ("vertical", "horizontal")[axis],
        ("q",),
        function=fn,
        in_time=True,
    )


# --- the generator ---------------------------------------------------------------------------
def test_the_generators_warm_magnets_scale_the_attraction_by_the_field_squared_and_the_rest_by_it():
    # every force the magnets make follows their field w(t) (MagnetWarming.field_factor): L2 with its
    # square, L1 and L3 with it, L4 (the armature's own attraction) not at all; the C core against
    # the NumPy model and the Python law to rounding
    warming = MagnetWarming.large()
    p = build_params(Scenario(name="p", seed=0, effects=(warming,)), PAPERS_CONSTANTS)
    rng = np.random.default_rng(3)
    for t in (0.0, 30.0, 60.0, 600.0):
        w = warming.field_factor(t)
        gap, iq, id_ = rng.uniform(0.012, 0.026), rng.uniform(-3, 3), rng.uniform(-2, 5)
        ds, _ = core.eval_rhs(p, np.array([gap, 0.0, 0.01, 0.0, 0, 0]), iq, id_, t)
        L1, L2, L3, L4 = model_functions(gap, PAPERS_CONSTANTS)
        assert ds[1] == pytest.approx(G - L4 * (iq**2 + id_**2) - w * L3 * id_ - w**2 * L2, rel=1e-12)
        assert ds[3] == pytest.approx(-w * L1 * iq, rel=1e-12)


@pytest.mark.parametrize("axis", ["horizontal", "vertical"])
def test_the_generators_friction_changes_its_level_as_the_guides_warm(axis):
    # at steady sliding (bristles at rest, 0.1 m/s: fifty Stribeck speeds) the friction is
    # sign(v) F_C + s2 v, both times 1 + c (1 - exp(-t / T)); the magnets stay as they were
    friction = dataclasses.replace(GuideFriction.large(axis), warming_change=-0.3, warming_time_constant=40.0)
    p = build_params(Scenario(name="p", seed=0, effects=(friction,)), PAPERS_CONSTANTS)
    v, k = 0.1, (3, 1) if axis == "horizontal" else (4, 2)
    for t in (0.0, 20.0, 60.0):
        f = 1 - 0.3 * (1 - np.exp(-t / 40.0))
        state = np.zeros(6)
        state[0], state[5 if axis == "vertical" else 4] = (
            0.0195,
            f * friction.coulomb_force / friction.bristle_stiffness,
        )
        state[3 if axis == "horizontal" else 1] = v
        ds, aux = core.eval_rhs(p, state, 0.0, 0.0, t)
        assert ds[4 if axis == "horizontal" else 5] == pytest.approx(0.0, abs=1e-12)
        assert aux[k[0]] == pytest.approx(
            f * (friction.coulomb_force + friction.viscous_coefficient * v), rel=1e-12
        )


def test_the_warming_follows_its_first_order_law():
    # dT(t) = rise (1 - exp(-t / T)); the field 1 - c dT: 1 at the start, 1 - c rise long after
    w = MagnetWarming.large()
    assert w.field_factor(0.0) == 1.0
    assert w.field_factor(60.0) == pytest.approx(1 - 1.2e-3 * 15 * (1 - np.exp(-1)), rel=1e-12)
    assert w.field_factor(1e6) == pytest.approx(1 - 1.2e-3 * 15, rel=1e-12)
    with pytest.raises(ValueError, match="time constant"):
        MagnetWarming(time_constant=0.0)


def test_a_later_log_of_a_session_starts_warmer_and_warms_less():
    # a log begun 90 s after the rig was switched on is the cold log's continuation: its field at t
    # is the cold log's at t + 90 s, in the C core too (to rounding), and it changes less over 60 s
    cold, later = MagnetWarming.large(), MagnetWarming(rise=15.0, time_constant=60.0, start_time=90.0)
    assert later.field_factor(10.0) == pytest.approx(cold.field_factor(100.0), rel=1e-15)
    assert later.change_over_log(60.0) == pytest.approx(
        cold.field_factor(150.0) / cold.field_factor(90.0) - 1.0, rel=1e-12
    )
    assert abs(later.change_over_log(60.0)) < 0.25 * abs(cold.change_over_log(60.0))
    state = np.array([0.0195, 0.0, 0.01, 0.0, 0, 0])
    for t in (0.0, 30.0):
        ds_later, _ = core.eval_rhs(
            build_params(Scenario("l", 0, effects=(later,)), PAPERS_CONSTANTS), state, 1.0, 2.0, t
        )
        ds_cold, _ = core.eval_rhs(
            build_params(Scenario("c", 0, effects=(cold,)), PAPERS_CONSTANTS), state, 1.0, 2.0, t + 90.0
        )
        np.testing.assert_allclose(ds_later, ds_cold, rtol=1e-13)


# --- terms that change over the log ------------------------------------------------------------
@pytest.fixture(scope="module")
def two_logs(model):
    return prepare(
        [_synthetic(model, seconds=8.0, seed=1), _synthetic(model, seconds=6.0, seed=2)], bandwidth=10.0
    )


def test_the_place_in_the_log_runs_from_minus_one_to_one_in_each_log(two_logs):
    s = two_logs.log_place
    for k in range(two_logs.n_logs):
        mine = two_logs.segment == k
        assert s[mine][0] == -1.0 and s[mine][-1] == 1.0
        assert np.all(np.diff(s[mine]) > 0)
        # linear in time: the middle sample's place is the middle time's
        t = two_logs.t[mine]
        assert np.interp(0.5 * (t[0] + t[-1]), t, s[mine]) == pytest.approx(0.0, abs=1e-12)


def test_a_term_in_time_has_its_place_in_the_design_and_none_where_time_is_unknown(model, two_logs):
    term = _drift()
    design = build_design(two_logs, model, estimate=("C1",), terms=[term])
    col = design.columns[design.groups["drift"][0]]
    valid = two_logs.valid
    # the filter is symmetric with unit gain at zero frequency: a straight line passes it unchanged
    np.testing.assert_allclose(col[1, valid], two_logs.log_place[valid], atol=1e-9)
    assert np.all(col[0] == 0.0)
    # without a time (a feedforward, a stage file) the term is taken at the middle of the log
    x, u, du = np.zeros(4), np.zeros(2), np.zeros(2)
    assert float(term.acceleration([2.0])(x, u, du)[1]) == 0.0
    assert float(term.acceleration_in_time([2.0])(x, u, du, 0.5)[1]) == pytest.approx(1.0)
    assert term.linear and not term.depends_on_inputs()


def test_a_term_in_time_reads_which_log_a_sample_is_from(model, two_logs):
    # s = (place, log): a force q on the second log alone is a column that is the second log's
    # indicator (a constant within a log passes the filter unchanged); a term of the place alone
    # (s (1), as _drift) reads the first entry
    np.testing.assert_array_equal(two_logs.log_time[0], two_logs.log_place)
    np.testing.assert_array_equal(two_logs.log_time[1], two_logs.segment)
    x, u, du, s, q = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("du", 2), when_symbol(), ca.SX.sym("q")
    fn = ca.Function("second", [x, u, du, s, q], [ca.vertcat(q * (s[1] == 1), 0)])
    term = AccelerationTerm(
        "second_log", "a force in the second log", "vertical", ("q",), function=fn, in_time=True
    )
    design = build_design(two_logs, model, estimate=("C1",), terms=[term])
    col = design.columns[design.groups["second_log"][0]]
    valid = two_logs.valid
    np.testing.assert_allclose(col[0, valid], (two_logs.segment == 1)[valid], atol=1e-9)
    zero = np.zeros(4), np.zeros(2), np.zeros(2)
    assert float(term.acceleration_in_time([2.0])(*zero, [0.3, 1.0])[0]) == 2.0
    assert float(term.acceleration_in_time([2.0])(*zero, [0.3, 0.0])[0]) == 0.0
    assert float(_drift().acceleration_in_time([2.0])(*zero, [0.3, 1.0])[1]) == pytest.approx(0.6)


def test_a_term_in_time_moves_the_simulated_windows_by_its_place_in_the_log(model, two_logs):
    # a force q s over a 50 ms window moves the position by about q s h^2 / 2: forward late in the
    # log, backward early (s = +-1), the same everywhere without it
    starts = np.array([200, two_logs.n // 2 - 100])  # early in the first log, late in the second
    h = 50
    base, _ = simulate_windows(two_logs, starts, h, model)
    with_drift, _ = simulate_windows(two_logs, starts, h, model, [(_drift(), [0.4])])
    moved = with_drift[2, :, -1] - base[2, :, -1]
    s = two_logs.log_place[starts]
    expected = 0.4 * s * (h * two_logs.sample_time) ** 2 / 2
    np.testing.assert_allclose(moved, expected, rtol=0.05)  # s changes by 1 % over a window


def test_sticking_guides_hold_a_term_in_time_as_any_other():
    # static friction holds a stuck axis against every force on it: at rest the share h is taken
    # off, in motion (50 reversal speeds) none of it; the place in the log is kept
    held = held_by_guides(_drift(), {"horizontal": 0.5})
    assert held.in_time
    x_stuck, x_moving = np.zeros(4), np.array([0.0, 0.0, 0.0, 0.1])
    u = du = np.zeros(2)
    assert float(held.acceleration_in_time([2.0])(x_stuck, u, du, 0.5)[1]) == pytest.approx(0.5)
    assert float(held.acceleration_in_time([2.0])(x_moving, u, du, 0.5)[1]) == pytest.approx(1.0)


def test_terms_in_time_are_refused_where_no_time_is_known(model):
    with pytest.raises(InputError, match="changes over the log"):
        ParameterLayout(model, estimate=("C1",), terms=(_drift(),))
    x, u, du, q = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("du", 2), ca.SX.sym("q")
    four = ca.Function("f", [x, u, du, q], [ca.vertcat(q, 0)])
    with pytest.raises(InputError, match="a term in time must map"):
        AccelerationTerm("d", "", "vertical", ("q",), function=four, in_time=True)


# --- the diagnosis ---------------------------------------------------------------------------------
def _diagnosed(tmp_path, name: str, seed: int, *effects):
    run = simulate(Scenario(name=name, seed=seed, effects=effects))
    csv, truth = write_log(run, tmp_path, name)
    out = diagnose([read_log(csv)], limits=False)
    return out, score(name, json.loads(truth.read_text()), out.to_dict()["effects"])


@pytest.fixture(scope="module")
def warm_and_lag(tmp_path_factory):
    # warm_large+lag_7401: the field 1.14 % lower after 60 s, a 150 Hz lag after 0.2 ms
    return _diagnosed(
        tmp_path_factory.mktemp("warm"), "warm_lag", 7401, MagnetWarming.large(), AmplifierDynamics.large()
    )


def test_warming_magnets_are_found_and_sized_and_a_lag_beside_them_is_found_again(warm_and_lag):
    # found: the field -1.11 % (truth -1.14 %), the lag 1.3 ms (truth 1.26 ms in all); before,
    # nothing was claimed
    d, s = warm_and_lag
    assert sorted(s.claimed) == ["current_amplifier_lag", "magnet_field_drift"]
    assert s.size_right, s.notes  # both within the 30 %
    [drift] = [e for e in d.effects if e.name == "magnet_field_drift"]
    said = drift.finding
    assert "warming by about" in said and "from its first sample to its last" in said
    # nothing left over: the confounded stand-ins of the drift are gone with it
    assert not d.unexplained
    assert not {"constant_vertical_force", "gap_sensor_offset"} & {n.name for n in d.not_separable}


def test_a_drift_is_no_part_of_the_stage_file_or_the_plant_fed_forward(warm_and_lag):
    # the constants beside the drift are the log's mean; the stage file says so and carries the
    # other effects, and the twin of the plant the compensation study runs has no drift in it
    from maglev_oc.diagnosis.feedback import _effects_acceleration
    from maglev_oc.diagnosis.stage_file import diagnosis_stage_file
    from maglev_oc.model.stage import StageModel
    from maglev_oc.model.stagefile import Provenance

    d, _ = warm_and_lag
    stage = diagnosis_stage_file(d, StageModel(), Provenance.now(("test",), "test"))
    assert [e.name for e in stage.effects] == ["current_amplifier_lag"]
    assert "magnet_field_drift" in stage.provenance["constants"].method
    [drift] = [e for e in d.effects if e.name == "magnet_field_drift"]
    twin = _effects_acceleration([drift], with_inputs=True)
    assert np.all(np.asarray(twin(np.array([0.0195, 0.0, 0.01, 0.0]), np.array([1.0, 1.5]))) == 0.0)


@pytest.mark.extended
def test_a_small_warming_alone_is_found_and_sized(tmp_path):
    # warm_small_7401: 0.28 % of the field over 60 s (6 K at 120 s), found -0.28 %
    _, s = _diagnosed(tmp_path, "warm_small", 7401, MagnetWarming.small())
    assert s.claimed == ["magnet_field_drift"]
    assert s.size_right, s.notes


@pytest.mark.parametrize("axis", ["horizontal", pytest.param("vertical", marks=pytest.mark.extended)])
def test_friction_that_changes_as_the_guides_warm_is_no_magnet_drift_and_is_reported(tmp_path, axis):
    # bench/diagnose_rigs.py --warming, friction_*_thinning_7401: large friction falling by 30 % with
    # a time constant of 60 s, so its Coulomb level by 0.3 x 0.63 = 19 % over the log (-0.19 N
    # horizontally, -0.38 N vertically); the drift of the magnets follows the thrust and the
    # attraction, not the direction of motion, and is not claimed. Found: -0.2 / -0.34 N
    friction = dataclasses.replace(GuideFriction.large(axis), warming_change=-0.3, warming_time_constant=60.0)
    d, s = _diagnosed(tmp_path, f"thinning_{axis}", 7401, friction)
    assert s.claimed == [f"guide_friction_{axis}"]
    assert s.size_right, s.notes  # the friction at the log's mean level: within 30 % of its start
    [found] = [u for u in d.unexplained if u.depends_on == "time"]
    assert found.axis == axis
    change = float(re.search(r"changes by ([-+0-9.e]+) N from the log's first sample", found.description)[1])
    truth = -0.3 * (1 - np.exp(-1.0)) * friction.coulomb_force
    assert change == pytest.approx(truth, rel=0.3)  # the 30 %


def test_a_gap_reading_that_drifts_is_read_as_the_same_forces_and_said_so(tmp_path):
    # the gap zero drifting by 50 um (time constant 60 s: 32 um over the log) changes the attraction
    # by the model's slope with the gap times that, and the thrust by half as much: the forces of the
    # magnets' drift. The effect is claimed with both readings; the gap reading's within 30 % (found
    # 29 um)
    d, s = _diagnosed(tmp_path, "gap_zero_drift", 7401, GapSensorZero(offset=0.0, drift=5e-5))
    assert s.claimed == ["magnet_field_drift"]
    assert s.size_right, s.notes
    [drift] = d.effects
    assert "gap reading drifting by" in drift.finding and "tells them apart" in drift.finding


# --- several logs of one rig ---------------------------------------------------------------------
def test_logs_of_a_warming_rig_each_get_their_drift_and_level(tmp_path):
    # two logs of one rig (the same constants), the first while the magnets warm by 9 K (the field
    # 1.14 % lower after 60 s, 0.66 % lower on average), the second with the magnets at the rig's
    # start temperature. With one drift for both logs (before), nothing was claimed: the two logs'
    # levels differ by 0.66 %, and constant forces, the attraction's gap dependence and a gap
    # offset took it, not separable. Each log now has its drift and its level (the levels about the
    # logs' mean): found -1.10 % and -0.004 %, the levels -0.33 and +0.33 % (truth -0.33 and +0.33)
    warming = MagnetWarming.large()
    warm = simulate(Scenario(name="warm", seed=7411, effects=(warming,)))
    constants = tuple(warm.truth["plant"]["constants_true"][c] for c in ("C1", "C2", "C3", "C4"))
    clean = simulate(Scenario(name="clean", seed=7412, constants=constants))
    paths = [write_log(run, tmp_path, run.scenario.name)[0] for run in (warm, clean)]
    d = diagnose([read_log(p) for p in paths], limits=False)
    assert [e.name for e in d.effects] == ["magnet_field_drift"]
    found = d.effects[0].parameters
    change = warming.field_factor(60.0) - 1.0
    level = 0.5 * (np.mean([warming.field_factor(t) for t in warm.t - warm.t[0]]) - 1.0)
    assert found["field_change_in_log1"].value == pytest.approx(change, rel=0.3)  # the 30 %
    assert abs(found["field_change_in_log2"].value) < 0.3 * abs(change)
    assert found["field_level_in_log1"].value == pytest.approx(level, rel=0.3)
    assert found["field_level_in_log2"].value == pytest.approx(-level, rel=0.3)
    assert "warm.csv" in d.effects[0].finding and "clean.csv" in d.effects[0].finding


@pytest.mark.slow
def test_clean_logs_of_one_rig_together_claim_no_drift(tmp_path):
    # the per-log drifts and levels are 3 L - 1 parameters more; on two clean logs of one rig none
    # of them is claimed (nor anything else: the clean logs)
    runs = [
        simulate(Scenario(name=f"clean_{seed}", seed=seed, constants=PAPERS_CONSTANTS))
        for seed in (7413, 7414)
    ]
    paths = [write_log(run, tmp_path, run.scenario.name)[0] for run in runs]
    d = diagnose([read_log(p) for p in paths], limits=False)
    assert not d.effects


@pytest.mark.slow
def test_friction_that_changes_in_one_log_of_two_is_reported_per_log(tmp_path):
    # two logs of one rig with 1 N of horizontal friction, the first while it falls by 30 % (time
    # constant 60 s: -0.19 N over the log, 0.11 N lower on average), the second steady. With one
    # change for both logs the residual went unsaid; each log now has its change and its level
    # (about the logs' mean): found -0.2 and -0.002 N, the levels -0.06 and +0.06 N (truth -0.055
    # and +0.055). Each within 30 % (the issue's), the steady change within 0.05 N
    start = GuideFriction.large("horizontal")
    thinning = dataclasses.replace(start, warming_change=-0.3, warming_time_constant=60.0)
    first = simulate(Scenario(name="thinning", seed=7901, effects=(thinning,)))
    constants = tuple(first.truth["plant"]["constants_true"][c] for c in ("C1", "C2", "C3", "C4"))
    second = simulate(Scenario(name="steady", seed=7902, effects=(start,), constants=constants))
    paths = [write_log(run, tmp_path, run.scenario.name)[0] for run in (first, second)]
    d = diagnose([read_log(p) for p in paths], limits=False)
    assert [e.name for e in d.effects] == ["guide_friction_horizontal"]
    [found] = [u for u in d.unexplained if u.depends_on == "time"]
    names = [re.escape(p.name) for p in paths]
    change = [float(re.search(rf"changes by .*?([-+0-9.e]+) N in {n}", found.description)[1]) for n in names]
    level = [
        float(re.search(rf"level over a log is .*?([-+0-9.e]+) N in {n}", found.description)[1])
        for n in names
    ]
    truth = -0.3 * (1 - np.exp(-1.0)) * start.coulomb_force
    mean = -0.3 * np.exp(-1.0) * start.coulomb_force  # the thinning log's mean against its start
    assert change[0] == pytest.approx(truth, rel=0.3) and abs(change[1]) < 0.05
    assert level[0] == pytest.approx(0.5 * mean, rel=0.3) and level[1] == pytest.approx(-0.5 * mean, rel=0.3)
