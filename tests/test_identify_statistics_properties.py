"""Numbers identify reports, against independent computations: the encoder error variance the
experiment design predicts with against sampled readings of the encoder as its docstring
describes it, and the report and the comparison with a truth against the fit's own values and
standard errors (``FitResult.report``, ``z_scores``, ``relative_errors``). On the synthetic
horizontal log of ``tests/test_statistics_properties.py``; about 1 s of CPU."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from maglev_oc.identification.design import encoder_noise_variance
from maglev_oc.identification.equation_error import EquationError
from maglev_oc.regression.terms import viscous_friction
from maglev_oc.sim.effects import Encoder
from tests.test_statistics_properties import RATE_FRICTION, _log


@pytest.mark.parametrize("resolution, noise", [(10e-6, 2e-6), (1e-6, 3e-6), (20e-6, 1e-7)])
def test_encoder_error_variance_is_that_of_sampled_readings(resolution, noise):
    """An encoder quantizes the position plus a white noise (``Encoder``: quantization to
    ``resolution`` of the position plus ``noise_std`` white noise before the quantizer). Over
    positions spread across many counts the reading's error has variance q^2 / 12 + s^2
    (Widrow: the quantization error of a uniformly spread input is uniform and independent of
    the noise): 200 000 sampled readings give it to 0.6 % (1/sqrt(n/2)), so 2 %."""
    rng = np.random.default_rng(0)
    enc = Encoder(resolution=resolution, noise_std=noise)
    x = rng.uniform(0, 1000 * resolution, 200_000)
    reading = np.floor((x + noise * rng.standard_normal(x.size)) / resolution + 0.5) * resolution
    assert encoder_noise_variance(enc) == pytest.approx(np.var(reading - x), rel=0.02)
    assert encoder_noise_variance(enc) == pytest.approx(resolution**2 / 12 + noise**2, rel=1e-12)


@pytest.fixture(scope="module")
def fit(model):
    problem = EquationError(
        _log(model, friction=RATE_FRICTION), model, estimate=("C1",), terms=[viscous_friction("horizontal")]
    )
    return problem.fit()


def test_comparison_with_a_truth_uses_the_fits_errors(fit):
    """z = (estimate - truth) / standard error and the relative error (estimate - truth) / truth,
    for the parameters the truth names only; a zero standard error or truth gives none."""
    truth = {"C1": 14.0, "viscous_horizontal.rate": RATE_FRICTION, "C2": 700.0}
    z = fit.z_scores(truth)
    rel = fit.relative_errors(truth)
    assert set(z) == set(rel) == {"C1", "viscous_horizontal.rate"}
    for k in z:
        v, s = fit.values[k], fit.stderr[k]
        assert z[k] == pytest.approx((v - truth[k]) / s, rel=1e-12)
        assert rel[k] == pytest.approx((v - truth[k]) / truth[k], rel=1e-12)
    assert fit.relative_errors({"C1": 0.0}) == {}


def test_report_states_each_value_error_and_the_timing_parts(fit):
    """The report's variable lines carry each value with its standard error and, with a truth,
    the error and z of that line's own numbers; the wall-time line gives the total once and its
    parts in parentheses (the total not among them)."""
    truth = {"C1": 14.0, "viscous_horizontal.rate": RATE_FRICTION}
    text = fit.report(truth)
    for k in fit.names:
        (line,) = [ln for ln in text.splitlines() if ln.strip().startswith(f"{k}")]
        numbers = [float(s) for s in re.findall(r"[-+]?\d+\.?\d*(?:e[-+]?\d+)?", line.split(":", 1)[1])]
        v, s = fit.values[k], fit.stderr[k]
        assert numbers[0] == pytest.approx(v, rel=1e-6) and numbers[1] == pytest.approx(s, rel=1e-3)
        z = float(re.search(r"z ([-+]\d+\.\d+)", line).group(1))
        assert z == pytest.approx((v - truth[k]) / s, abs=0.006)
    (wall,) = [ln for ln in text.splitlines() if "wall time" in ln]
    total = float(re.search(r"= (\d+\.\d+) s", wall).group(1))
    assert total == pytest.approx(fit.timings["total"], abs=1e-3)
    inside = wall[wall.index("(") + 1 : wall.rindex(")")]
    assert "total" not in inside
    assert [p.split()[0] for p in inside.split(", ")] == [k for k in fit.timings if k != "total"]
    assert not math.isnan(total)


def test_a_npfsi_only_outcome_is_validated_without_a_gap_offset(model):
    """identify with NPFSI alone has no least-squares fit (best is None): its validation uses
    NPFSI's constants with no gap offset and no terms, i.e. it is ``validate`` called with those
    (same numbers); on this exact synthetic log that model follows the measured position over
    0.1 s windows to better than 99 % (measured 99.9 %; a 1 m offset would leave nothing)."""
    from maglev_oc.identification.pipeline import VALIDATION_BANDWIDTH, identify
    from maglev_oc.regression.data import prepare
    from maglev_oc.validation import validate

    log = _log(model, friction=0.0)
    out = identify([log], model, estimate=("C1",), methods=("npfsi",), npfsi_eps=(0.01,))
    assert out.best is None and out.equation_error is None and len(out.npfsi) == 1
    data = prepare([log], bandwidth=VALIDATION_BANDWIDTH)
    fitted = model.with_constants(out.constants())
    direct = validate(data, data.valid, fitted, [], description="d", data_description="d", gap_offset=0.0)
    for got, want in zip(out.validation.fits, direct.fits, strict=True):
        assert got.fit["horizontal"] == pytest.approx(want.fit["horizontal"], rel=1e-12)
    assert out.validation.fits[0].horizon == pytest.approx(0.1)
    assert out.validation.fits[0].fit["horizontal"] > 99.0
