"""The building blocks the diagnosis library's candidates are written with
(``maglev_oc.diagnosis.candidate``), against closed forms and sampling: the delta method's
standard error against the exact gradient and against Monte Carlo, the Legendre polynomials'
orthogonality, the ranges and delays a library takes from its log. Numpy only, under a second."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.diagnosis.candidate import LibraryContext, delta_method, fmt, legendre
from maglev_oc.errors import InputError
from maglev_oc.model.hardware import RIG_SAMPLE_TIME
from maglev_oc.regression.data import prepare
from maglev_oc.results import Estimate
from tests.test_statistics_properties import RATE_FRICTION, _log


def test_delta_method_is_the_exact_gradient_propagated():
    """f(p) = p0 p1^2 / p2: its gradient in closed form, sqrt(g' C g) with a full covariance;
    central differences of step 1e-6 p agree to 1e-8 relative (truncation h^2 f''' / 6)."""
    p = np.array([2.0, -3.0, 0.5])
    cov = np.array([[0.04, 0.01, 0.0], [0.01, 0.09, -0.02], [0.0, -0.02, 0.01]])

    def f(q):
        return q[0] * q[1] ** 2 / q[2]

    g = np.array([p[1] ** 2 / p[2], 2 * p[0] * p[1] / p[2], -p[0] * p[1] ** 2 / p[2] ** 2])
    e = delta_method(f, p, cov, "N")
    assert e.value == f(p) and e.unit == "N"
    assert e.stderr == pytest.approx(math.sqrt(g @ cov @ g), rel=1e-8)


def test_delta_method_matches_the_scatter_of_sampled_parameters():
    """For small errors the delta method is the spread of f over parameters drawn from their
    covariance: 40 000 draws give the standard deviation to 0.35 % (1/sqrt(2 n)), and a 1 %
    relative parameter error keeps the nonlinearity's share below that; 3 % covers both."""
    rng = np.random.default_rng(0)
    p = np.array([1.5, 0.8])
    cov = np.diag((0.01 * p) ** 2)
    cov[0, 1] = cov[1, 0] = 0.5 * 0.01 * p[0] * 0.01 * p[1]

    def f(q):
        return np.hypot(q[0], q[1]) * np.exp(-q[1])

    draws = rng.multivariate_normal(p, cov, 40_000)
    spread = float(np.std([f(q) for q in draws]))
    assert delta_method(f, p, cov, "").stderr == pytest.approx(spread, rel=0.03)


def test_legendre_polynomials_are_orthogonal_with_their_norms():
    """int_-1^1 P_m P_n = 2 / (2 n + 1) delta_mn, by Gauss-Legendre quadrature of order 10 (exact
    for degree 19 polynomials); P_n(1) = 1 and P_n(-1) = (-1)^n."""
    xi, w = np.polynomial.legendre.leggauss(10)
    orders = (1, 2, 3, 4)
    ps = legendre(xi, orders)
    gram = np.array([[np.sum(w * a * b) for b in ps] for a in ps])
    assert_allclose(gram, np.diag([2 / (2 * n + 1) for n in orders]), atol=1e-14)
    ends = legendre(np.array([1.0, -1.0]), orders)
    for n, v in zip(orders, ends, strict=True):
        assert_allclose(v, [1.0, (-1.0) ** n], atol=1e-15)
    with pytest.raises(InputError):
        legendre(xi, (5,))


def test_fmt_scales_value_and_error_alike():
    assert fmt(Estimate(0.0123, 0.0004, "m"), 1e3, "mm") == "12 ± 0.4 mm"
    assert fmt(Estimate(2.0, 0.3, "N")) == "2 ± 0.3 N"


def test_fmt_writes_a_finding_in_positional_notation_to_its_significant_digits():
    """A finding a person reads: two significant digits for the value and one for its error, as %g
    rounds them, but without %g's exponent for the sizes the findings print (0.001 to 99 999):
    a 0.3 mm guide waviness in um read "3e+02 ± 1e+01 um" before."""
    assert fmt(Estimate(3e-4, 1e-5, "m"), 1e6, "um") == "300 ± 10 um"
    assert fmt(Estimate(347.0, 12.0, "N")) == "350 ± 10 N"
    assert fmt(Estimate(0.0999, 0.0096, "m")) == "0.1 ± 0.01 m"  # rounded up a decade
    assert fmt(Estimate(-1234.0, 55.0, "N")) == "-1200 ± 60 N"
    assert fmt(Estimate(1e-5, 2e-6, "m")) == "1e-05 ± 2e-06 m"  # outside the range: as %g


def test_library_context_takes_its_ranges_and_delay_from_the_log(model):
    """The gap and position ranges are the 1st-99th percentiles of the valid samples, the gap's
    median their median, the command's hold delay half a control period (the rig's 5 kHz when
    the log does not say), masses and weights the model's, and a reference ratio reference /
    fitted (1 for a constant the fit does not have)."""
    data = prepare([_log(model, friction=RATE_FRICTION)], bandwidth=10.0)
    ctx = LibraryContext(model, data)
    x = data.x[:, data.valid]
    assert ctx.position_range == pytest.approx(tuple(np.percentile(x[2], [1, 99])), rel=1e-12)
    assert ctx.gap_range == pytest.approx(tuple(np.percentile(x[0], [1, 99])), rel=1e-12)
    assert ctx.gap_median == pytest.approx(float(np.median(x[0])), rel=1e-12)
    assert ctx.hold_delay == pytest.approx(0.5 * RIG_SAMPLE_TIME, rel=1e-12)
    p = model.params
    assert ctx.mass("vertical") == p.mass_vertical and ctx.mass("horizontal") == p.mass_horizontal
    assert ctx.weight("horizontal") == pytest.approx(p.mass_horizontal * p.gravity, rel=1e-12)
    c2 = model.constants.C2
    assert ctx.reference_ratio("C2", {"C2": 2 * c2}) == pytest.approx(0.5, rel=1e-12)
    assert ctx.reference_ratio("C2", {}) == 1.0


def test_every_candidates_physical_parameters_are_numbers_with_units(model):
    """Every candidate of the library turns any coefficient vector (with its covariance) into
    physical parameters that are finite numbers with a non-negative finite standard error and a
    unit; the fixed periods a candidate reports are the motor's own (slot pitch and pole pitch
    for the thrust ripple)."""
    from maglev_oc.diagnosis.library import candidate_library

    data = prepare([_log(model, friction=RATE_FRICTION)], bandwidth=10.0)
    library = candidate_library(model, data)
    assert len(library) >= 15
    constants = {k: getattr(model.constants, k) for k in ("C1", "C2", "C3", "C4")}
    for cand in library:
        k = cand.term.n_parameters
        q = 0.01 * (1 + np.arange(k))  # small, distinct, positive
        params = cand.term.physical_parameters(q, 1e-6 * np.eye(k), constants)
        assert params, cand.name
        for name, e in params.items():
            assert isinstance(e.value, float) and math.isfinite(e.value), (cand.name, name, e)
            assert math.isfinite(e.stderr) and e.stderr >= 0, (cand.name, name, e)
            assert isinstance(e.unit, str), (cand.name, name, e)
    (ripple,) = [c for c in library if c.name == "thrust_ripple"]
    params = ripple.term.physical_parameters(np.array([0.01, 0.0, 0.0, 0.02]), 1e-6 * np.eye(4), constants)
    assert params["period"].value == model.params.slot_pitch
    assert params["period_pole_pitch"].value == model.params.pole_pitch


def test_reported_sizes_are_read_off_the_candidates_own_acceleration(model):
    """A candidate's physical size must describe the acceleration it adds: with the model's
    constants as the fit's, the end effects' thrust loss at each end is the change of its
    horizontal acceleration from the centre of the travel to that end, per unit of the thrust
    -L1 u1, and the loss at the ends their mean; the magnets' field departure at the smallest gap
    is twice the relative change of the thrust there from the centre of the logged gaps (the
    attraction follows B^2, the thrust B). Both evaluated here from the terms' functions and the
    model's L1 (1e-9: the same arithmetic in another order)."""
    from maglev_oc.diagnosis.library import candidate_library

    data = prepare([_log(model, friction=RATE_FRICTION)], bandwidth=10.0)
    by_name = {c.name: c for c in candidate_library(model, data)}
    constants = {k: getattr(model.constants, k) for k in ("C1", "C2", "C3", "C4")}
    u = np.array([0.7, 1.4])

    def acc_h(cand, q, gap, x3):
        x = np.array([gap, 0.0, x3, 0.0])
        return float(cand.term.acceleration(q)(x, u, np.zeros(2)).full()[1, 0])

    def thrust(gap):
        return -float(model.coefficients(gap)[0, 0]) * u[0]

    end = by_name["end_effects"]
    q_end = [0.1, 0.04, 0.0, 0.0]  # winding losses at the low and the high end; no magnet loss
    p = end.term.physical_parameters(np.array(q_end), np.eye(4) * 1e-8, constants)
    lo, hi = p["low_end_position"].value, p["high_end_position"].value
    gap = 0.02
    losses = []
    for label, x3 in (("low", lo), ("high", hi)):
        change = (acc_h(end, q_end, gap, x3) - acc_h(end, q_end, gap, 0.5 * (lo + hi))) / thrust(gap)
        assert p[f"thrust_loss_at_{label}_end"].value == pytest.approx(-change, rel=1e-9)
        losses.append(-change)
    assert p["thrust_loss_at_ends"].value == pytest.approx(np.mean(losses), rel=1e-9)

    field = by_name["magnet_field_gap_dependence"]
    q = np.array([0.03, -0.02])
    p = field.term.physical_parameters(q, np.eye(2) * 1e-8, constants)
    small, large = p["smallest_gap"].value, p["largest_gap"].value
    centre, half = 0.5 * (small + large), max(0.5 * (large - small), 1e-4)
    for key, g in (("at_smallest_gap", centre - half), ("at_largest_gap", centre + half)):
        rel = acc_h(field, q, g, 0.0) / thrust(g) - acc_h(field, q, centre, 0.0) / thrust(centre)
        assert p[f"attraction_change_{key}"].value == pytest.approx(2 * rel, rel=1e-9)
