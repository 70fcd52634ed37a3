"""Velocity and acceleration estimates from quantized positions (estimation/differentiate.py)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.signal import savgol_coeffs

from maglev_oc.data.logs import Log
from maglev_oc.estimation.differentiate import (
    DEFAULT_ACCELERATION_EPSILON,
    HighGainDifferentiator,
    SavitzkyGolay,
    differentiate_log,
    savgol_gain_error,
    with_estimated_velocities,
)
from maglev_oc.estimation.high_gain import HighGainObserver

Q = 10e-6  # encoder step [m]
SIGMA_Q = Q / np.sqrt(12)  # standard deviation of rounding to Q, uniform error


def _quantized(y: np.ndarray) -> np.ndarray:
    return np.round(y / Q) * Q


# The sum of sines of the module docstring's table.
AMPLITUDES = np.array([3.0, 2.0, 2.0, 1.0, 1.0]) * 1e-3  # [m]
FREQUENCIES = np.array([0.2, 0.5, 1.3, 2.9, 5.0])  # [Hz]
PHASES = np.array([0.3, 1.1, 2.0, 0.7, 1.9])


def _sum_of_sines(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    w = 2 * np.pi * FREQUENCIES
    arg = np.outer(t, w) + PHASES
    return 0.02 + np.sin(arg) @ AMPLITUDES, np.cos(arg) @ (AMPLITUDES * w), -np.sin(arg) @ (AMPLITUDES * w**2)


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e**2)))


# --- Savitzky-Golay -----------------------------------------------------------------------------
def test_savgol_is_exact_on_polynomials():
    # polyorder 5 reproduces a quintic and its derivatives, edges included (mode='interp').
    # Tolerance: scipy solves for the coefficients with a Vandermonde matrix in raw indices
    # (condition about M^5 for half-width M), so the result carries M^5 eps ||h||_1 max|y| / T^d.
    T = 1e-3
    t = np.arange(2000) * T
    c = np.array([0.02, 0.01, -0.03, 0.02, 0.004, -0.001])
    y = np.polynomial.polynomial.polyval(t, c)
    v = np.polynomial.polynomial.polyval(t, np.polynomial.polynomial.polyder(c))
    a = np.polynomial.polynomial.polyval(t, np.polynomial.polynomial.polyder(c, 2))
    sg = SavitzkyGolay(T)
    est = sg(y)
    for deriv, window, got, want in (
        (0, sg.velocity_window, est.position, y),
        (1, sg.velocity_window, est.velocity, v),
        (2, sg.acceleration_window, est.acceleration, a),
    ):
        half = (window - 1) // 2
        h = savgol_coeffs(window, 5, deriv=deriv)
        bound = half**5 * np.finfo(float).eps * np.abs(h).sum() / T**deriv * np.abs(y - y[0]).max()
        assert_allclose(got, want, rtol=0, atol=bound)


def test_savgol_windows_are_the_longest_within_the_band_error():
    sg = SavitzkyGolay(2e-4, bandwidth=20.0, tolerance=0.01)
    for deriv, window in ((1, sg.velocity_window), (2, sg.acceleration_window)):
        assert savgol_gain_error(window, 5, deriv, 2e-4, 20.0) <= 0.01
        assert savgol_gain_error(window + 2, 5, deriv, 2e-4, 20.0) > 0.01
    # the module docstring's windows
    assert (sg.velocity_window, sg.acceleration_window) == (241, 135)
    assert (SavitzkyGolay(1e-3).velocity_window, SavitzkyGolay(1e-3).acceleration_window) == (47, 27)


def test_savgol_error_on_a_quantized_sine_is_the_predicted_noise():
    # 2 mm at 2 Hz, 1 kHz: moving 2.5 encoder steps per sample, so the rounding error is close
    # to white with sigma_q = q / sqrt(12); the estimate then carries sigma_q ||h||_2 (the
    # noise_gain) plus the in-band gain error (below 1 % at 20 Hz, ~1e-5 at 2 Hz: negligible).
    # Tolerance 25 % of the prediction: the RMS of 4000 samples of non-white rounding error.
    T = 1e-3
    t = np.arange(5000) * T
    w = 2 * np.pi * 2.0
    y = 0.02 + 2e-3 * np.sin(w * t)
    sg = SavitzkyGolay(T)
    est = sg(_quantized(y))
    inner = slice(500, -500)
    v_err = _rms((est.velocity - 2e-3 * w * np.cos(w * t))[inner])
    a_err = _rms((est.acceleration + 2e-3 * w**2 * np.sin(w * t))[inner])
    assert_allclose(v_err, SIGMA_Q * sg.noise_gain["velocity"], rtol=0.25)
    assert_allclose(a_err, SIGMA_Q * sg.noise_gain["acceleration"], rtol=0.25)
    assert_allclose(est.settings["velocity_quantization_noise"], SIGMA_Q * sg.noise_gain["velocity"])


def test_savgol_keeps_the_input_shape():
    T = 1e-3
    y = 0.02 + 1e-3 * np.sin(np.arange(600) * T * 2 * np.pi)
    two = SavitzkyGolay(T)(np.vstack([y, 2 * y]))
    one = SavitzkyGolay(T)(y)
    assert two.velocity.shape == (2, 600) and one.velocity.shape == (600,)
    assert_allclose(two.velocity[0], one.velocity, rtol=0, atol=1e-15)  # same arithmetic


def test_savgol_refuses_bad_settings():
    with pytest.raises(ValueError, match="polyorder"):
        SavitzkyGolay(1e-3, polyorder=6)
    with pytest.raises(ValueError, match="Nyquist"):
        SavitzkyGolay(1e-3, bandwidth=400.0)
    with pytest.raises(ValueError, match="bandwidth"):
        SavitzkyGolay(1e-3, bandwidth=-1.0)
    with pytest.raises(ValueError, match="30 samples"):
        SavitzkyGolay(1e-3)(np.zeros(30))
    with pytest.raises(TypeError):
        SavitzkyGolay(1e-3, window=11)  # unknown keyword


# --- high-gain observers ------------------------------------------------------------------------
@pytest.mark.parametrize("sample_time", [1e-3, 2e-4])
def test_observer_is_the_papers_high_gain_observer(sample_time: float):
    # the vectorized filter must give what HighGainObserver.filter gives, to rounding
    rng = np.random.default_rng(3)
    y = 0.02 + np.cumsum(rng.standard_normal(3000)) * 1e-5
    est = HighGainDifferentiator(sample_time)(y)
    ref = HighGainObserver(sample_time).filter(y)
    assert_allclose(est.position, ref[0], rtol=0, atol=1e-15)  # metres: rounding of 0.02 m
    assert_allclose(est.velocity, ref[1], rtol=0, atol=1e-10 * np.abs(ref[1]).max() + 1e-13)


@pytest.mark.parametrize("sample_time", [1e-3, 2e-4])
def test_third_order_observer_on_a_parabola(sample_time: float):
    # y = a t^2 / 2 held between samples (the ZOH the observers are discretized for): the held
    # samples' sawtooth, aliased at the sample instants, biases the acceleration by
    # -v T^2 / (12 eps_a^3) (Fourier series of the sawtooth through 1/(eps_a^3 s), the observer
    # far above its bandwidth); the next term is O(1 / (eps_a omega_s)^2) = 1e-3 of the bias at
    # 1 kHz: tolerance 1 % of the bias.
    acc, eps = 3.0, DEFAULT_ACCELERATION_EPSILON
    t = np.arange(round(1 / sample_time)) * sample_time
    est = HighGainDifferentiator(sample_time)(0.5 * acc * t**2)
    bias = acc * t * sample_time**2 / (12 * eps**3)
    assert_allclose(acc - est.acceleration[-200:], bias[-200:], rtol=0.01)


def test_held_samples_scale_the_observer_velocity():
    # The module docstring's ZOH note: on a ramp the velocity estimate settles at
    # v (1 - (T/eps)^2 / 12), -2.1 % at 1 kHz; next term O((T/eps)^4) = 4e-4 of v: rtol 1e-3.
    T, eps, v = 1e-3, 2e-3, 0.05
    t = np.arange(1000) * T
    est = HighGainDifferentiator(T, epsilon=eps)(0.01 + v * t)
    assert_allclose(est.velocity[-100:], v * (1 - (T / eps) ** 2 / 12), rtol=1e-3)


def test_observer_settings_are_reported_and_checked():
    est = HighGainDifferentiator(2e-4)(np.full(100, 0.02))
    assert est.method == "high_gain_observer" and est.settings["epsilon"] == 2e-3
    assert_array_equal(est.velocity, 0.0)  # a constant is an equilibrium of the observers
    with pytest.raises(ValueError, match="acceleration_epsilon"):
        HighGainDifferentiator(2e-4, acceleration_epsilon=0.0)
    with pytest.raises(ValueError, match="epsilon"):
        HighGainDifferentiator(2e-4, epsilon=-1.0)


# --- the measurement in the module docstring ----------------------------------------------------
# (rate, method) -> (velocity RMS error [m/s], acceleration RMS error [m/s^2]) as printed there
DOCSTRING_TABLE = {
    (1000, "savitzky_golay"): (0.13e-3, 0.072),
    (1000, "high_gain_observer"): (3.5e-3, 0.32),
    (5000, "savitzky_golay"): (0.057e-3, 0.031),
    (5000, "high_gain_observer"): (3.0e-3, 0.33),
}


def test_docstring_table():
    # The numbers are deterministic (fixed phases, rounding to 10 um); printed to 2 digits,
    # so they agree to the rounding of the second digit: 5 %.
    for rate in (1000, 5000):
        T = 1 / rate
        t = np.arange(10 * rate) * T
        y, v, a = _sum_of_sines(t)
        inner = (t >= 0.5) & (t <= 9.5)
        for estimator in (SavitzkyGolay(T), HighGainDifferentiator(T)):
            est = estimator(_quantized(y))
            got = (_rms((est.velocity - v)[inner]), _rms((est.acceleration - a)[inner]))
            assert_allclose(
                got, DOCSTRING_TABLE[rate, est.method], rtol=0.05, err_msg=f"{rate} Hz {est.method}"
            )
        assert_allclose(_rms(v[inner]), 28.6e-3, rtol=2e-3)  # "true RMS velocity 28.6 mm/s"


# --- logs ---------------------------------------------------------------------------------------
def _log_without_rates(rate: float = 1000.0, n: int = 3000) -> tuple[Log, np.ndarray, np.ndarray]:
    T = 1 / rate
    t = np.arange(n) * T
    y, v, _ = _sum_of_sines(t)
    x3 = 0.01 * np.sin(2 * np.pi * 0.7 * t)
    v3 = 0.01 * 2 * np.pi * 0.7 * np.cos(2 * np.pi * 0.7 * t)
    x = np.vstack([_quantized(y), np.full(n, np.nan), _quantized(x3), np.full(n, np.nan)])
    u = np.vstack([np.sin(t), np.cos(t)])
    return Log(t, x, u, source="synthetic"), v, v3


def test_with_estimated_velocities_fills_only_the_missing_rows():
    log, v1, v3 = _log_without_rates()
    filled = with_estimated_velocities(log, SavitzkyGolay(log.sample_time))
    assert filled.states_measured == (True, True, True, True)
    inner = slice(300, -300)
    # the docstring's 0.13 mm/s at 1 kHz, with room: 0.3 mm/s against 29 and 44 mm/s signals
    assert _rms((filled.x[1] - v1)[inner]) < 0.3e-3
    assert _rms((filled.x[3] - v3)[inner]) < 0.3e-3
    assert "x2 and x4 estimated by savitzky_golay" in filled.notes[-1]
    assert_array_equal(filled.x[[0, 2]], log.x[[0, 2]])
    assert with_estimated_velocities(filled, SavitzkyGolay(log.sample_time)) is filled


def test_differentiate_log_checks_the_sample_time():
    log, _, _ = _log_without_rates()
    est = differentiate_log(log, HighGainDifferentiator(log.sample_time))
    assert est.velocity.shape == (2, log.n)
    with pytest.raises(ValueError, match="sample_time"):
        differentiate_log(log, HighGainDifferentiator(2e-4))
