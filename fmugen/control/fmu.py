"""Linearise a built Model-Exchange FMU through ``fmi2GetDirectionalDerivative``.

What a user of another FMI tool sees: the FMU is instantiated with fmpy's
``FMU2Model``, initialised (parameters set in initialisation mode), put in
continuous-time mode at the operating point (``fmi2SetContinuousStates``,
``fmi2SetReal`` on the inputs), and asked for one directional derivative per
state and per input (seed e_j):

    column j of [A B; C D] = d[der(x); y] / d[x; u] e_j.

States are ordered as the FMU's ``<Derivatives>`` (the FMI order of the
continuous-state vector), inputs and outputs as in modelDescription.xml;
signal names follow :mod:`fmugen.control.names`.
"""
from __future__ import annotations

import shutil
import tempfile
from typing import Mapping, Optional

import numpy as np

from .names import FmugenError, signal_name



def _first_per_vr(variables) -> list:
    """``variables`` without FMI aliases: the first of each value reference."""
    seen, out = set(), []
    for v in variables:
        if v.valueReference not in seen:
            seen.add(v.valueReference)
            out.append(v)
    return out

def _values(spec, names, what, fmu):
    """A vector in ``names`` order from an array, a mapping by name, or None (start values)."""
    if spec is None:
        return None
    if isinstance(spec, Mapping):
        unknown = sorted(set(spec) - set(names))
        if unknown:
            raise FmugenError(f"{fmu}: no {what} named {', '.join(unknown)} (has {', '.join(names)})")
        return spec
    v = np.asarray(spec, dtype=float).ravel()
    if v.size != len(names):
        raise FmugenError(f"{fmu}: {len(names)} {what}s ({', '.join(names)}) but {v.size} values given")
    return dict(zip(names, v))


def linearize_fmu(path, x=None, u=None, t: float = 0.0,
                  parameter_values: Optional[Mapping[str, float]] = None, outputs: str = "all"):
    """``control.StateSpace`` of the ME FMU at ``path`` linearised at (t, x, u).

    x, u: arrays in the FMU's order, mappings {FMI name: value}, or x an
    OperatingPoint from :func:`fmugen.trim` (matched by name; its u and
    parameter values are used unless given).  Unset values keep the FMU's
    start values.  outputs: "all" (every output of modelDescription.xml) or
    "computed" (outputs that are not states).
    """
    import control
    from fmpy import extract, read_model_description

    if hasattr(x, "x") and hasattr(x, "u") and hasattr(x, "states"):  # an OperatingPoint
        op = x
        x = dict(zip(op.states, op.x))
        u = dict(zip(op.inputs, op.u)) if u is None else u
        parameter_values = op.parameter_values if parameter_values is None else parameter_values
    md = read_model_description(str(path))
    if md.modelExchange is None:
        raise FmugenError(f"{path}: not a Model-Exchange FMU (build it with fmi_type='me' or 'both')")
    if not md.modelExchange.providesDirectionalDerivative:
        raise FmugenError(f"{path}: the FMU does not provide directional derivatives")
    by_name = {v.name: v for v in md.modelVariables}
    der_vars = [d.variable for d in md.derivatives]
    state_vars = [d.derivative for d in der_vars]
    # one column per value: an FMI alias (a URDF joint's "<joint>.tau" for tau[i]) shares its value
    # reference with the variable it names again and comes after it; keep the first name
    fmi3 = str(md.fmiVersion).startswith("3")
    real = "Float64" if fmi3 else "Real"  # FMI 3.0's name of the FMI 2.0 Real
    input_vars = _first_per_vr(v for v in md.modelVariables if v.causality == "input" and v.type == real)
    state_vrs = {v.valueReference for v in state_vars}
    out_vars = _first_per_vr(o.variable for o in md.outputs)
    if outputs == "computed":
        out_vars = [v for v in out_vars if v.valueReference not in state_vrs]
    elif outputs != "all":
        raise FmugenError(f"outputs must be 'all' or 'computed', not {outputs!r}")
    xs = _values(x, [v.name for v in state_vars], "state", path) or {}
    us = _values(u, [v.name for v in input_vars], "input", path) or {}
    for name in parameter_values or {}:
        if name not in by_name or by_name[name].causality != "parameter":
            raise FmugenError(f"{path}: no parameter named {name!r}")

    nx, nu = len(state_vars), len(input_vars)
    unzip = extract(str(path), tempfile.mkdtemp(prefix="fmugen_lin_"))
    if fmi3:
        from fmpy.fmi3 import FMU3Model as Model
    else:
        from fmpy.fmi2 import FMU2Model as Model
    fmu = Model(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.modelExchange.modelIdentifier,
                instanceName="linearize")
    set_real = fmu.setFloat64 if fmi3 else fmu.setReal
    get_real = fmu.getFloat64 if fmi3 else fmu.getReal
    try:
        fmu.instantiate()
        if fmi3:
            fmu.enterInitializationMode(startTime=t)
        else:
            fmu.setupExperiment(startTime=t)
            fmu.enterInitializationMode()
        if parameter_values:
            set_real([by_name[n].valueReference for n in parameter_values],
                     [float(v) for v in parameter_values.values()])
        fmu.exitInitializationMode()
        if fmi3:  # FMI 3.0 Model Exchange leaves initialisation in Event Mode
            fmu.updateDiscreteStates()
        fmu.enterContinuousTimeMode()
        fmu.setTime(t)
        x0 = np.array(get_real([v.valueReference for v in state_vars]), dtype=float)
        for i, v in enumerate(state_vars):
            x0[i] = xs.get(v.name, x0[i])
        if nx:
            from ctypes import c_double

            fmu.setContinuousStates((c_double * nx)(*x0), nx)
        if us:
            set_real([by_name[n].valueReference for n in us], [float(v) for v in us.values()])
        unknowns = [v.valueReference for v in der_vars + out_vars]
        knowns = [v.valueReference for v in state_vars + input_vars]
        J = np.zeros((len(unknowns), nx + nu))
        for j in range(nx + nu):
            J[:, j] = fmu.getDirectionalDerivative(unknowns, [knowns[j]], [1.0])
    finally:
        try:
            fmu.terminate()
        finally:
            fmu.freeInstance()
            shutil.rmtree(unzip, ignore_errors=True)
    A, B = J[:nx, :nx], J[:nx, nx:]
    C, D = J[nx:, :nx], J[nx:, nx:]
    return control.ss(A, B, C, D, states=[signal_name(v.name) for v in state_vars],
                      inputs=[signal_name(v.name) for v in input_vars],
                      outputs=[signal_name(v.name) for v in out_vars], name=signal_name(md.modelName))
