"""The ``maglev-oc`` command.

    maglev-oc report [--out DIR] [--only NAME ...] [--jobs N]
                                                     every analysis script, in parallel -> DIR/*.pdf
    maglev-oc model [--params JSON] [--gaps MM ...]  print the equilibrium table
    maglev-oc simulate --controller fl --scenario sinusoid --out run.csv
                                                     closed loop on the rig twin -> log (SPEC 2)
    maglev-oc simulate --stage microstepper --scenario setpoints --out run.csv
                                                     the 3-DOF microstepper -> CSV (t, x, y, gap, currents)
    maglev-oc region [--gaps MM ...] [--sdp] [--samples N] [--json OUT.json]
                                                     certified operating region (Procedure 2)
    maglev-oc region --stage microstepper --setpoint X Y GAP
                                                     the 3-DOF loop's certificate at one set-point [mm]
    maglev-oc diagnose LOG... --json OUT.json [--report OUT.pdf]
                                                     residual -> missing effect -> error before/after
    maglev-oc identify LOG... --json OUT.json [--report OUT.pdf]
                                                     C1..C4 by NLS (equation/output error) and NPFSI

Both ``--json`` outputs hold a stage file under ``stage`` (:mod:`maglev_oc.model.stagefile`); every
``--params`` reads a stage file or such an output as it is.

Errors in what the user hands in (files, values: :class:`~maglev_oc.errors.MaglevError`) and
in reading or writing files are reported in one line on stderr with exit status 2; nothing is
written in that case. Anything else is a bug of maglev_oc: a short "internal error" line and
exit status 1 (``--debug`` shows the traceback). ``region`` exits with 3 when a certificate fails
or a Monte Carlo run leaves the feasible set.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
import time
from pathlib import Path
from typing import NoReturn

import numpy as np

from maglev_oc.errors import InputError, MaglevError, OutputError
from maglev_oc.interrupts import honoured
from maglev_oc.model.hardware import PEAK_CURRENT_LIMIT
from maglev_oc.model.loading import load_model
from maglev_oc.units import M_TO_MM, MM_TO_M

__all__ = [
    "EXIT_INTERNAL",
    "EXIT_INTERRUPTED",
    "EXIT_NOT_CERTIFIED",
    "EXIT_USAGE",
    "build_parser",
    "main",
    "run",
]

EXIT_USAGE = 2
"""Exit status for errors in the user's input or files."""
EXIT_INTERNAL = 1
"""Exit status for anything else: a bug of maglev_oc."""
EXIT_NOT_CERTIFIED = 3
"""Exit status of ``region`` when a certificate fails or a Monte Carlo run leaves the feasible set."""
EXIT_INTERRUPTED = 130
"""Exit status after Ctrl-C (128 + SIGINT, as shells report it)."""

STAGES = ("two_dof", "microstepper")
"""``--stage``: the 2-DOF stage of papers 000-002, or the 3-DOF microstepper of 002 Sec. 8."""
SCENARIOS = {
    "two_dof": ("setpoint_steps", "small_step", "large_step", "sinusoid", "excitation"),
    "microstepper": ("setpoints", "sinusoid", "saturation"),
}
"""``simulate --scenario`` per stage; the first is the default."""
DEFAULT_REGION_GAPS = (15.0, 17.5, 20.0, 22.5, 25.0)
CERTIFY_BOXES = 100_000
"""``region --robust``: box budget per level of the certified robust level (an undecided level
costs ~3 s on one core; certifying the nominal level at 25 mm takes ~25 000, at 22.5 mm ~70 000)."""
CERTIFY_LADDER = (1.0, 0.6, 0.3)
"""``region --robust``: fractions of the nominal level the certificate tries (a short ladder keeps an
undecided set-point to ~10 s)."""
"""``region --gaps`` when not given [mm]."""


# ----------------------------------------------------------------------------------------------
def cmd_report(args: argparse.Namespace) -> int:
    from maglev_oc.reporting.runner import analysis_modules, run_reports

    modules = analysis_modules()
    names = args.only or list(modules)
    unknown = [n for n in names if n not in modules]
    if unknown:
        raise InputError(f"unknown analysis {unknown}; available: {', '.join(modules)}")
    if args.params is not None:
        load_model(args.params)  # a bad file is refused before any analysis starts
    if args.jobs is not None and args.jobs < 1:
        raise InputError(f"--jobs must be at least 1, got {args.jobs}")
    t0 = time.perf_counter()

    def done(run) -> None:
        if run.success:
            print(f"  {run.name:<22s} -> {run.path}  ({run.seconds:.1f} s)", flush=True)
        else:
            print(f"  {run.name:<22s} FAILED: {run.error}", file=sys.stderr, flush=True)

    runs = run_reports(names, args.out, params=args.params, jobs=args.jobs, done=done)
    failed = [r.name for r in runs if not r.success]
    print(f"{len(runs) - len(failed)} report(s) in {time.perf_counter() - t0:.1f} s")
    if failed:
        print(f"{len(failed)} report(s) failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


QP_ITERATION_BUDGET = 20
"""Default iteration budget of the exported NMPC's QP solver when it is qrqp (``--qp-solver qrqp``;
the dual active-set solver's default is :data:`maglev_oc.control.export.DUAL_QP_BUDGET`). The
papers' large step, the hardest of their scenarios for the NMPC, needs at most 7 iterations on its
constrained samples; when the budget runs out the step applies the saturated Riccati step (status
"fallback"), so the work of one step is bounded by construction (bench/export_step.py)."""


def cmd_export(args: argparse.Namespace) -> int:
    from maglev_oc.control.export import export_controller

    if args.qp_iterations is not None and not 1 <= args.qp_iterations <= 1000:
        raise InputError(f"--qp-iterations must be in [1, 1000], got {args.qp_iterations}")
    model = load_model(args.params)
    options = {}
    if args.controller == "nmpc":
        # the NMPC's real-time iteration as preparation and feedback; its QP solver the dual
        # active-set method in C (default) or qrqp, generated by CasADi into the file
        from maglev_oc.control.nmpc import NonlinearMPC
        from maglev_oc.model.stagefile import StageFile, holds_stage_file
        from maglev_oc.sim.compiled_nmpc import CompiledNMPC

        # a stage file's effects go into the prediction model, as in simulate
        stage = StageFile.read(args.params) if args.params and holds_stage_file(args.params) else None
        effects = stage.plant_effects() if stage is not None else None
        if args.qp_solver == "qrqp":
            budget = {"max_iter": args.qp_iterations or QP_ITERATION_BUDGET}  # a failure falls back
            nmpc = NonlinearMPC(model, preview=False, qp_solver="qrqp", qp_options=budget, effects=effects)
        else:
            nmpc = NonlinearMPC(model, preview=False, effects=effects)
            options["qp_iterations"] = args.qp_iterations
        ctrl = CompiledNMPC(nmpc, backend="vm")
        options["qp_solver"] = args.qp_solver or "dual"
    else:  # the FL regulator compensates the effects of a stage file given with --params
        if args.qp_iterations is not None or args.qp_solver is not None:
            raise InputError("--qp-iterations and --qp-solver apply to the NMPC only")
        ctrl = _controller_with_effects(args.controller, model, args.params)
    e = export_controller(ctrl, args.out, prefix=args.prefix, **options)
    print(
        f"{e.name}: {e.directory} ({', '.join(p.name for p in e.sources)}); "
        f"{' / '.join(f'{e.prefix}_{f}' for f in e.entry_points)}, {e.memory_bytes} bytes of memory, "
        f"{e.sample_time * 1e6:g} us sample time"
    )
    return 0


def cmd_model(args: argparse.Namespace) -> int:
    from maglev_oc.model.summary import TABLE_GAPS, equilibrium_table_rows, summarize_model

    model = load_model(args.params, args.constants)
    gaps = TABLE_GAPS if not args.gaps else np.asarray(args.gaps, dtype=float) * MM_TO_M
    if np.any(gaps <= 0):
        raise InputError(f"--gaps must be positive millimetres, got {args.gaps}")
    s = summarize_model(model, table_gaps=gaps)
    print(
        f"constants: C1={model.constants.C1:g} C2={model.constants.C2:g} "
        f"C3={model.constants.C3:g} C4={model.constants.C4:g}  ({model.constants.source})"
    )
    print(f"{'gap [mm]':>9s} {'i_d [A]':>9s}  {'amplifier':<18s} {'vertical pole [1/s]':>20s}")
    for gap_mm, current, status, pole in equilibrium_table_rows(s):
        print(f"{gap_mm:9.2f} {current:9.3f}  {status:<18s} {pole:20.2f}")
    if s.zero_current_gap is not None:
        print(f"zero-current gap: {s.zero_current_gap * M_TO_MM:.3f} mm")
    return 0


def _refuse(stage: str, options: dict[str, bool]) -> None:
    """One line naming every given option that does not apply to ``stage``."""
    given = [name for name, is_given in options.items() if is_given]
    if given:
        other = "two_dof" if stage == "microstepper" else "microstepper"
        raise InputError(
            f"{', '.join(given)} {'does' if len(given) == 1 else 'do'} not apply to --stage {stage} "
            f"(only to --stage {other})"
        )


def cmd_simulate(args: argparse.Namespace) -> int:
    if args.duration is not None and not args.duration > 0:
        raise InputError(f"--duration must be positive [s], got {args.duration}")
    if not args.rate > 0:
        raise InputError(f"--rate must be positive [Hz], got {args.rate}")
    scenarios = SCENARIOS[args.stage]
    if args.scenario is not None and args.scenario not in scenarios:
        raise InputError(
            f"--scenario {args.scenario} is not a scenario of --stage {args.stage}; "
            f"choose from {', '.join(scenarios)}"
        )
    if args.stage == "microstepper":
        _refuse(
            "microstepper",
            {
                f"--controller {args.controller}": args.controller not in (None, "fl"),
                "--twin-constants": args.twin_constants is not None,
                "--twin-params": args.twin_params is not None,
            },
        )
        if Path(args.out).suffix.lower() == ".mat":
            raise InputError(f"{args.out}: the microstepper's run is written as CSV only (give a .csv name)")
        return _simulate_microstepper(args)
    _refuse("two_dof", {"--no-anti-windup": args.no_anti_windup})
    return _simulate_two_dof(args)


def _simulate_two_dof(args: argparse.Namespace) -> int:
    from maglev_oc.data.logs import write_log
    from maglev_oc.sim.effects import TwinEffects
    from maglev_oc.sim.engine import ClosedLoop
    from maglev_oc.sim.metrics import evaluate
    from maglev_oc.sim.recording import result_to_log
    from maglev_oc.sim.scenarios import excitation_scenario, paper_scenarios
    from maglev_oc.sim.twin import RigTwin

    model = load_model(args.params)
    # the plant's stage is --twin-params, else the controller's (--params); its constants
    # --twin-constants, else that file's
    plant = (
        load_model(args.twin_params or args.params, args.twin_constants)
        if (args.twin_params or args.twin_constants)
        else model
    )
    name = args.scenario or SCENARIOS["two_dof"][0]
    if name == "excitation":
        scenario = excitation_scenario(60.0 if args.duration is None else args.duration, seed=args.seed)
    else:
        scenario = paper_scenarios()[name]
        if args.duration is not None:
            # a run that ends before the scenario's tracking window is scored from its start
            start = scenario.evaluate_from if args.duration > scenario.evaluate_from else 0.0
            scenario = dataclasses.replace(scenario, duration=args.duration, evaluate_from=start)
    effects = TwinEffects.rig() if args.twin == "rig" else TwinEffects.ideal()
    controller = _controller_with_effects(args.controller or "fl", model, args.params)
    result = ClosedLoop(RigTwin(plant, effects), controller).run(scenario, seed=args.seed)
    metrics = evaluate(result, scenario)
    log = result_to_log(result, rate_hz=args.rate, describe_twin=args.describe_twin)
    write_log(args.out, log)
    mean = [f"{M_TO_MM * e:.3f}" for e in metrics.mean_error]
    print(
        f"{controller.name} on {scenario.name} ({args.twin} twin): "
        f"{'ok' if result.success else 'FAILED: ' + result.message}"
    )
    print(
        f"  mean |error| (vertical, horizontal) = {mean[0]}, {mean[1]} mm; "
        f"peak current {metrics.peak_current:.2f} A; simulated in {result.timings['total']:.2f} s"
    )
    print(f"  wrote {args.out} ({log.n} samples at {1 / log.sample_time:g} Hz)")
    return 0 if result.success else 1


def _controller_with_effects(name: str, model, params_path):
    """The controller; with a stage file given with ``--params`` the FL regulator compensates its
    state-dependent effects and the NMPC predicts with all of them (the other controllers use its
    geometry and constants only)."""
    from maglev_oc.control.fl_regulator import FeedbackLinearizingRegulator
    from maglev_oc.control.registry import build_controller, nmpc_controller
    from maglev_oc.model.stagefile import StageFile, holds_stage_file

    stage = StageFile.read(params_path) if params_path and holds_stage_file(params_path) else None
    if stage is None or not stage.effects:
        return build_controller(name, model)
    if name == "nmpc":
        print(f"  NMPC predicting with {', '.join(e.name for e in stage.effects)} from {params_path}")
        return nmpc_controller(
            model, effects=stage.plant_effects(), name="NMPC, stage-file effects in the model"
        )
    if name != "fl" or stage.compensation() is None:
        print(f"  not compensated by {name}: {', '.join(e.name for e in stage.effects)} (from {params_path})")
        return build_controller(name, model)
    rest = [e.name for e in stage.effects if not e.compensable]
    print(
        f"  FL regulator compensating {', '.join(e.name for e in stage.effects if e.compensable)}"
        + (f" (not {', '.join(rest)}: they depend on the currents)" if rest else "")
        + f" from {params_path}"
    )
    return FeedbackLinearizingRegulator(
        model, compensation=stage.compensation(), name="FL regulator, stage-file effects compensated"
    )


def _simulate_microstepper(args: argparse.Namespace) -> int:
    from maglev_oc.control.microstepper import MicrostepperRegulator
    from maglev_oc.fileio import write_text_atomic
    from maglev_oc.model.platform import microstepper
    from maglev_oc.numerics import c_compiler
    from maglev_oc.sim.microstepper import MicrostepperLoop, evaluate_microstepper
    from maglev_oc.sim.microstepper_scenarios import microstepper_scenarios
    from maglev_oc.sim.microstepper_twin import MicrostepperEffects, MicrostepperTwin
    from maglev_oc.sim.recording import MICROSTEPPER_COLUMNS, microstepper_csv

    model = load_model(args.params)
    platform = microstepper(model.params, model.constants)
    scenario = microstepper_scenarios()[args.scenario or SCENARIOS["microstepper"][0]]
    if args.duration is not None:
        # a run shorter than the scenario's tracking window is scored from its start
        start = scenario.evaluate_from if args.duration > scenario.evaluate_from else 0.0
        scenario = scenario.shortened(args.duration, evaluate_from=start)
    effects = MicrostepperEffects.rig() if args.twin == "rig" else MicrostepperEffects.ideal()
    controller = MicrostepperRegulator(platform, anti_windup=not args.no_anti_windup)
    twin = MicrostepperTwin(platform, effects)
    loop = MicrostepperLoop(twin, controller, backend="c" if c_compiler() is not None else "vm")
    result = loop.run(scenario, seed=args.seed)
    metrics = evaluate_microstepper(result, scenario)
    text, n, rate = microstepper_csv(result, args.rate, describe_twin=args.describe_twin)
    write_text_atomic(args.out, text)

    def per_axis(values, scale: float = 1.0, digits: int = 2) -> str:
        return ", ".join("-" if not math.isfinite(v) else f"{v * scale:.{digits}f}" for v in values)

    print(
        f"{controller.name} on {scenario.name} ({args.twin} twin): "
        f"{'ok' if result.success else 'FAILED: ' + result.message}"
    )
    if metrics.steps:
        print(
            f"  settling, slowest step (x, y, gap): to 0.1 mm {per_axis(metrics.worst_settling('01mm'))} s; "
            f"to 10 um {per_axis(metrics.worst_settling('10um'))} s; overshoot "
            f"{per_axis(metrics.max_overshoot(), digits=0)} %"
        )
    print(
        f"  mean |error| (x, y, gap) = {per_axis(metrics.mean_error, M_TO_MM, 3)} mm from "
        f"{scenario.evaluate_from:g} s; peak pair current {metrics.peak_current:.2f} A "
        f"({metrics.saturated} samples over the limit); simulated in {result.timings['total']:.2f} s"
    )
    print(f"  wrote {args.out} ({n} samples at {rate:g} Hz; columns {', '.join(MICROSTEPPER_COLUMNS)})")
    return 0 if result.success else 1


def cmd_region(args: argparse.Namespace) -> int:
    if args.current_limit is not None and not (0 < args.current_limit < 100):
        raise InputError(f"--current-limit must be in (0, 100) A, got {args.current_limit}")
    if args.current_limit is not None and args.no_current_limit:
        raise InputError("--current-limit and --no-current-limit contradict each other: give one")
    limit = None if args.no_current_limit else (args.current_limit or PEAK_CURRENT_LIMIT)
    if args.stage == "microstepper":
        _refuse(
            "microstepper",
            {
                "--gaps": args.gaps is not None,
                "--position": args.position is not None,
                "--sinusoid": args.sinusoid,
                "--sdp": args.sdp,
                "--samples": args.samples is not None,
                "--robust": args.robust,
                "--without-effects": args.without_effects,
            },
        )
        return _region_microstepper(args, limit)
    _refuse("two_dof", {"--setpoint": args.setpoint is not None})
    if args.robust:
        return _region_robust(args, limit)
    only_robust = {
        "--confidence": args.confidence is not None,
        "--box": args.box is not None,
        "--scheduler": args.scheduler is not None,
        "--workers": args.workers is not None,
        "--seed": args.seed is not None,
        "--certify-boxes": args.certify_boxes is not None,
    }
    given = [name for name, is_given in only_robust.items() if is_given]
    if given:
        raise InputError(f"{', '.join(given)} only apply with --robust")
    return _region_two_dof(args, limit)


def _region_gaps(args: argparse.Namespace) -> list[float]:
    """The set-point gaps [mm] of ``region`` (--gaps, else the default ones), checked."""
    gaps = [float(g) for g in (DEFAULT_REGION_GAPS if args.gaps is None else args.gaps)]
    bad = [g for g in gaps if not (5.0 <= g <= 40.0)]
    if bad:
        raise InputError(f"--gaps are millimetres in [5, 40], got {bad}")
    return gaps


def _region_two_dof(args: argparse.Namespace, limit: float | None) -> int:
    import json

    from maglev_oc.fileio import write_text_atomic
    from maglev_oc.region.closed_loop import Reference, RegulatorLoop
    from maglev_oc.region.feasibility import FeasibleSet
    from maglev_oc.region.procedure2 import Procedure2

    model = load_model(args.params)
    gaps = _region_gaps(args)
    samples = 0 if args.samples is None else args.samples
    if samples < 0:
        raise InputError(f"--samples must be >= 0, got {samples}")
    position = 0.0 if args.position is None else args.position
    effects = _region_effects(args)
    if effects.compensation is not None and args.sdp:
        raise InputError(
            "--sdp: the SDP enlargement is for the loop without compensated effects; add "
            "--without-effects, or leave --sdp out to certify the compensated loop"
        )
    feasible = FeasibleSet(
        model,
        current_limit=limit,
        compensation=effects.compensation,
        compensated=effects.compensated,
        **({"gap_range": None} if args.no_stoppers else {}),
    )
    proc = Procedure2(feasible, RegulatorLoop())
    for g in gaps:
        feasible.check_setpoint(g * MM_TO_M, position * MM_TO_M)
    refs = [Reference.setpoint(g * MM_TO_M, position * MM_TO_M) for g in gaps]
    if args.sinusoid:
        refs.append(Reference.paper_sinusoid())
    print(f"feasible set: {feasible.label}; gains: printed K_h, K_v (001/002)")
    for line in effects.notes:
        print(f"  {line}")
    print(
        f"{'reference':>10s} {'P':>9s} {'level':>10s} {'c/upper':>8s} {'binding':>13s} "
        f"{'e1 [mm]':>8s} {'e1dot [mm/s]':>12s} {'e2 [mm]':>8s} {'e2dot [mm/s]':>12s} {'runs/viol.':>11s}"
    )
    check = _region_checker(model, proc.loop, samples, limit, effects.compensation)
    records = []
    for ref in refs:
        for label, cert in _certificates(proc, ref, sdp=args.sdp):
            runs, viol = check(ref, cert) if cert.success else (0, 0)
            _print_certificate(ref, label, cert, runs, viol)
            records.append(
                {
                    "reference": ref.label,
                    "P": label,
                    "certified": bool(cert.success),
                    "level": cert.level,
                    "level_upper": cert.level_upper,
                    "binding": cert.binding,
                    "semi_axes_SI": cert.initial_conditions.semi_axes,
                    "rectangle_m": list(cert.initial_conditions.rectangle),
                    "P_matrix": cert.P.tolist(),
                    "monte_carlo": {"runs": runs, "violations": viol},
                }
            )
    if args.json:
        doc = {
            "feasible_set": feasible.label,
            "effects_compensated": list(effects.compensated),
            "effects_not_covered": list(effects.not_covered),
            "semi_axes": "largest deviation of e1 [m], e1_rate [m/s], e2 [m], e2_rate [m/s] alone, at rest",
            "certificates": records,
        }
        write_text_atomic(args.json, json.dumps(doc, indent=2) + "\n")
        print(f"wrote {args.json}")
    ok = all(r["certified"] and r["monte_carlo"]["violations"] == 0 for r in records)
    return 0 if ok else EXIT_NOT_CERTIFIED


@dataclasses.dataclass(frozen=True)
class _RegionEffects:
    """A stage file's effects as the region analysis uses them."""

    compensation: object = None  # casadi.Function x (4) -> (x2', x4'), or None
    compensated: tuple[str, ...] = ()
    not_covered: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()


def _region_effects(args: argparse.Namespace) -> _RegionEffects:
    """The --params stage file's state-dependent effects, compensated by the FL regulator as in
    ``simulate --params`` and so part of the feasible set; none with --without-effects."""
    from maglev_oc.model.stagefile import StageFile, holds_stage_file

    if args.params is None or not holds_stage_file(args.params):
        return _RegionEffects()
    stage = StageFile.read(args.params)
    if not stage.effects:
        return _RegionEffects()
    names = ", ".join(e.name for e in stage.effects)
    if args.without_effects:
        return _RegionEffects(notes=(f"not included (--without-effects): {names} from {args.params}",))
    compensated = tuple(e.name for e in stage.effects if e.compensable)
    rest = tuple(e.name for e in stage.effects if not e.compensable)
    notes = []
    if compensated:
        notes.append(
            f"compensated by the FL regulator, so part of the feasible set: {', '.join(compensated)} "
            f"(from {args.params}); the certificate assumes the plant has them as identified"
        )
    if rest:
        notes.append(
            f"NOT covered by the certificate: {', '.join(rest)} (they depend on the currents, "
            "so the regulator cannot cancel them; the Monte Carlo runs leave them out too)"
        )
    return _RegionEffects(stage.compensation(), compensated, rest, tuple(notes))


def _robust_plants(args: argparse.Namespace, model):
    """The plant set of ``region --robust``: --box, else the confidence ellipsoid of the
    --params stage file's covariance (or of the assumed one) at --confidence (default 0.95)."""
    from maglev_oc.region.robust import ASSUMED_RELATIVE_STDERR, assumed_covariance
    from maglev_oc.region.sweep import CONSTANT_NAMES, PlantSet

    if args.box is not None and args.confidence is not None:
        raise InputError("--box and --confidence contradict each other: give one")
    nominal = np.asarray(model.constants.as_array(), dtype=float)
    if args.box is not None:
        lower, upper = nominal.copy(), nominal.copy()
        for item in args.box.split(","):
            name, sep, rng = item.strip().partition("=")
            lo_s, sep2, hi_s = rng.partition(":")
            if not sep or not sep2 or name not in CONSTANT_NAMES:
                names = ", ".join(CONSTANT_NAMES)
                raise InputError(f"--box takes C1=LO:HI,... with names among {names}; got {item!r}")
            try:
                lo, hi = float(lo_s), float(hi_s)
            except ValueError:
                raise InputError(f"--box {item!r}: LO and HI must be numbers") from None
            if not (0 < lo <= hi and math.isfinite(hi)):
                raise InputError(f"--box {item!r}: need 0 < LO <= HI")
            k = CONSTANT_NAMES.index(name)
            lower[k], upper[k] = lo, hi
        return PlantSet.box(lower, upper), "box given by --box"
    level = 0.95 if args.confidence is None else args.confidence
    if not (0 < level < 1):
        raise InputError(f"--confidence must be in (0, 1), got {level}")
    cov, source = None, ""
    if args.params is not None:
        from maglev_oc.model.stagefile import StageFile, holds_stage_file

        if holds_stage_file(args.params):
            cov = StageFile.read(args.params).covariance
            source = f"covariance of {args.params}"
    if cov is None:
        rel = "/".join(f"{100 * r:g}" for r in ASSUMED_RELATIVE_STDERR)
        cov = assumed_covariance(model.constants)
        source = f"no covariance given: ASSUMED standard errors {rel} % of C1..C4"
    return PlantSet.confidence(nominal, cov, level), source


def _region_robust(args: argparse.Namespace, limit: float | None) -> int:
    """``region --robust``: the nominal certificates on sampled plants (empirical, not certified)."""
    import json

    from maglev_oc.fileio import write_text_atomic
    from maglev_oc.region.closed_loop import Reference, RegulatorLoop
    from maglev_oc.region.feasibility import FeasibleSet
    from maglev_oc.region.procedure2 import Procedure2
    from maglev_oc.region.robust import empirical_robust_level
    from maglev_oc.region.robust_certificate import RobustCertifier, certificate_words, robust_lyapunov_matrix
    from maglev_oc.region.sweep import PlantSet, SweepSpec, dask_client, run_sweep

    _refuse("two_dof", {"--sinusoid": args.sinusoid, "--sdp": args.sdp})  # not in the robust sweep yet
    model = load_model(args.params)
    plants, source = _robust_plants(args, model)
    gaps = _region_gaps(args)
    runs = 2000 if args.samples is None else args.samples
    if runs < 1:
        raise InputError(f"--samples must be >= 1 with --robust, got {runs}")
    workers = 1 if args.workers is None else args.workers
    if workers < 1:
        raise InputError(f"--workers must be >= 1, got {workers}")
    seed = 0 if args.seed is None else args.seed
    if seed < 0:
        raise InputError(f"--seed must be >= 0, got {seed}")
    boxes = CERTIFY_BOXES if args.certify_boxes is None else args.certify_boxes
    if boxes < 1000:
        raise InputError(f"--certify-boxes must be >= 1000, got {boxes}")
    position = (0.0 if args.position is None else args.position) * MM_TO_M
    feasible = FeasibleSet(model, current_limit=limit, **({"gap_range": None} if args.no_stoppers else {}))
    proc = Procedure2(feasible, RegulatorLoop())
    certifier = RobustCertifier(feasible, proc.loop, max_boxes=boxes, ladder=CERTIFY_LADDER)
    for g in gaps:
        feasible.check_setpoint(g * MM_TO_M, position)
    print(f"plants: {plants.label} ({source}); controller: FL regulator with the nominal constants")
    effects = _region_effects(args)
    if effects.compensation is not None or effects.not_covered:
        names = ", ".join((*effects.compensated, *effects.not_covered))
        print(f"  the stage file's effects ({names}) are not part of --robust: its constants only")
    print(
        "empirical (sampled, not certified): runs start uniformly in the nominal certified set "
        "{z~' P z~ <= c}, P of the Lyapunov equation"
    )
    ladder = "/".join(f"{f:g}" for f in CERTIFY_LADDER)
    print(
        f"certified: a level set of V invariant for every plant of the set, P of the robust SDP; "
        f"levels {ladder} of the nominal one, {boxes} boxes each"
    )
    print(
        f"{'set-point':>9s} {'level c':>9s} {'nominal viol.':>14s} {'robust viol.':>13s} "
        f"{'feasible':>9s} {'empirical c_rob/c':>18s} {'certified c_rob/c':>18s}  certificate"
    )
    records, ok = [], True
    with dask_client(args.scheduler, workers) as client:
        for g in gaps:
            ref = Reference.setpoint(g * MM_TO_M, position)
            cert = proc.run(ref)
            if not cert.success:
                ok = False
                print(f"{g:7.4g} mm  not certified nominally: {cert.message}")
                continue
            spec = SweepSpec(
                PlantSet.point(model.constants),
                ref,
                constants=tuple(model.constants.as_array()),
                params=model.params,
                P=tuple(map(tuple, cert.P)),
                level=cert.level,
                current_limit=limit,
            )
            nominal = run_sweep(spec, runs, seed=seed, client=client)
            robust = run_sweep(spec.with_plants(plants), runs, seed=seed, client=client)
            shrunk = empirical_robust_level(f"{g:g} mm", spec, plants, runs=runs, seed=seed, client=client)
            ok &= nominal.success and shrunk.check.success
            ratio = f"{shrunk.ratio:.3f}" if shrunk.check.success else "not found"
            P_rob, sdp_message = robust_lyapunov_matrix(certifier, cert, plants)
            robust_cert = None if P_rob is None else certifier.run(proc.run(ref, P_rob), plants)
            if robust_cert is None:
                words, share = f"failed: robust SDP: {sdp_message}", "-"
            else:
                words, share = certificate_words(robust_cert), f"{robust_cert.ratio:.2f}"
            print(
                f"{g:6.4g} mm {cert.level:9.4g} {f'{nominal.violations}/{runs}':>14s} "
                f"{f'{robust.violations}/{runs}':>13s} {robust.share_feasible:9.2%} {ratio:>18s} "
                f"{share:>18s}  {words}",
                flush=True,
            )
            records.append(
                {
                    "setpoint_mm": [g, position * M_TO_MM],
                    "level": cert.level,
                    "runs": runs,
                    "nominal_violations": nominal.violations,
                    "robust_violations": robust.violations,
                    "robust_share_feasible": robust.share_feasible,
                    "empirical_robust_level": shrunk.level if shrunk.check.success else None,
                    "empirical_robust_ratio": shrunk.ratio if shrunk.check.success else None,
                    "certified": _certified_record(robust_cert, words, sdp_message),
                }
            )
    if args.json:
        doc = {
            "plants": plants.label,
            "plants_source": source,
            "seed": seed,
            "note": "Monte Carlo over sampled plants and starts: empirical, not a certificate",
            "certified_note": (
                "certified: a level set of V = z~' P z~ (P of the robust SDP) invariant in F for every "
                "plant of the set (continuous-time FL loop, constant C); level and nominal_level in V units"
            ),
            "certify_boxes": boxes,
            "certify_ladder": list(CERTIFY_LADDER),
            "setpoints": records,
        }
        write_text_atomic(args.json, json.dumps(doc, indent=2) + "\n")
        print(f"wrote {args.json}")
    return 0 if ok else EXIT_NOT_CERTIFIED


def _certified_record(certificate, words: str, sdp_message: str) -> dict:
    """The ``certified`` entry of a set-point in ``region --robust --json``."""
    if certificate is None:
        return {"status": "failed", "words": words, "level": None, "nominal_level": None, "ratio": None}
    plant = certificate.witness_plant
    return {
        "status": certificate.status,
        "words": words,
        "level": certificate.level,
        "nominal_level": certificate.nominal_level,
        "ratio": certificate.ratio,
        "refuted_at_level": None if plant is None else certificate.level_upper,
        "refuting_plant": None if plant is None else [float(c) for c in plant],
        "robust_sdp": sdp_message,
    }


def _region_microstepper(args: argparse.Namespace, limit: float | None) -> int:
    import json

    from maglev_oc.fileio import write_text_atomic
    from maglev_oc.model.hardware import MICROSTEPPER_STOPPER_GAP, STOPPER_POSITION
    from maglev_oc.model.platform import microstepper
    from maglev_oc.region.microstepper import PHYSICAL_GAP, MicrostepperRegion

    if args.setpoint is None:
        raise InputError("--stage microstepper needs --setpoint X Y GAP (millimetres)")
    x, y, gap = (float(v) for v in args.setpoint)
    if not (5.0 <= gap <= 40.0) or max(abs(x), abs(y)) > 100.0:
        raise InputError(
            f"--setpoint X Y GAP are millimetres, |X|, |Y| <= 100 and GAP in [5, 40]; got {x, y, gap}"
        )
    model = load_model(args.params)
    region = MicrostepperRegion(
        microstepper(model.params, model.constants), current_limit=limit, stoppers=not args.no_stoppers
    )
    parts = ["R >= 0"]
    if limit is not None:
        parts.append(f"pair currents <= {limit:g} A")
    if not args.no_stoppers:
        parts.append(
            f"x and y within +-{STOPPER_POSITION[1] * M_TO_MM:g} mm, gap in "
            f"[{MICROSTEPPER_STOPPER_GAP[0] * M_TO_MM:g}, {MICROSTEPPER_STOPPER_GAP[1] * M_TO_MM:g}] mm"
        )
    else:
        parts.append(f"gap >= {PHYSICAL_GAP * M_TO_MM:g} mm (the field model's domain)")
    constraints = "; ".join(parts)
    res = region.largest_level(np.array([x, y, gap]) * MM_TO_M)
    widths = {a: w * M_TO_MM for a, w in res.half_widths.items()}
    bracket = res.refuted_level / res.level - 1 if res.level > 0 else math.inf
    print(
        f"3-DOF microstepper, FL loop with the printed K_h (x, y) and K_v (gap); constraints: {constraints}"
    )
    print(f"set-point (x, y, gap) = ({x:g}, {y:g}, {gap:g}) mm: {res.status}")
    print(
        f"  level {res.level:.4g} certified; a constraint fails at {res.refuted_level:.4g} "
        f"(bracket {bracket:.1%})"
    )
    print(f"  binding: {res.binding}")
    print("  half-widths: " + ", ".join(f"{a} {w:.3f} mm" for a, w in widths.items()))
    print(f"  {res.boxes} boxes, {res.timings.get('total', math.nan):.1f} s; {res.message}")
    if args.json:
        doc = {
            "stage": "microstepper",
            "setpoint_mm": [x, y, gap],
            "constraints": constraints,
            "certified": bool(res.success),
            "status": res.status,
            "message": res.message,
            "level": res.level,
            "refuted_level": res.refuted_level,
            "binding": res.binding,
            "half_widths_mm": widths,
            "half_widths": "largest error of each axis inside {V <= level}, the other states free",
            "boxes": res.boxes,
        }
        write_text_atomic(args.json, json.dumps(doc, indent=2) + "\n")
        print(f"wrote {args.json}")
    return 0 if res.success else EXIT_NOT_CERTIFIED


def _certificates(proc, ref, *, sdp: bool) -> list[tuple[str, object]]:
    """("Lyapunov", Procedure 2's certificate) and, with ``sdp``, ("SDP", the enlarged one)."""
    certs = [("Lyapunov", proc.run(ref))]
    if sdp:
        from maglev_oc.region.sdp import enlarge

        result = enlarge(proc, ref)
        if result.certified is not None:
            certs.append(("SDP", result.certified))
    return certs


def _region_checker(model, loop, samples: int, limit, compensation=None):
    """(ref, cert) -> (runs, violations) of a Monte Carlo check inside the certified ellipsoid
    on the twin (no runs when ``samples`` is 0); with a ``compensation``, the twin has that
    effect and the FL regulator compensates it (the certificate's premise)."""
    if not samples:
        return lambda ref, cert: (0, 0)
    from maglev_oc.region.montecarlo import check_error_states, fl_batch_simulator, uniform_in_ellipsoid

    sim = fl_batch_simulator(model, compensation=compensation, duration=1.0)

    def check(ref, cert) -> tuple[int, int]:
        z = uniform_in_ellipsoid(cert.P, cert.level, samples, np.random.default_rng(0))
        chk = check_error_states(sim, loop, ref, cert.P, cert.level, z, current_limit=limit)
        return chk.n, chk.violations

    return check


def _print_certificate(ref, label: str, cert, runs: int, viol: int) -> None:
    s = cert.initial_conditions.semi_axes
    name = f"{ref.gap * M_TO_MM:g} mm" if ref.is_setpoint else "sinusoid"
    print(
        f"{name:>10s} {label:>9s} {cert.level:10.4g} {cert.tightness:8.3f} {cert.binding:>13s} "
        f"{s['e1'] * M_TO_MM:8.2f} {s['e1_rate'] * M_TO_MM:12.0f} {s['e2'] * M_TO_MM:8.2f} "
        f"{s['e2_rate'] * M_TO_MM:12.0f} {f'{runs}/{viol}' if runs else '-':>11s}"
    )


def _excited_axes(log, check_excitation) -> list[str]:
    """The axes a log excites; a log locked on one axis (the papers' verification runs) is
    fine, a log that excites neither raises the 'both' error."""
    excited = []
    for axis in ("vertical", "horizontal"):
        try:
            check_excitation(log, axis=axis)
            excited.append(axis)
        except InputError:
            pass
    if not excited:
        check_excitation(log)  # raises, naming what is constant
    return excited


def cmd_diagnose(args: argparse.Namespace) -> int:
    import json

    from maglev_oc.data.logs import check_excitation, read_log
    from maglev_oc.diagnosis.pipeline import diagnose
    from maglev_oc.diagnosis.selection import SIDE_WORDS
    from maglev_oc.diagnosis.stage_file import diagnosis_stage_file
    from maglev_oc.fileio import write_text_atomic
    from maglev_oc.model.stagefile import StageFile

    model = load_model(args.params)
    logs = []
    for path in args.logs:
        if not Path(path).is_file():
            raise InputError(f"{path}: no such file")
        log = read_log(path, params=model.params).currents_advanced(args.currents_late)
        _excited_axes(log, check_excitation)
        logs.append(log)
    diag = diagnose(logs, model, holdout_fraction=args.holdout, limits=not args.no_limits)
    doc = diag.to_dict()
    geometry = StageFile.geometry_provenance(args.params)
    doc["stage"] = diagnosis_stage_file(diag, model, geometry).to_dict()
    write_text_atomic(args.json, json.dumps(doc, indent=2) + "\n")
    print(diag.message)
    for w in diag.warnings:
        print(f"  WARNING: {w}")
    if diag.moving_mass is not None:
        print(f"  moving mass: {diag.moving_mass.says()}")
    for w in diag.payloads:
        print(f"  payload: {w}")
    for r in diag.left_out:
        print(f"  left out: {r.describe()}")
    for a, before in diag.error_before.items():
        if math.isfinite(before):
            print(f"  held-out error {a}: {before:.4g} -> {diag.error_after[a]:.4g} m/s^2")
    for e in diag.effects:
        seen = "" if e.judged_on == "accelerations" else f", seen predicting {SIDE_WORDS[e.judged_on]}"
        print(f"  {e.name} [{e.axis}, confidence {e.confidence:.2f}{seen}]: {e.finding}")
    for n in diag.not_separable:
        print(f"  not separable: {n.name} (confounded with {', '.join(n.confounded_with)}): {n.experiment}")
    for u in diag.unexplained:
        print(f"  unexplained: {u.description}")
    seen = [d for d in diag.detection_limits if math.isfinite(d.value)]
    if seen:
        from maglev_oc.diagnosis.words import plain
        from maglev_oc.reporting.diagnosis_report import LIMITS_IN_WORDS, limit_size

        words = ", ".join(f"{plain(d.name)} below {limit_size(d)}" for d in seen[:LIMITS_IN_WORDS])
        print(f"  this log could not have shown: {words} (all in the JSON's detection_limits)")
    for d in diag.detection_limits:
        if d.not_in_log:
            print(f"  {d.name.replace('_', ' ')}: {d.reason}")
    print(f"  wrote {args.json} ({diag.timings['total']:.1f} s)")
    if args.report:
        from maglev_oc.diagnosis.feedback import compensation_study
        from maglev_oc.reporting.diagnosis_report import write_diagnosis_report

        study = None if args.no_control else compensation_study(diag, model)
        write_diagnosis_report(args.report, diag, study=study)
        print(f"  wrote {args.report}")
    return 0


def cmd_identify(args: argparse.Namespace) -> int:
    import json

    from maglev_oc.fileio import write_text_atomic
    from maglev_oc.identification.pipeline import identify, load_logs
    from maglev_oc.model.stagefile import StageFile

    model = load_model(args.params)
    held = args.validate or []
    for path in [*args.logs, *held]:
        if not Path(path).is_file():
            raise InputError(f"{path}: no such file")
    both = {Path(p).resolve() for p in args.logs} & {Path(p).resolve() for p in held}
    if both:
        names = ", ".join(sorted(str(p) for p in both))
        raise InputError(f"--validate: {names} is also fitted; a held-out log must not be one of LOG")
    logs = load_logs(args.logs, params=model.params)
    outcome = identify(
        logs,
        model,
        estimate=args.estimate,
        methods=args.methods,
        npfsi_eps=args.eps,
        input_delay=args.input_delay,
        validation_logs=load_logs(held, params=model.params) if held else (),
    )
    print(outcome.report())
    doc = outcome.to_dict()
    geometry = StageFile.geometry_provenance(args.params)
    doc["stage"] = StageFile.from_identification(outcome, model, geometry).to_dict()
    write_text_atomic(args.json, json.dumps(doc, indent=2) + "\n")
    print(f"wrote {args.json}")
    if args.report:
        from maglev_oc.reporting.identification_plots import write_outcome_report

        write_outcome_report(args.report, outcome, logs)
        print(f"wrote {args.report}")
    fits = [f for f in (outcome.equation_error, outcome.output_error) if f is not None]
    return 0 if all(f.success for f in fits) and all(r.success for r in outcome.npfsi) else 1


def cmd_design_experiment(args: argparse.Namespace) -> int:
    from maglev_oc.identification.design import design_experiment, write_design

    if args.out.exists() and not args.out.is_dir():
        raise OutputError(
            f"{args.out}: is a file; --out takes the folder for reference.csv, reference.mat, design.json"
        )
    if not (math.isfinite(args.duration) and 10.0 <= args.duration <= 3600.0):
        raise InputError(f"--duration must be between 10 and 3600 s, got {args.duration:g}")
    design = design_experiment(args.kind, args.duration, model=load_model(args.params), seed=args.seed)
    print(design.report())
    for path in write_design(args.out, design).values():
        print(f"wrote {path}")
    return 0 if design.success else 1


def _version() -> str:
    """maglev-oc's version and the versions of what its numbers depend on."""
    import platform
    from importlib.metadata import version

    import casadi

    return (
        f"maglev-oc {version('maglev_oc')} (CasADi {casadi.__version__}, NumPy {np.__version__}, "
        f"Python {platform.python_version()})"
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="maglev-oc", description=__doc__.splitlines()[0])
    parser.add_argument("--debug", action="store_true", help="show the traceback of an internal error")
    parser.add_argument("--version", action="version", version=_version())
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("report", help="run every analysis script and write its PDF")
    p.add_argument("--out", type=Path, default=Path("reports"), help="output folder")
    p.add_argument("--only", nargs="+", metavar="NAME", help="run only these analyses")
    p.add_argument("--params", type=Path, help="stage/constants JSON (default: papers)")
    p.add_argument(
        "--jobs", type=int, help="analyses run at once, each in its own process (default: the cores)"
    )
    p.set_defaults(func=cmd_report)

    from maglev_oc.control.export import DUAL_QP_BUDGET, QP_SOLVERS
    from maglev_oc.control.registry import CONTROLLERS

    p = sub.add_parser("export", help="write a controller as plain C99 for the rig (no heap, libm only)")
    p.add_argument("controller", help=f"one of {', '.join(CONTROLLERS)}")
    p.add_argument("--out", type=Path, required=True, help="directory to write (replaced whole)")
    p.add_argument("--params", type=Path, help="stage/constants JSON of the controller (default: papers)")
    p.add_argument("--prefix", help="C prefix of the exported symbols (default maglev_<controller>)")
    p.add_argument(
        "--qp-iterations",
        type=int,
        metavar="K",
        help=f"nmpc: iteration budget of the QP solver; when it runs out the step applies the "
        f"saturated Riccati step and says so (default {DUAL_QP_BUDGET} for dual, {QP_ITERATION_BUDGET} "
        "for qrqp)",
    )
    p.add_argument(
        "--qp-solver",
        choices=QP_SOLVERS,
        help="nmpc: the QP solver in the C: dual (default; a dual active-set method on the prepared "
        "Riccati factorization) or qrqp (CasADi's, generated in)",
    )
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("model", help="print the equilibrium table")
    p.add_argument("--params", type=Path, help="stage/constants JSON (default: papers)")
    p.add_argument("--constants", help="a named set of the papers' constants, e.g. table3_eps0.05")
    p.add_argument("--gaps", nargs="+", type=float, metavar="MM", help="gaps in millimetres")
    p.set_defaults(func=cmd_model)

    p = sub.add_parser("simulate", help="closed loop on the rig twin, written as a log")
    p.add_argument(
        "--stage",
        choices=STAGES,
        default="two_dof",
        help="the 2-DOF stage (default) or the 3-DOF microstepper of 002 Sec. 8",
    )
    p.add_argument("--controller", choices=list(CONTROLLERS), help="two_dof: the controller (default fl)")
    p.add_argument(
        "--scenario",
        choices=list(dict.fromkeys(SCENARIOS["two_dof"] + SCENARIOS["microstepper"])),
        help="two_dof: "
        + ", ".join(SCENARIOS["two_dof"])
        + "; microstepper: "
        + ", ".join(SCENARIOS["microstepper"])
        + " (the first is the default)",
    )
    p.add_argument(
        "--no-anti-windup",
        action="store_true",
        help="microstepper: the regulator without back-calculation anti-windup",
    )
    p.add_argument(
        "--twin",
        choices=["ideal", "rig"],
        default="rig",
        help="ideal plant, or every rig effect on (default)",
    )
    p.add_argument("--twin-constants", help="named constant set for the plant (default: the controller's)")
    p.add_argument("--twin-params", type=Path, help="stage/constants JSON for the plant")
    p.add_argument("--params", type=Path, help="stage/constants JSON for the controller's model")
    p.add_argument("--duration", type=float, help="override the scenario's duration [s]")
    p.add_argument("--rate", type=float, default=1000.0, help="logging rate [Hz] (default 1000)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--describe-twin", action="store_true", help="write the twin's effects into the log")
    p.add_argument(
        "--out",
        type=Path,
        required=True,
        help="two_dof: log file (.csv or .mat, SPEC 2); microstepper: a CSV with columns "
        "t, x, y, gap, i_qA, i_dA, i_qB, i_dB (SPEC 2 holds two axes; the header lines say so)",
    )
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("region", help="certified operating region of the FL regulator (adapted Procedure 2)")
    p.add_argument(
        "--stage",
        choices=STAGES,
        default="two_dof",
        help="the 2-DOF stage (default) or the 3-DOF microstepper of 002 Sec. 8",
    )
    p.add_argument(
        "--setpoint",
        nargs=3,
        type=float,
        metavar=("X", "Y", "GAP"),
        help="microstepper: the set-point (x, y, gap) in millimetres",
    )
    p.add_argument(
        "--gaps",
        nargs="+",
        type=float,
        metavar="MM",
        help="two_dof: set-point gaps in millimetres (default 15 17.5 20 22.5 25)",
    )
    p.add_argument(
        "--position", type=float, metavar="MM", help="two_dof: horizontal set-point [mm] (default 0)"
    )
    p.add_argument("--sinusoid", action="store_true", help="two_dof: also the papers' ellipse reference")
    p.add_argument("--sdp", action="store_true", help="two_dof: also enlarge the certified set by SDP")
    p.add_argument("--current-limit", type=float, metavar="A", help="limit on |u| [A] (default 9)")
    p.add_argument("--no-current-limit", action="store_true", help="only R >= 0 (the papers' set A)")
    p.add_argument(
        "--no-stoppers",
        action="store_true",
        help="ignore the gap stoppers (microstepper: and the x, y travel)",
    )
    p.add_argument(
        "--samples", type=int, help="two_dof: Monte Carlo runs inside each certified set (default 0)"
    )
    p.add_argument("--json", type=Path, help="write the certificates (P, levels, sizes) here")
    p.add_argument("--params", type=Path, help="stage/constants JSON (default: papers)")
    p.add_argument(
        "--without-effects",
        action="store_true",
        help="two_dof: a stage file's constants only, its effects neither compensated nor in the set",
    )
    p.add_argument(
        "--robust",
        action="store_true",
        help="two_dof: Monte Carlo of the nominal certificates on sampled plants and an empirical "
        "robust level (--samples runs each, default 2000)",
    )
    p.add_argument(
        "--confidence",
        type=float,
        metavar="P",
        help="--robust: plants in the P confidence ellipsoid of --params' covariance (default 0.95)",
    )
    p.add_argument("--box", metavar="C1=LO:HI,...", help="--robust: plants in this box (others nominal)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="--robust: a Dask scheduler (tcp://host:port)")
    p.add_argument(
        "--workers", type=int, metavar="N", help="--robust: local Dask worker processes (default 1)"
    )
    p.add_argument("--seed", type=int, metavar="S", help="--robust: seed of the samples (default 0)")
    p.add_argument(
        "--certify-boxes",
        type=int,
        metavar="N",
        help=f"--robust: box budget per level of the certified robust level (default {CERTIFY_BOXES})",
    )
    p.set_defaults(func=cmd_region)

    p = sub.add_parser("diagnose", help="find what the model misses in logs and add it (SPEC 3)")
    p.add_argument("logs", nargs="+", type=Path, metavar="LOG", help="logs (.csv or .mat, SPEC 2)")
    p.add_argument("--json", type=Path, required=True, help="result (SPEC 3 contract)")
    p.add_argument("--report", type=Path, help="PDF report")
    p.add_argument("--params", type=Path, help="stage/constants JSON (geometry; constants refitted)")
    p.add_argument("--holdout", type=float, default=0.25, help="held-out fraction at each log's end")
    p.add_argument("--no-control", action="store_true", help="skip the closed-loop study in the report")
    p.add_argument(
        "--no-limits",
        action="store_true",
        help="skip the detection limits, what the log could not have shown (a fifth to a third of the time)",
    )
    p.add_argument(
        "--currents-late",
        type=float,
        default=0.0,
        metavar="SECONDS",
        help="the logs' currents were logged this late against the positions (a diagnosis's \"currents' "
        'timing" says by how much): moved that much earlier before anything is fitted',
    )
    p.set_defaults(func=cmd_diagnose)

    p = sub.add_parser("identify", help="identify C1..C4 from logs: NLS (equation/output error) and NPFSI")
    p.add_argument("logs", nargs="+", type=Path, metavar="LOG", help="logs (.csv or .mat, SPEC 2)")
    p.add_argument("--json", type=Path, required=True, help="estimates, standard errors, covariance, timings")
    p.add_argument("--report", type=Path, help="PDF report")
    p.add_argument("--params", type=Path, help="stage/constants JSON (geometry; initial and fixed constants)")
    p.add_argument(
        "--estimate",
        nargs="+",
        default=["C1", "C2", "C3", "C4"],
        choices=["C1", "C2", "C3", "C4", "gap_offset"],
        help="parameters to estimate (default C1..C4)",
    )
    p.add_argument(
        "--methods",
        nargs="+",
        default=["equation_error", "output_error", "npfsi"],
        choices=["equation_error", "output_error", "npfsi"],
        help="methods to run (default all)",
    )
    p.add_argument("--eps", nargs="+", type=float, default=[0.001, 0.01, 0.05], help="NPFSI eps values [s]")
    p.add_argument("--input-delay", type=float, default=0.0, help="delay of the applied currents [s]")
    p.add_argument(
        "--validate",
        nargs="+",
        type=Path,
        metavar="LOG",
        help="held-out logs the fit is validated on (default: in-sample, on the fitted logs)",
    )
    p.set_defaults(func=cmd_identify)

    p = sub.add_parser(
        "design-experiment", help="references for identification: multisine, PRBS, gap sweep, D-optimal"
    )
    p.add_argument("--kind", choices=["multisine", "prbs", "gap_sweep", "doptimal"], default="doptimal")
    p.add_argument("--duration", type=float, default=60.0, help="length of the experiment [s] (10-3600)")
    p.add_argument(
        "--out", type=Path, required=True, help="folder: reference.csv, reference.mat, design.json"
    )
    p.add_argument(
        "--seed", type=int, default=0, help="phases of the papers' excitation compared with; PRBS shift"
    )
    p.add_argument("--params", type=Path, help="stage/constants JSON (default: papers)")
    p.set_defaults(func=cmd_design_experiment)
    return parser


def _caused_by_interrupt(err: BaseException) -> bool:
    """Whether a KeyboardInterrupt is in ``err``'s chain of causes and contexts."""
    seen: set[int] = set()
    while err is not None and id(err) not in seen:
        if isinstance(err, KeyboardInterrupt):
            return True
        seen.add(id(err))
        err = err.__cause__ or err.__context__
    return False


def _check_outputs(args: argparse.Namespace) -> None:
    """Refuse unusable output paths before any work (the writes check again, atomically)."""
    files = [getattr(args, k, None) for k in ("json", "report")]
    if args.command == "simulate":
        files.append(args.out)
    for path in (Path(f) for f in files if f is not None):
        if path.is_dir():
            raise OutputError(f"{path}: is a directory; give a file name inside it")
        parent = next((q for q in path.absolute().parents if q.exists()), None)
        if parent is None or not parent.is_dir() or not os.access(parent, os.W_OK):
            raise OutputError(f"{path}: cannot write there ({parent} is not a writable folder)")
    if args.command == "report" and args.out.exists() and not args.out.is_dir():
        raise OutputError(f"{args.out}: is a file; --out takes the folder for the reports")


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        _check_outputs(args)
        with honoured():
            return int(args.func(args))
    except (MaglevError, OSError) as err:
        print(f"maglev-oc {args.command}: error: {err}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:  # outputs are written whole or not at all: nothing half-written
        print(f"maglev-oc {args.command}: interrupted (no output is left half-written)", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as err:  # a bug: say so, briefly, and never blame the user's input
        if _caused_by_interrupt(err):  # Ctrl-C inside a C extension surfaces as its SystemError
            print(f"maglev-oc {args.command}: interrupted (no output is left half-written)", file=sys.stderr)
            return EXIT_INTERRUPTED
        if args.debug:
            raise
        print(
            f"maglev-oc {args.command}: internal error ({type(err).__name__}: {err}); this is a bug of "
            "maglev_oc: please report it with the command line; --debug shows the traceback",
            file=sys.stderr,
        )
        return EXIT_INTERNAL


def run() -> NoReturn:
    """The ``maglev-oc`` program: :func:`main` on the command line, then exit with its status.

    After Ctrl-C the process ends at once with :data:`EXIT_INTERRUPTED`, without the interpreter's
    shutdown. Left to it, a caught interrupt sometimes still ended the process by SIGINT after the
    one-line message (status -2 to a parent, not 130): 2 of 55 interrupts on 2 loaded cores, both
    landing in code run by ``exec`` while a module was imported (dataclasses and scipy.stats build
    methods that way); 0 of 99 since. Nothing is left to write by then (outputs are written whole
    or not at all).
    """
    code = main()
    if code == EXIT_INTERRUPTED:
        for stream in (sys.stdout, sys.stderr):
            stream.flush()
        os._exit(code)
    raise SystemExit(code)


if __name__ == "__main__":
    run()
