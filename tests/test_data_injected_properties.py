"""Properties of the log layer that small injected bugs break (issue 21).

A reviewer injects one plausible bug at a time (a wrong sign, comparison or index, an ignored
option, a dropped validation) into ``maglev_oc/data/``; the quick suite must then fail. The
cases here were found by trying such bugs and keeping those no other test caught. Each test
checks a property the SPEC 2 log layer must have, not the text of one line:

- the plausibility limits (gap, horizontal position, currents) are limits on the magnitude: a
  value in millimetres or milliamperes is refused whatever its sign, naming line and column;
- time must increase strictly both when a file is read and when a :class:`Log` is made: a
  repeated time stamp is refused (the derivative filters divide by the step);
- the options of :func:`read_log` and :func:`check_excitation` act, in the documented
  direction (a note appears exactly when the disagreement exceeds ``transform_tolerance``; a
  signal is flat exactly when its standard deviation is at most its resolution);
- a .mat log's vectors must all have one length, and a numeric metadata field is kept to 17
  significant digits (a float64 read back exactly);
- the d-q transform and its inverse round-trip at any position, and the transform is the
  rotation the papers give (an independent numpy evaluation of eq. (2) of paper 001).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io
from numpy.testing import assert_allclose

from maglev_oc.data.logs import (
    MAX_AIR_GAP,
    MAX_CURRENT,
    MAX_HORIZONTAL_POSITION,
    Log,
    LogError,
    check_excitation,
    inputs_to_phase_currents,
    phase_currents_to_inputs,
    read_log,
)
from maglev_oc.model.parameters import StageParameters

TAU = StageParameters().pole_pitch
META = ("# sample_rate_hz: 1000", "# units: SI")  # header on line 3, data row i on line 4 + i
N = 600


def _signals(n: int = N, dt: float = 1e-3) -> dict[str, np.ndarray]:
    """A plausible run: gap around 20 mm, a few mm of motion, currents of a few A."""
    t = np.arange(n) * dt
    return {
        "t": t,
        "x1": 0.020 + 0.002 * np.sin(2 * np.pi * 1.3 * t),
        "x3": 0.010 * np.sin(2 * np.pi * 0.7 * t + 0.4),
        "u1": 0.8 * np.sin(2 * np.pi * 2.1 * t),
        "u2": 1.5 + 0.4 * np.cos(2 * np.pi * 0.9 * t),
    }


def _write_csv(path: Path, columns: dict[str, np.ndarray]) -> Path:
    table = np.column_stack(list(columns.values()))
    rows = (",".join(repr(float(v)) for v in row) for row in table)
    path.write_text("\n".join([*META, ",".join(columns), *rows]) + "\n")
    return path


# --- plausibility limits are on the magnitude ---------------------------------------------------
@pytest.mark.parametrize(
    ("column", "value", "limit"),
    [
        ("x1", 20.0, MAX_AIR_GAP),  # a 20 mm gap written in millimetres
        ("x3", 60.0, MAX_HORIZONTAL_POSITION),  # +60 mm
        ("x3", -60.0, MAX_HORIZONTAL_POSITION),  # -60 mm: the travel is symmetric (+-50 mm)
        ("u1", -1500.0, MAX_CURRENT),  # -1.5 A in milliamperes
        ("u2", 1500.0, MAX_CURRENT),
        ("u2", -1500.0, MAX_CURRENT),
    ],
)
def test_a_value_beyond_its_limit_is_refused_whatever_its_sign(tmp_path: Path, column, value, limit):
    """SPEC 2: values that look like millimetres or milliamperes are refused; the limits are on
    |value| (x3 and the currents take both signs), and the message names line and column."""
    assert abs(value) > limit  # the case is beyond the documented limit
    cols = _signals()
    row = 37
    cols[column] = cols[column].copy()
    cols[column][row] = value
    path = _write_csv(tmp_path / "units.csv", cols)
    with pytest.raises(LogError) as info:
        read_log(path)
    assert info.value.column == column
    assert info.value.line == len(META) + 2 + row
    assert str(info.value).startswith(str(path))


def test_values_just_inside_the_limits_are_read(tmp_path: Path):
    """The other side of the same limits: the largest plausible magnitudes of either sign pass."""
    cols = _signals()
    cols["x3"] = cols["x3"].copy()
    cols["x3"][10] = -0.99 * MAX_HORIZONTAL_POSITION
    cols["u1"] = cols["u1"].copy()
    cols["u1"][11] = -0.99 * MAX_CURRENT
    log = read_log(_write_csv(tmp_path / "edge.csv", cols))
    assert log.x[2, 10] == cols["x3"][10] and log.u[0, 11] == cols["u1"][11]


# --- time must increase strictly -----------------------------------------------------------------
def test_a_repeated_time_stamp_is_refused_by_the_log_and_by_the_reader(tmp_path: Path):
    """Time strictly increasing (SPEC 2; :class:`Log` docstring): a step of exactly zero is as
    wrong as a negative one (the rates are differences divided by the step)."""
    cols = _signals()
    t = cols["t"].copy()
    t[100] = t[99]
    x = np.vstack([cols["x1"], np.full(N, np.nan), cols["x3"], np.full(N, np.nan)])
    u = np.vstack([cols["u1"], cols["u2"]])
    with pytest.raises(ValueError, match=r"t\[100\]"):
        Log(t, x, u)
    cols["t"] = t
    path = _write_csv(tmp_path / "repeat.csv", cols)
    with pytest.raises(LogError) as info:
        read_log(path)
    assert info.value.column == "t" and info.value.line == len(META) + 2 + 100


# --- the options act in the documented direction ------------------------------------------------
def test_transform_tolerance_decides_the_note(tmp_path: Path):
    """``transform_tolerance`` [A]: a note exactly when the logged u differs from the transform
    of ia, ib, ic by more than it. The logged u2 is offset by 0.05 A from the transform."""
    cols = _signals()
    u = np.vstack([cols["u1"], cols["u2"]])
    phases = inputs_to_phase_currents(u, cols["x3"], TAU)
    offset = 0.05  # [A]
    both = {**cols, "u2": cols["u2"] + offset, "ia": phases[0], "ib": phases[1], "ic": phases[2]}
    path = _write_csv(tmp_path / "both.csv", both)

    def differs(log: Log) -> list[str]:
        return [note for note in log.notes if "differs" in note]

    assert differs(read_log(path)) and differs(read_log(path, transform_tolerance=0.01))
    loose = read_log(path, transform_tolerance=0.1)  # 0.05 A < 0.1 A: within tolerance
    assert differs(loose) == []
    assert_allclose(loose.u[1], cols["u2"] + offset, rtol=0, atol=0)  # the logged u2 is still used
    with pytest.raises(ValueError, match="transform_tolerance"):
        read_log(path, transform_tolerance=0.0)


@pytest.mark.parametrize("name", ["x1", "x3", "u1", "u2"])
def test_each_resolution_option_decides_its_own_signals(name):
    """check_excitation: a signal is constant when its std is at most its resolution; the
    position resolution applies to x1 and x3, the current resolution to u1 and u2. Setting the
    one resolution just above the signal's std (and leaving the other at its default) must make
    exactly that signal flat."""
    cols = _signals()
    x = np.vstack([cols["x1"], np.full(N, np.nan), cols["x3"], np.full(N, np.nan)])
    log = Log(cols["t"], x, np.vstack([cols["u1"], cols["u2"]]))
    base = check_excitation(log)
    std = base.std[name]
    assert std == pytest.approx(float(np.std(cols[name])), rel=1e-12)
    sharing = ("x1", "x3") if name in ("x1", "x3") else ("u1", "u2")
    option = "position_resolution" if name in ("x1", "x3") else "current_resolution"
    below = 0.999 * min(base.std[other] for other in sharing)  # every signal still moves
    assert check_excitation(log, **{option: below}).resolution[name] == below
    with pytest.raises(LogError) as info:
        check_excitation(log, **{option: 1.001 * std})
    assert info.value.column in sharing
    assert f"{name} std" in str(info.value)
    for bad in (0.0, -1e-5, float("nan")):
        with pytest.raises(ValueError, match=option):
            check_excitation(log, **{option: bad})


# --- .mat specifics ------------------------------------------------------------------------------
def test_mat_vectors_of_different_lengths_are_refused(tmp_path: Path):
    """Every column of a log is one sample per time: a shorter vector is refused naming it."""
    cols = _signals()
    payload = {name: cols[name] for name in ("t", "x1", "x3", "u1", "u2")}
    payload["u1"] = payload["u1"][:-3]
    scipy.io.savemat(tmp_path / "short.mat", payload)
    with pytest.raises(LogError) as info:
        read_log(tmp_path / "short.mat")
    assert info.value.column == "u1" and "597" in str(info.value)


def test_mat_numeric_metadata_keeps_every_digit(tmp_path: Path):
    """mat_reader docstring: numbers in the metadata struct are written with 17 significant
    digits, which round-trips any float64 exactly."""
    cols = _signals()
    value = 0.1 + 0.2  # 0.30000000000000004: needs all 17 digits
    payload = {name: cols[name] for name in ("t", "x1", "x3", "u1", "u2")}
    payload["metadata"] = {"sample_rate_hz": 1000.0, "gain": value}
    scipy.io.savemat(tmp_path / "meta.mat", payload)
    log = read_log(tmp_path / "meta.mat")
    assert float(log.metadata["gain"]) == value


# --- the d-q transform ---------------------------------------------------------------------------
def test_dq_transform_is_the_papers_rotation_and_round_trips():
    """Eq. (2) of paper 001 evaluated independently as a matrix product, and the inverse:
    inputs -> balanced phases -> inputs is the identity (float round-off, 1e-12 A on A-sized
    currents), at positions over several pole pitches and both signs."""
    rng = np.random.default_rng(21)
    n = 200
    x3 = rng.uniform(-3 * TAU, 3 * TAU, n)
    u = rng.uniform(-5.0, 5.0, (2, n))
    phases = inputs_to_phase_currents(u, x3, TAU)
    assert_allclose(phases.sum(axis=0), 0.0, atol=1e-12)  # star-connected stator: balanced
    assert_allclose(phase_currents_to_inputs(*phases, x3, TAU), u, rtol=0, atol=1e-12)
    theta = np.pi * x3 / TAU
    shifts = np.array([0.0, -2 * np.pi / 3, 2 * np.pi / 3])
    i_d = 2 / 3 * np.einsum("kn,kn->n", np.cos(theta[None] + shifts[:, None]), phases)
    i_q = -2 / 3 * np.einsum("kn,kn->n", np.sin(theta[None] + shifts[:, None]), phases)
    assert_allclose(np.vstack([i_q, i_d]), u, rtol=0, atol=1e-12)
    # one pole pitch shifts the electrical angle by pi: the phase currents change sign
    assert_allclose(inputs_to_phase_currents(u, x3 + TAU, TAU), -phases, rtol=0, atol=1e-12)
