"""The library of candidate physical effects a linear-guide PMLSM stage may show.

Each candidate is a parametrised CasADi term added to the accelerations (x2', x4'), linear in
its coefficients: acc = F(x, u, du) p, with F a (2, k) matrix Function of the state, the
commanded currents and their rates. Linear coefficients keep every fit an exact linear least-
squares problem (a 60 s log and 40 candidates fit in well under a second); hyper-parameters
that would make a term nonlinear (spatial periods, the gap exponent of cogging, the smoothing
speed of Coulomb friction) are fixed at physical values and, where several are plausible,
offered as separate candidates that compete in the selection.

The library goes beyond what the twin simulates: what the papers name (cogging, guide friction,
guide misalignment, current transients) and what real slotted PMLSM stages on linear guides are
known for (detent force and thrust ripple at the slot and pole pitches, commutation-angle
error, cable-carrier forces, encoder offsets, payload/gravity offsets, magnet-field model error).

Every candidate carries a one-sentence physical explanation and converts its coefficients to
physical parameters (N, N s/m, rad, s, m) with standard errors by the delta method.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.model.stage import StageModel

AXES = ("vertical", "horizontal", "both")
VARIABLES = ("gap", "gap_rate", "position", "position_rate", "current_rate", "current")
REFERENCE_GAP = 15e-3  # [m] where gap-dependent forces are quoted
COGGING_EXPONENT = 3.0  # cogging ~ gap^-3 (000: "inversely proportional", grows fast below 15 mm)


@dataclass(frozen=True)
class Physical:
    """A reported parameter: value and standard error in physical units."""

    value: float
    stderr: float
    unit: str


@dataclass(frozen=True)
class Candidate:
    """One candidate effect: acc = features(x, u, du) @ p (features is (2, k))."""

    name: str
    explanation: str
    axis: str
    coefficient_names: tuple[str, ...]
    features: ca.Function  # (x (4), u (2), du (2)) -> (2, k)
    physical: Callable[[np.ndarray, np.ndarray], dict[str, Physical]] = field(repr=False)
    signature: str = ""  # what in the residual points at it (for the report)
    variants: tuple[ca.Function, ...] = field(default=(), repr=False)
    variant_note: str = ""
    variable: str = "position"  # the signal the residual is plotted against (see VARIABLES)
    """Alternative features with the same coefficients' meaning, for the hyper-parameters the
    term fixes (friction's reversal width, cogging's gap exponent): the spread of the physical
    parameters over them is reported as a systematic (model-form) uncertainty."""

    def __post_init__(self) -> None:
        if self.axis not in AXES:
            raise ValueError(f"Candidate {self.name}: axis must be one of {AXES}, got {self.axis!r}")
        if self.variable not in VARIABLES:
            raise ValueError(f"Candidate {self.name}: variable must be one of {VARIABLES}")
        k = self.features.size2_out(0)
        if self.features.size1_out(0) != 2 or k != len(self.coefficient_names):
            raise ValueError(f"Candidate {self.name}: features must be (2, {len(self.coefficient_names)})")

    @property
    def n_coefficients(self) -> int:
        return len(self.coefficient_names)

    def with_features(self, features: ca.Function) -> Candidate:
        """The same candidate with other features (one of its variants)."""
        return dataclasses.replace(self, features=features, variants=())

    def acceleration(self, coefficients) -> ca.Function:
        """(x, u, du) -> acc (2) with the coefficients fixed."""
        x, u, du = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("du", 2)
        acc = ca.mtimes(self.features(x, u, du), ca.DM(np.asarray(coefficients, dtype=float)))
        return ca.Function(f"{self.name}_acc", [x, u, du], [acc], ["x", "u", "du"], ["acc"])


# --- helpers for physical conversions ---------------------------------------------------------
def _linear(names_units_scales) -> Callable[[np.ndarray, np.ndarray], dict[str, Physical]]:
    """Each coefficient times a scale is a physical parameter."""

    def convert(p: np.ndarray, cov: np.ndarray) -> dict[str, Physical]:
        out = {}
        for k, (name, unit, scale) in enumerate(names_units_scales):
            out[name] = Physical(float(p[k] * scale), float(math.sqrt(max(cov[k, k], 0)) * abs(scale)), unit)
        return out

    return convert


def _amplitude_phase(unit: str, scale: float, extra: dict | None = None):
    """(a sin + b cos) -> amplitude sqrt(a^2 + b^2) * scale and phase atan2(b, a)."""

    def convert(p: np.ndarray, cov: np.ndarray) -> dict[str, Physical]:
        a, b = float(p[0]), float(p[1])
        amp = math.hypot(a, b)
        if amp > 0:
            g = np.array([a, b]) / amp
            s_amp = math.sqrt(max(g @ cov[:2, :2] @ g, 0))
            h = np.array([-b, a]) / amp**2
            s_ph = math.sqrt(max(h @ cov[:2, :2] @ h, 0))
        else:
            s_amp = s_ph = float("nan")
        out = {
            "amplitude": Physical(amp * scale, s_amp * abs(scale), unit),
            "phase": Physical(math.atan2(b, a), s_ph, "rad"),
        }
        out.update(extra or {})
        return out

    return convert


def _fn(name: str, build) -> ca.Function:
    x, u, du = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("du", 2)
    cols = build(x, u, du)
    return ca.Function(name, [x, u, du], [ca.horzcat(*cols)], ["x", "u", "du"], ["F"])


def _v(expr):
    return ca.vertcat(expr, 0)


def _h(expr):
    return ca.vertcat(0, expr)


# --- the library -----------------------------------------------------------------------------
def candidate_library(model: StageModel, *, smoothing_speed: float = 2e-3) -> list[Candidate]:
    """All candidates for a model whose constants were fitted to the log.

    ``smoothing_speed`` [m/s] replaces sign(v) by tanh(v / smoothing_speed) in the friction
    terms: the Savitzky-Golay velocity's noise is ~0.1 mm/s at 1 kHz, so 2 mm/s keeps the
    sign reliable while resolving velocity reversals.
    """
    p = model.params
    mv, mh, G = p.mass_vertical, p.mass_horizontal, p.gravity
    t1, tau = p.slot_pitch, p.pole_pitch
    c = model.constants
    vs = float(smoothing_speed)

    def shapes(x):
        return model.shape(x[0])

    out: list[Candidate] = []

    # friction of the guides --------------------------------------------------------------
    def friction(axis, i, m, width):
        put = _v if axis == "vertical" else _h
        return _fn(f"fric_{axis}", lambda x, u, du: [put(-ca.tanh(x[i] / width) / m), put(-x[i] / m)])

    for axis, vel_idx, mass in (("vertical", 1, mv), ("horizontal", 3, mh)):
        out.append(Candidate(
            f"guide_friction_{axis}",
            f"The {axis} linear guides resist motion with a force of constant size opposing the "
            "velocity (Coulomb) plus a part growing with speed (viscous).",
            axis, ("coulomb", "viscous"),
            friction(axis, vel_idx, mass, vs),
            _linear([("coulomb", "N", 1.0), ("viscous", "N s/m", 1.0)]),
            "residual steps with the sign of the velocity",
            variants=tuple(friction(axis, vel_idx, mass, w) for w in (vs / 4, vs * 2.5)),
            variant_note=f"reversal width {vs / 4 * 1e3:g}-{vs * 2.5 * 1e3:g} mm/s",
            variable="gap_rate" if axis == "vertical" else "position_rate",
        ))
    # constant forces ---------------------------------------------------------------------
    out.append(Candidate(
        "horizontal_guide_tilt",
        "The horizontal guides are not level, so gravity pulls the platform along them with a "
        "constant force.",
        "horizontal", ("acceleration",),
        _fn("tilt_h", lambda x, u, du: [_h(ca.SX(1))]),
        lambda q, cov: {
            "tilt": Physical(math.asin(max(-1, min(1, q[0] / G))), math.sqrt(max(cov[0, 0], 0)) / G, "rad"),
            "force": Physical(q[0] * mh, math.sqrt(max(cov[0, 0], 0)) * mh, "N"),
        },
        "constant residual on the horizontal axis",
    ))
    out.append(Candidate(
        "vertical_force_offset",
        "A constant vertical force the model lacks, such as an unmodelled payload, a cable's "
        "weight or a preload of the vertical guides.",
        "vertical", ("acceleration",),
        _fn("offset_v", lambda x, u, du: [_v(ca.SX(1))]),
        lambda q, cov: {"force": Physical(-q[0] * mv, math.sqrt(max(cov[0, 0], 0)) * mv, "N")},
        "constant residual on the vertical axis",
        variable="gap",
    ))
    # position-dependent forces -----------------------------------------------------------
    out.append(Candidate(
        "cable_carrier_force",
        "The cable carrier (or a spring-like connection) pushes the platform back towards a "
        "neutral position with a force growing along the track.",
        "horizontal", ("stiffness_per_mass", "offset"),
        _fn("cable", lambda x, u, du: [_h(-x[2]), _h(ca.SX(1))]),
        lambda q, cov: {
            "stiffness": Physical(q[0] * mh, math.sqrt(max(cov[0, 0], 0)) * mh, "N/m"),
            "neutral_position": _ratio(q[1], q[0], cov[1, 1], cov[0, 0], cov[0, 1], "m"),
        },
        "residual linear in the horizontal position",
    ))
    out.append(Candidate(
        "gap_dependent_force",
        "The gap-dependence of the magnets' attraction differs from the magnetic-charge model "
        "(field shape, magnet height or saturation), leaving a smooth force that varies with the gap.",
        "vertical", ("slope", "curvature"),
        _fn("gapforce", lambda x, u, du: [_v((x[0] - 0.02) / 0.005), _v(((x[0] - 0.02) / 0.005) ** 2)]),
        _linear([("slope_force", "N per 5 mm", mv), ("curvature_force", "N per (5 mm)^2", mv)]),
        "residual varying smoothly with the gap",
        variable="gap",
    ))
    # position-periodic forces: cogging / detent / waviness at the physical periods ---------
    periods = {"slot_pitch": t1, "twice_slot_pitch": 2 * t1, "pole_pitch": tau, "twice_pole_pitch": 2 * tau}
    def periodic(axis, lam, mass, exponent):
        put = _v if axis == "vertical" else _h
        sign = -1.0 if axis == "vertical" else 1.0  # a force towards the stator lowers x2'
        return _fn(f"cog_{axis}", lambda x, u, du: [
            put(sign * ca.sin(2 * math.pi * x[2] / lam) * (REFERENCE_GAP / x[0]) ** exponent / mass),
            put(sign * ca.cos(2 * math.pi * x[2] / lam) * (REFERENCE_GAP / x[0]) ** exponent / mass),
        ])

    for pname, lam in periods.items():
        for axis, mass in (("vertical", mv), ("horizontal", mh)):
            magnetic = "cogging" if axis == "vertical" else "detent"
            out.append(Candidate(
                f"{magnetic}_{pname}",
                (f"The stator teeth and the magnet edges attract each other, adding a "
                 f"{'normal' if axis == 'vertical' else 'longitudinal'} force periodic in the "
                 f"position over {lam * 1e3:.2f} mm that grows as the gap closes"
                 + (" (000 eq. (9))." if (axis == "vertical" and pname == "twice_slot_pitch") else ".")),
                axis, ("sin", "cos"),
                periodic(axis, lam, mass, COGGING_EXPONENT),
                _amplitude_phase("N", 1.0, {"period": Physical(lam, 0.0, "m"),
                                            "at_gap": Physical(REFERENCE_GAP, 0.0, "m")}),
                f"residual periodic in x3 with period {lam * 1e3:.1f} mm, larger at small gaps",
                variants=tuple(periodic(axis, lam, mass, e)
                               for e in (COGGING_EXPONENT - 1, COGGING_EXPONENT + 1)),
                variant_note=f"gap exponent {COGGING_EXPONENT - 1:g}-{COGGING_EXPONENT + 1:g}",
            ))
    # current-dependent effects -------------------------------------------------------------
    for pname, lam in (("slot_pitch", t1), ("pole_pitch", tau)):
        out.append(Candidate(
            f"thrust_ripple_{pname}",
            f"The propulsion force per ampere varies along the track with period {lam * 1e3:.2f} mm "
            "(slotting and winding harmonics), so the thrust ripples in proportion to i_q.",
            "horizontal", ("sin", "cos"),
            _fn(f"ripple_{pname}", lambda x, u, du, lam=lam: [
                _h(-c.C1 * shapes(x)[0] * u[0] * ca.sin(2 * math.pi * x[2] / lam)),
                _h(-c.C1 * shapes(x)[0] * u[0] * ca.cos(2 * math.pi * x[2] / lam)),
            ]),
            _amplitude_phase("fraction of thrust", 1.0, {"period": Physical(lam, 0.0, "m")}),
            f"residual proportional to i_q and periodic in x3 ({lam * 1e3:.1f} mm)",
        ))
    out.append(Candidate(
        "commutation_offset",
        "The amplifiers' electrical angle is offset from the magnet poles, so part of i_d "
        "produces thrust and part of i_q normal force.",
        "both", ("angle",),
        # small angle: i_q' = i_q + d i_d, i_d' = i_d - d i_q (first order in d)
        _fn("commutation", lambda x, u, du: [ca.vertcat(
            c.C3 * shapes(x)[2] * u[0],              # x2' = ... - L3 i_d' -> +L3 d i_q
            -c.C1 * shapes(x)[0] * u[1],             # x4' = -L1 i_q' -> -L1 d i_d
        )]),
        _linear([("angle", "rad", 1.0)]),
        "horizontal residual proportional to i_d (and vertical to i_q)",
        variable="current",
    ))
    out.append(Candidate(
        "current_lag",
        "The current amplifiers (or the real-time loop) deliver the commanded currents late, "
        "so the force lags the command by a small time constant.",
        "both", ("time_constant",),
        _fn("lag", lambda x, u, du: [ca.vertcat(
            # acc(u - T du) - acc(u) = -(d acc / d u) du T (first order)
            -(-c.C3 * shapes(x)[2] - 2 * c.C4 * shapes(x)[3] * u[1]) * du[1]
            - (-2 * c.C4 * shapes(x)[3] * u[0]) * du[0],
            c.C1 * shapes(x)[0] * du[0],
        )]),
        _linear([("time_constant", "s", 1.0)]),
        "residual correlated with the rate of the commanded currents",
        variable="current_rate",
    ))
    out.append(Candidate(
        "guide_gap_tilt",
        "The horizontal guides are not parallel to the stator, so the magnetic gap the encoder "
        "does not see changes along the track in proportion to the position.",
        "both", ("angle",),
        _fn("gaptilt", lambda x, u, du: [_dacc_dgap(model, x, u) * x[2]]),
        _linear([("angle", "rad", 1.0)]),
        "vertical residual growing along the track with the model's gap sensitivity",
    ))
    out.append(Candidate(
        "gap_sensor_offset",
        "The gap encoder's zero is offset from the true magnetic gap, so every gap-dependent "
        "force is evaluated at the wrong gap.",
        "both", ("offset",),
        _fn("gapoffset", lambda x, u, du: [_dacc_dgap(model, x, u)]),
        _linear([("offset", "m", 1.0)]),
        "vertical residual following the model's gap sensitivity",
        variable="gap",
    ))
    return out


def _dacc_dgap(model: StageModel, x, u):
    """d(x2', x4')/d x1 of the model with its constants, at (x, u)."""
    xs = ca.SX.sym("xs", 4)
    acc = model.f(xs, u)[[1, 3]]
    return ca.substitute(ca.jacobian(acc, xs[0]), xs, x)


def _ratio(num, den, v_num, v_den, c_nd, unit) -> Physical:
    """num / den with the delta method."""
    if den == 0:
        return Physical(float("nan"), float("nan"), unit)
    r = num / den  # acc = -k x3 + b vanishes at x3 = b / k
    g = np.array([1 / den, -num / den**2])
    cov = np.array([[v_num, c_nd], [c_nd, v_den]])
    return Physical(float(r), float(math.sqrt(max(g @ cov @ g, 0))), unit)


def waviness_candidate(model: StageModel, axis: str, period: float) -> Candidate:
    """Guide waviness (or any mechanical force periodic in x3) at a period found in the
    residual's spatial spectrum, for ``axis`` "vertical" or "horizontal"."""
    p = model.params
    mass = p.mass_vertical if axis == "vertical" else p.mass_horizontal
    put = _v if axis == "vertical" else _h
    sign = -1.0 if axis == "vertical" else 1.0
    mm = period * 1e3
    return Candidate(
        f"guide_waviness_{axis}_{mm:.0f}mm",
        (f"The {'horizontal guides are' if axis == 'vertical' else 'track is'} not straight: a "
         f"force periodic in the position over {mm:.1f} mm (found in the residual's spatial "
         "spectrum, not a motor period) that does not depend on the gap."),
        axis, ("sin", "cos"),
        _fn(f"wav_{axis}_{mm:.0f}", lambda x, u, du: [
            put(sign * ca.sin(2 * math.pi * x[2] / period) / mass),
            put(sign * ca.cos(2 * math.pi * x[2] / period) / mass),
        ]),
        _amplitude_phase("N", 1.0, {"period": Physical(period, 0.0, "m")}),
        f"residual periodic in x3 with period {mm:.1f} mm at every gap",
    )
