"""Properties of ``maglev_oc.regression.terms`` written against the survivors of the seed-36 mutation-testing
run (issue 21): each test states a property of a result a user sees, not the mutated token.

* A periodic force's parameters are named for what they multiply: "sin" the coefficient of
  sin(2 pi x3 / P), "cos" that of the cosine (the words of the docstring's a sin + b cos, of the
  fits' qualified names "<term>.sin" / "<term>.cos" and of the guide waviness's parameters).
* A term keeps its parameter names as an immutable tuple, whatever sequence the caller passed: equal to
  the names given, unchanged when the caller's list changes afterwards, and the term stays hashable
  and equal to the one built with a tuple.
* The amplitude and phase of (a sin + b cos) take their standard errors from the (a, b) block of the
  covariance alone, also when the term has further parameters (a gap exponent): the delta method
  sqrt(g' C g) computed here from its closed-form gradients.
* A log too short for the differentiator (its two edges and 10 samples between) is refused with the
  length it needs; a log of exactly that length is accepted.
"""

from __future__ import annotations

import math
import re

import casadi as ca
import numpy as np
import pytest

from maglev_oc.data.logs import Log, LogError
from maglev_oc.model.parameters import StageParameters
from maglev_oc.regression.data import prepare
from maglev_oc.regression.terms import (
    REFERENCE_GAP,
    AccelerationTerm,
    amplitude_phase,
    periodic_force,
    term_function,
)


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


@pytest.mark.filterwarnings("ignore:nperseg")  # the logged currents' noise floor from a short log
def test_a_log_shorter_than_the_differentiators_need_is_refused_by_name_and_one_that_long_is_not():
    """The differentiator's filters run off both ends of a log (``edge`` samples each) and keep 10
    samples between: a log one sample shorter than the need the error states is refused with that
    need, a log of exactly that length is prepared (with all of its samples outside the edges valid)."""
    t = np.arange(20_000) * 1e-3
    x = np.vstack([0.02 + 1e-3 * np.sin(t), np.zeros_like(t), 0.01 * np.cos(t), np.zeros_like(t)])
    u = np.vstack([np.sin(3.0 * t), np.cos(2.0 * t)])

    def log(n: int) -> Log:
        return Log(t[:n], x[:, :n], u[:, :n], source=f"short{n}.csv")

    with pytest.raises(LogError, match=r"short40\.csv.*needs at least \d+") as err:
        prepare([log(40)], bandwidth=10.0)
    need = int(re.search(r"needs at least (\d+)", str(err.value)).group(1))
    assert need > 40
    with pytest.raises(LogError, match=rf"needs at least {need}\b"):
        prepare([log(need - 1)], bandwidth=10.0)
    data = prepare([log(need)], bandwidth=10.0)
    assert data.n == need and data.valid.sum() == 10
