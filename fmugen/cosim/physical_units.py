"""Physical units of coupled variables: a coupling that joins two units without a conversion is refused.

A variable's unit is its ``unit`` attribute or its declared type's; an FMU's ``<UnitDefinitions>`` may give it
SI base-unit exponents, a factor and an offset (FMI 2.0 section 2.2.2).  A coupling ``target = factor *
source`` with factor 1 needs the same unit on both sides: the same name, or definitions with the same
exponents, factor and offset (``N.m`` and ``J``).  A coupling with another factor states a conversion (a
gear ratio, mm to m) and is taken as written; a side without a unit is not checked.
"""
from __future__ import annotations

_BASE = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


def unit_of(variable) -> str:
    u = getattr(variable, "unit", None)
    if not u and getattr(variable, "declaredType", None) is not None:
        u = getattr(variable.declaredType, "unit", None)
    return str(u or "")


def _definition(md, name):
    for d in getattr(md, "unitDefinitions", None) or ():
        if d.name == name and getattr(d, "baseUnit", None) is not None:
            b = d.baseUnit
            return (tuple(int(getattr(b, k, 0) or 0) for k in _BASE), float(b.factor or 1.0), float(b.offset or 0.0))
    return None


def mismatch(src_md, src_var, dst_md, dst_var, factor: float):
    """None, or why a coupling of ``src_var`` to ``dst_var`` with ``factor`` joins different units."""
    a, b = unit_of(src_var), unit_of(dst_var)
    if not a or not b or a == b or factor != 1.0:
        return None
    da, db = _definition(src_md, a), _definition(dst_md, b)
    if da is not None and da == db:
        return None  # two names of one unit
    return f"units differ ({a} -> {b}) and the coupling states no conversion factor"
