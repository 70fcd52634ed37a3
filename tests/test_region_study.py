"""The whole operating-region study and its report (the QUICK configuration is slow: about a minute)."""

from __future__ import annotations

import dataclasses
import json

import pytest

from maglev_oc.region.study import StudyConfig, certificate_rows, operating_region_study
from maglev_oc.results import check_result

TINY = StudyConfig(
    setpoints_mm=(20.0,),
    sinusoid=False,
    sdp=False,
    samples=8,
    slice_setpoints_mm=(20.0,),
    slice_points=5,
    linear=False,
    quantization_samples=8,
    map_points=11,
    horizon=0.2,
    compile=False,
    threads=1,
)
"""One set-point, a few runs, no SDP or linear regulators: about a second."""


@pytest.fixture(scope="module")
def quick(shared_region_report):
    """The study in the report's QUICK configuration, computed once per session with its report
    (tests/report_support.py; tests/test_reports_model_region_layout.py checks the same report)."""
    return shared_region_report[0]


@pytest.mark.slow
def test_quick_report_prints_the_study(quick, shared_region_report):
    from maglev_oc.reporting.region_plots import BINDING_WORDS

    report = shared_region_report[1]  # operating_region.write_report of this study
    assert report.path.read_bytes()[:5] == b"%PDF-"
    table = report.section("Certified sets")
    lyapunov = [r for r in table.rows if r[1] == "Lyapunov"]
    assert len(lyapunov) == len(quick.references)
    for row, rs in zip(lyapunov, quick.references, strict=True):
        c = rs.lyapunov
        assert float(row[2]) == pytest.approx(c.level, rel=1e-3)  # printed to 4 digits
        assert float(row[4]) == pytest.approx(c.tightness, abs=1e-3)  # printed to 0.001
        assert row[5] == BINDING_WORDS[c.binding]  # the constraint in words


@pytest.mark.slow
def test_quick_study_numbers(quick):
    st = quick
    assert st.inside_totals()["violations"] == 0
    assert all(s.unsafe_certified == 0 for v in st.slices.values() for s in v)
    ls = st.large_step
    assert ls.fl_direction.best.reach >= 1.0  # the papers' large step is certified for the FL regulator
    assert all(x.large_step_ratio > 1 for x in ls.linear)  # and outside the linear ROA certificates


def test_tiny_study_follows_the_result_convention(model):
    """One set-point, a few runs, no SDP or linear regulators (about a second): the study is a
    result (success, status word, message, timings by step, JSON-able to_dict, report)."""
    st = operating_region_study(model, TINY)
    check_result(st)
    assert st.success and st.status == "certified"
    assert st.inside_totals() == {"runs": 16, "violations": 0}  # 8 full + 8 at rest
    steps = list(st.timings)
    assert steps[0] == "build solvers" and steps[-1] == "total"
    doc = json.loads(json.dumps(st.to_dict()))
    assert doc["status"] == "certified" and len(doc["references"]) == 1


def test_sinusoid_checks_sample_the_whole_period_and_every_run():
    # Monte Carlo inside a certificate for the ellipse reference: n runs spread over eight phases
    # of one period (not over a set-point's single phase), every run counted once
    import math

    from maglev_oc.region.closed_loop import Reference
    from maglev_oc.region.study import _phases

    for n in (0, 5, 8, 21):
        groups = _phases(Reference.paper_sinusoid(), n)
        assert sum(c for _, c in groups) == n
        if n:
            phases = [p for p, _ in groups]
            assert phases == sorted(phases) and phases[0] == 0.0
            assert max(phases) < 2 * math.pi and 2 * math.pi - max(phases) == pytest.approx(2 * math.pi / 8)
            counts = [c for _, c in groups]
            assert max(counts) - min(counts) <= 1
    assert _phases(Reference.setpoint(0.02), 7) == [(0.0, 7)]


@pytest.fixture(scope="module")
def tiny_with_sdp(model):
    """TINY with the SDP enlargement (about 4 s)."""
    return operating_region_study(model, dataclasses.replace(TINY, sdp=True))


def test_the_sdp_certificate_reaches_the_study_its_checks_and_its_table(tiny_with_sdp):
    # The SDP's certified set is what the study keeps for the set-point: the best certificate
    # (larger than the Lyapunov equation's: the enlargement's area > 1), sampled inside and from
    # its boundary like the Lyapunov one (no run leaves F), in the JSON and in the report's table
    # at its own level.
    (rs,) = tiny_with_sdp.references
    assert rs.sdp is not None and rs.sdp.certified is not None and rs.sdp.certified.success
    assert rs.best is rs.sdp.certified
    assert rs.enlargement is not None and rs.enlargement.area > 1.0
    assert {"SDP P, full", "SDP P, at rest"} <= set(rs.checks) and "SDP P" in rs.worst_start
    assert all(c.violations == 0 and c.n > 0 for c in rs.checks.values())
    assert rs.checks["SDP P, full"].level == pytest.approx(rs.sdp.certified.level)
    out = json.loads(json.dumps(tiny_with_sdp.to_dict()))["references"][0]
    assert out["sdp"]["best"] is not None and out["sdp"]["success"]
    rows = [r for r in certificate_rows(tiny_with_sdp) if r[1] == "SDP"]
    assert len(rows) == 1 and rows[0][2] == pytest.approx(rs.sdp.certified.level)
