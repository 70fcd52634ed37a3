"""The operating-region study's options reach the steps that use them (mutation seed 61).

Two steps of :func:`maglev_oc.region.study.operating_region_study` checked with their expensive
callees replaced by recorders, so that what each step hands on is compared with the option it was
given, at values other than the defaults (where a dropped option and its default agree):

* the robust sweep's runs last ``horizon``, the FL runs' length (its specs carried the sweep's own
  default duration of 1 s, the study's default horizon too);
* the conservativeness slices go on past a set-point with no certificate to the ones that have one.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.control.gains import OMEGA0, PAPER_K_H, PAPER_K_V
from maglev_oc.model.stage import StageModel
from maglev_oc.region import study
from maglev_oc.region.closed_loop import Reference
from maglev_oc.region.sweep import SweepSpec
from maglev_oc.units import MM_TO_M


class _Stop(Exception):
    """Raised by a recorder once it has what the test needs."""


def _reference_study(gap_mm: float) -> SimpleNamespace:
    cert = SimpleNamespace(success=True, P=np.eye(10), level=0.5)
    return SimpleNamespace(
        reference=Reference.setpoint(gap_mm * MM_TO_M, 0.0), best=cert, lyapunov=cert, sdp=None
    )


def _run(**config) -> SimpleNamespace:
    loop = SimpleNamespace(K_h=np.array(PAPER_K_H), K_v=np.array(PAPER_K_V), omega0=OMEGA0)
    return SimpleNamespace(
        config=SimpleNamespace(**config),
        loop=loop,
        model=StageModel(),
        limit=9.0,
        feasible=SimpleNamespace(gap_range=None, position_range=None),
        say=lambda *_: None,
        timings={},
    )


@pytest.mark.parametrize("horizon", [0.4, 2.5])
def test_the_robust_sweeps_runs_last_the_studys_horizon(monkeypatch, horizon):
    # every set-point's spec handed to the sweep carries config.horizon (the sweep's own default is
    # 1 s): recorded at the call of robustness_table, which is then stopped
    seen = {}

    def table(specs, covariance, **kw):
        seen.update(specs)
        raise _Stop

    monkeypatch.setattr(study, "robustness_table", table)
    run = _run(robust_runs=3, horizon=horizon, seed=0, robust_probe_runs=0, linear=False)
    assert SweepSpec.__dataclass_fields__["duration"].default != horizon
    with pytest.raises(_Stop):
        study._robust(run, [_reference_study(20.0), _reference_study(15.0)], None, "assumed")
    assert sorted(seen) == ["15 mm", "20 mm"]
    assert all(spec.duration == horizon for spec in seen.values())


def test_slices_skip_a_setpoint_without_a_certificate_and_go_on(monkeypatch):
    # slice set-points 12 and 20 mm with a reference study at 20 mm only: 12 mm is skipped, 20 mm
    # sliced (two slices, (e1, e2) and (e1, e1'), each checked against the Lyapunov certificate)
    calls = []

    def fake_slice(sim, loop, ref, P, level, axes, e_rng, yr, **kw):
        calls.append((round(ref.gap / MM_TO_M, 6), axes))
        return SimpleNamespace()

    monkeypatch.setattr(study, "fl_slice", fake_slice)
    run = _run(slice_points=5, slice_setpoints_mm=(12.0, 20.0))
    out = study._slices(run, None, [_reference_study(20.0)])
    assert calls == [(20.0, ("e1", "e2")), (20.0, ("e1", "e1_rate"))]
    assert len(out["Lyapunov P"]) == 2 and out["SDP P"] == ()


def test_the_robust_study_says_which_certificate_each_set_point_sweeps(monkeypatch):
    # a set-point whose best certificate is the SDP's is swept in "SDP P", one whose best is the
    # Lyapunov equation's in "Lyapunov P" (the report's table names the set the starts were drawn
    # from; seed 64: the label was "Lyapunov P" for both with every test passing)
    monkeypatch.setattr(study, "robustness_table", lambda specs, covariance, **kw: [])
    lyapunov = _reference_study(20.0)
    by_sdp = _reference_study(15.0)
    by_sdp.best = SimpleNamespace(success=True, P=2 * np.eye(10), level=0.3)  # not the Lyapunov one
    run = _run(robust_runs=3, horizon=1.0, seed=0, robust_probe_runs=0, linear=False, certify_boxes=False)
    out = study._robust(run, [lyapunov, by_sdp], None, "assumed")
    assert out.certificates == {"20 mm": "Lyapunov P", "15 mm": "SDP P"}
