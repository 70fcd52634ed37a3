"""Properties of the stage model that small injected bugs break (issue 21).

A reviewer injects one plausible bug at a time (a wrong sign, factor or index, an ignored
argument, a dropped validation) into ``maglev_oc/model/``; the quick suite must then fail. The
cases here were found by trying such bugs and keeping those no other test caught:

- the shape functions l1..l4 equal an independent numpy evaluation of eqs. (5)-(8) of paper 002
  (with eq. (1) of 000 for lam and Carter's coefficient of 002 Sec. 3), and obey two identities
  of those formulas that hold whatever lam, Kc and B are: l3^2 = l2 l4 and
  l3 = -l1 B cosh(a (h_m + y));
- the state equation is the one in the :mod:`maglev_oc.model.stage` docstring with those L_i;
- an equilibrium is at the requested position and gap, and :func:`gap_for_current` inverts
  :func:`equilibrium_currents` for any current in range, not only 0 A;
- the constructors refuse what cannot be a stage (a magnet wider than its pole pitch, a lumped
  constant of zero: L_i = 0 makes the feedback transformation divide by zero);
- the stage file's standard errors are the square roots of the covariance's diagonal (the same
  units as the constants), an identification's covariance lands on the constants it belongs to,
  and the compensation sums only the effects that can be fed forward.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.errors import InputError
from maglev_oc.expressions import function_to_data
from maglev_oc.model.equilibrium import equilibrium, equilibrium_currents, gap_for_current
from maglev_oc.model.parameters import DEFAULT_CONSTANTS, MU0, LumpedConstants, StageParameters
from maglev_oc.model.stagefile import Provenance, StageEffect, StageFile
from maglev_oc.results import Estimate

GAPS = np.linspace(5e-3, 35e-3, 31)  # the papers' field-fit range [m]


def _shapes_numpy(p: StageParameters, y: np.ndarray) -> np.ndarray:
    """l1..l4 (4, n) written out from the papers, in numpy (no CasADi, no package code)."""
    b0, t1, hm, tau = p.slot_width, p.slot_pitch, p.magnet_height, p.pole_pitch
    lam = 1 - b0**2 / (4 * t1 * (y + b0 / 2 + hm / p.recoil_permeability))  # 000 eq. (1)
    r = b0 / (2 * y)
    gamma1 = 4 / np.pi * (r * np.arctan(r) - np.log(np.sqrt(1 + r**2)))
    kc = t1 / (t1 - y * gamma1)  # Carter, 002 Sec. 3
    a = np.pi / tau
    amplitude = 4 * MU0 * p.surface_charge / np.pi * np.sin(np.pi * p.magnet_width / (2 * tau))
    b = amplitude * np.sinh(a * hm) / np.sinh(a * (hm + y))  # SPEC 1 field
    arg = a * (hm + y)
    coth = 1 / np.tanh(arg)
    return np.vstack([lam / (kc * np.sinh(arg)), lam * b**2, -lam * b * coth / kc, lam * coth**2 / kc**2])


def test_shape_functions_are_the_papers_formulas(model):
    """The CasADi shape functions against the numpy formulas: the same operations in another
    order, so they agree to round-off (rtol 1e-12 on values of order 1e-2..1)."""
    got = np.asarray(model.shape.map(GAPS.size)(GAPS[None, :]))
    assert_allclose(got, _shapes_numpy(model.params, GAPS), rtol=1e-12, atol=0)
    c = np.array(model.constants.as_array())[:, None]
    assert_allclose(model.coefficients(GAPS), c * _shapes_numpy(model.params, GAPS), rtol=1e-12)


def test_shape_function_identities(model):
    """Identities of eqs. (5)-(8) of 002 that hold whatever lam, Kc and B are:
    l3^2 = l2 l4 (both lam^2 B^2 coth^2 / Kc^2) and l3 / l1 = -B cosh(a (h_m + y)).
    Round-off only: rtol 1e-12."""
    p = model.params
    l1, l2, l3, l4 = np.asarray(model.shape.map(GAPS.size)(GAPS[None, :]))
    assert_allclose(l3**2, l2 * l4, rtol=1e-12)
    arg = np.pi / p.pole_pitch * (p.magnet_height + GAPS)
    assert_allclose(l3 / l1, -model.field_at(GAPS) * np.cosh(arg), rtol=1e-12)
    assert np.all(l1 > 0) and np.all(l2 > 0) and np.all(l3 < 0) and np.all(l4 > 0)  # signs of SPEC 1


def test_state_equation_is_the_documented_one(model):
    """x' of the stage docstring with L_i from the numpy formulas, at random states and inputs
    (rtol 1e-10: accelerations are differences of terms of order G)."""
    rng = np.random.default_rng(21)
    n = 40
    x = np.vstack([rng.uniform(6e-3, 34e-3, n), rng.normal(0, 0.1, n), rng.normal(0, 0.03, n)])
    x = np.vstack([x, rng.normal(0, 0.1, n)])
    u = rng.uniform(-6, 6, (2, n))
    L1, L2, L3, L4 = np.array(model.constants.as_array())[:, None] * _shapes_numpy(model.params, x[0])
    G = model.params.gravity
    want = np.vstack(
        [x[1], G - L4 * (u[0] ** 2 + u[1] ** 2) - L3 * u[1] - L2, x[3], -L1 * u[0]],
    )
    assert_allclose(model.dynamics(x, u), want, rtol=1e-10, atol=1e-12)


# --- equilibria -----------------------------------------------------------------------------------
@pytest.mark.parametrize("position", [-0.04, 0.0, 0.0123])
def test_equilibrium_is_where_it_was_asked(model, position):
    """x = (gap, 0, position, 0), u = (0, i_d) and x' = 0 there (force balance, 1e-10 m/s^2)."""
    op = equilibrium(model, 0.018, position)
    assert op.gap == 0.018 and op.position == position
    assert op.x[1] == 0.0 and op.x[3] == 0.0 and op.u[0] == 0.0
    assert np.max(np.abs(model.dynamics(op.x, op.u))) < 1e-10


@pytest.mark.parametrize("current", [-0.5, 0.0, 1.5, 4.0])
def test_gap_for_current_inverts_the_equilibrium_curve(model, current):
    """gap_for_current(I) is the gap whose equilibrium current is I (Brent to 1e-12 m; the curve
    falls about 0.4 A/mm, so the current agrees to 1e-8 A)."""
    gap = gap_for_current(model, current)
    assert 5e-3 < gap < 35e-3
    assert_allclose(equilibrium_currents(model, [gap]).current[0], current, atol=1e-8)
    # the curve decreases with the gap: a larger current holds a smaller gap
    assert gap_for_current(model, current + 0.5) < gap


def test_current_limit_option_is_the_one_applied(model):
    """equilibrium(current_limit=...) refuses exactly the currents above the limit given."""
    need = float(equilibrium_currents(model, [0.012]).current[0])  # about 4.5 A
    assert equilibrium(model, 0.012, current_limit=need * 1.01).u[1] == pytest.approx(need)
    with pytest.raises(InputError, match="limit"):
        equilibrium(model, 0.012, current_limit=need * 0.99)


# --- constructors refuse what cannot be a stage ---------------------------------------------------
def test_a_magnet_wider_than_its_pole_pitch_is_refused():
    """tau_p <= tau: wider magnets would overlap their neighbours (Table I: 28.58 of 57.15 mm)."""
    p = StageParameters()
    with pytest.raises(ValueError, match="magnet_width"):
        StageParameters(magnet_width=1.01 * p.pole_pitch)
    with pytest.raises(ValueError, match="slot_width"):
        StageParameters(slot_width=p.slot_pitch)
    assert StageParameters(magnet_width=p.pole_pitch).magnet_width == p.pole_pitch


@pytest.mark.parametrize("name", ["C1", "C2", "C3", "C4"])
@pytest.mark.parametrize("value", [0.0, -1.0, math.inf, math.nan])
def test_each_lumped_constant_must_be_positive(name, value):
    """C_i > 0 (SPEC 1, C3 > 0 with the sign in L3): C_i = 0 would make L_i = 0 and the feedback
    transformation divide by zero (u1 = -v1 / L1; u2 = ... / (2 L4))."""
    with pytest.raises(ValueError, match=name):
        DEFAULT_CONSTANTS.replace(**{name: value})


# --- the stage file -------------------------------------------------------------------------------
def _provenance() -> dict[str, Provenance]:
    return {part: Provenance.now((), "test") for part in ("geometry", "constants", "effects")}


def test_stage_file_standard_errors_are_square_roots_of_the_variances(tmp_path):
    """stderr_k = sqrt(cov_kk), in the constants' units (not their squares), also after a write
    and read; a stage file's covariance of diag(s^2) gives back s exactly up to sqrt's round-off."""
    s = np.array([0.1, 2.0, 0.3, 0.004])
    cov = np.diag(s**2)
    cov[1, 2] = cov[2, 1] = 0.5 * s[1] * s[2]  # correlation 0.5 leaves the variances alone
    stage = StageFile(StageParameters(), DEFAULT_CONSTANTS, cov, {}, (), _provenance())
    back = StageFile.read(stage.write(tmp_path / "stage.json"))
    for f in (stage, back):
        assert_allclose([f.stderr[k] for k in ("C1", "C2", "C3", "C4")], s, rtol=1e-15)


def test_identification_covariance_lands_on_its_constants():
    """An identification that fits C2..C4 only (C1 held fixed): its 3 x 3 covariance goes to the
    rows and columns of C2..C4 of the stage file, C1's row and column are zero."""
    cov3 = np.array([[4.0, 0.3, 0.1], [0.3, 0.25, 0.02], [0.1, 0.02, 0.01]])
    best = SimpleNamespace(
        names=("C2", "C3", "C4"),
        covariance=cov3,
        stderr={k: math.sqrt(cov3[i, i]) for i, k in enumerate(("C2", "C3", "C4"))},
        method="output_error",
    )
    outcome = SimpleNamespace(best=best, constants=lambda: DEFAULT_CONSTANTS, sources=("run.csv",))
    geometry = Provenance.now((), "Table I")
    stage = StageFile.from_identification(outcome, _model_stub(), geometry)
    assert_allclose(stage.covariance[1:, 1:], cov3, rtol=0, atol=0)
    assert np.all(stage.covariance[0] == 0) and np.all(stage.covariance[:, 0] == 0)
    assert stage.stderr["C2"] == 2.0 and stage.stderr["C1"] == 0.0


def _model_stub():
    return SimpleNamespace(params=StageParameters())


def _effect(name: str, force: float, compensable: bool) -> StageEffect:
    """A constant horizontal acceleration ``force`` [m/s^2]; current-dependent when not compensable."""
    x, i = ca.SX.sym("x", 4), ca.SX.sym("i", 2)
    acc = ca.vertcat(0, force + (0 if compensable else 0.1 * i[0]))
    comp = function_to_data(ca.Function("g", [x], [ca.vertcat(0, force + 0 * x[0])], ["x"], ["acc"]))
    return StageEffect(
        name,
        "horizontal",
        "test",
        "test",
        {"force": Estimate(force, math.nan, "m/s^2")},
        function_to_data(ca.Function("f", [x, i], [acc], ["x", "i"], ["acc"])),
        comp if compensable else None,
    )


def test_compensation_sums_only_the_compensable_effects():
    """StageFile.compensation: the effects a controller can feed forward (those with a state-only
    part); the plant's effects are all of them."""
    effects = (_effect("cable_carrier_force", 0.3, True), _effect("guide_misalignment", 0.05, False))
    stage = StageFile(StageParameters(), DEFAULT_CONSTANTS, None, {}, effects, _provenance())
    x = np.array([0.02, 0.0, 0.01, 0.0])
    assert_allclose(np.asarray(stage.compensation()(x)).ravel(), [0.0, 0.3], rtol=1e-15)
    assert_allclose(np.asarray(stage.plant_effects()(x, [2.0, 0.0])).ravel(), [0.0, 0.55], rtol=1e-15)
    only_current = StageFile(StageParameters(), DEFAULT_CONSTANTS, None, {}, effects[1:], _provenance())
    assert only_current.compensation() is None


def test_stage_file_model_uses_its_geometry_and_constants():
    """StageFile.model(): a StageModel of the file's own geometry and constants."""
    constants = LumpedConstants(15.0, 800.0, 30.0, 0.08, source="test")
    geometry = StageParameters(gravity=9.80)
    stage = StageFile(geometry, constants, None, {}, (), _provenance())
    model = stage.model()
    assert model.constants == constants and model.params == geometry
