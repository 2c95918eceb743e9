"""Numeric evaluation of a (small, closed-form) SymbolicModel with numpy.

For tests, linearisation and benchmarks at the Python level: the model's
programs are inlined to closed forms and lambdified once.  Parameters take
their start values unless given.

>>> from fmugen.components import joint_inertia
>>> ev = NumericModel(joint_inertia())
>>> ev.f(0.0, [0.0, 1.0], [7.0, 0.0]).tolist()   # [w, (tau - B_m w)/J]
[1.0, 1.0]
"""
from __future__ import annotations

from typing import Mapping, Optional

import numpy as np
import sympy as sp

from ..codegen.model import SymbolicModel
from .base import TIME


class NumericModel:
    """f(t, x, u), g(t, x, u) and the exact Jacobians dfdx, dfdu as numpy arrays."""

    def __init__(self, model: SymbolicModel, parameter_values: Optional[Mapping[str, float]] = None):
        self.model = model
        pv = {v.name: v.start for v in model.parameters}
        pv.update(parameter_values or {})
        missing = [k for k, v in pv.items() if v is None]
        if missing:
            raise ValueError(f"{model.name}: no value for parameter(s) {', '.join(missing)}")
        psub = {v.symbol: sp.Float(pv[v.name]) for v in model.parameters}
        xs = [v.symbol for v in model.states]
        us = [v.symbol for v in model.inputs]
        closed = model.program.inline(list(model.derivatives) + list(model.output_exprs))
        env = {}
        for st in model.program.steps:
            env[st.symbol] = st.expr.xreplace(env)
        jac_exprs = []
        if model.jacobian is not None:
            jenv = dict(env)
            for st in model.jacobian.steps:
                jenv[st.symbol] = st.expr.xreplace(jenv)
            jac_exprs = [model.dfdx.xreplace(jenv), model.dfdu.xreplace(jenv)]
        args = [TIME] + xs + us
        sub = lambda e: sp.sympify(e).xreplace(psub)  # noqa: E731
        nx, ny = model.nx, model.ny
        self._f = sp.lambdify(args, [sub(e) for e in closed[:nx]], "numpy")
        self._g = sp.lambdify(args, [sub(e) for e in closed[nx:]], "numpy")
        self._A = sp.lambdify(args, sub(jac_exprs[0]), "numpy") if jac_exprs else None
        self._B = sp.lambdify(args, sub(jac_exprs[1]), "numpy") if jac_exprs else None
        self.x0 = np.array([v.start or 0.0 for v in model.states], dtype=float)
        self.u0 = np.array([v.start or 0.0 for v in model.inputs], dtype=float)

    def _args(self, t, x, u):
        x = np.asarray(x, dtype=float).ravel()
        u = self.u0 if u is None else np.asarray(u, dtype=float).ravel()
        return (t, *x, *u)

    def f(self, t, x, u=None) -> np.ndarray:
        return np.array(self._f(*self._args(t, x, u)), dtype=float).reshape(self.model.nx)

    def g(self, t, x, u=None) -> np.ndarray:
        return np.array(self._g(*self._args(t, x, u)), dtype=float).reshape(self.model.ny)

    def dfdx(self, t, x, u=None) -> np.ndarray:
        return np.array(self._A(*self._args(t, x, u)), dtype=float).reshape(self.model.nx, self.model.nx)

    def dfdu(self, t, x, u=None) -> np.ndarray:
        return np.array(self._B(*self._args(t, x, u)), dtype=float).reshape(self.model.nx, self.model.nu)


def stable_step(eigenvalues, method: str = "rk4") -> float:
    """Largest step h with every h*lambda inside the method's stability region.

    Along each eigenvalue's ray h*lambda = r e^{i phi}, the boundary radius is
    found by bisection on |R(z)| = 1 (R the method's stability polynomial:
    1 + z for explicit Euler, 1 + z + z^2/2 + z^3/6 + z^4/24 for RK4); the
    region is star-shaped along the left-half-plane rays used here.
    """
    R = {"euler": lambda z: 1 + z,
         "rk4": lambda z: 1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24}[method]
    h = np.inf
    for lam in np.asarray(eigenvalues, dtype=complex):
        if lam == 0:
            continue
        d = lam / abs(lam)
        lo, hi = 0.0, 1.0
        while abs(R(hi * d)) <= 1:
            hi *= 2
        # first crossing: scan then bisect (the region is not convex for RK4)
        grid = np.linspace(0, hi, 4001)[1:]
        k = np.argmax(np.abs(R(grid * d)) > 1 + 1e-15)
        lo, hi = (grid[k - 1] if k > 0 else 0.0), grid[k]
        for _ in range(200):
            mid = (lo + hi) / 2
            lo, hi = (mid, hi) if abs(R(mid * d)) <= 1 else (lo, mid)
        h = min(h, lo / abs(lam))
    return h


def linearise(model: SymbolicModel, x=None, u=None, t: float = 0.0,
              parameter_values: Optional[Mapping[str, float]] = None) -> np.ndarray:
    """dfdx of the model (exact, from its Jacobian program) at (t, x, u)."""
    ev = NumericModel(model, parameter_values)
    return ev.dfdx(t, ev.x0 if x is None else x, u)
