"""One physical check for every path by which a value arrives.

A parameter value can come from a file (a robot file, a parameter set), from
a scene's ``parameters`` or ``start`` table, from ``--set``, from a sweep
point or from the Python API.  The file readers check what they read
(:mod:`fmugen.robot.checks`, :func:`fmugen.components.parameters.value_problem`);
the functions here apply the *same* rules to a value arriving any other way,
so an override can never make a model the file could not:

* :func:`as_number` -- a finite double, or a clear error (never ``OverflowError``
  for an integer beyond the double range);
* :func:`variable_problem` -- the physical sign a parameter declares
  (:attr:`fmugen.codegen.model.Variable.sign`: a time constant, an inertia,
  a volume is ``> 0``; a leakage or a friction ``>= 0``) and its declared
  range (``min``/``max`` of a component file's parameter);
* :func:`robot_value_problem` -- a robot's quantities re-evaluated with the
  new values, through the robot-file checks: every mass, length, inertia a
  finite number (``mass = "m1/k"`` with ``k = 0`` is a division by zero),
  masses positive, rotor inertias and damping not negative, every link a
  realisable rigid body (unless the file's own values were not), and a mass
  matrix that is not singular.

The numbers of XML formats (SSP's SSD/SSV/SSM, URDF, an FMU's modelDescription) follow
XML Schema's grammar, not Python's: :func:`parse_xs_double`, :func:`parse_xs_int`,
:func:`parse_xs_boolean` and :func:`parse_xs_double_list` read exactly the XSD 1.0
lexical spaces (``float()`` would take ``1_5``, Arabic-Indic digits, ``infinity``, ``nan``).

A number written as *text* elsewhere -- a TOML string of a robot file, a ``--set`` value, a sweep's
``--grid``/``--sample`` item, a number-valued command-line option -- follows one plain decimal
grammar, :data:`DECIMAL` (:func:`parse_decimal`): ASCII digits, an optional point, sign and
exponent; no ``_`` separators, no ``0x`` prefixes, no ``inf``/``nan`` words, no other scripts'
digits.  (A TOML *number* follows TOML's own grammar, which its reader has already applied.)
"""
from __future__ import annotations

import math
import re
import sys
from typing import Mapping, Optional

from .errors import FmugenError, InputFileError

__all__ = ["DECIMAL", "DECIMAL_LITERAL", "parse_decimal", "parse_xs_double", "parse_xs_int", "parse_xs_boolean",
           "parse_xs_double_list", "as_number", "sign_problem", "variable_problem", "check_model_values"]


# ---------------------------------------------------------------------------- XML Schema numbers
# XML Schema 1.0 Part 2 (Datatypes), 3.2.5 double: a decimal mantissa with an optional exponent, or
# the special values INF, -INF, NaN (exactly so spelled; "+INF" is only XSD 1.1).  ASCII digits
# only ([0-9], not \d, which matches every Unicode digit); no '_' separators, no hex floats.
_XS_DOUBLE = re.compile(r"[+-]?([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]+)?|-?INF|NaN")
# 3.3.13 integer and its restrictions (int: 32 bits; 3.3.17 long: 64 bits; unsignedInt ...)
_XS_INTEGER = re.compile(r"[+-]?[0-9]+")
_XS_INT_RANGE = {"int": (-2**31, 2**31 - 1), "long": (-2**63, 2**63 - 1), "unsignedInt": (0, 2**32 - 1),
                 "integer": (None, None)}
# XML's white space (the S production), which the 'collapse' facet of every numeric type removes at
# both ends; other Unicode spaces (no-break space, em space) are not white space to XML
_XML_SPACE = " \t\n\r"


# ---------------------------------------------------------------------------- plain decimal text
#: an unsigned decimal literal: ``12``, ``0.5``, ``.5``, ``3.``, ``1e-3`` (ASCII [0-9], never \d, which
#: matches every script's digits); a robot file's expression strings take their numbers in this form
DECIMAL_LITERAL = re.compile(r"([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]+)?")
#: a number written as text: an optional sign and a :data:`DECIMAL_LITERAL`
DECIMAL = re.compile(r"[+-]?([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]+)?")


def parse_decimal(text, where: str, error=FmugenError) -> float:
    """The finite number written as ``text`` in the plain decimal grammar :data:`DECIMAL` (surrounding
    ASCII spaces allowed); anything else -- ``1_5``, ``0x10``, ``inf``, ``nan``, ``1e999``, ``١٢``,
    ``1,5``, empty -- is an ``error`` (an :class:`FmugenError` class) ``"<where>: '1_5' is not a
    number ..."``."""
    if not isinstance(text, str):
        raise error(f"{where}: {text!r} is not text holding a number")
    t = text.strip(" \t")
    if not DECIMAL.fullmatch(t):
        raise error(f"{where}: {_shown(t)} is not a number (decimal: ASCII digits with an optional sign, "
                    f"'.' and exponent, as 1.5e-3; no '_', no 0x, no inf/nan)")
    x = float(t)
    if not math.isfinite(x):
        raise error(f"{where}: {_shown(t)} is not a finite number (beyond the double-precision range, "
                    f"|value| <= {sys.float_info.max:.3g})")
    return x


def _shown(text: str) -> str:
    return repr(text) if len(text) <= 40 else repr(text[:20]) + f"... ({len(text)} characters)"


def _collapsed(text, where: str, kind: str) -> str:
    if text is None:
        raise InputFileError(f"{where}: missing (an {kind} is required)")
    if not isinstance(text, str):
        raise InputFileError(f"{where}: {text!r} is not text holding an {kind}")
    return text.strip(_XML_SPACE)


def parse_xs_double(text, where: str, finite: bool = True) -> float:
    """The xs:double ``text`` (XSD 1.0 lexical space after white-space collapse) as a float.

    Anything else -- ``1_5``, ``١٢``, ``infinity``, ``nan``, ``0x1p3``, ``1,5``, empty -- is an
    :class:`InputFileError` ``"<where>: '1_5' is not an xs:double ..."``.  With ``finite`` (the
    default) ``INF``, ``-INF``, ``NaN`` and a literal beyond the double range (``1e999``) are refused
    too: most fields of a model need a finite number."""
    t = _collapsed(text, where, "xs:double")
    if not _XS_DOUBLE.fullmatch(t):
        raise InputFileError(f"{where}: {_shown(t)} is not an xs:double (XML Schema number: ASCII digits with "
                             f"an optional '.', sign and exponent 'E', or INF, -INF, NaN)")
    x = float(t)
    if finite and not math.isfinite(x):
        if t in ("INF", "-INF", "NaN"):
            raise InputFileError(f"{where}: {t} is not a finite number")
        raise InputFileError(f"{where}: {_shown(t)} is beyond the double-precision range "
                             f"(|value| <= {sys.float_info.max:.3g})")
    return x


def parse_xs_int(text, where: str, kind: str = "int") -> int:
    """The integer ``text`` of XML Schema type ``kind`` ("int", "long", "unsignedInt", "integer"):
    ASCII digits with an optional sign, within the type's range; else an :class:`InputFileError`."""
    t = _collapsed(text, where, f"xs:{kind}")
    if len(t) > 400 or not _XS_INTEGER.fullmatch(t):  # 400 digits: far beyond any range, far below int()'s limit
        raise InputFileError(f"{where}: {_shown(t)} is not an xs:{kind} (ASCII digits with an optional sign)")
    v = int(t)
    lo, hi = _XS_INT_RANGE[kind]
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise InputFileError(f"{where}: {_shown(t)} is outside the range of xs:{kind} ({lo} .. {hi})")
    return v


def parse_xs_boolean(text, where: str) -> bool:
    """The xs:boolean ``text``: exactly ``true``, ``false``, ``1`` or ``0`` (XSD 1.0, 3.2.2); else an
    :class:`InputFileError` (``True``, ``yes``, ``on`` are not booleans to XML Schema)."""
    t = _collapsed(text, where, "xs:boolean")
    if t in ("true", "1"):
        return True
    if t in ("false", "0"):
        return False
    raise InputFileError(f"{where}: {_shown(t)} is not an xs:boolean (true, false, 1 or 0)")


def parse_xs_double_list(text, where: str, count: Optional[int] = None, finite: bool = True) -> list:
    """A white-space separated list of xs:double (an xs:list, as URDF's ``xyz="0 0 1"``), of exactly
    ``count`` items when given; an item that is not an xs:double is named by its position."""
    t = _collapsed(text, where, "list of xs:double")
    items = re.split(f"[{_XML_SPACE}]+", t) if t else []
    if count is not None and len(items) != count:
        raise InputFileError(f"{where}: {_shown(t)} has {len(items)} numbers, not {count}")
    return [parse_xs_double(x, f"{where}[{i}]", finite) for i, x in enumerate(items)]


def as_number(value, where: str) -> float:
    """``value`` as a finite float; bool, text, NaN, infinity and integers beyond the double range
    are an :class:`FmugenError` at ``where``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise FmugenError(f"{where}: {value!r} is not a number")
    try:
        v = float(value)
    except OverflowError:
        digits = len(str(abs(value))) if isinstance(value, int) and abs(value) < 10 ** 4000 else "many"
        raise FmugenError(f"{where}: an integer of {digits} digits is beyond the double-precision range "
                          f"(|value| <= {sys.float_info.max:.3g})") from None
    if not math.isfinite(v):
        raise FmugenError(f"{where}: {value!r} is not a finite number")
    return v


def sign_problem(sign: str, value: float) -> Optional[str]:
    """Why ``value`` breaks the sign rule ``">0"`` / ``">=0"`` (a phrase), or None."""
    if sign == ">0" and not value > 0:
        return "is not > 0 (the equations need a positive value)"
    if sign == ">0" and value < sys.float_info.min:  # the FMU's least value (FMI's min is inclusive)
        return f"is below the smallest positive normal double {sys.float_info.min:.3g}"
    if sign == ">=0" and not value >= 0:
        return "is negative (must be >= 0)"
    return None


def variable_problem(var, value) -> Optional[str]:
    """Why ``value`` cannot be the value of Variable ``var`` (its declared sign), or None."""
    try:
        v = as_number(value, var.name)
    except FmugenError as exc:
        return str(exc).split(": ", 1)[1]
    problem = sign_problem(getattr(var, "sign", "") or "", v)
    if problem:
        return problem
    lo, hi = getattr(var, "min", None), getattr(var, "max", None)  # a declared range (component files)
    if lo is not None and v < lo:
        if lo == sys.float_info.min:  # the FMU's form of "> 0" (FMI's min is inclusive)
            return ("is not > 0 (the quantity must be positive)" if v <= 0 else
                    f"is below the smallest positive normal double {lo:.3g} (the FMU's least value)")
        if lo == 0.0:
            return "is negative (must be >= 0)"
        return f"is below its minimum {lo!r}"
    if hi is not None and v > hi:
        return f"is above its maximum {hi!r}"
    return None


def check_model_values(model, values: Mapping[str, object], where_of) -> None:
    """Refuse a value of ``values`` (name -> value) that a parameter of ``model`` cannot take.

    ``where_of(name)`` gives the place to name in the message (``"--set joint.J"``,
    ``"scene.toml: [instances.joint] start.J"``).
    """
    params = {v.name: v for v in model.parameters}
    for name, value in values.items():
        var = params.get(name)
        if var is None:
            continue
        problem = variable_problem(var, value)
        if problem:
            shown = repr(value) if len(repr(value)) <= 40 else repr(value)[:20] + "..."
            raise FmugenError(f"{where_of(name)} = {shown} {problem}")
