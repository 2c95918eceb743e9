"""Sampled-data control: the plant discretised, discrete controllers written as component files.

* :func:`c2d` -- a :class:`~fmugen.control.linearize.LinearModel` (or ``control.StateSpace``) held by a
  zero-order hold and sampled every T: ``x[k+1] = Ad x[k] + Bd u[k]``, ``y[k] = C x[k] + D u[k]``,
  ``Ad = exp(A T)``, ``Bd = int_0^T exp(A s) ds B`` (the matrix exponential of the augmented
  ``[[A, B], [0, 0]] T``: exact for a held input); what ``fmugen linearize --dt T`` writes;
* :func:`discrete_controller_file` -- any python-control system with a sample time (``StateSpace`` or
  ``TransferFunction`` with ``dt = T``: a ``control.c2d`` compensator, a discrete design) written as a
  component file that runs it at a sample clock (README "Sample clocks") -- its matrices are the
  file's parameters (``A_i_j``, ``B_i_j``, ``C_i_j``, ``D_i_j``, tunable by ``--set``), its state the
  discrete states ``x_1 ...``, its outputs held between samples::

      x[k+1] = A x[k] + B u[k],   y[k] = C x[k] + D u[k]      (u sampled at t_k, y held from t_k)

* a sampled state feedback ``u[k] = u_ff - K (x[k] - x_ref)`` (K from ``control.dlqr``):
  :func:`fmugen.control.state_feedback_file` with ``sample_period=T``.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from ..errors import FmugenError
from .feedback import _ratio_unit, variable_name


def zoh(A, B, T: float) -> tuple:
    """(Ad, Bd) of x' = A x + B u with u held over [kT, (k+1)T) (scipy's matrix exponential)."""
    from scipy.linalg import expm

    A, B = np.atleast_2d(np.asarray(A, float)), np.asarray(B, float).reshape(len(A), -1)
    if not (np.isfinite(T) and T > 0):
        raise FmugenError(f"sample period {T!r}: must be a positive number of seconds")
    n, m = A.shape[0], B.shape[1]
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = A * T, B * T
    E = expm(M)
    return E[:n, :n], E[:n, n:]


def c2d(lm, T: float):
    """The zero-order-hold discretisation of ``lm`` at period ``T``.

    ``lm``: a :class:`~fmugen.control.linearize.LinearModel` (returned as a copy with ``A``, ``B`` the
    discrete ones and ``dt = T``; ``C``, ``D`` unchanged) or a ``control.StateSpace`` (returned as
    ``control.c2d(lm, T, "zoh")``).
    """
    if hasattr(lm, "dt") and hasattr(lm, "A") and not hasattr(lm, "all_inputs"):
        import control

        return control.c2d(lm, T, "zoh")
    from dataclasses import replace

    Ad, Bd = zoh(lm.A, lm.B, float(T))
    out = replace(lm, A=Ad, B=Bd)
    out.dt = float(T)
    return out


def _names(given, n, what) -> list:
    if given is None:
        return [(f"{what}_{k + 1}", "1") for k in range(n)]
    out = []
    for g in given:
        name, unit = (g, "1") if isinstance(g, str) else tuple(g)
        out.append((name, unit or "1"))
    if len(out) != n:
        raise FmugenError(f"discrete controller: {len(out)} {what} names for a system with {n} {what}s")
    return out


def discrete_controller_file(path, sys, inputs: Optional[Sequence] = None, outputs: Optional[Sequence] = None,
                             name: str = "discrete_controller", description: str = "",
                             state_unit: str = "1", sample_period: Optional[float] = None) -> Path:
    """Write the discrete system ``sys`` as a component file run at its sample time; returns the path.

    ``sys``: ``control.StateSpace`` / ``control.TransferFunction`` with ``dt`` a period in s (or
    ``sample_period`` given), or a tuple ``(A, B, C, D)`` with ``sample_period``.  ``inputs``,
    ``outputs``: names (``"e"``) or ``(name, unit)`` pairs, FMI names of a plant allowed (``joint.theta``
    becomes ``joint_theta``); the matrices' units follow (``B_i_j`` [state unit / input unit], ...),
    dimension-checked on reading.  The states ``x_1 ...`` are in ``state_unit``.
    """
    if isinstance(sys, tuple):
        A, B, C, D = (np.atleast_2d(np.asarray(m, float)) for m in sys)
        dt = sample_period
    else:
        import control

        if isinstance(sys, control.TransferFunction):
            sys = control.ss(sys)
        if not isinstance(sys, control.StateSpace):
            raise FmugenError(f"discrete controller: expected a control.StateSpace, TransferFunction or (A, B, C, D), "
                              f"got {type(sys).__name__}")
        A, B, C, D = (np.atleast_2d(np.asarray(m, float)) for m in (sys.A, sys.B, sys.C, sys.D))
        dt = sys.dt if sample_period is None else sample_period
    if dt is None or dt is True or isinstance(dt, bool) or not np.isfinite(float(dt)) or float(dt) <= 0:
        raise FmugenError(f"discrete controller: the system has no sample period (dt = {dt!r}): discretise it "
                          f"(control.c2d(sys, T)) or give sample_period")
    T = float(dt)
    nx, nu, ny = A.shape[0], B.shape[1] if B.size else D.shape[1], C.shape[0] if C.size else D.shape[0]
    A, B, C, D = A.reshape(nx, nx), B.reshape(nx, nu), C.reshape(ny, nx), D.reshape(ny, nu)
    for m, what in ((A, "A"), (B, "B"), (C, "C"), (D, "D")):
        if not np.all(np.isfinite(m)):
            raise FmugenError(f"discrete controller: {what} has non-finite entries")
    ins = [(variable_name(n), u) for n, u in _names(inputs, nu, "u")]
    outs = [(variable_name(n), u) for n, u in _names(outputs, ny, "y")]
    xs = [f"x_{i + 1}" for i in range(nx)]
    taken = [n for n, _ in ins + outs] + xs + [f"{n}_k" for n, _ in outs]
    if len(set(taken)) != len(taken):
        raise FmugenError("discrete controller: two names coincide (inputs, outputs, x_i, <output>_k); rename them")

    params, lines = [], []

    def term(mat, i, j, sym, un_num, un_den, var):
        if mat[i, j] == 0.0:
            return None
        pname = f"{sym}_{i + 1}_{j + 1}"
        params.append(f'{pname} = {{ value = {float(mat[i, j])!r}, unit = "{_ratio_unit(un_num, un_den)}" }}')
        return f"{pname}*{var}"

    sets = {}
    for i in range(nx):
        ts = [term(A, i, j, "A", state_unit, state_unit, xs[j]) for j in range(nx)] + \
             [term(B, i, j, "B", state_unit, ins[j][1], ins[j][0]) for j in range(nu)]
        sets[xs[i]] = " + ".join(t for t in ts if t) or "0"
    for i, (o, ou) in enumerate(outs):
        ts = [term(C, i, j, "C", ou, state_unit, xs[j]) for j in range(nx)] + \
             [term(D, i, j, "D", ou, ins[j][1], ins[j][0]) for j in range(nu)]
        sets[f"{o}_k"] = " + ".join(t for t in ts if t) or "0"
    lines += ["# Discrete controller x[k+1] = A x[k] + B u[k], y[k] = C x[k] + D u[k], run every T_s (inputs sampled",
              "# at t_k, outputs held from t_k), written by fmugen.control.discrete_controller_file.",
              "[component]", f"name = {json.dumps(name)}",
              f"description = {json.dumps(description or f'discrete controller ({nx} states) at T_s = {T:g} s')}",
              "equations = [" + ", ".join(f'"{o} = {o}_k"' for o, _ in outs) + "]", "",
              "[parameters]", f'T_s = {{ value = {T!r}, unit = "s", min = 1e-12, description = "sample period" }}']
    lines += params
    lines += ["", "[inputs]"] + [f'{n} = {{ unit = "{u}", start = 0.0 }}' for n, u in ins]
    lines += ["", "[discrete]"] + [f'{x} = {{ start = 0.0, unit = "{state_unit}", output = false }}' for x in xs]
    lines += [f'{o}_k = {{ start = 0.0, unit = "{u}", description = "held output" }}' for o, u in outs]
    lines += ["", "[outputs]"] + [f'{o} = {{ unit = "{u}", description = "held between samples" }}' for o, u in outs]
    lines += ["", "[clocks.sample]", 'period = "T_s"', "", "[[when]]", 'name = "sample"', 'clock = "sample"',
              "set = { " + ", ".join(f'{k} = "{v}"' for k, v in sets.items()) + " }"]
    p = Path(path)
    p.write_text("\n".join(lines) + "\n")
    from ..components.equations import read_component_file

    read_component_file(p)  # what was written reads back, dimensions checked
    return p
