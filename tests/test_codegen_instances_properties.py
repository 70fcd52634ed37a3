"""Replaying recorded instances (maglev_oc.control.codegen): every call's inputs are split at the
Function's input sizes and its outputs come back in the nonzero layout, instance by instance, as
calling the Function on each instance directly gives (a sparse output included)."""

from __future__ import annotations

import casadi as ca
import numpy as np

from maglev_oc.control.codegen import RecordedInstances, evaluate_instances


def test_replayed_outputs_are_the_functions_outputs_on_each_instance():
    a, b = ca.SX.sym("a", 3), ca.SX.sym("b", 2)
    sparse = ca.SX(3, 3)
    sparse[0, 0], sparse[2, 1] = a[0] * b[1], ca.sin(a[2])  # 2 nonzeros of 9
    f = ca.Function("f", [a, b], [ca.vertcat(a * b[0], ca.sumsqr(b)), sparse])
    rng = np.random.default_rng(6)
    rows = rng.normal(size=(5, 5))
    inst = RecordedInstances(rows, (3, 2), (4, 2))
    assert len(inst) == 5
    dense, nz = evaluate_instances(f, inst)
    assert dense.shape == (5, 4) and nz.shape == (5, 2)
    for k, row in enumerate(rows):
        x, y = row[:3], row[3:]
        np.testing.assert_array_equal(dense[k], np.concatenate([x * y[0], [y @ y]]))  # same arithmetic
        np.testing.assert_array_equal(nz[k], [x[0] * y[1], np.sin(x[2])])
