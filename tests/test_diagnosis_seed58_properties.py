"""Properties of ``maglev_oc.diagnosis.pipeline`` from the survivors of the seed-58 mutation run:

* a diagnosis whose base fit could not remove the logged currents' errors (estimated larger than
  their signal) returns, says it is not a success and why, and does not crash;
* when the first selection's effects change the balance of the axes' residuals by more than
  ``REBALANCE_FACTOR``, everything after it (the converged constants included) uses the new
  weights;
* a chosen effect that an unexplained dependence on another variable explains as well is "not
  specific" (a code path no quick log reached: found by coverage, not by a mutant).

Logs from ``tests/independent`` (the independent generator), diagnosed with the defaults.
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

import maglev_oc.regression.data as data_module
from maglev_oc.diagnosis import pipeline
from tests.diagnosis_support import diagnose_path
from tests.independent.sets import named_set


def _stem(name: str) -> str:
    return next(s for s, sc in named_set("single") if sc.name == name)


def test_a_diagnosis_whose_current_errors_cannot_be_removed_says_it_failed(generated, monkeypatch):
    """The logged currents' errors are estimated from their white floor (regression.data); scaled
    1e5x (a standard deviation of 1.7 and 3.4 A on this log, beside currents of a few A) the base
    fit can remove only part of them, so its constants may be biased low: the diagnosis must still
    return, with success False and the reason in its message (pipeline._outcome)."""
    floor = data_module._white_floor
    monkeypatch.setattr(data_module, "_white_floor", lambda u, ts: 1e5 * floor(u, ts))
    path, _ = generated("single", _stem("normal_cogging_large"))
    d = diagnose_path(path)
    assert d.success is False
    assert "errors-in-variables compensation failed" in d.message


def test_a_rebalanced_selection_converges_the_constants_with_the_new_weights(generated, monkeypatch):
    """A large vertical cogging force: the base fit's vertical residual is several times its
    residual with the cogging, so the first selection rebalances the axes (measured: weights 57
    and 55 1/(m/s^2), their ratio changed by more than REBALANCE_FACTOR). The constants are then
    converged with those weights, not the base fit's."""
    rebalanced: list = []
    weights_used: list = []
    rebalance, converge = pipeline._rebalanced, pipeline.converged_references

    def recording_rebalance(*args, **kw):
        rebalanced.append(rebalance(*args, **kw))
        return rebalanced[-1]

    def recording_converge(model, fitted, data, chosen, train, hold, weights, **kw):
        weights_used.append(np.array(weights, dtype=float))
        return converge(model, fitted, data, chosen, train, hold, weights, **kw)

    monkeypatch.setattr(pipeline, "_rebalanced", recording_rebalance)
    monkeypatch.setattr(pipeline, "converged_references", recording_converge)
    path, _ = generated("single", _stem("normal_cogging_large"))
    d = diagnose_path(path)
    assert [e.name for e in d.effects] == ["cogging_vertical_19mm"]
    assert rebalanced and rebalanced[0] is not None, "this log must rebalance for the test to mean anything"
    assert weights_used, "the constants were converged"
    np.testing.assert_array_equal(weights_used[0], rebalanced[0])


def test_an_unexplained_dependence_that_explains_an_effect_as_well_makes_it_not_specific(generated):
    """``_explained_by_unexplained``: a chosen effect no longer stands when an unexplained
    dependence on another variable explains what it explains (its held-out contribution vanishes
    beside it); a dependence on its own variable is its own imperfect shape, not a rival. The
    limiting case: a rival whose columns are the effect's own (the vertical cogging of this log,
    renamed), said to depend on the gap: the cogging becomes "not specific", the reason naming the
    gap; said to depend on the position (the cogging's own variable), nothing changes; and with no
    unexplained dependence there is nothing to judge."""
    captured = {}
    original = pipeline._explained_by_unexplained

    def recording(session, model, chosen, unexplained):
        captured.setdefault("args", (session, model, chosen))
        return original(session, model, chosen, unexplained)

    path, _ = generated("single", _stem("normal_cogging_large"))
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(pipeline, "_explained_by_unexplained", recording)
        diagnose_path(path)
    session, model, chosen = captured["args"]
    (cogging,) = chosen
    assert cogging.name == "cogging_vertical_19mm" and cogging.variable == "position"
    copy = dataclasses.replace(cogging.term, name="rival")
    (stale,) = original(session, model, chosen, [SimpleNamespace(term=copy, depends_on="gap")])
    assert stale.name == cogging.name and stale.verdict == "not specific"
    assert "explained as well by a dependence on the gap" in stale.reason
    assert original(session, model, chosen, [SimpleNamespace(term=copy, depends_on="position")]) == []
    assert original(session, model, chosen, []) == []
