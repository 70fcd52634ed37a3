"""Shared fixtures: the nominal model is built once per session."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

# One BLAS thread per process, set before NumPy loads here and in the xdist workers this process
# starts (they inherit the environment): pytest-xdist already runs one worker per core, and
# OpenBLAS's own threads then spin against the other worker (measured on 2 cores: a diagnosis
# 2.2x slower with 2 BLAS threads than with 1; a 200-column block Gram 13x). A count the user set
# is kept.
if not any(os.environ.get(k) for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")):
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
# NumPy's huge-page advice off in every process, the same way (NumPy reads the variable when it
# loads): this machine's kernel compacts memory on a fault in an advised region and grants no huge
# page, so processes that allocate many large arrays wait (maglev_oc.numerics.without_hugepage_advice,
# which the diagnosis applies itself: 12 % of its time). Measured 2026-12-01 on the microstepper's
# region and the NMPC tests, one process: 118 s with the advice, 106 s without. A setting the user
# chose is kept.
os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")
# glibc's generic exp, sin, cos, atan and log1p in the xdist workers, the same way (glibc reads the
# variable when a process starts): on a CPU with FMA and AVX2 it picks variants that differ from the
# generic ones in the last bit now and then, and the independent generator's C core calls them on
# every step. A loop whose guides stick and slip amplifies that: experiments_37 (soft gains, 2 N of
# vertical friction) generated with the FMA variants sticks where the generic one slips, and its
# friction was no longer found, and a detection limit moved by 1 %; the tests were calibrated on
# machines that used the generic ones. With the mask every x86-64 machine generates the same logs
# (measured 2026-12-02 on an FMA machine: experiments_37's log changes with the mask, and both
# tests pass again). A run in one process (-n 0) starts before this line, so the pytest command
# is started again under the mask (with_generic_libm) unless the variable is set: its logs were
# otherwise those of the FMA variants, not the workers' or the benches' (2026-12-05: pair 32004 of
# bench/diagnose_rigs.py regenerated without the mask differed from line 693 on, with it
# bit-identical).
from tests.independent.core import GENERIC_LIBM, with_generic_libm

os.environ.setdefault("GLIBC_TUNABLES", GENERIC_LIBM)

import matplotlib
import pytest
from xdist.scheduler import LoadFileScheduling

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


# fixtures several property-test files share (module scope: built once in each file that uses one)
from tests._diagnosis_cases import cogged, data, horizontal_all, two_effects, two_periodic  # noqa: E402, F401
from tests._identification_cases import two_logs  # noqa: E402, F401
from tests._region_cases import loop  # noqa: E402, F401
from tests._regression_cases import friction_data  # noqa: E402, F401

# C objects and the NMPC's libraries compiled once per run, shared by the workers
from tests.compile_support import object_cache, shared_compile_cache  # noqa: E402, F401

# the independent generator's logs and their diagnoses, shared by the diagnosis test files
from tests.diagnosis_support import diagnosed, generated  # noqa: E402, F401

# studies and reports checked by several test files
from tests.report_support import (  # noqa: E402, F401
    shared_controllers_report,
    shared_eps_trend,
    shared_model_report,
    shared_region_report,
)

# --- where and in which order the tests run (pytest-xdist) ------------------------------------------------
DURATIONS = Path(__file__).with_name("durations.json")
"""Measured seconds (CPU of setup + call + teardown) of the longer tests: the order in which work is
handed out."""
SHARED_BY_FILES = {
    "shared_eps_trend": ("tests/test_eps_trend.py", "tests/test_reports_identification_layout.py"),
    "shared_region_report": ("tests/test_region_study.py", "tests/test_reports_model_region_layout.py"),
    "shared_model_report": ("tests/test_reports.py", "tests/test_reports_model_region_layout.py"),
    "diagnosed": ("tests/test_diagnose.py", "tests/test_diagnose_clean_seeds.py"),
    "shared_controllers_report": ("tests/test_calibration.py", "tests/test_controllers_report.py"),
}
"""The files that use each session fixture shared between files: they run on one worker, so the
fixture is computed once per run (the other session fixtures are cheap, or cached per key and
computed on each worker that needs them)."""


def _file_groups() -> dict[str, str]:
    """Test file -> its unit of work: the files of :data:`SHARED_BY_FILES` joined (transitively),
    every other file alone."""
    group: dict[str, str] = {}
    for files in SHARED_BY_FILES.values():
        joined = {group.get(f, f) for f in files}
        name = min(joined)
        for f, g in list(group.items()):
            if g in joined:
                group[f] = name
        for f in files:
            group[f] = name
    return group


FILE_GROUPS = _file_groups()


class SharedFileScheduling(LoadFileScheduling):
    """pytest-xdist's ``--dist loadfile`` with the files of :data:`FILE_GROUPS` as one unit.

    (``--dist loadgroup`` would take ``xdist_group`` marks, but pytest-xdist 3.8 puts the group
    into a node id that pytest 9 no longer reads: every test would be a unit of its own, and the
    module fixtures would be computed on both workers.)"""

    def _split_scope(self, nodeid: str) -> str:
        file = super()._split_scope(nodeid)
        return FILE_GROUPS.get(file, file)


def pytest_xdist_make_scheduler(config, log):
    if config.getvalue("dist") == "loadfile":
        return SharedFileScheduling(config, log)
    return None


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """The units of work (a file, or the files of :data:`FILE_GROUPS`) longest first, from
    :data:`DURATIONS`; with ``--no-loadscope-reorder`` pytest-xdist hands them out in this order as
    workers run dry, so the long units start at once and the many short files fill in at the end
    instead of one long unit running alone at the end of the suite. The order never changes what
    a test checks. A test file that uses a shared fixture without being listed is an error (it
    would compute the fixture again on another worker)."""
    for item in items:
        file = item.nodeid.split("::", 1)[0]
        defs = item._fixtureinfo.name2fixturedefs if hasattr(item, "_fixtureinfo") else {}
        for name, files in SHARED_BY_FILES.items():
            shared = name in defs and defs[name][-1].scope == "session"  # not a file's own of that name
            if shared and file not in files:
                raise pytest.UsageError(f"{file} uses {name}: add it to SHARED_BY_FILES in tests/conftest.py")
    measured = json.loads(DURATIONS.read_text())["seconds"] if DURATIONS.exists() else {}
    unit = {
        item: FILE_GROUPS.get(item.nodeid.split("::", 1)[0], item.nodeid.split("::", 1)[0]) for item in items
    }
    cost: dict[str, float] = {}
    for item in items:
        cost[unit[item]] = cost.get(unit[item], 0.0) + measured.get(item.nodeid, 0.1)
    order = {item: k for k, item in enumerate(items)}
    items.sort(key=lambda item: (-cost[unit[item]], unit[item], order[item]))


def pytest_configure(config) -> None:
    """A pytest command run without the mask (see above) is started again under it, before any test
    and before xdist starts its workers; the output capture suspended first, or the new process's
    output would go to the capture's files. A worker inherits the mask and is never started again."""
    if "PYTEST_XDIST_WORKER" in os.environ:
        return
    if not any(Path(a).name in ("pytest", "py.test") for a in sys.orig_argv[:3]):
        return  # pytest.main() from another program: its own command is not pytest's to run again
    capture = config.pluginmanager.getplugin("capturemanager")
    if capture is not None:
        capture.suspend_global_capture(in_=True)
    with_generic_libm()  # returns at once when the process started under the mask
    if capture is not None:
        capture.resume_global_capture()
