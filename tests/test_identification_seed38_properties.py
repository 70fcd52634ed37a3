"""Properties of ``maglev_oc.identification`` from the survivors of the seed-38 mutation run
(identification only, after the output tests):

* a sampled reference (what a reference file holds, what the rig plays) refuses a time axis that
  does not increase strictly: a repeated or a backward sample time, anywhere in it;
* the identification study measures the equilibrium currents at the two positions the papers'
  verification needs (000 Sec. V-C): x3 = 0 and 1.5 slot pitches along the track, where the
  cogging force acts; each run is simulated at its own position.
"""

from __future__ import annotations

import numpy as np
import pytest

from maglev_oc.errors import InputError
from maglev_oc.identification import study
from maglev_oc.identification.design import REFERENCE_RATE_HZ, SampledReference
from maglev_oc.identification.experiments import verification_effects


@pytest.mark.parametrize("where", [1, 5, 9])
@pytest.mark.parametrize("step", [0.0, -1.0 / REFERENCE_RATE_HZ])
def test_a_reference_whose_time_does_not_increase_is_refused(where, step):
    """t[k] - t[k-1] must be > 0 for every k: a repeated sample (step 0) or one going back in time,
    at the start, the middle or the end of a 10-sample reference, is refused; the same reference with
    increasing times is accepted."""
    t = np.arange(10) / REFERENCE_RATE_HZ
    values = np.zeros((6, 10))
    values[0] = 0.02
    SampledReference(t, values)  # increasing: accepted
    bad = t.copy()
    bad[where] = bad[where - 1] + step
    with pytest.raises(InputError, match="must start at 0 and increase"):
        SampledReference(bad, values)


class _Stop(Exception):
    pass


def test_the_studys_equilibrium_runs_are_at_x3_0_and_on_the_cogging_position(model, truth_model, monkeypatch):
    """The study's two equilibrium-current runs are simulated at x3 = 0 and at 1.5 slot pitches
    (28.6 mm, where the slot-pitch cogging of eq. (9) is at its extreme; the papers compare the two
    to show the cogging's share of the holding current). The simulator is replaced by a recorder
    that stops the study after the second call, so only the positions asked for are checked."""
    positions = []

    def record(truth, gaps, **kw):
        positions.append(kw.get("position", "not given"))
        if len(positions) == 2:
            raise _Stop
        return None

    monkeypatch.setattr(study, "equilibrium_current_runs", record)
    with pytest.raises(_Stop):
        study._equilibrium(study._Clock(), model, truth_model, verification_effects(), model, None)
    assert positions == [0.0, pytest.approx(1.5 * model.params.slot_pitch, rel=1e-12)]
