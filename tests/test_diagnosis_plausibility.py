"""The physical-plausibility checks a finding must pass (``maglev_oc.diagnosis.candidate``): each
refuses exactly the values it names and says which, checked against the inequality written out
here (hypothesis)."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from maglev_oc.diagnosis.candidate import all_of, detected, not_below, within
from maglev_oc.results import Estimate

values = st.floats(-1e3, 1e3, allow_nan=False)
errors = st.floats(0.0, 1e2, allow_nan=False)
k_values = st.floats(0.5, 4.0)


@settings(max_examples=200, deadline=None)
@given(value=values, stderr=errors, k=k_values)
def test_not_below_refuses_what_is_negative_by_more_than_k_standard_errors(value, stderr, k):
    reason = not_below("c", "viscous friction", k)({"c": Estimate(value, stderr, "N s/m")})
    assert (reason is not None) == (value < -k * stderr)
    if reason:
        assert reason.startswith("viscous friction of ") and "negative" in reason and "N s/m" in reason


@settings(max_examples=200, deadline=None)
@given(value=values, stderr=errors, k=k_values)
def test_detected_needs_a_value_positive_by_more_than_k_standard_errors(value, stderr, k):
    reason = detected("lag", "lag", k)({"lag": Estimate(value, stderr, "s")})
    assert (reason is None) == (value > k * stderr)
    if reason:
        assert reason.startswith("no lag: ") and "not positive" in reason


@settings(max_examples=200, deadline=None)
@given(value=values, bound=st.floats(1e-6, 1e3))
def test_within_refuses_a_magnitude_beyond_the_bound_on_either_side(value, bound):
    reason = within("slope", bound, "guide slope")({"slope": Estimate(value, 0.0, "rad")})
    assert (reason is None) == (abs(value) <= bound)
    if reason:
        assert reason.startswith("guide slope of ") and "beyond the physical bound" in reason


@settings(max_examples=100, deadline=None)
@given(a=values, b=values)
def test_all_of_gives_the_first_refusal_in_order(a, b):
    first = within("a", 1.0, "first")
    second = within("b", 1.0, "second")
    est = {"a": Estimate(a, 0.0, "N"), "b": Estimate(b, 0.0, "N")}
    reason = all_of(first, second)(est)
    expected = first(est) or second(est)
    assert reason == expected
    assert (reason is None) == (abs(a) <= 1.0 and abs(b) <= 1.0)
