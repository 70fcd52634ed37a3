"""The Monte Carlo checks of the region certificates (maglev_oc.region.montecarlo) flag what they
are there to flag: each kind of violation of F planted alone is caught, nothing at the limits
themselves is, and the merged and re-judged checks agree with counts computed from their parts.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.region.closed_loop import Reference
from maglev_oc.region.montecarlo import (
    BatchOutcome,
    BatchSimulator,
    CertificateCheck,
    SliceCheck,
    merge_checks,
    regulator_state,
    uniform_in_ellipsoid,
)
from maglev_oc.sim.twin import RigTwin

LIMIT = 9.0  # [A] the amplifiers' peak (FeasibleSet's default)


def _outcome(**planted) -> BatchOutcome:
    """Seven runs well inside F, with the fields in ``planted`` (index -> value per field) set."""
    n = 7
    arrays = {
        "min_margin": np.full(n, 5.0),
        "max_current": np.full(n, 3.0),
        "stopper_hit": np.zeros(n, bool),
        "min_gap": np.full(n, 0.019),
        "max_gap": np.full(n, 0.021),
        "max_abs_position": np.full(n, 0.001),
        "final_twin": np.zeros((4, n)),
        "final_controller": np.zeros((10, n)),
        "finite": np.ones(n, bool),
    }
    for name, values in planted.items():
        for k, v in values.items():
            arrays[name][k] = v
    return BatchOutcome.of({"total": 0.0}, **arrays)


def test_each_violation_planted_alone_is_flagged_and_the_limits_themselves_are_not():
    out = _outcome(
        stopper_hit={1: True},
        min_margin={2: -1e-9, 5: math.nan, 6: 0.0},  # NaN: a controller without a margin diagnostic
        max_current={3: LIMIT * (1 + 1e-6), 4: LIMIT},
        finite={0: False},
    )
    # run 0 diverged, 1 hit a stopper, 2 had R < 0, 3 exceeded the limit; 4 is at the limit, 5 has
    # no margin, 6 is at R = 0: on the boundary of F, not outside it
    assert list(out.violations(LIMIT)) == [True, True, True, True, False, False, False]
    # without a current limit the current is not judged; a smaller limit catches run 4 too
    assert list(out.violations(None)) == [True, True, True, False, False, False, False]
    assert list(out.violations(8.0)) == [True, True, True, True, True, False, False]
    assert not out.success and out.status == "diverged" and "1 diverged, 1 hit a stopper" in out.message
    clean = _outcome()
    assert clean.success and clean.status == "completed" and not clean.violations(LIMIT).any()


def test_runs_into_the_stoppers_are_flagged_on_the_twin(model):
    """Starts moving into the lower gap stopper and the right position stopper hit them on the twin
    (the extremes record the contact), and violations() flags them with and without the current
    limit; a start at rest at the set-point does not."""
    sim = BatchSimulator(RigTwin(model), FeedbackLinearizingRegulator(model), duration=0.05, compile=False)
    # gap 8.5 mm falling at 0.3 m/s; position 59 mm moving right at 0.5 m/s; at rest at 20 mm
    x0 = np.array([[0.0085, 0.020, 0.020], [-0.3, 0.0, 0.0], [0.0, 0.059, 0.0], [0.0, 0.5, 0.0]])
    out = sim.run(x0, regulator_state(x0, np.zeros((6, 3))), np.array([0.02, 0, 0, 0, 0, 0]))
    assert list(out.stopper_hit) == [True, True, False]
    assert out.min_gap[0] == pytest.approx(0.008, abs=1e-9)  # the lower stopper [m] (hardware.STOPPER_GAP)
    assert out.max_abs_position[1] == pytest.approx(0.060, abs=1e-9)  # the right stopper (STOPPER_POSITION)
    assert list(out.violations(None)) == [True, True, False]
    assert list(out.violations(LIMIT)[:2]) == [True, True]


def _check(violating, start, final, margin, current) -> CertificateCheck:
    violating = np.asarray(violating, bool)
    n = violating.size
    out = _outcome()
    return CertificateCheck.of(
        {"total": 1.0},
        reference=Reference.setpoint(0.02),
        level=2.0,
        n=n,
        violations=int(violating.sum()),
        violating=violating,
        start_ratio=np.asarray(start, float),
        final_ratio=np.asarray(final, float),
        min_margin=margin,
        max_current=current,
        outcome=BatchOutcome.of({"total": 1.0}, **{k: getattr(out, k)[..., :n] for k in _FIELDS}),
    )


_FIELDS = (
    "min_margin",
    "max_current",
    "stopper_hit",
    "min_gap",
    "max_gap",
    "max_abs_position",
    "final_twin",
    "final_controller",
    "finite",
)


def test_merged_checks_keep_every_run_and_the_worst_extremes():
    a = _check([False, False, True], [0.1, 0.5, 1.2], [0.01, 0.02, 3.0], 2.0, 8.0)
    b = _check([False, True], [0.3, 0.9], [0.0, 0.5], -0.5, 9.5)
    c = _check([False], [0.7], [0.1], 4.0, 1.0)
    merged = merge_checks([a, b, c])
    assert merged.n == 6 and merged.violations == 2 and not merged.success and merged.status == "violations"
    assert list(merged.violating) == [False, False, True, False, True, False]
    np.testing.assert_array_equal(merged.start_ratio, [0.1, 0.5, 1.2, 0.3, 0.9, 0.7])
    np.testing.assert_array_equal(merged.final_ratio, [0.01, 0.02, 3.0, 0.0, 0.5, 0.1])
    assert merged.min_margin == -0.5 and merged.max_current == 9.5
    assert merged.outcome.n == 6 and merged.timings["total"] == 3.0
    assert merge_checks([c]) is c
    ok = merge_checks([c, c])
    assert ok.success and ok.violations == 0 and ok.status == "no_violations" and ok.n == 2


def test_a_slice_rejudged_against_another_set_counts_from_its_own_starts():
    """with_certificate: certified = V(start - offset) <= level, unsafe = certified and not safe,
    coverage = |certified and safe| / |safe|, all recomputed here from the starts."""
    rng = np.random.default_rng(5)
    shape = (4, 5)
    starts = rng.normal(scale=1e-3, size=(10, 20))
    safe = rng.uniform(size=shape) < 0.7
    P = np.diag(rng.uniform(1e4, 1e6, 10))
    base = SliceCheck(
        True,
        "sound",
        "",
        "fl",
        Reference.setpoint(0.02),
        ("e1", "e2"),
        np.arange(5.0),
        np.arange(4.0),
        safe,
        np.zeros(shape, bool),
        0,
        0.0,
        np.zeros(shape),
        np.zeros(shape),
        starts,
    )
    offset = rng.normal(scale=5e-4, size=10)
    d = starts - offset[:, None]
    v = np.einsum("in,ij,jn->n", d, P, d).reshape(shape)
    for level in np.quantile(v, [0.0, 0.3, 0.6, 1.0]):
        got = base.with_certificate(P, level, offset)
        cert = v <= level
        assert np.array_equal(got.certified, cert)
        assert got.unsafe_certified == int(np.sum(cert & ~safe))
        assert got.coverage == pytest.approx(np.sum(cert & safe) / np.sum(safe), rel=1e-12)
        assert got.success == (got.unsafe_certified == 0)
        assert got.status == ("sound" if got.success else "unsound")
    # without an offset the set is centred at the steady state
    v0 = np.einsum("in,ij,jn->n", starts, P, starts).reshape(shape)
    level = float(np.median(v0))
    assert np.array_equal(base.with_certificate(P, level).certified, v0 <= level)


@pytest.mark.parametrize("dims", [None, [0, 5]], ids=["all-ten", "e1-e2-slice"])
def test_uniform_in_ellipsoid_is_inside_and_uniform(dims):
    """Uniform in a k-dimensional ellipsoid: V / level <= t holds for a share t^(k/2) of the
    points; checked at t = 0.25, 0.5, 0.9 to 5 standard errors of the share (binomial)."""
    rng = np.random.default_rng(9)
    A = rng.normal(size=(10, 10))
    P = A @ A.T + 10 * np.eye(10)
    level, n = 3.0, 20_000
    z = uniform_in_ellipsoid(P, level, n, rng, dims)
    k = 10 if dims is None else len(dims)
    if dims is not None:
        others = np.setdiff1d(np.arange(10), dims)
        assert np.all(z[others] == 0)
    v = np.einsum("in,ij,jn->n", z, P, z) / level
    assert np.all(v <= 1 + 1e-12)
    for t in (0.25, 0.5, 0.9):
        p = t ** (k / 2)
        assert abs(np.mean(v <= t) - p) <= 5 * math.sqrt(p * (1 - p) / n) + 1e-12, (t, p)
