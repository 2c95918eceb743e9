"""Seeded fuzzing of the SSP surface (issue 27): archives and documents mutated, then
:func:`fmugen.ssp.load_system`.

The base archive is the two-mass system of ``tests/ssp_third_party.py`` (hand-written third-party
FMUs) with every part fmugen reads: an inline and a file parameter set (.ssv), a LinearTransformation,
a unit conversion by the archive's own Units, the OSP step annotation and fmugen's run annotation
(order, units, start values, records, a setting).  Each case mutates it in one way and knows what
the outcome must be:

* **number** -- one numeric attribute (xs:double, xs:int, xs:boolean) set to a value: either a
  spelling the XML Schema grammar refuses or a value the field's rule refuses (a unit factor of 0, a
  step of -1, a stop time before the start), which must be *refused*; or a valid value, in any valid
  spelling (``" 250 "``, ``2.5E2``, ``+250.``), which must be *honoured*: the loaded system holds it;
* **structure** -- an element removed, doubled or pointed elsewhere so that the system is wrong
  (a connection to no component, an input driven twice, a binding of no variable, an annotation
  naming no component): must be *refused*;
* **zip** -- the archive itself: members missing, zip slip, symbolic links, duplicate members,
  corrupt or encrypted data, an FMU that is no FMU: must be *refused*;
* **random** -- any element deleted or doubled, an attribute set to hostile text, the SSD cut short
  or with bytes inserted, a bit of the archive flipped: refused or accepted, never a crash;
* **fmu** -- an FMU's modelDescription.xml damaged the same way: refused or accepted, never a crash.

Findings, per class: **crash** (an exception other than :class:`fmugen.errors.FmugenError`),
**silent-wrong** (a value that must be refused accepted, or an honoured value read differently),
**false refusal** (a valid value refused) and **bad message** (a refusal of several lines, or one
that does not start with the archive or does not name the field).

Short run (in the suite): ``tests/fuzz/test_fuzz_ssp.py``.  Long run:
``python tests/fuzz/fuzz_ssp.py --cases 2000 --seed 1`` (prints the table of counts).
"""
from __future__ import annotations

import argparse
import copy
import io
import math
import random
import re
import stat
import sys
import tempfile
import traceback
import zipfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

NS = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
      "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
      "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
      "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
      "fmugen": "urn:fmugen:ssp:1"}

BASE_SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    xmlns:osp="http://opensimulationplatform.com/SSP/OSPAnnotations"
    xmlns:fmugen="urn:fmugen:ssp:1" version="1.0" name="two_masses">
  <ssd:System name="two_masses">
    <ssd:Elements>
      <ssd:Component name="A" source="resources/mass.fmu">
        <ssd:Connectors>
          <ssd:Connector name="x" kind="output"><ssc:Real unit="m"/></ssd:Connector>
          <ssd:Connector name="v" kind="output"><ssc:Real unit="m/s"/></ssd:Connector>
          <ssd:Connector name="F" kind="input"><ssc:Real unit="N"/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings>
          <ssd:ParameterBinding>
            <ssd:ParameterValues>
              <ssv:ParameterSet version="1.0" name="A">
                <ssv:Parameters>
                  <ssv:Parameter name="m"><ssv:Real value="1.0"/></ssv:Parameter>
                </ssv:Parameters>
              </ssv:ParameterSet>
            </ssd:ParameterValues>
          </ssd:ParameterBinding>
        </ssd:ParameterBindings>
      </ssd:Component>
      <ssd:Component name="B" source="resources/spring.fmu">
        <ssd:Connectors>
          <ssd:Connector name="v_in" kind="input"><ssc:Real unit="mm/s"/></ssd:Connector>
          <ssd:Connector name="F" kind="output"><ssc:Real unit="N"/></ssd:Connector>
          <ssd:Connector name="v2" kind="output"><ssc:Real unit="m/s"/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings>
          <ssd:ParameterBinding source="resources/B.ssv"/>
        </ssd:ParameterBindings>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="A" startConnector="v" endElement="B" endConnector="v_in"/>
      <ssd:Connection startElement="B" startConnector="F" endElement="A" endConnector="F">
        <ssc:LinearTransformation factor="1.0"/>
      </ssd:Connection>
    </ssd:Connections>
  </ssd:System>
  <ssd:Units>
    <ssc:Unit name="mm/s"><ssc:BaseUnit m="1" s="-1" factor="0.001"/></ssc:Unit>
  </ssd:Units>
  <ssd:DefaultExperiment startTime="0" stopTime="0.5">
    <ssd:Annotations>
      <ssc:Annotation type="com.opensimulationplatform">
        <osp:Algorithm><osp:FixedStepAlgorithm baseStepSize="0.001"/></osp:Algorithm>
      </ssc:Annotation>
    </ssd:Annotations>
  </ssd:DefaultExperiment>
  <ssd:Annotations>
    <ssc:Annotation type="org.fmugen.run">
      <fmugen:Run version="1" scene="two_masses" scheme="newton" extrapolation="linear" step="0.001"
                  startTime="0" stopTime="0.5" jacobiHoldStep="0.001">
        <fmugen:Order>A B</fmugen:Order>
        <fmugen:Unit name="A" fmiType="cs" directionalDerivatives="false" members="A">
          <fmugen:Start name="c" value="150.0"/>
        </fmugen:Unit>
        <fmugen:Unit name="B" fmiType="cs" directionalDerivatives="false" members="B"/>
        <fmugen:Record column="A.x" unit="A" variable="x" physicalUnit="m"/>
        <fmugen:Record column="B.F" unit="B" variable="F" physicalUnit="N"/>
        <fmugen:Setting name="tol" value="0.0001"/>
      </fmugen:Run>
    </ssc:Annotation>
  </ssd:Annotations>
</ssd:SystemStructureDescription>
"""

BASE_SSV = """<?xml version="1.0" encoding="UTF-8"?>
<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="B">
  <ssv:Parameters>
    <ssv:Parameter name="k"><ssv:Real value="40000.0"/></ssv:Parameter>
  </ssv:Parameters>
</ssv:ParameterSet>
"""

# ------------------------------------------------------------------------------------------ values
#: spellings Python's float() (or int()) may read and XML Schema's xs:double does not, and non-numbers
NOT_XS_DOUBLE = ["1_5", "\u0661\u0662", "\u0663.\u0665", "\uff11", "infinity", "inf", "-inf", "nan", "NAN", "Infinity",
                 "+INF", "0x1p3", "1,5", "", " ", "1e", "e3", ".", "1.2.3", "\u00a01", "1\u20002", "-", "+", "1d5",
                 "1.5f", "0b1", "x" * 5000, "1 2", "--1", "1e+", "\U0001d7d9", "\u066b5"]
#: xs:double spellings that are numbers no field takes (non-finite, beyond the double range)
NON_FINITE = ["INF", "-INF", "NaN", "1e999", "-1e999", "1" * 400]
NOT_XS_INT = ["1.0", "1_0", "\u0663", "+-1", "", "1e0", "0x1", "99999999999", "INF", "NaN", "one", "\uff11"]
NOT_XS_BOOL = ["True", "FALSE", "yes", "no", "2", "", "on", "TRUE", "t", "1.0"]


def spellings(x: float) -> list:
    """Valid xs:double spellings of ``x`` that all mean exactly ``x`` (the values used are exact in
    binary and in 6 significant digits)."""
    r = repr(float(x))
    out = [r, " " + r + "\n", "\t" + r, f"{x:e}", f"{x:E}", f"{x:.6e}".replace("e", "E")]
    if math.copysign(1.0, x) > 0:  # not for -0.0
        out += ["+" + r, "0" + r]
    if r.endswith(".0"):
        out += [r[:-1], r[:-2]]
    return out


VALUES = [0.5, 2.0, 250.0, 1500.0, 0.125, 3.0, 1e-3, 0.0, -0.0, -2.0, -0.25, 1e300, 1e-300, 12.5]


# ------------------------------------------------------------------------------------------ targets
def _q(tag: str) -> str:
    prefix, local = tag.split(":")
    return f"{{{NS[prefix]}}}{local}"


def _find(root, path: str):
    el = root
    for step in path.split("/"):
        m = re.fullmatch(r"([a-z]+:[A-Za-z]+)(?:\[(\d+)\])?", step)
        found = el.findall(_q(m.group(1)))
        el = found[int(m.group(2) or 0)]
    return el


S, DE, RUN = "ssd:System", "ssd:DefaultExperiment", "ssd:Annotations/ssc:Annotation/fmugen:Run"
CONN0, CONN1 = f"{S}/ssd:Connections/ssd:Connection[0]", f"{S}/ssd:Connections/ssd:Connection[1]"
UNIT = "ssd:Units/ssc:Unit/ssc:BaseUnit"
INLINE_M = (f"{S}/ssd:Elements/ssd:Component[0]/ssd:ParameterBindings/ssd:ParameterBinding/ssd:ParameterValues/"
            f"ssv:ParameterSet/ssv:Parameters/ssv:Parameter/ssv:Real")


def _factor0(s):
    return s.couplings[0].factor


#: numeric slots: (label, file, element path, attribute, type, rule, read(system), expected(value), field regex)
#: rule: "any" | "pos" (> 0) | "before_stop" (< 0.5) | "after_start" (> 0)
SLOTS = [
    ("LinearTransformation factor", "ssd", f"{CONN1}/ssc:LinearTransformation", "factor", "double", "any",
     lambda s: s.couplings[1].factor, lambda x: x, r"factor"),
    ("BaseUnit factor", "ssd", UNIT, "factor", "double", "pos_inverse", _factor0, lambda x: 1.0 / x, r"factor"),
    ("BaseUnit s", "ssd", UNIT, "s", "int", "is:-1", _factor0, lambda x: 1000.0,
     r"BaseUnit s|attribute 's'|different quantities"),
    ("DefaultExperiment stopTime", "ssd", DE, "stopTime", "double", "after_start", lambda s: s.stop_time,
     lambda x: x, r"stopTime"),
    ("DefaultExperiment startTime", "ssd", DE, "startTime", "double", "before_stop", lambda s: s.start_time,
     lambda x: x, r"startTime|stopTime"),
    ("inline Real m", "ssd", INLINE_M, "value", "double", "any", lambda s: s.unit("A").start_values["m"],
     lambda x: x, r"parameter m: Real value"),
    ("SSV Real k", "ssv", "ssv:Parameters/ssv:Parameter/ssv:Real", "value", "double", "any",
     lambda s: s.unit("B").start_values["k"], lambda x: x, r"B\.ssv: .*(parameter k: Real value|'value')"),
    ("suppressUnitConversion", "ssd", CONN0, "suppressUnitConversion", "bool", "any", _factor0,
     lambda b: 1.0 if b else 1000.0, r"suppressUnitConversion"),
    ("Run step", "ssd", RUN, "step", "double", "pos", lambda s: s.step, lambda x: x, r"Run step"),
    ("Run jacobiHoldStep", "ssd", RUN, "jacobiHoldStep", "double", "pos", None, None, r"Run jacobiHoldStep"),
    ("Run jacobiHoldLimit", "ssd", RUN, "jacobiHoldLimit", "double", "pos", None, None, r"Run jacobiHoldLimit"),
    ("Run Start c", "ssd", f"{RUN}/fmugen:Unit[0]/fmugen:Start", "value", "double", "any",
     lambda s: s.unit("A").start_values["c"], lambda x: x, r"Start c value"),
    ("OSP baseStepSize", "ssd", f"{DE}/ssd:Annotations/ssc:Annotation/osp:Algorithm/osp:FixedStepAlgorithm",
     "baseStepSize", "double", "pos", None, None, r"baseStepSize"),
    ("Run directionalDerivatives", "ssd", f"{RUN}/fmugen:Unit[0]", "directionalDerivatives", "bool", "any",
     lambda s: s.unit("A").provides_directional_derivative, lambda b: b, r"directionalDerivatives"),
    ("Setting tol", "ssd", f"{RUN}/fmugen:Setting", "value", "double", "pos", lambda s: s.settings["tol"],
     lambda x: x, r"Setting tol"),
]


def _allowed(rule: str, x) -> bool:
    if rule == "any":
        return True
    if rule == "pos":
        return x > 0
    if rule == "pos_inverse":  # a unit factor: > 0, and the conversion 1 / factor a double
        return x > 0 and 1.0 / x < float("inf")
    if rule == "after_start":
        return x > 0.0
    if rule == "before_stop":
        return x < 0.5
    if rule.startswith("is:"):
        return x == int(rule[3:])
    raise ValueError(rule)


# structural faults, each refused naming the field: (label, edit of the SSD root, field regex)
def _set(path, attr, value):
    return lambda r: _find(r, path).set(attr, value)


def _remove(path):
    def edit(r):
        el = _find(r, path)
        el.getparent().remove(el)
    return edit


def _double(path):
    def edit(r):
        el = _find(r, path)
        el.addnext(copy.deepcopy(el))
    return edit


COMP_A, COMP_B = f"{S}/ssd:Elements/ssd:Component[0]", f"{S}/ssd:Elements/ssd:Component[1]"
STRUCTURE = [
    ("connection to no component", _set(CONN1, "startElement", "Z"), r"no component 'Z'"),
    ("connection to no connector", _set(CONN1, "endConnector", "G"), r"declares no Connector 'G'"),
    ("connection from an input", _set(CONN1, "startConnector", "v_in"), r"B\.v_in is input, not output"),
    ("connection into an output", _set(CONN0, "endConnector", "F"), r"B\.F is output, not input|already driven"),
    ("input driven twice", _double(CONN1), r"already driven"),
    ("component removed", _remove(COMP_A), r"no component 'A'|Order names|Unit A: no component"),
    ("component doubled", _double(COMP_A), r"used twice"),
    ("component renamed with a dot", _set(COMP_B, "name", "B.x"), r"contains '\.'"),
    ("component name with a newline", _set(COMP_B, "name", "B\nx"), r"control"),
    ("component source missing", _set(COMP_A, "source", "resources/nope.fmu"), r"source 'resources/nope\.fmu'"),
    ("component source outside", _set(COMP_A, "source", "../mass.fmu"), r"unsafe path"),
    ("component source absolute", _set(COMP_A, "source", "/etc/passwd"), r"unsafe path"),
    ("component type not an FMU", _set(COMP_A, "type", "application/x-ssp-definition"), r"type .* is not supported"),
    ("implementation ModelExchange", _set(COMP_A, "implementation", "ModelExchange"),
     r"implementation ModelExchange but annotation"),
    ("connector doubled", _double(f"{COMP_A}/ssd:Connectors/ssd:Connector[0]"), r"declared twice"),
    ("connector of no variable", _set(f"{COMP_A}/ssd:Connectors/ssd:Connector[0]", "name", "nosuch"),
     r"Connector 'nosuch': its FMU"),
    ("connector in another unit", _set(f"{COMP_A}/ssd:Connectors/ssd:Connector[0]/ssc:Real", "unit", "mm"),
     r"declared in \[mm\]"),
    ("connector kind wrong", _set(f"{COMP_A}/ssd:Connectors/ssd:Connector[0]", "kind", "input"),
     r"declared input; the FMU's variable is output"),
    ("binding of no variable", _set(INLINE_M.rsplit("/", 1)[0], "name", "nosuch"), r"names 'nosuch'"),
    ("binding doubled", _double(INLINE_M.rsplit("/", 1)[0]), r"parameter m: given twice"),
    ("binding in another quantity", _set(INLINE_M, "unit", "m"), r"different quantities"),
    ("binding source missing", _set(f"{COMP_B}/ssd:ParameterBindings/ssd:ParameterBinding", "source",
                                    "resources/none.ssv"), r"'resources/none\.ssv' is not a file"),
    ("binding source outside", _set(f"{COMP_B}/ssd:ParameterBindings/ssd:ParameterBinding", "source",
                                    "../B.ssv"), r"unsafe path"),
    ("binding source is the SSD", _set(f"{COMP_B}/ssd:ParameterBindings/ssd:ParameterBinding", "source",
                                       "SystemStructure.ssd"), r"not an SSP 1\.0 ParameterSet"),
    ("unit doubled", _double("ssd:Units/ssc:Unit"), r"Unit 'mm/s': defined twice"),
    ("annotation doubled", _double("ssd:Annotations/ssc:Annotation"), r"appears twice"),
    ("annotation emptied", _remove(RUN), r"holds nothing, not fmugen's Run"),
    ("order names no component", lambda r: setattr(_find(r, f"{RUN}/fmugen:Order"), "text", "A Z"),
     r"Order names 'Z'"),
    ("order misses a component", lambda r: setattr(_find(r, f"{RUN}/fmugen:Order"), "text", "A"),
     r"must name every component once"),
    ("order doubled", _double(f"{RUN}/fmugen:Order"), r"Order given 2 times"),
    ("run unit of no component", _set(f"{RUN}/fmugen:Unit[1]", "name", "Z"), r"Unit Z: no component"),
    ("run unit doubled", _double(f"{RUN}/fmugen:Unit[1]"), r"Unit B: given twice"),
    ("run unit Model Exchange", _set(f"{RUN}/fmugen:Unit[1]", "fmiType", "me"), r"asks for Model Exchange"),
    ("run unit type unknown", _set(f"{RUN}/fmugen:Unit[1]", "fmiType", "CS"), r"fmiType 'CS' is neither"),
    ("start of no variable", _set(f"{RUN}/fmugen:Unit[0]/fmugen:Start", "name", "nosuch"), r"Start 'nosuch'"),
    ("start doubled", _double(f"{RUN}/fmugen:Unit[0]/fmugen:Start"), r"Start c: given twice"),
    ("record of no variable", _set(f"{RUN}/fmugen:Record[0]", "variable", "nosuch"), r"no Real variable 'nosuch'"),
    ("record of no component", _set(f"{RUN}/fmugen:Record[0]", "unit", "Z"), r"unit 'Z' is no component"),
    ("record doubled", _double(f"{RUN}/fmugen:Record[0]"), r"Record A\.x: given twice"),
    ("setting unknown", _set(f"{RUN}/fmugen:Setting", "name", "tolerance_x"), r"unknown key 'tolerance_x'"),
    ("setting doubled", _double(f"{RUN}/fmugen:Setting"), r"Setting tol: given twice"),
    ("scheme unknown", _set(RUN, "scheme", "runge"), r"scheme 'runge'"),
    ("run version", _set(RUN, "version", "7"), r"version '7'"),
    ("run stop before start", _set(RUN, "stopTime", "-1"), r"Run stopTime '-1' is not after"),
    ("system without components", lambda r: _empty_system(r), r"has no components|ssd:Elements"),
]

def _empty_system(root):
    for c in root.findall(f"{_q(S)}/{_q('ssd:Elements')}/{_q('ssd:Component')}"):
        c.getparent().remove(c)
    _remove(f"{S}/ssd:Connections")(root)


# the archive itself: (label, edit of the member list [(name, bytes, ZipInfo attributes)], regex)
ZIP = [
    ("SSD missing", lambda m: [x for x in m if x[0] != "SystemStructure.ssd"], r"no SystemStructure\.ssd"),
    ("SSV missing", lambda m: [x for x in m if x[0] != "resources/B.ssv"], r"'resources/B\.ssv' is not a file"),
    ("FMU missing", lambda m: [x for x in m if x[0] != "resources/mass.fmu"], r"source 'resources/mass\.fmu'"),
    ("zip slip", lambda m: m + [("../evil.txt", b"x", {})], r"unsafe path"),
    ("absolute member", lambda m: m + [("/tmp/evil.txt", b"x", {})], r"unsafe path"),
    ("backslash member", lambda m: m + [("resources\\evil.txt", b"x", {})], r"unsafe path"),
    ("symbolic link", lambda m: m + [("resources/link", b"/etc/passwd",
                                      {"external_attr": (stat.S_IFLNK | 0o777) << 16})],
     r"symbolic link"),
    ("member twice", lambda m: m + [m[0]], r"appears twice"),
    ("file where a folder is", lambda m: [("resources", b"x", {})] + m, r"cannot be extracted|appears twice"),
    ("FMU not a zip", lambda m: [(n, b"not a zip" if n == "resources/mass.fmu" else d, a) for n, d, a in m],
     r"component A \(mass\.fmu\): not an FMU"),
    ("FMU without description", lambda m: [(n, _fmu_without(d, "modelDescription.xml") if n == "resources/mass.fmu"
                                            else d, a) for n, d, a in m], r"not an FMU"),
    ("FMU of FMI 3.0", lambda m: [(n, _fmu_edit(d, b'fmiVersion="2.0"', b'fmiVersion="3.0"')
                                   if n == "resources/mass.fmu" else d, a) for n, d, a in m],
     r"does not follow the FMI 3\.0 schema: .*attribute .guid."),  # FMI 2.0 content labelled 3.0
    ("FMU description broken", lambda m: [(n, _fmu_edit(d, b"<ModelVariables>", b"<ModelVariables")
                                           if n == "resources/mass.fmu" else d, a) for n, d, a in m],
     r"modelDescription\.xml: not well-formed"),
    ("FMU description with DOCTYPE", lambda m: [(n, _fmu_edit(d, b"<fmiModelDescription",
                                                              b"<!DOCTYPE x [<!ENTITY e 'x'>]><fmiModelDescription")
                                                 if n == "resources/mass.fmu" else d, a) for n, d, a in m],
     r"DOCTYPE"),
    ("SSD with DOCTYPE", lambda m: [(n, d.replace(b"<ssd:SystemStructureDescription",
                                                  b"<!DOCTYPE x [<!ENTITY e SYSTEM 'file:///etc/passwd'>]>"
                                                  b"<ssd:SystemStructureDescription", 1)
                                     if n == "SystemStructure.ssd" else d, a) for n, d, a in m], r"DOCTYPE"),
    ("SSD not UTF-8 XML", lambda m: [(n, b"\xff\xfe<x" if n == "SystemStructure.ssd" else d, a) for n, d, a in m],
     r"not well-formed"),
]


def _fmu_edit(data: bytes, old: bytes, new: bytes) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(data)) as zi, zipfile.ZipFile(buf, "w") as zo:
        for i in zi.infolist():
            d = zi.read(i)
            zo.writestr(i, d.replace(old, new, 1) if i.filename == "modelDescription.xml" else d)
    return buf.getvalue()


def _fmu_replace(data: bytes, member: str, new: bytes) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(data)) as zi, zipfile.ZipFile(buf, "w") as zo:
        for i in zi.infolist():
            zo.writestr(i, new if i.filename == member else zi.read(i))
    return buf.getvalue()


def _fmu_without(data: bytes, member: str) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(data)) as zi, zipfile.ZipFile(buf, "w") as zo:
        for i in zi.infolist():
            if i.filename != member:
                zo.writestr(i, zi.read(i))
    return buf.getvalue()


HOSTILE_TEXT = ["", " ", "\u202e", "A", "B", "x" * 3000, "é", "..", "../x", "A.v", "<", "&amp;", "0", "-1", "NaN",
                "\t", "名前", "resources/mass.fmu", "true", "1e999"]

CLASSES = ("number", "structure", "zip", "random", "fmu")
OUTCOMES = ("cases", "accepted", "refused", "crash", "silent-wrong", "false refusal", "bad message")


class Runner:
    def __init__(self, seed: int, workdir: Path):
        from ssp_third_party import build_fmus

        self.rng = random.Random(seed)
        self.seed = seed
        self.dir = Path(workdir)
        self.fmus = build_fmus(self.dir / "fmus")
        self.fmu_bytes = {k: Path(v).read_bytes() for k, v in self.fmus.items()}
        self.counts = {c: dict.fromkeys(OUTCOMES, 0) for c in CLASSES}
        self.findings = []
        self.base = self.load_base()

    def load_base(self):
        """The unmutated archive loads, with the values the mutations are measured against (else every
        "must be refused" would pass for the wrong reason)."""
        from fmugen.ssp import load_system

        ssd, ssv = self.roots()
        s = load_system(self.write(-1, self.members(self.text(ssd), self.text(ssv))), workdir=self.dir / "base")
        got = (s.couplings[0].factor, s.couplings[1].factor, s.unit("A").start_values, s.unit("B").start_values,
               s.step, s.start_time, s.stop_time, s.order, dict(s.settings), [r.column for r in s.recorded])
        want = (1000.0, 1.0, {"c": 150.0, "m": 1.0}, {"k": 40000.0}, 0.001, 0.0, 0.5, ("A", "B"),
                {"tol": 0.0001, "scheme": "newton", "extrapolation": "linear"}, ["A.x", "B.F"])
        if got != want:
            raise AssertionError(f"the base archive reads as {got}, not {want}")
        return s

    # -- the archive -------------------------------------------------------------------------
    def members(self, ssd: bytes, ssv: bytes) -> list:
        return [("SystemStructure.ssd", ssd, {}), ("resources/B.ssv", ssv, {}),
                ("resources/mass.fmu", self.fmu_bytes["mass"], {}),
                ("resources/spring.fmu", self.fmu_bytes["spring"], {})]

    def write(self, n: int, members: list) -> Path:
        path = self.dir / f"case_{n}.ssp"
        with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as zf:
            for name, data, attrs in members:
                info = zipfile.ZipInfo(name, (2026, 1, 1, 0, 0, 0))
                for k, v in attrs.items():
                    setattr(info, k, v)
                zf.writestr(info, data)
        return path

    @staticmethod
    def roots():
        from lxml import etree

        return etree.fromstring(BASE_SSD.encode()), etree.fromstring(BASE_SSV.encode())

    @staticmethod
    def text(root) -> bytes:
        from lxml import etree

        return etree.tostring(root, xml_declaration=True, encoding="UTF-8")

    # -- the verdict -------------------------------------------------------------------------
    def check(self, cls: str, n: int, what: str, path: Path, expect: str, field: str = None, read=None,
              want=None) -> None:
        """``expect``: "refuse", "honour" (then ``read(system) == want``) or "any"."""
        import shutil

        from fmugen.errors import FmugenError
        from fmugen.ssp import load_system

        c = self.counts[cls]
        c["cases"] += 1
        work = self.dir / f"work_{n}"
        tag = f"{cls} #{n} (seed {self.seed}): {what}"
        try:
            system = load_system(path, workdir=work)
        except FmugenError as e:
            c["refused"] += 1
            msg = str(e)
            if expect == "honour":
                c["false refusal"] += 1
                self.findings.append(f"{tag}: a valid value refused: {msg[:300]}")
            elif "\n" in msg.strip() or not msg.startswith(f"{path}: "):
                c["bad message"] += 1
                self.findings.append(f"{tag}: a refusal of several lines or not naming the archive: {msg[:300]!r}")
            elif not re.search(r"SystemStructure\.ssd|\.ssv|\.fmu|archive member|not an SSP archive", msg):
                c["bad message"] += 1
                self.findings.append(f"{tag}: a refusal naming no file inside the archive: {msg[:300]!r}")
            elif field and not re.search(field, msg):
                c["bad message"] += 1
                self.findings.append(f"{tag}: a refusal not naming the field /{field}/: {msg[:300]!r}")
            return
        except Exception as e:  # noqa: BLE001 - any other exception is a finding
            c["crash"] += 1
            tb = traceback.format_exc(limit=4).strip().splitlines()
            self.findings.append(f"{tag}: {type(e).__name__}: {str(e)[:200]} ({tb[-3].strip()[:200]})")
            return
        finally:
            shutil.rmtree(work, ignore_errors=True)
            path.unlink(missing_ok=True)
        c["accepted"] += 1
        if expect == "refuse":
            c["silent-wrong"] += 1
            self.findings.append(f"{tag}: accepted, must be refused")
        elif expect == "honour" and read is not None:
            try:
                got = read(system)
            except Exception as e:  # noqa: BLE001
                got = f"<{type(e).__name__}: {e}>"
            same = got == want and not (isinstance(got, float) and isinstance(want, float)
                                        and math.copysign(1, got) != math.copysign(1, want))  # -0.0 is not 0.0
            if not same:
                c["silent-wrong"] += 1
                self.findings.append(f"{tag}: read as {got!r}, the archive says {want!r}")

    # -- the four classes --------------------------------------------------------------------
    def number(self, n: int) -> None:
        rng = self.rng
        label, file, where, attr, kind, rule, read, expected, field = rng.choice(SLOTS)
        ssd, ssv = self.roots()
        root = ssd if file == "ssd" else ssv
        el = _find(root, where)
        r = rng.random()
        if kind == "double":
            if r < 0.35:
                text, expect, value = rng.choice(NOT_XS_DOUBLE), "refuse", None
            elif r < 0.5:
                text, expect, value = rng.choice(NON_FINITE), "refuse", None
            else:
                value = rng.choice(VALUES)
                text = rng.choice(spellings(value))
                expect = "honour" if _allowed(rule, value) else "refuse"
        elif kind == "int":
            if r < 0.5:
                text, expect, value = rng.choice(NOT_XS_INT), "refuse", None
            else:
                value = rng.choice([-1, -1, 0, 1, 2, -2, 7])
                text = rng.choice([str(value), f" {value} ", ("+" if value >= 0 else "-") + "0" + str(abs(value))])
                expect = "honour" if _allowed(rule, value) else "refuse"
        else:  # bool
            if r < 0.5:
                text, expect, value = rng.choice(NOT_XS_BOOL), "refuse", None
            else:
                text = rng.choice(["true", "false", "1", "0", " true ", "\tfalse\n"])
                value, expect = text.strip() in ("true", "1"), "honour"
        el.set(attr, text)
        want = expected(value) if expect == "honour" and expected else None
        path = self.write(n, self.members(self.text(ssd), self.text(ssv)))
        self.check("number", n, f"{label} = {text[:40]!r}", path, expect, field if expect == "refuse" else None,
                   read if expect == "honour" else None, want)

    def structure(self, n: int) -> None:
        label, edit, field = self.rng.choice(STRUCTURE)
        ssd, ssv = self.roots()
        edit(ssd)
        path = self.write(n, self.members(self.text(ssd), self.text(ssv)))
        self.check("structure", n, label, path, "refuse", field)

    def zip(self, n: int) -> None:
        label, edit, field = self.rng.choice(ZIP)
        ssd, ssv = self.roots()
        members = edit(self.members(self.text(ssd), self.text(ssv)))
        path = self.write(n, members)
        self.check("zip", n, label, path, "refuse", field)

    def random(self, n: int) -> None:
        rng = self.rng
        ssd, ssv = self.roots()
        root = ssd if rng.random() < 0.85 else ssv
        elements = [e for e in root.iter() if isinstance(e.tag, str)]
        el = rng.choice(elements)
        kind = rng.randrange(6)
        if kind == 0 and el is not root:
            el.getparent().remove(el)
            what = f"{el.tag.split('}')[-1]} removed"
        elif kind == 1 and el is not root:
            el.addnext(copy.deepcopy(el))
            what = f"{el.tag.split('}')[-1]} doubled"
        elif kind == 2 and el.attrib:
            attr = rng.choice(sorted(el.attrib))
            value = rng.choice(HOSTILE_TEXT + NOT_XS_DOUBLE[:8])
            el.set(attr, value)
            what = f"{el.tag.split('}')[-1]} {attr} = {value[:30]!r}"
        elif kind == 3:
            data = self.text(ssd)
            cut = rng.randrange(len(data))
            path = self.write(n, [("SystemStructure.ssd", data[:cut], {})] + self.members(b"", self.text(ssv))[1:])
            return self.check("random", n, f"SSD cut at byte {cut}", path, "any")
        elif kind == 4:
            data = bytearray(self.text(ssd))
            pos = rng.randrange(len(data))
            data[pos:pos] = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 5)))
            path = self.write(n, [("SystemStructure.ssd", bytes(data), {})] + self.members(b"", self.text(ssv))[1:])
            return self.check("random", n, f"bytes inserted at {pos}", path, "any")
        else:
            data = bytearray(self.write(n, self.members(self.text(ssd), self.text(ssv))).read_bytes())
            pos = rng.randrange(len(data))
            data[pos] ^= 1 << rng.randrange(8)  # a flipped bit anywhere: headers, CRCs, the FMUs' bytes
            path = self.dir / f"case_{n}.ssp"
            path.write_bytes(bytes(data))
            return self.check("random", n, f"bit flipped at byte {pos}", path, "any")
        path = self.write(n, self.members(self.text(ssd), self.text(ssv)))
        self.check("random", n, what, path, "any")

    def fmu(self, n: int) -> None:
        """One FMU's modelDescription.xml damaged (an attribute hostile, an element gone or doubled): the
        FMU is someone else's file too; refused naming the component and the FMU, or accepted."""
        from lxml import etree

        rng = self.rng
        with zipfile.ZipFile(io.BytesIO(self.fmu_bytes["mass"])) as zf:
            md = etree.fromstring(zf.read("modelDescription.xml"))
        elements = [e for e in md.iter() if isinstance(e.tag, str)]
        el = rng.choice(elements)
        kind = rng.randrange(3)
        if kind == 0 and el.attrib:
            attr = rng.choice(sorted(el.attrib))
            value = rng.choice(HOSTILE_TEXT + NOT_XS_DOUBLE[:8] + ["a\nb", "x\u2028y"])
            el.set(attr, value)
            what = f"modelDescription {el.tag} {attr} = {value[:30]!r}"
        elif kind == 1 and el is not md:
            el.getparent().remove(el)
            what = f"modelDescription {el.tag} removed"
        elif el is not md:
            el.addnext(copy.deepcopy(el))
            what = f"modelDescription {el.tag} doubled"
        else:
            what = "modelDescription unchanged"
        data = _fmu_replace(self.fmu_bytes["mass"], "modelDescription.xml", etree.tostring(md))
        ssd, ssv = self.roots()
        members = [(m, data if m == "resources/mass.fmu" else d, a) for m, d, a in
                   self.members(self.text(ssd), self.text(ssv))]
        self.check("fmu", n, what, self.write(n, members), "any")

    def run(self, cases: int) -> None:
        for n in range(cases):
            getattr(self, CLASSES[n % len(CLASSES)])(n)

    def table(self) -> str:
        head = f"{'class':<10}" + "".join(f"{o:>15}" for o in OUTCOMES)
        rows = [f"{c:<10}" + "".join(f"{self.counts[c][o]:>15}" for o in OUTCOMES) for c in CLASSES]
        total = f"{'all':<10}" + "".join(f"{sum(self.counts[c][o] for c in CLASSES):>15}" for o in OUTCOMES)
        return "\n".join([f"SSP fuzz, seed {self.seed}: {len(self.findings)} findings", head, *rows, total])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=400)
    ap.add_argument("--seed", type=int, default=20261203)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="fmugen_fuzz_ssp_") as d:
        r = Runner(args.seed, Path(d))
        r.run(args.cases)
        for f in r.findings:
            print("FINDING", f)
        print(r.table())
    return 1 if r.findings else 0


if __name__ == "__main__":
    sys.exit(main())
