"""High-gain observer for position/velocity from a quantized position (002 Sec. 4, 000 Sec. IV).

The papers estimate the velocities x2, x4 from the 10 um encoders with high-gain observers. For
one axis with measured position y and (optionally) a known acceleration a:

    p^' = q^ + (alpha1 / eps) (y - p^)
    q^' = a  + (alpha2 / eps^2) (y - p^)

whose error dynamics have the characteristic polynomial s^2 + (alpha1/eps) s + alpha2/eps^2
(alpha1 = 2, alpha2 = 1: a double pole at -1/eps). The observer is linear, so it is discretized
exactly (zero-order hold on y and a over one sample) and the same matrices serve the online
controllers (as CasADi expressions) and the offline log processing (as a numpy filter).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import expm

from maglev_oc.errors import InputError

__all__ = ["DEFAULT_EPSILON", "HighGainObserver"]

DEFAULT_EPSILON = 2e-3
"""Observer time constant [s]: poles at -1/eps = -500 rad/s, 25x the fastest regulator pole
(-18.8 for the printed K_v) and 8x the fastest open-loop pole (64 1/s at 10 mm), while the
10 um quantization step gives a velocity noise of about q / eps = 5 mm/s."""


@dataclass(frozen=True)
class HighGainObserver:
    """Discrete-time high-gain observer for one axis.

    Parameters
    ----------
    sample_time : float
        Sample period [s] (rig: 2e-4 s, 5 kHz).
    epsilon : float
        Time constant [s]; smaller is faster and noisier.
    alpha : (float, float)
        alpha1, alpha2 > 0 (default (2, 1): critically damped).

    Attributes
    ----------
    Ad : (2, 2), By : (2, 1), Ba : (2, 1)
        xhat[k+1] = Ad xhat[k] + By y[k] + Ba a[k] with xhat = (position, velocity).
    """

    sample_time: float
    epsilon: float = DEFAULT_EPSILON
    alpha: tuple[float, float] = (2.0, 1.0)
    Ad: np.ndarray = field(init=False, repr=False)
    By: np.ndarray = field(init=False, repr=False)
    Ba: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not (self.sample_time > 0 and np.isfinite(self.sample_time)):
            raise InputError(f"sample_time must be positive [s], got {self.sample_time!r}")
        if not (self.epsilon > 0 and np.isfinite(self.epsilon)):
            raise InputError(f"epsilon must be positive [s], got {self.epsilon!r}")
        a1, a2 = self.alpha
        if not (a1 > 0 and a2 > 0):
            raise InputError(f"alpha must be positive, got {self.alpha!r}")
        eps = self.epsilon
        a = np.array([[-a1 / eps, 1.0], [-a2 / eps**2, 0.0]])
        b = np.array([[a1 / eps, 0.0], [a2 / eps**2, 1.0]])
        # exact ZOH: expm([[A, B], [0, 0]] T) = [[Ad, Bd], [0, I]]
        m = np.zeros((4, 4))
        m[:2, :2] = a
        m[:2, 2:] = b
        e = expm(m * self.sample_time)
        object.__setattr__(self, "Ad", e[:2, :2])
        object.__setattr__(self, "By", e[:2, 2:3])
        object.__setattr__(self, "Ba", e[:2, 3:4])

    def step(self, xhat, y, a=0.0):
        """One update; works on numpy arrays ((2,) or (2, 1), same shape back) and CasADi
        column expressions alike.

        Parameters
        ----------
        xhat : (2,) or (2, 1) array, or CasADi column
            (position [m], velocity [m/s]) estimate.
        y : float or CasADi scalar
            Measured position [m].
        a : float or CasADi scalar
            Known acceleration [m/s^2] over the sample.

        Returns
        -------
        The estimate at the next sample, the shape of ``xhat``.
        """
        if isinstance(xhat, np.ndarray) and xhat.ndim == 1:
            if xhat.shape != (2,):
                raise InputError(f"xhat must have 2 entries, got shape {xhat.shape}")
            return self.Ad @ xhat + self.By[:, 0] * y + self.Ba[:, 0] * a
        return self.Ad @ xhat + self.By * y + self.Ba * a

    def filter(self, y: np.ndarray, a: np.ndarray | None = None, x0=None) -> np.ndarray:
        """Run over a sampled position.

        The estimate at sample k uses y[0..k-1] (the same one-sample delay as online).

        Parameters
        ----------
        y : (n,) array
            Positions [m].
        a : (n,) array, optional
            Known accelerations [m/s^2] (default zero).
        x0 : (2,) array, optional
            Start (default (y[0], 0)).

        Returns
        -------
        (2, n) array
            Position [m] and velocity [m/s] estimates.
        """
        y = np.asarray(y, dtype=float).ravel()
        acc = np.zeros_like(y) if a is None else np.asarray(a, dtype=float).ravel()
        out = np.empty((2, y.size))
        xh = np.array([y[0], 0.0]) if x0 is None else np.asarray(x0, dtype=float).copy()
        ad, by, ba = self.Ad, self.By[:, 0], self.Ba[:, 0]
        for k in range(y.size):
            out[:, k] = xh
            xh = ad @ xh + by * y[k] + ba * acc[k]
        return out
