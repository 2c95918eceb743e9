"""``modelDescription.xml`` (FMI 2.0) of a :class:`SymbolicModel`.

The variables follow the value-reference layout of
``c_runtime/fmugen_model.h`` (:func:`variable_layout` returns it, so no other
part of fmugen writes value references by hand):

=========================  =================  ==========  ============  ==========
block                      value references   causality   variability   initial
=========================  =================  ==========  ============  ==========
states x                   [0, nx)            local or    continuous    exact
                                              output
derivatives der(x)         [nx, 2nx)          local       continuous    calculated
inputs u                   [2nx, +nu)         input       continuous    (exact)
computed outputs y         [2nx+nu, +ny)      output      continuous    calculated
parameters p               [.., +np)          parameter   fixed         exact
runtime Real parameters    [.., +4)           parameter   fixed         exact
runtime Integers           Integer vr 0..4    parameter / fixed /
                                              local       discrete
=========================  =================  ==========  ============  ==========

``<ModelStructure>`` holds the exact dependencies taken from the program
(:func:`dependencies`): Outputs and Derivatives on states and inputs, the
InitialUnknowns on the knowns of Initialization Mode (inputs, and variables
with initial="exact": states and parameters), as the FMI 2.0 schema
documentation of ``InitialUnknowns/Unknown`` defines them.
"""
from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from typing import Optional, Sequence

import sympy as sp

from .. import __version__
from ..errors import FmugenError
from ..codegen.model import SymbolicModel, physical_range
from ..codegen.runtime_parameters import header_defines, runtime_parameters, runtime_starts
from .units import base_units

FMI_VERSION = "2.0"
GENERATION_TOOL = f"fmugen {__version__}"

#: Log categories of the runtime, in its order (c_runtime/runtime_support.c).
LOG_CATEGORIES = (
    ("logEvents", "mode changes and other events of the FMI state machine"),
    ("logStatusWarning", "messages of status fmi2Warning"),
    ("logStatusError", "messages of status fmi2Error, fmi2Discard and fmi2Fatal"),
    ("logAll", "all messages"),
)


@dataclass
class ScalarVariable:
    """One ``<ScalarVariable>``; ``index`` is its 1-based position in the list."""

    index: int
    name: str
    value_reference: int
    type: str
    causality: str
    variability: str
    initial: Optional[str]
    start: Optional[float] = None
    unit: str = ""
    description: str = ""
    nominal: Optional[float] = None
    min: Optional[float] = None
    max: Optional[float] = None
    derivative: Optional[int] = None  # index of the state, for der(x)
    kind: str = ""  # state, derivative, input, output, parameter, runtime, alias
    symbol: Optional[sp.Symbol] = None
    alias_of: Optional[int] = None  # for an alias: the index of the variable it names again


@dataclass
class VariableLayout:
    """Variables in ``<ModelVariables>`` order with their value references.

    ``real``/``integer``: FMI name -> value reference (for fmpy's
    ``start_values``, ``fmi2GetReal``...); ``variables``: all of them.
    """

    variables: list = field(default_factory=list)
    real: dict = field(default_factory=dict)
    integer: dict = field(default_factory=dict)

    def by_kind(self, kind: str) -> list:
        return [v for v in self.variables if v.kind == kind]

    def index_of(self, name: str) -> int:
        for v in self.variables:
            if v.name == name:
                return v.index
        raise KeyError(name)


def variable_layout(model: SymbolicModel) -> VariableLayout:
    """Every variable of the FMU in value-reference order (see module doc)."""
    nx, nu, ny, np_ = model.nx, model.nu, model.ny, model.np
    out = VariableLayout()

    def add(**kw):
        v = ScalarVariable(index=len(out.variables) + 1, **kw)
        out.variables.append(v)
        (out.real if v.type == "Real" else out.integer)[v.name] = v.value_reference
        return v

    origin = f" (from {model.provenance})" if model.provenance else ""
    for i, v in enumerate(model.states):
        if v.start is None:
            raise FmugenError(f"model {model.name!r}{origin}: state {v.name!r} has no start value")
        add(name=v.name, value_reference=i, type="Real",
            causality="output" if v.output else "local", variability="continuous", initial="exact",
            start=v.start, unit=v.unit, description=v.description, nominal=v.nominal, min=v.min, max=v.max,
            kind="state", symbol=v.symbol)
    for i, v in enumerate(model.states):
        add(name=f"der({v.name})", value_reference=nx + i, type="Real", causality="local",
            variability="continuous", initial="calculated", unit=_derivative_unit(v.unit),
            description=f"time derivative of {v.name}", derivative=i + 1, kind="derivative")
    for i, v in enumerate(model.inputs):
        add(name=v.name, value_reference=2 * nx + i, type="Real", causality="input", variability="continuous",
            initial=None, start=v.start if v.start is not None else 0.0, unit=v.unit,
            description=v.description, nominal=v.nominal, min=v.min, max=v.max, kind="input", symbol=v.symbol)
    for i, v in enumerate(model.outputs):
        add(name=v.name, value_reference=2 * nx + nu + i, type="Real", causality="output",
            variability="continuous", initial="calculated", unit=v.unit, description=v.description,
            nominal=v.nominal, min=v.min, max=v.max, kind="output", symbol=v.symbol)
    for i, v in enumerate(model.parameters):
        if v.start is None:
            raise FmugenError(f"model {model.name!r}{origin}: parameter {v.name!r} has no start value; give it "
                              f"a value in the file's [parameters] (or fmugen build --set {v.name}=...)")
        add(name=v.name, value_reference=2 * nx + nu + ny + i, type="Real", causality="parameter",
            variability="fixed", initial="exact", start=v.start, unit=v.unit, description=v.description,
            nominal=v.nominal, min=physical_range(v)[0], max=v.max, kind="parameter", symbol=v.symbol)
    first_rt = 2 * nx + nu + ny + np_
    for r in runtime_parameters():
        if r.name == "solver.n_events" and model.events is None:
            continue
        add(name=r.name, value_reference=(first_rt + r.offset) if r.type == "Real" else r.offset, type=r.type,
            causality=r.causality, variability=r.variability, initial=r.initial, start=r.start, unit=r.unit,
            description=r.description, min=r.min, max=r.max, kind="runtime")
    # a hybrid model's discrete states: after the runtime's Real parameters (c_runtime/fmugen_model.h),
    # piecewise constant (variability discrete), changed only at events; a start is settable before
    # initialisation like a parameter's
    first_d = first_rt + header_defines()["FMUGEN_RT_COUNT"]
    for k, v in enumerate(model.events.discrete if model.events is not None else ()):
        add(name=v.name, value_reference=first_d + k, type="Real", causality="local", variability="discrete",
            initial="exact", start=v.start, unit=v.unit, description=v.description or "discrete state",
            kind="discrete", symbol=v.symbol)
    if model.events is not None:  # then the runtime's time of the last event (fmugen_model.h)
        add(name="solver.last_event_time", value_reference=first_d + len(model.events.discrete), type="Real",
            causality="local", variability="discrete", initial="calculated", unit="s",
            description="time of the last event the runtime handled (the start time before any)", kind="runtime")
    # FMI 2.0 aliases (sec. 2.2.7: the same value reference; of a non-constant alias set only one variable may
    # carry a start value), last so that no value reference or index above moves. A state's alias keeps the
    # state's causality, initial="calculated" without a start (the state holds it). An input's alias is a
    # *local*, initial="calculated": FMI 2.0 requires a start on every input, so an alias with causality
    # input would be a second start in the set, which FMI Library (the Compliance Checker, libcosim,
    # OMSimulator) answers by removing both variables. The joint name reads the value; the input sets it.
    for v in [v for v in out.variables if v.kind in ("state", "input") and v.symbol is not None]:
        src = next(s for s in (model.states if v.kind == "state" else model.inputs) if s.symbol == v.symbol)
        if not src.alias:
            continue
        add(name=src.alias, value_reference=v.value_reference, type="Real",
            causality=v.causality if v.kind == "state" else "local", variability=v.variability,
            initial="calculated", start=None, unit=v.unit,
            description=f"alias of {v.name}: {v.description}", nominal=v.nominal, min=v.min, max=v.max,
            kind="alias", alias_of=v.index)
    names = [v.name for v in out.variables]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise FmugenError(f"model {model.name!r}: variable names used twice: {', '.join(dup)}")
    return out


def clock_annotations(model: SymbolicModel) -> list:
    """Per sample clock: its period and offset at the start values, and the parameter each is (when it is
    one) -- ``{"period", "offset", "periodParameter", "offsetParameter"}``."""
    if model.events is None or not model.events.clocks:
        return []
    starts = {v.symbol: v.start for v in model.parameters}
    names = {v.symbol: v.name for v in model.parameters}
    out = []
    for c in model.events.clocks:
        row = {}
        for key, e in (("period", c.period), ("offset", c.offset)):
            e = sp.sympify(e)
            value = e.xreplace({k: sp.Float(v) for k, v in starts.items() if v is not None})
            if not value.is_Number:
                raise FmugenError(f"model {model.name!r}: a clock's {key} {e} is no number at the start values")
            row[key] = float(value)
            if e in names:
                row[f"{key}Parameter"] = names[e]
        out.append(row)
    return out


def _derivative_unit(unit: str) -> str:
    """Unit of dx/dt: ``rad`` -> ``rad/s``, ``m/s`` -> ``m/s2``, ``1`` -> ``1/s``."""
    if not unit:
        return ""
    if unit == "1":
        return "1/s"
    m = re.fullmatch(r"(.+)/s(\d*)", unit)
    if m and "(" not in unit and "/" not in m.group(1):
        return f"{m.group(1)}/s{int(m.group(2) or 1) + 1}"
    if "/" in unit:
        num, den = unit.split("/", 1)
        den = den[1:-1] if den.startswith("(") and den.endswith(")") else den
        return f"{num}/({den}.s)"
    return f"{unit}/s"


def _fmt(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    return repr(float(v))


#: characters XML 1.0 forbids anywhere (sec. 2.2): C0 controls except tab,
#: newline and carriage return, lone surrogates, U+FFFE and U+FFFF
_XML_INVALID = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]")


def xml_text(s: str) -> str:
    """``s`` with every character XML 1.0 cannot carry replaced by ``?``
    (ElementTree escapes ``& < > "`` but writes control characters as they
    are, which no XML parser reads back)."""
    return _XML_INVALID.sub("?", s)


def _xml_safe_tree(root, model_name: str) -> None:
    """Make every attribute of the tree valid XML 1.0 text.

    Free text (descriptions, units, the model name) is cleaned with
    :func:`xml_text`; a variable *name* with such a character is refused,
    because cleaning could make two names equal.
    """
    for el in root.iter():
        for k, v in el.attrib.items():
            if _XML_INVALID.search(v):
                if el.tag == "ScalarVariable" and k == "name":
                    raise FmugenError(f"model {xml_text(model_name)!r}: variable name {v!r} contains a "
                                      f"character that XML 1.0 cannot carry")
                el.set(k, xml_text(v))


def _set(el, **attrs):
    for k, v in attrs.items():
        if v is None or v == "":
            continue
        el.set(k, v if isinstance(v, str) else _fmt(v))


def unit_definitions(root, layout, model_name: str) -> list:
    """``<UnitDefinitions>`` of the variables' units in order of first use, each as SI base-unit exponents
    and factor (the element is the same in FMI 2.0 and 3.0); a unit fmugen cannot decompose is refused
    naming the first variable that has it.  Returns the units."""
    units = []
    for v in layout.variables:
        if v.unit and v.unit not in units:
            units.append(v.unit)
    if not units:
        return units
    ud = ET.SubElement(root, "UnitDefinitions")
    for u in units:
        try:
            b = base_units(u)
        except ValueError as e:
            owners = [v.name for v in layout.variables if v.unit == u]
            raise FmugenError(f"model {model_name!r}, variable {owners[0]}: {e}") from None
        uel = ET.SubElement(ud, "Unit", name=u)
        bel = ET.SubElement(uel, "BaseUnit")
        _set(bel, **{k: int(x) for k, x in b.exponents().items()})
        if b.factor != 1.0:
            _set(bel, factor=b.factor)
    return units


def model_description_xml(
    model: SymbolicModel,
    guid: str,
    model_identifier: str,
    fmi_types: Sequence[str] = ("me", "cs"),
    source_files: Sequence[str] = (),
    default_experiment: Optional[dict] = None,
    runtime_start: Optional[dict] = None,
) -> str:
    """The text of modelDescription.xml.

    ``default_experiment``: optional ``{startTime, stopTime, stepSize,
    tolerance}`` (a scene's run), written as ``<DefaultExperiment>``.

    ``fmi_types``: "me" and/or "cs"; ``source_files``: the C files of the
    FMU's ``sources/`` to list under ``<SourceFiles>`` (FMI 2.0 sec. 2.2.6);
    ``runtime_start``: start values of the runtime's solver parameters (see
    :func:`runtime_starts`; the C model must be generated with the same).
    """
    fmi_types = tuple(fmi_types)
    if not fmi_types or any(t not in ("me", "cs") for t in fmi_types):
        raise FmugenError(f"fmi_types must be a non-empty subset of ('me', 'cs'), got {fmi_types!r}")
    layout = variable_layout(model)
    if runtime_start:
        rs = runtime_starts(runtime_start)
        for v in layout.variables:
            if v.kind == "runtime" and v.name in rs:
                v.start = rs[v.name]
    has_jac = model.jacobian is not None

    root = ET.Element("fmiModelDescription")
    _set(root, fmiVersion=FMI_VERSION, modelName=model.name, guid=guid,
         description=model.description, generationTool=GENERATION_TOOL,
         variableNamingConvention="structured",
         numberOfEventIndicators=str(len(model.events.indicators) if model.events is not None else 0))

    def interface(tag, **flags):
        el = ET.SubElement(root, tag)
        _set(el, modelIdentifier=model_identifier, needsExecutionTool=False, **flags,
             canBeInstantiatedOnlyOncePerProcess=False, canNotUseMemoryManagementFunctions=False,
             canGetAndSetFMUstate=True, canSerializeFMUstate=True, providesDirectionalDerivative=has_jac)
        if source_files:
            files = ET.SubElement(el, "SourceFiles")
            for f in source_files:
                ET.SubElement(files, "File", name=f)

    if "me" in fmi_types:
        # the runtime checks validity ranges in fmi2CompletedIntegratorStep: needed only when there are some
        ranged = any(v.min is not None or v.max is not None for v in model.states + model.inputs + model.outputs)
        interface("ModelExchange", completedIntegratorStepNotNeeded=not ranged)
    if "cs" in fmi_types:
        # first output derivatives: a state's is f; a computed output's needs the Jacobian (dg/dx f + dg/du du)
        computed = len(model.outputs) > 0
        interface("CoSimulation", canHandleVariableCommunicationStepSize=True, canInterpolateInputs=True,
                  maxOutputDerivativeOrder=1 if (has_jac or not computed) else 0, canRunAsynchronuously=False)

    unit_definitions(root, layout, model.name)

    cats = ET.SubElement(root, "LogCategories")
    for name, desc in LOG_CATEGORIES:
        ET.SubElement(cats, "Category", name=name, description=desc)
    if default_experiment:
        _set(ET.SubElement(root, "DefaultExperiment"), **{k: float(v) for k, v in default_experiment.items()})
    clocks = clock_annotations(model)
    if clocks:
        # the sample clocks of a sampled component, for a master that lands its macro steps on their
        # instants (fmugen's does: fmugen/cosim/README.md "Sample clocks"); FMI 2.0 has no element for them
        tool = ET.SubElement(ET.SubElement(root, "VendorAnnotations"), "Tool", name="fmugen")
        for c in clocks:
            _set(ET.SubElement(tool, "Clock"), **c)

    mv = ET.SubElement(root, "ModelVariables")
    for v in layout.variables:
        el = ET.SubElement(mv, "ScalarVariable")
        _set(el, name=v.name, valueReference=v.value_reference, description=v.description,
             causality=v.causality, variability=v.variability, initial=v.initial)
        t = ET.SubElement(el, v.type)
        if v.type == "Real":
            _set(t, unit=v.unit, min=v.min, max=v.max, nominal=v.nominal, start=v.start, derivative=v.derivative)
        else:
            _set(t, min=None if v.min is None else int(v.min), max=None if v.max is None else int(v.max),
                 start=None if v.start is None else int(v.start))

    # ---- ModelStructure
    idx = {v.symbol: v.index for v in layout.variables if v.symbol is not None}
    states = layout.by_kind("state")
    ders = layout.by_kind("derivative")
    outs = layout.by_kind("output")
    x_u = [v.symbol for v in model.states + model.inputs]
    d_run = model.dependencies(x_u)
    d_init = model.dependencies(x_u + [v.symbol for v in model.parameters])

    def unknown(parent, var_index, dep_syms, expr=None):
        el = ET.SubElement(parent, "Unknown", index=str(var_index))
        ids = sorted(idx[s] for s in dep_syms)
        el.set("dependencies", " ".join(map(str, ids)))
        if expr is not None and ids and sp.sympify(expr) in idx and len(ids) == 1:
            el.set("dependenciesKind", "constant")  # the unknown is the known itself
        return el

    ms = ET.SubElement(root, "ModelStructure")
    output_entries = [(v.index, {v.symbol}, v.symbol) for v in states if v.causality == "output"]
    output_entries += [(v.index, d_run["outputs"][i], model.output_exprs[i]) for i, v in enumerate(outs)]
    aliases = [v for v in layout.by_kind("alias") if v.causality == "output"]
    by_index = {v.index: v for v in layout.variables}
    output_entries += [(v.index, {by_index[v.alias_of].symbol}, by_index[v.alias_of].symbol) for v in aliases]
    output_entries.sort(key=lambda e: e[0])
    if output_entries:
        o = ET.SubElement(ms, "Outputs")
        for i, deps_, expr in output_entries:
            unknown(o, i, deps_, expr)
    if ders:
        d = ET.SubElement(ms, "Derivatives")
        for i, v in enumerate(ders):
            unknown(d, v.index, d_run["derivatives"][i], model.derivatives[i])
    init = [(v.index, d_init["derivatives"][i]) for i, v in enumerate(ders)]
    init += [(v.index, d_init["outputs"][i]) for i, v in enumerate(outs)]
    init += [(v.index, {by_index[v.alias_of].symbol}) for v in aliases]  # the state it names, known at init
    if init:
        iu = ET.SubElement(ms, "InitialUnknowns")
        for i, deps_ in sorted(init, key=lambda e: e[0]):
            unknown(iu, i, deps_)

    _xml_safe_tree(root, model.name)
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
