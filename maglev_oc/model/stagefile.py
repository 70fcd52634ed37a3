"""The stage file: one versioned JSON document that holds a stage as the tools found it.

    {
      "format": "maglev_oc.stage", "version": 1,
      "geometry":  {StageParameters fields, SI},
      "constants": {"C1": .., "C2": .., "C3": .., "C4": .., "source": "...",
                    "covariance": 4x4 over (C1, C2, C3, C4) or null,
                    "stderr": {"C1": ..} (only without a covariance; null entries: unknown)},
      "effects":   [{"name", "axis", "explanation", "finding",
                     "parameters": {name: {"value", "stderr", "unit"}},
                     "acceleration": (x (4), i (2)) -> (x2', x4') [m/s^2],
                     "compensation": (x (4)) -> (x2', x4') [m/s^2] or null}],
      "provenance": {"geometry" | "constants" | "effects":
                     {"sources": [paths], "method": "...", "date": ISO 8601, "tool_version": "..."}}
    }

``maglev-oc identify --json`` and ``diagnose --json`` write one under the key ``stage`` of their
output; every ``--params`` option reads either form as it is (:func:`maglev_oc.model.loading.load_model`).
An effect's ``acceleration`` is the whole effect (current rates taken as zero, as in a twin of the
identified plant) and ``compensation`` the part a controller can feed forward (null when the
effect depends on the currents): both are formulas written as data
(:mod:`maglev_oc.expressions`), built from a diagnosis by
:func:`maglev_oc.diagnosis.stage_file.diagnosis_stage_file`.

Floats are written with ``repr`` precision: a file read back gives bit-identical numbers. A file
of another version, or a malformed one, raises :class:`~maglev_oc.errors.InputError` naming the
file and the field path (``stage.json: constants.covariance[2][1]: ...``). Files are written
atomically and never modified.
"""

from __future__ import annotations

import datetime
import json
import math
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from types import MappingProxyType
from typing import Any

import casadi as ca
import numpy as np

from maglev_oc.errors import InputError
from maglev_oc.expressions import function_from_data
from maglev_oc.fileio import write_text_atomic
from maglev_oc.model.parameters import LumpedConstants, StageParameters
from maglev_oc.model.stage import StageModel
from maglev_oc.results import Estimate

__all__ = [
    "EFFECT_NAMES",
    "FORMAT",
    "VERSION",
    "Provenance",
    "StageEffect",
    "StageFile",
    "holds_stage_file",
    "known_effect",
    "stage_covariance",
    "stage_effects",
]

FORMAT = "maglev_oc.stage"
VERSION = 1
"""The version this maglev_oc writes and reads."""
CONSTANT_NAMES = ("C1", "C2", "C3", "C4")
PARTS = ("geometry", "constants", "effects")
EFFECT_NAMES = (
    r"guide_friction_(vertical|horizontal)",
    r"horizontal_guides_not_level",
    r"constant_vertical_force",
    r"cable_carrier_force",
    r"guide_misalignment",
    r"guide_waviness_\d+mm",
    r"gap_sensor_offset",
    r"cogging_(vertical|horizontal)_\d+mm",
    r"end_effects",
    r"magnet_field_gap_dependence",
    r"attraction_gap_dependence",
    r"thrust_ripple",
    r"commutation_offset",
    r"current_amplifier_lag",
    r"current_saturation",
    r"current_sensor_offset",
    r"current_sensor_gain_mismatch",
    r"magnet_field_drift",
)
"""The names of the diagnosis library's effects (:mod:`maglev_oc.diagnosis.library`), as patterns."""
_MAX_BYTES = 20_000_000  # [bytes] a stage file is a few kB per effect; refuse anything huge
# a covariance is symmetric and positive semidefinite up to rounding: relative to its scale
_SYMMETRY_TOL = 1e-9
_PSD_TOL = 1e-9


def tool_version() -> str:
    """``maglev_oc <version>`` from the installed package's metadata."""
    try:
        return f"maglev_oc {version('maglev_oc')}"
    except PackageNotFoundError:  # a source tree that is not installed
        return "maglev_oc (not installed)"


# --- checked access to JSON values ---------------------------------------------------------
class _At:
    """A JSON value and where it is: the file and the field path, for error messages."""

    def __init__(self, value: Any, file: str, path: str = "") -> None:
        self.value, self.file, self.path = value, file, path

    def error(self, problem: str) -> InputError:
        return InputError(f"{self.file}: {self.path or '(top level)'}: {problem}")

    def key(self, name: str) -> _At:
        return _At(
            self.value.get(name) if isinstance(self.value, dict) else None, self.file, self._join(name)
        )

    def item(self, k: int) -> _At:
        return _At(self.value[k], self.file, f"{self.path}[{k}]")

    def _join(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def obj(self, required: tuple[str, ...], optional: tuple[str, ...] = ()) -> dict[str, _At]:
        if not isinstance(self.value, dict):
            raise self.error(f"expected an object, got {_kind(self.value)}")
        missing = [k for k in required if k not in self.value]
        if missing:
            raise _At(None, self.file, self._join(missing[0])).error("missing")
        unknown = sorted(set(self.value) - set(required) - set(optional))
        if unknown:
            raise _At(None, self.file, self._join(unknown[0])).error(
                f"unknown field; known: {', '.join((*required, *optional))}"
            )
        return {k: self.key(k) for k in (*required, *optional) if k in self.value}

    def list(self) -> list[_At]:
        if not isinstance(self.value, list):
            raise self.error(f"expected a list, got {_kind(self.value)}")
        return [self.item(k) for k in range(len(self.value))]

    def str(self) -> str:
        if not isinstance(self.value, str):
            raise self.error(f"expected a string, got {_kind(self.value)}")
        return self.value

    def number(self, *, optional: bool = False) -> float | None:
        v = self.value
        if v is None and optional:
            return None
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.error(f"expected a number, got {_kind(v)}")
        if not math.isfinite(v):
            raise self.error(f"expected a finite number, got {v!r}")
        return float(v) if isinstance(v, float) else v


def _kind(v: Any) -> str:
    if v is None:
        return "null"
    return {dict: "an object", list: "a list", str: "a string", bool: "true/false"}.get(
        type(v), f"{type(v).__name__} {v!r}"
    )


def _wrap(at: _At, build):
    """``build()``, with the InputError of a constructor re-raised with the file and field."""
    try:
        return build()
    except InputError as err:
        message = re.sub(r"^(StageParameters|LumpedConstants)\.", "", str(err))
        raise at.error(message) from None


# --- the parts ------------------------------------------------------------------------------
@dataclass(frozen=True)
class Provenance:
    """Where a part of the stage file came from.

    Attributes
    ----------
    sources : tuple of str
        The logs (or the file) it was computed from; empty for the papers' values.
    method : str
        How, in words (``"output_error"``, ``"diagnose: equation-error refit with the effects"``).
    date : str
        When, ISO 8601 with the time zone.
    tool_version : str
        ``maglev_oc <version>`` that computed it.
    """

    sources: tuple[str, ...]
    method: str
    date: str
    tool_version: str

    def __post_init__(self) -> None:
        object.__setattr__(self, "sources", tuple(str(s) for s in self.sources))

    @classmethod
    def now(cls, sources, method: str) -> Provenance:
        """Made now by this maglev_oc."""
        date = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
        return cls(tuple(str(s) for s in sources), method, date, tool_version())

    def to_dict(self) -> dict[str, Any]:
        return {
            "sources": list(self.sources),
            "method": self.method,
            "date": self.date,
            "tool_version": self.tool_version,
        }

    @classmethod
    def _read(cls, at: _At) -> Provenance:
        f = at.obj(("sources", "method", "date", "tool_version"))
        sources = tuple(s.str() for s in f["sources"].list())
        date = f["date"].str()
        try:
            datetime.datetime.fromisoformat(date)
        except ValueError:
            raise f["date"].error(f"not an ISO 8601 date: {date!r}") from None
        return cls(sources, f["method"].str(), date, f["tool_version"].str())


@dataclass(frozen=True)
class StageEffect:
    """A found effect as the stage file holds it.

    Attributes
    ----------
    name, axis, explanation, finding : str
        As ``diagnose`` reported them (``axis``: vertical, horizontal or both).
    parameters : mapping name -> Estimate
        Physical parameters with standard errors (NaN: unknown) and units.
    acceleration : dict
        The whole effect's acceleration as data (:mod:`maglev_oc.expressions`):
        (x (4), i (2)) -> (x2', x4') [m/s^2].
    compensation : dict or None
        The part a controller can feed forward: (x (4)) -> (x2', x4') [m/s^2]; None when the
        effect depends on the currents.
    acceleration_function, compensation_function : casadi.Function (or None)
        Built from the data when the object is made.
    """

    name: str
    axis: str
    explanation: str
    finding: str
    parameters: Mapping[str, Estimate]
    acceleration: Mapping[str, Any]
    compensation: Mapping[str, Any] | None = None
    acceleration_function: ca.Function = field(init=False, repr=False, compare=False)
    compensation_function: ca.Function | None = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if not known_effect(self.name):
            raise InputError(f"StageEffect.name: {_unknown_effect(self.name)}")
        if self.axis not in ("vertical", "horizontal", "both"):
            raise InputError(
                f"StageEffect {self.name}: axis must be vertical, horizontal or both, got {self.axis!r}"
            )
        set_(self, "parameters", MappingProxyType(dict(self.parameters)))
        where = f"StageEffect {self.name}: "
        set_(self, "acceleration_function", _effect_function(self.acceleration, f"{where}acceleration", 2))
        comp = None
        if self.compensation is not None:
            comp = _effect_function(self.compensation, f"{where}compensation", 1)
        set_(self, "compensation_function", comp)

    @property
    def compensable(self) -> bool:
        """Whether a controller can feed the effect forward (it depends on the state alone)."""
        return self.compensation is not None

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "axis": self.axis,
            "explanation": self.explanation,
            "finding": self.finding,
            "parameters": {
                k: {"value": e.value, "stderr": e.stderr if math.isfinite(e.stderr) else None, "unit": e.unit}
                for k, e in self.parameters.items()
            },
            "acceleration": self.acceleration,
            "compensation": self.compensation,
        }

    @classmethod
    def _read(cls, at: _At) -> StageEffect:
        f = at.obj(("name", "axis", "explanation", "finding", "parameters", "acceleration", "compensation"))
        params = {}
        pa = f["parameters"]
        if not isinstance(pa.value, dict):
            raise pa.error(f"expected an object, got {_kind(pa.value)}")
        for k in pa.value:
            p = pa.key(k).obj(("value", "stderr", "unit"))
            stderr = p["stderr"].number(optional=True)
            if stderr is not None and stderr < 0:
                raise p["stderr"].error(f"a standard error must be >= 0, got {stderr!r}")
            params[k] = Estimate(p["value"].number(), math.nan if stderr is None else stderr, p["unit"].str())
        name, axis = f["name"].str(), f["axis"].str()
        if not known_effect(name):
            raise f["name"].error(_unknown_effect(name))
        if axis not in ("vertical", "horizontal", "both"):
            raise f["axis"].error(f"expected vertical, horizontal or both, got {axis!r}")
        acc, comp = f["acceleration"], f["compensation"]
        _effect_function(acc.value, f"{acc.file}: {acc.path}", 2)
        if comp.value is not None:
            _effect_function(comp.value, f"{comp.file}: {comp.path}", 1)
        return cls(name, axis, f["explanation"].str(), f["finding"].str(), params, acc.value, comp.value)


def known_effect(name: str) -> bool:
    """Whether ``name`` is one of the diagnosis library's effects (:data:`EFFECT_NAMES`)."""
    return any(re.fullmatch(p, name) for p in EFFECT_NAMES)


def _unknown_effect(name: str) -> str:
    return f"unknown effect {name!r}; the diagnosis's effects are " + ", ".join(EFFECT_NAMES)


def _effect_function(data: Any, where: str, n_in: int) -> ca.Function:
    """An effect's (x (4), i (2)) -> acc (2) (``n_in`` 2) or (x (4)) -> acc (2) (``n_in`` 1)."""
    fn = function_from_data(data, "effect", where)
    want = [4, 2][:n_in]
    if [fn.size1_in(k) for k in range(fn.n_in())] != want or fn.n_out() != 1 or fn.size1_out(0) != 2:
        shape = "(x (4), i (2))" if n_in == 2 else "(x (4))"
        raise InputError(f"{where}: must map {shape} -> acc (2)")
    return fn


@dataclass(frozen=True, eq=False)
class StageFile:
    """A stage: geometry, constants with their uncertainty, found effects, and provenance.

    Attributes
    ----------
    geometry : StageParameters
    constants : LumpedConstants
    covariance : (4, 4) array or None
        Covariance of (C1, C2, C3, C4) [their units squared]; zero rows for constants held
        fixed. None when not known (then ``stderr`` may say what is).
    stderr : mapping C1..C4 -> float or None
        Standard errors; from the covariance when there is one, NaN where unknown.
    effects : tuple of StageEffect
    provenance : mapping part -> Provenance
        For ``"geometry"``, ``"constants"`` and ``"effects"``.
    """

    geometry: StageParameters
    constants: LumpedConstants
    covariance: np.ndarray | None
    stderr: Mapping[str, float]
    effects: tuple[StageEffect, ...]
    provenance: Mapping[str, Provenance]

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if self.covariance is not None:
            cov = np.array(self.covariance, dtype=float)
            _check_covariance(cov, lambda i, j, p: InputError(f"StageFile.covariance{_index(i, j)}: {p}"))
            cov.setflags(write=False)
            set_(self, "covariance", cov)
            set_(self, "stderr", {k: math.sqrt(cov[i, i]) for i, k in enumerate(CONSTANT_NAMES)})
        stderr = {k: float(self.stderr.get(k, math.nan)) for k in CONSTANT_NAMES}
        set_(self, "stderr", MappingProxyType(stderr))
        set_(self, "effects", tuple(self.effects))
        missing = [p for p in PARTS if p not in self.provenance]
        if missing:
            raise InputError(f"StageFile.provenance: missing {', '.join(missing)}")
        set_(self, "provenance", MappingProxyType(dict(self.provenance)))

    # --- use ------------------------------------------------------------------------------
    def model(self) -> StageModel:
        """The StageModel of this geometry and these constants (the effects are not part of it)."""
        return StageModel(self.geometry, self.constants)

    def compensation(self) -> ca.Function | None:
        """Sum of the compensable effects: (x (4)) -> (x2', x4') [m/s^2], for
        ``FeedbackLinearizingRegulator(compensation=...)``; None when there are none."""
        parts = [e.compensation_function for e in self.effects if e.compensable]
        if not parts:
            return None
        x = ca.SX.sym("x", 4)
        return ca.Function("effects", [x], [sum((f(x) for f in parts), ca.SX.zeros(2, 1))], ["x"], ["acc"])

    def plant_effects(self) -> ca.Function | None:
        """Sum of every effect: (x (4), i (2)) -> (x2', x4') [m/s^2], for
        ``TwinEffects(extra=...)`` (a twin of the identified plant); None without effects."""
        if not self.effects:
            return None
        x, i = ca.SX.sym("x", 4), ca.SX.sym("i", 2)
        acc = sum((e.acceleration_function(x, i) for e in self.effects), ca.SX.zeros(2, 1))
        return ca.Function("effects", [x, i], [acc], ["x", "i"], ["acc"])

    # --- JSON -----------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        c = self.constants
        constants: dict[str, Any] = {k: getattr(c, k) for k in CONSTANT_NAMES}
        constants["source"] = c.source
        constants["covariance"] = None if self.covariance is None else self.covariance.tolist()
        if self.covariance is None and any(math.isfinite(v) for v in self.stderr.values()):
            constants["stderr"] = {k: (v if math.isfinite(v) else None) for k, v in self.stderr.items()}
        return {
            "format": FORMAT,
            "version": VERSION,
            "geometry": self.geometry.to_dict(),
            "constants": constants,
            "effects": [e.to_dict() for e in self.effects],
            "provenance": {p: self.provenance[p].to_dict() for p in PARTS},
        }

    @classmethod
    def from_dict(cls, data: Any, *, source: str = "<stage file>", path: str = "") -> StageFile:
        """From JSON data; errors name ``source`` (the file) and the field path under ``path``."""
        top = _At(data, source, path)
        if not isinstance(data, dict):
            raise top.error(f"expected an object, got {_kind(data)}")
        fmt, ver = top.key("format"), top.key("version")
        for at in (fmt, ver):
            if at.path.rsplit(".", 1)[-1] not in data:
                raise at.error("missing")
        if fmt.value != FORMAT:
            raise fmt.error(f"expected {FORMAT!r}, got {fmt.value!r} (not a maglev_oc stage file)")
        if isinstance(ver.value, bool) or not isinstance(ver.value, int):
            raise ver.error(f"expected an integer, got {_kind(ver.value)}")
        if ver.value != VERSION:
            raise ver.error(
                f"version {ver.value} is not supported: {tool_version()} reads stage files of version "
                f"{VERSION} only" + (" (write it again with this version)" if ver.value < VERSION else "")
            )
        f = top.obj(("format", "version", "geometry", "constants", "effects", "provenance"))
        geometry = _read_geometry(f["geometry"])
        constants, covariance, stderr = _read_constants(f["constants"])
        effects = tuple(StageEffect._read(at) for at in f["effects"].list())
        prov = f["provenance"].obj(PARTS)
        provenance = {p: Provenance._read(prov[p]) for p in PARTS}
        return cls(geometry, constants, covariance, stderr, effects, provenance)

    @classmethod
    def read(cls, path: str | os.PathLike) -> StageFile:
        """A stage file, or the output of ``identify``/``diagnose --json`` (its ``stage`` key)."""
        data = _load(path)
        if isinstance(data, dict) and "format" not in data and isinstance(data.get("stage"), dict):
            return cls.from_dict(data["stage"], source=str(path), path="stage")
        return cls.from_dict(data, source=str(path))

    def write(self, path: str | os.PathLike) -> Path:
        """Write atomically (the whole file or nothing)."""
        text = json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n"
        return write_text_atomic(path, text)

    # --- made by the tools ----------------------------------------------------------------
    @classmethod
    def from_identification(cls, outcome, model: StageModel, geometry: Provenance) -> StageFile:
        """From an :class:`~maglev_oc.identification.pipeline.IdentificationOutcome`: the
        identified constants with the best fit's covariance; no effects."""
        best = outcome.best
        constants = outcome.constants()
        covariance, stderr = None, {}
        if best is not None:
            cov = np.zeros((4, 4))
            idx = [(i, best.names.index(k)) for i, k in enumerate(CONSTANT_NAMES) if k in best.names]
            for i, a in idx:
                for j, b in idx:
                    cov[i, j] = best.covariance[a, b]
            if np.all(np.isfinite(cov)):
                covariance = cov
            else:
                stderr = {k: best.stderr[k] for k in CONSTANT_NAMES if k in best.stderr}
            method = best.method
        else:
            method = f"npfsi ({constants.source})"
        return cls(
            model.params,
            constants,
            covariance,
            stderr,
            (),
            {
                "geometry": geometry,
                "constants": Provenance.now(outcome.sources, method),
                "effects": Provenance.now((), "none: identify fits the constants only"),
            },
        )

    @staticmethod
    def geometry_provenance(params_path: str | os.PathLike | None) -> Provenance:
        """Where a command's geometry came from: the stage file's own provenance, the
        ``--params`` file, or the papers' Table I."""
        if params_path is None:
            return Provenance.now((), "Table I of paper 000 (the papers' stage)")
        if holds_stage_file(params_path):
            return StageFile.read(params_path).provenance["geometry"]
        return Provenance.now((str(params_path),), "stage/constants JSON given with --params")


def _index(i: int | None, j: int | None) -> str:
    return "".join(f"[{k}]" for k in (i, j) if k is not None)


def _check_covariance(cov: np.ndarray, error) -> None:
    """Raise ``error(i, j, problem)`` unless ``cov`` is a symmetric PSD 4x4 matrix."""
    if cov.shape != (4, 4):
        raise error(None, None, f"expected 4 x 4 (C1..C4), got {' x '.join(map(str, cov.shape))}")
    for i in range(4):
        if not cov[i, i] >= 0:
            raise error(i, i, f"a variance must be >= 0, got {float(cov[i, i])!r}")
    for i in range(4):
        for j in range(i):
            scale = math.sqrt(cov[i, i] * cov[j, j])
            if abs(cov[i, j] - cov[j, i]) > _SYMMETRY_TOL * max(scale, 1e-300):
                raise error(
                    i,
                    j,
                    f"{float(cov[i, j])!r} differs from [{j}][{i}] = {float(cov[j, i])!r}: not symmetric",
                )
            # |cov[i][j]| <= sqrt(cov[i][i] cov[j][j]): beside a zero variance a covariance is zero
            # (the correlations below leave such a row out), up to rounding: a product A A' whose
            # small entries' squares underflow keeps their products with the large ones (4.7e-181
            # beside a variance of 0 and one of 1, found by hypothesis)
            room = _PSD_TOL * math.sqrt(max(cov[i, i], cov[j, j]) * float(np.max(np.diag(cov))))
            if (cov[i, i] == 0 or cov[j, j] == 0) and abs(cov[i, j]) > max(room, 1e-300):
                raise error(
                    i,
                    j,
                    f"{float(cov[i, j])!r} beside a zero variance: not positive semidefinite",
                )
    d = np.sqrt(np.diag(cov))
    scaled = np.where(np.outer(d, d) > 0, cov / np.where(np.outer(d, d) > 0, np.outer(d, d), 1.0), 0.0)
    lowest = float(np.linalg.eigvalsh(0.5 * (scaled + scaled.T)).min())
    if lowest < -_PSD_TOL * 4:
        raise error(None, None, f"not positive semidefinite (correlation eigenvalue {lowest:.3g} < 0)")


def _read_geometry(at: _At) -> StageParameters:
    known = tuple(f.name for f in fields(StageParameters))
    f = at.obj((), known)
    values = {k: v.number() for k, v in f.items()}
    return _wrap(at, lambda: StageParameters(**values))


def _read_constants(at: _At) -> tuple[LumpedConstants, np.ndarray | None, dict[str, float]]:
    f = at.obj((*CONSTANT_NAMES, "source", "covariance"), ("stderr",))
    values = {k: f[k].number() for k in CONSTANT_NAMES}
    for k in CONSTANT_NAMES:
        if values[k] <= 0:
            raise f[k].error(f"must be positive, got {values[k]!r}")
    constants = _wrap(at, lambda: LumpedConstants(**values, source=f["source"].str()))
    covariance = None
    cv = f["covariance"]
    if cv.value is not None:
        rows = cv.list()
        if len(rows) != 4:
            raise cv.error(f"expected 4 rows (C1..C4), got {len(rows)}")
        matrix = []
        for r in rows:
            cells = r.list()
            if len(cells) != 4:
                raise r.error(f"expected 4 columns (C1..C4), got {len(cells)}")
            matrix.append([c.number() for c in cells])
        covariance = np.array(matrix, dtype=float)
        _check_covariance(covariance, lambda i, j, p: _At(None, cv.file, cv.path + _index(i, j)).error(p))
    stderr: dict[str, float] = {}
    if "stderr" in f:
        if covariance is not None:
            raise f["stderr"].error("give a covariance or standard errors, not both")
        s = f["stderr"].obj((), CONSTANT_NAMES)
        for k, v in s.items():
            value = v.number(optional=True)
            if value is not None and value < 0:
                raise v.error(f"a standard error must be >= 0, got {value!r}")
            stderr[k] = math.nan if value is None else value
    return constants, covariance, stderr


def _load(path: str | os.PathLike) -> Any:
    """The JSON value of ``path``; a clear InputError when it is not a readable JSON text."""
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{p}: is a directory; expected a stage file (JSON)")
    if not p.is_file():
        raise InputError(f"{p}: no such file")
    if p.stat().st_size > _MAX_BYTES:
        raise InputError(f"{p}: {p.stat().st_size} bytes is too large for a stage file")
    try:
        text = p.read_bytes().decode("utf-8")
    except UnicodeDecodeError as err:
        raise InputError(f"{p}: not a text file (byte {err.start} is not UTF-8)") from None
    if not text.strip():
        raise InputError(f"{p}: empty file; expected a stage file (JSON)")
    try:
        # NaN and Infinity are read as floats so that the field they stand in is named when refused
        return json.loads(text)
    except json.JSONDecodeError as err:
        raise InputError(f"{p}: line {err.lineno}, column {err.colno}: not valid JSON ({err.msg})") from None


def holds_stage_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` is meant as a stage file: a JSON object with a ``format`` (or
    ``version``) field, or a command's output with one under ``stage``. A bad stage file is then
    refused by :meth:`StageFile.read` with the reason; any other JSON object is for the older
    stage/constants reader.

    Raises
    ------
    InputError
        The file cannot be read as JSON (naming the line and column).
    """
    data = _load(path)
    if not isinstance(data, dict):
        return False
    if "format" in data or "version" in data:
        return True
    stage = data.get("stage")
    return isinstance(stage, dict) and ("format" in stage or "version" in stage)


def stage_effects(path: str | os.PathLike) -> tuple[StageEffect, ...]:
    """The found effects of a stage file (none for a file of the older stage/constants form)."""
    if not holds_stage_file(path):
        return ()
    return StageFile.read(path).effects


def stage_covariance(path: str | os.PathLike | None) -> tuple[np.ndarray | None, str]:
    """The covariance (4, 4) of C1..C4 of a stage file and where it came from, or (None, "") for
    no file, a file of the older stage/constants form, or a stage file without a covariance."""
    if path is None or not holds_stage_file(path):
        return None, ""
    stage = StageFile.read(path)
    if stage.covariance is None:
        return None, ""
    return np.asarray(stage.covariance, dtype=float), f"the stage file {Path(path).name}"
