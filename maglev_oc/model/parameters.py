"""Physical parameters of the stage (Table I) and the lumped constants C1..C4 (Tables II, III).

Everything is in SI units. Papers: 000 = Owen & Maggiore, ACC 2005; 001 = Owen, Maggiore &
Apkarian, CCA 2005; 002 = Owen, Maggiore & Apkarian, IEEE CSM 26(3), 2006.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from maglev_oc.errors import InputError
from maglev_oc.fileio import write_text_atomic

__all__ = [
    "DEFAULT_CONSTANTS",
    "MU0",
    "PAPER_CONSTANTS",
    "LumpedConstants",
    "StageParameters",
    "load_json",
    "paper_constants",
    "save_json",
]

MU0 = 4e-7 * math.pi
"""Free-space permeability [N/A^2]."""

# A geometric length of this stage above this bound is not a length in metres: the largest one
# in Table I is 0.2 m (back-iron length); 1 m is generous and 12.7 (b0 in mm) is caught.
_MAX_LENGTH_M = 1.0


def _field(unit: str, doc: str, **kw: Any) -> Any:
    return field(metadata={"unit": unit, "doc": doc}, **kw)


@dataclass(frozen=True)
class StageParameters:
    """Table I of papers 000/001/002 in SI units.

    Every field has ``metadata['unit']`` and ``metadata['doc']``; :func:`describe` lists them.
    Invalid values (non-positive lengths or masses, lengths that look like millimetres,
    non-integer counts) raise ``ValueError`` naming the field, when the object is made.
    """

    slot_width: float = _field("m", "stator slot width b0 (Table I, 000)", default=12.7e-3)
    slot_pitch: float = _field("m", "stator slot pitch t1 (Table I, 000)", default=19.05e-3)
    turns_per_phase: int = _field("-", "turns per phase W (Table I, 000)", default=900)
    coil_pitch: float = _field("m", "coil pitch w_c (Table I, 000)", default=57.15e-3)
    pole_pairs: int = _field("-", "stator pole pairs p (Table I, 000)", default=3)
    n_slots: int = _field("-", "number of stator slots z1 (Table I, 000)", default=18)
    magnet_height: float = _field("m", "PM height h_m (Table I, 000)", default=5e-3)
    magnet_length: float = _field("m", "PM length L_A (depth along z) (Table I, 000)", default=50e-3)
    n_magnets: int = _field("-", "number of PMs p_m (Table I, 000)", default=4)
    pole_pitch: float = _field("m", "pole pitch tau (Table I, 000)", default=57.15e-3)
    magnet_width: float = _field("m", "PM width tau_p (Table I, 000)", default=28.58e-3)
    coercivity: float = _field("A/m", "PM coercivity H_c, N35 (Table I, 000)", default=875400.0)
    recoil_permeability: float = _field(
        "-", "relative recoil permeability mu_rec (Table 1, 002)", default=1.1
    )
    surface_charge: float = _field(
        "A/m",
        "magnetic surface charge density sigma_m; unknown in 002, SPEC 1 takes sigma_m = H_c",
        default=875400.0,
    )
    back_iron_height: float = _field("m", "back-iron height h_b (Table I, 000)", default=4.7e-3)
    mass_horizontal: float = _field("kg", "horizontal mover mass M_h (Table I, 000)", default=1.594)
    mass_vertical: float = _field("kg", "vertical mover mass M_v (Table I, 000)", default=4.350)
    gravity: float = _field("m/s^2", "gravitational acceleration G (SPEC 1)", default=9.81)

    _LENGTHS = (
        "slot_width",
        "slot_pitch",
        "coil_pitch",
        "magnet_height",
        "magnet_length",
        "pole_pitch",
        "magnet_width",
        "back_iron_height",
    )
    _COUNTS = ("turns_per_phase", "pole_pairs", "n_slots", "n_magnets")

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise InputError(f"StageParameters.{f.name}: expected a number, got {value!r}")
            if not math.isfinite(value) or value <= 0:
                raise InputError(
                    f"StageParameters.{f.name}: must be positive and finite "
                    f"[{f.metadata['unit']}], got {value!r}"
                )
        for name in self._LENGTHS:
            value = getattr(self, name)
            if value > _MAX_LENGTH_M:
                raise InputError(
                    f"StageParameters.{name} = {value!r} m looks like millimetres; "
                    f"lengths are in metres (e.g. {value / 1000:g})"
                )
        for name in self._COUNTS:
            value = getattr(self, name)
            if float(value) != int(value):
                raise InputError(f"StageParameters.{name}: must be a whole number, got {value!r}")
            object.__setattr__(self, name, int(value))
        if self.magnet_width > self.pole_pitch:
            raise InputError(
                f"StageParameters.magnet_width = {self.magnet_width} m exceeds "
                f"pole_pitch = {self.pole_pitch} m"
            )
        if self.slot_width >= self.slot_pitch:
            raise InputError(
                f"StageParameters.slot_width = {self.slot_width} m must be smaller than "
                f"slot_pitch = {self.slot_pitch} m"
            )

    # --- derived quantities -------------------------------------------------------------
    @property
    def winding_factor(self) -> float:
        """Fundamental winding factor k_w1 from the formula of paper 002 (Section 3).

        k_w1 = sin(pi/6) / ((w_c / (3 t1)) sin(pi t1 / (2 tau))) * sin(pi w_c / (2 tau)).
        Equal to 1 for Table I's full-pitch winding.
        """
        t1, tau, wc = self.slot_pitch, self.pole_pitch, self.coil_pitch
        distribution = math.sin(math.pi / 6) / (wc / (3 * t1) * math.sin(math.pi * t1 / (2 * tau)))
        pitch = math.sin(math.pi * wc / (2 * tau))
        return distribution * pitch

    def physical_constants(self) -> LumpedConstants:
        """C1..C4 evaluated from the formulas of paper 002 (Section 3, below eq. (8)).

        With SPEC 1's corrections: C2 = L_A p_m tau / (4 M_v mu0) (000 prints M_v^4) and
        C3 > 0 (the sign lives in L3). These use sigma_m = ``surface_charge`` and are the
        values the lumped constants would have if Table I and the magnetic-charge model were
        exact; the identified values (Table III) differ, which is why the papers identify them.
        """
        W, kw, pm, LA = self.turns_per_phase, self.winding_factor, self.n_magnets, self.magnet_length
        tau, p, hm = self.pole_pitch, self.pole_pairs, self.magnet_height
        a = math.pi / tau
        c1 = (
            12
            * math.sqrt(2)
            * W
            * kw
            * pm
            * LA
            * self.surface_charge
            * MU0
            * math.sinh(a * hm)
            * math.sin(math.pi * self.magnet_width / (2 * tau))
            / (self.mass_horizontal * math.pi * p)
        )
        c2 = LA * pm * tau / (4 * self.mass_vertical * MU0)
        c3 = 3 * math.sqrt(2) * LA * pm * W * kw / (self.mass_vertical * p**2)
        c4 = 18 * LA * pm * W**2 * kw**2 * MU0 / (self.mass_vertical * tau * p**2)
        return LumpedConstants(c1, c2, c3, c4, source="physical (002 formulas, sigma_m = H_c)")

    # --- I/O -----------------------------------------------------------------------------
    def to_dict(self) -> dict[str, float]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_dict(cls, data: dict[str, Any], *, where: str = "StageParameters") -> StageParameters:
        """From a JSON object; absent fields keep Table I's values. Errors name ``where`` and
        the field."""
        return _from_checked(cls, _checked_keys(cls, data, where), where)

    @classmethod
    def describe(cls) -> list[tuple[str, str, str]]:
        """(name, unit, description) for every field."""
        return [(f.name, f.metadata["unit"], f.metadata["doc"]) for f in fields(cls)]


@dataclass(frozen=True)
class LumpedConstants:
    """The lumped constants C1..C4 of eq. (2) of paper 000 / eqs. (5)-(8) of paper 002.

    Units follow from L_i = C_i * (shape function of the gap): C1 [m/(s^2 A)], C2 [m/(s^2 T^2)],
    C3 [m/(s^2 A T)], C4 [m/(s^2 A^2)]. C3 is positive; L3 carries the minus sign (SPEC 1, 4.).
    """

    C1: float
    C2: float
    C3: float
    C4: float
    source: str = ""

    def __post_init__(self) -> None:
        for name in ("C1", "C2", "C3", "C4"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise InputError(f"LumpedConstants.{name}: expected a number, got {value!r}")
            if not math.isfinite(value) or value <= 0:
                raise InputError(f"LumpedConstants.{name}: must be positive, got {value!r}")
            object.__setattr__(self, name, float(value))

    def as_array(self) -> list[float]:
        return [self.C1, self.C2, self.C3, self.C4]

    def replace(self, **changes: Any) -> LumpedConstants:
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        return {"C1": self.C1, "C2": self.C2, "C3": self.C3, "C4": self.C4, "source": self.source}

    @classmethod
    def from_dict(
        cls, data: dict[str, Any], *, where: str = "LumpedConstants", defaults: LumpedConstants | None = None
    ) -> LumpedConstants:
        """From a JSON object. With ``defaults``, absent constants are taken from it (and
        ``source`` says which); without, all four are required. Errors name ``where`` and the key."""
        values = _checked_keys(cls, data, where)
        given = [k for k in ("C1", "C2", "C3", "C4") if k in values]
        missing = [k for k in ("C1", "C2", "C3", "C4") if k not in values]
        if missing and defaults is None:
            raise InputError(f"{where}: missing {', '.join(missing)}")
        if missing:
            values.setdefault(
                "source",
                f"{where} ({', '.join(given) or 'none'}); {', '.join(missing)} from "
                + (defaults.source or "the defaults"),
            )
            values.update({k: getattr(defaults, k) for k in missing})
        return _from_checked(cls, values, where)


# Tables II and III of paper 000 (reduced-order NPFSI estimates at three values of eps).
# Table II is vertical only (C2..C4, mover fixed at x3 = 0); its C1 is taken from Table III at
# the same eps so that the named set is a complete model; the `source` string says so.
_TABLE_II = {0.001: (790.97, 30.47, 0.11), 0.01: (791.00, 30.90, 0.12), 0.05: (788.98, 32.44, 0.18)}
_TABLE_III = {
    0.001: (13.97, 796.93, 30.33, 0.06),
    0.01: (14.20, 796.99, 31.04, 0.07),
    0.05: (16.23, 795.01, 33.44, 0.15),
}


def _paper_sets() -> dict[str, LumpedConstants]:
    sets: dict[str, LumpedConstants] = {}
    for eps, (c1, c2, c3, c4) in _TABLE_III.items():
        sets[f"table3_eps{eps:g}"] = LumpedConstants(
            c1, c2, c3, c4, source=f"Table III of 000, eps = {eps:g}"
        )
    for eps, (c2, c3, c4) in _TABLE_II.items():
        c1 = _TABLE_III[eps][0]
        sets[f"table2_eps{eps:g}"] = LumpedConstants(
            c1, c2, c3, c4, source=f"Table II of 000, eps = {eps:g} (C1 from Table III)"
        )
    c1, _, c3, c4 = _TABLE_III[0.01]
    sets["cogging_x3_3t1_2"] = LumpedConstants(
        c1,
        769.99,
        c3,
        c4,
        source="000 Sec. V-C: C2 = 769.99 at x3 = 3 t1/2, eps = 0.01 (others Table III)",
    )
    return sets


PAPER_CONSTANTS: dict[str, LumpedConstants] = _paper_sets()
"""Every column of Tables II and III (and the cogging-procedure C2) by name, e.g.
``PAPER_CONSTANTS['table3_eps0.01']``."""

DEFAULT_CONSTANTS = PAPER_CONSTANTS["table3_eps0.01"]
"""SPEC 1 default: Table III at eps = 0.01, also the values quoted in 002 Section 5.3."""


def paper_constants(name: str) -> LumpedConstants:
    """Look up a named set of the papers' constants (:data:`PAPER_CONSTANTS`).

    Parameters
    ----------
    name : str
        For example ``"table3_eps0.01"`` (the default constants).

    Returns
    -------
    LumpedConstants

    Raises
    ------
    InputError
        Unknown name; the message lists the known ones.
    """
    try:
        return PAPER_CONSTANTS[name]
    except KeyError:
        raise InputError(
            f"unknown constant set {name!r}; known: {', '.join(sorted(PAPER_CONSTANTS))}"
        ) from None


# --- JSON ---------------------------------------------------------------------------------
def _checked_keys(cls: type, data: Any, where: str) -> dict[str, Any]:
    if not isinstance(data, dict):
        raise InputError(f"{where}: expected a JSON object, got {type(data).__name__}")
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise InputError(f"{where}: unknown key(s) {unknown}; known keys: {sorted(known)}")
    return dict(data)


_MAX_STAGE_FILE = 1_000_000  # [bytes] a stage file is a few kB; refuse to parse anything huge


def _from_checked(cls: type, values: dict[str, Any], where: str):
    """``cls(**values)``, its validation errors prefixed with ``where`` (the file and section)."""
    try:
        return cls(**values)
    except InputError as err:
        raise InputError(f"{where}.{str(err).removeprefix(cls.__name__ + '.')}") from None


def save_json(path: str | os.PathLike, params: StageParameters, constants: LumpedConstants) -> Path:
    """Write parameters and constants to ``path`` atomically (whole file or nothing)."""
    payload = {"stage": params.to_dict(), "constants": constants.to_dict()}
    return write_text_atomic(path, json.dumps(payload, indent=2) + "\n")


def load_json(path: str | os.PathLike) -> tuple[StageParameters, LumpedConstants]:
    """Read a file written by :func:`save_json`. Either section, and any key in it, may be
    omitted: the rest comes from Table I and the default constants."""
    path = Path(path)
    if path.stat().st_size > _MAX_STAGE_FILE:
        raise InputError(f"{path}: {path.stat().st_size} bytes is not a stage file (they are a few kB)")
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as err:
        raise InputError(f"{path}: not a text file (byte {err.start} is not UTF-8)") from None
    if not text.strip():
        raise InputError(f"{path}: empty file; expected a JSON object with 'stage' and/or 'constants'")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as err:
        raise InputError(f"{path}: not valid JSON (line {err.lineno}: {err.msg})") from None
    data = _checked_keys(_Sections, data, str(path))
    params = StageParameters.from_dict(data.get("stage", {}), where=f"{path}: stage")
    if "constants" in data:
        constants = LumpedConstants.from_dict(
            data["constants"], where=f"{path}: constants", defaults=DEFAULT_CONSTANTS
        )
    else:
        constants = DEFAULT_CONSTANTS
    return params, constants


@dataclass(frozen=True)
class _Sections:
    stage: dict = field(default_factory=dict)
    constants: dict = field(default_factory=dict)
