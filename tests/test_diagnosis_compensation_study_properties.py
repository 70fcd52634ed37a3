"""Properties of feeding the found effects back to the controllers (``maglev_oc.diagnosis.feedback``),
checked against twins and accelerations written out by hand:

- the effects' accelerations add up, and the compensation leaves out the share sticking guides
  hold (which the twin keeps);
- the compensation study's default plant carries the found effects, its runs are labelled before
  and after, and its "after" regulator compensates the found force (a different, better loop).
"""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import casadi as ca
import numpy as np
from matplotlib.figure import Figure

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.diagnosis.candidate import Candidate
from maglev_oc.diagnosis.feedback import compensation_study
from maglev_oc.diagnosis.guides import friction_candidates
from maglev_oc.diagnosis.result import Effect
from maglev_oc.regression.terms import constant_force
from maglev_oc.reporting.diagnosis_plots import compensation_plot
from maglev_oc.results import Estimate, PerAxis
from maglev_oc.sim.effects import Encoder, TwinEffects
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.scenarios import paper_scenarios
from maglev_oc.sim.twin import RigTwin
from tests._diagnosis_cases import _ctx, _effect
from tests.diagnosis_support import stub_diagnosis


def test_the_compensation_leaves_out_the_share_the_guides_hold_and_the_twin_keeps_it(model):
    """Horizontal guide friction (Coulomb 2 N, viscous 5 N s/m, 60 % held while sticking) at a speed
    of 1 mm/s (stuck: exp(-(v / 2 mm/s)^2) = 0.78): what the regulator feeds forward is the Coulomb
    and viscous force alone, -(F_c tanh(v / v_r) + c v) / M_h (closed form), the held share being
    no force a controller can cancel; the twin of the identified plant has the whole friction, the
    held share of the model's own acceleration added (-h a_model exp(-(v / v_s)^2), from the
    model's f). The stage file carries the same two functions (1e-12: the same arithmetic)."""
    from maglev_oc.diagnosis.feedback import _effects_acceleration, improvement
    from maglev_oc.regression.terms import REVERSAL_SPEED

    ctx = _ctx(model)
    (friction,) = [c for c in friction_candidates(ctx) if c.name == "guide_friction_horizontal"]
    fc, c, h = 2.0, 5.0, 0.6
    e = _effect(friction, [fc, c, h])
    v = 1e-3
    x = np.array([0.02, 0.0, 0.01, v])
    u = np.array([0.3, 1.2])
    mh = model.params.mass_horizontal
    own = -(fc * math.tanh(v / REVERSAL_SPEED) + c * v) / mh
    a_model = float(np.asarray(ca.DM(model.f(x, u))).ravel()[3])
    held = -h * a_model * math.exp(-((v / REVERSAL_SPEED) ** 2))
    comp = np.asarray(_effects_acceleration([e], with_inputs=False)(x)).ravel()
    twin = np.asarray(_effects_acceleration([e], with_inputs=True)(x, u)).ravel()
    np.testing.assert_allclose(comp, [0.0, own], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(twin, [0.0, own + held], rtol=1e-12, atol=1e-15)
    # a ratio of errors above 1 is an improvement: before / after, per axis
    study = SimpleNamespace(
        before=SimpleNamespace(mean_error=PerAxis.of([2e-6, 9e-6])),
        after=SimpleNamespace(mean_error=PerAxis.of([1e-6, 3e-6])),
    )
    np.testing.assert_allclose(improvement(study), [2.0, 3.0], rtol=1e-12)


FORCE = 2.0
"""[N] the found constant horizontal force of the compensation study's diagnosis."""


# --- the compensation study's default plant --------------------------------------------------------------
def _force_found(model):
    """A stub diagnosis with the papers' constants (before and after) and one found effect: a
    constant horizontal force of ``FORCE`` N."""
    term = constant_force(model.params, "horizontal")
    cand = Candidate(term, "constant", "position", "a held position", lambda e: None, lambda e: "")
    nan = PerAxis(math.nan, math.nan)
    effect = Effect(
        term.name,
        "",
        "",
        "horizontal",
        {"force": Estimate(FORCE, 0.1, "N")},
        1.0,
        0.1,
        5.0,
        nan,
        nan,
        "",
        "",
        np.array([FORCE]),
        cand,
    )
    c = {k: Estimate(getattr(model.constants, k), 0.0, "") for k in ("C1", "C2", "C3", "C4")}
    return dataclasses.replace(stub_diagnosis(), constants_base=c, constants_final=c, effects=[effect])


def test_the_compensation_studys_default_plant_carries_the_found_effects(model):
    """The default plant, rebuilt here: the identified constants, 10 um encoders, and the found
    force written out as its acceleration (0, F / M_h). The study's runs (seed 0) are those of
    this twin; a twin with the constants alone gives visibly different runs."""
    diag = _force_found(model)
    scenario = dataclasses.replace(paper_scenarios()["sinusoid"], duration=1.0)
    study = compensation_study(diag, model, scenario=scenario)
    assert study.plant.startswith("twin of the identified plant")
    assert study.compensated == (diag.effects[0].name,)

    x, i = ca.SX.sym("x", 4), ca.SX.sym("i", 2)
    acc = ca.vertcat(0, FORCE / model.params.mass_horizontal)
    push = ca.Function("push", [x, i], [acc], ["x", "i"], ["acc"])
    with_force = RigTwin(model, TwinEffects(encoder=Encoder(), extra=push))
    without = RigTwin(model, TwinEffects(encoder=Encoder()))
    base = FeedbackLinearizingRegulator(model, name="FL, base model fitted")  # the papers' constants
    expected = ClosedLoop(with_force, base).run(scenario)
    plain = ClosedLoop(without, base).run(scenario)
    assert study.result_before.success and expected.success
    scale = np.max(np.abs(expected.x[2]))
    np.testing.assert_allclose(study.result_before.x, expected.x, rtol=1e-9, atol=1e-9 * scale)
    assert np.max(np.abs(plain.x[2] - expected.x[2])) > 1e-4


# --- the compensation study's labels --------------------------------------------------------------------
def test_the_compensation_studys_runs_are_labelled_before_and_after(model):
    """A found constant force, 1 s of the papers' sinusoid: the run without compensation is the "FL,
    base model fitted" regulator's and the other the "FL, effects compensated" one's, in the results,
    their metrics and the legend of the report's compensation plot (before, then after)."""
    scenario = dataclasses.replace(paper_scenarios()["sinusoid"], duration=1.0)
    study = compensation_study(_force_found(model), model, scenario=scenario)
    names = ("FL, base model fitted", "FL, effects compensated")
    assert (study.result_before.controller, study.result_after.controller) == names
    assert (study.before.controller, study.after.controller) == names
    fig = Figure(figsize=(6, 5))
    compensation_plot(study)(fig, (0.0, 0.0, 1.0, 1.0))
    assert [t.get_text() for t in fig.legends[0].get_texts()] == list(names)


def test_the_effects_accelerations_add_up(model):
    """The stage file's and the controllers' effects Function is the sum of every found effect's
    acceleration (seed-45 survivor: each effect replaced the one before, so only the last was
    compensated): two guide frictions, one per axis, give each alone on its axis and their sum
    (1e-12: the same arithmetic), for the compensation (state only) and the twin (with currents)."""
    from maglev_oc.diagnosis.feedback import _effects_acceleration
    from maglev_oc.diagnosis.guides import friction_candidates
    from tests._diagnosis_cases import _ctx, _effect

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


# --- the compensation study ------------------------------------------------------------------------------
def test_the_compensation_studys_after_regulator_compensates_the_found_force(model):
    """A found constant horizontal force, the papers' constants before and after, 1 s of the
    sinusoid on the default twin (which carries the force): the regulator with the force compensated
    runs a different closed loop from the base one and tracks the horizontal axis better over its
    second half."""
    scenario = dataclasses.replace(paper_scenarios()["sinusoid"], duration=1.0)
    study = compensation_study(_force_found(model), model, scenario=scenario)
    assert not np.array_equal(study.result_before.u, study.result_after.u)
    # the horizontal tracking error over the second half (the papers' metrics start at 8 s)
    errors = [
        np.sqrt(np.mean((res.x[2] - res.reference[3])[res.t >= 0.5] ** 2))
        for res in (study.result_before, study.result_after)
    ]
    assert errors[1] < errors[0]


def test_with_nothing_found_the_key_figure_shows_one_loop_and_says_why():
    """A diagnosis that found nothing has nothing to compensate: the key figure draws the FL loop
    with the refitted constants alone (one line, the run's |encoder - reference| in um, no
    before/after legend) under a caption that says nothing was found, not "what the found effects
    explain"."""
    from types import SimpleNamespace

    from maglev_oc.reporting.diagnosis_plots import key_plot

    t = np.linspace(0.0, 1.0, 11)
    y = np.vstack([0.0195 + 1e-6 * t, 1e-6 * t])
    reference = np.zeros((6, t.size))
    reference[0] = 0.0195
    run = SimpleNamespace(t=t, y=y, reference=reference)
    study = SimpleNamespace(result_before=run, result_after=run, scenario="sinusoid")
    fig = Figure(figsize=(6, 4))
    title = key_plot(stub_diagnosis(), study)(fig, (0.0, 0.0, 1.0, 1.0))
    assert "nothing found" in title.lower() and "found effects explain" not in title
    (ax,) = fig.axes
    (line,) = ax.get_lines()
    # (1e-9: the gap error is a difference of two numbers near 19.5 mm)
    np.testing.assert_allclose(line.get_ydata(), np.hypot(1e-6 * t, 1e-6 * t) * 1e6, rtol=1e-9)
    assert not fig.legends
