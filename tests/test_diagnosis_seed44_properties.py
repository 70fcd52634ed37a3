"""Properties of ``maglev_oc.diagnosis`` from the survivor of the seed-44 mutation run: a
candidate's own gain (the relative drop of the held-out error on the axes it acts on, the figure
``min_gain`` is held to) is the mean of its finite per-axis gains, and none at all where no axis
has one (an axis it does not act on, or a locked one, is NaN): a candidate that acts on no axis
of the log is never credited with a drop it cannot have made."""

from __future__ import annotations

import numpy as np
import pytest

from maglev_oc.diagnosis.selection import SelectionSettings, _own_gain

NAN = np.nan


@pytest.mark.parametrize(
    ("gains", "own"),
    [
        ([NAN, NAN], 0.0),
        ([0.02, NAN], 0.02),
        ([NAN, 0.3], 0.3),
        ([0.02, 0.04], 0.03),
        ([-0.01, NAN], -0.01),
    ],
)
def test_a_candidates_own_gain_is_the_mean_over_the_axes_it_acts_on(gains, own):
    assert _own_gain(np.array(gains)) == pytest.approx(own, abs=1e-15)


def test_a_candidate_with_no_gain_on_any_axis_does_not_pass_the_gain_threshold():
    assert _own_gain(np.full(2, NAN)) < SelectionSettings().min_gain


@pytest.mark.parametrize("form", ["full", "stribeck"])
def test_a_viscous_part_within_two_standard_errors_of_zero_is_reported_as_not_resolved(form):
    """The friction's finding names its viscous part as found only when it is 2 standard errors
    from zero (the independent generator's vertical friction: 48 ± 81 N s/m for a true 10; a slow
    gap axis does not resolve it), else as not resolved, with the estimate beside it."""
    from maglev_oc.diagnosis.guides import _friction_words
    from maglev_oc.results import Estimate

    est = {
        "coulomb": Estimate(1.78, 0.65, "N"),
        "breakaway": Estimate(2.4, 0.7, "N"),
        "viscous": Estimate(47.6, 81.0, "N s/m"),
    }
    words = _friction_words("vertical", form, 0.05)(est)  # a fast axis: no caveat
    assert words.startswith("The vertical linear guides resist motion with 1.8 ± 0.7 N of Coulomb friction")
    assert words.endswith(
        "(and hold the axis while it sticks); their viscous friction is not resolved on this log "
        "(48 ± 80 N s/m)."
    )
    est["viscous"] = Estimate(4.91, 0.12, "N s/m")
    words = _friction_words("horizontal", form, 0.05)(est)
    assert words.endswith("4.9 ± 0.1 N s/m of viscous friction (and hold the axis while it sticks).")
    assert "not resolved" not in words
    if form == "full":  # the sentence as before the check
        assert words == (
            "The horizontal linear guides resist motion with 1.8 ± 0.7 N of Coulomb friction and "
            "4.9 ± 0.1 N s/m of viscous friction (and hold the axis while it sticks)."
        )


def test_the_effects_accelerations_add_up(model):
    """The stage file's and the controllers' effects Function is the sum of every found effect's
    acceleration (seed-45 survivor: each effect replaced the one before, so only the last was
    compensated): two guide frictions, one per axis, give each alone on its axis and their sum
    (1e-12: the same arithmetic), for the compensation (state only) and the twin (with currents)."""
    from maglev_oc.diagnosis.feedback import _effects_acceleration
    from maglev_oc.diagnosis.guides import friction_candidates
    from tests.test_diagnosis_round3_properties import _ctx, _effect

    cands = {c.name: c for c in friction_candidates(_ctx(model))}
    h = _effect(cands["guide_friction_horizontal"], [2.0, 5.0, 0.6])
    v = _effect(cands["guide_friction_vertical"], [1.0, 3.0, 0.5])
    x, u = np.array([0.02, 4e-3, 0.01, 6e-3]), np.array([0.3, 1.2])
    for args, with_inputs in (((x,), False), ((x, u), True)):
        each = [
            np.asarray(_effects_acceleration([e], with_inputs=with_inputs)(*args)).ravel() for e in (h, v)
        ]
        both = np.asarray(_effects_acceleration([h, v], with_inputs=with_inputs)(*args)).ravel()
        assert each[0][1] != 0 and each[1][0] != 0  # each acts on its own axis
        np.testing.assert_allclose(both, each[0] + each[1], rtol=1e-12, atol=1e-15)


def test_a_negative_parameter_is_refused_with_how_many_standard_errors_below_zero_it_is():
    """not_below's reason gives value / standard error (seed-45 survivor: value times it)."""
    from maglev_oc.diagnosis.candidate import not_below
    from maglev_oc.results import Estimate

    check = not_below("viscous", "viscous friction")
    assert check({"viscous": Estimate(-6.0, 2.0, "N s/m")}) == (
        "viscous friction of -6 N s/m is negative (-3.0 standard errors)"
    )
    assert check({"viscous": Estimate(-3.0, 2.0, "N s/m")}) is None  # 1.5 standard errors: not refused
