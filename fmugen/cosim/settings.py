"""Run settings of a co-simulation: one resolution for every command and the API.

A scene's ``[cosim]`` table, ``--set cosim.KEY=VALUE`` and the command-line
flags (or the keywords of :func:`fmugen.cosim.run`) all name the same
settings.  :func:`resolve` merges them -- the file, then ``--set``, then an
explicit flag or keyword -- checks each value where it is read, and refuses
an unknown key with the list of the valid ones.  ``fmugen cosim``,
``fmugen report``, ``fmugen sweep``, :func:`fmugen.cosim.run` (with a
CosimSystem, a scene or a built scene) and the main job all go through it, so
a key is honoured by all of them or refused by all of them.

=====================  ==========================  ===================================================
``[cosim]`` key        flag / keyword               meaning
=====================  ==========================  ===================================================
scheme                 --scheme                    jacobi | gauss-seidel | iterative | newton
extrapolation          --extrapolation             hold | linear | quadratic | cubic (iterated only)
step                   --step                      macro step H [s] (default: ``[scene] step``)
adaptive               --adaptive                  control H by the interface defect
tol                    --tol                       adaptive: defect tolerance, relative to each signal
min_step, max_step     (keywords)                  adaptive: bounds of H [s]
order                  (keyword)                   Gauss-Seidel order of the FMUs (group names)
iterations             --iterations                iterated schemes: most iterations per macro step
coupling_tol           --coupling-tol              iterated schemes: convergence of the coupled values,
                                                   relative to each signal (``iteration_tol``: old name)
workers                --workers                   threads that step the FMUs side by side
detect_divergence      --no-divergence-check       stop a run whose coupling diverges
=====================  ==========================  ===================================================

The stop time is the scene's (``[scene] stop``, ``--set scene.stop=``) or ``--stop``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Mapping, Optional

from .errors import CosimError
from .interpolants import EXTRAPOLATIONS
from .schemes import SCHEMES

DEFAULT_SCHEME, DEFAULT_EXTRAPOLATION = "gauss-seidel", "linear"

#: [cosim] key -> RunSettings field (old names kept as aliases)
KEYS = {"scheme": "scheme", "extrapolation": "extrapolation", "step": "step", "adaptive": "adaptive",
        "tol": "tol", "min_step": "min_step", "max_step": "max_step", "order": "order",
        "iterations": "max_iterations", "coupling_tol": "coupling_tol", "iteration_tol": "coupling_tol",
        "workers": "workers", "detect_divergence": "detect_divergence"}


@dataclass(frozen=True)
class RunSettings:
    """Everything a run of the master takes besides the system; None: the master's or the system's default."""

    scheme: str = DEFAULT_SCHEME
    extrapolation: str = DEFAULT_EXTRAPOLATION
    step: Optional[float] = None  # None: the system's (the scene's [scene] step)
    stop: Optional[float] = None  # None: the system's stop time
    adaptive: bool = False
    tol: Optional[float] = None
    min_step: Optional[float] = None
    max_step: Optional[float] = None
    order: Optional[tuple] = None
    max_iterations: Optional[int] = None
    coupling_tol: Optional[float] = None
    workers: int = 1
    detect_divergence: Optional[bool] = None
    dense: Optional[bool] = None  # API only: record the outputs' slopes for dense output (fmugen.cosim.dense)
    estimate: Optional[bool] = None  # API only: the coupling error estimate (fmugen.cosim.accuracy; on)

    def master_keywords(self) -> dict:
        """Keywords of :class:`fmugen.cosim.master.Master` (besides the system)."""
        return {"scheme": self.scheme, "extrapolation": self.extrapolation, "order": self.order,
                "workers": self.workers}

    def run_keywords(self) -> dict:
        """Keywords of ``Master.run``: only those set (the master keeps its defaults for the others)."""
        out = {"step": self.step, "stop": self.stop, "adaptive": self.adaptive}
        for k in ("tol", "min_step", "max_step", "max_iterations", "coupling_tol", "detect_divergence", "dense",
                  "estimate"):
            v = getattr(self, k)
            if v is not None:
                out[k] = v
        return out

    def keywords(self) -> dict:
        """Every keyword of :func:`fmugen.cosim.run`."""
        return {**self.master_keywords(), **self.run_keywords()}

    def describe(self) -> str:
        """The settings that differ from the defaults, for summaries: ``coupling_tol 1e-06, iterations 50``."""
        base = RunSettings()
        return ", ".join(f"{f.name} {getattr(self, f.name)}" for f in fields(self)
                         if f.name not in ("scheme", "extrapolation") and getattr(self, f.name) != getattr(base, f.name))


FIELDS = {f.name for f in fields(RunSettings)}

# other spellings of the choices (the master, the commands and the scene files take them all)
ALIASES = {"gs": "gauss-seidel", "gauss_seidel": "gauss-seidel", "seidel": "gauss-seidel",
           "fixed-point": "iterative", "held": "hold", "constant": "hold", "zoh": "hold"}


def _norm_choice(value, choices, what) -> str:
    v = str(value).strip().lower().replace("_", "-")
    v = ALIASES.get(v, v)
    if v not in choices:
        raise CosimError(f"unknown {what} {value!r}; choose one of {', '.join(choices)}")
    return v


def check_choices(scheme: str, extrapolation: str) -> tuple:
    """(scheme, extrapolation) normalised, or a CosimError naming the choices (callable before any build).
    Here, not in the master: the settings are resolved before a master exists, and the master imports them
    (the other way round made master and settings import each other)."""
    scheme = _norm_choice(scheme, SCHEMES, "scheme")
    extrapolation = _norm_choice(extrapolation, EXTRAPOLATIONS, "extrapolation")
    if extrapolation == "cubic" and scheme not in ("iterative", "newton"):
        raise CosimError("cubic inputs interpolate between both ends of a macro step (values and slopes): "
                         "they need an iterated scheme, iterative or newton, not " + scheme)
    return scheme, extrapolation


def _number(where, v):
    if isinstance(v, bool):
        raise CosimError(f"{where} must be a number, not {v!r}")
    if isinstance(v, str):  # text holding a number: the plain decimal grammar (values.py), not float()'s
        from ..values import DECIMAL

        if not DECIMAL.fullmatch(v.strip(" \t")):
            raise CosimError(f"{where} must be a number, not {v!r}")
    try:
        x = float(v)
    except (TypeError, ValueError, OverflowError):
        raise CosimError(f"{where} must be a number, not {v!r}") from None
    if not math.isfinite(x):
        raise CosimError(f"{where} must be finite, not {v!r}")
    return x


def _positive(where, v):
    x = _number(where, v) if isinstance(v, bool) else v
    try:
        x = float(x)
    except (TypeError, ValueError, OverflowError):
        raise CosimError(f"{where} must be a number, not {v!r}") from None
    if not (math.isfinite(x) and x > 0):
        raise CosimError(f"{where} must be finite and positive, not {v!r}")
    return x


def _whole(where, v, low=1):
    if isinstance(v, bool) or not (isinstance(v, int) or (isinstance(v, float) and v.is_integer())):
        raise CosimError(f"{where} must be a whole number >= {low}, not {v!r}")
    if v < low:
        raise CosimError(f"{where} must be >= {low}, not {v!r}")
    return int(v)


def _flag(where, v):
    if not isinstance(v, bool):
        raise CosimError(f"{where} must be true or false, not {v!r}")
    return v


def _check(field: str, value, where: str):
    """``value`` for ``field``, checked and normalised (a CosimError naming ``where`` otherwise)."""
    if field in ("scheme", "extrapolation"):
        if not isinstance(value, str):
            raise CosimError(f"{where} must be a name, not {value!r}")
        return value
    if field == "stop":  # checked against the start time by the master
        return _number(where, value)
    if field in ("step", "tol", "min_step", "max_step", "coupling_tol"):
        return _positive(where, value)
    if field in ("max_iterations", "workers"):
        return _whole(where, value)
    if field in ("adaptive", "detect_divergence", "dense", "estimate"):
        return _flag(where, value)
    if field == "order":
        if isinstance(value, str):
            value = [v.strip() for v in value.split(",") if v.strip()]
        if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
            raise CosimError(f"{where} must be a list of FMU names, not {value!r}")
        return tuple(value)
    raise AssertionError(field)


def unknown_key(key: str, where: str) -> CosimError:
    import difflib

    close = difflib.get_close_matches(key, list(KEYS), n=1, cutoff=0.6)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    return CosimError(f"{where}: unknown key {key!r}{hint}; valid [cosim] keys: {', '.join(KEYS)}")


def check_table(table: Mapping, where: str = "[cosim]") -> dict:
    """A ``[cosim]`` table checked key by key: {RunSettings field: value}."""
    out = {}
    for k, v in dict(table or {}).items():
        if k not in KEYS:
            raise unknown_key(k, where)
        out[KEYS[k]] = _check(KEYS[k], v, f"{where} {k}")
    if "scheme" in out or "extrapolation" in out:
        try:
            check_choices(out.get("scheme", DEFAULT_SCHEME), out.get("extrapolation", DEFAULT_EXTRAPOLATION))
        except CosimError as exc:
            raise CosimError(f"{where}: {exc}") from None
    return out


def resolve(table: Optional[Mapping] = None, sets: Optional[Mapping] = None, where: str = "[cosim]",
            **explicit) -> RunSettings:
    """The run settings: ``table`` (a scene's ``[cosim]``) < ``sets`` (``{"cosim.step": 4e-3}``; other
    names are ignored) < ``explicit`` (flags and keywords by RunSettings field or [cosim] key; None: not
    given).  Scheme and extrapolation are checked together (cubic needs an iterated scheme)."""
    values = check_table(table or {}, where)
    for name, v in dict(sets or {}).items():
        head, _, key = name.partition(".")
        if head == "cosim":
            if key not in KEYS:
                raise unknown_key(key, f"--set {name}")
            values[KEYS[key]] = _check(KEYS[key], v, f"--set {name}")
    for k, v in explicit.items():
        if v is None:
            continue
        f = KEYS.get(k, k)
        if f not in FIELDS:
            raise CosimError(f"unknown run setting {k!r}; valid: {', '.join(sorted(FIELDS))}")
        values[f] = _check(f, v, k)
    s = RunSettings(**values)
    scheme, ext = check_choices(s.scheme, s.extrapolation)
    return replace(s, scheme=scheme, extrapolation=ext)


def resolve_file(path, sets=None, **explicit) -> RunSettings:
    """:func:`resolve` for the scene file ``path``: its ``[cosim]`` table, ``--set`` overrides ``sets``,
    then ``explicit``; read without analysing the scene (to refuse bad settings before anything is built)."""
    import tomllib

    from ..scene.settings import parse_sets

    try:
        with open(path, "rb") as fh:
            table = tomllib.load(fh).get("cosim", {})
    except (OSError, tomllib.TOMLDecodeError):
        table = {}  # the scene's own loading reports what is wrong with the file
    return resolve(table if isinstance(table, dict) else {}, parse_sets(sets), f"{path}: [cosim]", **explicit)
