"""Benchmark: our NMPC against do-mpc on the same optimal control problem, in one run.

    python bench/peer_dompc.py [--seconds 0.3] [--scenarios large_step small_step] [--no-jit]
                               [--no-c] [--json OUT.json]

Issue 7 asks for "at least 10x faster than do-mpc at equal closed-loop cost (within 1 %)".

The same OCP in both tools, at the rig's 5 kHz:

* model: ``StageModel().f``, one RK4 step per shooting interval (do-mpc: a ``discrete`` model
  whose right-hand side is that RK4 step; the interval length is a time-varying parameter, so
  do-mpc carries our grid exactly: a first interval of one sample, 0.2 ms, then N - 1 = 19
  intervals of 5 ms);
* cost: the integrated stage cost h_j (|x_j - xr_j|_Q^2 + |u_j - ur_j|_R^2) with our default
  weights and the feedforward current ur of the reference, plus the terminal cost
  |x_N - xr_N|_P(r_v,N)^2 with our tabulated LQR weight (as a CasADi expression in do-mpc's
  ``mterm``); no input-rate penalty in either;
* constraints: the current octagon (do-mpc: box bounds on u and four linear ``set_nl_cons``
  rows, hard), gap 10-29 mm and horizontal +-55 mm on the states (do-mpc bounds nodes 1..N, we
  bound nodes 2..N: neither is active in these scenarios);
* the same reference preview (each node reads the reference at its own time);
* the same measurements and state estimate: both controllers see the encoder positions and
  estimate the velocities with the same high-gain observer (eps = 2 ms, driven by the model
  acceleration at the applied current); our disturbance estimate is switched off
  (``disturbance_bandwidth=0``), since do-mpc has none and the ideal twin has no disturbance.

Run on the papers' small and large steps on the ideal twin (``RigTwin(StageModel())``, the
plant equal to the model), the first ``--seconds`` (default 0.3 s: both closed loops have
settled to below 1 um by 0.2 s; the cost after that is nil). Compared:

* ours, RTI (one Gauss-Newton SQP step per sample, HPIPM + Riccati shortcut), CasADi VM and
  with the SX parts JIT-compiled (``compile=True``);
* ours, RTI generated as C (gcc -O3, HPIPM; ``maglev_oc.control.codegen``), replayed by
  bench/nmpc_c/harness.c on every call recorded in the VM run (two timed passes); its outputs
  are those of the VM run (checked on every tenth call), so its cost is the VM run's;
* ours, converged (IPOPT to convergence each sample; our IPOPT options), a cross-check that
  both tools solve the same problem: it must reproduce do-mpc's currents;
* do-mpc 5, twice: IPOPT with do-mpc's defaults (MUMPS, tol 1e-8), and IPOPT with our
  converged mode's options (tol 1e-10, adaptive mu, warm-start init point: the same solver
  settings); do-mpc warm-starts from its previous primal-dual solution; output storage trimmed
  (no Lagrange multipliers stored). The speed-up and cost ratios are against the faster of the
  two on each scenario.

Agreement: our converged mode and do-mpc with the same IPOPT options must give the same
currents (they do, to 6e-6 A or better); with do-mpc's default tolerance IPOPT stops up to 5e-4 A
inside an active current bound.

Per-step time: the engine's timer around each controller call (observer included in both),
median / p99 / worst; for do-mpc also IPOPT's own wall time (``t_wall_total``), which shows how
much of ``make_step`` is do-mpc's bookkeeping. Closed-loop cost: J = sum_k Ts (|x_k - r_k|_Q^2 +
|u_k - ur_k|_R^2) over the run, on the twin's true state, the same formula for every controller
(Q, R our default weights). The machine has 2 cores shared with other jobs: the load average
is printed.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import shutil
import sys
import tempfile
import time
import warnings
from pathlib import Path

import casadi as ca
import numpy as np
from common import fmt, machine

from maglev_oc.control import codegen
from maglev_oc.control.nmpc import DEFAULT_GAP_BOUNDS, DEFAULT_POSITION_BOUNDS, NMPCWeights, NonlinearMPC
from maglev_oc.control.nmpc.converged import IPOPT_OPTIONS
from maglev_oc.estimation.high_gain import DEFAULT_EPSILON, HighGainObserver
from maglev_oc.model.feedback import transformation_expressions
from maglev_oc.model.stage import StageModel
from maglev_oc.numerics import c_compiler, rk4_step
from maglev_oc.sim.engine import ClosedLoop, SimulationResult
from maglev_oc.sim.nmpc_instances import record_instances
from maglev_oc.sim.scenarios import paper_scenarios
from maglev_oc.sim.twin import RigTwin

try:
    with warnings.catch_warnings():  # do-mpc warns about its optional extras (ONNX, opcua, torch)
        warnings.simplefilter("ignore")
        import do_mpc
except ImportError:
    sys.exit("bench/peer_dompc.py needs do-mpc (a peer, not a dependency): pip install -e '.[peers]'")


OUR_IPOPT_OPTIONS = {f"ipopt.{key}": value for key, value in IPOPT_OPTIONS.items()}
"""The IPOPT options of our converged mode (maglev_oc.control.nmpc.converged), for do-mpc's second
row (do-mpc passes the previous multipliers to IPOPT, so the primal-dual warm start is the same)."""
DOMPC_ROWS = ("do-mpc (IPOPT defaults)", "do-mpc (IPOPT, our options)")


# ------------------------------------------------------------------------------------------
def rk4_function(model: StageModel) -> ca.Function:
    """(x, u, h) -> x after one RK4 step of length h: the same step our NMPC shoots with."""
    x, u, h = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("h")
    return ca.Function("rk4", [x, u, h], [rk4_step(model.f, x, h, u)])


def feedforward_function(model: StageModel) -> ca.Function:
    """r (6) -> ur (2): the current that realises the reference's accelerations at its gap
    (the feedback transformation at x1 = r_v, v = (r_h'', r_v'')), no disturbance."""
    r = ca.SX.sym("r", 6)
    _, _, u = transformation_expressions(model, r[0], ca.vertcat(r[5], r[2]))
    return ca.Function("feedforward", [r], [u])


class DoMPCController:
    """do-mpc's MPC on our OCP, as an OnlineController for our engine (see the module docstring).

    The state estimate is the one our NMPC uses with its disturbance estimate off: encoder
    positions and the high-gain observer's velocities, the observer driven by the model
    acceleration at the applied current.
    """

    diag_names = ("solver_ok", "ipopt_iterations", "ipopt_wall")

    def __init__(self, model: StageModel, ours: NonlinearMPC, nlpsol_options: dict | None = None) -> None:
        self.name = "do-mpc"
        self.model = model
        self.ours = ours  # for the grid, the weights, the terminal table and node_references
        self.sample_time = ours.sample_time
        grid = ours.grid
        self.intervals = grid.intervals
        self.observer = HighGainObserver(ours.sample_time, DEFAULT_EPSILON)
        self._refs = np.zeros((6, grid.horizon + 1))

        dm = do_mpc.model.Model("discrete", "SX")
        x = dm.set_variable("_x", "x", shape=(4, 1))
        u = dm.set_variable("_u", "u", shape=(2, 1))
        ref = dm.set_variable("_tvp", "ref", shape=(6, 1))
        h = dm.set_variable("_tvp", "h", shape=(1, 1))
        dm.set_rhs("x", rk4_function(model)(x, u, h))
        dm.setup()

        mpc = do_mpc.controller.MPC(dm)
        mpc.settings.n_horizon = grid.horizon
        mpc.settings.t_step = ours.sample_time
        mpc.settings.store_full_solution = False
        mpc.settings.store_lagr_multiplier = False
        mpc.settings.store_solver_stats = ["success", "t_wall_total", "iter_count"]
        mpc.settings.supress_ipopt_output()
        mpc.settings.nlpsol_opts["record_time"] = True  # t_wall_total in the stats (no printing)
        mpc.settings.nlpsol_opts.update(nlpsol_options or {})

        q = ca.DM(ours.weights.state_weight)
        r = ca.DM(ours.weights.input_weight)
        xr = ca.vertcat(ref[0], ref[1], ref[3], ref[4])
        ur = feedforward_function(model)(ref)
        lterm = h * (ca.bilin(q, x - xr, x - xr) + ca.bilin(r, u - ur, u - ur))
        mterm = ca.bilin(ours.terminal_cost.expression(ref[0]), x - xr, x - xr)
        mpc.set_objective(lterm=lterm, mterm=mterm)
        mpc.set_rterm(u=np.zeros(2))

        radius = ours.current_limit * math.cos(math.pi / 8)
        mpc.bounds["lower", "_u", "u"] = -radius * np.ones(2)
        mpc.bounds["upper", "_u", "u"] = radius * np.ones(2)
        lim = math.sqrt(2) * radius
        for label, expr in (("sum", u[0] + u[1]), ("diff", u[0] - u[1])):
            mpc.set_nl_cons(f"octagon_{label}_up", expr, ub=lim)
            mpc.set_nl_cons(f"octagon_{label}_down", -expr, ub=lim)
        mpc.bounds["lower", "_x", "x"] = np.array(
            [DEFAULT_GAP_BOUNDS[0], -np.inf, DEFAULT_POSITION_BOUNDS[0], -np.inf]
        )
        mpc.bounds["upper", "_x", "x"] = np.array(
            [DEFAULT_GAP_BOUNDS[1], np.inf, DEFAULT_POSITION_BOUNDS[1], np.inf]
        )

        template = mpc.get_tvp_template()
        h_nodes = np.append(self.intervals, self.intervals[-1])

        def tvp_fun(_t_now):
            # the whole struct at once, node by node (ref (6), h): 40 us, where the per-entry
            # assignment of do-mpc's examples, template["_tvp", k, "ref"] = ..., costs 1.9 ms
            template.master = ca.DM(np.vstack([self._refs, h_nodes]).ravel(order="F"))
            return template

        mpc.set_tvp_fun(tvp_fun)
        mpc.setup()
        self.mpc = mpc
        self._obs = np.zeros(4)

    def reset(self, y0, r0, u0) -> None:
        y0 = np.asarray(y0, dtype=float).ravel()
        self._obs = np.array([y0[0], 0.0, y0[1], 0.0])
        mpc = self.mpc
        mpc.reset_history()
        mpc.x0 = self._obs.copy()
        mpc.u0 = np.asarray(u0, dtype=float).ravel()
        mpc.set_initial_guess()

    def control(self, k: int, y, reference: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        y = np.asarray(y, dtype=float).ravel()
        x_hat = np.array([y[0], self._obs[1], y[1], self._obs[3]])
        self._refs = self.ours.node_references(k, reference)
        u = self.mpc.make_step(x_hat).ravel()
        stats = self.mpc.solver_stats
        acc = np.asarray(self.model.f(x_hat, u)).ravel()
        o = self.observer  # HighGainObserver.step works on columns (By, Ba are (2, 1))
        v = o.step(self._obs[0:2, None], y[0], acc[1])
        h = o.step(self._obs[2:4, None], y[1], acc[3])
        self._obs = np.concatenate([v.ravel(), h.ravel()])
        diag = np.array(
            [float(stats["success"]), stats.get("iter_count", -1), stats.get("t_wall_total", np.nan)]
        )
        return u, diag


# ------------------------------------------------------------------------------------------
def closed_loop_cost(res: SimulationResult, model: StageModel, weights: NMPCWeights) -> float:
    """sum_k Ts (|x_k - r_k|_Q^2 + |u_k - ur_k|_R^2) on the true state and the commands."""
    ff = feedforward_function(model).map(res.t.size)
    ur = np.asarray(ff(res.reference))
    ex = res.x - res.reference[[0, 1, 3, 4]]
    eu = res.u - ur
    q, r = weights.state_weight, weights.input_weight
    stage = np.einsum("ik,ij,jk->k", ex, q, ex) + np.einsum("ik,ij,jk->k", eu, r, eu)
    return float(res.sample_time * np.sum(stage))


def stats(times) -> dict[str, float]:
    t = np.asarray(times, dtype=float)
    t = t[np.isfinite(t)]
    return {"median": float(np.median(t)), "p99": float(np.percentile(t, 99)), "worst": float(t.max())}


def run(label: str, twin: RigTwin, ctrl, scenario, model, weights) -> tuple[dict, SimulationResult]:
    res = ClosedLoop(twin, ctrl).run(scenario)
    if not res.success:
        raise RuntimeError(f"{label}: closed loop failed: {res.message}")
    s = stats(res.step_times) | {"cost": closed_loop_cost(res, model, weights), "n": int(res.t.size)}
    return s, res


def c_run(ctrl: NonlinearMPC, exe: Path, twin: RigTwin, scenario, workdir: Path) -> dict:
    """Replay the RTI calls of ``scenario`` through the generated C; check against Python."""
    inst = record_instances(ctrl, twin, scenario)
    path = codegen.write_instances(workdir / "instances.bin", inst)
    timing = codegen.run_harness(exe, path, workdir / "outputs.bin", repeat=2)
    got = codegen.read_outputs(workdir / "outputs.bin")
    sub = codegen.RecordedInstances(inst.inputs[::10], inst.nnz_in, inst.nnz_out)
    expected = codegen.evaluate_instances(ctrl.rti_step, sub)
    diff = max(float(np.max(np.abs(a[::10] - b))) for a, b in zip(got, expected, strict=True))
    return {
        "median": timing.median,
        "p99": timing.p99,
        "worst": timing.worst,
        "n": timing.calls,
        "failed_calls": timing.failed_calls,
        "max_abs_diff_vs_python": diff,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=0.3, help="simulated time per run [s]")
    parser.add_argument("--scenarios", nargs="+", default=["large_step", "small_step"])
    parser.add_argument("--no-jit", action="store_true", help="skip our JIT-compiled RTI")
    parser.add_argument("--no-c", action="store_true", help="skip our RTI generated as C")
    parser.add_argument("--json", type=Path, help="write the figures to this file")
    args = parser.parse_args()
    warnings.simplefilter("ignore", FutureWarning)

    model = StageModel()
    twin = RigTwin(model)
    weights = NMPCWeights()
    print(f"machine: {machine()}; casadi {ca.__version__}, do-mpc {do_mpc.__version__}")
    print(f"load average at start: {' '.join(f'{v:.2f}' for v in os.getloadavg())} (2 cores)")
    print("OCP: N = 20 (0.2 ms, then 19 x 5 ms), RK4 per interval, octagon |i| <= 8.3 A, 5 kHz, ideal twin")

    t0 = time.perf_counter()
    rti = NonlinearMPC(model, disturbance_bandwidth=0.0)
    builds = {"ours RTI (VM)": time.perf_counter() - t0}
    controllers: list[tuple[str, object]] = [("ours RTI (VM)", rti)]
    if not args.no_jit and c_compiler() is not None:
        t0 = time.perf_counter()
        controllers.append(("ours RTI (JIT)", NonlinearMPC(model, disturbance_bandwidth=0.0, compile=True)))
        builds["ours RTI (JIT)"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    controllers.append(
        ("ours converged (IPOPT)", NonlinearMPC(model, disturbance_bandwidth=0.0, mode="converged"))
    )
    builds["ours converged (IPOPT)"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    controllers.append((DOMPC_ROWS[0], DoMPCController(model, rti)))
    controllers.append((DOMPC_ROWS[1], DoMPCController(model, rti, OUR_IPOPT_OPTIONS)))
    builds["do-mpc (both)"] = time.perf_counter() - t0
    exe = None
    workdir = Path(tempfile.mkdtemp(prefix="peer_dompc_"))
    if not args.no_c and c_compiler() is not None:
        t0 = time.perf_counter()
        exe = codegen.build_harness(codegen.generate_c(rti, workdir), workdir / "harness")
        builds["ours RTI (C)"] = time.perf_counter() - t0
    print("build: " + ", ".join(f"{k} {v:.1f} s" for k, v in builds.items()))

    results: dict = {"machine": machine(), "seconds": args.seconds, "build_s": builds}
    for name in args.scenarios:
        scenario = dataclasses.replace(paper_scenarios()[name], duration=args.seconds)
        print(
            f"\n{scenario.title}, first {args.seconds:g} s ({round(args.seconds / rti.sample_time)} samples)"
        )
        runs: dict = {}
        sims: dict = {}
        for label, ctrl in controllers:
            s, res = run(label, twin, ctrl, scenario, model, weights)
            if label in DOMPC_ROWS:
                s["ipopt_wall"] = stats(res.diagnostic("ipopt_wall"))
                s["ipopt_iterations_median"] = float(np.median(res.diagnostic("ipopt_iterations")))
                s["solver_failures"] = int(np.sum(res.diagnostic("solver_ok") == 0))
            runs[label], sims[label] = s, res
        if exe is not None:
            c = c_run(rti, exe, twin, scenario, workdir)
            c["cost"] = runs["ours RTI (VM)"]["cost"]  # the same outputs (checked below)
            runs = {"ours RTI (C)": c, **runs}
        # the reference: the faster do-mpc configuration on this scenario (the conservative choice)
        ref_label = min(DOMPC_ROWS, key=lambda lbl: runs[lbl]["median"])
        ref = runs[ref_label]
        peer = sims[DOMPC_ROWS[1]]  # converged as tightly as ours: the cross-check below
        print(f"  reference for the ratios: {ref_label} (the faster do-mpc row here)")
        print(
            f"  {'controller':<28s} {'median':>10s} {'p99':>10s} {'worst':>10s}  {'cost J':>10s}  "
            f"{'J / J_do-mpc':>12s}  {'speed-up median':>15s}  {'p99':>6s}"
        )
        for label, s in runs.items():
            ratio = s["cost"] / ref["cost"]
            speed = ref["median"] / s["median"]
            s["cost_ratio_vs_dompc"] = ratio
            s["speedup_median_vs_dompc"] = speed
            s["speedup_p99_vs_dompc"] = ref["p99"] / s["p99"]
            print(
                f"  {label:<28s} {fmt(s['median']):>10s} {fmt(s['p99']):>10s} {fmt(s['worst']):>10s}  "
                f"{s['cost']:10.5g}  {ratio:12.5f}  {speed:14.1f}x  {s['speedup_p99_vs_dompc']:5.1f}x"
            )
        for label in DOMPC_ROWS:
            w = runs[label]["ipopt_wall"]
            print(
                f"  {label}: IPOPT alone median {fmt(w['median'])}, p99 {fmt(w['p99'])} (the rest of "
                f"make_step is do-mpc's bookkeeping); IPOPT iterations median "
                f"{runs[label]['ipopt_iterations_median']:.0f}, failures {runs[label]['solver_failures']}"
            )
        if exe is not None:
            print(
                f"  ours RTI (C): outputs equal to the VM run's within {c['max_abs_diff_vs_python']:.1e} "
                f"(every tenth call), {c['failed_calls']} failed calls"
            )
        for label in runs:
            if label in (DOMPC_ROWS[1], "ours RTI (C)"):
                continue
            du = float(np.max(np.abs(sims[label].u - peer.u)))
            dx = float(np.max(np.abs(sims[label].x[[0, 2]] - peer.x[[0, 2]])))
            runs[label]["max_abs_du_vs_dompc_A"] = du
            runs[label]["max_abs_dposition_vs_dompc_m"] = dx
            print(
                f"  {label:<28s} vs {DOMPC_ROWS[1]}: max |du| {du:.2e} A, max |d position| {dx * 1e6:.3g} um"
            )
        results[name] = runs
    shutil.rmtree(workdir, ignore_errors=True)
    print(f"\nload average at the end: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=2) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
