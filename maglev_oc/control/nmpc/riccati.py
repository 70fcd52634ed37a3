"""The unconstrained shortcut of the RTI: the Riccati recursion of the equality-constrained QP.

Most samples have no active inequality. The Riccati recursion of the QP without its
inequalities (the LQ problem; its exact minimizer, ~10k flops) is computed first and, when it
satisfies every bound and polytope row, it IS the QP's solution and the QP solver is not called.
"""

from __future__ import annotations

import casadi as ca

from maglev_oc.control.nmpc.layout import N_POLYTOPE_ROWS, NU, NX, STAGE_ROWS, u_index, x_index

__all__ = ["FACTOR_STAGE", "riccati_factor", "riccati_function", "satisfies_inequalities"]

FACTOR_STAGE = 2 * NX * NU + NU * NU + NX * NX + N_POLYTOPE_ROWS * NU
"""Entries of :func:`riccati_factor` per shooting interval (40)."""


def riccati_function(qp_data: ca.Function, horizon: int) -> ca.Function:
    """The LQ step and whether it solves the QP.

    Parameters
    ----------
    qp_data : casadi.Function
        :meth:`Transcription.qp_data_function <.transcription.Transcription.qp_data_function>`
        (for the sparsity of H and A).
    horizon : int
        N.

    Returns
    -------
    casadi.Function
        (H, g, A, lba, uba, lbx, ubx) -> (dz, feasible): the minimizer of the QP without its
        inequalities and 1 if it satisfies every bound and polytope row (then it is the QP's
        solution), else 0.
    """
    n = horizon
    nz, na = qp_data.size1_out("g"), qp_data.size1_out("lba")
    hess = ca.SX.sym("H", qp_data.sparsity_out("H"))
    grad = ca.SX.sym("g", nz)
    a = ca.SX.sym("A", qp_data.sparsity_out("A"))
    lba = ca.SX.sym("lba", na)
    uba = ca.SX.sym("uba", na)
    lbx = ca.SX.sym("lbx", nz)
    ubx = ca.SX.sym("ubx", nz)

    bs, as_, cs = _stage_matrices(a, lba, n)
    gains = _backward_pass(hess, grad, as_, bs, cs, n)
    dz = _forward_pass(gains, as_, bs, cs, n)
    feasible = satisfies_inequalities(dz, a, lba, uba, lbx, ubx, n)
    return ca.Function(
        "nmpc_riccati",
        [hess, grad, a, lba, uba, lbx, ubx],
        [dz, feasible],
        ["H", "g", "A", "lba", "uba", "lbx", "ubx"],
        ["dz", "feasible"],
    )


def riccati_factor(hess, a, horizon: int):
    """The Riccati factorization of the QP's equality-constrained part, per interval, as one column.

    Per interval j = 0..N-1, column-major: B_j (NX x NU), Quu_j^-1 (NU x NU), K_j (NU x NX), A_j
    (NX x NX) and D_j (N_POLYTOPE_ROWS x NU, the polytope rows), with K_0 = A_0 = 0 (x_0 is not a
    variable). With them, the minimizer of 1/2 dz' H dz + g' dz under the homogeneous dynamics
    dx_{j+1} = A_j dx_j + B_j du_j (dx_0 = 0) is, for any gradient g: backwards from
    p = g_{x_N}, qu_j = g_{u_j} + B_j' p, k_j = Quu_j^-1 qu_j, p = g_{x_j} + A_j' p - K_j' qu_j
    (j > 0); forwards du_j = -K_j dx_j - k_j. This is the same backward pass as
    :func:`riccati_function`'s (the same expressions: a Function with ``cse`` computes them once),
    for a QP solver that reuses it (the export's dual active-set method).

    Parameters
    ----------
    hess, a : CasADi SX
        The QP's Hessian and constraint matrix (:meth:`~.transcription.Transcription.qp_data_function`).
    horizon : int
        N.

    Returns
    -------
    CasADi SX column of FACTOR_STAGE N entries.
    """
    n = horizon
    bs, as_, cs = _stage_matrices(a, ca.SX.zeros(a.size1()), n)
    gains = _backward_pass(hess, ca.SX.zeros(hess.size1()), as_, bs, cs, n)
    parts = []
    for j in range(n):
        k_mat, _, quu_inv = gains[j]
        row = STAGE_ROWS * j + NX
        parts += [
            bs[j],
            quu_inv,
            ca.SX.zeros(NU, NX) if k_mat is None else k_mat,
            ca.SX.zeros(NX, NX) if as_[j] is None else as_[j],
            _block(a, row, u_index(j), N_POLYTOPE_ROWS, NU),
        ]
    return ca.vertcat(*[ca.vec(ca.densify(m)) for m in parts])


def _stage_matrices(a, lba, n):
    """(B_j, A_j (None for j = 0), c_j = -lba of the dynamics rows) per interval."""
    bs, as_, cs = [], [], []
    for j in range(n):
        row = STAGE_ROWS * j
        bs.append(_block(a, row, u_index(j), NX, NU))
        as_.append(_block(a, row, x_index(j), NX, NX) if j > 0 else None)
        cs.append(-lba[row : row + NX])
    return bs, as_, cs


def satisfies_inequalities(dz, a, lba, uba, lbx, ubx, horizon: int):
    """1 if the step dz satisfies every simple bound and polytope row of the QP, else 0.

    Parameters
    ----------
    dz : CasADi column (nz)
    a, lba, uba, lbx, ubx : CasADi
        The QP's constraint matrix and bounds (:meth:`~.transcription.Transcription.qp_data_function`).
    horizon : int
        N.

    Returns
    -------
    CasADi scalar
    """
    rows = [STAGE_ROWS * j + NX + i for j in range(horizon) for i in range(N_POLYTOPE_ROWS)]
    adz = ca.mtimes(a[rows, :], dz)
    slack = ca.vertcat(dz - lbx, ubx - dz, adz - lba[rows], uba[rows] - adz)
    return ca.mmin(slack) >= 0


def _block(m, r, c, nr, nc):
    return ca.densify(m[r : r + nr, c : c + nc])


def _inv2(m):
    det = m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]
    return ca.vertcat(ca.horzcat(m[1, 1], -m[0, 1]), ca.horzcat(-m[1, 0], m[0, 0])) / det


def _backward_pass(hess, grad, as_, bs, cs, n):
    """Feedback and feedforward gains (K_j, k_j) of du_j = -K_j dx_j - k_j, and Quu_j^-1, for
    j = 0..N-1 (K_0 is None: x_0 is not a variable), from the cost-to-go recursion backwards
    from x_N."""
    xn = x_index(n)
    p_mat = _block(hess, xn, xn, NX, NX)
    p_vec = grad[xn : xn + NX]
    gains = []
    for j in range(n - 1, -1, -1):
        iu = u_index(j)
        b, c = bs[j], cs[j]
        pcp = ca.mtimes(p_mat, c) + p_vec
        quu = _block(hess, iu, iu, NU, NU) + ca.mtimes(b.T, ca.mtimes(p_mat, b))
        qu = grad[iu : iu + NU] + ca.mtimes(b.T, pcp)
        quu_inv = _inv2(quu)
        if j == 0:
            gains.append((None, ca.mtimes(quu_inv, qu), quu_inv))
            break
        am = as_[j]
        ix = x_index(j)
        pa = ca.mtimes(p_mat, am)  # shared by B' P A and A' P A
        qux = ca.mtimes(b.T, pa)
        k_mat = ca.mtimes(quu_inv, qux)
        k_vec = ca.mtimes(quu_inv, qu)
        gains.append((k_mat, k_vec, quu_inv))
        p_new = _block(hess, ix, ix, NX, NX) + ca.mtimes(am.T, pa) - ca.mtimes(qux.T, k_mat)
        p_vec = grad[ix : ix + NX] + ca.mtimes(am.T, pcp) - ca.mtimes(qux.T, k_vec)
        p_mat = 0.5 * (p_new + p_new.T)
    return gains[::-1]


def _forward_pass(gains, as_, bs, cs, n):
    """dz = (du_0, dx_1, du_1, ..., dx_N) by rolling the linear dynamics forward."""
    parts = []
    du = -gains[0][1]
    dx = ca.mtimes(bs[0], du) + cs[0]
    parts += [du, dx]
    for j in range(1, n):
        k_mat, k_vec, _ = gains[j]
        du = -ca.mtimes(k_mat, dx) - k_vec
        dx = ca.mtimes(as_[j], dx) + ca.mtimes(bs[j], du) + cs[j]
        parts += [du, dx]
    return ca.vertcat(*parts)
