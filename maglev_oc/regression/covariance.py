"""Standard errors that allow for autocorrelated residuals (long-run variance of the influence).

A least-squares estimate moves with the residuals through its influence:
theta_hat - theta ~= sum_k d_k with d_k = H^-1 J_k' W r_k (k = time sample, both axes summed,
H = J'WJ). The plain covariance s^2 H^-1 assumes independent r_k. Equation-error residuals
are not independent: the accelerations come out of a smoothing differentiator, and the noise
it leaves is a second derivative of the encoders' quantization noise, so its spectrum is
anything but flat (near zero at low frequencies, rising as f^4 up to the filter's band);
model errors, on a real stage, add slow components. What the estimate feels is the spectrum
of the influence series d_k at frequency zero: Cov(theta_hat) = sum_k sum_l E[d_k d_l'].

We estimate it by the averaged periodogram of d over the lowest Fourier frequencies (a flat,
Daniell, spectral window at zero; Brockwell & Davis, Sec. 10.4): with D_j = sum_k d_k
exp(-2 pi i j k / n),

    Cov = mean_{j = 1..m} Re(D_j D_j^*),   m = max(4, floor(band * duration)),

band = 0.25 Hz by default: below the lowest excitation frequencies' spacing, so the window
does not reach the rising part of the spectrum. (j = 0 is left out: at the least-squares
solution sum_k d_k = 0 exactly.) Independent logs add their covariances. The estimate has
2m degrees of freedom (m = 15 on a 60 s log: the standard errors are good to about 20 %).

Why not Bartlett/Newey-West with an automatic lag count: Andrews' AR(1) rule picks ~100 lags
here, a window 10 Hz wide, which averages the rising spectrum into the value at zero and
overstates the standard errors of C2..C4 by 2-4x on the twin (measured over 8 logs, see
tests/test_identify_uncertainty.py); with 3000 lags Bartlett agrees with the periodogram.
:func:`bartlett_long_run` is kept for that cross-check.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from maglev_oc.errors import InputError

__all__ = [
    "DEFAULT_BAND",
    "MIN_FREQUENCIES",
    "LongRunCovariance",
    "bartlett_long_run",
    "correlation_from",
    "frequencies_for",
    "long_run_covariance",
    "per_log_long_run",
    "periodogram_long_run",
]

DEFAULT_BAND = 0.25
"""[Hz] Width of the spectral window at zero frequency."""
MIN_FREQUENCIES = 4
"""Fewest Fourier frequencies averaged (8 degrees of freedom)."""


@dataclass(frozen=True)
class LongRunCovariance:
    """The covariance of an estimate and how it was made.

    Attributes
    ----------
    covariance : (p, p)
        Long-run (HAC) covariance.
    naive : (p, p)
        s^2 H^-1, which assumes independent residuals.
    frequencies : int
        Fourier frequencies averaged (summed over logs).
    variance_inflation : (p,)
        HAC / naive variance: below 1 when the residual noise is mostly high-frequency (as
        for differentiated quantization noise), above 1 when it is slow (model errors).
    """

    covariance: np.ndarray
    naive: np.ndarray
    frequencies: int
    variance_inflation: np.ndarray


def frequencies_for(n: int, sample_time: float, band: float = DEFAULT_BAND) -> int:
    """m = max(4, floor(band * n * sample_time)), at most n // 2 - 1.

    The floor allows 1e-9 relative for the sample time's last bits: logs cut from one record carry
    0.001 or 0.0010000000000000009 s, and at a whole band * n * T (8 Hz on 1 s) they would otherwise
    average 7 or 8 frequencies, so a fit's standard errors moved with the order of its logs."""
    m = max(MIN_FREQUENCIES, math.floor(band * n * sample_time * (1 + 1e-9)))
    return int(max(1, min(m, n // 2 - 1)))


def periodogram_long_run(influence: np.ndarray, m: int) -> np.ndarray:
    """mean_{j=1..m} Re(D_j D_j^*) of one (p, n) influence series.

    The m lowest Fourier coefficients as one product with their twiddle factors when that table is
    small (:data:`DIRECT_DFT_SIZE`): a fit's series has the length of its log's fitted samples,
    often a product of large primes (44 854 = 2 x 41 x 547 for a 60 s log), where the FFT of every
    coefficient costs ten times the m wanted (the two agree to rounding)."""
    d = np.asarray(influence, dtype=float)
    n = d.shape[1]
    k = min(m, n // 2)  # the coefficients there are (the FFT's slice below)
    if k > 0 and n * k <= DIRECT_DFT_SIZE:
        part = d @ _twiddles(n, k)  # (p, 2k): real and imaginary parts of D_1..D_k
        re, im = part[:, :k], part[:, k:]
        return (re @ re.T + im @ im.T) / k
    f = np.fft.rfft(d, axis=1)[:, 1 : m + 1]
    return np.einsum("pk,qk->pq", f, np.conj(f)).real / f.shape[1]


def per_log_long_run(
    scores: np.ndarray, log: np.ndarray, sample_time: float, band: float = DEFAULT_BAND
) -> tuple[np.ndarray, int]:
    """(the long-run covariance (p, p) of per-sample ``scores`` (p, n), the frequencies averaged):
    :func:`periodogram_long_run` over each log's samples (``log`` (n,): which log each comes from),
    the logs' covariances added (independent logs), symmetrised."""
    s = np.asarray(scores, dtype=float)
    meat = np.zeros((s.shape[0], s.shape[0]))
    total = 0
    for which in np.unique(log):
        part = s[:, log == which]
        m = frequencies_for(part.shape[1], sample_time, band)
        meat += periodogram_long_run(part, m)
        total += m
    return 0.5 * (meat + meat.T), total


DIRECT_DFT_SIZE = 1_000_000
"""Largest n x m whose twiddle factors (16 n m bytes) :func:`periodogram_long_run` tabulates."""


@functools.lru_cache(maxsize=4)
def _twiddles(n: int, m: int) -> np.ndarray:
    """(n, 2m) cos and -sin of 2 pi j k / n, k = 0..n-1, j = 1..m (the exponent reduced modulo n
    in integers first, so every angle is within one rounding of the exact one)."""
    turns = (np.arange(n, dtype=np.int64)[:, None] * np.arange(1, m + 1, dtype=np.int64)[None, :]) % n
    angle = (2 * math.pi / n) * turns
    return np.concatenate([np.cos(angle), -np.sin(angle)], axis=1)


def long_run_covariance(
    influence: Sequence[np.ndarray],
    naive: np.ndarray,
    sample_time: float,
    *,
    band: float = DEFAULT_BAND,
) -> LongRunCovariance:
    """HAC covariance of an estimate that is (to first order) a sum of per-sample influences.

    Parameters
    ----------
    influence : list of (p, n_i)
        Per log, the contribution of each time sample to theta_hat - theta (zero where a
        sample is not used).
    naive : (p, p)
        The plain covariance s^2 H^-1, reported beside the HAC one.
    sample_time : float
        [s]
    band : float
        [Hz] Spectral window width at zero frequency (default 0.25 Hz).
    """
    if not (band > 0 and math.isfinite(band)):
        raise InputError(f"band must be positive [Hz], got {band!r}")
    p = np.asarray(naive).shape[0]
    cov = np.zeros((p, p))
    total_m = 0
    for d in influence:
        n = np.asarray(d).shape[1]
        m = frequencies_for(n, sample_time, band)
        cov += periodogram_long_run(d, m)
        total_m += m
    cov = 0.5 * (cov + cov.T)
    with np.errstate(divide="ignore", invalid="ignore"):
        d_naive = np.diag(naive)
        inflation = np.where(d_naive > 0, np.diag(cov) / d_naive, np.nan)
    return LongRunCovariance(cov, np.asarray(naive, dtype=float), total_m, inflation)


def bartlett_long_run(influence: Sequence[np.ndarray], lags: int) -> np.ndarray:
    """Newey-West: sum over logs of sum_{|l| <= L} (1 - |l| / (L + 1)) Gamma_l, by FFT."""
    p = np.asarray(influence[0]).shape[0]
    out = np.zeros((p, p))
    for s in influence:
        s = np.asarray(s, dtype=float)
        n = s.shape[1]
        L = int(min(lags, n - 1))
        nfft = 1 << int(np.ceil(np.log2(2 * n)))
        f = np.fft.rfft(s, nfft, axis=1)
        cross = np.fft.irfft(f[:, None, :] * np.conj(f[None, :, :]), nfft, axis=2)
        w = 1 - np.arange(L + 1) / (L + 1)
        out += cross[:, :, : L + 1] @ w
        if L > 0:
            out += cross[:, :, nfft - L :][:, :, ::-1] @ w[1:]
    return 0.5 * (out + out.T)


def correlation_from(cov: np.ndarray) -> np.ndarray:
    """The correlation matrix of a covariance (zero where a variance is zero)."""
    d = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = cov / np.outer(d, d)
    corr[~np.isfinite(corr)] = 0.0
    np.fill_diagonal(corr, 1.0)
    return corr
