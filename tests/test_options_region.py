"""Options of ``maglev_oc.region`` passed by name, each test failing when its option is ignored (the
default used instead) or inverted:

- branch and bound: ``phase_cells`` is the number of cells over the phase of the first cover, for
  the nominal certificate and the robust one (the cells meeting the ball counted directly);
- inner polygons: ``n_vertices`` directions, and ``max_cells`` the interval budget per vertex;
  ``SdpCandidate.of`` keeps the construction level and solve time it is given;
- the robust analyses: ``assumed_covariance(relative)``, ``critical_radius(max_radius)`` and
  ``empirical_robust_level(max_rounds)`` (closed forms and planted thresholds);
- sampled plants and batches: the twin's ``initial_state(scales)``, ``run_plants(scales)`` and
  ``BatchSimulator.run(twin_states)``; ``Reference(gap_phase, position_phase)``;
- the study: ``StudyConfig(certify_boxes, certify_ladder)`` reach the robust certifier, the robust
  sweep's runs last the study's ``horizon``, the conservativeness slices go on past a set-point
  without a certificate, and the robust study says which certificate each set-point sweeps
  (steps checked with their expensive callees replaced by recorders).
"""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
from maglev_oc.control.gains import OMEGA0, PAPER_K_H, PAPER_K_V
from maglev_oc.model.stage import StageModel
from maglev_oc.region import robust as robust_module
from maglev_oc.region import study
from maglev_oc.region import study as study_module
from maglev_oc.region.branch_and_bound import LevelCertifier
from maglev_oc.region.closed_loop import Reference
from maglev_oc.region.feasibility import FeasibleSet
from maglev_oc.region.montecarlo import BatchSimulator, regulator_state
from maglev_oc.region.robust import assumed_covariance, critical_radius
from maglev_oc.region.robust_certificate import RobustCertifier
from maglev_oc.region.sdp import PolygonBuilder, SdpCandidate
from maglev_oc.region.sweep import PlantBatchSimulator, PlantSet, SampledPlantTwin, SweepSpec
from maglev_oc.sim.effects import TwinEffects
from maglev_oc.sim.twin import RigTwin
from maglev_oc.units import MM_TO_M


@pytest.fixture(scope="module")
def feasible(model):
    return FeasibleSet(model)


# --- branch and bound: the phase cells -----------------------------------------------------------------
def _ball_cells(d: int) -> int:
    """Cells of the 4^d grid over [-1, 1]^d that meet the unit ball, in closed form: a cell's point
    nearest the origin has |coordinate| 0.5 on its k outer sides and 0 on the others, so it meets
    the ball iff k / 4 <= 1; there are C(d, k) 2^k 2^(d - k) cells with k outer sides."""
    return sum(math.comb(d, k) * 2**d for k in range(d + 1) if k <= 4)


def test_nominal_branch_and_bound_starts_from_phase_cells_cells_over_the_phase(feasible, loop):
    """A small level of the papers' sinusoid is certified on the first pass when the phase is split
    finely (measured: 24 cells or more): the search then costs exactly the first cover, 64 zeta
    cells times ``phase_cells``. A coarse split needs refining, so it costs more than its cover.
    For a set-point the phase is pinned: every ``phase_cells`` gives the same search."""
    cert = LevelCertifier(feasible, loop, max_boxes=100_000)
    P = loop.lyapunov_matrix()
    ref = Reference.paper_sinusoid()
    assert _ball_cells(3) == 64
    for cells in (24, 48, 96):
        out = cert.certify(ref, P, 0.01, phase_cells=cells)
        assert out.status == "certified" and out.boxes == 64 * cells, (cells, out.boxes)
    coarse = cert.certify(ref, P, 0.01, phase_cells=1)
    assert coarse.status == "certified" and coarse.boxes > 64
    point = Reference.setpoint(0.02)
    assert {cert.certify(point, P, 1.0, phase_cells=c).boxes for c in (1, 24, 96)} == {
        cert.certify(point, P, 1.0).boxes
    }


def test_robust_branch_and_bound_starts_from_phase_cells_cells_over_the_phase(model, feasible, loop):
    """Condition (b) on a small level with a +-0.1 % box of plants: the mismatch's rate grows like
    sqrt(level) and the decay like level, so small levels are refuted, here on the first pass
    (measured for every split tried). The search then costs exactly the first cover (992 of the
    4^5 zeta cells meet the ball, times ``phase_cells``), and its witness is a first-pass box's
    midpoint: its phase the middle of one of the ``phase_cells`` cells over [0, 2 pi)."""
    C = np.asarray(model.constants.as_array())
    plants = PlantSet.box(0.999 * C, 1.001 * C)
    P = loop.lyapunov_matrix()
    assert _ball_cells(5) == 992
    for cells in (1, 5, 24):
        certifier = RobustCertifier(feasible, loop, max_boxes=1000, phase_cells=cells)
        out = certifier.certify(Reference.paper_sinusoid(), P, 1e-3, plants)
        assert out.status == "refuted" and out.boxes == 992 * cells, (cells, out.boxes)
        k = out.witness_phase / (2 * math.pi / cells) - 0.5  # the cell's index: an integer (1e-9)
        assert abs(k - round(k)) < 1e-9 and 0 <= round(k) < cells, (cells, out.witness_phase)


# --- inner polygons of the SDP -------------------------------------------------------------------------
@pytest.fixture(scope="module")
def builder(feasible, loop):
    return PolygonBuilder(feasible, loop)


def _area(poly) -> float:
    x, y = poly.vertices
    return 0.5 * abs(float(np.dot(x, np.roll(y, 1)) - np.dot(y, np.roll(x, 1))))


def _ratios_along_rays(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """|a_k| / |b_m| for each column a_k of ``a`` and the column b_m of ``b`` on the same ray (cross
    product 0 to 1e-9 relative, same way); fails if a column of ``a`` has none."""
    out = []
    for v in a.T:
        norm_b = np.linalg.norm(b, axis=0)
        cross = np.abs(v[0] * b[1] - v[1] * b[0]) / (np.linalg.norm(v) * norm_b)
        on_ray = np.flatnonzero((cross < 1e-9) & (b.T @ v > 0))
        assert on_ray.size == 1, v
        out.append(np.linalg.norm(v) / norm_b[on_ray[0]])
    return np.array(out)


def test_polygon_has_one_vertex_per_direction(builder):
    """``n_vertices`` directions, each vertex's radius found along its own direction alone: 6
    directions give a hexagon whose vertices are among those of the 24-direction polygon (every
    fourth direction), exactly (1e-12 relative: the same bisection and proof on the same ray);
    48 give 48 vertices, and a polygon on more rays of the same convex slice is no smaller."""
    ref = Reference.setpoint(0.02)
    polys = {n: builder.build(ref, 3e-3, n_vertices=n) for n in (6, 24, 48)}
    assert all(p.success for p in polys.values())
    assert {n: p.vertices.shape[1] for n, p in polys.items()} == {6: 6, 24: 24, 48: 48}
    default = builder.build(ref, 3e-3)
    assert_array_equal(default.vertices, polys[24].vertices)
    assert_allclose(_ratios_along_rays(polys[6].vertices, polys[24].vertices), 1.0, rtol=1e-12)
    assert _area(polys[6]) < _area(polys[24]) <= _area(polys[48]) * (1 + 1e-12)


def test_polygon_interval_budget_limits_the_proof(builder):
    """``max_cells`` is the interval budget per vertex. A set-point's first cover is 16 cells of the
    gap error per vertex: with a budget of 1 no vertex is refined, so each is tried, 3 % smaller at a
    time, until the first pass proves it: the same rays as the default polygon, every radius 0.97^j
    of the default's (j >= 0, some j > 0; 1e-9 relative), a smaller polygon. The papers' sinusoid
    needs refinement that even 12 shrinks do not avoid: refused, not claimed, while the default
    budget proves it."""
    ref = Reference.setpoint(0.02)
    full = builder.build(ref, 3e-3)
    tight = builder.build(ref, 3e-3, max_cells=1)
    assert full.success and tight.success
    assert tight.vertices.shape == full.vertices.shape
    ratio = _ratios_along_rays(tight.vertices, full.vertices)
    j = np.log(ratio) / math.log(0.97)
    assert np.all(np.abs(j - np.round(j)) < 1e-6) and np.all(np.round(j) >= 0) and np.max(j) > 0.5, j
    assert _area(tight) < _area(full)
    # no box split: every try of a vertex costs exactly its first cover, 16 cells
    assert tight.cells % 16 == 0 and tight.cells >= 16 * tight.vertices.shape[1]
    sinus = Reference.paper_sinusoid()
    assert builder.build(sinus, 3e-3).success
    refused = builder.build(sinus, 3e-3, max_cells=1)
    assert refused.status == "not_proved" and "could not be proved" in refused.message
    # a refusal after the branch and bound reports the cells it spent (16 per first cover, as
    # above); one before it (a gap range reaching 0) spent none (seed 64: it said 0 for both)
    assert refused.cells >= 16 and refused.cells % 16 == 0
    assert builder.build(sinus, 0.025).cells == 0


def test_sdp_candidate_keeps_its_construction_level_and_solve_time(builder):
    poly = builder.build(Reference.setpoint(0.02), 3e-3, n_vertices=6)
    cand = SdpCandidate.of(3e-3, poly, "optimal", construction_level=0.37, solve_time=1.25)
    assert cand.construction_level == 0.37 and cand.timings == {"sdp": 1.25}
    plain = SdpCandidate.of(3e-3, poly, "optimal")
    assert plain.construction_level == 0.0 and plain.timings == {"sdp": 0.0}


# --- the robust analyses ---------------------------------------------------------------------------------
def test_assumed_covariance_uses_the_relative_errors_given(model):
    """diag((relative_i C_i)^2), checked element by element (1e-15 relative: one product and a
    square); negative or misshaped relative errors are refused."""
    from maglev_oc.errors import InputError

    C = np.asarray(model.constants.as_array())
    rel = np.array([0.01, 0.03, 0.05, 0.2])
    cov = assumed_covariance(model.constants, relative=rel)
    assert_allclose(np.diag(cov), (rel * C) ** 2, rtol=1e-15)
    assert np.count_nonzero(cov - np.diag(np.diag(cov))) == 0
    # the default is the documented assumption (2 % for C1..C3, 10 % for C4)
    assert_allclose(
        np.diag(assumed_covariance(model.constants)), (np.array([0.02, 0.02, 0.02, 0.1]) * C) ** 2
    )
    for bad in ([0.01, 0.02, -0.01, 0.1], [0.01, 0.02, 0.03]):
        with pytest.raises(InputError, match="relative"):
            assumed_covariance(model.constants, relative=bad)


def _planted_radius(monkeypatch, threshold: float, unit: float) -> list[float]:
    """run_sweep replaced by a planted verdict: violations exactly when the plant set's radius
    (from its shape r^2 cov, ``unit`` = cov[0, 0]) exceeds ``threshold``; the radii probed."""
    probed: list[float] = []

    def fake(spec, runs, **_):
        r = math.sqrt(np.asarray(spec.plants.shape)[0, 0] / unit)
        probed.append(r)
        return SimpleNamespace(violations=int(r > threshold))

    monkeypatch.setattr(robust_module, "run_sweep", fake)
    return probed


def test_critical_radius_never_probes_beyond_max_radius(model, monkeypatch):
    """Runs first leave F at r* = 41 sigma: with ``max_radius`` 20 no probe goes beyond 20 and
    the answer is [20, inf) (nothing broke up to the cap); with 60 the bracket holds r* (to
    rel_tol 0.05 of its upper end) and never reaches past the cap, probes again at most 60."""
    cov = np.diag([1e-6, 1.0, 4e-6, 1e-8])
    spec = SweepSpec(PlantSet.point(model.constants), Reference.setpoint(0.02), start=(0.02, 0, 0, 0))
    probed = _planted_radius(monkeypatch, 41.0, cov[0, 0])
    capped = critical_radius("planted", spec, cov, runs=10, max_radius=20.0, rel_tol=0.05)
    assert capped.safe_radius == 20.0 and capped.broken_radius == math.inf
    assert probed and max(probed) <= 20.0 * (1 + 1e-12)
    probed.clear()
    wide = critical_radius("planted", spec, cov, runs=10, max_radius=60.0, rel_tol=0.05)
    assert wide.safe_radius <= 41.0 < wide.broken_radius <= 60.0
    assert wide.broken_radius - wide.safe_radius <= 0.05 * wide.broken_radius * (1 + 1e-12)
    assert max(probed) <= 60.0 * (1 + 1e-12)
    # a loose tolerance stops at the first bracket: the cap, found broken, is its upper end (the
    # doubling 1, 2, ..., 32, 64 overshoots it; 64 was never probed)
    probed.clear()
    loose = critical_radius("planted", spec, cov, runs=10, max_radius=60.0, rel_tol=0.9)
    assert (loose.safe_radius, loose.broken_radius) == (32.0, 60.0) and max(probed) <= 60.0


@pytest.mark.parametrize("max_rounds", [1, 3])
def test_empirical_robust_level_gives_up_after_max_rounds(model, loop, monkeypatch, max_rounds):
    """Every sweep violates, its least violating start at V = 0.5 c: each round multiplies the level
    by 0.95 x 0.5, and after ``max_rounds`` sweeps (no more, no fewer) the level is
    level0 (0.475)^max_rounds (1e-12: round-off of the products) and the last sweep is returned."""
    seen = []

    def always_violating(spec, runs, *, seed, task_size, client):
        seen.append(spec.level)
        return SimpleNamespace(
            violations=1, start_ratio=np.array([0.5, 0.9]), violating=np.array([True, True])
        )

    monkeypatch.setattr(robust_module, "run_sweep", always_violating)
    P = loop.lyapunov_matrix()
    spec = SweepSpec(
        PlantSet.point(model.constants), Reference.setpoint(0.02), P=tuple(map(tuple, P)), level=2.0
    )
    out = robust_module.empirical_robust_level("20 mm", spec, spec.plants, runs=4, max_rounds=max_rounds)
    assert len(seen) == max_rounds and out.rounds == max_rounds
    assert out.level == pytest.approx(2.0 * 0.475**max_rounds, rel=1e-12)
    assert seen == pytest.approx([2.0 * 0.475**k for k in range(max_rounds)], rel=1e-12)


# --- sampled plants and the twin's starting states ---------------------------------------------------
RIG = TwinEffects.rig(misalignment=None)


NO_EFFECTS = dataclasses.replace(RIG, friction_vertical=None, friction_horizontal=None, cogging=None)


def test_sampled_twin_initial_state_holds_the_scales_given(model):
    """The state is the rig twin's, then the 3 effect scales, then C1..C4 (class docstring)."""
    twin = SampledPlantTwin(model, RIG)
    x, u = np.array([0.018, 0.01, 0.004, -0.02]), np.array([0.5, -0.3])
    C = np.asarray(model.constants.as_array())
    s = twin.initial_state(x, u, constants=1.01 * C, scales=(2.0, 0.5, 3.0))
    base = RigTwin(model, RIG).initial_state(x, u)
    assert_array_equal(s[: base.size], base)
    assert_array_equal(s[base.size : base.size + 3], [2.0, 0.5, 3.0])
    assert_allclose(s[-4:], 1.01 * C, rtol=1e-15)
    assert_array_equal(twin.initial_state(x, u)[base.size : base.size + 3], np.ones(3))


def test_run_plants_runs_each_plant_with_its_effect_scales(model):
    """Two runs from a moving start (friction and cogging act) with effect scales 0 and 3: the
    scale rows come back unchanged (the step passes them on), the run at scale 0 ends where the
    same loop ends on a separate rig twin without friction and cogging (1e-9 relative: the same
    arithmetic with zeros multiplied in), and the run at scale 3 elsewhere."""
    ctrl = FeedbackLinearizingRegulator(model)
    sim = PlantBatchSimulator(SampledPlantTwin(model, RIG), ctrl, duration=0.05, threads=1, compile=False)
    x = np.tile(np.array([[0.021], [0.02], [0.003], [0.05]]), (1, 2))
    c0 = regulator_state(x, np.zeros((6, 2)))
    ref = Reference.setpoint(0.02).signals(0.0)[:, 0]
    C = np.tile(np.asarray(model.constants.as_array())[:, None], (1, 2))
    scales = np.array([[0.0, 3.0], [0.0, 3.0], [0.0, 3.0]])
    out = sim.run_plants(x, c0, ref, C, scales)
    nb = RigTwin(model, RIG).n_state
    assert_array_equal(out.final_twin[nb : nb + 3], scales)
    bare = BatchSimulator(RigTwin(model, NO_EFFECTS), ctrl, duration=0.05, threads=1, compile=False)
    want = bare.run(x[:, :1], c0[:, :1], ref)
    # the mechanical states (the first four rows) of the two twins
    assert_allclose(out.final_twin[:4, 0], want.final_twin[:4, 0], rtol=1e-9, atol=1e-12)
    assert np.max(np.abs(out.final_twin[:4, 1] - out.final_twin[:4, 0])) > 1e-6


def test_batch_run_starts_the_twin_at_the_states_given(model):
    """``twin_states`` are the twin's whole starting states: a run with x0 = A but the twin started
    at B is the run from B (bit for bit: the same numbers in), not the one from A."""
    ctrl = FeedbackLinearizingRegulator(model)
    twin = RigTwin(model)
    sim = BatchSimulator(twin, ctrl, duration=0.05, threads=1, compile=False)
    a = np.array([[0.020], [0.0], [0.0], [0.0]])
    b = np.array([[0.023], [0.01], [0.004], [0.0]])
    c0 = regulator_state(a, np.zeros((6, 1)))
    ref = Reference.setpoint(0.02).signals(0.0)[:, 0]
    started_at_b = sim.run(a, c0, ref, twin_states=twin.initial_state(b[:, 0])[:, None])
    from_b = sim.run(b, c0, ref)
    from_a = sim.run(a, c0, ref)
    assert_array_equal(started_at_b.final_twin, from_b.final_twin)
    assert_array_equal(started_at_b.min_gap, from_b.min_gap)
    assert np.max(np.abs(started_at_b.final_twin[:4] - from_a.final_twin[:4])) > 1e-6


# --- references and the study's settings --------------------------------------------------------------------
def test_reference_phases_shift_the_sinusoids():
    """r_v = gap + a sin(w t + gap_phase), r_h = position + b sin(w t + position_phase), their
    derivatives a w cos(.), -a w^2 sin(.) (class docstring; 1e-15 m: rounding)."""
    g, p, a, b, gp, pp = 0.02, 0.01, 4e-3, 30e-3, 0.7, -2.1
    ref = Reference(g, p, a, b, gap_phase=gp, position_phase=pp)
    phi = np.linspace(0, 2 * math.pi, 13)
    s = ref.signals(phi)
    w = ref.omega
    want = np.vstack(
        [
            g + a * np.sin(phi + gp),
            a * w * np.cos(phi + gp),
            -a * w**2 * np.sin(phi + gp),
            p + b * np.sin(phi + pp),
            b * w * np.cos(phi + pp),
            -b * w**2 * np.sin(phi + pp),
        ]
    )
    assert_allclose(s, want, rtol=1e-13, atol=1e-15)
    # the papers' ellipse: r_v = 20 + 5 cos(omega0 t) mm is gap_phase pi/2
    assert Reference.paper_sinusoid().signals(0.0)[0, 0] == pytest.approx(0.025, abs=1e-15)


def test_study_certify_settings_are_the_robust_certifiers(model, feasible, loop, monkeypatch):
    """``certify_boxes`` and ``certify_ladder`` reach the robust certifier of the study's certified
    part (and its record); with no set-point to certify, nothing else runs."""
    made = []

    class Recording(RobustCertifier):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            made.append(self)

    monkeypatch.setattr(study_module, "RobustCertifier", Recording)
    config = study_module.StudyConfig(certify_boxes=12_345, certify_ladder=(0.8, 0.4, 0.1))
    run = SimpleNamespace(config=config, model=model, feasible=feasible, loop=loop)
    out = study_module._certified(run, [], assumed_covariance(model.constants), {})
    assert len(made) == 1 and made[0].max_boxes == 12_345 and made[0].ladder == (0.8, 0.4, 0.1)
    assert out.boxes == 12_345 and out.ladder == (0.8, 0.4, 0.1) and out.rows == ()


def test_the_ball_cell_count_is_a_direct_count_of_the_grid():
    """:func:`_ball_cells` against enumerating the 4^d grid (3, 4, 5 dims): a cell meets the unit
    ball iff its point nearest the origin (each coordinate clipped to the cell) lies in it."""
    edges = np.linspace(-1, 1, 5)
    for d in (3, 4, 5):
        idx = np.array(np.meshgrid(*[range(4)] * d, indexing="ij")).reshape(d, -1)
        near = np.clip(0.0, edges[idx], edges[idx + 1])
        assert int(np.sum(np.sum(near**2, axis=0) <= 1.0)) == _ball_cells(d)


class _Stop(Exception):
    """Raised by a recorder once it has what the test needs."""


def _reference_study(gap_mm: float) -> SimpleNamespace:
    cert = SimpleNamespace(success=True, P=np.eye(10), level=0.5)
    return SimpleNamespace(
        reference=Reference.setpoint(gap_mm * MM_TO_M, 0.0), best=cert, lyapunov=cert, sdp=None
    )


def _run(**config) -> SimpleNamespace:
    loop = SimpleNamespace(K_h=np.array(PAPER_K_H), K_v=np.array(PAPER_K_V), omega0=OMEGA0)
    return SimpleNamespace(
        config=SimpleNamespace(**config),
        loop=loop,
        model=StageModel(),
        limit=9.0,
        feasible=SimpleNamespace(gap_range=None, position_range=None),
        say=lambda *_: None,
        timings={},
    )


@pytest.mark.parametrize("horizon", [0.4, 2.5])
def test_the_robust_sweeps_runs_last_the_studys_horizon(monkeypatch, horizon):
    # every set-point's spec handed to the sweep carries config.horizon (the sweep's own default is
    # 1 s): recorded at the call of robustness_table, which is then stopped
    seen = {}

    def table(specs, covariance, **kw):
        seen.update(specs)
        raise _Stop

    monkeypatch.setattr(study, "robustness_table", table)
    run = _run(robust_runs=3, horizon=horizon, seed=0, robust_probe_runs=0, linear=False)
    assert SweepSpec.__dataclass_fields__["duration"].default != horizon
    with pytest.raises(_Stop):
        study._robust(run, [_reference_study(20.0), _reference_study(15.0)], None, "assumed")
    assert sorted(seen) == ["15 mm", "20 mm"]
    assert all(spec.duration == horizon for spec in seen.values())


def test_slices_skip_a_setpoint_without_a_certificate_and_go_on(monkeypatch):
    # slice set-points 12 and 20 mm with a reference study at 20 mm only: 12 mm is skipped, 20 mm
    # sliced (two slices, (e1, e2) and (e1, e1'), each checked against the Lyapunov certificate)
    calls = []

    def fake_slice(sim, loop, ref, P, level, axes, e_rng, yr, **kw):
        calls.append((round(ref.gap / MM_TO_M, 6), axes))
        return SimpleNamespace()

    monkeypatch.setattr(study, "fl_slice", fake_slice)
    run = _run(slice_points=5, slice_setpoints_mm=(12.0, 20.0))
    out = study._slices(run, None, [_reference_study(20.0)])
    assert calls == [(20.0, ("e1", "e2")), (20.0, ("e1", "e1_rate"))]
    assert len(out["Lyapunov P"]) == 2 and out["SDP P"] == ()


def test_the_robust_study_says_which_certificate_each_set_point_sweeps(monkeypatch):
    # a set-point whose best certificate is the SDP's is swept in "SDP P", one whose best is the
    # Lyapunov equation's in "Lyapunov P" (the report's table names the set the starts were drawn
    # from; seed 64: the label was "Lyapunov P" for both with every test passing)
    monkeypatch.setattr(study, "robustness_table", lambda specs, covariance, **kw: [])
    lyapunov = _reference_study(20.0)
    by_sdp = _reference_study(15.0)
    by_sdp.best = SimpleNamespace(success=True, P=2 * np.eye(10), level=0.3)  # not the Lyapunov one
    run = _run(robust_runs=3, horizon=1.0, seed=0, robust_probe_runs=0, linear=False, certify_boxes=False)
    out = study._robust(run, [lyapunov, by_sdp], None, "assumed")
    assert out.certificates == {"20 mm": "Lyapunov P", "15 mm": "SDP P"}
