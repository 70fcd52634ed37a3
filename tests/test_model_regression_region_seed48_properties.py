"""Properties behind the survivors of the seed-48 mutation sample of ``maglev_oc.model``,
``maglev_oc.regression`` and ``maglev_oc.region`` (bench/README, "Mutation testing"). The 28 tests
take about 1.5 s together (plus a few seconds of imports; no SDP is solved, no long log is made):

* an unknown effect's error lists the diagnosis's effects one by one (", " between them);
* a stage file's covariance with a nonzero covariance beside a zero variance is refused, naming the
  entry (it is not positive semidefinite whatever its units; the correlation test, which leaves
  zero-variance rows out, used to pass it);
* ``FeedbackTransformation.discriminant`` and ``feasibility_margin`` take any real numbers (an
  object array, fractions) and return floats;
* ``prepare`` records in its settings the filter edge it leaves out of each log's ends;
* an ``AccelerationTerm`` of any name with a letter or digit builds (valid CasADi Function names);
* a guide friction's explanation names each part the term has, with the laws' proper names;
* ``periodic_force`` refuses bad arguments saying which value is wrong;
* ``enlarge``'s timings of a reference at the stoppers are the (nonnegative) time it took."""

from __future__ import annotations

import json
import math
import re
import time
from fractions import Fraction

import casadi as ca
import numpy as np
import pytest

from maglev_oc.data.logs import Log
from maglev_oc.errors import InputError
from maglev_oc.model.feedback import FeedbackTransformation
from maglev_oc.model.parameters import StageParameters
from maglev_oc.model.stagefile import EFFECT_NAMES, StageEffect, StageFile
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.region.sdp import enlarge
from maglev_oc.regression.data import prepare
from maglev_oc.regression.terms import AccelerationTerm, guide_friction, periodic_force, term_function
from tests.test_stage_file import _good, _stage


# --- model.stagefile ----------------------------------------------------------------------------
def _listed_effects(message: str) -> list[str]:
    head = "the diagnosis's effects are "
    assert head in message, message
    return message.split(head, 1)[1].split(", ")


def test_an_unknown_effect_is_refused_listing_each_known_effect(tmp_path):
    """The message lists every effect of the library, each on its own (comma separated), both when
    a StageEffect is made and when a stage file is read."""
    with pytest.raises(InputError, match="unknown effect 'gremlins'") as made:
        StageEffect("gremlins", "horizontal", "", "", {}, {}, None)
    assert _listed_effects(str(made.value)) == list(EFFECT_NAMES)
    doc = _good()
    doc["effects"][0]["name"] = "gremlins"
    path = tmp_path / "stage.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"effects\[0\]\.name: unknown effect 'gremlins'") as read:
        StageFile.read(path)
    assert _listed_effects(str(read.value)) == list(EFFECT_NAMES)


def _beside_zero(i: int, j: int, value: float) -> np.ndarray:
    """A diagonal covariance of the constants' scale with variance i zero and cov[i][j] = value."""
    cov = np.diag([1e-4, 4.0, 1.0, 1e-4])
    cov[i, i] = 0.0
    cov[i, j] = cov[j, i] = value
    return cov


# (i, j, value): a covariance beside a zero variance, above the check's rounding room
# (_PSD_TOL = 1e-9 of sqrt(the other variance x the largest), 2e-9 beside C3's variance 1 here);
# |cov_ij| <= sqrt(cov_ii cov_jj) = 0
BESIDE_ZERO = [(0, 1, 0.1), (1, 0, -0.5), (3, 2, 1e-6), (2, 3, 1e-7)]


@pytest.mark.parametrize("i, j, value", BESIDE_ZERO)
def test_a_covariance_beside_a_zero_variance_is_refused_naming_its_entry(i, j, value, tmp_path):
    """[[0, c], [c, v]] has the eigenvalue (v - sqrt(v^2 + 4 c^2)) / 2 < 0 for every c != 0: not
    positive semidefinite beyond rounding once c is above the check's room. The error names the
    entry, as the other covariance errors do, in a StageFile and in a file."""
    cov = _beside_zero(i, j, value)
    entry = rf"\[({i}\]\[{j}|{j}\]\[{i})\]"
    with pytest.raises(InputError, match=rf"^StageFile\.covariance{entry}: .*not positive semidefinite"):
        _stage(covariance=cov)
    doc = _good()
    doc["constants"]["covariance"] = cov.tolist()
    path = tmp_path / "stage.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=rf"constants\.covariance{entry}: .*not positive semidefinite"):
        StageFile.read(path)


@pytest.mark.parametrize("value", [1e-12, 1e-181, 1e-300])
def test_a_rounding_level_covariance_beside_a_zero_variance_is_accepted(value):
    """The other side of the room: beside a zero variance and one of 1, a covariance c gives the
    eigenvalue -c^2 (to first order), 1e-24 or less here, rounding against the matrix's scale 4 (a
    product A A' whose small entries' squares underflow keeps 4.7e-181 beside a zero variance:
    tests/test_stage_file.py's round trip found it)."""
    stage = _stage(covariance=_beside_zero(3, 2, value))
    assert stage.covariance[3, 2] == value


def test_zero_rows_of_constants_held_fixed_are_still_accepted():
    """The other side: a zero variance with zeros beside it (a constant held fixed) is a valid
    covariance, and the others' correlations are kept."""
    cov = _beside_zero(2, 0, 0.0)
    cov[1, 3] = cov[3, 1] = 0.9 * math.sqrt(4.0 * 1e-4)  # correlation 0.9: PSD
    stage = _stage(covariance=cov)
    assert np.array_equal(stage.covariance, cov)
    assert stage.stderr["C3"] == 0.0


# --- model.feedback -----------------------------------------------------------------------------
@pytest.mark.parametrize("method", ["discriminant", "feasibility_margin"])
def test_the_transformation_takes_any_real_numbers_and_returns_floats(model, method):
    """An object array (what pandas or a list of mixed numbers gives) and fractions are real numbers:
    the result is the float array of the same numbers as floats. Exact equality: every input here
    converts to the same float64 as the float input, and then the same evaluation follows."""
    fn = getattr(FeedbackTransformation(model), method)
    x1, v1, v2 = [0.02, 0.021, 0.019], [0.5, -1.0, 2.0], [3.0, -4.0, 0.25]
    want = fn(np.array(x1), np.array(v1), np.array(v2))
    assert want.dtype == np.float64 and np.all(np.isfinite(want))
    as_object = fn(*(np.array(a, dtype=object) for a in (x1, v1, v2)))
    assert as_object.dtype == np.float64
    assert np.array_equal(as_object, want)
    fractions = fn(Fraction(1, 50), Fraction(1, 2), Fraction(3))
    assert fractions.dtype == np.float64 and fractions.shape == ()
    assert fractions == want[0]


# --- regression.data ----------------------------------------------------------------------------
def _log(n: int, seed: int) -> Log:
    t = np.arange(n) / 1000.0
    rng = np.random.default_rng(seed)
    x = np.vstack([0.02 + 1e-3 * np.sin(t), np.zeros(n), 0.01 * np.sin(2 * t + seed), np.zeros(n)])
    u = np.vstack([np.sin(3 * t), 1.5 + 0.1 * np.cos(t)]) + 1e-3 * rng.standard_normal((2, n))
    return Log(t, x, u, source=f"s48 {seed}")


def test_prepare_records_the_edge_it_leaves_out_of_each_log():
    """settings["edge_samples"] is what each log loses at each end: the invalid samples at its start
    and at its end (the filters' memory), the same count as ``edge``."""
    data = prepare([_log(2500, 1), _log(2200, 2)], bandwidth=10.0)
    edge = data.settings["edge_samples"]
    assert isinstance(edge, int) and edge == data.edge > 0
    for start, stop in data.segment_bounds:
        valid = data.valid[start:stop]
        first, last = np.flatnonzero(valid)[[0, -1]]
        assert first == edge and (stop - start - 1) - last == edge
        assert valid[first : last + 1].all()


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


# --- region.sdp ---------------------------------------------------------------------------------
def test_enlarge_at_the_stoppers_reports_the_time_it_took(model):
    """A reference whose gap orbit reaches the upper stopper (30 mm) is refused at once; its
    ``timings["total"]`` [s] is the time enlarge took: nonnegative and no more than the wall time
    measured around the call (the same clock, perf_counter, read outside enlarge's own readings)."""
    proc = Procedure2(FeasibleSet(model), RegulatorLoop())
    t0 = time.perf_counter()
    res = enlarge(proc, Reference(0.027, gap_amplitude=0.004))
    elapsed = time.perf_counter() - t0
    assert res.status == "infeasible" and not res.success
    assert 0.0 <= res.timings["total"] <= elapsed
