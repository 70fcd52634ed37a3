"""Synthetic diagnosis cases shared by the diagnosis and regression property tests: sweeps with
planted effects (a slot-pitch cogging, guide friction with cogging, two periodic forces), their
designs and candidate contexts, a hand-built :class:`Judgement` and a found effect.

The fixtures are registered in ``tests/conftest.py`` (module scope: built once per file that uses
them).
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.diagnosis.candidate import Candidate, LibraryContext, within
from maglev_oc.diagnosis.library import candidate_library
from maglev_oc.diagnosis.result import Effect
from maglev_oc.diagnosis.selection import Judgement, _verdict_and_rival
from maglev_oc.regression.data import prepare
from maglev_oc.regression.design import build_design
from maglev_oc.regression.terms import periodic_force
from maglev_oc.results import PerAxis
from tests.test_diagnosis_selection_properties import cogged_design
from tests.test_statistics_properties import RATE_FRICTION, _friction_candidate, _log


def _verdict(*args, **kwargs) -> tuple[str, str]:
    """(verdict, reason) of ``selection._verdict_and_rival`` without the rival's variable."""
    return _verdict_and_rival(*args, **kwargs)[:2]


def _judgement(*, z, wald, gain_axes=(0.1, 0.1), rms=(0.01, 0.01), peak=(0.01, 0.01), threshold=10.0):
    fit = SimpleNamespace(compensation=1.0)
    gain_axes = np.asarray(gain_axes, dtype=float)
    return Judgement(
        "effect",
        "passes",
        "",
        float(np.nanmean(gain_axes)),
        gain_axes,
        z,
        z,
        wald,
        threshold,
        1.0,
        (),
        np.asarray(rms, dtype=float),
        np.asarray(peak, dtype=float),
        {},
        fit,
    )


@pytest.fixture(scope="module")
def cogged(model):
    """(design, library by name): the horizontal sweep with a cogging force planted at the slot pitch
    (0.02 m/s^2), the cogging and horizontal friction candidates' columns beside C1, a quarter held
    out (:func:`tests.test_diagnosis_selection_properties.cogged_design`)."""
    return cogged_design(model)


def _ctx(model, n: int = 400) -> LibraryContext:
    """A LibraryContext of a stand-in log: gaps 16-24 mm, positions -30..40 mm (its valid samples)."""
    t = np.linspace(0.0, 1.0, n)
    x = np.vstack([0.02 + 0.004 * np.sin(7 * t), 0.01 * np.cos(7 * t), 0.005 + 0.035 * np.sin(5 * t), 0 * t])
    return LibraryContext(model, SimpleNamespace(x=x, valid=np.ones(n, dtype=bool), settings={}))


def _effect(cand, coefficients) -> Effect:
    nan = PerAxis.of([float("nan")] * 2)
    return Effect(
        cand.name, "", "", cand.axis, {}, 1.0, 0.1, 5.0, nan, nan, "", "", np.asarray(coefficients), cand
    )


@pytest.fixture(scope="module")
def horizontal_all(model):
    """(data, design): the horizontal sweep with viscous friction (gap held: the vertical axis does
    not move), all four constants estimated beside the friction, a quarter held out."""
    data = prepare([_log(model, friction=RATE_FRICTION)], bandwidth=10.0)
    train, hold = data.masks(0.25)
    return data, build_design(data, model, terms=[_friction_candidate().term], fit=train, holdout=hold)


@pytest.fixture(scope="module")
def data(twin_log):
    """The twin's 6 s excitation prepared for the fits (its logged currents carry amplifier noise)."""
    return prepare([twin_log], bandwidth=10.0)


@pytest.fixture(scope="module")
def two_effects(model):
    """(design, library by name): the sweep with guide friction and a slot-pitch cogging planted
    (:func:`two_effects_design`), both candidates' columns beside C1."""
    return two_effects_design(model)


def two_effects_design(model):
    """(design, library by name): the 30 s horizontal sweep with guide friction (0.02 m/s^2 of Coulomb
    friction, 5 mm/s reversal) and a cogging force at the slot pitch (0.02 m/s^2) planted, the two
    candidates' columns beside C1."""
    from maglev_oc.diagnosis.library import candidate_library

    period = model.params.slot_pitch

    def force(x3):
        v = np.gradient(x3, 1e-3)  # the sweep's 1 kHz samples
        return 0.02 * np.sin(2 * math.pi * x3 / period + 0.5) - 0.02 * np.tanh(v / 5e-3)

    data = prepare([_log(model, friction=0.0, force=force)], bandwidth=10.0)
    lib = {c.name: c for c in candidate_library(model, data)}
    fit, hold = data.masks(0.25)
    terms = (lib["guide_friction_horizontal"].term, lib["cogging_horizontal_19mm"].term)
    design = build_design(data, model, estimate=("C1",), terms=terms, fit=fit, holdout=hold)
    return design, lib


SECOND_PERIOD = 0.025
"""[m] a second horizontal periodic force beside the 19 mm slot pitch: 1/P - 1/P' = 12.6 1/m, so
over the synthetic sweep's 63 mm travel the two drift apart by 0.79 of a cycle (under the default
``min_beats`` of 1), while over the travel the two sines are far from collinear (the joint fit's
variance inflation is about 1.3)."""


def _two_forces(x3: np.ndarray, slot_pitch: float) -> np.ndarray:
    """[m/s^2] the planted horizontal accelerations: 0.02 at the slot pitch, 0.015 at 25 mm (both
    about 10 times the selection's 2.25e-3 m/s^2 size floor)."""
    return 0.02 * np.sin(2 * math.pi * x3 / slot_pitch + 0.5) + 0.015 * np.sin(
        2 * math.pi * x3 / SECOND_PERIOD + 1.3
    )


@pytest.fixture(scope="module")
def two_periodic(model):
    """(prepared log, library by name, design): the synthetic horizontal sweep of
    ``tests/test_statistics_properties`` (30 s, the gap held at 20 mm) with both periodic forces
    planted, and the 19 mm cogging and a 25 mm periodic force as the candidates."""
    data = prepare(
        [_log(model, friction=0.0, force=lambda x3: _two_forces(x3, model.params.slot_pitch))], bandwidth=10.0
    )
    lib = {c.name: c for c in candidate_library(model, data)}
    fit, hold = data.masks(0.25)
    other = Candidate(
        periodic_force(model.params, "horizontal", SECOND_PERIOD, name="detent_25mm"),
        "periodic",
        "position",
        "runs over a longer travel",
        within("amplitude", 10.0, "peak force"),
        lambda e: f"A force of {e['amplitude'].value:.2g} N periodic over 25 mm.",
    )
    lib[other.name] = other
    terms = (lib["cogging_horizontal_19mm"].term, other.term)
    design = build_design(data, model, estimate=("C1",), terms=terms, fit=fit, holdout=hold)
    return data, lib, design
