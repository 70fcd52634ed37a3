"""Properties of ``maglev_oc.diagnosis.pipeline`` from the survivors of the seed-57 mutation run:

* a log exactly as long as the shortest a diagnosis takes is diagnosed (the bound is inclusive,
  as its message says: "at least");
* the end effects are reported at the fall-off width the scan chose (``_end_profile``);
* when the chosen effects move the constants by more than ``REFIT_TOLERANCE``, the selection is
  repeated around the converged constants, and the model it keeps is the converged one.

Logs from ``tests/independent`` (the independent generator), diagnosed with the defaults.
"""

from __future__ import annotations

import pytest

from maglev_oc.data.logs import LogError
from maglev_oc.data.reading import read_log
from maglev_oc.diagnosis import pipeline
from maglev_oc.diagnosis.refit import REFIT_TOLERANCE
from tests.diagnosis_support import diagnose_path
from tests.independent.sets import named_set


def _stem(name: str) -> str:
    return next(s for s, sc in named_set("single") if sc.name == name)


def test_a_log_as_long_as_the_shortest_diagnosed_is_accepted(generated):
    path, _ = generated("single", _stem("guide_friction_horizontal_small"))
    log = read_log(path)
    _, train, hold = pipeline._prepare([log], 0.25, 10.0, log.duration)
    assert train.any() and hold.any() and not (train & hold).any()
    with pytest.raises(LogError, match="too short to diagnose: need at least"):
        pipeline._prepare([log], 0.25, 10.0, log.duration * (1 + 1e-9))


def test_the_end_effects_are_reported_at_the_width_the_scan_chose(generated, monkeypatch):
    """The end effects' fall-off width is scanned once they are chosen (or shown); the selection
    then judges them at that width, which the finding reports. The scan's answers are recorded as
    it runs (the real scan), and the reported width and shape must be the last it gave."""
    scans: list = []
    scan = pipeline.best_end_profile

    def recording(*args, **kw):
        scans.append(scan(*args, **kw))
        return scans[-1]

    monkeypatch.setattr(pipeline, "best_end_profile", recording)
    path, _ = generated("single", _stem("end_effect_large"))
    d = diagnose_path(path)
    (end,) = [e for e in d.effects if e.name == "end_effects"]
    assert scans and scans[-1] is not None, scans
    assert end.parameters["width"].value == pytest.approx(scans[-1].width, rel=1e-12)
    assert scans[-1].describe() in end.finding


def test_effects_that_move_the_constants_have_the_selection_repeated_around_them(generated, monkeypatch):
    """``_select``'s docstring: when the chosen effects move the constants by more than
    REFIT_TOLERANCE the references are converged and the selection repeated. On a log whose first
    selection keeps its constants (nothing held, no new weights, no new width: measured, the first
    assertion), the first comparison is made to report a move beyond the tolerance: the model
    ``_select`` returns must then be the converged one, not the one it started from."""
    path, _ = generated("single", _stem("thrust_ripple_large"))
    converged: list = []
    returned: list = []
    refs, select, moved = pipeline.converged_references, pipeline._select, pipeline.moved

    def recording_refs(*args, **kw):
        converged.append(refs(*args, **kw))
        return converged[-1]

    def recording_select(session, fitted, exclude):
        out = select(session, fitted, exclude)
        returned.append((fitted, out[-1]))
        return out

    monkeypatch.setattr(pipeline, "converged_references", recording_refs)
    monkeypatch.setattr(pipeline, "_select", recording_select)
    diagnose_path(path)
    assert len(converged) == 1, "the log's first selection must be kept for this test to mean anything"
    ((start, kept),) = returned
    assert kept is start
    calls = []

    def first_moves(a, b):
        calls.append(1)
        return 10 * REFIT_TOLERANCE if len(calls) == 1 else moved(a, b)

    converged.clear()
    returned.clear()
    monkeypatch.setattr(pipeline, "moved", first_moves)
    diagnose_path(path)
    ((start, kept),) = returned
    assert len(converged) >= 2 and kept is not start
    assert any(kept is c for c in converged)


def test_a_diagnosis_that_found_its_effect_says_so_as_a_boolean(generated):
    """Seed 58: the result's ``success`` (a bool in the JSON contract, SPEC section 3) with its
    status: a log with one large effect is "effects_found" and successful."""
    path, _ = generated("single", _stem("thrust_ripple_large"))
    d = diagnose_path(path)
    assert d.status == "effects_found" and d.success is True
    assert d.to_dict()["success"] is True
