"""Reference solutions: the whole scene as one ODE, solved far below any co-simulation error.

The :class:`~fmugen.cosim.system.ReferenceProblem` is x' = f(t, x, u, p),
y = g(t, x, u, p) with constant free inputs u (one model assembled from the
same symbolic components the FMUs were generated from).  It is solved with
scipy's Radau IIA (order 5, L-stable) at rtol = 1e-12 and atol = 1e-12 times
each state's nominal magnitude (pressures ~1e7 Pa, angles ~1 rad), with the
model's exact Jacobian df/dx.  The solve is confirmed by

* a tenfold tighter Radau solve (rtol, atol / 10), and
* where the problem is not stiff over the span (explicit steps would number
  fewer than ``DOP853_MAX_STEPS``), an explicit Dormand-Prince 8(5,3) solve at
  the tight tolerances -- a second method with a different error structure;

the largest difference between the solutions, per column, is the reference's
own error estimate (:attr:`ReferenceSolution.error`).  Reports refuse to
quote co-simulation errors closer than 100x to it.

Values are those of the solvers' dense output at the requested times
(Radau's collocation polynomial), so the estimate covers the interpolation
as well.  Solutions are cached on disk (``~/.cache/fmugen/reference`` or
``$FMUGEN_CACHE``), keyed by a hash of the model's equations, parameter values,
x0, u, times and settings; an entry holds its key and a sha256 of its arrays,
and is served only when both match (a truncated, swapped or edited file is
solved again).
"""
from __future__ import annotations

import hashlib
import json
import os
import time as _time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from .errors import CosimError
from .system import ReferenceProblem

RTOL = 1e-12
DOP853_MAX_STEPS = 300_000
CACHE_VERSION = 2  # 2: entries carry their key and a digest, checked before use


@dataclass
class ReferenceSolution:
    """Reference values ``values[i, j]`` of ``columns[j]`` at ``time[i]``."""

    time: np.ndarray
    values: np.ndarray
    columns: tuple
    error: np.ndarray  # per column: max |difference| between the confirming solves
    settings: dict = field(default_factory=dict)  # rtol, methods, steps, wall times
    cached: bool = False

    def __getitem__(self, column: str) -> np.ndarray:
        try:
            return self.values[:, self.columns.index(column)]
        except ValueError:
            raise KeyError(f"no reference column {column!r}; columns: {', '.join(self.columns)}") from None

    def error_of(self, column: str) -> float:
        return float(self.error[self.columns.index(column)])


def cache_dir() -> Path:
    root = os.environ.get("FMUGEN_CACHE")
    return Path(root) / "reference" if root else Path.home() / ".cache" / "fmugen" / "reference"


def _column_map(problem: ReferenceProblem) -> list:
    """(kind, index) per column: ('x', i) for a state, ('y', i) for a computed output."""
    m = problem.model
    xs = {v.name: i for i, v in enumerate(m.states)}
    ys = {v.name: i for i, v in enumerate(m.outputs)}
    out = []
    for c in problem.columns:
        if c in xs:
            out.append(("x", xs[c]))
        elif c in ys:
            out.append(("y", ys[c]))
        else:
            import difflib

            near = difflib.get_close_matches(c, list(xs) + list(ys), n=3)
            raise CosimError(f"reference problem {m.name}: column {c!r} is neither a state nor an output"
                             + (f" (did you mean {', '.join(near)}?)" if near else ""))
    return out


def _key(problem: ReferenceProblem, times: np.ndarray, rtol: float, param_values: dict) -> str:
    m = problem.model
    h = hashlib.sha256()
    h.update(f"v{CACHE_VERSION}|{m.name}|{rtol!r}".encode())
    for part in (m.states, m.inputs, m.outputs):
        h.update(("|".join(v.name for v in part)).encode())
    h.update(repr(sorted(param_values.items())).encode())
    h.update(repr([str(e) for e in m.derivatives]).encode())
    h.update(repr([str(e) for e in m.output_exprs]).encode())
    h.update(repr([(str(getattr(s, "lhs", s)), str(getattr(s, "rhs", ""))) for s in m.program.steps]).encode())
    for a in (np.asarray(problem.x0, float), np.asarray(problem.u, float), times,
              np.asarray(problem.nominals if problem.nominals is not None else [], float)):
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(repr(tuple(problem.columns)).encode())
    return h.hexdigest()[:32]


def _digest(times, values, error, settings: str) -> str:
    """sha256 of a stored solution's arrays and settings: an entry is served only when it still matches."""
    h = hashlib.sha256()
    for a in (times, values, error):
        a = np.ascontiguousarray(np.asarray(a, dtype=float))
        h.update(repr(a.shape).encode())
        h.update(a.tobytes())
    h.update(settings.encode())
    return h.hexdigest()


def default_times(problem: ReferenceProblem, n: int = 2001) -> np.ndarray:
    return np.linspace(problem.start_time, problem.stop_time, max(int(n), 1001))


def solve_reference(problem: ReferenceProblem, times: Optional[Sequence[float]] = None, rtol: float = RTOL,
                    cache: bool = True, parameter_values: Optional[dict] = None) -> ReferenceSolution:
    """Solve ``problem`` and return the columns at ``times`` (default: 2001 uniform points).

    ``times`` must lie in [start_time, stop_time].  See the module docstring
    for the method and the error estimate.
    """
    from scipy.integrate import solve_ivp

    from ..codegen.evaluate import ModelEvaluator

    t0, t1 = float(problem.start_time), float(problem.stop_time)
    if not (np.isfinite(t0) and np.isfinite(t1) and t1 > t0):
        raise CosimError(f"reference: start {t0} and stop {t1} must be finite, stop after start")
    times = default_times(problem) if times is None else np.asarray(times, dtype=float).ravel()
    if len(times) == 0 or times.min() < t0 - 1e-12 or times.max() > t1 + 1e-12:
        raise CosimError(f"reference: times must lie in [{t0}, {t1}]")
    times = np.clip(times, t0, t1)
    m = problem.model
    pv = {v.name: v.start for v in m.parameters}
    pv.update(parameter_values or {})
    cols = _column_map(problem)
    key = _key(problem, times, rtol, pv)
    path = cache_dir() / f"{key}.npz"
    if cache and path.is_file():
        try:
            with np.load(path, allow_pickle=False) as z:
                t_, v_, e_, s_ = z["time"], z["values"], z["error"], str(z["settings"])
                whole = (str(z["key"]) == key and str(z["digest"]) == _digest(t_, v_, e_, s_)
                         and t_.shape == times.shape and np.array_equal(t_, times)
                         and v_.shape == (len(times), len(cols)) and e_.shape == (len(cols),))
            if whole:  # this entry, as written: a truncated, swapped or edited file is recomputed
                return ReferenceSolution(t_, v_, tuple(problem.columns), e_, json.loads(s_), cached=True)
        except Exception:  # a damaged cache file is recomputed
            pass
    ev = ModelEvaluator(m, parameter_values)
    x0 = np.asarray(problem.x0, dtype=float).ravel()
    u = np.asarray(problem.u, dtype=float).ravel()
    if x0.shape != (m.nx,) or u.shape != (m.nu,):
        raise CosimError(f"reference problem {m.name}: x0 has {x0.size} values for {m.nx} states, "
                         f"u {u.size} for {m.nu} inputs")
    if problem.nominals is not None:
        nom = np.abs(np.asarray(problem.nominals, dtype=float).ravel())
    else:
        nom = np.array([abs(v.nominal) if v.nominal else max(1.0, abs(x)) for v, x in zip(m.states, x0)])
    nom = np.where(nom > 0, nom, 1.0)

    def f(t, x):
        return ev.f(t, x, u)

    def jac(t, x):
        return ev.jacobians(t, x, u)[0]

    def values(sol):
        X = sol.sol(times)  # (nx, n)
        out = np.empty((len(times), len(cols)))
        need_y = any(k == "y" for k, _ in cols)
        Ys = np.array([ev.g(t, X[:, i], u) for i, t in enumerate(times)]) if need_y else None
        for j, (k, i) in enumerate(cols):
            out[:, j] = X[i] if k == "x" else Ys[:, i]
        return out

    def solve(method, rt, at, use_jac=True):
        w = _time.perf_counter()
        kw = {"jac": jac} if use_jac and m.jacobian is not None and method in ("Radau", "BDF") else {}
        sol = solve_ivp(f, (t0, t1), x0, method=method, rtol=rt, atol=at * nom, dense_output=True, **kw)
        if not sol.success:
            raise CosimError(f"reference solve of {m.name} with {method} at rtol {rt:g} failed: {sol.message}")
        return sol, _time.perf_counter() - w

    sol1, w1 = solve("Radau", rtol, rtol)
    v1 = values(sol1)
    tight = max(rtol / 10, 2.3e-14)  # scipy's floor is 100 eps
    sol2, w2 = solve("Radau", tight, rtol / 10)
    v2 = values(sol2)
    err = np.max(np.abs(v1 - v2), axis=0)
    settings = {"method": "Radau", "rtol": rtol, "atol": f"{rtol:g} x nominal", "steps": int(sol1.t.size - 1),
                "wall_time": w1, "confirm": [f"Radau rtol {tight:g}: {sol2.t.size - 1} steps, {w2:.3g} s"]}
    # a second method where explicit steps stay affordable (not stiff over the span)
    lam = 0.0
    if m.jacobian is not None:
        lam = float(np.max(np.abs(np.linalg.eigvals(jac(t0, x0))))) if m.nx else 0.0
    if lam * (t1 - t0) / 3.0 < DOP853_MAX_STEPS:
        sol3, w3 = solve("DOP853", tight, rtol / 10, use_jac=False)
        v3 = values(sol3)
        err = np.maximum(err, np.max(np.abs(v1 - v3), axis=0))
        settings["confirm"].append(f"DOP853 rtol {tight:g}: {sol3.t.size - 1} steps, {w3:.3g} s")
    else:
        settings["confirm"].append(f"DOP853 skipped: stiff (|lambda|max = {lam:.3g} 1/s over {t1 - t0:g} s)")
    ref = ReferenceSolution(times, v1, tuple(problem.columns), err, settings)
    if cache:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npz")  # one per writer
            text = json.dumps(settings)
            np.savez(tmp, time=times, values=v1, error=err, settings=text, key=key,
                     digest=_digest(times, v1, err, text))
            os.replace(tmp, path)
        except OSError:
            pass  # a read-only home: no cache
    return ref


def write_reference_csv(ref: ReferenceSolution, path) -> None:
    """``time`` then every column, full precision."""
    path = Path(path)
    header = ",".join(["time", *ref.columns])
    np.savetxt(path, np.column_stack([ref.time, ref.values]), delimiter=",", header=header, comments="",
               fmt="%.17g")
