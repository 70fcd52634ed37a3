"""The errors maglev_oc raises on purpose: one hierarchy, so that a caller (and the command line)
can tell a mistake in the input from a bug in the tool.

:class:`MaglevError` is the base of every error a user can act on: bad input (a log, a parameter
file, an option) or a computation that cannot do what was asked (a solver that fails, a set-point
outside the feasible set). The command line reports these in one line with exit status 2;
anything else is a bug and is reported as one (exit status 1).

The input errors also derive from ``ValueError`` (and the solver error from ``RuntimeError``), so
code that catches those keeps working.
"""

from __future__ import annotations

__all__ = ["InputError", "LogError", "MaglevError", "OutputError", "ParameterError", "SolverError"]


class MaglevError(Exception):
    """Base of the errors a user can act on."""


class InputError(MaglevError, ValueError):
    """A value the user gave is invalid (an option, a set-point, a file)."""


class ParameterError(InputError):
    """A parameter file or field is invalid; the message names the file and the key."""


class OutputError(MaglevError, OSError):
    """An output cannot be written where the user asked (a directory, no permission, a full
    disk); the message names the path the user gave, never a temporary file."""


class SolverError(MaglevError, RuntimeError):
    """A computation could not do what was asked (and says why)."""


class LogError(InputError):
    """A log that cannot be used, with where (file, line or element, column) and what is wrong.

    Attributes
    ----------
    source : str
        The file.
    line : int or None
        1-based line of a CSV file, counting metadata lines (None for .mat and whole-file problems).
    column : str or None
        The column (or MATLAB variable) name, when one is at fault.
    problem : str
        What is wrong, without the location.
    """

    def __init__(
        self,
        source: str,
        problem: str,
        *,
        where: str | None = None,
        line: int | None = None,
        column: str | None = None,
    ) -> None:
        self.source = str(source)
        self.line = line
        self.column = column
        self.problem = problem
        prefix = f"{self.source}: {where}" if where else self.source
        super().__init__(f"{prefix}: {problem}")
