"""``--set NAME=VALUE``: one override of a scene, robot or assembly value.

Values are numbers in the plain decimal grammar (``5``, ``1e-3``: no ``1_5``,
no ``0x10``, no ``inf``), ``true``/``false``, quoted strings (``"PI"``) or a
bare word taken as a string (``--set amp1.control=PI``); nothing is
evaluated.  Non-finite numbers are refused here, where they are read.
"""
from __future__ import annotations

import math
import re
import tomllib
from typing import Iterable, Mapping, Union

from ..values import parse_decimal
from .errors import SceneError

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\[[0-9]+\])?(\.[A-Za-z_][A-Za-z0-9_]*(\[[0-9]+\])?)*$")
_WORD = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*$")

Value = Union[float, int, bool, str]


def parse_value(text: str, where: str) -> Value:
    """A number, true/false, a quoted TOML string or a bare word (a string); never evaluated.

    Numbers follow the plain decimal grammar of :func:`fmugen.values.parse_decimal` (TOML's own would
    take ``1_5`` as 15 and ``0x10`` as 16); a whole number stays an integer."""
    t = text.strip(" \t")
    if re.fullmatch(r"[+-]?[0-9]+", t):
        digits = len(t.lstrip("+-"))
        if digits > 4000:  # int() refuses more than 4300 digits; far beyond any double anyway
            raise SceneError(f"{where}: an integer of {digits} digits is beyond the double-precision range")
        return int(t)
    if t[:1] in tuple("+-.0123456789"):  # it looks like a number: it must be one
        return parse_decimal(t, where, SceneError)
    if t in ("true", "false"):
        return t == "true"
    if t.lower().lstrip("+-") in ("inf", "infinity", "nan"):
        raise SceneError(f"{where}: {t!r} is not a finite number")
    if t[:1] in ("'", '"'):
        try:
            value = tomllib.loads(f"v = {t}")["v"]
        except tomllib.TOMLDecodeError:
            value = None
        if not isinstance(value, str):
            raise SceneError(f"{where}: {t[:40]!r} is not one quoted string")
        return value
    if _WORD.match(t):
        return t
    raise SceneError(f"{where}: {t[:40]!r} is not a number, true/false or a word")


def parse_sets(items: Union[None, Iterable[str], Mapping[str, Value]]) -> dict:
    """``["joint.J=5", "m=1.0"]`` (or a dict) -> ``{"joint.J": 5, "m": 1.0}``.

    >>> parse_sets(["joint.J=5", "amp1.control=PI", "arm.q[2]=-0.5"])
    {'joint.J': 5, 'amp1.control': 'PI', 'arm.q[2]': -0.5}
    """
    if items is None:
        return {}
    if isinstance(items, Mapping):
        out = {}
        for k, v in items.items():
            _check_name(k, f"--set {k}")
            if isinstance(v, float) and not math.isfinite(v):
                raise SceneError(f"--set {k}: {v!r} is not a finite number")
            out[k] = v
        return out
    out = {}
    for item in items:
        if "=" not in item:
            raise SceneError(f"--set {item!r}: expected NAME=VALUE")
        name, text = item.split("=", 1)
        name = name.strip()
        _check_name(name, f"--set {item}")
        out[name] = parse_value(text, f"--set {item}" if len(item) <= 80 else f"--set {name}=...")
    return out


def _check_name(name: str, where: str) -> None:
    if not isinstance(name, str) or not _NAME.match(name):
        raise SceneError(f"{where}: {name!r} is not a name like 'joint.J', 'm' or 'arm.q[2]'")
