"""Terms of the regression layer as the papers write them, evaluated (issue 21): the normal
cogging of 000 eq. (9) with the geometry it is given (or the papers' when none), and the
constant-force terms saying what they stand for on each axis. Under 0.5 s of CPU."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from maglev_oc.model.parameters import StageParameters
from maglev_oc.regression.terms import cogging_term, constant_acceleration


def _acc(term, x, p):
    return term.acceleration(p)(x, np.zeros(2), np.zeros(2)).full().ravel()


@pytest.mark.parametrize("given", [None, "wider"])
def test_cogging_is_periodic_over_two_slot_pitches_of_the_given_stage(given):
    """x2' = -(a_s sin(pi x3 / t1) + a_c cos(pi x3 / t1)) (g_ref / x1)^3 / M_v (000 eq. (9)): at
    x3 = t1 / 2 with a_s = 1 N it is -1 / M_v at the reference gap, 8 times that at half the gap,
    of the other sign at x3 = 3 t1 / 2, and the same again one period 2 t1 later; t1 and M_v are
    those of the parameters given (default the papers')."""
    p = StageParameters()
    if given == "wider":
        p = dataclasses.replace(p, slot_pitch=1.5 * p.slot_pitch, mass_vertical=2.0 * p.mass_vertical)
    term = cogging_term(None if given is None else p, reference_gap=0.015)
    t1, mv = p.slot_pitch, p.mass_vertical
    q = np.array([1.0, 0.0])
    at = _acc(term, np.array([0.015, 0.0, t1 / 2, 0.0]), q)
    assert at == pytest.approx([-1.0 / mv, 0.0], rel=1e-12)
    assert _acc(term, np.array([0.0075, 0.0, t1 / 2, 0.0]), q)[0] == pytest.approx(-8.0 / mv, rel=1e-12)
    assert _acc(term, np.array([0.015, 0.0, 1.5 * t1, 0.0]), q)[0] == pytest.approx(1.0 / mv, rel=1e-12)
    later = _acc(term, np.array([0.015, 0.0, t1 / 2 + 2 * t1, 0.0]), q)
    assert later[0] == pytest.approx(at[0], rel=1e-9)
    # the cosine part peaks at x3 = 0
    assert _acc(term, np.array([0.015, 0.0, 0.0, 0.0]), np.array([0.0, 1.0]))[0] == pytest.approx(-1 / mv)
    assert math.isclose(term.physical_parameters(q, np.eye(2))["period"].value, 2 * t1, rel_tol=1e-12)


def test_a_constant_force_says_what_it_stands_for_on_its_axis():
    """A vertical constant acceleration is a weight or gravity error, a horizontal one guides
    that are not level; each acts on its own axis only."""
    v, h = constant_acceleration("vertical"), constant_acceleration("horizontal")
    assert "weight" in v.explanation and "level" not in v.explanation
    assert "level" in h.explanation and "weight" not in h.explanation
    x = np.array([0.02, 0.0, 0.01, 0.0])
    assert _acc(v, x, np.array([0.3])) == pytest.approx([0.3, 0.0])
    assert _acc(h, x, np.array([0.3])) == pytest.approx([0.0, 0.3])
