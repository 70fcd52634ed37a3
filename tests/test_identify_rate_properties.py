"""Equation error on a log faster than 1 kHz (``maglev_oc.identification.equation_error``): the
log is reduced to 1 kHz by block means, so the samples a caller chooses at the log's own rate
decide which means are fitted: a mean is fitted when every sample it averages is chosen. Checked
on a 5 kHz synthetic log against the same choice rounded out to whole blocks by hand. Numpy and
one small least-squares problem per fit, about a second."""

from __future__ import annotations

import numpy as np
import pytest

from maglev_oc.data.logs import Log
from maglev_oc.identification.equation_error import EquationError
from tests.test_regression import AMPS, FREQS, GAP

RATE = 5000.0  # [Hz] the rig's loop rate; reduced by q = 5 to 1 kHz
Q = 5


def fast_log(model, seconds: float = 8.0, rate: float = RATE, seed: int = 11) -> Log:
    """The horizontal sines of tests.test_regression at ``rate`` (the rig's 5 kHz by default) with the
    current that drives them through the model's L1 at a locked gap (an exact answer for C1)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * rate)) / rate
    w = 2 * np.pi * FREQS
    phases = rng.uniform(0, 2 * np.pi, FREQS.size)
    x3 = np.sum(AMPS[:, None] * np.sin(np.outer(w, t) + phases[:, None]), axis=0)
    acc = -np.sum((AMPS * w**2)[:, None] * np.sin(np.outer(w, t) + phases[:, None]), axis=0)
    l1 = float(model.coefficients(GAP)[0, 0])
    x = np.full((4, t.size), np.nan)
    x[0], x[2] = GAP, x3 + 1e-6 * rng.standard_normal(t.size)
    u = np.vstack([-acc / l1, np.full(t.size, 1.5)])
    return Log(t, x, u, source=f"fast_{rate:g}.csv")


@pytest.fixture(scope="module")
def problem(model):
    return EquationError(fast_log(model), model, estimate=("C1",))


def test_a_fast_log_is_fitted_at_1_khz(problem):
    assert problem.sample_time == pytest.approx(Q / RATE, rel=1e-12)


@pytest.mark.parametrize(("start", "stop"), [(7003, 31002), (5000, 30000), (12_345, 36_789)])
def test_a_chosen_block_keeps_the_means_it_covers_whole(problem, start, stop):
    """Samples [start, stop) at 5 kHz: the fit is the one on the blocks of five lying wholly
    inside, [ceil(start / 5) 5, floor(stop / 5) 5) (same samples, so the same numbers to
    rounding: 1e-12), and C1 is found (1e-3: the 1 um position noise through the 10 Hz
    differentiator)."""
    n = problem.logs[0].n
    mask = np.zeros(n, dtype=bool)
    mask[start:stop] = True
    whole = np.zeros(n, dtype=bool)
    whole[-(-start // Q) * Q : (stop // Q) * Q] = True
    a, b = problem.fit(mask), problem.fit(whole)
    assert a.success and b.success
    assert a.n_samples == b.n_samples
    assert a.values["C1"] == pytest.approx(b.values["C1"], rel=1e-12)
    assert a.values["C1"] == pytest.approx(problem.model.constants.C1, rel=1e-3)
    # one sample fewer at either end drops that whole block
    trimmed = mask.copy()
    trimmed[[start, stop - 1]] = False
    c = problem.fit(trimmed)
    blocks_lost = (start % Q == 0) + (stop % Q == 0)
    assert c.n_samples == a.n_samples - blocks_lost
