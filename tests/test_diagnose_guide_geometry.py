"""The guides' shape reported as one effect: a misalignment and a waviness found together
(``maglev_oc.diagnosis.pipeline._merged_guide_geometry``)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from maglev_oc.diagnosis.pipeline import _merged_guide_geometry
from maglev_oc.diagnosis.result import Effect
from maglev_oc.results import Estimate, PerAxis


def _effect(name: str, contribution: tuple[float, float], **parameters: float) -> Effect:
    return Effect(
        name=name,
        explanation=f"{name} explained.",
        finding=f"{name} found.",
        axis="both",
        parameters={k: Estimate(v, 0.1 * abs(v), "m") for k, v in parameters.items()},
        confidence=1.0,
        gain=0.1,
        z=5.0,
        contribution_rms=PerAxis(*contribution),
        force_rms=PerAxis(*contribution),
        runner_up="",
        signature="",
        coefficients=np.full(1, float(len(name))),
        candidate=None,
    )


rms = st.floats(0.0, 0.05)


@settings(max_examples=40, deadline=None)
@given(slope=st.tuples(rms, rms), wave=st.tuples(rms, rms), amplitude=st.floats(1e-6, 1e-4))
def test_a_misalignment_and_a_waviness_become_one_effect(slope, wave, amplitude):
    friction = _effect("guide_friction_horizontal", (0.0, 0.01), coulomb=0.3)
    misalignment = _effect("guide_misalignment", slope, slope=3e-3)
    waviness = _effect("guide_waviness_60mm", wave, amplitude=amplitude, period=0.06)
    merged = _merged_guide_geometry([friction, misalignment, waviness])
    assert [e.name for e in merged] == ["guide_friction_horizontal", "guide_misalignment"]
    assert merged[0] is friction
    m = merged[1]
    assert m.parameters["slope"] == misalignment.parameters["slope"]
    assert m.parameters["waviness_amplitude"] == waviness.parameters["amplitude"]
    assert m.parameters["waviness_period"] == waviness.parameters["period"]
    assert m.finding == "guide_misalignment found. guide_waviness_60mm found."
    # the two shapes are independent columns: their held-out RMS adds in quadrature (to rounding:
    # numpy's and math's hypot may differ in the last bit)
    for a in range(2):
        assert m.contribution_rms[a] == pytest.approx(math.hypot(slope[a], wave[a]), rel=1e-12, abs=1e-300)
    assert misalignment.parameters == {"slope": misalignment.parameters["slope"]}  # the input is left alone
    # the waviness's term stays in the model the output error, the validation, the compensation and
    # the stage file are built from (Effect.terms)
    assert [c for _, c in m.terms()] == [misalignment.coefficients, waviness.coefficients]


def test_either_alone_is_reported_as_found():
    misalignment = _effect("guide_misalignment", (0.0, 0.004), slope=3e-3)
    waviness = _effect("guide_waviness_60mm", (0.0, 0.003), amplitude=8e-6, period=0.06)
    assert _merged_guide_geometry([misalignment]) == [misalignment]
    assert _merged_guide_geometry([waviness]) == [waviness]
    assert _merged_guide_geometry([]) == []
