"""The model a user names: a stage file (:mod:`maglev_oc.model.stagefile`, or the output of
``identify``/``diagnose --json`` that holds one), the older stage/constants JSON
(:func:`~maglev_oc.model.parameters.save_json`), or the papers' parameters, optionally with one of
the papers' constant sets."""

from __future__ import annotations

import os
from pathlib import Path

from maglev_oc.errors import InputError
from maglev_oc.model.parameters import DEFAULT_CONSTANTS, StageParameters, load_json, paper_constants
from maglev_oc.model.stage import StageModel

__all__ = ["load_model"]


def load_model(params_path: str | os.PathLike | None = None, constants: str | None = None) -> StageModel:
    """The model from a stage file, or Table I with the default constants.

    Parameters
    ----------
    params_path : path, optional
        A stage file (``format: maglev_oc.stage``; its geometry and constants, the effects are
        read by :func:`maglev_oc.model.stagefile.stage_effects`), a command's ``--json`` output with one
        under ``stage``, or the older JSON with optional sections ``stage`` (fields of
        StageParameters, SI) and ``constants``.
    constants : str, optional
        One of the papers' constant sets by name (replaces the file's constants).

    Returns
    -------
    StageModel

    Raises
    ------
    InputError
        The file does not exist, or it or the set name is invalid (the message names which).
    """
    if params_path is not None:
        if Path(params_path).is_dir():
            raise InputError(f"{params_path}: is a directory; --params takes a stage file (JSON)")
        if not Path(params_path).is_file():
            raise InputError(f"{params_path}: no such file")
        from maglev_oc.model.stagefile import StageFile, holds_stage_file

        if holds_stage_file(params_path):
            stage = StageFile.read(params_path)
            params, consts = stage.geometry, stage.constants
        else:
            params, consts = load_json(params_path)
    else:
        params, consts = StageParameters(), DEFAULT_CONSTANTS
    if constants is not None:
        consts = paper_constants(constants)
    return StageModel(params, consts)
