"""Effects drawn at random within the ranges real linear-guide PMLSM stages show.

The named sets use each effect at two fixed sizes (``small()`` and ``large()``) and the variants
bench a few fixed shapes. A user's rig has each effect in its own proportions: this module draws
every parameter that a rig chooses (size, phase, sign, shape) independently, so that a diagnosis
tuned to the sets' values is tried on values nobody chose. The ranges are physical, written next
to each draw, and span at least the sets' small and large sizes; sizes are drawn log-uniformly
(a rig is as likely to be twice as rough as half as rough), phases uniformly, signs fairly.

``draw(kind, rng)`` returns one effect of that kind; :data:`KINDS` lists the kinds drawn.
Current saturation is left out (the diagnosis does not yet claim it; ``bench/diagnose_rigs.py
--saturation`` tries it alone).
"""

from __future__ import annotations

import math

import numpy as np

from . import effects as E

TWO_PI = 2.0 * math.pi


def _log(rng: np.random.Generator, lo: float, hi: float) -> float:
    """Log-uniform in [lo, hi]."""
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _sign(rng: np.random.Generator) -> float:
    return 1.0 if rng.random() < 0.5 else -1.0


def _friction(rng: np.random.Generator, axis: str) -> E.GuideFriction:
    # Coulomb force: well-adjusted to sealed, preloaded ball guides (0.3-1.2 N horizontally; the
    # vertical guides carry the magnets' side load, 0.6-2.4 N); breakaway 1-2x the Coulomb force;
    # Stribeck speeds of ball guides 1-10 mm/s; viscous drag of the lubricant and seals.
    horizontal = axis == "horizontal"
    coulomb = _log(rng, 0.3, 1.2) if horizontal else _log(rng, 0.6, 2.4)
    extra = {} if horizontal else {"bristle_stiffness": 3e5, "bristle_damping": 690.0}
    return E.GuideFriction(
        axis_=axis,
        coulomb_force=coulomb,
        static_force=coulomb * rng.uniform(1.0, 2.0),
        stribeck_velocity=_log(rng, 1e-3, 1e-2),
        viscous_coefficient=_log(rng, 1.0, 6.0) if horizontal else _log(rng, 3.0, 12.0),
        **extra,
    )


def _cogging(rng: np.random.Generator, cls: type, lo: float, hi: float) -> E.Effect:
    # The slot-pitch fundamental's peak, its phase against the encoder's zero, and a second
    # harmonic from the slot and magnet shapes (up to 0.9 of the fundamental).
    return cls(
        peak_force=_log(rng, lo, hi),
        phase=rng.uniform(0.0, TWO_PI),
        harmonic2_ratio=rng.uniform(0.0, 0.9),
        harmonic2_phase=rng.uniform(0.0, TWO_PI),
    )


def _end_effect(rng: np.random.Generator) -> E.EndEffect:
    # Thrust 5-12 % lost at the logged ends, attraction up to the same fraction (it needs no
    # winding under the mover, so it may fall less), fall-off 8-35 mm; one end may be far away
    # (a mover whose travel is off the stator's centre). The fringing's profile is any of the
    # generator's three (exponential, Gaussian, raised cosine), drawn last so that the other
    # parameters are those the same seed drew before the profiles existed.
    thrust = _log(rng, 0.05, 0.12)
    far = rng.random() < 0.25
    attraction, width = thrust * rng.uniform(0.0, 1.0), _log(rng, 0.008, 0.035)
    return E.EndEffect(
        thrust_loss=thrust,
        attraction_loss=attraction,
        width=width,
        end_position_minus=-0.3 if far else -0.05,
        profile=E.EndEffect.PROFILES[int(rng.integers(len(E.EndEffect.PROFILES)))],
    )


def _misalignment(rng: np.random.Generator) -> E.GuideMisalignment:
    # Guides 2-5 mrad out of parallel with the stator either way, and on half the rigs a waviness
    # of 3-8 um at the mounting-bolt pitch (40-80 mm).
    wavy = rng.random() < 0.5
    return E.GuideMisalignment(
        slope=_sign(rng) * _log(rng, 2e-3, 5e-3),
        waviness_amplitude=_log(rng, 3e-6, 8e-6) if wavy else 0.0,
        waviness_wavelength=rng.uniform(0.04, 0.08),
        waviness_phase=rng.uniform(0.0, TWO_PI),
    )


def _cable(rng: np.random.Generator) -> E.CableCarrier:
    # A cable carrier's spring (4-12 N/m) about a neutral point within the travel, and its sag's
    # constant pull either way.
    return E.CableCarrier(
        stiffness=_log(rng, 4.0, 12.0),
        neutral_position=rng.uniform(-0.03, 0.03),
        constant_force=rng.uniform(-0.2, 0.2),
    )


def _ripple(rng: np.random.Generator) -> E.ThrustRipple:
    # 2-5 % ripple at the 6th electrical harmonic, 0-2 % at the 2nd, phases unknown.
    return E.ThrustRipple(
        ratio=_log(rng, 0.02, 0.05),
        phase=rng.uniform(0.0, TWO_PI),
        ratio2=rng.uniform(0.0, 0.02),
        phase2=rng.uniform(0.0, TWO_PI),
    )


def _amplifier(rng: np.random.Generator) -> E.AmplifierDynamics:
    # Current loops of 150-600 Hz and 0-0.3 ms of transport delay (PWM and sampling).
    return E.AmplifierDynamics(bandwidth=_log(rng, 150.0, 600.0), delay=rng.uniform(0.0, 3e-4))


def _field(rng: np.random.Generator) -> E.FieldShape:
    # The magnets' field falling 2-4 /m faster (log-slope) with the gap than the model's, with a
    # curvature up to the large set's.
    return E.FieldShape(k1=_log(rng, 2.0, 4.0), k2=rng.uniform(-300.0, 0.0))


DRAWS = {
    "guide_friction_horizontal": lambda rng: _friction(rng, "horizontal"),
    "guide_friction_vertical": lambda rng: _friction(rng, "vertical"),
    "normal_cogging": lambda rng: _cogging(rng, E.NormalCogging, 1.0, 2.5),
    "detent_force": lambda rng: _cogging(rng, E.DetentForce, 0.8, 2.0),
    "end_effect": _end_effect,
    "guide_misalignment": _misalignment,
    "cable_carrier": _cable,
    "thrust_ripple": _ripple,
    # electrical angle offset 0.02-0.06 rad either way (a Hall sensor's or encoder zero's error)
    "commutation_offset": lambda rng: E.CommutationOffset(angle=_sign(rng) * _log(rng, 0.02, 0.06)),
    "amplifier_dynamics": _amplifier,
    "field_shape": _field,
    # a base 5-15 mrad out of level either way
    "tilted_base": lambda rng: E.TiltedBase(angle=_sign(rng) * _log(rng, 5e-3, 1.5e-2)),
}
KINDS = tuple(DRAWS)


def draw(kind: str, rng: np.random.Generator) -> E.Effect:
    """One effect of ``kind`` (a key of :data:`DRAWS`) with its parameters drawn from ``rng``."""
    return DRAWS[kind](rng)
