"""Interval arithmetic over CasADi SX Functions: sound enclosures of a function's range on boxes.

:class:`IntervalFunction` walks the instruction list of an SX :class:`casadi.Function` once and
replays it on intervals ``[lo, hi]`` (numpy arrays, one entry per box, so thousands of boxes are
evaluated at once). Every elementary operation returns an enclosure of the exact range of that
operation on its argument intervals (the *natural interval extension*), so the output interval
of the whole graph contains every value the function takes on the box. The enclosure is
pessimistic where a variable occurs several times (the dependency effect); it tightens linearly
with the box width, which is what branch and bound exploits.

Rounding: numpy rounds to nearest; after every operation the bounds are moved outward by a few
units in the last place (``_PAD``), which covers the rounding of the basic operations and of
libm's elementary functions (accurate to within one ulp on glibc). The enclosure is therefore
rigorous for the function as CasADi evaluates it in double precision, up to that assumption on
libm.

Supported operations are those the stage model and the region analyses use (arithmetic, square,
square root, exp/log, sinh/cosh/tanh, atan, sin/cos, fabs, fmin/fmax, the comparisons <= and < that
the derivatives of fmin/fmax contain, non-integer constant powers);
any other operation raises ``NotImplementedError`` when the function is wrapped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.errors import InputError

__all__ = ["CenteredForm", "IntervalFunction"]

_EPS = np.finfo(float).eps
_PAD = 4 * _EPS  # relative outward padding per operation
_TINY = 1e-300  # absolute padding so that bounds at 0 move outward too

_UNARY_MONOTONE_INCREASING = {
    ca.OP_SQRT: np.sqrt,
    ca.OP_EXP: np.exp,
    ca.OP_LOG: np.log,
    ca.OP_SINH: np.sinh,
    ca.OP_TANH: np.tanh,
    ca.OP_ATAN: np.arctan,
}


def _pad(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Move the bounds outward; NaN bounds become infinite (an enclosure of anything)."""
    # lo - (|lo| PAD + TINY) and hi + (|hi| PAD + TINY), in new arrays updated in place
    out_lo = np.abs(lo)
    out_lo *= _PAD
    out_lo += _TINY
    np.subtract(lo, out_lo, out=out_lo)
    out_hi = np.abs(hi)
    out_hi *= _PAD
    out_hi += _TINY
    out_hi += hi
    out_lo[np.isnan(out_lo)] = -np.inf
    out_hi[np.isnan(out_hi)] = np.inf
    return out_lo, out_hi


def _mul(alo, ahi, blo, bhi):
    with np.errstate(invalid="ignore"):
        p1, p2, p3, p4 = alo * blo, alo * bhi, ahi * blo, ahi * bhi
        lo = np.minimum(np.minimum(p1, p2), np.minimum(p3, p4))
        hi = np.maximum(np.maximum(p1, p2), np.maximum(p3, p4))
    # 0 * inf is NaN: the product of a zero and an unbounded interval is unbounded (np.minimum and
    # np.maximum pass a NaN of any product on, so the NaNs of lo and hi mark those boxes)
    bad = np.isnan(lo)
    lo[bad] = -np.inf
    hi[bad] = np.inf
    return lo, hi


def _inv(lo, hi):
    contains_zero = (lo <= 0) & (hi >= 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        rlo = np.where(contains_zero, -np.inf, 1.0 / hi)
        rhi = np.where(contains_zero, np.inf, 1.0 / lo)
    return rlo, rhi


def _sq(lo, hi):
    a, b = lo * lo, hi * hi
    contains_zero = (lo <= 0) & (hi >= 0)
    return np.where(contains_zero, 0.0, np.minimum(a, b)), np.maximum(a, b)


def _cos(lo, hi):
    """Range of cos on [lo, hi]: endpoint values, and +-1 where a multiple of pi lies inside."""
    width = hi - lo
    clo, chi = np.cos(lo), np.cos(hi)
    rlo, rhi = np.minimum(clo, chi), np.maximum(clo, chi)
    with np.errstate(invalid="ignore"):
        # maximum +1 at 2 k pi, minimum -1 at (2 k + 1) pi
        k_max = np.ceil(lo / (2 * math.pi))
        has_max = 2 * math.pi * k_max <= hi
        k_min = np.ceil((lo - math.pi) / (2 * math.pi))
        has_min = 2 * math.pi * k_min + math.pi <= hi
    full = ~np.isfinite(width) | (width >= 2 * math.pi)
    rhi = np.where(has_max | full, 1.0, rhi)
    rlo = np.where(has_min | full, -1.0, rlo)
    return rlo, rhi


def _fabs(lo, hi):
    contains_zero = (lo <= 0) & (hi >= 0)
    a, b = np.abs(lo), np.abs(hi)
    return np.where(contains_zero, 0.0, np.minimum(a, b)), np.maximum(a, b)


def _cosh(lo, hi):
    alo, ahi = _fabs(lo, hi)
    return np.cosh(alo), np.cosh(ahi)


def _constpow(lo, hi, expo):
    """x**expo for a non-integer constant exponent (CasADi expands integer powers of SX into
    products and inverses before they get here): defined for x >= 0, monotone there."""
    if float(expo).is_integer():
        raise NotImplementedError(f"pow with the integer exponent {expo:g} (CasADi expands these)")
    with np.errstate(invalid="ignore"):
        if expo > 0:
            return np.maximum(lo, 0.0) ** expo, np.where(hi < 0, np.nan, hi**expo)
        return np.where(hi < 0, np.nan, hi**expo), np.where(lo <= 0, np.inf, lo**expo)


@dataclass(frozen=True, eq=False)
class IntervalFunction:
    """The natural interval extension of an SX Function with dense inputs and outputs.

    Parameters
    ----------
    function : casadi.Function
        An SX Function (``ca.Function`` built from ``ca.SX`` expressions).

    Calling it with ``lo`` and ``hi`` lists (one array per input, each of shape
    ``(size_in, n_boxes)``) returns lists ``(lo_out, hi_out)`` of arrays of shape
    ``(size_out, n_boxes)`` that enclose every value of the function on each box.
    """

    function: ca.Function
    _program: tuple = field(init=False, repr=False)

    def __post_init__(self) -> None:
        f = self.function
        if not f.is_a("SXFunction"):
            raise TypeError(f"IntervalFunction needs an SX Function, got {f.class_name()}")
        program = []
        supported = {
            ca.OP_ASSIGN,
            ca.OP_INPUT,
            ca.OP_OUTPUT,
            ca.OP_CONST,
            ca.OP_ADD,
            ca.OP_SUB,
            ca.OP_MUL,
            ca.OP_DIV,
            ca.OP_NEG,
            ca.OP_SQ,
            ca.OP_TWICE,
            ca.OP_INV,
            ca.OP_COSH,
            ca.OP_COS,
            ca.OP_SIN,
            ca.OP_FABS,
            ca.OP_FMIN,
            ca.OP_FMAX,
            ca.OP_CONSTPOW,
            ca.OP_LE,
            ca.OP_LT,
            *_UNARY_MONOTONE_INCREASING,
        }
        for k in range(f.n_instructions()):
            op = f.instruction_id(k)
            if op not in supported:
                names = {getattr(ca, n): n for n in dir(ca) if n.startswith("OP_")}
                raise NotImplementedError(
                    f"{f.name()}: operation {names.get(op, op)} has no interval extension here"
                )
            const = f.instruction_constant(k) if op == ca.OP_CONST else None
            program.append((op, tuple(f.instruction_input(k)), tuple(f.instruction_output(k)), const))
        object.__setattr__(self, "_program", tuple(program))

    def __call__(self, lo, hi) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Enclosures of the function's outputs on boxes.

        Parameters
        ----------
        lo, hi : lists of arrays
            One per input, each broadcastable to ``(size_in, n_boxes)``, ``lo <= hi``.

        Returns
        -------
        (list of arrays, list of arrays)
            Lower and upper bounds of each output, ``(size_out, n_boxes)``.
        """
        f = self.function
        lo, hi, n = self._boxes(lo, hi)
        w_lo: dict[int, np.ndarray] = {}
        w_hi: dict[int, np.ndarray] = {}
        out_lo = [np.full((f.nnz_out(k), n), np.nan) for k in range(f.n_out())]
        out_hi = [np.full((f.nnz_out(k), n), np.nan) for k in range(f.n_out())]
        for op, ins, outs, const in self._program:
            if op == ca.OP_INPUT:
                w_lo[outs[0]] = lo[ins[0]][ins[1]]
                w_hi[outs[0]] = hi[ins[0]][ins[1]]
                continue
            if op == ca.OP_OUTPUT:
                out_lo[outs[0]][outs[1]] = w_lo[ins[0]]
                out_hi[outs[0]][outs[1]] = w_hi[ins[0]]
                continue
            if op == ca.OP_CONST:
                w_lo[outs[0]] = np.full(n, const)
                w_hi[outs[0]] = np.full(n, const)
                continue
            a = (w_lo[ins[0]], w_hi[ins[0]])
            b = (w_lo[ins[1]], w_hi[ins[1]]) if len(ins) > 1 else (None, None)
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                r_lo, r_hi = _operation(op, *a, *b)
                r_lo, r_hi = _pad(np.asarray(r_lo, dtype=float), np.asarray(r_hi, dtype=float))
            w_lo[outs[0]] = r_lo
            w_hi[outs[0]] = r_hi
        return out_lo, out_hi

    def _boxes(self, lo, hi) -> tuple[list[np.ndarray], list[np.ndarray], int]:
        """The inputs' bounds broadcast to (nnz_in, n), checked, and the number of boxes n."""
        f = self.function
        lo = [np.atleast_2d(np.asarray(a, dtype=float)) for a in lo]
        hi = [np.atleast_2d(np.asarray(a, dtype=float)) for a in hi]
        if len(lo) != f.n_in() or len(hi) != f.n_in():
            raise InputError(f"{f.name()} takes {f.n_in()} inputs, got {len(lo)} and {len(hi)}")
        n = max(a.shape[1] for a in lo + hi)
        for k in range(f.n_in()):
            shape = (f.nnz_in(k), n)
            lo[k] = np.broadcast_to(lo[k], shape)
            hi[k] = np.broadcast_to(hi[k], shape)
            if np.any(lo[k] > hi[k]):
                raise InputError(f"{f.name()}: input {k} has lo > hi")
        return lo, hi, n


def _operation(op: int, a_lo, a_hi, b_lo, b_hi):
    """The exact range (before padding) of one elementary operation on [a] (and [b])."""
    if op == ca.OP_ASSIGN:
        return a_lo, a_hi
    if op == ca.OP_ADD:
        return a_lo + b_lo, a_hi + b_hi
    if op == ca.OP_SUB:
        return a_lo - b_hi, a_hi - b_lo
    if op == ca.OP_MUL:
        return _mul(a_lo, a_hi, b_lo, b_hi)
    if op == ca.OP_DIV:
        i_lo, i_hi = _inv(b_lo, b_hi)
        return _mul(a_lo, a_hi, i_lo, i_hi)
    if op == ca.OP_NEG:
        return -a_hi, -a_lo
    if op == ca.OP_SQ:
        return _sq(a_lo, a_hi)
    if op == ca.OP_TWICE:
        return 2 * a_lo, 2 * a_hi
    if op == ca.OP_INV:
        return _inv(a_lo, a_hi)
    if op == ca.OP_SQRT:
        return np.sqrt(np.maximum(a_lo, 0.0)), np.where(a_hi < 0, np.nan, np.sqrt(np.maximum(a_hi, 0.0)))
    if op == ca.OP_LOG:
        r_lo = np.where(a_lo <= 0, -np.inf, np.log(np.maximum(a_lo, 0.0)))
        return r_lo, np.where(a_hi <= 0, np.nan, np.log(np.maximum(a_hi, 0.0)))
    if op in _UNARY_MONOTONE_INCREASING:
        fn = _UNARY_MONOTONE_INCREASING[op]
        return fn(a_lo), fn(a_hi)
    if op == ca.OP_COSH:
        return _cosh(a_lo, a_hi)
    if op == ca.OP_COS:
        return _cos(a_lo, a_hi)
    if op == ca.OP_SIN:
        return _cos(a_lo - math.pi / 2, a_hi - math.pi / 2)
    if op == ca.OP_FABS:
        return _fabs(a_lo, a_hi)
    if op == ca.OP_FMIN:
        return np.minimum(a_lo, b_lo), np.minimum(a_hi, b_hi)
    if op == ca.OP_FMAX:
        return np.maximum(a_lo, b_lo), np.maximum(a_hi, b_hi)
    if op in (ca.OP_LE, ca.OP_LT):  # 1 or 0, or [0, 1] where the intervals overlap (derivatives of fmin/fmax)
        strict = op == ca.OP_LT
        always = a_hi < b_lo if strict else a_hi <= b_lo
        never = a_lo >= b_hi if strict else a_lo > b_hi
        return np.where(always, 1.0, 0.0), np.where(never, 0.0, 1.0)
    if op == ca.OP_CONSTPOW:
        expo = float(np.unique(b_lo)[0]) if np.all(b_lo == b_hi) else None
        if expo is None or np.unique(b_lo).size != 1:
            raise NotImplementedError("pow with a non-constant exponent")
        return _constpow(a_lo, a_hi, expo)
    raise NotImplementedError(op)  # pragma: no cover - screened in IntervalFunction.__post_init__


@dataclass(frozen=True, eq=False)
class CenteredForm:
    """Enclosures that tighten quadratically with the box: the natural interval extension
    intersected with the mean-value form.

    For x in a box X with centre m, f(x) = f(m) + J(xi) (x - m) for some xi in X (the mean-value
    theorem; where fmin/fmax kink, Lebourg's version with Clarke's generalized gradient, which the
    interval extension of CasADi's derivative encloses: its comparisons are [0, 1] where the
    arguments overlap). So f(X) lies in F(m) + sum_k [-1, 1] r_k max|J_k(X)|, r the half-widths.
    The natural extension's excess over the true range shrinks like the width, this one like its
    square: on the small boxes where branch and bound spends its budget it is the tighter of the two.
    Where the Jacobian is unbounded on the box (a square root at 0, a pole) the natural
    extension is kept.

    Parameters
    ----------
    function : casadi.Function
        An SX Function with one output; the first ``boxed`` inputs range over the box, the others
        are passed as intervals too (degenerate for parameters).
    boxed : int
        How many leading inputs the mean-value form expands in.

    Called like :class:`IntervalFunction`, it returns ``([lo], [hi])``, each ``(size_out, n_boxes)``.
    """

    function: ca.Function
    boxed: int = 1
    natural: IntervalFunction = field(init=False, repr=False)
    jacobian: IntervalFunction = field(init=False, repr=False)

    def __post_init__(self) -> None:
        f = self.function
        if f.n_out() != 1 or not 1 <= self.boxed <= f.n_in():
            raise InputError(f"{f.name()}: a centred form needs one output and 1..{f.n_in()} boxed inputs")
        object.__setattr__(self, "natural", IntervalFunction(f))  # an SX Function, or TypeError
        args = [ca.SX.sym(f.name_in(k), f.sparsity_in(k)) for k in range(f.n_in())]
        x = ca.vertcat(*(ca.vec(a) for a in args[: self.boxed]))
        jac = ca.densify(ca.jacobian(f(*args), x))
        object.__setattr__(self, "jacobian", IntervalFunction(ca.Function(f"d_{f.name()}", args, [jac])))

    def __call__(self, lo, hi) -> tuple[list[np.ndarray], list[np.ndarray]]:
        (nat_lo,), (nat_hi,) = self.natural(lo, hi)
        mv_lo, mv_hi = self.mean_value(lo, hi)
        # fmax/fmin: a NaN of the mean-value form (inf - inf) bounds nothing
        return [np.fmax(nat_lo, mv_lo)], [np.fmin(nat_hi, mv_hi)]

    def mean_value(self, lo, hi) -> tuple[np.ndarray, np.ndarray]:
        """The mean-value form alone, (lo, hi) each (size_out, n_boxes), for a caller that holds
        the natural enclosure already (intersect the two: each is an enclosure)."""
        lo, hi, n = self.natural._boxes(lo, hi)
        mid = [0.5 * (a + b) if k < self.boxed else a for k, (a, b) in enumerate(zip(lo, hi, strict=True))]
        mid_hi = [m if k < self.boxed else b for k, (m, b) in enumerate(zip(mid, hi, strict=True))]
        (at_lo,), (at_hi,) = self.natural(mid, mid_hi)  # F(m), rounding enclosed
        (j_lo,), (j_hi,) = self.jacobian(lo, hi)
        radius = np.vstack([0.5 * (b - a) for a, b in zip(lo[: self.boxed], hi[: self.boxed], strict=True)])
        m_out = at_lo.shape[0]
        # the densified Jacobian (m_out, d) arrives column-major: row k m_out + i is dh_i / dx_k
        slope = np.maximum(np.abs(j_lo), np.abs(j_hi)).reshape(radius.shape[0], m_out, n)
        with np.errstate(invalid="ignore"):
            terms = np.where(radius[:, None, :] == 0.0, 0.0, slope * radius[:, None, :])
        spread = np.sum(terms, axis=0)
        spread[np.isnan(spread)] = np.inf
        # the sum's own rounding: a few units in the last place of everything added
        slack = (4 + 2 * radius.shape[0]) * _EPS * (np.abs(at_lo) + np.abs(at_hi) + spread) + _TINY
        with np.errstate(invalid="ignore"):
            return at_lo - spread - slack, at_hi + spread + slack
