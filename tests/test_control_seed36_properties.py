"""Properties of the controllers that the seed-36 mutation run found untested.

Each test checks what a user of ``maglev_oc/control/`` relies on:

- the NMPC exposes the weights it was built with (``NonlinearMPC.weights``, what the
  controllers report prints as the NMPC's Q and R): the settings' weights, whether given in
  :class:`~maglev_oc.control.nmpc.NMPCSettings`, as a keyword, or left at the defaults;
- the gap bounds of the NMPC are positive: a lower bound of exactly 0 (a closed gap, where the
  field model is not defined) is refused like a negative one, by name, while the smallest
  positive bound is accepted;
- a shooting grid refuses an ``interval_samples`` that is not a positive integer (0, a
  negative count, a float, a count given as a string) with a message naming the field and
  the value given, as it does for ``sample_time`` and ``horizon``;
- the per-axis augmented system refuses a zero or non-finite input gain (each, not only one of
  the two conditions) and carries any other into B.
"""

from __future__ import annotations

import math
import re

import pytest

from maglev_oc.control.gains import augmented_axis
from maglev_oc.control.nmpc import NMPCSettings, NMPCWeights, NonlinearMPC
from maglev_oc.control.nmpc.grid import ShootingGrid
from maglev_oc.errors import InputError

TS = 2e-4  # [s] the controller's sample time


# --- the NMPC's weights ---------------------------------------------------------------------------
def test_the_nmpc_exposes_the_weights_it_was_built_with(model):
    """Other weights than the defaults (every entry changed), given in the settings or as a
    keyword, and no weights at all (the defaults, NMPCWeights()): ``weights`` is the settings'
    object, equal to what was given."""
    other = NMPCWeights(gap=2e5, gap_rate=50.0, position=3e5, position_rate=20.0, i_q=3.0, i_d=0.5)
    assert other != NMPCWeights()
    settings = NMPCSettings(weights=other, horizon=5)
    built = NonlinearMPC(model, settings)
    assert built.weights == other and built.weights is built.settings.weights
    by_keyword = NonlinearMPC(model, weights=other, horizon=5)
    assert by_keyword.weights == other
    default = NonlinearMPC(model, horizon=5)
    assert default.weights == NMPCWeights() == default.settings.weights


# --- the gap bounds ---------------------------------------------------------------------------------
@pytest.mark.parametrize("lower", [0.0, -0.0, -1e-3])
def test_a_gap_lower_bound_at_or_below_zero_is_refused(lower):
    """Gaps are positive distances in metres: (0, upper) is refused as (-1 mm, upper) is, with the
    field's name and the bounds given."""
    bounds = (lower, 0.03)
    with pytest.raises(InputError, match=r"^gap_bounds must be positive and in metres, got ") as err:
        NMPCSettings(gap_bounds=bounds)
    assert str(err.value).endswith(repr(bounds))


def test_the_smallest_positive_gap_lower_bound_is_accepted():
    """Any positive lower bound is a gap (the smallest positive float too): kept as given."""
    tiny = 5e-324
    assert NMPCSettings(gap_bounds=(tiny, 0.03)).gap_bounds == (tiny, 0.03)


# --- the shooting grid ------------------------------------------------------------------------------
@pytest.mark.parametrize("bad", [0, -1, 1.5, 25.0, "25"])
def test_a_grid_refuses_a_bad_interval_count_by_name_and_value(bad):
    """The message names ``interval_samples`` and shows the value given (its repr: 25.0 is a
    float, not the count 25), so the caller sees which argument and why."""
    with pytest.raises(InputError) as err:
        ShootingGrid(TS, bad, 20)
    assert str(err.value) == f"interval_samples must be a positive integer, got {bad!r}"


@pytest.mark.parametrize(
    ("args", "field", "value"),
    [((0.0, 25, 20), "sample_time", 0.0), ((TS, 25, 1), "horizon", 1), ((TS, 25, 2.0), "horizon", 2.0)],
)
def test_a_grid_names_each_bad_argument(args, field, value):
    with pytest.raises(InputError, match=rf"^{field} must be .*, got {re.escape(repr(value))}$"):
        ShootingGrid(*args)


def test_a_good_grid_is_one_sample_then_whole_intervals():
    """interval_samples = 1 (the smallest) and 25 (the default): node offsets 0, 1, 1 + m, ..."""
    for m in (1, 25):
        grid = ShootingGrid(TS, m, 4)
        assert grid.node_offsets.tolist() == [0, 1, 1 + m, 1 + 2 * m, 1 + 3 * m]
        assert grid.intervals.tolist() == [TS] + [m * TS] * 3


@pytest.mark.parametrize("gain", [0.0, -0.0, math.inf, -math.inf, math.nan])
def test_an_augmented_axis_refuses_a_zero_or_non_finite_input_gain(gain):
    """The input gain divides the pole placement (B = (0, g, 0, 0, 0)'): zero makes the axis
    uncontrollable and inf or nan propagates into every gain, so each is refused by name."""
    with pytest.raises(InputError, match="input_gain must be finite and nonzero"):
        augmented_axis(input_gain=gain)


def test_an_augmented_axis_carries_its_input_gain_into_b():
    """Any finite nonzero gain, either sign, is accepted and is B's only nonzero entry (e')."""
    for gain in (1e-3, -2.5, 40.0):
        _, b = augmented_axis(input_gain=gain)
        assert b.ravel().tolist() == [0.0, gain, 0.0, 0.0, 0.0]
