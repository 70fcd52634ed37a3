"""Properties of ``maglev_oc.identification`` written against the survivors of the seed-36 mutation-testing
run: each test states a property the code should have, not the mutated token.

* an NPFSI run's report says which Q the estimator used: the papers' A'A (002 sidebar) when none was
  given, "given matrix" when one was;
* equation error on a log faster than 1 kHz fits block means of q samples; a mean is fitted exactly when
  all q samples it averages are chosen, for q = 2 and 3 as for the rig's q = 5
  (tests/test_identify_rate_properties.py), and a 1 kHz log (q = 1) keeps the mask as given;
* a sampled reference refuses gap set-points outside (0, 0.1] m, saying they must be metres in that
  range (a gap of 20 is 20 mm written in millimetres);
* the identification study's fixed-gap runs (000 Sec. V-A) are simulated with the twin effects the study
  was given (the rig's cogging among them), not the defaults.
"""

from __future__ import annotations

import numpy as np
import pytest

from maglev_oc.errors import InputError
from maglev_oc.identification import study
from maglev_oc.identification.design import REFERENCE_RATE_HZ, SampledReference
from maglev_oc.identification.equation_error import EquationError, _reduced_mask
from maglev_oc.identification.experiments import (
    FIXED_GAPS,
    fixed_gap_logs,
    identification_effects,
    verification_effects,
)
from maglev_oc.identification.npfsi import NpfsiEstimator
from tests.test_identify_rate_properties import fast_log


# --- NPFSI's report ------------------------------------------------------------------------------------
def _scalar_data(h: float = 1e-3, duration: float = 1.0):
    """v' = 2.5 a(t), a = sin(3t) + 0.5 cos(7t), exact velocity samples (as tests/test_identify_npfsi.py)."""
    t = np.arange(0, duration, h)
    a = np.sin(3 * t) + 0.5 * np.cos(7 * t)
    v = 2.5 * ((1 - np.cos(3 * t)) / 3 + 0.5 * np.sin(7 * t) / 7)
    return a.reshape(-1, 1, 1), np.zeros((t.size, 1)), v.reshape(-1, 1)


@pytest.mark.parametrize(
    ("Q", "words"), [(None, "Q = A'A (002 sidebar)"), (np.array([[0.5]]), "Q = given matrix")]
)
def test_the_npfsi_report_says_which_q_was_used(Q, words):
    """The report's first line names Q: A'A (the papers' choice, Sigma' = (1 - gamma^-2) A'A) when the
    estimator was made without one, "given matrix" when a Q was passed; never the other."""
    A, b, v = _scalar_data()
    run = NpfsiEstimator(0.01, Q=Q).run(A, b, v, 1e-3, [1.0], names=("theta",))
    head = run.report().splitlines()[0]
    assert head.endswith(f"{words}]]"), head
    other = "given matrix" if Q is None else "A'A"
    assert other not in head


# --- equation error on a fast log -------------------------------------------------------------------------
@pytest.mark.parametrize("q", [2, 3])
def test_a_reduced_mask_keeps_a_mean_iff_all_its_samples_are_chosen(q):
    """q-sample block means of a log: one entry per whole block (a partial block at the end is dropped, as
    the reduction drops it), True exactly when every sample of the block is True. Checked on random masks
    against the definition written out block by block."""
    rng = np.random.default_rng(q)
    for n in (6 * q, 6 * q + 1, 6 * q + q - 1):
        mask = rng.uniform(size=n) < 0.8
        mask[:q] = True  # one whole block chosen, so both answers occur
        want = [all(mask[j * q : (j + 1) * q]) for j in range(n // q)]
        assert _reduced_mask(mask, q).tolist() == want


def test_at_the_fitting_rate_the_mask_is_the_one_given():
    """q = 1 (a 1 kHz log is not reduced): the samples chosen are the samples fitted."""
    mask = np.array([True, False, True, True, False])
    assert _reduced_mask(mask, 1).tolist() == mask.tolist()


@pytest.mark.parametrize("q", [2, 3])
def test_equation_error_on_a_fast_log_fits_the_means_a_choice_covers_whole(model, q):
    """A log at q kHz is fitted at 1 kHz. Choosing samples [start, stop) at the log's rate, with both ends
    inside a block, fits the blocks lying wholly inside, [ceil(start / q) q, floor(stop / q) q): the same
    number of fitted means, the same C1 to rounding (1e-12: same samples), found to 1e-3 (the 1 um
    position noise through the differentiator). The count is that of the whole blocks inside less the
    differentiator's edge at each end of the log (none of which the choice reaches)."""
    problem = EquationError(fast_log(model, 6.0, rate=1000.0 * q, seed=36), model, estimate=("C1",))
    assert problem.sample_time == pytest.approx(1e-3, rel=1e-12)
    n = problem.logs[0].n
    start, stop = 1000 * q + 1, 5000 * q - 1  # 1 s to 5 s, each end one sample into a block
    mask = np.zeros(n, dtype=bool)
    mask[start:stop] = True
    first, last = -(-start // q), stop // q  # the whole blocks inside: [first, last)
    whole = np.zeros(n, dtype=bool)
    whole[first * q : last * q] = True
    a, b = problem.fit(mask), problem.fit(whole)
    assert a.success and b.success
    edge = problem.prepared.edge
    assert edge < first and last <= n // q - edge  # the choice stays clear of the filters' edges
    assert a.n_samples == b.n_samples == last - first
    assert a.values["C1"] == pytest.approx(b.values["C1"], rel=1e-12)
    assert a.values["C1"] == pytest.approx(model.constants.C1, rel=1e-3)


# --- sampled references -------------------------------------------------------------------------------------
def _reference(gap: float) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(5) / REFERENCE_RATE_HZ
    values = np.zeros((6, t.size))
    values[0] = 0.02
    values[0, 2] = gap
    return t, values


@pytest.mark.parametrize("gap", [0.0, -0.02, 0.1 + 1e-12, 20.0])
def test_a_reference_refuses_gaps_outside_metres_range_and_says_so(gap):
    """A gap set-point must be in (0, 0.1] m; 20.0 is 20 mm written in millimetres, 0 a closed gap. The
    message says metres and gives the range, so the caller knows the unit to write."""
    t, values = _reference(gap)
    with pytest.raises(InputError) as err:
        SampledReference(t, values)
    assert str(err.value) == "SampledReference: gap set-points must be in metres, in (0, 0.1]"


@pytest.mark.parametrize("gap", [1e-6, 0.1])
def test_a_reference_accepts_gaps_in_range(gap):
    """Both ends of (0, 0.1]: the reference keeps the values given."""
    t, values = _reference(gap)
    assert SampledReference(t, values).values[0, 2] == gap


# --- the study's fixed-gap runs ------------------------------------------------------------------------
def test_the_studys_fixed_gap_runs_use_the_effects_it_was_given(model, truth_model):
    """run_study passes its verification effects (the rig's cogging, 000 eq. (9)) to every experiment
    after the excitation fits. The fixed-gap step's parabolas are fitted to the runs simulated with those
    effects: each parabola's position trace is the run's (bit for bit: the same simulation, seeded by the
    study's seed). The effects are not lost: at 10 mm the cogging (1.5 N x (15/10)^3, 5 N) moves the
    mover beyond the 10 um encoder's resolution, so the run differs from one without it."""
    seed = 1
    veff = verification_effects()
    out = study._fixed_gaps(study._Clock(), model, truth_model, veff, seed)
    runs = fixed_gap_logs(truth_model, FIXED_GAPS, effects=veff, seed=seed)
    assert len(out["parabolas"]) == len(runs) == len(FIXED_GAPS)
    for parabola, run, gap in zip(out["parabolas"], runs, FIXED_GAPS, strict=True):
        assert parabola.gap == gap
        np.testing.assert_array_equal(parabola.x3, run.x[2])
    plain = fixed_gap_logs(truth_model, FIXED_GAPS[:1], effects=identification_effects(), seed=seed)[0]
    first = out["parabolas"][0].x3
    assert first.size != plain.n or not np.array_equal(first, plain.x[2])
