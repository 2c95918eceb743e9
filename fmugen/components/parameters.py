"""Parameter sets of the actuator-chain components (TOML data files).

A parameter set is a TOML file with one table per component family
(``[amplifier]``, ``[current_driver]``, ``[servo_valve]``,
``[hydraulic_actuator]``, ``[joint_inertia]``, ``[dc_motor]``,
``[controller]``, ``[trajectory]``) holding plain numbers in SI units (the
units are declared once, on the component's parameter Variables, and repeated
as comments in the files).  Shipped sets live in ``fmugen/components/data``:

* ``default`` -- PUMA-shoulder size, docs/actuator-chain.md;
* ``stiff`` -- the stability-test set of the same note;
* ``puma_joint1`` ... ``puma_joint6`` -- sized for the thesis PUMA
  (see :mod:`fmugen.components.sizing` and the file headers).

Files are parsed with :mod:`tomllib` (never evaluated); every error names
the file and the field.
"""
from __future__ import annotations

import math
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Union

from ..errors import IDENTIFIER_PATTERN, MAX_IDENTIFIER_LENGTH, FmugenError, InputFileError, read_text_file, toml_problem

DATA_DIR = Path(__file__).resolve().parent / "data"

#: Physical sign of the parameters that have one: ">0" (a time constant, an
#: inertia, a volume, a bulk modulus, a supply pressure, a smoothing width --
#: zero or less makes the equations singular or meaningless) or ">=0"
#: (a leakage, a friction, a tank pressure).  Checked for every value a
#: parameter set or an override gives, with the file and the field.
SIGNS = {
    "amplifier": {"T_I": ">0", "U_max": ">0", "eps_U": ">0", "A0": ">0", "GBW": ">0"},
    "current_driver": {"omega_i": ">0", "L": ">0", "R_c": ">0", "R_s": ">=0", "A_pa": ">0"},
    "servo_valve": {"omega_v": ">0", "zeta_v": ">0", "i_rated": ">0", "P_s": ">0", "P_T": ">=0", "Q_N": ">0",
                    "dp_N": ">0", "K_c0": ">=0", "dp_reg": ">0", "eps_x": ">0"},
    "hydraulic_actuator": {"D_m": ">0", "A_p": ">0", "V_t": ">0", "beta_e": ">0", "C_tm": ">=0", "C_im": ">=0",
                           "C_em": ">=0", "eps_P": ">0", "stroke": ">0"},
    "joint_inertia": {"J": ">0", "B_m": ">=0", "M": ">0", "B_p": ">=0"},
    "dc_motor": {"J_m": ">0", "omega_c": ">0", "zeta_c": ">0", "R_v0": ">=0", "R_v1": ">=0", "w_fric": ">0",
                 "c": ">0", "d": ">=0"},
    "controller": {"T_s": ">0"},
    "trajectory": {"qd_max": ">0", "qdd_max": ">0", "T_move": ">0"},
}


def value_problem(family: str, name: str, value) -> str | None:
    """Why ``value`` cannot be parameter ``name`` of ``family`` (a phrase to
    follow ``"name = value"``), or None."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return "is not a number"
    try:
        value = float(value)
    except OverflowError:  # an integer beyond the double range
        return "is beyond the double-precision range"
    if not math.isfinite(value):
        return "is not finite"
    sign = SIGNS.get(family, {}).get(name)
    if sign == ">0" and not value > 0:
        return "is not > 0 (the equations need a positive value)"
    if sign == ">0" and value < sys.float_info.min:  # the FMU's least value (its min: FMI's min is inclusive)
        return f"is below the smallest positive normal double {sys.float_info.min:.3g}"
    if sign == ">=0" and not value >= 0:
        return "is negative (must be >= 0)"
    return None


FAMILIES = ("amplifier", "current_driver", "servo_valve", "hydraulic_actuator",
            "joint_inertia", "dc_motor", "controller", "trajectory")


class MissingParameterError(InputFileError, KeyError):
    """A parameter set has no value for a parameter a component needs (also a
    KeyError, as before; printed without KeyError's quotes)."""

    __str__ = BaseException.__str__


@dataclass(frozen=True)
class ParameterSet:
    """Values of one parameter set: ``sections[family][name] -> float``."""

    name: str
    source: str  # file the values came from, for error messages
    sections: Mapping[str, Mapping[str, float]]

    def value(self, family: str, name: str) -> float:
        sec = self.sections.get(family)
        if sec is None:
            raise MissingParameterError(f"{self.source}: no [{family}] table (needed for parameter {name})")
        if name not in sec:
            raise MissingParameterError(f"{self.source}: [{family}] has no value for {name}")
        return sec[name]

    def check_section(self, family: str, known) -> None:
        sec = self.sections.get(family, {})
        unknown = sorted(set(sec) - set(known))
        if unknown:
            raise InputFileError(f"{self.source}: [{family}] has unknown parameter(s) {', '.join(unknown)}; "
                             f"known: {', '.join(sorted(known))}")


def available_sets() -> list:
    return sorted(p.stem for p in DATA_DIR.glob("*.toml"))


def _resolve(name_or_path: Union[str, Path]) -> Path:
    p = Path(name_or_path)
    if p.suffix == ".toml":
        try:
            found = p.is_file()
        except OSError as exc:  # e.g. a name longer than the file system allows
            raise InputFileError(f"{str(p)[:80]!r}: not a usable file name: {exc.strerror}") from None
        if not found:
            raise InputFileError(f"{p}: parameter set file not found")
        return p
    # a shipped set is named by its file stem: an identifier, never a path
    if not (isinstance(name_or_path, str) and IDENTIFIER_PATTERN.match(name_or_path)
            and len(name_or_path) <= MAX_IDENTIFIER_LENGTH) or not (DATA_DIR / f"{name_or_path}.toml").is_file():
        raise FmugenError(f"unknown parameter set {str(name_or_path)[:80]!r}; shipped sets: "
                          f"{', '.join(available_sets())} (or give a path to a .toml file)")
    return DATA_DIR / f"{name_or_path}.toml"


def parse_parameter_set(data: Mapping, source: str, name: str = "") -> ParameterSet:
    """Validate a parsed TOML mapping into a :class:`ParameterSet`."""
    sections = {}
    for family, table in data.items():
        if family not in FAMILIES:
            raise InputFileError(f"{source}: unknown table [{family}]; known: {', '.join(FAMILIES)}")
        if not isinstance(table, Mapping):
            raise InputFileError(f"{source}: {family} must be a table of numbers")
        sec = {}
        for key, val in table.items():
            problem = value_problem(family, key, val)
            if problem:
                shown = repr(val) if len(repr(val)) <= 40 else repr(val)[:40] + "..."
                raise InputFileError(f"{source}: [{family}] {key} = {shown} {problem}")
            sec[key] = float(val)
        sections[family] = sec
    return ParameterSet(name=name or Path(source).stem, source=source, sections=sections)


_cache: dict = {}


def load_parameter_set(name_or_path: Union[str, Path] = "default") -> ParameterSet:
    """Load a shipped set by name (``"default"``, ``"stiff"``, ``"puma_joint2"``)
    or any TOML file by path."""
    path = _resolve(name_or_path)
    text = read_text_file(path, "parameter set")
    key = (str(path), text)  # by content: an edited file is read again, whatever its time stamp
    if key not in _cache:
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise InputFileError(f"{path}: not valid TOML: {exc}") from None
        except RecursionError:
            raise InputFileError(f"{path}: {toml_problem(RecursionError())}") from None
        if len(_cache) > 256:
            _cache.clear()
        _cache[key] = parse_parameter_set(data, str(path), path.stem)
    return _cache[key]
