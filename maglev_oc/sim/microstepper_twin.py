"""The 3-DOF microstepper's rig twin (002 Sec. 8): the platform model plus the rig's effects.

The twin is the platform of :func:`~maglev_oc.model.platform.microstepper` (state (x, x', y, y',
gap, gap'), inputs (i_qA, i_dA, i_qB, i_dB)) with the effects of :mod:`~maglev_oc.sim.effects`,
sampled at 5 kHz with a zero-order hold on the commands:

    y[k]   = measure(s[k], w[k])       encoder readings (x, y, gap) [m], w (3) standard normal
    s[k+1] = step(s[k], u_cmd[k])      one sample of the plant

with s = (q (6), applied currents (4) [A], Dahl friction forces (3) [N] (x, y, gap), delay buffer
(4 * input_delay_samples) [A]). Per effect, as in the 2-DOF twin (:class:`~maglev_oc.sim.twin.RigTwin`)
and with its rig preset's sizes (:meth:`MicrostepperEffects.rig`):

* encoders: 10 um quantization after white noise (2 um) on all three axes;
* amplifiers: each pair's current magnitude limited to 9 A (the vector scaled, direction kept),
  then a first-order current response (1 kHz); one sample of computation delay before them;
* guide friction per axis: Dahl (Coulomb with pre-sliding) plus viscous, x and y sized like the
  2-DOF horizontal guides (0.1 N, 1 N s/m), the gap like its vertical guides (0.3 N, 2 N s/m);
* cogging of each motor (:class:`~maglev_oc.sim.effects.Cogging`, 000 eq. (9)) at its own gap
  and position along its stator, along its normal (0.63 N per motor at 20 mm, 0.19 N at 30 mm);
* stoppers: x and y at +-60 mm (the 2-DOF's horizontal ones); the gap at 8 mm (the 2-DOF's lower
  one) and 35 mm: the 2-DOF's upper stopper, 30 mm, is the edge of the microstepper's operating
  region [20, 30] mm (002 Sec. 8), so it sits 5 mm further out here, as the 2-DOF's sits 5 mm
  above that rig's working range.

Left out, and why: the thermal foldback to 7 A (the holding currents are under 4 A and the
saturated transients last tenths of a second), guide misalignment (002 Sec. 8 credits the
microstepper's precision to "better alignment of the linear guides"), thrust ripple, commutation
offset and cable force (off in the 2-DOF rig preset too).

Mechanics: RK4 (``substeps`` per sample, the currents entering at each stage's time along the
amplifier's exact first-order response); the friction forces held over the sample and updated
exactly (Dahl's law is linear in the force at a held velocity), as in the 2-DOF twin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.control.microstepper import AXES, N_MEASUREMENTS, saturated_currents
from maglev_oc.errors import InputError
from maglev_oc.model.allocation import MicrostepperTransformation
from maglev_oc.model.hardware import MICROSTEPPER_STOPPER_GAP, RIG_SAMPLE_TIME, STOPPER_POSITION
from maglev_oc.model.platform import Platform, PlatformModel
from maglev_oc.numerics import rk4_step
from maglev_oc.sim.effects import Cogging, CurrentAmplifier, Encoder, GuideFriction, Stoppers

__all__ = ["MICROSTEPPER_STOPPERS", "MicrostepperEffects", "MicrostepperTwin"]

MICROSTEPPER_STOPPERS = Stoppers(gap=MICROSTEPPER_STOPPER_GAP, horizontal=STOPPER_POSITION)
"""Stoppers of the microstepper twin [m]: ``horizontal`` on x and y (module docstring)."""


@dataclass(frozen=True)
class MicrostepperEffects:
    """The effects switched on in a microstepper twin (None = off); see :meth:`rig`.

    ``friction`` has one entry per axis (x, y, gap).
    """

    encoder: Encoder | None = None
    amplifier: CurrentAmplifier | None = None
    friction: tuple[GuideFriction | None, GuideFriction | None, GuideFriction | None] = (None, None, None)
    cogging: Cogging | None = None
    stoppers: Stoppers | None = MICROSTEPPER_STOPPERS
    input_delay_samples: int = 0

    def __post_init__(self) -> None:
        if len(self.friction) != 3:
            raise InputError(f"friction needs one entry per axis (x, y, gap), got {len(self.friction)}")
        if self.encoder is not None and any(o != 0 for o in self.encoder.offset):
            raise InputError(
                f"encoder offsets are not modelled on the microstepper, got {self.encoder.offset}"
            )
        if not (isinstance(self.input_delay_samples, int) and 0 <= self.input_delay_samples <= 10):
            raise InputError(
                f"input_delay_samples must be an integer in 0..10, got {self.input_delay_samples!r}"
            )

    @classmethod
    def ideal(cls) -> MicrostepperEffects:
        """The model exactly: exact positions, ideal amplifiers, no friction (stoppers kept)."""
        return cls()

    @classmethod
    def rig(cls, **overrides) -> MicrostepperEffects:
        """The rig's effects with the 2-DOF rig preset's sizes (module docstring); override any by
        keyword (unknown ones raise TypeError)."""
        horizontal = GuideFriction(coulomb=0.1, viscous=1.0)
        base = dict(
            encoder=Encoder(),
            amplifier=CurrentAmplifier(),
            friction=(horizontal, horizontal, GuideFriction(coulomb=0.3, viscous=2.0)),
            cogging=Cogging(),
            stoppers=MICROSTEPPER_STOPPERS,
            input_delay_samples=1,
        )
        unknown = set(overrides) - set(base)
        if unknown:
            raise TypeError(f"unknown effect(s) {sorted(unknown)}; known: {sorted(base)}")
        base.update(overrides)
        return cls(**base)

    def enabled(self) -> list[str]:
        """Names of the effects that are on."""
        on = [n for n in ("encoder", "amplifier", "cogging", "stoppers") if getattr(self, n) is not None]
        on += [f"friction_{a}" for a, f in zip(AXES, self.friction, strict=True) if f is not None]
        return on + (["input_delay"] if self.input_delay_samples else [])


@dataclass(frozen=True, eq=False)
class MicrostepperTwin:
    """The 3-DOF rig twin (module docstring). Build once; its Functions serve every run.

    Parameters
    ----------
    platform : Platform
        The true plant (:func:`~maglev_oc.model.platform.microstepper`).
    effects : MicrostepperEffects
        Default: :meth:`MicrostepperEffects.rig`.
    sample_time : float
        [s], default 2e-4 (5 kHz).
    substeps : int
        RK4 steps per sample.

    Attributes
    ----------
    n_state : int
    model : PlatformModel
        The true plant's Functions.
    measure : (s, w (3)) -> y (3) [m]
    step : (s, u_cmd (4)) -> (s_next, flags (3)); flags :attr:`FLAG_NAMES`, 0/1
    acceleration : (q (6), i (4), friction (3)) -> q'' (3) [m/s^2] of the true plant at applied
        currents i [A] and Dahl friction forces [N], every effect on the mechanics included
    """

    platform: Platform
    effects: MicrostepperEffects = field(default_factory=MicrostepperEffects.rig)
    sample_time: float = RIG_SAMPLE_TIME
    substeps: int = 1
    n_state: int = field(init=False)
    measure: ca.Function = field(init=False, repr=False)
    step: ca.Function = field(init=False, repr=False)
    acceleration: ca.Function = field(init=False, repr=False)

    FLAG_NAMES = ("limited_A", "limited_B", "stopper_hit")

    def __post_init__(self) -> None:
        if not (self.sample_time > 0 and math.isfinite(self.sample_time)):
            raise InputError(f"sample_time must be positive [s], got {self.sample_time!r}")
        if not (isinstance(self.substeps, int) and self.substeps >= 1):
            raise InputError(f"substeps must be a positive integer, got {self.substeps!r}")
        set_ = object.__setattr__
        set_(self, "n_state", 13 + 4 * self.effects.input_delay_samples)
        set_(self, "model", PlatformModel(self.platform))
        set_(self, "transformation", MicrostepperTransformation(self.platform))
        q, i, fr = ca.SX.sym("q", 6), ca.SX.sym("i", 4), ca.SX.sym("friction", 3)
        set_(
            self,
            "acceleration",
            ca.Function(
                "microstepper_acc",
                [q, i, fr],
                [self._acceleration(q, i, fr)],
                ["q", "i", "friction"],
                ["acc"],
            ),
        )
        set_(self, "step", self._step_function())
        set_(self, "measure", self._measure_function())

    def _acceleration(self, q, i, friction):
        """q'' (3) [m/s^2] at state q (6), applied currents i (4), Dahl forces (3) [N]."""
        pf, e = self.platform, self.effects
        acc = self.model.f(q, i)[1::2]
        masses = ca.DM(pf.masses)
        if e.cogging is not None:
            c = e.cogging
            _, _, gaps, positions = self.model.motor_forces(q, ca.DM.zeros(pf.n_inputs))
            force = ca.SX.zeros(3)
            for k, motor in enumerate(pf.motors):
                scale = (c.reference_gap / gaps[k]) ** c.exponent
                angle = math.pi * positions[k] / pf.params.slot_pitch + c.phase
                force += c.peak_at_reference * scale * ca.sin(angle) * ca.DM(motor.normal)
                if c.horizontal_peak > 0:
                    force += c.horizontal_peak * scale * ca.sin(2 * angle) * ca.DM(motor.thrust)
            acc += force / masses
        for j, fr in enumerate(e.friction):
            if fr is not None:
                acc[j] -= (friction[j] + fr.viscous * q[2 * j + 1]) / pf.masses[j]
        return acc

    def _current_at(self, u_sat, i0, theta: float):
        """The applied currents theta [s] into the sample (first-order response, exact)."""
        amp = self.effects.amplifier
        if amp is None:
            return u_sat
        return u_sat + (i0 - u_sat) * math.exp(-theta / amp.time_constant)

    def _step_function(self) -> ca.Function:
        e = self.effects
        s = ca.SX.sym("s", self.n_state)
        u_cmd = ca.SX.sym("u", 4)
        q, cur, fric = s[0:6], s[6:10], s[10:13]
        if e.input_delay_samples > 0:
            buf = s[13:]
            u_in, buf_next = buf[0:4], ca.vertcat(buf[4:], u_cmd)
        else:
            u_in, buf_next = u_cmd, ca.SX.zeros(0, 1)
        if e.amplifier is not None:
            u_sat, over = saturated_currents(u_in, e.amplifier.peak)
        else:
            u_sat, over = u_in, ca.SX.zeros(2)

        def rhs(z, i):
            acc = self._acceleration(z, i, fric)
            return ca.vertcat(z[1], acc[0], z[3], acc[1], z[5], acc[2])

        h = self.sample_time / self.substeps
        z = q
        for k in range(self.substeps):
            t0 = k * h
            z = rk4_step(
                rhs,
                z,
                h,
                self._current_at(u_sat, cur, t0),
                args_mid=(self._current_at(u_sat, cur, t0 + h / 2),),
                args_end=(self._current_at(u_sat, cur, t0 + h),),
            )
        z, hit = self._stopped(z)
        fric_next = ca.vertcat(
            *(_dahl(fric[j], fr, q[2 * j + 1], self.sample_time) for j, fr in enumerate(e.friction))
        )
        s_next = ca.vertcat(z, self._current_at(u_sat, cur, self.sample_time), fric_next, buf_next)
        return ca.Function(
            "microstepper_twin_step",
            [s, u_cmd],
            [s_next, ca.vertcat(over, hit)],
            ["s", "u"],
            ["s_next", "flags"],
        )

    def _stopped(self, z):
        """(state after the stoppers, hit flag): a hit stops the axis (inelastic)."""
        st = self.effects.stoppers
        if st is None:
            return z, ca.SX(0)
        out, hits = [], []
        for j, (lo, hi) in enumerate((st.horizontal, st.horizontal, st.gap)):
            pos, vel = z[2 * j], z[2 * j + 1]
            hit = ca.logic_or(pos < lo, pos > hi)
            out += [ca.fmin(ca.fmax(pos, lo), hi), ca.if_else(hit, 0, vel)]
            hits.append(hit)
        return ca.vertcat(*out), ca.logic_or(ca.logic_or(hits[0], hits[1]), hits[2])

    def _measure_function(self) -> ca.Function:
        s = ca.SX.sym("s", self.n_state)
        w = ca.SX.sym("w", N_MEASUREMENTS)
        pos = s[0:6:2]
        enc = self.effects.encoder
        if enc is not None:
            y = ca.floor((pos + enc.noise_std * w) / enc.resolution + 0.5) * enc.resolution
        else:
            y = pos
        return ca.Function("microstepper_measure", [s, w], [y], ["s", "w"], ["y"])

    def holding_currents(self, gap: float) -> np.ndarray:
        """The currents that hold the true plant at rest (minimum norm).

        Parameters
        ----------
        gap : float
            [m].

        Returns
        -------
        (4,) array
            (i_qA, i_dA, i_qB, i_dB) [A]; zeros where no equilibrium exists.
        """
        alloc = self.transformation.allocate(gap, np.zeros(3))
        return alloc.currents if alloc.defined else np.zeros(4)

    def initial_state(self, q0, u0) -> np.ndarray:
        """The twin state at a mechanical state with currents already flowing.

        Parameters
        ----------
        q0 : (6,) array
            (x, x', y, y', gap, gap') [m, m/s].
        u0 : (4,) array
            (i_qA, i_dA, i_qB, i_dB) [A], also filling the delay buffer.

        Returns
        -------
        (n_state,) array
            With the guides' friction relaxed (zero force).
        """
        q0 = np.asarray(q0, dtype=float).reshape(6)
        u0 = np.asarray(u0, dtype=float).reshape(4)
        buf = np.tile(u0, self.effects.input_delay_samples)
        return np.concatenate([q0, u0, np.zeros(3), buf])


def _dahl(force, fr: GuideFriction | None, vel, h: float):
    """Dahl's friction force over a step h [s] with the velocity held (the 2-DOF twin's law,
    :meth:`GuideFriction.dahl_step`)."""
    if fr is None:
        return ca.SX(0)
    return fr.dahl_step(force, vel, h)
