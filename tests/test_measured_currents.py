"""Logs whose currents are the amplifiers' measured ones (``# currents: measured``), from the
independent generator (``Rig(logged_currents="measured")``, no code shared with ``maglev_oc.sim``).

A rig that logs its current sensors instead of its commands logs the current the motor gets: an
amplifier's lag is already in it, and no diagnosis of such a log can show the lag (on the named sets
recorded so, ``bench/diagnose_score.py --rig measured``: nothing claimed on the three lag logs, no
false claim on 41 logs).
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from scipy import signal

from maglev_oc.data.reading import read_log
from maglev_oc.diagnosis.pipeline import diagnose
from tests.independent.effects import AmplifierDynamics
from tests.independent.logio import write_log
from tests.independent.scoring import score
from tests.independent.sets import named_set
from tests.independent.simulate import Rig, Scenario, simulate

MEASURED = Rig(logged_currents="measured", current_sensor_noise=0.01)
SEED = 4321
DURATION = 8.0


def _run(rig: Rig, *effects):
    return simulate(Scenario(name="measured", seed=SEED, duration=DURATION, effects=effects, rig=rig))


def test_without_noise_or_lag_the_measured_currents_are_the_commands():
    # an ideal amplifier delivers each command over its control period: at the logging instants its
    # output is the command to the last bit
    commanded, measured = _run(Rig()), _run(Rig(logged_currents="measured"))
    np.testing.assert_array_equal(measured.u1, commanded.u1)
    np.testing.assert_array_equal(measured.u2, commanded.u2)


def test_the_sensors_noise_is_white_and_of_its_size():
    commanded, measured = _run(Rig()), _run(MEASURED)
    np.testing.assert_array_equal(measured.states["x1"], commanded.states["x1"])  # the same run
    error = np.vstack([measured.u1 - commanded.u1, measured.u2 - commanded.u2])
    n = error.shape[1]
    # the standard deviation within 5 standard errors of a sample of n (sd / sqrt(2 n))
    np.testing.assert_allclose(error.std(axis=1), 0.01, rtol=5 / np.sqrt(2 * n))
    lag1 = np.mean(error[:, 1:] * error[:, :-1], axis=1) / error.var(axis=1)
    assert np.all(np.abs(lag1) < 5 / np.sqrt(n))  # white: no correlation from one sample to the next


def test_the_measured_currents_carry_the_amplifiers_lag():
    # a 150 Hz first-order amplifier (1.06 ms) after 0.2 ms of delay: the logged current follows the
    # command late by about their sum, the delay at which the two correlate best (to a sample, 1 ms)
    lag = AmplifierDynamics.large()
    commanded, measured = _run(Rig(), lag), _run(Rig(logged_currents="measured"), lag)
    c = np.diff(commanded.u2)
    m = np.diff(measured.u2)
    xc = signal.correlate(m - m.mean(), c - c.mean(), mode="full")
    shift = int(np.argmax(xc)) - (len(c) - 1)  # [samples of 1 ms]
    assert shift in (1, 2)


def test_a_lag_in_the_measured_currents_is_not_claimed(tmp_path):
    # eleven_07 (the amplifiers' lag, 1.26 ms in all) with the currents measured: the motor gets
    # what is logged, nothing is missing; with the commands logged the lag is claimed and sized
    # (bench/README, the named sets)
    stem, scenario = next(x for x in named_set("eleven") if x[0] == "eleven_07")
    run = simulate(dataclasses.replace(scenario, rig=MEASURED))
    csv, truth = write_log(run, tmp_path, stem)
    log = read_log(csv)
    assert log.currents_measured
    out = diagnose([log], limits=False).to_dict()
    s = score(stem, json.loads(truth.read_text()), out["effects"])
    assert s.claimed == []
    assert not out["unexplained"]


@pytest.mark.parametrize("bad", [{"logged_currents": "sensed"}, {"current_sensor_noise": 0.01}])
def test_the_rigs_current_settings_are_checked(bad):
    with pytest.raises(ValueError, match="Rig"):
        Rig(**bad)
