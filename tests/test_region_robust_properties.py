"""The robust certificate's conservativeness figures (maglev_oc.region.robust_certificate.coverage)
recomputed from the runs they summarise: shares of the safe starts inside each certified set,
unsafe starts counted inside each, the verdict on the robust set, and the sweep's own time; and the
robust SDP's choice of P does not depend on how the nominal certificate's V is normalised."""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.region.robust import assumed_covariance
from maglev_oc.region.robust_certificate import RobustCertifier, coverage, robust_lyapunov_matrix
from maglev_oc.region.sweep import PlantSet
from maglev_oc.results import check_result


def _sweep(ratio, violating, level=4.0, total=12.5):
    ratio, violating = np.asarray(ratio, float), np.asarray(violating, bool)
    spec = SimpleNamespace(P=np.eye(10), level=level)
    return SimpleNamespace(
        spec=spec, start_ratio=ratio, violating=violating, n=ratio.size, timings={"total": total}
    )


def test_coverage_is_recomputed_from_the_runs():
    rng = np.random.default_rng(2)
    ratio = rng.uniform(0, 1, 400)
    v = 4.0 * ratio
    violating = v > 3.0  # every unsafe start lies beyond V = 3
    nominal, robust = 2.5, 1.5
    got = coverage(_sweep(ratio, violating), nominal, robust)
    check_result(got)
    safe = ~violating
    assert got.runs == 400 and got.safe == int(safe.sum()) and got.probe_level == 4.0
    assert got.nominal == pytest.approx(np.mean(v[safe] <= nominal), rel=1e-12)
    assert got.robust == pytest.approx(np.mean(v[safe] <= robust), rel=1e-12)
    assert 0 < got.robust < got.nominal < 1  # the smaller set covers less of the safe starts
    assert got.unsafe_in_nominal == got.unsafe_in_robust == 0 and got.success and got.status == "sound"
    assert got.timings["sweep"] == 12.5  # the sweep's wall time [s], carried over


def test_an_unsafe_start_inside_the_robust_set_is_a_violation():
    ratio = np.array([0.1, 0.2, 0.5, 0.7, 0.9])
    violating = np.array([False, True, False, True, False])  # V = 0.8 and 2.8 left F
    got = coverage(_sweep(ratio, violating), 3.0, 1.0)  # nominal, robust levels
    assert got.unsafe_in_robust == 1 and got.unsafe_in_nominal == 2
    assert not got.success and got.status == "violated"
    # the safe starts have V = 0.4, 2.0 and 3.6
    assert got.nominal == pytest.approx(2 / 3) and got.robust == pytest.approx(1 / 3)


def test_a_sweep_from_a_fixed_start_has_no_coverage():
    sweep = _sweep([0.5], [False])
    sweep.spec.P = None
    with pytest.raises(ValueError, match="level set"):
        coverage(sweep, 1.0, 1.0)


@pytest.mark.parametrize("scale", [1e-6, 1e4])
def test_the_robust_p_does_not_depend_on_the_normalisation_of_v(model, scale):
    """{z' P z <= c} is the same set as {z' (k P) z <= k c}: the robust SDP, handed the nominal
    certificate in either form, returns the same P (normalised to level 1). Measured agreement
    5e-5 relative (the SDP solver's tolerance), asserted to 1e-3."""
    loop = RegulatorLoop()
    feasible = FeasibleSet(model)
    nominal = Procedure2(feasible, loop).run(Reference.setpoint(0.025))
    certifier = RobustCertifier(feasible, loop, max_boxes=1000, ladder=(1.0,))
    plants = PlantSet.confidence(model.constants, assumed_covariance(model.constants), 0.9)
    P, msg = robust_lyapunov_matrix(certifier, nominal, plants, alphas=(1.0,))
    scaled = dataclasses.replace(nominal, P=scale * nominal.P, level=scale * nominal.level)
    Q, msg_q = robust_lyapunov_matrix(certifier, scaled, plants, alphas=(1.0,))
    assert P is not None and Q is not None, (msg, msg_q)
    np.testing.assert_allclose(Q, P, rtol=1e-3, atol=1e-3 * np.abs(P).max())


def test_the_robust_certificate_reports_its_share_of_the_nominal_level(model):
    """With the nominal plant alone and a ladder starting at half the nominal level, the first
    rung is certified (Delta = 0: V decreases): level = c_nom / 2 exactly, said so in the message
    and in ``ratio``. A nominal certificate that failed gives a robust one that did too,
    carrying the nominal it was given."""
    loop = RegulatorLoop()
    feasible = FeasibleSet(model)
    nominal = Procedure2(feasible, loop).run(Reference.setpoint(0.02))
    certifier = RobustCertifier(feasible, loop, max_boxes=100_000, ladder=(0.5,))
    res = certifier.run(nominal, PlantSet.point(model.constants))
    check_result(res)
    assert res.status == "certified" and res.level == 0.5 * nominal.level and res.ratio == 0.5
    assert ": 0.5 of it" in res.message
    failed = dataclasses.replace(nominal, success=False, status="not_certified", level=0.0, message="none")
    out = certifier.run(failed, PlantSet.point(model.constants))
    check_result(out)
    assert not out.success and out.status == "not_certified" and out.level == 0.0
    assert out.nominal is failed and "the nominal certificate failed: none" in out.message


def test_with_no_mismatch_the_robust_sdp_keeps_the_nominal_p(model):
    """The nominal plant alone: every sampled worst-case mismatch is zero, so there is nothing to
    design for and the nominal certificate's P is returned as it is, said so (a P from an SDP
    solved with mu = 0 would be another matrix, normalised otherwise); a nominal certificate with
    no level gives no P."""
    loop = RegulatorLoop()
    feasible = FeasibleSet(model)
    nominal = Procedure2(feasible, loop).run(Reference.setpoint(0.02))
    certifier = RobustCertifier(feasible, loop, max_boxes=1000, ladder=(1.0,))
    P, msg = robust_lyapunov_matrix(certifier, nominal, PlantSet.point(model.constants), samples=200)
    assert msg == "no mismatch: the nominal P is kept"
    np.testing.assert_array_equal(P, nominal.P)
    none, why = robust_lyapunov_matrix(
        certifier, dataclasses.replace(nominal, level=0.0), PlantSet.point(model.constants)
    )
    assert none is None and why == "the nominal certificate has no level"


def test_the_refuting_points_lie_on_the_level_set_also_from_a_box_at_the_centre(model, monkeypatch):
    """RobustCertifier._refute lifts each undecided box's midpoint to states z~ on V = z~' P z~ =
    level, where the exact rate is evaluated: the image part from the midpoint (V = level |zeta|^2,
    the least-V preimage) plus the rest of the level along a null-space direction P-orthogonal to
    it. A box centred at the origin has no image part and no lifted direction (its P-norm is zero):
    the points are then level times the spare null-space direction, still on the level set (to
    1e-9 relative: the Cholesky factor and the lift's rounding)."""
    from maglev_oc.region.robust_certificate import N_IMAGE, _geometry

    loop = RegulatorLoop()
    feasible = FeasibleSet(model)
    nominal = Procedure2(feasible, loop).run(Reference.setpoint(0.02))
    certifier = RobustCertifier(feasible, loop, max_boxes=1000, ladder=(1.0,))
    P, level = nominal.P, float(nominal.level)
    geo = _geometry(loop, P)
    rng = np.random.default_rng(3)
    centres = np.column_stack([np.zeros(N_IMAGE), rng.uniform(-0.4, 0.4, (N_IMAGE, 5))])
    lo = np.vstack([centres - 0.01, np.zeros((1, 6))])  # the last row: the reference's phase
    hi = np.vstack([centres + 0.01, np.full((1, 6), 0.5)])
    seen = {}

    def rate(P_, reference, plants, pts, phases):
        seen["pts"] = pts
        return np.full(pts.shape[1], -1.0), np.zeros((4, pts.shape[1]))

    monkeypatch.setattr(certifier, "rate", rate)
    plants = PlantSet.point(model.constants)
    which = np.zeros(6, dtype=int)
    assert certifier._refute(nominal.reference, P, level, plants, geo, lo, hi, which) is None
    pts = seen["pts"]
    assert pts.shape == (10, 12) and np.all(np.isfinite(pts))
    np.testing.assert_allclose(np.einsum("in,ij,jn->n", pts, P, pts), level, rtol=1e-9)
    # the centred box's two points are +- sqrt(level) times the spare direction
    np.testing.assert_allclose(pts[:, 0], math.sqrt(level) * geo.spare, rtol=1e-12)
    np.testing.assert_allclose(pts[:, 6], -math.sqrt(level) * geo.spare, rtol=1e-12)
