"""The candidate effects a linear-guide PMLSM stage may show, as terms of the regression layer.

Each :class:`Candidate` is an :class:`~maglev_oc.regression.terms.AccelerationTerm` (linear in its
coefficients, so every fit is an exact linear solve) plus what the diagnosis needs around it:
the family it belongs to, the signal its signature lives in, a physical plausibility check,
the experiment that would separate it from the base constants, and a sentence saying what was
found in plain words.

Hyper-parameters that would make a term nonlinear (spatial periods, the gap exponent of cogging,
the reversal speed of friction) are fixed at physical values; where several are plausible they
are separate candidates that compete, or variants whose spread is reported as a model-form
uncertainty.

What the library holds (papers 000/002 name the first four; the rest are what real slotted
PMLSM stages on linear guides are known for):

* guide friction on each axis (Coulomb + viscous);
* cogging (normal) and detent (longitudinal) forces periodic in the position at the slot pitch
  t1, 2 t1 (000 eq. (9)) and the pole pitch tau, growing as the gap closes;
* guide misalignment: the gap changes along the travel, unseen by the gap encoder;
* end effects and field non-uniformity: thrust and attraction varying smoothly along the stator
  (even and odd Legendre profiles over the travel the log covers);
* the attraction's dependence on the gap differing smoothly from the field model;
* thrust ripple along the track (slot and pole pitch), proportional to i_q;
* commutation-angle offset (i_d and i_q mix), current-amplifier lag;
* a cable carrier's spring force, a constant horizontal force (guides not level), a constant
  vertical force, a gap-encoder offset.

Coefficients that multiply the magnetic shape functions use the base fit's constants as
references (``model``); their physical values are converted with the constants of the fit they
come from (the ``constants`` argument of the conversions), so a joint refit stays consistent.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.model.hardware import RIG_SAMPLE_TIME
from maglev_oc.model.stage import StageModel
from maglev_oc.regression.data import PreparedLogs
from maglev_oc.regression.terms import (
    REFERENCE_GAP,
    AccelerationTerm,
    Estimate,
    amplitude_phase,
    cogging_force,
    constant_force,
    guide_friction,
    linear_physical,
    term_function,
)

__all__ = [
    "FAMILIES",
    "VARIABLES",
    "Candidate",
    "candidate_library",
    "refine_waviness_period",
    "waviness_candidate",
]

VARIABLES = ("gap", "gap_rate", "position", "position_rate", "current_rate", "current")
FAMILIES = ("friction", "periodic", "profile", "current", "constant", "geometry")
MAX_FORCE_SHARE = 0.25
"""An effect whose RMS force exceeds this share of its axis's weight (M g) is not plausible as an
unmodelled detail of a working stage: the papers' model predicts the equilibrium currents to
5 % (002 Sec. 5.2), so a missing force of a quarter of the weight would have shown there."""


Plausibility = Callable[[Mapping[str, Estimate]], str | None]
"""physical parameters -> None when plausible, else the reason it is not."""


@dataclass(frozen=True)
class Candidate:
    """A candidate effect: a term and what the diagnosis needs to judge and report it.

    Attributes
    ----------
    term : AccelerationTerm
    family : str  one of :data:`FAMILIES`
    variable : str  the signal its signature lives in (one of :data:`VARIABLES`)
    separate_by : str  the experiment that separates it from the base constants
    plausible : callable  physical parameters -> None or the reason they are not physical
    describe : callable  physical parameters -> one sentence with the sizes, plain words
    """

    term: AccelerationTerm
    family: str
    variable: str
    separate_by: str
    plausible: Plausibility = field(repr=False)
    describe: Callable[[Mapping[str, Estimate]], str] = field(repr=False)
    nuisance: tuple[str, ...] = ()
    """Parameters that only shape the term (not reported as its size) and are expected to be
    correlated with the constants: left out of the separability test."""

    def __post_init__(self) -> None:
        if self.family not in FAMILIES:
            raise ValueError(f"Candidate {self.term.name}: family must be one of {FAMILIES}")
        if self.variable not in VARIABLES:
            raise ValueError(f"Candidate {self.term.name}: variable must be one of {VARIABLES}")

    @property
    def name(self) -> str:
        return self.term.name

    @property
    def axis(self) -> str:
        return self.term.axis


# --- helpers -----------------------------------------------------------------------------------
def _not_below(name: str, what: str, k: float = 2.0) -> Plausibility:
    """Refuse a parameter that is negative by more than k standard errors."""

    def check(est):
        e = est[name]
        if e.value < -k * max(e.stderr, 0.0):
            sigmas = e.value / max(e.stderr, 1e-300)
            return f"{what} of {e.value:.3g} {e.unit} is negative ({sigmas:.1f} standard errors)"
        return None

    return check


def _detected(name: str, what: str, k: float = 2.0) -> Plausibility:
    """Refuse unless a parameter is positive by more than k standard errors."""

    def check(est):
        e = est[name]
        if not e.value > k * max(e.stderr, 0.0):
            return (
                f"no {what}: {e.value:.3g} ± {e.stderr:.2g} {e.unit} is not positive by {k:g} standard errors"
            )
        return None

    return check


def _within(name: str, bound: float, what: str) -> Plausibility:
    def check(est):
        e = est[name]
        if abs(e.value) > bound:
            return f"{what} of {e.value:.3g} {e.unit} is beyond the physical bound {bound:g} {e.unit}"
        return None

    return check


def _all(*checks: Plausibility) -> Plausibility:
    def check(est):
        for c in checks:
            reason = c(est)
            if reason:
                return reason
        return None

    return check


def _fmt(e: Estimate, scale: float = 1.0, unit: str | None = None, digits: int = 2) -> str:
    u = e.unit if unit is None else unit
    return f"{e.value * scale:.{digits}g} ± {e.stderr * scale:.1g} {u}".strip()


def _delta(f: Callable[[np.ndarray], float], p: np.ndarray, cov: np.ndarray, unit: str) -> Estimate:
    """f(p) with the delta method (central differences on the gradient)."""
    p = np.asarray(p, dtype=float)
    val = float(f(p))
    g = np.zeros_like(p)
    for k in range(p.size):
        h = 1e-6 * max(abs(p[k]), 1e-6)
        d = np.zeros_like(p)
        d[k] = h
        g[k] = (f(p + d) - f(p - d)) / (2 * h)
    return Estimate(val, float(math.sqrt(max(g @ cov @ g, 0.0))), unit)


def _legendre(xi, orders):
    """Legendre polynomials P_k(xi) for k in orders (symbolic or numeric)."""
    out = []
    for k in orders:
        if k == 1:
            out.append(xi)
        elif k == 2:
            out.append((3 * xi**2 - 1) / 2)
        elif k == 3:
            out.append((5 * xi**3 - 3 * xi) / 2)
        elif k == 4:
            out.append((35 * xi**4 - 30 * xi**2 + 3) / 8)
        else:
            raise ValueError(f"Legendre order {k} not provided")
    return out


# --- the library -------------------------------------------------------------------------------
def candidate_library(model: StageModel, data: PreparedLogs) -> list[Candidate]:
    """Every candidate for ``data``, with magnetic references from ``model`` (the base fit)."""
    p = model.params
    mv, mh, G = p.mass_vertical, p.mass_horizontal, p.gravity
    t1, tau = p.slot_pitch, p.pole_pitch
    c_ref = model.constants
    fit_x = data.x[:, data.valid]
    gap_lo, gap_hi = (float(v) for v in np.percentile(fit_x[0], [1, 99]))
    pos_lo, pos_hi = (float(v) for v in np.percentile(fit_x[2], [1, 99]))
    gap_mid = float(np.median(fit_x[0]))
    out: list[Candidate] = []

    def shapes(x):
        return model.shape(x[0])

    # guide friction ---------------------------------------------------------------------------
    def modelled(axis):  # the base model's acceleration on an axis, with the references
        row = 1 if axis == "vertical" else 3
        return lambda x, u: model.f(x, u)[row]

    def friction_physical(term, axis):
        base = term.physical

        def convert(q, cov, c):
            out_ = base(q, cov, c)
            if axis == "horizontal":  # the holding column carries the reference C1
                k = c_ref.C1 / c.get("C1", c_ref.C1)
                h = out_["holding"]
                out_["holding"] = Estimate(h.value * k, h.stderr * abs(k), "1")
            return out_

        return convert

    for axis, mass in (("vertical", mv), ("horizontal", mh)):
        term = guide_friction(p, axis, holding=modelled(axis))
        term = _with_physical(term, friction_physical(term, axis))
        out.append(
            Candidate(
                term,
                "friction",
                "gap_rate" if axis == "vertical" else "position_rate",
                "slow constant-speed sweeps in both directions (speed reversals at several speeds) separate "
                "Coulomb from viscous friction and from the thrust constant",
                _all(
                    _detected("coulomb", "Coulomb friction (sticking without friction is not physical)"),
                    _not_below("viscous", "viscous friction"),
                    _within("coulomb", MAX_FORCE_SHARE * mass * G, "Coulomb friction"),
                    _within("holding", 1.5, "share of the force held while sticking"),
                ),
                lambda e, axis=axis: (
                    f"The {axis} linear guides resist motion with {_fmt(e['coulomb'])} of "
                    f"Coulomb friction and {_fmt(e['viscous'])} of viscous friction (and hold the "
                    "axis while it "
                    "sticks)."
                ),
                nuisance=("holding",),
            )
        )

    # constant forces --------------------------------------------------------------------------
    tilt = constant_force(
        p,
        "horizontal",
        name="horizontal_guides_not_level",
        explanation="The horizontal guides are not level, so gravity pulls the platform along them "
        "with a constant force.",
    )
    out.append(
        Candidate(
            _with_physical(
                tilt,
                lambda q, cov, c: {
                    "force": Estimate(float(q[0]), math.sqrt(max(cov[0, 0], 0)), "N"),
                    "tilt": Estimate(
                        math.asin(max(-1.0, min(1.0, q[0] / (mh * G)))),
                        math.sqrt(max(cov[0, 0], 0)) / (mh * G),
                        "rad",
                    ),
                },
            ),
            "constant",
            "position",
            "runs centred at different horizontal positions separate a constant force from a spring",
            _within("force", MAX_FORCE_SHARE * mh * G, "horizontal force"),
            lambda e: (
                f"The horizontal guides are tilted by {_fmt(e['tilt'], 1e3, 'mrad')}: a constant force "
                f"of {_fmt(e['force'])} along the track."
            ),
        )
    )
    vf = constant_force(
        p,
        "vertical",
        name="constant_vertical_force",
        explanation="A constant vertical force the model lacks (a cable's weight, a preload of the vertical "
        "guides); positive towards the stator.",
    )
    out.append(
        Candidate(
            vf,
            "constant",
            "gap",
            "a run with a known mass added to the platform (a load change) or over a wider gap range "
            "separates a constant force from the scale of the magnetic force, which near equilibrium "
            "always carries the weight",
            _within("force", MAX_FORCE_SHARE * mv * G, "vertical force"),
            lambda e: f"A constant vertical force of {_fmt(e['force'])} (positive towards the stator).",
        )
    )
    cable = AccelerationTerm(
        "cable_carrier_force",
        "The cable carrier (or a spring-like connection) pushes the platform back towards a neutral "
        "position with a force growing along the track.",
        "horizontal",
        ("stiffness", "force_at_zero"),
        function=term_function("cable", lambda x, u, du, q: ca.vertcat(0, (-q[0] * x[2] + q[1]) / mh), 2),
        physical=lambda q, cov, c: {
            "stiffness": Estimate(float(q[0]), math.sqrt(max(cov[0, 0], 0)), "N/m"),
            "neutral_position": _delta(lambda v: v[1] / v[0] if v[0] else float("nan"), q, cov, "m"),
        },
        signature="residual linear in the horizontal position",
    )
    out.append(
        Candidate(
            cable,
            "constant",
            "position",
            "runs over different parts of the travel separate a spring from a constant force and from the "
            "thrust's variation along the stator",
            _all(
                _not_below("stiffness", "cable stiffness"),
                lambda e: (
                    None
                    if abs(e["stiffness"].value) * max(abs(pos_lo), abs(pos_hi)) <= MAX_FORCE_SHARE * mh * G
                    else "spring force beyond a quarter of the platform's weight over the travel"
                ),
            ),
            lambda e: (
                f"A spring-like force along the track (cable carrier): stiffness {_fmt(e['stiffness'])}, "
                f"neutral at {_fmt(e['neutral_position'], 1e3, 'mm')}."
            ),
        )
    )

    # cogging and detent ------------------------------------------------------------------------
    periodic = (
        ("vertical", t1, 2, "the slot pitch"),
        ("vertical", 2 * t1, 1, "two slot pitches (000 eq. (9))"),
        ("horizontal", t1, 2, "the slot pitch"),
        ("horizontal", tau, 1, "the pole pitch (the mover's ends)"),
    )
    for axis, period, harmonics, what in periodic:
        mm = period * 1e3
        kind = "normal (vertical)" if axis == "vertical" else "longitudinal (detent)"
        term = cogging_force(
            p,
            axis,
            period,
            harmonics=harmonics,
            reference_gap=gap_mid,
            name=f"cogging_{axis}_{mm:.0f}mm",
            explanation=(
                f"The stator teeth and the magnet edges attract each other, adding a {kind} force "
                f"periodic in the position over {what} ({mm:.1f} mm) that grows as the gap closes."
            ),
        )
        out.append(
            Candidate(
                _with_physical(term, _cogging_physical(term, period)),
                "periodic",
                "position",
                "runs at two gaps separate a force that grows as the gap closes from guide waviness",
                _within("amplitude", MAX_FORCE_SHARE * (mv if axis == "vertical" else mh) * G, "peak force"),
                lambda e, kind=kind, mm=mm: (
                    f"A {kind} cogging force of {_fmt(e['amplitude'])} peak at a "
                    f"{e['at_gap'].value * 1e3:.1f} mm gap ({_fmt(e['amplitude_15mm'])} at 15 mm), periodic "
                    f"over {mm:.1f} mm."
                ),
            )
        )

    # end effects: thrust and attraction falling towards the ends of the stator -----------------
    def end_profile(x3, width):
        """1 at the logged ends of the travel, decaying inwards over ``width``."""
        return ca.exp((x3 - pos_hi) / width) + ca.exp((pos_lo - x3) / width)

    def end_fn(width):
        def build(x, u, du, q):
            l = shapes(x)
            prof = end_profile(x[2], width)
            thrust = -c_ref.C1 * l[0] * u[0]
            winding_normal = -(c_ref.C3 * l[2] * u[1] + c_ref.C4 * l[3] * (u[0] ** 2 + u[1] ** 2))
            magnets = -c_ref.C2 * l[1]
            # a loss fraction q of each force at the ends: acc changes by -q * force * profile
            return ca.vertcat(-(q[0] * winding_normal + q[1] * magnets) * prof, -q[0] * thrust * prof)

        return term_function("end_effects", build, 2)

    def end_physical(width):
        def convert(q, cov, c):
            k = float(np.exp(-(pos_hi - pos_lo) / width))  # the profile at the centre of the travel, ~0
            mid = float(2 * np.exp(-(pos_hi - pos_lo) / (2 * width)))
            scale_t = c_ref.C1 / c.get("C1", c_ref.C1)
            scale_a = c_ref.C2 / c.get("C2", c_ref.C2)
            drop = 1 + k - mid  # profile at an end minus at the centre
            return {
                "thrust_loss_at_ends": Estimate(
                    q[0] * drop * scale_t, math.sqrt(max(cov[0, 0], 0)) * drop * scale_t, "1"
                ),
                "attraction_loss_at_ends": Estimate(
                    q[1] * drop * scale_a, math.sqrt(max(cov[1, 1], 0)) * drop * scale_a, "1"
                ),
                "low_end_position": Estimate(pos_lo, 0.0, "m"),
                "high_end_position": Estimate(pos_hi, 0.0, "m"),
                "width": Estimate(width, 0.0, "m"),
            }

        return convert

    end_width = 0.015
    out.append(
        Candidate(
            AccelerationTerm(
                "end_effects",
                "Towards the ends of the travel the mover overhangs the stator: the thrust (and the "
                "normal force "
                "the currents make) and the magnets' attraction fall smoothly.",
                "both",
                ("winding_loss", "magnet_loss"),
                function=end_fn(end_width),
                physical=end_physical(end_width),
                signature="thrust- and attraction-proportional residual growing towards both ends of the "
                "travel",
                variants=(end_fn(end_width / 2), end_fn(end_width * 2)),
                variant_note=f"fall-off width {end_width / 2 * 1e3:g}-{end_width * 2 * 1e3:g} mm",
            ),
            "profile",
            "position",
            "set-point runs at several positions along the stator at one gap (equilibrium currents and "
            "parabola fits of L1 per position, 000 Sec. V-A) separate it from the constants",
            _all(
                _within("thrust_loss_at_ends", 0.5, "thrust loss at the ends"),
                _within("attraction_loss_at_ends", 0.5, "attraction loss at the ends"),
                lambda e: (
                    None
                    if e["thrust_loss_at_ends"].value + e["attraction_loss_at_ends"].value > 0
                    else "the forces grow, not fall, towards the ends"
                ),
            ),
            lambda e: (
                f"Towards the ends of the travel ({e['low_end_position'].value * 1e3:.0f} and "
                f"{e['high_end_position'].value * 1e3:.0f} mm) the thrust falls by "
                f"{_fmt(e['thrust_loss_at_ends'], 100, '%')} "
                f"and the magnets' attraction by {_fmt(e['attraction_loss_at_ends'], 100, '%')} "
                "relative to the centre."
            ),
        )
    )

    # the attraction's gap dependence --------------------------------------------------------
    g_centre, g_half = 0.5 * (gap_lo + gap_hi), max(0.5 * (gap_hi - gap_lo), 1e-4)

    gap_means = [float(np.mean(b)) for b in _legendre((fit_x[0] - g_centre) / g_half, (1, 2))]

    def gap_shape(x, u, du, q):
        l = shapes(x)
        xi = (x[0] - g_centre) / g_half
        b1, b2 = (b - m for b, m in zip(_legendre(xi, (1, 2)), gap_means, strict=True))
        return ca.vertcat(-c_ref.C2 * l[1] * (q[0] * b1 + q[1] * b2), 0)

    def gap_physical(q, cov, c):
        s = c_ref.C2 / c.get("C2", c_ref.C2)
        res = {}
        for label, xi in (("at_smallest_gap", -1.0), ("at_largest_gap", 1.0)):
            res[f"attraction_change_{label}"] = _delta(
                lambda v, xi=xi: s * (v[0] * xi + v[1] * (3 * xi**2 - 1) / 2 + v[1] / 2), q, cov, "1"
            )
        res["smallest_gap"] = Estimate(gap_lo, 0.0, "m")
        res["largest_gap"] = Estimate(gap_hi, 0.0, "m")
        return res

    out.append(
        Candidate(
            AccelerationTerm(
                "attraction_gap_dependence",
                "The magnets' attraction changes with the gap differently from the field model (field shape, "
                "magnet height or iron saturation), leaving a smooth error that varies with the gap.",
                "vertical",
                ("P1", "P2"),
                function=term_function("gapdep", gap_shape, 2),
                physical=gap_physical,
                signature="residual proportional to the attraction varying smoothly with the gap",
            ),
            "profile",
            "gap",
            "equilibrium currents over a wide range of gaps (000 Sec. V-B, 10-25 mm) separate the field's "
            "gap dependence from C2..C4",
            lambda e: (
                None
                if max(
                    abs(e["attraction_change_at_smallest_gap"].value),
                    abs(e["attraction_change_at_largest_gap"].value),
                )
                <= 0.3
                else "attraction off the field model by more than 30 % within the logged gaps"
            ),
            lambda e: (
                "The attraction departs from the field model by "
                f"{_fmt(e['attraction_change_at_smallest_gap'], 100, '%')} "
                f"at a {e['smallest_gap'].value * 1e3:.1f} mm gap and "
                f"{_fmt(e['attraction_change_at_largest_gap'], 100, '%')} "
                f"at {e['largest_gap'].value * 1e3:.1f} mm."
            ),
        )
    )

    # current-dependent effects -----------------------------------------------------------
    ripple_periods = (t1, tau)  # slotting (the slot pitch) and the winding's pole-pitch harmonic

    def ripple(x, u, du, q):
        thrust = -c_ref.C1 * shapes(x)[0] * u[0]
        total = 0
        for k, period in enumerate(ripple_periods):
            arg = 2 * math.pi * x[2] / period
            total = total + q[2 * k] * ca.sin(arg) + q[2 * k + 1] * ca.cos(arg)
        return ca.vertcat(0, thrust * total)

    def ripple_physical(q, cov, c):
        s = c_ref.C1 / c.get("C1", c_ref.C1)
        out_ = {}
        for k, (label, period) in enumerate(zip(("", "_pole_pitch"), ripple_periods, strict=True)):
            sl = slice(2 * k, 2 * k + 2)
            out_[f"amplitude{label}"] = _delta(lambda v: s * math.hypot(v[0], v[1]), q[sl], cov[sl, sl], "1")
            out_[f"phase{label}"] = _delta(lambda v: math.atan2(v[1], v[0]), q[sl], cov[sl, sl], "rad")
            out_[f"period{label}"] = Estimate(period, 0.0, "m")
        return out_

    out.append(
        Candidate(
            AccelerationTerm(
                "thrust_ripple",
                f"The thrust per ampere ripples along the track over the slot pitch ({t1 * 1e3:.2f} "
                "mm) and the "
                f"pole pitch ({tau * 1e3:.2f} mm) (slotting and winding harmonics), so the propulsion force "
                "ripples in proportion to i_q.",
                "horizontal",
                ("sin_slot", "cos_slot", "sin_pole", "cos_pole"),
                function=term_function("ripple", ripple, 4),
                physical=ripple_physical,
                signature="residual proportional to i_q and periodic in x3",
            ),
            "current",
            "position",
            "runs with the same path at two different accelerations separate thrust ripple from a "
            "position-periodic force",
            _all(
                _within("amplitude", 0.3, "ripple amplitude"),
                _within("amplitude_pole_pitch", 0.3, "ripple amplitude"),
            ),
            lambda e: (
                f"The thrust ripples by {_fmt(e['amplitude'], 100, '%')} of its value over the slot "
                "pitch and "
                f"{_fmt(e['amplitude_pole_pitch'], 100, '%')} over the pole pitch."
            ),
        )
    )

    def commutation(x, u, du, q):
        l = shapes(x)
        # i_q' = i_q + d i_d, i_d' = i_d - d i_q (first order in d): x2' = ... - L3 i_d' -> +L3 d i_q
        return ca.vertcat(c_ref.C3 * l[2] * u[0] * q[0], -c_ref.C1 * l[0] * u[1] * q[0])

    out.append(
        Candidate(
            AccelerationTerm(
                "commutation_offset",
                "The amplifiers' electrical angle is offset from the magnet poles, so part of i_d produces "
                "thrust and part of i_q normal force.",
                "both",
                ("angle",),
                function=term_function("commutation", commutation, 1),
                physical=linear_physical([("angle", "rad", 1.0)]),
                signature="horizontal residual proportional to i_d (and vertical to i_q)",
            ),
            "current",
            "current",
            "a run at two levitation gaps (different i_d) with the same horizontal motion separates it "
            "from the thrust constant",
            _within("angle", 0.35, "commutation angle"),
            lambda e: f"The commutation angle is off by {_fmt(e['angle'], 180 / math.pi, 'degrees')}.",
        )
    )

    # the loop holds each command for one control period: on average the force follows the command
    # by half of it (0.1 ms at the rig's 5 kHz); the amplifier's own lag is what is beyond that
    hold_delay = 0.5 / data.settings.get("control_rate_hz", 1.0 / RIG_SAMPLE_TIME)

    def lag(x, u, du, q):
        l = shapes(x)
        # acc(u - T du) - acc(u) = -(d acc / d u) du T (first order in T)
        dv_du2 = -c_ref.C3 * l[2] - 2 * c_ref.C4 * l[3] * u[1]
        dv_du1 = -2 * c_ref.C4 * l[3] * u[0]
        dh_du1 = -c_ref.C1 * l[0]
        return ca.vertcat(-(dv_du2 * du[1] + dv_du1 * du[0]) * q[0], -dh_du1 * du[0] * q[0])

    out.append(
        Candidate(
            AccelerationTerm(
                "current_amplifier_lag",
                "The current amplifiers (or the real-time loop) deliver the commanded currents late, so the "
                "forces lag the commands by a small time constant.",
                "both",
                ("time_constant",),
                function=term_function("lag", lag, 1),
                physical=lambda q, cov, c: {
                    "time_constant": Estimate(float(q[0]) - hold_delay, math.sqrt(max(cov[0, 0], 0)), "s"),
                    "total_delay": Estimate(float(q[0]), math.sqrt(max(cov[0, 0], 0)), "s"),
                    "hold_delay": Estimate(hold_delay, 0.0, "s"),
                },
                signature="residual correlated with the rate of the commanded currents",
            ),
            "current",
            "current_rate",
            "current steps at several amplitudes, measured with a current probe, separate an amplifier lag "
            "from the regulator's own dynamics",
            _all(_detected("total_delay", "lag"), _within("time_constant", 5e-3, "lag")),
            lambda e: (
                f"The currents lag their commands by {_fmt(e['time_constant'], 1e3, 'ms')} beyond the "
                f"{e['hold_delay'].value * 1e3:.2g} ms of the loop's zero-order hold."
            ),
        )
    )

    def dacc_dgap(x, u):
        xs = ca.SX.sym("xs", 4)
        acc = model.f(xs, u)[[1, 3]]
        return ca.substitute(ca.jacobian(acc, xs[0]), xs, x)

    def misalignment(x, u, du, q):
        """Guides sloping by q[0] against a level stator (true gap = reading + q x3): the gap error
        changes both accelerations, and along the guides the weight of everything that moves
        horizontally pulls down-slope while the magnetic normal force F_n = M_v (G - x2'_model)
        pulls towards the stator: x4' += q (M_h G - F_n) / M_h."""
        normal = mv * (G - model.f(x, u)[1])
        along = ca.vertcat(0, (mh * G - normal) / mh)
        return (dacc_dgap(x, u) * x[2] + along) * q[0]

    out.append(
        Candidate(
            AccelerationTerm(
                "guide_misalignment",
                "The horizontal guides are not parallel to the stator: the magnetic gap changes along the "
                "track in proportion to the position while the gap encoder does not see it, and the normal "
                "force and the weight push the platform along the sloping guides.",
                "both",
                ("slope",),
                function=term_function("misalign", misalignment, 1),
                physical=lambda q, cov, c: {
                    "slope": Estimate(float(q[0]), math.sqrt(max(cov[0, 0], 0)), "rad"),
                    "gap_change_over_travel": Estimate(
                        float(q[0]) * (pos_hi - pos_lo), math.sqrt(max(cov[0, 0], 0)) * (pos_hi - pos_lo), "m"
                    ),
                },
                signature="vertical residual growing along the track with the model's gap sensitivity",
            ),
            "geometry",
            "position",
            "a gauge-block check of the gap at both ends of the travel, or set-point runs at several "
            "positions "
            "at one gap reading",
            _within("slope", 0.05, "guide slope"),
            lambda e: (
                f"The gap the encoder reads is off by {_fmt(e['gap_change_over_travel'], 1e3, 'mm')} "
                "from one "
                f"end of the travel to the other (slope {_fmt(e['slope'], 1e3, 'mrad')})."
            ),
        )
    )
    out.append(
        Candidate(
            AccelerationTerm(
                "gap_sensor_offset",
                "The gap encoder's zero is offset from the true magnetic gap, so every gap-dependent "
                "force is "
                "evaluated at the wrong gap.",
                "both",
                ("offset",),
                function=term_function("gapoff", lambda x, u, du, q: dacc_dgap(x, u) * q[0], 1),
                physical=linear_physical([("offset", "m", 1.0)]),
                signature="vertical residual following the model's gap sensitivity",
            ),
            "geometry",
            "gap",
            "the gap measured with a gauge block at a stopper, or equilibrium currents over a wide gap range",
            _within("offset", 2e-3, "gap offset"),
            lambda e: f"The gap encoder reads {_fmt(e['offset'], 1e3, 'mm')} off the true gap.",
        )
    )
    return out


def _with_physical(term: AccelerationTerm, physical) -> AccelerationTerm:
    import dataclasses

    return dataclasses.replace(term, physical=physical)


def _cogging_physical(term: AccelerationTerm, period: float):
    """The term's conversion plus the fundamental's peak at 15 mm (the papers' reference gap)."""
    base = term.physical

    def convert(q, cov, c):
        out = base(q, cov, c)
        amp, at = out["amplitude"], out["at_gap"].value
        k = math.exp(-(REFERENCE_GAP - at) * 2 * math.pi / period)
        out["amplitude_15mm"] = Estimate(amp.value * k, amp.stderr * k, "N")
        return out

    return convert


def waviness_candidate(model: StageModel, data: PreparedLogs, period: float) -> Candidate:
    """Guide waviness at a period the residual's spatial spectrum points to (no motor period).

    The horizontal guides are not straight: the magnetic gap differs from the reading by
    w(x3) = a sin(2 pi x3 / P) + b cos(2 pi x3 / P), which changes both accelerations through the
    model's gap sensitivity and, along the locally sloping guides (slope w'(x3)), lets the weight
    and the magnetic normal force push the platform: x4' += w'(x3) (M_h G - F_n) / M_h, as for a
    uniform slope (:func:`candidate_library`'s ``guide_misalignment``)."""
    p = model.params
    mv, mh, G = p.mass_vertical, p.mass_horizontal, p.gravity
    k = 2 * math.pi / period

    def build(x, u, du, q):
        xs = ca.SX.sym("xs", 4)
        acc = model.f(xs, u)[[1, 3]]
        sens = ca.substitute(ca.jacobian(acc, xs[0]), xs, x)
        w = q[0] * ca.sin(k * x[2]) + q[1] * ca.cos(k * x[2])
        slope = k * (q[0] * ca.cos(k * x[2]) - q[1] * ca.sin(k * x[2]))
        normal = mv * (G - model.f(x, u)[1])
        return sens * w + ca.vertcat(0, slope * (mh * G - normal) / mh)

    mm = period * 1e3
    term = AccelerationTerm(
        f"guide_waviness_{mm:.0f}mm",
        f"The horizontal guides are not straight: the magnetic gap the encoder does not see changes "
        f"periodically along the track over {mm:.1f} mm (a period found in the residual, not a motor "
        "period).",
        "both",
        ("sin", "cos"),
        function=term_function(f"waviness{mm:.0f}", build, 2),
        physical=lambda q, cov, c: {
            **amplitude_phase("m", 1.0)(q, cov, c),
            "period": Estimate(period, 0.0, "m"),
        },
        signature=f"vertical residual periodic in x3 ({mm:.1f} mm) following the gap sensitivity",
    )
    return Candidate(
        term,
        "geometry",
        "position",
        "a straightness measurement of the guides, or set-point runs along the track at one gap reading",
        _within("amplitude", 5e-4, "waviness"),
        lambda e: (
            f"The guides wave by {_fmt(e['amplitude'], 1e6, 'um')} over {mm:.1f} mm: the gap changes "
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
    p = model.params
    x, u = ca.SX.sym("x", 4), ca.SX.sym("u", 2)
    acc = model.f(x, u)[[1, 3]]
    normal = p.mass_vertical * (p.gravity - acc[0])
    fn = ca.Function(
        "wav_parts",
        [x, u],
        [ca.jacobian(acc, x[0]), (p.mass_horizontal * p.gravity - normal) / p.mass_horizontal],
    )
    sens, along = (np.asarray(v) for v in fn.map(data.n)(data.x, data.u))
    x3 = data.x[2]
    best, best_sse = guess, np.inf
    y = (residual * weights[:, None])[:, fit].reshape(-1)
    for period in guess * np.linspace(1 - span, 1 + span, points):
        k = 2 * math.pi / period
        sn, cs = np.sin(k * x3), np.cos(k * x3)
        cols = np.stack(
            [sens * sn + np.vstack([0 * x3, along * k * cs]), sens * cs - np.vstack([0 * x3, along * k * sn])]
        )  # (2, 2, n)
        cols = data.filter(cols) * weights[None, :, None]
        a = cols[:, :, fit].reshape(2, -1).T
        coef, *_ = np.linalg.lstsq(a, y, rcond=None)
        sse = float(np.sum((y - a @ coef) ** 2))
        if sse < best_sse:
            best, best_sse = float(period), sse
    return best


PROBE_VARIABLES = {
    "gap": (0, "the gap"),
    "position": (2, "the horizontal position"),
    "gap_rate": (1, "the gap rate (vertical velocity)"),
    "position_rate": (3, "the horizontal velocity"),
}
"""State variables a generic probe depends on: name -> (row of x, words)."""
PROBE_ORDER = 4
"""Legendre orders 1..4: a smooth dependence with as many coefficients as the richest candidate."""


def smooth_probes(data: PreparedLogs) -> dict[tuple[str, str], AccelerationTerm]:
    """Generic smooth additive terms, one per (axis, state variable): mean-free Legendre polynomials
    of orders 1..4 of the variable over its logged range (1st-99th percentile), as an acceleration
    on that axis. They are the rivals a named effect has to beat (it must explain the held-out data
    better than a generic function of its variable) and the probes of what nothing named explains."""
    fit_x = data.x[:, data.valid]
    out = {}
    for axis in ("vertical", "horizontal"):
        for var, (row, _) in PROBE_VARIABLES.items():
            lo, hi = (float(v) for v in np.percentile(fit_x[row], [1, 99]))
            c, h = 0.5 * (lo + hi), max(0.5 * (hi - lo), 1e-12)
            orders = range(1, PROBE_ORDER + 1)
            means = [float(np.mean(b)) for b in _legendre((fit_x[row] - c) / h, orders)]

            # horizontally the base model has no constant acceleration, so the probe carries one;
            # vertically a constant is the weight's business (C2..C4), so the probe is mean-free
            k = PROBE_ORDER + (axis == "horizontal")

            def build(x, u, du, q, row=row, c=c, h=h, means=means, axis=axis, orders=orders):
                basis = _legendre((x[row] - c) / h, orders)
                val = sum(
                    (q[i] * (b - m) for i, (b, m) in enumerate(zip(basis, means, strict=True))), ca.SX(0)
                )
                if axis == "horizontal":
                    return ca.vertcat(0, val + q[PROBE_ORDER])
                return ca.vertcat(val, 0)

            name = f"probe_{axis}_{var}"
            out[(axis, var)] = AccelerationTerm(
                name,
                f"A smooth function of {PROBE_VARIABLES[var][1]} on the {axis} axis.",
                axis,
                tuple(f"P{i}" for i in orders) + (("P0",) if axis == "horizontal" else ()),
                function=term_function(name, build, k),
            )
    return out
