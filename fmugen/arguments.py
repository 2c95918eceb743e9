"""Checks of command-line arguments, made before anything is built or written.

Every refusal names the argument (``--steps 'a,b': 'a' is not a number``) and
says what would be accepted.  A number given as text follows the plain decimal
grammar of :data:`fmugen.values.DECIMAL` (``1e-3``, ``.5``; not ``1_5``,
``inf`` or other scripts' digits, which ``float()`` takes).  Output paths are checked against the command's
inputs: a command never writes over its own input file, never writes a file
where the user named a folder (``-o newdir/``) or puts a folder where a file
is (``--out results.csv`` that exists as a file).
"""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Iterable, Optional

from .errors import FmugenError
from .values import DECIMAL

__all__ = ["number", "positive", "tolerance", "time_value", "count", "number_list", "output_file",
           "output_folder", "MAX_POINTS"]

#: most output points a command may be asked for (a reference grid): 8 bytes x columns each
MAX_POINTS = 10_000_000


def _text_number(value, option: str, problem: str) -> float:
    """A number given as text in the plain decimal grammar (:func:`fmugen.values.parse_decimal`:
    ``float()`` would take ``1_5``, ``infinity`` and other scripts' digits)."""
    t = value.strip(" \t")
    if not DECIMAL.fullmatch(t):
        raise FmugenError(f"{option} {value!r}: {problem}")
    return float(t)


def number(value, option: str) -> float:
    """A finite number; the text of the argument is named when it is not one."""
    if isinstance(value, bool):
        raise FmugenError(f"{option} {value!r}: not a number")
    try:
        v = _text_number(value, option, "not a number") if isinstance(value, str) else float(value)
    except (TypeError, ValueError):
        raise FmugenError(f"{option} {value!r}: not a number") from None
    except OverflowError:
        raise FmugenError(f"{option}: an integer beyond the double-precision range") from None
    if not math.isfinite(v):
        raise FmugenError(f"{option} {value!r}: must be a finite number")
    return v


def positive(value, option: str, what: str = "a positive number") -> float:
    v = number(value, option)
    if not v > 0:
        raise FmugenError(f"{option} {value!r}: must be {what}")
    return v


def tolerance(value, option: str = "--tol") -> float:
    """A tolerance: finite, > 0 and below 1 (a relative error)."""
    v = number(value, option)
    if not 0 < v < 1:
        raise FmugenError(f"{option} {value!r}: a tolerance must be > 0 and < 1")
    return v


def time_value(value, option: str, start: Optional[float] = None, stop: Optional[float] = None) -> float:
    """A finite time, within [start, stop] when they are given."""
    v = number(value, option)
    if start is not None and v < start:
        raise FmugenError(f"{option} {value!r}: before the start time {start!r}")
    if stop is not None and v > stop:
        raise FmugenError(f"{option} {value!r}: after the stop time {stop!r}")
    return v


def count(value, option: str, low: int = 1, high: Optional[int] = None) -> int:
    """A whole number in [low, high] (the bound is the work the command would take on)."""
    if isinstance(value, bool):
        raise FmugenError(f"{option} {value!r}: not a whole number")
    try:
        f = _text_number(value, option, "not a whole number") if isinstance(value, str) else float(value)
    except (TypeError, ValueError, OverflowError):
        raise FmugenError(f"{option} {value!r}: not a whole number") from None
    if not math.isfinite(f) or f != int(f):
        raise FmugenError(f"{option} {value!r}: not a whole number")
    n = int(f)
    if n < low:
        raise FmugenError(f"{option} {value!r}: must be at least {low}")
    if high is not None and n > high:
        raise FmugenError(f"{option} {n}: at most {high} (the work and memory it asks for: "
                          f"{n:.3g} against a bound of {high:.3g})")
    return n


def number_list(text, option: str, check=None) -> list:
    """``"1e-3,2e-3"`` -> [0.001, 0.002]; each item checked by ``check(value, where)`` when given."""
    items = [t.strip(" \t") for t in str(text).split(",")]
    if not items or any(not t for t in items):
        raise FmugenError(f"{option} {text!r}: expected comma-separated numbers, e.g. 1e-3,2e-3")
    out = []
    for t in items:
        where = f"{option} {text!r}: item"
        if not DECIMAL.fullmatch(t):
            raise FmugenError(f"{option} {text!r}: {t!r} is not a number")
        v = float(t)
        if not math.isfinite(v):
            raise FmugenError(f"{option} {text!r}: {t!r} is not a finite number")
        out.append(check(v, where) if check else v)
    return out


def _same(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def output_file(path, option: str, inputs: Iterable = ()) -> Path:
    """``path`` as a file to write: not a folder (existing, or written with a trailing '/'), not one of
    ``inputs``, its folder not a file."""
    text = str(path)
    p = Path(text)
    if text.endswith(("/", os.sep)) or p.is_dir():
        raise FmugenError(f"{option} {text}: a folder; {option} names the file to write")
    for i in inputs:
        if i is not None and (_same(p, Path(i)) or p.resolve() == Path(i).resolve()):
            raise FmugenError(f"{option} {text}: this is the input file {i}; writing it would destroy it")
    for parent in p.resolve().parents:
        if parent.exists():
            if not parent.is_dir():
                raise FmugenError(f"{option} {text}: {parent} is a file, not a folder")
            break
    return p


def output_folder(path, option: str, inputs: Iterable = ()) -> Path:
    """``path`` as a folder to write into: not an existing file (an input or anything else)."""
    p = Path(str(path))
    for i in inputs:
        if i is not None and _same(p, Path(i)):
            raise FmugenError(f"{option} {path}: this is the input file {i}, not a folder")
    if p.exists() and not p.is_dir():
        raise FmugenError(f"{option} {path}: a file exists there; {option} names a folder")
    for parent in p.resolve().parents:
        if parent.exists():
            if not parent.is_dir():
                raise FmugenError(f"{option} {path}: {parent} is a file, not a folder")
            break
    return p
