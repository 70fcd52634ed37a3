"""Properties of ``maglev_oc.identification`` from the survivors of the seed-42 mutation run:

* a multisine takes one amplitude per harmonic: harmonics and amplitudes of different lengths are
  refused with an ``InputError`` that says so and shows the harmonics given, rather than failing
  inside NumPy's broadcasting or building a signal from one amplitude stretched over several tones;
* :class:`MultipleShooting` refuses a ``segment_duration`` that is not a positive, finite number of
  seconds, with a message naming the option, what it must be and the value given;
* :func:`load_logs` refuses an empty list of paths with a message saying no log files were given.

Two other survivors of the sample are equivalent and have no test here: the stopping test of the
constrained Gauss-Newton (``<`` against ``<=`` at 1000 x tolerance) and the integer type of the
multiple-shooting column indices (SciPy casts float indices to its own index type).
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from maglev_oc.data.log import Log
from maglev_oc.errors import InputError
from maglev_oc.identification.design import multisine
from maglev_oc.identification.output_error import MultipleShooting
from maglev_oc.identification.pipeline import load_logs


# --- multisine: one amplitude per harmonic ---------------------------------------------------------------
@pytest.mark.parametrize(
    ("harmonics", "amplitudes"),
    [
        ([1, 2, 3], [1.0, 0.5]),  # fewer amplitudes: NumPy cannot broadcast (2,) against (3,)
        ([1, 2, 3], [1.0]),  # one amplitude: NumPy would broadcast it over the three tones
        ([2], [1.0, 0.5]),  # more amplitudes than harmonics: would broadcast the one tone
    ],
)
def test_multisine_refuses_harmonics_and_amplitudes_of_different_lengths(harmonics, amplitudes):
    """The docstring's sum_k a_k sin(2 pi h_k t / T + phi_k) pairs each harmonic with one amplitude;
    a mismatch is the user's mistake and the message says what is expected and shows the harmonics."""
    expected = "harmonics must be distinct positive integers, one per amplitude, got " + repr(harmonics)
    with pytest.raises(InputError, match=re.escape(expected)):
        multisine(harmonics, amplitudes)


def test_multisine_returns_one_phase_per_harmonic():
    """The accepted case beside the refused ones: as many phases as harmonics, and a finite crest
    factor of at least 1 (the peak of a signal is at least its RMS)."""
    phases, crest = multisine([1, 2, 3], [1.0, 0.5, 0.25])
    assert phases.shape == (3,)
    assert math.isfinite(crest) and crest >= 1.0


# --- multiple shooting: the segment length ---------------------------------------------------------------
@pytest.fixture(scope="module")
def still_log() -> Log:
    """0.5 s at 1 kHz, the stage held at a 20 mm gap: long enough to cut into segments."""
    t = np.arange(500) / 1000.0
    x = np.vstack([np.full(t.size, 20e-3), np.zeros(t.size), np.zeros(t.size), np.zeros(t.size)])
    return Log(t, x, np.ones((2, t.size)), source="still.csv")


@pytest.mark.parametrize("segment", [0.0, -0.05, math.nan, math.inf])
def test_multiple_shooting_refuses_a_segment_that_is_not_a_positive_duration(model, still_log, segment):
    """A segment of zero, negative, NaN or infinite length cannot cut a log: refused when the problem
    is made, the message naming the option, that it must be positive, its unit and the value."""
    expected = f"segment_duration must be positive [s], got {segment!r}"
    with pytest.raises(InputError, match=re.escape(expected)):
        MultipleShooting(still_log, model, segment_duration=segment)


# --- load_logs: nothing to load --------------------------------------------------------------------------
@pytest.mark.parametrize("paths", [[], ()])
def test_load_logs_refuses_an_empty_list_saying_no_files_were_given(paths):
    """An empty selection (a shell glob that matched nothing) is refused when the logs are loaded, the
    message saying that no log files were given."""
    with pytest.raises(InputError, match="no log files given"):
        load_logs(paths)
