"""Logs of measured or simulated runs: reading, validating, writing (SPEC 2).

:mod:`~maglev_oc.data.logs` is the public entry (its docstring gives the file formats); the
parts live in :mod:`~maglev_oc.data.log`, :mod:`~maglev_oc.data.phase_currents`,
:mod:`~maglev_oc.data.reading` (with :mod:`~maglev_oc.data.csv_reader` and
:mod:`~maglev_oc.data.mat_reader`), :mod:`~maglev_oc.data.validation`,
:mod:`~maglev_oc.data.excitation` and :mod:`~maglev_oc.data.writing`.
"""

from maglev_oc.data.logs import (
    Excitation,
    Log,
    LogError,
    check_excitation,
    read_log,
    write_log,
    write_log_arrays,
)

__all__ = [
    "Excitation",
    "Log",
    "LogError",
    "check_excitation",
    "read_log",
    "write_log",
    "write_log_arrays",
]
