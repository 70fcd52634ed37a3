"""The identification study on the twin: every method and every verification procedure, with
the true constants known (what ``analyses/identification.py`` reports).

:func:`run_study` does the computing; the figures and the PDF are made from the returned
:class:`IdentificationStudy` by :mod:`maglev_oc.reporting.identification_plots`.

Experiments (all on the rig twin with :data:`~maglev_oc.identification.experiments.TWIN_TRUTH`,
the papers' constants perturbed, encoders 10 um + 2 um noise, amplifiers with their lag;
PIDs designed on the nominal model, logged at 1 kHz):

1. 60 s sum-of-sines run: equation-error and multiple-shooting NLS for C1..C4, NPFSI at
   eps = 0.001, 0.01, 0.05 with the papers' observer velocities and with zero-phase ones
   (Table III of 000).
2. Coverage: equation error on ``coverage_seeds`` shorter runs (other seeds): z-scores of the
   estimates against the truth, with the long-run and the plain standard errors.
3. Vertical-only runs (mover locked at x3 = 0 and at 3 t1 / 2, gap about 16 mm, cogging on):
   NPFSI for C2..C4 at x3 = 0 (Table II), C2 alone at 3 t1 / 2 (cogging procedure, 000 V-C).
4. Fixed-gap runs 10-27.5 mm, u1 = -0.5 A from x3 = -50 mm (cogging on): parabolas vs NPFSI.
5. Equilibrium currents 10-25 mm at x3 = 0 and at 3 t1 / 2 (cogging on) vs eq. (8) of 000
   with the Table II-style constants (and with the cogging-corrected C2).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from maglev_oc.data.logs import Log
from maglev_oc.estimation.differentiate import SavitzkyGolay
from maglev_oc.identification.equation_error import EquationError
from maglev_oc.identification.experiments import (
    EQUILIBRIUM_GAPS,
    FIXED_GAPS,
    TWIN_TRUTH,
    EquilibriumMeasurement,
    equilibrium_current_runs,
    excitation_log,
    fixed_gap_logs,
    verification_effects,
)
from maglev_oc.identification.layout import CONSTANT_NAMES
from maglev_oc.identification.npfsi import PAPER_EPSILONS, npfsi
from maglev_oc.identification.output_error import MultipleShooting, simulate_open_loop
from maglev_oc.identification.result import FitResult, NpfsiResult
from maglev_oc.identification.verification import (
    EquilibriumComparison,
    ParabolaComparison,
    ParabolaFit,
    cogging_from_c2,
    compare_equilibrium_currents,
    compare_parabola_npfsi,
    fit_parabola,
    npfsi_fixed_gap,
)
from maglev_oc.model.parameters import LumpedConstants
from maglev_oc.model.stage import StageModel

__all__ = [
    "COMMAND_TO_CURRENT_DELAY",
    "PARTIAL",
    "VERTICAL_GAP",
    "Coverage",
    "IdentificationStudy",
    "run_study",
]

VERTICAL_GAP = 16e-3
"""[m] Centre of the vertical-only excitation: the sines span about 12-20 mm, where the
cogging (1.5 N at 15 mm) acts."""
PARTIAL = ("C2", "C3", "C4")
COMMAND_TO_CURRENT_DELAY = 1 / (2 * np.pi * 1000.0) + 1e-4
"""[s] The amplifiers' first-order lag (1 kHz: 0.16 ms) plus half the 5 kHz hold (0.1 ms)."""


@dataclass(frozen=True)
class Coverage:
    """Equation-error estimates over several twin runs against the truth.

    z[k, i] = (estimate - truth) / stderr for run k, parameter i (long-run standard errors);
    z_naive likewise with the plain s^2 (J'J)^-1 ones; error_pct the relative errors.
    """

    names: tuple[str, ...]
    seeds: tuple[int, ...]
    duration: float
    z: np.ndarray
    z_naive: np.ndarray
    error_pct: np.ndarray
    stderr_pct: np.ndarray

    def fraction_within(self, k: float = 2.0) -> np.ndarray:
        return np.mean(np.abs(self.z) <= k, axis=0)


@dataclass(frozen=True, eq=False)
class IdentificationStudy:
    """Everything :func:`run_study` computed (see the module docstring)."""

    nominal: StageModel
    truth: StageModel
    log: Log
    equation_error: FitResult
    equation_error_delayed: FitResult  # the same with the currents shifted by the amplifier + ZOH delay
    output_error: FitResult
    npfsi_observer: tuple[NpfsiResult, ...]
    npfsi_zero_phase: tuple[NpfsiResult, ...]
    open_loop: np.ndarray  # (4, k) single-shooting simulation with the true constants
    coverage: Coverage
    vertical_log: Log
    table2: tuple[NpfsiResult, ...]
    table2_equation_error: FitResult
    cogging_log: Log
    cogging_npfsi: NpfsiResult
    cogging_equation_error: FitResult
    cogging_gaps: np.ndarray
    cogging_xi_npfsi: np.ndarray
    cogging_xi_equation_error: np.ndarray
    cogging_xi_true: np.ndarray
    parabolas: tuple[ParabolaFit, ...]
    fixed_gap_npfsi: dict[float, tuple[NpfsiResult, ...]]
    parabola_comparisons: dict[float, ParabolaComparison]
    equilibrium_x0: EquilibriumMeasurement
    equilibrium_cogging: EquilibriumMeasurement
    prediction_x0: EquilibriumComparison
    prediction_cogging: EquilibriumComparison
    prediction_cogging_corrected: EquilibriumComparison
    table2_model: StageModel
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def truth_values(self) -> dict[str, float]:
        return dict(zip(CONSTANT_NAMES, self.truth.constants.as_array(), strict=True))


def run_study(
    nominal: StageModel,
    *,
    truth_constants: LumpedConstants = TWIN_TRUTH,
    duration: float = 60.0,
    seed: int = 1,
    coverage_seeds: int = 8,
    coverage_duration: float = 20.0,
    vertical_duration: float = 40.0,
) -> IdentificationStudy:
    """Run the twin experiments and every identification/verification on them.

    Parameters
    ----------
    nominal : StageModel
        The model the controllers and the fits start from.
    truth_constants : LumpedConstants
        The twin's constants (what the fits should find).
    duration, coverage_duration, vertical_duration : float
        [s] Lengths of the excitation log, of each coverage log and of the vertical runs.
    seed, coverage_seeds : int
        Seed of the main logs; number of coverage logs (seeds 100, 101, ...).

    Returns
    -------
    IdentificationStudy
        Every result, with ``timings`` [s] by step.
    """
    clock = _Clock()
    truth = nominal.with_constants(truth_constants)
    fields = _excitation_fits(clock, nominal, truth, duration, seed)
    fields["coverage"] = _coverage(clock, nominal, truth, coverage_seeds, coverage_duration)
    veff = verification_effects()
    fields |= _vertical_runs(clock, nominal, truth, veff, vertical_duration, seed)
    fields |= _fixed_gaps(clock, nominal, truth, veff, seed)
    fields |= _equilibrium(clock, nominal, truth, veff, fields["table2_model"], fields["cogging_npfsi"])
    return IdentificationStudy(nominal=nominal, truth=truth, timings=clock.times, **fields)


class _Clock:
    """Wall times by step name (repeated steps add up)."""

    def __init__(self) -> None:
        self.times: dict[str, float] = {}

    def __call__(self, key: str, fn):
        t0 = time.perf_counter()
        out = fn()
        self.add(key, time.perf_counter() - t0)
        return out

    def add(self, key: str, seconds: float) -> None:
        self.times[key] = self.times.get(key, 0.0) + seconds


def _excitation_fits(
    clock: _Clock, nominal: StageModel, truth: StageModel, duration: float, seed: int
) -> dict:
    """The 60 s excitation log and every method on it (000 Sec. IV)."""
    log = clock(
        "simulate: 60 s excitation",
        lambda: excitation_log(truth, duration=duration, seed=seed, controller_model=nominal),
    )
    ee = clock("equation error (60 s)", lambda: EquationError(log, nominal).fit())
    ee_delayed = EquationError(log, nominal, input_delay=COMMAND_TO_CURRENT_DELAY).fit()
    oe = clock("output error (60 s)", lambda: MultipleShooting(log, nominal).fit(initial=ee))
    obs = tuple(
        clock("NPFSI x3 eps (observer velocities)", lambda e=e: npfsi(log, nominal, eps=e))
        for e in PAPER_EPSILONS
    )
    sg = SavitzkyGolay(log.sample_time)
    zero = tuple(
        clock(
            "NPFSI x3 eps (zero-phase velocities)", lambda e=e: npfsi(log, nominal, eps=e, differentiator=sg)
        )
        for e in PAPER_EPSILONS
    )
    return {
        "log": log,
        "equation_error": ee,
        "equation_error_delayed": ee_delayed,
        "output_error": oe,
        "npfsi_observer": obs,
        "npfsi_zero_phase": zero,
        "open_loop": simulate_open_loop(log, truth, 1.0),
    }


def _coverage(
    clock: _Clock, nominal: StageModel, truth: StageModel, n_seeds: int, duration: float
) -> Coverage:
    """Equation-error fits on ``n_seeds`` independent logs: do the standard errors cover the truth?"""
    t0 = time.perf_counter()
    z, zn, err, se = [], [], [], []
    seeds = tuple(100 + k for k in range(n_seeds))
    tv = dict(zip(CONSTANT_NAMES, truth.constants.as_array(), strict=True))
    for s in seeds:
        lg = excitation_log(truth, duration=duration, seed=s, controller_model=nominal)
        fit = EquationError(lg, nominal).fit()
        z.append([fit.z_scores(tv)[k] for k in CONSTANT_NAMES])
        zn.append([(fit.values[k] - tv[k]) / fit.stderr_naive[k] for k in CONSTANT_NAMES])
        err.append([100 * fit.relative_errors(tv)[k] for k in CONSTANT_NAMES])
        se.append([100 * fit.stderr[k] / tv[k] for k in CONSTANT_NAMES])
    clock.add("coverage runs (simulate + fit)", time.perf_counter() - t0)
    return Coverage(CONSTANT_NAMES, seeds, duration, np.array(z), np.array(zn), np.array(err), np.array(se))


def _vertical_runs(
    clock: _Clock, nominal: StageModel, truth: StageModel, veff, duration: float, seed: int
) -> dict:
    """Vertical-only runs: Table II (x3 = 0) and the cogging procedure (x3 = 1.5 slot pitches)."""
    pos = 1.5 * nominal.params.slot_pitch

    def vertical_log(offset: int, position: float):
        return excitation_log(
            truth,
            duration=duration,
            seed=seed + offset,
            controller_model=nominal,
            effects=veff,
            gap_offset=VERTICAL_GAP,
            locked_position=position,
        )

    vlog = clock("simulate: vertical runs", lambda: vertical_log(1, 0.0))
    clog = clock("simulate: vertical runs", lambda: vertical_log(2, pos))
    table2 = tuple(
        clock("NPFSI (vertical runs)", lambda e=e: npfsi(vlog, nominal, estimate=PARTIAL, eps=e))
        for e in PAPER_EPSILONS
    )
    t2 = table2[PAPER_EPSILONS.index(0.01)]
    table2_model = nominal.with_constants(
        nominal.constants.replace(
            **{k: t2.values[k] for k in PARTIAL}, source="Table II style: NPFSI eps = 0.01, x3 = 0"
        )
    )
    t2_ee = clock(
        "equation error (vertical runs)", lambda: EquationError(vlog, nominal, estimate=PARTIAL).fit()
    )
    cog = clock(
        "NPFSI (vertical runs)",
        lambda: npfsi(clog, table2_model, estimate=("C2",), eps=0.01, theta0={"C2": t2.values["C2"]}),
    )
    cog_ee = clock(
        "equation error (vertical runs)",
        lambda: EquationError(clog, t2_ee.model(nominal), estimate=("C2",)).fit(),
    )
    gaps = np.linspace(10e-3, 25e-3, 61)
    c = veff.cogging
    assert c is not None
    # the twin adds -F sin(pi x3 / t1 + phase) / M_v to x2' with F = peak (ref / x1)^exponent,
    # i.e. K2 -> K2 + F sin(...): at x3 = 3 t1 / 2 that is K2 - F (less attraction)
    angle = np.pi * pos / nominal.params.slot_pitch + c.phase
    return {
        "vertical_log": vlog,
        "table2": table2,
        "table2_equation_error": t2_ee,
        "table2_model": table2_model,
        "cogging_log": clog,
        "cogging_npfsi": cog,
        "cogging_equation_error": cog_ee,
        "cogging_gaps": gaps,
        "cogging_xi_npfsi": cogging_from_c2(nominal, t2.values["C2"], cog.values["C2"], gaps),
        "cogging_xi_equation_error": cogging_from_c2(nominal, t2_ee.values["C2"], cog_ee.values["C2"], gaps),
        "cogging_xi_true": c.peak_at_reference * (c.reference_gap / gaps) ** c.exponent * np.sin(angle),
    }


def _fixed_gaps(clock: _Clock, nominal: StageModel, truth: StageModel, veff, seed: int) -> dict:
    """Fixed-gap runs: the parabola fit of L1 against NPFSI at each eps (000 Sec. V)."""
    fg_logs = clock(
        "simulate: fixed-gap runs", lambda: fixed_gap_logs(truth, FIXED_GAPS, effects=veff, seed=seed)
    )
    parabolas = tuple(fit_parabola(lg, g) for lg, g in zip(fg_logs, FIXED_GAPS, strict=True))
    l1_guess = nominal.coefficients(np.array(FIXED_GAPS))[0]
    fg_npfsi: dict[float, tuple[NpfsiResult, ...]] = {}
    comparisons: dict[float, ParabolaComparison] = {}
    t0 = time.perf_counter()
    for e in PAPER_EPSILONS:
        runs = tuple(
            npfsi_fixed_gap(lg, eps=e, theta0=float(g0)) for lg, g0 in zip(fg_logs, l1_guess, strict=True)
        )
        fg_npfsi[e] = runs
        comparisons[e] = compare_parabola_npfsi(parabolas, runs)
    clock.add("NPFSI (fixed-gap runs)", time.perf_counter() - t0)
    return {"parabolas": parabolas, "fixed_gap_npfsi": fg_npfsi, "parabola_comparisons": comparisons}


def _equilibrium(
    clock: _Clock, nominal: StageModel, truth: StageModel, veff, table2_model: StageModel, cog: NpfsiResult
) -> dict:
    """Equilibrium currents measured at x3 = 0 and on the cogging position, against predictions."""
    pos = 1.5 * nominal.params.slot_pitch

    def runs(position: float):
        return equilibrium_current_runs(
            truth, EQUILIBRIUM_GAPS, position=position, effects=veff, controller_model=nominal
        )

    eq0 = clock("simulate: equilibrium currents", lambda: runs(0.0))
    eq1 = clock("simulate: equilibrium currents", lambda: runs(pos))
    cog_model = table2_model.with_constants(table2_model.constants.replace(C2=cog.values["C2"]))
    return {
        "equilibrium_x0": eq0,
        "equilibrium_cogging": eq1,
        "prediction_x0": compare_equilibrium_currents(table2_model, eq0.gap, eq0.current),
        "prediction_cogging": compare_equilibrium_currents(table2_model, eq1.gap, eq1.current),
        "prediction_cogging_corrected": compare_equilibrium_currents(cog_model, eq1.gap, eq1.current),
    }
