"""Shared fixtures: the nominal model is built once per session."""

from __future__ import annotations

import matplotlib
import pytest

matplotlib.use("Agg")

from maglev_oc.model.feedback import FeedbackTransformation
from maglev_oc.model.stage import StageModel


@pytest.fixture(scope="session")
def model() -> StageModel:
    """The papers' stage: Table I, Table III constants at eps = 0.01, closed-form field."""
    return StageModel()


@pytest.fixture(scope="session")
def transformation(model: StageModel) -> FeedbackTransformation:
    return FeedbackTransformation(model)
