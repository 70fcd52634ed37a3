"""The filtered regression design: columns, target and their Gram matrices per block of samples.

Rows are samples of both axes; columns are the estimated base parameters (among C1..C4 and the
gap offset) followed by every term's parameters. The target is the measured acceleration minus
everything known (gravity, the constants held fixed, and for parameters entered nonlinearly the
part of their linearization that does not multiply them). Columns and target pass through the
same filter F (:mod:`~maglev_oc.regression.data`).

Everything a fit needs is accumulated once per block of ``block_seconds`` of fitted samples
(weighted by the per-axis weights):

* ``gram`` X_b' X_b, ``rhs`` X_b' y_b, ``yy`` y_b' y_b — any subset's fit is a small solve;
* ``noise`` N_b, the expected contribution of the logged currents' errors to X_b' X_b
  (errors-in-variables, see :mod:`~maglev_oc.regression.data`): a column c(x, u, du) with
  u = u_applied + e carries F[dc/du e] + F[dc/d(du) D e] (D the SG velocity filter), whose
  expected cross-products, for white e of variance s_i^2 per channel and slowly varying
  sensitivities, are s_i^2 (|F|^2 sum dc_j/du_i dc_k/du_i + |F*D|^2 sum dc_j/ddu_i dc_k/ddu_i);
* the held-out block's per-axis (unweighted) Gram matrices, so any subset's held-out error is a
  quadratic form.

Blocks never span two logs or the gap around a held-out block; the fits' covariance treats the
block scores as a time series (:mod:`~maglev_oc.regression.solve`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from functools import cached_property

import casadi as ca
import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.model.stage import StageModel
from maglev_oc.numerics import NumpyCall
from maglev_oc.regression.base import CONSTANT_NAMES, ESTIMABLE, GAP_OFFSET
from maglev_oc.regression.data import PreparedLogs
from maglev_oc.regression.terms import AccelerationTerm, when_symbol

__all__ = [
    "COLUMN_CACHE_BYTES",
    "DEFAULT_BLOCK",
    "ColumnCache",
    "Design",
    "build_design",
    "restated",
    "reusing_columns",
]

DEFAULT_BLOCK = 0.5
"""[s] Block length: the covariance's spectral window (0.25 Hz) is well inside the block
series' band (1 Hz), and a 45 s fitting part gives 90 blocks for the bootstrap."""


@dataclass(frozen=True, eq=False)
class Design:
    """Filtered columns and their block sums.

    Attributes
    ----------
    names : tuple of str
        Parameters in column order: estimated base parameters, then ``"<term>.<parameter>"``.
    groups : dict
        "base" (the estimated base parameters) and each term's name -> column indices.
    terms : tuple of AccelerationTerm
    columns : (P, 2, n) filtered columns; target : (2, n) filtered target
    weights : (2,) per-axis weights (1 / residual scale; 0 for an axis that does not move)
    fit, holdout : (n,) bool masks
    gram, noise : (B, P, P); rhs : (B, P); yy : (B,) per fitted block, weighted
    block_log : (B,) the log each block belongs to; block_of : (n,) each sample's block (-1: not
    fitted); block_seconds : float
    hold_gram : (2, P, P); hold_rhs : (2, P); hold_yy : (2,); hold_n : int (unweighted, per axis)
    at : (P,) the parameter values the nonlinear parameters were linearized at
    prepared : PreparedLogs
    """

    names: tuple[str, ...]
    groups: dict[str, np.ndarray]
    terms: tuple[AccelerationTerm, ...]
    columns: np.ndarray
    target: np.ndarray
    weights: np.ndarray
    fit: np.ndarray
    holdout: np.ndarray
    gram: np.ndarray
    noise: np.ndarray
    rhs: np.ndarray
    yy: np.ndarray
    block_log: np.ndarray
    block_of: np.ndarray
    block_seconds: float
    hold_gram: np.ndarray
    hold_rhs: np.ndarray
    hold_yy: np.ndarray
    hold_n: int
    at: np.ndarray
    prepared: PreparedLogs

    @property
    def n_parameters(self) -> int:
        return len(self.names)

    @cached_property
    def optional(self) -> np.ndarray:
        """(P,) bool: the columns of the terms' optional parameters (``AccelerationTerm.optional``)."""
        out = np.zeros(len(self.names), dtype=bool)
        for t in self.terms:
            if t.optional and t.name in self.groups:
                cols = self.groups[t.name]
                out[[cols[t.parameter_names.index(q)] for q in t.optional]] = True
        return out

    @cached_property
    def held_out_columns(self) -> np.ndarray:
        """(P, 2, n_hold) the columns on the held-out samples, copied once (selection computes
        held-out residuals of hundreds of subsets; contiguous: np.take, where a boolean index on
        the last axis leaves a transposed layout that every later product copies again)."""
        return np.take(self.columns, np.flatnonzero(self.holdout), axis=2)

    @cached_property
    def held_out_target(self) -> np.ndarray:
        """(2, n_hold) the target on the held-out samples."""
        return np.take(self.target, np.flatnonzero(self.holdout), axis=1)

    @property
    def moving(self) -> np.ndarray:
        return self.prepared.moving

    def indices(self, groups: Sequence[str]) -> np.ndarray:
        return np.concatenate([self.groups[g] for g in groups]) if groups else np.zeros(0, dtype=int)

    def term(self, name: str) -> AccelerationTerm:
        for t in self.terms:
            if t.name == name:
                return t
        raise KeyError(name)


def _linearized(term: AccelerationTerm, xs, u, du, s, p0: ca.DM):
    """A term's acceleration at the parameters ``p0`` and its Jacobian in them there (``s``: the
    place in the log, for a term that changes over it)."""
    acc = term.evaluate(xs, u, du, s, p0)
    p = ca.SX.sym("p", term.n_parameters)
    jac = ca.substitute(ca.jacobian(term.evaluate(xs, u, du, s, p), p), p, p0)
    return acc, jac


def _sensitivities(flat, u, du) -> tuple[list, list]:
    """Sensitivities of the column-major columns ``flat`` to the currents and their rates: only
    their structural nonzeros, as vectors, with (column, axis, input, kind) of each; kind 0 = d/du,
    1 = d/d(du)."""
    outs, where = [], []
    for kind, var in enumerate((u, du)):
        jac = ca.jacobian(flat, var)
        rows, cols = jac.sparsity().get_triplet()
        outs.append(jac.nz[:] if rows else ca.SX.zeros(0, 1))
        where.extend((r // 2, r % 2, c, kind) for r, c in zip(rows, cols, strict=True))
    return outs, where


_CSE = {"cse": True}
"""The design Functions with common subexpressions merged (CasADi's ``cse``): a term's columns,
its known part and their sensitivities share most of their operations (the Legendre and
harmonic bases of the diagnosis's candidates), so the evaluation over every sample, most of a
design's cost, takes about half the instructions and 40 % of the time (measured on an
independent log: 0.95 -> 0.41 s a diagnosis). The same operations on the same inputs: the
values are the same to the bit."""


def _symbolic(model: StageModel, estimate: Sequence[str], terms: Sequence[AccelerationTerm], at: np.ndarray):
    """CasADi Function (x, u, du, s) -> (columns (2, P), known (2,), sensitivities (m,)) and, for each of
    the m sensitivities, (column, axis, input, kind): d column / d u_input (kind 0) or
    d column / d du_input (kind 1), the structural nonzeros only."""
    x, u, du, s = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("du", 2), when_symbol()
    consts = np.asarray(model.constants.as_array(), dtype=float)
    names = [c for c in CONSTANT_NAMES if c in estimate]
    k = len(names) + (GAP_OFFSET in estimate)
    for c in names:
        consts[CONSTANT_NAMES.index(c)] = at[names.index(c)]
    delta0 = float(at[len(names)]) if GAP_OFFSET in estimate else 0.0
    delta = ca.SX.sym("delta")
    xs = ca.vertcat(x[0] + delta, x[1], x[2], x[3])
    phi, b = model.regressor(xs, u)
    cols, known = [], b
    for j, c in enumerate(CONSTANT_NAMES):
        if c in names:
            cols.append(phi[:, j])
        else:
            known = known + phi[:, j] * consts[j]
    total = phi @ ca.DM(consts) + b  # the model at the linearization point, for the offset's column
    term_acc = []
    for term in terms:
        p0 = ca.DM(at[k : k + term.n_parameters])
        acc, jac = _linearized(term, xs, u, du, s, p0)
        cols.extend(jac[:, i] for i in range(term.n_parameters))
        known = known + acc - jac @ p0
        term_acc.append(acc)
        k += term.n_parameters
    if GAP_OFFSET in estimate:
        full = total + sum(term_acc, ca.SX.zeros(2, 1))
        dcol = ca.jacobian(full, delta)
        cols.insert(len(names), dcol)
        known = known - dcol * delta0
    cols_m = ca.horzcat(*cols) if cols else ca.SX.zeros(2, 0)
    cols_m = ca.substitute(cols_m, delta, delta0)
    known = ca.substitute(known, delta, delta0)
    flat = ca.reshape(cols_m, -1, 1)  # column-major: (axis, column) -> axis + 2 column
    outs, where = _sensitivities(flat, u, du)
    fn = ca.Function(
        "design",
        [x, u, du, s],
        [cols_m, known, ca.vertcat(*outs)],
        ["x", "u", "du", "s"],
        ["cols", "known", "sensitivities"],
        _CSE,
    )
    return fn, np.array(where, dtype=int).reshape(-1, 4)


def _term_symbolic(terms: Sequence[AccelerationTerm], at: Sequence[np.ndarray]):
    """The terms' part of :func:`_symbolic` (no gap offset), each term's expressions built as there:
    Function (x, u, du, s) -> (columns (2, P), known parts (2, K), sensitivities (m,)), the sensitivities'
    (column, axis, input, kind) and, per term, the positions in the known parts of its
    acceleration at the linearization point and of its columns times that point (-1 where
    structurally zero: a linear term linearized at zero has neither)."""
    x, u, du, s = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("du", 2), when_symbol()
    delta = ca.SX.sym("delta")
    xs = ca.vertcat(x[0] + delta, x[1], x[2], x[3])
    cols, parts, slots = [], [], []
    for term, p_at in zip(terms, at, strict=True):
        p0 = ca.DM(p_at)
        acc, jac = _linearized(term, xs, u, du, s, p0)
        cols.extend(jac[:, i] for i in range(term.n_parameters))
        slot = []
        for part in (acc, jac @ p0):
            part = ca.substitute(part, delta, 0.0)
            if all(part[i].is_zero() for i in range(2)):
                slot.append(-1)
            else:
                slot.append(len(parts))
                parts.append(part)
        slots.append(tuple(slot))
    cols_m = ca.substitute(ca.horzcat(*cols), delta, 0.0)
    flat = ca.reshape(cols_m, -1, 1)
    outs, where = _sensitivities(flat, u, du)
    known = ca.horzcat(*parts) if parts else ca.SX.zeros(2, 0)
    fn = ca.Function(
        "design_terms",
        [x, u, du, s],
        [cols_m, known, ca.vertcat(*outs)],
        ["x", "u", "du", "s"],
        ["cols", "known", "sensitivities"],
        _CSE,
    )
    return fn, np.array(where, dtype=int).reshape(-1, 4), slots


@dataclass(frozen=True, eq=False)
class _Evaluated:
    """One piece of a design (the base columns, or one term's) evaluated on every sample."""

    columns: np.ndarray  # (p, 2, n) filtered
    sens: np.ndarray  # (m, n) sensitivities, unscaled
    where: np.ndarray  # (m, 4) (column within the piece, axis, input, kind)
    known: tuple[np.ndarray | None, ...]  # unfiltered (2, n) parts of the known output (None: zero)

    @property
    def nbytes(self) -> int:
        return self.columns.nbytes + self.sens.nbytes + sum(k.nbytes for k in self.known if k is not None)


COLUMN_CACHE_BYTES = 256 * 2**20
"""[bytes] What a :class:`ColumnCache` keeps at most. The diagnosis's library on a 60 s log at 1 kHz
takes about 95 MB, and every later design of the diagnosis reuses it. On
:data:`~maglev_oc.diagnosis.pipeline.MAX_SAMPLES` samples it would take about 470 MB: the first
design that does not fit empties the cache and turns it off, so that such a diagnosis holds no more
memory than without it (each design then evaluated in one Function, as outside the cache)."""


class ColumnCache:
    """The filtered columns of the pieces of designs built on one :class:`PreparedLogs`, each piece
    (the base parameters' columns, or one term's) evaluated once and reused by every later design
    that holds it: a term is the same piece when its CasADi Function (serialized) and linearization
    point are. Active within :func:`reusing_columns`; every value is the one a design built
    without it has (the same expressions evaluated on the same samples, filtered alike)."""

    def __init__(self, prepared: PreparedLogs, max_bytes: int = COLUMN_CACHE_BYTES) -> None:
        self.prepared = prepared
        self.max_bytes = int(max_bytes)
        self._pieces: dict[tuple, _Evaluated] = {}
        self._bytes = 0
        self.active = True

    def __len__(self) -> int:
        return len(self._pieces)

    @property
    def nbytes(self) -> int:
        """Bytes of the pieces kept."""
        return self._bytes

    def _off(self) -> None:
        self._pieces.clear()
        self._bytes = 0
        self.active = False

    def columns(self, model: StageModel, estimate, terms: Sequence[AccelerationTerm], at: np.ndarray, P: int):
        """(columns (P, 2, n) filtered, known (2, n), sensitivities (m, n), where (m, 4)) of a design,
        as :func:`build_design` computes them in one Function; None when the cache is off or this
        design's new pieces would not fit in it (it is then turned off)."""
        if not self.active:
            return None
        prep = self.prepared
        k = len([c for c in CONSTANT_NAMES if c in estimate])
        base_fn, base_where = _symbolic(model, estimate, (), at[:k])
        base_key = ("base", base_fn.serialize())
        starts = np.cumsum([k, *(t.n_parameters for t in terms)])
        term_at = [at[a : a + t.n_parameters] for a, t in zip(starts[:-1], terms, strict=True)]
        keys = [("term", t.function.serialize(), a.tobytes()) for t, a in zip(terms, term_at, strict=True)]
        found = {key: self._pieces.get(key) for key in keys}
        missing: list[tuple[tuple, int]] = []  # (key, its first term) of the pieces to evaluate
        for j, key in enumerate(keys):
            if found[key] is None and all(key != m for m, _ in missing):
                missing.append((key, j))
        fn = (
            _term_symbolic([terms[j] for _, j in missing], [term_at[j] for _, j in missing])
            if missing
            else None
        )
        base = self._pieces.get(base_key)
        rows = (0 if base else 2 * k + len(base_where) + 2) + (
            2 * fn[0].size2_out(0) + fn[0].size1_out(2) + 2 * fn[0].size2_out(1) if fn else 0
        )
        if self._bytes + 8 * prep.n * rows > self.max_bytes:
            self._off()
            return None
        if base is None:
            cols, known, sens = _evaluate(base_fn, prep, k, len(base_where))
            base = _Evaluated(prep.filter(cols, inplace=True), sens, base_where, (known,))
            self._pieces[base_key] = base
            self._bytes += base.nbytes
        if missing:
            new = self._evaluate([terms[j] for _, j in missing], fn)
            for (key, _), piece in zip(missing, new, strict=True):
                found[key] = self._pieces[key] = piece
                self._bytes += piece.nbytes
        return _assembled([base, *(found[key] for key in keys)], prep.n, P)

    def _evaluate(self, terms: Sequence[AccelerationTerm], symbolic) -> list[_Evaluated]:
        """The pieces of ``terms``, evaluated through their one Function (:func:`_term_symbolic`) and
        filtered together (each piece's columns a view of the evaluated array)."""
        prep = self.prepared
        fn, where, slots = symbolic
        P = sum(t.n_parameters for t in terms)
        cols, known, sens = _evaluate(fn, prep, P, len(where), fn.size2_out(1))
        cols = prep.filter(cols, inplace=True)
        out, start = [], 0
        for term, slot in zip(terms, slots, strict=True):
            stop = start + term.n_parameters
            mine = (where[:, 0] >= start) & (where[:, 0] < stop)
            piece_where = where[mine]
            piece_where[:, 0] -= start
            parts = tuple(None if s < 0 else known[s].copy() for s in slot)
            out.append(_Evaluated(cols[start:stop], sens[mine], piece_where, parts))
            start = stop
        return out


def _assembled(pieces: Sequence[_Evaluated], n: int, P: int):
    """A design's columns, known output and sensitivities from its pieces, in :func:`_symbolic`'s
    order: the known output summed as it does ((known + acceleration) - columns x point, term after
    term), the sensitivities ordered as its Jacobians' nonzeros (by kind, input, then the flattened
    (axis, column) row)."""
    columns = np.empty((P, 2, n))
    base = pieces[0]
    known = base.known[0].copy()
    sens, where, start = [], [], 0
    for piece in pieces:
        p = piece.columns.shape[0]
        columns[start : start + p] = piece.columns
        if piece is not base:
            acc, jp = piece.known
            if acc is not None:
                known += acc
            if jp is not None:
                known -= jp
        w = piece.where.copy()
        w[:, 0] += start
        sens.append(piece.sens)
        where.append(w)
        start += p
    where_all = np.concatenate(where) if where else np.zeros((0, 4), dtype=int)
    sens_all = np.concatenate(sens) if sens else np.zeros((0, n))
    order = np.lexsort((where_all[:, 1] + 2 * where_all[:, 0], where_all[:, 2], where_all[:, 3]))
    return columns, known, sens_all[order], where_all[order]


_REUSED: ContextVar[ColumnCache | None] = ContextVar("maglev_oc_design_columns", default=None)


@contextmanager
def reusing_columns(prepared: PreparedLogs, max_bytes: int = COLUMN_CACHE_BYTES) -> Iterator[ColumnCache]:
    """Within the block, every :func:`build_design` on ``prepared`` (without a gap offset) takes the
    columns of the pieces it shares with an earlier one from a :class:`ColumnCache` instead of
    evaluating and filtering them again (a diagnosis builds the library's design two or three
    times and a dozen designs of some of its terms)."""
    token = _REUSED.set(ColumnCache(prepared, max_bytes))
    try:
        yield _REUSED.get()
    finally:
        _REUSED.reset(token)


def _blocks(fit: np.ndarray, segment: np.ndarray, size: int) -> list[np.ndarray]:
    """Index arrays of the fitted samples cut into blocks of ``size`` (a last piece shorter than
    half a block joins its predecessor); blocks never cross a log or a gap in the mask."""
    idx = np.flatnonzero(fit)
    if idx.size == 0:
        return []
    breaks = np.flatnonzero((np.diff(idx) > 1) | (np.diff(segment[idx]) != 0)) + 1
    out = []
    for run in np.split(idx, breaks):
        pieces = [run[k : k + size] for k in range(0, run.size, size)]
        if len(pieces) > 1 and pieces[-1].size < size // 2:
            # pop first: ``pieces[-2] = concatenate([pieces[-2], pieces.pop()])`` indexes the target
            # after the pop, i.e. the piece before, dropping its samples and counting the next twice
            tail = pieces.pop()
            pieces[-1] = np.concatenate([pieces[-1], tail])
        out.extend(pieces)
    return out


def build_design(
    prepared: PreparedLogs,
    model: StageModel,
    *,
    estimate: Sequence[str] = CONSTANT_NAMES,
    terms: Sequence[AccelerationTerm] = (),
    fit: np.ndarray | None = None,
    holdout: np.ndarray | None = None,
    at: Mapping[str, float] | np.ndarray | None = None,
    weights: np.ndarray | None = None,
    block_seconds: float = DEFAULT_BLOCK,
) -> Design:
    """Evaluate, filter and accumulate the design.

    Parameters
    ----------
    prepared : PreparedLogs
    model : StageModel
        Geometry, and the values of the constants not estimated.
    estimate : sequence of str
        Base parameters among C1..C4 and ``gap_offset``.
    terms : sequence of AccelerationTerm
    fit, holdout : (n,) bool, optional
        Samples fitted (default every valid one) and held out (default none).
    at : mapping or array, optional
        Values at which parameters that enter nonlinearly (the gap offset, nonlinear terms' ones)
        are linearized; default the model's constants, zero offset, the terms' initial values.
    weights : (2,), optional
        Per-axis weights; default 1 / RMS residual of an unweighted fit of this design.
    block_seconds : float
        [s] Length of the blocks of fitted samples.
    """
    estimate, terms = tuple(estimate), tuple(terms)
    names, groups, at_vec = _parameters(model, estimate, terms, at)
    prep = prepared
    n, P = prep.n, len(names)
    cache = _REUSED.get()
    reused = None
    if cache is not None and cache.prepared.same_samples(prep) and GAP_OFFSET not in estimate:
        reused = cache.columns(model, estimate, terms, at_vec, P)
    if reused is not None:
        columns, known, sens, where = reused
    else:
        fn, where = _symbolic(model, estimate, terms, at_vec)
        columns, known, sens = _evaluate(fn, prep, P, len(where))
        columns = prep.filter(columns, inplace=True)
    target = prep.acc - prep.filter(known)

    fit = prep.valid.copy() if fit is None else np.asarray(fit, dtype=bool) & prep.valid
    holdout = np.zeros(n, dtype=bool) if holdout is None else np.asarray(holdout, dtype=bool)
    if weights is None:
        weights = _axis_weights(columns, target, fit, prep.moving)
    weights = np.where(prep.moving, np.asarray(weights, dtype=float), 0.0)
    size = max(1, round(block_seconds / prep.sample_time))
    noise = _NoiseSensitivities.of(prep, sens, where, weights, P)
    acc = _accumulate(columns, target, weights, _blocks(fit, prep.segment, size), prep.segment, noise)
    hold_gram, hold_rhs = _held_out_normal_equations(columns, target, holdout)
    return Design(
        names=names,
        groups=groups,
        terms=terms,
        columns=columns,
        target=target,
        weights=weights,
        fit=fit,
        holdout=holdout,
        **acc,
        block_seconds=size * prep.sample_time,
        hold_gram=hold_gram,
        hold_rhs=hold_rhs,
        hold_yy=np.array([float(target[a, holdout] @ target[a, holdout]) for a in range(2)]),
        hold_n=int(holdout.sum()),
        at=at_vec,
        prepared=prep,
    )


def restated(design: Design, columns: np.ndarray, target: np.ndarray, weights: np.ndarray) -> Design:
    """``design`` with other columns (P, 2, n), target (2, n) and per-axis weights (2,): the same
    parameters, samples, fitted blocks and held-out part, the block sums recomputed, and no
    errors-in-variables correction (the noise Grams zero): the regression restated in other units,
    such as the currents the measured accelerations need
    (:mod:`maglev_oc.diagnosis.thrust_current`)."""
    weights = np.where(design.moving, np.asarray(weights, dtype=float), 0.0)
    size = max(1, round(design.block_seconds / design.prepared.sample_time))
    blocks = _blocks(design.fit, design.prepared.segment, size)
    acc = _accumulate(columns, target, weights, blocks, design.prepared.segment, None)
    hold_gram, hold_rhs = _held_out_normal_equations(columns, target, design.holdout)
    hold = design.holdout
    return dataclasses.replace(
        design,
        columns=columns,
        target=target,
        weights=weights,
        **acc,
        hold_gram=hold_gram,
        hold_rhs=hold_rhs,
        hold_yy=np.array([float(target[a, hold] @ target[a, hold]) for a in range(2)]),
    )


def _held_out_normal_equations(columns: np.ndarray, target: np.ndarray, holdout: np.ndarray):
    """Per axis, X X' and X y over the held-out samples, run by run of consecutive samples (no
    copy of the held-out columns)."""
    P = columns.shape[0]
    gram, rhs = np.zeros((2, P, P)), np.zeros((2, P))
    edges = np.flatnonzero(np.diff(np.concatenate([[0], holdout.astype(np.int8), [0]])))
    for start, stop in zip(edges[::2], edges[1::2], strict=True):
        for a in range(2):
            x = columns[:, a, start:stop]
            gram[a] += x @ x.T
            rhs[a] += x @ target[a, start:stop]
    return gram, rhs


def _evaluate(fn: ca.Function, prep: PreparedLogs, P: int, m: int, n_known: int | None = None):
    """``fn`` over every sample, ``_CHUNK`` samples per mapped call into preallocated arrays:
    columns (P, 2, n), known (2, n) (or, given ``n_known``, the (n_known, 2, n) columns of a known
    output (2, n_known)), sensitivities (m, n). (One map over all samples would hold its output and
    the rearranged copy, each of the size of the columns, at once.)"""
    n = prep.n
    place = prep.log_time
    parts = 1 if n_known is None else n_known
    cols, known, sens = np.empty((P, 2, n)), np.empty((parts, 2, n)), np.empty((m, n))
    mapped: dict[int, NumpyCall] = {}
    for a in range(0, n, _CHUNK):
        b = min(a + _CHUNK, n)
        if b - a not in mapped:  # one mapped Function per chunk length (two at most)
            mapped[b - a] = NumpyCall(fn.map(b - a))
        c, k, s = mapped[b - a](prep.x[:, a:b], prep.u[:, a:b], prep.du[:, a:b], place[:, a:b])
        # mapped outputs are concatenated sample by sample: (2, k P) -> (P, 2, k)
        cols[:, :, a:b] = c.reshape(2, b - a, P).transpose(2, 0, 1)
        known[:, :, a:b] = k.reshape(2, b - a, parts).transpose(2, 0, 1)
        sens[:, a:b] = s.reshape(m, b - a)
    return cols, (known[0] if n_known is None else known), sens


_CHUNK = 5_000
"""Samples per mapped evaluation of the design (5 s at 1 kHz; larger chunks are no faster)."""


def _parameters(model: StageModel, estimate: tuple[str, ...], terms: tuple[AccelerationTerm, ...], at):
    """(names, groups, linearization point) of a design; checks the names."""
    unknown = [e for e in estimate if e not in ESTIMABLE]
    if unknown:
        raise InputError(f"estimate: unknown name(s) {unknown}; choose among {ESTIMABLE}")
    if len(set(estimate)) != len(estimate):
        raise InputError(f"estimate: duplicate names in {estimate!r}")
    tnames = [t.name for t in terms]
    if len(set(tnames)) != len(tnames):
        raise InputError(f"terms: duplicate names {tnames}")
    base = [c for c in CONSTANT_NAMES if c in estimate] + ([GAP_OFFSET] if GAP_OFFSET in estimate else [])
    names = tuple(base) + tuple(q for t in terms for q in t.qualified_names)
    defaults = [getattr(model.constants, c) for c in base if c != GAP_OFFSET]
    defaults += [0.0] * (GAP_OFFSET in estimate) + [v for t in terms for v in t.initial]
    if at is None:
        at_vec = np.array(defaults, dtype=float)
    elif isinstance(at, Mapping):
        at_vec = np.array([float(at.get(nm, d)) for nm, d in zip(names, defaults, strict=True)])
    else:
        at_vec = np.asarray(at, dtype=float).ravel()
        if at_vec.size != len(names):
            raise InputError(f"at: expected {len(names)} values {names}, got {at_vec.size}")
    groups = {"base": np.arange(len(base))}
    k = len(base)
    for t in terms:
        groups[t.name] = np.arange(k, k + t.n_parameters)
        k += t.n_parameters
    return names, groups, at_vec


@dataclass(frozen=True)
class _NoiseSensitivities:
    """Errors in variables: sensitivity e of column p on axis a to input I carries, after the
    filter, variance s2_I |K|^2 per unit; each is scaled by sqrt(w_a^2 s2_I |K|^2) so that the
    block Gram of the scaled sensitivities, summed over pairs on the same (axis, input, kind) and
    scattered to their columns, is the block's noise Gram N_b."""

    scaled: np.ndarray  # (m, n) one row per structural sensitivity
    same: np.ndarray  # (m, m) pairs on the same (axis, input, kind)
    scatter: np.ndarray  # (P, m) sensitivity -> its column

    @classmethod
    def of(cls, prep: PreparedLogs, sens: np.ndarray, where: np.ndarray, weights: np.ndarray, P: int):
        if not (sens.size and np.any(prep.current_noise > 0)):
            return None
        kf = float(np.sum(prep.kernel**2))
        kfd = float(np.sum(np.convolve(prep.kernel, _velocity_kernel(prep)) ** 2))
        gain = np.array(
            [weights[a] ** 2 * prep.current_noise[i] * (kf if k == 0 else kfd) for _, a, i, k in where]
        )
        group = where[:, 1] * 4 + where[:, 2] * 2 + where[:, 3]
        scatter = np.zeros((P, len(where)))
        scatter[where[:, 0], np.arange(len(where))] = 1.0
        sens *= np.sqrt(gain)[:, None]  # in place: the sensitivities are this design's own copy
        return cls(sens, group[:, None] == group[None, :], scatter)

    def gram(self, part: slice) -> np.ndarray:
        e = self.scaled[:, part]
        return self.scatter @ ((e @ e.T) * self.same) @ self.scatter.T


def _accumulate(columns, target, weights, blocks, segment, noise: _NoiseSensitivities | None) -> dict:
    """Per-block weighted Grams, right-hand sides, target energies and noise Grams (Design fields)."""
    P, n = columns.shape[0], columns.shape[2]
    grams, noises, rhss, yys, logs = [], [], [], [], []
    block_of = np.full(n, -1)
    for b, sel in enumerate(blocks):
        block_of[sel] = b
        part = slice(sel[0], sel[-1] + 1)  # blocks are runs of consecutive samples
        xw = (columns[:, :, part] * weights[None, :, None]).reshape(P, -1)
        yw = (target[:, part] * weights[:, None]).reshape(-1)
        grams.append(xw @ xw.T)
        rhss.append(xw @ yw)
        yys.append(float(yw @ yw))
        logs.append(int(segment[sel[0]]))
        noises.append(noise.gram(part) if noise is not None else np.zeros((P, P)))
    empty = np.zeros((0, P, P))
    return {
        "gram": np.array(grams) if grams else empty,
        "noise": np.array(noises) if noises else empty,
        "rhs": np.array(rhss) if rhss else np.zeros((0, P)),
        "yy": np.array(yys),
        "block_log": np.array(logs, dtype=int),
        "block_of": block_of,
    }


def _velocity_kernel(prep: PreparedLogs) -> np.ndarray:
    from scipy.signal import savgol_coeffs

    sg = prep.differentiator
    return savgol_coeffs(sg.velocity_window, sg.polyorder, deriv=1, delta=sg.sample_time, use="conv")


def _axis_weights(columns: np.ndarray, target: np.ndarray, fit: np.ndarray, moving: np.ndarray) -> np.ndarray:
    """1 / RMS residual per axis of an unweighted fit on the fitted samples (1 if no columns)."""
    P = columns.shape[0]
    at = np.flatnonzero(fit)
    y = np.take(target, at, axis=1)
    if P:
        x = np.take(columns, at, axis=2)  # contiguous (a boolean index leaves a transposed layout)
        coef, *_ = np.linalg.lstsq(x.reshape(P, -1).T, y.reshape(-1), rcond=None)
        y = y - np.einsum("p,pan->an", coef, x)
    rms = np.sqrt(np.mean(y**2, axis=1)) if y.shape[1] else np.ones(2)
    return np.where(moving & (rms > 0), 1.0 / np.maximum(rms, 1e-12), 0.0)
