"""Closing the loop with measured data, on a built-in log recorded from the rig twin with effects
the diagnosis is not told about.

    python analyses/closing_the_loop.py [--out reports/closing_the_loop.pdf]
"""

from __future__ import annotations

import math
from pathlib import Path

from maglev_oc.control.pid import paper_pid
from maglev_oc.diagnosis.feedback import compensation_study
from maglev_oc.diagnosis.pipeline import diagnose
from maglev_oc.model.stage import StageModel
from maglev_oc.reporting.diagnosis_report import write_diagnosis_report
from maglev_oc.reporting.pdf import ReportContents
from maglev_oc.reporting.twins import DIAGNOSIS_TRUTH
from maglev_oc.sim.effects import TwinEffects
from maglev_oc.sim.engine import ClosedLoop
from maglev_oc.sim.recording import result_to_log
from maglev_oc.sim.scenarios import excitation_scenario
from maglev_oc.sim.twin import RigTwin
from maglev_oc.units import M_TO_UM

__all__ = ["ORDER", "REPORT", "build", "main"]

REPORT = "closing_the_loop.pdf"
ORDER = 60


def _builtin_log(model: StageModel, duration: float = 60.0):
    """60 s of the papers' PID sum-of-sines excitation on the rig twin, logged at 1 kHz. The log
    carries no description of the twin. Returns (log, twin)."""
    twin = RigTwin(model.with_constants(DIAGNOSIS_TRUTH), TwinEffects.rig())
    res = ClosedLoop(twin, paper_pid(model)).run(excitation_scenario(duration, seed=7))
    return result_to_log(res, rate_hz=1000.0), twin


def truth_rows(diag, twin: RigTwin, model: StageModel) -> list[tuple[str, str, str, str]]:
    """Found against true for the twin's effects: (true effect, true size, found as, found size)."""
    e = twin.effects
    found = {f.name: f for f in diag.effects}

    def size(name: str, key: str, scale: float = 1.0, unit: str = "") -> tuple[str, str]:
        f = found.get(name)
        if f is None:
            return "not found", "—"
        p = f.parameters[key]
        return name.replace("_", " "), f"{p.value * scale:.3g} ± {p.stderr * scale:.2g} {unit}".strip()

    rows = []
    cog = found.get("cogging_vertical_38mm")
    gap = cog.parameters["at_gap"].value if cog else 0.02
    true_cog = e.cogging.peak_at_reference * (e.cogging.reference_gap / gap) ** e.cogging.exponent
    rows.append(
        (
            f"normal cogging over 2 t1 (peak at {gap * 1e3:.1f} mm)",
            f"{true_cog:.3g} N",
            *size("cogging_vertical_38mm", "amplitude", unit="N"),
        )
    )
    rows.append(
        (
            "guide friction, horizontal (Coulomb)",
            f"{e.friction_horizontal.coulomb:.3g} N",
            *size("guide_friction_horizontal", "coulomb", unit="N"),
        )
    )
    rows.append(
        (
            "guide friction, vertical (Coulomb)",
            f"{e.friction_vertical.coulomb:.3g} N",
            *size("guide_friction_vertical", "coulomb", unit="N"),
        )
    )
    rows.append(
        (
            "guides off level (force along the track)",
            f"{model.params.mass_horizontal * model.params.gravity * e.misalignment.level_tilt:.3g} N",
            *size("horizontal_guides_not_level", "force", unit="N"),
        )
    )
    rows.append(
        (
            "guides tilted against the stator (slope)",
            f"{e.misalignment.tilt * 1e3:.3g} mrad",
            *size("guide_misalignment", "slope", 1e3, "mrad"),
        )
    )
    rows.append(
        (
            f"guide waviness ({e.misalignment.waviness_period * 1e3:g} mm period)",
            f"{e.misalignment.waviness * M_TO_UM:.3g} µm",
            "not found"
            if "guide_misalignment" not in found
            or "waviness_amplitude" not in found["guide_misalignment"].parameters
            else "guide misalignment",
            "—",
        )
    )
    lag_ms = 1e3 / (2 * math.pi * e.amplifier.bandwidth_hz) + 0.2 * e.input_delay_samples
    rows.append(
        (
            "amplifier lag (1st order) + one-sample loop delay",
            f"{lag_ms:.3g} ms",
            *size("current_amplifier_lag", "time_constant", 1e3, "ms"),
        )
    )
    return rows


def build(out: Path, model: StageModel) -> ReportContents:
    """Diagnose the built-in log, compensate what was found, and write the report to ``out``."""
    log, twin = _builtin_log(model)
    diag = diagnose([log], model)
    study = compensation_study(diag, model, twin=twin)
    preamble = [
        "A 60 s log of the papers' PID sum-of-sines excitation (000 Sec. IV) recorded at 1 kHz from the "
        "project's rig twin, whose effects the diagnosis is not told about. The diagnosis gets only the log "
        "(encoder readings and commanded currents) and the papers' geometry; it refits C1..C4 itself. The "
        "table after this page compares what it found with what the twin had. (The diagnosis's acceptance "
        "tests use logs of an independent simulator instead: tests/test_diagnose.py, bench/peer_pysindy.py.)",
    ]
    return write_diagnosis_report(
        out, diag, study=study, preamble=preamble, truth_rows=truth_rows(diag, twin, model)
    )


def main(argv: list[str] | None = None) -> int:
    from maglev_oc.analyses import analysis_parser

    from maglev_oc.model.loading import load_model

    parser = analysis_parser(__doc__, REPORT)
    args = parser.parse_args(argv)
    print(f"wrote {build(args.out, load_model(args.params)).path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
