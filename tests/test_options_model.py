"""Options of ``maglev_oc.model`` passed by name, each test failing when its option is ignored (the
default used instead) or inverted:

- ``gap_for_current(bracket)``: Brent's method searches only the bracket given;
- ``fit_field_polynomial(degree)``: a degree-d fit has d + 1 coefficients, its reported maximum
  error is the one measured against the closed-form field, and the error falls as 3^-d (the
  Bernstein ellipse of the field's singularity);
- ``Motor(gap_at_zero, position_at_zero)``: a mirrored, offset 2-DOF platform is the 2-DOF stage
  at the gap and position those place;
- the stage-file reader's optional fields may be left out or null where documented, and a missing
  required field or a null required number is refused naming it.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.errors import InputError
from maglev_oc.expressions import function_to_data
from maglev_oc.model.equilibrium import NoEquilibriumError, equilibrium_currents, gap_for_current
from maglev_oc.model.magnetics import FIELD_FIT_RANGE, fit_field_polynomial
from maglev_oc.model.parameters import DEFAULT_CONSTANTS, MU0, StageParameters
from maglev_oc.model.platform import Motor, Platform, PlatformModel
from maglev_oc.model.stagefile import Provenance, StageEffect, StageFile
from maglev_oc.results import Estimate

GAP = 0.020  # [m] a scheduled gap (8 mm + 24 x 0.5 mm)


# --- model: equilibrium and field -------------------------------------------------------------
def test_gap_for_current_searches_only_its_bracket(model):
    """With bracket 15-25 mm, the 10 mm equilibrium current (inside the default 5-35 mm) has no
    gap in the bracket and is refused naming it; the 20 mm current is found at 20 mm (brentq's
    xtol 1e-12 m; 1e-9 m leaves room for the residual's rounding at a slope of 0.4 A/mm)."""
    i10, i20 = equilibrium_currents(model, [10e-3, GAP]).current
    assert 5e-3 < gap_for_current(model, float(i10)) < 35e-3  # the default bracket holds it
    with pytest.raises(NoEquilibriumError, match=r"no gap in \[15, 25\] mm"):
        gap_for_current(model, float(i10), bracket=(15e-3, 25e-3))
    assert_allclose(gap_for_current(model, float(i20), bracket=(15e-3, 25e-3)), GAP, rtol=0, atol=1e-9)
    # a bracket reaching past the default one finds a gap beyond 35 mm (the current there is
    # below i(35 mm), which the default refuses)
    i40 = float(equilibrium_currents(model, [40e-3]).current[0])
    with pytest.raises(NoEquilibriumError):
        gap_for_current(model, i40)
    assert_allclose(gap_for_current(model, i40, bracket=(30e-3, 45e-3)), 40e-3, rtol=0, atol=1e-9)


def _closed_form_field(p: StageParameters, y: np.ndarray) -> np.ndarray:
    """B(y) [T] of SPEC 1 written out with numpy (the magnetic-charge model's fundamental)."""
    a = math.pi / p.pole_pitch
    amp = 4 * MU0 * p.surface_charge / math.pi * math.sin(math.pi * p.magnet_width / (2 * p.pole_pitch))
    return amp * np.sinh(a * p.magnet_height) / np.sinh(a * (p.magnet_height + y))


def test_field_fit_degree_is_the_polynomials_degree():
    """A degree-d fit has d + 1 coefficients, its max_error is the largest deviation from the
    closed form on the dense grid (recomputed here with numpy; 1e-6 relative), and it falls as
    rho^-d with rho = 3: B ~ 1/sinh(a (h_m + y)) is analytic but for a pole at y = -h_m = -5 mm,
    which in the scaled gap s = (y - 20 mm) / 15 mm is at s = -5/3, on the Bernstein ellipse
    rho = 5/3 + sqrt((5/3)^2 - 1) = 3. Near-best (Chebyshev-node) fits converge at that rate:
    from degree 3 to 7 the error falls by 3^4 = 81 (measured 80.5), from 7 to 12 by 3^5 = 243
    (measured 243); a factor 2 either way is the bound asserted."""
    p = StageParameters()
    lo, hi = FIELD_FIT_RANGE
    s_pole = (-p.magnet_height - 0.5 * (lo + hi)) / (0.5 * (hi - lo))
    rho = abs(s_pole) + math.sqrt(s_pole**2 - 1)
    assert rho == pytest.approx(3.0, rel=1e-12)
    y = np.linspace(lo, hi, 3001)
    b = _closed_form_field(p, y)
    errors = {}
    for degree in (3, 7, 12):
        fit = fit_field_polynomial(p, degree=degree) if degree != 12 else fit_field_polynomial(p)
        assert len(fit.coefficients) == degree + 1
        errors[degree] = np.max(np.abs(np.asarray(fit(y), dtype=float) - b))
        assert_allclose(fit.max_error, errors[degree], rtol=1e-6)
    for low, high in ((3, 7), (7, 12)):
        assert 0.5 < errors[low] / errors[high] / rho ** (high - low) < 2.0


def test_a_motors_gap_and_position_at_zero_place_it(model):
    """Motor(gap_at_zero, position_at_zero): y = gap_at_zero - n . q and s = position_at_zero +
    t . q. A 2-DOF stage mirrored (stator on the +q1 side, gravity -G along q1) and offset (gap
    30 mm and position 10 mm at q = 0) is the 2-DOF stage at y and s: q1'' = -x2', q2'' = x4'
    of StageModel at the gap y (1e-12 relative: the same shape functions; the base model does
    not depend on s, which motor_forces reports)."""
    p = model.params
    motor = Motor("mirrored", (0.0, 1.0), (1.0, 0.0), (0, 1), gap_at_zero=0.030, position_at_zero=0.010)
    platform = Platform(("q1", "q2"), (p.mass_vertical, p.mass_horizontal), (-p.gravity, 0.0), (motor,), 2)
    pm = PlatformModel(platform)
    rng = np.random.default_rng(5)
    for _ in range(5):
        q = np.array([rng.uniform(0.005, 0.020), rng.uniform(-0.02, 0.02)])  # gaps 10-25 mm
        qd, u = rng.normal(0, 0.05, 2), rng.uniform(-5, 5, 2)
        x = np.array([q[0], qd[0], q[1], qd[1]])
        _, _, y, s = (float(v) for v in pm.motor_forces(x, u))
        assert_allclose([y, s], [0.030 - q[0], 0.010 + q[1]], rtol=1e-15)
        acc = np.asarray(pm.f(x, u)).ravel()
        stage = np.asarray(model.dynamics(np.array([y, -qd[0], s, qd[1]]), u)).ravel()
        assert_allclose([acc[1], acc[3]], [-stage[1], stage[3]], rtol=1e-12, atol=1e-12 * p.gravity)


# --- model: the stage file's optional and required fields ----------------------------------------
def _effect() -> StageEffect:
    x, i = ca.SX.sym("x", 4), ca.SX.sym("i", 2)
    acc = ca.vertcat(0, 0.1 - 2.0 * x[2] + 0 * i[0])
    return StageEffect(
        "cable_carrier_force",
        "horizontal",
        "A spring-like force along the track.",
        "stiffness -2",
        {"force": Estimate(0.1, 0.01, "N"), "stiffness": Estimate(-2.0, 0.5, "N/m")},
        function_to_data(ca.Function("f", [x, i], [acc], ["x", "i"], ["acc"])),
        None,
    )


def _document() -> dict:
    provenance = {part: Provenance.now((), "test") for part in ("geometry", "constants", "effects")}
    stage = StageFile(StageParameters(), DEFAULT_CONSTANTS, None, {}, (_effect(),), provenance)
    return json.loads(json.dumps(stage.to_dict()))


def test_stage_file_optional_fields_may_be_left_out_or_null():
    """Geometry fields are each optional (Table I for those left out); ``constants.stderr`` is
    optional, and so is each constant in it and its value (null: unknown, NaN); an effect's
    parameter may have a null standard error (NaN)."""
    doc = _document()
    doc["geometry"] = {"mass_vertical": 4.0}
    doc["constants"]["stderr"] = {"C1": 0.5, "C3": None}
    doc["effects"][0]["parameters"]["force"]["stderr"] = None
    stage = StageFile.from_dict(doc)
    assert stage.geometry == dataclasses.replace(StageParameters(), mass_vertical=4.0)
    assert stage.stderr["C1"] == 0.5
    assert all(math.isnan(stage.stderr[k]) for k in ("C2", "C3", "C4"))
    force = stage.effects[0].parameters["force"]
    assert force.value == 0.1 and math.isnan(force.stderr)
    assert stage.effects[0].parameters["stiffness"].stderr == 0.5
    del doc["constants"]["stderr"]
    assert all(math.isnan(v) for v in StageFile.from_dict(doc).stderr.values())


@pytest.mark.parametrize(
    "path",
    [
        "constants.source",
        "constants.covariance",
        "effects.0.parameters.force.unit",
        "effects.0.parameters.force.stderr",
        "effects.0.compensation",
        "provenance.effects.method",
    ],
)
def test_a_missing_required_stage_field_is_refused_naming_it(path):
    """Required fields (including those that may be null) must be present; the error names the
    field's path, whatever other fields are present."""
    doc = _document()
    *parents, last = path.split(".")
    obj = doc
    for key in parents:
        obj = obj[int(key)] if key.isdigit() else obj[key]
    del obj[last]
    shown = path.replace(".0.", "[0].")
    with pytest.raises(InputError, match=re.escape(f"{shown}: missing")):
        StageFile.from_dict(doc)


@pytest.mark.parametrize(
    ("path", "shown"),
    [("constants.C3", r"constants\.C3"), ("effects.0.parameters.force.value", r"\.force\.value")],
)
def test_a_required_number_may_not_be_null(path, shown):
    """Where a standard error may be null, a value may not: null is refused as not a number."""
    doc = _document()
    *parents, last = path.split(".")
    obj = doc
    for key in parents:
        obj = obj[int(key)] if key.isdigit() else obj[key]
    obj[last] = None
    with pytest.raises(InputError, match=rf"{shown}: expected a number, got null"):
        StageFile.from_dict(doc)
