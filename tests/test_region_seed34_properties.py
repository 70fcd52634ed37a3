"""Region properties from the survivors of the seed-34 mutation run at ef280fd (issue 21), each a
property of a result a user sees, not of one line:

* The linearized loop's Lyapunov matrix solves its own equation A'P + PA = -diag(1/scale^2) to
  round-off (a P off by a factor still certifies the same sets, but every level it reports is off).
* A robust certificate's ratio is its level over the nominal level, whatever the size of the
  levels: scaling P by 1e-6 scales both levels and leaves the ratio.
* F's closed-loop constraints see the gap stoppers: the gap rows are the signed distances of the
  gap to each stopper, negative beyond it.
* The large step's ratio for the Lyapunov P is V(start) over that P's certified level.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from maglev_oc.control.linear_regulator import paper_linear_regulator
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import CONSTRAINT_NAMES, FeasibleSet
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.region.roa import LinearizedLoop
from maglev_oc.region.robust_certificate import certify_robust
from maglev_oc.region.sweep import PlantSet

EPS = np.finfo(float).eps


@pytest.mark.parametrize("gap", [0.012, 0.02, 0.027])
def test_the_linearized_loops_lyapunov_matrix_solves_its_equation(model, gap):
    """A'P + PA + Q = 0 with Q = diag(1/state_scale^2), P symmetric positive definite. Tolerance:
    a backward-stable solver leaves a residual of a few n eps ||A|| ||P|| (n = 10 states); 1e3 eps
    is far above that and far below a P off by any factor (its residual is of the order of ||Q||)."""
    loop = LinearizedLoop(model, paper_linear_regulator(model), Reference.setpoint(gap))
    P = loop.lyapunov_matrix()
    Q = np.diag(1.0 / loop.state_scale() ** 2)
    residual = loop.A.T @ P + P @ loop.A + Q
    scale = np.linalg.norm(loop.A, 2) * np.linalg.norm(P, 2)
    assert np.linalg.norm(residual, 2) <= 1e3 * EPS * scale
    assert np.linalg.norm(Q, 2) > 1e6 * EPS * scale  # the bound is not vacuous against a wrong P
    np.testing.assert_array_equal(P, P.T)
    assert np.linalg.eigvalsh(P)[0] > 0


def test_a_robust_certificates_ratio_is_its_level_over_the_nominal_one_at_any_scale(model):
    """For the nominal plant alone the robust level is the nominal one: ratio 1. V = z'Pz scaled by
    1e-6 gives the same sets with levels 1e-6 as large (both below 1 here), and the same ratio,
    which is always level / nominal_level (to round-off: one division)."""
    feasible, loop = FeasibleSet(model), RegulatorLoop()
    reference = Reference.setpoint(0.02)
    nominal = Procedure2(feasible, loop).run(reference)
    plants = PlantSet.point(model.constants.as_array())
    small = certify_robust(feasible, loop, reference, plants, P=1e-6 * nominal.P)
    assert small.status == "certified"
    assert 0 < small.nominal_level < 1
    # the same set up to Procedure 2's search, which stops on a bracket of about 1 % (1.1 % measured)
    assert small.nominal_level == pytest.approx(1e-6 * nominal.level, rel=0.03)
    assert small.ratio == pytest.approx(small.level / small.nominal_level, rel=4 * EPS)
    assert small.ratio == pytest.approx(1.0, rel=1e-12)


@pytest.mark.parametrize("reference", [Reference.setpoint(0.02), Reference(0.02, 0.01, 0.004, 0.02, 0.3)])
def test_the_loops_gap_constraints_are_the_distances_to_the_stoppers(model, reference):
    """With stoppers at (lo, hi), F's closed-loop rows gap_low and gap_high are x1 - lo and hi - x1
    at the gap x1 = reference gap at the phase + e1, on both sides of each stopper (negative
    beyond it); with no stoppers they are a constant satisfied value. Exact up to the sum's
    round-off (a few eps of the gap)."""
    loop = RegulatorLoop()
    lo, hi = 0.011, 0.029
    rows = [CONSTRAINT_NAMES.index("gap_low"), CONSTRAINT_NAMES.index("gap_high")]
    with_stoppers = FeasibleSet(model, gap_range=(lo, hi)).loop_function(loop, reference)
    without = FeasibleSet(model, gap_range=None).loop_function(loop, reference)
    rng = np.random.default_rng(34)
    for phase in (0.0, 1.1, 4.0):
        centre = reference.gap + reference.gap_amplitude * np.sin(phase + reference.gap_phase)
        for e1 in (-0.012, -0.005, 0.0, 0.004, 0.011):
            z = 1e-4 * rng.standard_normal(10)
            z[0] = e1
            h = np.asarray(with_stoppers(z, phase)).ravel()
            x1 = centre + e1
            np.testing.assert_allclose(h[rows], [x1 - lo, hi - x1], rtol=0, atol=1e-15)
            free = np.asarray(without(z, phase)).ravel()
            assert np.all(free[rows] > 0)
            np.testing.assert_allclose(free[:2], h[:2], rtol=1e-12)  # the other rows do not care


def test_the_large_steps_lyapunov_ratio_is_v_at_the_start_over_the_certified_level(model, monkeypatch):
    """``LargeStepStudy.fl_ratio_lyapunov`` is V(start) / level for Procedure 2's certificate
    with the Lyapunov P at the large step's target (computed here from the same certificate,
    to the round-off of a quadratic form). The runs and maps of the study are stubbed: only the
    certificate is computed."""
    import maglev_oc.region.study as study
    from tests.test_region_study import TINY

    stubbed = ("_linear_regions", "_start_target_maps", "frozen_poles", "step_extremes")
    stubbed += ("_predicted_stoppers",)
    for name in stubbed:
        monkeypatch.setattr(study, name, lambda *a, **k: {})
    monkeypatch.setattr(study, "check_error_states", lambda *a, **k: None)
    config = dataclasses.replace(TINY, sdp=False)
    feasible, loop = FeasibleSet(model), RegulatorLoop()
    run = study._Run(model, config, feasible, loop, np.random.default_rng(0), print, {})
    proc = Procedure2(feasible, loop)
    ls = study._large_step(run, proc, None, None)
    reference = Reference.setpoint(*study.LARGE_STEP_TARGET)
    cert = Procedure2(feasible, loop).run(reference, seed=config.seed)
    assert cert.success
    z0 = loop.error_state(np.array(study.LARGE_STEP_START), np.zeros(6), reference)[:, 0]
    assert ls.fl_ratio_lyapunov == pytest.approx(float(z0 @ cert.P @ z0) / cert.level, rel=1e-12)
    assert ls.fl_ratio_sdp == np.inf  # no SDP asked for
