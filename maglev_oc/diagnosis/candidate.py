"""The candidate type of the diagnosis and the building blocks its library is written with.

A :class:`Candidate` is an :class:`~maglev_oc.regression.terms.AccelerationTerm` (linear in its
coefficients, so every fit is an exact linear solve) plus what the diagnosis needs around it: the
family it belongs to, the signal its signature lives in, a physical plausibility check, the
experiment that would separate it from the base constants, and a sentence saying what was found
in plain words. :class:`LibraryContext` carries what every candidate of one log is built from:
the model whose constants are the magnetic references, and the logged ranges.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.model.hardware import RIG_SAMPLE_TIME
from maglev_oc.model.stage import StageModel
from maglev_oc.regression.data import PreparedLogs
from maglev_oc.regression.terms import AccelerationTerm, term_function, term_function_in_time
from maglev_oc.results import Estimate

__all__ = [
    "FAMILIES",
    "MAX_FORCE_SHARE",
    "VARIABLES",
    "Candidate",
    "LibraryContext",
    "Plausibility",
    "all_of",
    "delta_method",
    "detected",
    "fmt",
    "legendre",
    "not_below",
    "with_physical",
    "within",
]

VARIABLES = (
    "gap",
    "gap_rate",
    "position",
    "position_rate",
    "current_rate",
    "current",
    "axis_current",
    "time",
)
FAMILIES = ("friction", "periodic", "profile", "current", "constant", "geometry", "drift")
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
    fallback_for: str | None = None
    """The candidate this one stands in for when that one's fit is physically implausible: the same
    effect with a parameter held at its physical bound (the bound-constrained least-squares fit when
    the unconstrained one lies beyond it). Judged only then, and reported under that name."""
    fallback_when: Plausibility | None = field(default=None, repr=False)
    """For a fallback: the parent's physical parameters -> the reason its free fit lies beyond the
    bound this one holds (None: it does not, and the fallback is not judged). An implausible parent
    for another reason is no case for holding that parameter (a pure viscous friction refused for
    "no Coulomb" is not a Coulomb friction with its viscous part held at zero)."""
    fallback_verdicts: tuple[str, ...] = ("implausible",)
    """For a fallback: the parent's verdicts that make the case for it. A form that leaves out a
    coefficient of the parent's (the commutation offset fitted on the thrust alone) stands in where
    that coefficient made the parent "not specific": an axis it made worse."""
    size_direction: Callable[[Mapping[str, float]], np.ndarray] | None = field(default=None, repr=False)
    """For an effect whose size is one number shared by several coefficients (the commutation
    angle, one coefficient per axis): the fitted constants -> the direction in the space of its
    reported coefficients along which that number moves them together. Separability is then
    judged for that one combination (the effect as a whole), not for each coefficient alone,
    which a constant may be collinear with while the shared size is well determined. None: every
    direction (the effect's coefficients are its sizes)."""
    size_relative_to: tuple[str, ...] = ()
    """For an effect whose size is each coefficient over a base constant (one of C1..C4 per
    parameter of the term, in its order): the size is unchanged when the constant and the
    coefficient scale together, so separability is judged with each constant's column carrying
    the column of a judged coefficient along (the model's derivative in the constant at a fixed
    size; :func:`~maglev_oc.diagnosis.selection._at_fixed_size`). Empty: the sizes are the
    coefficients themselves."""
    beside_friction: bool = True
    """Whether its evidence on an axis with claimed guide friction counts. False for an effect of
    the currents' rates (the amplifiers' lag): the regulator makes an axis's current rate follow
    its velocity and acceleration, so there the term's column is a viscous force and a change of
    mass, which the friction's viscous part (free, or held at zero after a negative fit) trades
    with. It is then judged on the other axes alone; with none left, not separable from the
    friction if it passes on its own axes."""
    rival_span: tuple[str, str, int] | None = None
    """(axis, variable, k) when its columns span the same functions as the first k of that generic
    rival's (:mod:`~maglev_oc.diagnosis.probes`; a spring along the track is a line in the
    position): the equal-complexity comparison is then a tie by construction, so its shape is
    judged by what is left: the rival's further orders must not explain significantly more of the
    held-out data beside it."""
    simpler: str | None = None
    """The candidate with fewer parameters that this one becomes with its extra ones at zero (a
    spring along the track at zero stiffness is a constant force, a tilt's): once everything else is
    chosen, it takes this one's place where what this one adds to it beside the rest does not pass
    the held-out test of an effect (the selection's backward pass)."""
    physical_sign: int = 0
    """+1 when only a positive size is physical (a friction's Coulomb force, a lag, a loss of force):
    the detection limit (:mod:`~maglev_oc.diagnosis.limits`) is then sought in that direction
    alone; 0 when either sign is (a ripple's phase, a slope, a tilt)."""
    thrust_proportional: bool = False
    """Whether its horizontal force is proportional to the thrust current (a thrust ripple, the
    thrust's dependence on the gap, saturation): where the logged thrust current is mostly its
    logging error it is judged on that current too
    (:mod:`~maglev_oc.diagnosis.thrust_current`)."""
    confounded_beside: tuple[str, str] | None = None
    """(effect, why): a chosen effect beside which no log of this stage separates this one, and
    why. Judged beside it, a candidate that would pass is not separable, confounded with it (a
    current sensor offset beside guides tilted against the stator: what the offset does along the
    travel is what a waviness of the guides does;
    :func:`~maglev_oc.diagnosis.currents.sensor_offset_candidate`)."""
    two_axis_signature: bool = False
    """Whether what tells it from a force of the position is the tie between the two axes' forces
    (the current sensors' errors: on one axis alone a force periodic in the position at a motor
    pitch). On a log where one axis does not move, a candidate that would pass is not separable
    from a smooth dependence on the position, and its residual is still reported by its signature."""
    form_of: str | None = None
    """The candidate this one is a richer form of (the same effect with one more parameter, e.g.
    guide friction with its Stribeck rise): judged beside it and reported under its name; chosen
    over it only when its held-out gain beats the simpler form's by more than the parsimony
    penalty of its extra parameter."""
    commutation_angle: float = 0.0
    """[rad] The commutation offset its library was built beside (:attr:`LibraryContext.commutation_angle`):
    its columns take the logged currents in the amplifiers' frame and turn them into the magnets'
    where the offset acts (:meth:`LibraryContext.force_terms`), so currents put into them from
    elsewhere (:func:`~maglev_oc.diagnosis.thrust_current.felt_currents`) must be in that frame too."""

    def __post_init__(self) -> None:
        if self.family not in FAMILIES:
            raise InputError(f"Candidate {self.term.name}: family must be one of {FAMILIES}")
        if self.variable not in VARIABLES:
            raise InputError(f"Candidate {self.term.name}: variable must be one of {VARIABLES}")

    @property
    def name(self) -> str:
        return self.term.name

    @property
    def reported_name(self) -> str:
        """The effect's name in results: a fallback's or a richer form's is its parent's."""
        return self.form_of or self.fallback_for or self.term.name

    @property
    def axis(self) -> str:
        return self.term.axis


# --- helpers -----------------------------------------------------------------------------------
def not_below(name: str, what: str, k: float = 2.0) -> Plausibility:
    """Refuse a parameter that is negative by more than k standard errors."""

    def check(est):
        e = est[name]
        if e.value < -k * max(e.stderr, 0.0):
            sigmas = e.value / max(e.stderr, 1e-300)
            return f"{what} of {e.value:.3g} {e.unit} is negative ({sigmas:.1f} standard errors)"
        return None

    return check


def detected(name: str, what: str, k: float = 2.0) -> Plausibility:
    """Refuse unless a parameter is positive by more than k standard errors."""

    def check(est):
        e = est[name]
        if not e.value > k * max(e.stderr, 0.0):
            return (
                f"no {what}: {e.value:.3g} ± {e.stderr:.2g} {e.unit} is not positive by {k:g} standard errors"
            )
        return None

    return check


def within(name: str, bound: float, what: str) -> Plausibility:
    def check(est):
        e = est[name]
        if abs(e.value) > bound:
            return f"{what} of {e.value:.3g} {e.unit} is beyond the physical bound {bound:g} {e.unit}"
        return None

    return check


def all_of(*checks: Plausibility) -> Plausibility:
    def check(est):
        for c in checks:
            reason = c(est)
            if reason:
                return reason
        return None

    return check


def fmt(e: Estimate, scale: float = 1.0, unit: str | None = None, digits: int = 2) -> str:
    """The estimate as "value ± standard error unit", with ``digits`` and 1 significant digits, in
    positional notation from 0.001 to 99 999 (a 0.3 mm wave reads "300 ± 10 um", not
    "3e+02 ± 1e+01 um")."""
    u = e.unit if unit is None else unit
    return f"{_significant(e.value * scale, digits)} ± {_significant(e.stderr * scale, 1)} {u}".strip()


def _significant(x: float, digits: int) -> str:
    """``x`` to ``digits`` significant digits as %g writes them, but positional for 1e-3 <= |x| < 1e5."""
    if not math.isfinite(x) or x == 0 or not 1e-3 <= abs(x) < 1e5:
        return f"{x:.{digits}g}"
    decimals = digits - 1 - math.floor(math.log10(abs(x)))
    rounded = round(x, decimals)
    if rounded and math.floor(math.log10(abs(rounded))) > math.floor(math.log10(abs(x))):
        decimals -= 1  # rounded up a decade (0.0999 -> 0.10): one decimal fewer
    text = f"{round(x, decimals):.{max(decimals, 0)}f}"
    return text.rstrip("0").rstrip(".") if "." in text else text  # no trailing zeros, as %g


def delta_method(f: Callable[[np.ndarray], float], p: np.ndarray, cov: np.ndarray, unit: str) -> Estimate:
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


def legendre(xi, orders):
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
            raise InputError(f"Legendre order {k} not provided")
    return out


def with_physical(term: AccelerationTerm, physical) -> AccelerationTerm:
    """``term`` with another conversion to physical parameters."""
    return dataclasses.replace(term, physical=physical)


@dataclass(frozen=True, eq=False)
class LibraryContext:
    """What the candidates of one log are built from.

    ``model``: geometry and the magnetic references (the base fit's constants); ``data``: the
    prepared log, whose valid samples give the ranges (1st-99th percentiles) that profiles and
    reports use; ``commutation_angle``: the chosen commutation offset, beside which the thrust's
    ripple and the shares of the forces lost (:meth:`force_terms`) act.
    """

    model: StageModel
    data: PreparedLogs
    commutation_angle: float = 0.0
    """[rad] The commutation offset chosen, as the thrust sees it (its ``angle_horizontal``): the
    current that makes thrust, which the thrust's ripple ripples, is i_q + d i_d (0: none chosen)."""
    gap_range: tuple[float, float] = field(init=False)
    position_range: tuple[float, float] = field(init=False)
    gap_median: float = field(init=False)
    hold_delay: float = field(init=False)

    def __post_init__(self) -> None:
        x = self.fitted_states
        set_ = object.__setattr__
        set_(self, "gap_range", tuple(float(v) for v in np.percentile(x[0], [1, 99])))
        set_(self, "position_range", tuple(float(v) for v in np.percentile(x[2], [1, 99])))
        set_(self, "gap_median", float(np.median(x[0])))
        # the loop holds each command for one control period: on average the force follows the
        # command by half of it (0.1 ms at the rig's 5 kHz)
        set_(self, "hold_delay", 0.5 / self.data.settings.get("control_rate_hz", 1.0 / RIG_SAMPLE_TIME))

    @property
    def fitted_states(self) -> np.ndarray:
        return self.data.x[:, self.data.valid]

    @property
    def params(self):
        return self.model.params

    @property
    def references(self):
        """The constants the magnetic columns are scaled with (the base fit's)."""
        return self.model.constants

    def mass(self, axis: str) -> float:
        """[kg] the mass the forces on ``axis`` ("vertical" or "horizontal") move: M_v or M_h."""
        if axis == "vertical":
            return self.params.mass_vertical
        if axis == "horizontal":
            return self.params.mass_horizontal
        raise InputError(f"LibraryContext: axis must be 'vertical' or 'horizontal', got {axis!r}")

    def weight(self, axis: str) -> float:
        """[N] M g of the mass on ``axis`` (:meth:`mass`)."""
        return self.mass(axis) * self.params.gravity

    @property
    def payloads(self) -> tuple[float, ...]:
        """[kg] The payload each log declares (``# payload_kg``), in the order of the logs; (0,)
        when none does."""
        declared = self.data.settings.get("payload_kg")
        return tuple(float(m) for m in declared) if declared else (0.0,)

    @property
    def payloads_differ(self) -> bool:
        """Whether the logs declare different payloads (a load change): then what the guides carry
        differs between logs, and :meth:`weight_carried` reads the log's index."""
        return len(set(self.payloads)) > 1

    def weight_carried(self, s=None):
        """[N] The weight sloping horizontal guides pull along the track: the horizontal mover's
        and the payload its log declares, (M_h + m) G. A term's forces are read as the unloaded
        stage's (:mod:`~maglev_oc.regression.payload`), but the payload's weight on the guides is a
        force of its own: with it left out, a 0.8 kg payload declared on guides sloping by 4.2 mrad
        (drawn pairs 27904 and 27907 of the independent generator) left 0.033 N along the track,
        claimed as a tilted base. ``s``: a term's time symbol (:func:`~maglev_oc.regression.terms.
        when_symbol`), read when :attr:`payloads_differ`."""
        return (self.params.mass_horizontal + self.payload(s)) * self.params.gravity

    def payload(self, s=None):
        """[kg] The payload of the log a sample is from: the one all logs declare, or when
        :attr:`payloads_differ` an expression of ``s``, a term's time symbol (:func:`~maglev_oc.
        regression.terms.when_symbol`: the log's index is ``s[1]``)."""
        loads = self.payloads
        if not self.payloads_differ:
            return loads[0]
        if s is None:
            raise ValueError(
                "LibraryContext: the logs' payloads differ; give the log's index (a term in time)"
            )
        return sum(m * (s[1] == k) for k, m in enumerate(loads))

    def along_the_guides(self, name: str, build: Callable, n_parameters: int):
        """A term Function of ``build(x, u, du, q, weight)``, ``weight`` the weight the guides carry
        (:meth:`weight_carried`): (x, u, du, p) -> acc, or (x, u, du, s, p) -> acc when the logs'
        payloads differ (the term is then in time, :attr:`~maglev_oc.regression.terms.
        AccelerationTerm.in_time`)."""
        if not self.payloads_differ:
            weight = self.weight_carried()
            return term_function(name, lambda x, u, du, q: build(x, u, du, q, weight), n_parameters)
        return term_function_in_time(
            name, lambda x, u, du, s, q: build(x, u, du, q, self.weight_carried(s)), n_parameters
        )

    def shapes(self, x):
        """The shape functions l1..l4 at the gap x[0] (L = C l)."""
        return self.model.shape(x[0])

    def modelled(self, axis: str) -> Callable:
        """(x, u) -> what sticking guides on ``axis`` hold: the base model's acceleration there, with
        the references and the currents in the magnets' frame (:meth:`magnets_frame`; the motor's
        whole force, the chosen commutation offset's thrust d i_d too), less the acceleration of the
        stage at rest (:meth:`at_rest`). (x, u, s) -> the same, ``s`` a term's time symbol, when the
        payload a vertical stuck axis carries differs between the logs (:meth:`holds_in_time`)."""
        row = 1 if axis == "vertical" else 3
        if self.holds_in_time(axis):
            return lambda x, u, s: self.model.f(x, self.magnets_frame(u))[row] - self.at_rest(axis, s)
        rest = self.at_rest(axis)
        return lambda x, u: self.model.f(x, self.magnets_frame(u))[row] - rest

    def holds_in_time(self, axis: str) -> bool:
        """Whether what the guides on ``axis`` hold reads the log's index (:meth:`modelled`): on the
        vertical axis when the logs declare different payloads."""
        return axis == "vertical" and self.payloads_differ

    def at_rest(self, axis: str, s=None):
        """[m/s^2] The acceleration of a stage at rest on ``axis`` as the regression reads it, in the
        unloaded stage's units (:func:`~maglev_oc.regression.payload.unloaded`): G (1 - (M_v + m) / M_v)
        = -m G / M_v vertically with a payload of m kg, 0 along the track. A stuck axis's guides
        carry the weight the magnets do not, the payload's with it; held to an acceleration of 0,
        a 1 kg payload left -2.3 m/s^2 on every stuck sample of vertical guides, and their friction
        came out with a holding share of 0.01 and a viscous part of -150 N s/m (drawn pair 28907
        of the independent generator: Coulomb 0.93 N for 0.70 on the viscous part's bound).
        ``s``: a term's time symbol, read when the logs' payloads differ."""
        if axis != "vertical":
            return 0.0
        return -self.payload(s) * self.params.gravity / self.params.mass_vertical

    def magnets_frame(self, u):
        """The logged currents (i_q, i_d) in the magnets' frame beside the chosen commutation
        offset d (:attr:`commutation_angle`), to first order in d: (i_q + d i_d, i_d - d i_q);
        ``u`` itself when none is chosen."""
        d = self.commutation_angle
        if not d:
            return u
        return ca.vertcat(u[0] + d * u[1], u[1] - d * u[0])

    def gap_sensitivity(self, x, u):
        """d(x2', x4')/d x1 of the model with the references, at (x, u), with the currents in the
        magnets' frame (:meth:`magnets_frame`): a gap error changes the forces the currents make
        there. Set 24110 of the independent generator on 1 um encoders (guides tilted by 2.5 mrad,
        a -2.7 degree commutation offset, a cable carrier): with the logged i_q alone the thrust's
        change along the tilted guides missed the offset's d i_d, about a tenth of the thrust
        current there, and the tilt made the held-out horizontal error 26 % worse beside the other
        two, while it explained 99.7 % of the vertical one; it was not claimed."""
        xs = ca.SX.sym("xs", 4)
        acc = self.model.f(xs, self.magnets_frame(u))[[1, 3]]
        return ca.substitute(ca.jacobian(acc, xs[0]), xs, x)

    def force_terms(self, x, u):
        """(thrust, currents' normal force, magnets' attraction): each force's part of the model's
        acceleration with the references, the thrust's on the horizontal axis and the other two on
        the vertical one (a share lost of a force changes the acceleration by minus that share of
        its term).

        Beside a chosen commutation offset d (:attr:`commutation_angle`) the currents in the
        magnets' frame are i_q + d i_d and i_d - d i_q (to first order in d): a share lost of the
        thrust is a share of what both make. Drawn pair 22407 of the independent generator (a 3.2
        degree offset, i_d about 1.7 A against at most 0.14 A of i_q, and end effects of 11 % of the
        thrust at +50 mm on a vibrating base): with i_q alone the end effects' thrust part made the
        horizontal held-out error 59 % worse beside the offset, and they were not claimed."""
        l, c, framed = self.shapes(x), self.references, self.magnets_frame(u)
        thrust = -c.C1 * l[0] * framed[0]
        winding_normal = -(c.C3 * l[2] * framed[1] + c.C4 * l[3] * (u[0] ** 2 + u[1] ** 2))
        magnets = -c.C2 * l[1]
        return thrust, winding_normal, magnets

    def normal_force(self, x, u):
        """The magnetic normal force F_n = M_v (G - x2'_model) [N], positive towards the stator, of the
        currents in the magnets' frame (:meth:`magnets_frame`)."""
        return self.params.mass_vertical * (self.params.gravity - self.model.f(x, self.magnets_frame(u))[1])

    def reference_ratio(self, name: str, constants: Mapping[str, float]) -> float:
        """reference / fitted value of one constant (1 when the fit has none)."""
        ref = getattr(self.references, name)
        return ref / constants.get(name, ref)
