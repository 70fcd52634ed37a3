"""Physical effects of the real rig that the papers' model leaves out, each with its parameters.

Every effect is a frozen dataclass with physical parameters in SI units and defaults of the size
a stage like the Quanser 2-DOF maglev has; :class:`TwinEffects` collects the ones switched on.
The twin (:mod:`maglev_oc.sim.twin`) turns them into CasADi expressions.

Sources for the defaults: papers 000/001/002 where they give numbers (encoder 10 um, amplifier
7 A continuous / 9 A peak, loop 5 kHz, cogging over 1 N below 15 mm, guide friction and
misalignment limiting the tracking to about 0.1-0.2 mm); typical catalogue values for small
preloaded linear ball guides and linear current amplifiers elsewhere (stated per field).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field, fields
from typing import Any

import casadi as ca

from maglev_oc.errors import InputError
from maglev_oc.model.hardware import (
    CONTINUOUS_CURRENT_LIMIT,
    ENCODER_RESOLUTION,
    PEAK_CURRENT_LIMIT,
    STOPPER_GAP,
    STOPPER_POSITION,
)

__all__ = [
    "CableForce",
    "Cogging",
    "CommutationOffset",
    "CurrentAmplifier",
    "Encoder",
    "ForceRipple",
    "GuideFriction",
    "GuideMisalignment",
    "Stoppers",
    "TwinEffects",
]


def _positive(obj: Any, *names: str, allow_zero: bool = True) -> None:
    for name in names:
        value = getattr(obj, name)
        ok = value >= 0 if allow_zero else value > 0
        if not (isinstance(value, (int, float)) and math.isfinite(value) and ok):
            kind = "non-negative" if allow_zero else "positive"
            raise InputError(f"{type(obj).__name__}.{name} must be {kind} and finite, got {value!r}")


@dataclass(frozen=True)
class Cogging:
    """Cogging of the slotted stator, eq. (9) of paper 000, acting on the normal force.

    F_n += xi(x1) sin(pi x3 / t1 + phase), xi(x1) = peak_at_reference * (reference_gap / x1)^exponent,
    plus an optional longitudinal detent force F_x = horizontal_peak (reference_gap / x1)^exponent
    sin(2 pi x3 / t1 + phase). The defaults put xi(15 mm) = 1.5 N, growing as the gap closes
    (5 N at 10 mm) and under 0.35 N above 25 mm: "appreciable (greater than 1 N) when the air gap
    is smaller than 15 mm, and otherwise negligible" (000 Sec. V-C).
    """

    peak_at_reference: float = 1.5  # [N]
    reference_gap: float = 15e-3  # [m]
    exponent: float = 3.0  # [-]
    phase: float = 0.0  # [rad]
    horizontal_peak: float = 0.0  # [N] longitudinal detent at reference_gap (off by default)

    def __post_init__(self) -> None:
        _positive(self, "peak_at_reference", "exponent", "horizontal_peak")
        _positive(self, "reference_gap", allow_zero=False)


@dataclass(frozen=True)
class GuideFriction:
    """Friction of one axis's linear guides: Dahl's model (Coulomb with pre-sliding) + viscous.

    The Coulomb part is a state F with dF/dt = sigma v (1 - F sign(v) / F_c), sigma =
    coulomb / presliding_distance: at reversal the force builds up over a few micrometres of
    elastic pre-sliding (as in real ball guides) instead of jumping, so integral action can
    position the mover to the encoder's resolution without the hunting limit cycle that a pure
    Coulomb law produces. Total force opposing the motion: F + viscous v.
    Defaults (class): a preloaded miniature ball guide pair, 1 N, 5 um of pre-sliding.
    The rig preset (:meth:`TwinEffects.rig`) uses 0.1 N horizontally and 0.3 N vertically. The
    reason is a finding: with the papers' regulator, whose internal model contains an
    undamped omega0 oscillator, guide friction sustains a hunting limit cycle at omega0 around a
    set-point whose amplitude grows with the Coulomb level (about 135 um at 1 N vertically,
    50 um at 0.3 N, 10 um at 0.1 N on the twin). The papers' rig settled to the encoder's 10 um,
    which bounds its effective friction to these levels.
    """

    coulomb: float = 1.0  # [N]
    viscous: float = 2.0  # [N s/m]
    presliding_distance: float = 5e-6  # [m]

    def __post_init__(self) -> None:
        _positive(self, "coulomb", "viscous")
        _positive(self, "presliding_distance", allow_zero=False)

    @property
    def stiffness(self) -> float:
        """Pre-sliding stiffness sigma [N/m]."""
        return self.coulomb / self.presliding_distance

    def dahl_step(self, force, velocity, h: float, level=None, scale=1.0, coulomb=None):
        """The Coulomb state after a step ``h`` [s] with the velocity held (CasADi expressions):
        dF/dt = sigma v - (sigma |v| / Fc) F is linear in F, so F(h) = Fss + (F - Fss)
        exp(-sigma |v| h / Fc), Fss = Fc sign(v). ``level``: the Coulomb level Fc (default
        the guides' Coulomb level; the 2-DOF twin raises it where the guides bind). ``scale``: guides
        whose Coulomb level and pre-sliding stiffness are ``scale`` times these (the same
        pre-sliding distance), whose state is ``scale`` times this one's; 0 is frictionless.
        ``coulomb``: the guides' Coulomb level in place of :attr:`coulomb` (a number, or a
        CasADi expression that must stay positive: a twin whose level is a state row). Without
        Coulomb friction (sigma = 0) the state stays where it is (zero from rest): a purely
        viscous guide."""
        coulomb = self.coulomb if coulomb is None else coulomb
        fc = coulomb if level is None else level
        f_ss = scale * fc * ca.sign(velocity)
        if isinstance(coulomb, (int, float)) and coulomb == 0:
            return force
        stiffness = coulomb / self.presliding_distance  # :attr:`stiffness` at this level
        # (-sigma h) first: CasADi folds a number sigma so, and a level given as an expression
        # then gives the same operations
        return f_ss + (force - f_ss) * ca.exp((-stiffness * h) * ca.fabs(velocity) / fc)


@dataclass(frozen=True)
class GuideMisalignment:
    """Imperfect alignment of the linear guides (001 Sec. VI-B, 002 Sec. 7.2).

    - The horizontal guides are not parallel to the stator: the magnetic gap differs from the
      vertical encoder's reading by tilt * x3 + waviness sin(2 pi x3 / waviness_period).
    - The horizontal guides are not level: gravity pulls along them, G sin(level_tilt) (a
      constant disturbance Delta_1 of 001).
    - Binding: the guide preload, hence the Coulomb friction, grows away from the aligned
      position, by ``binding`` [N/m] * |x3|, on both axes.
    Defaults: 0.5 mrad tilt (25 um of gap over +-50 mm), 15 um waviness over a 25 mm period,
    1 mrad off level, 3 N/m binding (0.15 N extra at the ends of travel).
    """

    tilt: float = 5e-4  # [rad]
    waviness: float = 15e-6  # [m]
    waviness_period: float = 25e-3  # [m]
    level_tilt: float = 1e-3  # [rad]
    binding: float = 3.0  # [N/m]

    def __post_init__(self) -> None:
        for name in ("tilt", "level_tilt"):
            value = getattr(self, name)
            if not (math.isfinite(value) and abs(value) < 0.05):
                raise InputError(f"GuideMisalignment.{name} must be a small angle [rad], got {value!r}")
        _positive(self, "waviness", "binding")
        _positive(self, "waviness_period", allow_zero=False)


@dataclass(frozen=True)
class CurrentAmplifier:
    """The three linear current amplifiers (LCAMs), seen in d-q coordinates.

    First-order current response with the given bandwidth; the current-vector magnitude
    (= the phase-current amplitude for the amplitude-invariant transform of 002) is limited to
    ``peak`` [A], and to ``continuous`` [A] once the thermal state, a low-pass of |i|^2 with
    ``thermal_time_constant``, exceeds continuous^2 (I^2 t foldback). 002 Sec. 4: 7 A continuous,
    9 A peak; "factory tuned to account for the inductance of the stator coils".
    """

    bandwidth_hz: float = 1000.0  # [Hz]
    peak: float = PEAK_CURRENT_LIMIT  # [A]
    continuous: float = CONTINUOUS_CURRENT_LIMIT  # [A]
    thermal_time_constant: float = 2.0  # [s]

    def __post_init__(self) -> None:
        _positive(self, "bandwidth_hz", "peak", "continuous", "thermal_time_constant", allow_zero=False)
        if self.continuous > self.peak:
            raise InputError(
                f"CurrentAmplifier.continuous = {self.continuous} A exceeds peak = {self.peak} A"
            )

    @property
    def time_constant(self) -> float:
        return 1.0 / (2 * math.pi * self.bandwidth_hz)


@dataclass(frozen=True)
class Encoder:
    """The two linear optical encoders: quantization to ``resolution`` plus white noise.

    000 Sec. II: resolution 10 um. ``noise_std`` models vibration/electrical pick-up before the
    quantizer (default 2 um, a fifth of a count); ``offset`` is a mounting offset of the gap
    reading [m] (default 0).
    """

    resolution: float = ENCODER_RESOLUTION  # [m]
    noise_std: float = 2e-6  # [m]
    offset: tuple[float, float] = (0.0, 0.0)  # [m] (gap, horizontal)

    def __post_init__(self) -> None:
        _positive(self, "resolution", "noise_std")


@dataclass(frozen=True)
class CommutationOffset:
    """Misaligned commutation: the amplifiers' electrical angle is off by ``angle`` [rad] from the
    magnets' poles (the encoder zero was set a little off), so the applied d-q currents are the
    commanded ones rotated: i_q' = i_q cos(d) + i_d sin(d), i_d' = i_d cos(d) - i_q sin(d).
    Part of i_d then produces thrust and part of i_q normal force. Default 0.05 rad (3 deg:
    1 mm of encoder-zero error over the 57 mm pole pitch)."""

    angle: float = 0.05  # [rad]

    def __post_init__(self) -> None:
        if not (math.isfinite(self.angle) and abs(self.angle) < 0.5):
            raise InputError(f"CommutationOffset.angle must be a small angle [rad], got {self.angle!r}")


@dataclass(frozen=True)
class ForceRipple:
    """Thrust ripple: the propulsion force K1 i_q is modulated along the track,
    (1 + amplitude sin(2 pi x3 / period + phase)), from the slotting and the winding harmonics.
    Default 4 % at the slot pitch t1 = 19.05 mm (= tau / 3, the sixth electrical harmonic)."""

    amplitude: float = 0.04  # [-] fraction of the thrust
    period: float = 19.05e-3  # [m]
    phase: float = 0.0  # [rad]

    def __post_init__(self) -> None:
        if not (0 <= self.amplitude < 0.5):
            raise InputError(f"ForceRipple.amplitude must be a fraction in [0, 0.5), got {self.amplitude!r}")
        _positive(self, "period", allow_zero=False)


@dataclass(frozen=True)
class CableForce:
    """The cable carrier of the moving platform: a position-dependent horizontal force
    F = -stiffness (x3 - neutral) (a bent cable chain pushes back towards its neutral position).
    Default 8 N/m, neutral at -20 mm: up to 0.56 N at the far end of travel."""

    stiffness: float = 8.0  # [N/m]
    neutral: float = -20e-3  # [m]

    def __post_init__(self) -> None:
        _positive(self, "stiffness")


@dataclass(frozen=True)
class Stoppers:
    """Mechanical stoppers of the vertical and horizontal guides (002 Fig. 5).

    Travel about 10 mm vertically and +-50 mm horizontally (002 Sec. 4); the stoppers sit a
    little outside the working range. A hit stops the axis (inelastic) and is reported.
    """

    gap: tuple[float, float] = STOPPER_GAP  # [m]
    horizontal: tuple[float, float] = STOPPER_POSITION  # [m]


@dataclass(frozen=True)
class TwinEffects:
    """The effects switched on in a twin (None = off). See :meth:`ideal` and :meth:`rig`.

    ``locked_gap`` / ``locked_position`` block an axis at a value (the papers' verification
    experiments constrain one axis by hardware, 000 Sec. V); see :meth:`locked`.
    """

    cogging: Cogging | None = None
    friction_horizontal: GuideFriction | None = None
    friction_vertical: GuideFriction | None = None
    misalignment: GuideMisalignment | None = None
    amplifier: CurrentAmplifier | None = None
    encoder: Encoder | None = None
    commutation: CommutationOffset | None = None
    ripple: ForceRipple | None = None
    cable: CableForce | None = None
    extra: Any = None  # casadi.Function (x (4), i (2)) -> (x2', x4') [m/s^2]: e.g. an identified effect
    stoppers: Stoppers | None = field(default_factory=Stoppers)
    input_delay_samples: int = 0  # computation delay of the real-time loop [samples]
    locked_gap: float | None = None  # [m] vertical motion blocked by stoppers at this gap
    locked_position: float | None = None  # [m] horizontal motion blocked at this position

    def __post_init__(self) -> None:
        if self.extra is not None:
            f = self.extra
            ok = hasattr(f, "n_in") and f.n_in() == 2 and f.size1_in(0) == 4 and f.size1_in(1) == 2
            if not ok or f.size1_out(0) != 2:
                raise InputError("TwinEffects.extra must be a casadi.Function (x (4), i (2)) -> acc (2)")
        if self.locked_gap is not None and not (0 < self.locked_gap < 0.1):
            raise InputError(f"TwinEffects.locked_gap must be a gap in metres, got {self.locked_gap!r}")
        if self.locked_position is not None and not abs(self.locked_position) < 0.5:
            raise InputError(
                f"TwinEffects.locked_position must be a position in metres, got {self.locked_position!r}"
            )
        if not (isinstance(self.input_delay_samples, int) and 0 <= self.input_delay_samples <= 10):
            raise InputError(
                f"TwinEffects.input_delay_samples must be an integer in 0..10, got "
                f"{self.input_delay_samples!r}"
            )

    @classmethod
    def ideal(cls) -> TwinEffects:
        """The papers' model exactly: exact positions, ideal amplifier, no friction (stoppers kept)."""
        return cls()

    @classmethod
    def rig(cls, **overrides: Any) -> TwinEffects:
        """The effects the papers report for their rig, with the defaults above; override or add
        any by keyword (commutation, ripple and cable are off unless given)."""
        base = dict(
            commutation=None,
            ripple=None,
            cable=None,
            cogging=Cogging(),
            friction_horizontal=GuideFriction(coulomb=0.1, viscous=1.0),
            friction_vertical=GuideFriction(coulomb=0.3, viscous=2.0),
            misalignment=GuideMisalignment(),
            amplifier=CurrentAmplifier(),
            encoder=Encoder(),
            stoppers=Stoppers(),
            input_delay_samples=1,
        )
        unknown = set(overrides) - set(base)
        if unknown:
            raise TypeError(f"unknown effect(s) {sorted(unknown)}; known: {sorted(base)}")
        base.update(overrides)
        return cls(**base)

    def enabled(self) -> list[str]:
        """Names of the effects that are on."""
        skip = ("input_delay_samples", "locked_gap", "locked_position")
        return [f.name for f in fields(self) if f.name not in skip and getattr(self, f.name)]

    def describe(self) -> list[str]:
        """Each effect that is on, in plain words with its size (what a report states)."""
        words = []
        if c := self.cogging:
            words.append(
                f"cogging {c.peak_at_reference:g} N peak at {c.reference_gap * 1e3:g} mm gap, "
                f"falling as gap^-{c.exponent:g}"
                + (f", {c.horizontal_peak:g} N along the travel" if c.horizontal_peak else "")
            )
        for axis, f in (("horizontal", self.friction_horizontal), ("vertical", self.friction_vertical)):
            if f:
                words.append(f"{axis} guide friction {f.coulomb:g} N Coulomb + {f.viscous:g} N s/m viscous")
        if m := self.misalignment:
            words.append(
                f"guide misalignment ({m.tilt * 1e3:g} mrad tilt, {m.waviness * 1e6:g} µm waviness "
                f"over {m.waviness_period * 1e3:g} mm, guides {m.level_tilt * 1e3:g} mrad off level, "
                f"binding {m.binding:g} N/m)"
            )
        if a := self.amplifier:
            words.append(
                f"current amplifiers {a.bandwidth_hz:g} Hz bandwidth, {a.continuous:g} A continuous / "
                f"{a.peak:g} A peak"
            )
        if e := self.encoder:
            words.append(f"encoders {e.resolution * 1e6:g} µm steps, {e.noise_std * 1e6:g} µm noise")
        if c := self.commutation:
            words.append(f"commutation angle off by {c.angle:g} rad")
        if r := self.ripple:
            words.append(f"thrust ripple {r.amplitude * 100:g} % over {r.period * 1e3:g} mm")
        if c := self.cable:
            words.append(f"cable drag {c.stiffness:g} N/m about {c.neutral * 1e3:g} mm")
        if self.extra is not None:
            words.append("an identified extra force")
        if self.input_delay_samples:
            n = self.input_delay_samples
            words.append(f"{n} sample{'s' if n > 1 else ''} of computation delay")
        return words

    def locked(self, **locks: float | None) -> TwinEffects:
        """The same effects with an axis blocked by the hardware stoppers, as in the papers'
        verification procedures (000 Sec. V): ``locked(gap=0.02)`` or ``locked(position=0.0)``."""
        unknown = set(locks) - {"gap", "position"}
        if unknown:
            raise TypeError(f"locked() takes gap and/or position, got {sorted(unknown)}")
        return dataclasses.replace(
            self,
            locked_gap=locks.get("gap", self.locked_gap),
            locked_position=locks.get("position", self.locked_position),
        )
