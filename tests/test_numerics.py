"""``NumpyCall``: the buffer-interface evaluation gives what CasADi's own call gives."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from maglev_oc.numerics import ColumnMap, NumpyCall


def _reference(fn: ca.Function, *args) -> list[np.ndarray]:
    out = fn.call([ca.DM(np.asarray(a, dtype=float)) for a in args])
    return [np.asarray(ca.densify(o)) for o in out]


def test_mapped_outputs_match_the_dm_call_bit_for_bit():
    x, u = ca.SX.sym("x", 4), ca.SX.sym("u", 2)
    f = ca.Function("f", [x, u], [ca.vertcat(ca.sin(x[0]) * u[1], x[2] * x[3]), ca.horzcat(x, 2 * x)])
    F = f.map(37)
    rng = np.random.default_rng(0)
    X, U = rng.normal(size=(4, 37)), rng.normal(size=(2, 37))
    got = NumpyCall(F)(X, U)
    for g, r in zip(got, _reference(F, X, U), strict=True):
        assert g.shape == r.shape
        np.testing.assert_array_equal(g, r)  # same arithmetic, so the same bits


def test_sparse_outputs_come_back_dense_with_their_zeros():
    x = ca.SX.sym("x", 3)
    f = ca.Function("f", [x], [ca.jacobian(ca.vertcat(x[0] ** 2, x[2]), x)])  # structural zeros
    assert not f.sparsity_out(0).is_dense()
    got = NumpyCall(f)([1.5, -2.0, 3.0])[0]
    np.testing.assert_array_equal(got, [[3.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def test_inputs_broadcast_and_the_caller_arrays_are_untouched():
    x, y = ca.SX.sym("x", 2, 3), ca.SX.sym("y")
    f = NumpyCall(ca.Function("f", [x, y], [x * y]))
    a = np.arange(6.0).reshape(2, 3)
    before = a.copy()
    np.testing.assert_array_equal(f(a, 2.0)[0], 2 * a)
    np.testing.assert_array_equal(a, before)
    # a row broadcast over the rows; a wrong shape is refused by NumPy's broadcasting
    np.testing.assert_array_equal(f([1.0, 2.0, 3.0], 1.0)[0], [[1, 2, 3], [1, 2, 3]])
    with pytest.raises(ValueError):
        f(np.zeros((3, 2)), 1.0)
    with pytest.raises(TypeError, match="2 inputs"):
        f(a)


def test_repeated_calls_do_not_share_output_memory():
    x = ca.SX.sym("x")
    f = NumpyCall(ca.Function("f", [x], [3 * x]))
    first = f(1.0)[0]
    f(5.0)
    assert float(first[0, 0]) == 3.0


@pytest.mark.parametrize("n", [1, 5, 7, 8, 19])
def test_column_map_is_the_functions_map_bit_for_bit(n):
    """ColumnMap in chunks of 4 (a padded last chunk, a held parameter column, two outputs) against
    CasADi's own map(n) with DMs."""
    x, p = ca.SX.sym("x", 3), ca.SX.sym("p", 2)
    f = ca.Function("f", [x, p], [ca.sin(x) * p[0] + ca.exp(-x[0] * p[1]), ca.sumsqr(x) / p[1]])
    rng = np.random.default_rng(n)
    X, P = rng.normal(size=(3, n)), np.array([[1.3], [0.7]])
    got = ColumnMap(f, chunk=4)(X, P)
    want = f.map(n)(X, P)
    assert len(got) == 2
    for g, w in zip(got, want, strict=True):
        assert g.shape == w.shape
        assert np.array_equal(g, np.asarray(w))


def test_column_map_refuses_what_it_cannot_map():
    x = ca.SX.sym("x", 2, 2)
    with pytest.raises(ValueError, match="not a column"):
        ColumnMap(ca.Function("f", [x], [x[0, 0]]))
    y, z = ca.SX.sym("y", 2), ca.SX.sym("z", 2)
    cm = ColumnMap(ca.Function("g", [y, z], [y + z]), chunk=2)
    with pytest.raises(ValueError, match="1 or 3 columns"):
        cm(np.zeros((2, 3)), np.zeros((2, 2)))
