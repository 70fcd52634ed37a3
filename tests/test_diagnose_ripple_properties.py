"""``diagnose`` end to end on a log with a planted thrust ripple whose answer is exact
(``tests/test_statistics_properties._log``: the horizontal sweep at a held gap, the current the
plant needs computed from its acceleration): the plant's thrust per ampere is
-L1 (1 + A sin(2 pi x3 / slot pitch + phi)), and its C1 is 8 % above the model's, so the ripple's
size as a fraction of the thrust is only right when the fitted C1 (not the model's starting one)
is the reference. About 1 s of CPU per diagnosis (30 s log, one axis)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from maglev_oc.diagnosis.pipeline import diagnose
from tests.diagnosis_support import check_confidence
from tests.test_regression import _synthetic
from tests.test_statistics_properties import _log

C1_FACTOR = 1.08


@pytest.fixture(scope="module", params=[(0.03, 0.5), (0.02, -2.0)], ids=["3pct", "2pct"])
def rippled(request, model):
    amplitude, phase = request.param
    truth = model.with_constants(model.constants.replace(C1=model.constants.C1 * C1_FACTOR))
    x3 = _synthetic(truth, seconds=30.0, seed=3).x[2]  # the true positions (_log's, without noise)
    log = _log(truth, friction=0.0)
    u = log.u.copy()
    u[0] = u[0] / (1 + amplitude * np.sin(2 * math.pi * x3 / model.params.slot_pitch + phase))
    return amplitude, phase, truth, diagnose([dataclasses.replace(log, u=u)], model)


def test_a_planted_thrust_ripple_is_the_one_effect_with_its_size_and_phase(rippled, model):
    """Amplitude (a fraction of the thrust) within 3 standard errors and 3 % of the planted one,
    phase within 3 standard errors (measured: 0.03004 +- 0.0003 and 0.4995 +- 0.0011 rad; the
    fit's 10 Hz band and the sweep's noise are all that separate them), at the slot pitch; the
    pole-pitch harmonic, not planted, within 3 standard errors of zero; and the fitted C1 the
    plant's, to 0.5 % (measured 0.02 %)."""
    amplitude, phase, truth, d = rippled
    assert [e.name for e in d.effects] == ["thrust_ripple"]
    p = d.effects[0].parameters
    a, ph = p["amplitude"], p["phase"]
    assert abs(a.value - amplitude) < 3 * a.stderr and a.value == pytest.approx(amplitude, rel=0.03)
    wrapped = (ph.value - phase + math.pi) % (2 * math.pi) - math.pi
    assert abs(wrapped) < 3 * ph.stderr, (ph, phase)
    assert p["period"].value == model.params.slot_pitch
    assert abs(p["amplitude_pole_pitch"].value) < 3 * p["amplitude_pole_pitch"].stderr
    assert d.constants_final["C1"].value == pytest.approx(truth.constants.C1, rel=5e-3)


def test_every_reported_size_is_the_candidates_function_of_the_final_fit(rippled):
    """What the JSON reports can be recomputed from it: each effect's physical parameters are its
    candidate's function of the reported coefficients with the final fit's constants (the
    candidates' references are the base fit's, which the ripple biased by 0.2 % here), to rounding
    (1e-12); the standard errors only grow from there (the model-form spread is added in
    quadrature)."""
    *_, d = rippled
    constants = {k: e.value for k, e in d.constants_final.items() if math.isfinite(e.value)}
    assert constants["C1"] != d.constants_base["C1"].value
    for e in d.effects:
        k = e.coefficients.size
        own = e.candidate.term.physical_parameters(e.coefficients, np.zeros((k, k)), constants)
        assert own, e.name
        for name, est in own.items():
            assert e.parameters[name].value == pytest.approx(est.value, rel=1e-12, abs=1e-300), (e.name, name)
            assert e.parameters[name].stderr >= est.stderr


def test_a_planted_ripples_confidence_is_a_share(rippled):
    check_confidence(rippled[-1])
