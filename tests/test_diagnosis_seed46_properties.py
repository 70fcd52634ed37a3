"""Survivors of the seed-46 mutation sample of ``maglev_oc.diagnosis`` (bench/README, "Mutation
testing"), as properties of what a user reads:

* the JSON's output-error metric says its unit, metres, in SI's lower case (an upper-cased "IN M"
  would be mega-units);
* an unexplained periodic residual names its period in millimetres, as its key does (a period of
  15 mm printed as "0.0 mm" slipped).
"""

from __future__ import annotations

import pytest

from maglev_oc.diagnosis.unexplained import _probes
from maglev_oc.regression.data import prepare
from tests.diagnosis_support import stub_diagnosis
from tests.test_statistics_properties import _log


def test_the_metrics_name_their_si_units():
    d = stub_diagnosis().to_dict()
    assert d["output_error_metric"].endswith("held-out block, per axis, in m")
    assert "m/s^2" in d["error_metric"]


@pytest.mark.parametrize("period", [0.015, 0.0191, 0.06])
def test_a_periodic_probe_names_its_period_in_mm(model, period):
    data = prepare([_log(model, friction=0.0)], bandwidth=10.0)
    assert data.moving[1]  # the horizontal sweep: its probes are built
    (periodic,) = [p for p in _probes(data, [("horizontal", period)]) if p[3] is not None]
    term, key, words, got = periodic
    mm = f"{period * 1e3:.1f} mm"
    assert key == f"position (period {mm})"
    assert words == f"the horizontal position, periodically over {mm}"
    assert got == period and term.axis == "horizontal"
