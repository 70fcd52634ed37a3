"""Properties of ``maglev_oc.regression`` written against the survivors of the seed-37 mutation-testing
run (issue 21): each test states a property of a result a user sees, not the mutated token.

* A prepared set of logs keeps each sample's time within its own log: ``t`` starts at zero at the
  first sample of every log (also one whose clock started elsewhere), steps by the sample time,
  ends at the log's duration, and sits beside the log's index in ``segment`` and the log's own
  states at that time; a log faster than ``max_rate`` keeps the times of its block means.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from maglev_oc.data.log import Log
from maglev_oc.regression.data import prepare
from tests.test_regression import _synthetic


@pytest.mark.filterwarnings("ignore:nperseg")  # the logged currents' noise floor from a short log
def test_a_prepared_sample_keeps_its_time_within_its_own_log(model):
    """Two logs of the synthetic horizontal sweep at 1 kHz (4 s and 3 s), the second's clock
    starting at 12.5 s (a log cut from a longer run). Prepared together, every sample keeps its
    log's index and its time from that log's first sample: log.t - log.t[0], exactly (the same
    subtraction of the same numbers), so 0 at each log's start, steps of the 1 ms sample time and
    the log's duration at its end; the states beside it are the log's at that time (the gap held
    at 20 mm, the position the Savitzky-Golay estimate of the logged one, to 1e-6 m inside the
    filters' edges on sines of 1-20 mm below 2.3 Hz in a 10 Hz band)."""
    first = _synthetic(model, seconds=4.0, seed=1)
    late = _synthetic(model, seconds=3.0, seed=2)
    late = dataclasses.replace(late, t=late.t + 12.5, source="late.csv")
    data = prepare([first, late], bandwidth=10.0)
    assert data.n == first.n + late.n
    for k, log in enumerate((first, late)):
        mine = data.segment == k
        assert int(mine.sum()) == log.n
        t = data.t[mine]
        assert np.array_equal(t, log.t - log.t[0])
        assert t[0] == 0.0 and t[-1] == pytest.approx(log.duration, rel=1e-12)
        assert np.diff(t) == pytest.approx(np.full(log.n - 1, 1e-3), rel=1e-9)
        inside = data.valid[mine]
        assert np.max(np.abs(data.x[2, mine][inside] - log.x[2][inside])) < 1e-6
        assert np.all(data.x[0, mine] == pytest.approx(0.020, rel=1e-9))


@pytest.mark.filterwarnings("ignore:nperseg")
def test_a_log_faster_than_the_fit_rate_keeps_the_times_of_its_block_means(model):
    """A 2 kHz log prepared at the default 1 kHz ``max_rate`` is reduced by means over pairs of
    samples: its prepared times are those means from the first one, k x 1 ms (the mean of
    t_2k and t_2k+1 less the mean of t_0 and t_1), and the note says it was reduced."""
    base = _synthetic(model, seconds=3.0, seed=4)
    t = np.arange(2 * base.n) * 5e-4
    fast = Log(t, np.repeat(base.x, 2, axis=1), np.repeat(base.u, 2, axis=1), source="fast.csv")
    data = prepare([fast], bandwidth=10.0)
    assert data.sample_time == pytest.approx(1e-3, rel=1e-9)
    assert data.n == base.n
    assert data.t == pytest.approx(np.arange(base.n) * 1e-3, abs=1e-12)
    assert any("reduced to 1000 Hz" in n for n in data.notes)
