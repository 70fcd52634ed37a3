"""The axes' weights after the first selection (``diagnosis.pipeline._rebalanced``): the base fit's
1 / RMS residual per axis until then, the fit with the chosen effects' when those change the two
axes' balance by more than ``REBALANCE_FACTOR``. Stand-ins for the session, the design and the
selection; the residuals are handed in, so each rule is checked on numbers chosen for it. Under a
second of CPU."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.diagnosis import pipeline
from maglev_oc.diagnosis.pipeline import REBALANCE_FACTOR, _rebalanced

N = 400


def _case(monkeypatch, rms, base_weights=(1.0, 1.0), moving=(True, True), outside=0.0):
    """A session with ``base_weights`` and a selection whose residual on the fitted samples (the
    first three quarters) has RMS ``rms`` per axis; ``outside`` on the samples not fitted."""
    fit = np.arange(N) < 3 * N // 4
    signs = np.where(np.arange(N) % 2 == 0, 1.0, -1.0)  # RMS of +-a is a
    r = np.vstack([rms[0] * signs, rms[1] * signs])
    r[:, ~fit] = outside
    monkeypatch.setattr(pipeline, "residuals", lambda design, fit_: r)
    session = SimpleNamespace(
        data=SimpleNamespace(moving=np.array(moving)), weights=np.array(base_weights, dtype=float)
    )
    design = SimpleNamespace(fit=fit)
    return _rebalanced(session, design, SimpleNamespace(final=None))


def test_an_unchanged_balance_keeps_the_base_weights(monkeypatch):
    # the effects lowered both axes' residuals tenfold: the ratio, all that weighs a shared
    # parameter, is the same
    assert _case(monkeypatch, (0.01, 0.002), base_weights=(10.0, 50.0)) is None


def test_an_effect_that_explains_one_axis_gives_the_fit_with_it_its_weights(monkeypatch):
    # a large cogging force: the base vertical residual 0.14, 0.02 with the cogging; the
    # horizontal one 0.018 either way. The weights become 1 / the new RMS, exactly.
    w = _case(monkeypatch, (0.02, 0.018), base_weights=(1 / 0.14, 1 / 0.018))
    np.testing.assert_allclose(w, [1 / 0.02, 1 / 0.018], rtol=1e-12)
    # and the other way round: an effect on the horizontal axis
    w = _case(monkeypatch, (0.018, 0.02), base_weights=(1 / 0.018, 1 / 0.14))
    np.testing.assert_allclose(w, [1 / 0.018, 1 / 0.02], rtol=1e-12)


@pytest.mark.parametrize("direction", [1.0, -1.0])
def test_the_rule_turns_at_the_factor_either_way(monkeypatch, direction):
    # the ratio of the weights moved by just under REBALANCE_FACTOR (1e-9 relative, above the
    # rounding of 1 / (1 / f)): kept; by 1 % more: rebalanced
    for factor, kept in ((REBALANCE_FACTOR * (1 - 1e-9), True), (REBALANCE_FACTOR * 1.01, False)):
        f = factor**direction
        got = _case(monkeypatch, (1.0 / f, 1.0), base_weights=(1.0, 1.0))
        assert (got is None) == kept, (factor, direction)


def test_only_the_fitted_samples_count(monkeypatch):
    # the held-out block's residual (here huge) must not set the weights the selection uses
    a = _case(monkeypatch, (0.02, 0.018), base_weights=(1 / 0.14, 1 / 0.018))
    b = _case(monkeypatch, (0.02, 0.018), base_weights=(1 / 0.14, 1 / 0.018), outside=5.0)
    np.testing.assert_array_equal(a, b)


def test_one_moving_axis_is_never_rebalanced(monkeypatch):
    # a single axis's weight only scales its own fit
    assert _case(monkeypatch, (0.02, 0.018), base_weights=(1 / 0.14, 0.0), moving=(True, False)) is None
    assert _case(monkeypatch, (0.02, 0.018), base_weights=(0.0, 1 / 0.14), moving=(False, True)) is None
