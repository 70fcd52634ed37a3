"""Reading a log: CSV or MATLAB .mat by suffix, then the checks of
:mod:`~maglev_oc.data.validation` (SPEC 2). The input file is only ever opened for reading."""

from __future__ import annotations

import math
import os
from pathlib import Path

from maglev_oc.data.csv_reader import read_csv
from maglev_oc.data.log import Log
from maglev_oc.data.mat_reader import read_mat
from maglev_oc.data.validation import TRANSFORM_TOLERANCE, validated
from maglev_oc.errors import InputError
from maglev_oc.model.parameters import StageParameters

__all__ = ["read_log"]


def read_log(
    path: str | os.PathLike,
    *,
    params: StageParameters | None = None,
    min_samples: int = 100,
    min_duration: float = 0.5,
    transform_tolerance: float = TRANSFORM_TOLERANCE,
) -> Log:
    """Read and validate a log (CSV or MATLAB .mat, by suffix; SPEC 2).

    Parameters
    ----------
    path : path-like
        ``.mat`` is read with ``scipy.io.loadmat``; any other suffix as CSV text.
    params : StageParameters, optional
        Supplies the pole pitch tau [m] for the phase-current transform (default Table I).
    min_samples : int
        Fewest samples accepted (default 100).
    min_duration : float
        Shortest duration accepted [s] (default 0.5 s).
    transform_tolerance : float
        [A] When u1, u2 and ia, ib, ic are both present, a larger disagreement gets a note.

    Returns
    -------
    Log
        ``source`` is ``str(path)``; ``notes`` says what was ignored or converted.

    Raises
    ------
    LogError
        The file is not a valid log; the message names the file, line/element and column.
    FileNotFoundError
        No such file.
    """
    if isinstance(min_samples, bool) or not isinstance(min_samples, int) or min_samples < 2:
        raise InputError(f"min_samples must be an integer >= 2, got {min_samples!r}")
    if not (min_duration >= 0 and math.isfinite(min_duration)):
        raise InputError(f"min_duration must be >= 0 [s], got {min_duration!r}")
    if not (transform_tolerance > 0):
        raise InputError(f"transform_tolerance must be positive [A], got {transform_tolerance!r}")
    params = StageParameters() if params is None else params
    path = Path(path)
    source = str(path)
    if not path.is_file():
        raise FileNotFoundError(f"{source}: no such file")
    raw = read_mat(path, source) if path.suffix.lower() == ".mat" else read_csv(path, source)
    return validated(raw, params, min_samples, min_duration, transform_tolerance)
