"""The feasible set F (maglev_oc.region.feasibility)."""

from __future__ import annotations

import dataclasses
import re

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from maglev_oc.errors import InputError
from maglev_oc.model.equilibrium import equilibrium_currents
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import (
    GAP_TRAVEL,
    FeasibleSet,
    _bisect,
    feasibility_map,
)
from maglev_oc.results import check_result


@pytest.fixture(scope="module")
def feasible(model):
    return FeasibleSet(model)


def _samples(n=2000, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(8e-3, 30e-3, n), rng.uniform(-50, 50, n), rng.uniform(-60, 30, n)


def test_matches_the_feedback_transformation(feasible, transformation):
    """margin = R/(4 L4) and headroom = 81 - |u|^2 with the physical root (SPEC 1 reading 5)."""
    x1, v1, v2 = _samples()
    h = feasible.evaluate(x1, v1, v2)
    np.testing.assert_allclose(h[0], transformation.feasibility_margin(x1, v1, v2), rtol=1e-12, atol=1e-12)
    ok = h[0] >= 0
    u = np.asarray(transformation.currents.map(x1.size)(x1[None, :], np.vstack([v1, v2])))
    # the rationalised root equals (-L3 - sqrt R)/(2 L4) up to rounding (a few 1e-13 A^2)
    np.testing.assert_allclose(h[1][ok], 81 - u[0][ok] ** 2 - u[1][ok] ** 2, atol=1e-10)


def test_current_constraint_is_an_ellipse(feasible, model):
    """|u| <= I  <=>  (v1/L1)^2 + ((v2 - G + L2 + L4 I^2)/L3)^2 <= I^2 when -L3/(2 L4) >= I."""
    x1, v1, v2 = _samples(seed=1)
    L1, L2, L3, L4 = model.coefficients(x1)
    c0 = model.params.gravity - L2 - L4 * 81
    ell = (v1 / L1) ** 2 + ((v2 - c0) / L3) ** 2 - 81
    h = feasible.evaluate(x1, v1, v2)
    clear = np.abs(ell) > 1e-6
    np.testing.assert_array_equal((h[1] >= 0)[clear], (ell <= 0)[clear])


def test_root_at_R0_needs_twice_the_peak_current(model):
    """Over the stoppers' range -L3/(2 L4) >= 18 A > 9 A: the current limit binds before R = 0."""
    g = np.linspace(*GAP_TRAVEL, 500)
    _, _, L3, L4 = model.coefficients(g)
    assert np.min(-L3 / (2 * L4)) > 18.0


def test_map_boundary_is_exact(feasible):
    """Newton roots on the grid lines are zeros of the constraint to solver tolerance."""
    loop = RegulatorLoop()
    fm = feasibility_map(
        feasible, loop, Reference.setpoint(0.02), ("e1", "e1_rate"), (-0.011, 0.009), (-0.6, 0.6), n=41
    )
    assert fm.newton_failures == 0
    check_result(fm)
    assert fm.status == "mapped"
    pts = fm.boundary["headroom"]
    assert pts.shape[1] > 20
    fn = feasible.loop_function(loop, Reference.setpoint(0.02))
    z = np.zeros((10, pts.shape[1]))
    z[0], z[1] = pts
    h = np.asarray(fn.map(pts.shape[1])(z, np.zeros((1, pts.shape[1]))))
    np.testing.assert_allclose(h[1], 0, atol=1e-9)  # rootfinder abstol 1e-12 [A^2]
    assert fm.feasible[fm.y.size // 2, fm.x.size // 2]  # the set-point itself is feasible


def test_validation(model):
    with pytest.raises(ValueError, match="current_limit"):
        FeasibleSet(model, current_limit=-1)
    with pytest.raises(ValueError, match="metres"):
        FeasibleSet(model, gap_range=(8, 30))
    with pytest.raises(TypeError):
        FeasibleSet(model, limit=9)
    with pytest.raises(ValueError, match="unknown slice variable"):
        feasibility_map(
            FeasibleSet(model), RegulatorLoop(), Reference.setpoint(0.02), ("gap", "e1"), (0, 1), (0, 1)
        )


@pytest.mark.parametrize("gap_mm", [12.0, 20.0, 26.0])
def test_a_setpoint_is_held_exactly_when_its_equilibrium_current_fits(model, gap_mm):
    # at rest the currents are (0, u2_eq) (000 eq. (7), closed form): a limit 1 mA above |u2_eq|
    # leaves a headroom of about 2 |u2_eq| 1e-3 A^2 (far below 1 A^2) and must be accepted; 1 mA
    # below must be refused, naming the current
    gap = gap_mm * 1e-3
    current = abs(float(equilibrium_currents(model, [gap]).current[0]))
    FeasibleSet(model, current_limit=current + 1e-3).check_setpoint(gap)
    tight = FeasibleSet(model, current_limit=current - 1e-3)
    with pytest.raises(InputError, match="needs \\|u\\| >") as refused:
        tight.check_setpoint(gap)
    # the refusal gives the gaps held at rest within the limit: the set-point is at one end of that
    # range (1 mA under its current, the boundary is within a step of the 401-point grid, 0.055 mm),
    # and the range's middle is held
    lo, hi = (
        float(v)
        for v in re.search(r"within the limits: \(([\d.]+), ([\d.]+)\) mm", str(refused.value)).groups()
    )
    assert min(abs(lo - gap_mm), abs(hi - gap_mm)) <= 0.1
    tight.check_setpoint(0.5 * (lo + hi) * 1e-3)


# --- the bisection that replaces Newton on a boundary line ---------------------------------------
@settings(max_examples=60, deadline=None)
@given(
    root=st.floats(-0.9, 0.9),
    width=st.floats(1e-4, 1.0),
    slope=st.floats(0.1, 10.0),
    falling=st.booleans(),
)
def test_bisection_finds_the_sign_change_in_its_bracket(root, width, slope, falling):
    # g(s; c, k) = k (s - c) (falling: its negative), cubed so Newton-like shortcuts are no help;
    # the bracket [c - width a, c + width b] holds one sign change. 60 halvings of a bracket of at
    # most 2 leave 2 / 2^60 ~ 2e-18: the root to 1e-12 (well above double rounding near 1).
    s, p = ca.SX.sym("s"), ca.SX.sym("p", 3)
    g = ca.Function("g", [s, p], [p[2] * (p[1] * (s - p[0])) ** 3])
    lo, hi = root - 0.37 * width, root + 0.63 * width
    found = _bisect(g, lo, hi, np.array([root, slope, -1.0 if falling else 1.0]))
    assert lo <= found <= hi
    assert found == pytest.approx(root, abs=1e-12)


@pytest.mark.parametrize("margin", [0.5, -0.5])
def test_a_refused_setpoint_names_its_reason_on_either_side_of_r_zero(model, margin):
    # a stage whose passive attraction C2 leaves R / (4 L4) at rest at 20 mm = +-0.5 m/s^2 (C2
    # moved by the margin's change over L2's shape at 20 mm): just above R = 0 the equilibrium
    # exists and it is the current (far above 0.5 A there) that refuses it; just below, R < 0
    gap = 0.02
    _, L2, L3, L4 = np.asarray(model.coefficients([gap]))[:, 0]
    at_rest = L3**2 / (4 * L4) + model.params.gravity - L2
    c = model.constants
    moved = model.with_constants(dataclasses.replace(c, C2=c.C2 + (at_rest - margin) * c.C2 / L2))
    feasible = FeasibleSet(moved, current_limit=0.5)
    assert feasible.evaluate(gap, 0.0, 0.0)[0] == pytest.approx(margin, rel=1e-9)
    why = "needs \\|u\\| > 0.5 A" if margin > 0 else "no equilibrium \\(R < 0\\)"
    with pytest.raises(InputError, match=why):
        feasible.check_setpoint(gap)


def test_a_newton_that_does_not_converge_hands_its_bracket_to_the_bisection(feasible, monkeypatch):
    """The boundary's Newton is stopped after one iteration on every bracket: each must then be
    counted as a failure and bisected, and the boundary is as exact as before (the bisection's 60
    halvings of a grid step); an unconverged Newton raising instead (CasADi's default) or its
    iterate being taken would not do."""
    from maglev_oc.region import feasibility as F

    real = ca.rootfinder

    def one_iteration(name, plugin, g, opts=None):
        return real(name, plugin, g, {**(opts or {}), "max_iter": 1})

    monkeypatch.setattr(F.ca, "rootfinder", one_iteration)
    loop = RegulatorLoop()
    fm = feasibility_map(
        feasible, loop, Reference.setpoint(0.02), ("e1", "e1_rate"), (-0.011, 0.009), (-0.6, 0.6), n=41
    )
    pts = fm.boundary["headroom"]
    assert fm.newton_failures >= pts.shape[1] > 20
    fn = feasible.loop_function(loop, Reference.setpoint(0.02))
    z = np.zeros((10, pts.shape[1]))
    z[0], z[1] = pts
    h = np.asarray(fn.map(pts.shape[1])(z, np.zeros((1, pts.shape[1]))))
    np.testing.assert_allclose(h[1], 0, atol=1e-9)
