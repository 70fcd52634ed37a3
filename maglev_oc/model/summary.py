"""Everything the model report and ``maglev-oc model`` show, computed in one place."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from maglev_oc.model.equilibrium import (
    EquilibriumCurve,
    NoEquilibriumError,
    equilibrium_currents,
    gap_for_current,
)
from maglev_oc.model.feedback import FeedbackTransformation
from maglev_oc.model.linearization import OpenLoopPoles, open_loop_poles
from maglev_oc.model.magnetics import FieldPolynomial, fit_field_polynomial
from maglev_oc.model.parameters import PAPER_CONSTANTS, LumpedConstants
from maglev_oc.model.stage import StageModel

__all__ = ["TABLE_GAPS", "ModelSummary", "equilibrium_table_rows", "summarize_model"]

TABLE_GAPS = np.array([8.0, 10.0, 12.5, 15.0, 17.5, 20.0, 22.5, 25.0, 27.5, 30.0]) * 1e-3
"""Gaps [m] of the printed equilibrium table."""


@dataclass(frozen=True)
class ModelSummary:
    """Model quantities over a gap grid. Arrays indexed by gap have shape (n,) or (k, n)."""

    model: StageModel
    gap: np.ndarray  # [m]
    coefficients: np.ndarray  # (4, n): L1 [m/(s^2 A)], L2 [m/s^2], L3 [m/(s^2 A)], L4 [m/(s^2 A^2)]
    equilibrium: EquilibriumCurve
    equilibrium_by_set: dict[str, EquilibriumCurve]  # the papers' constant sets
    open_loop: OpenLoopPoles
    field: np.ndarray  # closed-form B [T]
    field_fit: FieldPolynomial
    field_fit_values: np.ndarray  # polynomial B [T]
    v2_max: np.ndarray  # largest feasible v2 at v1 = 0: R / (4 L4) at v = 0 [m/s^2]
    zero_current_gap: float | None  # [m] where i_d = 0 holds the gap
    physical_constants: LumpedConstants
    winding_factor: float
    table: EquilibriumCurve  # at TABLE_GAPS
    table_poles: OpenLoopPoles  # at TABLE_GAPS


def summarize_model(model: StageModel, gaps=None, *, table_gaps=TABLE_GAPS) -> ModelSummary:
    """Compute the model summary over ``gaps`` [m] (default 5-35 mm, 301 points); the table
    rows are at ``table_gaps`` [m]."""
    gap = np.linspace(5e-3, 35e-3, 301) if gaps is None else np.asarray(gaps, dtype=float)
    fit = fit_field_polynomial(model.params)
    fbt = FeedbackTransformation(model)
    by_set = {
        name: equilibrium_currents(model.with_constants(c), gap)
        for name, c in PAPER_CONSTANTS.items()
        if name.startswith("table3")
    }
    try:
        zero_gap: float | None = gap_for_current(model, 0.0)
    except NoEquilibriumError:
        zero_gap = None
    return ModelSummary(
        model=model,
        gap=gap,
        coefficients=model.coefficients(gap),
        equilibrium=equilibrium_currents(model, gap),
        equilibrium_by_set=by_set,
        open_loop=open_loop_poles(model, gap),
        field=StageModel(model.params, model.constants).field_at(gap),  # closed form
        field_fit=fit,
        field_fit_values=np.asarray(fit(gap)),
        v2_max=fbt.feasibility_margin(gap, 0.0, 0.0),
        zero_current_gap=zero_gap,
        physical_constants=model.params.physical_constants(),
        winding_factor=model.params.winding_factor,
        table=equilibrium_currents(model, table_gaps),
        table_poles=open_loop_poles(model, table_gaps),
    )


def equilibrium_table_rows(summary: ModelSummary) -> list[tuple]:
    """Rows (gap mm, i_d A, status, vertical open-loop pole 1/s) of the printed table."""
    rows = []
    t, p = summary.table, summary.table_poles
    for k in range(t.gap.size):
        if not t.exists[k]:
            status = "no equilibrium"
        elif t.within_continuous[k]:
            status = "ok"
        elif t.within_peak[k]:
            status = "> 7 A continuous"
        else:
            status = "> 9 A peak"
        rows.append((t.gap[k] * 1e3, float(t.current[k]), status, float(p.vertical[k, 0].real)))
    return rows
