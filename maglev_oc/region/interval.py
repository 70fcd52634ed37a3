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
square root, exp/log, sinh/cosh/tanh, atan, sin/cos, fabs, fmin/fmax, integer constant powers);
any other operation raises ``NotImplementedError`` when the function is wrapped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from maglev_oc.errors import InputError

__all__ = ["IntervalFunction"]

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
    if op == ca.OP_CONSTPOW:
        expo = float(np.unique(b_lo)[0]) if np.all(b_lo == b_hi) else None
        if expo is None or np.unique(b_lo).size != 1:
            raise NotImplementedError("pow with a non-constant exponent")
        return _constpow(a_lo, a_hi, expo)
    raise NotImplementedError(op)  # pragma: no cover - screened in IntervalFunction.__post_init__
