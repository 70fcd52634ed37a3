"""Properties of ``maglev_oc.diagnosis`` written against the survivors of the seed-42 mutation-testing run
(``bench/mutation.py``, mutmut 3, made from commit 35ae479): each test states a property of a result a
user or a reviewer relies on, not the mutated token.

* A library's masses and weights are asked for by axis name, and only the two axes have one: any other
  name is refused with the name in the message (it used to get the horizontal mass, so a misspelt
  "horizontal" went unnoticed, and "vertical" misspelt got the wrong mass silently).
* Guide waviness moves both accelerations through the model's gap sensitivity and, along the sloping
  guides, pushes the platform with the horizontal weight less the normal force over the horizontal
  mass: its columns against central differences of the model and the slope in closed form.
* A force of the library at a motor period sets that period aside, in the search for guide waviness,
  only on the axis that force acts on: the periods per axis as the selection sized them, and the
  residual peaks that are then left for waviness.

Synthetic inputs only (one 30 s synthetic log for the library's ranges), about a second in all.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.diagnosis.candidate import LibraryContext
from maglev_oc.diagnosis.library import candidate_library, waviness_candidate
from maglev_oc.diagnosis.pipeline import _periods_on_axis
from maglev_oc.diagnosis.selection import Selection
from maglev_oc.diagnosis.trace import Trace, motor_periods, unexplained_periods
from maglev_oc.errors import InputError
from maglev_oc.regression.data import prepare
from tests.test_statistics_properties import RATE_FRICTION, _log

WAVINESS_TOLERANCE = 0.03
"""The relative distance from a motor period within which the pipeline sets a residual peak aside
(``_waviness_periods`` calls ``unexplained_periods(..., tolerance=0.03, ...)``)."""


@pytest.fixture(scope="module")
def data(model):
    """A 30 s synthetic log prepared for the fits: what a library takes its ranges from."""
    return prepare([_log(model, friction=RATE_FRICTION)], bandwidth=10.0)


# --- masses by axis ---------------------------------------------------------------------------------------
def test_a_library_context_has_a_mass_and_a_weight_on_the_two_axes_only(model, data):
    """M_v and M_h (and M g) for "vertical" and "horizontal"; "both" (an effect's axis, which has no
    one mass) or a misspelt axis is refused with the name it was given."""
    ctx = LibraryContext(model, data)
    p = model.params
    assert ctx.mass("vertical") == p.mass_vertical
    assert ctx.mass("horizontal") == p.mass_horizontal
    assert ctx.weight("horizontal") == pytest.approx(p.mass_horizontal * p.gravity, rel=1e-15)
    for axis in ("both", "Horizontal", "horizonal"):
        with pytest.raises(InputError, match=repr(axis)):
            ctx.mass(axis)
        with pytest.raises(InputError, match=repr(axis)):
            ctx.weight(axis)


# --- guide waviness's physics on each axis ----------------------------------------------------------------
def test_the_waviness_columns_are_the_gap_sensitivity_and_the_slope_over_the_horizontal_mass(model, data):
    """At a state off equilibrium (thrust current on, the normal force 101 N, not the weight) and a
    60 mm waviness w(x3) = a sin(k x3) + b cos(k x3): the vertical acceleration changes by
    d(x2')/d(x1) w and the horizontal one by d(x4')/d(x1) w + w'(x3) (M_h G - F_n) / M_h, with
    F_n = M_v (G - x2'_model) (the platform on a locally sloping guide, as for a uniform slope).

    The gap sensitivities by central differences of the model with h = 1e-7 m: the truncation
    h^2 f''' / 6 is about 5e-11 relative (measured 5e-9 at h = 1e-6 m, scaling with h^2) and the
    rounding eps |f| / (h |f'|) about 1e-11 (the column and this sum agree to 3e-11 measured); 1e-8
    covers both. The masses differ by a factor 2.7,
    so the vertical mass in the slope term would be off by 82 % here (checked below)."""
    p = model.params
    period = 0.06
    cand = waviness_candidate(model, data, period)
    x = np.array([0.015, 0.0, 0.013, 0.0])
    u = np.array([0.8, 1.2])
    q = np.array([1.2e-4, -0.7e-4])  # [m] a, b
    column = np.asarray(cand.term.function(x, u, np.zeros(2), q)).ravel()

    k = 2 * math.pi / period
    w = q[0] * math.sin(k * x[2]) + q[1] * math.cos(k * x[2])
    slope = k * (q[0] * math.cos(k * x[2]) - q[1] * math.sin(k * x[2]))
    h = 1e-7
    step = np.array([h, 0.0, 0.0, 0.0])  # along the gap
    sensitivity = (model.dynamics(x + step, u) - model.dynamics(x - step, u)).ravel() / (2 * h)
    normal = p.mass_vertical * (p.gravity - model.dynamics(x, u).ravel()[1])
    vertical = sensitivity[1] * w
    horizontal = sensitivity[3] * w + slope * (p.mass_horizontal * p.gravity - normal) / p.mass_horizontal
    assert_allclose(column, [vertical, horizontal], rtol=1e-8)

    with_vertical_mass = sensitivity[3] * w + slope * (p.mass_vertical * p.gravity - normal) / p.mass_vertical
    assert abs(with_vertical_mass / horizontal - 1) > 0.5  # the test tells the two masses apart


# --- motor periods set aside per axis ---------------------------------------------------------------------
def _sized_by_the_selection(library):
    """A selection that judged every candidate: each one's physical parameters from its own
    conversion (a periodic force's period is the one it was built with, whatever its coefficients)."""
    last = {}
    for cand in library:
        n = len(cand.term.parameter_names)
        physical = cand.term.physical_parameters(np.full(n, 1e-3), 1e-8 * np.eye(n), {})
        last[cand.name] = SimpleNamespace(name=cand.name, physical=physical)
    return Selection(steps=[], base=None, final=None, last=last)


def test_the_motor_periods_set_aside_are_those_of_the_forces_on_each_axis(model, data):
    """The library's forces of the position at a motor period: the normal cogging on the vertical axis
    at the slot pitch t1 and at 2 t1 (000 eq. (9)); the detent on the horizontal axis at t1 and at the
    pole pitch tau, and the thrust ripple there at t1. Guide waviness (a geometry, its period found in
    the residual) and the forces with no period set nothing aside. The periods are the model's own,
    passed through unchanged (rel 1e-12)."""
    wavy = waviness_candidate(model, data, 0.039)
    library = [*candidate_library(model, data), wavy]
    on_axis = _periods_on_axis(library, _sized_by_the_selection(library))
    t1, tau = model.params.slot_pitch, model.params.pole_pitch
    assert set(on_axis) == {"vertical", "horizontal"}
    assert_allclose(sorted(on_axis["vertical"]), [t1, 2 * t1], rtol=1e-12)
    assert_allclose(sorted(on_axis["horizontal"]), [t1, t1, tau], rtol=1e-12)


def test_a_peak_near_a_motor_period_is_left_for_waviness_on_the_axis_with_no_force_there(model, data):
    """A 39 mm guide waviness (2.4 % from 2 t1 = 38.1 mm, within the pipeline's 3 %) shows on both
    axes, and the horizontal residual also has a larger peak at 57.6 mm (0.8 % from the pole pitch).
    With the library's periods per axis: the vertical 39 mm peak is a normal cogging's period and the
    57.6 mm one the detent's, both set aside; the horizontal 39 mm peak, where no force of the library
    has a period near it, is the one left for waviness. Every motor period on both axes (no
    ``on_axis``) would have set it aside as well: the waviness would not be searched for."""
    library = candidate_library(model, data)
    on_axis = _periods_on_axis(library, _sized_by_the_selection(library))
    trace = Trace(
        periods=np.zeros(0),
        spectrum=np.zeros((2, 0)),
        motor_periods=motor_periods(model.params),
        peaks=[("horizontal", 0.0576, 0.30), ("vertical", 0.039, 0.25), ("horizontal", 0.039, 0.20)],
        binned={},
        lags=np.zeros(0),
        lag_correlation=np.zeros((2, 0)),
    )
    assert unexplained_periods(trace, tolerance=WAVINESS_TOLERANCE, on_axis=on_axis) == [
        ("horizontal", 0.039)
    ]
    assert unexplained_periods(trace, tolerance=WAVINESS_TOLERANCE) == []
