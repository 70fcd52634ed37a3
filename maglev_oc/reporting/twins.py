"""The twins the reports run on, each with one stated truth: the same sentence in every report.

A twin is the plant a study simulates: true constants (which the controllers and estimators do
not know) and the effects the papers' model lacks. Each report states the twins it uses with
:func:`twin_table` or :func:`twin_sentence`, so a reader comparing reports sees one truth per twin.
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass

from maglev_oc.identification.experiments import TWIN_TRUTH, identification_effects
from maglev_oc.model.parameters import DEFAULT_CONSTANTS, PAPER_CONSTANTS, LumpedConstants
from maglev_oc.reporting.pdf import Table
from maglev_oc.sim.comparison import RIG_CONSTANTS
from maglev_oc.sim.effects import TwinEffects

__all__ = ["DIAGNOSIS_TRUTH", "TWINS", "NamedTwin", "twin_sentence", "twin_table"]

DIAGNOSIS_TRUTH = PAPER_CONSTANTS["table3_eps0.05"]
"""The true constants of the closing-the-loop log's twin (they differ from the papers' default)."""


@dataclass(frozen=True)
class NamedTwin:
    """A twin as the reports name it."""

    name: str
    constants: LumpedConstants
    effects: TwinEffects
    used_for: str

    @property
    def constants_text(self) -> str:
        c = self.constants
        return (
            f"C1..C4 = {c.C1:.4g}, {c.C2:.4g}, {c.C3:.4g}, {c.C4:.3g} "
            f"({_plain_source(c)}; the controllers use {_plain_source(DEFAULT_CONSTANTS)})"
        )

    @property
    def effects_text(self) -> str:
        words = self.effects.describe()
        return "; ".join(words) if words else "none: the papers' model exactly (stoppers kept)"


def _plain_source(c: LumpedConstants) -> str:
    roman = {"table2": "Table II", "table3": "Table III"}
    for key, known in PAPER_CONSTANTS.items():
        if list(known.as_array()) == list(c.as_array()):
            table, eps = key.split("_eps")
            return f"{roman.get(table, table)} at eps = {eps}"
    return c.source.removeprefix("twin truth: ") or "custom"


TWINS: dict[str, NamedTwin] = {
    "ideal twin": NamedTwin(
        "ideal twin",
        DEFAULT_CONSTANTS,
        TwinEffects.ideal(),
        "the design check and the operating region's simulations (the controllers' own model)",
    ),
    "rig twin": NamedTwin(
        "rig twin",
        PAPER_CONSTANTS[RIG_CONSTANTS],
        TwinEffects.rig(),
        "the controller comparison on a plant like the papers' rig",
    ),
    "identification twin": NamedTwin(
        "identification twin",
        TWIN_TRUTH,
        identification_effects(),
        "the identification study, where the truth is known and estimates are scored",
    ),
    "diagnosis twin": NamedTwin(
        "diagnosis twin",
        DIAGNOSIS_TRUTH,
        TwinEffects.rig(),
        "the closing-the-loop log, whose effects the diagnosis is not told",
    ),
}


def twin_sentence(name: str) -> str:
    """One sentence stating twin ``name``'s truth."""
    t = TWINS[name]
    return f"The {t.name}, used for {t.used_for}: true {t.constants_text}; effects: {t.effects_text}."


def twin_table(names: tuple[str, ...] = tuple(TWINS)) -> Table:
    """The twins as a table block (every report prints the same rows)."""
    rows = [
        (t.name, t.constants_text.replace(" (", "\n("), _wrap(t.effects_text)) for t in map(TWINS.get, names)
    ]
    return Table(
        "The twins: one truth each, the same in every report", ("twin", "true constants", "effects"), rows
    )


def _wrap(text: str, width: int = 60) -> str:
    return "\n".join(textwrap.wrap(text, width))
