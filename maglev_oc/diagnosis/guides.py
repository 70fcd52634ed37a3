"""Candidates of the linear guides and what hangs on them: friction, tilt, cable carrier, forces,
misalignment and waviness (papers 000/002 name guide friction and misalignment as what limits the
2-DOF stage; the rest is what real linear-guide stages are known for)."""

from __future__ import annotations

import math
from collections.abc import Callable

import casadi as ca
import numpy as np

from maglev_oc.diagnosis.candidate import (
    MAX_FORCE_SHARE,
    Candidate,
    LibraryContext,
    all_of,
    delta_method,
    detected,
    fmt,
    not_below,
    with_physical,
    within,
)
from maglev_oc.model.stage import StageModel
from maglev_oc.numerics import NumpyCall
from maglev_oc.regression.data import PreparedLogs
from maglev_oc.regression.terms import (
    AccelerationTerm,
    amplitude_phase,
    constant_force,
    guide_friction,
    linear_physical,
    term_function,
)
from maglev_oc.results import Estimate

__all__ = [
    "STRIBECK_SPEED",
    "cable_candidate",
    "friction_candidates",
    "gap_offset_candidate",
    "level_candidates",
    "misalignment_candidate",
    "refine_waviness_period",
    "waviness_candidate",
]

STRIBECK_SPEED = 5e-3
"""[m/s] The Stribeck speed of the friction's richer form (variants at half and twice): ball and
roller guides show 0.1-10 mm/s; below the 2 mm/s over which the friction's sign is smoothed a rise
is held by the sticking column, so the form resolves the rises that reach beyond it."""

STRIBECK_SPEED_LARGEST = 10e-3
"""[m/s] The largest Stribeck speed of ball and roller guides (:data:`STRIBECK_SPEED`'s range). An
axis that nine samples in ten move slower than this never shows the friction's Coulomb level."""


COULOMB_Z = 3.0
"""A guide friction's Coulomb force must be positive by this many standard errors: it is what makes
the effect a friction of the guides, and a claim needs its defining part as clearly as the
selection needs the held-out gain (``SelectionSettings.min_z``). Drawn pair 46110 of the
independent generator's filtered-current rig under steps (0.91 N of horizontal Coulomb friction and
amplifiers lagging by 1.2 ms; no vertical friction): at 2 standard errors a vertical friction of
0.0038 +- 0.0016 N of Coulomb force and 3.0 +- 0.3 N s/m of viscous force was claimed (0.7 % of
the held-out error), a damping of the gap that the delayed currents make, not the guides. On 12
true vertical frictions of the noisy-observer rig (Coulomb 0.6-2.4 N) every one passed at 3."""


def friction_candidates(ctx: LibraryContext) -> list[Candidate]:
    """For each axis's guides: Coulomb + viscous friction with the share held while sticking; the
    same friction with no viscous part, judged only when the full fit's viscous coefficient comes
    out negative (its bound-constrained fit: at slow speeds, where a gap axis spends most of its
    time, the viscous force is small beside the Coulomb force and its coefficient takes up the
    friction model's misfit, so a fit can turn it negative while the Coulomb force is clear); and
    the full friction with its Stribeck rise at low speed (:data:`STRIBECK_SPEED`), a richer form
    chosen only when the data pay for its parameter. Without that form a large Stribeck rise (a
    breakaway force twice the Coulomb force) is taken up by the Coulomb force: 1.37 N for 1 N on an
    independent log."""
    out = []
    negative_viscous = not_below("viscous", "viscous friction")
    for axis in ("vertical", "horizontal"):
        name = f"guide_friction_{axis}"
        stribeck_name = f"{name}_with_stribeck"
        for form in ("full", "without_viscous", "stribeck", "stribeck_without_viscous"):
            viscous = not form.endswith("without_viscous")
            stribeck = form.startswith("stribeck")
            term = guide_friction(
                ctx.params,
                axis,
                holding=ctx.modelled(axis),
                holding_in_time=ctx.holds_in_time(axis),
                viscous=viscous,
                stribeck_speed=STRIBECK_SPEED if stribeck else None,
                name=name if form == "full" else f"{name}_{'with_' if stribeck else ''}{form}",
            )
            plausible = [
                detected(
                    "coulomb", "Coulomb friction (sticking without friction is not physical)", k=COULOMB_Z
                ),
                within("coulomb", MAX_FORCE_SHARE * ctx.weight(axis), "Coulomb friction"),
                within("holding", 1.5, "share of the force held while sticking"),
                _held_within_breakaway,
            ]
            if viscous:
                plausible.insert(1, negative_viscous)
            if stribeck:
                plausible += [
                    detected("stribeck_rise", "Stribeck rise (a breakaway force above the Coulomb force)"),
                    within("breakaway", MAX_FORCE_SHARE * ctx.weight(axis), "breakaway force"),
                ]
            out.append(
                Candidate(
                    with_physical(term, _friction_physical(ctx, term, axis)),
                    "friction",
                    "gap_rate" if axis == "vertical" else "position_rate",
                    "slow constant-speed sweeps in both directions (speed reversals at several speeds) "
                    "separate Coulomb from viscous friction and from the thrust constant",
                    all_of(*plausible),
                    _friction_words(axis, form, _speed_p90(ctx, axis)),
                    nuisance=("holding",),
                    fallback_for=None if viscous else (stribeck_name if stribeck else name),
                    fallback_when=None if viscous else negative_viscous,
                    form_of=name if stribeck else None,
                    physical_sign=1,  # friction opposes the motion
                )
            )
    return out


_VISCOUS_HELD = (
    "their viscous friction is not resolved on this log (fitted freely it came out negative, so it is "
    "held at zero)."
)


_HOLDS = " (and hold the axis while it sticks)"


def _viscous_words(viscous: Estimate, before: str, joiner: str, holds: str = _HOLDS) -> str:
    """The end of a friction's finding from its viscous part: found, when it is 2 standard errors
    from zero, else not resolved, the estimate beside it (a gap axis moves slowly: on the
    independent generator's logs the vertical coefficient came out 48 ± 81 N s/m for a true 10,
    and a bare "48 N s/m" reads as a finding). ``before``: the finding up to its last clause,
    ``joiner`` what joins the viscous part to it, ``holds`` the clause on sticking ("" where the
    share held was not fitted)."""
    if viscous.value > 2.0 * viscous.stderr:
        return f"{before}{joiner} {fmt(viscous)} of viscous friction{holds}."
    return f"{before}{holds}; their viscous friction is not resolved on this log ({fmt(viscous)})."


def _speed_p90(ctx: LibraryContext, axis: str) -> float:
    """[m/s] The 90th percentile of the axis's speed over the fitted samples."""
    return float(np.percentile(np.abs(ctx.fitted_states[1 if axis == "vertical" else 3]), 90))


def _slow_axis_words(axis: str, speed_p90: float) -> str:
    """Why a Coulomb friction found on an axis that moves slowly may be more than its Coulomb
    level: a guide whose friction falls with speed over the first few mm/s (Stribeck) pushes back
    harder at these speeds than at its asymptote, and a log that never leaves them cannot tell
    the two apart (on the independent generator's gap axes, 90 % below 4-5 mm/s and Stribeck
    speeds of 6-8 mm/s, the Coulomb force came out 1.3-1.45 times the true level). Empty when the
    axis moves fast enough (:data:`STRIBECK_SPEED_LARGEST`)."""
    if speed_p90 >= STRIBECK_SPEED_LARGEST:
        return ""
    return (
        f" This is the friction at the speeds logged (nine samples in ten move the {axis} axis slower "
        f"than {speed_p90 * 1e3:.1f} mm/s): if the guides' friction falls with speed there (Stribeck), "
        f"their Coulomb level is lower; moves faster than {STRIBECK_SPEED_LARGEST * 1e3:.0f} mm/s "
        "would show it."
    )


def _friction_words(axis: str, form: str, speed_p90: float):
    """The finding's sentence; a Coulomb-only form on a slowly moving axis says what its size is
    (:func:`_slow_axis_words`), a Stribeck form has measured the rise."""
    slow = "" if form.startswith("stribeck") else _slow_axis_words(axis, speed_p90)

    def sentence(e):
        h = e.get("holding")
        # the share held while sticking held at zero (AccelerationTerm.optional): no sticking said
        unheld = h is not None and h.value == 0.0 and h.stderr == 0.0
        holds = "" if unheld else _HOLDS
        coulomb = f"The {axis} linear guides resist motion with {fmt(e['coulomb'])} of Coulomb friction"
        if form == "full":
            text = _viscous_words(e["viscous"], coulomb, " and", holds)
        elif form.startswith("stribeck"):
            rising = (
                f"{coulomb}, rising to a breakaway force of {fmt(e['breakaway'])} at low speed (Stribeck)"
            )
            if form == "stribeck":
                text = _viscous_words(e["viscous"], rising, ", and", holds)
            else:
                text = f"{rising}{'' if unheld else ', and hold the axis while it sticks'}; {_VISCOUS_HELD}"
        else:
            text = f"{coulomb}{holds}; {_VISCOUS_HELD}"
        return text + (_BARELY_STICKS if unheld else "") + slow

    return sentence


_BARELY_STICKS = (
    " The axis hardly sticks on this log: what the guides would hold while it is stopped is mostly the "
    "logged currents' errors there, so it is not fitted."
)


def _friction_physical(ctx: LibraryContext, term: AccelerationTerm, axis: str):
    """The term's conversion, with the viscous part at its bound when left out, the breakaway
    force of a Stribeck form, the share held in the reference C1's units along the track, and the
    force held while sticking (``held_force``, :func:`_held_force`)."""
    base = term.physical
    held = _held_force(ctx, term, axis)

    def convert(q, cov, c):
        out = base(q, cov, c)
        out.setdefault("viscous", Estimate(0.0, 0.0, "N s/m"))  # held at its bound
        if "stribeck_rise" in out:  # the breakaway force F_c + F_x, with their covariance
            i, j = term.parameter_names.index("coulomb"), term.parameter_names.index("stribeck_rise")
            var = cov[i, i] + cov[j, j] + 2 * cov[i, j]
            out["breakaway"] = Estimate(float(q[i] + q[j]), math.sqrt(max(float(var), 0.0)), "N")
        if "holding" in out:
            k = term.parameter_names.index("holding")
            out["held_force"] = held(float(q[k]), math.sqrt(max(float(cov[k, k]), 0.0)))
        if axis == "horizontal":  # the holding column carries the reference C1
            k = ctx.reference_ratio("C1", c)
            h = out["holding"]
            out["holding"] = Estimate(h.value * k, h.stderr * abs(k), "1")
        return out

    return convert


HELD_BEYOND_BREAKAWAY = 3.0
"""How many times its breakaway force (the Coulomb force, the Stribeck rise with it when fitted)
the force a friction's guides hold while the axis sticks may be, nine samples in ten: static
friction holds a stuck axis up to the breakaway force and no further, and the breakaway force of
ball and roller guides is 1-2 times the Coulomb force (the independent generator draws up to 1.9).
A closed loop keeps a slowly moving axis's acceleration near zero whatever force the model lacks,
so on a gap axis that barely moves the share held takes up any such force as if the guides held
it: a 2.2 N normal cogging on a log with no vertical friction (drawn pair 41108 of the
independent generator, noisy observers, steps) was claimed as 0.15 N of Coulomb friction whose
guides held 1.55 N, 10 times as much. Every true vertical friction claimed on 30 logs of the
benches held 0.8-1.2 times its Coulomb force (at most 2.0 times the Coulomb part of a Stribeck
form)."""


def _held_force(ctx: LibraryContext, term: AccelerationTerm, axis: str) -> Callable[[float, float], Estimate]:
    """(share held, its standard error) -> [N] the force ``term``'s guides hold while the axis
    sticks, nine samples in ten, over the log's fitted samples: the share times the holding
    column's 90th percentile (the column evaluated once, when first asked for)."""
    k, row = term.parameter_names.index("holding"), 0 if axis == "vertical" else 1
    column: list[float] = []

    def held(h: float, sd: float) -> Estimate:
        if not column:
            data, valid = ctx.data, ctx.data.valid
            args = [data.x[:, valid], data.u[:, valid], data.du[:, valid]]
            if term.in_time:
                args.append(data.log_time[:, valid])
            feats = NumpyCall(term.features.map(int(valid.sum())))(*args)[0]
            per_share = feats.reshape(2, -1, term.n_parameters)[row, :, k]
            column.append(ctx.mass(axis) * float(np.percentile(np.abs(per_share), 90)))
        return Estimate(abs(h) * column[0], sd * column[0], "N")

    return held


def _held_within_breakaway(est) -> str | None:
    """Refuse a friction whose guides would hold more than :data:`HELD_BEYOND_BREAKAWAY` times its
    breakaway force (its Coulomb force plus two standard errors when no Stribeck rise is fitted)."""
    held = est.get("held_force")
    if held is None:
        return None
    what = "breakaway" if "breakaway" in est else "coulomb"
    bound = est[what]
    cap = HELD_BEYOND_BREAKAWAY * max(bound.value + 2.0 * bound.stderr, 0.0)
    if held.value <= cap:
        return None
    return (
        f"the guides would hold {held.value:.3g} N while the axis sticks (nine samples in ten less), "
        f"beyond {HELD_BEYOND_BREAKAWAY:g} times their {'breakaway' if what == 'breakaway' else 'Coulomb'} "
        f"force of {fmt(bound)}: static friction holds no more than the force it breaks away at; a force "
        "the model lacks, which the loop keeps from moving a slow axis, looks the same"
    )


def level_candidates(ctx: LibraryContext) -> list[Candidate]:
    """A constant horizontal force (guides not level) and a constant vertical force. The tilt is the
    force over the weight the guides carry, the payload's with the mover's (the logs' mean where
    they declare different ones, whose pulls one constant force cannot hold apart)."""
    weight_h = (ctx.mass("horizontal") + float(np.mean(ctx.payloads))) * ctx.params.gravity
    tilt = constant_force(
        ctx.params,
        "horizontal",
        name="horizontal_guides_not_level",
        explanation="The horizontal guides are not level, so gravity pulls the platform along them "
        "with a constant force.",
    )

    def tilt_physical(q, cov, c):
        sd = math.sqrt(max(cov[0, 0], 0))
        return {
            "force": Estimate(float(q[0]), sd, "N"),
            "tilt": Estimate(math.asin(max(-1.0, min(1.0, q[0] / weight_h))), sd / weight_h, "rad"),
        }

    vertical = constant_force(
        ctx.params,
        "vertical",
        name="constant_vertical_force",
        explanation="A constant vertical force the model lacks (a cable's weight, a preload of the vertical "
        "guides); positive towards the stator.",
    )
    return [
        Candidate(
            with_physical(tilt, tilt_physical),
            "constant",
            "position",
            "runs centred at different horizontal positions separate a constant force from a spring",
            within("force", MAX_FORCE_SHARE * weight_h, "horizontal force"),
            lambda e: (
                f"The horizontal guides are tilted by {fmt(e['tilt'], 1e3, 'mrad')}: a constant force "
                f"of {fmt(e['force'])} along the track (any constant force there looks the same on "
                "one log: a cable's preload, a spring whose neutral point is beyond the travel)."
            ),
        ),
        Candidate(
            vertical,
            "constant",
            "gap",
            "a run with a known mass added to the platform (a load change, declared in that log as "
            "'# payload_kg: m' and diagnosed beside this one; a mass near half the mover's, 2 kg, "
            "separated a 3 N force on independent logs, 1 kg did not) or over a wider gap range "
            "separates a constant force from the scale of the magnetic force, which near equilibrium "
            "always carries the weight",
            within("force", MAX_FORCE_SHARE * ctx.weight("vertical"), "vertical force"),
            lambda e: f"A constant vertical force of {fmt(e['force'])} (positive towards the stator).",
        ),
    ]


def cable_candidate(ctx: LibraryContext) -> Candidate:
    """A spring along the track (cable carrier): F = -k x3 + F0."""
    mh = ctx.mass("horizontal")
    lo, hi = ctx.position_range
    term = AccelerationTerm(
        "cable_carrier_force",
        "The cable carrier (or a spring-like connection) pushes the platform back towards a neutral "
        "position with a force growing along the track.",
        "horizontal",
        ("stiffness", "force_at_zero"),
        function=term_function("cable", lambda x, u, du, q: ca.vertcat(0, (-q[0] * x[2] + q[1]) / mh), 2),
        physical=lambda q, cov, c: {
            "stiffness": Estimate(float(q[0]), math.sqrt(max(cov[0, 0], 0)), "N/m"),
            "neutral_position": delta_method(lambda v: v[1] / v[0] if v[0] else float("nan"), q, cov, "m"),
        },
        signature="residual linear in the horizontal position",
    )

    def not_too_strong(e):
        force = abs(e["stiffness"].value) * max(abs(lo), abs(hi))
        if force <= MAX_FORCE_SHARE * ctx.weight("horizontal"):
            return None
        return "spring force beyond a quarter of the platform's weight over the travel"

    return Candidate(
        term,
        "constant",
        "position",
        "runs over different parts of the travel separate a spring from a constant force and from the "
        "thrust's variation along the stator",
        # a spring whose stiffness the log does not resolve is the constant force alone, which the
        # tilt's candidate is (a random pair of the independent generator, a tilt beside a detent,
        # was claimed as a "cable carrier" of -0.016 +- 0.01 N/m neutral at 14 m)
        all_of(detected("stiffness", "spring along the track"), not_too_strong),
        # its neutral position takes up every constant force along the track: a tilt of the guides
        # beside it is the same two columns (drawn pair 18009 of the independent generator: a 0.087 N
        # tilt beside a 6 N/m cable carrier; the spring found at 6.04 N/m, its neutral moved from
        # -28.8 mm to -25 mm, the tilt not separable on that log)
        lambda e: (
            f"A spring-like force along the track (cable carrier): stiffness {fmt(e['stiffness'])}, "
            f"neutral at {fmt(e['neutral_position'], 1e3, 'mm')}: where it balances every constant force "
            "along the track too (a tilt of the guides, a preload), which one log cannot tell from its own "
            "(a run with a load added would: a tilt's force grows with the mass, a spring's does not)."
        ),
        # a line in the position: the linear part of any smooth dependence on it (a random pair of
        # the independent generator claimed 0.32 N/m for the horizontal force of a 69 mm guide
        # waviness, whose bow the next orders explained as well again)
        rival_span=("horizontal", "position", 2),
        # at zero stiffness the tilt's constant force: set 24602 of the independent generator (guides
        # tilted with a 7 um waviness at 70 mm, a base tilted 12 mrad) chose a 0.06 N/m spring before
        # the waviness, whose slope it took; beside the waviness it explained no more than the tilt
        simpler="horizontal_guides_not_level",
        physical_sign=1,  # a spring pulls back towards its neutral position
    )


def misalignment_candidate(ctx: LibraryContext) -> Candidate:
    """Horizontal guides sloping against a level stator (true gap = reading + slope x3)."""
    mh = ctx.mass("horizontal")
    lo, hi = ctx.position_range

    def misalignment(x, u, du, q, weight):
        # the gap error changes both accelerations; along the sloping guides the weight of what
        # moves horizontally (its payload too) pulls down-slope and the normal force towards the stator
        along = ca.vertcat(0, (weight - ctx.normal_force(x, u)) / mh)
        return (ctx.gap_sensitivity(x, u) * x[2] + along) * q[0]

    def physical(q, cov, c):
        sd = math.sqrt(max(cov[0, 0], 0))
        return {
            "slope": Estimate(float(q[0]), sd, "rad"),
            "gap_change_over_travel": Estimate(float(q[0]) * (hi - lo), sd * (hi - lo), "m"),
        }

    return Candidate(
        AccelerationTerm(
            "guide_misalignment",
            "The horizontal guides are not parallel to the stator: the magnetic gap changes along the "
            "track in proportion to the position while the gap encoder does not see it, and the normal "
            "force and the weight push the platform along the sloping guides.",
            "both",
            ("slope",),
            function=ctx.along_the_guides("misalign", misalignment, 1),
            physical=physical,
            signature="vertical residual growing along the track with the model's gap sensitivity",
            in_time=ctx.payloads_differ,
        ),
        "geometry",
        "position",
        "a gauge-block check of the gap at both ends of the travel, or set-point runs at several positions "
        "at one gap reading",
        within("slope", 0.05, "guide slope"),
        lambda e: (
            f"The gap the encoder reads is off by {fmt(e['gap_change_over_travel'], 1e3, 'mm')} from one "
            f"end of the travel to the other (slope {fmt(e['slope'], 1e3, 'mrad')})."
        ),
    )


def gap_offset_candidate(ctx: LibraryContext) -> Candidate:
    """The gap encoder's zero offset from the true gap."""
    return Candidate(
        AccelerationTerm(
            "gap_sensor_offset",
            "The gap encoder's zero is offset from the true magnetic gap, so every gap-dependent force is "
            "evaluated at the wrong gap.",
            "both",
            ("offset",),
            function=term_function("gapoff", lambda x, u, du, q: ctx.gap_sensitivity(x, u) * q[0], 1),
            physical=linear_physical([("offset", "m", 1.0)]),
            signature="vertical residual following the model's gap sensitivity",
        ),
        "geometry",
        "gap",
        "the gap measured with a gauge block at a stopper, or equilibrium currents over a wide gap range",
        within("offset", 2e-3, "gap offset"),
        lambda e: f"The gap encoder reads {fmt(e['offset'], 1e3, 'mm')} off the true gap.",
    )


def waviness_candidate(model: StageModel, data: PreparedLogs, period: float) -> Candidate:
    """Guide waviness at a period the residual's spatial spectrum points to (no motor period).

    The horizontal guides are not straight: the magnetic gap differs from the reading by
    w(x3) = a sin(2 pi x3 / P) + b cos(2 pi x3 / P), which changes both accelerations through the
    model's gap sensitivity and, along the locally sloping guides (slope w'(x3)), lets the weight
    and the magnetic normal force push the platform: x4' += w'(x3) (M_h G - F_n) / M_h, as for a
    uniform slope (:func:`misalignment_candidate`)."""
    ctx = LibraryContext(model, data)
    mh = ctx.mass("horizontal")
    k = 2 * math.pi / period

    def build(x, u, du, q, weight):
        w = q[0] * ca.sin(k * x[2]) + q[1] * ca.cos(k * x[2])
        slope = k * (q[0] * ca.cos(k * x[2]) - q[1] * ca.sin(k * x[2]))
        return ctx.gap_sensitivity(x, u) * w + ca.vertcat(0, slope * (weight - ctx.normal_force(x, u)) / mh)

    mm = period * 1e3
    term = AccelerationTerm(
        f"guide_waviness_{mm:.0f}mm",
        f"The horizontal guides are not straight: the magnetic gap the encoder does not see changes "
        f"periodically along the track over {mm:.1f} mm (a period found in the residual, not a motor "
        "period).",
        "both",
        ("sin", "cos"),
        function=ctx.along_the_guides(f"waviness{mm:.0f}", build, 2),
        physical=lambda q, cov, c: {
            **amplitude_phase("m", 1.0)(q, cov, c),
            "period": Estimate(period, 0.0, "m"),
        },
        signature=f"vertical residual periodic in x3 ({mm:.1f} mm) following the gap sensitivity",
        in_time=ctx.payloads_differ,
    )
    return Candidate(
        term,
        "geometry",
        "position",
        "a straightness measurement of the guides, or set-point runs along the track at one gap reading",
        within("amplitude", 5e-4, "waviness"),
        lambda e: (
            f"The guides wave by {fmt(e['amplitude'], 1e6, 'um')} over {mm:.1f} mm: the gap changes "
            "periodically along the track."
        ),
    )


def refine_waviness_period(
    model: StageModel,
    data: PreparedLogs,
    residual: np.ndarray,
    weights: np.ndarray,
    fit: np.ndarray,
    guess: float,
    *,
    span: float = 0.25,
    points: int = 41,
) -> float:
    """The waviness period near ``guess`` that explains most of ``residual`` (2, n) on the fitted
    samples: a periodogram peak over a travel of one or two periods is broad, and a slope or an
    end effect shifts it; this scans periods within +-``span`` of the guess by least squares on
    the waviness's own columns (both axes, filtered and weighted like the design)."""
    ctx = LibraryContext(model, data)
    x, u = ca.SX.sym("x", 4), ca.SX.sym("u", 2)
    fn = ca.Function("wav_parts", [x, u], [ctx.gap_sensitivity(x, u), ctx.normal_force(x, u)])
    sens, normal = NumpyCall(fn.map(data.n))(data.x, data.u)
    # the weight the guides carry, each log's payload with it (LibraryContext.weight_carried)
    carried = ctx.mass("horizontal") / data.load_factors[1] * model.params.gravity
    along_v = (carried - normal) / ctx.mass("horizontal")
    x3 = data.x[2]
    best, best_sse = guess, np.inf
    y = (residual * weights[:, None])[:, fit].reshape(-1)
    zero = np.zeros_like(x3)
    for period in guess * np.linspace(1 - span, 1 + span, points):
        k = 2 * math.pi / period
        sn, cs = np.sin(k * x3), np.cos(k * x3)
        cols = np.stack(
            [sens * sn + np.vstack([zero, along_v * k * cs]), sens * cs - np.vstack([zero, along_v * k * sn])]
        )
        cols = data.filter(cols) * weights[None, :, None]
        a = cols[:, :, fit].reshape(2, -1).T
        coef, *_ = np.linalg.lstsq(a, y, rcond=None)
        sse = float(np.sum((y - a @ coef) ** 2))
        if sse < best_sse:
            best, best_sse = float(period), sse
    return best
