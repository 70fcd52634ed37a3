"""One branch-and-bound pass of the microstepper's region (``MicrostepperRegion.certify``) says
what it found and nothing else: a refutation names the constraint that fails and a state of
{V <= level} at which the controller's own transformation breaks it; a certification or a pass
that ran out of boxes names no constraint and no state; and the verdicts are ordered along the
level (what is certified at c is certified below c, what is refuted at c is refuted above).
A budget of one pass (256 boxes) keeps it to about a second."""

from __future__ import annotations

import numpy as np
import pytest

from maglev_oc.region.microstepper import MICROSTEPPER_CONSTRAINTS, MicrostepperRegion
from tests.test_microstepper_region import PLATFORM, _violations

ORDER = {"certified": 0, "undecided": 1, "refuted": 2}


@pytest.mark.parametrize("setpoint", [(0.0, 0.0, 0.025), (0.04, -0.04, 0.021)])
def test_a_pass_names_a_failing_constraint_only_when_it_refutes(setpoint):
    region = MicrostepperRegion(PLATFORM)
    seen = []
    for level in np.geomspace(1e-2, 1e3, 16):
        status, boxes, binding, state = region.certify(setpoint, level, max_boxes=1)
        assert boxes > 0
        seen.append(status)
        if status == "refuted":
            assert binding in MICROSTEPPER_CONSTRAINTS
            # inside the level set (1e-9: rounding of the quadratic form), and failing there
            # the constraint it names, judged by the controller's Function, not the interval code
            assert state @ region.P @ state <= level * (1 + 1e-9)
            assert _violations(region, setpoint, state[:, None])[binding] == 1, (level, binding)
        else:
            assert status in ("certified", "undecided")
            assert binding == "" and state is None, (level, status, binding)
    # all three verdicts occur along the sweep (measured: certified up to ~0.3, refuted from ~10)
    assert set(seen) == set(ORDER)
    ranks = [ORDER[s] for s in seen]
    assert ranks == sorted(ranks), seen


def test_the_reported_box_count_is_the_work_of_every_pass():
    """``largest_level`` reports the boxes of all its branch-and-bound passes: the set-point's own
    check, the pass at the refuted level and each bisection step. The passes are counted here
    beside the method (the same object's ``certify``, observed, not re-implemented). A budget
    of 256 boxes a pass and a 30 % bracket keep it to a few passes."""
    region = MicrostepperRegion(PLATFORM)
    seen = []
    certify = region.certify

    def counted(*args, **kwargs):
        out = certify(*args, **kwargs)
        seen.append(out[1])
        return out

    region.certify = counted
    res = region.largest_level((0.0, 0.0, 0.025), rel_tol=0.3, max_boxes=1)
    assert len(seen) >= 3, seen  # the set-point, the refuted level, at least one bisection step
    assert all(b > 0 for b in seen)
    assert res.boxes == sum(seen), (res.boxes, seen)


def test_the_constraint_functions_are_the_margin_and_each_pairs_current_headroom():
    """The branch and bound's constraints h(l) (``_h_of_l``: the margin R and limit^2 - |i|^2 of
    each motor pair) against the controller's own transformation evaluated here: at random
    points of l = (gap error, v) around three gaps, each entry equals its definition (1e-9
    relative: the same arithmetic in another order), so a wrong sign or a swapped pair in one
    headroom is seen wherever that pair carries current."""
    from tests.test_microstepper_region import TRANSFORM

    region = MicrostepperRegion(PLATFORM)
    limit2 = region.current_limit**2
    rng = np.random.default_rng(5)
    for gap0 in (0.015, 0.021, 0.03):
        for ell in rng.normal(0.0, [1e-3, 2.0, 2.0, 2.0], (20, 4)):
            h = np.asarray(region._h_of_l(ell, gap0)).ravel()
            u, R = (np.asarray(a).ravel() for a in TRANSFORM(gap0 + ell[0], ell[1:4]))
            want = [float(R[0]), limit2 - u[0] ** 2 - u[1] ** 2, limit2 - u[2] ** 2 - u[3] ** 2]
            assert h == pytest.approx(want, rel=1e-9, abs=1e-9), (gap0, ell)


@pytest.mark.parametrize("budget", [64, 1024])
def test_the_bisection_closes_its_bracket_when_the_box_budget_binds(budget):
    """When the box budget, not a refutation, stops the proof (at 64 and 1024 boxes a pass the
    set-point (0, 0, 25 mm) is certified near 0.71 and 1.83, far below the refuted 4.33), the
    level returned is the bisection's: certified with that budget, and not certified 10 % above
    it (``rel_tol`` 5 %: the bracket is closed to 5 %, so 1.1x lies above the budget's limit).
    A bisection that stops early or halves the wrong end returns a level the same budget still
    certifies at 1.1x."""
    region = MicrostepperRegion(PLATFORM)
    setpoint = (0.0, 0.0, 0.025)
    res = region.largest_level(setpoint, rel_tol=0.05, max_boxes=budget)
    assert res.success and res.level < 0.5 * res.refuted_level, res.message
    assert "box budget spent" in res.message
    assert region.certify(setpoint, res.level, max_boxes=budget)[0] == "certified"
    assert region.certify(setpoint, 1.1 * res.level, max_boxes=budget)[0] != "certified"
