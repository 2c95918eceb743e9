"""Unit strings -> SI base-unit exponents for FMI 2.0 ``<UnitDefinitions>``.

A unit string is written the Modelica way (the syntax of the Modelica
Specification, section "Unit expressions"): factors joined by ``.``, each a
unit name with an optional integer exponent, optionally ``/`` and a
denominator in parentheses when it has several factors::

    "N.m"   "kg.m2"   "rad/s2"   "m3/(s.Pa)"   "N.m.s/rad"   "1/s"   "1"

FMI 2.0 describes a unit by the exponents of kg, m, s, A, K, mol, cd and rad
(``<BaseUnit>``) and ``factor``/``offset`` (value_SI = factor * value + offset).

>>> base_units("N.m.s/rad")
BaseUnit(kg=1, m=2, s=-1, A=0, K=0, mol=0, cd=0, rad=-1, factor=1.0, offset=0.0)
>>> base_units("m3/(s.Pa)").exponents()
{'kg': -1, 'm': 4, 's': 1}
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

BASE = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


@dataclass(frozen=True)
class BaseUnit:
    kg: int = 0
    m: int = 0
    s: int = 0
    A: int = 0
    K: int = 0
    mol: int = 0
    cd: int = 0
    rad: int = 0
    factor: float = 1.0
    offset: float = 0.0

    def exponents(self) -> dict:
        """Non-zero exponents, in FMI's attribute order."""
        return {b: getattr(self, b) for b in BASE if getattr(self, b)}

    def __mul__(self, other: "BaseUnit") -> "BaseUnit":
        return BaseUnit(*(getattr(self, b) + getattr(other, b) for b in BASE),
                        factor=self.factor * other.factor)

    def __pow__(self, k: int) -> "BaseUnit":
        return BaseUnit(*(getattr(self, b) * k for b in BASE), factor=self.factor ** k)


def _u(factor=1.0, **exps) -> BaseUnit:
    return BaseUnit(factor=factor, **exps)


#: Unit names and their SI definition.  Derived units are written in base
#: units; angles keep the rad exponent (FMI 2.0 treats rad as a base unit so
#: that rad/s and 1/s stay apart).
UNITS: dict = {
    "1": _u(),
    "kg": _u(kg=1), "g": _u(1e-3, kg=1),
    "m": _u(m=1), "mm": _u(1e-3, m=1), "cm": _u(1e-2, m=1),
    "s": _u(s=1), "ms": _u(1e-3, s=1), "min": _u(60.0, s=1), "h": _u(3600.0, s=1),
    "A": _u(A=1), "mA": _u(1e-3, A=1),
    "K": _u(K=1),
    "mol": _u(mol=1),
    "cd": _u(cd=1),
    "rad": _u(rad=1), "deg": _u(math.pi / 180.0, rad=1),
    "rev": _u(2.0 * math.pi, rad=1),
    "Hz": _u(s=-1),
    "N": _u(kg=1, m=1, s=-2),
    "Pa": _u(kg=1, m=-1, s=-2), "bar": _u(1e5, kg=1, m=-1, s=-2), "MPa": _u(1e6, kg=1, m=-1, s=-2),
    "J": _u(kg=1, m=2, s=-2),
    "W": _u(kg=1, m=2, s=-3),
    "V": _u(kg=1, m=2, s=-3, A=-1),
    "Ohm": _u(kg=1, m=2, s=-3, A=-2),
    "H": _u(kg=1, m=2, s=-2, A=-2),
    "Wb": _u(kg=1, m=2, s=-2, A=-1),
    "C": _u(s=1, A=1),
    "F": _u(kg=-1, m=-2, s=4, A=2),
    "S": _u(kg=-1, m=-2, s=3, A=2),
    "l": _u(1e-3, m=3),
}

_FACTOR = re.compile(r"([A-Za-z]+|1)([+-]?\d+)?$")


class UnitError(ValueError):
    """A unit string that cannot be parsed or uses an unknown unit name."""


def _split_top(text: str) -> list:
    """Split at '.' outside parentheses."""
    parts, depth, cur = [], 0, ""
    for ch in text:
        if ch == "(":
            depth += 1
        elif ch == ")":
            depth -= 1
        if ch == "." and depth == 0:
            parts.append(cur)
            cur = ""
        else:
            cur += ch
    parts.append(cur)
    return parts


def _parse(text: str, whole: str) -> BaseUnit:
    text = text.strip()
    if not text:
        raise UnitError(f"unit {whole!r}: empty factor")
    # numerator/denominator: at most one '/' outside parentheses
    depth, slash = 0, -1
    for i, ch in enumerate(text):
        depth += ch == "("
        depth -= ch == ")"
        if depth < 0:
            raise UnitError(f"unit {whole!r}: unbalanced parentheses")
        if ch == "/" and depth == 0:
            if slash >= 0:
                raise UnitError(f"unit {whole!r}: more than one '/' (write a/(b.c))")
            slash = i
    if depth != 0:
        raise UnitError(f"unit {whole!r}: unbalanced parentheses")
    if slash >= 0:
        return _parse(text[:slash], whole) * _parse(text[slash + 1:], whole) ** -1
    if text.startswith("(") and text.endswith(")"):
        return _parse(text[1:-1], whole)
    out = BaseUnit()
    for part in _split_top(text):
        m = _FACTOR.match(part.strip())
        if not m:
            raise UnitError(f"unit {whole!r}: cannot read factor {part!r}")
        name, exp = m.group(1), int(m.group(2) or 1)
        if name not in UNITS:
            raise UnitError(f"unit {whole!r}: unknown unit {name!r} (known: {', '.join(sorted(UNITS))})")
        out = out * UNITS[name] ** exp
    return out


def base_units(unit: str) -> BaseUnit:
    """SI base-unit exponents and factor of a unit string (see module doc)."""
    if not isinstance(unit, str) or not unit.strip():
        raise UnitError(f"unit {unit!r}: empty")
    return _parse(unit, unit)
