"""Properties of preparing logs for the fits (``maglev_oc.regression.data``), checked against numpy
means and hand counts:

- a log is reduced to at most ``max_rate`` by the fewest samples per mean, and a log faster than
  the fit rate keeps the times of its block means; a control rate that is not positive is refused;
- a prepared sample keeps its time within its own log;
- a log shorter than the differentiator needs is refused with that length, one of exactly that
  length is prepared, and ``prepare`` records the edge it leaves out of each log.
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from maglev_oc.data.log import Log
from maglev_oc.data.logs import LogError
from maglev_oc.regression.data import logging_error_share, prepare, reduce_rate
from tests.test_regression import _synthetic


@pytest.mark.parametrize("rate", [800.0, 1000.0, 1500.0, 2500.0, 5000.0])
def test_a_log_is_reduced_to_at_most_max_rate_by_the_fewest_samples(rate):
    n = 2000
    t = np.arange(n) / rate
    x = np.vstack([np.full(n, 0.02), np.zeros(n), np.linspace(0, 0.01, n), np.zeros(n)])
    reduced, q = reduce_rate(Log(t, x, np.ones((2, n))), 1000.0)
    assert 1.0 / reduced.sample_time <= 1000.0 * (1 + 1e-9)
    assert q == 1 or rate / (q - 1) > 1000.0  # one sample fewer per mean would be too fast
    assert reduced.n == n // q


@pytest.mark.parametrize("meta", ["0", "-1000"])
def test_a_control_rate_that_is_not_positive_is_refused(meta):
    n = 200
    t = np.arange(n) / 1000.0
    x = np.vstack([np.full(n, 0.02), np.zeros(n), np.linspace(0, 0.01, n), np.zeros(n)])
    log = Log(t, x, np.ones((2, n)), metadata={"control_rate_hz": meta})
    with pytest.raises(LogError, match="control_rate_hz"):
        logging_error_share(log)
    with pytest.raises(LogError, match="control_rate_hz"):
        logging_error_share(Log(t, x, np.ones((2, n))), control_rate=float(meta))


@pytest.mark.filterwarnings("ignore:nperseg")  # the logged currents' noise floor from a short log
def test_a_log_shorter_than_the_differentiators_need_is_refused_by_name_and_one_that_long_is_not():
    """The differentiator's filters run off both ends of a log (``edge`` samples each) and keep 10
    samples between: a log one sample shorter than the need the error states is refused with that
    need, a log of exactly that length is prepared (with all of its samples outside the edges valid)."""
    t = np.arange(20_000) * 1e-3
    x = np.vstack([0.02 + 1e-3 * np.sin(t), np.zeros_like(t), 0.01 * np.cos(t), np.zeros_like(t)])
    u = np.vstack([np.sin(3.0 * t), np.cos(2.0 * t)])

    def log(n: int) -> Log:
        return Log(t[:n], x[:, :n], u[:, :n], source=f"short{n}.csv")

    with pytest.raises(LogError, match=r"short40\.csv.*needs at least \d+") as err:
        prepare([log(40)], bandwidth=10.0)
    need = int(re.search(r"needs at least (\d+)", str(err.value)).group(1))
    assert need > 40
    with pytest.raises(LogError, match=rf"needs at least {need}\b"):
        prepare([log(need - 1)], bandwidth=10.0)
    data = prepare([log(need)], bandwidth=10.0)
    assert data.n == need and data.valid.sum() == 10


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


# --- regression.data ----------------------------------------------------------------------------
def _log(n: int, seed: int) -> Log:
    t = np.arange(n) / 1000.0
    rng = np.random.default_rng(seed)
    x = np.vstack([0.02 + 1e-3 * np.sin(t), np.zeros(n), 0.01 * np.sin(2 * t + seed), np.zeros(n)])
    u = np.vstack([np.sin(3 * t), 1.5 + 0.1 * np.cos(t)]) + 1e-3 * rng.standard_normal((2, n))
    return Log(t, x, u, source=f"s48 {seed}")


def test_prepare_records_the_edge_it_leaves_out_of_each_log():
    """settings["edge_samples"] is what each log loses at each end: the invalid samples at its start
    and at its end (the filters' memory), the same count as ``edge``."""
    data = prepare([_log(2500, 1), _log(2200, 2)], bandwidth=10.0)
    edge = data.settings["edge_samples"]
    assert isinstance(edge, int) and edge == data.edge > 0
    for start, stop in data.segment_bounds:
        valid = data.valid[start:stop]
        first, last = np.flatnonzero(valid)[[0, -1]]
        assert first == edge and (stop - start - 1) - last == edge
        assert valid[first : last + 1].all()
