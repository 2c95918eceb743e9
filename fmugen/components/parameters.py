"""Parameter sets of the actuator-chain components (TOML data files).

A parameter set is a TOML file with one table per component family
(``[amplifier]``, ``[current_driver]``, ``[servo_valve]``,
``[hydraulic_actuator]``, ``[joint_inertia]``, ``[dc_motor]``,
``[controller]``, ``[trajectory]``) holding plain numbers in SI units (the
units are declared once, on the component's parameter Variables, and repeated
as comments in the files).  Shipped sets live in ``fmugen/components/data``:

* ``default`` -- PUMA-shoulder size, /work/shared/actuator-chain.md;
* ``stiff`` -- the stability-test set of the same note;
* ``puma_joint1`` ... ``puma_joint6`` -- sized for the thesis PUMA
  (see :mod:`fmugen.components.sizing` and the file headers).

Files are parsed with :mod:`tomllib` (never evaluated); every error names
the file and the field.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Union

DATA_DIR = Path(__file__).resolve().parent / "data"

FAMILIES = ("amplifier", "current_driver", "servo_valve", "hydraulic_actuator",
            "joint_inertia", "dc_motor", "controller", "trajectory")


@dataclass(frozen=True)
class ParameterSet:
    """Values of one parameter set: ``sections[family][name] -> float``."""

    name: str
    source: str  # file the values came from, for error messages
    sections: Mapping[str, Mapping[str, float]]

    def value(self, family: str, name: str) -> float:
        sec = self.sections.get(family)
        if sec is None:
            raise KeyError(f"{self.source}: no [{family}] table (needed for parameter {name})")
        if name not in sec:
            raise KeyError(f"{self.source}: [{family}] has no value for {name}")
        return sec[name]

    def check_section(self, family: str, known) -> None:
        sec = self.sections.get(family, {})
        unknown = sorted(set(sec) - set(known))
        if unknown:
            raise ValueError(f"{self.source}: [{family}] has unknown parameter(s) {', '.join(unknown)}; "
                             f"known: {', '.join(sorted(known))}")


def available_sets() -> list:
    return sorted(p.stem for p in DATA_DIR.glob("*.toml"))


def _resolve(name_or_path: Union[str, Path]) -> Path:
    p = Path(name_or_path)
    if p.suffix == ".toml":
        if not p.is_file():
            raise FileNotFoundError(f"parameter set file not found: {p}")
        return p
    q = DATA_DIR / f"{name_or_path}.toml"
    if not q.is_file():
        raise ValueError(f"unknown parameter set {name_or_path!r}; shipped sets: {', '.join(available_sets())} "
                         f"(or give a path to a .toml file)")
    return q


def parse_parameter_set(data: Mapping, source: str, name: str = "") -> ParameterSet:
    """Validate a parsed TOML mapping into a :class:`ParameterSet`."""
    sections = {}
    for family, table in data.items():
        if family not in FAMILIES:
            raise ValueError(f"{source}: unknown table [{family}]; known: {', '.join(FAMILIES)}")
        if not isinstance(table, Mapping):
            raise ValueError(f"{source}: {family} must be a table of numbers")
        sec = {}
        for key, val in table.items():
            if isinstance(val, bool) or not isinstance(val, (int, float)):
                raise ValueError(f"{source}: [{family}] {key} = {val!r} is not a number")
            if not math.isfinite(val):
                raise ValueError(f"{source}: [{family}] {key} is not finite")
            sec[key] = float(val)
        sections[family] = sec
    return ParameterSet(name=name or Path(source).stem, source=source, sections=sections)


_cache: dict = {}


def load_parameter_set(name_or_path: Union[str, Path] = "default") -> ParameterSet:
    """Load a shipped set by name (``"default"``, ``"stiff"``, ``"puma_joint2"``)
    or any TOML file by path."""
    path = _resolve(name_or_path)
    key = (str(path), path.stat().st_mtime)
    if key not in _cache:
        with open(path, "rb") as f:
            try:
                data = tomllib.load(f)
            except tomllib.TOMLDecodeError as exc:
                raise ValueError(f"{path}: not valid TOML: {exc}") from None
        _cache[key] = parse_parameter_set(data, str(path), path.stem)
    return _cache[key]
