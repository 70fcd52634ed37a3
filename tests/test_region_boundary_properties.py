"""The boundary search that bounds a certificate from above (maglev_oc.region.boundary): its
rays start where the constraint first fails, what it returns lies on the boundary, and a search
that meets no boundary says so."""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_oc.errors import InputError
from maglev_oc.region.boundary import BoundaryMinimizer
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.ellipsoid import ellipsoid_image
from maglev_oc.region.feasibility import NONLINEAR, FeasibleSet
from maglev_oc.results import check_result

REF = Reference.setpoint(0.02)


@pytest.fixture(scope="module")
def search(model):
    loop = RegulatorLoop()
    return BoundaryMinimizer(FeasibleSet(model), loop), loop.lyapunov_matrix()


@pytest.mark.parametrize("constraint", NONLINEAR)
def test_each_ray_starts_at_the_first_point_where_the_constraint_fails(search, constraint):
    minimizer, P = search
    img = ellipsoid_image(minimizer.loop, P)
    F = minimizer.loop.offset_coefficients(REF)
    fn = minimizer.feasible.loop_function(minimizer.loop, REF)
    j = NONLINEAR.index(constraint)
    rng = np.random.default_rng(4)
    crossed = 0
    for d in rng.standard_normal((12, 3)):
        d /= np.linalg.norm(d)
        start = minimizer._ray_start(img, F, d, 0.0, j)
        if start is None:  # a ray that leaves the gap domain before the constraint fails
            continue
        crossed += 1
        z = start[0][:-1]
        assert np.asarray(fn(z, 0.0)).ravel()[j] < 0  # infeasible at the start
        # and feasible a grid step (a factor 1e6^(1/240) along the ray) closer to the set-point
        assert np.asarray(fn(z / 10 ** (6 / 240), 0.0)).ravel()[j] >= 0
    assert crossed >= 3


def test_the_least_v_found_is_on_the_boundary(search):
    minimizer, P = search
    res = minimizer.minimize(REF, P, "headroom", starts=6)
    check_result(res)
    assert res.success and res.status == "found" and 0 < res.converged <= res.starts == 6
    fn = minimizer.feasible.loop_function(minimizer.loop, REF)
    h = np.asarray(fn(res.state, res.phase)).ravel()
    assert abs(h[1]) < 1e-6  # [A^2]: IPOPT's tolerance 1e-10 on the scaled problem
    assert res.state @ P @ res.state == pytest.approx(res.level, rel=1e-9)
    assert res.level == pytest.approx(res.levels.min(), rel=0)


def test_a_search_that_meets_no_boundary_says_so(search):
    minimizer, P = search
    res = minimizer.minimize(REF, P, "margin", starts=0)
    check_result(res)
    assert not res.success and res.status == "not_found" and "no start" in res.message
    assert res.level == math.inf and res.state is None and res.converged == 0


def test_a_ray_that_meets_no_boundary_is_skipped_not_the_end_of_the_search(search, monkeypatch):
    # the first ray that reaches the boundary made to leave the gap domain before its constraint
    # fails instead, as rays do (test_each_ray_starts_...): the rays after it still search, from the
    # same phases (drawn for every ray), so they find the same levels as before, less at most the
    # one of the ray made to miss
    minimizer, P = search
    real = minimizer._ray_start
    reached = []

    def record(img, F, d, phi0, j):
        start = real(img, F, d, phi0, j)
        reached.append(start is not None)
        return start

    monkeypatch.setattr(minimizer, "_ray_start", record)
    full = minimizer.minimize(REF, P, "headroom", starts=6)
    first = reached.index(True)
    assert first < 5 and full.converged >= 2  # a ray after it that converges
    calls = []

    def misses_once(img, F, d, phi0, j):
        calls.append(d)
        return None if len(calls) == first + 1 else real(img, F, d, phi0, j)

    monkeypatch.setattr(minimizer, "_ray_start", misses_once)
    res = minimizer.minimize(REF, P, "headroom", starts=6)
    check_result(res)
    assert len(calls) == 6  # every ray was tried
    assert res.success and res.starts == 6 and res.converged >= full.converged - 1
    left = list(full.levels)
    for level in res.levels:  # each level found again is one of the full search's (IPOPT: 1e-9)
        k = int(np.argmin(np.abs(np.array(left) - level)))
        assert left[k] == pytest.approx(level, rel=1e-9)
        left.pop(k)
    assert res.level == pytest.approx(res.levels.min(), rel=0) and res.level >= full.level * (1 - 1e-9)


def test_without_a_current_limit_only_the_margin_has_a_boundary_to_search(model, search):
    """With the current limit switched off the headroom is no constraint (h = 1 everywhere), so
    the minimizer searches the margin R >= 0 alone and refuses the headroom, naming the constraints
    it has; with the limit on it has both."""
    _, P = search
    loop = RegulatorLoop()
    free = BoundaryMinimizer(FeasibleSet(model, current_limit=None), loop)
    with pytest.raises(InputError, match=r"constraint must be one of \['margin'\], got 'headroom'"):
        free.minimize(REF, P, "headroom", starts=1)
    limited, _ = search
    assert set(limited._solvers) == set(NONLINEAR)
