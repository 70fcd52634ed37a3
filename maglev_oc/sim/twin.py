"""The rig twin: the stage model of SPEC 1 plus the effects of :mod:`maglev_oc.sim.effects`,
sampled at the rig's 5 kHz with a zero-order hold on the current commands.

The twin is a discrete-time system built once as CasADi Functions:

    y[k]   = measure(s[k], w[k])          encoder readings (gap, horizontal) [m]
    s[k+1] = step(s[k], u_cmd[k])         one sample of the plant under ZOH

with the twin state s = (x (4), i (2) actual d-q currents [A], heat (1) [A^2], guide friction
forces (2) [N] (Dahl model: vertical, horizontal), delay buffer
(2 * input_delay_samples) [A]) and w[k] (2) standard-normal encoder noise. Inside a sample the
mechanics are integrated with fixed-step RK4 (``substeps`` per sample; one step of 200 us is
accurate to ~1e-12 relative, since the fastest mechanical pole is 64 1/s) and the amplifier's
linear first-order current response to the held command is solved exactly. Its true
constants are those of ``model`` and may differ from the ones a controller is designed with.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.model.hardware import RIG_SAMPLE_TIME
from maglev_oc.model.stage import StageModel
from maglev_oc.numerics import rk4_step
from maglev_oc.sim.effects import TwinEffects

__all__ = ["ConstantsAsInput", "RigTwin"]


class ConstantsAsInput:
    """What :meth:`RigTwin._accelerations` reads of a model (``params``, ``L``), with the
    constants given as a CasADi expression instead of the model's numbers (the twins whose plant
    is part of their state)."""

    def __init__(self, model: StageModel, constants) -> None:
        self.params = model.params
        self._model = model
        self._constants = constants

    def L(self, y):
        L = self._model.L_theta(y, self._constants)
        return L[0], L[1], L[2], L[3]


@dataclass(frozen=True, eq=False)
class RigTwin:
    """A configured twin. Build once; its Functions are reused by every simulation.

    Parameters
    ----------
    model : StageModel
        The true plant (Table I and the true C1..C4).
    effects : TwinEffects
        Effects switched on (default: none, the ideal plant).
    sample_time : float
        Control period [s] (default 2e-4, 5 kHz).
    substeps : int
        RK4 steps per sample.

    Attributes
    ----------
    n_state : int
    measure : (s, w) -> y (2)
    step : (s, u_cmd) -> (s_next, flags (3))  flags: :attr:`FLAG_NAMES` (current limited by
        the amplifier, a stopper hit, thermal foldback to the continuous limit), 0/1
    acceleration : (x, i, friction) -> (x2', x4') of the true plant at applied current i and
        guide friction forces (vertical, horizontal) [N], every effect on the mechanics
        included (continuous time; for analyses and diagnosis tests)
    """

    model: StageModel
    effects: TwinEffects = field(default_factory=TwinEffects.ideal)
    sample_time: float = RIG_SAMPLE_TIME
    substeps: int = 1
    n_state: int = field(init=False)
    measure: ca.Function = field(init=False, repr=False)
    step: ca.Function = field(init=False, repr=False)
    acceleration: ca.Function = field(init=False, repr=False)

    FLAG_NAMES = ("current_limited", "stopper_hit", "thermal_foldback")

    def __post_init__(self) -> None:
        if not (self.sample_time > 0 and math.isfinite(self.sample_time)):
            raise InputError(f"sample_time must be positive [s], got {self.sample_time!r}")
        if not (isinstance(self.substeps, int) and self.substeps >= 1):
            raise InputError(f"substeps must be a positive integer, got {self.substeps!r}")
        object.__setattr__(self, "n_state", 9 + 2 * self.effects.input_delay_samples)
        self._build()

    # ------------------------------------------------------------------------------------
    def _accelerations(self, x, i, friction):
        """(x2', x4') of the true plant with every effect that acts on the mechanics;
        ``friction`` (2) is the Dahl friction force state (vertical, horizontal) [N]."""
        p, e = self.model.params, self.effects
        gap = x[0]
        if e.misalignment is not None:
            m = e.misalignment
            gap = gap + m.tilt * x[2] + m.waviness * ca.sin(2 * math.pi * x[2] / m.waviness_period)
        L1, L2, L3, L4 = self.model.L(gap)
        G = p.gravity
        rotation = self._commutation_rotation()
        if rotation is not None:
            cd, sd = rotation
            i = ca.vertcat(i[0] * cd + i[1] * sd, i[1] * cd - i[0] * sd)
        thrust = L1
        if e.ripple is not None:
            r = e.ripple
            thrust = L1 * (1 + r.amplitude * ca.sin(2 * math.pi * x[2] / r.period + r.phase))
        acc_v = G - L2 - L3 * i[1] - L4 * (i[0] ** 2 + i[1] ** 2)
        acc_h = -thrust * i[0]
        if e.cable is not None:
            acc_h -= e.cable.stiffness * (x[2] - e.cable.neutral) / p.mass_horizontal
        if e.extra is not None:
            extra = e.extra(x, i)
            acc_v += extra[0]
            acc_h += extra[1]
        if e.cogging is not None:
            cog_v, cog_h = self._cogging_forces(x, gap)
            acc_v -= cog_v / p.mass_vertical
            if e.cogging.horizontal_peak > 0:
                acc_h += cog_h / p.mass_horizontal
        if e.misalignment is not None:
            acc_h += G * math.sin(e.misalignment.level_tilt)
        if e.friction_vertical is not None:
            acc_v -= (friction[0] + self._viscous_force(0, x[1])) / p.mass_vertical
        if e.friction_horizontal is not None:
            acc_h -= (friction[1] + self._viscous_force(1, x[3])) / p.mass_horizontal
        return acc_v, acc_h

    def _commutation_rotation(self):
        """(cos, sin) of the commutation offset, or None without one."""
        c = self.effects.commutation
        return None if c is None else (math.cos(c.angle), math.sin(c.angle))

    def _cogging_forces(self, x, gap):
        """(normal, along-travel) cogging forces [N] at the (misaligned) gap; effects.cogging set."""
        c, p = self.effects.cogging, self.model.params
        scale = (c.reference_gap / gap) ** c.exponent
        angle = math.pi * x[2] / p.slot_pitch + c.phase
        return self._cogging_peak() * scale * ca.sin(angle), c.horizontal_peak * scale * ca.sin(2 * angle)

    def _cogging_peak(self):
        """Normal cogging force at the reference gap [N]; effects.cogging set."""
        return self.effects.cogging.peak_at_reference

    def _viscous_force(self, axis: int, velocity):
        """Viscous friction force [N] of the guides of ``axis`` (0 vertical, 1 horizontal)."""
        fr = (self.effects.friction_vertical, self.effects.friction_horizontal)[axis]
        return fr.viscous * velocity

    def _coulomb_levels(self, x):
        """Coulomb levels (vertical, horizontal) [N]; binding raises them away from x3 = 0."""
        e = self.effects
        binding = 0.0
        if e.misalignment is not None:
            binding = e.misalignment.binding * ca.sqrt(x[2] ** 2 + 1e-8)
        levels = []
        for k, fr in enumerate((e.friction_vertical, e.friction_horizontal)):
            levels.append(0.0 if fr is None else self._coulomb(k) + binding)
        return levels

    def _coulomb(self, axis: int):
        """Coulomb level [N] of the guides of ``axis`` (0 vertical, 1 horizontal; friction on)."""
        return (self.effects.friction_vertical, self.effects.friction_horizontal)[axis].coulomb

    def _friction_update(self, friction, x, h):
        """Dahl's law over one step with the velocity held (:meth:`GuideFriction.dahl_step`), at
        the Coulomb levels of :meth:`_coulomb_levels`."""
        e = self.effects
        out = []
        levels = self._coulomb_levels(x)
        for k, (fr, vel) in enumerate(((e.friction_vertical, x[1]), (e.friction_horizontal, x[3]))):
            if fr is None:
                out.append(ca.SX(0))
            else:
                out.append(
                    fr.dahl_step(
                        friction[k], vel, h, levels[k], self._friction_scale(k), coulomb=self._coulomb(k)
                    )
                )
        return ca.vertcat(*out)

    def _friction_scale(self, axis: int):
        """Scale of the guides' Coulomb friction of ``axis`` (0 vertical, 1 horizontal): 1 here."""
        return 1.0

    def _build(self) -> None:
        """The Functions ``acceleration``, ``step`` and ``measure`` (built once, at construction)."""
        set_ = object.__setattr__
        set_(self, "acceleration", self._acceleration_function())
        set_(self, "step", self._step_function())
        set_(self, "measure", self._measure_function())

    def _acceleration_function(self) -> ca.Function:
        x = ca.SX.sym("x", 4)
        i = ca.SX.sym("i", 2)
        fr = ca.SX.sym("friction", 2)
        acc_v, acc_h = self._accelerations(x, i, fr)
        return ca.Function(
            "twin_acc", [x, i, fr], [ca.vertcat(acc_v, acc_h)], ["x", "i", "friction"], ["acc"]
        )

    def _step_function(self) -> ca.Function:
        """One sample under ZOH: delay buffer, amplifier, RK4 of the mechanics, stoppers, friction."""
        s = ca.SX.sym("s", self.n_state)
        u_cmd = ca.SX.sym("u", 2)
        s_next, flags = self._step_rows(s, u_cmd)
        return ca.Function("twin_step", [s, u_cmd], [s_next, flags], ["s", "u"], ["s_next", "flags"])

    def _step_rows(self, s, u_cmd):
        """(next state, flags) of one sample on the twin's own rows ``s`` (a subclass that carries
        more rows steps these and passes its own on)."""
        xs, cur, heat, fric = s[0:4], s[4:6], s[6], s[7:9]
        u_in, buf_next = self._delayed(s, u_cmd)
        u_sat, limited, foldback = self._amplified(u_in, heat)
        z = self._integrate(xs, heat, cur, fric, u_sat)
        x_next, hit = self._stopped(z[0:4])
        cur_next = self._current_at(u_sat, cur, self.sample_time)
        fric_next = self._friction_update(fric, xs, self.sample_time)
        return ca.vertcat(x_next, cur_next, z[4], fric_next, buf_next), ca.vertcat(limited, hit, foldback)

    def _delayed(self, s, u_cmd):
        """(command applied now, next delay buffer): the oldest command in the buffer when the
        loop has a computation delay, else the command itself."""
        if self.effects.input_delay_samples > 0:
            buf = s[9:]
            return buf[0:2], ca.vertcat(buf[2:], u_cmd)
        return u_cmd, ca.SX.zeros(0, 1)

    def _amplified(self, u_in, heat):
        """(command the amplifier follows, limited flag, foldback flag): the current-vector
        magnitude clipped to the peak, or to the continuous limit once the thermal state exceeds it."""
        amp = self.effects.amplifier
        if amp is None:
            return u_in, ca.SX(0), ca.SX(0)
        limit = ca.if_else(heat > amp.continuous**2, amp.continuous, amp.peak)
        mag = ca.sqrt(u_in[0] ** 2 + u_in[1] ** 2 + 1e-30)
        scale = ca.fmin(1.0, limit / mag)
        return u_in * scale, mag > limit, heat > amp.continuous**2

    def _current_at(self, u_sat, i0, theta: float):
        """The amplifier's current theta [s] into the step: its first-order response to the held
        command ``u_sat`` from ``i0``, exact (the lag is linear); ``u_sat`` itself without amplifier."""
        if self.effects.amplifier is None:
            return u_sat
        return u_sat + (i0 - u_sat) * self._current_decay(theta)

    def _current_decay(self, theta: float):
        """exp(-theta / tau) of the amplifiers' first-order lag (amplifier on)."""
        return math.exp(-theta / self.effects.amplifier.time_constant)

    def _integrate(self, xs, heat, i0, fric, u_sat):
        """(x (4), heat) at the end of the sample: ``substeps`` RK4 steps of the mechanics and the
        thermal state, the current entering at each stage's time."""
        amp = self.effects.amplifier
        tau_heat = amp.thermal_time_constant if amp is not None else 2.0  # bookkeeping only without

        def rhs(z, i_applied):
            xz, hz = z[0:4], z[4]
            av, ah = self._accelerations(xz, i_applied, fric)
            dh = (i_applied[0] ** 2 + i_applied[1] ** 2 - hz) / tau_heat
            return ca.vertcat(xz[1], av, xz[3], ah, dh)

        z = ca.vertcat(xs, heat)
        h = self.sample_time / self.substeps
        for k in range(self.substeps):
            t0 = k * h
            z = rk4_step(
                rhs,
                z,
                h,
                self._current_at(u_sat, i0, t0),
                args_mid=(self._current_at(u_sat, i0, t0 + h / 2),),
                args_end=(self._current_at(u_sat, i0, t0 + h),),
            )
        return z

    def _stopped(self, x_next):
        """(x after the stoppers and locks, stopper-hit flag): a hit stops the axis (inelastic)."""
        e = self.effects
        hit = ca.SX(0)
        if e.stoppers is not None:
            (g_lo, g_hi), (h_lo, h_hi) = e.stoppers.gap, e.stoppers.horizontal
            x1, x2, x3, x4 = x_next[0], x_next[1], x_next[2], x_next[3]
            hit_v = ca.logic_or(x1 < g_lo, x1 > g_hi)
            hit_h = ca.logic_or(x3 < h_lo, x3 > h_hi)
            hit = ca.logic_or(hit_v, hit_h)
            x_next = ca.vertcat(
                ca.fmin(ca.fmax(x1, g_lo), g_hi),
                ca.if_else(hit_v, 0, x2),
                ca.fmin(ca.fmax(x3, h_lo), h_hi),
                ca.if_else(hit_h, 0, x4),
            )
        if e.locked_gap is not None:
            x_next = ca.vertcat(e.locked_gap, 0, x_next[2], x_next[3])
        if e.locked_position is not None:
            x_next = ca.vertcat(x_next[0], x_next[1], e.locked_position, 0)
        return x_next, hit

    def _measure_function(self) -> ca.Function:
        """Encoder readings (gap, horizontal) [m]: offset, noise and quantization when on."""
        s = ca.SX.sym("s", self.n_state)
        w = ca.SX.sym("w", 2)
        xs = s[0:4]
        enc = self.effects.encoder
        if enc is not None:
            raw = ca.vertcat(xs[0] + enc.offset[0], xs[2] + enc.offset[1]) + enc.noise_std * w
            y = ca.floor(raw / enc.resolution + 0.5) * enc.resolution
        else:
            y = ca.vertcat(xs[0], xs[2])
        return ca.Function("twin_measure", [s, w], [y], ["s", "w"], ["y"])

    # ------------------------------------------------------------------------------------
    def initial_state(self, x0, u0=(0.0, 0.0)) -> np.ndarray:
        """Twin state for mechanical state ``x0`` with currents ``u0`` already flowing.

        Parameters
        ----------
        x0 : (4,) array
            [m, m/s, m, m/s] (a locked axis is put at its lock).
        u0 : (2,) array
            (i_q, i_d) [A], also filling the delay buffer; the thermal state is |u0|^2.

        Returns
        -------
        (n_state,) array
        """
        x0 = np.array(x0, dtype=float).reshape(4)
        u0 = np.asarray(u0, dtype=float).reshape(2)
        if self.effects.locked_gap is not None:
            x0[:2] = (self.effects.locked_gap, 0.0)
        if self.effects.locked_position is not None:
            x0[2:] = (self.effects.locked_position, 0.0)
        buf = np.tile(u0, self.effects.input_delay_samples)
        return np.concatenate([x0, u0, [u0 @ u0], [0.0, 0.0], buf])

    @staticmethod
    def mechanical(states: np.ndarray) -> np.ndarray:
        """The mechanical state rows (4, n) of a twin-state trajectory (n_state, n)."""
        return np.asarray(states)[:4]

    @staticmethod
    def currents(states: np.ndarray) -> np.ndarray:
        """The applied d-q current rows (2, n) of a twin-state trajectory."""
        return np.asarray(states)[4:6]
