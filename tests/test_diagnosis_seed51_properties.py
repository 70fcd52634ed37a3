"""Diagnosis properties from the survivors of the seed-51 mutation run, each a property of what a
user reads, not of one line:

* once guide friction is claimed on an axis, the held-out samples slower than ``slow_speed`` stop
  counting as evidence, and a sample at exactly that speed still counts ("slower than");
* a cogging candidate names its direction in words: the vertical ones a normal force, the
  horizontal ones a longitudinal (detent) force, in its explanation and in its finding.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.diagnosis.candidate import LibraryContext
from maglev_oc.diagnosis.magnetics import cogging_candidates
from maglev_oc.diagnosis.selection import SelectionSettings, evidence
from maglev_oc.regression.data import prepare
from maglev_oc.results import Estimate
from tests.test_statistics_properties import _log


@pytest.fixture(scope="module")
def ctx(model):
    return LibraryContext(model, prepare([_log(model, friction=0.0)], bandwidth=10.0))


@pytest.mark.parametrize(("axis", "row"), [("vertical", 0), ("horizontal", 1)])
def test_only_samples_slower_than_the_slow_speed_are_left_out(axis, row):
    """Held-out speeds of 0, 0.9, 1 and 1.1 times ``slow_speed`` (either sign) on the friction's axis:
    the first two are left out, the others count; the other axis counts everywhere."""
    s = SelectionSettings().slow_speed
    v = s * np.array([0.0, 0.9, 1.0, 1.1, -0.9, -1.0, -1.1])
    x = np.zeros((4, v.size))
    x[1 if row == 0 else 3] = v
    x[3 if row == 0 else 1] = 1e-6  # the other axis almost still: not left out, no friction there
    design = SimpleNamespace(prepared=SimpleNamespace(x=x), holdout=np.ones(v.size, bool))
    friction = SimpleNamespace(family="friction", axis=axis)
    counted = evidence(design, [friction], SelectionSettings())
    assert counted[row].tolist() == [False, False, True, True, False, True, True]
    assert counted[1 - row].all()


def test_a_cogging_candidate_names_its_direction(ctx):
    """Each of the library's cogging candidates: 'normal (vertical)' for the vertical axis and
    'longitudinal (detent)' for the horizontal, in the term's explanation and in the sentence of
    its finding."""
    physical = {
        "amplitude": Estimate(1.0, 0.1, "N"),
        "at_gap": Estimate(0.019, 0.0, "m"),
        "amplitude_15mm": Estimate(1.5, 0.15, "N"),
    }
    cands = cogging_candidates(ctx)
    assert {c.term.axis for c in cands} == {"vertical", "horizontal"}
    for c in cands:
        words = "normal (vertical)" if c.term.axis == "vertical" else "longitudinal (detent)"
        other = "longitudinal (detent)" if c.term.axis == "vertical" else "normal (vertical)"
        for text in (c.term.explanation, c.describe(physical)):
            assert words in text and other not in text, (c.name, text)
