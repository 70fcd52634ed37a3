"""Additive acceleration terms fitted jointly with the lumped constants.

The base model's accelerations are linear in C1..C4 (eq. (2) of paper 000):

    (x2', x4') = Phi(x, u) C + b + sum_k term_k(x, u, p_k)

An :class:`AccelerationTerm` is one such extra contribution with its own parameters, for an
effect the papers' model leaves out (cogging, friction, a level offset, ...). Both fits
(:mod:`~maglev_oc.identify.equation_error`, :mod:`~maglev_oc.identify.output_error`) take a
sequence of them and estimate their parameters together with the chosen constants. The
diagnosis layer builds its candidate effects as terms.

A few terms with the papers' physics are provided (:func:`cogging_term`,
:func:`constant_acceleration`, :func:`viscous_friction`); each is linear in its parameters,
so a fit with them stays a linear least-squares problem.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca

from maglev_oc.model.parameters import StageParameters

AXES = ("vertical", "horizontal", "both")


@dataclass(frozen=True)
class AccelerationTerm:
    """An additive term in the accelerations (x2', x4') with its own parameters."""

    name: str
    explanation: str  # one sentence, physical
    axis: str  # "vertical" | "horizontal" | "both"
    parameter_names: tuple[str, ...]
    initial: tuple[float, ...]  # initial guesses
    scale: tuple[float, ...]  # typical magnitudes (for conditioning / x_scale)
    lower: tuple[float, ...]  # bounds (use -inf/inf when free)
    upper: tuple[float, ...]
    function: ca.Function  # (x (4), u (2), p (n_p)) -> acc (2,) [m/s^2] added to (x2', x4')

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"AccelerationTerm.name must be a non-empty string, got {self.name!r}")
        if self.axis not in AXES:
            raise ValueError(f"AccelerationTerm {self.name}: axis must be one of {AXES}, got {self.axis!r}")
        names = tuple(self.parameter_names)
        n_p = len(names)
        if n_p == 0:
            raise ValueError(f"AccelerationTerm {self.name}: needs at least one parameter")
        if len(set(names)) != n_p or not all(isinstance(p, str) and p.strip() for p in names):
            raise ValueError(
                f"AccelerationTerm {self.name}: parameter_names must be distinct non-empty strings, got "
                f"{names!r}"
            )
        object.__setattr__(self, "parameter_names", names)
        for field_name in ("initial", "scale", "lower", "upper"):
            values = tuple(float(v) for v in getattr(self, field_name))
            if len(values) != n_p:
                raise ValueError(
                    f"AccelerationTerm {self.name}: {field_name} has {len(values)} values for {n_p} "
                    f"parameters {names}"
                )
            object.__setattr__(self, field_name, values)
        for p, x0, s, lo, hi in zip(names, self.initial, self.scale, self.lower, self.upper, strict=True):
            if not (math.isfinite(x0) and math.isfinite(s) and s > 0):
                raise ValueError(
                    f"AccelerationTerm {self.name}.{p}: initial must be finite and scale positive, got "
                    f"initial={x0!r}, scale={s!r}"
                )
            if not (lo <= x0 <= hi) or lo == hi:
                raise ValueError(
                    f"AccelerationTerm {self.name}.{p}: need lower <= initial <= upper and lower < upper, "
                    f"got {lo!r} <= {x0!r} <= {hi!r}"
                )
        f = self.function
        if not isinstance(f, ca.Function):
            raise ValueError(f"AccelerationTerm {self.name}: function must be a casadi.Function")
        shapes_in = [(f.size1_in(k), f.size2_in(k)) for k in range(f.n_in())]
        if f.n_in() != 3 or shapes_in != [(4, 1), (2, 1), (n_p, 1)] or f.n_out() != 1:
            raise ValueError(
                f"AccelerationTerm {self.name}: function must map (x (4), u (2), p ({n_p})) -> acc (2); "
                f"its inputs are {shapes_in} with {f.n_out()} output(s)"
            )
        if (f.size1_out(0), f.size2_out(0)) != (2, 1):
            raise ValueError(
                f"AccelerationTerm {self.name}: output must be (2, 1) = (x2', x4'), got "
                f"{(f.size1_out(0), f.size2_out(0))}"
            )

    @property
    def n_parameters(self) -> int:
        return len(self.parameter_names)

    @property
    def qualified_names(self) -> tuple[str, ...]:
        """Parameter names as the fits report them: ``"<term>.<parameter>"``."""
        return tuple(f"{self.name}.{p}" for p in self.parameter_names)

    def is_linear(self) -> bool:
        """True when the term is linear in its parameters (then a linear LS solve is exact)."""
        return is_linear_in_parameters(self.function)


def is_linear_in_parameters(function: ca.Function, parameter_input: int = 2) -> bool:
    """Whether ``function`` is affine in its input ``parameter_input`` (symbolic check)."""
    args = [ca.SX.sym(f"a{k}", function.sparsity_in(k)) for k in range(function.n_in())]
    out = function(*args)
    out = out[0] if isinstance(out, (list, tuple)) else out
    p = args[parameter_input]
    jac = ca.jacobian(out, p)
    return not ca.depends_on(jac, p)


# --- a few terms with the papers' physics ----------------------------------------------------
def cogging_term(
    params: StageParameters | None = None,
    *,
    reference_gap: float = 15e-3,
    exponent: float = 3.0,
) -> AccelerationTerm:
    """Normal cogging force, eq. (9) of paper 000, with an unknown peak and phase.

    x2' += -[(a_s sin(pi x3 / t1) + a_c cos(pi x3 / t1)) (reference_gap / x1)^exponent] / M_v,
    a_s, a_c [N]: the peak xi(reference_gap) = sqrt(a_s^2 + a_c^2), linear in (a_s, a_c).
    """
    p = StageParameters() if params is None else params
    if not (reference_gap > 0 and exponent >= 0):
        raise ValueError(f"need reference_gap > 0 and exponent >= 0, got {reference_gap!r}, {exponent!r}")
    x, u, th = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("p", 2)
    angle = math.pi * x[2] / p.slot_pitch
    scale = (reference_gap / x[0]) ** exponent
    acc_v = -(th[0] * ca.sin(angle) + th[1] * ca.cos(angle)) * scale / p.mass_vertical
    fn = ca.Function("cogging", [x, u, th], [ca.vertcat(acc_v, 0)], ["x", "u", "p"], ["acc"])
    return AccelerationTerm(
        name="cogging",
        explanation=(
            "Attraction between the stator teeth and the magnet edges adds a normal force periodic in the "
            "mover position over one slot pitch, growing as the gap closes (000 eq. (9))."
        ),
        axis="vertical",
        parameter_names=("sin_peak", "cos_peak"),
        initial=(0.0, 0.0),
        scale=(1.0, 1.0),
        lower=(-math.inf, -math.inf),
        upper=(math.inf, math.inf),
        function=fn,
    )


def constant_acceleration(axis: str) -> AccelerationTerm:
    """A constant acceleration [m/s^2] on one axis: a level error of the guides (horizontal,
    G sin(tilt), 001's Delta_1) or a weight error (vertical)."""
    if axis not in ("vertical", "horizontal"):
        raise ValueError(f"axis must be 'vertical' or 'horizontal', got {axis!r}")
    x, u, th = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("p", 1)
    acc = ca.vertcat(th[0], 0) if axis == "vertical" else ca.vertcat(0, th[0])
    fn = ca.Function(f"bias_{axis}", [x, u, th], [acc], ["x", "u", "p"], ["acc"])
    what = "a weight or gravity error" if axis == "vertical" else "guides that are not level"
    return AccelerationTerm(
        name=f"bias_{axis}",
        explanation=f"A constant {axis} force, from {what}, shifts the {axis} acceleration.",
        axis=axis,
        parameter_names=("acceleration",),
        initial=(0.0,),
        scale=(0.01,),
        lower=(-math.inf,),
        upper=(math.inf,),
        function=fn,
    )


def viscous_friction(axis: str) -> AccelerationTerm:
    """Viscous guide friction on one axis: acc += -c v, c [1/s] (force / mass / speed)."""
    if axis not in ("vertical", "horizontal"):
        raise ValueError(f"axis must be 'vertical' or 'horizontal', got {axis!r}")
    x, u, th = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("p", 1)
    acc = ca.vertcat(-th[0] * x[1], 0) if axis == "vertical" else ca.vertcat(0, -th[0] * x[3])
    fn = ca.Function(f"viscous_{axis}", [x, u, th], [acc], ["x", "u", "p"], ["acc"])
    return AccelerationTerm(
        name=f"viscous_{axis}",
        explanation=f"The {axis} linear guides resist motion in proportion to the speed.",
        axis=axis,
        parameter_names=("rate",),
        initial=(0.0,),
        scale=(1.0,),
        lower=(-math.inf,),
        upper=(math.inf,),
        function=fn,
    )
