"""Helpers shared by the control property tests: Bryson's weights written out by hand and the
equilibrium current at a gap.
"""

from __future__ import annotations

import numpy as np

from maglev_oc.control.lqr import AxisWeights
from maglev_oc.model.equilibrium import equilibrium_currents

GAP = 0.020  # [m] a scheduled gap (8 mm + 24 x 0.5 mm)


def _bryson(w: AxisWeights) -> tuple[np.ndarray, np.ndarray]:
    """Bryson's rule written out: Q = diag(1 / max^2), R = 1 / current_max^2."""
    maxima = np.array([w.error, w.error_rate, *w.internal_model])
    return np.diag(maxima**-2.0), np.array([[w.current**-2.0]])


def _equilibrium_current(model, gap: float = GAP) -> float:
    return float(np.asarray(equilibrium_currents(model, [gap]).current)[0])
