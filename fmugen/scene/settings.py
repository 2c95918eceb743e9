"""``--set NAME=VALUE``: one override of a scene, robot or assembly value.

Values are read as TOML scalars -- ``5``, ``1e-3``, ``true``, ``"PI"`` --
with a bare word taken as a string (``--set amp1.control=PI``); nothing is
evaluated.  Non-finite numbers are refused here, where they are read.
"""
from __future__ import annotations

import math
import re
import tomllib
from typing import Iterable, Mapping, Union

from .errors import SceneError

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\[[0-9]+\])?(\.[A-Za-z_][A-Za-z0-9_]*(\[[0-9]+\])?)*$")
_WORD = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*$")

Value = Union[float, int, bool, str]


def parse_value(text: str, where: str) -> Value:
    """A TOML scalar, or a bare word as a string; never evaluated."""
    text = text.strip()
    try:
        value = tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        if _WORD.match(text):
            return text
        raise SceneError(f"{where}: {text!r} is not a number, true/false or a word") from None
    if isinstance(value, float) and not math.isfinite(value):
        raise SceneError(f"{where}: {text!r} is not a finite number")
    if not isinstance(value, (int, float, bool, str)):
        raise SceneError(f"{where}: {text!r} must be a single number, true/false or a word")
    return value


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
        out[name] = parse_value(text, f"--set {item}")
    return out


def _check_name(name: str, where: str) -> None:
    if not isinstance(name, str) or not _NAME.match(name):
        raise SceneError(f"{where}: {name!r} is not a name like 'joint.J', 'm' or 'arm.q[2]'")
