"""Cases shared by the identification property tests: two short pieces of the twin log, the unit
circle problem for constrained Gauss-Newton, and a stand-in prediction for C1..C4. The fixture is
registered in ``tests/conftest.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from maglev_oc.identification.design import Prediction
from maglev_oc.regression.base import CONSTANT_NAMES

DATA = np.array([2.0, 0.5])


def _circle(w):
    """r = w - DATA, c = |w|^2 - 1: the closest point of the unit circle to DATA."""
    r = w - DATA
    c = np.array([w @ w - 1.0])
    return r, c, sp.identity(2, format="csr"), sp.csr_matrix(2 * w[None, :])


@pytest.fixture(scope="module")
def two_logs(twin_log):
    """Two 1 s pieces of the 6 s twin log (1001 samples: 20 segments of 50 samples each)."""
    return twin_log.index_slice(0, 1001), twin_log.index_slice(3000, 4001)


def _prediction(model, violations=()) -> Prediction:
    """A prediction for C1..C4 with 10 % standard errors (only its names and stderr are read)."""
    nominal = np.array(model.constants.as_array())
    return Prediction(
        CONSTANT_NAMES,
        nominal,
        np.diag((0.1 * nominal) ** 2),
        1.0,
        np.array([1.0, 2.0]),
        1.5,
        np.array([15e-3, 25e-3]),
        np.array([-40e-3, 40e-3]),
        tuple(violations),
    )
