"""Properties of the eps-trend study (``maglev_oc.identification.eps_trend``), checked against the
papers' Table III, twin runs repeated here and stand-in trends:

- its logs: the Table II log is the locked run of the next seed, reproducible, and the friction
  trend runs the Table III log with that friction; it identifies the twin of the truth it is given
  and hands its options to every NPFSI run;
- it reads from the smallest to the largest eps; the damping rate is the friction runs' C1 slope
  less the default runs'; its verdict names the constants that follow the papers; its status is
  one of its documented three; it records its total wall time and reports its friction under the
  documented names.
"""

from __future__ import annotations

import dataclasses
import json
import re
from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.errors import InputError
from maglev_oc.identification import eps_trend, study
from maglev_oc.identification.eps_trend import (
    FLAT_BAND,
    RIG_FRICTION,
    TABLE2_NAMES,
    EpsTrend,
    _explanation,
    _papers,
    eps_trend_study,
)
from maglev_oc.identification.experiments import (
    TWIN_TRUTH,
    excitation_log,
    identification_effects,
    verification_effects,
)
from maglev_oc.identification.layout import CONSTANT_NAMES
from maglev_oc.identification.npfsi import PAPER_EPSILONS


def test_eps_trend_study_runs_the_twin_of_the_given_truth(model):
    """The eps-trend study identifies the twin whose constants it is given: with C1 25 % above and
    C2 15 % below the default twin's, the Table III NPFSI estimates (study's effects, eps = 0.01)
    are within 5 % of the given constants (on 5 s runs: 3 % for C1, 0.1 % for C2 measured), far
    from the default twin's."""
    given = TWIN_TRUTH.replace(C1=TWIN_TRUTH.C1 * 1.25, C2=TWIN_TRUTH.C2 * 0.85)
    st = eps_trend_study(model, truth_constants=given, duration=5.0, vertical_duration=5.0)
    assert st.truth["C1"] == given.C1
    for c in ("C1", "C2"):
        estimate = st.default_table3.value(c, 0.01)
        assert estimate == pytest.approx(getattr(given, c), rel=0.05), c


# --- the eps trend ---------------------------------------------------------------------------------------
def _trend(names, change):
    """An EpsTrend over the papers' eps whose constants change by ``change`` (relative) each."""
    eps = PAPER_EPSILONS
    values = np.array([[1.0, 1.0 + c / 2, 1.0 + c] for c in change])
    return EpsTrend("t", names, eps, values)


def test_the_damping_rate_is_the_friction_runs_c1_slope_less_the_default_runs(model, monkeypatch):
    # EpsTrendStudy.damping_rate: "read from the C1 slopes (friction minus default)"; papers_damping:
    # the papers' C1 slope (Table III of 000: 13.97 -> 16.23 from eps = 0.001 to 0.05) less our
    # default's, times M_h. The twin runs are replaced by trends of known slopes (the study's own
    # arithmetic is what is checked; its runs are checked in tests/test_eps_trend.py). 1e-9: round-off.
    t2 = ("C2", "C3", "C4")
    d3, d2 = _trend(CONSTANT_NAMES, (-0.04, 0.002, -0.02, -0.3)), _trend(t2, (0.002, -0.02, -0.3))
    f3, f2 = _trend(CONSTANT_NAMES, (0.06, 0.002, 0.03, 0.2)), _trend(t2, (0.002, 0.03, 0.2))
    log = SimpleNamespace(sample_time=1e-3)

    def runs(model, friction, **kw):
        return (d3, d2, log, True) if friction == (None, None) else (f3, f2, log, True)

    monkeypatch.setattr(eps_trend, "_twin_trend", runs)
    monkeypatch.setattr(eps_trend, "_npfsi_trend", lambda *a, **k: (d3, True))
    monkeypatch.setattr(eps_trend, "_limit", lambda *a: d3)
    study = eps_trend.eps_trend_study(model)
    span = PAPER_EPSILONS[-1] - PAPER_EPSILONS[0]
    assert study.damping_rate == pytest.approx((0.06 - -0.04) / span, rel=1e-9)
    papers_slope = (16.23 / 13.97 - 1) / span
    expected = model.params.mass_horizontal * (papers_slope - -0.04 / span)
    assert study.papers_damping == pytest.approx(expected, rel=1e-3)  # the table's 4 digits


# --- eps trend -------------------------------------------------------------------------------------
def test_an_eps_trend_reads_from_the_smallest_to_the_largest_eps_and_refuses_another_order():
    tr = EpsTrend(
        "Table III", ("C1", "C3"), (0.001, 0.01, 0.05), [[13.97, 14.20, 16.23], [30.33, 31.04, 33.44]]
    )
    # Table III of 000: C1 13.97 -> 16.23 is +16.18 %, over 0.049 s of eps (exact arithmetic, 1e-12)
    assert tr.change["C1"] == pytest.approx(16.23 / 13.97 - 1, rel=1e-12)
    assert tr.slope["C1"] == pytest.approx((16.23 / 13.97 - 1) / 0.049, rel=1e-12)
    # the same numbers with the columns out of order would turn the change round: refused
    with pytest.raises(InputError, match="increase"):
        EpsTrend("shuffled", ("C1",), (0.05, 0.001, 0.01), [[16.23, 13.97, 14.20]])


# --- the eps-trend study's logs --------------------------------------------------------------------------
def test_the_table2_log_is_the_locked_run_of_the_next_seed_and_reproducible(model, truth_model):
    """_logs docstring: the Table II log (mover locked at x3 = 0, gap about 16 mm) uses seed + 1, as the
    identification study does. It is the same run as excitation_log with that seed (bit for bit: the same
    simulation), and the same again on a second call."""
    seed, duration = 3, 1.5
    _, t2 = eps_trend._logs(
        truth_model, model, identification_effects(), verification_effects(), duration, duration, seed
    )
    expected = excitation_log(
        truth_model,
        duration=duration,
        seed=seed + 1,
        controller_model=model,
        effects=verification_effects(),
        gap_offset=study.VERTICAL_GAP,
        locked_position=0.0,
    )
    np.testing.assert_array_equal(t2.x, expected.x)
    np.testing.assert_array_equal(t2.u, expected.u)
    assert t2.source == expected.source
    _, again = eps_trend._logs(
        truth_model, model, identification_effects(), verification_effects(), duration, duration, seed
    )
    np.testing.assert_array_equal(again.x, t2.x)


def test_the_friction_trend_runs_the_table3_log_with_that_friction(model, truth_model):
    """_twin_trend: NPFSI on the study's twin runs with the given guide friction added to the study's
    effects. Its Table III log is the identification effects' run with that friction, bit for bit, and
    differs from the run without it (the friction is not lost on the way)."""
    friction = eps_trend.RIG_FRICTION
    seed, duration = 3, 2.0
    _, _, log, _ = eps_trend._twin_trend(
        model, friction, duration=duration, vertical_duration=duration, seed=seed
    )
    with_friction = dataclasses.replace(
        identification_effects(), friction_horizontal=friction[0], friction_vertical=friction[1]
    )
    common = {"duration": duration, "seed": seed, "controller_model": model}
    expected = excitation_log(truth_model, effects=with_friction, **common)
    np.testing.assert_array_equal(log.x, expected.x)
    np.testing.assert_array_equal(log.u, expected.u)
    plain = excitation_log(truth_model, effects=identification_effects(), **common)
    assert not np.array_equal(log.x, plain.x)


# --- the eps-trend study's wall time -------------------------------------------------------------------
def test_eps_trend_study_records_and_reports_its_total_wall_time(model, monkeypatch):
    """The study's timings hold its total under ``"total"``: from its start to its end, so at least
    the sum of its steps; the report prints it with ``.2f`` and the JSON carries it. The twin runs are
    replaced by trends (as in tests/test_identification_round2_properties.py) and the clock by one
    that advances by a power of two on each read, so every difference is exact."""
    t2 = ("C2", "C3", "C4")
    d3, d2 = _trend(CONSTANT_NAMES, (-0.04, 0.002, -0.02, -0.3)), _trend(t2, (0.002, -0.02, -0.3))
    f3, f2 = _trend(CONSTANT_NAMES, (0.06, 0.002, 0.03, 0.2)), _trend(t2, (0.002, 0.03, 0.2))
    log = SimpleNamespace(sample_time=1e-3)
    reads: list[float] = []

    def clock():
        reads.append(float(2 ** len(reads)) - 1.0)  # 0, 1, 3, 7, ...: each step takes a new time
        return reads[-1]

    def runs(model, friction, **kw):
        return (d3, d2, log, True) if friction == (None, None) else (f3, f2, log, True)

    monkeypatch.setattr(eps_trend, "_twin_trend", runs)
    monkeypatch.setattr(eps_trend, "_npfsi_trend", lambda *a, **k: (d3, True))
    monkeypatch.setattr(eps_trend, "_limit", lambda *a: d3)
    monkeypatch.setattr(eps_trend.time, "perf_counter", clock)
    study = eps_trend.eps_trend_study(model)
    monkeypatch.undo()
    total = study.timings["total"]
    assert total == reads[-1] - reads[0]  # the first read starts the study, the last ends it
    steps = [v for k, v in study.timings.items() if k != "total"]
    assert len(steps) == 4 and total >= sum(steps)
    assert f"total {total:.2f}" in study.report()
    assert study.to_dict()["timings"]["total"] == total


def test_eps_trend_study_status_is_one_of_its_documented_three(model, monkeypatch):
    """``EpsTrendStudy.status`` (its docstring): ``"reproduced"`` when with friction every constant
    moves the papers' way, ``"partly_reproduced"`` naming the rest otherwise, ``"failed"`` when a run
    did not complete; reports and the workflow compare it to these exact strings. The friction runs
    are replaced by the papers' own trends (every direction matches), then by the same with C4 of
    Table III reversed, then by a run that did not complete."""
    p3 = eps_trend._papers("table3", CONSTANT_NAMES)
    p2 = eps_trend._papers("table2", eps_trend.TABLE2_NAMES)
    d3 = _trend(CONSTANT_NAMES, (-0.04, 0.002, -0.02, -0.3))
    log = SimpleNamespace(sample_time=1e-3)
    reversed_c4 = p3.values.copy()
    reversed_c4[CONSTANT_NAMES.index("C4")] = reversed_c4[CONSTANT_NAMES.index("C4")][::-1]
    partly = eps_trend.EpsTrend("t", CONSTANT_NAMES, p3.eps, reversed_c4)
    cases = {
        "reproduced": ((p3, p2, log, True), None),
        "partly_reproduced": ((partly, p2, log, True), "C4"),
        "failed": ((p3, p2, log, False), None),
    }
    monkeypatch.setattr(eps_trend, "_npfsi_trend", lambda *a, **k: (d3, True))
    monkeypatch.setattr(eps_trend, "_limit", lambda *a: d3)
    for status, (friction_run, named) in cases.items():

        def runs(model, friction, run=friction_run, **kw):
            return (d3, p2, log, True) if friction == (None, None) else run

        monkeypatch.setattr(eps_trend, "_twin_trend", runs)
        study = eps_trend.eps_trend_study(model)
        assert study.status == status
        assert study.success == (status != "failed")
        assert named is None or f"Table III {named}" in study.message


# --- eps trend: the verdict names the agreeing constants ----------------------------------------------
def _flipped(trend: EpsTrend, names) -> EpsTrend:
    """``trend`` with the estimates of ``names`` in reverse eps order: their direction reversed."""
    values = np.array(trend.values)
    for k in names:
        i = trend.names.index(k)
        values[i] = values[i, ::-1]
    return EpsTrend("test: " + trend.source, trend.names, trend.eps, values)


@pytest.mark.parametrize(
    ("flip3", "flip2", "verdict"),
    [
        ((), (), "all of them"),
        (("C1",), (), "Table III C3, Table III C4, Table II C3, Table II C4"),
        (("C3",), ("C4",), "Table III C1, Table III C4, Table II C3"),
        (("C1", "C3", "C4"), ("C3", "C4"), "none of them"),
    ],
)
def test_the_eps_trend_verdict_names_the_constants_that_follow_the_papers(model, flip3, flip2, verdict):
    p3, p2 = _papers("table3", CONSTANT_NAMES), _papers("table2", TABLE2_NAMES)
    fields = dict(
        papers_table3=p3,
        papers_table2=p2,
        default_table3=p3,
        default_table2=p2,
        friction_table3=_flipped(p3, flip3),
        friction_table2=_flipped(p2, flip2),
        limit_default_table3=p3,
        zero_phase_table3=p3,
        band=FLAT_BAND,
        damping_rate=0.0,  # no damping paragraph: only the verdict is read here
        papers_damping=0.0,
    )
    text = _explanation(model, RIG_FRICTION, 1e-3, 1e-3, **fields)
    m = re.search(r"the papers' direction for (.*?)\. C2, pinned", text)
    assert m, text
    assert m.group(1) == verdict


# --- the eps-trend study's friction --------------------------------------------------------------------
def test_the_eps_trend_study_reports_its_friction_under_the_documented_names(model, monkeypatch):
    """``EpsTrendStudy.friction``: per axis given, {"coulomb_N", "viscous_N_s_per_m"} (the JSON's
    names, read by analyses/identification.py); an axis without friction is left out. The twin
    runs are replaced by the papers' trends (tests/test_identification_seed41_properties.py)."""
    from types import SimpleNamespace

    from maglev_oc.identification import eps_trend
    from maglev_oc.identification.layout import CONSTANT_NAMES
    from maglev_oc.sim.effects import GuideFriction

    p3 = eps_trend._papers("table3", CONSTANT_NAMES)
    p2 = eps_trend._papers("table2", eps_trend.TABLE2_NAMES)
    log = SimpleNamespace(sample_time=1e-3)
    monkeypatch.setattr(eps_trend, "_twin_trend", lambda model, friction, **kw: (p3, p2, log, True))
    monkeypatch.setattr(eps_trend, "_npfsi_trend", lambda *a, **k: (p3, True))
    monkeypatch.setattr(eps_trend, "_limit", lambda *a: p3)
    friction = (GuideFriction(coulomb=0.25, viscous=1.5), None)
    study = eps_trend.eps_trend_study(model, friction=friction)
    assert study.friction == {"horizontal": {"coulomb_N": 0.25, "viscous_N_s_per_m": 1.5}}
    assert json.loads(json.dumps(study.to_dict()))["friction"] == study.friction


def test_the_eps_trend_hands_its_options_to_every_npfsi_run(monkeypatch):
    from types import SimpleNamespace

    from maglev_oc.identification import eps_trend as E

    calls = []

    def npfsi(log, model, *, estimate, eps, **kw):
        calls.append((eps, kw))
        return SimpleNamespace(values={k: 1.0 for k in estimate}, success=True)

    monkeypatch.setattr(E, "npfsi", npfsi)
    marker = object()
    trend, ok = E._npfsi_trend("src", None, None, ("C1", "C2"), differentiator=marker)
    assert ok
    assert [e for e, _ in calls] == list(E.PAPER_EPSILONS)
    assert all(kw == {"differentiator": marker} for _, kw in calls)
    assert trend.values.shape == (2, len(E.PAPER_EPSILONS))
