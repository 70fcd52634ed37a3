"""Properties of the residual's trace and the unexplained structure (``maglev_oc.diagnosis.trace``,
``unexplained``), checked against numpy's least squares and binned statistics:

- a bin's standard error is its standard deviation over the root of its count; each axis's
  residual is correlated with its own current's rate at the lag;
- the spectrum's share at a period is the R^2 gain of a sinusoid over a constant whatever the
  residual's mean, and a period longer than the travel is found at its period;
- an unexplained force is its size times its own axis's mass; it is reported only when large
  enough and at most ``max_per_axis`` times per axis, and a periodic probe names its period in mm.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from maglev_oc.diagnosis.selection import SelectionSettings
from maglev_oc.diagnosis.trace import trace
from maglev_oc.diagnosis.unexplained import _Probe, _probes, _unexplained, find_unexplained
from maglev_oc.model.parameters import StageParameters
from maglev_oc.regression.data import prepare
from maglev_oc.regression.design import build_design
from tests.test_diagnosis_trace import sweep_signals
from tests.test_statistics_properties import _log


# --- what the residual depends on --------------------------------------------------------------------
def _traced(seed=5, n=6000, lag=7):
    """A trace of residuals that are the own-axis current rates delayed by ``lag`` samples (the two
    rates independent), at states that sweep the gap and the position."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-3
    x = np.vstack(
        [
            0.02 + 2e-3 * np.sin(2 * np.pi * 0.3 * t),
            rng.normal(0, 0.01, n),
            0.03 * np.sin(2 * np.pi * 0.2 * t),
            rng.normal(0, 0.02, n),
        ]
    )
    du = rng.normal(size=(2, n))
    residual = np.vstack([np.roll(du[1], lag), np.roll(du[0], lag)]) + 0.1 * rng.normal(size=(2, n))
    return x, du, residual


def test_the_binned_standard_error_is_the_sd_over_the_root_of_the_count(model):
    # recomputed with numpy in the trace's own bins (their edges from its centres): std / sqrt(count)
    x, du, residual = _traced()
    tr = trace(x, du, residual, model.params, 1e-3)
    for name, row in (("gap", 0), ("position", 2)):
        b = tr.binned[name]
        half = 0.5 * (b.centers[1] - b.centers[0])
        edges = np.concatenate([b.centers - half, [b.centers[-1] + half]])
        idx = np.clip(np.digitize(x[row], edges) - 1, 0, edges.size - 2)
        for k in np.flatnonzero(b.count >= 20)[:5]:
            sel = idx == k
            assert sel.sum() == b.count[k]
            want = residual[:, sel].std(axis=1) / math.sqrt(sel.sum())
            np.testing.assert_allclose(b.stderr[:, k], want, rtol=1e-9)


def test_each_axis_is_correlated_with_its_own_current_rate_at_the_lag(model):
    # vertical residual = d(i_d)/dt 7 samples late, horizontal = d(i_q)/dt: each axis's
    # correlation peaks at +7 ms near 1 (1/sqrt(1 + 0.1^2) = 0.995, the added noise), the rates
    # being independent white sequences
    lag = 7
    x, du, residual = _traced(lag=lag)
    tr = trace(x, du, residual, model.params, 1e-3)
    for a in range(2):
        k = int(np.argmax(tr.lag_correlation[a]))
        assert tr.lags[k] == pytest.approx(lag * 1e-3)
        assert tr.lag_correlation[a, k] > 0.95


def test_an_unexplained_force_is_its_size_times_its_own_axis_mass(model):
    p = model.params
    assert p.mass_vertical != p.mass_horizontal
    for axis, mass in (("vertical", p.mass_vertical), ("horizontal", p.mass_horizontal)):
        entry = _Probe(SimpleNamespace(axis=axis), "gap", "the gap")
        u = _unexplained(model, entry, 0.01, 0.1, 5.0)
        assert u.force_rms == pytest.approx(0.01 * mass, rel=1e-12)


@pytest.fixture(scope="module")
def bumpy(model):
    """The horizontal sweep with a smooth position-dependent force (0.05 m/s^2, a cubic in x3) that
    no candidate is given: the position probe finds it."""
    log = _log(model, friction=0.0, force=lambda x3: 0.05 * (x3 / 0.03) ** 3)
    data = prepare([log], bandwidth=10.0)
    fit, hold = data.masks(0.25)
    design = build_design(data, model, estimate=("C1",), fit=fit, holdout=hold)
    return data, fit, hold, design.weights


def test_unexplained_structure_is_reported_only_when_large_enough_and_at_most_max_per_axis(model, bumpy):
    data, fit, hold, weights = bumpy
    settings = SelectionSettings()
    found = find_unexplained(data, model, [], fit, hold, weights, [], settings)
    assert found, "the planted force is found"
    assert all(u.size >= settings.min_effect for u in found)
    biggest = max(u.size for u in found)
    for most in (0, 1):  # one moving axis: at most ``most`` reports in all
        assert (
            len(find_unexplained(data, model, [], fit, hold, weights, [], settings, max_per_axis=most))
            <= most
        )
    # the same structure, with a size threshold above it: nothing is reported
    larger = SelectionSettings(min_effect=1.5 * biggest)
    assert find_unexplained(data, model, [], fit, hold, weights, [], larger) == []


TS = 1e-3  # [s] the logs' 1 kHz


# --- the residual's trace ----------------------------------------------------------------------------
def _sweep():
    """(x (4, n), du (2, n)): 6 s of a stage sweeping +-30 mm at 0.17 Hz with a 2 mm wobble."""
    return sweep_signals(6000, position_hz=0.17)


def test_the_spectrums_share_is_the_r2_gain_of_a_sinusoid_over_a_constant_whatever_the_mean():
    """A residual with a large mean (10x its sinusoid: a constant the base model lacks) plus a
    sinusoid of 23 mm and noise: at every fifth period of the grid the share is 1 - RSS / TSS of
    numpy's least squares on [1, sin, cos] of the position, TSS about the mean (the share is of
    the residual's variance; within 1e-6: the phases are computed in single precision, 1e-5 rad at
    63 rad, a relative error of the share of that order)."""
    x, du = _sweep()
    rng = np.random.default_rng(1)
    n = x.shape[1]
    r = np.vstack(
        [
            0.5 + 0.05 * np.sin(2 * math.pi * x[2] / 0.023) + 0.05 * rng.standard_normal(n),
            -0.3 + 0.02 * np.cos(2 * math.pi * x[2] / 0.011) + 0.05 * rng.standard_normal(n),
        ]
    )
    tr = trace(x, du, r, StageParameters(), TS)
    for j in range(0, tr.periods.size, 5):
        k = 2 * math.pi / tr.periods[j]
        a = np.column_stack([np.ones(n), np.sin(k * x[2]), np.cos(k * x[2])])
        for axis in range(2):
            coef, *_ = np.linalg.lstsq(a, r[axis], rcond=None)
            rss = float(np.sum((r[axis] - a @ coef) ** 2))
            tss = float(np.sum((r[axis] - r[axis].mean()) ** 2))
            assert tr.spectrum[axis, j] == pytest.approx(1 - rss / tss, abs=1e-6), (axis, tr.periods[j])


def test_a_period_longer_than_the_travel_is_found_at_its_period():
    """A residual that is a sinusoid of the position over 1.3 times the logged travel (83 mm on a
    64 mm sweep: less than a cycle, what a long guide wave looks like) and a little noise: the
    horizontal spectrum has a peak reported there (within 2 %, the 300-period grid's spacing over a
    factor of 24; the grid reaches 1.5 travels)."""
    x, du = _sweep()
    rng = np.random.default_rng(2)
    span = float(np.ptp(x[2]))
    lam = 1.3 * span
    n = x.shape[1]
    r = np.vstack([0.01 * rng.standard_normal(n), 0.05 * np.sin(2 * math.pi * x[2] / lam + 0.3)])
    r[1] += 0.01 * rng.standard_normal(n)
    tr = trace(x, du, r, StageParameters(), TS)
    found = [p for axis, p, _ in tr.peaks if axis == "horizontal"]
    assert found and min(abs(p / lam - 1) for p in found) < 0.02, found


@pytest.mark.parametrize("period", [0.015, 0.0191, 0.06])
def test_a_periodic_probe_names_its_period_in_mm(model, period):
    data = prepare([_log(model, friction=0.0)], bandwidth=10.0)
    assert data.moving[1]  # the horizontal sweep: its probes are built
    (periodic,) = [p for p in _probes(data, [("horizontal", period)]) if p.period is not None]
    term, key, words, got, detail = periodic
    assert detail is None
    mm = f"{period * 1e3:.1f} mm"
    assert key == f"position (period {mm})"
    assert words == f"the horizontal position, periodically over {mm}"
    assert got == period and term.axis == "horizontal"
