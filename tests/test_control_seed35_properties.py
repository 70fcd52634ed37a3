"""Properties of the controllers that the seed-35 mutation run found untested (issue 21).

Each test checks what a user of ``maglev_oc/control/`` relies on, against an independent
computation where there is one:

- a recorded NMPC instance (:func:`~maglev_oc.control.codegen.instance_row`) is the call the
  controller makes: replaying it through ``rti_step`` gives the current and the memory that
  ``control`` gave at that sample, on a reference that changes from sample to sample;
- the NMPC honours its ``disturbance_limit``: the disturbance estimate never exceeds it and
  reaches it when the readings keep disagreeing with the model;
- the converged NMPC (IPOPT) holds an equilibrium with the equilibrium current of
  :func:`~maglev_oc.model.equilibrium.equilibrium_currents`, and the RTI's current differs from
  its optimum by second order in the distance from the plan (one Gauss-Newton step);
- the QP's Hessian has its smallest diagonal entry equal to 1 whatever the weights and the
  sampling (the scaling that makes HPIPM's absolute tolerances mean the same precision on
  every entry, :meth:`Transcription.qp_data_function`, Notes);
- ``rk4_lin``, called by its documented input names (x, u, d, h), is ``rk4``'s step with its
  Jacobians (central differences);
- the exported NMPC's README documents every entry point of the export and gives every
  diagnostic row its meaning, the QP status codes of the dual solver among them.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.control.codegen import RecordedInstances, evaluate_instances, instance_row
from maglev_oc.control.export import export_controller
from maglev_oc.control.export_qp import STATUS_CODES
from maglev_oc.control.nmpc import DEFAULT_DISTURBANCE_LIMIT, NMPCSettings, NMPCWeights, NonlinearMPC
from maglev_oc.control.nmpc.transcription import Transcription
from maglev_oc.model.equilibrium import equilibrium_currents

GAP = 0.020  # [m] an operating gap of the papers' runs


def _equilibrium_current(model, gap: float = GAP) -> float:
    return float(np.asarray(equilibrium_currents(model, [gap]).current)[0])


# --- recorded instances -------------------------------------------------------------------------
def test_a_recorded_instance_is_the_call_the_controller_makes(model):
    """Per sample k: the row recorded before ``control(k, y, reference)``, replayed through
    ``rti_step``, gives that call's current and next memory. The reference moves (a parabola in
    the horizontal position), so its node references differ from sample to sample. Same
    Function, same arithmetic: bit for bit."""
    ctrl = NonlinearMPC(model)
    n = 400
    ts = ctrl.sample_time
    reference = np.zeros((6, n))
    reference[0] = GAP
    t = ts * np.arange(n)
    reference[3], reference[4], reference[5] = 10.0 * t**2, 20.0 * t, 20.0  # m, m/s, m/s^2
    ctrl.reset([GAP, 0.0], reference[:, 0], [0.0, _equilibrium_current(model)])
    for k in range(6):
        y = np.array([GAP + 1e-5 * k, 2e-6 * k])
        inst = RecordedInstances.of(ctrl, [instance_row(ctrl, k, y, reference)])
        u_replayed, memory_replayed, _ = evaluate_instances(ctrl.rti_step, inst)
        u, _ = ctrl.control(k, y, reference)
        np.testing.assert_array_equal(u_replayed[0], u)
        np.testing.assert_array_equal(memory_replayed[0], ctrl.memory)


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


# --- the exported NMPC's README ------------------------------------------------------------------
def test_the_exported_nmpcs_readme_documents_its_interface_and_diagnostics(model, tmp_path):
    from maglev_oc.sim.compiled_nmpc import CompiledNMPC

    nmpc = NonlinearMPC(model, preview=False)
    export = export_controller(CompiledNMPC(nmpc, backend="vm"), tmp_path / "nmpc")
    assert export.qp_solver == "dual"
    readme = (tmp_path / "nmpc" / "README.md").read_text()
    # how to call it: every entry point the export has, the split's prepare / prepare_for /
    # feedback among them, the restart and the memory's size for hosts that allocate it
    calls = ("init", "reset", "step", "prepare", "prepare_for", "feedback")
    assert set(calls) | {"mem_size"} == set(export.entry_points)
    for entry in calls:
        assert f"{export.prefix}_{entry}(&m" in readme, entry
    assert f"{export.prefix}_mem_size()" in readme
    # every diagnostic row with its meaning; the dual solver's qp_status its status codes
    rows = {}
    for line in readme.split("## Diagnostics", 1)[1].splitlines():
        if line.startswith("| ") and "| `" in line:
            _, row, name, meaning, _ = (part.strip() for part in line.split("|"))
            rows[name.strip("`")] = (int(row), meaning)
    assert [rows[n][0] for n in export.diag_names] == list(range(len(export.diag_names)))
    assert all(rows[n][1] for n in export.diag_names)
    for code, text in STATUS_CODES.items():
        assert f"{code}: {text}" in rows["qp_status"][1]
    assert "else the QP solver's steps" in rows["qp_iterations"][1]  # counted in C, unlike Python
