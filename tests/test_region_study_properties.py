"""The operating-region study (maglev_oc.region.study) on a tiny configuration: its random starts
follow the configuration's seed (the same seed, the same study; another seed, other starts),
and its progress says each step in words."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from maglev_oc.region.study import operating_region_study
from tests.test_region_study import TINY as TINY_STUDY

TINY = dataclasses.replace(TINY_STUDY, robust_runs=6, robust_probe_runs=4, certify_runs=8)
"""test_region_study's tiny study with a few runs of the robust part too (about 1.3 s of CPU)."""


@pytest.fixture(scope="module")
def studies(model):
    """(messages, study) for seeds 0, 0 and 1."""
    out = []
    for seed in (0, 0, 1):
        messages = []
        st = operating_region_study(model, dataclasses.replace(TINY, seed=seed), progress=messages.append)
        out.append((messages, st))
    return out


def _starts(st) -> list[np.ndarray]:
    """The V / level of every sampled start of the study (inside checks and quantisation runs)."""
    rs = st.references[0]
    return [c.start_ratio for c in rs.checks.values()] + [st.quantization.start_ratio]


def test_the_seed_determines_the_study(studies):
    (_, a), (_, b), (_, c) = studies
    for x, y in zip(_starts(a), _starts(b), strict=True):
        np.testing.assert_array_equal(x, y)  # bit for bit: the same draws, the same arithmetic
    full_a, full_c = _starts(a)[0], _starts(c)[0]
    assert full_a.size == full_c.size == 8 and not np.allclose(full_a, full_c)
    assert [(r.runs, r.violations) for r in a.robust.rows] == [(r.runs, r.violations) for r in b.robust.rows]


def test_progress_names_every_step_in_words(studies):
    messages, st = studies[0]
    assert messages and all(isinstance(m, str) and m.strip() for m in messages)
    for words in ("Procedure 2", "Monte Carlo", "slices", "quantising", "robust"):
        assert any(words in m for m in messages), (words, messages)
    assert st.robust is not None and st.robust.certified is not None  # the robust steps did run


@pytest.mark.parametrize("stoppers", [True, False])
def test_the_maps_span_the_gaps_the_stage_can_reach(model, stoppers):
    """The slices of F through the 20 mm set-point show the gap error over the stoppers' range
    widened by 2 mm each side (so the stoppers' edges are in view), and without stoppers over
    5-35 mm likewise: the e1 axis runs from that lower gap to that upper gap minus 20 mm
    (1e-15 m: rounding of millimetre sums), increasing, through the set-point. Every slice's
    second axis (an error or its rate) is centred on the reference: it spans -a to a, so the
    picture shows as much of F on either side of the set-point (exact: the ends are negatives)."""
    from maglev_oc.region.feasibility import GAP_TRAVEL, FeasibleSet

    feasible = FeasibleSet(model) if stoppers else FeasibleSet(model, gap_range=None)
    lo, hi = GAP_TRAVEL if stoppers else (5e-3, 35e-3)
    st = operating_region_study(model, dataclasses.replace(TINY, robust_runs=0), feasible=feasible)
    maps = [m for m in st.maps if m.axes[0] == "e1"]
    assert len(maps) >= 3
    for m in maps:
        assert m.x[0] == pytest.approx(lo - 2e-3 - 0.02, abs=1e-15)
        assert m.x[-1] == pytest.approx(hi + 2e-3 - 0.02, abs=1e-15)
        assert np.all(np.diff(m.x) > 0) and m.x[0] < 0 < m.x[-1]
    for m in st.maps:
        assert m.y[0] == -m.y[-1] < 0, m.axes
