"""Properties of the stage model and the log layer that the second hand-injected round found
untested (issue 21; the round is summed up in bench/README.md, "Second hand-injected round").

A reviewer injects one plausible bug at a time into ``maglev_oc/model/`` and ``maglev_oc/data/``;
the quick suite must then fail. Each test checks what a user relies on against an independent
computation (numpy on the model's L1..L4, the platform's own state equation, a hand count):

- :meth:`StageModel.with_constants` changes the constants only: the field model (closed form or
  the papers' polynomial) and so the shape functions l1..l4 are those of the model it came from;
- :func:`equilibrium` refuses an equilibrium whose current exceeds ``current_limit`` in
  magnitude, of either sign (beyond the zero-current gap the holding current is negative);
- :func:`gap_for_current` raises :class:`NoEquilibriumError` for a current just outside what
  its bracket holds, and inverts the equilibrium current just inside it;
- the feedback transformation's feasibility margin is R / (4 L4) in m/s^2, the room left in v2:
  R vanishes when v2 grows by the margin (for any v1, v2; each at its own place), and the clipped
  currents are the physical root where R >= 0 and the vertex -L3 / (2 L4) of the quadratic (the
  closest realisable i_d) where R < 0;
- the microstepper's maximum-margin allocation realises the requested accelerations on the
  platform's own state equation, balances the two pairs' magnitudes (the minimax of two
  monotone functions) below the minimum-norm peak, and ``peak`` is the larger pair magnitude.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.data.logs import inputs_to_phase_currents, read_log, write_log_arrays
from maglev_oc.errors import InputError
from maglev_oc.model.allocation import MicrostepperTransformation
from maglev_oc.model.equilibrium import (
    NoEquilibriumError,
    equilibrium,
    equilibrium_currents,
    gap_for_current,
)
from maglev_oc.model.parameters import PAPER_CONSTANTS
from maglev_oc.model.platform import PlatformModel, microstepper
from maglev_oc.model.stage import StageModel
from tests.test_data_injected_properties import N, _signals, _write_csv
from tests.test_logs import META, TAU, _bad, _csv_text, _line

GAPS = np.linspace(5e-3, 35e-3, 13)  # the papers' field-fit range [m]


# --- the stage model ---------------------------------------------------------------------------
def test_with_constants_keeps_the_field_model_and_the_shape_functions(model):
    """A model made by ``with_constants`` has the field model of the one it came from and the
    same shape functions bit for bit (they do not depend on C); its L are the new C times them
    (rtol 1e-14: one product of doubles)."""
    other = next(c for c in PAPER_CONSTANTS.values() if c != model.constants)
    poly = StageModel(model.params, model.constants, "polynomial")
    for base in (model, poly):
        new = base.with_constants(other)
        assert new.field_model == base.field_model and new.constants == other
        assert_allclose(
            np.asarray(new.shape.map(GAPS.size)(GAPS[None, :])),
            np.asarray(base.shape.map(GAPS.size)(GAPS[None, :])),
            rtol=0,
            atol=0,
        )
        shapes = np.asarray(base.shape.map(GAPS.size)(GAPS[None, :]))
        assert_allclose(new.coefficients(GAPS), np.asarray(other.as_array())[:, None] * shapes, rtol=1e-14)
    # the two field models differ inside the fit by more than rounding (3.8e-6 relative, measured
    # in tests/test_model_field_properties.py), so a dropped field model is seen
    b_poly = np.asarray(poly.with_constants(other).pm_field.map(GAPS.size)(GAPS[None, :])).ravel()
    b_closed = np.asarray(model.pm_field.map(GAPS.size)(GAPS[None, :])).ravel()
    assert np.max(np.abs(b_poly / b_closed - 1)) > 1e-8


def test_equilibrium_current_limit_is_on_the_magnitude(model):
    """Above the zero-current gap (about 24.3 mm) the holding current is negative (measured
    -4.85 A at 40 mm, +7.24 A at 6 mm): a limit below |i_d| refuses it whatever its sign, and a
    limit above accepts it with the current of :func:`equilibrium_currents`."""
    for gap in (6e-3, 40e-3):
        current = float(equilibrium_currents(model, [gap]).current[0])
        with pytest.raises(NoEquilibriumError, match="beyond"):
            equilibrium(model, gap, current_limit=0.9 * abs(current))
        op = equilibrium(model, gap, current_limit=1.1 * abs(current))
        assert op.u[1] == current and op.u[0] == 0.0
    assert float(equilibrium_currents(model, [40e-3]).current[0]) < 0


@pytest.mark.parametrize("gap", [math.inf, -0.02, 0.0, math.nan])
def test_an_impossible_gap_is_refused_naming_it(model, gap):
    """A gap that is not positive and finite is refused, and the message shows that gap (an
    infinite one too, which a filter on gap > 0 alone would leave out: "got []")."""
    with pytest.raises(InputError, match="positive and finite") as err:
        equilibrium_currents(model, np.array([0.02, gap]))
    assert str(err.value).endswith(f"got {gap:g}")


def test_gap_for_current_refuses_just_outside_its_bracket(model):
    """The bracket 5-35 mm holds currents between i(35 mm) and i(5 mm); 10 mA beyond either end
    (a residual product of a few 0.01 A^2, far below 1) is refused as NoEquilibriumError, 10 mA
    inside is found, the equilibrium current there within 1e-9 A (brentq's xtol 1e-12 m times a
    slope of about 0.4 A/mm)."""
    lo_i, hi_i = equilibrium_currents(model, [35e-3, 5e-3]).current
    for current in (hi_i + 0.01, lo_i - 0.01):
        with pytest.raises(NoEquilibriumError, match="no gap"):
            gap_for_current(model, float(current))
    for current in (hi_i - 0.01, lo_i + 0.01):
        gap = gap_for_current(model, float(current))
        assert 5e-3 < gap < 35e-3
        assert_allclose(equilibrium_currents(model, [gap]).current[0], current, rtol=0, atol=1e-9)


# --- the feedback transformation ---------------------------------------------------------------
def _L(model, x1):
    return [np.asarray(a).ravel() for a in model.L.map(x1.size)(x1[None, :])]


def test_the_margin_is_the_room_left_in_v2(model, transformation):
    """margin = R / (4 L4) with R = L3^2 - 4 L4 (L4 (v1 / L1)^2 + L2 - G + v2) evaluated here in
    numpy, and R at v2 + margin is zero (relative to L3^2: 1e-9, round-off of a difference of
    terms of size L3^2). v1 and v2 differ at every point, and over gaps, signs and sizes."""
    rng = np.random.default_rng(221)
    n = 40
    x1 = rng.uniform(8e-3, 32e-3, n)
    v1 = rng.uniform(-20.0, 20.0, n)
    v2 = rng.uniform(-20.0, 300.0, n)  # margins at v2 = 0 are 25-280 m/s^2 here
    L1, L2, L3, L4 = _L(model, x1)
    R = L3**2 - 4 * L4 * (L4 * (v1 / L1) ** 2 + L2 - model.params.gravity + v2)
    assert_allclose(transformation.discriminant(x1, v1, v2), R, rtol=1e-12, atol=1e-12 * np.max(L3**2))
    margin = transformation.feasibility_margin(x1, v1, v2)
    assert_allclose(margin, R / (4 * L4), rtol=1e-12, atol=1e-12)
    assert np.any(margin > 0) and np.any(margin < 0)  # both sides of the boundary are sampled
    at_edge = transformation.discriminant(x1, v1, v2 + margin)
    assert_allclose(at_edge, 0.0, rtol=0, atol=1e-9 * np.max(L3**2))


def test_clipped_currents_are_the_root_inside_and_the_vertex_outside(model, transformation):
    """Where R >= 0 the clipped currents are the transformation's (the physical root); where
    R < 0 (no real root) i_d is the vertex -L3 / (2 L4), the current that comes closest to the
    requested v2, and i_q is -v1 / L1 in both cases (rtol 1e-12: a few operations)."""
    x1 = np.full(6, 20e-3)
    v1 = np.array([0.0, 5.0, -5.0, 0.0, 40.0, -40.0])
    room = float(transformation.feasibility_margin(20e-3, 0.0, 0.0))  # about 35 m/s^2
    v2 = room * np.array([0.0, -0.5, 0.5, 2.0, 1.5, 0.9])
    R = transformation.discriminant(x1, v1, v2)
    assert np.any(R > 0) and np.any(R < 0)
    L1, _, L3, L4 = _L(model, x1)
    for k in range(x1.size):
        u, r = (np.asarray(a).ravel() for a in transformation.currents_clipped(x1[k], [v1[k], v2[k]]))
        assert_allclose(r[0], R[k], rtol=1e-12)
        assert_allclose(u[0], -v1[k] / L1[k], rtol=1e-12)
        if R[k] >= 0:
            exact = np.asarray(transformation.currents(x1[k], [v1[k], v2[k]])).ravel()
            assert_allclose(u, exact, rtol=1e-12)
            assert_allclose(u[1], (-L3[k] - np.sqrt(R[k])) / (2 * L4[k]), rtol=1e-12)
        else:
            assert_allclose(u[1], -L3[k] / (2 * L4[k]), rtol=1e-12)


# --- the microstepper's allocation -------------------------------------------------------------
@pytest.fixture(scope="module")
def stepper():
    platform = microstepper()
    return MicrostepperTransformation(platform), PlatformModel(platform)


def test_maximum_margin_realises_v_and_balances_the_pairs(stepper):
    """For requests that load the two pairs unequally (|v_x| != |v_y|): the maximum-margin
    currents give the platform the accelerations v on its own state equation (1e-9 relative, as
    for the minimum norm in tests/test_model_seed35_properties.py), both pairs carry the same
    magnitude (the minimax of two monotone functions of the split; 1e-4 A, the bounded Brent
    search's tolerance of 1e-5 in i_dA times a slope below 10), and that peak is below the
    minimum-norm one by more than that tolerance (measured 7 mA at v = (3, -2, 1) m/s^2)."""
    fl, pm = stepper
    rng = np.random.default_rng(222)
    for v in ([3.0, -2.0, 1.0], [0.0, 4.0, -1.0], *rng.uniform(-4.0, 4.0, (4, 3))):
        v = np.asarray(v)
        gap = 0.02
        plain, best = fl.allocate(gap, v), fl.allocate(gap, v, "maximum_margin")
        assert best.method == "maximum_margin" and best.defined
        u = best.currents
        x = np.array([0.0, 0.0, 0.0, 0.0, gap, 0.0])
        acc = np.asarray(pm.dynamics(x, u)).ravel()[1::2]
        assert_allclose(acc, v, rtol=1e-9, atol=1e-9 * 9.81)
        pair = np.hypot(u[[0, 2]], u[[1, 3]])
        assert_allclose(pair[0], pair[1], rtol=0, atol=1e-4)
        assert best.peak == pytest.approx(max(pair), abs=1e-12)
        assert plain.peak == pytest.approx(max(np.hypot(plain.currents[[0, 2]], plain.currents[[1, 3]])))
        assert best.peak <= plain.peak + 1e-12
    # the first request: the pairs' thrusts differ by 0.9 A, the balance gains 7 mA (measured)
    assert (
        fl.allocate(0.02, [3.0, -2.0, 1.0], "maximum_margin").peak
        < fl.allocate(0.02, [3.0, -2.0, 1.0]).peak - 1e-3
    )


# --- the log layer's sampling checks -----------------------------------------------------------
def test_jitter_is_measured_in_steps(tmp_path):
    """A time stamp 20 % of a step off the uniform grid (0.2 ms at 1 kHz: steps of 1.2 and 0.8
    ms, no gap by GAP_FACTOR 1.5) is refused naming its line and column; one 5 % off (half of
    JITTER_TOLERANCE = 10 %) is read. The tolerance scales with the step: at 100 Hz the same 20 %
    is refused too."""
    for dt, meta in ((1e-3, META), (1e-2, ("# sample_rate_hz: 100", "# units: SI"))):
        for shift, refused in ((0.2, True), (0.05, False)):

            def edit(rows, shift=shift, dt=dt):
                rows[300][0] = repr(300 * dt + shift * dt)

            text = _csv_text(meta=meta, n=600, dt=dt, edit=edit)
            if refused:
                err = _bad(tmp_path, text)
                assert "irregular sampling" in str(err)
                assert f"line {_line(300, meta)}, column 1 ('t')" in str(err)
            else:
                path = tmp_path / "ok.csv"
                path.write_text(text)
                assert read_log(path).t.size == 600


@pytest.mark.parametrize(
    ("stated", "refused"), [("1020", True), ("980", True), ("1005", False), ("995", False)]
)
def test_sample_rate_tolerance_is_one_percent(tmp_path, stated, refused):
    """``sample_rate_hz`` 2 % off the 1 kHz of the time column is refused at its metadata line;
    0.5 % off is read (SAMPLE_RATE_TOLERANCE = 1 %)."""
    meta = (f"# sample_rate_hz: {stated}", "# units: SI")
    text = _csv_text(meta=meta)
    if refused:
        err = _bad(tmp_path, text)
        assert "line 1 (metadata 'sample_rate_hz')" in str(err) and "disagrees" in str(err)
    else:
        path = tmp_path / "ok.csv"
        path.write_text(text)
        assert read_log(path).metadata["sample_rate_hz"] == stated


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
