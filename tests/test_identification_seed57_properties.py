"""Properties of ``maglev_oc.identification`` from the survivors of the seed-57 mutation run:

* the output-error fit stops at the tolerance it is given (a loose one stops no later than a
  tight one, and the message names the one in force);
* when the papers' excitation beats every designed shape, the design keeps its duration and seed
  beside the shapes' names, and no design's candidate rows carry the grid search's private
  objects (they go to JSON);
* a fit of a method without a title reports the method's own name;
* the eps-trend study's friction is reported under the names its JSON documents.
"""

from __future__ import annotations

import json
import re

import pytest

from maglev_oc.identification.design import design_experiment
from maglev_oc.identification.output_error import MultipleShooting
from tests.test_identification_outputs import make_fit
from tests.test_identification_seed41_properties import DURATION, JOINT, OTHER, _ShapeDesigner


# --- the output-error fit's tolerance -------------------------------------------------------------
def test_the_output_error_fit_stops_at_the_tolerance_it_is_given(model, twin_log):
    """One second of the twin log fitted from the papers' constants at a tolerance of 1e-2 and of
    1e-9 on the scaled step: the loose fit takes no more iterations than the tight one, and a fit
    that converged on its step says so with the tolerance in force (``constrained_gn``'s message:
    "scaled step below {tolerance:g}" or the full step's size, below 1000 x tolerance)."""
    log = twin_log.index_slice(0, 1001)
    loose = MultipleShooting([log], model).fit(tolerance=1e-2, hac_band=7.5)
    tight = MultipleShooting([log], model).fit(tolerance=1e-9, hac_band=7.5)
    assert loose.success and tight.success, (loose.message, tight.message)
    assert loose.iterations <= tight.iterations
    for fit, tolerance in ((loose, 1e-2), (tight, 1e-9)):
        below = re.search(r"scaled step below (\S+),", fit.message)
        full = re.search(r"scaled step ([0-9.e+-]+), continuity", fit.message)
        assert below or full, fit.message
        if below:
            assert float(below.group(1)) == tolerance
        else:
            assert float(full.group(1)) < 1e3 * tolerance
    assert loose.iterations < tight.iterations or "below 0.01" in loose.message


# --- the design when the papers' excitation wins -----------------------------------------------------
class _PapersWin(_ShapeDesigner):
    """The shape designer of the seed-41 tests whose papers' excitation predicts more than every
    shape (log det 50 against at most 9)."""

    def predict(self, reference, *, effect=False, budget=None, run=None):
        return self._prediction(50.0, 1e-5, 1e-5)


@pytest.mark.parametrize("designer", [_PapersWin(1.0), _ShapeDesigner(1.0)], ids=["papers_win", "joint_wins"])
def test_a_design_keeps_its_settings_and_its_rows_are_plain_data(model, designer):
    design = design_experiment("doptimal", DURATION, model=model, designer=designer, grid=(JOINT, OTHER))
    assert design.settings["duration_s"] == DURATION and design.settings["seed"] == 0
    if isinstance(designer, _PapersWin):
        assert design.settings["vertical"] == design.settings["horizontal"] == "papers' sum of sines"
    else:
        assert design.settings["vertical"] == JOINT.to_dict()
    for row in design.candidates:
        assert not [k for k in row if k.startswith("_")], row
    json.dumps(design.to_dict())  # every field is plain data


# --- a report's title -----------------------------------------------------------------------------------
def test_a_fit_of_a_method_without_a_title_reports_the_methods_name():
    assert make_fit(method="output_error").report().startswith("[[Fit: output error")
    assert make_fit(method="my_own_fit").report().startswith("[[Fit: my_own_fit]]")


# --- the eps-trend study's friction --------------------------------------------------------------------
def test_the_eps_trend_study_reports_its_friction_under_the_documented_names(model, monkeypatch):
    """``EpsTrendStudy.friction``: per axis given, {"coulomb_N", "viscous_N_s_per_m"} (the JSON's
    names, read by analyses/identification.py); an axis without friction is left out. The twin
    runs are replaced by the papers' trends (tests/test_identification_seed41_properties.py)."""
    from types import SimpleNamespace

    from maglev_oc.identification import eps_trend
    from maglev_oc.identification.layout import CONSTANT_NAMES
    from maglev_oc.sim.effects import GuideFriction

    p3 = eps_trend._papers("table3", CONSTANT_NAMES)
    p2 = eps_trend._papers("table2", eps_trend.TABLE2_NAMES)
    log = SimpleNamespace(sample_time=1e-3)
    monkeypatch.setattr(eps_trend, "_twin_trend", lambda model, friction, **kw: (p3, p2, log, True))
    monkeypatch.setattr(eps_trend, "_npfsi_trend", lambda *a, **k: (p3, True))
    monkeypatch.setattr(eps_trend, "_limit", lambda *a: p3)
    friction = (GuideFriction(coulomb=0.25, viscous=1.5), None)
    study = eps_trend.eps_trend_study(model, friction=friction)
    assert study.friction == {"horizontal": {"coulomb_N": 0.25, "viscous_N_s_per_m": 1.5}}
    assert json.loads(json.dumps(study.to_dict()))["friction"] == study.friction


# --- the Gauss-Newton step where the Hessian is singular -------------------------------------------------
@pytest.mark.parametrize("scale", [0.5, 40.0])
def test_a_singular_hessian_is_damped_by_a_millionth_of_its_scale(scale):
    """``constrained_gn._factor``'s docstring: a singular H is damped by 1e-6 max(max diag H, 1).
    H = diag(scale, 0) without constraints: the undetermined second
    direction steps by g / damp, the first by g / (scale + damp); round-off only (1e-12)."""
    import numpy as np
    import scipy.sparse as sp

    from maglev_oc.identification.constrained_gn import _factor

    H = sp.csc_matrix(np.diag([scale, 0.0]))
    Jc = sp.csc_matrix((0, 2))
    damp = 1e-6 * max(scale, 1.0)
    step = _factor(H, Jc).solve(np.array([1.0, 1.0]))
    np.testing.assert_allclose(step, [1.0 / (scale + damp), 1.0 / damp], rtol=1e-12)


def test_the_designer_keeps_the_feasible_set_it_is_given(model):
    """Seed 58: ``ExperimentDesigner(feasible=...)`` designs inside the set it is given (a user's
    stoppers or current limit), not the default one."""
    from maglev_oc.identification.design import ExperimentDesigner
    from maglev_oc.region.feasibility import FeasibleSet

    limited = FeasibleSet(model, current_limit=4.0)
    assert ExperimentDesigner(model, feasible=limited).feasible is limited
    assert ExperimentDesigner(model).feasible is not limited
