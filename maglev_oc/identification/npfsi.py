"""The reduced-order NPFSI estimator (eq. (3) of paper 000; sidebar "NPFSI Estimator" of 002).

For a system x' = A(x, u) theta + b(x, u) + w with a noisy full-state measurement y (positions
from the encoders, velocities from high-gain observers), Didinsky, Pan & Basar's H-infinity
estimator, in the reduced-order form the papers use, is

    theta_hat' = eps^-1 Sigma^-1 A(y, u)' (y - x_hat),          theta_hat(0) = theta_0
    x_hat'     = A(y, u) theta_hat + b(y, u) + eps^-1 (y - x_hat), x_hat(0) = y(0)
    Sigma'     = A(y, u)' A(y, u) - gamma^-2 Q,                  Sigma(0) = Q_0

with Q = A'A in 002's sidebar (Sigma' = (1 - gamma^-2) A'A). For the stage only the velocity
rows of A are non-zero (x1' = x2 and x3' = x4 carry no parameter), so only the velocity
errors e = (y2 - x_hat2, y4 - x_hat4) matter: m = 2 rows (1 for the fixed-gap horizontal
experiment), p parameters.

Discretization (sample time h, data held over each sample, the measured velocity taken as a
ramp between samples): the error obeys e' = y' - A theta - b - e / eps, which is solved
exactly over the sample (phi = exp(-h / eps)); theta is advanced with Sigma frozen and the new
theta in the error (semi-implicit, stable for any eps / h, including eps = h = 1 ms):

    (Sigma_k + beta A'A) theta_{k+1} = Sigma_k theta_k + A' [(1 - phi) e_k + beta (dy_k - b)]
    e_{k+1} = phi e_k + eps (1 - phi) (dy_k - A theta_{k+1} - b),   beta = h - eps (1 - phi)
    Sigma_{k+1} = Sigma_k + h (A'A - gamma^-2 Q)

The recursion runs inside CasADi (``mapaccum`` over chunks of the log), so a 60 s log at 1 kHz
takes a fraction of a second.

Reading eps. In the estimator eps is both the assumed size of the measurement noise and the
time constant with which x_hat follows y: the error e is the model's acceleration error low-
passed at 1/eps. A small eps trusts the (observer) velocities; a large one filters them. With
the papers' observer velocities (which lag by about 2 eps_obs and are sampled at 1 kHz) the
estimates carry an eps-dependent bias; with zero-phase velocities the bias disappears (see the
identification report). Q0 sets how much the initial guess counts: it should be small
(default: the information of 1 ms of data), otherwise poorly excited directions (C4, strongly
correlated with C3) stay near the guess.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import casadi as ca
import numpy as np

from maglev_oc.data.logs import Log
from maglev_oc.errors import InputError
from maglev_oc.estimation.differentiate import HighGainDifferentiator, SavitzkyGolay, differentiate_log
from maglev_oc.identification.layout import CONSTANT_NAMES
from maglev_oc.identification.result import NpfsiResult
from maglev_oc.model.stage import StageModel
from maglev_oc.numerics import NumpyCall
from maglev_oc.regression.payload import factors

__all__ = [
    "CHUNK",
    "DEFAULT_Q0_SECONDS",
    "PAPER_EPSILONS",
    "PAPER_GAMMA",
    "NpfsiEstimator",
    "npfsi",
    "stage_regression",
]

PAPER_EPSILONS = (0.001, 0.01, 0.05)
"""The eps values of Tables II and III of 000."""
PAPER_GAMMA = 1.1
"""gamma ~= 1.1 (000 Sec. IV: "choosing gamma ~= 1.1 and eps ~= 0.01 produced good convergence")."""
DEFAULT_Q0_SECONDS = 1e-3
"""Default Sigma(0): the diagonal of the mean A'A over the log times 1 ms."""
CHUNK = 1_000
"""Samples per mapaccum call: CasADi's build time grows with the length (0.45 s for 10^4), and a
Python loop over 1 s chunks costs little (a 60 s log: 0.8 s against 1.4 s with 10^4)."""

_CHUNKS: dict[tuple, ca.Function] = {}
"""The chunk Functions by (eps, gamma, Q, m, p, h, size), shared by every estimator of the process:
the eps studies run the same few settings on many logs (each built once: 25 ms)."""


class NpfsiEstimator:
    """The estimator with its settings; :meth:`run` applies it to regressor data along a log.

    Parameters
    ----------
    eps : float
        [s] eps > 0 (the papers: 0.001, 0.01, 0.05).
    gamma : float
        Attenuation level gamma > 1 (papers: 1.1).
    Q : (p, p) array, optional
        Constant Q of 000's Sigma' = A'A - gamma^-2 Q. Default None: Q = A'A (002 sidebar).
    Q0 : (p, p) array, optional
        Sigma(0), symmetric positive definite. Default: ``DEFAULT_Q0_SECONDS`` times the
        diagonal of the mean A'A over the data.
    """

    def __init__(
        self,
        eps: float,
        gamma: float = PAPER_GAMMA,
        Q: np.ndarray | None = None,
        Q0: np.ndarray | None = None,
    ) -> None:
        if not (math.isfinite(eps) and eps > 0):
            raise InputError(f"eps must be positive [s], got {eps!r}")
        if not (math.isfinite(gamma) and gamma > 1):
            raise InputError(f"gamma must be > 1, got {gamma!r}")
        self.eps = float(eps)
        self.gamma = float(gamma)
        self.Q = None if Q is None else self._matrix(Q, "Q", definite=False)
        self.Q0 = None if Q0 is None else self._matrix(Q0, "Q0", definite=True)

    @staticmethod
    def _matrix(value, name: str, *, definite: bool) -> np.ndarray:
        a = np.atleast_2d(np.asarray(value, dtype=float))
        if a.ndim != 2 or a.shape[0] != a.shape[1] or not np.all(np.isfinite(a)):
            raise InputError(f"{name} must be a finite square matrix, got shape {a.shape}")
        if not np.allclose(a, a.T, rtol=1e-10, atol=0):
            raise InputError(f"{name} must be symmetric")
        if definite and np.min(np.linalg.eigvalsh(a)) <= 0:
            raise InputError(f"{name} must be positive definite (eigenvalues {np.linalg.eigvalsh(a)})")
        return a

    def _chunk(self, m: int, p: int, h: float, size: int) -> ca.Function:
        """``size`` steps of the estimator (a mapaccum of :meth:`_step`): (z, data (nd, size)) ->
        (z after the last step, theta after each step (p, size)); the states in between are not
        returned (converting them to numpy cost more than the steps)."""
        key = (self.eps, self.gamma, None if self.Q is None else self.Q.tobytes(), m, p, h, size)
        if key not in _CHUNKS:
            step = self._step(m, p, h)
            z = ca.MX.sym("z", step.size1_in(0))
            data = ca.MX.sym("data", step.size1_in(1), size)
            zs, th = step.mapaccum("npfsi_steps", size)(z, data)
            _CHUNKS[key] = ca.Function("npfsi_chunk", [z, data], [zs[:, -1], th])
        return _CHUNKS[key]

    def _step(self, m: int, p: int, h: float) -> ca.Function:
        """One sample of the estimator: (z, d) -> (z next, theta next), z = (theta, e, vec Sigma)."""
        eps, gamma = self.eps, self.gamma
        phi = math.exp(-h / eps)
        beta = h - eps * (1 - phi)
        theta = ca.SX.sym("theta", p)
        e = ca.SX.sym("e", m)
        sig = ca.SX.sym("sigma", p, p)
        A = ca.SX.sym("A", m, p)
        b = ca.SX.sym("b", m)
        dy = ca.SX.sym("dy", m)
        ata = A.T @ A
        rhs = sig @ theta + A.T @ ((1 - phi) * e + beta * (dy - b))
        theta_next = ca.solve(sig + beta * ata, rhs)
        e_next = phi * e + eps * (1 - phi) * (dy - A @ theta_next - b)
        q = ata if self.Q is None else ca.DM(self.Q)
        sig_next = sig + h * (ata - q / gamma**2)
        z = ca.vertcat(theta, e, ca.vec(sig))
        d = ca.vertcat(ca.vec(A), b, dy)
        z_next = ca.vertcat(theta_next, e_next, ca.vec(sig_next))
        return ca.Function("npfsi_step", [z, d], [z_next, theta_next])

    def run(
        self,
        regressor: np.ndarray,
        offset: np.ndarray,
        velocity: np.ndarray,
        sample_time: float,
        theta0: Sequence[float],
        *,
        names: Sequence[str] | None = None,
        t: np.ndarray | None = None,
        sources: Sequence[str] = (),
        velocity_method: str = "",
    ) -> NpfsiResult:
        """Run along data: ``regressor`` A (n, m, p), ``offset`` b (n, m) and the measured
        velocities y (n, m) [m/s] at each sample; ``theta0`` (p,) the initial guesses.

        The acceleration model is velocity' = A theta + b; returns the trajectory of theta.
        """
        t0 = time.perf_counter()
        A, b, y, theta, names = self._checked(regressor, offset, velocity, theta0, names)
        n, m, p = A.shape
        h = float(sample_time)
        q0 = self._initial_sigma(A, names)
        dy = np.zeros((n, m))
        dy[:-1] = np.diff(y, axis=0) / h
        data = np.concatenate([A.transpose(0, 2, 1).reshape(n, m * p), b, dy], axis=1).T  # (nd, n)
        z0 = np.concatenate([theta, np.zeros(m), q0.ravel(order="F")])
        traj, z, status, message = self._integrate(m, p, z0, data, h)
        sigma = z[p + m :].reshape(p, p, order="F")
        success = status == "completed"
        if success:
            eig = np.linalg.eigvalsh(0.5 * (sigma + sigma.T))
            if eig.min() <= 0:
                success, status = False, "ill_posed"
                message = (
                    f"Sigma lost positive definiteness (smallest eigenvalue {eig.min():.3g}); lower Q or "
                    "raise gamma"
                )
        t_arr = np.arange(n) * h if t is None else np.asarray(t, dtype=float)
        return NpfsiResult(
            names=names,
            t=t_arr,
            trajectory=traj,
            values=dict(zip(names, traj[:, -1], strict=True)),
            eps=self.eps,
            gamma=self.gamma,
            Q=self.Q,
            Q0=q0,
            theta0=dict(zip(names, theta, strict=True)),
            sigma_final=sigma,
            velocity_method=velocity_method,
            success=success,
            status=status,
            message=message,
            timings={"total": time.perf_counter() - t0},
            sources=tuple(sources),
            settings={
                "sample_time_s": h,
                "rows": m,
                "Q0_default_seconds": DEFAULT_Q0_SECONDS if self.Q0 is None else None,
            },
        )

    def _checked(self, regressor, offset, velocity, theta0, names):
        """The data as float arrays (A (n, m, p), b, y (n, m), theta (p,)) and the names; refuses
        inconsistent shapes and non-finite data."""
        A = np.asarray(regressor, dtype=float)
        if A.ndim != 3:
            raise InputError(f"regressor must have shape (n, m, p), got {A.shape}")
        n, m, p = A.shape
        b = np.asarray(offset, dtype=float).reshape(n, m)
        y = np.asarray(velocity, dtype=float).reshape(n, m)
        theta = np.asarray(theta0, dtype=float).ravel()
        if theta.size != p:
            raise InputError(f"theta0 has {theta.size} values for {p} parameters")
        if n < 3:
            raise InputError(f"need at least 3 samples, got {n}")
        if not (np.all(np.isfinite(A)) and np.all(np.isfinite(b)) and np.all(np.isfinite(y))):
            raise InputError("regressor, offset and velocity must be finite")
        names = tuple(names) if names is not None else tuple(f"theta{k + 1}" for k in range(p))
        if len(names) != p:
            raise InputError(f"names: {len(names)} for {p} parameters")
        for mat, label in ((self.Q, "Q"), (self.Q0, "Q0")):
            if mat is not None and mat.shape != (p, p):
                raise InputError(f"{label} must be ({p}, {p}) for {p} parameters, got {mat.shape}")
        return A, b, y, theta, names

    def _initial_sigma(self, A: np.ndarray, names: tuple[str, ...]) -> np.ndarray:
        """Sigma(0): the given Q0, else DEFAULT_Q0_SECONDS times the mean information's diagonal."""
        if self.Q0 is not None:
            return self.Q0
        diag = np.diag(np.einsum("nij,nik->jk", A, A) / A.shape[0]).copy()
        if np.any(diag <= 0):
            bad = [names[k] for k in np.flatnonzero(diag <= 0)]
            raise InputError(f"the data carry no information on {bad} (zero regressor)")
        return DEFAULT_Q0_SECONDS * np.diag(diag)

    def _integrate(self, m: int, p: int, z: np.ndarray, data: np.ndarray, h: float):
        """(trajectory (p, n), final state, status, message): the estimator run over chunks of
        CHUNK samples; stops at the first non-finite state."""
        n = data.shape[1]
        traj = np.empty((p, n))
        traj[:, 0] = z[:p]
        k, steps = 0, n - 1
        while k < steps:
            size = min(CHUNK, steps - k)
            z_last, th = self._chunk(m, p, h, size)(z, data[:, k : k + size])
            traj[:, k + 1 : k + 1 + size] = np.asarray(th)
            z = np.asarray(z_last).ravel()
            k += size
            if not np.all(np.isfinite(z)):
                traj[:, k + 1 :] = np.nan
                return traj, z, "diverged", f"diverged (non-finite estimate) before t = {k * h:.3f} s"
        return traj, z, "completed", "completed"


def stage_regression(
    log: Log,
    model: StageModel,
    estimate: Sequence[str],
    differentiator: HighGainDifferentiator | SavitzkyGolay,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """A (n, 2, p), b (n, 2) and the velocities (n, 2) of eq. (2) of 000 along a log, at the
    measured positions and estimated velocities; constants not in ``estimate`` go into b."""
    estimate = tuple(estimate)
    unknown = [e for e in estimate if e not in CONSTANT_NAMES]
    if unknown or not estimate:
        raise InputError(f"estimate: choose among {CONSTANT_NAMES}, got {estimate!r}")
    der = differentiate_log(log, differentiator)
    n = log.n
    positions = log.x[[0, 2]]
    x = np.vstack([positions[0], der.velocity[0], positions[1], der.velocity[1]])
    phi, b = NumpyCall(model.regressor.map(n))(x, log.u)
    phi = phi.reshape(2, n, 4).transpose(1, 0, 2)  # (n, 2, 4)
    b = np.broadcast_to(np.asarray(b).reshape(2, n).T, (n, 2)).copy()
    idx = [CONSTANT_NAMES.index(c) for c in estimate]
    fixed = [k for k in range(4) if k not in idx]
    consts = np.array(model.constants.as_array())
    b += np.einsum("nij,j->ni", phi[:, :, fixed], consts[fixed])
    if log.payload:  # the forces move the platform and its payload (regression.payload)
        s = factors(model.params, log.payload)
        g = model.params.gravity
        phi = phi * s[None, :, None]
        b = np.column_stack([g + s[0] * (b[:, 0] - g), s[1] * b[:, 1]])
    return phi[:, :, idx], b, der.velocity.T.copy(), der.method


def npfsi(
    log: Log,
    model: StageModel,
    *,
    estimate: Sequence[str] = CONSTANT_NAMES,
    eps: float = 0.01,
    gamma: float = PAPER_GAMMA,
    Q: np.ndarray | None = None,
    Q0: np.ndarray | None = None,
    theta0: dict[str, float] | None = None,
    differentiator: HighGainDifferentiator | SavitzkyGolay | None = None,
) -> NpfsiResult:
    """Run the reduced-order NPFSI estimator along ``log`` for the constants in ``estimate``.

    Parameters
    ----------
    log : Log
    model : StageModel
        Geometry; the constants not estimated are held at its values, and its values are the
        default initial guesses.
    estimate : sequence of str
        Among C1..C4 (000: all four for Table III, C2..C4 for Table II with the mover locked,
        C2 alone in the cogging procedure).
    eps, gamma, Q, Q0
        See :class:`NpfsiEstimator`.
    theta0 : dict, optional
        Initial guesses by name (default: the model's constants).
    differentiator : optional
        How the velocities are estimated. Default: the papers' high-gain observer
        (``HighGainDifferentiator``, eps_obs = 2 ms); pass a ``SavitzkyGolay`` for zero-phase
        velocities.

    Returns
    -------
    NpfsiResult
        The estimate's trajectory and final values; ``status`` ``"diverged"`` or ``"ill_posed"``
        when the run did not give an estimate.
    """
    diff = HighGainDifferentiator(log.sample_time) if differentiator is None else differentiator
    A, b, y, method = stage_regression(log, model, estimate, diff)
    consts = dict(zip(CONSTANT_NAMES, model.constants.as_array(), strict=True))
    init = {k: consts[k] for k in estimate}
    for key, value in (theta0 or {}).items():
        if key not in init:
            raise InputError(f"theta0: {key!r} is not estimated ({tuple(estimate)})")
        init[key] = float(value)
    est = NpfsiEstimator(eps, gamma, Q, Q0)
    return est.run(
        A,
        b,
        y,
        log.sample_time,
        [init[k] for k in estimate],
        names=tuple(estimate),
        t=log.t - log.t[0],
        sources=(log.source,),
        velocity_method=method,
    )
