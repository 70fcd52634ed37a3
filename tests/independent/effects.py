"""Effects of a real linear-guide PMLSM stage that the papers' model lacks.

Each effect is a frozen dataclass whose fields are its physical parameters in SI units (the
unit is in each field's metadata and in the truth file). ``small()`` and ``large()`` give two
sizes that are both typical of real stages (the loop stays stable and levitated with either).
The equations below are what the C core (``core.c``, ``plant_rhs``) computes.

Sign conventions of the plant
-----------------------------
``x1`` is the gap as the vertical encoder reads it (positive downwards, gravity opens it),
``x3`` the horizontal position. ``F_x`` [N] is the horizontal force on the horizontally moving
mass ``M_h`` (positive along +x3); ``F_n`` [N] is the normal force *attracting* the mover to the
stator (it closes the gap). The plant is

.. math::

    M_v \\ddot x_1 = M_v G - F_n - F_{f,v}(\\dot x_1),\\qquad M_h \\ddot x_3 = F_x - F_{f,h}(\\dot x_3)

with, before any effect, ``F_x = -M_h L_1(g) i_q`` and
``F_n = M_v [L_2(g) + L_3(g) i_d + L_4(g)(i_d^2 + i_q^2)]`` at the magnetic gap ``g = x1``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

from .physics import GEOMETRY, G

T1 = GEOMETRY.t1
TAU = GEOMETRY.tau
PHASE_SHIFTS = (0.0, -2 * math.pi / 3, 2 * math.pi / 3)
"""The phases' shifts s_k in 002's transform (a, b, c)."""


def phase_harmonic(values: tuple[float, float, float], harmonic: int) -> tuple[float, float]:
    """(2/3) sum_k v_k (cos, sin)(h s_k): what per-phase values (a, b, c) put into the dq frame at
    ``harmonic`` h times the electrical angle (h = 1: a sensor offset's missing current fixed to
    the stator; h = 2: a gain mismatch's mixing of i_d and i_q)."""
    pairs = tuple(zip(PHASE_SHIFTS, values, strict=True))
    return (
        2 / 3 * sum(math.cos(harmonic * s) * v for s, v in pairs),
        2 / 3 * sum(math.sin(harmonic * s) * v for s, v in pairs),
    )


def _p(default: float, unit: str, doc: str) -> Any:
    return field(default=default, metadata={"unit": unit, "doc": doc})


@dataclass(frozen=True)
class Effect:
    """Base class: a named physical effect with SI parameters.

    Subclasses set ``kind`` and ``axis`` and implement :meth:`apply` (write their parameters
    into the C core's ``Params``), :meth:`description` and :meth:`equation`.
    """

    kind: ClassVar[str] = ""
    axis: ClassVar[str] = ""

    def apply(self, p: Any, ctx: dict[str, float]) -> None:  # pragma: no cover - abstract
        """Write the effect into the core's parameter struct ``p``. ``ctx`` holds rig values
        (``plant_step`` [s], ``M_h``, ``M_v`` [kg])."""
        raise NotImplementedError

    def description(self) -> str:  # pragma: no cover - abstract
        """One sentence in plain words."""
        raise NotImplementedError

    def equation(self) -> str:  # pragma: no cover - abstract
        """The force law as the core computes it (plain text)."""
        raise NotImplementedError

    def derived(self, ctx: dict[str, float]) -> dict[str, float]:
        """Sizes that follow from the parameters (e.g. the force at the 19.5 mm reference gap)."""
        return {}

    def parameters(self) -> dict[str, float]:
        """The physical parameters by name (SI units, see :meth:`units`)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if "unit" in f.metadata}

    def units(self) -> dict[str, str]:
        """Unit of every parameter."""
        return {f.name: f.metadata["unit"] for f in dataclasses.fields(self) if "unit" in f.metadata}

    def axis_name(self) -> str:
        """'horizontal', 'vertical' or 'both'."""
        return self.axis

    def key(self) -> str:
        """Unique key of the effect within one scenario (kind, plus the axis when it has one)."""
        return self.kind

    def truth(self, ctx: dict[str, float]) -> dict[str, Any]:
        """Everything the truth file says about this effect."""
        return {
            "kind": self.kind,
            "axis": self.axis_name(),
            "description": self.description(),
            "equation": self.equation(),
            "parameters": self.parameters(),
            "units": self.units(),
            "parameter_notes": {
                f.name: f.metadata["doc"] for f in dataclasses.fields(self) if "unit" in f.metadata
            },
            "derived": self.derived(ctx),
        }


# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class GuideFriction(Effect):
    """Friction of the recirculating-ball linear guides on one axis, LuGre model.

    The LuGre model (Canudas de Wit et al. 1995) gives Coulomb and viscous friction at speed,
    the Stribeck drop from static to Coulomb friction at low speed, and pre-sliding (a stiff,
    damped elastic displacement of a few micrometres before gross sliding) near zero speed, so
    that the force is a continuous function of time through velocity reversals:

    .. math::

        \\dot z = v - \\sigma_0 |v| z / g(v),\\quad g(v) = F_C + (F_S - F_C) e^{-(v/v_s)^2}

        F_f = \\sigma_0 z + \\sigma_1 e^{-(v/v_s)^2} \\dot z + \\sigma_2 v

    ``v`` is the axis velocity (x4 horizontal, x2 vertical) and ``F_f`` opposes it. The
    bristle damping is faded out with speed (Olsson's variant) so the model stays passive. At
    steady sliding ``F_f = sign(v) g(v) + sigma_2 v``: Coulomb ``F_C`` plus viscous ``sigma_2 v``.
    The pre-sliding distance is about ``F_C / sigma_0``.
    """

    axis_: str = field(
        default="horizontal", metadata={"doc": "'horizontal' (x3 guides) or 'vertical' (x1 guides)"}
    )
    coulomb_force: float = _p(0.3, "N", "Coulomb (sliding) friction force F_C")
    static_force: float = _p(0.4, "N", "static (breakaway) friction force F_S >= F_C")
    stribeck_velocity: float = _p(2e-3, "m/s", "Stribeck velocity v_s")
    viscous_coefficient: float = _p(2.0, "N s/m", "viscous coefficient sigma_2")
    bristle_stiffness: float = _p(2e5, "N/m", "pre-sliding (bristle) stiffness sigma_0")
    bristle_damping: float = _p(
        340.0, "N s/m", "bristle damping sigma_1 (about 0.3 of critical with the axis mass)"
    )
    level_slope: float = _p(
        0.0,
        "1/m",
        "horizontal guides only: F_C and F_S times 1 + level_slope x3 (a rail whose preload or "
        "lubrication changes along the track)",
    )
    direction_asymmetry: float = _p(
        0.0, "1", "F_C and F_S times 1 + a moving forward (v > 0), 1 - a backward (seals, a rail's twist)"
    )
    warming_change: float = _p(
        0.0,
        "1",
        "F_C, F_S and sigma_2 times 1 + c (1 - exp(-t / T)): the share the friction changes by as the "
        "guides' lubricant warms over the run (< 0: it thins)",
    )
    warming_time_constant: float = _p(60.0, "s", "time constant T of the guides' warming")

    kind: ClassVar[str] = "guide_friction"

    def __post_init__(self) -> None:
        if self.axis_ not in ("horizontal", "vertical"):
            raise ValueError(f"GuideFriction.axis_ must be 'horizontal' or 'vertical', got {self.axis_!r}")
        if not (0 < self.coulomb_force <= self.static_force):
            raise ValueError("GuideFriction: need 0 < coulomb_force <= static_force [N]")
        if self.level_slope and self.axis_ != "horizontal":
            raise ValueError("GuideFriction.level_slope is along the track: horizontal guides only")
        if not (
            abs(self.direction_asymmetry) < 1 and abs(self.level_slope) * 0.1 < 1 and self.warming_change > -1
        ):
            raise ValueError(
                "GuideFriction: the friction must stay positive (|a| < 1, |slope| x3 < 1, change > -1)"
            )
        if not self.warming_time_constant > 0:
            raise ValueError("GuideFriction.warming_time_constant must be > 0 [s]")

    def axis_name(self) -> str:
        return self.axis_

    def key(self) -> str:
        return f"{self.kind}:{self.axis_}"

    @classmethod
    def small(cls, axis: str = "horizontal") -> GuideFriction:
        """Well-adjusted guides: 0.3 N / 2 N s/m horizontally, 0.6 N / 4 N s/m vertically."""
        if axis == "horizontal":
            return cls(axis_=axis, coulomb_force=0.3, static_force=0.4, viscous_coefficient=2.0)
        return cls(axis_=axis, coulomb_force=0.6, static_force=0.75, viscous_coefficient=4.0,
                   bristle_stiffness=3e5, bristle_damping=690.0)  # fmt: skip

    @classmethod
    def large(cls, axis: str = "horizontal") -> GuideFriction:
        """Sealed, preloaded guides: 1.0 N / 5 N s/m horizontally, 2.0 N / 10 N s/m vertically."""
        if axis == "horizontal":
            return cls(axis_=axis, coulomb_force=1.0, static_force=1.3, viscous_coefficient=5.0)
        return cls(axis_=axis, coulomb_force=2.0, static_force=2.5, viscous_coefficient=10.0,
                   bristle_stiffness=3e5, bristle_damping=690.0)  # fmt: skip

    def apply(self, p: Any, ctx: dict[str, float]) -> None:
        pre = "fh" if self.axis_ == "horizontal" else "fv"
        setattr(p, f"{pre}_on", 1)
        values = {
            "Fc": self.coulomb_force,
            "Fs": self.static_force,
            "vs": self.stribeck_velocity,
            "s0": self.bristle_stiffness,
            "s1": self.bristle_damping,
            "s2": self.viscous_coefficient,
        }
        if self.axis_ == "horizontal":
            values["slope"] = self.level_slope
        values["asym"] = self.direction_asymmetry
        values["warm"] = self.warming_change
        values["warm_tau"] = self.warming_time_constant
        for name, val in values.items():
            setattr(p, f"{pre}_{name}", val)

    def description(self) -> str:
        what = (
            "horizontal guides (opposing x4)"
            if self.axis_ == "horizontal"
            else "vertical guides (opposing x2)"
        )
        return (
            f"Friction of the {what}: Coulomb {self.coulomb_force:g} N, breakaway {self.static_force:g} N, "
            f"viscous {self.viscous_coefficient:g} N s/m, with pre-sliding (LuGre model)"
            + self._shape_words()
            + "."
        )

    def _shape_words(self) -> str:
        words = []
        if self.level_slope:
            words.append(f"{self.level_slope * 4:+.0%} of its level per 40 mm along the track")
        if self.direction_asymmetry:
            words.append(
                f"{self.direction_asymmetry:+.0%} moving forward, {-self.direction_asymmetry:+.0%} backward"
            )
        if self.warming_change:
            words.append(
                f"{self.warming_change:+.0%} of its level as the guides warm (time constant "
                f"{self.warming_time_constant:g} s)"
            )
        return "; " + ", ".join(words) if words else ""

    def equation(self) -> str:
        return (
            "dz/dt = v - s0 |v| z / g(v), g(v) = Fc + (Fs - Fc) exp(-(v/vs)^2); "
            "F_f = s0 z + s1 exp(-(v/vs)^2) dz/dt + s2 v, opposing v; Fc, Fs times "
            "(1 + level_slope x3) (1 + direction_asymmetry sign(v)); Fc, Fs, s2 times "
            "(1 + warming_change (1 - exp(-t / warming_time_constant)))"
        )

    def derived(self, ctx: dict[str, float]) -> dict[str, float]:
        m = ctx["M_h"] if self.axis_ == "horizontal" else ctx["M_v"]
        return {
            "presliding_distance_m": self.coulomb_force / self.bristle_stiffness,
            "sliding_force_at_0.05_m_per_s_N": self.coulomb_force + self.viscous_coefficient * 0.05,
            "coulomb_acceleration_m_per_s2": self.coulomb_force / m,
            "bristle_damping_ratio": self.bristle_damping / (2.0 * math.sqrt(self.bristle_stiffness * m)),
        }


# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Cogging(Effect):
    peak_force: float = _p(1.0, "N", "peak of the fundamental at the reference gap")
    reference_gap: float = _p(0.015, "m", "gap at which peak_force is stated")
    period: float = _p(T1, "m", "spatial period of the fundamental (the slot pitch t1)")
    phase: float = _p(0.0, "rad", "phase of the fundamental at x3 = 0")
    harmonic2_ratio: float = _p(
        0.3, "-", "peak of the second harmonic (period/2) relative to the fundamental, at the reference gap"
    )
    harmonic2_phase: float = _p(0.7, "rad", "phase of the second harmonic at x3 = 0")

    def _decays(self) -> tuple[float, float]:
        return self.period / (2 * math.pi), self.period / (4 * math.pi)

    def _fill(self, p: Any, pre: str) -> None:
        setattr(p, f"{pre}_on", 1)
        d1, d2 = self._decays()
        arr = getattr(p, f"{pre}_amp")
        arr[0], arr[1], arr[2] = self.peak_force, self.peak_force * self.harmonic2_ratio, 0.0
        per = getattr(p, f"{pre}_period")
        per[0], per[1], per[2] = self.period, self.period / 2, 1.0
        ph = getattr(p, f"{pre}_phase")
        ph[0], ph[1], ph[2] = self.phase, self.harmonic2_phase, 0.0
        dec = getattr(p, f"{pre}_decay")
        dec[0], dec[1], dec[2] = d1, d2, 1.0
        setattr(p, f"{pre}_gref", self.reference_gap)

    def _eq(self, name: str) -> str:
        return (
            f"{name} = sum_k A_k exp(-(g - g_ref) / l_k) sin(2 pi x3 / P_k + phi_k), k = 1, 2: "
            "P_1 = period, P_2 = period/2, A_1 = peak_force, A_2 = harmonic2_ratio A_1, "
            "l_k = P_k / (2 pi) (a spatial harmonic of wavelength P decays as exp(-2 pi g / P) "
            "across the gap); "
            "g the magnetic gap"
        )

    def _peak_at(self, gap: float) -> float:
        d1, d2 = self._decays()
        g0 = self.reference_gap
        return self.peak_force * (
            math.exp(-(gap - g0) / d1) + self.harmonic2_ratio * math.exp(-(gap - g0) / d2)
        )

    def derived(self, ctx: dict[str, float]) -> dict[str, float]:
        d1, d2 = self._decays()
        return {
            "decay_length_fundamental_m": d1,
            "decay_length_harmonic2_m": d2,
            "bound_on_force_at_14.5_mm_N": self._peak_at(0.0145),
            "bound_on_force_at_19.5_mm_N": self._peak_at(0.0195),
            "bound_on_force_at_24.5_mm_N": self._peak_at(0.0245),
        }


@dataclass(frozen=True)
class NormalCogging(_Cogging):
    """Normal cogging force: the magnets' attraction to the slotted stator varies with position.

    The permeance seen by the magnets' edges changes as they pass the slot openings, so the
    normal attraction has a part periodic in x3 over the slot pitch t1 (000 Sec. V-C, eq. (9):
    peak growing as the gap closes, above 1 N below 15 mm). Added to the attraction ``F_n``:

    .. math::

        F_{n,cog} = \\sum_{k=1,2} A_k e^{-(g - g_{ref}) / \\ell_k} \\sin(2\\pi x_3 / P_k + \\varphi_k)

    with ``P_1 = t1``, ``P_2 = t1/2`` and ``l_k = P_k / (2 pi)``. It averages to zero over a
    slot pitch. (000 prints ``sin(pi x3 / t1)``, whose period is 2 t1; the slotting is
    t1-periodic, and that is what is used here.)
    """

    kind: ClassVar[str] = "normal_cogging"
    axis: ClassVar[str] = "vertical"

    @classmethod
    def small(cls) -> NormalCogging:
        """1.0 N at 15 mm (0.23 N at 19.5 mm)."""
        return cls(peak_force=1.0)

    @classmethod
    def large(cls) -> NormalCogging:
        """2.5 N at 15 mm (0.57 N at 19.5 mm, 2.9 N at 14.5 mm)."""
        return cls(peak_force=2.5)

    def apply(self, p: Any, ctx: dict[str, float]) -> None:
        self._fill(p, "cn")

    def description(self) -> str:
        return (
            f"Normal cogging: the magnets' attraction to the slotted stator varies along x3 with the slot "
            f"pitch ({self.period * 1e3:.2f} mm) and its second harmonic, peak {self.peak_force:g} N at a "
            f"{self.reference_gap * 1e3:g} mm gap, growing as the gap closes."
        )

    def equation(self) -> str:
        return self._eq("F_n,cog (added to the attraction, closes the gap when positive)")


@dataclass(frozen=True)
class DetentForce(_Cogging):
    """Longitudinal cogging (detent) force along the travel, periodic over the slot pitch.

    The magnets' edges seek the position of least reluctance over the stator teeth, giving a
    thrust-independent horizontal force with period t1 and harmonics, larger at small gaps:

    .. math::

        F_{x,cog} = \\sum_{k=1,2} A_k e^{-(g - g_{ref}) / \\ell_k} \\sin(2\\pi x_3 / P_k + \\varphi_k)

    with ``P_1 = t1``, ``P_2 = t1/2``, ``l_k = P_k/(2 pi)``; it averages to zero over a slot pitch.
    """

    kind: ClassVar[str] = "detent_force"
    axis: ClassVar[str] = "horizontal"
    harmonic2_ratio: float = _p(
        0.4, "-", "peak of the second harmonic (period/2) relative to the fundamental, at the reference gap"
    )
    harmonic2_phase: float = _p(1.9, "rad", "phase of the second harmonic at x3 = 0")

    @classmethod
    def small(cls) -> DetentForce:
        """0.8 N at 15 mm (0.18 N at 19.5 mm): about 1 % of the 9 A thrust."""
        return cls(peak_force=0.8)

    @classmethod
    def large(cls) -> DetentForce:
        """2.0 N at 15 mm (0.45 N at 19.5 mm)."""
        return cls(peak_force=2.0)

    def apply(self, p: Any, ctx: dict[str, float]) -> None:
        self._fill(p, "cl")

    def description(self) -> str:
        return (
            f"Detent (longitudinal cogging) force along x3 with the slot pitch ({self.period * 1e3:.2f} mm) "
            f"and its second harmonic, peak {self.peak_force:g} N at a {self.reference_gap * 1e3:g} mm gap, "
            "independent of the currents and growing as the gap closes."
        )

    def equation(self) -> str:
        return self._eq("F_x,cog (along +x3)")


# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class EndEffect(Effect):
    """End effects: thrust and attraction fall smoothly as the mover nears the stator's ends.

    The stator is 342.9 mm long (18 slots) and the mover's back iron 200 mm: at x3 = +-50 mm the
    mover's end is about 21 mm from the stator's end, where the field fringes. The loss grows
    exponentially towards each end:

    .. math::

        \\ell(x_3) = e^{(x_3 - x_+)/w} + e^{(x_- - x_3)/w},\\quad
        \\eta_T = 1 - f_T \\ell,\\quad \\eta_A = 1 - f_A \\ell

    ``eta_T`` multiplies the current-produced forces (the thrust ``L1 i_q`` and the normal terms
    ``L3 i_d``, ``L4 (i_d^2 + i_q^2)``, which need winding under the mover), ``eta_A`` the
    magnets' attraction to the stator iron ``L2``. At ``x3 = x+`` (or ``x-``) the loss is
    ``f_T`` (``f_A``); it falls by 1/e every ``w`` inwards.

    ``profile`` gives the loss other shapes towards each end, for rigs whose fringing is not an
    exponential: ``"gaussian"``, :math:`e^{-(u/w)^2}` at a distance u inside an end (flat at the
    end, then falling faster), and ``"cosine"``, a raised cosine :math:`(1 + \\cos(\\pi u / 3w))/2`
    that is exactly zero further in than 3 w. Both are 1 at the end and beyond (so at most 2 with
    both ends counted, as the exponential is clipped).
    """

    PROFILES: ClassVar[tuple[str, ...]] = ("exponential", "gaussian", "cosine")

    thrust_loss: float = _p(
        0.05, "-", "fraction of thrust (and current-produced normal force) lost at the end positions"
    )
    attraction_loss: float = _p(0.03, "-", "fraction of the magnets' attraction lost at the end positions")
    end_position_plus: float = _p(0.05, "m", "x3 at which the losses are stated, positive end")
    end_position_minus: float = _p(-0.05, "m", "x3 at which the losses are stated, negative end")
    width: float = _p(0.015, "m", "length over which the loss falls by 1/e inwards")
    profile: str = "exponential"

    kind: ClassVar[str] = "end_effect"
    axis: ClassVar[str] = "both"

    @classmethod
    def small(cls) -> EndEffect:
        """5 % thrust, 3 % attraction lost at +-50 mm, width 15 mm (half that at +-40 mm)."""
        return cls()

    @classmethod
    def large(cls) -> EndEffect:
        """12 % thrust, 8 % attraction lost at +-50 mm, width 20 mm."""
        return cls(thrust_loss=0.12, attraction_loss=0.08, width=0.020)

    def __post_init__(self) -> None:
        if self.profile not in self.PROFILES:
            raise ValueError(f"EndEffect.profile: {self.profile!r} is not one of {self.PROFILES}")

    def parameters(self) -> dict[str, Any]:
        """The physical parameters, with ``profile`` only when it is not the exponential (the
        truth files of the sets' logs stay as they were)."""
        out: dict[str, Any] = super().parameters()
        if self.profile != "exponential":
            out["profile"] = self.profile
        return out

    def loss(self, x3: float) -> float:
        """The loss profile l(x3) at position x3 [m], both ends counted, as the core computes it."""
        if self.profile == "exponential":
            out = math.exp((x3 - self.end_position_plus) / self.width) + math.exp(
                (self.end_position_minus - x3) / self.width
            )
        else:
            out = _end_profile(self.profile, self.end_position_plus - x3, self.width) + _end_profile(
                self.profile, x3 - self.end_position_minus, self.width
            )
        return min(out, 2.0)

    def apply(self, p: Any, ctx: dict[str, float]) -> None:
        p.ee_on = 1
        p.ee_fT, p.ee_fA = self.thrust_loss, self.attraction_loss
        p.ee_xp, p.ee_xm, p.ee_w = self.end_position_plus, self.end_position_minus, self.width
        p.ee_profile = self.PROFILES.index(self.profile)

    def description(self) -> str:
        return (
            f"End effects: thrust falls by {self.thrust_loss:.0%} and the magnets' attraction by "
            f"{self.attraction_loss:.0%} at x3 = {self.end_position_minus * 1e3:g} / "
            f"+{self.end_position_plus * 1e3:g} mm, decaying inwards over {self.width * 1e3:g} mm"
            + ("." if self.profile == "exponential" else f" ({self.profile} profile).")
        )

    def equation(self) -> str:
        ends = {
            "exponential": "l(x3) = exp((x3 - x+)/w) + exp((x- - x3)/w)",
            "gaussian": "l(x3) = p(x+ - x3) + p(x3 - x-), p(u) = exp(-(u/w)^2) for u > 0, else 1",
            "cosine": "l(x3) = p(x+ - x3) + p(x3 - x-), p(u) = (1 + cos(pi u / 3w))/2 for 0 < u < 3w, "
            "1 for u <= 0, 0 beyond 3w",
        }[self.profile]
        return (
            f"{ends}, at most 2; thrust, L3 and L4 terms times (1 - f_T l); L2 attraction times (1 - f_A l)"
        )

    def derived(self, ctx: dict[str, float]) -> dict[str, float]:
        loss = self.loss
        return {
            "thrust_loss_at_+40_mm": self.thrust_loss * loss(0.04),
            "thrust_loss_at_-40_mm": self.thrust_loss * loss(-0.04),
            "attraction_loss_at_+40_mm": self.attraction_loss * loss(0.04),
            "thrust_loss_at_0_mm": self.thrust_loss * loss(0.0),
        }


def _end_profile(profile: str, u: float, w: float) -> float:
    """One end's loss at distance u [m] inside it for the non-exponential profiles (core.c's
    ``end_profile``)."""
    if u <= 0.0:
        return 1.0
    if profile == "gaussian":
        return math.exp(-((u / w) ** 2))
    return 0.0 if u >= 3.0 * w else 0.5 * (1.0 + math.cos(math.pi * u / (3.0 * w)))


# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class GuideMisalignment(Effect):
    """The horizontal guides are not parallel to the stator (plus optional waviness).

    The vertical encoder measures the base that carries the horizontal guides; the mover rides
    on those guides, so the magnetic gap differs from the reading along the travel:

    .. math::

        g = x_1 + \\Delta(x_3),

        \\Delta(x_3) = \\alpha x_3 + a_w [\\sin(2\\pi x_3/\\lambda_w + \\varphi_w) - \\sin\\varphi_w]

    (the encoder is zeroed at x3 = 0). All magnetic forces act at ``g``. Along the tilted guide
    the normal force and the weight of ``M_h`` have a component
    ``F_x = Delta'(x3) (M_h G - F_n)`` (``F_n`` the attraction). The inertial coupling
    ``M_h Delta''`` is of relative size alpha ~ 1e-3 and left out.
    """

    slope: float = _p(
        1.5e-3, "rad", "angle between the horizontal guides and the stator face (gap grows with x3 when > 0)"
    )
    waviness_amplitude: float = _p(0.0, "m", "amplitude of the guide's waviness")
    waviness_wavelength: float = _p(0.06, "m", "wavelength of the waviness (mounting-bolt pitch)")
    waviness_phase: float = _p(0.0, "rad", "phase of the waviness at x3 = 0")

    kind: ClassVar[str] = "guide_misalignment"
    axis: ClassVar[str] = "both"

    @classmethod
    def small(cls) -> GuideMisalignment:
        """1.5 mrad: the gap is 60 um off at +-40 mm."""
        return cls()

    @classmethod
    def large(cls) -> GuideMisalignment:
        """4 mrad (160 um at +-40 mm) plus 8 um waviness at 60 mm wavelength."""
        return cls(slope=4e-3, waviness_amplitude=8e-6, waviness_phase=0.5)

    def apply(self, p: Any, ctx: dict[str, float]) -> None:
        p.mis_on = 1
        p.mis_slope, p.mis_amp = self.slope, self.waviness_amplitude
        p.mis_len, p.mis_phase = self.waviness_wavelength, self.waviness_phase

    def description(self) -> str:
        s = (
            f"Horizontal guides tilted by {self.slope * 1e3:g} mrad against the stator: the true magnetic "
            f"gap is the encoder reading plus {self.slope * 0.04 * 1e6:.0f} um at x3 = +40 mm"
        )
        if self.waviness_amplitude:
            s += (
                f", plus {self.waviness_amplitude * 1e6:g} um waviness of wavelength "
                f"{self.waviness_wavelength * 1e3:g} mm"
            )
        return s + "."

    def equation(self) -> str:
        return (
            "g = x1 + alpha x3 + a_w (sin(2 pi x3/lambda_w + phi_w) - sin(phi_w)); forces at g; "
            "F_x += dDelta/dx3 (M_h G - F_n)"
        )

    def derived(self, ctx: dict[str, float]) -> dict[str, float]:
        fn = ctx["M_v"] * G
        return {
            "gap_offset_at_+40_mm_m": self.slope * 0.04,
            "horizontal_force_at_rest_N": self.slope * (ctx["M_h"] * G - fn),
        }


# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CableCarrier(Effect):
    """Cable carrier (drag chain) of the encoder read-head cable pulling on the horizontal axis.

    .. math::

        F_x = -k_c (x_3 - x_c) + F_0
    """

    stiffness: float = _p(4.0, "N/m", "stiffness about the neutral position")
    neutral_position: float = _p(0.02, "m", "x3 where the spring part vanishes")
    constant_force: float = _p(0.0, "N", "constant part along +x3")

    kind: ClassVar[str] = "cable_carrier"
    axis: ClassVar[str] = "horizontal"

    @classmethod
    def small(cls) -> CableCarrier:
        """4 N/m about +20 mm: 0.24 N at -40 mm."""
        return cls()

    @classmethod
    def large(cls) -> CableCarrier:
        """12 N/m about -30 mm plus 0.1 N: +0.22 N at -40 mm, -0.74 N at +40 mm."""
        return cls(stiffness=12.0, neutral_position=-0.03, constant_force=0.1)

    def apply(self, p: Any, ctx: dict[str, float]) -> None:
        p.cab_on = 1
        p.cab_k, p.cab_x0, p.cab_F0 = self.stiffness, self.neutral_position, self.constant_force

    def description(self) -> str:
        return (
            f"Cable carrier on the horizontal axis: a spring of {self.stiffness:g} N/m about "
            f"x3 = {self.neutral_position * 1e3:g} mm plus {self.constant_force:g} N."
        )

    def equation(self) -> str:
        return "F_x += -k_c (x3 - x_c) + F_0"

    def derived(self, ctx: dict[str, float]) -> dict[str, float]:
        f = lambda x: -self.stiffness * (x - self.neutral_position) + self.constant_force  # noqa: E731
        return {"force_at_-40_mm_N": f(-0.04), "force_at_0_mm_N": f(0.0), "force_at_+40_mm_N": f(0.04)}


# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ThrustRipple(Effect):
    """Thrust ripple: the force constant varies along the track.

    The 5th and 7th harmonics of the magnets' field (back-EMF) produce a 6th-harmonic ripple of
    the electrical period 2 tau, i.e. period tau/3 (= t1 here); an offset or gain mismatch of the
    phase currents produces a 2nd harmonic, period tau:

    .. math::

        F_x = -M_h L_1(g) i_q
              [1 + r_1 \\cos(2\\pi x_3/P_1 + \\varphi_1) + r_2 \\cos(2\\pi x_3/P_2 + \\varphi_2)]

    Unlike cogging it is proportional to the thrust current.
    """

    ratio: float = _p(0.02, "-", "ripple amplitude r_1 as a fraction of the thrust")
    period: float = _p(TAU / 3, "m", "period P_1 (tau/3, the 6th harmonic of the electrical period)")
    phase: float = _p(0.3, "rad", "phase phi_1 at x3 = 0")
    ratio2: float = _p(0.01, "-", "second ripple amplitude r_2")
    period2: float = _p(TAU, "m", "period P_2 (tau, the 2nd electrical harmonic)")
    phase2: float = _p(1.2, "rad", "phase phi_2 at x3 = 0")

    kind: ClassVar[str] = "thrust_ripple"
    axis: ClassVar[str] = "horizontal"

    @classmethod
    def small(cls) -> ThrustRipple:
        """2 % at tau/3 plus 1 % at tau."""
        return cls()

    @classmethod
    def large(cls) -> ThrustRipple:
        """5 % at tau/3 plus 2 % at tau."""
        return cls(ratio=0.05, ratio2=0.02)

    def apply(self, p: Any, ctx: dict[str, float]) -> None:
        p.tr_on = 1
        p.tr_amp[0], p.tr_amp[1] = self.ratio, self.ratio2
        p.tr_period[0], p.tr_period[1] = self.period, self.period2
        p.tr_phase[0], p.tr_phase[1] = self.phase, self.phase2

    def description(self) -> str:
        return (
            f"Thrust ripple: the thrust per ampere varies by {self.ratio:.0%} with period "
            f"{self.period * 1e3:.2f} mm and {self.ratio2:.0%} with period "
            f"{self.period2 * 1e3:.2f} mm along x3."
        )

    def equation(self) -> str:
        return "F_x = -M_h L1(g) i_q (1 + r1 cos(2 pi x3/P1 + phi1) + r2 cos(2 pi x3/P2 + phi2))"


# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CommutationOffset(Effect):
    """Commutation-angle error of the amplifiers: i_d and i_q mix.

    The phase currents are generated with the electrical angle ``pi x3 / tau + delta`` (e.g. the
    horizontal encoder's index is ``delta tau / pi`` off the magnets' axis). With 002's
    transform the currents in the motor's true frame are the commanded ones rotated by delta:

    .. math::

        i_d = i_d^* \\cos\\delta - i_q^* \\sin\\delta,\\qquad i_q = i_q^* \\cos\\delta + i_d^* \\sin\\delta

    so the levitation current i_d* leaks into thrust (a horizontal force ``-M_h L1 i_d* sin delta``).
    """

    angle: float = _p(0.02, "rad", "electrical angle offset delta")

    kind: ClassVar[str] = "commutation_offset"
    axis: ClassVar[str] = "both"

    @classmethod
    def small(cls) -> CommutationOffset:
        """0.02 rad (1.1 deg electrical, 0.36 mm of encoder index offset)."""
        return cls()

    @classmethod
    def large(cls) -> CommutationOffset:
        """0.06 rad (3.4 deg electrical, 1.1 mm of encoder index offset)."""
        return cls(angle=0.06)

    def apply(self, p: Any, ctx: dict[str, float]) -> None:
        p.com_cos, p.com_sin = math.cos(self.angle), math.sin(self.angle)

    def description(self) -> str:
        return (
            f"Commutation-angle error of {self.angle:g} rad ({math.degrees(self.angle):.1f} deg electrical): "
            "the amplifiers' dq frame is rotated against the magnets', so i_d and i_q mix."
        )

    def equation(self) -> str:
        return "i_d = i_d* cos(delta) - i_q* sin(delta); i_q = i_q* cos(delta) + i_d* sin(delta)"

    def derived(self, ctx: dict[str, float]) -> dict[str, float]:
        return {"encoder_index_offset_m": self.angle * TAU / math.pi}


# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class AmplifierDynamics(Effect):
    """Current-amplifier dynamics: first-order current loop plus a transport delay.

    The LCAMs are "factory tuned" for the coils' inductance; their closed current loop is close
    to first order with bandwidth ``f_a``, and the D/A conversion and the amplifier add a delay
    ``T_d``. In the dq frame (the electrical frequency pi v / tau stays below 15 rad/s, far
    below the bandwidth, so the lag commutes with the rotation):

    .. math::

        \\tau_a \\dot i = i^*(t - T_d) - i,\\quad \\tau_a = 1/(2 \\pi f_a)

    solved exactly over each plant step (the command is piecewise constant). ``T_d`` is rounded
    to a whole number of plant steps (the truth file gives the value used).
    """

    bandwidth: float = _p(500.0, "Hz", "current-loop bandwidth f_a (first order)")
    delay: float = _p(1e-4, "s", "transport delay T_d of the current command")

    kind: ClassVar[str] = "amplifier_dynamics"
    axis: ClassVar[str] = "both"

    @classmethod
    def small(cls) -> AmplifierDynamics:
        """500 Hz and 100 us."""
        return cls()

    @classmethod
    def large(cls) -> AmplifierDynamics:
        """150 Hz and 200 us (a poorly tuned current loop)."""
        return cls(bandwidth=150.0, delay=2e-4)

    def apply(self, p: Any, ctx: dict[str, float]) -> None:
        p.amp_tau = 1.0 / (2.0 * math.pi * self.bandwidth)
        p.amp_delay_sub = round(self.delay / ctx["plant_step"])

    def description(self) -> str:
        return (
            "Current amplifiers follow the commands with a first-order lag of bandwidth "
            f"{self.bandwidth:g} Hz (time constant {1e3 / (2 * math.pi * self.bandwidth):.2f} ms) "
            f"after a {self.delay * 1e6:g} us delay."
        )

    def equation(self) -> str:
        return "tau_a di/dt = i*(t - T_d) - i for i = (i_q, i_d), tau_a = 1/(2 pi f_a)"

    def derived(self, ctx: dict[str, float]) -> dict[str, float]:
        n = round(self.delay / ctx["plant_step"])
        return {
            "time_constant_s": 1.0 / (2 * math.pi * self.bandwidth),
            "delay_used_s": n * ctx["plant_step"],
        }


# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FieldShape(Effect):
    """The magnets' field depends on the gap slightly differently from the closed form.

    The closed-form B(y) is the 2-D fundamental of an infinitely wide magnet array; the real
    magnets are 50 mm wide (3-D fringing at their ends) and the back iron is finite, so the
    field falls a little faster (or slower) with the gap. Modelled as a smooth factor on the
    field, normalised to 1 at a reference gap (a constant factor would only rescale C1..C3):

    .. math::

        B_{true}(g) = B(g) f(g),\\quad f(g) = \\exp(-k_1 (g - g_{ref}) - k_2 (g - g_{ref})^2)

    The attraction ``L2`` scales with ``f^2``; the magnet-current terms ``L1`` (thrust) and ``L3``
    with ``f`` when ``applies_to_thrust`` is 1 (the thrust constant is proportional to the
    magnets' field too).
    """

    k1: float = _p(2.0, "1/m", "log-slope of the field factor (> 0: field falls faster with the gap)")
    k2: float = _p(0.0, "1/m^2", "curvature of the log field factor")
    reference_gap: float = _p(0.0195, "m", "gap at which the factor is 1")
    applies_to_thrust: float = _p(
        1.0, "-", "1: the factor also multiplies L1 and L3; 0: only the attraction L2"
    )

    kind: ClassVar[str] = "field_shape"
    axis: ClassVar[str] = "both"

    @classmethod
    def small(cls) -> FieldShape:
        """k1 = 2 /m: field +1 % at 14.5 mm, -1 % at 24.5 mm (attraction +-2 %)."""
        return cls()

    @classmethod
    def large(cls) -> FieldShape:
        """k1 = 4 /m, k2 = -300 /m^2: field +2.8 % at 14.5 mm, -1.2 % at 24.5 mm."""
        return cls(k1=4.0, k2=-300.0)

    def apply(self, p: Any, ctx: dict[str, float]) -> None:
        p.fs_on = 1
        p.fs_k1, p.fs_k2, p.fs_gref = self.k1, self.k2, self.reference_gap
        p.fs_thrust = 1 if self.applies_to_thrust else 0

    def _f(self, g: float) -> float:
        d = g - self.reference_gap
        return math.exp(-self.k1 * d - self.k2 * d * d)

    def description(self) -> str:
        return (
            f"The magnets' field differs smoothly from the closed form: {100 * (self._f(0.0145) - 1):+.1f} % "
            f"at 14.5 mm, {100 * (self._f(0.0245) - 1):+.1f} % at 24.5 mm (1 at "
            f"{self.reference_gap * 1e3:g} mm); attraction changes by twice that."
        )

    def equation(self) -> str:
        return "f(g) = exp(-k1 (g - g_ref) - k2 (g - g_ref)^2); L2 *= f^2; L1, L3 *= f if applies_to_thrust"

    def derived(self, ctx: dict[str, float]) -> dict[str, float]:
        return {
            "field_factor_at_14.5_mm": self._f(0.0145),
            "field_factor_at_24.5_mm": self._f(0.0245),
            "attraction_factor_at_14.5_mm": self._f(0.0145) ** 2,
            "attraction_factor_at_24.5_mm": self._f(0.0245) ** 2,
        }


# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TiltedBase(Effect):
    """The horizontal guides are not level: gravity has a component along the travel.

    The whole frame (stator and guides) is tilted by ``beta`` about the transverse axis, so the
    gap is unaffected and the horizontally moving mass feels a constant force

    .. math::

        F_x = M_h G \\sin\\beta
    """

    angle: float = _p(5e-3, "rad", "tilt beta of the travel axis from level (> 0: downhill towards +x3)")

    kind: ClassVar[str] = "tilted_base"
    axis: ClassVar[str] = "horizontal"

    @classmethod
    def small(cls) -> TiltedBase:
        """5 mrad (0.29 deg): 0.078 N."""
        return cls()

    @classmethod
    def large(cls) -> TiltedBase:
        """15 mrad (0.86 deg): 0.23 N."""
        return cls(angle=1.5e-2)

    def apply(self, p: Any, ctx: dict[str, float]) -> None:
        p.tilt_F = ctx["M_h"] * G * math.sin(self.angle)

    def description(self) -> str:
        return (
            f"Guides not level: tilted {self.angle * 1e3:g} mrad, a constant horizontal force of "
            f"{GEOMETRY.M_h * G * math.sin(self.angle):.3f} N along +x3."
        )

    def equation(self) -> str:
        return "F_x += M_h G sin(beta)"

    def derived(self, ctx: dict[str, float]) -> dict[str, float]:
        return {"horizontal_force_N": ctx["M_h"] * G * math.sin(self.angle)}


# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class VerticalForce(Effect):
    """A force on the vertical axis that the magnets carry besides the platform's weight.

    A bundle of cables (the motor's phases, the encoder) hanging from the platform to the frame
    adds part of its weight, and bent between them it acts as a soft spring along the gap; a
    preloaded seal or a counterweight string does the same with the other sign:

    .. math::

        F_v = F_0 - k_v (x_1 - x_{1,0})

    along +x1 (opening the gap, as the weight does), so that ``M_v x1'' = M_v G - F_n + F_v``.
    """

    force: float = _p(2.0, "N", "force along +x1 (downwards, opening the gap) at x1 = neutral_gap")
    stiffness: float = _p(0.0, "N/m", "spring along the gap: F_v falls by k per metre the gap opens")
    neutral_gap: float = _p(0.0195, "m", "x1 where the force is F_0")

    kind: ClassVar[str] = "vertical_force"
    axis: ClassVar[str] = "vertical"

    @classmethod
    def small(cls) -> VerticalForce:
        """1 N downwards (2.3 % of the weight; a 100 g share of a cable bundle)."""
        return cls(force=1.0)

    @classmethod
    def large(cls) -> VerticalForce:
        """3 N downwards (7 % of the weight) plus a 100 N/m spring along the gap."""
        return cls(force=3.0, stiffness=100.0)

    def apply(self, p: Any, ctx: dict[str, float]) -> None:
        p.vf_on = 1
        p.vf_F, p.vf_k, p.vf_x0 = self.force, self.stiffness, self.neutral_gap

    def description(self) -> str:
        return (
            f"A force of {self.force:g} N on the vertical axis along +x1 (a hanging cable's weight), "
            f"less {self.stiffness:g} N/m times the gap's opening beyond {self.neutral_gap * 1e3:g} mm."
        )

    def equation(self) -> str:
        return "M_v x1'' += F_0 - k_v (x1 - x1_0)"

    def derived(self, ctx: dict[str, float]) -> dict[str, float]:
        return {
            "force_towards_stator_N": -self.force,
            "share_of_weight": self.force / (ctx["M_v"] * G),
        }


# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CurrentSaturation(Effect):
    r"""The iron saturates under the stator current: the force per ampere falls at large currents.

    An iron-cored PMLSM's armature flux runs through the stator teeth; as the current grows they
    saturate and the flux per ampere falls. Modelled as a factor on the armature's flux,

    .. math::

        s = 1 / (1 + |i|^2 / I_s^2),\quad |i|^2 = i_d^2 + i_q^2,

    so the thrust ``L1 i_q`` and the magnet-current attraction ``L3 i_d`` scale with ``s`` and the
    current's own attraction ``L4 (i_d^2 + i_q^2)`` with ``s^2``; the magnets' own attraction
    ``L2`` is unchanged. ``I_s`` is the current at which the force per ampere has halved.
    """

    saturation_current: float = _p(30.0, "A", "current I_s at which the armature's flux per ampere halves")

    kind: ClassVar[str] = "current_saturation"
    axis: ClassVar[str] = "both"

    @classmethod
    def small(cls) -> CurrentSaturation:
        """I_s = 30 A: the force per ampere 2.7 % lower at 5 A, 8.3 % at 9 A (the amplifiers' peak)."""
        return cls()

    @classmethod
    def large(cls) -> CurrentSaturation:
        """I_s = 15 A: 10 % lower at 5 A, 26 % at 9 A."""
        return cls(saturation_current=15.0)

    def apply(self, p: Any, ctx: dict[str, float]) -> None:
        p.sat_on = 1
        p.sat_current = self.saturation_current

    def factor(self, current: float) -> float:
        """s at a current magnitude [A]."""
        return 1.0 / (1.0 + (current / self.saturation_current) ** 2)

    def description(self) -> str:
        return (
            f"The iron saturates under the stator current: the force per ampere is "
            f"{100 * (1 - self.factor(5.0)):.1f} % lower at 5 A and {100 * (1 - self.factor(9.0)):.1f} % "
            f"at 9 A (halved at {self.saturation_current:g} A)."
        )

    def equation(self) -> str:
        return "s = 1 / (1 + (i_d^2 + i_q^2) / I_s^2); L1 i_q, L3 i_d *= s; L4 (i_d^2 + i_q^2) *= s^2"

    def derived(self, ctx: dict[str, float]) -> dict[str, float]:
        return {"factor_at_5_A": self.factor(5.0), "factor_at_9_A": self.factor(9.0)}


# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CurrentSensorOffset(Effect):
    r"""The amplifiers' phase current sensors read a little off zero.

    Each phase amplifier drives its sensor's reading, the actual current plus its offset
    ``o_k``, to the command, so the actual phase current lacks ``o_k``. With 002's transform at
    the electrical angle ``theta = pi x3 / tau`` the missing currents are a vector fixed to the
    stator, which in the motor's dq frame turns once per two pole pitches:

    .. math::

        i_d = i_d^* - rac{2}{3} \sum_k \cos(	heta + s_k) o_k,\quad
        i_q = i_q^* + rac{2}{3} \sum_k \sin(	heta + s_k) o_k,\quad s = (0, -2\pi/3, 2\pi/3)

    so the thrust and the attraction get a part that depends on the position along the stator
    (period ``2 tau`` = 114.3 mm) and not on the commanded current: the classic force ripple at
    the electrical frequency of a drive with current sensor offsets.
    """

    offset_a: float = _p(0.03, "A", "offset of phase a's current sensor")
    offset_b: float = _p(-0.01, "A", "offset of phase b's current sensor")
    offset_c: float = _p(0.0, "A", "offset of phase c's current sensor")

    kind: ClassVar[str] = "current_sensor_offset"
    axis: ClassVar[str] = "both"

    @classmethod
    def small(cls) -> CurrentSensorOffset:
        """30 and -10 mA (0.3 % of the amplifiers' 9 A peak): 24 mA in dq, 0.26 N of thrust at 19.5 mm."""
        return cls()

    @classmethod
    def large(cls) -> CurrentSensorOffset:
        """80 and -50 mA on phases a and c: 76 mA in dq, 0.83 N of thrust at 19.5 mm."""
        return cls(offset_a=0.08, offset_b=0.0, offset_c=-0.05)

    def apply(self, p: Any, ctx: dict[str, float]) -> None:
        p.cso_on = 1
        p.cso_offset[0], p.cso_offset[1], p.cso_offset[2] = self.offset_a, self.offset_b, self.offset_c

    def dq_amplitude(self) -> float:
        """The missing current's magnitude in the dq frame [A] (the zero-sequence part has none)."""
        return math.hypot(*phase_harmonic((self.offset_a, self.offset_b, self.offset_c), 1))

    def description(self) -> str:
        return (
            f"The phase current sensors read {self.offset_a * 1e3:g}, {self.offset_b * 1e3:g} and "
            f"{self.offset_c * 1e3:g} mA off zero: the motor lacks a current of "
            f"{self.dq_amplitude() * 1e3:.0f} mA fixed to the stator, a force ripple along the travel "
            f"with a period of two pole pitches ({2 * TAU * 1e3:.1f} mm)."
        )

    def equation(self) -> str:
        return (
            "theta = pi x3 / tau; i_d -= 2/3 sum cos(theta + s_k) o_k; i_q += 2/3 sum sin(theta + s_k) o_k, "
            "s = (0, -2 pi/3, 2 pi/3)"
        )

    def derived(self, ctx: dict[str, float]) -> dict[str, float]:
        return {"dq_amplitude_A": self.dq_amplitude(), "period_m": 2 * TAU}


# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CurrentSensorGain(Effect):
    r"""The amplifiers' phase current sensors differ in gain.

    Amplifier k drives its reading ``(1 + e_k) i_k`` to the command ``i_k^* = cos(theta + s_k)
    i_d^* - sin(theta + s_k) i_q^*`` (002's inverse transform at ``theta = pi x3 / tau``), so the
    motor gets

    .. math::

        i_k = i_k^* / (1 + e_k),\quad i_d = \frac{2}{3} \sum_k \cos(\theta + s_k) i_k,\quad
        i_q = -\frac{2}{3} \sum_k \sin(\theta + s_k) i_k

    The common part of the errors scales both currents (the constants take it); their differences
    mix i_d and i_q at twice the electrical angle, a force ripple over one pole pitch (57.15 mm)
    that grows with the currents: the classic second-harmonic ripple of a drive with mismatched
    current sensors. With the levitation current i_d of 1-3 A the normal force ripples most.
    """

    error_a: float = _p(0.01, "1", "relative gain error of phase a's current sensor")
    error_b: float = _p(-0.01, "1", "relative gain error of phase b's current sensor")
    error_c: float = _p(0.0, "1", "relative gain error of phase c's current sensor")

    kind: ClassVar[str] = "current_sensor_gain"
    axis: ClassVar[str] = "both"

    @classmethod
    def small(cls) -> CurrentSensorGain:
        """+1 % and -1 % on two phases: a mismatch of 1.2 % at twice the electrical angle."""
        return cls()

    @classmethod
    def large(cls) -> CurrentSensorGain:
        """+3 % and -2 % on phases a and c: a mismatch of 2.9 %."""
        return cls(error_a=0.03, error_b=0.0, error_c=-0.02)

    def apply(self, p: Any, ctx: dict[str, float]) -> None:
        p.csg_on = 1
        p.csg_error[0], p.csg_error[1], p.csg_error[2] = self.error_a, self.error_b, self.error_c

    def mismatch(self) -> float:
        """The errors' part at twice the electrical angle: (2/3) |sum_k e_k exp(2 j s_k)| [1], to
        first order (the part the constants cannot take)."""
        return math.hypot(*phase_harmonic((self.error_a, self.error_b, self.error_c), 2))

    def description(self) -> str:
        return (
            f"The phase current sensors' gains are off by {100 * self.error_a:+g}, "
            f"{100 * self.error_b:+g} and {100 * self.error_c:+g} %: a mismatch of "
            f"{100 * self.mismatch():.1f} % mixes i_d and i_q over one pole pitch ({TAU * 1e3:.2f} mm)."
        )

    def equation(self) -> str:
        return (
            "i_k = (cos(theta + s_k) i_d* - sin(theta + s_k) i_q*) / (1 + e_k); "
            "i_d = 2/3 sum cos(theta + s_k) i_k; i_q = -2/3 sum sin(theta + s_k) i_k"
        )

    def derived(self, ctx: dict[str, float]) -> dict[str, float]:
        return {"mismatch": self.mismatch(), "period_m": TAU}


# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class GapSensorZero(Effect):
    """The gap encoder's zero is off: the magnetic gap is the reading plus ``offset``.

    The vertical encoder is zeroed against a stopper whose height is known to a fraction of a
    millimetre; every force of the gap is felt at the magnetic gap while the controller and the
    log see ``x1``. Optionally the zero drifts during the run as the frame and the sensor's mount
    warm and expand (first-order, ``drift`` in all):

    .. math::

        g = x_1 + \\mathrm{offset} + \\mathrm{drift} (1 - e^{-t/T})
    """

    offset: float = _p(2e-4, "m", "magnetic gap minus the encoder's reading")
    drift: float = _p(0.0, "m", "how far the zero moves as the rig warms (first-order, over the run)")
    drift_time_constant: float = _p(60.0, "s", "time constant T of the zero's drift")

    kind: ClassVar[str] = "gap_sensor_zero"
    axis: ClassVar[str] = "both"

    @classmethod
    def small(cls) -> GapSensorZero:
        """0.2 mm."""
        return cls()

    @classmethod
    def large(cls) -> GapSensorZero:
        """-0.5 mm."""
        return cls(offset=-5e-4)

    def __post_init__(self) -> None:
        if not self.drift_time_constant > 0:
            raise ValueError("GapSensorZero.drift_time_constant must be > 0 [s]")

    def apply(self, p: Any, ctx: dict[str, float]) -> None:
        p.gap_zero = self.offset
        p.gz_drift, p.gz_drift_tau = self.drift, self.drift_time_constant

    def description(self) -> str:
        drift = (
            f"; it drifts by {self.drift * 1e6:+.0f} um as the rig warms (time constant "
            f"{self.drift_time_constant:g} s)"
            if self.drift
            else ""
        )
        return (
            f"The gap encoder's zero is {self.offset * 1e3:+.2f} mm off: the magnetic gap is the reading "
            f"plus that{drift}."
        )

    def equation(self) -> str:
        return "g = x1 + offset + drift (1 - exp(-t / T)) in every gap-dependent force"


# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BaseVibration(Effect):
    """The floor shakes the base, and with it the stator, the guides and the encoders' scales.

    The encoders read the stage against the base, so the stage's coordinates feel the base's
    acceleration a_b(t) with the opposite sign: x1'' and x3'' get -a_b on top of the forces. a_b is
    Gaussian noise per axis through a second-order Butterworth band-pass over [band_low, band_high],
    scaled to the RMS given, held over each control period; it is drawn from the scenario's seed
    (:meth:`signal`). Not a function of the state: no model of the stage describes it, and a
    diagnosis should claim nothing for it.

    .. math::

        \\ddot x_{1,3} = \\ldots - a_{b,v/h}(t)
    """

    rms_vertical: float = _p(5e-3, "m/s^2", "RMS of the base's vertical acceleration")
    rms_horizontal: float = _p(5e-3, "m/s^2", "RMS of the base's horizontal acceleration")
    band_low: float = _p(1.0, "Hz", "lower edge of the band-pass")
    band_high: float = _p(100.0, "Hz", "upper edge of the band-pass")

    kind: ClassVar[str] = "base_vibration"
    axis: ClassVar[str] = "both"

    def __post_init__(self) -> None:
        if not (self.rms_vertical >= 0 and self.rms_horizontal >= 0 and 0 < self.band_low < self.band_high):
            raise ValueError("BaseVibration: RMS >= 0 [m/s^2] and 0 < band_low < band_high [Hz]")

    @classmethod
    def small(cls) -> BaseVibration:
        """5 mm/s^2 RMS over 1-100 Hz: a quiet laboratory floor (a few VC-A bands)."""
        return cls()

    @classmethod
    def large(cls) -> BaseVibration:
        """20 mm/s^2 RMS over 1-100 Hz: a workshop floor near running machines."""
        return cls(rms_vertical=2e-2, rms_horizontal=2e-2)

    def apply(self, p: Any, ctx: dict[str, float]) -> None:
        p.vib_on = 1

    def signal(self, rng: Any, n: int, rate: float) -> Any:
        """(n, 2) base accelerations (vertical, horizontal) [m/s^2] at ``rate`` [Hz] from ``rng``."""
        import numpy as np
        from scipy import signal as sig

        sos = sig.butter(2, [self.band_low, self.band_high], btype="bandpass", fs=rate, output="sos")
        out = np.empty((n, 2))
        for k, rms in enumerate((self.rms_vertical, self.rms_horizontal)):
            x = sig.sosfilt(sos, rng.standard_normal(n))
            out[:, k] = rms * x / max(float(np.sqrt(np.mean(x**2))), 1e-300)
        return out

    def description(self) -> str:
        return (
            f"The base vibrates: {self.rms_vertical * 1e3:g} mm/s^2 RMS vertically and "
            f"{self.rms_horizontal * 1e3:g} mm/s^2 horizontally over {self.band_low:g}-{self.band_high:g} Hz."
        )

    def equation(self) -> str:
        return "x1'' += -a_bv(t), x3'' += -a_bh(t); a_b band-passed Gaussian noise (2nd-order Butterworth)"


# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MagnetWarming(Effect):
    r"""The magnets warm up during the run, and their field falls with their temperature.

    The stator's coils dissipate i^2 R; the heat reaches the magnets across the gap and through
    the frame, and a neodymium magnet's remanence falls by about 0.12 % per kelvin (reversible).
    The magnets' temperature rises first-order from the rig's start (the ambient),
    dT(t) = rise (1 - exp(-(t + start_time) / time_constant)), t the time in the log and
    ``start_time`` how long the rig had run when the log began (0: a log from a cold start; a
    later log of the same session starts warmer and warms less), and every force made by their
    field follows:
    the attraction L2 with the square of the field, the thrust L1 and the i_d term L3 with the
    field. The armature's own attraction (L4) does not depend on the magnets. A constant that
    drifts in time, not a function of the state: the constants fitted over a log are its mean.

    .. math::

        B(t) = B_0 (1 - c\, dT(t)),\quad L_2 \propto B^2,\quad L_1, L_3 \propto B
    """

    temperature_coefficient: float = _p(1.2e-3, "1/K", "fall of the field per kelvin (NdFeB: 1.1-1.2e-3)")
    rise: float = _p(6.0, "K", "final rise of the magnets' temperature")
    time_constant: float = _p(120.0, "s", "thermal time constant of the magnets' warming")
    start_time: float = _p(0.0, "s", "how long the rig had run (and warmed) when the log began")

    kind: ClassVar[str] = "magnet_warming"
    axis: ClassVar[str] = "both"

    def __post_init__(self) -> None:
        if not (
            self.temperature_coefficient >= 0
            and self.rise >= 0
            and self.time_constant > 0
            and self.start_time >= 0
        ):
            raise ValueError(
                "MagnetWarming: coefficient >= 0 [1/K], rise >= 0 [K], time constant > 0 [s], "
                "start time >= 0 [s]"
            )

    @classmethod
    def small(cls) -> MagnetWarming:
        """6 K final rise, 120 s: the field 0.28 % lower after 60 s (the attraction 0.57 %)."""
        return cls()

    @classmethod
    def large(cls) -> MagnetWarming:
        """15 K final rise, 60 s: the field 1.1 % lower after 60 s (the attraction 2.3 %)."""
        return cls(rise=15.0, time_constant=60.0)

    def apply(self, p: Any, ctx: dict[str, float]) -> None:
        p.heat_on = 1
        p.heat_coef, p.heat_rise, p.heat_tau = self.temperature_coefficient, self.rise, self.time_constant
        p.heat_t0 = self.start_time

    def field_factor(self, t: float) -> float:
        """The field relative to its value at the rig's start (the ambient), at time ``t`` [s] in the log."""
        warmed = 1.0 - math.exp(-(t + self.start_time) / self.time_constant)
        return 1.0 - self.temperature_coefficient * self.rise * warmed

    def change_over_log(self, duration: float) -> float:
        """The field's relative change from the log's first sample to its last (``duration`` [s])."""
        return self.field_factor(duration) / self.field_factor(0.0) - 1.0

    def description(self) -> str:
        return (
            f"The magnets warm by up to {self.rise:g} K (time constant {self.time_constant:g} s): their "
            f"field is {100 * (1 - self.field_factor(60.0)):.2f} % lower after 60 s, the attraction "
            "twice that."
        )

    def equation(self) -> str:
        return "B(t) = B0 (1 - c rise (1 - exp(-t / T))); L2 *= (B/B0)^2; L1, L3 *= B/B0"

    def derived(self, ctx: dict[str, float]) -> dict[str, float]:
        at_60 = self.field_factor(60.0)
        return {"field_factor_at_60_s": at_60, "attraction_factor_at_60_s": at_60**2}


EFFECT_KINDS: dict[str, type[Effect]] = {
    cls.kind: cls
    for cls in (
        GuideFriction, NormalCogging, DetentForce, EndEffect, GuideMisalignment, CableCarrier,
        ThrustRipple, CommutationOffset, AmplifierDynamics, FieldShape, TiltedBase, CurrentSaturation,
        CurrentSensorOffset, CurrentSensorGain, GapSensorZero, BaseVibration, MagnetWarming, VerticalForce,
    )
}  # fmt: skip
"""Every effect class by its ``kind``."""


def effect_from_truth(entry: dict[str, Any]) -> Effect:
    """Rebuild an effect from its truth-file entry (``kind``, ``axis`` and ``parameters``)."""
    cls = EFFECT_KINDS[entry["kind"]]
    params = dict(entry["parameters"])
    if cls is GuideFriction:
        params["axis_"] = entry["axis"]
    return cls(**params)
