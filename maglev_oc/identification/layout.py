"""The vector of parameters a fit estimates, and the model's accelerations as a function of it.

Both fits estimate theta = (chosen constants among C1..C4, optionally ``gap_offset``, then the
parameters of every :class:`~maglev_oc.identification.terms.AccelerationTerm`), in that order. The
constants not chosen are held at the model's values.

``gap_offset`` [m] is a mounting offset of the gap encoder: the true gap is the reading plus
the offset, and the physics (L1..L4 and every term) sees the true gap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.model.stage import StageModel
from maglev_oc.regression.base import (
    CONSTANT_NAMES,
    ESTIMABLE,
    GAP_OFFSET,
    GAP_OFFSET_BOUND,
    GAP_OFFSET_SCALE,
    UNITS,
)
from maglev_oc.regression.terms import AccelerationTerm

__all__ = ["ParameterLayout"]


@dataclass(frozen=True, eq=False)
class ParameterLayout:
    """Which parameters are estimated, their initial values, scales and bounds, and the model.

    Parameters
    ----------
    model : StageModel
        Geometry and the values of the constants that are held fixed (and the initial guesses).
    estimate : sequence of str
        Names among ``C1, C2, C3, C4, gap_offset`` (default the four constants).
    terms : sequence of AccelerationTerm

    Attributes
    ----------
    names, initial, scale, lower, upper : tuples, one entry per estimated parameter
    acceleration_reading : Function (x (4), u (2), theta) -> (x2', x4') [m/s^2] with x1 the gap
        *reading* (the offset is added inside)
    acceleration_true : Function (x, u, theta) -> (x2', x4') with x1 the true gap
    linear : bool
        The accelerations are affine in theta (no offset, every term linear).
    """

    model: StageModel
    estimate: tuple[str, ...] = CONSTANT_NAMES
    terms: tuple[AccelerationTerm, ...] = ()
    names: tuple[str, ...] = field(init=False)
    initial: tuple[float, ...] = field(init=False)
    scale: tuple[float, ...] = field(init=False)
    lower: tuple[float, ...] = field(init=False)
    upper: tuple[float, ...] = field(init=False)
    acceleration_reading: ca.Function = field(init=False, repr=False)
    acceleration_true: ca.Function = field(init=False, repr=False)
    linear: bool = field(init=False)

    def __post_init__(self) -> None:
        if not isinstance(self.model, StageModel):
            raise TypeError(f"model must be a StageModel, got {type(self.model).__name__}")
        estimate = (self.estimate,) if isinstance(self.estimate, str) else tuple(self.estimate)
        unknown = [e for e in estimate if e not in ESTIMABLE]
        if unknown:
            raise InputError(f"estimate: unknown name(s) {unknown}; choose among {ESTIMABLE}")
        if len(set(estimate)) != len(estimate):
            raise InputError(f"estimate: duplicate names in {estimate!r}")
        terms = tuple(self.terms)
        for term in terms:
            if not isinstance(term, AccelerationTerm):
                raise TypeError(f"terms must be AccelerationTerm, got {type(term).__name__}")
            if term.in_time:
                raise InputError(
                    f"terms: {term.name} changes over the log (in_time); the output-error fit simulates "
                    "without the logs' times, so it takes only terms of the state and the currents"
                )
        term_names = [t.name for t in terms]
        if len(set(term_names)) != len(term_names):
            raise InputError(f"terms: duplicate names {term_names}")
        if not estimate and not terms:
            raise InputError("nothing to estimate: give constants in estimate or at least one term")
        object.__setattr__(self, "estimate", estimate)
        object.__setattr__(self, "terms", terms)

        consts = self.model.constants
        names, initial, scale, lower, upper = [], [], [], [], []
        for c in CONSTANT_NAMES:
            if c in estimate:
                value = getattr(consts, c)
                names.append(c)
                initial.append(value)
                scale.append(abs(value))
                lower.append(0.0)
                upper.append(math.inf)
        if GAP_OFFSET in estimate:
            names.append(GAP_OFFSET)
            initial.append(0.0)
            scale.append(GAP_OFFSET_SCALE)
            lower.append(-GAP_OFFSET_BOUND)
            upper.append(GAP_OFFSET_BOUND)
        for term in terms:
            names.extend(term.qualified_names)
            initial.extend(term.initial)
            scale.extend(term.scale)
            lower.extend(term.lower)
            upper.extend(term.upper)
        object.__setattr__(self, "names", tuple(names))
        object.__setattr__(self, "initial", tuple(initial))
        object.__setattr__(self, "scale", tuple(scale))
        object.__setattr__(self, "lower", tuple(lower))
        object.__setattr__(self, "upper", tuple(upper))
        self._build()

    # ------------------------------------------------------------------------------------
    def _build(self) -> None:
        n = len(self.names)
        x = ca.SX.sym("x", 4)
        u = ca.SX.sym("u", 2)
        theta = ca.SX.sym("theta", n)
        consts = self.model.constants.as_array()
        c_full = []
        for k, c in enumerate(CONSTANT_NAMES):
            c_full.append(theta[self.names.index(c)] if c in self.names else consts[k])
        c_vec = ca.vertcat(*c_full)
        offset = theta[self.names.index(GAP_OFFSET)] if GAP_OFFSET in self.names else 0

        def accelerations(x_true):
            phi, b = self.model.regressor(x_true, u)
            acc = ca.mtimes(phi, c_vec) + b
            k = len(self.names) - sum(t.n_parameters for t in self.terms)
            for term in self.terms:
                # the simulation has no current rates: terms see du = 0 (and one that changes over
                # the log is refused where the terms are given, its place in a log unknown here)
                acc = acc + term.evaluate(x_true, u, ca.DM.zeros(2), 0.0, theta[k : k + term.n_parameters])
                k += term.n_parameters
            return acc

        x_shift = ca.vertcat(x[0] + offset, x[1], x[2], x[3])
        acc_reading = accelerations(x_shift)
        acc_true = accelerations(x)
        set_ = object.__setattr__
        set_(
            self,
            "acceleration_reading",
            ca.Function("acc_reading", [x, u, theta], [acc_reading], ["x", "u", "theta"], ["acc"]),
        )
        set_(
            self,
            "acceleration_true",
            ca.Function("acc_true", [x, u, theta], [acc_true], ["x", "u", "theta"], ["acc"]),
        )
        set_(self, "linear", not ca.depends_on(ca.jacobian(acc_reading, theta), theta))

    # ------------------------------------------------------------------------------------
    @property
    def n(self) -> int:
        return len(self.names)

    def initial_vector(self, initial: dict[str, float] | None = None) -> np.ndarray:
        """The initial theta, with any entries of ``initial`` (by name) replacing the defaults."""
        theta = np.array(self.initial, dtype=float)
        for key, value in (initial or {}).items():
            if key not in self.names:
                raise InputError(f"initial: {key!r} is not estimated; estimated: {self.names}")
            theta[self.names.index(key)] = float(value)
        return theta

    def fixed(self) -> dict[str, float]:
        """The constants held at the model's values."""
        c = self.model.constants
        return {k: getattr(c, k) for k in CONSTANT_NAMES if k not in self.names}

    def unit(self, name: str) -> str:
        return UNITS.get(name, "")
