"""The whole operating-region study and its report (slow: about a minute)."""

from __future__ import annotations

import pytest

pytestmark = pytest.mark.slow


def test_quick_report(tmp_path, model):
    from maglev_oc.analyses import operating_region

    out = operating_region.build(tmp_path / "operating_region.pdf", model, operating_region.QUICK)
    assert out.is_file() and out.stat().st_size > 50_000


def test_quick_study_numbers(model):
    from maglev_oc.analyses.operating_region import QUICK

    from maglev_oc.region.study import operating_region_study

    st = operating_region_study(model, QUICK)
    assert st.inside_totals()["violations"] == 0
    assert all(s.unsafe_certified == 0 for v in st.slices.values() for s in v)
    ls = st.large_step
    assert ls.fl_direction.best.reach >= 1.0  # the papers' large step is certified for the FL regulator
    assert all(x.large_step_ratio > 1 for x in ls.linear)  # and outside the linear ROA certificates
