"""Properties of ``maglev_oc.diagnosis`` written against the survivors of the seed-37 mutation-testing run
(issue 21): each test states a property of a result a user sees, not the mutated token.

* A guide waviness is reported by its size: the amplitude sqrt(a^2 + b^2) of its (sin, cos) gap
  change with the period it was built at, in plain words in micrometres over that period; a wave
  of more than 0.5 mm (a fortieth of the 20 mm working gap) is refused as not physical, with a
  reason that names the waviness and the bound, and one below it is not.
* The held-out significance of a candidate that removes most of the residual is built from each
  0.5 s block's full log-ratio log(SS0_b / SS1_b): recomputed here from the factor by which each
  block's residual shrinks (-2 log k_b), whatever the size of SS1_b in units of the base model's
  mean square.
* Two forces periodic in the position whose periods the logged travel does not tell apart
  (T |1/P - 1/P'| under ``min_beats`` cycles) are never both claimed by the selection: with both
  planted, the one chosen second is not separable and confounded with the first, at the beats
  recomputed here from the travel.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from maglev_oc.diagnosis.candidate import Candidate, within
from maglev_oc.diagnosis.guides import waviness_candidate
from maglev_oc.diagnosis.library import candidate_library
from maglev_oc.diagnosis.selection import SelectionSettings, _block_z, holdout_significance, select
from maglev_oc.regression.data import prepare
from maglev_oc.regression.design import build_design
from maglev_oc.regression.terms import periodic_force
from tests.test_regression import GAP
from tests.test_statistics_properties import _log

SECOND_PERIOD = 0.025
"""[m] a second horizontal periodic force beside the 19 mm slot pitch: 1/P - 1/P' = 12.6 1/m, so
over the synthetic sweep's 63 mm travel the two drift apart by 0.79 of a cycle (under the default
``min_beats`` of 1), while over the travel the two sines are far from collinear (the joint fit's
variance inflation is about 1.3)."""


def _two_forces(x3: np.ndarray, slot_pitch: float) -> np.ndarray:
    """[m/s^2] the planted horizontal accelerations: 0.02 at the slot pitch, 0.015 at 25 mm (both
    about 10 times the selection's 2.25e-3 m/s^2 size floor)."""
    return 0.02 * np.sin(2 * math.pi * x3 / slot_pitch + 0.5) + 0.015 * np.sin(
        2 * math.pi * x3 / SECOND_PERIOD + 1.3
    )


@pytest.fixture(scope="module")
def two_periodic(model):
    """(prepared log, library by name, design): the synthetic horizontal sweep of
    ``tests/test_statistics_properties`` (30 s, the gap held at 20 mm) with both periodic forces
    planted, and the 19 mm cogging and a 25 mm periodic force as the candidates."""
    data = prepare(
        [_log(model, friction=0.0, force=lambda x3: _two_forces(x3, model.params.slot_pitch))], bandwidth=10.0
    )
    lib = {c.name: c for c in candidate_library(model, data)}
    fit, hold = data.masks(0.25)
    other = Candidate(
        periodic_force(model.params, "horizontal", SECOND_PERIOD, name="detent_25mm"),
        "periodic",
        "position",
        "runs over a longer travel",
        within("amplitude", 10.0, "peak force"),
        lambda e: f"A force of {e['amplitude'].value:.2g} N periodic over 25 mm.",
    )
    lib[other.name] = other
    terms = (lib["cogging_horizontal_19mm"].term, other.term)
    design = build_design(data, model, estimate=("C1",), terms=terms, fit=fit, holdout=hold)
    return data, lib, design


# --- guide waviness: its size and its bound -------------------------------------------------------------
@pytest.mark.parametrize("amplitude", [3e-4, 8e-4])
def test_a_guide_waviness_reports_its_amplitude_and_is_refused_beyond_half_a_millimetre(
    model, two_periodic, amplitude
):
    """w(x3) = a sin(2 pi x3 / P) + b cos(2 pi x3 / P) is the gap change the encoder does not see;
    its size is sqrt(a^2 + b^2) (here a, b = 0.6, 0.8 of the amplitude: exactly the amplitude; with
    the covariance 1e-10 I m^2 its standard error is 1e-5 m whatever the phase), the finding says it
    in micrometres (to two significant digits) over P in millimetres. The working gap is 20 mm: a
    0.3 mm wave is a guide's shape, a 0.8 mm one (4 % of the gap, beyond the library's 0.5 mm bound)
    is refused, and the reason names the waviness and that bound in metres."""
    data, _, _ = two_periodic
    assert GAP == 0.020
    period = 0.031
    cand = waviness_candidate(model, data, period)
    q = np.array([0.6, 0.8]) * amplitude
    cov = np.diag([1e-10, 1e-10])
    e = cand.term.physical_parameters(q, cov, {})
    assert e["amplitude"].value == pytest.approx(amplitude, rel=1e-12)
    assert e["amplitude"].unit == "m"
    assert e["period"].value == period
    said = re.search(r"wave by (\S+) ± (\S+) um over (\S+) mm", cand.describe(e))
    assert said is not None
    assert float(said.group(1)) == pytest.approx(amplitude * 1e6, rel=0.05)  # two significant digits
    assert float(said.group(2)) == pytest.approx(10.0)  # sqrt(1e-10) m, the (a, b) block's standard error
    assert float(said.group(3)) == period * 1e3
    reason = cand.plausible(e)
    if amplitude < 5e-4:
        assert reason is None
    else:
        assert reason is not None and reason.startswith("waviness of 0.0008 m")
        assert float(re.search(r"physical bound (\S+) m", reason).group(1)) == 5e-4


# --- the held-out significance of a dominant effect -----------------------------------------------------
def test_the_held_out_z_of_an_effect_that_removes_most_of_the_error_uses_each_blocks_full_log_ratio(
    two_periodic,
):
    """A candidate that shrinks the held-out residual by a factor k_b in 0.5 s block b (here
    10^-1.5 to 10^-3: an effect that is most of the residual) lowers that block's sum of squares
    by k_b^2 exactly, so its log-ratio log(SS0_b / SS1_b) is -2 log k_b, whatever the block's sum
    in units of the base model's mean square (here SS1_b is below 1, the block holding 500 samples
    of SS0_b about 500). The blocks are recomputed here: each log's held-out samples in order, cut
    into whole blocks of round(0.5 s / sample time) samples, a shorter rest left out. z is then the
    mean of those log-ratios over their long-run standard error (the same series statistic,
    ``_block_z``, fed the ratios computed here; 1e-9: the rounding of the sums of 500 squares);
    the gain is the relative drop of the held-out mean square, computed here."""
    _, _, d = two_periodic
    axes = np.array([1])  # the horizontal axis, the one that moves
    assert d.moving[1]
    n = int(d.holdout.sum())
    size = round(d.block_seconds / d.prepared.sample_time)
    assert size == 500
    nb = n // size  # one log: its held-out samples are the last quarter
    rng = np.random.default_rng(5)
    k_block = 10.0 ** -rng.uniform(1.5, 3.0, nb)
    k = np.ones(n)
    k[: nb * size] = np.repeat(k_block, size)
    r0 = rng.standard_normal((2, n))
    r1 = r0 * k
    gain, z = holdout_significance(d, r0, r1, axes)
    assert gain == pytest.approx(1 - np.mean(r1[1] ** 2) / np.mean(r0[1] ** 2), rel=1e-12)
    ratios = -2.0 * np.log(k_block)
    expected = _block_z(ratios, np.zeros(nb), d.block_seconds)
    assert expected > 10
    assert z == pytest.approx(expected, rel=1e-9)


# --- two periodic forces the travel cannot tell apart ---------------------------------------------------
def test_two_periodic_forces_the_travel_cannot_tell_apart_are_not_both_claimed(two_periodic, model):
    """Both forces are planted and each alone passes the held-out, Wald and size tests (the second
    lowers the held-out error by about half). Over the logged travel T (1st to 99th percentile of
    the training positions, recomputed here) their periods drift apart by T |1/P - 1/P'| = 0.79
    cycles, under ``min_beats``: the data do not say which period is there, so the selection
    claims one and refuses the other as not separable, confounded with the chosen one, with the
    beats in its reason. Its own fit beside the chosen one is not what refuses it (variance
    inflation below the 100 bound)."""
    _, lib, design = two_periodic
    settings = SelectionSettings()
    cands = [lib["cogging_horizontal_19mm"], lib["detent_25mm"]]
    sel = select(design, cands, settings)
    travel = float(np.subtract(*np.percentile(design.prepared.x[2, design.fit], [99, 1])))
    beats = travel * abs(1 / model.params.slot_pitch - 1 / SECOND_PERIOD)
    assert 0.5 < beats < settings.min_beats
    first = sel.steps[0].judgements
    assert all(first[c.name].verdict in ("passes", "accepted") for c in cands)
    assert len(sel.selected) == 1
    chosen = sel.selected[0]
    refused = next(c.name for c in cands if c.name != chosen)
    j = sel.last[refused]
    assert j.verdict == "not separable", j.reason
    assert j.confounded_with == (chosen,)
    assert j.vif < settings.max_vif
    assert f"drift apart by {beats:.2f} of a cycle" in j.reason
