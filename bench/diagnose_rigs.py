"""Score ``diagnose`` on independent logs recorded under other rig settings than the default.

    python bench/diagnose_rigs.py [--rigs log500 enc20um ...] [--out bench/out/diagnose_rigs]
    python bench/diagnose_rigs.py --experiments [steps short ...] [--out ...]
    python bench/diagnose_rigs.py --variants [end_effect_narrow ...] [--out ...]
    python bench/diagnose_rigs.py --saturation [--out ...]
    python bench/diagnose_rigs.py --sensors [--rig obs2800] [--out ...]
    python bench/diagnose_rigs.py --sensor-pairs [--rig obs2800] [--out ...]
    python bench/diagnose_rigs.py --friction-shapes [--rig obs2800] [--out ...]
    python bench/diagnose_rigs.py --vibration [--rig obs2800] [--out ...]
    python bench/diagnose_rigs.py ... --shake small|large
    python bench/diagnose_rigs.py --warming [--rig obs2800] [--out ...]
    python bench/diagnose_rigs.py ... --warm small|large
    python bench/diagnose_rigs.py --lift-off [--rig ...]
    python bench/diagnose_rigs.py --drawn 2 [--kinds end_effect ...] [--seed 1200] [--out ...]
    python bench/diagnose_rigs.py --drawn-pairs 24 [--seed 9000] [--out ...]
    python bench/diagnose_rigs.py --drawn-pairs 16 --pairs-with end_effect normal_cogging detent_force
    python bench/diagnose_rigs.py --drawn-pairs 12 --per-log 3 [--rig obs2800] [--seed 20400]
    python bench/diagnose_rigs.py --vertical-force [--load-change 2] [--rig ...]
    python bench/diagnose_rigs.py ... --payload 1.5 | --load-change 2

The sets of ``bench/diagnose_score.py`` all come from one rig: a 5 kHz loop logged at 1 kHz with 10
um encoders. A user's rig differs: it may log at 500 Hz or 2.5 kHz, have finer or coarser encoders,
run its loop at 2 or 10 kHz, log its current sensors instead of its commands (``measured``), or be
run by the two PID loops the papers identify with (``pid``). Each rig below records a clean log and
four single effects (large horizontal guide friction, normal cogging, a cable carrier, a commutation
offset) with the independent generator (``tests/independent``, no code shared with
``maglev_oc.sim``), each is diagnosed with the defaults and scored as ``diagnose_score`` does: true
effect first, no false claim, size within 30 %. Prints one line per log and the totals per rig;
writes ``OUT/summary.json``. Not run in CI.

``--experiments [NAME ...]``: the generator's ``experiments`` set instead (``tests/independent/sets.py``),
on the default rig: a user's experiments unlike the other sets' (set-point steps, a small
excursion, faster sines, a short log, an off-centre travel, softer and stiffer gains, constants
further from the papers'), each with a clean log and six large effects alone.

``--variants [NAME ...]``: each effect in shapes the sets never use (:func:`variants`: end effects
narrower, wider, on the thrust alone or at one end; cogging with a strong second harmonic; friction
with a large Stribeck drop; a misalignment tilted the other way with a 40 mm waviness; ...), alone
on the default rig: a user's rig has the same effects in its own proportions, and a rule tuned to
the sets' small and large sizes may not hold there.

``--sensors``: sensors that read off zero or differ in gain, each at both sizes on three seeds: the
phase current sensors' offsets (``tests.independent.effects.CurrentSensorOffset``, 24 and 76 mA in
the dq frame), whose missing current is a force along the travel over two pole pitches on both
axes, their gains (``CurrentSensorGain``, a mismatch of 1.2 and 2.9 %), which mix i_d and i_q over
one pole pitch, and the gap encoder's zero (``GapSensorZero``, +0.2 and -0.5 mm), which the
constants absorb. None was in the generator or the named sets when the diagnosis's rules were
written. ``--sensor-pairs``: each current sensor error beside one large effect of another kind
(:func:`sensor_pairs`, eight logs, seeds 7100-7107): a rig has more than one.

``--friction-shapes``: guide friction in shapes the library's friction does not have, each at the
generator's small and large friction on three seeds (:func:`friction_shapes`): horizontal guides
whose friction changes along the track (``GuideFriction.level_slope``, +5 and -8 /m: 20-32 % over
the logged travel), and guides on either axis whose friction differs between the directions
(``direction_asymmetry``, +25 and -30 %). Friction larger one way is friction of the mean level plus
a constant force while the platform slides, which guides not level give too.

``--vibration``: the floor shaking the base, stator and encoders
(``tests.independent.effects.BaseVibration``: 5 and 20 mm/s^2 RMS over 1-100 Hz), alone and beside
large horizontal friction, normal cogging or an amplifier lag, on three seeds: a disturbance that
no function of the state describes, where nothing should be claimed for it (the scoring leaves it
out of the truth).

``--warming``: the magnets warming during the run (``tests.independent.effects.MagnetWarming``: the
field 0.28 and 1.1 % lower after 60 s), alone and beside large horizontal friction, normal cogging or
an amplifier lag, on three seeds: forces that drift over the log, which no function of the state
describes; and, as a drift that is not the magnets', large guide friction on either axis whose level
falls by 30 % (time constant 60 s) as the guides' lubricant warms (``GuideFriction.warming_change``);
and a gap reading whose zero drifts by 20 or 50 um (time constant 60 s) as the frame warms
(``GapSensorZero.drift``), which gives the forces of the magnets' drift.
``--warm small|large`` adds the magnets' warming to every log of whatever runs (scored as a true
effect).

``--lift-off``: logs that begin with the platform resting on its stopper at 30 mm and lift off
after about a second (``Rig.stopper_gap``; the reference steps from 30 mm to 19.5 mm from 1 s on),
clean, beside large horizontal friction or normal cogging, and one that lands again from 56 s on;
and three (clean, friction, cogging) whose reference steps 2 mm beyond a stopper at 26 mm from 25 s
to 26.5 s, the loop pressing the platform against it; two (clean, cogging) whose reference runs
below a stop at a 15 mm gap and two (clean, friction) beyond an end stop of the travel at +45 mm
over the same 1.5 s: samples where a stop holds the stage, which no fit may read. Each line also gives the
refitted constants' errors against the plant's (C1..C3 the largest, and C4).

``--vertical-force``: a force on the vertical axis besides the weight (a hanging cable's,
``tests.independent.effects.VerticalForce``: 1 N, and 3 N with a 100 N/m spring along the gap),
alone and beside large vertical guide friction or a large field shape, on three seeds (8100-8102).
One log cannot tell it from the magnets' scale; ``--load-change KG`` records every log of whatever
runs a second time on the same plant (its true constants, seed + 50000) with a payload of KG kg
declared (``# payload_kg``) and diagnoses the two together, the experiment the diagnosis proposes
for it. ``--payload KG`` declares a payload of KG kg on every log run instead (each diagnosed
alone): every effect's size must come out the unloaded stage's.

``--shake small|large`` adds the base's vibration to every log of whatever runs (the scoring leaves
it out of the truth): the other benches on a floor that is not quiet.

``--saturation``: the iron saturated by the stator current
(``tests.independent.effects.CurrentSaturation``, the force per ampere halved at 30 A or 15 A),
an effect in none of the named sets, on three seeds each. On a regulated stage the levitation
current follows the gap, so most of it looks like a smooth dependence on the gap: what matters is
that nothing else is claimed in its place.

``--drawn-pairs N [--seed S]``: N logs, each with two effects of different kinds drawn at random
(the kinds from seed S + j, each effect's parameters as ``--drawn`` draws them), on the default
rig: a rig has more than one effect, in combinations no set chose. ``--pairs-with A B C``: only
the pairs of kind A beside B or C, the seeds still run from S on and each pair drawn as without it
(``--drawn-pairs 16 --pairs-with end_effect normal_cogging detent_force --seed 9000`` gives the
sixteen pairs 9006-9657 of cogging or detents beside end effects that bench/README (xxxiii) scores).

``--drawn N``: every effect kind N times, each with its parameters drawn at random within the
ranges real stages show (``tests/independent/draws.py``: sizes log-uniform over at least the sets'
small-to-large span, phases and signs at random), alone on the default rig. The sets and variants
are values somebody chose; these are not, which is what a user's rig is like.

``--experiment NAME`` (with any of the above): every log recorded under one experiment of the
``experiments`` set instead of the default sines (``steps``, ``small_travel``, ``fast_sines``,
``short_log``, ``off_centre``, ``soft_gains``, ``stiff_gains``, ``far_constants``): drawn pairs
under a user's own excitation, which ``--experiments`` records with one effect at a time.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


EFFECTS = (None, "guide_friction_horizontal", "normal_cogging", "cable_carrier", "commutation_offset")
"""What each rig records: a clean log and these effects alone, at their large size."""


def variants() -> dict:
    """Effects in shapes and proportions the sets' ``small()`` and ``large()`` never use, by name."""
    from tests.independent import effects as E

    return {
        "end_effect_narrow": E.EndEffect(thrust_loss=0.10, attraction_loss=0.06, width=0.008),
        "end_effect_wide": E.EndEffect(thrust_loss=0.06, attraction_loss=0.04, width=0.035),
        "end_effect_thrust_only": E.EndEffect(thrust_loss=0.10, attraction_loss=0.0, width=0.02),
        "end_effect_one_end": E.EndEffect(thrust_loss=0.12, attraction_loss=0.08, end_position_minus=-0.3),
        "detent_strong_harmonic": E.DetentForce(peak_force=1.5, harmonic2_ratio=0.9, harmonic2_phase=0.2),
        "normal_cogging_strong_harmonic": E.NormalCogging(peak_force=2.0, harmonic2_ratio=0.8),
        "friction_h_stribeck": E.GuideFriction(
            axis_="horizontal",
            coulomb_force=0.6,
            static_force=1.2,
            stribeck_velocity=0.01,
            viscous_coefficient=1.0,
        ),
        "friction_v_stribeck": E.GuideFriction(
            axis_="vertical",
            coulomb_force=1.0,
            static_force=2.0,
            stribeck_velocity=0.005,
            viscous_coefficient=5.0,
            bristle_stiffness=3e5,
            bristle_damping=690.0,
        ),
        "misalignment_negative_wavy": E.GuideMisalignment(
            slope=-3e-3, waviness_amplitude=6e-6, waviness_wavelength=0.04, waviness_phase=2.0
        ),
        "cable_carrier_offset": E.CableCarrier(stiffness=6.0, neutral_position=0.0, constant_force=-0.2),
        "thrust_ripple_phase": E.ThrustRipple(ratio=0.04, phase=2.0, ratio2=0.0),
        "commutation_negative": E.CommutationOffset(angle=-0.04),
        "amplifier_delay": E.AmplifierDynamics(bandwidth=2000.0, delay=6e-4),
        "amplifier_slow": E.AmplifierDynamics(bandwidth=100.0, delay=0.0),
        "tilted_base_negative": E.TiltedBase(angle=-8e-3),
        # the fringing in other shapes than the library's exponential (EndEffect.profile): flat at
        # the ends and then falling faster (Gaussian), or none further in than 3 w (cosine); last,
        # so that the variants above keep their seeds
        "end_effect_gaussian": E.EndEffect(
            thrust_loss=0.10, attraction_loss=0.06, width=0.02, profile="gaussian"
        ),
        "end_effect_gaussian_narrow": E.EndEffect(
            thrust_loss=0.12, attraction_loss=0.08, width=0.012, profile="gaussian"
        ),
        "end_effect_cosine": E.EndEffect(
            thrust_loss=0.10, attraction_loss=0.06, width=0.01, profile="cosine"
        ),
        "end_effect_cosine_wide": E.EndEffect(
            thrust_loss=0.08, attraction_loss=0.05, width=0.015, profile="cosine"
        ),
        "end_effect_cosine_one_end": E.EndEffect(
            thrust_loss=0.12, attraction_loss=0.08, width=0.01, end_position_minus=-0.3, profile="cosine"
        ),
    }


SATURATION_SEEDS = (901, 902, 903)
"""Seeds of the ``--saturation`` logs (one log per seed and saturation current)."""


SENSOR_SEEDS = (7001, 7002, 7003)
"""Seeds of the ``--sensors`` logs (one log per seed, kind and size)."""


def sensors() -> dict:
    """The sensors' errors ``--sensors`` runs, by name."""
    from tests.independent import effects as E

    return {
        f"{cls.kind}_{size}": getattr(cls, size)()
        for cls in (E.CurrentSensorOffset, E.CurrentSensorGain, E.GapSensorZero)
        for size in ("small", "large")
    }


FRICTION_SHAPE_SEEDS = (7201, 7202, 7203)
"""Seeds of the ``--friction-shapes`` logs (one log per seed, shape and size)."""


def friction_shapes() -> dict:
    """The ``--friction-shapes`` effects by name: guide friction whose level changes along the track
    or differs between the directions, at the generator's small and large friction."""
    import dataclasses as dc

    from tests.independent import effects as E

    f = E.GuideFriction
    shapes = {
        "friction_h_along": ("horizontal", {"level_slope": 5.0}, {"level_slope": -8.0}),
        "friction_h_direction": ("horizontal", {"direction_asymmetry": 0.25}, {"direction_asymmetry": -0.3}),
        "friction_v_direction": ("vertical", {"direction_asymmetry": 0.25}, {"direction_asymmetry": -0.3}),
    }
    return {
        f"{name}_{size}": dc.replace(getattr(f, size)(axis), **shape)
        for name, (axis, small, large) in shapes.items()
        for size, shape in (("small", small), ("large", large))
    }


VIBRATION_SEEDS = (7301, 7302, 7303)
"""Seeds of the ``--vibration`` logs (one log per seed and case)."""


def vibration() -> dict:
    """The ``--vibration`` logs' effects by name: the base shaking, alone and beside one effect."""
    from tests.independent import effects as E

    small, large = E.BaseVibration.small(), E.BaseVibration.large()
    return {
        "vibration_small": (small,),
        "vibration_large": (large,),
        "vibration_large+friction_h": (large, E.GuideFriction.large("horizontal")),
        "vibration_large+cogging": (large, E.NormalCogging.large()),
        "vibration_large+lag": (large, E.AmplifierDynamics.large()),
    }


WARMING_SEEDS = (7401, 7402, 7403)
"""Seeds of the ``--warming`` logs (one log per seed and case)."""


def warming() -> dict:
    """The ``--warming`` logs' effects by name: the magnets warming, alone and beside one effect."""
    from tests.independent import effects as E

    small, large = E.MagnetWarming.small(), E.MagnetWarming.large()
    thinning = {"warming_change": -0.3, "warming_time_constant": 60.0}
    return {
        # guides whose lubricant thins as they warm: a drift that is not the magnets'
        "friction_h_thinning": (dataclasses.replace(E.GuideFriction.large("horizontal"), **thinning),),
        "friction_v_thinning": (dataclasses.replace(E.GuideFriction.large("vertical"), **thinning),),
        # a gap reading that drifts as the frame warms: the same forces as the magnets' drift
        "gap_zero_drift_20um": (E.GapSensorZero(offset=0.0, drift=2e-5),),
        "gap_zero_drift_50um": (E.GapSensorZero(offset=0.0, drift=5e-5),),
        "warm_small": (small,),
        "warm_large": (large,),
        "warm_large+friction_h": (large, E.GuideFriction.large("horizontal")),
        "warm_large+cogging": (large, E.NormalCogging.large()),
        "warm_large+lag": (large, E.AmplifierDynamics.large()),
    }


def sensor_pairs() -> dict:
    """The ``--sensor-pairs`` logs by name: a current sensor error beside another effect."""
    from tests.independent import effects as E
    from tests.independent.sets import SINGLE_EFFECTS

    offset, gain = E.CurrentSensorOffset, E.CurrentSensorGain
    pairs = (
        (offset.small(), "guide_friction_horizontal"),
        (offset.large(), "normal_cogging"),
        (offset.small(), "cable_carrier"),
        (offset.large(), "end_effect"),
        (gain.small(), "guide_friction_vertical"),
        (gain.large(), "detent_force"),
        (gain.small(), "thrust_ripple"),
        (gain.large(), "commutation_offset"),
    )
    return {f"{sensor.kind}+{other}": (sensor, SINGLE_EFFECTS[other]("large")) for sensor, other in pairs}


STOPPER_GAP = 0.030
"""[m] The ``--lift-off`` rig's stopper (the platform rests on it at the largest gap)."""

TOUCHED_STOPPER_GAP = 0.026
"""[m] The stopper of the ``--lift-off`` logs whose reference runs beyond it in the middle of the log."""

TOP_STOP_GAP = 0.015
"""[m] The stop at the smallest gap of the ``--lift-off`` logs whose reference runs below it ..."""

END_STOPS = (-0.045, 0.045)
"""[m] ... and the travel's end stops of those whose reference runs beyond one."""


def lift_off() -> dict:
    """The ``--lift-off`` logs by name: (seed, reference, effects, the rig's stops as ``Rig`` fields)."""
    from tests.independent import effects as E
    from tests.independent.reference import ReferenceSpec

    lift = ReferenceSpec(gap_center=STOPPER_GAP, steps_v=((1.0, -0.0105),), step_time=1.0, ramp_time=4.0)
    land = ReferenceSpec(
        gap_center=STOPPER_GAP, steps_v=((1.0, -0.0105), (56.0, 0.0115)), step_time=1.0, ramp_time=4.0
    )
    # from 25 s on, the reference steps 8 mm up for 1.5 s: 2 mm beyond the stopper at 26 mm; or 6 mm
    # down, beyond a stop at a 15 mm gap; or 25 mm along the travel, beyond an end stop at +45 mm
    touch = ReferenceSpec(steps_v=((25.0, 0.008), (26.5, -0.008)), step_time=0.3)
    top = ReferenceSpec(steps_v=((25.0, -0.006), (26.5, 0.006)), step_time=0.3)
    end = ReferenceSpec(steps_h=((25.0, 0.025), (26.5, -0.025)), step_time=0.3)
    rests = {"stopper_gap": STOPPER_GAP}
    touches = {"stopper_gap": TOUCHED_STOPPER_GAP}
    tops = {"top_stopper_gap": TOP_STOP_GAP}
    ends = {"end_stops": END_STOPS}
    friction, cogging = E.GuideFriction.large("horizontal"), E.NormalCogging.large()
    return {
        "lift_clean": (7601, lift, (), rests),
        "lift_land_clean": (7602, land, (), rests),
        "lift_friction_h": (7603, lift, (friction,), rests),
        "lift_cogging": (7604, lift, (cogging,), rests),
        "touch_clean": (7701, touch, (), touches),
        "touch_friction_h": (7702, touch, (friction,), touches),
        "touch_cogging": (7703, touch, (cogging,), touches),
        "top_clean": (7711, top, (), tops),
        "top_cogging": (7712, top, (cogging,), tops),
        "end_clean": (7721, end, (), ends),
        "end_friction_h": (7722, end, (friction,), ends),
    }


def saturation() -> dict:
    """The saturations ``--saturation`` runs, by name."""
    from tests.independent import effects as E

    return {
        "current_saturation_30A": E.CurrentSaturation.small(),
        "current_saturation_15A": E.CurrentSaturation.large(),
    }


def main() -> None:
    sys.path.insert(0, str(ROOT))
    from tests.independent.rigs import RIGS  # the rigs the tests reproduce too

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rigs", nargs="+", default=list(RIGS), choices=list(RIGS))
    parser.add_argument(
        "--experiments", nargs="*", default=None, help="score the experiments set instead (all, or these)"
    )
    parser.add_argument(
        "--variants", nargs="*", default=None, help="score the effects' variants instead (all, or these)"
    )
    parser.add_argument(
        "--saturation", action="store_true", help="score the iron saturated by the current instead"
    )
    parser.add_argument("--sensors", action="store_true", help="score sensors that read off zero instead")
    parser.add_argument(
        "--friction-shapes",
        action="store_true",
        help="score guide friction that changes along the track or with the direction instead",
    )
    parser.add_argument(
        "--vibration", action="store_true", help="score logs of a vibrating base (alone and beside an effect)"
    )
    parser.add_argument(
        "--warming", action="store_true", help="score logs of magnets warming (alone and beside an effect)"
    )
    parser.add_argument(
        "--lift-off", action="store_true", help="score logs that begin (or end) resting on the stopper"
    )
    parser.add_argument(
        "--sensor-pairs", action="store_true", help="score current sensor errors beside other effects instead"
    )
    parser.add_argument(
        "--drawn", type=int, default=0, help="score N random draws of every effect kind instead"
    )
    parser.add_argument(
        "--drawn-pairs", type=int, default=0, help="score N random pairs of drawn effects instead"
    )
    parser.add_argument(
        "--per-log",
        type=int,
        default=2,
        metavar="K",
        help="with --drawn-pairs: K drawn effects of different kinds on each log instead of two (a rig "
        "with friction, cogging and a cable carrier at once); the logs are named set_<seed>",
    )
    parser.add_argument("--kinds", nargs="*", default=None, help="with --drawn: only these kinds")
    parser.add_argument(
        "--pairs-with",
        nargs="+",
        default=None,
        metavar="KIND",
        help="with --drawn-pairs: only the pairs of the first kind and one of the others, drawn in "
        "turn from --seed on until N are found (the seeds the same as without it)",
    )
    parser.add_argument(
        "--rig",
        default="default",
        choices=list(RIGS),
        help="the rig of the --drawn, --drawn-pairs, "
        "--variants, --saturation, --sensors and --experiments logs (default: the generator's own)",
    )
    parser.add_argument(
        "--shake",
        choices=("small", "large"),
        default=None,
        help="add the base's vibration (BaseVibration.small/large) to every log run",
    )
    parser.add_argument(
        "--warm",
        choices=("small", "large"),
        default=None,
        help="add the magnets' warming (MagnetWarming.small/large) to every log run",
    )
    parser.add_argument(
        "--vertical-force",
        action="store_true",
        help="score a vertical force besides the weight (a hanging cable's), alone and beside an effect",
    )
    parser.add_argument(
        "--payload", type=float, default=0.0, help="declare a payload of this many kg on every log run"
    )
    parser.add_argument(
        "--undeclared",
        action="store_true",
        help="with --payload: leave the payload out of the log's header (a load nobody declared)",
    )
    parser.add_argument(
        "--experiment",
        default=None,
        help="record every log run under this experiment of the experiments set (its references, gains, "
        "length or constants' spread: steps, small_travel, fast_sines, short_log, off_centre, soft_gains, "
        "stiff_gains, far_constants) instead of the default sines",
    )
    parser.add_argument(
        "--duration", type=float, default=None, help="record every log run for this many seconds (default 60)"
    )
    parser.add_argument(
        "--load-change",
        type=float,
        default=0.0,
        help="record every log again on the same plant with this payload [kg] declared; diagnose both",
    )
    parser.add_argument("--seed", type=int, default=700, help="seed of the first log; one more per effect")
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "out" / "diagnose_rigs")
    args = parser.parse_args()
    if args.undeclared and not args.payload:
        parser.error("--undeclared: give the payload it leaves out of the logs (--payload KG)")
    from tests.independent.core import with_generic_libm

    with_generic_libm()  # the logs the test suite generates, whatever the CPU
    from maglev_oc.data.reading import read_log
    from maglev_oc.diagnosis.pipeline import diagnose
    from tests.independent.logio import write_log
    from tests.independent.scoring import score
    from tests.independent.sets import EXPERIMENTS, SINGLE_EFFECTS, named_set
    from tests.independent.simulate import Rig, Scenario, SimulationError, simulate

    groups: dict[str, list] = {}
    rig = Rig(**RIGS[args.rig])
    if args.drawn:
        import numpy as np

        from tests.independent.draws import KINDS, draw

        unknown = sorted(set(args.kinds or ()) - set(KINDS))
        if unknown:
            parser.error(f"--kinds: unknown {unknown}; choose from {list(KINDS)}")
        for kind in args.kinds or KINDS:
            for j in range(args.drawn):
                seed = args.seed + 100 * KINDS.index(kind) + j  # the same draws whichever kinds run
                effect = draw(kind, np.random.default_rng(seed))
                groups.setdefault(kind, []).append(
                    (f"{kind}_{seed}", Scenario(name=kind, seed=seed, effects=(effect,), rig=rig))
                )
    elif args.drawn_pairs:
        import numpy as np

        from tests.independent.draws import KINDS, draw

        unknown = sorted(set(args.pairs_with or ()) - set(KINDS))
        if unknown:
            parser.error(f"--pairs-with: unknown {unknown}; choose from {list(KINDS)}")
        wanted = args.pairs_with or []

        def chosen(kinds) -> bool:
            names = {KINDS[k] for k in kinds}
            return not wanted or (wanted[0] in names and bool(names & set(wanted[1:] or KINDS)))

        if not 1 <= args.per_log <= len(KINDS):
            parser.error(f"--per-log: between 1 and {len(KINDS)} effects on a log")
        per_log, stem = args.per_log, "pair" if args.per_log == 2 else "set"
        seed = args.seed - 1
        for _ in range(args.drawn_pairs):
            seed += 1
            while not chosen(np.random.default_rng(seed).choice(len(KINDS), size=per_log, replace=False)):
                seed += 1
            kinds = sorted(np.random.default_rng(seed).choice(len(KINDS), size=per_log, replace=False))
            effects = tuple(draw(KINDS[k], np.random.default_rng([seed, int(k)])) for k in kinds)
            name = "+".join(KINDS[k] for k in kinds)
            groups.setdefault("drawn_pairs", []).append(
                (f"{stem}_{seed}", Scenario(name=name, seed=seed, effects=effects, rig=rig))
            )
    elif args.sensors:
        for name, effect in sensors().items():
            for seed in SENSOR_SEEDS:
                scenario = Scenario(name=name, seed=seed, effects=(effect,), rig=rig)
                groups.setdefault(name.rsplit("_", 1)[0], []).append((f"{name}_{seed}", scenario))
    elif args.friction_shapes:
        for name, effect in friction_shapes().items():
            for seed in FRICTION_SHAPE_SEEDS:
                scenario = Scenario(name=name, seed=seed, effects=(effect,), rig=rig)
                groups.setdefault(name.rsplit("_", 1)[0], []).append((f"{name}_{seed}", scenario))
    elif args.vibration:
        for name, effects in vibration().items():
            for seed in VIBRATION_SEEDS:
                scenario = Scenario(name=name, seed=seed, effects=effects, rig=rig)
                groups.setdefault(name, []).append((f"{name}_{seed}", scenario))
    elif args.warming:
        for name, effects in warming().items():
            for seed in WARMING_SEEDS:
                scenario = Scenario(name=name, seed=seed, effects=effects, rig=rig)
                groups.setdefault(name, []).append((f"{name}_{seed}", scenario))
    elif args.lift_off:
        for name, (seed, reference, effects, stops) in lift_off().items():
            on_stopper = Rig(**RIGS[args.rig], **stops)
            scenario = Scenario(name=name, seed=seed, effects=effects, reference=reference, rig=on_stopper)
            groups.setdefault("lift_off", []).append((name, scenario))
    elif args.vertical_force:
        from tests.independent.effects import FieldShape, GuideFriction, VerticalForce

        beside = {"": (), "friction": (GuideFriction.large("vertical"),), "shape": (FieldShape.large(),)}
        for k in range(3):
            for size in ("small", "large"):
                for label, others in beside.items():
                    stem = f"force_{size}{'_' + label if label else ''}_{8100 + k}"
                    effects = (getattr(VerticalForce, size)(), *others)
                    scenario = Scenario(name=stem, seed=8100 + k, effects=effects, rig=rig)
                    groups.setdefault("vertical_force", []).append((stem, scenario))
    elif args.sensor_pairs:
        for k, (name, effects) in enumerate(sensor_pairs().items()):
            scenario = Scenario(name=name, seed=7100 + k, effects=effects, rig=rig)
            groups.setdefault("sensor_pairs", []).append((f"sensor_pair_{7100 + k}", scenario))
    elif args.saturation:
        for name, effect in saturation().items():
            for seed in SATURATION_SEEDS:
                scenario = Scenario(name=name, seed=seed, effects=(effect,), rig=rig)
                groups.setdefault("saturation", []).append((f"{name}_{seed}", scenario))
    elif args.variants is not None:
        chosen = variants()
        for k, (name, effect) in enumerate(chosen.items()):
            if not args.variants or name in args.variants:
                scenario = Scenario(name=name, seed=args.seed + 100 + k, effects=(effect,), rig=rig)
                groups.setdefault("variants", []).append((name, scenario))
    elif args.experiments is not None:
        wanted = args.experiments or list(EXPERIMENTS)
        for stem, scenario in named_set("experiments"):
            experiment = next(e for e in EXPERIMENTS if scenario.name.startswith(e + "_"))
            if experiment in wanted:
                # the experiment's rig (its gains) with the chosen rig's settings
                rig_here = dataclasses.replace(scenario.rig, **RIGS[args.rig])
                scenario = dataclasses.replace(scenario, rig=rig_here)
                groups.setdefault(experiment, []).append((stem, scenario))
    else:
        for rig_name in args.rigs:
            for k, effect in enumerate(EFFECTS):
                effects = () if effect is None else (SINGLE_EFFECTS[effect]("large"),)
                stem = f"{rig_name}_{effect or 'clean'}"
                scenario = Scenario(name=stem, seed=args.seed + k, effects=effects, rig=Rig(**RIGS[rig_name]))
                groups.setdefault(rig_name, []).append((stem, scenario))
    if args.shake:
        from tests.independent.effects import BaseVibration

        shaking = getattr(BaseVibration, args.shake)()
        groups = {
            g: [(stem, dataclasses.replace(sc, effects=(*sc.effects, shaking))) for stem, sc in runs]
            for g, runs in groups.items()
        }
    if args.warm:
        from tests.independent.effects import MagnetWarming

        warm = getattr(MagnetWarming, args.warm)()
        groups = {
            g: [(stem, dataclasses.replace(sc, effects=(*sc.effects, warm))) for stem, sc in runs]
            for g, runs in groups.items()
        }
    if args.payload:
        groups = {
            g: [
                (stem, dataclasses.replace(sc, payload=args.payload, declare_payload=not args.undeclared))
                for stem, sc in runs
            ]
            for g, runs in groups.items()
        }
    if args.experiment:
        from tests.independent.sets import under_experiment

        if args.experiment not in EXPERIMENTS:
            parser.error(f"--experiment: unknown {args.experiment!r}; choose from {list(EXPERIMENTS)}")
        groups = {
            g: [(stem, under_experiment(sc, args.experiment)) for stem, sc in runs]
            for g, runs in groups.items()
        }
    if args.duration is not None:
        groups = {
            g: [(stem, dataclasses.replace(sc, duration=args.duration)) for stem, sc in runs]
            for g, runs in groups.items()
        }
    summary: dict[str, dict] = {}
    totals = [0, 0, 0]
    skipped: list[str] = []
    for group, scenarios in groups.items():
        marks = [0, 0, 0]
        ran = 0
        for stem, scenario in scenarios:
            try:
                run = simulate(scenario)
            except SimulationError as exc:  # a drawn rig the generator's own loop cannot hold: no log
                skipped.append(stem)
                print(f"{stem:16s} {scenario.name:38s} skipped: {exc}", flush=True)
                continue
            ran += 1
            csv, truth_path = write_log(run, args.out / "logs", stem)
            logs = [read_log(csv)]
            if args.load_change:  # the same plant again, carrying a declared payload
                constants = tuple(run.truth["plant"]["constants_true"][c] for c in ("C1", "C2", "C3", "C4"))
                loaded = dataclasses.replace(
                    scenario,
                    seed=scenario.seed + 50_000,
                    constants=constants,
                    payload=args.load_change,
                    declare_payload=True,
                )
                try:
                    logs.append(read_log(write_log(simulate(loaded), args.out / "logs", f"{stem}_loaded")[0]))
                except SimulationError as exc:
                    skipped.append(stem)
                    ran -= 1
                    print(f"{stem:16s} {scenario.name:38s} skipped (loaded): {exc}", flush=True)
                    continue
            t0 = time.perf_counter()
            result = diagnose(logs).to_dict()
            s = score(stem, json.loads(truth_path.read_text()), result["effects"])
            row = {
                "scenario": scenario.name,
                "truth": s.truth,
                "effects": [e.description() for e in scenario.effects],
                "claimed": s.claimed,
                "not_separable": [n["name"] for n in result["not_separable"]],
                "unexplained": [f"{u['axis']}: {u['depends_on']}" for u in result["unexplained"]],
                "warnings": result["warnings"],  # constants refitted beyond a rig of this design
                "marks": [s.true_first, s.no_false_claim, s.size_right],
                "notes": s.notes,
                "constants_off": {
                    c: result["constants_final"][c]["value"] / v - 1.0
                    for c, v in run.truth["plant"]["constants_true"].items()
                },
                "left_out": [f"{r['from_s']:.2f}-{r['to_s']:.2f} s" for r in result["left_out"]],
                "wall_s": time.perf_counter() - t0,
            }
            summary[stem] = row
            marks = [m + int(v) for m, v in zip(marks, row["marks"], strict=True)]
            flags = "".join("x" if v else "." for v in row["marks"])
            print(
                f"{stem:16s} {scenario.name:38s} {flags}  claimed {s.claimed}  "
                f"unexplained {row['unexplained']}  {'; '.join(s.notes)}"
                + (f"  warnings {len(row['warnings'])}" if row["warnings"] else "")
                + (_constants_words(row) if args.lift_off or args.vertical_force else "")
                + f"  ({row['wall_s']:.1f} s)",
                flush=True,
            )
        n = ran
        totals = [t + m for t, m in zip(totals, marks, strict=True)]
        print(
            f"{group}: {marks[0]}/{n} true first, {marks[1]}/{n} no false claim, {marks[2]}/{n} sized right"
        )
    n = sum(len(v) for v in groups.values()) - len(skipped)
    print(f"all: {totals[0]}/{n} true first, {totals[1]}/{n} no false claim, {totals[2]}/{n} sized right")
    if skipped:
        print(f"skipped (the generator's loop went unstable, no log): {', '.join(skipped)}")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")


def _constants_words(row: dict) -> str:
    """The refitted constants' errors and the stretches left out, for a line of the output."""
    off = row["constants_off"]
    worst = max(abs(off[c]) for c in ("C1", "C2", "C3"))
    return f"  C1..C3 within {100 * worst:.2f} %, C4 {100 * off['C4']:+.1f} %, left out {row['left_out']}"


if __name__ == "__main__":
    main()
