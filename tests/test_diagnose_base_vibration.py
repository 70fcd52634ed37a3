"""A base that shakes: a disturbance no function of the state describes, so nothing is claimed for it.

The floor's vibration (``tests.independent.effects.BaseVibration``, 20 mm/s^2 RMS over 1-100 Hz)
reaches the stage's coordinates as minus the base's acceleration; the regulator's derivative action
answers it, so the currents follow the accelerations a few milliseconds late, which an
equation-error fit reads as forces that follow the currents late. Two of three such logs had an
amplifier lag claimed (0.32 and 0.40 ms beyond the hold on the band); a lag is now also sized on a
quarter of the band, where that one shrinks and a real one does not
(``pipeline._not_on_a_narrower_band``). Logs from ``tests/independent`` (no code shared with
``maglev_oc.sim``).
"""

from __future__ import annotations

import json

import pytest

from maglev_oc.data.reading import read_log
from maglev_oc.diagnosis.pipeline import diagnose
from tests.independent.effects import AmplifierDynamics, BaseVibration
from tests.independent.logio import write_log
from tests.independent.scoring import score
from tests.independent.simulate import Scenario, simulate


def _diagnosed(tmp_path, name: str, seed: int, *effects):
    run = simulate(Scenario(name=name, seed=seed, effects=effects))
    csv, truth = write_log(run, tmp_path, name)
    out = diagnose([read_log(csv)], limits=False)
    return out, score(name, json.loads(truth.read_text()), out.to_dict()["effects"])


def test_the_loops_answer_to_a_shaking_base_is_not_claimed_as_a_lag(tmp_path):
    # bench/diagnose_rigs.py --vibration, vibration_large_7301: before, a 0.14 ms lag (z 9) on half
    # the band; on a quarter 0.079 ms, 0.058 below the half's value: not twice the standard error
    # that change adds above the hold
    d, s = _diagnosed(tmp_path, "shaken", 7301, BaseVibration.large())
    assert s.claimed == []
    assert not d.unexplained
    [lag] = [j for j in d.rejected if j.name == "current_amplifier_lag"]
    assert lag.verdict == "implausible"
    assert "quarter of the band" in lag.reason


@pytest.mark.extended
def test_a_real_lag_on_a_shaking_base_is_still_found_and_sized(tmp_path):
    # vibration_large+lag_7301: 150 Hz after 0.2 ms (1.26 ms in all), found at 1.38 ms on half the
    # band (1.30 on a quarter)
    lag = AmplifierDynamics.large()
    _, s = _diagnosed(tmp_path, "shaken_lag", 7301, BaseVibration.large(), lag)
    assert s.claimed == ["current_amplifier_lag"]
    assert s.size_right, s.notes  # within the 30 %
