"""The evidence a residual carries (``maglev_oc.diagnosis.trace``) against signals built with a
known answer: a sinusoid in the position is found at its period with its share of the variance,
binned means are the samples' means, a delayed copy of a current rate correlates at its delay.
Numpy only; the file takes well under a second of CPU."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from maglev_oc.diagnosis.trace import motor_periods, trace, unexplained_periods
from maglev_oc.model.parameters import StageParameters

TS = 1e-3  # [s] the logs' 1 kHz
N = 20_000


def sweep_signals(n: int = N, seed: int = 0, position_hz: float = 0.05):
    """(x (4, n), du (2, n)): a stage sweeping +-30 mm at ``position_hz`` with a 2 mm wobble at 0.7 Hz,
    the gap 20 +- 4 mm at 0.21 Hz, and random current rates."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * TS
    x = np.zeros((4, n))
    x[0] = 0.020 + 0.004 * np.sin(2 * math.pi * 0.21 * t)
    x[1] = np.gradient(x[0], TS)
    x[2] = 0.03 * np.sin(2 * math.pi * position_hz * t) + 0.002 * np.sin(2 * math.pi * 0.7 * t)
    x[3] = np.gradient(x[2], TS)
    return x, rng.standard_normal((2, n))


@pytest.fixture(scope="module")
def signals():
    """States of a stage sweeping 60 mm slowly and random current rates."""
    return sweep_signals()


def test_a_sinusoid_in_the_position_is_found_at_its_period_with_its_share(signals):
    """A horizontal residual a sin(2 pi x3 / 23 mm) plus white noise of variance s^2: the
    periodogram's largest share on that axis is at 23 mm (within the grid's 2 % spacing:
    300 periods over a factor of 22) and worth var(a sin) / (var(a sin) + s^2) of the variance,
    var(a sin) computed here over the logged positions (within 0.02: the noise's chance
    correlation with the two basis functions is of order 1/sqrt(N) = 0.007); the vertical
    residual, noise alone, has no share above 0.01 (that chance share of two basis functions,
    2/N = 1e-4 on average, far below). A period no motor has is reported as unexplained, on its
    axis only."""
    x, du = signals
    rng = np.random.default_rng(1)
    lam, a, s = 0.023, 0.05, 0.05
    r = np.vstack(
        [s * rng.standard_normal(N), a * np.sin(2 * math.pi * x[2] / lam) + s * rng.standard_normal(N)]
    )
    tr = trace(x, du, r, StageParameters(), TS)
    j = int(np.argmax(tr.spectrum[1]))
    assert abs(tr.periods[j] / lam - 1) < 0.02
    signal = np.var(a * np.sin(2 * math.pi * x[2] / lam))
    assert tr.spectrum[1, j] == pytest.approx(signal / (signal + s**2), abs=0.02)
    assert np.max(tr.spectrum[0]) < 0.01
    assert tr.peaks and all(axis == "horizontal" for axis, _, _ in tr.peaks)
    assert unexplained_periods(tr) == [("horizontal", pytest.approx(tr.periods[j]))]


def test_a_sinusoid_at_a_motor_period_is_not_unexplained(signals):
    """The same residual at the pole pitch: found, and left to the cogging candidates."""
    x, du = signals
    rng = np.random.default_rng(1)
    params = StageParameters()
    lam = motor_periods(params)["pole_pitch"]
    r = np.vstack([np.zeros(N), 0.05 * np.sin(2 * math.pi * x[2] / lam) + 0.01 * rng.standard_normal(N)])
    tr = trace(x, du, r, params, TS)
    assert abs(tr.periods[int(np.argmax(tr.spectrum[1]))] / lam - 1) < 0.02
    assert unexplained_periods(tr) == []
    # a tolerance of zero matches no motor period: then it is reported
    assert [axis for axis, _ in unexplained_periods(tr, tolerance=0.0)] == ["horizontal"]


def test_a_motor_period_is_set_aside_only_on_the_axes_a_force_there_can_explain(signals):
    """The same residual at twice the slot pitch on the horizontal axis, where the library has no
    force at that period (its horizontal cogging is at the slot and pole pitches): set aside as a
    motor period when every motor period counts on both axes, reported when the periods are given
    per axis; set aside again when the horizontal axis has a force at that period."""
    x, du = signals
    rng = np.random.default_rng(1)
    params = StageParameters()
    lam = motor_periods(params)["twice_slot_pitch"]
    r = np.vstack([np.zeros(N), 0.05 * np.sin(2 * math.pi * x[2] / lam) + 0.01 * rng.standard_normal(N)])
    tr = trace(x, du, r, params, TS)
    t1, tau = params.slot_pitch, params.pole_pitch
    assert unexplained_periods(tr) == []
    library = {"vertical": [t1, 2 * t1], "horizontal": [t1, tau]}
    assert [axis for axis, _ in unexplained_periods(tr, on_axis=library)] == ["horizontal"]
    library["horizontal"].append(2 * t1)
    assert unexplained_periods(tr, on_axis=library) == []


def test_motor_periods_are_the_slot_and_pole_pitches_and_their_doubles():
    p = StageParameters()
    assert motor_periods(p) == {
        "slot_pitch": p.slot_pitch,
        "twice_slot_pitch": 2 * p.slot_pitch,
        "pole_pitch": p.pole_pitch,
        "twice_pole_pitch": 2 * p.pole_pitch,
    }


def test_binned_means_are_the_samples_means(signals):
    """Each bin's mean and standard error are those of the residual samples whose variable
    falls in it (numpy here, same edges: percentiles 1-99 for positions, symmetric for rates),
    bins with fewer than 20 samples are NaN, and a residual that is a line in the velocity shows
    that line in the velocity's bins."""
    x, du = signals
    rng = np.random.default_rng(1)
    r = np.vstack([3.0 * x[1] + 0.01 * rng.standard_normal(N), -2.0 * x[2] + 0.01 * rng.standard_normal(N)])
    tr = trace(x, du, r, StageParameters(), TS)
    for name, row in (("gap", 0), ("gap_rate", 1), ("position", 2), ("position_rate", 3)):
        b = tr.binned[name]
        assert b.unit == ("m/s" if "rate" in name else "m")  # SI, as the report labels its axes
        v = x[row]
        lo, hi = np.percentile(v, [1, 99])
        edges = (
            np.linspace(-max(abs(lo), abs(hi)), max(abs(lo), abs(hi)), 25)
            if "rate" in name
            else np.linspace(lo, hi, 21)
        )
        assert_allclose(b.centers, 0.5 * (edges[1:] + edges[:-1]), rtol=1e-12)
        idx = np.clip(np.digitize(v, edges) - 1, 0, edges.size - 2)
        for k in range(edges.size - 1):
            sel = idx == k
            assert b.count[k] == sel.sum()
            if sel.sum() >= 20:
                assert_allclose(b.mean[:, k], r[:, sel].mean(axis=1), rtol=1e-10, atol=1e-15)
                assert_allclose(b.stderr[:, k], r[:, sel].std(axis=1) / np.sqrt(sel.sum()), rtol=1e-10)
            else:
                assert np.all(np.isnan(b.mean[:, k]))
    # the line: the vertical residual's bin means against the gap rate have slope 3 (the noise's
    # standard error per bin is 1e-2 / sqrt(hundreds): the fitted slope within 2 %)
    b = tr.binned["gap_rate"]
    ok = np.isfinite(b.mean[0])
    slope = np.polyfit(b.centers[ok], b.mean[0, ok], 1)[0]
    assert slope == pytest.approx(3.0, rel=0.02)
    b = tr.binned["position"]
    ok = np.isfinite(b.mean[1])
    assert np.polyfit(b.centers[ok], b.mean[1, ok], 1)[0] == pytest.approx(-2.0, rel=0.02)


@pytest.mark.parametrize("delay", [0, 7])
def test_a_delayed_current_rate_correlates_at_its_delay_on_its_own_axis(signals, delay):
    """The vertical residual a delayed copy of the d-axis current rate (du[1]) and the horizontal
    one minus a delayed copy of the q-axis rate (du[0]), each plus as much independent noise:
    the correlation peaks at the delay (in seconds) with the copy's sign and size 1/sqrt(2)
    (equal signal and noise variances; within 0.03, about 4/sqrt(N)); the other rate, which
    the residual does not contain, correlates below 0.03 everywhere."""
    x, du = signals
    rng = np.random.default_rng(1)
    v = np.roll(du[1], delay)
    h = -np.roll(du[0], delay)
    r = np.vstack([v, h]) + rng.standard_normal((2, N))
    tr = trace(x, du, r, StageParameters(), TS)
    assert tr.lags[0] == pytest.approx(-0.02) and tr.lags[-1] == pytest.approx(0.02)
    for a, sign in ((0, 1.0), (1, -1.0)):
        k = int(np.argmax(np.abs(tr.lag_correlation[a])))
        assert tr.lags[k] == pytest.approx(delay * TS, abs=1e-12)
        assert sign * tr.lag_correlation[a, k] == pytest.approx(1 / math.sqrt(2), abs=0.03)
    crossed = trace(x, du[::-1], r, StageParameters(), TS)
    assert np.max(np.abs(crossed.lag_correlation)) < 0.03


def test_traces_of_several_residuals_are_each_ones_own_trace(signals):
    """The pipeline traces the base fit's residual and the selection's together (their spatial
    spectra share the sines of the position): each is, to the bit, the trace of that residual alone."""
    from maglev_oc.diagnosis.trace import traces

    x, du = (a[:, : N // 4] for a in signals)  # a quarter of the samples: the comparison is exact
    rng = np.random.default_rng(2)
    residuals = [rng.standard_normal((2, N // 4)), np.vstack([np.sin(2 * math.pi * x[2] / 0.019), x[1]])]
    for together, residual in zip(traces(x, du, residuals, StageParameters(), TS), residuals, strict=True):
        alone = trace(x, du, residual, StageParameters(), TS)
        np.testing.assert_array_equal(together.spectrum, alone.spectrum)
        np.testing.assert_array_equal(together.lag_correlation, alone.lag_correlation)
        assert together.peaks == alone.peaks
        for name, binned in alone.binned.items():
            np.testing.assert_array_equal(together.binned[name].mean, binned.mean)


@pytest.mark.parametrize("where", [1, 150, -2])
def test_a_sinusoid_at_any_inner_period_of_the_grid_is_a_peak_there(signals, where):
    """The periodogram's grid runs from 4 mm to 1.5 x the position's span (here 96 mm, 300
    periods 1.1 % apart). A sinusoid in the position at any period inside the grid, the second and
    the second-to-last included, is a peak at that period (a local maximum: only the grid's own
    ends cannot be one), on the axis that carries it and not on the other. The noise is small
    (share of the sinusoid 0.93): near the grid's long end neighbouring periods explain nearly the
    same share, and a noise as large as the sinusoid moves the maximum to the end."""
    x, du = signals
    span = float(np.ptp(x[2]))
    periods = np.geomspace(4e-3, max(min(1.5 * span, 0.15), 0.01), 300)
    lam = periods[where]
    rng = np.random.default_rng(3)
    residual = 0.1 * rng.standard_normal((2, x.shape[1]))
    residual[1] += 0.5 * np.sin(2 * math.pi * x[2] / lam + 0.4)
    tr = trace(x, du, residual, StageParameters(), TS)
    assert_allclose(tr.periods, periods, rtol=1e-12)
    found = [p for axis, p, _ in tr.peaks if axis == "horizontal"]
    assert any(p == pytest.approx(lam, rel=1e-9) for p in found), (lam, found)
    assert not [p for axis, p, _ in tr.peaks if axis == "vertical"]
