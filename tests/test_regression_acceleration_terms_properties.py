"""Properties of the acceleration terms (``maglev_oc.regression.terms``), checked against the terms'
own CasADi functions, closed forms and the delta method computed by hand:

- a periodic force's parameters are named for the sine and the cosine; a term's parameter names
  are an immutable tuple, and a term of any name builds and evaluates;
- amplitude and phase reproduce the sine-cosine pair, and their standard errors use the (a, b)
  block of the covariance alone (also with a gap exponent as a further parameter); a linear
  physical quantity's standard error is |k| times the parameter's;
- a constant force is its size over its own axis's mass, vertically towards the stator; sticking
  guides hold at most the whole force and never reverse it;
- a term's variant note states its variants (the friction's reversal speeds, a periodic force's
  gap exponents); a guide friction's explanation names each part it has; ``periodic_force`` says
  which argument is wrong.
"""

from __future__ import annotations

import math
import re

import casadi as ca
import numpy as np
import pytest

from maglev_oc.errors import InputError
from maglev_oc.model.parameters import StageParameters
from maglev_oc.regression.terms import (
    REFERENCE_GAP,
    AccelerationTerm,
    amplitude_phase,
    constant_force,
    guide_friction,
    periodic_force,
    term_function,
)


# --- the regression layer's terms and data -----------------------------------------------------------------
def test_amplitude_and_phase_reproduce_the_sine_and_cosine_pair():
    # a sin(x) + b cos(x) = A sin(x + phi): checked pointwise; the phase's standard error against
    # the delta method with a numerical gradient of atan2 (central differences, step 1e-6: the
    # truncation error is ~1e-12 relative, 1e-6 covers the round-off of the differences)
    a, b = 0.3, -0.7
    cov = np.array([[4e-4, 1e-4], [1e-4, 9e-4]])
    out = amplitude_phase("N", 2.0)(np.array([a, b]), cov, {})
    x = np.linspace(0, 2 * np.pi, 17)
    amp = out["amplitude"].value / 2.0
    np.testing.assert_allclose(
        amp * np.sin(x + out["phase"].value), a * np.sin(x) + b * np.cos(x), atol=1e-12
    )
    h = 1e-6
    g = np.array(
        [
            (math.atan2(b, a + h) - math.atan2(b, a - h)) / (2 * h),
            (math.atan2(b + h, a) - math.atan2(b - h, a)) / (2 * h),
        ]
    )
    assert out["phase"].stderr == pytest.approx(math.sqrt(g @ cov @ g), rel=1e-6)
    ga = np.array([a, b]) / math.hypot(a, b)
    assert out["amplitude"].stderr == pytest.approx(2.0 * math.sqrt(ga @ cov @ ga), rel=1e-12)


@pytest.mark.parametrize("axis", ["vertical", "horizontal"])
def test_a_constant_force_is_its_size_over_its_own_axis_mass_towards_the_stator(model, axis):
    # 1 N: vertically towards the stator (closes the gap, x2' = -F / M_v), horizontally along +x3
    p = model.params
    term = constant_force(p, axis)
    acc = np.asarray(term.function([0.02, 0, 0, 0], [0, 1.5], [0, 0], [1.0])).ravel()
    if axis == "vertical":
        np.testing.assert_allclose(acc, [-1.0 / p.mass_vertical, 0.0], rtol=1e-12)
    else:
        np.testing.assert_allclose(acc, [0.0, 1.0 / p.mass_horizontal], rtol=1e-12)
    assert p.mass_vertical != p.mass_horizontal


def test_sticking_guides_hold_at_most_the_whole_force_and_never_reverse_it(model):
    """held_by_guides multiplies a term's acceleration by 1 - h exp(-(v / v_s)^2): at rest with a
    share of 0.6 the force is 40 % of itself, at v = v_s 1 - 0.6 / e, at +-2 v_s 1 - 0.6 e^-4 in
    either direction (closed form); a share fitted
    beyond 1 holds the whole force (the guides cannot push back harder than they are pushed: static
    friction only opposes) and a negative one holds nothing (1e-12: the same arithmetic)."""
    from maglev_oc.regression.terms import REVERSAL_SPEED, constant_force, held_by_guides

    term = constant_force(model.params, "horizontal")

    def acc(share, v):
        held = held_by_guides(term, {"horizontal": share})
        x = np.array([0.02, 0.0, 0.0, v])
        return float(held.acceleration([1.0])(x, np.zeros(2), np.zeros(2)).full()[1, 0])

    free = 1.0 / model.params.mass_horizontal
    assert acc(0.6, 0.0) == pytest.approx(0.4 * free, rel=1e-12)
    assert acc(0.6, REVERSAL_SPEED) == pytest.approx((1 - 0.6 / math.e) * free, rel=1e-12)
    for v in (2 * REVERSAL_SPEED, -2 * REVERSAL_SPEED):  # either direction alike
        assert acc(0.6, v) == pytest.approx((1 - 0.6 * math.exp(-4)) * free, rel=1e-12)
    assert acc(1.5, 0.0) == pytest.approx(0.0, abs=1e-15)
    assert acc(-0.5, 0.0) == pytest.approx(free, rel=1e-12)


def test_a_linear_physical_quantitys_standard_error_is_not_negative_for_a_negative_scale():
    """linear_physical: value p k and standard error sqrt(var p) |k| (a standard error is a spread,
    of either sign of the scale)."""
    from maglev_oc.regression.terms import linear_physical

    out = linear_physical([("force", "N", -2.0), ("length", "m", 1e-3)])(
        np.array([0.5, 3.0]), np.diag([0.04, 0.09]), {}
    )
    assert (out["force"].value, out["force"].stderr, out["force"].unit) == (-1.0, 0.4, "N")
    assert out["length"].value == pytest.approx(3e-3) and out["length"].stderr == pytest.approx(3e-4)


# --- the terms' variant notes ----------------------------------------------------------------------------
def _numbers(note: str) -> tuple[float, float]:
    lo, hi = re.search(r"([0-9.]+)-([0-9.]+)", note).groups()
    return float(lo), float(hi)


@pytest.mark.parametrize("axis", ["horizontal", "vertical"])
@pytest.mark.parametrize("speed", [2e-3, 5e-3])
def test_the_friction_note_states_the_reversal_speeds_of_its_variants(axis, speed):
    """guide_friction: acc = -(F_c tanh(v / v_r) + c v) / M, variants at other v_r. With F_c = 1 N and
    c = 0 each variant's v_r is recovered from its function: tanh(v / v_r) = acc(v) / acc(v_big)
    (v_big = 1 m/s, 100 v_r or more, where tanh is 1 in double precision). The note "reversal speed
    A-B mm/s" gives the smallest and largest of them (to 1e-4: %g prints 6 significant digits)."""
    term = guide_friction(StageParameters(), axis, reversal_speed=speed)
    vi, row = (1, 0) if axis == "vertical" else (3, 1)

    def acc(fn, v):
        x = np.zeros(4)
        x[0], x[vi] = 0.02, v
        return float(np.asarray(fn(x, np.zeros(2), np.zeros(2), [1.0, 0.0])).ravel()[row])

    widths = sorted(speed / math.atanh(acc(fn, speed) / acc(fn, 1.0)) for fn in term.variants)
    assert len(widths) == 2 and widths[0] < speed < widths[1]
    assert "mm/s" in term.variant_note
    lo, hi = _numbers(term.variant_note)
    assert (lo, hi) == pytest.approx((widths[0] * 1e3, widths[1] * 1e3), rel=1e-4)


def test_a_periodic_forces_note_states_its_variants_gap_exponents_and_is_empty_without_any():
    """periodic_force: F = (a sin + b cos)(reference_gap / x1)^e; a variant's exponent is recovered as
    log2 of its force at half the reference gap over its force at the reference gap (exact to 1e-12).
    The note "gap exponent A-B" gives their range; without variants there is nothing to note."""
    p = StageParameters()
    term = periodic_force(p, "vertical", 0.02, gap_exponent=3.0, exponent_variants=(2.0, 4.0))

    def force(fn, gap):
        x = np.array([gap, 0.0, 0.005, 0.0])
        return float(np.asarray(fn(x, np.zeros(2), np.zeros(2), [1.0, 0.0])).ravel()[0])

    exps = sorted(math.log2(force(fn, REFERENCE_GAP / 2) / force(fn, REFERENCE_GAP)) for fn in term.variants)
    np.testing.assert_allclose(exps, [2.0, 4.0], rtol=0, atol=1e-12)
    assert "gap exponent" in term.variant_note
    assert _numbers(term.variant_note) == pytest.approx(tuple(exps), abs=1e-12)
    plain = periodic_force(p, "horizontal", 0.02)
    assert plain.variants == () and plain.variant_note == ""


# --- a periodic force's parameter names ------------------------------------------------------------------
@pytest.mark.parametrize("axis", ["horizontal", "vertical"])
def test_a_periodic_forces_parameters_are_named_for_the_sine_and_the_cosine(axis):
    """periodic_force: F = (a sin(2 pi x3 / P) + b cos(2 pi x3 / P)) / M on the axis. The parameter
    named "sin" is the one whose column is the sine: at x3 = P / 4 (sine 1, cosine 0) its column is
    +-1 / M and the other's 0; at x3 = 0 the reverse (to 1e-12 / M: sin(pi / 2) and cos(pi / 2) in
    double precision). The fits report them as "<term>.sin" and "<term>.cos"."""
    p = StageParameters()
    period = 0.019
    term = periodic_force(p, axis, period)
    assert term.parameter_names == ("sin", "cos")
    assert term.qualified_names == (f"{term.name}.sin", f"{term.name}.cos")
    row, mass = (0, p.mass_vertical) if axis == "vertical" else (1, p.mass_horizontal)
    sin_col, cos_col = (term.parameter_names.index(n) for n in ("sin", "cos"))

    def columns(x3):
        x = np.array([0.02, 0.0, x3, 0.0])
        return np.asarray(term.features(x, np.zeros(2), np.zeros(2)))[row]

    at_quarter, at_zero = columns(period / 4), columns(0.0)
    assert abs(at_quarter[sin_col]) == pytest.approx(1 / mass, rel=1e-12)
    assert abs(at_quarter[cos_col]) < 1e-12 / mass
    assert abs(at_zero[cos_col]) == pytest.approx(1 / mass, rel=1e-12)
    assert abs(at_zero[sin_col]) < 1e-12 / mass


# --- parameter names normalised ---------------------------------------------------------------------------
_LEVEL_AND_SPRING = term_function("ls", lambda x, u, du, q: ca.vertcat(0, q[0] + q[1] * x[2]), 2)


def _term(names) -> AccelerationTerm:
    """The same term (one CasADi Function, which compares by identity) with the names given."""
    return AccelerationTerm(
        "level_and_spring",
        "A constant force and a spring along the track.",
        "horizontal",
        names,
        function=_LEVEL_AND_SPRING,
    )


def test_a_terms_parameter_names_are_an_immutable_tuple_of_the_names_given():
    """AccelerationTerm documents parameter_names as a tuple of str and is a frozen (hashable) dataclass:
    built from a list, the names are the tuple of the list's items (in order), so the term equals and
    hashes like the one built from that tuple, and appending to the caller's list afterwards changes
    neither the names nor the parameter count the fits use."""
    given = ["force", "stiffness"]
    term = _term(given)
    assert isinstance(term.parameter_names, tuple) and term.parameter_names == ("force", "stiffness")
    same = _term(("force", "stiffness"))
    assert term == same and hash(term) == hash(same) and len({term, same}) == 1
    given.append("extra")
    assert term.parameter_names == ("force", "stiffness") and term.n_parameters == 2
    assert term.qualified_names == ("level_and_spring.force", "level_and_spring.stiffness")
    # a generator of names (read once) gives the same
    assert _term(n for n in ("force", "stiffness")).parameter_names == ("force", "stiffness")


# --- amplitude and phase beside further parameters --------------------------------------------------------
def test_amplitude_and_phase_standard_errors_use_the_sine_cosine_block_only():
    """(a, b) -> amplitude A = sqrt(a^2 + b^2) [x scale], phase atan2(b, a). Delta method with the exact
    gradients g_A = (a, b) / A and g_phi = (-b, a) / A^2: sd = sqrt(g' C_ab g), C_ab the covariance of
    (a, b). A term with a third parameter (a gap exponent, here in a covariance with non-zero
    correlations to a and b and a large variance) hands the converter its 3 x 3 covariance: the third
    row and column must not enter. Values and standard errors to 1e-12 relative (a few products);
    the same as the converter given the 2 x 2 block."""
    a, b, scale = 0.3, -0.4, 2.0
    cov = np.array([[4e-4, 1e-4, 3e-3], [1e-4, 9e-4, -2e-3], [3e-3, -2e-3, 0.5]])
    out = amplitude_phase("N", scale)(np.array([a, b, 3.0]), cov, {})
    amp = math.hypot(a, b)
    c = cov[:2, :2]
    g_amp = np.array([a, b]) / amp
    g_phase = np.array([-b, a]) / amp**2
    assert out["amplitude"].value == pytest.approx(scale * amp, rel=1e-12)
    assert out["phase"].value == pytest.approx(math.atan2(b, a), rel=1e-12)
    assert out["amplitude"].stderr == pytest.approx(scale * math.sqrt(g_amp @ c @ g_amp), rel=1e-12)
    assert out["phase"].stderr == pytest.approx(math.sqrt(g_phase @ c @ g_phase), rel=1e-12)
    two = amplitude_phase("N", scale)(np.array([a, b]), c, {})
    assert {k: (v.value, v.stderr) for k, v in out.items()} == {
        k: (v.value, v.stderr) for k, v in two.items()
    }


def test_a_periodic_force_with_a_gap_exponent_as_a_parameter_reports_its_amplitude_and_phase():
    """A user's term: F = (a sin + b cos)(reference_gap / x1)^e with the exponent e fitted (a third,
    nonlinear parameter) and the amplitude/phase conversion as its physical map. Its physical
    parameters from a 3 x 3 covariance are the peak at the reference gap and the phase with the
    (a, b) block's standard errors (the same closed forms as above, to 1e-12)."""
    p = StageParameters()
    period = 0.038

    def build(x, u, du, q):
        arg = 2 * math.pi * x[2] / period
        return ca.vertcat(
            -(q[0] * ca.sin(arg) + q[1] * ca.cos(arg)) * (REFERENCE_GAP / x[0]) ** q[2] / p.mass_vertical, 0
        )

    term = AccelerationTerm(
        "cogging_free_exponent",
        "Normal cogging with its gap exponent fitted.",
        "vertical",
        ["sin", "cos", "exponent"],
        initial=(0.0, 0.0, 3.0),
        function=term_function("cfe", build, 3),
        physical=amplitude_phase("N"),
    )
    assert not term.linear
    q = np.array([0.12, 0.05, 2.7])
    cov = np.array([[1e-4, 2e-5, 1e-3], [2e-5, 4e-4, -1e-3], [1e-3, -1e-3, 0.09]])
    out = term.physical_parameters(q, cov, {})
    amp = math.hypot(q[0], q[1])
    g_amp, g_phase = q[:2] / amp, np.array([-q[1], q[0]]) / amp**2
    assert out["amplitude"].value == pytest.approx(amp, rel=1e-12)
    assert out["amplitude"].stderr == pytest.approx(math.sqrt(g_amp @ cov[:2, :2] @ g_amp), rel=1e-12)
    assert out["phase"].stderr == pytest.approx(math.sqrt(g_phase @ cov[:2, :2] @ g_phase), rel=1e-12)


# --- regression.terms ---------------------------------------------------------------------------
_SPRING = term_function("spring", lambda x, u, du, q: ca.vertcat(0, q[0] * x[2]), 1)


@pytest.mark.parametrize("name", ["friction (x)", "-offset-", "__x__", "2nd harmonic!", "a--b", "_", "()"])
def test_a_term_of_any_name_builds_and_evaluates(name):
    """AccelerationTerm.name is any identifier for reports; the term's CasADi Functions (features,
    offset, acceleration) get valid CasADi names from it whatever punctuation it has at its ends or
    inside, and evaluate: the feature of a spring q x3 is x3, exactly."""
    term = AccelerationTerm(name, "A spring along the track.", "horizontal", ("k",), function=_SPRING)
    x = np.array([0.02, 0.0, 0.3, 0.0])
    fns = (term.features, term.offset, term.acceleration([2.0]))
    assert all(ca.Function.check_name(f.name()) for f in fns)
    assert np.array_equal(np.asarray(fns[0](x, [0, 0], [0, 0])).ravel(), [0.0, 0.3])
    assert np.array_equal(np.asarray(fns[2](x, [0, 0], [0, 0])).ravel(), [0.0, 0.6])


@pytest.mark.parametrize("viscous", [True, False])
@pytest.mark.parametrize("stribeck", [None, 2e-3])
@pytest.mark.parametrize("holding", [None, lambda x, u: u[0]])
def test_a_guide_friction_explanation_names_each_part_it_has(viscous, stribeck, holding):
    """The explanation names each part of the friction the term fits and no other, the laws by their
    proper names (Coulomb, Stribeck: as the diagnosis's findings and the variant note write them)."""
    term = guide_friction(
        StageParameters(), "horizontal", viscous=viscous, stribeck_speed=stribeck, holding=holding
    )
    text = term.explanation
    assert "(Coulomb)" in text
    assert ("(viscous)" in text) == viscous
    assert ("(Stribeck)" in text) == (stribeck is not None)
    assert ("Stribeck" in term.variant_note) == (stribeck is not None)
    assert ("sticks" in text) == (holding is not None)
    assert "stribeck" not in text and "coulomb" not in text  # lower case: not the laws' names
    assert text.endswith(".") and text.count(".") == 1


@pytest.mark.parametrize(
    "kwargs, bad, requirement",
    [
        ({"period": 0.0}, "0.0", "period > 0"),
        ({"period": -0.019}, "-0.019", "period > 0"),
        ({"period": math.nan}, "nan", "period > 0"),
        ({"period": 0.019, "reference_gap": 0.0}, "0.0", "reference_gap > 0"),
        ({"period": 0.019, "gap_exponent": -1.5}, "-1.5", "gap_exponent >= 0"),
    ],
)
def test_periodic_force_says_which_argument_is_wrong(kwargs, bad, requirement):
    """The refusal states the requirements and the values given (the bad one among them)."""
    with pytest.raises(InputError) as err:
        periodic_force(StageParameters(), "horizontal", **kwargs)
    message = str(err.value)
    assert requirement in message
    assert re.search(rf"(?<![\d.]){re.escape(bad)}(?![\d])", message), message
