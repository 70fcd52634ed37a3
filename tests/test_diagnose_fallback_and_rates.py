"""Two things a user's rig can differ in from ours: guide friction that is viscous only, and a
control loop at another rate than the rig's 5 kHz (``control_rate_hz`` in the log's metadata)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from maglev_oc.data.logs import Log
from maglev_oc.diagnosis.candidate import LibraryContext
from maglev_oc.diagnosis.currents import lag_candidate
from maglev_oc.diagnosis.pipeline import diagnose
from maglev_oc.regression.data import prepare
from tests.test_statistics_properties import _log


def test_viscous_only_friction_is_not_reported_as_coulomb_friction(model):
    """3.2 N s/m of viscous friction and no Coulomb part: the full friction candidate is refused
    for "no Coulomb" (sticking without friction is not physical), and its fallback, Coulomb
    friction with the viscous part held at zero, is no stand-in for that: it is judged only when
    the free fit's viscous part is negative. (It used to be claimed, with 0.08 N of Coulomb friction
    that is not there.) The velocity dependence goes to the unexplained residual instead."""
    m = model.params.mass_horizontal
    d = diagnose([_log(model, friction=3.2 / m)], model)
    assert d.effects == []
    judged = d.selection.last
    full = judged["guide_friction_horizontal"]
    assert full.verdict == "implausible" and "no Coulomb" in full.reason
    # the free fit's viscous part: positive, 3.2 N s/m within 3 standard errors
    viscous = full.physical["viscous"]
    assert abs(viscous.value - 3.2) < 3 * viscous.stderr + 0.02 * 3.2  # + the 2 % calibration
    assert "guide_friction_horizontal_without_viscous" not in judged
    assert [(u.axis, u.depends_on) for u in d.unexplained] == [("horizontal", "position_rate")]


def _moving_log(rate_hz: float, **metadata) -> Log:
    """10 s at 1 kHz of a stage moving sinusoidally at a 20 mm gap (the currents do not matter)."""
    t = np.arange(10_000) / 1000.0
    x3 = 0.02 * np.sin(2 * np.pi * 0.5 * t)
    x1 = 0.02 + 1e-3 * np.sin(2 * np.pi * 0.3 * t)
    x = np.vstack([x1, np.gradient(x1, t), x3, np.gradient(x3, t)])
    meta = {k: str(v) for k, v in metadata.items()}
    if rate_hz:
        meta["control_rate_hz"] = str(rate_hz)
    return Log(t, x, np.ones((2, t.size)), metadata=meta)


@pytest.mark.parametrize(("rate_hz", "hold"), [(0.0, 1e-4), (2000.0, 2.5e-4), (10_000.0, 5e-5)])
def test_the_lag_candidates_hold_delay_is_half_the_logs_control_period(model, rate_hz, hold):
    """The loop holds each command for one control period, so on average the force follows the
    command by half of it: 0.1 ms at the rig's 5 kHz (no metadata), 0.25 ms at 2 kHz, 0.05 ms at
    10 kHz. (The preparation never passed the log's rate on, so it was 0.1 ms for every log.)"""
    data = prepare([_moving_log(rate_hz)], bandwidth=10.0)
    assert data.settings["control_rate_hz"] == (rate_hz or 5000.0)
    assert LibraryContext(model, data).hold_delay == pytest.approx(hold, rel=1e-12)


def test_logs_of_two_control_rates_take_the_slower_one(model):
    data = prepare([_moving_log(2000.0), _moving_log(5000.0)], bandwidth=10.0)
    assert data.settings["control_rate_hz"] == 2000.0  # the larger hold, the lag's lower bound


@pytest.mark.parametrize("rate_hz", [0.0, 2000.0])
def test_a_lag_found_against_an_assumed_loop_rate_says_so(model, rate_hz):
    """A log that does not declare its loop's rate is read at the rig's 5 kHz. The lag's finding
    then says that it was assumed, and at which rate the loop's own hold (half its period) would be
    the whole delay: 0.5 / total delay (0.27 ms total -> 1.85 kHz, the 2 kHz loop of the
    independent generator's ctrl2k rig, whose clean log gave such a lag). A declared rate carries no
    such caveat; nor do measured currents (no loop holds them)."""
    data = prepare([_moving_log(rate_hz)], bandwidth=10.0)
    assert data.settings["control_rate_assumed"] == (rate_hz == 0.0)
    cand = lag_candidate(LibraryContext(model, data))
    hold = 0.5 / (rate_hz or 5000.0)
    text = cand.describe(cand.term.physical([hold + 1.7e-4], np.array([[4e-10]]), None))
    assert ("kHz is assumed" in text) == (rate_hz == 0.0)
    if rate_hz == 0.0:
        assert "a loop at 1.9 kHz would hold" in text  # 0.5 / 0.27 ms = 1.85 kHz, 2 digits
    measured = prepare([dataclasses.replace(_moving_log(0.0), currents_measured=True)], bandwidth=10.0)
    assert measured.settings["control_rate_assumed"] is False


@pytest.mark.parametrize(("declared_hz", "assumed"), [(2000.0, False), (10_000.0, True)])
def test_the_rate_is_assumed_only_when_the_slowest_comes_from_a_log_that_does_not_declare_it(
    model, declared_hz, assumed
):
    """A log declaring 2 kHz beside one that declares nothing (5 kHz assumed): the slower, declared
    2 kHz sets the hold, nothing is assumed. Beside a declared 10 kHz, the undeclared log's assumed
    5 kHz is the slowest: the lag's finding must say it was assumed."""
    data = prepare([_moving_log(declared_hz), _moving_log(0.0)], bandwidth=10.0)
    assert data.settings["control_rate_hz"] == min(declared_hz, 5000.0)
    assert data.settings["control_rate_assumed"] is assumed
