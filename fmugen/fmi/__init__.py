"""FMI 2.0 export: modelDescription.xml, units, and the FMU builder.

One call builds an FMU::

    from fmugen.fmi import build_fmu
    result = build_fmu(model, "Pendulum.fmu", fmi_type="both")

``variable_layout(model)`` gives every variable's value reference (the
layout of c_runtime/fmugen_model.h).
"""
from .build import BuildBudgetExceeded, BuildError, BuildInterrupted, BuildResult, build_fmu
from .model_description import VariableLayout, model_description_xml, variable_layout
from .units import UnitError, base_units

__all__ = ["build_fmu", "BuildError", "BuildResult", "model_description_xml", "variable_layout",
           "VariableLayout", "base_units", "UnitError"]
