"""The points of a sweep: a grid (every combination of listed values) or Monte-Carlo samples.

``--grid joint.J=1,2,4`` lists values (or ``linspace(1,4,7)``, ``geomspace(1e8,1e10,5)``:
numpy's spacings); several ``--grid`` options span their Cartesian product (the first name
varies slowest).  ``--sample
actuator.beta_e=normal(1.6e9,5e7) -n 200 --seed 1`` draws ``n`` values per
name from a distribution; several ``--sample`` options draw independently
(one column each, in the order given, from one seeded generator), and grid
and samples together give every sample at every grid point.

Distribution specifications are parsed, never evaluated: a name from
:data:`DISTRIBUTIONS` and that many finite numbers in parentheses.

=========================  ===================================================
``normal(mean, std)``      Gaussian, std > 0
``uniform(low, high)``     flat on [low, high), low < high
``lognormal(mu, sigma)``   exp of a Gaussian with mean mu, std sigma > 0 (the
                           logarithm's parameters, as numpy's ``lognormal``)
``triangular(low, mode, high)``  low <= mode <= high, low < high
=========================  ===================================================

A point's identity is its parameter values (``point_key``): a restarted
sweep recognises the points it already ran whatever their order.
"""
from __future__ import annotations

import hashlib
import itertools
import math
import re
from dataclasses import dataclass
from typing import Iterable, Mapping, Optional, Sequence, Union

import numpy as np

from ..values import parse_decimal
from .errors import SweepError

#: name -> (number of arguments, their names, numpy draw)
DISTRIBUTIONS = {
    "normal": (("mean", "std"), lambda rng, a, n: rng.normal(a[0], a[1], n)),
    "uniform": (("low", "high"), lambda rng, a, n: rng.uniform(a[0], a[1], n)),
    "lognormal": (("mu", "sigma"), lambda rng, a, n: rng.lognormal(a[0], a[1], n)),
    "triangular": (("low", "mode", "high"), lambda rng, a, n: rng.triangular(a[0], a[1], a[2], n)),
}

#: most points one sweep may have (each is a co-simulation run and a row of the table)
MAX_POINTS = 1_000_000

# a parameter name as the scene writes it: instance.parameter (an element index allowed, arm.q[2])
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*\.[A-Za-z_][A-Za-z0-9_]*(\[[0-9]+\])?$")
_DIST = re.compile(r"^([a-z]+)\((.*)\)$")
_HELP = "write " + ", ".join(f"{k}({', '.join(v[0])})" for k, v in DISTRIBUTIONS.items())


@dataclass(frozen=True)
class Distribution:
    """One parsed ``--sample`` right-hand side."""

    kind: str
    args: tuple

    def draw(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return np.asarray(DISTRIBUTIONS[self.kind][1](rng, self.args, n), dtype=float)

    def __str__(self) -> str:
        return f"{self.kind}({', '.join(repr(a) for a in self.args)})"


def _number(text: str, where: str) -> float:
    """A finite decimal number (``1.6e9``, ``-3``, ``.5``) in the plain decimal grammar of
    :func:`fmugen.values.parse_decimal` (ASCII digits: ``\\d`` took Arabic-Indic ones); anything
    else is refused."""
    return parse_decimal(text, where, SweepError)


def parse_name(name: str, where: str) -> str:
    name = name.strip()
    if not _NAME.match(name):
        raise SweepError(f"{where}: {name!r} is not a scene parameter name like 'joint.J' or 'actuator.beta_e'")
    return name


def _split_assignment(text: str, option: str) -> tuple:
    if "=" not in text:
        raise SweepError(f"{option} {text!r}: expected NAME=...")
    name, rhs = text.split("=", 1)
    return parse_name(name, f"{option} {text}"), rhs.strip()


def parse_distribution(text: str, where: str = "--sample") -> Distribution:
    """``"normal(1.6e9, 5e7)"`` -> Distribution('normal', (1.6e9, 5e7)); never evaluated.

    >>> parse_distribution("uniform(1, 3)")
    Distribution(kind='uniform', args=(1.0, 3.0))
    """
    t = re.sub(r"\s+", "", str(text))
    m = _DIST.match(t)
    if not m:
        raise SweepError(f"{where}: {text!r} is not a distribution; {_HELP}")
    kind, inner = m.group(1), m.group(2)
    if kind not in DISTRIBUTIONS:
        raise SweepError(f"{where}: unknown distribution {kind!r}; {_HELP}")
    names = DISTRIBUTIONS[kind][0]
    parts = inner.split(",") if inner else []
    if len(parts) != len(names):
        raise SweepError(f"{where}: {kind} takes {len(names)} numbers ({', '.join(names)}), got {len(parts)}")
    a = tuple(_number(p, f"{where}: {kind} {n}") for p, n in zip(parts, names))
    if kind in ("normal", "lognormal") and not a[1] > 0:
        raise SweepError(f"{where}: {kind} needs {names[1]} > 0, got {a[1]:g}")
    if kind == "uniform" and not a[0] < a[1]:
        raise SweepError(f"{where}: uniform needs low < high, got {a[0]:g}, {a[1]:g}")
    if kind == "triangular" and not (a[0] <= a[1] <= a[2] and a[0] < a[2]):
        raise SweepError(f"{where}: triangular needs low <= mode <= high and low < high, got {a}")
    return Distribution(kind, a)


def parse_grid(items: Union[Iterable[str], Mapping[str, Sequence[float]], None]) -> dict:
    """``["joint.J=1,2,4"]`` (or ``{"joint.J": [1, 2, 4]}``) -> ``{"joint.J": (1.0, 2.0, 4.0)}``."""
    out = {}
    if not items:
        return out
    pairs = items.items() if isinstance(items, Mapping) else (_split_assignment(t, "--grid") for t in items)
    for name, values in pairs:
        name = parse_name(name, f"--grid {name}")
        where = f"--grid {name}"
        if isinstance(values, str) and _SPACE.match(re.sub(r"\s+", "", values)):
            vals = _spaced(re.sub(r"\s+", "", values), where)
        elif isinstance(values, str):
            values = [v for v in values.split(",")]
            if not values or any(not v.strip() for v in values):
                raise SweepError(f"{where}: expected comma-separated numbers, e.g. {name}=1,2,4, "
                                 f"or linspace(a,b,n) / geomspace(a,b,n)")
            vals = tuple(_number(v, where) for v in values)
        else:
            vals = tuple(_finite(v, where) for v in values)
        if not vals:
            raise SweepError(f"{where}: no values")
        if name in out:
            raise SweepError(f"{where}: {name} is given twice")
        out[name] = vals
    return out


def _finite(v, where) -> float:
    if isinstance(v, bool):
        raise SweepError(f"{where}: {v!r} is not a number")
    if isinstance(v, str):
        return _number(v, where)
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise SweepError(f"{where}: {v!r} is not a number") from None
    if not math.isfinite(f):
        raise SweepError(f"{where}: {v!r} is not a finite number")
    return f


_SPACE = re.compile(r"^(linspace|geomspace)\((.*)\)$")


def _spaced(text: str, where: str) -> tuple:
    """``linspace(a,b,n)``: n values evenly spaced from a to b; ``geomspace(a,b,n)``: in constant ratio."""
    kind, inner = _SPACE.match(text).groups()
    parts = inner.split(",")
    if len(parts) != 3:
        raise SweepError(f"{where}: {kind} takes three numbers (first, last, count), got {len(parts)}")
    a, b = _number(parts[0], f"{where}: {kind} first"), _number(parts[1], f"{where}: {kind} last")
    if not re.fullmatch(r"[0-9]+", parts[2].strip()) or not 1 <= int(parts[2]) <= 1_000_000:
        raise SweepError(f"{where}: {kind} count {parts[2]!r} must be a whole number from 1 to 1000000")
    if kind == "geomspace" and not (a * b > 0):
        raise SweepError(f"{where}: geomspace needs first and last of the same sign, neither zero")
    f = np.linspace if kind == "linspace" else np.geomspace
    return tuple(float(v) for v in f(a, b, int(parts[2])))


def parse_samples(items: Union[Iterable[str], Mapping[str, object], None]) -> dict:
    """``["actuator.beta_e=normal(1.6e9,5e7)"]`` -> ``{"actuator.beta_e": Distribution(...)}``."""
    out = {}
    if not items:
        return out
    pairs = items.items() if isinstance(items, Mapping) else (_split_assignment(t, "--sample") for t in items)
    for name, spec in pairs:
        name = parse_name(name, f"--sample {name}")
        d = spec if isinstance(spec, Distribution) else parse_distribution(spec, f"--sample {name}")
        if name in out:
            raise SweepError(f"--sample {name}: {name} is given twice")
        out[name] = d
    return out


def make_points(grid: Optional[dict] = None, samples: Optional[dict] = None, n: Optional[int] = None,
                seed: Optional[int] = None) -> list:
    """The sweep's points, each ``{name: value}``.

    grid: name -> values (Cartesian product, first name slowest); samples:
    name -> :class:`Distribution`, ``n`` draws each from
    ``numpy.random.default_rng(seed)`` (column by column in the order given,
    so the same specification and seed give the same points on any machine
    with the same numpy); both: every sample at every grid point.
    """
    grid = grid or {}
    samples = samples or {}
    if not grid and not samples:
        raise SweepError("a sweep needs --grid NAME=v1,v2,... or --sample NAME=dist(...)")
    both = set(grid) & set(samples)
    if both:
        raise SweepError(f"{', '.join(sorted(both))}: given both as --grid and --sample")
    total = math.prod(len(v) for v in grid.values()) if grid else 1
    n_int = None
    if samples and n is not None and not isinstance(n, bool) and isinstance(n, (int, float)) and n >= 1 \
            and (isinstance(n, int) or math.isfinite(n)):
        n_int = int(n)
        total *= n_int
    if total > MAX_POINTS:  # estimated before a single point is made: the product would not fit in memory
        def big(k: int) -> str:
            return f"{k:.3g}" if k < 10**300 else f"a {len(str(k))}-digit number of"
        sizes = " x ".join([str(len(v)) for v in grid.values()] + ([f"{big(n_int)} samples"] if n_int else []))
        raise SweepError(f"--grid/--sample: {sizes} = {big(total)} points, more than {MAX_POINTS:.0e}; "
                         f"split the study or use fewer values")
    rows = [dict(zip(grid, combo)) for combo in itertools.product(*grid.values())] if grid else [{}]
    if samples:
        if n is None or isinstance(n, bool) or int(n) != n or n < 1:
            raise SweepError(f"-n: Monte-Carlo sampling needs a number of samples >= 1, not {n!r}")
        if seed is None:
            raise SweepError("--seed: Monte-Carlo sampling needs a seed (the sweep must be reproducible)")
        if isinstance(seed, bool) or int(seed) != seed or seed < 0:
            raise SweepError(f"--seed: {seed!r} is not a non-negative integer")
        rng = np.random.default_rng(int(seed))
        cols = {name: d.draw(rng, int(n)) for name, d in samples.items()}
        drawn = [{name: float(cols[name][i]) for name in samples} for i in range(int(n))]
        rows = [dict(g, **s) for g in rows for s in drawn]
    elif n is not None:
        raise SweepError("-n: a number of samples is only meaningful with --sample")
    return rows


def point_key(values: Mapping[str, float]) -> str:
    """The identity of a point: a hash of its names and values (exact: ``float.hex``)."""
    text = ";".join(f"{k}={float(values[k]).hex()}" for k in sorted(values))
    return hashlib.sha256(text.encode()).hexdigest()[:16]
