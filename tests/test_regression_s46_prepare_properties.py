"""What ``maglev_oc.regression.data.prepare`` records about its logs, against the definitions in its
docstrings:

* an axis moves when the standard deviation of its *position* exceeds ``MOTION`` (50 um, five encoder
  counts): a slow drift of a millimetre moves, a fast vibration of 20 um (whose velocity is large)
  does not;
* ``settings["control_rate_hz"]`` is the slowest of the logs' loop rates, and
  ``control_rate_assumed`` says whether that slowest rate is the rig's 5 kHz assumed for a log that
  does not declare it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_oc.data.logs import Log
from maglev_oc.regression.data import MOTION, prepare

RATE = 1000.0


def _log(gap_motion, position_motion, *, metadata=None, source="s46") -> Log:
    t = np.arange(3000) / RATE
    x = np.vstack([0.02 + gap_motion(t), np.zeros_like(t), position_motion(t), np.zeros_like(t)])
    u = np.vstack([np.sin(2 * math.pi * 1.3 * t), 1.5 + 0.2 * np.cos(2 * math.pi * 0.9 * t)])
    return Log(t, x, u, metadata=metadata or {}, source=source)


def _still(t):
    return np.zeros_like(t)


def _drift(t):
    return 1e-3 * t / t[-1]  # 1 mm over 3 s: position std 0.29 mm, velocity 0.33 mm/s, constant


def _vibration(t):
    return 20e-6 * np.sin(2 * math.pi * 20.0 * t)  # std 14 um, velocity std 1.8 mm/s


@pytest.mark.parametrize(
    "gap, position, expected",
    [
        (_drift, _still, (True, False)),
        (_still, _drift, (False, True)),
        (_vibration, _drift, (False, True)),
        (_drift, _vibration, (True, False)),
    ],
)
def test_an_axis_moves_when_its_position_spreads_by_more_than_five_counts(gap, position, expected):
    # the thresholds' margins: drift std 289 um and vibration std 14 um against MOTION = 50 um, so the
    # differentiator's smoothing (a few per cent at 20 Hz in a 10 Hz band) cannot move either across
    assert MOTION == pytest.approx(50e-6)
    data = prepare(_log(gap, position), bandwidth=10.0)
    assert tuple(bool(m) for m in data.moving) == expected


@pytest.mark.parametrize(
    "declared, rate, assumed",
    [
        (("5000", "2000"), 2000.0, False),  # both declared: the slower
        (("2000", "5000"), 2000.0, False),  # in either order
        ((None, "10000"), 5000.0, True),  # the slower is the rig's 5 kHz, assumed for the first log
        (("10000", None), 5000.0, True),
        ((None, "2000"), 2000.0, False),  # the assumed 5 kHz is not the slowest
    ],
)
def test_the_settings_record_the_slowest_loop_rate_and_whether_it_was_assumed(declared, rate, assumed):
    logs = [
        _log(_drift, _drift, metadata={} if d is None else {"control_rate_hz": d}, source=f"log{k}")
        for k, d in enumerate(declared)
    ]
    settings = prepare(logs, bandwidth=10.0).settings
    assert settings["control_rate_hz"] == rate
    assert settings["control_rate_assumed"] is assumed
    # an explicit control_rate overrides every log's and is never assumed
    explicit = prepare(logs, bandwidth=10.0, control_rate=3000.0).settings
    assert explicit["control_rate_hz"] == 3000.0 and explicit["control_rate_assumed"] is False
