"""``terminalsAndIcons/terminalsAndIcons.xml`` (FMI 3.0 sec. 2.4.9, schema ``fmi3TerminalsAndIcons.xsd``):
fmugen's connectors (:mod:`fmugen.components.connectors`) as terminals of an FMI 3.0 FMU.

A terminal groups the FMU variables of one physical connector -- a robot's
joint, a component's flange or port -- so that an importer can connect a
drive to a joint as one terminal instead of signal by signal.  FMI 2.0 has no
terminals; fmugen writes the file into FMI 3.0 FMUs only, and only when there
is at least one terminal (``<Terminals>`` needs one).  Icons
(``<GraphicalRepresentation>``, ``icon.png``) are not written.

What is written, and why:

``terminalKind``
    the connector type in reverse domain name notation, as the standard
    recommends (fmugen's SSP annotation is ``org.fmugen.run`` likewise):

    =====================================  =========================================
    ``org.fmugen.RotationalFlange``        ``phi`` [rad], ``w`` [rad/s]; ``tau`` [N.m]
    ``org.fmugen.TranslationalFlange``     ``s`` [m], ``v`` [m/s]; ``f`` [N]
    ``org.fmugen.HydraulicPort``           ``p`` [Pa]; ``Q`` [m3/s]
    ``org.fmugen.ElectricalPin``           ``v`` [V]; ``i`` [A]
    =====================================  =========================================

    the member names are the connector type's variable names (before the
    semicolon the potentials, after it the flow).
``matchingRule="bus"``
    members matched by ``memberName``, some may be absent.  Not ``plug``
    (every member present): fmugen's connectors are causal and a side may
    leave out a potential the other side computes -- the hydraulic
    actuator's flange has no angle, yet bonds to a joint whose flange has
    one (``connect``, fmugen/scene/connect.py, accepts it) -- and pruning
    removes members nothing reads.  What ``bus`` does not say, the kinds
    do: each input member needs the member of the same name, computed by the
    other side.
``variableKind``
    a potential is ``signal`` (connected values are equal, as the across
    variables of a bond are).  The flow -- torque, force, volume flow,
    current -- obeys Kirchhoff's law at the bond: ``inflow`` / ``outflow``.
    fmugen's bonds copy the flow its computing side outputs, unchanged, to
    the other side's input (``connect``: the torque an actuator outputs is
    the torque the joint receives), so the flow sums to zero at the bond
    only when the computing side counts it positive *out* of itself and the
    receiving side positive *into* itself: an output flow is ``outflow``, an
    input flow ``inflow``.
``name``
    the connector's name as the FMU's variables are named: its own name in
    an FMU of one instance (``flange``, ``joint[2]``), ``instance.connector``
    in an FMU of several (``act2.flange``); a robot built alone has
    ``joint[k]`` for each joint.

Every member is an input or an output of the FMU (the standard restricts
member variables to inputs, outputs and parameters); a connector variable
the FMU does not have there (pruned, or an internal state) is left out, a
connector with none left is no terminal.
"""
from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Mapping, Optional, Sequence

from ..components.connectors import TYPES, arm_joint
from ..errors import FmugenError
from .model_description import _XML_INVALID, _set, variable_layout, xml_text

#: the file's path inside the FMU (FMI 3.0 sec. 2.5)
TERMINALS_PATH = "terminalsAndIcons/terminalsAndIcons.xml"

#: connector type -> terminalKind
TERMINAL_KINDS = {
    "rotational": "org.fmugen.RotationalFlange",
    "translational": "org.fmugen.TranslationalFlange",
    "hydraulic": "org.fmugen.HydraulicPort",
    "electrical": "org.fmugen.ElectricalPin",
}

#: connector type -> its flow (through) variable: the table of fmugen/components/connectors.py; the
#: TYPES "power" pairs are bond-graph effort x flow, where a mechanical flow is the speed, not the torque
FLOWS = {"rotational": "tau", "translational": "f", "hydraulic": "Q", "electrical": "i"}

#: the standard's predefined matching rules and variable kinds (sec. 2.4.9.2)
MATCHING_RULES = ("plug", "bus", "sequence", "none")
VARIABLE_KINDS = ("signal", "inflow", "outflow")

# xs:normalizedString carries no tab, line feed or carriage return; a name with one, or with a
# character XML 1.0 cannot carry, is refused (cleaning it could make two names equal)
_NOT_IN_NAMES = re.compile("[\t\n\r]")


@dataclass(frozen=True)
class Member:
    variable: str  # the FMU variable (variableName)
    member: str  # memberName: the connector type's variable, e.g. "tau"
    kind: str  # variableKind: "signal", "inflow" or "outflow"


@dataclass(frozen=True)
class Terminal:
    name: str
    kind: str  # terminalKind, e.g. "org.fmugen.RotationalFlange"
    members: tuple  # of Member
    matching_rule: str = "bus"
    description: str = ""


def interface(model) -> dict:
    """Causality of each input and output of ``model`` as its modelDescription writes them (a state exposed
    as an output included; aliases not: a terminal names the variable itself)."""
    return {v.name: v.causality for v in variable_layout(model).variables
            if v.kind != "alias" and v.causality in ("input", "output")}


def connector_terminal(name: str, ctype: str, mapping: Mapping[str, str], io: Mapping[str, str],
                       description: str = "") -> Optional[Terminal]:
    """The terminal of a connector of type ``ctype`` (``mapping``: ``{connector variable: FMU variable}``)
    with those of its variables that are in the FMU's interface ``io`` (:func:`interface`); None when
    none of them is."""
    if ctype not in TYPES:
        raise FmugenError(f"terminal {name!r}: connector type {ctype!r}; types: {', '.join(TYPES)}")
    members = []
    for var in TYPES[ctype]["vars"]:  # the type's order: potentials, then the flow
        fmu_var = mapping.get(var)
        if fmu_var not in io:
            continue
        kind = "signal" if var != FLOWS[ctype] else ("outflow" if io[fmu_var] == "output" else "inflow")
        members.append(Member(fmu_var, var, kind))
    if not members:
        return None
    return Terminal(name, TERMINAL_KINDS[ctype], tuple(members), description=description)


def joint_terminals(model) -> list:
    """One terminal ``joint[k]`` per joint of a robot's model: the states ``q[k]`` and ``qd[k]`` and the
    input ``tau[k]`` that are in its interface (a revolute joint's angle is in rad: a rotational flange,
    else a translational one -- as the scene's ``joint[k]`` connectors, fmugen/scene/connect.py).  Empty
    for a model without joints."""
    states = {v.name: v for v in model.states}
    io = interface(model)
    out = []
    for v in model.states:
        m = re.fullmatch(r"q\[([1-9][0-9]*)\]", v.name)
        if m is None or f"qd[{m.group(1)}]" not in states:
            continue
        k = int(m.group(1))
        ctype, mapping = arm_joint(k, v.unit == "rad")
        t = connector_terminal(f"joint[{k}]", ctype, mapping, io,
                               description=f"joint {k}: position q[{k}], speed qd[{k}], "
                                           f"{'torque' if ctype == 'rotational' else 'force'} tau[{k}]")
        if t is not None:
            out.append(t)
    return out


def check_terminals(terminals: Sequence[Terminal], model) -> list:
    """``terminals`` as a list, refused (FmugenError) unless each names only inputs and outputs of ``model``,
    uses the standard's matching rules and variable kinds, and has unique names where the standard wants
    them (terminals among themselves, members within a terminal)."""
    io = interface(model)
    out, names = [], set()
    for t in terminals:
        if not isinstance(t, Terminal):
            raise FmugenError(f"terminals: {t!r} is not a fmugen.fmi.terminals.Terminal")
        where = f"terminal {xml_text(str(t.name))!r}"
        texts = [("name", t.name), ("terminalKind", t.kind)]
        for m in t.members:
            texts += [("variableName", m.variable), ("memberName", m.member)]
        for what, text in texts:
            if not isinstance(text, str) or not text or _XML_INVALID.search(text) or _NOT_IN_NAMES.search(text):
                raise FmugenError(f"{where}: {what} {text!r} must be a non-empty text without control "
                                  f"characters")
        if t.name in names:
            raise FmugenError(f"{where} is listed twice (terminal names are unique)")
        names.add(t.name)
        if t.matching_rule not in MATCHING_RULES:
            raise FmugenError(f"{where}: matchingRule {t.matching_rule!r}; predefined: {', '.join(MATCHING_RULES)}")
        if not t.members:
            raise FmugenError(f"{where} has no member variables")
        members = [m.member for m in t.members]
        if len(set(members)) != len(members):
            raise FmugenError(f"{where}: a memberName is listed twice ({', '.join(members)})")
        for m in t.members:
            if m.kind not in VARIABLE_KINDS:
                raise FmugenError(f"{where}: variableKind {m.kind!r}; predefined: {', '.join(VARIABLE_KINDS)}")
            if m.variable not in io:
                raise FmugenError(f"{where}: {xml_text(m.variable)!r} is not an input or output of model "
                                  f"{xml_text(model.name)!r}")
        out.append(t)
    return out


def terminals_xml(terminals: Sequence[Terminal], fmi_version: str = "3.0") -> str:
    """The text of ``terminalsAndIcons.xml`` holding ``terminals`` (at least one: ``<Terminals>`` needs a
    ``<Terminal>``).  ElementTree escapes ``& < > "`` in attribute values; a description's characters
    that XML 1.0 cannot carry become ``?`` (as in modelDescription.xml); names were checked by
    :func:`check_terminals`."""
    if not terminals:
        raise FmugenError("terminalsAndIcons.xml needs at least one terminal")
    root = ET.Element("fmiTerminalsAndIcons", fmiVersion=fmi_version)
    parent = ET.SubElement(root, "Terminals")
    for t in terminals:
        el = ET.SubElement(parent, "Terminal")
        _set(el, name=t.name, matchingRule=t.matching_rule, terminalKind=t.kind,
             description=xml_text(t.description) if t.description else None)
        for m in t.members:
            _set(ET.SubElement(el, "TerminalMemberVariable"), variableName=m.variable, memberName=m.member,
                 variableKind=m.kind)
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
