"""``modelDescription.xml`` (FMI 3.0) of a :class:`SymbolicModel` -- opt-in
(``fmugen build --fmi-version 3``), beside the FMI 2.0 writer of
:mod:`fmugen.fmi.model_description`, whose variable list
(:func:`variable_layout`) and XML escaping it reuses.

Value references (FMI 3.0 has one space for all types;
``c_runtime/fmi3/fmi3_functions.c`` maps it onto the runtime's):

=========================  ==================================================
Float64                    the FMI 2.0 Real value references, unchanged
event indicators           Float64 locals right after them (``<EventIndicator>``
                           elements name variables in FMI 3.0)
Int32                      the runtime's FMI 2.0 Integers, after the indicators
=========================  ==================================================

A state's or an input's alias is an ``<Alias>`` child of the variable (FMI
3.0 sec. 2.4.7.5) instead of a second variable with its value reference.

Scalars only: arrays (a robot's joint vector as one ``<Float64>`` with a
``<Dimension>``) are not written yet.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Optional, Sequence

import sympy as sp

from ..codegen.model import SymbolicModel
from ..codegen.runtime_parameters import header_defines, runtime_starts
from ..errors import FmugenError
from .model_description import (GENERATION_TOOL, _XML_INVALID, _set, clock_annotations, unit_definitions,
                                variable_layout, xml_text)

FMI3_VERSION = "3.0"

#: the runtime's log categories (c_runtime/runtime_support.c), in its order, with FMI 3.0 status names
LOG_CATEGORIES3 = (
    ("logEvents", "mode changes and other events of the FMI state machine"),
    ("logStatusWarning", "messages of status fmi3Warning"),
    ("logStatusError", "messages of status fmi3Error, fmi3Discard and fmi3Fatal"),
    ("logAll", "all messages"),
)

_TYPES = {"Real": "Float64", "Integer": "Int32"}


def fmi3_value_references(model: SymbolicModel) -> dict:
    """FMI 3.0 value reference of every variable name (aliases under their own name too), and
    ``"<event indicator k>"`` keys for the indicators -- the layout of fmi3_functions.c."""
    layout = variable_layout(model)
    reals = [v for v in layout.variables if v.type == "Real"]
    z_base = max(v.value_reference for v in reals) + 1
    nz = len(model.events.indicators) if model.events is not None else 0
    int_base = z_base + nz
    out = {}
    for v in layout.variables:
        out[v.name] = v.value_reference if v.type == "Real" else int_base + v.value_reference
    for k in range(nz):
        out[f"<event indicator {k}>"] = z_base + k
    out["<time>"] = int_base + header_defines()["FMUGEN_INT_COUNT"]
    return out


def has_event_mode(model: SymbolicModel) -> bool:
    """``hasEventMode`` of the FMI 3.0 Co-Simulation interface: the model has events (event indicators,
    clauses or sample clocks -- ``fmugen_has_events`` of the runtime, which refuses ``eventModeUsed``
    otherwise)."""
    ev = model.events
    return ev is not None and bool(ev.indicators or ev.clauses or ev.clocks)


def model_description3_xml(
    model: SymbolicModel,
    instantiation_token: str,
    model_identifier: str,
    fmi_types: Sequence[str] = ("me", "cs"),
    default_experiment: Optional[dict] = None,
    runtime_start: Optional[dict] = None,
) -> str:
    """The text of an FMI 3.0 modelDescription.xml; the arguments as
    :func:`fmugen.fmi.model_description.model_description_xml` (the
    instantiation token is the GUID the C model is generated with)."""
    fmi_types = tuple(fmi_types)
    if not fmi_types or any(t not in ("me", "cs") for t in fmi_types):
        raise FmugenError(f"fmi_types must be a non-empty subset of ('me', 'cs'), got {fmi_types!r}")
    layout = variable_layout(model)
    for v in layout.variables:
        if _XML_INVALID.search(v.name):  # cleaning could make two names equal: refused, as for FMI 2.0
            raise FmugenError(f"model {xml_text(model.name)!r}: variable name {v.name!r} contains a character "
                              f"that XML 1.0 cannot carry")
    if runtime_start:
        rs = runtime_starts(runtime_start)
        for v in layout.variables:
            if v.kind == "runtime" and v.name in rs:
                v.start = rs[v.name]
    vrs = fmi3_value_references(model)
    has_jac = model.jacobian is not None
    indicators = list(model.events.indicators) if model.events is not None else []

    root = ET.Element("fmiModelDescription")
    _set(root, fmiVersion=FMI3_VERSION, modelName=model.name, instantiationToken=instantiation_token,
         description=model.description, generationTool=GENERATION_TOOL, variableNamingConvention="structured")

    def interface(tag, **flags):
        el = ET.SubElement(root, tag)
        _set(el, modelIdentifier=model_identifier, needsExecutionTool=False,
             canBeInstantiatedOnlyOncePerProcess=False, canGetAndSetFMUState=True, canSerializeFMUState=True,
             providesDirectionalDerivative=has_jac, **flags)

    if "me" in fmi_types:
        # the runtime checks validity ranges in fmi3CompletedIntegratorStep: needed only when there are some
        ranged = any(v.min is not None or v.max is not None for v in model.states + model.inputs + model.outputs)
        interface("ModelExchange", needsCompletedIntegratorStep=ranged)
    if "cs" in fmi_types:
        computed = len(model.outputs) > 0
        # Event Mode for a model with events (state events, clauses, sample clocks): with eventModeUsed an
        # event ends fmi3DoStep and the importer's fmi3UpdateDiscreteStates runs its iteration; a model
        # without any has none to hand over, and eventModeUsed = true is refused for it (fmi3_functions.c).
        # The intermediate update after each accepted solver step, and an early return from it, for all.
        interface("CoSimulation", canHandleVariableCommunicationStepSize=True,
                  maxOutputDerivativeOrder=1 if (has_jac or not computed) else 0,
                  hasEventMode=has_event_mode(model), providesIntermediateUpdate=True,
                  mightReturnEarlyFromDoStep=True, canReturnEarlyAfterIntermediateUpdate=True)

    units = unit_definitions(root, layout, model.name)

    cats = ET.SubElement(root, "LogCategories")
    for name, desc in LOG_CATEGORIES3:
        ET.SubElement(cats, "Category", name=name, description=desc)
    if default_experiment:
        _set(ET.SubElement(root, "DefaultExperiment"), **{k: float(v) for k, v in default_experiment.items()})

    by_index = {v.index: v for v in layout.variables}
    reinit = model.events is not None and any(
        t in {s.symbol for s in model.states} for c in model.events.clauses for t, _ in c.assign)
    if any(v.name == "time" for v in layout.variables):
        raise FmugenError(f"model {xml_text(model.name)!r}: a variable is named 'time', the name of FMI 3.0's "
                          f"independent variable; rename it for an FMI 3.0 FMU")
    mv = ET.SubElement(root, "ModelVariables")
    # FMI 3.0 requires exactly one independent variable: the time, last in value references (fmi3_functions.c)
    _set(ET.SubElement(mv, "Float64"), name="time", valueReference=vrs["<time>"], causality="independent",
         variability="continuous", unit="s" if "s" in units else None, description="simulation time")
    elements = {}
    for v in layout.variables:
        if v.kind == "alias":
            continue
        el = ET.SubElement(mv, _TYPES[v.type])
        elements[v.index] = el
        # the runtime's descriptions name FMI 2.0 statuses (solver.range_check)
        desc = v.description.replace("fmi2", "fmi3") if v.kind == "runtime" else v.description
        _set(el, name=v.name, valueReference=vrs[v.name], description=desc, causality=v.causality,
             variability=v.variability, initial=v.initial)
        if "cs" in fmi_types and v.causality == "output":
            _set(el, intermediateUpdate=True)  # readable in the intermediate-update callback
        if "cs" in fmi_types and v.causality == "input" and v.variability == "continuous":
            # settable in the intermediate update: where the solver needs u(t) inside a step, the importer
            # sets it (intermediateVariableSetRequested; FMI 3.0's replacement for input derivatives)
            _set(el, intermediateUpdate=True)
        if v.type == "Real":
            deriv = None if v.derivative is None else by_index[v.derivative]  # the state (FMI 2.0 index)
            _set(el, unit=v.unit, min=v.min, max=v.max, nominal=v.nominal, start=v.start,
                 derivative=None if deriv is None else vrs[deriv.name])
            if v.kind == "state" and reinit:
                _set(el, reinit=True)  # a clause may re-initialise it at an event
        else:
            _set(el, min=None if v.min is None else int(v.min), max=None if v.max is None else int(v.max),
                 start=None if v.start is None else int(v.start))
    for v in layout.by_kind("alias"):
        _set(ET.SubElement(elements[v.alias_of], "Alias"), name=v.name, description=v.description)
    for k, (name, _) in enumerate(indicators):
        _set(ET.SubElement(mv, "Float64"), name=f"solver.event_indicator_{k + 1}",
             valueReference=vrs[f"<event indicator {k}>"],
             description=f"event indicator {k + 1}: {name} (a state event where it changes sign)",
             causality="local", variability="continuous", initial="calculated")

    # ---- ModelStructure: dependencies as value references
    vr_of = {v.symbol: vrs[v.name] for v in layout.variables if v.symbol is not None and v.kind != "alias"}
    states = layout.by_kind("state")
    ders = layout.by_kind("derivative")
    outs = layout.by_kind("output")
    x_u = [v.symbol for v in model.states + model.inputs]
    d_run = model.dependencies(x_u)
    d_init = model.dependencies(x_u + [v.symbol for v in model.parameters])

    def unknown(parent, tag, vr, dep_syms, expr=None):
        el = ET.SubElement(parent, tag, valueReference=str(vr))
        ids = sorted(vr_of[s] for s in dep_syms)
        el.set("dependencies", " ".join(map(str, ids)))
        if ids:
            kinds = ["dependent"] * len(ids)
            if expr is not None and len(ids) == 1 and sp.sympify(expr) in vr_of:
                kinds = ["constant"]  # the unknown is the known itself
            el.set("dependenciesKind", " ".join(kinds))
        return el

    ms = ET.SubElement(root, "ModelStructure")
    output_entries = [(vrs[v.name], {v.symbol}, v.symbol) for v in states if v.causality == "output"]
    output_entries += [(vrs[v.name], d_run["outputs"][i], model.output_exprs[i]) for i, v in enumerate(outs)]
    for vr, deps_, expr in sorted(output_entries, key=lambda e: e[0]):
        unknown(ms, "Output", vr, deps_, expr)
    for i, v in enumerate(ders):
        unknown(ms, "ContinuousStateDerivative", vrs[v.name], d_run["derivatives"][i], model.derivatives[i])
    init = [(vrs[v.name], d_init["derivatives"][i]) for i, v in enumerate(ders)]
    init += [(vrs[v.name], d_init["outputs"][i]) for i, v in enumerate(outs)]
    for vr, deps_ in sorted(init, key=lambda e: e[0]):
        unknown(ms, "InitialUnknown", vr, deps_)
    for k in range(len(indicators)):
        # no dependencies attribute: may depend on every known (the indicators read discrete states too)
        ET.SubElement(ms, "EventIndicator", valueReference=str(vrs[f"<event indicator {k}>"]))

    clocks = clock_annotations(model)
    if clocks:
        # FMI 2.0's vendor annotation (fmugen/cosim/README.md "Sample clocks") in FMI 3.0's place for it,
        # last; FMI 3.0 clocks are not written yet (their instants are time events, as in FMI 2.0)
        tool = ET.SubElement(ET.SubElement(root, "Annotations"), "Annotation", type="fmugen")
        for c in clocks:
            _set(ET.SubElement(tool, "Clock"), **c)

    for el in root.iter():  # free text (descriptions, units, the model name) made valid XML 1.0 text
        for k, v in el.attrib.items():
            if _XML_INVALID.search(v):
                el.set(k, xml_text(v))
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def build_description3_xml(model_identifier: str, source_files: Sequence[str]) -> str:
    """``sources/buildDescription.xml`` (FMI 3.0 sec. 2.5.1): the C files of ``sources/``, compiled
    together into the binary, with ``FMI2_Export`` defined empty, so that the runtime's fmi2* functions
    (the binary's internals) are not marked for export (fmugen/fmi/build.py, ``fmi2_header_for_fmi3``):
    a Windows DLL then exports the fmi3* functions alone.  What it cannot say: ELF and Mach-O export every
    function of default visibility, so a binary built without ``-fvisibility=hidden`` or the version
    script (sources/README.txt) exports the internals too, which FMI 3.0 importers do not look for."""
    root = ET.Element("fmiBuildDescription", fmiVersion=FMI3_VERSION)
    bc = ET.SubElement(root, "BuildConfiguration", modelIdentifier=model_identifier)
    fs = ET.SubElement(bc, "SourceFileSet", language="C99")
    for f in source_files:
        ET.SubElement(fs, "SourceFile", name=f)
    ET.SubElement(fs, "PreprocessorDefinition", name="FMI2_Export", value="",
                  description="empty: the fmi2* functions of the runtime stay internal")
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
