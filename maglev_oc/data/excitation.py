"""Excitation checks: refuse a log on which a signal that identification needs does not move."""

from __future__ import annotations

import math
import types
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np

from maglev_oc.data.log import Log
from maglev_oc.errors import InputError, LogError
from maglev_oc.model.hardware import ENCODER_RESOLUTION

__all__ = ["CURRENT_RESOLUTION", "Excitation", "check_excitation"]

CURRENT_RESOLUTION = 1e-3
"""Resolution of a logged current [A], about 1 mA."""


@dataclass(frozen=True)
class Excitation:
    """How much the signals that identification needs move.

    Attributes
    ----------
    std : mapping
        Standard deviation of x1, x3 [m] and u1, u2 [A].
    resolution : mapping
        The resolution each was compared with (same units).
    checked : tuple of str
        The signals that had to vary (the others are reported but not required).
    """

    std: Mapping[str, float]
    resolution: Mapping[str, float]
    checked: tuple[str, ...]


def check_excitation(
    log: Log,
    *,
    axis: Literal["vertical", "horizontal", "both"] = "both",
    position_resolution: float = ENCODER_RESOLUTION,
    current_resolution: float = CURRENT_RESOLUTION,
) -> Excitation:
    """Refuse a log on which a needed input or output is constant to within its resolution.

    A signal whose standard deviation is at most its resolution (encoder 10 um, current 1 mA)
    is constant as far as the data can tell: a held value toggling between two quantization
    levels has a standard deviation of at most half a step. Equation-error identification of
    the terms it multiplies is then impossible.

    Parameters
    ----------
    log : Log
    axis : {"vertical", "horizontal", "both"}
        Which dynamics are to be identified: vertical needs x1 and u2 (i_d) to vary, horizontal
        x3 and u1 (i_q); "both" all four (the vertical-only runs of 000 Table II hold x3 fixed).
    position_resolution : float
        [m] Default 10 um (the encoders).
    current_resolution : float
        [A] Default 1 mA.

    Returns
    -------
    Excitation

    Raises
    ------
    LogError
        Listing every constant signal with its standard deviation.
    """
    needed = {"vertical": ("x1", "u2"), "horizontal": ("x3", "u1"), "both": ("x1", "x3", "u1", "u2")}
    if axis not in needed:
        raise InputError(f"axis must be 'vertical', 'horizontal' or 'both', got {axis!r}")
    for name, value in (
        ("position_resolution", position_resolution),
        ("current_resolution", current_resolution),
    ):
        if not (value > 0 and math.isfinite(value)):
            raise InputError(f"{name} must be positive, got {value!r}")
    signals = {"x1": log.x[0], "x3": log.x[2], "u1": log.u[0], "u2": log.u[1]}
    resolution = {"x1": position_resolution, "x3": position_resolution}
    resolution |= {"u1": current_resolution, "u2": current_resolution}
    std = {name: float(np.std(value)) for name, value in signals.items()}
    flat = [name for name in needed[axis] if std[name] <= resolution[name]]
    if flat:
        units = {"x1": "m", "x3": "m", "u1": "A", "u2": "A"}
        listed = "; ".join(
            f"{name} std {std[name]:.3g} {units[name]} <= resolution {resolution[name]:g} {units[name]}"
            for name in flat
        )
        raise LogError(
            log.source or "<log>",
            f"no excitation: {listed}; identification needs these signals to vary "
            f"(e.g. the sum-of-sines references of 000 Sec. IV)",
            where=f"column(s) {', '.join(flat)}",
            column=flat[0],
        )
    return Excitation(types.MappingProxyType(std), types.MappingProxyType(resolution), needed[axis])
