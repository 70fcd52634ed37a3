"""Regions of attraction of the linear regulators (maglev_oc.region.roa)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_oc.control.gains import PAPER_GAINS, axis_poles
from maglev_oc.control.linear_regulator import paper_linear_regulator
from maglev_oc.region.closed_loop import Reference
from maglev_oc.region.roa import LinearizedLoop, RoaCertifier, certify_roa, frozen_poles
from maglev_oc.results import check_result

TARGET = Reference.setpoint(0.018, 0.020)


@pytest.fixture(scope="module")
def linear(model):
    return paper_linear_regulator(model)


@pytest.fixture(scope="module")
def roa(model, linear):
    return certify_roa(model, linear, TARGET)


def test_linearized_loop_has_the_papers_poles(model, linear):
    """On the Jacobian linearization the scheduled gains place the printed gains' FL poles (002 7.1)."""
    loop = LinearizedLoop(model, linear, TARGET)
    ev = np.sort_complex(np.linalg.eigvals(loop.A))
    expect = np.sort_complex(
        np.concatenate([axis_poles(PAPER_GAINS["K_v"].printed), axis_poles(PAPER_GAINS["K_h"].printed)])
    )
    np.testing.assert_allclose(ev, expect, rtol=1e-6)  # 18 mm is a schedule node: interpolation exact
    g0 = np.asarray(loop.remainder(np.zeros(3))).ravel()
    j0 = np.asarray(loop.remainder_jacobian(np.zeros(3)))
    np.testing.assert_allclose(g0, 0, atol=1e-9)
    np.testing.assert_allclose(j0, 0, atol=1e-6)  # exact Jacobian at the equilibrium (CasADi)


def test_certified_level_has_decreasing_V_on_the_nonlinear_plant(model, linear, roa):
    """Independent check: V' = 2 z' P z' < 0 with the full nonlinear closed loop at 5000 points of
    the certified ellipsoid (not the bound used to certify it)."""
    assert roa.success and roa.level > 0
    check_result(roa)
    assert roa.status == "certified" and set(roa.timings) == {"stability", "total"}
    loop = LinearizedLoop(model, linear, TARGET)
    rng = np.random.default_rng(0)
    g = rng.standard_normal((10, 5000))
    g /= np.linalg.norm(g, axis=0)
    g *= rng.uniform(0, 1, 5000) ** 0.1
    z = math.sqrt(roa.level) * np.linalg.solve(np.linalg.cholesky(roa.P).T, g)
    ell = loop.output @ z
    rem = np.asarray(loop.remainder.map(z.shape[1])(ell))
    zdot = loop.A @ z
    zdot[1] += rem[0]
    zdot[6] += rem[1]
    vdot = 2 * np.einsum("in,ij,jn->n", z, roa.P, zdot)
    assert np.all(vdot < 0)


def test_feedforward_only_moves_the_start(model, linear, roa):
    """Without feedforward the loop in z^ is the same (same gains); only z_eq, hence V(start), differ."""
    noff = paper_linear_regulator(model, feedforward=False)
    roa2 = certify_roa(model, noff, TARGET)
    np.testing.assert_allclose(roa2.level, roa.level, rtol=1e-9)
    loop2 = LinearizedLoop(model, noff, TARGET)
    assert abs(loop2.z_eq[2]) > 0
    # z_eq is the regulator's equilibrium: with zero errors its internal model alone supplies the
    # equilibrium current (u2 = K_v z_eq without feedforward), and the internal model is at rest
    # there (phi xi_eq = 0: only xi1, the integrator's state, is nonzero)
    np.testing.assert_allclose(loop2.K_v @ loop2.z_eq[:5], loop2.u_eq[1], rtol=1e-12)
    np.testing.assert_allclose(loop2.z_eq[[0, 1, 3, 4]], 0.0, atol=0)
    start = [0.026, 0, 0, 0]
    v1 = roa.value(LinearizedLoop(model, linear, TARGET).initial_error(start))
    v2 = roa2.value(loop2.initial_error(start))
    assert v2 > v1 > 1  # the papers' large step is outside both certified regions


def test_frozen_poles_at_the_design_gap(model, linear):
    p = frozen_poles(model, linear, TARGET, [0.018])[0]
    np.testing.assert_allclose(
        np.sort_complex(p), np.sort_complex(axis_poles(PAPER_GAINS["K_v"].printed)), rtol=1e-6
    )


def test_validation(model, linear):
    with pytest.raises(ValueError, match="set-points"):
        LinearizedLoop(model, linear, Reference.paper_sinusoid())
    with pytest.raises(TypeError):
        LinearizedLoop(model, object(), TARGET)


def test_the_stability_level_is_the_largest_certified_within_one_percent(model, linear, roa):
    # bisection on the Jacobian box's decrease test: at the certified level the box proves
    # V' < 0, and 1 % above it the same test fails (unless the stoppers' level, which caps the
    # search at 4x, is below it)
    cert = RoaCertifier(LinearizedLoop(model, linear, TARGET))
    assert cert.decrease_margin(roa.P, cert.jacobian_box(roa.P, roa.level_stability)) < 0
    if roa.level_stability < 4 * roa.level_travel:
        assert cert.decrease_margin(roa.P, cert.jacobian_box(roa.P, 1.01 * roa.level_stability)) >= 0
