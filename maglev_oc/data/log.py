"""The :class:`Log` type: one run of the stage in SI units, validated when made (SPEC 2).

A log holds time, the four states and the two inputs,

    t [s];  x = (x1 air gap [m], x2 its rate [m/s], x3 horizontal position [m], x4 its rate [m/s]);
    u = (u1 = i_q [A], u2 = i_d [A]),

with the shapes ``t (n,)``, ``x (4, n)``, ``u (2, n)``. A log that did not carry the velocities
has NaN rows for x2 and x4 (:attr:`Log.states_measured` says which rows are data);
:mod:`maglev_oc.estimation.differentiate` estimates them from x1, x3.
"""

from __future__ import annotations

import dataclasses
import math
import types
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from maglev_oc.errors import InputError

__all__ = [
    "INPUT_COLUMNS",
    "KNOWN_COLUMNS",
    "MAX_PAYLOAD",
    "PAYLOAD_KEY",
    "PHASE_COLUMNS",
    "REQUIRED_COLUMNS",
    "STATE_COLUMNS",
    "Log",
    "payload_problem",
]

REQUIRED_COLUMNS = ("t", "x1", "x3", "u1", "u2")
"""Columns every log must have (u1, u2 may be replaced by the phase currents ia, ib, ic)."""
STATE_COLUMNS = ("x1", "x2", "x3", "x4")
INPUT_COLUMNS = ("u1", "u2")
PHASE_COLUMNS = ("ia", "ib", "ic")
KNOWN_COLUMNS = ("t", *STATE_COLUMNS, *INPUT_COLUMNS, *PHASE_COLUMNS)
PAYLOAD_KEY = "payload_kg"
"""Metadata key of the mass [kg] the platform carried during the run beyond the model's movers
(``# payload_kg: 0.5``): a log of a load change, the experiment that separates a constant vertical
force from the magnets' scale (:mod:`maglev_oc.regression.payload`)."""
MAX_PAYLOAD = 20.0
"""[kg] The largest payload read: the magnets lift the 4.35 kg mover with a few amperes, and a
number beyond this is more likely grams than kilograms."""


def payload_problem(text: str) -> str | None:
    """None if ``text`` (a ``payload_kg`` value) is a mass in [0, MAX_PAYLOAD] kg; else what is wrong."""
    try:
        value = float(text)
    except ValueError:
        return f"{text!r} is not a number (the payload's mass in kg)"
    if not (value >= 0.0 and value <= MAX_PAYLOAD):
        return (
            f"{text!r} is not a mass in [0, {MAX_PAYLOAD:g}] kg (the payload carried beyond the "
            "model's movers; a number this large may be in grams)"
        )
    return None


def _readonly(value: object, name: str, shape: tuple[int, ...] | None = None) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float, copy=True)
    except (TypeError, ValueError):
        raise InputError(f"Log.{name}: expected a numeric array, got {type(value).__name__}") from None
    if shape is not None and arr.shape != shape:
        raise InputError(f"Log.{name}: expected shape {shape}, got {arr.shape}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Log:
    """One run of the stage, SI units, validated when made.

    Parameters
    ----------
    t : (n,) array
        Time [s], finite and strictly increasing, n >= 2.
    x : (4, n) array
        States: air gap x1 [m], its rate x2 [m/s], horizontal position x3 [m], its rate x4 [m/s].
        x1 and x3 are finite; x2 and x4 are either finite or all NaN (not measured).
    u : (2, n) array
        Inputs u1 = i_q [A], u2 = i_d [A], finite.
    metadata : mapping of str to str
        The ``# key: value`` lines of the file (stored read-only).
    source : str
        Where the log came from (a path).
    notes : tuple of str
        What reading did beyond copying numbers: ignored columns, conversions, slicing.
    currents_measured : bool
        True when the currents were measured (metadata ``currents: measured``); otherwise they
        are the commanded values (SPEC 2).

    A metadata entry ``payload_kg`` (:data:`PAYLOAD_KEY`) declares a mass carried on the platform
    (:attr:`payload`).

    The arrays are copies and read-only. Invalid values raise ``ValueError`` naming the field.
    """

    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    metadata: Mapping[str, str] = field(default_factory=dict)
    source: str = ""
    notes: tuple[str, ...] = ()
    currents_measured: bool = False

    def __post_init__(self) -> None:
        t = _readonly(self.t, "t")
        if t.ndim != 1:
            raise InputError(f"Log.t: expected a 1-D array (n,), got shape {t.shape}")
        n = t.size
        if n < 2:
            raise InputError(f"Log.t: need at least 2 samples, got {n}")
        x = _readonly(self.x, "x", (4, n))
        u = _readonly(self.u, "u", (2, n))
        if not np.all(np.isfinite(t)):
            k = int(np.flatnonzero(~np.isfinite(t))[0])
            raise InputError(f"Log.t: sample {k} is {float(t[k])!r}; time must be finite")
        steps = np.diff(t)
        if np.any(steps <= 0):
            k = int(np.flatnonzero(steps <= 0)[0]) + 1
            raise InputError(
                f"Log.t: time must increase strictly; t[{k}] = {float(t[k])!r} s after "
                f"t[{k - 1}] = {float(t[k - 1])!r} s"
            )
        for row, name in enumerate(STATE_COLUMNS):
            finite = np.isfinite(x[row])
            if name in ("x2", "x4") and not np.any(finite) and np.all(np.isnan(x[row])):
                continue  # not measured
            if not np.all(finite):
                k = int(np.flatnonzero(~finite)[0])
                raise InputError(
                    f"Log.x: row {row} ({name}) has {float(x[row, k])!r} at sample {k}; x1, x3 must be "
                    "finite and x2, x4 either finite or all NaN"
                )
        if not np.all(np.isfinite(u)):
            row, k = (int(i[0]) for i in np.nonzero(~np.isfinite(u)))
            raise InputError(f"Log.u: row {row} (u{row + 1}) has {float(u[row, k])!r} at sample {k}")
        metadata = dict(self.metadata)
        for key, value in metadata.items():
            if not isinstance(key, str) or not isinstance(value, str):
                raise InputError(f"Log.metadata: keys and values must be str, got {key!r}: {value!r}")
        if PAYLOAD_KEY in metadata and (problem := payload_problem(metadata[PAYLOAD_KEY])):
            raise InputError(f"Log.metadata[{PAYLOAD_KEY!r}]: {problem}")
        notes = tuple(self.notes)
        if not all(isinstance(note, str) for note in notes):
            raise InputError(f"Log.notes: expected a tuple of str, got {self.notes!r}")
        if not isinstance(self.currents_measured, (bool, np.bool_)):
            raise InputError(f"Log.currents_measured: expected a bool, got {self.currents_measured!r}")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "u", u)
        object.__setattr__(self, "metadata", types.MappingProxyType(metadata))
        object.__setattr__(self, "source", str(self.source))
        object.__setattr__(self, "notes", notes)
        object.__setattr__(self, "currents_measured", bool(self.currents_measured))

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.t.size)

    @property
    def payload(self) -> float:
        """[kg] Mass carried on the platform beyond the model's movers during the run (metadata
        ``payload_kg``; 0 when the log does not say)."""
        return float(self.metadata.get(PAYLOAD_KEY, 0.0))

    @property
    def sample_time(self) -> float:
        """Median time step [s]."""
        return float(np.median(np.diff(self.t)))

    @property
    def duration(self) -> float:
        """t[-1] - t[0] [s]."""
        return float(self.t[-1] - self.t[0])

    @property
    def recorded(self) -> float:
        """The time the log covers [s]: its samples times the sample time (a 10 s recording at
        1 kHz has 10000 samples, from t = 0 to 9.999 s). What a minimum length is held to: held to
        :attr:`duration`, a 10 s log was refused as "10.0 s is too short: need at least 10 s"."""
        return self.n * self.sample_time

    @property
    def states_measured(self) -> tuple[bool, bool, bool, bool]:
        """For x1..x4, whether the row holds data (False: x2 or x4 was not in the log, NaN row)."""
        return tuple(bool(np.all(np.isfinite(row))) for row in self.x)  # type: ignore[return-value]

    def index_slice(self, start: int | None = None, stop: int | None = None) -> Log:
        """Samples ``start:stop`` (Python slice semantics) as a new Log with a note saying so.

        Parameters
        ----------
        start, stop : int or None
            Sample indices.

        Returns
        -------
        Log
        """
        rows = range(self.n)[slice(start, stop)]
        if len(rows) < 2:
            raise InputError(
                f"Log.index_slice: samples [{start}:{stop}] of a {self.n}-sample log leave "
                f"{len(rows)} sample(s); need at least 2"
            )
        sel = slice(rows.start, rows.stop)
        note = f"samples {rows.start}..{rows.stop - 1} of {self.n} (index_slice)"
        return dataclasses.replace(
            self, t=self.t[sel], x=self.x[:, sel], u=self.u[:, sel], notes=(*self.notes, note)
        )

    def currents_advanced(self, delay: float) -> Log:
        """The log with its currents moved ``delay`` seconds earlier against the positions, as a new
        Log with a note saying so: for currents that were logged late (a logger that stamps them
        after the positions they acted on, a filter on measured currents; ``diagnose`` reports
        such a log's "currents' timing"). Each current at t is the logged one at t + delay (linear
        interpolation between samples, exact for whole samples); the last samples, which have no
        current that late, are left out.

        Parameters
        ----------
        delay : float
            [s], at least 0 and under a tenth of the log.

        Returns
        -------
        Log
        """
        if not (math.isfinite(delay) and 0.0 <= delay < 0.1 * self.duration):
            raise InputError(
                f"{self.source}: currents late by {delay!r} s: expected a delay of at least 0 and under a "
                f"tenth of the log ({0.1 * self.duration:.3g} s)"
            )
        if delay == 0.0:
            return self
        samples = round(delay / self.sample_time)
        if samples and abs(delay - samples * self.sample_time) <= 1e-6 * self.sample_time:
            keep = np.arange(self.n) < self.n - samples  # whole samples: the logged values themselves
            u = self.u[:, samples:]
        else:
            keep = self.t + delay <= self.t[-1]
            u = np.vstack([np.interp(self.t[keep] + delay, self.t, row) for row in self.u])
        t = self.t[keep]
        note = f"currents moved {delay * 1e3:.3g} ms earlier against the positions (logged late)"
        return dataclasses.replace(self, t=t, x=self.x[:, keep], u=u, notes=(*self.notes, note))

    def time_slice(self, t_start: float, t_stop: float) -> Log:
        """Samples with ``t_start <= t < t_stop`` as a new Log (e.g. a held-out part).

        Parameters
        ----------
        t_start, t_stop : float
            [s], ``t_start < t_stop``.

        Returns
        -------
        Log
        """
        if not t_start < t_stop:
            raise InputError(f"Log.time_slice: need t_start < t_stop, got {t_start!r}, {t_stop!r}")
        start = int(np.searchsorted(self.t, t_start, side="left"))
        stop = int(np.searchsorted(self.t, t_stop, side="left"))
        if stop - start < 2:
            raise InputError(
                f"Log.time_slice: [{t_start!r}, {t_stop!r}) s holds {stop - start} sample(s) of a log "
                f"spanning [{float(self.t[0])!r}, {float(self.t[-1])!r}] s; need at least 2"
            )
        note = f"t in [{t_start!r}, {t_stop!r}) s (time_slice)"
        return dataclasses.replace(
            self,
            t=self.t[start:stop],
            x=self.x[:, start:stop],
            u=self.u[:, start:stop],
            notes=(*self.notes, note),
        )

    def columns(self) -> dict[str, np.ndarray]:
        """The log as named columns (the file's names): t, x1, [x2], x3, [x4], u1, u2."""
        out = {"t": self.t}
        for row, name in enumerate(STATE_COLUMNS):
            if self.states_measured[row]:
                out[name] = self.x[row]
        out["u1"], out["u2"] = self.u[0], self.u[1]
        return out
