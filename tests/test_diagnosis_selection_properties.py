"""Selection's judgement of a periodic candidate beside effects already chosen
(``maglev_oc.diagnosis.selection.judge``), on a log whose answer is exact: the horizontal sweep of
``tests/test_statistics_properties._log`` with a cogging force planted at the slot pitch
(0.02 m/s^2, ~0.03 N). Two periods P, P' are told apart when the logged travel T (1st to 99th
percentile of the training positions, recomputed here) sees them drift apart by at least
``min_beats`` cycles, T |1/P - 1/P'|; otherwise the candidate is not separable and names the
effect it is confounded with. A candidate the held-out test rejects gets no Wald statistic.
Numpy and one design, about a second."""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest

from maglev_oc.diagnosis.guides import waviness_candidate
from maglev_oc.diagnosis.selection import SelectionSettings, judge
from maglev_oc.regression.data import prepare
from maglev_oc.regression.design import build_design
from maglev_oc.regression.solve import fit_subset, residuals
from tests.test_statistics_properties import _log


@pytest.fixture(scope="module")
def cogged(model):
    """(design, library by name): the cogging and friction candidates' columns beside C1."""
    return cogged_design(model)


def cogged_design(model):
    """(design, library by name): the horizontal sweep with a cogging force planted at the slot pitch
    (0.02 m/s^2), the cogging and friction candidates' columns beside C1, a quarter held out."""
    from maglev_oc.diagnosis.library import candidate_library

    period = model.params.slot_pitch
    log = _log(model, friction=0.0, force=lambda x3: 0.02 * np.sin(2 * math.pi * x3 / period + 0.5))
    data = prepare([log], bandwidth=10.0)
    lib = {c.name: c for c in candidate_library(model, data)}
    fit, hold = data.masks(0.25)
    terms = (lib["cogging_horizontal_19mm"].term, lib["guide_friction_horizontal"].term)
    design = build_design(data, model, estimate=("C1",), terms=terms, fit=fit, holdout=hold)
    return design, lib


def _judge(design, cand, settings, beside=(), friction_axes=frozenset(), periodic=()):
    base = fit_subset(design, ["base"])
    r0 = residuals(design, base)[:, design.holdout]
    mse0 = np.maximum(np.mean(r0**2, axis=1), 1e-30)
    return judge(
        design,
        cand,
        ["base"],
        base,
        r0,
        mse0,
        settings,
        beside=beside,
        friction_axes=friction_axes,
        periodic=periodic,
    )


def test_a_period_the_travel_cannot_tell_from_a_chosen_ones_is_confounded_with_it(cogged, model):
    """Alone, the planted cogging passes; beside a chosen horizontal effect whose period drifts
    from its own by min_beats x (1 - 1e-3) cycles over the travel it is not separable and
    confounded with that effect, by min_beats x (1 + 1e-3) it passes (1e-3: far above the rounding
    of the percentiles, far below the steps of the travel between samples); an effect on the
    other axis never confounds it, whatever its period."""
    design, lib = cogged
    cog, other = lib["cogging_horizontal_19mm"], lib["cogging_horizontal_57mm"]
    settings = SelectionSettings()
    assert _judge(design, cog, settings).verdict == "passes"
    travel = float(np.subtract(*np.percentile(design.prepared.x[2, design.fit], [99, 1])))
    period = model.params.slot_pitch
    for factor, verdict in ((1 - 1e-3, "not separable"), (1 + 1e-3, "passes")):
        beats = factor * settings.min_beats
        p_other = 1.0 / (1.0 / period - beats / travel)  # T |1/P - 1/P'| = beats
        j = _judge(design, cog, settings, beside=[(other, p_other)])
        assert j.verdict == verdict, (factor, j.reason)
        assert j.confounded_with == ((other.reported_name,) if verdict == "not separable" else ())
        # the travel that would tell them apart: min_beats cycles of drift, travel / factor
        expected = travel / factor if verdict == "not separable" else None
        assert j.travel_needed == (None if expected is None else pytest.approx(expected, rel=1e-9))
        # a force at a motor pitch in the pool is not a waviness the residual showed: no hold
        assert _judge(design, cog, settings, periodic=[(other, p_other)]).verdict == "passes"
    vertical = lib["cogging_vertical_19mm"]
    assert _judge(design, cog, settings, beside=[(vertical, period)]).verdict == "passes"


def test_a_true_cogging_keeps_its_place_beside_a_waviness_that_explains_less(cogged, model):
    """The planted 19 mm cogging beside a guide waviness in the pool at a period the travel does
    not tell from its own (0.9 of a cycle): the waviness in its place explains less of the held-out
    error, so the cogging passes; a candidate that explains nothing (the base model's own test)
    is matched by any waviness that explains something (selection._explains_as_much)."""
    from maglev_oc.diagnosis.selection import _explains_as_much, _held_out_test

    design, lib = cogged
    cog = lib["cogging_horizontal_19mm"]
    settings = SelectionSettings()
    travel = float(np.subtract(*np.percentile(design.prepared.x[2, design.fit], [99, 1])))
    p_wavy = 1.0 / (1.0 / model.params.slot_pitch - 0.9 * settings.min_beats / travel)
    wavy = waviness_candidate(model, design.prepared, p_wavy)
    data = design.prepared
    with_wavy = build_design(
        data,
        model,
        estimate=("C1",),
        terms=(*design.terms, wavy.term),
        fit=design.fit,
        holdout=design.holdout,
    )
    j = _judge(with_wavy, cog, settings, periodic=[(wavy, p_wavy)])
    assert j.verdict == "passes", j.reason
    base = fit_subset(with_wavy, ["base"])
    r0 = residuals(with_wavy, base)[:, with_wavy.holdout]
    axes = np.array([1])
    own = _held_out_test(with_wavy, ["base", cog.name], r0, None, None, axes)
    alt = _held_out_test(with_wavy, ["base", wavy.name], r0, None, None, axes)
    assert alt.pooled_axes[1] < own.pooled_axes[1]
    assert not _explains_as_much(with_wavy, wavy, own, ["base"], r0, None, None, axes)
    nothing = _held_out_test(with_wavy, ["base"], r0, None, None, axes)
    assert _explains_as_much(with_wavy, wavy, nothing, ["base"], r0, None, None, axes) == (
        alt.pooled_axes[1] >= 0
    )


def test_a_candidate_the_held_out_test_rejects_has_no_wald_statistic(cogged):
    """Friction on a log without friction: the held-out error does not fall enough, its
    covariance is never estimated, and it is reported with a Wald statistic of zero at any alpha
    (not a number it was never given), below every threshold."""
    design, lib = cogged
    for alpha in (0.05, 0.9):
        j = _judge(design, lib["guide_friction_horizontal"], SelectionSettings(alpha=alpha))
        assert j.verdict == "not significant"
        assert j.wald == 0.0 and j.wald < j.wald_threshold


def test_evidence_on_an_axis_with_claimed_friction_does_not_count_for_a_candidate_it_hides(cogged):
    """A candidate not judged beside friction (the amplifiers' lag: there the regulator makes its
    column the friction's viscous part) is judged on the axes without claimed friction. The
    planted cogging, so marked, passes beside friction on the vertical axis (which it does not act
    on) and is not separable, confounded with the horizontal friction, beside friction on its own
    axis; unmarked, it passes beside either (what the friction axes are must not matter then).
    A marked candidate the data do not show (friction on the frictionless log) stays not
    significant beside friction on its axis: only one that passes is confounded with it."""
    design, lib = cogged
    settings = SelectionSettings()
    vertical, horizontal = frozenset({0}), frozenset({1})  # rows of regression.base.AXES
    cog = lib["cogging_horizontal_19mm"]
    hidden = dataclasses.replace(cog, beside_friction=False)
    assert _judge(design, hidden, settings, friction_axes=vertical).verdict == "passes"
    j = _judge(design, hidden, settings, friction_axes=horizontal)
    assert j.verdict == "not separable", j.reason
    assert j.confounded_with == ("guide_friction_horizontal",)
    assert "viscous" in j.reason and "horizontal" in j.reason
    for axes in (vertical, horizontal):
        assert _judge(design, cog, settings, friction_axes=axes).verdict == "passes"
    # one the data do not show keeps its verdict: only what passes is confounded with the friction
    viscous = dataclasses.replace(lib["guide_friction_horizontal"], beside_friction=False)
    j = _judge(design, viscous, settings, friction_axes=horizontal)
    assert j.verdict == "not significant" and j.confounded_with == (), j.reason


def _spring_selection(model, force, settings=None):
    """select() over the cable carrier alone (a line in the position, ``rival_span``) on the
    horizontal sweep with ``force`` [m/s^2] of the true position planted, the position's generic
    probe in the design as its rival."""
    from maglev_oc.diagnosis.library import candidate_library
    from maglev_oc.diagnosis.probes import smooth_probes
    from maglev_oc.diagnosis.selection import select

    data = prepare([_log(model, friction=0.0, force=force)], bandwidth=10.0)
    cable = next(c for c in candidate_library(model, data) if c.name == "cable_carrier_force")
    probe = smooth_probes(data)[("horizontal", "position")]
    fit, hold = data.masks(0.25)
    design = build_design(data, model, estimate=("C1",), terms=(cable.term, probe), fit=fit, holdout=hold)
    return select(design, [cable], settings or SelectionSettings(), {("horizontal", "position"): probe.name})


def test_a_line_in_the_position_is_a_spring_only_when_nothing_further_depends_on_the_position(model):
    """A spring along the track spans the first two terms of the position's generic rival, so the
    equal-size comparison cannot refuse it: what is left must. A planted spring force (a line,
    0.02 m/s^2 at the ends of the sweep) is claimed; the same line plus a bow of the position
    (a Legendre P2 of the same size) is not: refused as not specific, on the position, though the
    line alone would pass the forward step. Without ``judge_lines`` (the diagnosis's selections
    before its search for guide waviness) the bowed line is claimed."""
    travel = 0.5 * float(np.ptp(_log(model, friction=0.0).x[2]))
    centre = float(np.mean(_log(model, friction=0.0).x[2][[0, -1]]))

    def line(x3):
        return -0.02 * (x3 - centre) / travel

    def bowed(x3):
        s = (x3 - centre) / travel
        return line(x3) + 0.02 * (1.5 * s**2 - 0.5)

    assert _spring_selection(model, line).selected == ["cable_carrier_force"]
    sel = _spring_selection(model, bowed)
    assert sel.selected == []
    j = sel.last["cable_carrier_force"]
    assert j.verdict == "not specific" and "position" in j.reason, j.reason
    early = _spring_selection(model, bowed, SelectionSettings(judge_lines=False))
    assert early.selected == ["cable_carrier_force"]


def test_a_periodic_force_on_one_half_of_the_travel_is_no_cogging(model):
    """Cogging repeats with the stator's slots, so it is the same all along the travel
    (``selection._drift_along_travel``). The planted slot-pitch force at 0.4 of its size below the
    middle of the sweep and full size above is refused as not specific, the reason giving each
    half's share of the whole-log fit in the planted ratio 1 : 0.4 (within 10 %: the filtered
    columns straddle the split for a filter length); at one size all along it passes (the first
    test). With the change allowed up to 10x its size it is still refused, for its size (a factor
    2.5 between the halves, above ``max_half_ratio`` 2); with a factor 3 allowed too, it passes."""
    from maglev_oc.diagnosis.library import candidate_library

    period = model.params.slot_pitch
    x3 = _log(model, friction=0.0).x[2]
    middle = float(np.median(x3))

    def one_sided(x):
        return 0.03 * np.sin(2 * math.pi * x / period + 0.5) * np.where(x > middle, 1.0, 0.4)

    data = prepare([_log(model, friction=0.0, force=one_sided)], bandwidth=10.0)
    lib = {c.name: c for c in candidate_library(model, data)}
    fit, hold = data.masks(0.25)
    cog = lib["cogging_horizontal_19mm"]
    design = build_design(data, model, estimate=("C1",), terms=(cog.term,), fit=fit, holdout=hold)
    j = _judge(design, cog, SelectionSettings())
    assert j.verdict == "not specific", j.reason
    low, high = (int(s) for s in re.findall(r"(\d+)% and (\d+)% of its whole-log size", j.reason)[0])
    assert high / low == pytest.approx(1.0 / 0.4, rel=0.1), j.reason
    # its size changes by 1 / 0.4 = 2.5 between the halves: refused on that alone, above a factor 2
    j = _judge(design, cog, SelectionSettings(max_half_change=10.0))
    assert j.verdict == "not specific" and "keeps its size" in j.reason, j.reason
    assert (
        _judge(design, cog, SelectionSettings(max_half_change=10.0, max_half_ratio=3.0)).verdict == "passes"
    )
