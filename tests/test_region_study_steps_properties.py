"""Properties of what the operating-region study runs and records (``maglev_oc.region.study``), with
its expensive steps replaced by recorders or stubs where the property is about what is handed on:

- its timings name its steps in the order they ran, with the large step's when it is on; each
  critical radius is labelled with the reference it probes; a certified robust row certifies the P
  its SDP chose;
- a basin run is labelled by the first outcome that applies, and a sinusoid spreads its runs over
  eight phases;
- the quantisation runs start inside the certified set about the reference at t = 0, and their
  Monte Carlo adds encoder noise;
- the large step's sweep is the map column at the start nearest the papers', and its Lyapunov
  ratio is V at the start over the certified level.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from types import SimpleNamespace

import numpy as np
import pytest

import maglev_oc.region.study as study
from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.control.gains import OMEGA0
from maglev_oc.region import study as study_module
from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.montecarlo import BatchSimulator
from maglev_oc.region.procedure2 import Procedure2
from maglev_oc.region.study import BASIN_OUTCOMES, operating_region_study
from maglev_oc.results import check_result
from tests.test_region_study import TINY


# --- the study --------------------------------------------------------------------------------
def test_a_basin_run_is_labelled_by_the_first_outcome_that_applies():
    """BASIN_OUTCOMES: "the first that applies in this order: diverged, hit a stopper, not settled,
    met R < 0, commanded more than the current limit; else converged", on every combination of
    the five flags."""
    flags = np.array(list(itertools.product([False, True], repeat=5))).T  # (5, 32)
    finite, stopper, settled, over, negative = ~flags[0], flags[1], ~flags[2], flags[3], flags[4]
    code = study_module._outcome_codes(finite, stopper, settled, over, negative)
    for k in range(flags.shape[1]):
        order = (
            ("diverged", not finite[k]),
            ("stopper", stopper[k]),
            ("not settled", not settled[k]),
            ("R < 0", negative[k]),
            ("over the current limit", over[k]),
            ("converged", True),
        )
        expected = next(name for name, applies in order if applies)
        assert BASIN_OUTCOMES[code[k]] == expected, flags[:, k]


@pytest.mark.parametrize("n", [0, 1, 7, 8, 13, 420, 421])
def test_a_sinusoid_spreads_every_run_over_eight_phases(n):
    """The runs of a sinusoid's check are spread over 8 phases of the orbit, evenly (counts differ
    by at most 1) and all of them (the counts add up to n); a set-point runs all at phase 0."""
    groups = study_module._phases(Reference.paper_sinusoid(), n)
    counts = [c for _, c in groups]
    assert sum(counts) == n
    if n:
        assert len(groups) == 8 and max(counts) - min(counts) <= 1
        np.testing.assert_allclose([p for p, _ in groups], 2 * math.pi * np.arange(8) / 8)
    assert study_module._phases(Reference.setpoint(0.02), n) == [(0.0, n)]


def test_the_large_steps_lyapunov_ratio_is_v_at_the_start_over_the_certified_level(model, monkeypatch):
    """``LargeStepStudy.fl_ratio_lyapunov`` is V(start) / level for Procedure 2's certificate
    with the Lyapunov P at the large step's target (computed here from the same certificate,
    to the round-off of a quadratic form). The runs and maps of the study are stubbed: only the
    certificate is computed."""
    import maglev_oc.region.study as study
    from tests.test_region_study import TINY

    stubbed = ("_linear_regions", "_start_target_maps", "frozen_poles", "step_extremes")
    stubbed += ("_predicted_stoppers",)
    for name in stubbed:
        monkeypatch.setattr(study, name, lambda *a, **k: {})
    monkeypatch.setattr(study, "check_error_states", lambda *a, **k: None)
    config = dataclasses.replace(TINY, sdp=False)
    feasible, loop = FeasibleSet(model), RegulatorLoop()
    run = study._Run(model, config, feasible, loop, np.random.default_rng(0), print, {})
    proc = Procedure2(feasible, loop)
    ls = study._large_step(run, proc, None, None)
    reference = Reference.setpoint(*study.LARGE_STEP_TARGET)
    cert = Procedure2(feasible, loop).run(reference, seed=config.seed)
    assert cert.success
    z0 = loop.error_state(np.array(study.LARGE_STEP_START), np.zeros(6), reference)[:, 0]
    assert ls.fl_ratio_lyapunov == pytest.approx(float(z0 @ cert.P @ z0) / cert.level, rel=1e-12)
    assert ls.fl_ratio_sdp == np.inf  # no SDP asked for


MM = 1e-3


# --- the large step's sweep at the papers' start -----------------------------------------------------
@pytest.mark.parametrize(
    ("starts_mm", "nearest_mm"),
    [
        (study.StudyConfig().map_starts_mm, 26.0),  # the report's starts, 9..29 mm: the papers' 26 mm itself
        ((9.0, 20.0, 25.4, 27.0, 29.0), 25.4),  # 0.6 mm below beats 1 mm above
        ((29.0, 9.0, 26.8, 12.0), 26.8),  # any order: the nearest, not the first or the least
    ],
    ids=["report", "below", "unordered"],
)
def test_the_large_step_sweep_is_the_map_column_at_the_start_nearest_the_papers(
    model, monkeypatch, starts_mm, nearest_mm
):
    """The maps are stubbed with each entry holding its own start and target gap, so the sweep
    must hold, for every target, the start nearest 26 mm (LARGE_STEP_START) and the targets in
    order. Everything else of the step (certificates, runs, linear regions, poles) is stubbed:
    only the choice of the column is computed."""
    assert study.LARGE_STEP_START[0] == 26 * MM

    def maps(run, sim, ctrls, starts, targets):
        grid = {"start": np.tile(starts, (targets.size, 1)), "target": np.tile(targets[:, None], starts.size)}
        return {"fl": grid, "lqr": {k: v.copy() for k, v in grid.items()}}

    for name in ("_linear_regions", "frozen_poles", "step_extremes", "_predicted_stoppers"):
        monkeypatch.setattr(study, name, lambda *a, **k: {})
    for name in ("check_error_states", "paper_linear_regulator", "lqr_regulator"):
        monkeypatch.setattr(study, name, lambda *a, **k: None)
    monkeypatch.setattr(study, "_start_target_maps", maps)
    config = dataclasses.replace(TINY, sdp=False, map_starts_mm=starts_mm, map_targets_mm=(12.0, 18.0, 24.0))
    feasible, loop = FeasibleSet(model), RegulatorLoop()
    run = study._Run(model, config, feasible, loop, np.random.default_rng(0), lambda _m: None, {})
    no_certificate = SimpleNamespace(run=lambda *a, **k: SimpleNamespace(success=False, P=None, level=0.0))
    ls = study._large_step(run, no_certificate, None, None)
    assert set(ls.sweep) == {"fl", "lqr"}
    for sweep in ls.sweep.values():
        np.testing.assert_array_equal(sweep["start"], np.full(3, nearest_mm * MM))
        np.testing.assert_array_equal(sweep["target"], np.array([12.0, 18.0, 24.0]) * MM)


# --- the quantisation Monte Carlo's starts --------------------------------------------------------
def test_the_quantisation_runs_start_inside_the_certified_set_about_the_reference_at_t0(
    model, loop, monkeypatch
):
    """A study of the papers' sinusoid alone (its certificate by Procedure 2; no 20 mm set-point,
    so the quantisation runs use the sinusoid's): the simulator is handed reference samples that
    start at t = 0 (the closed form r(0): 25 mm, 0 mm, ...; 1e-12 in SI) and start states whose
    error coordinates about r(0), z = error_state(x, xi, r, phase 0), lie in the certified set:
    V / level <= 1 (+1e-9: the round-off of mapping mm-sized errors through cm-sized states) and
    equal to the start ratios the check reports (1e-9 absolute, the same round-off)."""
    ref = Reference.paper_sinusoid()
    feasible = FeasibleSet(model)
    cert = Procedure2(feasible, loop, starts=2).run(ref)
    assert cert.success, cert.message
    rs = study.ReferenceStudy(ref, cert, None, None, {}, {})
    config = study.StudyConfig(
        setpoints_mm=(15.0,), sdp=False, linear=False, quantization_samples=8, horizon=0.004, compile=False
    )
    run = study._Run(model, config, feasible, loop, np.random.default_rng(0), lambda _m: None, {})
    calls = []
    original = BatchSimulator.run

    def recording(self, x0, c0, reference, *args, **kwargs):
        calls.append((np.array(x0), np.array(c0), np.array(reference)))
        return original(self, x0, c0, reference, *args, **kwargs)

    monkeypatch.setattr(BatchSimulator, "run", recording)
    fl = FeedbackLinearizingRegulator(model, loop.K_h, loop.K_v, omega0=loop.omega0)
    check = study._quantization(run, fl, [rs])
    assert check is not None and len(calls) == 1
    x0, c0, samples = calls[0]
    w = OMEGA0
    r0 = [25 * MM, 0.0, -5 * MM * w**2, 0.0, 30 * MM * w, 0.0]
    np.testing.assert_allclose(samples[:, 0], r0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(c0[:4], x0, rtol=0, atol=0)  # observers at the true state
    z = loop.error_state(x0, c0[4:], ref, 0.0)
    ratio = np.einsum("in,ij,jn->n", z, cert.P, z) / cert.level
    assert np.all(ratio <= 1 + 1e-9), ratio
    np.testing.assert_allclose(ratio, check.start_ratio, rtol=0, atol=1e-9)


# --- the study: its timings and its quantisation Monte Carlo --------------------------------------
CONFIG = dataclasses.replace(
    TINY, samples=2, slice_points=3, quantization_samples=4, map_points=0, horizon=0.05, robust_runs=0
)
"""tests/test_region_study.py's TINY smaller still (one set-point, 0.05 s runs, no robust part):
about 0.4 s."""


STEPS = [
    "build solvers",
    "procedure 2 (Lyapunov P)",
    "SDP enlargement (incl. re-certification)",
    "feasibility maps",
    "build Monte Carlo (FL)",
    "Monte Carlo inside the certified sets",
    "Monte Carlo on slices (conservativeness)",
    "Monte Carlo with encoder quantisation",
    "total",
]
"""The steps such a study runs, in order, as the report's timing table names them."""


@pytest.fixture(scope="module")
def recorded_study(model):
    """The study, with every batch of runs it simulates recorded: (simulator, x0, c0, reference,
    outcome)."""
    calls = []
    original = BatchSimulator.run

    def recording(self, x0, c0, reference, noise=None, twin_states=None):
        out = original(self, x0, c0, reference, noise, twin_states)
        calls.append((self, np.array(x0), np.array(c0), np.array(reference), out))
        return out

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(BatchSimulator, "run", recording)
        study = operating_region_study(model, CONFIG)
    return study, calls, original


def test_the_studys_timings_name_its_steps_in_the_order_they_ran(recorded_study):
    study, _, _ = recorded_study
    check_result(study)
    assert list(study.timings) == STEPS
    assert all(v >= 0 for v in study.timings.values())
    assert study.slices["Lyapunov P"], "the slices step ran"


def test_the_quantisation_monte_carlo_adds_encoder_noise(recorded_study):
    """The quantisation check is the one batch run on a twin with an encoder; the same starts on
    that simulator without noise (its default, zero) end elsewhere: final gap or position apart by
    more than 1e-8 m (measured: ~1e-6 m, the noise's 2 um; rounding of cm-sized states is ~1e-17 m),
    while the check's outcome is that of its own run."""
    study, calls, original = recorded_study
    quantising = [c for c in calls if c[0].twin.effects.encoder is not None]
    assert len(quantising) == 1
    sim, x0, c0, reference, out = quantising[0]
    assert study.quantization is not None and study.quantization.outcome is out
    assert study.quantization.n == x0.shape[1] == CONFIG.quantization_samples
    quiet = original(sim, x0, c0, reference)
    moved = np.abs(out.final_twin[[0, 2]] - quiet.final_twin[[0, 2]])
    assert np.all(np.isfinite(moved)) and moved.max() > 1e-8, moved
    assert math.isfinite(study.quantization.max_current)


# --- the study's timings with the large step ---------------------------------------------------------
def test_a_study_with_the_large_step_names_its_steps_in_its_timings(model):
    """The seed-41 file's small study (tests/test_region_seed41_properties.py) with the large step
    turned on, for one start and one target and 0.05 s runs (about 2 s). Its timings name the
    steps in the order they ran, as the report's timing table prints them: the steps of the study
    without the large step, then the large step's FL certificates, the linear regulators' certified
    regions and the start x target map, then the total. Each step takes a time of zero or more and
    no more than the total."""
    config = dataclasses.replace(
        CONFIG, linear=True, map_starts_mm=(26.0,), map_targets_mm=(18.0,), linear_horizon=0.05
    )
    study = operating_region_study(model, config)
    check_result(study)
    large = [
        "large step: FL certificates",
        "large step: certified regions of attraction",
        "large step: sampled start x target map",
    ]
    assert list(study.timings) == [*STEPS[:-1], *large, "total"]
    assert all(0 <= v <= study.timings["total"] for v in study.timings.values())
    # the steps the names stand for ran: three linear regulators, one start x target map each
    assert len(study.large_step.linear) == 3
    assert all(m["outcome"].shape == (1, 1) for m in study.large_step.maps.values())
    # four different controllers, as the papers compare them: the FL regulator, the linear regulator
    # with and without its feedforward, and the LQR (a map per controller, each under its own name)
    assert len(study.large_step.maps) == 4 and "FL regulator" in study.large_step.maps
    assert sum("no feedforward" in name for name in study.large_step.maps) == 1


def test_each_critical_radius_is_labelled_with_the_reference_it_probes(model):
    """The seed-41 file's small study with a robust part of 4 runs per probe (about 1 s): each
    bisection for the radius where runs first leave F carries the name of the certificate it grows
    (the report's bracket table finds its row by that name), there is one per certificate, and
    the bracket is ordered (safe below broken)."""
    config = dataclasses.replace(CONFIG, robust_runs=4, robust_probe_runs=4, certify_boxes=0)
    study = operating_region_study(model, config)
    check_result(study)
    rb = study.robust
    assert rb is not None and rb.certificates
    assert sorted(c.reference for c in rb.radii) == sorted(rb.certificates)
    assert all(0 <= c.safe_radius < c.broken_radius for c in rb.radii)


def test_a_certified_robust_row_certifies_the_p_its_sdp_chose(model):
    """The seed-41 file's small study with a certified robust part (2000 boxes per level, no
    Monte Carlo; about 1.2 s): a set-point whose robust SDP found a P (its message says so) has
    its nominal certificate made for that P, not for the Lyapunov equation's P of the nominal
    loop, which the SDP replaced because the confidence set's plants mismatch it."""
    config = dataclasses.replace(
        CONFIG, robust_runs=4, robust_probe_runs=0, certify_boxes=2000, certify_runs=0
    )
    study = operating_region_study(model, config)
    check_result(study)
    rows = study.robust.certified.rows
    assert rows
    for row in rows:
        assert row.nominal is not None and "P from the robust SDP" in row.sdp_message, row.sdp_message
        assert not np.allclose(row.nominal.P, RegulatorLoop().lyapunov_matrix(), rtol=1e-6)
