"""Shared fixtures: the nominal model is built once per session."""

from __future__ import annotations

import os

# One BLAS thread per process, set before NumPy loads here and in the xdist workers this process
# starts (they inherit the environment): pytest-xdist already runs one worker per core, and
# OpenBLAS's own threads then spin against the other worker (measured on 2 cores: a diagnosis
# 2.2x slower with 2 BLAS threads than with 1; a 200-column block Gram 13x). A count the user set
# is kept.
if not any(os.environ.get(k) for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")):
    os.environ["OPENBLAS_NUM_THREADS"] = "1"

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


# the independent generator's logs and their diagnoses, shared by the diagnosis test files
from tests.diagnosis_support import diagnosed, generated  # noqa: E402, F401


def pytest_collection_modifyitems(config, items):
    """Files with slow tests first (stable otherwise): pytest-xdist's ``--dist loadfile`` hands
    files to the workers in collection order, so the long files start first and the many short
    ones fill in at the end instead of one long file running alone at the end of the suite."""
    heavy = {item.path for item in items if item.get_closest_marker("slow")}
    items.sort(key=lambda item: item.path not in heavy)
