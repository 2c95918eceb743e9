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
as well: it is the largest difference over every step point of the main
solve, their midpoints and the requested times.

Solutions are cached on disk (``~/.cache/fmugen/reference`` or
``$FMUGEN_CACHE``) **independently of the output grid**: what is stored is the
main solve's dense output (per Radau step: its start, length, start value and
collocation coefficients) with the error estimate, keyed by a hash of the
model's equations, parameter values, x0, u, the time span and the settings.
Another grid over the same problem is evaluated from it (states from the
polynomials, computed outputs through the model's output function) without
solving again.  An entry holds its key and a sha256 of its arrays, and is served
only when both match (a truncated, swapped or edited file is solved again).
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

from ..cache import cache_home
from .errors import CosimError
from .system import ReferenceProblem

RTOL = 1e-12
DOP853_MAX_STEPS = 300_000
CACHE_VERSION = 3  # 2: entries carry their key and a digest; 3: the dense output, not one grid's values
MAX_ERROR_POINTS = 200_001  # evaluation points of the error estimate (step points, midpoints)


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
    return cache_home() / "reference"


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


def _key(problem: ReferenceProblem, rtol: float, param_values: dict) -> str:
    m = problem.model
    h = hashlib.sha256()
    h.update(f"v{CACHE_VERSION}|{m.name}|{rtol!r}".encode())
    for part in (m.states, m.inputs, m.outputs):
        h.update(("|".join(v.name for v in part)).encode())
    h.update(repr(sorted(param_values.items())).encode())
    h.update(repr([str(e) for e in m.derivatives]).encode())
    h.update(repr([str(e) for e in m.output_exprs]).encode())
    h.update(repr([(str(getattr(s, "lhs", s)), str(getattr(s, "rhs", ""))) for s in m.program.steps]).encode())
    h.update(repr((float(problem.start_time), float(problem.stop_time))).encode())
    for a in (np.asarray(problem.x0, float), np.asarray(problem.u, float),
              np.asarray(problem.nominals if problem.nominals is not None else [], float)):
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(repr(tuple(problem.columns)).encode())
    return h.hexdigest()[:32]


class DenseOutput:
    """x(t) of a Radau solve from its stored steps: on step k, x = y_old[k] + Q[k] @ (s, s^2, s^3) with
    s = (t - t_old[k]) / h[k] -- scipy's RadauDenseOutput, evaluated for many points at once."""

    def __init__(self, ts: np.ndarray, y_old: np.ndarray, Q: np.ndarray):
        self.ts, self.y_old, self.Q = np.asarray(ts, float), np.asarray(y_old, float), np.asarray(Q, float)

    @classmethod
    def of(cls, sol) -> "DenseOutput":
        """From scipy's ``solve_ivp(..., method="Radau", dense_output=True)`` result."""
        ip = sol.sol.interpolants
        return cls(np.asarray(sol.sol.ts), np.array([d.y_old for d in ip]), np.array([d.Q for d in ip]))

    def __call__(self, times: np.ndarray) -> np.ndarray:
        """(nx, len(times))"""
        times = np.asarray(times, float)
        seg = np.clip(np.searchsorted(self.ts, times, side="left") - 1, 0, len(self.ts) - 2)
        out = np.empty((self.y_old.shape[1], len(times)))
        for a in range(0, len(times), 20_000):  # bounded memory: Q[seg] is (points, nx, order)
            k = seg[a:a + 20_000]
            x = (times[a:a + 20_000] - self.ts[k]) / (self.ts[k + 1] - self.ts[k])
            P = np.cumprod(np.repeat(x[:, None], self.Q.shape[2], axis=1), axis=1)
            out[:, a:a + 20_000] = (np.einsum("nij,nj->ni", self.Q[k], P) + self.y_old[k]).T
        return out


def _digest(arrays, settings: str) -> str:
    """sha256 of a stored solution's arrays and settings: an entry is served only when it still matches."""
    h = hashlib.sha256()
    for a in arrays:
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
    key = _key(problem, rtol, pv)
    path = cache_dir() / f"{key}.npz"
    x0 = np.asarray(problem.x0, dtype=float).ravel()
    u = np.asarray(problem.u, dtype=float).ravel()
    evaluator = []  # the model's evaluator, made when first needed (outputs, or a solve)

    def ev():
        if not evaluator:
            evaluator.append(ModelEvaluator(m, parameter_values))
        return evaluator[0]

    def values_at(X):
        """The columns from the states X (nx, n) at ``times``."""
        out = np.empty((len(times), len(cols)))
        Ys = np.array([ev().g(t, X[:, i], u) for i, t in enumerate(times)]) if any(k == "y" for k, _ in cols) \
            else None
        for j, (k, i) in enumerate(cols):
            out[:, j] = X[i] if k == "x" else Ys[:, i]
        return out

    if cache and path.is_file() and m.events is None:
        try:
            with np.load(path, allow_pickle=False) as z:
                ts, y_old, Q, error, text = z["ts"], z["y_old"], z["Q"], z["error"], str(z["settings"])
                whole = (str(z["key"]) == key and str(z["digest"]) == _digest((ts, y_old, Q, error), text)
                         and error.shape == (len(cols),) and Q.ndim == 3 and Q.shape[:2] == y_old.shape
                         and y_old.shape[1] == m.nx and len(ts) == len(y_old) + 1)
            if whole:  # this entry, as written: a truncated, swapped or edited file is recomputed
                return ReferenceSolution(times, values_at(DenseOutput(ts, y_old, Q)(times)), tuple(problem.columns),
                                         error, json.loads(text), cached=True)
        except Exception:  # a damaged cache file is recomputed
            pass
    if x0.shape != (m.nx,) or u.shape != (m.nu,):
        raise CosimError(f"reference problem {m.name}: x0 has {x0.size} values for {m.nx} states, "
                         f"u {u.size} for {m.nu} inputs")
    if problem.nominals is not None:
        nom = np.abs(np.asarray(problem.nominals, dtype=float).ravel())
    else:
        nom = np.array([abs(v.nominal) if v.nominal else max(1.0, abs(x)) for v, x in zip(m.states, x0)])
    nom = np.where(nom > 0, nom, 1.0)
    if m.events is not None:  # piecewise smooth: located events and restarts (not cached)
        from .hybrid_reference import solve_hybrid_reference

        values, err, settings = solve_hybrid_reference(problem, times, rtol, parameter_values, cols, nom)
        return ReferenceSolution(times, values, tuple(problem.columns), err, settings)

    model_ev = ev()

    def f(t, x):
        return model_ev.f(t, x, u)

    def jac(t, x):
        return model_ev.jacobians(t, x, u)[0]

    def solve(method, rt, at, use_jac=True):
        w = _time.perf_counter()
        kw = {"jac": jac} if use_jac and m.jacobian is not None and method in ("Radau", "BDF") else {}
        sol = solve_ivp(f, (t0, t1), x0, method=method, rtol=rt, atol=at * nom, dense_output=True, **kw)
        if not sol.success:
            raise CosimError(f"reference solve of {m.name} with {method} at rtol {rt:g} failed: {sol.message}")
        return sol, _time.perf_counter() - w

    sol1, w1 = solve("Radau", rtol, rtol)
    dense = DenseOutput.of(sol1)
    # the error estimate over every step point of the main solve, their midpoints and the requested times:
    # it holds for any later grid evaluated from the cached dense output
    ts = dense.ts
    probe = np.concatenate([ts, 0.5 * (ts[1:] + ts[:-1])])
    if len(probe) > MAX_ERROR_POINTS:
        probe = probe[np.linspace(0, len(probe) - 1, MAX_ERROR_POINTS).astype(int)]
    grid = times
    times = np.unique(np.concatenate([probe, grid]))
    v1 = values_at(dense(times))
    tight = max(rtol / 10, 2.3e-14)  # scipy's floor is 100 eps
    sol2, w2 = solve("Radau", tight, rtol / 10)
    v2 = values_at(sol2.sol(times))
    err = np.max(np.abs(v1 - v2), axis=0)
    settings = {"method": "Radau", "rtol": rtol, "atol": f"{rtol:g} x nominal", "steps": int(sol1.t.size - 1),
                "wall_time": w1, "confirm": [f"Radau rtol {tight:g}: {sol2.t.size - 1} steps, {w2:.3g} s"]}
    # a second method where explicit steps stay affordable (not stiff over the span)
    lam = 0.0
    if m.jacobian is not None:
        lam = float(np.max(np.abs(np.linalg.eigvals(jac(t0, x0))))) if m.nx else 0.0
    if lam * (t1 - t0) / 3.0 < DOP853_MAX_STEPS:
        sol3, w3 = solve("DOP853", tight, rtol / 10, use_jac=False)
        v3 = values_at(sol3.sol(times))
        err = np.maximum(err, np.max(np.abs(v1 - v3), axis=0))
        settings["confirm"].append(f"DOP853 rtol {tight:g}: {sol3.t.size - 1} steps, {w3:.3g} s")
    else:
        settings["confirm"].append(f"DOP853 skipped: stiff (|lambda|max = {lam:.3g} 1/s over {t1 - t0:g} s)")
    settings["error_points"] = int(len(times))
    pick = np.searchsorted(times, grid)  # the requested grid inside the evaluation points
    ref = ReferenceSolution(grid, v1[pick], tuple(problem.columns), err, settings)
    if cache:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npz")  # one per writer
            text = json.dumps(settings)
            np.savez(tmp, ts=dense.ts, y_old=dense.y_old, Q=dense.Q, error=err, settings=text, key=key,
                     digest=_digest((dense.ts, dense.y_old, dense.Q, err), text))
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
