"""Shared fixtures: the nominal model is built once per session."""

from __future__ import annotations

import matplotlib
import pytest

matplotlib.use("Agg")

from maglev_oc.data.log import Log
from maglev_oc.identification.experiments import TWIN_TRUTH, excitation_log
from maglev_oc.model.feedback import FeedbackTransformation
from maglev_oc.model.stage import StageModel


@pytest.fixture(scope="session")
def model() -> StageModel:
    """The papers' stage: Table I, Table III constants at eps = 0.01, closed-form field."""
    return StageModel()


@pytest.fixture(scope="session")
def transformation(model: StageModel) -> FeedbackTransformation:
    return FeedbackTransformation(model)


@pytest.fixture(scope="session")
def truth_model(model: StageModel) -> StageModel:
    """The identification twin's plant: the papers' stage with the twin's true constants."""
    return model.with_constants(TWIN_TRUTH)


@pytest.fixture(scope="session")
def twin_log(model: StageModel, truth_model: StageModel) -> Log:
    """6 s of the papers' excitation on the twin (encoder + amplifier; identification needs 5 s),
    controlled with the nominal model."""
    return excitation_log(truth_model, duration=6.0, seed=7, controller_model=model)
