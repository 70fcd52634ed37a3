"""A log whose platform rests on its stopper before lift-off or after landing, or is pressed against
it in between.

The stopper, not the magnets, holds the platform there, while the loop goes on commanding currents:
those samples are wrong by the stopper's force in any fit. Before they were left out, a 60 s log of
the independent generator that lifted off after 1.2 s gave C2 +2 %, C3 +7.6 % and C4 +125 % off the
plant's in the diagnosis's base fit (and +2.3 / +8.5 / +136 % in identify's output error), without a
word (bench/README, "A log that begins on the stopper"); a reference 2 mm beyond a stopper at 26 mm
for 1.5 s in the middle of a log gave C4 six times the plant's and lost a normal cogging. Logs from
``tests/independent``
(``Rig.stopper_gap``; no code shared with ``maglev_oc.sim``).
"""

from __future__ import annotations

import numpy as np
import pytest

from maglev_oc.data.reading import read_log
from maglev_oc.diagnosis.pipeline import diagnose
from maglev_oc.identification.pipeline import identify
from maglev_oc.model.stage import StageModel
from maglev_oc.regression.data import levitating_parts, prepare
from maglev_oc.regression.stoppers import RESTING_WHY, TOUCHING_WHY
from tests.independent.logio import write_log
from tests.independent.reference import ReferenceSpec
from tests.independent.sets import named_set
from tests.independent.simulate import Rig, Scenario, simulate

STOPPER = 0.030
"""[m] The generator's stopper: the platform falls onto it at a 30 mm gap (gravity opens the gap)."""

LIFT = ReferenceSpec(gap_center=STOPPER, steps_v=((1.0, -0.0105),), step_time=1.0, ramp_time=4.0)
"""Resting at 30 mm, lifted to 19.5 mm from 1 s on, then the usual sines (fading in over 4 s)."""

LIFT_AND_LAND = ReferenceSpec(
    gap_center=STOPPER, steps_v=((1.0, -0.0105), (56.0, 0.0115)), step_time=1.0, ramp_time=4.0
)
"""... and set down again from 56 s on (a reference beyond the stopper: the loop presses it down)."""

TOUCHED = 0.026
"""[m] A stopper the reference runs beyond in the middle of a log ..."""

TOUCH = ReferenceSpec(steps_v=((25.0, 0.008), (26.5, -0.008)), step_time=0.3)
"""... the usual sines around 19.5 mm, stepped 8 mm up from 25 s to 26.5 s: 2 mm beyond it."""

TOP = ReferenceSpec(steps_v=((25.0, -0.006), (26.5, 0.006)), step_time=0.3)
"""The usual sines stepped 6 mm down from 25 s to 26.5 s: beyond a stop at a 15 mm gap ..."""

END = ReferenceSpec(steps_h=((25.0, 0.025), (26.5, -0.025)), step_time=0.3)
"""... or 25 mm along the travel: beyond an end stop at +45 mm."""

OTHER_STOPS = {
    # name: (seed, reference, rig, the limit's name, (state, the limit))
    "smallest_gap": (7711, TOP, Rig(top_stopper_gap=0.015), ("x1", 0.015)),
    "high_end": (7721, END, Rig(end_stops=(-0.045, 0.045)), ("x3", 0.045)),
}

CONSTANTS = ("C1", "C2", "C3", "C4")


def _truth_constants(run) -> np.ndarray:
    return np.array([run.truth["plant"]["constants_true"][c] for c in CONSTANTS])


def _at_stopper(run, stopper: float = STOPPER) -> np.ndarray:
    """(n,) the logged samples whose true gap is the stopper's."""
    return run.states["x1"] >= stopper - 1e-12


def _lift_off(run) -> float:
    """[s] The time in the log of the last sample on the stopper before 30 s."""
    early = _at_stopper(run) & (run.t - run.t[0] < 30.0)
    return float(run.t[np.flatnonzero(early)[-1]] - run.t[0])


@pytest.fixture(scope="module")
def lifted(tmp_path_factory):
    run = simulate(Scenario(name="lift", seed=7601, reference=LIFT, rig=Rig(stopper_gap=STOPPER)))
    return run, write_log(run, tmp_path_factory.mktemp("lift"))[0]


@pytest.fixture(scope="module")
def touched(tmp_path_factory):
    run = simulate(Scenario(name="touch", seed=7701, reference=TOUCH, rig=Rig(stopper_gap=TOUCHED)))
    return run, write_log(run, tmp_path_factory.mktemp("touch"))[0]


def _contacts(run, on: np.ndarray) -> list[tuple[float, float]]:
    """[s] (first, last) time in the log of each run of the samples ``on`` a stop."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], on.astype(np.int8), [0]])))
    t = run.t - run.t[0]
    return [(float(t[a]), float(t[b - 1])) for a, b in zip(edges[::2], edges[1::2], strict=True)]


# --- the generator -----------------------------------------------------------------------------
def test_the_generators_stopper_holds_the_platform_until_the_magnets_lift_it(lifted):
    # the true gap never opens beyond the stopper; the platform sits on it for the first second
    # or so (the loop's first commands raise it by a few micrometres, then it winds up against the
    # stopper), then leaves it for good
    run, _ = lifted
    assert run.states["x1"].max() <= STOPPER + 1e-12
    resting = _at_stopper(run)
    lift_off = _lift_off(run)
    assert 0.8 < lift_off < 1.6 and resting.sum() * run.truth["rig"]["log_rate_hz"] ** -1 > 0.8
    after = run.t - run.t[0] > lift_off
    assert not resting[after].any()
    held = resting & (run.t - run.t[0] > 0.5)
    assert np.all(run.states["x2"][held] == 0.0)  # at rest on it


# --- finding the stretches ---------------------------------------------------------------------------
def test_the_stretch_before_lift_off_is_found_and_left_out(lifted):
    # found where the true gap sits on the stopper, to within the filters' smoothing (0.15 s: the
    # lift-off's first motion is within a count of the stopper for a few samples), and left out of
    # the valid samples with one filter memory beyond it
    run, path = lifted
    data = prepare([read_log(path)], bandwidth=10.0, model=StageModel())
    [stretch] = data.resting
    lift_off = _lift_off(run)
    assert stretch.start == pytest.approx(0.0, abs=0.15)
    assert stretch.stop == pytest.approx(lift_off, abs=0.15)
    assert stretch.position == pytest.approx(STOPPER, abs=2e-5)  # the encoder's 10 um, and its noise
    left = ~data.valid & (data.t > 0.5) & (data.t < 30.0)  # not the log's own end
    assert data.t[left].max() == pytest.approx(stretch.stop + data.edge * data.sample_time, abs=2e-3)
    assert any("rests on its stopper" in n for n in data.notes)


def test_landing_at_the_end_and_its_bounce_are_one_stretch(tmp_path):
    # set down from 56 s on: the platform lands, bounces within a quarter second and stays; the
    # stretch runs from the landing to the log's last sample, and the lift-off's is found too
    run = simulate(Scenario(name="land", seed=7602, reference=LIFT_AND_LAND, rig=Rig(stopper_gap=STOPPER)))
    data = prepare([read_log(write_log(run, tmp_path)[0])], bandwidth=10.0, model=StageModel())
    assert len(data.resting) == 2
    landing = data.resting[1]
    first_down = run.t[np.flatnonzero(_at_stopper(run) & (run.t - run.t[0] > 30.0))[0]] - run.t[0]
    assert landing.start == pytest.approx(first_down, abs=0.15)
    assert landing.stop == pytest.approx(run.t[-1] - run.t[0], abs=1e-9)


def test_a_touch_in_the_middle_of_a_log_and_its_bounce_are_found_and_left_out(touched):
    # the loop presses the platform against the stopper for 2 s (25.16-27.14 s), then it bounces
    # once (27.52-27.58 s, the misfit there only 1.1 m/s^2 above the levitating platform's: found
    # as the stopper's gap, which the first stretch showed). Each stretch within the filters'
    # smoothing of the true contact (0.15 s), said as a touch, and left out with one filter memory
    run, path = touched
    data = prepare([read_log(path)], bandwidth=10.0, model=StageModel())
    contacts = _contacts(run, _at_stopper(run, TOUCHED))
    assert [round(a) for a, _ in contacts[:2]] == [25, 28] and len(data.resting) == 2
    for stretch, (first, last) in zip(data.resting, contacts, strict=False):
        assert stretch.during and stretch.to_dict()["why"] == TOUCHING_WHY
        assert stretch.start == pytest.approx(first, abs=0.15) and stretch.stop == pytest.approx(
            last, abs=0.15
        )
        assert stretch.position == pytest.approx(TOUCHED, abs=2e-5)
    assert data.resting[0].misfit > 20.0  # the loop wound up to the amplifiers' 9 A against it
    left = ~data.valid & (data.t > 1.0) & (data.t < 59.0)
    assert data.t[left].min() == pytest.approx(data.resting[0].start - data.edge * data.sample_time, abs=2e-3)
    assert data.t[left].max() == pytest.approx(data.resting[1].stop + data.edge * data.sample_time, abs=2e-3)
    assert any("pressed against its stopper" in n for n in data.notes)


@pytest.fixture(scope="module")
def other_stops(tmp_path_factory):
    out = {}
    for name, (seed, reference, rig, _) in OTHER_STOPS.items():
        run = simulate(Scenario(name=name, seed=seed, reference=reference, rig=rig))
        out[name] = run, write_log(run, tmp_path_factory.mktemp(name))[0]
    return out


@pytest.mark.parametrize("limit", list(OTHER_STOPS))
def test_the_stop_at_the_smallest_gap_and_the_end_stops_are_found(other_stops, limit):
    # the loop presses the stage against the stop at a 15 mm gap (0.84 s) or the travel's end stop
    # at +45 mm (0.89 s, then again for 0.30 s): each stretch within the filters' smoothing of the
    # true contact (0.15 s), named by its limit, and nothing else found. With them in the fit the
    # constants came out C2 -37 %, C3 -143 %, C4 -2500 % (the smallest gap) and C1 -99.9 % (the end)
    run, path = other_stops[limit]
    state, at = OTHER_STOPS[limit][3]
    data = prepare([read_log(path)], bandwidth=10.0, model=StageModel())
    contacts = _contacts(run, np.abs(run.states[state] - at) < 1e-12)
    assert len(data.resting) == len(contacts) >= 1
    for stretch, (first, last) in zip(data.resting, contacts, strict=True):
        assert stretch.limit == limit and stretch.position == pytest.approx(at, abs=2e-5)
        assert stretch.start == pytest.approx(first, abs=0.15) and stretch.stop == pytest.approx(
            last, abs=0.15
        )
        assert stretch.to_dict()["why"] == TOUCHING_WHY


@pytest.mark.parametrize(
    "limit", [pytest.param("high_end"), pytest.param("smallest_gap", marks=pytest.mark.slow)]
)
def test_a_log_pressed_against_another_stop_is_diagnosed_on_its_motion(other_stops, limit):
    # nothing claimed and the constants of a clean log (the bounds); found within 0.2 %
    # and 2 %
    run, path = other_stops[limit]
    d = diagnose([read_log(path)], limits=False)
    assert not d.effects and not d.unexplained
    error = np.array([d.constants_final[c].value for c in CONSTANTS]) / _truth_constants(run) - 1.0
    assert np.all(np.abs(error[:3]) < 0.01) and abs(error[3]) < 0.10, error
    assert {r.limit for r in d.left_out} == {limit}


def test_guides_that_stick_at_a_log_s_extreme_gap_are_no_stopper(generated):
    # single_04 (2 N of vertical friction): the platform sticks still at the log's largest gap for
    # 0.31 s at 11.4 s while the model is off by up to 1.1 m/s^2, which a stopper anywhere in the log
    # would be taken for; the friction's evidence stays in the fit. experiments_30 (the same friction,
    # an off-centre travel at a 17 mm gap): it sticks at the log's smallest gap, 12.88 mm, for 0.31 s
    # at 52.8 s, the model off by 2.9 m/s^2 there (its constants' error at that gap), which a stop at
    # the smallest gap judged by the misfit itself would be taken for; beside it the sliding platform
    # is off by nearly as much. Nothing found on the clean log either
    [stem] = [s for s, sc in named_set("single") if sc.name == "guide_friction_vertical_large"]
    for set_name, name in (("single", stem), ("experiments", "experiments_30"), ("clean", "clean_01")):
        path, _ = generated(set_name, name)
        assert prepare([read_log(path)], bandwidth=10.0, model=StageModel()).resting == (), name


def test_a_narrow_band_leaves_out_the_stretches_found_on_the_fits_band(lifted):
    # at 2 Hz (the band the logged currents' error is calibrated on) the smoothed gap and misfit show
    # the stretch otherwise (ending 0.03 s earlier; with the log's largest reading as the stopper's
    # gap, not at all): it is left out by the fit band's times, with the narrow band's longer memory
    _, path = lifted
    log = read_log(path)
    fits = prepare([log], bandwidth=10.0, model=StageModel())
    assert prepare([log], bandwidth=2.0, model=StageModel()).resting != fits.resting
    narrow = prepare([log], bandwidth=2.0, resting=fits.resting)
    assert narrow.resting == fits.resting
    [stretch] = fits.resting
    out = ~narrow.valid & (narrow.t < 30.0)
    assert narrow.t[out].max() == pytest.approx(stretch.stop + narrow.edge * narrow.sample_time, abs=2e-3)


# --- the fits -------------------------------------------------------------------------------------
def test_a_log_that_lifts_off_is_diagnosed_on_its_levitation(lifted):
    # nothing claimed and the constants of a clean log (the bounds: C1..C3 within 1 %, C4
    # within 10 %; found within 0.1 % and 1.5 %); the stretch said in the result
    run, path = lifted
    d = diagnose([read_log(path)], limits=False)
    assert not d.effects and not d.unexplained
    found = np.array([d.constants_final[c].value for c in CONSTANTS])
    error = found / _truth_constants(run) - 1.0
    assert np.all(np.abs(error[:3]) < 0.01) and abs(error[3]) < 0.10, error
    [left] = d.to_dict()["left_out"]
    assert left["why"] == RESTING_WHY and left["from_s"] < 0.15 < 0.9 < left["to_s"]


def test_a_log_with_a_touch_is_diagnosed_on_its_levitation(touched):
    # nothing claimed, the constants of a clean log (the bounds); with the touch in the fit
    # C4 came out at 0.45 (538 % above the papers' 0.07), with the touch out but its bounce in, 18 %
    # high. Found within 0.3 % and 1 %
    run, path = touched
    d = diagnose([read_log(path)], limits=False)
    assert not d.effects and not d.unexplained
    error = np.array([d.constants_final[c].value for c in CONSTANTS]) / _truth_constants(run) - 1.0
    assert np.all(np.abs(error[:3]) < 0.01) and abs(error[3]) < 0.10, error
    assert [r["why"] for r in d.to_dict()["left_out"]] == [TOUCHING_WHY] * 2


@pytest.mark.slow
def test_beside_a_touch_the_cogging_is_found_and_sized(tmp_path):
    # 2 N normal cogging: with the touch in the fit it was not claimed (a residual "that varies with
    # the gap" reported instead, C3 +33 %, C4 +589 %); now claimed first, alone, sized within the
    # issue's 30 %
    from tests.independent.effects import NormalCogging
    from tests.independent.scoring import score

    scenario = Scenario(
        name="touch_cogging",
        seed=7703,
        effects=(NormalCogging.large(),),
        reference=TOUCH,
        rig=Rig(stopper_gap=TOUCHED),
    )
    run = simulate(scenario)
    d = diagnose([read_log(write_log(run, tmp_path)[0])], limits=False)
    s = score("touch_cogging", run.truth, d.to_dict()["effects"])
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes)
    assert all(r.during for r in d.left_out)


@pytest.mark.slow
def test_identify_fits_the_levitation_either_side_of_a_touch(touched):
    # the output error simulates the log's samples: the log is cut in two at the touch (and its
    # bounce), each piece fitted; both fits within the bounds
    run, path = touched
    pieces, resting = levitating_parts([read_log(path)], StageModel())
    assert len(pieces) == 2 and len(resting) == 2
    assert pieces[0].t[-1] - run.t[0] == pytest.approx(resting[0].start - 0.1, abs=2e-3)
    assert pieces[1].t[0] - run.t[0] == pytest.approx(resting[1].stop + 0.1, abs=2e-3)
    out = identify([read_log(path)], StageModel(), methods=("equation_error", "output_error"))
    truth = _truth_constants(run)
    for fit in (out.equation_error, out.output_error):
        error = np.array([fit.values[c] for c in CONSTANTS]) / truth - 1.0
        assert np.all(np.abs(error[:3]) < 0.01) and abs(error[3]) < 0.10, (fit.method, error)
        assert fit.sources == (str(path),)  # one log, not its two pieces
    assert out.sources == (str(path),)
    # the report plots the first residuals on the first piece (on the longest it failed: 25 070
    # residuals against 32 298 samples)
    from maglev_oc.reporting.identification_plots import write_outcome_report

    write_outcome_report(path.with_suffix(".pdf"), out, [read_log(path)])
    assert path.with_suffix(".pdf").stat().st_size > 10_000


@pytest.mark.slow
def test_identify_leaves_the_resting_stretch_out_of_every_fit_and_its_report(lifted):
    # the equation error, the output error (simulated from the log's samples) and NPFSI all read
    # the log from its lift-off on: each within the bounds of the true constants
    run, path = lifted
    out = identify([read_log(path)], StageModel(), methods=("equation_error", "output_error", "npfsi"))
    truth = _truth_constants(run)
    for fit in (out.equation_error, out.output_error):
        error = np.array([fit.values[c] for c in CONSTANTS]) / truth - 1.0
        assert np.all(np.abs(error[:3]) < 0.01) and abs(error[3]) < 0.10, (fit.method, error)
    assert [r.source for r in out.left_out] == [str(path)]
    trimmed, _ = levitating_parts([read_log(path)], StageModel())
    assert trimmed[0].t[0] - run.t[0] == pytest.approx(out.left_out[0].stop + 0.1, abs=2e-3)
    # the report plots each fit's residuals on the samples it read (on the whole log it failed:
    # 58 557 residuals against 60 000 samples)
    from maglev_oc.reporting.identification_plots import write_outcome_report

    write_outcome_report(path.with_suffix(".pdf"), out, [read_log(path)])
    assert path.with_suffix(".pdf").stat().st_size > 10_000


@pytest.mark.slow
def test_on_the_noisy_rig_the_currents_error_is_calibrated_without_the_stopper(tmp_path):
    # lift-off and landing on the rig as noisy as ../shared/logs/independent_clean.csv: the logged
    # currents' error is calibrated where the constants fitted on 2 Hz and on the band agree
    # (regression.noise_scale). With the stretches left out of the band's fit only, the 2 Hz fit
    # still read them, the bands agreed at no level (disagreement 162) and C1 came out 4.3 % high,
    # five of its standard errors; left out of both, C2, C3 within 1 % and C4 within 10 % (the
    # issue's bounds), and C1 within three standard errors (0.8 % each: its noisy currents' scatter
    # from seed to seed; found +1.0 %)
    from tests.independent.rigs import RIGS

    rig = Rig(**RIGS["obs2800"], stopper_gap=STOPPER)
    run = simulate(Scenario(name="land", seed=7602, reference=LIFT_AND_LAND, rig=rig))
    d = diagnose([read_log(write_log(run, tmp_path)[0])], limits=False)
    assert not d.effects
    found = np.array([d.constants_final[c].value for c in CONSTANTS])
    truth = _truth_constants(run)
    error = found / truth - 1.0
    assert np.all(np.abs(error[1:3]) < 0.01) and abs(error[3]) < 0.10, error
    assert abs(found[0] - truth[0]) < 3 * d.constants_final["C1"].stderr, error
