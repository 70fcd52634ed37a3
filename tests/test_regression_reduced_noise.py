"""The current error's variance of a log faster than the fit's rate (``prepare`` reduces it by
q-sample means): what the bias compensation removes must be the variance of the reduced currents'
error, measured here from the error itself.

A 5 kHz log of measured currents with 0.01 A of white sensor noise, reduced to 1 kHz by 5-sample
means: each reduced current carries the mean of five independent errors, variance 1e-4 / 5 =
2e-5 A^2. ``prepare`` once gave 4e-6 (the 1/5 of the means counted twice: in the floor, measured
on the reduced log, and in the share), and the compensation removed a fifth of the bias.
"""

from __future__ import annotations

import numpy as np
import pytest

from maglev_oc.data.log import Log
from maglev_oc.regression.data import prepare


def _log(
    rate: float, noise: float, *, measured: bool, seconds: float = 30.0, seed: int = 3
) -> tuple[Log, np.ndarray]:
    """(log, its current error): a horizontal sweep at ``rate`` with white current errors."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * rate)) / rate
    x = np.full((4, t.size), np.nan)
    x[0] = 0.020
    x[2] = 0.02 * np.sin(2 * np.pi * 0.4 * t) + 0.004 * np.sin(2 * np.pi * 1.3 * t + 1.0)
    clean = np.vstack([0.5 * np.sin(2 * np.pi * 0.4 * t), np.full(t.size, 1.5)])
    error = noise * rng.standard_normal(clean.shape)
    meta = {"currents": "measured"} if measured else {"control_rate_hz": f"{rate:g}"}
    return Log(t, x, clean + error, metadata=meta, currents_measured=measured), error


@pytest.mark.parametrize("rate", [5000.0, 2000.0, 1000.0])
def test_the_current_noise_is_the_reduced_currents_error_variance(rate):
    log, error = _log(rate, 0.01, measured=True)
    data = prepare([log], bandwidth=10.0)
    q = round(rate / 1000.0)
    assert data.sample_time == pytest.approx(q / rate, rel=1e-9)
    n = (error.shape[1] // q) * q
    truth = error[:, :n].reshape(2, -1, q).mean(axis=2).var(axis=1)  # the reduced error, measured
    assert truth == pytest.approx(1e-4 / q, rel=0.05)  # 6000-30000 draws: 2.6 % sd at most
    # Welch's median over the noise band against the truth: within 10 % (the band's periodogram
    # bins average some 30 segments each; the clean sweep leaves the band empty)
    assert data.current_noise == pytest.approx(truth, rel=0.1)
    assert data.settings["logging_error_share"] == [1.0]


def test_commands_logged_at_their_loops_rate_carry_no_error_when_reduced():
    # every command was applied over its interval: none of the floor is error, before or after means
    log, _ = _log(5000.0, 0.01, measured=False)
    data = prepare([log], bandwidth=10.0)
    assert data.settings["logging_error_share"] == [0.0]
    assert np.all(data.current_noise == 0.0)
