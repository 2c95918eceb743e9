"""Small helpers shared by the component factories.

A component is a factory function returning a
:class:`fmugen.codegen.model.SymbolicModel`.  The helpers here give every
variable a real sympy symbol named like the variable, take parameter values
from a parameter set (:mod:`fmugen.components.parameters`), and hold the model
time symbol.

Time
----
Sources (trajectories) are explicit functions of time.  They use
:data:`TIME` = ``sympy.Symbol("t", real=True)``, which is the name of the
``double t`` argument of the generated ``evaluate``/``jacobian`` functions
(c_runtime/fmugen_model.h), so the code generator prints it as ``t`` with no
mapping.  Assembly never renames it.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Mapping, Optional, Sequence

import sympy as sp

from ..codegen.model import POSITIVE_MIN, Variable
from ..errors import FmugenError
from .parameters import SIGNS, ParameterSet, load_parameter_set, value_problem

#: the model time, the ``t`` argument of the generated C functions
TIME = sp.Symbol("t", real=True)


def var(name: str, unit: str = "", description: str = "", start: Optional[float] = None,
        output: bool = False, nominal: Optional[float] = None, symbol: Optional[str] = None,
        min: Optional[float] = None, max: Optional[float] = None) -> Variable:
    """A Variable whose sympy symbol is the (C-safe) name itself.

    ``min``/``max``: the validity range of the equations (the FMU reports a
    value outside it after a Co-Simulation step; modelDescription.xml carries
    it as the variable's min/max)."""
    return Variable(name=name, symbol=sp.Symbol(symbol or name, real=True), unit=unit,
                    description=description, start=start, output=output, nominal=nominal, min=min, max=max)


def parameters(family: str, specs: Sequence[tuple], used: Sequence[str], parameter_set="default",
               overrides: Optional[Mapping[str, float]] = None) -> dict:
    """Parameter Variables of one component family, values from a set.

    ``specs`` is the family's full list of ``(name, unit, description)``;
    ``used`` names those the chosen fidelity needs (the others are left out of
    the model).  Values come from section ``[family]`` of the parameter set
    (a set name such as ``"default"``, a path to a TOML file, or a loaded
    :class:`ParameterSet`), then ``overrides``.  Keys that the family does not
    know are errors naming the file and section.  Returns ``{name: Variable}``
    in ``specs`` order.
    """
    pset = parameter_set if isinstance(parameter_set, ParameterSet) else load_parameter_set(parameter_set)
    overrides = dict(overrides or {})
    known = {s[0] for s in specs}
    unknown = sorted(set(overrides) - known)
    if unknown:
        raise FmugenError(f"{family}: unknown parameter override(s) {', '.join(unknown)}; "
                          f"known: {', '.join(sorted(known))}")
    for key, val in overrides.items():
        problem = value_problem(family, key, val)
        if problem:
            raise FmugenError(f"{family}: parameter override {key} = {val!r} {problem}")
    pset.check_section(family, known)
    out = {}
    for name, unit, description in specs:
        if name not in used:
            continue
        value = overrides[name] if name in overrides else pset.value(family, name)
        # the sign the equations need is also the parameter's min in the FMU: its
        # fmi2SetReal refuses what a parameter file would have been refused for
        sign = SIGNS.get(family, {}).get(name, "")
        low = POSITIVE_MIN if sign == ">0" else 0.0 if sign == ">=0" else None
        out[name] = replace(var(name, unit, description, start=float(value), min=low), sign=sign)
    return out


def values(params: Mapping[str, Variable]) -> dict:
    """{name: start value} of a parameter dict (for numeric sizing in docstrings)."""
    return {k: v.start for k, v in params.items()}
