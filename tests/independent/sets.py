"""Named sets of scenarios: ``clean``, ``eleven``, ``single`` and ``pairs``.

Each set is a list of ``(stem, Scenario)``: the stem is the neutral file name the log is written
under (``<set>_<nn>``, saying nothing about what is in it), the scenario's ``name`` says what it
is (only in the truth file). Seeds are fixed per set, so a set is the same on every machine.

clean
    20 logs without any effect, seeds 101-120 (true constants 1-4 % off the papers', different
    per seed).
eleven
    One clean log and ten with one or two effects (seeds 201-211), in a fixed shuffled order.
single
    Each effect alone at its ``small()`` and ``large()`` size (seeds 301-324).
pairs
    Six logs with two effects together (seeds 401-406).
triples
    Eight logs with three or four effects together, as a rig has them: guide friction beside
    cogging, a cable carrier, ripple, end effects, a commutation offset, a tilt, a misalignment or
    the field's shape; cogging and ripple beside an amplifier lag (seeds 601-608).
experiments
    A user's experiments unlike the other sets' (which all excite both axes with sines of
    0.05-2 Hz, 4-5 mm around 19.5 mm and 35-40 mm along the travel, for 60 s, with the papers'
    gains): set-point steps, a small excursion, faster sines, a short log, an off-centre travel,
    softer and stiffer gains, constants further from the papers'. Each records a clean log and six
    effects alone at their large size (seeds 501-507, the same seed per effect in every
    experiment); the stem is ``experiments_<nn>``, the scenario's name ``<experiment>_<effect>``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

from .controller import K_H, K_V, scaled_gains
from .effects import (
    AmplifierDynamics,
    CableCarrier,
    CommutationOffset,
    DetentForce,
    Effect,
    EndEffect,
    FieldShape,
    GuideFriction,
    GuideMisalignment,
    NormalCogging,
    ThrustRipple,
    TiltedBase,
)
from .reference import ReferenceSpec
from .simulate import Scenario

SINGLE_EFFECTS: dict[str, Callable[[str], Effect]] = {
    "guide_friction_horizontal": lambda size: getattr(GuideFriction, size)("horizontal"),
    "guide_friction_vertical": lambda size: getattr(GuideFriction, size)("vertical"),
    "normal_cogging": lambda size: getattr(NormalCogging, size)(),
    "detent_force": lambda size: getattr(DetentForce, size)(),
    "end_effect": lambda size: getattr(EndEffect, size)(),
    "guide_misalignment": lambda size: getattr(GuideMisalignment, size)(),
    "cable_carrier": lambda size: getattr(CableCarrier, size)(),
    "thrust_ripple": lambda size: getattr(ThrustRipple, size)(),
    "commutation_offset": lambda size: getattr(CommutationOffset, size)(),
    "amplifier_dynamics": lambda size: getattr(AmplifierDynamics, size)(),
    "field_shape": lambda size: getattr(FieldShape, size)(),
    "tilted_base": lambda size: getattr(TiltedBase, size)(),
}
"""Every effect that ``single`` runs alone, by name; called with 'small' or 'large'."""


def _eleven() -> list[tuple[str, tuple[Effect, ...]]]:
    return [
        ("clean", ()),
        ("guide_friction_both_axes", (GuideFriction.small("horizontal"), GuideFriction.small("vertical"))),
        ("cogging_normal_and_detent", (NormalCogging.large(), DetentForce.small())),
        ("end_effect", (EndEffect.large(),)),
        ("guide_misalignment", (GuideMisalignment.large(),)),
        ("cable_carrier", (CableCarrier.large(),)),
        ("commutation_offset", (CommutationOffset.small(),)),
        ("amplifier_dynamics", (AmplifierDynamics.large(),)),
        ("field_shape", (FieldShape.large(),)),
        (
            "papers_hardware_friction_and_misalignment",
            (GuideFriction.large("horizontal"), GuideMisalignment.small()),
        ),
        ("normal_cogging_and_field_shape", (NormalCogging.small(), FieldShape.small())),
    ]


ELEVEN_ORDER = (3, 9, 6, 0, 10, 1, 7, 4, 2, 8, 5)
"""File k of ``eleven`` (eleven_01 ... eleven_11) holds entry ELEVEN_ORDER[k-1] of the list above."""


def _pairs() -> list[tuple[str, tuple[Effect, ...]]]:
    return [
        ("friction_h_and_cable", (GuideFriction.small("horizontal"), CableCarrier.small())),
        ("normal_cogging_and_field_shape", (NormalCogging.large(), FieldShape.large())),
        ("misalignment_and_end_effect", (GuideMisalignment.large(), EndEffect.small())),
        ("commutation_and_tilted_base", (CommutationOffset.small(), TiltedBase.large())),
        ("amplifier_and_friction_v", (AmplifierDynamics.large(), GuideFriction.small("vertical"))),
        ("detent_and_thrust_ripple", (DetentForce.large(), ThrustRipple.large())),
    ]


def _triples() -> list[tuple[str, tuple[Effect, ...]]]:
    return [
        (
            "friction_h_cogging_cable",
            (GuideFriction.small("horizontal"), NormalCogging.small(), CableCarrier.small()),
        ),
        (
            "friction_both_detent_ripple",
            (
                GuideFriction.small("horizontal"),
                GuideFriction.small("vertical"),
                DetentForce.small(),
                ThrustRipple.small(),
            ),
        ),
        (
            "friction_h_end_commutation",
            (GuideFriction.large("horizontal"), EndEffect.small(), CommutationOffset.small()),
        ),
        (
            "friction_v_misalignment_cable",
            (GuideFriction.small("vertical"), GuideMisalignment.small(), CableCarrier.large()),
        ),
        (
            "cogging_ripple_amplifier",
            (NormalCogging.large(), ThrustRipple.small(), AmplifierDynamics.large()),
        ),
        (
            "friction_h_cogging_detent_cable",
            (
                GuideFriction.small("horizontal"),
                NormalCogging.small(),
                DetentForce.small(),
                CableCarrier.small(),
            ),
        ),
        (
            "friction_h_tilt_ripple",
            (GuideFriction.large("horizontal"), TiltedBase.small(), ThrustRipple.large()),
        ),
        ("end_field_friction_h", (EndEffect.large(), FieldShape.large(), GuideFriction.small("horizontal"))),
    ]


COMBINED = {"pairs": (_pairs, 401), "triples": (_triples, 601)}
"""The sets of effects together: (their entries, the first log's seed)."""


EXPERIMENTS: dict[str, dict] = {
    "steps": {
        "reference": {
            "n_sines": 2,
            "gap_peak_range": (0.002, 0.0025),
            "steps_v": ((15.0, 0.002), (30.0, -0.004), (45.0, 0.002)),
            "steps_h": ((10.0, 0.02), (25.0, -0.04), (40.0, 0.02)),
        }
    },
    "small_travel": {
        "reference": {"gap_peak_range": (0.0015, 0.002), "horizontal_peak_range": (0.012, 0.015)}
    },
    "fast_sines": {"reference": {"f_min": 0.2, "f_max": 5.0, "horizontal_peak_range": (0.02, 0.025)}},
    "short_log": {"duration": 20.0},
    "off_centre": {
        "reference": {"horizontal_center": 0.02, "horizontal_peak_range": (0.02, 0.025), "gap_center": 0.017}
    },
    "soft_gains": {"gain_scale": 0.6},
    "stiff_gains": {"gain_scale": 1.5},
    "far_constants": {"constant_spread": (0.06, 0.10)},
}
"""A user's experiment by name: fields of ``ReferenceSpec`` (``reference``), of ``Scenario`` (the
rest), and ``gain_scale``: the papers' regulator gains re-placed with every closed-loop pole scaled
by it (:func:`~tests.independent.controller.scaled_gains`; a softer or stiffer loop)."""

EXPERIMENT_EFFECTS = (
    "guide_friction_vertical",
    "detent_force",
    "end_effect",
    "thrust_ripple",
    "guide_misalignment",
    "amplifier_dynamics",
)
"""The effects each experiment records (large), beside a clean log: those an experiment changes most."""


def experiment_scenario(experiment: str, effect: str | None, seed: int, duration: float = 60.0) -> Scenario:
    """One log of an experiment of :data:`EXPERIMENTS`: ``effect`` (a key of :data:`SINGLE_EFFECTS`,
    at its large size, or None for a clean log)."""
    scenario = Scenario(
        name=f"{experiment}_{effect or 'clean'}",
        seed=seed,
        duration=duration,
        effects=() if effect is None else (SINGLE_EFFECTS[effect]("large"),),
        description=f"set experiments: {experiment}, {effect or 'no effect'}",
    )
    return under_experiment(scenario, experiment)


def under_experiment(scenario: Scenario, experiment: str) -> Scenario:
    """``scenario`` recorded under an experiment of :data:`EXPERIMENTS`: its references, its gains
    (re-placed from the papers' by ``gain_scale``, the scenario's rig otherwise kept), its length
    and its constants' spread where the experiment sets them; the effects and the seed unchanged."""
    spec = dict(EXPERIMENTS[experiment])
    reference = ReferenceSpec(**spec.pop("reference", {}))
    scale = spec.pop("gain_scale", None)
    rig = scenario.rig
    if scale is not None:
        rig = dataclasses.replace(rig, K_h=scaled_gains(K_H, scale), K_v=scaled_gains(K_V, scale))
    return dataclasses.replace(scenario, reference=reference, rig=rig, **spec)


SET_NAMES = ("clean", "eleven", "single", "pairs", "triples", "experiments")
"""The named sets."""


def named_set(name: str, duration: float = 60.0, seed_offset: int = 0) -> list[tuple[str, Scenario]]:
    """The scenarios of set ``name`` as ``(file stem, Scenario)``; ``duration`` [s] per log.

    ``seed_offset`` is added to every seed: the same scenarios on fresh constants, references and
    noise (a set the tools were never tuned on; the sets' own seeds are those with offset 0)."""
    out: list[tuple[str, Scenario]] = []
    if seed_offset:
        return [
            (stem, dataclasses.replace(sc, seed=sc.seed + seed_offset))
            for stem, sc in named_set(name, duration)
        ]
    if name == "clean":
        for i in range(20):
            out.append(
                (
                    f"clean_{i + 1:02d}",
                    Scenario(
                        name=f"clean_seed{101 + i}",
                        seed=101 + i,
                        duration=duration,
                        description="no effect beyond the papers' model",
                    ),
                )
            )
    elif name == "eleven":
        entries = _eleven()
        for k, j in enumerate(ELEVEN_ORDER):
            label, effects = entries[j]
            out.append(
                (
                    f"eleven_{k + 1:02d}",
                    Scenario(
                        name=label,
                        seed=201 + j,
                        duration=duration,
                        effects=effects,
                        description=f"set eleven: {label}",
                    ),
                )
            )
    elif name == "single":
        n = 0
        for label, make in SINGLE_EFFECTS.items():
            for size in ("small", "large"):
                n += 1
                out.append(
                    (
                        f"single_{n:02d}",
                        Scenario(
                            name=f"{label}_{size}",
                            seed=300 + n,
                            duration=duration,
                            effects=(make(size),),
                            description=f"set single: {label} alone, {size} size",
                        ),
                    )
                )
    elif name in COMBINED:
        entries, first_seed = COMBINED[name]
        for i, (label, effects) in enumerate(entries()):
            out.append(
                (
                    f"{name}_{i + 1:02d}",
                    Scenario(
                        name=label,
                        seed=first_seed + i,
                        duration=duration,
                        effects=effects,
                        description=f"set {name}: {label}",
                    ),
                )
            )
    elif name == "experiments":
        n = 0
        for experiment in EXPERIMENTS:
            for k, effect in enumerate((None, *EXPERIMENT_EFFECTS)):
                n += 1
                out.append(
                    (f"experiments_{n:02d}", experiment_scenario(experiment, effect, 501 + k, duration))
                )
    else:
        raise ValueError(f"unknown set {name!r}; the sets are {', '.join(SET_NAMES)}")
    return out
