"""Properties of forces periodic in the position (guide waviness, cogging, detents) in the diagnosis:
the periods set aside for the motor, the waviness's columns and size, and what the travel can
tell apart, checked against central differences of the model, closed forms and beats recomputed
from the logged travel:

- a library context has a mass and a weight on the two axes only; the waviness's columns are the
  gap sensitivity and the slope over the horizontal mass; its amplitude is reported, and beyond
  half a millimetre refused;
- the motor periods set aside are those of the forces on each axis, a peak near a motor period is
  that period within the tolerance asked for, and elsewhere it is left for waviness;
- the waviness period is refined on both sides of the periodogram's guess;
- every force periodic in the position alone has a spatial period; two the travel cannot tell
  apart are never both claimed (unresolved either way); a cogging candidate names its direction.
"""

from __future__ import annotations

import math
import re
from types import SimpleNamespace

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.diagnosis.candidate import LibraryContext
from maglev_oc.diagnosis.currents import ripple_candidate
from maglev_oc.diagnosis.guides import misalignment_candidate, waviness_candidate
from maglev_oc.diagnosis.library import candidate_library
from maglev_oc.diagnosis.magnetics import cogging_candidates
from maglev_oc.diagnosis.pipeline import _periods_on_axis
from maglev_oc.diagnosis.selection import Selection, SelectionSettings, _spatial_period, _unresolved, select
from maglev_oc.diagnosis.trace import Trace, motor_periods, unexplained_periods
from maglev_oc.errors import InputError
from maglev_oc.regression.data import prepare
from maglev_oc.results import Estimate
from tests._diagnosis_cases import SECOND_PERIOD
from tests.test_regression import GAP
from tests.test_statistics_properties import RATE_FRICTION, _log


# --- the residual's periods ----------------------------------------------------------------------------
@pytest.mark.parametrize(("tolerance", "kept"), [(0.015, True), (0.03, False)])
def test_a_peak_near_a_motor_period_is_a_motor_period_within_the_tolerance_asked_for(model, tolerance, kept):
    # a peak 2 % off the slot pitch: beyond a 1.5 % tolerance it is a period no motor period
    # explains (a waviness candidate), within 3 % it is the slot pitch
    t1 = model.params.slot_pitch
    tr = Trace(
        np.array([t1]),
        np.zeros((2, 1)),
        motor_periods(model.params),
        [("horizontal", 1.02 * t1, 0.2)],
        {},
        np.zeros(1),
        np.zeros((2, 1)),
    )
    assert (unexplained_periods(tr, tolerance=tolerance) == [("horizontal", 1.02 * t1)]) is kept


@pytest.mark.parametrize("factor", [0.85, 1.2])
def test_the_waviness_period_is_refined_on_both_sides_of_the_periodograms_guess(
    model, horizontal_all, factor
):
    """A residual that is exactly a guide waviness (0.1 mm at 40 mm, its own acceleration through
    the log's filter, no noise) and a periodogram guess 15 % too long or 20 % too short: the scan
    (+-25 % of the guess, 41 periods) returns the planted period, a point of its grid (1e-9: the
    grid's own rounding)."""
    from maglev_oc.diagnosis.guides import refine_waviness_period, waviness_candidate

    data, design = horizontal_all
    true_period = 0.040
    guess = true_period / factor
    term = waviness_candidate(model, data, true_period).term
    acc = term.acceleration([1e-4, 0.5e-4]).map(data.n)(data.x, data.u, data.du)
    residual = data.filter(np.asarray(acc))
    found = refine_waviness_period(model, data, residual, np.ones(2), design.fit, guess)
    assert found == pytest.approx(true_period, rel=1e-9)


# --- guide waviness: its size and its bound -------------------------------------------------------------
@pytest.mark.parametrize("amplitude", [3e-4, 8e-4])
def test_a_guide_waviness_reports_its_amplitude_and_is_refused_beyond_half_a_millimetre(
    model, two_periodic, amplitude
):
    """w(x3) = a sin(2 pi x3 / P) + b cos(2 pi x3 / P) is the gap change the encoder does not see;
    its size is sqrt(a^2 + b^2) (here a, b = 0.6, 0.8 of the amplitude: exactly the amplitude; with
    the covariance 1e-10 I m^2 its standard error is 1e-5 m whatever the phase), the finding says it
    in micrometres (to two significant digits) over P in millimetres. The working gap is 20 mm: a
    0.3 mm wave is a guide's shape, a 0.8 mm one (4 % of the gap, beyond the library's 0.5 mm bound)
    is refused, and the reason names the waviness and that bound in metres."""
    data, _, _ = two_periodic
    assert GAP == 0.020
    period = 0.031
    cand = waviness_candidate(model, data, period)
    q = np.array([0.6, 0.8]) * amplitude
    cov = np.diag([1e-10, 1e-10])
    e = cand.term.physical_parameters(q, cov, {})
    assert e["amplitude"].value == pytest.approx(amplitude, rel=1e-12)
    assert e["amplitude"].unit == "m"
    assert e["period"].value == period
    said = re.search(r"wave by (\S+) ± (\S+) um over (\S+) mm", cand.describe(e))
    assert said is not None
    assert float(said.group(1)) == pytest.approx(amplitude * 1e6, rel=0.05)  # two significant digits
    assert float(said.group(2)) == pytest.approx(10.0)  # sqrt(1e-10) m, the (a, b) block's standard error
    assert float(said.group(3)) == period * 1e3
    reason = cand.plausible(e)
    if amplitude < 5e-4:
        assert reason is None
    else:
        assert reason is not None and reason.startswith("waviness of 0.0008 m")
        assert float(re.search(r"physical bound (\S+) m", reason).group(1)) == 5e-4


# --- two periodic forces the travel cannot tell apart ---------------------------------------------------
def test_two_periodic_forces_the_travel_cannot_tell_apart_are_not_both_claimed(two_periodic, model):
    """Both forces are planted and each alone passes the held-out, Wald and size tests (the second
    lowers the held-out error by about half). Over the logged travel T (1st to 99th percentile of
    the training positions, recomputed here) their periods drift apart by T |1/P - 1/P'| = 0.79
    cycles, under ``min_beats``: the data do not say which period is there, so the selection
    claims one and refuses the other as not separable, confounded with the chosen one, with the
    beats in its reason. Its own fit beside the chosen one is not what refuses it (variance
    inflation below the 100 bound)."""
    _, lib, design = two_periodic
    settings = SelectionSettings()
    cands = [lib["cogging_horizontal_19mm"], lib["detent_25mm"]]
    sel = select(design, cands, settings)
    travel = float(np.subtract(*np.percentile(design.prepared.x[2, design.fit], [99, 1])))
    beats = travel * abs(1 / model.params.slot_pitch - 1 / SECOND_PERIOD)
    assert 0.5 < beats < settings.min_beats
    first = sel.steps[0].judgements
    assert all(first[c.name].verdict in ("passes", "accepted") for c in cands)
    assert len(sel.selected) == 1
    chosen = sel.selected[0]
    refused = next(c.name for c in cands if c.name != chosen)
    j = sel.last[refused]
    assert j.verdict == "not separable", j.reason
    assert j.confounded_with == (chosen,)
    assert j.vif < settings.max_vif
    assert f"drift apart by {beats:.2f} of a cycle" in j.reason


@pytest.fixture(scope="module")
def ctx(model):
    return LibraryContext(model, prepare([_log(model, friction=0.0)], bandwidth=10.0))


def test_every_force_periodic_in_the_position_alone_has_a_spatial_period(model, ctx):
    """Waviness (geometry) and cogging (periodic) give the period they are fitted at; thrust ripple
    (it scales with the current) and a uniform misalignment (no period) give none."""
    period = {"period": Estimate(0.06, 0.0, "m")}
    wavy = waviness_candidate(model, ctx.data, 0.06)
    assert _spatial_period(wavy, period) == 0.06
    cog = cogging_candidates(ctx)[0]
    assert _spatial_period(cog, {"period": Estimate(0.019, 0.0, "m")}) == 0.019
    assert _spatial_period(ripple_candidate(ctx), period) is None
    assert _spatial_period(misalignment_candidate(ctx), {}) is None
    assert _spatial_period(wavy, {"period": Estimate(-0.06, 0.0, "m")}) is None  # no such period


def test_a_waviness_and_a_detent_the_travel_does_not_tell_apart_are_unresolved_either_way(model, ctx):
    """travel 70 mm x |1/60 mm - 1/57 mm| = 0.06 beats < 1 (``min_beats``): whichever was chosen
    first, the other is unresolved beside it; at 19 mm against 60 mm (2.5 beats) both are told."""
    x3 = np.linspace(-0.035, 0.035, 4001) / 0.98  # 1st-99th percentile span: 70 mm
    design = SimpleNamespace(prepared=SimpleNamespace(x=np.vstack([x3] * 4)), fit=np.ones(x3.size, bool))
    wavy = waviness_candidate(model, ctx.data, 0.060)
    detent = SimpleNamespace(
        axis="horizontal", family="periodic", variable="position", reported_name="detent"
    )
    settings = SelectionSettings()
    out = _unresolved(wavy, {"period": Estimate(0.060, 0.0, "m")}, [(detent, 0.057)], design, settings)
    assert [name for name, _ in out] == ["detent"]
    assert out[0][1] == pytest.approx(0.070 * abs(1 / 0.060 - 1 / 0.057), rel=1e-6)
    told = _unresolved(wavy, {"period": Estimate(0.060, 0.0, "m")}, [(detent, 0.019)], design, settings)
    assert told == []
    # the detent judged beside the chosen waviness: the same pair, the same verdict
    cog = cogging_candidates(ctx)[0]
    back = _unresolved(cog, {"period": Estimate(0.057, 0.0, "m")}, [(wavy, 0.060)], design, settings)
    assert [name for name, _ in back] == [wavy.reported_name]


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


def test_a_cogging_candidate_names_its_direction(ctx):
    """Each of the library's cogging candidates: 'normal (vertical)' for the vertical axis and
    'longitudinal (detent)' for the horizontal, in the term's explanation and in the sentence of
    its finding."""
    physical = {
        "amplitude": Estimate(1.0, 0.1, "N"),
        "at_gap": Estimate(0.019, 0.0, "m"),
        "amplitude_15mm": Estimate(1.5, 0.15, "N"),
    }
    cands = cogging_candidates(ctx)
    assert {c.term.axis for c in cands} == {"vertical", "horizontal"}
    for c in cands:
        words = "normal (vertical)" if c.term.axis == "vertical" else "longitudinal (detent)"
        other = "longitudinal (detent)" if c.term.axis == "vertical" else "normal (vertical)"
        for text in (c.term.explanation, c.describe(physical)):
            assert words in text and other not in text, (c.name, text)
