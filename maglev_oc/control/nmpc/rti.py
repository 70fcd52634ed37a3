"""The real-time iteration: one Gauss-Newton SQP step per sample, as one CasADi Function.

Real-time iteration (``mode="rti"``)
    ONE Gauss-Newton SQP step per sample (Diehl et al.'s RTI): the cost is a linear least
    squares in (x, u), so its Gauss-Newton Hessian is the exact, constant block-diagonal
    2 diag(h_0 R, h_1 Q, h_1 R, ..., P); the dynamics are linearized by CasADi AD at the shifted
    plan. The whole update -- observer, linearization and QP data (an SX Function), the sparse
    QP (a ``ca.conic`` call), the check of its solution, the fallback, the shift and the observer
    update (an SX Function) -- is ONE CasADi Function, ``NonlinearMPC.rti_step``, called
    once per sample from Python and code-generated to C by :mod:`maglev_oc.control.codegen`.

QP solver and the unconstrained shortcut
    The QP variables are ordered (u_0, x_1, u_1, ..., x_N) and the constraints per stage
    (dynamics, current polytope): the OCP structure HPIPM's Riccati-based interior point method
    exploits (u_0 plays HPIPM's "x_0" since x_0 is not a variable). ``hpipm`` is the default
    (mode "speed_abs", iteration limit 30) because its cost on a constrained sample is bounded
    (4-10 interior point iterations of fixed cost) where QRQP's active-set iterations each
    refactorize the KKT matrix, so that QRQP's cost grows with the number of constraints that
    switch (the start of a large step). The QP is scaled (positions in mm, and the cost so that
    its smallest Hessian entry is 1: :meth:`.transcription.Transcription.qp_data_function`) so
    that HPIPM's absolute tolerances mean the same precision on every entry (in SI units its
    Hessian spans 1e-3..1e7 and the first sample of a large step ran into the iteration limit;
    without the cost scale its first current was up to 0.07 A off the exact solution). Measured
    by bench/nmpc_step.py with the QP solved every sample (N = 20, CasADi VM, per call, two
    runs): HPIPM 0.42-0.47 ms, QRQP 0.42 ms, OSQP 0.75-0.83 ms (OSQP needs tight tolerances for
    the solution check, hence many ADMM iterations); in the generated C the p99 over a large
    step, set by the samples that need the QP, was 0.14 ms with HPIPM and 0.24 ms with QRQP.
    Most samples have no active inequality: the Riccati recursion of the equality-constrained QP
    (:mod:`.riccati`) is computed first and, when it satisfies every bound and polytope row, it
    IS the QP's solution and the solver is not called (a CasADi Switch: only the selected branch
    runs, in Python and in the generated C). The QP solver runs on the other samples (0.1-1 % of
    the samples of the papers' scenarios); ``unconstrained_shortcut=False`` solves the QP every
    sample.

Preparation and feedback (initial value embedding)
    The same update split at the reading, for the exported controller's latency
    (:func:`rti_prepare_function`, :func:`rti_feedback_function`): the preparation linearizes
    at the predicted initial state x0_pred (the observer's state before the reading) and
    computes the QP data, the Riccati step there and its exact sensitivity to the initial
    state; the feedback corrects the step affinely by x0 - x0_pred, checks it against the bounds
    and solves the QP (the prepared data, the first dynamics rows' bounds corrected) only when
    it violates one. What differs from :func:`rti_step_function`: the linearization point of the
    first interval's dynamics (x0_pred instead of x0); with x0 = x0_pred the two are the same
    arithmetic; otherwise their currents differ by the first interval's Jacobians' change over
    x0 - x0_pred times the QP's step (about 0.5 mA at 10 um off and 0.5 mm from the plan;
    tests/test_nmpc.py).

A failed QP never raises: the solution is checked inside the Function (finite, dynamics
residual and constraint violation below tolerance); when it fails (also when the solver runs
out of its iteration budget, ``qp_options={"max_iter": K}``: the bound on the step's work) the
controller applies the unconstrained (Riccati) step of the same QP with its currents projected
onto the current polytope (a saturated LQ step around the plan: still feedback, where the
shifted previous plan alone would be open loop and, applied sample after sample, dropped the
stage on the large step), shifts that plan into the next linearization point and reports
``solver_ok = 0`` (status ``"fallback"``, :mod:`.status`). If the Riccati step is not finite,
the shifted previous plan (or the feedforward current of the reference) is applied.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from maglev_oc.control.base import N_MEASUREMENTS, N_REFERENCE
from maglev_oc.control.nmpc.layout import N_POLYTOPE_ROWS, NU, NX, STAGE_ROWS, MemoryLayout
from maglev_oc.control.nmpc.riccati import (
    FACTOR_STAGE,
    riccati_factor,
    riccati_function,
    satisfies_inequalities,
)
from maglev_oc.control.nmpc.status import DIAG_NAMES
from maglev_oc.control.nmpc.transcription import Transcription
from maglev_oc.estimation.extended_high_gain import N_DISTURBANCE, N_OBSERVER_STATE, ExtendedHighGainObserver
from maglev_oc.numerics import jit

__all__ = [
    "SOLUTION_TOLERANCE",
    "PreparedLayout",
    "RTIParts",
    "python_entry",
    "qp_solver_function",
    "read_qp_statistics",
    "rti_feedback_function",
    "rti_feedback_parts",
    "rti_parts",
    "rti_prepare_function",
    "rti_step_function",
]

SOLUTION_TOLERANCE = 1e-6
"""Largest dynamics residual and constraint violation accepted in a QP solution, in the QP's
scaled units (mm, m/s, A); the solvers reach 1e-8 or better on a good solve, a failed one is
far off."""
_QP_INPUTS = ("H", "g", "A", "lba", "uba", "lbx", "ubx")


@dataclass(frozen=True)
class RTIParts:
    """The three SX Functions of the RTI step (the QP solver call joins them in MX).

    Attributes
    ----------
    qp_data : casadi.Function
        (z_bar, x0, d, ref) -> the QP (:meth:`Transcription.qp_data_function`).
    riccati : casadi.Function
        The unconstrained shortcut (:func:`~.riccati.riccati_function`).
    post : casadi.Function
        Check, fallback, shift and observer update (:func:`rti_parts`).
    """

    qp_data: ca.Function
    riccati: ca.Function
    post: ca.Function

    def compiled(self) -> RTIParts:
        """The same parts JIT-compiled with -O1 (unchanged where there is no C compiler)."""
        return RTIParts(*(jit(f, flags=("-O1",)) for f in (self.qp_data, self.riccati, self.post)))


def rti_parts(ocp: Transcription, observer: ExtendedHighGainObserver, shift: np.ndarray) -> RTIParts:
    """Build the SX parts of the RTI step.

    Parameters
    ----------
    ocp : Transcription
    observer : ExtendedHighGainObserver
    shift : (6N, 6N) array
        The warm-start shift (:func:`~.grid.shift_matrix`).

    Returns
    -------
    RTIParts
    """
    qp_data = ocp.qp_data_function()
    return RTIParts(qp_data, riccati_function(qp_data, ocp.N), _post_function(ocp, observer, shift, qp_data))


def _post_function(
    ocp: Transcription, observer: ExtendedHighGainObserver, shift: np.ndarray, qp_data: ca.Function
) -> ca.Function:
    """Post-processing of a QP step: check, fallback, projection, shift and observer update."""
    n, nz, na = ocp.N, ocp.nz, ocp.na
    zb = ca.SX.sym("z_bar", nz)
    dz = ca.SX.sym("dz", nz)
    lam_x = ca.SX.sym("lam_x", nz)
    lam_a = ca.SX.sym("lam_a", na)
    a = ca.SX.sym("A", qp_data.sparsity_out("A"))
    lba = ca.SX.sym("lba", na)
    uba = ca.SX.sym("uba", na)
    lbx = ca.SX.sym("lbx", nz)
    ubx = ca.SX.sym("ubx", nz)
    data_ok = ca.SX.sym("data_ok")
    obs = ca.SX.sym("obs", N_OBSERVER_STATE)
    d = ca.SX.sym("d", N_DISTURBANCE)
    y = ca.SX.sym("y", N_MEASUREMENTS)
    hess = ca.SX.sym("H", qp_data.sparsity_out("H"))
    z_ref = ca.SX.sym("z_ref", nz)
    dz_lq = ca.SX.sym("dz_lq", nz)

    adz = ca.mtimes(a, dz)
    viol = ca.vertcat(lba - adz, adz - uba, lbx - dz, dz - ubx)
    worst = ca.mmax(viol)
    size = ca.sum1(ca.fabs(dz)) + ca.sum1(ca.fabs(lam_a))
    ok = ca.logic_and(ca.logic_and(data_ok, size < 1e20), worst <= SOLUTION_TOLERANCE)
    z_qp = zb + dz * ca.DM(ocp.z_scale)
    plan_finite = ca.sum1(ca.fabs(zb)) < 1e20
    ref_finite = ca.sum1(ca.fabs(z_ref)) < 1e20
    # fallback: the unconstrained (Riccati) step of this QP, its currents projected onto the
    # limits below (it keeps the loop's feedback when the QP solver runs out of iterations; the
    # shifted previous plan alone is open loop and, applied sample after sample, drops the
    # stage); if that step is not finite, the shifted previous plan, else the reference plan (its
    # first input is the feedforward current of the reference), else no current at all
    lq_finite = ca.logic_and(data_ok, ca.sum1(ca.fabs(dz_lq)) < 1e20)
    z_lq = zb + dz_lq * ca.DM(ocp.z_scale)
    z_keep = ca.if_else(plan_finite, zb, ca.if_else(ref_finite, z_ref, ca.DM.zeros(nz)))
    z_new = ca.if_else(ok, z_qp, ca.if_else(lq_finite, z_lq, z_keep))
    u = ocp.project_current(z_new[0:NU])
    z_next = ca.mtimes(ca.DM(ca.sparsify(ca.DM(shift))), z_new)
    e = (z_new - z_ref) / ca.DM(ocp.z_scale)
    cost = 0.5 * ca.bilin(hess, e, e) / ocp.cost_scale  # the OCP's cost (H is c times its Hessian)
    obs_next, d_next = observer.update(obs, d, y, u)
    memory_next = ca.vertcat(obs_next, d_next, z_next)
    # inequality rows of A (N_POLYTOPE_ROWS per stage) and bounds with a nonzero multiplier
    ineq = [lam_a[STAGE_ROWS * j + NX + i] for j in range(n) for i in range(N_POLYTOPE_ROWS)]
    # (multipliers of the OCP's cost: the QP's are cost_scale times larger)
    active = ca.sum1(ca.fabs(ca.vertcat(*ineq, lam_x)) > 1e-9 * ocp.cost_scale)
    # DIAG_NAMES without qp_status; qp_iterations is filled in by the step
    diag = ca.vertcat(ok, 0, cost, d, ca.if_else(ok, active, -1))
    names = ["z_bar", "dz", "lam_x", "lam_a", "A", "lba", "uba", "lbx", "ubx", "data_ok", "H", "z_ref"]
    return ca.Function(
        "nmpc_post",
        [zb, dz, lam_x, lam_a, a, lba, uba, lbx, ubx, data_ok, hess, z_ref, obs, d, y, dz_lq],
        [u, memory_next, diag, z_new],
        [*names, "obs", "d", "y", "dz_lq"],
        ["u", "memory_next", "diag", "plan"],
    )


def qp_solver_function(
    qp_solver: str, qp_options: Mapping[str, Any], horizon: int, qp_data: ca.Function
) -> ca.Function:
    """The sparse QP solver (``ca.conic``) of the RTI.

    Parameters
    ----------
    qp_solver : {"hpipm", "qrqp", "osqp"}
    qp_options : mapping
        Solver options merged into the defaults, one level deep.
    horizon : int
        N (HPIPM's stage structure).
    qp_data : casadi.Function
        For the sparsity of H and A.

    Returns
    -------
    casadi.Function
    """
    n = horizon
    sp = {"h": qp_data.sparsity_out("H"), "a": qp_data.sparsity_out("A")}
    opts: dict = {"error_on_fail": False}
    if qp_solver == "hpipm":
        opts.update(
            N=n,
            nx=[NU] + [NX] * n,
            nu=[0] + [NU] * (n - 1) + [0],
            ng=[N_POLYTOPE_ROWS] * n + [0],
            # mu0: the initial barrier for the cost scaled by Transcription.cost_scale (on the
            # large step's 54 constrained QPs: 4.4 iterations on average, at most 7, first
            # current within 4e-7 A of the exact solution; HPIPM's default mu0 = 10 takes up to
            # 10 iterations there, and without the cost scale it stopped 0.07 A off)
            hpipm={"mode": "speed_abs", "iter_max": 30, "mu0": 1e2},
        )
    elif qp_solver == "qrqp":
        opts.update(print_iter=False, print_header=False, print_info=False, max_iter=200)
    else:
        opts.update(
            osqp={"verbose": False, "eps_abs": 1e-9, "eps_rel": 1e-9, "max_iter": 20000, "polish": True}
        )
    for key, value in qp_options.items():  # solver-specific overrides, one level deep
        if isinstance(value, Mapping) and isinstance(opts.get(key), dict):
            opts[key] = {**opts[key], **value}
        else:
            opts[key] = value
    return ca.conic("nmpc_qp", qp_solver, sp, opts)


def _solve_qp_function(qp: ca.Function, qp_data: ca.Function, nz: int, na: int) -> tuple[list, ca.Function]:
    """(the QP's symbolic inputs plus dz_lq, Function (H, ..., ubx, dz_lq) -> (dz, lam_x, lam_a))."""
    sparsities = [qp_data.sparsity_out(i) for i in range(len(_QP_INPUTS))] + [ca.Sparsity.dense(nz, 1)]
    qp_in = [ca.MX.sym(name, sp) for name, sp in zip((*_QP_INPUTS, "dz_lq"), sparsities, strict=True)]
    # Cold start: QRQP warm-started with the previous multipliers was seen to return a wrong
    # step (equality rows dropped from its initial active set) while reporting success, and
    # an interior point method has no use for them. All of the conic's outputs are used:
    # CasADi 3.8.2's HPIPM interface writes lam_a even when nobody asked for it (a NULL
    # pointer inside an MX graph: segfault).
    sol = qp(
        h=qp_in[0],
        g=qp_in[1],
        a=qp_in[2],
        lba=qp_in[3],
        uba=qp_in[4],
        lbx=qp_in[5],
        ubx=qp_in[6],
        x0=ca.DM.zeros(nz),
        lam_x0=ca.DM.zeros(nz),
        lam_a0=ca.DM.zeros(na),
    )
    return qp_in, ca.Function("nmpc_solve_qp", qp_in, [sol["x"], sol["lam_x"], sol["lam_a"]])


def rti_step_function(
    parts: RTIParts, qp: ca.Function, observer: ExtendedHighGainObserver, *, horizon: int, shortcut: bool
) -> ca.Function:
    """The whole RTI update as one Function.

    Parameters
    ----------
    parts : RTIParts
    qp : casadi.Function
        The QP solver (:func:`qp_solver_function`), its own instance so that the statistics read
        after a call are that call's.
    observer : ExtendedHighGainObserver
    horizon : int
        N.
    shortcut : bool
        Take the Riccati step when it is feasible (else solve the QP every sample).

    Returns
    -------
    casadi.Function
        ``nmpc_rti_step``: (memory, y (2), ref (6, N + 1)) -> (u (2), memory_next, diag (7)).
    """
    qp_data = parts.qp_data
    nz, na = qp_data.size1_out("g"), qp_data.size1_out("lba")
    layout = MemoryLayout(nz)
    mem = ca.MX.sym("memory", layout.size)
    y = ca.MX.sym("y", N_MEASUREMENTS)
    ref = ca.MX.sym("ref", N_REFERENCE, horizon + 1)
    obs, d, zb = mem[layout.observer], mem[layout.disturbance], mem[layout.plan]
    x0 = observer.state_estimate(obs, y)
    data = qp_data(zb, x0, d, ref)
    _, _, a, lba, uba, lbx, ubx, data_ok, _ = data
    # the unconstrained step: the answer when it satisfies every bound (shortcut), and the
    # fallback when the QP solver fails (its iteration budget, qp_options max_iter, runs out)
    dz_lq, lq_feasible = parts.riccati(*data[:7])
    if shortcut:
        feasible = lq_feasible
        dz, lam_x, lam_a = _step_or_qp(qp, qp_data, nz, na)(feasible, *data[:7], dz_lq)
    else:
        feasible = ca.MX(0)
        _, solve_qp = _solve_qp_function(qp, qp_data, nz, na)
        dz, lam_x, lam_a = solve_qp(*data[:7], ca.DM.zeros(nz))
    hess, z_ref = data[0], data[8]
    u, mem_next, diag, _ = parts.post(
        zb, dz, lam_x, lam_a, a, lba, uba, lbx, ubx, data_ok, hess, z_ref, obs, d, y, dz_lq
    )
    diag = _step_diagnostics(diag, feasible)
    return ca.Function(
        "nmpc_rti_step",
        [mem, y, ref],
        [u, mem_next, diag],
        ["memory", "y", "ref"],
        ["u", "memory_next", "diag"],
    )


def _step_diagnostics(diag, feasible):
    """The post-processing's diagnostics with the QP's entries of the step.

    qp_iterations: 0 when the unconstrained step was taken, -1 (filled in from the solver's
    statistics in Python) when the QP was solved; qp_status: -1 no QP, NaN until filled in.
    """
    return ca.vertcat(diag[0], ca.if_else(feasible, 0, -1), diag[2:], ca.if_else(feasible, -1, np.nan))


def _step_or_qp(qp: ca.Function, qp_data: ca.Function, nz: int, na: int) -> ca.Function:
    """(feasible, H, ..., ubx, dz_lq) -> (dz, lam_x, lam_a): the unconstrained step dz_lq when it is
    feasible, else the QP's solution (a CasADi Switch: only the selected branch runs, also in the
    generated C)."""
    qp_in, solve_qp = _solve_qp_function(qp, qp_data, nz, na)
    take_lq = ca.Function("nmpc_take_lq", qp_in, [qp_in[7], ca.DM.zeros(nz), ca.DM.zeros(na)])
    return ca.Function.if_else("nmpc_lq_or_qp", take_lq, solve_qp)


# ------------------------------------------------------------------------------------------
# Preparation and feedback: the RTI step split at the measurement (initial value embedding)
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PreparedLayout:
    """Where the prepared QP sits in the vector the preparation hands to the feedback.

    Entries, in this order: H and A (their nonzeros), g, lba, uba, lbx, ubx, data_ok, z_ref
    (:meth:`Transcription.qp_data_function <.transcription.Transcription.qp_data_function>` at
    the predicted initial state), the predicted initial state x0_pred (4), the Riccati step
    there dz_pred (nz), its sensitivity to the initial state S (nz, 4, column-major), the
    sensitivity of the first dynamics rows' bounds to the initial state J (4, 4, column-major)
    and the Riccati factorization of the QP (:func:`~.riccati.riccati_factor`, for a QP solver
    that reuses it: the C export's dual active-set method; the feedback here does not read it).
    """

    sizes: tuple[tuple[str, int], ...]

    @classmethod
    def of(cls, qp_data: ca.Function) -> PreparedLayout:
        nz, na = qp_data.size1_out("g"), qp_data.size1_out("lba")
        return cls(
            (
                ("H", qp_data.nnz_out("H")),
                ("A", qp_data.nnz_out("A")),
                ("g", nz),
                ("lba", na),
                ("uba", na),
                ("lbx", nz),
                ("ubx", nz),
                ("data_ok", 1),
                ("z_ref", nz),
                ("x0_pred", NX),
                ("dz_pred", nz),
                ("S", nz * NX),
                ("J", NX * NX),
                ("riccati", FACTOR_STAGE * (nz // (NX + NU))),
            )
        )

    @property
    def size(self) -> int:
        """Entries of the prepared vector."""
        return sum(n for _, n in self.sizes)

    def split(self, v) -> dict[str, Any]:
        """The named parts of a prepared vector (CasADi column)."""
        out, k = {}, 0
        for name, n in self.sizes:
            out[name] = v[k : k + n]
            k += n
        return out


def _predicted_initial_state(observer: ExtendedHighGainObserver, obs):
    """The estimate before the reading: the observer's estimate at the reading it predicts (its
    positions p_v, p_h), i.e. its own state."""
    return observer.state_estimate(obs, ca.vertcat(obs[0], obs[2]))


def rti_prepare_function(parts: RTIParts, observer: ExtendedHighGainObserver, *, horizon: int) -> ca.Function:
    """The preparation of the RTI step: everything that does not need the new reading.

    In the RTI with initial value embedding (Diehl et al.) the QP is linearized at the predicted
    initial state x0_pred; the initial state x0 (the observer's estimate once the reading is in)
    then enters the QP only through the bounds of the first dynamics rows, affinely:
    ``lba_0(x0) = lba_0(x0_pred) + J (x0 - x0_pred)`` with J = -A_0 (the first interval's state
    Jacobian, scaled), and the Riccati step of the equality-constrained QP is affine in them:
    ``dz(x0) = dz_pred + S (x0 - x0_pred)``. Both J and S are computed here (S by forward AD
    through the Riccati recursion: exact, the step is affine).

    Parameters
    ----------
    parts : RTIParts
    observer : ExtendedHighGainObserver
    horizon : int
        N.

    Returns
    -------
    casadi.Function
        ``nmpc_rti_prepare``: (memory, ref (6, N + 1)) -> prepared (:class:`PreparedLayout`).
    """
    qp_data = parts.qp_data
    nz = qp_data.size1_out("g")
    layout = MemoryLayout(nz)
    mem = ca.SX.sym("memory", layout.size)
    ref = ca.SX.sym("ref", N_REFERENCE, horizon + 1)
    obs, d, zb = mem[layout.observer], mem[layout.disturbance], mem[layout.plan]
    x0_pred = ca.SX.sym("x0_pred", NX)
    h, g, a, lba, uba, lbx, ubx, data_ok, z_ref = qp_data(zb, x0_pred, d, ref)
    jac = ca.jacobian(lba[0:NX], x0_pred)
    delta = ca.SX.sym("delta", NX)  # x0 - x0_pred
    shifted = ca.vertcat(lba[0:NX] + ca.mtimes(jac, delta), lba[NX:])
    dz, _ = parts.riccati(h, g, a, shifted, ca.vertcat(uba[0:NX] + ca.mtimes(jac, delta), uba[NX:]), lbx, ubx)
    sens = ca.substitute(ca.jacobian(dz, delta), delta, ca.DM.zeros(NX))  # constant: dz is affine
    dz_pred = ca.substitute(dz, delta, ca.DM.zeros(NX))
    prepared = ca.vertcat(
        ca.vertcat(*h.nonzeros()),
        ca.vertcat(*a.nonzeros()),
        g,
        lba,
        uba,
        lbx,
        ubx,
        data_ok,
        z_ref,
        x0_pred,
        dz_pred,
        ca.vec(ca.densify(sens)),
        ca.vec(ca.densify(jac)),
        riccati_factor(h, a, horizon),  # the same expressions as the step's: computed once (cse)
    )
    prepared = ca.substitute(prepared, x0_pred, _predicted_initial_state(observer, obs))
    return ca.Function(
        "nmpc_rti_prepare", [mem, ref], [prepared], ["memory", "ref"], ["prepared"], {"cse": True}
    )


def rti_feedback_function(
    parts: RTIParts, qp: ca.Function, observer: ExtendedHighGainObserver, *, horizon: int
) -> ca.Function:
    """The feedback of the RTI step: what needs the reading, on a prepared QP.

    The observer's estimate x0 from the reading; the Riccati step ``dz_pred + S (x0 - x0_pred)``
    and the first dynamics rows' bounds ``lba_0 + J (x0 - x0_pred)``
    (:func:`rti_prepare_function`); the check of that step against every bound; the QP (with
    the same data) only when it violates one; then the post-processing of :func:`rti_parts`
    (check of the QP's solution, fallback, shift, observer update) as in the one-Function step.

    Parameters
    ----------
    parts : RTIParts
    qp : casadi.Function
        The QP solver (:func:`qp_solver_function`).
    observer : ExtendedHighGainObserver
    horizon : int
        N.

    Returns
    -------
    casadi.Function
        ``nmpc_rti_feedback``: (memory, prepared, y (2)) -> (u (2), memory_next, diag (7)).
    """
    qp_data = parts.qp_data
    nz, na = qp_data.size1_out("g"), qp_data.size1_out("lba")
    layout = MemoryLayout(nz)
    prep_layout = PreparedLayout.of(qp_data)
    mem = ca.MX.sym("memory", layout.size)
    prepared = ca.MX.sym("prepared", prep_layout.size)
    y = ca.MX.sym("y", N_MEASUREMENTS)
    f = _feedback_data(qp_data, observer, mem, prepared, y, horizon)
    dz, lam_x, lam_a = _step_or_qp(qp, qp_data, nz, na)(
        f["feasible"], f["H"], f["g"], f["A"], f["lba"], f["uba"], f["lbx"], f["ubx"], f["dz_lq"]
    )
    u, mem_next, diag = _feedback_post(parts, f, dz, lam_x, lam_a)
    return ca.Function(
        "nmpc_rti_feedback",
        [mem, prepared, y],
        [u, mem_next, _step_diagnostics(diag, f["feasible"])],
        ["memory", "prepared", "y"],
        ["u", "memory_next", "diag"],
    )


def rti_feedback_parts(
    parts: RTIParts, observer: ExtendedHighGainObserver, *, horizon: int
) -> tuple[ca.Function, ca.Function]:
    """The feedback of :func:`rti_feedback_function` in two Functions around a QP solver that is
    not a CasADi Function (the C export's dual active-set method, :mod:`maglev_oc.control.export_qp`).

    Parameters
    ----------
    parts : RTIParts
    observer : ExtendedHighGainObserver
    horizon : int
        N.

    Returns
    -------
    lq : casadi.Function
        ``nmpc_rti_feedback_lq``: (memory, prepared, y) -> (dz_lq (nz), feasible): the Riccati
        step corrected by the reading and 1 if it satisfies every bound (then it is the QP's
        solution), as in :func:`rti_feedback_function`.
    post : casadi.Function
        ``nmpc_rti_feedback_post``: (memory, prepared, y, dz, lam_x, lam_a, dz_lq,
        qp_iterations, qp_status) -> (u, memory_next, diag): the post-processing of
        :func:`rti_feedback_function` (solution check, fallback to the saturated ``dz_lq``,
        shift, observer update) of the QP's solution (dz, lam_x, lam_a) -- or of (dz_lq, 0, 0)
        where ``feasible`` -- with the solver's iteration count and status in the diagnostics
        (0 and -1 where no QP was solved). With the same QP solution, the same arithmetic as
        :func:`rti_feedback_function`.
    """
    qp_data = parts.qp_data
    nz, na = qp_data.size1_out("g"), qp_data.size1_out("lba")
    mem = ca.MX.sym("memory", MemoryLayout(nz).size)
    prepared = ca.MX.sym("prepared", PreparedLayout.of(qp_data).size)
    y = ca.MX.sym("y", N_MEASUREMENTS)
    f = _feedback_data(qp_data, observer, mem, prepared, y, horizon)
    lq = ca.Function(
        "nmpc_rti_feedback_lq",
        [mem, prepared, y],
        [f["dz_lq"], f["feasible"]],
        ["memory", "prepared", "y"],
        ["dz_lq", "feasible"],
    )
    dz, lam_x, lam_a, dz_lq = (
        ca.MX.sym(name, n) for name, n in (("dz", nz), ("lam_x", nz), ("lam_a", na), ("dz_lq", nz))
    )
    iterations, status = ca.MX.sym("qp_iterations"), ca.MX.sym("qp_status")
    u, mem_next, diag = _feedback_post(parts, {**f, "dz_lq": dz_lq}, dz, lam_x, lam_a)
    diag = ca.vertcat(diag[0], iterations, diag[2:], status)
    post = ca.Function(
        "nmpc_rti_feedback_post",
        [mem, prepared, y, dz, lam_x, lam_a, dz_lq, iterations, status],
        [u, mem_next, diag],
        ["memory", "prepared", "y", "dz", "lam_x", "lam_a", "dz_lq", "qp_iterations", "qp_status"],
        ["u", "memory_next", "diag"],
    )
    return lq, post


def _feedback_data(qp_data: ca.Function, observer, mem, prepared, y, horizon: int) -> dict[str, Any]:
    """The feedback's QP (MX): the prepared data with the first dynamics rows' bounds corrected
    by the reading's estimate, the corrected Riccati step ``dz_lq``, whether it is ``feasible``,
    and the memory's parts (:func:`rti_feedback_function`)."""
    nz = qp_data.size1_out("g")
    layout = MemoryLayout(nz)
    p = PreparedLayout.of(qp_data).split(prepared)
    obs, d, zb = mem[layout.observer], mem[layout.disturbance], mem[layout.plan]
    delta = observer.state_estimate(obs, y) - p["x0_pred"]
    # a reading that is not finite: no correction, and the data flagged (the post-processing then
    # keeps the shifted plan, as the one-Function step does with a non-finite estimate)
    delta_ok = ca.sum1(ca.fabs(delta)) < 1e20
    data_ok = ca.logic_and(p["data_ok"], delta_ok)
    delta = ca.if_else(delta_ok, delta, ca.DM.zeros(NX))
    jac = ca.reshape(p["J"], NX, NX)
    shift0 = ca.if_else(p["data_ok"], ca.mtimes(jac, delta), ca.DM.zeros(NX))
    lba = ca.vertcat(p["lba"][0:NX] + shift0, p["lba"][NX:])
    uba = ca.vertcat(p["uba"][0:NX] + shift0, p["uba"][NX:])
    hess = ca.MX(qp_data.sparsity_out("H"), p["H"])
    a = ca.MX(qp_data.sparsity_out("A"), p["A"])
    dz_lq = p["dz_pred"] + ca.mtimes(ca.reshape(p["S"], nz, NX), delta)
    feasible = satisfies_inequalities(dz_lq, a, lba, uba, p["lbx"], p["ubx"], horizon)
    return {
        **{key: p[key] for key in ("g", "lbx", "ubx", "z_ref")},
        "H": hess,
        "A": a,
        "lba": lba,
        "uba": uba,
        "data_ok": data_ok,
        "dz_lq": dz_lq,
        "feasible": feasible,
        "memory": (mem, obs, d, zb),
        "y": y,
    }


def _feedback_post(parts: RTIParts, f: dict[str, Any], dz, lam_x, lam_a):
    """(u, memory_next, diag) of the post-processing on the feedback's data ``f``."""
    _, obs, d, zb = f["memory"]
    u, mem_next, diag, _ = parts.post(
        zb,
        dz,
        lam_x,
        lam_a,
        f["A"],
        f["lba"],
        f["uba"],
        f["lbx"],
        f["ubx"],
        f["data_ok"],
        f["H"],
        f["z_ref"],
        obs,
        d,
        f["y"],
        f["dz_lq"],
    )
    return u, mem_next, diag


def python_entry(step: ca.Function, n_memory: int, horizon: int) -> ca.Function:
    """The RTI step with its inputs and outputs packed, for the Python loop.

    Each numpy <-> CasADi conversion costs 10-25 us in Python while the memory can stay a DM
    from one call to the next.

    Parameters
    ----------
    step : casadi.Function
        :func:`rti_step_function`'s Function.
    n_memory : int
        Entries of the memory.
    horizon : int
        N.

    Returns
    -------
    casadi.Function
        (memory, [y; vec(ref)]) -> ([u; diag], memory_next).
    """
    mem = ca.MX.sym("memory", n_memory)
    yr = ca.MX.sym("y_ref", N_MEASUREMENTS + N_REFERENCE * (horizon + 1))
    u, mem_next, diag = step(
        mem, yr[0:N_MEASUREMENTS], ca.reshape(yr[N_MEASUREMENTS:], N_REFERENCE, horizon + 1)
    )
    return ca.Function("nmpc_control", [mem, yr], [ca.vertcat(u, diag), mem_next])


def read_qp_statistics(diag: np.ndarray, qp: ca.Function) -> None:
    """Put the QP solver's iteration count and success into ``diag`` (in place).

    A conic called inside an MX Function (here behind a Switch) keeps its statistics in the
    memory the enclosing Function checked out for it, index 1 for a Function evaluated from one
    thread; the enclosing Function's own stats() does not forward them through the Switch.
    Diagnostics only: if they are not there, the entries stay -1 / NaN.

    Parameters
    ----------
    diag : (7,) array
        A row of :data:`~.status.DIAG_NAMES`, changed in place.
    qp : casadi.Function
        The QP solver inside the step that wrote ``diag``.
    """
    try:
        stats = qp.stats(1)
    except RuntimeError:
        return
    diag[DIAG_NAMES.index("qp_iterations")] = stats.get("iter_count", -1)
    diag[DIAG_NAMES.index("qp_status")] = 0.0 if stats.get("success", False) else 1.0
