"""The reference a run is judged against: the same SymbolicModel, integrated
by scipy with the exact Jacobian at rtol 1e-12, and confirmed by a second,
different solve.

Stiff cases: Radau at rtol 1e-12 against Radau at 1e-11 (Radau is the only
scipy method that reaches 1e-12 on them in reasonable time).  Non-stiff
cases: Radau at 1e-12 against DOP853 at 1e-12 (two unrelated methods).  The
difference of the two is the reference's own uncertainty; the suite reports
it and never calls an error below 10x it a failure.

Absolute tolerances are scaled by each state's nominal value (pressures of
1e7 Pa next to angles of 0.1 rad).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from ..codegen.evaluate import ModelEvaluator


@dataclass
class Setup:
    """Numeric form of a case: evaluator with the case's parameters, x0, held inputs."""

    ev: ModelEvaluator
    x0: np.ndarray
    u: np.ndarray
    nominal: np.ndarray
    names: list  # states then outputs, the columns of Reference.values

    def column(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"{self.ev.model.name}: no state or output {name!r}") from None


def setup(model, start: dict) -> Setup:
    """Split a case's start values into parameters, inputs and state starts."""
    pnames = {v.name for v in model.parameters}
    params = {k: v for k, v in start.items() if k in pnames}
    ev = ModelEvaluator(model, params)
    snames = [v.name for v in model.states]
    inames = [v.name for v in model.inputs]
    unknown = set(start) - pnames - set(snames) - set(inames)
    if unknown:
        raise KeyError(f"{model.name}: start values for unknown variables {sorted(unknown)}")
    x0, u = ev.x0.copy(), ev.u0.copy()
    for k, v in start.items():
        if k in snames:
            x0[snames.index(k)] = v
        elif k in inames:
            u[inames.index(k)] = v
    nominal = np.array([abs(v.nominal) if v.nominal else 1.0 for v in model.states])
    return Setup(ev, x0, u, nominal, snames + [v.name for v in model.outputs])


@dataclass
class Reference:
    t: np.ndarray
    values: np.ndarray  # len(t) x (nx + ny): states, then outputs
    uncertainty: np.ndarray  # per column, max |first solve - confirmation|
    f_evals: int
    jac_evals: int
    wall: float  # s, the first solve


def _jacobian(s: Setup, t, x):
    """The exact df/dx; columns it leaves non-finite (a 0/0 in a derivative of
    |.| exactly at a kink) by central differences of f."""
    A = s.ev.jacobians(t, x, s.u)[0]
    bad = ~np.all(np.isfinite(A), axis=0)
    for j in np.flatnonzero(bad):
        d = 1e-7 * max(abs(x[j]), s.nominal[j])
        xp, xm = x.copy(), x.copy()
        xp[j] += d
        xm[j] -= d
        A[:, j] = (s.ev.f(t, xp, s.u) - s.ev.f(t, xm, s.u)) / (2 * d)
    return A


def _solve(s: Setup, t, method, rtol):
    f = lambda tt, x: s.ev.f(tt, x, s.u)  # noqa: E731
    kw = {"jac": lambda tt, x: _jacobian(s, tt, x)} if method in ("Radau", "BDF", "LSODA") else {}
    t0 = time.perf_counter()
    sol = solve_ivp(f, (t[0], t[-1]), s.x0, method=method, rtol=rtol, atol=rtol * s.nominal, t_eval=t,
                    dense_output=False, **kw)
    wall = time.perf_counter() - t0
    if not sol.success:
        raise RuntimeError(f"reference solve ({method}, rtol {rtol:g}) failed: {sol.message}")
    x = sol.y.T
    y = np.array([s.ev.g(tt, xx, s.u) for tt, xx in zip(t, x)]) if s.ev.model.outputs else np.zeros((len(t), 0))
    return np.hstack([x, y.reshape(len(t), -1)]), sol.nfev, sol.njev, wall


def reference(s: Setup, t: np.ndarray, stiff: bool) -> Reference:
    vals, nf, nj, wall = _solve(s, t, "Radau", 1e-12)
    conf, *_ = _solve(s, t, "Radau" if stiff else "DOP853", 1e-11 if stiff else 1e-12)
    return Reference(t, vals, np.max(np.abs(vals - conf), axis=0), nf, nj, wall)


def sensitivity(s: Setup, t: np.ndarray, columns, ref: Reference, stiff: bool, rel: float = 1e-6) -> float:
    """G = max over t of |y(t; x0 + dx0) - y(t; x0)| / |dx0|, dx0 = rel x nominal
    along every state at once (in units of the nominals): how much the motion
    amplifies an error made early on.  Solved at rtol 1e-10, so G is good to
    ~1e-4 relative.  >= 1 by convention (a decaying motion still carries the
    last step's error)."""
    pert = Setup(s.ev, s.x0 + rel * s.nominal, s.u, s.nominal, s.names)
    vals, *_ = _solve(pert, t, "Radau" if stiff else "DOP853", 1e-10)
    return max(1.0, float(np.max(np.abs(vals[:, columns] - ref.values[:, columns]))) / rel)


def work_precision_radau(s: Setup, t: np.ndarray, column: int, ref: Reference, rtols=(1e-4, 1e-6, 1e-8)):
    """scipy Radau's error, f and Jacobian evaluations and wall time over rtols
    (for the comparison with the FMU's implicit solver at equal error)."""
    rows = []
    for rtol in rtols:
        vals, nf, nj, wall = _solve(s, t, "Radau", rtol)
        rows.append((rtol, float(np.max(np.abs(vals[:, column] - ref.values[:, column]))), nf, nj, wall))
    return rows
