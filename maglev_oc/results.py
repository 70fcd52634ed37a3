"""The result convention every computation of maglev_oc follows, and the small types it shares.

Every result object is a frozen dataclass that carries

* ``success`` (bool), ``status`` (a short lower-case word: ``"converged"``, ``"certified"``,
  ``"failed"``, ...), ``message`` (one sentence a person reads) and ``timings`` (wall times in
  seconds by step name);
* ``to_dict()``: everything in plain JSON types (:func:`jsonable`);
* ``report()``: the result as text.

:class:`Result` supplies the two methods; :func:`check_result` is what a test asserts of any result.
Physical estimates are :class:`Estimate` (value, standard error, unit); per-axis values are
:class:`PerAxis` (vertical, horizontal), written ``{"vertical": ..., "horizontal": ...}`` in JSON.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping
from typing import Any, Literal

import numpy as np

__all__ = ["AXES", "Axis", "Estimate", "PerAxis", "Result", "check_result", "jsonable"]

Axis = Literal["vertical", "horizontal"]
AXES: tuple[Axis, Axis] = ("vertical", "horizontal")
"""The two axes, in the order of every per-axis array: 0 = vertical (the gap), 1 = horizontal."""


def jsonable(value: Any) -> Any:
    """``value`` in plain JSON types: NaN and infinities become None, arrays lists, objects with
    a ``to_dict`` their dict, dataclasses their fields, mappings dicts with string keys."""
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if hasattr(value, "to_dict") and callable(value.to_dict):
        return value.to_dict()
    if isinstance(value, np.ndarray):
        return [jsonable(v) for v in value.tolist()] if value.ndim else jsonable(value.item())
    if isinstance(value, Mapping):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if dataclasses.is_dataclass(value):
        return {f.name: jsonable(getattr(value, f.name)) for f in dataclasses.fields(value) if f.repr}
    return str(value)


@dataclasses.dataclass(frozen=True)
class Estimate:
    """A physical quantity estimated from data: value, standard error and unit (SI)."""

    value: float
    stderr: float
    unit: str

    def to_dict(self) -> dict:
        return {"value": jsonable(self.value), "stderr": jsonable(self.stderr), "unit": self.unit}

    def __str__(self) -> str:
        """The value to the precision of its standard error (two significant digits of it)."""
        if not (math.isfinite(self.stderr) and self.stderr > 0 and math.isfinite(self.value)):
            return f"{self.value:.4g} {self.unit}".strip()
        decimals = max(0, 1 - math.floor(math.log10(self.stderr)))
        if decimals > 12 or abs(self.value) >= 1e9:
            return f"{self.value:.4g} ± {self.stderr:.2g} {self.unit}".strip()
        return f"{self.value:.{decimals}f} ± {self.stderr:.2g} {self.unit}".strip()


@dataclasses.dataclass(frozen=True)
class PerAxis:
    """One value per axis. Index by name (``v["vertical"]``) or position (``v[0]``)."""

    vertical: float
    horizontal: float

    def __getitem__(self, key: str | int) -> float:
        if isinstance(key, str):
            if key not in AXES:
                raise KeyError(f"axis must be one of {AXES}, got {key!r}")
            return getattr(self, key)
        return (self.vertical, self.horizontal)[key]

    def __iter__(self):
        return iter((self.vertical, self.horizontal))

    def __len__(self) -> int:
        return 2

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        """``np.asarray(v)`` is the pair (vertical, horizontal), as a tuple was before."""
        return np.array([self.vertical, self.horizontal], dtype=dtype)

    def items(self):
        return (("vertical", self.vertical), ("horizontal", self.horizontal))

    def as_array(self) -> np.ndarray:
        return np.array([self.vertical, self.horizontal], dtype=float)

    def to_dict(self) -> dict:
        return {"vertical": jsonable(self.vertical), "horizontal": jsonable(self.horizontal)}

    @classmethod
    def of(cls, values) -> PerAxis:
        """From a pair (vertical, horizontal), a mapping by axis name, or a PerAxis."""
        if isinstance(values, PerAxis):
            return values
        if isinstance(values, Mapping):
            return cls(float(values["vertical"]), float(values["horizontal"]))
        v, h = values
        return cls(float(v), float(h))


class Result:
    """Mixin of the result convention (see the module doc); for frozen dataclasses."""

    def to_dict(self) -> dict:
        """Every field shown in the repr, in plain JSON types."""
        return jsonable({f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.repr})

    def report(self) -> str:
        """The result as text: status and message, then its scalar fields."""
        outcome = "success" if self.success else "failure"
        head = f"{type(self).__name__}: {outcome} ({self.status}): {self.message}"
        lines = [head]
        for f in dataclasses.fields(self):
            if f.name in ("success", "status", "message", "timings") or not f.repr:
                continue
            value = getattr(self, f.name)
            if isinstance(value, (int, float, str, Estimate, PerAxis)) and not isinstance(value, bool):
                lines.append(f"    {f.name:<22s} = {value}")
        if getattr(self, "timings", None):
            lines.append("    timings [s]: " + ", ".join(f"{k} {v:.3g}" for k, v in self.timings.items()))
        return "\n".join(lines)


def check_result(result: Any) -> None:
    """Raise AssertionError unless ``result`` follows the convention (for tests)."""
    assert isinstance(result.success, bool), f"{type(result).__name__}.success is not a bool"
    assert isinstance(result.status, str) and result.status, f"{type(result).__name__}.status is not a word"
    assert isinstance(result.message, str), f"{type(result).__name__}.message is not a str"
    assert isinstance(result.timings, Mapping), f"{type(result).__name__}.timings is not a mapping"
    assert all(isinstance(v, float) for v in result.timings.values()), "timings must be floats [s]"
    d = result.to_dict()
    name = type(result).__name__
    assert isinstance(d, dict) and {"success", "status", "message"} <= set(d)
    # the JSON says what the object says, and is JSON (a script reads one, a person the other)
    for key in ("success", "status", "message"):
        assert d[key] == getattr(result, key), f"{name}.to_dict()[{key!r}] differs from .{key}"
    if "timings" in d:
        assert d["timings"] == dict(result.timings), f"{name}.to_dict() changes the timings"
    json.dumps(d, allow_nan=False)
    text = result.report()
    assert isinstance(text, str)
    assert result.status in text, f"{name}.report() does not name its status {result.status!r}"
