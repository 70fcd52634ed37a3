"""A log whose current columns are late against its positions: said so, not read as a damping.

A filter on measured currents, or a logger that stamps the currents after the positions they acted
on, makes the forces lead the logged currents. The amplifier lag refuses a negative delay (no
amplifier makes a force before its current), and the residual used to go to the probe of the gap
rate, read as "a force against the motion, as damping or friction the model lacks gives"."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from maglev_oc import diagnose, read_log
from maglev_oc.diagnosis.currents import LAG
from maglev_oc.diagnosis.unexplained import TIMING
from maglev_oc.model.hardware import RIG_SAMPLE_TIME
from tests.diagnosis_support import diagnose_path
from tests.independent.logio import write_log
from tests.independent.sets import named_set
from tests.independent.simulate import Rig, simulate


def _late(path, samples: int):
    """The log at ``path`` with its current columns ``samples`` samples late (the first repeated)."""
    log = read_log(path)
    u = np.concatenate([np.repeat(log.u[:, :1], samples, axis=1), log.u[:, :-samples]], axis=1)
    return dataclasses.replace(log, u=u)


@pytest.mark.slow
@pytest.mark.parametrize("samples", [1, 2])
def test_currents_logged_late_are_said_to_be_late_not_a_missing_damping(generated, samples):
    path, _ = generated("clean", "clean_01")
    d = diagnose([_late(path, samples)], limits=False)
    assert d.effects == []
    # one entry, the currents' timing, and not also the gap rate's probe (the lag is in the model
    # the probes are judged beside)
    assert [u.depends_on for u in d.unexplained] == [TIMING]
    lag = d.selection.last[LAG]
    assert lag.verdict == "implausible"
    # the lead: the skew less the delay the clean log's lag fits (the loop's hold at 5 kHz, 0.1 ms,
    # and the log's own lag, +0.12 ms on ../shared/logs/independent_clean.csv, not significant),
    # within three of the fit's standard errors and the 0.05 ms of that lag
    delay = lag.physical["total_delay"]
    skew = samples * read_log(path).sample_time
    hold = 0.5 * RIG_SAMPLE_TIME  # the generator's 5 kHz loop
    tolerance = 3 * delay.stderr + 0.05e-3
    assert abs(-delay.value - (skew - hold)) < tolerance
    # the words give the skew in sample periods to one decimal: within the same tolerance, and the
    # rounding (0.85 +- 0.02 ms with the 0.1 ms hold is 0.95 periods, printed "0.9" or "1.0")
    said = re.search(r"\(([0-9.]+) sample periods", d.unexplained[0].description)
    assert said and abs(float(said.group(1)) - samples) <= tolerance / read_log(path).sample_time + 0.05


@pytest.mark.slow
def test_the_same_log_as_recorded_has_no_timing_entry(generated):
    path, _ = generated("clean", "clean_01")
    d = diagnose_path(path)
    assert d.effects == [] and d.unexplained == []
    assert d.selection.last[LAG].physical["total_delay"].value > 0


@pytest.mark.slow
def test_measured_currents_through_a_sensor_filter_are_said_to_be_late_by_its_delay(tmp_path):
    """The independent generator's clean_01 on a rig that logs its amplifiers' current sensors
    through a 300 Hz first-order filter (an amplifier's current monitor): the measured currents
    are 1 / (2 pi 300 Hz) = 0.53 ms late against the positions, and no hold lies between a
    measured current and its force."""
    bandwidth = 300.0
    rig = Rig(logged_currents="measured", current_sensor_noise=0.01, current_sensor_bandwidth=bandwidth)
    scenario = dataclasses.replace(dict(named_set("clean"))["clean_01"], rig=rig)
    csv, _ = write_log(simulate(scenario), tmp_path, stem="filtered")
    d = diagnose_path(csv)
    assert d.effects == []
    assert [u.depends_on for u in d.unexplained] == [TIMING]
    delay = d.selection.last[LAG].physical["total_delay"]
    filter_delay = 1.0 / (2.0 * np.pi * bandwidth)
    # within three of the fit's standard errors (0.05 ms): measured 0.47 ms
    assert abs(-delay.value - filter_delay) < 3 * delay.stderr
    assert "first-order filter on the current sensors" in d.unexplained[0].description


@pytest.mark.slow
def test_the_command_line_moves_late_currents_back_and_then_nothing_is_left(generated, tmp_path):
    """``maglev-oc diagnose --currents-late`` with the delay the timing entry gives: the same log,
    its currents put back, explains itself (nothing claimed, nothing unexplained); the input file
    is left as it was."""
    import json

    from maglev_oc.cli import main
    from maglev_oc.data.logs import write_log as write_project_log

    path, _ = generated("clean", "clean_01")
    late = tmp_path / "late.csv"
    write_project_log(late, _late(path, 1))
    before = late.read_bytes()
    out = tmp_path / "d.json"
    assert main(["diagnose", str(late), "--json", str(out), "--no-limits", "--currents-late", "0.001"]) == 0
    doc = json.loads(out.read_text())
    assert doc["effects"] == [] and doc["unexplained"] == []
    assert late.read_bytes() == before


def _lag_judgement(delay: float, sd: float, gains, verdict: str = "implausible"):
    """A judgement of the amplifier lag as the selection makes one: its fitted total delay [s] with
    standard error ``sd``, the loop's 0.1 ms hold, and its pooled held-out gain per axis."""
    from maglev_oc.diagnosis.selection import Judgement
    from maglev_oc.results import Estimate

    gains = np.asarray(gains, dtype=float)
    return Judgement(
        name=LAG,
        verdict=verdict,
        reason="",
        gain=float(np.nanmean(gains)),
        gain_axes=gains,
        z=5.0,
        z_holdout=5.0,
        wald=100.0,
        wald_threshold=4.0,
        vif=1.0,
        confounded_with=(),
        contribution_rms=np.array([0.01, 0.002]),
        contribution_peak=np.array([0.02, 0.004]),
        physical={"total_delay": Estimate(delay, sd, "s"), "hold_delay": Estimate(1e-4, 0.0, "s")},
        fit=None,
        pooled_gain_axes=gains,
    )


@pytest.mark.parametrize(
    ("delay", "gains", "moving", "verdict", "said"),
    [
        (-0.9e-3, [0.035, 0.004], (True, True), "implausible", True),  # the shared log, 1 sample late
        (-0.9e-3, [0.018, -0.001], (True, True), "implausible", True),  # the horizontal within 2 %
        (-0.9e-3, [0.035, np.nan], (True, True), "implausible", True),  # horizontal beside friction
        (-0.9e-3, [0.035, -0.03], (True, True), "implausible", False),  # the horizontal 3 % worse
        (-0.9e-3, [-0.01, 0.3], (True, True), "implausible", False),  # not the vertical: a damping
        (-15e-3, [np.nan, 0.3], (False, True), "implausible", False),  # the twin's viscous friction
        (-0.9e-3, [0.035, np.nan], (True, False), "implausible", False),  # one axis moves
        (-6e-3, [0.035, 0.004], (True, True), "implausible", False),  # beyond the lag's 5 ms bound
        (-0.2e-3, [0.035, 0.004], (True, True), "implausible", False),  # under 0.05 ms + 2 sd
        (-0.9e-3, [0.035, 0.004], (True, True), "not significant", False),  # the data do not show it
        (+0.9e-3, [0.035, 0.004], (True, True), "implausible", False),  # a lag, not a lead
    ],
)
def test_a_lead_is_the_logs_timing_only_on_both_axes_where_the_vertical_shows_it(
    model, delay, gains, moving, verdict, said
):
    """Each condition of :func:`currents_late` on its own (its docstring gives the logs behind
    them): 0.1 ms hold, 0.1 ms standard error, so a lead counts from 0.25 ms up to 5 ms."""
    from types import SimpleNamespace

    from maglev_oc.diagnosis.unexplained import currents_late

    data = SimpleNamespace(moving=np.array(moving), sample_time=1e-3, settings={})
    j = _lag_judgement(delay, 1e-4, gains, verdict)
    entry = currents_late(j, SimpleNamespace(term=None), model, data)
    assert (entry is not None) == said
    if said:
        assert entry.depends_on == TIMING and entry.axis == "vertical"
        # the skew: the lead and the hold, in samples of the log
        assert f"{(-delay + 1e-4) / 1e-3:.1f} sample periods" in entry.description


@pytest.mark.slow
def test_an_amplifier_lag_before_measured_currents_is_said_to_be_out_of_the_log(tmp_path):
    """single_20 of the independent generator (its amplifiers' lag, 1.26 ms in all, found on the
    commanded currents) on a rig that logs the amplifiers' measured output with 10 mA of noise: the
    forces follow the measured currents, so no size of the amplifiers' lag shows. Nothing is
    claimed, and where the lag's detection limit stood (a limit of forces lagging the measured
    currents, which a reader would take for the amplifiers') the log says why none is found."""
    from maglev_oc.diagnosis.currents import AMPLIFIER_LAG_NOT_LOGGED
    from maglev_oc.diagnosis.library import candidate_library
    from maglev_oc.model.stage import StageModel

    rig = Rig(logged_currents="measured", current_sensor_noise=0.01)
    scenario = dataclasses.replace(dict(named_set("single"))["single_20"], rig=rig)
    csv, _ = write_log(simulate(scenario), tmp_path, stem="measured")
    d = diagnose_path(csv, limits=True)
    assert d.effects == []
    (lag,) = [x for x in d.detection_limits if x.name == LAG]
    assert lag.value == np.inf and lag.reason == AMPLIFIER_LAG_NOT_LOGGED
    # the lag the library fits on this log is of the forces behind the measured currents
    (cand,) = [c for c in candidate_library(StageModel(), d.data) if c.name == LAG]
    assert cand.term.explanation.startswith("The forces lag the measured currents")
    # and the report says so where it is read first: the scorecard and the findings' words
    from maglev_oc.reporting.diagnosis_report import _finding_paragraphs, _finding_rows

    assert ("not in this log at any size", "current amplifier lag") in [r[:2] for r in _finding_rows(d)]
    assert f"Current amplifier lag: {AMPLIFIER_LAG_NOT_LOGGED}." in _finding_paragraphs(d)
