"""Linearisation of any SymbolicModel (arm, component, assembly, scene) for python-control.

At an operating point (t, x0, u0) the model x' = f(x, u), y = g(x, u) is
replaced by

    dx' = A dx + B du,   dy = C dx + D du,
    A = df/dx [1/s-scaled units of x per x],  B = df/du,  C = dg/dx,  D = dg/du,

from the model's exact Jacobian program (the same one the generated C and
the FMU's fmi2GetDirectionalDerivative evaluate) -- no finite differences,
so the matrices are right at any non-zero pose.  Signal names follow the
rule of :mod:`fmugen.control.names` (FMI names, '.' written '_').

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

from dataclasses import dataclass, field
from typing import Mapping, Optional, Sequence, Union

import numpy as np

from ..codegen.evaluate import ModelEvaluator
from .names import FmugenError, check_signal_names, lookup, signal_name, signals


def as_model(source):
    """The SymbolicModel of ``source``: a SymbolicModel, or a scene (anything
    with ``monolithic_model()``)."""
    if hasattr(source, "monolithic_model"):
        return source.monolithic_model()
    if not hasattr(source, "states") or not hasattr(source, "program"):
        raise FmugenError(f"expected a SymbolicModel or a scene (an object with monolithic_model()), "
                          f"got {type(source).__name__}")
    return source


def select(model, names: Union[str, Sequence[str], None], kinds: Sequence[str], default: list) -> list:
    """Signals named by ``names`` (None: ``default``), in the order given."""
    if names is None:
        return default
    if isinstance(names, str):
        names = [n for n in names.split(",") if n]
    out = []
    for n in names:
        for s in lookup(model, n, kinds):
            if s not in out:
                out.append(s)
    return out


def linearize(model, x=None, u=None, t: float = 0.0,
              parameter_values: Optional[Mapping[str, float]] = None,
              outputs: Union[str, Sequence[str]] = "all", inputs: Optional[Sequence[str]] = None):
    """``control.StateSpace`` of ``model`` linearised at (t, x, u).

    model: a SymbolicModel or a scene (``monolithic_model()`` is used).
    x: state vector [state units], or an operating point from
       :func:`fmugen.trim` (then u, t and its parameter values are taken
       from it unless given).  x and u default to the start values.
    outputs: "all" -- the states exposed as outputs (q, qd of an arm)
       followed by the computed outputs; "computed" -- only the latter; or a
       list of names (states or computed outputs; base names such as ``q``
       expand to ``q[1]`` ... ``q[n]``).
    inputs: None (all) or a list of input names: the columns of B and D.
    """
    import control

    lm = linear_model(model, x, u, t, parameter_values, outputs, inputs)
    return control.ss(lm.A, lm.B, lm.C, lm.D, states=[signal_name(n) for n in lm.states],
                      inputs=[signal_name(n) for n in lm.inputs], outputs=[signal_name(n) for n in lm.outputs],
                      name=signal_name(lm.name))


@dataclass
class LinearModel:
    """(A, B, C, D) with FMI names, and the point (t, x0, u0, y0) they were taken at."""

    name: str
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    states: list
    inputs: list
    outputs: list
    t: float
    x0: np.ndarray
    u0: np.ndarray  # every input of the model, not only the selected columns
    y0: np.ndarray  # the selected outputs
    all_inputs: list
    # a hybrid model is linearised in one mode: its discrete states' values (name -> value), {} if smooth;
    # choose another with parameter_values={"mode": 1, ...}
    mode: dict = field(default_factory=dict)


def linear_model(model, x=None, u=None, t: float = 0.0, parameter_values=None, outputs="all",
                 inputs=None) -> LinearModel:
    """What :func:`linearize` returns, as plain arrays with FMI names (for files and other tools)."""
    model = as_model(model)
    if hasattr(x, "x") and hasattr(x, "u"):  # an OperatingPoint
        op = x
        x, u = op.x, (op.u if u is None else u)
        t = op.t if t == 0.0 else t
        if parameter_values is None:
            parameter_values = op.parameter_values
    check_signal_names(model)
    for what, v, n in (("x", x, model.nx), ("u", u, model.nu)):
        if v is not None and np.size(v) != n:
            raise FmugenError(f"{model.name}: {what} has {np.size(v)} values, the model has {n} "
                              f"{'states' if what == 'x' else 'inputs'}")
    ev = ModelEvaluator(model, parameter_values)
    A, B, C, D = ev.jacobians(t, x, u)
    if isinstance(outputs, str) and outputs in ("all", "computed"):
        chosen = signals(model, "output")
        if outputs == "all":
            chosen = [s for s in signals(model, "state") if model.states[s.index].output] + chosen
    else:
        chosen = select(model, outputs, ("state", "output"), [])
    cols = [s.index for s in select(model, inputs, ("input",), signals(model, "input"))]
    eye = np.eye(model.nx)
    C_rows = [eye[s.index] if s.kind == "state" else C[s.index] for s in chosen]
    D_rows = [np.zeros(model.nu) if s.kind == "state" else D[s.index] for s in chosen]
    C = np.array(C_rows).reshape(len(chosen), model.nx)
    D = np.array(D_rows).reshape(len(chosen), model.nu)[:, cols]
    B = B[:, cols]
    x0 = ev.x0 if x is None else np.asarray(x, dtype=float).ravel()
    u0 = ev.u0 if u is None else np.asarray(u, dtype=float).ravel()
    g = ev.g(t, x0, u0)
    y0 = np.array([x0[s.index] if s.kind == "state" else g[s.index] for s in chosen])
    return LinearModel(model.name, A, B, C, D, [v.name for v in model.states],
                       [model.inputs[i].name for i in cols], [s.name for s in chosen], t, x0, u0, y0,
                       [v.name for v in model.inputs], dict(ev.mode))
