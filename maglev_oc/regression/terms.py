"""Extra accelerations fitted jointly with the lumped constants: the one term type of the project.

The base model's accelerations are linear in C1..C4 (eq. (2) of paper 000):

    (x2', x4') = Phi(x, u) C + b + sum_k term_k(x, u, du, p_k)

An :class:`AccelerationTerm` is one extra contribution with its own parameters p_k, for an
effect the papers' model leaves out (friction, cogging, a force along the track, ...). It may
depend on the state x, the currents u and their rates du. Most physical terms are linear in
their parameters (then one linear least-squares solve is exact; ``features`` holds the columns
acc = features(x, u, du) p); a term may also be nonlinear in some parameters, and the fits then
iterate Gauss-Newton steps on its exact Jacobian.

Each term carries a one-sentence physical explanation and, optionally, the conversion of its
parameters to physical quantities with units (:class:`Estimate`, delta method). The identify
fits take a sequence of terms; the diagnosis library is a list of them.

The constructors below build the physics that both identify and the diagnosis use: guide
friction (:func:`guide_friction`), constant forces (:func:`constant_force`), forces periodic in
the position (:func:`periodic_force`, cogging of 000 eq. (9) being :func:`cogging_term`).
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.model.parameters import StageParameters
from maglev_oc.results import Estimate

__all__ = [
    "AXES",
    "REVERSAL_SPEED",
    "AccelerationTerm",
    "Estimate",
    "amplitude_phase",
    "cogging_force",
    "cogging_term",
    "constant_acceleration",
    "constant_force",
    "guide_friction",
    "held_by_guides",
    "is_linear_in_parameters",
    "linear_physical",
    "periodic_force",
    "term_function",
    "term_function_in_time",
    "viscous_friction",
    "when_symbol",
]

AXES = ("vertical", "horizontal", "both")
REFERENCE_GAP = 15e-3
"""[m] Gap at which gap-dependent forces (cogging) are quoted; 000 Fig. 6 shows the peak cogging
force becoming appreciable below it."""


PhysicalMap = Callable[[np.ndarray, np.ndarray, Mapping[str, float]], dict[str, Estimate]]
"""(parameters, their covariance, fitted constants C1..C4 by name) -> physical quantities."""


WHEN_NAMES = ("place", "log")
"""What a term :attr:`~AccelerationTerm.in_time` reads of each sample's time, s (2): its place in
its log, from -1 at the first sample to +1 at the last, and the index of that log (0, 1, ...) among
the logs fitted together (:attr:`~maglev_oc.regression.data.PreparedLogs.log_time`)."""


def when_symbol() -> ca.SX:
    """The symbol s (2) of a term in time: (place in the log, the log's index) (:data:`WHEN_NAMES`)."""
    return ca.SX.sym("s", len(WHEN_NAMES))


def term_function(name: str, build: Callable, n_parameters: int) -> ca.Function:
    """A term Function (x (4), u (2), du (2), p) -> acc (2) from ``build(x, u, du, p)``."""
    x, u, du = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("du", 2)
    p = ca.SX.sym("p", n_parameters)
    acc = build(x, u, du, p)
    return ca.Function(name, [x, u, du, p], [ca.vertcat(acc)], ["x", "u", "du", "p"], ["acc"])


def term_function_in_time(name: str, build: Callable, n_parameters: int) -> ca.Function:
    """A term Function in time (x (4), u (2), du (2), s (2), p) -> acc (2) from
    ``build(x, u, du, s, p)``, s the sample's time (:func:`when_symbol`;
    :attr:`AccelerationTerm.in_time`)."""
    x, u, du, s = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("du", 2), when_symbol()
    p = ca.SX.sym("p", n_parameters)
    acc = build(x, u, du, s, p)
    return ca.Function(name, [x, u, du, s, p], [ca.vertcat(acc)], ["x", "u", "du", "s", "p"], ["acc"])


def _casadi_name(name: str) -> str:
    """A valid CasADi Function name from any term name (letters, digits, single underscores)."""
    clean = re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9]", "_", name)).strip("_")
    return clean if clean[:1].isalpha() else f"t_{clean}" if clean else "t"


def _as_four_inputs(fn: ca.Function, n_p: int, name: str, in_time: bool = False) -> ca.Function:
    """Accept (x, u, p) Functions too (no dependence on the current rates); a term ``in_time`` takes
    (x, u, du, s, p) (:attr:`AccelerationTerm.in_time`), s (2) = (place in the log, the log's index)
    or s (1), the place alone (the same in every log)."""
    shapes = [(fn.size1_in(k), fn.size2_in(k)) for k in range(fn.n_in())]
    if fn.n_out() != 1 or (fn.size1_out(0), fn.size2_out(0)) != (2, 1):
        raise InputError(
            f"AccelerationTerm {name}: function must return acc (2) = (x2', x4'); it returns "
            f"{fn.n_out()} output(s) of shape {(fn.size1_out(0), fn.size2_out(0)) if fn.n_out() else None}"
        )
    if in_time:
        if shapes == [(4, 1), (2, 1), (2, 1), (len(WHEN_NAMES), 1), (n_p, 1)]:
            return fn
        if shapes == [(4, 1), (2, 1), (2, 1), (1, 1), (n_p, 1)]:  # the place alone
            x, u, du, s = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("du", 2), when_symbol()
            p = ca.SX.sym("p", n_p)
            return ca.Function(
                fn.name(), [x, u, du, s, p], [fn(x, u, du, s[0], p)], ["x", "u", "du", "s", "p"], ["acc"]
            )
        raise InputError(
            f"AccelerationTerm {name}: a term in time must map (x (4), u (2), du (2), s (2: place in the "
            f"log, the log's index) or s (1: the place), p ({n_p})) -> acc (2); its inputs are {shapes}"
        )
    if shapes == [(4, 1), (2, 1), (n_p, 1)]:
        x, u, du, p = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("du", 2), ca.SX.sym("p", n_p)
        return ca.Function(fn.name(), [x, u, du, p], [fn(x, u, p)], ["x", "u", "du", "p"], ["acc"])
    if shapes == [(4, 1), (2, 1), (2, 1), (n_p, 1)]:
        return fn
    raise InputError(
        f"AccelerationTerm {name}: function must map (x (4), u (2), p ({n_p})) or (x (4), u (2), du (2), "
        f"p ({n_p})) -> acc (2); its inputs are {shapes}"
    )


@dataclass(frozen=True)
class AccelerationTerm:
    """An additive term in the accelerations (x2', x4') with its own parameters.

    Parameters
    ----------
    name : str
        Identifier (plain physical words; underscores allowed).
    explanation : str
        One sentence in physical terms.
    axis : {"vertical", "horizontal", "both"}
        The accelerations it acts on.
    parameter_names : tuple of str
    initial, scale, lower, upper : tuples of float, one per parameter
        Starting values (default 0), typical magnitudes (default 1; conditioning only) and bounds
        (default unbounded).
    function : casadi.Function
        (x (4), u (2), [du (2),] p) -> acc (2) [m/s^2] added to (x2', x4'); du are the current
        rates [A/s].
    physical : callable, optional
        (p, cov(p), constants) -> {name: Estimate}: the parameters in physical units.
    signature : str
        What in a residual points at this term (for reports).
    variants : tuple of casadi.Function
        Alternative functions with the same parameters' meaning for the hyper-parameters the
        term fixes (a friction reversal width, a gap exponent); their spread is a model-form
        uncertainty.
    variant_note : str
    in_time : bool
        The acceleration also changes over the log (a constant drifting as the rig warms): the
        function takes (x, u, du, s, p), s (2) = (the sample's place in its log, in [-1, 1] from
        the first sample to the last, and the index of its log among those fitted together;
        :data:`WHEN_NAMES`, :attr:`~maglev_oc.regression.data.PreparedLogs.log_time`), or s (1), the
        place alone. Where no time is at hand (:meth:`acceleration`: a controller's feedforward, a
        stage file) it is taken at s = (0, 0), the middle of the first log.
    optional : tuple of str
        Parameters a fit holds at zero when the logged currents' errors are most of their column
        (:data:`~maglev_oc.regression.solve.OPTIONAL_NOISE_SHARE`): nuisance parts that only matter
        where the data carry them (the share of the motor's force the guides hold while an axis
        sticks, on an axis that barely sticks).

    Attributes
    ----------
    linear : bool
        The accelerations are affine in p (then ``features`` gives the columns exactly).
    features : casadi.Function
        (x, u, du) -> d acc / d p, shape (2, n_p) (evaluated at p = initial when nonlinear).
    offset : casadi.Function
        (x, u, du) -> acc at p = 0 (zero for a linear term through the origin).
    """

    name: str
    explanation: str
    axis: str
    parameter_names: tuple[str, ...]
    initial: tuple[float, ...] = ()
    scale: tuple[float, ...] = ()
    lower: tuple[float, ...] = ()
    upper: tuple[float, ...] = ()
    function: ca.Function | None = None
    physical: PhysicalMap | None = field(default=None, repr=False, compare=False)
    signature: str = ""
    variants: tuple[ca.Function, ...] = field(default=(), repr=False, compare=False)
    variant_note: str = ""
    in_time: bool = False
    optional: tuple[str, ...] = ()
    linear: bool = field(init=False, compare=False)
    features: ca.Function = field(init=False, repr=False, compare=False)
    offset: ca.Function = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if not isinstance(self.name, str) or not self.name.strip():
            raise InputError(f"AccelerationTerm.name must be a non-empty string, got {self.name!r}")
        if self.axis not in AXES:
            raise InputError(f"AccelerationTerm {self.name}: axis must be one of {AXES}, got {self.axis!r}")
        names = tuple(self.parameter_names)
        n_p = len(names)
        if n_p == 0:
            raise InputError(f"AccelerationTerm {self.name}: needs at least one parameter")
        if len(set(names)) != n_p or not all(isinstance(p, str) and p.strip() for p in names):
            raise InputError(
                f"AccelerationTerm {self.name}: parameter_names must be distinct non-empty strings, "
                f"got {names!r}"
            )
        set_(self, "parameter_names", names)
        set_(self, "optional", tuple(self.optional))
        if not set(self.optional) <= set(names):
            raise InputError(
                f"AccelerationTerm {self.name}: optional {self.optional!r} are not all among its "
                f"parameters {names!r}"
            )
        defaults = {"initial": 0.0, "scale": 1.0, "lower": -math.inf, "upper": math.inf}
        for field_name, default in defaults.items():
            values = tuple(float(v) for v in getattr(self, field_name)) or (default,) * n_p
            if len(values) != n_p:
                raise InputError(
                    f"AccelerationTerm {self.name}: {field_name} has {len(values)} values for {n_p} "
                    f"parameters {names}"
                )
            set_(self, field_name, values)
        for p, x0, s, lo, hi in zip(names, self.initial, self.scale, self.lower, self.upper, strict=True):
            if not (math.isfinite(x0) and math.isfinite(s) and s > 0):
                raise InputError(
                    f"AccelerationTerm {self.name}.{p}: initial must be finite and scale positive, got "
                    f"initial={x0!r}, scale={s!r}"
                )
            if not (lo <= x0 <= hi) or lo == hi:
                raise InputError(
                    f"AccelerationTerm {self.name}.{p}: need lower <= initial <= upper and lower < upper, "
                    f"got {lo!r} <= {x0!r} <= {hi!r}"
                )
        if not isinstance(self.function, ca.Function):
            raise InputError(f"AccelerationTerm {self.name}: function must be a casadi.Function")
        fn = _as_four_inputs(self.function, n_p, self.name, self.in_time)
        set_(self, "function", fn)
        set_(self, "variants", tuple(_as_four_inputs(v, n_p, self.name, self.in_time) for v in self.variants))
        x, u, du, p = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("du", 2), ca.SX.sym("p", n_p)
        s = when_symbol()
        acc = self.evaluate(x, u, du, s, p)
        jac = ca.jacobian(acc, p)
        p0 = ca.DM(self.initial)
        set_(self, "linear", not ca.depends_on(jac, p))
        inputs, names = [x, u, du], ["x", "u", "du"]
        if self.in_time:
            inputs, names = [*inputs, s], [*names, "s"]
        set_(
            self,
            "features",
            ca.Function(f"{_casadi_name(self.name)}_F", inputs, [ca.substitute(jac, p, p0)], names, ["F"]),
        )
        set_(
            self,
            "offset",
            ca.Function(
                f"{_casadi_name(self.name)}_0",
                inputs,
                [ca.substitute(acc, p, ca.DM.zeros(n_p))],
                names,
                ["acc"],
            ),
        )

    def evaluate(self, x, u, du, s, p):
        """The acceleration (2) at the state ``x``, currents ``u``, their rates ``du``, the time ``s``
        (2: place in the log, the log's index; read only by a term :attr:`in_time`) and the
        parameters ``p``."""
        return self.function(x, u, du, s, p) if self.in_time else self.function(x, u, du, p)

    @property
    def n_parameters(self) -> int:
        return len(self.parameter_names)

    @property
    def qualified_names(self) -> tuple[str, ...]:
        """Parameter names as the fits report them: ``"<term>.<parameter>"``."""
        return tuple(f"{self.name}.{p}" for p in self.parameter_names)

    def is_linear(self) -> bool:
        """True when the term is linear in its parameters (then a linear LS solve is exact)."""
        return self.linear

    def depends_on_inputs(self) -> bool:
        """Whether the term depends on the currents or their rates (not the state alone)."""
        acc, u, du = self._symbolic()
        return bool(ca.depends_on(acc, u) or ca.depends_on(acc, du))

    def depends_on_rates(self) -> bool:
        """Whether the term depends on the currents' rates du (an amplifier's lag)."""
        acc, _, du = self._symbolic()
        return bool(ca.depends_on(acc, du))

    def _symbolic(self) -> tuple[ca.SX, ca.SX, ca.SX]:
        """(acc, u, du): the term's accelerations in symbols (x, u, du, [s,] p)."""
        x, u, du = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("du", 2)
        return self.evaluate(x, u, du, when_symbol(), ca.SX.sym("p", self.n_parameters)), u, du

    def acceleration(self, parameters) -> ca.Function:
        """(x, u, du) -> acc (2) with the parameters fixed (a term :attr:`in_time` at the middle of
        the first log, s = (0, 0))."""
        x, u, du = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("du", 2)
        p = ca.DM(np.asarray(parameters, dtype=float).ravel())
        return ca.Function(
            f"{_casadi_name(self.name)}_acc",
            [x, u, du],
            [self.evaluate(x, u, du, ca.DM.zeros(len(WHEN_NAMES)), p)],
            ["x", "u", "du"],
            ["acc"],
        )

    def acceleration_in_time(self, parameters) -> ca.Function:
        """(x, u, du, s) -> acc (2) with the parameters fixed, s (2) the place in the log and the
        log's index (see :attr:`in_time`; a term not in time ignores it)."""
        x, u, du, s = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("du", 2), when_symbol()
        p = ca.DM(np.asarray(parameters, dtype=float).ravel())
        return ca.Function(
            f"{_casadi_name(self.name)}_acc_t",
            [x, u, du, s],
            [self.evaluate(x, u, du, s, p)],
            ["x", "u", "du", "s"],
            ["acc"],
        )

    def with_function(self, function: ca.Function) -> AccelerationTerm:
        """The same term with another function (one of its variants), without variants."""
        import dataclasses

        return dataclasses.replace(self, function=function, variants=())

    def physical_parameters(
        self, p: np.ndarray, cov: np.ndarray, constants: Mapping[str, float] | None = None
    ) -> dict[str, Estimate]:
        """The parameters in physical units (default: the parameters themselves, no unit)."""
        p = np.asarray(p, dtype=float)
        cov = np.asarray(cov, dtype=float)
        if self.physical is not None:
            return self.physical(p, cov, constants or {})
        return {
            n: Estimate(float(p[k]), float(math.sqrt(max(cov[k, k], 0.0))), "")
            for k, n in enumerate(self.parameter_names)
        }


def is_linear_in_parameters(function: ca.Function, parameter_input: int | None = None) -> bool:
    """Whether ``function`` is affine in its last input (or ``parameter_input``), symbolically."""
    k = function.n_in() - 1 if parameter_input is None else parameter_input
    args = [ca.SX.sym(f"a{i}", function.sparsity_in(i)) for i in range(function.n_in())]
    out = function(*args)
    out = out[0] if isinstance(out, (list, tuple)) else out
    return not ca.depends_on(ca.jacobian(out, args[k]), args[k])


# --- physical conversions (delta method) ------------------------------------------------------
def _sd(var: float) -> float:
    return float(math.sqrt(max(var, 0.0)))


def linear_physical(names_units_scales) -> PhysicalMap:
    """Each parameter times a scale is a physical quantity: [(name, unit, scale), ...]."""

    def convert(p, cov, constants):
        return {
            name: Estimate(float(p[k] * scale), _sd(cov[k, k]) * abs(scale), unit)
            for k, (name, unit, scale) in enumerate(names_units_scales)
        }

    return convert


def amplitude_phase(
    unit: str, scale: float = 1.0, extra: Mapping[str, Estimate] | None = None
) -> PhysicalMap:
    """(a sin + b cos) -> amplitude sqrt(a^2 + b^2) * scale [unit] and phase atan2(b, a) [rad]."""

    def convert(p, cov, constants):
        a, b = float(p[0]), float(p[1])
        amp = math.hypot(a, b)
        if amp > 0:
            g = np.array([a, b]) / amp
            h = np.array([-b, a]) / amp**2
            s_amp, s_ph = _sd(g @ cov[:2, :2] @ g), _sd(h @ cov[:2, :2] @ h)
        else:
            s_amp = s_ph = float("nan")
        out = {
            "amplitude": Estimate(amp * scale, s_amp * abs(scale), unit),
            "phase": Estimate(math.atan2(b, a), s_ph, "rad"),
        }
        out.update(extra or {})
        return out

    return convert


def _put(axis: str, expr):
    return ca.vertcat(expr, 0) if axis == "vertical" else ca.vertcat(0, expr)


def _mass(params: StageParameters, axis: str) -> float:
    return params.mass_vertical if axis == "vertical" else params.mass_horizontal


# --- physical terms ----------------------------------------------------------------------------
REVERSAL_SPEED = 2e-3
"""[m/s] Over which guide friction's sign is smoothed and below which an axis counts as stuck
(:func:`guide_friction`)."""


def held_by_guides(term: AccelerationTerm, held: Mapping[str, float]) -> AccelerationTerm:
    """``term`` with the share of its force that sticking guides hold taken off.

    ``held``: axis -> share h (0..1) of the force the guides of that axis hold while it sticks (the
    friction term's ``holding``). Static friction holds a stuck axis against every force on it, not
    only the motor's: the term's acceleration on that axis is multiplied by 1 - h exp(-(v / v_s)^2),
    v the axis velocity and v_s :data:`REVERSAL_SPEED`, as the friction term holds the modelled one.
    """
    x, u, du, s = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("du", 2), when_symbol()
    scale = ca.vertcat(
        *(
            1 - min(max(held.get(axis, 0.0), 0.0), 1.0) * ca.exp(-((x[vi] / REVERSAL_SPEED) ** 2))
            for axis, vi in (("vertical", 1), ("horizontal", 3))
        )
    )

    def wrap(fn: ca.Function) -> ca.Function:
        if term.in_time:  # (x, u, du, s, p)
            p = ca.SX.sym("p", fn.size1_in(4))
            return ca.Function(
                fn.name(), [x, u, du, s, p], [fn(x, u, du, s, p) * scale], ["x", "u", "du", "s", "p"], ["acc"]
            )
        p = ca.SX.sym("p", fn.size1_in(3))
        return ca.Function(
            fn.name(), [x, u, du, p], [fn(x, u, du, p) * scale], ["x", "u", "du", "p"], ["acc"]
        )

    return dataclasses.replace(
        term, function=wrap(term.function), variants=tuple(wrap(v) for v in term.variants)
    )


def guide_friction(
    params: StageParameters,
    axis: str,
    *,
    reversal_speed: float = REVERSAL_SPEED,
    holding: Callable | None = None,
    holding_in_time: bool = False,
    stick_speed: float | None = None,
    viscous: bool = True,
    stribeck_speed: float | None = None,
    name: str | None = None,
    explanation: str | None = None,
) -> AccelerationTerm:
    """Coulomb plus viscous friction of the linear guides on one axis, optionally with sticking.

    acc += -(F_c tanh(v / v_r) + c v) / M, parameters (F_c [N], c [N s/m]); v the axis velocity
    (x2 or x4), M its mass. sign(v) is smoothed over ``reversal_speed`` v_r [m/s] (the SG
    velocity's noise at 1 kHz is about 0.1 mm/s, so 2 mm/s keeps the sign reliable while
    resolving reversals); variants at v_r / 2 and 2 v_r.

    ``holding`` (x, u) -> the axis's modelled acceleration adds a third parameter, the share h
    of it that the guides hold while the axis sticks: acc += -h a_model(x, u) exp(-(v / v_s)^2),
    v_s = ``stick_speed`` (default the reversal speed: below it the axis is as good as stopped for
    the encoder, whose 10 um over a 10 Hz band resolve about 1 mm/s). Static friction (with the
    micrometre pre-sliding of ball guides, far
    below the encoder's resolution) holds a stuck axis against whatever the motor applies, up to
    the breakaway force; without this column the stuck samples (no acceleration under a changing
    current) pull the motor constants towards zero.

    ``holding_in_time``: ``holding`` is (x, u, s) -> that acceleration, s the sample's time
    (:func:`when_symbol`), and the term is :attr:`~AccelerationTerm.in_time` (what a stuck axis
    holds differs between logs that carry different payloads).

    ``viscous=False`` leaves the viscous part out (c = 0: the friction with its viscous coefficient
    held at its physical bound).

    ``stribeck_speed`` v_st [m/s] adds the Stribeck rise of the friction at low speed, a parameter
    F_x = F_s - F_c [N] (breakaway force F_s above the Coulomb force): acc += -F_x tanh(v / v_r)
    exp(-(v / v_st)^2) / M, the steady-sliding friction of the LuGre model (Canudas de Wit et al.
    1995) with its shape exponent 2, the Stribeck speed fixed (scaled with the variants).
    """
    if axis not in ("vertical", "horizontal"):
        raise InputError(f"axis must be 'vertical' or 'horizontal', got {axis!r}")
    stick_speed = reversal_speed if stick_speed is None else stick_speed
    if not (reversal_speed > 0 and stick_speed > 0):
        raise InputError(
            f"reversal_speed and stick_speed must be positive [m/s], got {reversal_speed!r}, {stick_speed!r}"
        )
    if stribeck_speed is not None and not stribeck_speed > 0:
        raise InputError(f"stribeck_speed must be positive [m/s], got {stribeck_speed!r}")
    vi = 1 if axis == "vertical" else 3
    m = _mass(params, axis)
    units = {"coulomb": "N", "viscous": "N s/m", "stribeck_rise": "N", "holding": "1"}
    names = tuple(
        n
        for n, on in (
            ("coulomb", True),
            ("viscous", viscous),
            ("stribeck_rise", stribeck_speed is not None),
            ("holding", holding is not None),
        )
        if on
    )
    k = len(names)

    def fn(width):
        stick = stick_speed * width / reversal_speed  # the variants scale every speed
        slide = None if stribeck_speed is None else stribeck_speed * width / reversal_speed

        def build(x, u, du, p, s=None):
            q = dict(zip(names, (p[i] for i in range(k)), strict=True))
            sign = ca.tanh(x[vi] / width)
            acc = -(q["coulomb"] * sign + q.get("viscous", 0) * x[vi]) / m
            if slide is not None:
                acc = acc - q["stribeck_rise"] * sign * ca.exp(-((x[vi] / slide) ** 2)) / m
            if holding is not None:
                held = holding(x, u, s) if holding_in_time else holding(x, u)
                acc = acc - q["holding"] * held * ca.exp(-((x[vi] / stick) ** 2))
            return _put(axis, acc)

        form = ("" if viscous else "_coulomb") + ("_stribeck" if stribeck_speed is not None else "")
        if not holding_in_time:
            return term_function(f"friction_{axis}{form}", build, k)
        return term_function_in_time(
            f"friction_{axis}{form}", lambda x, u, du, s, p: build(x, u, du, p, s), k
        )

    if holding_in_time and holding is None:
        raise ValueError("guide_friction: holding_in_time without a holding")
    physical = [(n, units[n], 1.0) for n in names]
    return AccelerationTerm(
        # the holding share is left out of a fit where the logged currents' errors are most of its
        # column: an axis that barely sticks (a viscous damping of 20 N s/m beside 0.1 N of Coulomb
        # friction on a noisy independent log, 1.2 times its variance) gives it no signal, and fitted
        # it stopped the errors' compensation where the equations are nearly singular (the damping
        # refused as made of those errors; at 0.68 of them a holding share of -0.8 and -25 N s/m)
        optional=("holding",) if holding is not None else (),
        name=name or f"guide_friction_{axis}",
        explanation=explanation
        or (
            f"The {axis} linear guides resist motion with a force of constant size opposing the velocity "
            "(Coulomb)"
            + (" plus a part growing with speed (viscous)" if viscous else "")
            + (", larger below a few mm/s (Stribeck)" if stribeck_speed is not None else "")
            + (", and hold the axis while it sticks." if holding is not None else ".")
        ),
        axis=axis,
        parameter_names=names,
        scale=(1.0,) * k,
        function=fn(reversal_speed),
        physical=linear_physical(physical),
        signature="residual steps with the sign of the velocity",
        in_time=holding_in_time,
        variants=(fn(reversal_speed / 2), fn(reversal_speed * 2)),
        variant_note=f"reversal speed {reversal_speed / 2 * 1e3:g}-{reversal_speed * 2 * 1e3:g} mm/s"
        + (
            f" (Stribeck speed {stribeck_speed / 2 * 1e3:g}-{stribeck_speed * 2 * 1e3:g} mm/s)"
            if stribeck_speed is not None
            else ""
        ),
    )


def constant_force(
    params: StageParameters, axis: str, *, name: str | None = None, explanation: str | None = None
) -> AccelerationTerm:
    """A constant force F [N] on one axis, positive along +x3 (horizontal) or towards the stator
    (vertical: it closes the gap, acc x2' -= F / M_v)."""
    if axis not in ("vertical", "horizontal"):
        raise InputError(f"axis must be 'vertical' or 'horizontal', got {axis!r}")
    m = _mass(params, axis)
    sign = -1.0 if axis == "vertical" else 1.0
    return AccelerationTerm(
        name=name or f"constant_force_{axis}",
        explanation=explanation or f"A constant {axis} force the model lacks.",
        axis=axis,
        parameter_names=("force",),
        function=term_function(f"force_{axis}", lambda x, u, du, p: _put(axis, sign * p[0] / m), 1),
        physical=linear_physical([("force", "N", 1.0)]),
        signature=f"constant residual on the {axis} axis",
    )


def periodic_force(
    params: StageParameters,
    axis: str,
    period: float,
    *,
    gap_exponent: float = 0.0,
    reference_gap: float = REFERENCE_GAP,
    name: str | None = None,
    explanation: str | None = None,
    exponent_variants: tuple[float, ...] = (),
) -> AccelerationTerm:
    """A force periodic in the horizontal position, optionally growing as the gap closes.

    F = (a sin(2 pi x3 / period) + b cos(2 pi x3 / period)) (reference_gap / x1)^gap_exponent,
    parameters (a, b) [N] (the peak at the reference gap is sqrt(a^2 + b^2)); on the vertical axis
    positive F pulls towards the stator (x2' -= F / M_v), on the horizontal axis it pushes along +x3.
    """
    if axis not in ("vertical", "horizontal"):
        raise InputError(f"axis must be 'vertical' or 'horizontal', got {axis!r}")
    if not (period > 0 and reference_gap > 0 and gap_exponent >= 0):
        raise InputError(
            f"need period > 0, reference_gap > 0, gap_exponent >= 0, got {period!r}, "
            f"{reference_gap!r}, {gap_exponent!r}"
        )
    m = _mass(params, axis)
    sign = -1.0 if axis == "vertical" else 1.0

    def fn(exponent):
        def build(x, u, du, p):
            arg = 2 * math.pi * x[2] / period
            scale = (reference_gap / x[0]) ** exponent if exponent else 1.0
            return _put(axis, sign * (p[0] * ca.sin(arg) + p[1] * ca.cos(arg)) * scale / m)

        return term_function(f"periodic_{axis}", build, 2)

    extra = {"period": Estimate(period, 0.0, "m")}
    if gap_exponent:
        extra["at_gap"] = Estimate(reference_gap, 0.0, "m")
    return AccelerationTerm(
        name=name or f"periodic_force_{axis}_{period * 1e3:.1f}mm",
        explanation=explanation or f"A {axis} force periodic in the position over {period * 1e3:.2f} mm.",
        axis=axis,
        parameter_names=("sin", "cos"),
        function=fn(gap_exponent),
        physical=amplitude_phase("N", 1.0, extra),
        signature=f"residual periodic in x3 with period {period * 1e3:.1f} mm",
        variants=tuple(fn(e) for e in exponent_variants),
        variant_note=(
            f"gap exponent {min(exponent_variants):g}-{max(exponent_variants):g}" if exponent_variants else ""
        ),
    )


def cogging_force(
    params: StageParameters,
    axis: str,
    period: float,
    *,
    harmonics: int = 2,
    reference_gap: float = REFERENCE_GAP,
    decay_scale: float = 1.0,
    scale_variants: tuple[float, ...] = (0.7, 1.4),
    name: str | None = None,
    explanation: str | None = None,
) -> AccelerationTerm:
    """Cogging (normal) or detent (longitudinal) force of a slotted stator: periodic in the position,
    decaying with the gap as the field harmonics that make it.

    F = sum_k (a_k sin(2 pi k x3 / P) + b_k cos(2 pi k x3 / P)) exp(-(x1 - g_ref) / d_k),
    k = 1..``harmonics``, P = ``period``, d_k = decay_scale P / (2 pi k): a spatial harmonic of
    wavelength P / k in the air gap decays as exp(-2 pi k y / P) away from its source (Laplace's
    equation in the gap), so the force of the k-th harmonic decays with that length. Parameters
    (a_1, b_1, a_2, b_2, ...) [N] at ``reference_gap``; on the vertical axis positive F pulls towards
    the stator. Variants: decay lengths scaled by ``scale_variants``.
    """
    if axis not in ("vertical", "horizontal"):
        raise InputError(f"axis must be 'vertical' or 'horizontal', got {axis!r}")
    if not (period > 0 and reference_gap > 0 and decay_scale > 0 and harmonics >= 1):
        raise InputError("need period > 0, reference_gap > 0, decay_scale > 0, harmonics >= 1")
    m = _mass(params, axis)
    sign = -1.0 if axis == "vertical" else 1.0

    def fn(scale):
        def build(x, u, du, p):
            total = 0
            for k in range(1, harmonics + 1):
                arg = 2 * math.pi * k * x[2] / period
                decay = ca.exp(-(x[0] - reference_gap) * 2 * math.pi * k / (scale * period))
                total = total + (p[2 * k - 2] * ca.sin(arg) + p[2 * k - 1] * ca.cos(arg)) * decay
            return _put(axis, sign * total / m)

        return term_function(f"cogging_{axis}", build, 2 * harmonics)

    def physical(q, cov, constants):
        out = amplitude_phase("N", 1.0)(q[:2], cov[:2, :2], constants)
        for k in range(2, harmonics + 1):
            sub = amplitude_phase("N", 1.0)(
                q[2 * k - 2 : 2 * k], cov[2 * k - 2 : 2 * k, 2 * k - 2 : 2 * k], constants
            )
            out[f"harmonic{k}_amplitude"] = sub["amplitude"]
        out["period"] = Estimate(period, 0.0, "m")
        out["at_gap"] = Estimate(reference_gap, 0.0, "m")
        out["decay_length"] = Estimate(decay_scale * period / (2 * math.pi), 0.0, "m")
        return out

    names = tuple(f"{w}{k}" for k in range(1, harmonics + 1) for w in ("sin", "cos"))
    return AccelerationTerm(
        name=name or f"cogging_{axis}_{period * 1e3:.0f}mm",
        explanation=explanation or f"A {axis} cogging force periodic over {period * 1e3:.2f} mm.",
        axis=axis,
        parameter_names=names,
        function=fn(decay_scale),
        physical=physical,
        signature=f"residual periodic in x3 with period {period * 1e3:.1f} mm, larger at small gaps",
        variants=tuple(fn(decay_scale * v) for v in scale_variants),
        variant_note=f"decay length x{min(scale_variants):g}-x{max(scale_variants):g}"
        if scale_variants
        else "",
    )


def cogging_term(
    params: StageParameters | None = None, *, reference_gap: float = REFERENCE_GAP, exponent: float = 3.0
) -> AccelerationTerm:
    """Normal cogging force, eq. (9) of paper 000, with an unknown peak and phase.

    x2' += -[(a_s sin(pi x3 / t1) + a_c cos(pi x3 / t1)) (reference_gap / x1)^exponent] / M_v,
    a_s, a_c [N]: the peak xi(reference_gap) = sqrt(a_s^2 + a_c^2), linear in (a_s, a_c).
    """
    p = StageParameters() if params is None else params
    if not (reference_gap > 0 and exponent >= 0):
        raise InputError(f"need reference_gap > 0 and exponent >= 0, got {reference_gap!r}, {exponent!r}")
    term = periodic_force(
        p,
        "vertical",
        2 * p.slot_pitch,
        gap_exponent=exponent,
        reference_gap=reference_gap,
        name="cogging",
        explanation=(
            "Attraction between the stator teeth and the magnet edges adds a normal force periodic "
            "in the mover position over two slot pitches, growing as the gap closes (000 eq. (9))."
        ),
    )
    import dataclasses

    return dataclasses.replace(term, parameter_names=("sin_peak", "cos_peak"))


def constant_acceleration(axis: str) -> AccelerationTerm:
    """A constant acceleration [m/s^2] on one axis: a level error of the guides (horizontal,
    G sin(tilt), 001's Delta_1) or a weight error (vertical)."""
    if axis not in ("vertical", "horizontal"):
        raise InputError(f"axis must be 'vertical' or 'horizontal', got {axis!r}")
    what = "a weight or gravity error" if axis == "vertical" else "guides that are not level"
    return AccelerationTerm(
        name=f"bias_{axis}",
        explanation=f"A constant {axis} force, from {what}, shifts the {axis} acceleration.",
        axis=axis,
        parameter_names=("acceleration",),
        scale=(0.01,),
        function=term_function(f"bias_{axis}", lambda x, u, du, p: _put(axis, p[0]), 1),
    )


def viscous_friction(axis: str) -> AccelerationTerm:
    """Viscous guide friction on one axis: acc += -c v, c [1/s] (force / mass / speed)."""
    if axis not in ("vertical", "horizontal"):
        raise InputError(f"axis must be 'vertical' or 'horizontal', got {axis!r}")
    vi = 1 if axis == "vertical" else 3
    return AccelerationTerm(
        name=f"viscous_{axis}",
        explanation=f"The {axis} linear guides resist motion in proportion to the speed.",
        axis=axis,
        parameter_names=("rate",),
        function=term_function(f"viscous_{axis}", lambda x, u, du, p: _put(axis, -p[0] * x[vi]), 1),
    )
