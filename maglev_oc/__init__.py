"""maglev_oc: model, identify, control and analyse the Quanser maglev positioning stage."""

from maglev_oc.model.parameters import (
    DEFAULT_CONSTANTS,
    PAPER_CONSTANTS,
    LumpedConstants,
    StageParameters,
    paper_constants,
)
from maglev_oc.model.stage import StageModel

__all__ = [
    "DEFAULT_CONSTANTS",
    "PAPER_CONSTANTS",
    "LumpedConstants",
    "StageModel",
    "StageParameters",
    "paper_constants",
]
__version__ = "0.1.0"
