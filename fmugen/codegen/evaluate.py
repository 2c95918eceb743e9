"""Numeric evaluation of any SymbolicModel, and its linearisation for python-control.

:class:`ModelEvaluator` compiles the model's programs (the same straight-line
programs the C generator prints, linear solves included) into Python
functions: f(t, x, u), g(t, x, u) and the exact Jacobians A = df/dx,
B = df/du, C = dg/dx, D = dg/du.  It works for the arm (mass-matrix solve)
as for the small actuator components, without ever expanding closed forms.

:func:`fmugen.control.linearize` (re-exported here as ``linearize``) turns
the Jacobians into a ``control.StateSpace``.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Mapping, Optional

import numpy as np
import sympy as sp

from .model import SymbolicModel
from .program import Program
from .python_code import compile_program

TIME = sp.Symbol("t", real=True)


class ModelEvaluator:
    """f, g and the exact Jacobians of a SymbolicModel as numpy functions.

    Parameters take their start values, overridden by ``parameter_values``
    (a mapping of FMI parameter names to numbers).
    """

    def __init__(self, model: SymbolicModel, parameter_values: Optional[Mapping[str, float]] = None):
        self.model = model
        # a hybrid model is evaluated in one mode: its discrete states are parameters here, at their start
        # values unless ``parameter_values`` names them (``self.mode``: the values used)
        discrete = tuple(model.events.discrete) if model.events is not None else ()
        if discrete:
            model = replace(model, parameters=tuple(model.parameters) + discrete)
        self.mode = {v.name: v.start for v in discrete}
        values = {v.name: v.start for v in model.parameters}
        unknown = set(parameter_values or {}) - set(values)
        if unknown:
            raise KeyError(f"{model.name}: unknown parameter(s) {sorted(unknown)}")
        values.update(parameter_values or {})
        missing = [k for k, v in values.items() if v is None]
        if missing:
            raise ValueError(f"{model.name}: no value for parameter(s) {', '.join(missing)}")
        self.p = np.array([values[v.name] for v in model.parameters], dtype=float)
        self.mode = {k: values[k] for k in self.mode}
        xs = [v.symbol for v in model.states]
        us = [v.symbol for v in model.inputs]
        ps = [v.symbol for v in model.parameters]
        args = [[TIME], xs, us, ps]
        self._fg = compile_program(model.program, args,
                                   [sp.Matrix(list(model.derivatives) or [0]),
                                    sp.Matrix(list(model.output_exprs) or [0])], "f_and_g")
        self._jac = None
        if model.jacobian is not None:
            both = Program(model.program.prefix)
            both.steps = list(model.program.steps) + list(model.jacobian.steps)
            mats = [m if m is not None and m.shape[0] * m.shape[1] else sp.zeros(1, 1)
                    for m in (model.dfdx, model.dfdu, model.dgdx, model.dgdu)]
            self._jac = compile_program(both, args, mats, "jacobians")
        self.x0 = np.array([0.0 if v.start is None else v.start for v in model.states], dtype=float)
        self.u0 = np.array([0.0 if v.start is None else v.start for v in model.inputs], dtype=float)
        self._events = None
        if self.model.events is not None:
            self._compile_events(model, args)

    # -- hybrid models: the discrete states are the last entries of p --------------------------------
    def _compile_events(self, model, args) -> None:
        ev = self.model.events
        nd = len(ev.discrete)
        self._d0 = len(self.p) - nd
        d_index = {v.symbol: k for k, v in enumerate(ev.discrete)}
        x_index = {v.symbol: j for j, v in enumerate(model.states)}
        targets, clause_of, guards, values = [], [], [], []
        for k, c in enumerate(ev.clauses):
            guards.append(sp.Piecewise((sp.Float(1.0), c.guard), (sp.Float(0.0), True)))
            for t, e in c.assign:
                targets.append(("d", d_index[t]) if t in d_index else ("x", x_index[t]))
                clause_of.append(k)
                values.append(sp.sympify(e))
        z = [sp.sympify(e) for _, e in ev.indicators]
        self._z = compile_program(model.program, args, [sp.Matrix(z or [0])], "indicators")
        self._upd = compile_program(model.program, args, [sp.Matrix(guards or [0]), sp.Matrix(values or [0])],
                                    "update")
        self._events = (targets, clause_of, len(z))
        self.indicator_names = tuple(n for n, _ in ev.indicators)
        self._ticks = [d_index[c.tick.symbol] for c in ev.clocks]
        self._clock_fn = None
        if ev.clocks:
            self._clock_fn = compile_program(model.program, args,
                                             [sp.Matrix([sp.sympify(c.period) for c in ev.clocks]),
                                              sp.Matrix([sp.sympify(c.offset) for c in ev.clocks])], "clocks")

    def clocks(self) -> tuple:
        """(periods, offsets) of the sample clocks (empty arrays without)."""
        if self._events is None or self._clock_fn is None:
            return np.zeros(0), np.zeros(0)
        P, O = self._clock_fn(*self._args(0.0, None, None))
        return P[:, 0], O[:, 0]

    def next_tick(self, t) -> tuple:
        """(the first tick strictly after t, the clocks ticking at t): c_runtime/events.c's rule."""
        P, O = self.clocks()
        nxt, at = np.inf, []
        for k, (p_, o) in enumerate(zip(P, O)):
            if not (p_ > 0 and np.isfinite(p_)):
                raise ValueError(f"{self.model.name}: clock {k + 1}'s period {p_} is not positive")
            tol = max(1e-9 * p_, 8 * np.finfo(float).eps * abs(t))
            j = np.floor((t - o) / p_ + 0.5)
            if t < o - tol:
                nk = o
            elif abs(o + j * p_ - t) <= tol:
                at.append(k)
                nk = o + (j + 1) * p_
            else:
                nk = o + np.ceil((t - o) / p_) * p_
            nxt = min(nxt, nk)
        return nxt, at

    def tick_iteration(self, t, x, u=None, clocks=()) -> np.ndarray:
        """The event iteration at a sample instant of ``clocks``: their tick flags set for its first round."""
        for k in clocks:
            self.p[self._d0 + self._ticks[k]] = 1.0
        x, _ = self.event_round(t, x, u)
        for k in clocks:
            self.p[self._d0 + self._ticks[k]] = 0.0
        return self.event_iteration(t, x, u)

    @property
    def discrete(self) -> np.ndarray:
        """The discrete states' current values (a copy)."""
        return self.p[self._d0:].copy() if self._events is not None else np.zeros(0)

    @discrete.setter
    def discrete(self, values) -> None:
        self.p[self._d0:] = np.asarray(values, dtype=float)

    def indicators(self, t, x=None, u=None) -> np.ndarray:
        """The event indicators z(t, x, u) in the current mode."""
        if self._events is None or not self._events[2]:
            return np.zeros(0)
        return self._z(*self._args(t, x, u))[0][: self._events[2], 0]

    def event_round(self, t, x, u=None) -> tuple:
        """One round of the clauses at (t, x, u) (c_runtime/events.c's rule): every guard and value from the
        values now, then the firing assignments in order.  Returns (x after, changed); the discrete states
        change in place."""
        x = np.array(x, dtype=float)
        if self._events is None:
            return x, False
        targets, clause_of, _ = self._events
        g, vals = self._upd(*self._args(t, x, u))
        g, vals = g[:, 0], vals[:, 0]
        changed = False
        for a, (kind, i) in enumerate(targets):
            if g[clause_of[a]] == 0.0:
                continue
            if not np.isfinite(vals[a]):
                raise ValueError(f"{self.model.name}: an event assignment is not finite at t = {t}")
            arr, off = (x, 0) if kind == "x" else (self.p, self._d0)
            if arr[off + i] != vals[a]:
                arr[off + i] = vals[a]
                changed = True
        return x, changed

    def event_iteration(self, t, x, u=None, max_rounds: int = 100) -> np.ndarray:
        """Rounds of :meth:`event_round` until nothing changes; the state after."""
        for _ in range(max_rounds):
            x, changed = self.event_round(t, x, u)
            if not changed:
                return x
        raise ValueError(f"{self.model.name}: the event iteration at t = {t} does not converge after "
                         f"{max_rounds} rounds")

    def _args(self, t, x, u):
        x = self.x0 if x is None else np.asarray(x, dtype=float).ravel()
        u = self.u0 if u is None else np.asarray(u, dtype=float).ravel()
        return [t], x, u, self.p

    def f(self, t, x=None, u=None) -> np.ndarray:
        return self._fg(*self._args(t, x, u))[0][: self.model.nx, 0]

    def g(self, t, x=None, u=None) -> np.ndarray:
        return self._fg(*self._args(t, x, u))[1][: self.model.ny, 0]

    def jacobians(self, t, x=None, u=None) -> tuple:
        """(A, B, C, D) at (t, x, u), exact (from the model's Jacobian program)."""
        if self._jac is None:
            raise ValueError(f"{self.model.name} has no Jacobian program")
        m = self.model
        shapes = ((m.nx, m.nx), (m.nx, m.nu), (m.ny, m.nx), (m.ny, m.nu))
        # empty blocks were compiled as a 1x1 placeholder
        return tuple(M[: r, : c] if r and c else np.zeros((r, c))
                     for M, (r, c) in zip(self._jac(*self._args(t, x, u)), shapes))
