"""Properties of the operating-region study's figures and verdict (``maglev_oc.region.study``),
checked against linear responses integrated independently, finer grids and planted runs:

- a step is predicted to hit a stopper exactly when its linear response reaches either one;
- the worst start is the witness scaled onto the certified boundary and is judged against the
  study's current limit; the enlargement is the ratio of each size; the least current on R = 0 is
  the least over the gap range;
- the verdict names every contradiction, the highest certified confidence needs every lower one,
  and the FL map succeeds only within F (a linear regulator's whenever it converged);
- the table of certified sets gives every semi-axis in millimetres, and set-point gaps are
  accepted up to 40 mm exactly.
"""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.linalg import expm

from maglev_oc.errors import InputError
from maglev_oc.region import study as study_module
from maglev_oc.region.closed_loop import N_ERROR, Reference, RegulatorLoop
from maglev_oc.region.ellipsoid import initial_condition_set
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.montecarlo import BatchOutcome, check_error_states
from maglev_oc.region.study import _predicted_stoppers, operating_region_study, step_extremes
from tests._region_cases import _nominal
from tests.test_region_study_properties import TINY


# --- the study -------------------------------------------------------------------------------------
def test_a_step_is_predicted_to_hit_a_stopper_when_its_linear_response_reaches_either_one(model):
    """Where F holds the FL loop is linear in the errors, so a step from rest reaches a stopper
    exactly when the linear response target + e(t) does, on either side. Checked on a grid of
    start and target gaps against the response integrated independently (scipy expm, 1 ms steps
    over 10 s, the same horizon), away from the few pairs within 10 um of a stopper (where the
    two discretisations may disagree: the response moves < 1 um per 1 ms step near its extreme)."""
    loop = RegulatorLoop()
    feasible = FeasibleSet(model)
    starts = np.linspace(0.009, 0.029, 21)
    targets = np.linspace(0.009, 0.029, 21)
    predicted = _predicted_stoppers(feasible, step_extremes(loop), starts, targets)
    step = expm(loop.A * 1e-3)
    z, e1 = np.zeros(N_ERROR), [1.0]
    z[0] = 1.0
    for _ in range(10_000):
        z = step @ z
        e1.append(z[0])
    e1 = np.array(e1)
    g_lo, g_hi = feasible.gap_range
    assert predicted.any()  # some steps do reach a stopper on this grid
    for i, target in enumerate(targets):
        for j, start in enumerate(starts):
            gap = target + (start - target) * e1
            distance = min(gap.min() - g_lo, g_hi - gap.max())
            if abs(distance) > 1e-5:
                assert predicted[i, j] == (distance < 0), (start, target)


def test_the_worst_start_is_the_witness_scaled_onto_the_certified_boundary(loop, monkeypatch):
    """The run "from the certified boundary nearest F's edge": the witness (V = level_upper, outside)
    scaled back along its own ray to V = 0.999 level, at the witness's phase."""
    seen = {}

    def fake(sim, loop_, reference, P, level, z, *, phase, current_limit):
        seen.update(z=z[:, 0], phase=phase, level=level)
        return "run"

    monkeypatch.setattr(study_module, "check_error_states", fake)
    w = np.linspace(1.0, 2.0, 10) * 1e-3
    nominal = dataclasses.replace(_nominal(loop, 0.4), witness=w, witness_phase=1.25, level_upper=0.9)
    assert w @ nominal.P @ w > 0.4  # the witness lies outside the certified set
    assert study_module._worst_start(None, loop, nominal.reference, nominal, 9.0) == "run"
    z = seen["z"]
    assert z @ nominal.P @ z == pytest.approx(0.999 * 0.4, rel=1e-12)
    cos = z @ w / (np.linalg.norm(z) * np.linalg.norm(w))
    assert cos == pytest.approx(1.0, abs=1e-12)
    assert seen["phase"] == 1.25 and seen["level"] == 0.4


def test_the_enlargement_is_the_ratio_of_each_size(loop):
    """Enlargement: the SDP's certified rectangle and semi-axes over the Lyapunov P's, each side
    over its own side (two certificates whose e1 and e2 grow by different factors)."""
    P0 = loop.lyapunov_matrix()
    P1 = P0.copy()
    P1[5:, 5:] *= 0.25  # the horizontal axis 2 x larger at the same level
    ok = {"success": True}
    lyap = dataclasses.replace(_nominal(loop, 0.4), **ok)
    sdp_cert = dataclasses.replace(
        _nominal(loop, 0.9), P=P1, initial_conditions=initial_condition_set(P1, 0.9)
    )
    sdp = type("Sdp", (), {"certified": sdp_cert})()
    enl = study_module._enlargement(lyap, sdp)
    (a0, b0), (a1, b1) = lyap.initial_conditions.rectangle, sdp_cert.initial_conditions.rectangle
    assert enl.e1 == pytest.approx(a1 / a0, rel=1e-12) and enl.e2 == pytest.approx(b1 / b0, rel=1e-12)
    assert enl.e2 > 1.5 * enl.e1  # the two sides did grow differently
    assert enl.area == pytest.approx(a1 * b1 / (a0 * b0), rel=1e-12)
    s0, s1 = lyap.initial_conditions.semi_axes, sdp_cert.initial_conditions.semi_axes
    assert enl.semi_axes == pytest.approx({k: s1[k] / s0[k] for k in s0}, rel=1e-12)


def _study_parts(certified=True, bad=0, unsafe=0):
    ref = type("R", (), {"lyapunov": type("L", (), {"success": certified})(), "checks": {}})()
    ref.checks = {"x": type("C", (), {"n": 5, "violations": bad})()}
    slices = {"Lyapunov P": (type("S", (), {"unsafe_certified": unsafe})(),)}
    return [ref], slices


def test_the_study_verdict_names_every_contradiction():
    """OperatingRegionStudy.status: "violations" when a run inside a certified set left F *or* a
    certified slice start was unsafe; "not_certified" when a reference has no certificate;
    otherwise "certified"."""
    assert study_module._verdict(*_study_parts())[:2] == (True, "certified")
    assert study_module._verdict(*_study_parts(bad=1))[:2] == (False, "violations")
    assert study_module._verdict(*_study_parts(unsafe=1))[:2] == (False, "violations")
    assert study_module._verdict(*_study_parts(certified=False))[:2] == (False, "not_certified")


def test_the_least_current_on_r_zero_is_the_least_over_the_gap_range(model):
    """|u| >= |i_d| = |L3 / (2 L4)| on R = 0: the study reports the least of it over the stoppers'
    gap range and where. Checked on a grid 10 x finer (the reported value is a grid minimum: within
    1e-3 of the finer one, the function being smooth on a 0.1 mm grid) and at its own gap."""
    feasible = FeasibleSet(model)
    current, gap = study_module._r_zero_current(model, feasible)
    gaps = np.linspace(*feasible.gap_range, 2201)
    _, _, L3, L4 = model.coefficients(gaps)
    fine = np.abs(L3 / (2 * L4))
    assert current <= fine.min() * (1 + 1e-3)
    _, _, l3, l4 = model.coefficients(np.array([gap]))
    assert current == pytest.approx(abs(l3[0] / (2 * l4[0])), rel=1e-12)
    assert feasible.gap_range[0] <= gap <= feasible.gap_range[1]


def test_the_highest_certified_confidence_needs_every_lower_one():
    """CertifiedRobustStudy.highest_certified: the highest level certified "with every lower one":
    a failure at 0.9 stops the count there even if 0.95 was certified."""
    cert = [type("C", (), {"success": ok})() for ok in (True, False, True)]
    row = study_module.CertifiedRobustRow("20 mm", None, "", tuple(cert))
    st = study_module.CertifiedRobustStudy((0.5, 0.9, 0.95, 0.99), 0.9, 1000, (1.0,), (row,), None, 0, 0)
    assert st.highest_certified(row) == 0.5
    none = study_module.CertifiedRobustRow("20 mm", None, "", (cert[1],))
    assert st.highest_certified(none) is None


class _PlantedSim:
    """A simulator whose runs end as planted, one per start: converged, over the current limit,
    R < 0, converged (the start x target map's outcomes, BASIN_OUTCOMES 0, 1, 2, 0)."""

    def __init__(self, name):
        self.controller = type("Ctrl", (), {"name": name, "n_state": 10})()
        self.references = []

    def with_duration(self, duration):
        return self

    def run(self, x0, c0, reference):
        self.references.append(np.array(reference, dtype=float))
        n = x0.shape[1]
        final = np.zeros((4, n))
        final[0], final[2] = reference[0], reference[3]  # every run settles on its target
        return BatchOutcome.of(
            {"total": 0.0},
            min_margin=np.array([1.0, 1.0, -0.5, 1.0]),
            max_current=np.array([5.0, 12.0, 5.0, 5.0]),
            stopper_hit=np.zeros(n, bool),
            min_gap=np.full(n, 0.01),
            max_gap=np.full(n, 0.02),
            max_abs_position=np.full(n, 0.02),
            final_twin=final,
            final_controller=np.zeros((10, n)),
            finite=np.ones(n, bool),
        )


def test_the_fl_map_succeeds_only_within_f_and_the_linear_ones_when_converged(model):
    """The start x target maps: "success (converged without a stopper; for the FL regulator also
    without leaving F)". Planted runs: the FL map's success is outcome 0 only, a linear
    regulator's every converged outcome (0, 1, 2: the ideal twin does not limit the current)."""
    run = type("Run", (), {})()
    run.model, run.limit = model, 9.0
    run.config = type("Cfg", (), {"linear_horizon": 1.0})()
    run.simulator = lambda twin, ctrl, duration: _PlantedSim(ctrl.name)
    starts, targets = np.array([0.01, 0.012, 0.014, 0.016]), np.array([0.018, 0.02])
    linear = type("Lin", (), {"name": "linear regulator"})()
    fl_sim = _PlantedSim("FL")
    maps = study_module._start_target_maps(run, fl_sim, [linear], starts, targets)
    # every run is the set-point (target gap, 20 mm), as Reference.setpoint lays it out (values,
    # velocities and accelerations of gap and position): at rest there
    assert len(fl_sim.references) == targets.size
    for g, ref in zip(targets, fl_sim.references, strict=True):
        setpoint = Reference.setpoint(g, study_module.LARGE_STEP_TARGET[1]).signals(0.0)[:, 0]
        np.testing.assert_array_equal(ref, setpoint)
    np.testing.assert_array_equal(maps["FL"]["outcome"], [[0, 1, 2, 0]] * 2)
    np.testing.assert_array_equal(maps["FL"]["success"], [[True, False, False, True]] * 2)
    np.testing.assert_array_equal(maps["linear regulator"]["success"], [[True, True, True, True]] * 2)


def test_the_worst_start_is_judged_against_the_studys_current_limit(model, monkeypatch):
    """Every run of the study's Monte Carlo, the worst start included, is judged with the study's
    current limit (the default F's 9 A): recorded at each call; the worst start did run."""
    limits = []

    def recording(*args, **kwargs):
        limits.append(kwargs.get("current_limit", "default"))
        return check_error_states(*args, **kwargs)

    monkeypatch.setattr("maglev_oc.region.study.check_error_states", recording)
    st = operating_region_study(model, dataclasses.replace(TINY, robust_runs=0))
    assert st.references[0].worst_start  # the run from the boundary point was made
    assert limits and set(limits) == {FeasibleSet(model).current_limit}


# --- region -------------------------------------------------------------------------------------
def test_the_table_of_certified_sets_gives_every_semi_axis_in_millimetres():
    """certificate_rows: (reference, P, level, upper, tightness, binding, e1 [mm], e1' [mm/s],
    e2 [mm], e2' [mm/s], rectangle [mm]) from a certificate's semi-axes and rectangle in metres."""
    from maglev_oc.region.closed_loop import Reference
    from maglev_oc.region.study import certificate_rows

    semi = {"e1": 1.5e-3, "e1_rate": 2.5e-2, "e2": 7.0e-3, "e2_rate": 4.0e-2}
    cert = SimpleNamespace(
        level=0.8,
        level_upper=0.9,
        tightness=0.1,
        binding="travel",
        initial_conditions=SimpleNamespace(semi_axes=semi, rectangle=(1.25e-3, 6.5e-3)),
    )
    ref = SimpleNamespace(reference=Reference.setpoint(0.02), lyapunov=cert, sdp=None)
    (row,) = certificate_rows(SimpleNamespace(references=[ref]))
    assert row[1:6] == ("Lyapunov eq.", 0.8, 0.9, 0.1, "travel")
    np.testing.assert_allclose(row[6:10], [1.5, 25.0, 7.0, 40.0], rtol=1e-12)
    assert row[10] == "1.25 x 6.50"


def test_a_studys_set_point_gaps_are_accepted_up_to_40_mm_exactly():
    from maglev_oc.region.study import StudyConfig

    StudyConfig(setpoints_mm=(5.0, 40.0), slice_setpoints_mm=(40.0,))
    for bad in (math.nextafter(40.0, 41.0), math.nextafter(5.0, 0.0)):
        with pytest.raises(InputError, match=r"set-point gaps are in millimetres in \[5, 40\]"):
            StudyConfig(setpoints_mm=(bad,))
        with pytest.raises(InputError, match=r"set-point gaps are in millimetres in \[5, 40\]"):
            StudyConfig(slice_setpoints_mm=(bad,))
