"""The rigs the independent generator records on, by name: fields of
:class:`tests.independent.simulate.Rig` that differ from its defaults. ``bench/diagnose_rigs.py
--rig NAME`` draws its logs on them, and the tests that reproduce a bench's log name the same rig."""

from __future__ import annotations

RIGS = {
    "default": {},
    "log500": {"log_every": 10},
    "log2500": {"log_every": 2},
    "enc1um": {"encoder_resolution": 1e-6, "encoder_noise": 0.5e-6},
    "enc20um": {"encoder_resolution": 20e-6, "encoder_noise": 4e-6},
    "ctrl2k": {"control_rate": 2000.0, "log_every": 2},
    "ctrl10k": {"control_rate": 10000.0, "log_every": 10},
    # observers 2.8x faster: the commanded currents' noise floor above 200 Hz (1.7e-6 and 5.9e-6 A^2/Hz)
    # and sample-to-sample jitter (41 and 77 mA) then match ../shared/logs/independent_clean.csv's
    # (1.7e-6 and 6.0e-6, 42 and 78 mA) within 3 %, against 20x lower at the default 1000 rad/s
    "obs2800": {"observer_bandwidth": 2800.0},
    # the amplifiers' current sensors logged instead of the commands, with 10 mA of white noise (a
    # Hall sensor of a 9 A amplifier through a 12-bit converter: 4.4 mA per count)
    "measured": {"logged_currents": "measured", "current_sensor_noise": 0.01},
    # the same through a first-order filter of 300 Hz on the current sensors (an amplifier's current
    # monitor): the measured currents 0.53 ms late against the positions
    "filtered": {
        "logged_currents": "measured",
        "current_sensor_noise": 0.01,
        "current_sensor_bandwidth": 300.0,
    },
    # the papers' identification runs: two independent PID loops instead of the FL regulator
    "pid": {"controller": "pid"},
}
"""Rig settings (fields of ``tests.independent.simulate.Rig``) by name."""
