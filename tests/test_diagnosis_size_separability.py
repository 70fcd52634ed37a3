"""Separability judged on an effect's size when that size is a coefficient over a constant.

A commutation offset d makes i_d push along the track: a thrust C1 l1 d i_d, fitted as a coefficient
q = C1 d on the column l1 i_d. The loop cancels that steady thrust with a steady i_q, so the larger
the offset, the more of C1's column l1 i_q is -d times the offset's own column: the coefficient
and C1 are collinear (a variance inflation of 110-112 on drawn logs of the independent generator
with 3.1-3.4 degree offsets, above ``max_vif``), while their ratio, the angle, is not (1.0-1.2).
:func:`maglev_oc.diagnosis.selection._at_fixed_size` judges the effect with its size as the
parameter: each constant's column carries the coefficient's along, X_C + (q / C) X_q. The checks:
the variance inflation so judged is the delta method's for q / C from the original normal matrix
(an independent computation); the closed form of the loop's collinearity; nothing changes for an
effect without ``size_relative_to``; and the drawn logs that were refused are claimed and sized,
with nothing false, on the generator's default rig and on the rig as noisy as the shared log.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from maglev_oc.diagnosis.selection import SelectionSettings, _at_fixed_size, _inflation
from tests.test_diagnose_effects import _drawn_pair
from tests.test_diagnosis_confounded_rivals import NOISY

MAX_VIF = SelectionSettings().max_vif


def _fit(coef, names=("C1", "C3", "q")):
    """The parts of a SubsetFit that the reparametrization reads: columns 0..p-1 of the design."""
    coef = np.asarray(coef, dtype=float)
    return SimpleNamespace(index=np.arange(coef.size), names=tuple(names), coef=coef)


def _delta_method_inflation(g: np.ndarray, q: int, c: int, coef: np.ndarray) -> float:
    """var(q / C) from the whole inverse normal matrix (delta method, gradient (1 / C, -q / C^2))
    over var(q / C) with every other parameter known ((1 / C)^2 / g_qq)."""
    grad = np.zeros(g.shape[0])
    grad[q], grad[c] = 1.0 / coef[c], -coef[q] / coef[c] ** 2
    return float(grad @ np.linalg.solve(g, grad) / (grad[q] ** 2 / g[q, q]))


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    ratio=st.floats(-0.2, 0.2).filter(lambda r: abs(r) > 1e-3),
    tie=st.floats(0.0, 0.99),
)
def test_the_inflation_at_a_fixed_size_is_the_delta_methods(seed, ratio, tie):
    # three columns (C1, C3, the effect's q); C1's made partly of q's own column, as the loop makes
    # it; q / C1 judged by the reparametrized normal matrix's canonical correlation and by the delta
    # method on the original: the same number (both exact for a ratio at the fitted point; 1e-6
    # relative is rounding in a 3 x 3 solve at inflations up to ~1e4)
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((400, 3))
    x[:, 0] = (1 - tie) * x[:, 0] + tie * x[:, 2]
    g = x.T @ x
    coef = np.array([14.0, 31.0, 14.0 * ratio])
    g_fixed = _at_fixed_size(g, _fit(coef), [(2, "C1")], np.ones(3, dtype=bool))
    own = np.array([False, False, True])
    assert _inflation(g_fixed, own, ~own) == pytest.approx(_delta_method_inflation(g, 2, 0, coef), rel=1e-6)


def test_the_loops_cancelling_current_inflates_the_coefficient_not_the_angle():
    # C1's column a - d b (a: the part that accelerates the stage, b: the offset's own column, a
    # and b orthogonal), the data y = C1 (a - d b) + C1 d b. The coefficient's variance inflation
    # is 1 + d^2 |b|^2 / |a|^2 (closed form for two columns); the angle's, judged at a fixed
    # angle, is 1: C1's column then is a itself
    rng = np.random.default_rng(5)
    a, b = rng.standard_normal((2, 2000))
    b -= (a @ b) / (a @ a) * a
    a *= 0.004  # the stage's accelerations are small beside the cancelled thrust (inflation 226)
    d, c1 = 0.06, 14.0
    x = np.column_stack([a - d * b, b])
    g = x.T @ x
    own = np.array([False, True])
    closed_form = 1 + d**2 * (b @ b) / (a @ a)
    assert _inflation(g, own, ~own) == pytest.approx(closed_form, rel=1e-9)
    assert closed_form > MAX_VIF  # refused coefficient by coefficient
    fit = _fit([c1, c1 * d], names=("C1", "q"))
    g_fixed = _at_fixed_size(g, fit, [(1, "C1")], np.ones(2, dtype=bool))
    assert _inflation(g_fixed, own, ~own) == pytest.approx(1.0, abs=1e-9)


def test_an_effect_whose_sizes_are_its_coefficients_is_judged_as_fitted():
    # no pairs, a constant the fit does not have, one it holds at 0 or did not estimate, or a
    # coefficient it did not estimate: the Gram is returned as it is
    rng = np.random.default_rng(6)
    x = rng.standard_normal((100, 3))
    g = x.T @ x
    coef = np.array([14.0, 31.0, 0.5])
    live = np.ones(3, dtype=bool)
    assert _at_fixed_size(g, _fit(coef), [], live) is g
    for fit, pairs, estimated in (
        (_fit(coef), [(2, "C2")], live),
        (_fit([0.0, 31.0, 0.5]), [(2, "C1")], live),
        (_fit(coef), [(2, "C1")], np.array([False, True, True])),
        (_fit(coef), [(2, "C1")], np.array([True, True, False])),
        (_fit(coef), [(7, "C1")], live),
    ):
        np.testing.assert_array_equal(_at_fixed_size(g, fit, pairs, estimated), g)


@pytest.mark.slow
def test_a_large_commutation_offset_alone_is_claimed_and_sized(tmp_path):
    # bench/diagnose_rigs.py --drawn 2, commutation_offset_1501 (the generator's default rig): a
    # 3.4 degree offset was "not separable", coefficient variance inflation 112 against C1. Judged
    # at a fixed angle it is claimed alone, within 30 % of the truth (the bound; measured
    # 0.1 %)
    import json

    from tests.diagnosis_support import diagnose_path
    from tests.independent import write_log
    from tests.independent.draws import draw
    from tests.independent.scoring import score
    from tests.independent.simulate import Scenario, simulate

    effect = draw("commutation_offset", np.random.default_rng(1501))
    assert effect.angle == pytest.approx(0.0588, abs=1e-4)  # the bench's log
    path, truth = write_log(
        simulate(Scenario(name="commutation_offset", seed=1501, effects=(effect,))), tmp_path, stem="drawn"
    )
    d = diagnose_path(path)
    s = score("drawn", json.loads(truth.read_text()), d.to_dict()["effects"])
    assert [e.name for e in d.effects] == ["commutation_offset"]
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes, s.sizes)
    assert not d.not_separable


@pytest.mark.slow
def test_a_commutation_offset_on_the_noisy_rig_is_not_taken_by_a_misalignment(tmp_path):
    # random pair 9128 on the noisy rig (bench/diagnose_rigs.py --drawn-pairs 30 --seed 9100 --rig
    # obs2800): a 3.1 degree offset and end effects at one end. The offset was "not separable"
    # (variance inflation 110) and a guide misalignment, whose steady horizontal force stood in for
    # the offset's, was claimed: a false claim. Both true effects are now found, sized within 30 %
    # (the bound; measured 3 % and 7 %), and nothing else
    effects, d, s = _drawn_pair(tmp_path, 9128, ("end_effect", "commutation_offset"), NOISY)
    assert effects[1].angle == pytest.approx(0.0546, abs=1e-4)  # the bench's log
    assert sorted(e.name for e in d.effects) == ["commutation_offset", "end_effects"]
    assert s.true_first and s.no_false_claim and s.size_right, (s.claimed, s.notes, s.sizes)
