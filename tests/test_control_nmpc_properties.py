"""Properties of the NMPC (``maglev_oc.control.nmpc``): its settings, its transcription and what a
step reports, checked against independent computations (central differences, the equilibrium of
``maglev_oc.model.equilibrium``, the QP's cost recomputed from the plan, closed-form grids):

- the settings refuse a disturbance bandwidth near the observers' and a gap lower bound at or
  below zero (the smallest positive one is kept), and R is in the order of u;
- the NMPC exposes the weights it was built with and honours its ``disturbance_limit``;
- the converged NMPC holds an equilibrium with the equilibrium current, and the RTI's current is
  one Gauss-Newton step from the plan (second order close to the optimum);
- the QP Hessian's smallest diagonal entry is 1 whatever the weights; ``rk4_lin`` called by its
  documented names is ``rk4``'s step with its Jacobians;
- a shooting grid names each bad argument and its value, and a good grid is one sample then
  whole intervals;
- an RTI step's reported cost is the OCP's cost of the applied plan, and the converged
  controller's fallback current lies in the current limit's octagon.
"""

from __future__ import annotations

import math
import re

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.control.nmpc import DEFAULT_DISTURBANCE_LIMIT, NMPCSettings, NMPCWeights, NonlinearMPC
from maglev_oc.control.nmpc.converged import ConvergedSolver
from maglev_oc.control.nmpc.grid import ShootingGrid
from maglev_oc.control.nmpc.layout import MemoryLayout
from maglev_oc.control.nmpc.rti import rti_parts
from maglev_oc.control.nmpc.status import DIAG_NAMES
from maglev_oc.control.nmpc.transcription import Transcription
from maglev_oc.errors import InputError
from maglev_oc.estimation.high_gain import DEFAULT_EPSILON
from tests._control_cases import _equilibrium_current

GAP = 0.020  # [m] a scheduled gap (8 mm + 24 x 0.5 mm)


# --- the NMPC's settings --------------------------------------------------------------------------
def test_nmpc_refuses_a_disturbance_bandwidth_near_the_observers():
    limit = 0.5 / DEFAULT_EPSILON  # [rad/s] w_d eps <= 0.5 (settings' message)
    NMPCSettings(disturbance_bandwidth=limit * 0.99)
    with pytest.raises(InputError, match="disturbance_bandwidth"):
        NMPCSettings(disturbance_bandwidth=limit * 1.5)


def test_nmpc_input_weight_is_in_the_order_of_u():
    w = NMPCWeights(i_q=3.0, i_d=0.5)
    assert_allclose(w.input_weight, np.diag([3.0, 0.5]))
    assert_allclose(w.state_weight, np.diag([w.gap, w.gap_rate, w.position, w.position_rate]))


# --- the disturbance estimate's limit ----------------------------------------------------------
@pytest.mark.parametrize("limit", [0.05, 0.3])
def test_the_nmpc_honours_its_disturbance_limit(model, limit):
    """Readings that stay 0.2 mm / 0.1 mm off whatever the controller does: the disturbance
    estimate runs away (to 1.6 m/s^2 in 300 samples with the default limit of 5 m/s^2) and stops
    at the limit given, on both axes."""
    assert limit < DEFAULT_DISTURBANCE_LIMIT
    ctrl = NonlinearMPC(model, disturbance_limit=limit)
    reference = np.zeros((6, 400))
    reference[0] = GAP
    ctrl.reset([GAP, 0.0], reference[:, 0], [0.0, _equilibrium_current(model)])
    y = np.array([GAP + 2e-4, 1e-4])
    d = []
    for k in range(300):
        ctrl.control(k, y, reference)
        d.append(ctrl.disturbance)
    peak = np.max(np.abs(d), axis=0)
    assert np.all(peak <= limit * (1 + 1e-12))
    assert_allclose(peak, limit, rtol=1e-12)  # reached: the clip, not the dynamics, bounds it


# --- the converged mode --------------------------------------------------------------------------
def test_converged_nmpc_holds_the_equilibrium_and_the_rti_is_second_order_close(model):
    """At rest on a constant reference the optimum is to stay: the equilibrium current
    (atol 1e-7 A: IPOPT stops at tol 1e-10; measured 2e-9 A). A reading dy off the plan: the
    RTI's current is one Gauss-Newton step from the plan, so it differs from the converged
    optimum by O(dy^2): ten times the distance, a hundred times the difference (measured 99.8
    between 10 um and 0.1 mm; the band allows the third-order terms)."""
    converged, rti = NonlinearMPC(model, mode="converged"), NonlinearMPC(model)
    reference = np.zeros((6, 200))
    reference[0] = GAP
    u_eq = _equilibrium_current(model)
    gaps = {}
    for dy in (0.0, 1e-5, 1e-4):
        for c in (converged, rti):
            c.reset([GAP, 0.0], reference[:, 0], [0.0, u_eq])
        y = np.array([GAP + dy, -dy])
        u_c, diag = converged.control(0, y, reference)
        u_r, _ = rti.control(0, y, reference)
        assert diag[converged.diag_names.index("solver_ok")] == 1
        gaps[dy] = np.linalg.norm(u_c - u_r)
        if dy == 0.0:
            assert_allclose(u_c, [0.0, u_eq], atol=1e-7)
    assert 80 < gaps[1e-4] / gaps[1e-5] < 125


# --- the transcription -----------------------------------------------------------------------------
SETTINGS = [
    NMPCSettings(),
    NMPCSettings(weights=NMPCWeights(i_q=3.0, i_d=0.5), sample_time=1e-4, interval=4e-3, horizon=10),
]


def _transcription(model, s: NMPCSettings) -> Transcription:
    return Transcription(model, s.grid, s.weights, s.current_limit, s.gap_bounds, s.position_bounds)


@pytest.mark.parametrize("settings", SETTINGS, ids=["defaults", "other weights and sampling"])
def test_the_qp_hessians_smallest_diagonal_entry_is_one(model, settings):
    """The first interval's smaller input weight 2 h_0 min(R) times the cost scale is 1 (rtol
    1e-12: one product and one division), every other diagonal entry larger; the same c relates
    the QP's cost to the OCP's."""
    ocp = _transcription(model, settings)
    n = settings.grid.horizon
    reference = np.zeros((6, n + 1))
    reference[0] = GAP
    out = ocp.qp_data_function()(np.zeros(ocp.nz), [GAP, 0.0, 0.0, 0.0], [0.0, 0.0], reference)
    diag = np.diag(np.asarray(out[0]))
    assert_allclose(diag.min(), 1.0, rtol=1e-12)
    h0, r = settings.grid.intervals[0], min(settings.weights.i_q, settings.weights.i_d)
    assert_allclose(ocp.cost_scale, 1 / (2 * h0 * r), rtol=1e-12)


def test_rk4_lin_by_its_names_is_the_rk4_step_and_its_jacobians(model):
    """x_next equals rk4's bit for bit; A and B equal central differences of rk4 (steps 1e-7 m
    and 1e-6 A: truncation and round-off both under 1e-10, A is O(1), B O(1e-3)); the
    disturbance d enters as a constant acceleration, h d on the velocities to first order."""
    ocp = _transcription(model, NMPCSettings())
    rk4 = ocp.rk4
    x, u, d, h = np.array([GAP, 0.01, 0.001, -0.02]), np.array([0.3, 1.2]), np.array([0.1, -0.2]), 2e-4
    out = ocp.rk4_lin(x=x, u=u, d=d, h=h)
    x_next = np.asarray(out["x_next"]).ravel()
    np.testing.assert_array_equal(x_next, np.asarray(rk4(x, u, d, h)).ravel())

    def central(f, v, k, step):
        e = np.zeros_like(v)
        e[k] = step
        return (f(v + e) - f(v - e)) / (2 * step)

    a = np.column_stack(
        [central(lambda s: np.asarray(rk4(s, u, d, h)).ravel(), x, k, 1e-7) for k in range(4)]
    )
    b = np.column_stack(
        [central(lambda s: np.asarray(rk4(x, s, d, h)).ravel(), u, k, 1e-6) for k in range(2)]
    )
    assert_allclose(np.asarray(out["A"]), a, rtol=0, atol=1e-10)
    assert_allclose(np.asarray(out["B"]), b, rtol=0, atol=1e-10)
    without = np.asarray(ocp.rk4_lin(x=x, u=u, d=np.zeros(2), h=h)["x_next"]).ravel()
    # velocities: h d, to relative 1e-4 (the disturbance moves the state the model sees within
    # the step by h^2 d / 2, a relative change of about 1e-5 measured)
    assert_allclose((x_next - without)[[1, 3]], h * d, rtol=1e-4)


TS = 2e-4  # [s] the controller's sample time


# --- the NMPC's weights ---------------------------------------------------------------------------
def test_the_nmpc_exposes_the_weights_it_was_built_with(model):
    """Other weights than the defaults (every entry changed), given in the settings or as a
    keyword, and no weights at all (the defaults, NMPCWeights()): ``weights`` is the settings'
    object, equal to what was given."""
    other = NMPCWeights(gap=2e5, gap_rate=50.0, position=3e5, position_rate=20.0, i_q=3.0, i_d=0.5)
    assert other != NMPCWeights()
    settings = NMPCSettings(weights=other, horizon=5)
    built = NonlinearMPC(model, settings)
    assert built.weights == other and built.weights is built.settings.weights
    by_keyword = NonlinearMPC(model, weights=other, horizon=5)
    assert by_keyword.weights == other
    default = NonlinearMPC(model, horizon=5)
    assert default.weights == NMPCWeights() == default.settings.weights


# --- the gap bounds ---------------------------------------------------------------------------------
@pytest.mark.parametrize("lower", [0.0, -0.0, -1e-3])
def test_a_gap_lower_bound_at_or_below_zero_is_refused(lower):
    """Gaps are positive distances in metres: (0, upper) is refused as (-1 mm, upper) is, with the
    field's name and the bounds given."""
    bounds = (lower, 0.03)
    with pytest.raises(InputError, match=r"^gap_bounds must be positive and in metres, got ") as err:
        NMPCSettings(gap_bounds=bounds)
    assert str(err.value).endswith(repr(bounds))


def test_the_smallest_positive_gap_lower_bound_is_accepted():
    """Any positive lower bound is a gap (the smallest positive float too): kept as given."""
    tiny = 5e-324
    assert NMPCSettings(gap_bounds=(tiny, 0.03)).gap_bounds == (tiny, 0.03)


# --- the shooting grid ------------------------------------------------------------------------------
@pytest.mark.parametrize("bad", [0, -1, 1.5, 25.0, "25"])
def test_a_grid_refuses_a_bad_interval_count_by_name_and_value(bad):
    """The message names ``interval_samples`` and shows the value given (its repr: 25.0 is a
    float, not the count 25), so the caller sees which argument and why."""
    with pytest.raises(InputError) as err:
        ShootingGrid(TS, bad, 20)
    assert str(err.value) == f"interval_samples must be a positive integer, got {bad!r}"


@pytest.mark.parametrize(
    ("args", "field", "value"),
    [((0.0, 25, 20), "sample_time", 0.0), ((TS, 25, 1), "horizon", 1), ((TS, 25, 2.0), "horizon", 2.0)],
)
def test_a_grid_names_each_bad_argument(args, field, value):
    with pytest.raises(InputError, match=rf"^{field} must be .*, got {re.escape(repr(value))}$"):
        ShootingGrid(*args)


def test_a_good_grid_is_one_sample_then_whole_intervals():
    """interval_samples = 1 (the smallest) and 25 (the default): node offsets 0, 1, 1 + m, ..."""
    for m in (1, 25):
        grid = ShootingGrid(TS, m, 4)
        assert grid.node_offsets.tolist() == [0, 1, 1 + m, 1 + 2 * m, 1 + 3 * m]
        assert grid.intervals.tolist() == [TS] + [m * TS] * 3


# --- the RTI step's reported cost ------------------------------------------------------------------------
@pytest.fixture(scope="module")
def rti(model):
    nmpc = NonlinearMPC(model)
    return nmpc, rti_parts(nmpc._ocp, nmpc._observer, nmpc.shift).post


def _post_call(nmpc, post, dz, z_bar, z_ref, hess):
    """The post-processing of an accepted QP step ``dz`` (no constraint, data finite): its diag
    (DIAG_NAMES without qp_status) as an array."""
    ocp = nmpc._ocp
    nz, na = ocp.nz, ocp.na
    big = 1e8
    args = {
        "z_bar": z_bar,
        "dz": dz,
        "lam_x": np.zeros(nz),
        "lam_a": np.zeros(na),
        "A": ca.DM(post.sparsity_in("A"), 0.0),
        "lba": -big * np.ones(na),
        "uba": big * np.ones(na),
        "lbx": -big * np.ones(nz),
        "ubx": big * np.ones(nz),
        "data_ok": 1.0,
        "H": hess,
        "z_ref": z_ref,
        "obs": np.zeros(4),
        "d": np.zeros(2),
        "y": np.zeros(2),
        "dz_lq": np.zeros(nz),
    }
    out = post(**{k: args[k] for k in post.name_in()})
    return np.asarray(out["diag"]).ravel(), np.asarray(out["plan"]).ravel()


def test_the_rti_steps_cost_is_the_ocps_cost_of_the_applied_plan(rti):
    """An accepted step: the reported cost is 0.5 e' H e / cost_scale with e the applied plan's
    deviation from the reference plan in the QP's scaled variables, (z - z_ref) / z_scale; zero when
    the plan is the reference."""
    nmpc, post = rti
    ocp = nmpc._ocp
    rng = np.random.default_rng(48)
    sp = post.sparsity_in("H")
    hess = ca.DM(sp, rng.uniform(0.5, 2.0, sp.nnz()))
    scale = np.asarray(ocp.z_scale, dtype=float)
    z_bar = rng.normal(size=ocp.nz) * scale
    z_ref = z_bar + rng.normal(size=ocp.nz) * scale
    dz = 0.1 * rng.normal(size=ocp.nz)
    diag, plan = _post_call(nmpc, post, dz, z_bar, z_ref, hess)
    names = [n for n in DIAG_NAMES if n != "qp_status"]
    assert diag[names.index("solver_ok")] == 1.0
    z = z_bar + dz * scale
    np.testing.assert_allclose(plan, z, rtol=1e-12)
    e = (z - z_ref) / scale
    expected = 0.5 * e @ np.asarray(hess.full()) @ e / ocp.cost_scale
    # the same sums in another order: rounding only
    assert diag[names.index("cost")] == pytest.approx(expected, rel=1e-10)
    assert expected > 0
    # the plan on the reference: no cost
    diag, _ = _post_call(nmpc, post, dz, z_bar, z_bar + dz * scale, hess)
    assert abs(diag[names.index("cost")]) < 1e-20  # a difference of equal doubles: exactly 0


# --- the converged NMPC's fallback -----------------------------------------------------------------------
def _octagon_excess(u, r):
    """Largest of the octagon's rows over the radius (<= 1 inside)."""
    return max(abs(u[0]), abs(u[1]), abs(u[0] + u[1]) / math.sqrt(2), abs(u[0] - u[1]) / math.sqrt(2)) / r


def test_the_converged_fallback_current_lies_in_the_octagon(model):
    """A solve that cannot start (the encoder reading is not finite) applies the plan's first
    current: scaled back onto the octagon along its own direction when outside (on its boundary),
    the plan's own when inside."""
    nmpc = NonlinearMPC(model, mode="converged")
    ocp = nmpc._ocp
    solver = ConvergedSolver(ocp, nmpc._observer, nmpc.shift)
    lay = MemoryLayout(ocp.nz)
    r = ocp.radius
    ref = np.zeros((6, nmpc.grid.horizon + 1))
    y = np.array([np.nan, np.nan])
    for u_plan, inside in (((3.0 * r, r), False), ((0.9 * r, -0.9 * r), False), ((0.3 * r, -0.2 * r), True)):
        memory = np.zeros(lay.size)
        memory[lay.plan.start : lay.plan.start + 2] = u_plan
        u, _, diag = solver.step(memory, y, ref)
        assert diag[DIAG_NAMES.index("solver_ok")] == 0.0
        u_plan = np.asarray(u_plan)
        if inside:
            np.testing.assert_array_equal(u, u_plan)
        else:
            # one division: rounding only
            assert _octagon_excess(u, r) == pytest.approx(1.0, rel=1e-12)
            assert u[0] * u_plan[1] - u[1] * u_plan[0] == pytest.approx(0.0, abs=1e-12 * r * r)
            assert u @ u_plan > 0
