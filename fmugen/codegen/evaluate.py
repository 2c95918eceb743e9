"""Numeric evaluation of any SymbolicModel, and its linearisation for python-control.

:class:`ModelEvaluator` compiles the model's programs (the same straight-line
programs the C generator prints, linear solves included) into Python
functions: f(t, x, u), g(t, x, u) and the exact Jacobians A = df/dx,
B = df/du, C = dg/dx, D = dg/du.  It works for the arm (mass-matrix solve)
as for the small actuator components, without ever expanding closed forms.

:func:`linearize` returns the model linearised at an operating point as a
``control.StateSpace`` with named states, inputs and outputs (FMI names,
with '.' replaced by '_', which python-control reserves):

    dx = A dx + B du,   dy = C dx + D du

>>> import sympy as sp
>>> from fmugen.codegen.model import SymbolicModel, Variable
>>> x, u, k = sp.symbols("x u k", real=True)
>>> m = SymbolicModel.from_equations("lag", [Variable("x", x, start=0.0)], [Variable("u", u, start=0.0)],
...                                  [Variable("k", k, start=2.0)], [-k * x + u],
...                                  [Variable("y", sp.Symbol("y", real=True))], [x])
>>> sys = linearize(m)
>>> sys.A.tolist(), sys.B.tolist(), sys.C.tolist(), sys.D.tolist()
([[-2.0]], [[1.0]], [[1.0]], [[0.0]])
"""
from __future__ import annotations

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
        values = {v.name: v.start for v in model.parameters}
        unknown = set(parameter_values or {}) - set(values)
        if unknown:
            raise KeyError(f"{model.name}: unknown parameter(s) {sorted(unknown)}")
        values.update(parameter_values or {})
        missing = [k for k, v in values.items() if v is None]
        if missing:
            raise ValueError(f"{model.name}: no value for parameter(s) {', '.join(missing)}")
        self.p = np.array([values[v.name] for v in model.parameters], dtype=float)
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


def linearize(model: SymbolicModel, x=None, u=None, t: float = 0.0,
              parameter_values: Optional[Mapping[str, float]] = None, outputs: str = "all"):
    """``control.StateSpace`` of ``model`` linearised at (t, x, u).

    ``outputs="all"`` gives the state-outputs (q, qd of an arm) followed by
    the computed outputs; ``"computed"`` only the latter.  x and u default to
    the start values.
    """
    import control

    ev = ModelEvaluator(model, parameter_values)
    A, B, C, D = ev.jacobians(t, x, u)
    names_y = [v.name for v in model.outputs]
    if outputs == "all":
        sel = [i for i, v in enumerate(model.states) if v.output]
        C = np.vstack([np.eye(model.nx)[sel], C])
        D = np.vstack([np.zeros((len(sel), model.nu)), D])
        names_y = [model.states[i].name for i in sel] + names_y
    elif outputs != "computed":
        raise ValueError(f"outputs must be 'all' or 'computed', not {outputs!r}")
    # python-control reserves '.' in signal names (subsystem paths): valve.x_v -> valve_x_v
    def sig(name):
        return name.replace(".", "_")

    return control.ss(A, B, C, D, states=[sig(v.name) for v in model.states],
                      inputs=[sig(v.name) for v in model.inputs], outputs=[sig(n) for n in names_y],
                      name=sig(model.name))
