"""A diagnosis as a stage file (:mod:`maglev_oc.model.stagefile`): the constants refitted with the
found effects, and each effect's acceleration and compensable part as
:mod:`maglev_oc.diagnosis.feedback` builds them for the FL regulator and the twin."""

from __future__ import annotations

import math

import numpy as np

from maglev_oc.diagnosis.feedback import _effects_acceleration, _state_only
from maglev_oc.diagnosis.result import Diagnosis
from maglev_oc.expressions import function_to_data
from maglev_oc.model.parameters import LumpedConstants
from maglev_oc.model.stage import StageModel
from maglev_oc.model.stagefile import CONSTANT_NAMES, Provenance, StageEffect, StageFile

__all__ = ["diagnosis_stage_file"]


def diagnosis_stage_file(diagnosis: Diagnosis, model: StageModel, geometry: Provenance) -> StageFile:
    """The stage file of a diagnosis.

    Parameters
    ----------
    diagnosis : Diagnosis
    model : StageModel
        The model diagnosed (its geometry; its constants stand in for any the logs do not move).
    geometry : Provenance
        Where the geometry came from (:meth:`StageFile.geometry_provenance`).

    Returns
    -------
    StageFile
        C1..C4 with the long-run covariance of the final joint fit (the effects' coefficients
        estimated beside them; standard errors only when an axis did not move), the effects with their
        physical parameters, accelerations (x, i) -> (x2', x4') with current rates taken as zero,
        and compensable parts (x) -> (x2', x4') for the state-dependent ones.
    """
    final = diagnosis.constants_final
    moved = {k: math.isfinite(final[k].value) and final[k].value > 0 for k in CONSTANT_NAMES}
    values = {k: final[k].value if moved[k] else getattr(model.constants, k) for k in CONSTANT_NAMES}
    covariance = _constants_covariance(diagnosis) if all(moved.values()) else None
    stderr = {} if covariance is not None else {k: final[k].stderr for k in CONSTANT_NAMES if moved[k]}
    sources = tuple(diagnosis.sources)
    constants = LumpedConstants(
        **values, source=f"diagnose: refitted with the found effects on {', '.join(sources)}"
    )
    effects = tuple(
        StageEffect(
            e.name,
            e.axis,
            e.explanation,
            e.finding,
            dict(e.parameters),
            function_to_data(_effects_acceleration([e], with_inputs=True)),
            function_to_data(_effects_acceleration([e], with_inputs=False)) if _state_only(e) else None,
        )
        for e in diagnosis.effects
        if not _drifts(e)
    )
    method = "diagnose: equation-error refit of C1..C4 with the selected effects (held-out validated)"
    drifts = [e.name for e in diagnosis.effects if _drifts(e)]
    if drifts:
        method += f"; the forces drifted over the logs ({', '.join(drifts)}): C1..C4 are the logs' mean"
    return StageFile(
        model.params,
        constants,
        covariance,
        stderr,
        effects,
        {
            "geometry": geometry,
            "constants": Provenance.now(sources, method),
            "effects": Provenance.now(sources, "diagnose: forward selection from the candidate library"),
        },
    )


def _drifts(effect) -> bool:
    """Whether a found effect is a drift over the logs (its terms change with the time in a log): no
    part of the stage at any one time, so not one of the stage file's effects."""
    return all(cand.term.in_time for cand, _ in effect.terms())


def _constants_covariance(diagnosis: Diagnosis) -> np.ndarray | None:
    """The (4, 4) block of C1..C4 in the final fit's long-run covariance (None when the fit does not
    hold all four)."""
    fit = diagnosis.selection.final
    if not all(k in fit.names for k in CONSTANT_NAMES):
        return None
    k = [fit.names.index(n) for n in CONSTANT_NAMES]
    cov = np.array(fit.covariance, dtype=float)[np.ix_(k, k)]
    return 0.5 * (cov + cov.T) if np.all(np.isfinite(cov)) else None
