"""Properties of writing logs and of the phase-current transform (``maglev_oc.data``), checked
against an independent evaluation of eq. (2) of paper 001 and files read back:

- the d-q transform is the papers' rotation and round-trips at any position;
- a note appears exactly when the logged inputs and the transformed phase currents disagree by
  more than ``transform_tolerance``, and a zero-sequence current gets a note where it peaks;
- a write that fails midway leaves the previous file; the written header describes the data, not
  stale metadata; .mat logs are written compressed and read back unchanged.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.data.logs import (
    Log,
    inputs_to_phase_currents,
    phase_currents_to_inputs,
    read_log,
    write_log,
    write_log_arrays,
)
from tests._log_files import _signals, _write_csv
from tests.test_logs import TAU

N = 600


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


def test_a_zero_sequence_current_gets_a_note_where_it_peaks(tmp_path):
    """Balanced phase currents (from :func:`inputs_to_phase_currents`, sum about 1e-16 A) read
    without a note about ia + ib + ic; 0.5 A added to ia on one row (a star point that leaks, or
    a phase logged with an offset) gives a note naming that row's line and the 0.5 A, however
    small the sum is on every other row."""
    sig = _signals()
    phases = inputs_to_phase_currents(np.vstack([sig["u1"], sig["u2"]]), sig["x3"], TAU)
    columns = {"t": sig["t"], "x1": sig["x1"], "x3": sig["x3"]}
    columns |= dict(zip(("ia", "ib", "ic"), phases, strict=True))
    log = read_log(_write_csv(tmp_path / "balanced.csv", columns))
    assert not any("ia + ib + ic" in note for note in log.notes)
    columns["ia"] = columns["ia"].copy()
    columns["ia"][200] += 0.5
    log = read_log(_write_csv(tmp_path / "leak.csv", columns))
    notes = [note for note in log.notes if "ia + ib + ic" in note]
    assert len(notes) == 1 and "reaches 0.5 A" in notes[0] and f"line {4 + 200}" in notes[0]


# --- writing -----------------------------------------------------------------------------------
def test_a_write_that_fails_midway_leaves_the_previous_file(tmp_path, monkeypatch):
    """The text is written to a temporary file renamed onto the target only when complete: a
    write that stops half-way (a full disk) leaves the previous file as it was and no stray
    temporary file beside it."""
    sig = _signals()
    x = np.vstack([sig["x1"], np.full(N, np.nan), sig["x3"], np.full(N, np.nan)])
    u = np.vstack([sig["u1"], sig["u2"]])
    target = tmp_path / "out.csv"
    target.write_text("previous")
    original = Path.write_text

    def half_then_full(self, data, *args, **kwargs):
        original(self, data[: len(data) // 2], *args, **kwargs)
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(Path, "write_text", half_then_full)
    with pytest.raises(OSError):
        write_log_arrays(target, sig["t"], x, u)
    monkeypatch.undo()
    assert target.read_text() == "previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.csv"]


def test_the_written_header_describes_the_data_not_stale_metadata(tmp_path):
    """Metadata carried over from another log (1 kHz, measured currents) does not override what
    the writer derives from the data and the flag: 500 Hz arrays with ``currents_measured=False``
    are written as ``sample_rate_hz: 500`` and ``currents: commanded``, and read back as such
    (a stale 1000 would be refused by the reader, 1 % tolerance)."""
    sig = _signals(dt=2e-3)
    x = np.vstack([sig["x1"], np.full(N, np.nan), sig["x3"], np.full(N, np.nan)])
    u = np.vstack([sig["u1"], sig["u2"]])
    stale = {"sample_rate_hz": "1000", "currents": "measured", "units": "SI", "rig": "B"}
    for name in ("out.csv", "out.mat"):
        path = write_log_arrays(tmp_path / name, sig["t"], x, u, metadata=stale, currents_measured=False)
        log = read_log(path)
        assert not log.currents_measured
        assert float(log.metadata["sample_rate_hz"]) == pytest.approx(500.0, rel=1e-9)
        assert log.metadata["rig"] == "B"


DT = 1e-3


def test_mat_logs_are_written_compressed(tmp_path):
    """A .mat log is written with zlib compression (scipy's do_compression): a slowly varying
    60 s log at 1 kHz takes less than half of its raw 8-byte doubles. Read back, it is the same log."""
    n = 60_000
    t = np.arange(n) * DT
    rows = np.vstack([t, 0.02 + 0 * t, np.round(np.sin(t) * 1e3) / 1e5, 0 * t, 1.5 + 0 * t])
    csv = tmp_path / "run.csv"
    csv.write_text(
        "# sample_rate_hz: 1000\nt,x1,x3,u1,u2\n" + "\n".join(",".join(map(repr, r)) for r in rows.T.tolist())
    )
    log = read_log(csv)
    out = tmp_path / "run.mat"
    write_log(out, log)
    assert out.stat().st_size < 0.5 * rows.size * 8
    again = read_log(out)
    np.testing.assert_array_equal(again.x, log.x)
    np.testing.assert_array_equal(again.u, log.u)
