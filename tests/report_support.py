"""Studies and reports that several test files check, computed once per session.

The fixtures are registered in ``tests/conftest.py``, which also runs the files that use one of
them on the same pytest-xdist worker (``SHARED_BY_FILES``), so each is computed once per run.
"""

from __future__ import annotations

import pytest

__all__ = ["shared_controllers_report", "shared_eps_trend", "shared_model_report", "shared_region_report"]


@pytest.fixture(scope="session")
def shared_model_report(tmp_path_factory, model):
    """reports/model.pdf on the papers' stage: (study, contents)."""
    from maglev_oc.analyses import model as analysis

    study = analysis.model_study(model)
    return study, analysis.write_report(tmp_path_factory.mktemp("model") / "model.pdf", study)


@pytest.fixture(scope="session")
def shared_region_report(tmp_path_factory, model):
    """The operating-region study in the report's QUICK configuration (about a minute) and its
    report: (study, contents)."""
    from maglev_oc.analyses import operating_region as analysis

    from maglev_oc.region.study import operating_region_study

    study = operating_region_study(model, analysis.QUICK)
    path = tmp_path_factory.mktemp("region") / "operating_region.pdf"
    return study, analysis.write_report(path, study, model)


@pytest.fixture(scope="session")
def shared_eps_trend(model):
    """The eps-trend study with its defaults: the identification study's runs, with and without
    the rig twin's guide friction (about 12 s on one core)."""
    from maglev_oc.identification.eps_trend import eps_trend_study

    return eps_trend_study(model)


@pytest.fixture(scope="session")
def shared_controllers_report(tmp_path_factory, model):
    """reports/controllers.pdf as ``maglev-oc report`` writes it: the comparison with the NMPC and the
    twin calibrated to 002's step experiments (about a minute): (calibration, study, contents).
    tests/test_calibration.py checks the calibration and the report's calibrated-twin rows,
    tests/test_controllers_report.py the scorecard and tables (the report a user gets, not a
    quicker variant of it)."""
    from maglev_oc.analyses import controllers as analysis

    from maglev_oc.sim.calibration import calibrate_to_paper

    calibration = calibrate_to_paper(model)
    study = analysis.compare_controllers(model, calibration=calibration)
    path = tmp_path_factory.mktemp("controllers") / "controllers.pdf"
    return calibration, study, analysis.write_report(path, study)
