"""Logs of runs on the stage: reading, validating and writing them (SPEC 2).

A log is one run: time, the four states and the two inputs, in SI units,

    t [s];  x = (x1 air gap [m], x2 its rate [m/s], x3 horizontal position [m], x4 its rate [m/s]);
    u = (u1 = i_q [A], u2 = i_d [A]),

held by :class:`Log` with the shapes ``t (n,)``, ``x (4, n)``, ``u (2, n)``. A log that did not
carry the velocities has NaN rows for x2 and x4 (:attr:`Log.states_measured` says which rows
are data); :mod:`maglev_oc.estimation.differentiate` estimates them from x1, x3.

File formats
------------
CSV: any number of metadata lines ``# key: value`` (for example ``# sample_rate_hz: 5000``,
``# units: SI``, ``# currents: measured``), then one header line of comma-separated column
names, then one numeric row per sample. MATLAB ``.mat`` (v5/v7, what ``scipy.io.loadmat``
reads): the same names as top-level vectors and, optionally, a struct ``metadata`` of strings.

Columns: ``t, x1, x3, u1, u2`` are required; ``x2, x4`` are optional; the phase currents
``ia, ib, ic`` [A] may replace ``u1, u2``: then ``(i_q, i_d)`` come from the transform of
eq. (2) of paper 001 (002 Sec. 3) at the logged mover position x3 (:func:`phase_currents_to_inputs`).
If both are present the logged u1, u2 are used and a note records how far they are from the
transform when that exceeds ``transform_tolerance``. Any other column is ignored with a note.
The currents are taken to be the commanded ones unless the metadata says ``currents: measured``.

Validation
----------
Every problem raises :class:`LogError` (a ``ValueError``) whose message names the file, the line
(1-based, counting the metadata lines, as an editor shows it) or the MATLAB variable and element,
the column, and what is wrong: missing columns, duplicate names, non-numeric cells, NaN or inf,
time not strictly increasing, gaps in time (a step above 1.5x the median), a metadata sample rate
the time column contradicts, values that look like millimetres (gap above 0.1 m, |x3| above
0.5 m) or milliamperes (above 100 A), and logs too short to identify anything from. Nothing is
guessed, converted or repaired silently, and the input file is only ever opened for reading.
:func:`check_excitation` refuses logs on which an input or output does not move.

Where each part lives
---------------------
This module is the public entry; the parts are, by concept:
:mod:`~maglev_oc.data.log` (the :class:`Log` type and the column names),
:mod:`~maglev_oc.data.phase_currents` (the d-q transform),
:mod:`~maglev_oc.data.reading` (:func:`read_log`) with :mod:`~maglev_oc.data.csv_reader` and
:mod:`~maglev_oc.data.mat_reader`, :mod:`~maglev_oc.data.validation` (the checks every format
passes), :mod:`~maglev_oc.data.excitation` (:func:`check_excitation`) and
:mod:`~maglev_oc.data.writing` (:func:`write_log`).
"""

from maglev_oc.data.excitation import CURRENT_RESOLUTION, Excitation, check_excitation
from maglev_oc.data.log import (
    INPUT_COLUMNS,
    KNOWN_COLUMNS,
    PHASE_COLUMNS,
    REQUIRED_COLUMNS,
    STATE_COLUMNS,
    Log,
)
from maglev_oc.data.phase_currents import inputs_to_phase_currents, phase_currents_to_inputs
from maglev_oc.data.reading import read_log
from maglev_oc.data.validation import (
    GAP_FACTOR,
    MAX_AIR_GAP,
    MAX_CURRENT,
    MAX_HORIZONTAL_POSITION,
    MAX_SAMPLE_TIME,
    SAMPLE_RATE_TOLERANCE,
    TRANSFORM_TOLERANCE,
)
from maglev_oc.data.writing import write_log, write_log_arrays
from maglev_oc.errors import LogError

__all__ = [
    "CURRENT_RESOLUTION",
    "GAP_FACTOR",
    "INPUT_COLUMNS",
    "KNOWN_COLUMNS",
    "MAX_AIR_GAP",
    "MAX_CURRENT",
    "MAX_HORIZONTAL_POSITION",
    "MAX_SAMPLE_TIME",
    "PHASE_COLUMNS",
    "REQUIRED_COLUMNS",
    "SAMPLE_RATE_TOLERANCE",
    "STATE_COLUMNS",
    "TRANSFORM_TOLERANCE",
    "Excitation",
    "Log",
    "LogError",
    "check_excitation",
    "inputs_to_phase_currents",
    "phase_currents_to_inputs",
    "read_log",
    "write_log",
    "write_log_arrays",
]
