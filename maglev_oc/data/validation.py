"""The checks every log passes whatever its format, and the :class:`~maglev_oc.data.log.Log` they make.

A reader (:mod:`~maglev_oc.data.csv_reader`, :mod:`~maglev_oc.data.mat_reader`) returns what it
found as a :class:`RawLog`: named columns, metadata and a way to say where sample k of a column
is in the file. :func:`validated` then checks, in this order, and raises
:class:`~maglev_oc.errors.LogError` naming the file, the line (or MATLAB element) and the column
at the first problem:

1. every cell finite;
2. time strictly increasing; enough samples over a long enough duration; a median step that is
   in seconds; no gaps (a step above ``GAP_FACTOR`` x the median);
3. the metadata: ``sample_rate_hz`` agrees with the time column, ``units`` is SI,
   ``currents`` is ``measured`` or ``commanded``;
4. values that look like millimetres (gap above 0.1 m, |x3| above 0.5 m) or milliamperes
   (above 100 A);

then builds the states (NaN rows for missing rates) and the inputs (from the phase currents by
the d-q transform when u1, u2 are absent), with a note for everything that was not plain copying.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from maglev_oc.data.log import INPUT_COLUMNS, PAYLOAD_KEY, PHASE_COLUMNS, STATE_COLUMNS, Log, payload_problem
from maglev_oc.data.phase_currents import phase_currents_to_inputs
from maglev_oc.errors import LogError
from maglev_oc.model.hardware import PEAK_CURRENT_LIMIT
from maglev_oc.model.parameters import StageParameters

__all__ = [
    "GAP_FACTOR",
    "JITTER_TOLERANCE",
    "MAX_AIR_GAP",
    "MAX_CURRENT",
    "MAX_HORIZONTAL_POSITION",
    "MAX_SAMPLE_TIME",
    "SAMPLE_RATE_TOLERANCE",
    "TRANSFORM_TOLERANCE",
    "RawLog",
    "check_required_columns",
    "validated",
]

MAX_AIR_GAP = 0.1
"""[m] The air gap of the stage is 0..40 mm; a value above 0.1 m is a gap in millimetres."""
MAX_HORIZONTAL_POSITION = 0.5
"""[m] Horizontal travel is about +-50 mm (SPEC 4); |x3| above 0.5 m is millimetres."""
MAX_CURRENT = 100.0
"""[A] The amplifiers give 9 A peak (``PEAK_CURRENT_LIMIT``); a current above 100 A is in
milliamperes."""
MAX_SAMPLE_TIME = 0.05
"""[s] The control loop runs at 5 kHz; a median step above 50 ms (20 Hz, too coarse for the
closed-loop dynamics at up to 9 Hz) means the time column is in milliseconds or the log is
decimated beyond use."""
GAP_FACTOR = 1.5
"""A time step larger than this multiple of the median step is a gap (samples missing)."""
SAMPLE_RATE_TOLERANCE = 0.01
"""Relative disagreement allowed between ``sample_rate_hz`` in the metadata and the data."""
JITTER_TOLERANCE = 0.1
"""Largest distance of a sample's time from the best uniform grid, in steps."""
TRANSFORM_TOLERANCE = 0.01
"""[A] Logged u1, u2 differing from the transform of ia, ib, ic by more than this get a note:
10x the current resolution, so rounding never triggers it, while a wrong pole pitch, phase
order or sign (errors of the order of the currents themselves) always does."""


@dataclass
class RawLog:
    """What a reader found, before the checks common to both formats.

    Attributes
    ----------
    source : str
        The file.
    columns : dict of str to (n,) array
        The known columns, by name, as read.
    metadata : dict of str to str
        The ``# key: value`` lines (CSV) or the ``metadata`` struct (.mat).
    metadata_where : dict of str to str
        Where each metadata entry is ("line 2 (metadata 'units')", "metadata.units").
    notes : list of str
        What reading ignored so far.
    where : callable (sample, column or None) -> (place, line or None)
        Where sample k of a column is in the file, for messages.
    """

    source: str
    columns: dict[str, np.ndarray]
    metadata: dict[str, str]
    metadata_where: dict[str, str]
    notes: list[str]
    where: Callable[[int, str | None], tuple[str, int | None]]

    def error(self, k: int, name: str | None, problem: str) -> LogError:
        """A LogError at sample ``k`` of column ``name``."""
        place, line = self.where(k, name)
        return LogError(self.source, problem, where=place, line=line, column=name)

    def metadata_error(self, key: str, problem: str, *, column: str | None = None) -> LogError:
        """A LogError at the metadata entry ``key``."""
        where = self.metadata_where[key]
        return LogError(self.source, problem, where=where, line=_line_number(where), column=column)


def check_required_columns(names: list[str], source: str, *, where: str | None, line: int | None) -> None:
    """Raise LogError unless ``names`` hold t, x1, x3 and either u1, u2 or all of ia, ib, ic.

    Parameters
    ----------
    names : list of str
        The file's column (or variable) names.
    source : str
        The file, for the message.
    where, line : str or None, int or None
        The header's location (CSV) or None (.mat).
    """
    present = set(names)
    partial = [c for c in PHASE_COLUMNS if c in present]
    if partial and len(partial) < len(PHASE_COLUMNS):
        missing = [c for c in PHASE_COLUMNS if c not in present]
        raise LogError(
            source,
            f"phase currents need all of ia, ib, ic; found {', '.join(partial)}, missing "
            f"{', '.join(missing)} (columns found: {', '.join(names)})",
            where=where,
            line=line,
            column=missing[0],
        )
    has_phases = len(partial) == len(PHASE_COLUMNS)
    missing = [c for c in ("t", "x1", "x3") if c not in present]
    if not has_phases:
        missing += [c for c in INPUT_COLUMNS if c not in present]
    if missing:
        alternative = "" if has_phases else " (u1, u2 may be replaced by phase currents ia, ib, ic)"
        raise LogError(
            source,
            f"missing required column(s) {', '.join(missing)}{alternative}; columns found: "
            f"{', '.join(names) if names else 'none'}",
            where=where,
            line=line,
            column=missing[0],
        )


def validated(
    raw: RawLog,
    params: StageParameters,
    min_samples: int,
    min_duration: float,
    transform_tolerance: float,
) -> Log:
    """The checks common to CSV and .mat (module docstring), then the Log.

    Parameters
    ----------
    raw : RawLog
        What the reader found.
    params : StageParameters
        Supplies the pole pitch [m] of the d-q transform.
    min_samples : int
        Fewest samples accepted.
    min_duration : float
        Shortest duration accepted [s].
    transform_tolerance : float
        [A] Logged u1, u2 further than this from the transform of ia, ib, ic get a note.

    Returns
    -------
    Log
    """
    cols = raw.columns
    notes = list(raw.notes)
    _check_finite(raw)
    t = cols["t"]
    _check_increasing(raw, t)
    _check_length(raw.source, t, min_samples, min_duration)
    median = _check_sampling(raw, t)
    currents = _check_metadata(raw, median)
    _check_si_units(raw)
    x = _states(cols, t.size, notes)
    u = _inputs(raw, params.pole_pitch, transform_tolerance, notes)
    return Log(
        t=t,
        x=x,
        u=u,
        metadata=dict(raw.metadata),
        source=raw.source,
        notes=tuple(notes),
        currents_measured=currents == "measured",
    )


def _check_finite(raw: RawLog) -> None:
    """NaN / inf: the first bad sample, and the first column bad there."""
    cols = raw.columns
    names = list(cols)
    finite = np.vstack([np.isfinite(cols[name]) for name in names])
    if not finite.all():
        bad_rows = ~finite.all(axis=0)
        k = int(np.argmax(bad_rows))
        name = names[int(np.argmax(~finite[:, k]))]
        raise raw.error(k, name, f"{float(cols[name][k])!r} value; every cell must be a finite number")


def _check_increasing(raw: RawLog, t: np.ndarray) -> None:
    if t.size < 2:
        return
    steps = np.diff(t)
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0)) + 1
        previous = raw.where(k - 1, None)[0]
        raise raw.error(
            k,
            "t",
            f"time does not increase: t = {float(t[k])!r} s here after t = {float(t[k - 1])!r} s "
            f"({previous})",
        )


def _check_length(source: str, t: np.ndarray, min_samples: int, min_duration: float) -> None:
    n = t.size
    duration = float(t[-1] - t[0])
    if n < min_samples or duration < min_duration:
        raise LogError(
            source,
            f"too short: {n} samples over {duration:.6g} s; need at least min_samples = {min_samples} "
            f"samples and min_duration = {min_duration:g} s to identify anything",
        )


def _check_sampling(raw: RawLog, t: np.ndarray) -> float:
    """The median step [s], after checking that it is in seconds and that no samples are missing."""
    steps = np.diff(t)
    median = float(np.median(steps))
    if median > MAX_SAMPLE_TIME:
        raise LogError(
            raw.source,
            f"the median time step is {median:.6g} s ({1 / median:.4g} Hz): is t in milliseconds? "
            f"Logs are in seconds, and steps above {MAX_SAMPLE_TIME:g} s are too coarse for the stage",
            column="t",
        )
    if np.any(steps > GAP_FACTOR * median):
        gaps = np.flatnonzero(steps > GAP_FACTOR * median)
        k = int(gaps[0]) + 1
        previous = raw.where(k - 1, None)[0]
        raise raw.error(
            k,
            "t",
            f"gap in time: t jumps by {steps[k - 1]:.6g} s from {float(t[k - 1])!r} s ({previous}) to "
            f"{float(t[k])!r} s, {steps[k - 1] / median:.3g} x the median step {median:.6g} s "
            f"(more than {GAP_FACTOR:g} x means samples are missing; {gaps.size} such gap(s) in all)",
        )
    # jitter: the derivative filters assume a uniform grid; the best-fitting one (rate and offset)
    # must hold every sample to JITTER_TOLERANCE of a step (rounding t to a digit below a fifth of
    # the step passes; timestamps from a non-real-time logger do not)
    k = np.arange(t.size, dtype=float)
    slope, offset = np.polyfit(k, t - t[0], 1)
    deviation = np.abs(t - t[0] - (offset + slope * k))
    worst = int(np.argmax(deviation))
    if deviation[worst] > JITTER_TOLERANCE * median:
        raise raw.error(
            worst,
            "t",
            f"irregular sampling: t = {float(t[worst])!r} s is {deviation[worst]:.3g} s "
            f"({deviation[worst] / median:.0%} of the {median:.6g} s step) off a uniform grid "
            f"(tolerance {JITTER_TOLERANCE:.0%}); the tools need uniformly sampled logs: log on the "
            "real-time target, or resample",
        )
    return median


def _check_metadata(raw: RawLog, median: float) -> str:
    """Check sample_rate_hz, units and currents; return the currents' kind ('measured'/'commanded')."""
    meta = raw.metadata
    if "sample_rate_hz" in meta:
        stated_text = meta["sample_rate_hz"]
        try:
            stated = float(stated_text)
        except ValueError:
            stated = math.nan
        if not (stated > 0 and math.isfinite(stated)):
            raise raw.metadata_error(
                "sample_rate_hz", f"sample_rate_hz {stated_text!r} is not a positive number"
            )
        measured = 1.0 / median
        if abs(measured - stated) > SAMPLE_RATE_TOLERANCE * stated:
            raise raw.metadata_error(
                "sample_rate_hz",
                f"sample_rate_hz = {stated_text} disagrees with the time column, whose median step "
                f"{median:.6g} s is {measured:.6g} Hz (tolerance {SAMPLE_RATE_TOLERANCE:.0%})",
                column="t",
            )
    if "units" in meta:
        problem = _units_problem(meta["units"])
        if problem:
            raise raw.metadata_error("units", f"units {meta['units']!r}: {problem}")
    if PAYLOAD_KEY in meta and (problem := payload_problem(meta[PAYLOAD_KEY])):
        raise raw.metadata_error(PAYLOAD_KEY, f"{PAYLOAD_KEY} {problem}")
    currents = meta.get("currents", "commanded").strip().lower()
    if currents not in ("measured", "commanded"):
        raise raw.metadata_error(
            "currents", f"currents {meta['currents']!r}: expected 'measured' or 'commanded'"
        )
    return currents


_SI_UNITS = ("m", "m/s", "A", "s")
"""The units of a log's columns (gap and position, their rates, currents, time)."""


def _units_problem(stated: str) -> str | None:
    """None if a ``units`` line says SI, with or without a list of units that are ours
    (``SI``, ``SI (m, A, s)``, ``si [m, m/s, A, s]``); else what is wrong."""
    expected = f"expected 'SI' or 'SI ({', '.join(_SI_UNITS)})'"
    match = re.fullmatch(r"\s*SI\s*(?:[(\[]([^)\]]*)[)\]])?\s*", stated, flags=re.IGNORECASE)
    if not match:
        return f"only SI logs are read; {expected}, the values in metres, amperes and seconds"
    listed = [u.strip() for u in re.split(r"[,;]", match.group(1) or "") if u.strip()]
    foreign = [u for u in listed if u not in _SI_UNITS]
    if foreign:
        return f"{', '.join(foreign)} not among the log's SI units ({', '.join(_SI_UNITS)}); {expected}"
    return None


def _check_si_units(raw: RawLog) -> None:
    """Refuse columns whose values look like millimetres or milliamperes."""
    cols = raw.columns
    limits = [("x1", MAX_AIR_GAP, "air gap", "m", "0..40 mm", "millimetres", "metres")]
    limits.append(
        ("x3", MAX_HORIZONTAL_POSITION, "horizontal position", "m", "+-50 mm", "millimetres", "metres")
    )
    for name in (*INPUT_COLUMNS, *PHASE_COLUMNS):
        span = f"+-{PEAK_CURRENT_LIMIT:g} A"
        limits.append((name, MAX_CURRENT, "current", "A", span, "milliamperes", "amperes"))
    for name, limit, what, unit, span, small, si in limits:
        if name not in cols:
            continue
        big = np.abs(cols[name]) > limit
        if np.any(big):
            k = int(np.argmax(big))
            raise raw.error(
                k,
                name,
                f"{what} {float(cols[name][k])!r} {unit} is beyond {limit:g} {unit} (the stage spans "
                f"{span}): the column looks like {small}; logs are in {si} (SI)",
            )


def _states(cols: dict[str, np.ndarray], n: int, notes: list[str]) -> np.ndarray:
    """x (4, n) with NaN rows for the rates the log does not carry (and a note saying so)."""
    x = np.full((4, n), np.nan)
    for row, name in enumerate(STATE_COLUMNS):
        if name in cols:
            x[row] = cols[name]
    missing_rates = [name for name in ("x2", "x4") if name not in cols]
    if missing_rates:
        notes.append(f"{', '.join(missing_rates)} not in the log: NaN row(s)")
    return x


def _inputs(raw: RawLog, tau: float, tolerance: float, notes: list[str]) -> np.ndarray:
    """u (2, n): the logged u1, u2, or what the d-q transform makes of ia, ib, ic (pole pitch tau [m])."""
    cols = raw.columns
    if not all(name in cols for name in PHASE_COLUMNS):
        return np.vstack([cols["u1"], cols["u2"]])
    from_phases = phase_currents_to_inputs(cols["ia"], cols["ib"], cols["ic"], cols["x3"], tau)
    u = from_phases.copy()
    logged = [name for name in INPUT_COLUMNS if name in cols]
    for name in logged:
        u[INPUT_COLUMNS.index(name)] = cols[name]
    converted = [name for name in INPUT_COLUMNS if name not in cols]
    if converted:
        notes.append(
            f"{' and '.join(converted)} from ia, ib, ic by eq. (2) of paper 001 with tau = {tau:g} m"
        )
    for name in logged:
        row = INPUT_COLUMNS.index(name)
        diff = np.abs(cols[name] - from_phases[row])
        k = int(np.argmax(diff))
        if diff[k] > tolerance:
            notes.append(
                f"logged {name} differs from the transform of ia, ib, ic (tau = {tau:g} m) by up to "
                f"{diff[k]:.4g} A ({raw.where(k, None)[0]}); tolerance {tolerance:g} A; the "
                f"logged {name} is used"
            )
    zero_sequence = np.abs(cols["ia"] + cols["ib"] + cols["ic"])
    if zero_sequence.max() > tolerance:
        k = int(np.argmax(zero_sequence))
        notes.append(
            f"ia + ib + ic reaches {zero_sequence[k]:.4g} A ({raw.where(k, None)[0]}); the dq transform "
            "ignores this zero-sequence part"
        )
    return u


def _line_number(where: str) -> int | None:
    match = re.match(r"line (\d+)", where)
    return int(match.group(1)) if match else None
