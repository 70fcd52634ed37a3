"""The rig twin with its calibrated sizes as state rows: one build, one compiled loop, many plants.

A :class:`~maglev_oc.sim.twin.RigTwin` bakes every size into its step Function, so each plant a
study tries costs a new CasADi build and, with the C backend, a new gcc run (about 0.15 s of
CPU each, most of a calibration's time). :class:`ParametricTwin` carries the sizes a
calibration varies (:data:`TUNABLE`) as state rows that every step passes on unchanged, so
:meth:`ParametricTwin.at` gives another plant that shares the step and measure Functions, and a
:class:`~maglev_oc.sim.engine.ClosedLoop` built once runs it (:meth:`ClosedLoop.on`).

A plant at :meth:`ParametricTwin.at` steps like the :class:`RigTwin` of the same model and
effects, operation for operation (the same expressions with a row where the RigTwin has a
number; a commutation offset of 0 rotates by cos 0 = 1 and sin 0 = 0). What stays fixed at the
build (the computation delay, the stoppers, every other effect) is the template's.
"""

from __future__ import annotations

import copy
import dataclasses
import math

import casadi as ca
import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.model.stage import StageModel
from maglev_oc.sim.effects import CommutationOffset, TwinEffects
from maglev_oc.sim.twin import ConstantsAsInput, RigTwin

__all__ = ["TUNABLE", "ParametricTwin"]

TUNABLE = (
    "C1",
    "C2",
    "C3",
    "C4",
    "amplifier_bandwidth_hz",
    "commutation_angle",
    "vertical_coulomb",
    "cogging_peak",
)
"""The state rows after the :class:`RigTwin` state, in order: the plant's lumped constants, the
current amplifiers' bandwidth [Hz], the commutation offset [rad] (0 without one), the vertical
guides' Coulomb level [N] and the normal cogging force at the reference gap [N]."""


def _rows(model: StageModel, effects: TwinEffects) -> np.ndarray:
    """The :data:`TUNABLE` values of the plant ``model`` with ``effects``."""
    angle = effects.commutation.angle if effects.commutation is not None else 0.0
    return np.array(
        [
            *model.constants.as_array(),
            effects.amplifier.bandwidth_hz,
            angle,
            effects.friction_vertical.coulomb,
            effects.cogging.peak_at_reference,
        ],
        dtype=float,
    )


def _structure(effects: TwinEffects) -> TwinEffects:
    """``effects`` with the tunable sizes at fixed values: what a build depends on."""
    return dataclasses.replace(
        effects,
        amplifier=dataclasses.replace(effects.amplifier, bandwidth_hz=1.0),
        commutation=CommutationOffset(0.0),
        friction_vertical=dataclasses.replace(effects.friction_vertical, coulomb=1.0),
        cogging=dataclasses.replace(effects.cogging, peak_at_reference=1.0),
    )


class ParametricTwin(RigTwin):
    """A :class:`RigTwin` whose :data:`TUNABLE` sizes are state rows (the last ``len(TUNABLE)``).

    Made like a RigTwin, from the true plant and its effects, which must include the current
    amplifiers, the vertical guide friction (Coulomb level above 0) and cogging. Its own rows are
    ``model``'s and ``effects``' sizes (:meth:`initial_state`); :meth:`at` is another plant of the
    same build. ``acceleration`` is this plant's, with its sizes as numbers.
    """

    def __post_init__(self) -> None:
        e = self.effects
        if e.amplifier is None or e.friction_vertical is None or e.cogging is None:
            raise InputError(
                "ParametricTwin needs the current amplifiers, the vertical guide friction and cogging "
                f"in its effects; got {e.enabled()}"
            )
        if not e.friction_vertical.coulomb > 0:
            raise InputError(
                "ParametricTwin needs a vertical Coulomb level above 0 N, got "
                f"{e.friction_vertical.coulomb!r}"
            )
        super().__post_init__()

    def _build(self) -> None:
        object.__setattr__(self, "n_state", self.n_state + len(TUNABLE))  # once, from __post_init__
        self._own_rows()
        super()._build()

    def _own_rows(self) -> None:
        object.__setattr__(self, "_tuned", ca.DM(_rows(self.model, self.effects)))

    # --- RigTwin's hooks, reading the rows -----------------------------------------------------
    def _accelerations(self, x, i, friction):
        plant = self.model
        object.__setattr__(self, "model", ConstantsAsInput(plant, self._tuned[0:4]))
        try:
            return super()._accelerations(x, i, friction)
        finally:
            object.__setattr__(self, "model", plant)

    def _current_decay(self, theta: float):
        time_constant = 1.0 / (2 * math.pi * self._tuned[4])  # CurrentAmplifier.time_constant
        return ca.exp(-theta / time_constant)

    def _commutation_rotation(self):
        return ca.cos(self._tuned[5]), ca.sin(self._tuned[5])

    def _coulomb(self, axis: int):
        return self._tuned[6] if axis == 0 else super()._coulomb(axis)

    def _cogging_peak(self):
        return self._tuned[7]

    def _step_function(self) -> ca.Function:
        """RigTwin's step on the first rows, the tunable rows passed on."""
        nb = self.n_state - len(TUNABLE)
        s = ca.SX.sym("s", self.n_state)
        u_cmd = ca.SX.sym("u", 2)
        object.__setattr__(self, "_tuned", s[nb:])
        base_next, flags = self._step_rows(s[:nb], u_cmd)
        self._own_rows()
        s_next = ca.vertcat(base_next, s[nb:])
        return ca.Function("twin_step", [s, u_cmd], [s_next, flags], ["s", "u"], ["s_next", "flags"])

    # ------------------------------------------------------------------------------------------
    def at(self, model: StageModel, effects: TwinEffects) -> ParametricTwin:
        """The plant ``model`` (true constants) with ``effects``, on this twin's Functions.

        Parameters
        ----------
        model : StageModel
            The true plant: this twin's geometry and field model, any constants.
        effects : TwinEffects
            This twin's effects but for the :data:`TUNABLE` sizes (commutation on or off; a
            vertical Coulomb level above 0).

        Returns
        -------
        ParametricTwin
            Sharing ``step``, ``measure`` and ``n_state`` with this one; its ``acceleration`` is
            this one's (the template's sizes).
        """
        if model.params != self.model.params or model.field_model != self.model.field_model:
            raise InputError("ParametricTwin.at: the plant must have this twin's parameters and field model")
        if effects.amplifier is None or effects.friction_vertical is None or effects.cogging is None:
            raise InputError(f"ParametricTwin.at: effects {effects.enabled()} lack a tunable effect")
        if not effects.friction_vertical.coulomb > 0:
            raise InputError(
                f"ParametricTwin.at: the vertical Coulomb level must be above 0 N, got "
                f"{effects.friction_vertical.coulomb!r}"
            )
        if _structure(effects) != _structure(self.effects):
            raise InputError(
                "ParametricTwin.at: the effects differ from this twin's in more than the tunable sizes"
            )
        plant = copy.copy(self)
        object.__setattr__(plant, "model", model)
        object.__setattr__(plant, "effects", effects)
        object.__setattr__(plant, "_tuned", ca.DM(_rows(model, effects)))
        return plant

    def initial_state(self, x0, u0=(0.0, 0.0)) -> np.ndarray:
        """:meth:`RigTwin.initial_state` followed by this plant's :data:`TUNABLE` rows."""
        return np.concatenate([super().initial_state(x0, u0), np.asarray(self._tuned, dtype=float).ravel()])
