"""Every candidate's physical parameters as functions of its fitted coefficients
(``Candidate.term.physical_parameters``), checked against what any error propagation must give:
the value depends on the coefficients only (not on their covariance), and its standard error is
the first-order propagation sqrt(g' C g) of the coefficients' covariance C through the value's
own gradient g, taken here by central differences of the reported values (not through the
candidate's code for the errors). Numpy and the library's CasADi terms, a few seconds."""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_oc.regression.data import prepare
from tests.test_statistics_properties import RATE_FRICTION, _log


@pytest.fixture(scope="module")
def library_and_constants(model):
    from maglev_oc.diagnosis.library import candidate_library

    data = prepare([_log(model, friction=RATE_FRICTION)], bandwidth=10.0)
    constants = {k: getattr(model.constants, k) for k in ("C1", "C2", "C3", "C4")}
    return candidate_library(model, data), constants


def _covariance(k: int, rng: np.random.Generator, scale: float) -> np.ndarray:
    """A full positive definite covariance with standard errors ~scale and correlations up to ~0.5."""
    a = rng.standard_normal((k, k))
    c = a @ a.T + k * np.eye(k)
    d = np.sqrt(np.diag(c))
    return scale**2 * c / np.outer(d, d)


def test_each_physical_standard_error_is_the_propagated_covariance(library_and_constants):
    """For every candidate and every parameter it reports: at coefficients away from zero (where
    an amplitude or a ratio is smooth) the value is the same for two covariances, and the
    standard error is sqrt(g' C g) with g the central difference of the value (step 1e-6 of the
    coefficient's size: truncation ~1e-12 relative, rounding ~1e-10), to 1e-4 relative plus
    1e-12 of the value (a delta method from an exact gradient agrees far closer; 1e-4 leaves room
    for a candidate that differentiates its own value numerically). Parameters that do not depend
    on the coefficients (a period, an end position) must then have a zero error."""
    library, constants = library_and_constants
    rng = np.random.default_rng(5)
    checked = 0
    for cand in library:
        k = cand.term.n_parameters
        q = 0.02 * (1.0 + rng.random(k)) * rng.choice([-1.0, 1.0], k)
        cov = _covariance(k, rng, 1e-4)
        params = cand.term.physical_parameters(q, cov, constants)
        other = cand.term.physical_parameters(q, 4.0 * cov, constants)
        grads = {name: np.zeros(k) for name in params}
        for i in range(k):
            h = 1e-6 * abs(q[i])
            up, down = q.copy(), q.copy()
            up[i] += h
            down[i] -= h
            p_up = cand.term.physical_parameters(up, cov, constants)
            p_down = cand.term.physical_parameters(down, cov, constants)
            for name in params:
                grads[name][i] = (p_up[name].value - p_down[name].value) / (2 * h)
        for name, e in params.items():
            assert other[name].value == e.value, (cand.name, name)
            g = grads[name]
            expected = math.sqrt(float(g @ cov @ g))
            assert e.stderr == pytest.approx(expected, rel=1e-4, abs=1e-12 * abs(e.value)), (
                cand.name,
                name,
                e,
                expected,
            )
            # four times the covariance, twice the error (first-order propagation is linear in C^1/2)
            assert other[name].stderr == pytest.approx(2 * e.stderr, rel=1e-9, abs=1e-15), (cand.name, name)
            checked += 1
    assert checked >= 40


def test_each_model_form_variant_is_another_model_form(library_and_constants, model):
    """A candidate's variants are the alternative forms its model-form spread is taken over
    (``with_model_form_spread``: half the range of the parameters refitted with each): every
    variant must differ from the nominal form and from every other variant, or the spread
    understates the form's uncertainty. Compared on 200 states across the logged gaps and
    positions with the same coefficients: somewhere they must differ by more than 1e-6 of the
    accelerations' size (the forms differ by O(1) there; rounding is 1e-16)."""
    library, _ = library_and_constants
    rng = np.random.default_rng(8)
    n = 200
    x = np.vstack(
        [
            rng.uniform(0.012, 0.03, n),
            rng.uniform(-0.05, 0.05, n),
            rng.uniform(-0.04, 0.04, n),
            rng.uniform(-0.2, 0.2, n),
        ]
    )
    u, du = rng.uniform(-3, 3, (2, n)), rng.uniform(-50, 50, (2, n))
    with_variants = [c for c in library if c.term.variants]
    assert with_variants
    for cand in with_variants:
        q = 0.05 * (1 + np.arange(cand.term.n_parameters))
        forms = [cand.term.function, *cand.term.variants]
        acc = [np.asarray(f.map(n)(x, u, du, np.repeat(q[:, None], n, 1))) for f in forms]
        size = max(np.max(np.abs(a)) for a in acc)
        assert size > 0, cand.name
        for i in range(len(acc)):
            for k in range(i):
                assert np.max(np.abs(acc[i] - acc[k])) > 1e-6 * size, (cand.name, k, i)


def test_systematic_errors_are_added_in_quadrature_never_more():
    """``with_model_form_spread`` without model-form variants: an angle's or a length's error is
    the fit's alone; any other parameter's is sqrt(stderr^2 + (1 % of its value)^2) (the
    differentiator's calibration, ``refit.CALIBRATION``). Summed linearly, or the error's square
    replaced by anything else, it exceeds that; exact to rounding."""
    from types import SimpleNamespace

    from maglev_oc.diagnosis.refit import CALIBRATION, with_model_form_spread
    from maglev_oc.regression.terms import Estimate

    params = {
        "angle": Estimate(0.02, 0.003, "rad"),
        "gap": Estimate(0.015, 2e-4, "m"),
        "force": Estimate(-1.5, 0.04, "N"),
        "tiny": Estimate(3.0, 1e-6, "1"),
    }
    cand = SimpleNamespace(name="x", term=SimpleNamespace(variants=()))
    out = with_model_form_spread(params, None, None, [], cand, None, None, None)
    for k, v in params.items():
        systematic = 0.0 if v.unit in ("rad", "m") else CALIBRATION * abs(v.value)
        assert out[k].value == v.value and out[k].unit == v.unit
        assert out[k].stderr == pytest.approx(math.hypot(v.stderr, systematic), rel=1e-12), k
