"""The diagnosis's effects named in the words a control engineer uses, for the reports and for
the sentences the diagnosis itself writes (the experiment that would separate an effect)."""

from __future__ import annotations

import re
from pathlib import Path

__all__ = ["listed", "log_names", "plain"]

_WORDS = {
    "guide_friction_horizontal": "horizontal guide friction",
    "guide_friction_vertical": "vertical guide friction",
    "horizontal_guides_not_level": "horizontal guides off level",
    "constant_vertical_force": "constant vertical force",
    "attraction_gap_dependence": "gap dependence of the attraction",
    "magnet_field_gap_dependence": "gap dependence of the magnets' field",
    "magnet_field_drift": "magnets' field drifting (warming)",
    "gap_sensor_offset": "gap sensor offset",
    "thrust_ripple": "thrust ripple",
    "guide_misalignment": "guides tilted against the stator",
    "cable_carrier_force": "cable carrier force",
    "commutation_offset": "commutation angle offset",
    "commutation_offset_horizontal": "commutation angle offset, fitted on the thrust",
    "current_sensor_offset": "current sensor offset",
    "current_sensor_gain_mismatch": "current sensors' gain mismatch",
    "end_effects": "end effects",
    "current_amplifier_lag": "current amplifier lag",
    "current_amplifier_lag_vertical": "current amplifier lag, fitted on the vertical axis",
    "current_saturation": "iron saturated by the current",
}
"""The diagnosis library's effects in the words a control engineer uses."""


def plain(name: str) -> str:
    """An effect's name in words: ``cogging_vertical_38mm`` -> ``normal cogging, 38 mm period``,
    ``guide_friction_horizontal`` -> ``horizontal guide friction`` (its forms ``..._with_stribeck``
    and ``..._without_viscous`` say so); unknown names lose their underscores."""
    if name in _WORDS:
        return _WORDS[name]
    if m := re.fullmatch(r"cogging_(vertical|horizontal)_(\d+)mm", name):
        kind = "normal cogging" if m[1] == "vertical" else "cogging along the travel"
        return f"{kind} ({m[2]} mm period)"
    if m := re.fullmatch(r"guide_waviness_(\d+)mm", name):
        return f"guide waviness ({m[1]} mm period)"
    # a friction's other forms (diagnosis.guides)
    if m := re.fullmatch(r"(.+)_without_viscous", name):
        return f"{plain(m[1])}, without its viscous part"
    if m := re.fullmatch(r"(.+)_with_stribeck", name):
        return f"{plain(m[1])} with its Stribeck rise"
    return name.replace("_", " ")


def listed(items: list[str]) -> str:
    """ "a", "a and b", "a, b and c"."""
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} and {items[-1]}"


def log_names(sources: tuple[str, ...]) -> list[str]:
    """The logs' file names as a report names them ("log 2" where two share a name)."""
    names = [Path(s).name for s in sources]
    return names if len(set(names)) == len(names) else [f"log {k + 1}" for k in range(len(names))]
