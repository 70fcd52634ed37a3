"""Benchmark: our identification against plain scipy.optimize.least_squares fits, same log, one run.

    python bench/peer_scipy_identification.py [--seconds 60] [--json OUT.json]

The log: the sum-of-sines excitation tracked by the paper's PIDs on the twin whose true
constants are ``TWIN_TRUTH`` (the papers' C1..C4 times 1.03, 0.98, 1.03, 1.15), with encoders
(10 um, 2 um noise) and amplifiers, logged at 1 kHz (the log of bench/identification.py). Every
fit starts from the papers' constants (what the model holds) and estimates C1..C4.

Ours:

* equation error (``fit_equation_error``: zero-phase Savitzky-Golay derivatives, the model side
  filtered by the same kernel, one linear least-squares solve, HAC standard errors);
* output error by multiple shooting (``MultipleShooting``: 50 ms segments joined within 0.2 s
  windows, constrained Gauss-Newton with exact CasADi Jacobians, started from the equation-error
  fit).

A reasonable scipy user's versions, with ``scipy.optimize.least_squares`` (TRF) and
finite-difference Jacobians, the model evaluated by ``StageModel().f_theta`` (mapped over the
samples):

* equation error: positions, velocities and accelerations from ``scipy.signal.savgol_filter``
  (cubic, 51 samples = 51 ms, the textbook choice), residual = SG acceleration - model
  acceleration at the SG states and the logged currents, both axes unweighted;
  ``jac="2-point"``, ``x_scale="jac"``;
* output error on independent 50 ms segments (the same segments as ours, without continuity:
  a single simulation of the open-loop unstable stage over the log diverges): the unknowns are
  C1..C4 and each segment's initial state, each segment simulated with RK4 per sample (currents
  linear between samples, as ours), residual = simulated - read positions in encoder counts;
  ``jac="2-point"`` with ``jac_sparsity`` (the block structure: each segment's state touches
  only its own residuals), started from the scipy equation-error fit.

Standard errors of the scipy fits: the naive s^2 (J'J)^-1 (for the segments, its C block via a
sparse factorization); ours are the long-run (HAC) ones.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import casadi as ca
import numpy as np
import scipy
import scipy.sparse as sp
from common import fmt, machine
from scipy.optimize import least_squares
from scipy.signal import savgol_filter
from scipy.sparse.linalg import splu

from maglev_oc.identification.equation_error import fit_equation_error
from maglev_oc.identification.experiments import TWIN_TRUTH, excitation_log
from maglev_oc.identification.output_error import MultipleShooting
from maglev_oc.model.stage import StageModel

NAMES = ("C1", "C2", "C3", "C4")
SG_WINDOW = 51
SG_ORDER = 3
SEGMENT = 50  # samples (50 ms at 1 kHz), as DEFAULT_SEGMENT of output_error.py
COUNT = 10e-6  # [m] encoder count: residual scale of the output error


def naive_stderr(jac, residual: np.ndarray, n_params: int) -> np.ndarray:
    """sqrt(diag(s^2 (J'J)^-1)) for the first ``n_params`` columns (J dense or sparse)."""
    dof = residual.size - jac.shape[1]
    s2 = float(residual @ residual) / dof
    if sp.issparse(jac):
        h = (jac.T @ jac).tocsc()
        rhs = np.zeros((h.shape[0], n_params))
        rhs[np.arange(n_params), np.arange(n_params)] = 1.0
        block = splu(h).solve(rhs)[:n_params]
    else:
        block = np.linalg.inv(jac.T @ jac)[:n_params, :n_params]
    return np.sqrt(s2 * np.diag(block))


def scipy_equation_error(log, model: StageModel, c0: np.ndarray):
    """Savitzky-Golay derivatives and least_squares on the acceleration residual."""
    dt = log.sample_time
    y = np.vstack([log.x[0], log.x[2]])
    pos = savgol_filter(y, SG_WINDOW, SG_ORDER, deriv=0, axis=1)
    vel = savgol_filter(y, SG_WINDOW, SG_ORDER, deriv=1, delta=dt, axis=1)
    acc = savgol_filter(y, SG_WINDOW, SG_ORDER, deriv=2, delta=dt, axis=1)
    keep = slice(SG_WINDOW, log.n - SG_WINDOW)  # away from the filter's edges
    x = np.vstack([pos[0], vel[0], pos[1], vel[1]])[:, keep]
    u = np.asarray(log.u)[:, keep]
    a = acc[:, keep]
    f = model.f_theta.map(x.shape[1])

    def residual(c):
        xdot = np.asarray(f(x, u, c))
        return (a - xdot[[1, 3]]).ravel()

    res = least_squares(residual, c0, jac="2-point", x_scale="jac", method="trf")
    return res, np.vstack([pos[0], vel[0], pos[1], vel[1]])


def scipy_output_error(log, model: StageModel, c0: np.ndarray, states0: np.ndarray):
    """Independent 50 ms segments, each with its own initial state; least_squares with a
    finite-difference Jacobian over the block sparsity."""
    dt = log.sample_time
    m = SEGMENT
    j = (log.n - 1) // m
    idx = np.arange(j)[:, None] * m + np.arange(m + 1)[None, :]  # (J, M + 1)
    y = np.stack([np.asarray(log.x[0])[idx[:, :m]], np.asarray(log.x[2])[idx[:, :m]]])  # (2, J, M)
    u = np.asarray(log.u)[:, idx]  # (2, J, M + 1)
    f = model.f_theta.map(j)
    s_init = states0[:, idx[:, 0]]  # (4, J)

    def simulate(c, s):
        x = s
        out = np.empty((2, j, m))
        for k in range(m):
            out[:, :, k] = x[[0, 2]]
            u0, u1 = u[:, :, k], u[:, :, k + 1]
            um = 0.5 * (u0 + u1)
            k1 = np.asarray(f(x, u0, c))
            k2 = np.asarray(f(x + dt / 2 * k1, um, c))
            k3 = np.asarray(f(x + dt / 2 * k2, um, c))
            k4 = np.asarray(f(x + dt * k3, u1, c))
            x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return out

    def residual(w):
        c, s = w[:4], w[4:].reshape(j, 4).T
        return ((simulate(c, s) - y) / COUNT).transpose(1, 0, 2).ravel()  # segment-major rows

    rows_per = 2 * m
    pattern = sp.lil_matrix((j * rows_per, 4 + 4 * j), dtype=bool)
    pattern[:, 0:4] = True
    for seg in range(j):
        pattern[seg * rows_per : (seg + 1) * rows_per, 4 + 4 * seg : 8 + 4 * seg] = True
    w0 = np.concatenate([c0, s_init.T.ravel()])
    res = least_squares(
        residual, w0, jac="2-point", jac_sparsity=pattern.tocsr(), x_scale="jac", method="trf"
    )
    return res, j


def row(label: str, values, stderr, truth, wall: float, extra: str = "") -> str:
    err = 100 * (np.asarray(values) / truth - 1)
    rel_se = 100 * np.asarray(stderr) / truth
    cells = "  ".join(f"{e:+8.3f} ({s:.3f})" for e, s in zip(err, rel_se, strict=True))
    return f"  {label:<40s} {cells}  {fmt(wall):>9s}{extra}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="log duration [s]")
    parser.add_argument("--json", type=Path, help="write the figures to this file")
    args = parser.parse_args()

    model = StageModel()
    truth = np.array(TWIN_TRUTH.as_array())
    c0 = np.array(model.constants.as_array())
    t0 = time.perf_counter()
    log = excitation_log(
        model.with_constants(TWIN_TRUTH), duration=args.seconds, seed=1, controller_model=model
    )
    log_s = time.perf_counter() - t0
    print(f"machine: {machine()}; casadi {ca.__version__}, scipy {scipy.__version__}")
    print(f"load average at start: {os.getloadavg()[0]:.2f} (2 cores)")
    print(
        f"log: {log.n} samples at 1 kHz ({args.seconds:g} s, twin with encoders and amplifiers; "
        f"made in {log_s:.1f} s); initial guess: the papers' constants, "
        f"{', '.join(f'{100 * (v - 1):+.0f} %' for v in c0 / truth)} from the truth\n"
    )

    fits: dict = {}
    walls = []
    for _ in range(3):
        t0 = time.perf_counter()
        ee = fit_equation_error(log, model)
        walls.append(time.perf_counter() - t0)
    fits["ours, equation error"] = (
        [ee.values[n] for n in NAMES],
        [ee.stderr[n] for n in NAMES],
        min(walls),
        "best of 3",
    )
    walls = []
    for _ in range(2):
        t0 = time.perf_counter()
        oe = MultipleShooting(log, model).fit(initial=ee)
        walls.append(time.perf_counter() - t0)
    fits["ours, output error (multiple shooting)"] = (
        [oe.values[n] for n in NAMES],
        [oe.stderr[n] for n in NAMES],
        min(walls),
        f"best of 2, from the EE fit, {oe.iterations} iterations",
    )

    walls = []
    for _ in range(3):
        t0 = time.perf_counter()
        see, states = scipy_equation_error(log, model, c0)
        walls.append(time.perf_counter() - t0)
    fits["scipy, equation error (SG 51, 2-point)"] = (
        see.x,
        naive_stderr(see.jac, see.fun, 4),
        min(walls),
        f"best of 3, {see.nfev} evaluations",
    )
    t0 = time.perf_counter()
    soe, n_seg = scipy_output_error(log, model, see.x, states)
    wall = time.perf_counter() - t0
    fits["scipy, output error (segments, 2-point)"] = (
        soe.x[:4],
        naive_stderr(soe.jac, soe.fun, 4),
        wall,
        f"one run, from the scipy EE fit, {n_seg} segments, {soe.nfev} evaluations, {soe.njev} Jacobians",
    )

    print("  error against the truth [%] (standard error [%])")
    print(f"  {'fit':<40s} " + "  ".join(f"{n:^19s}" for n in NAMES) + f"  {'wall':>9s}")
    results: dict = {"machine": machine(), "log_samples": log.n, "truth": truth.tolist(), "fits": {}}
    for label, (values, stderr, wall, note) in fits.items():
        print(row(label, values, stderr, truth, wall, f"  {note}"))
        results["fits"][label] = {
            "values": list(map(float, values)),
            "stderr": list(map(float, stderr)),
            "error_pct": (100 * (np.asarray(values) / truth - 1)).tolist(),
            "wall_s": wall,
            "note": note,
        }
    print(f"\n  scipy OE status: {soe.message}; scipy EE status: {see.message}")
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=2) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
