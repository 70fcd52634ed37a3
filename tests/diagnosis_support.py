"""Logs of the independent generator and their diagnoses, shared by the diagnosis tests.

The fixtures are registered in ``tests/conftest.py``; the test files are split (clean seeds, the
effects, the rest) so that pytest-xdist, which keeps a file on one worker, spreads them over the
cores.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace
from unittest import mock

import numpy as np
import pytest

from maglev_oc.data.logs import read_log
from maglev_oc.diagnosis.pipeline import diagnose
from maglev_oc.diagnosis.result import Diagnosis
from maglev_oc.diagnosis.selection import Ranked
from maglev_oc.regression import design as regression_design
from maglev_oc.results import Estimate, PerAxis
from tests.independent import write_log
from tests.independent.sets import named_set
from tests.independent.simulate import simulate

__all__ = ["check_confidence", "diagnose_path", "diagnosed", "generated", "relative_errors", "stub_diagnosis"]


@pytest.fixture(scope="session")
def generated(tmp_path_factory):
    """Logs of the independent generator by (set, stem), written once per session: (csv, truth)."""
    root = tmp_path_factory.mktemp("independent")
    cache: dict[tuple[str, str], tuple[Path, dict]] = {}

    def get(set_name: str, stem: str) -> tuple[Path, dict]:
        key = (set_name, stem)
        if key not in cache:
            scenario = dict(named_set(set_name))[stem]
            csv, truth_path = write_log(simulate(scenario), root / set_name, stem=stem)
            truth = json.loads(truth_path.read_text())
            # the generator's own sanity, on every log a test here diagnoses: its loop never had
            # to clip (R >= 0 throughout, currents inside the amplifiers' range)
            assert truth["run"]["samples_with_R_clipped"] == 0, stem
            assert truth["run"]["samples_with_current_clipped"] == 0, stem
            cache[key] = (csv, truth)
        return cache[key]

    return get


EVERY_STEP = {("clean", "clean_01")}
"""The logs :func:`diagnosed` runs through every step, detection limits included (a test counts
the designs of every step, tests/test_diagnose.py)."""


@pytest.fixture(scope="session")
def diagnosed(generated):
    """The default diagnosis of a generated log by (set, stem), run once per session (the quick
    clean tests and the twenty-seed test share theirs): (diagnosis, truth). The detection limits are
    worked out for the logs of :data:`EVERY_STEP` alone.

    ``get.weightings[(set, stem)]``: how many designs of that diagnosis chose their own axis
    weights (``regression.design._axis_weights``) instead of being handed the base fit's."""
    cache: dict[tuple[str, str], tuple] = {}

    def get(set_name: str, stem: str):
        key = (set_name, stem)
        if key not in cache:
            path, truth = generated(set_name, stem)
            calls = []
            own = regression_design._axis_weights

            def counted(*args, **kw):
                calls.append(1)
                return own(*args, **kw)

            with mock.patch.object(regression_design, "_axis_weights", counted):
                cache[key] = (diagnose_path(path, limits=key in EVERY_STEP), truth)
            get.weightings[key] = len(calls)
        return cache[key]

    get.weightings = {}
    return get


def diagnose_path(path: Path, *, limits: bool = False, **kw):
    """The diagnosis of the log at ``path``; its detection limits (a fifth to a third of its time)
    only if asked for. Most tests check what is claimed, which the limits, worked out last, never
    change (``diagnose(limits=...)``); the tests that read the limits ask for them."""
    return diagnose([read_log(path)], limits=limits, **kw)


def relative_errors(d, truth: dict) -> dict[str, float]:
    true = truth["plant"]["constants_true"]
    return {k: d.constants_final[k].value / true[k] - 1 for k in true}


def stub_diagnosis(
    success: bool = True,
    status: str = "nothing_found",
    message: str = "no missing effect found",
    *,
    sources: tuple[str, ...] = ("a.csv",),
    ranking: list = (),
    validation_before=None,
    validation_after=None,
) -> Diagnosis:
    """A Diagnosis with known fields and no computation behind it, for tests of what it writes: C1
    14.7 +- 0.1 before and after, held-out errors (0.5, 0.25) -> (0.4, 0.2) m/s^2, two fitted samples
    and one held out, settings {"holdout_fraction": 0.25}, timings {"total": 1.5}."""
    nan = PerAxis(math.nan, math.nan)
    est = {"C1": Estimate(14.7, 0.1, "N/A^2")}
    selection = SimpleNamespace(ranking=[Ranked(*r) for r in ranking], steps=[], last={})
    return Diagnosis(
        success,
        status,
        message,
        sources,
        est,
        est,
        [],
        [],
        [],
        [],
        PerAxis(0.5, 0.25),
        PerAxis(0.4, 0.2),
        nan,
        nan,
        selection,
        None,
        np.zeros((2, 3)),
        np.zeros((2, 3)),
        None,
        np.array([True, True, False]),
        np.array([False, False, True]),
        {"holdout_fraction": 0.25},
        {"total": 1.5},
        validation_before=validation_before,
        validation_after=validation_after,
    )


def check_confidence(d) -> None:
    """The confidence of each choice is the share of bootstrap resamples in which it ranks first among
    the candidates that pass at its step: with none beside it 1 (not 0: no resample is drawn), and
    a share whatever the contest."""
    assert d.effects
    found = {e.name: e for e in d.effects}  # a choice dropped by the backward pass has no effect
    for step in d.selection.steps:
        passing = [n for n, j in step.judgements.items() if j.verdict in ("passes", "accepted")]
        assert 0.0 < step.confidence <= 1.0
        if step.chosen in found:
            assert found[step.chosen].confidence == step.confidence
        if passing == [step.chosen]:
            assert step.confidence == 1.0
    assert d.to_dict()["effects"][0]["confidence"] == pytest.approx(d.effects[0].confidence)
