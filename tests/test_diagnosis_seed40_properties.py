"""Properties of ``maglev_oc.diagnosis`` written against the survivors of the seed-40 mutation-testing run
(issue 21): each test states a property of a result a user sees, not the mutated token.

* The block significance of a held-out gain on one log of n >= 4 blocks divides the mean log-ratio by
  its long-run standard error, the averaged periodogram of the blocks at the m lowest frequencies
  (``frequencies_for``), computed here with numpy's FFT: sqrt(mean_j |X_j|^2) / n. On one log the
  deviations from the pooled mean sum to zero, so any shortcut through their sum gives no standard
  error at all (z = 0) and would hide every effect on a short log.
* The spatial period that the resolution rule reads (Rayleigh: two forces of the position alone whose
  periods the travel does not tell apart) is the period of every force of the position alone and
  periodic in it, the guides' waviness (a geometry) as well as cogging and detents; a force that
  scales with the current (thrust ripple) or has no period (a straight misalignment) has none. The
  documented case: a 60 mm waviness beside a 57 mm detent over 70 mm of travel (0.05 beats) is
  unresolved whichever of the two came first.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.diagnosis.candidate import LibraryContext
from maglev_oc.diagnosis.currents import ripple_candidate
from maglev_oc.diagnosis.guides import misalignment_candidate, waviness_candidate
from maglev_oc.diagnosis.magnetics import cogging_candidates
from maglev_oc.diagnosis.selection import SelectionSettings, _block_z, _spatial_period, _unresolved
from maglev_oc.regression.covariance import DEFAULT_BAND, frequencies_for
from maglev_oc.regression.data import prepare
from maglev_oc.results import Estimate
from tests.test_statistics_properties import _log


@pytest.mark.parametrize("n", [4, 5, 6, 9, 16, 40])
def test_the_block_z_of_one_log_is_its_mean_over_the_periodograms_standard_error(n):
    """One log of n blocks: z = mean / (sqrt(P) / n), P = mean over j = 1..m of |FFT(x - mean)_j|^2
    (numpy's FFT here; 1e-9: the same sums in another order)."""
    rng = np.random.default_rng(n)
    ratios = rng.normal(0.1, 0.3, n)
    x = ratios - ratios.mean()
    m = frequencies_for(n, 0.5, DEFAULT_BAND)
    p = np.mean(np.abs(np.fft.fft(x)[1 : m + 1]) ** 2)
    want = ratios.mean() / (np.sqrt(p) / n)
    got = _block_z(ratios, np.zeros(n, dtype=int), 0.5)
    assert got != 0.0
    assert got == pytest.approx(want, rel=1e-9)


@pytest.fixture(scope="module")
def ctx(model):
    return LibraryContext(model, prepare([_log(model, friction=0.0)], bandwidth=10.0))


def test_every_force_periodic_in_the_position_alone_has_a_spatial_period(model, ctx):
    """Waviness (geometry) and cogging (periodic) give the period they are fitted at; thrust ripple
    (it scales with the current) and a uniform misalignment (no period) give none."""
    period = {"period": Estimate(0.06, 0.0, "m")}
    wavy = waviness_candidate(model, ctx.data, 0.06)
    assert _spatial_period(wavy, period) == 0.06
    cog = cogging_candidates(ctx)[0]
    assert _spatial_period(cog, {"period": Estimate(0.019, 0.0, "m")}) == 0.019
    assert _spatial_period(ripple_candidate(ctx), period) is None
    assert _spatial_period(misalignment_candidate(ctx), {}) is None
    assert _spatial_period(wavy, {"period": Estimate(-0.06, 0.0, "m")}) is None  # no such period


def test_a_waviness_and_a_detent_the_travel_does_not_tell_apart_are_unresolved_either_way(model, ctx):
    """travel 70 mm x |1/60 mm - 1/57 mm| = 0.06 beats < 1 (``min_beats``): whichever was chosen
    first, the other is unresolved beside it; at 19 mm against 60 mm (2.5 beats) both are told."""
    x3 = np.linspace(-0.035, 0.035, 4001) / 0.98  # 1st-99th percentile span: 70 mm
    design = SimpleNamespace(prepared=SimpleNamespace(x=np.vstack([x3] * 4)), fit=np.ones(x3.size, bool))
    wavy = waviness_candidate(model, ctx.data, 0.060)
    detent = SimpleNamespace(
        axis="horizontal", family="periodic", variable="position", reported_name="detent"
    )
    settings = SelectionSettings()
    out = _unresolved(wavy, {"period": Estimate(0.060, 0.0, "m")}, [(detent, 0.057)], design, settings)
    assert [name for name, _ in out] == ["detent"]
    assert out[0][1] == pytest.approx(0.070 * abs(1 / 0.060 - 1 / 0.057), rel=1e-6)
    told = _unresolved(wavy, {"period": Estimate(0.060, 0.0, "m")}, [(detent, 0.019)], design, settings)
    assert told == []
    # the detent judged beside the chosen waviness: the same pair, the same verdict
    cog = cogging_candidates(ctx)[0]
    back = _unresolved(cog, {"period": Estimate(0.057, 0.0, "m")}, [(wavy, 0.060)], design, settings)
    assert [name for name, _ in back] == [wavy.reported_name]
