"""One branch and bound of the FL regulator's certificate (``LevelCertifier.certify``) reports
what it found and nothing else: a refutation names the nonlinear constraint that fails and a
witness, the state of least V on the ellipsoid image's point it sampled, at which the loop's own
constraint Function (not the interval code) is negative and whose V is the reported level, within
{V <= level}; a certification or a spent budget names no constraint and no witness. Verdicts are
ordered along the level. A budget of 100 boxes keeps it to about a second."""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_oc.region.branch_and_bound import LevelCertifier
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.ellipsoid import ellipsoid_image
from maglev_oc.region.feasibility import CONSTRAINT_NAMES, NONLINEAR, FeasibleSet

ORDER = {"certified": 0, "undecided": 1, "refuted": 2}


@pytest.fixture(scope="module")
def certifier(model):
    loop = RegulatorLoop()
    feasible = FeasibleSet(model)
    return feasible, loop, loop.lyapunov_matrix(), LevelCertifier(feasible, loop, max_boxes=100)


def test_a_search_names_a_failing_constraint_only_when_it_refutes(certifier):
    feasible, loop, P, cert = certifier
    ref = Reference.setpoint(0.02)
    fn = feasible.loop_function(loop, ref)
    img = ellipsoid_image(loop, P, cert.rows)
    seen = []
    for level in np.geomspace(1.0, 1e4, 13):  # measured: certified to ~3, refuted from ~30
        b = cert.certify(ref, P, level)
        seen.append(b.status)
        assert b.success == (b.status == "certified")
        if b.status != "refuted":
            assert b.binding == "" and b.witness is None and b.witness_level == math.inf, (level, b.status)
            continue
        assert b.binding in NONLINEAR
        zeta, phase = b.witness[:-1], b.witness[-1]
        z = math.sqrt(level) * img.Pinv_Mt @ np.linalg.solve(img.S, img.chol @ zeta)
        # V of the witness state is the reported level (1e-9: rounding of the solves), inside
        assert z @ P @ z == pytest.approx(b.witness_level, rel=1e-9)
        assert b.witness_level <= level * (1 + 1e-12)
        h = np.asarray(fn(z, phase)).ravel()
        assert h[CONSTRAINT_NAMES.index(b.binding)] < 0, (level, b.binding, h)
    assert set(seen) == set(ORDER)
    ranks = [ORDER[s] for s in seen]
    assert ranks == sorted(ranks), seen
