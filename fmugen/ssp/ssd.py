"""Read and validate an SSP archive (System Structure and Parameterization 1.0): untrusted input.

One module reads, the loader (:mod:`fmugen.ssp.loader`) runs -- the split of
libcosim's ``ssp_parser``/``ssp_loader`` and FMPy's ``fmpy.ssp.ssd``.  What
comes out is plain data (:class:`Ssd`); nothing here runs an FMU.

An ``.ssp`` is a zip archive from anyone, so:

* **paths**: every member name is checked before anything is written --
  no absolute paths, no drive letters, no ``..``, no backslashes, no
  symbolic links (zip entries whose Unix mode says "link"), nothing that
  resolves outside the extraction folder (zip slip);
* **sizes**: at most :data:`MAX_MEMBERS` members, :data:`MAX_TOTAL_BYTES`
  uncompressed in all, :data:`MAX_XML_BYTES` per XML file; the sizes the
  archive declares are not trusted: extraction stops when more bytes come
  out than declared;
* **XML**: parsed by lxml with ``resolve_entities=False`` (no entity
  expansion: no "billion laughs", no external entities reading local
  files), ``no_network=True``, ``load_dtd=False`` and ``huge_tree=False``;
  a DOCTYPE is refused outright (SSP files have none).  lxml, not the
  standard library's ElementTree, because lxml also validates against XML
  Schema, which the standard library cannot do; the SSP schemas are the
  ones FMPy ships (``fmpy/ssp/schema``);
* **values**: every numeric attribute is read by its XML Schema grammar
  (:func:`fmugen.values.parse_xs_double`, ``parse_xs_int``, ``parse_xs_boolean``:
  ``1_5``, Arabic-Indic digits, ``infinity`` are not numbers there, as they are
  to Python's ``float()``), every name is checked for control characters,
  every reference (a connection's component and connector, a binding's file)
  must exist, and nothing may be given twice; a refusal is one line naming the
  archive, the file inside it, the element and the attribute;
* every SSD and SSV is validated against those schemas before it is read,
  and what fmugen does not support is refused with one line each: signal
  dictionaries, parameter mappings (.ssm), nested systems, connections to
  the system's own connectors, non-Real connectors, FMI 1.0/3.0 components,
  non-FMU components.
"""
from __future__ import annotations

import stat
import unicodedata
import zipfile
import zlib
from dataclasses import dataclass, field, replace
from pathlib import Path, PurePosixPath
from typing import Optional

from ..errors import InputFileError
from ..values import parse_xs_boolean, parse_xs_double, parse_xs_int

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "ssm": "http://ssp-standard.org/SSP1/SystemStructureParameterMapping",
    "ssb": "http://ssp-standard.org/SSP1/SystemStructureSignalDictionary",
}
#: fmugen's own annotation (its run settings): a URN, an identifier that names no web address
FMUGEN_NS = "urn:fmugen:ssp:1"
FMUGEN_ANNOTATION = "org.fmugen.run"
#: the Open Simulation Platform's annotation that gives libcosim its fixed step
OSP_NS = "http://opensimulationplatform.com/SSP/OSPAnnotations"
OSP_ANNOTATION = "com.opensimulationplatform"

MAX_MEMBERS = 4096
MAX_TOTAL_BYTES = 2 << 30  # 2 GiB uncompressed
MAX_XML_BYTES = 64 << 20  # 64 MiB per SSD/SSV
SSD_NAME = "SystemStructure.ssd"


@dataclass(frozen=True)
class Connector:
    name: str
    kind: str  # input, output, parameter, calculatedParameter, inout
    type: str  # Real, Integer, Boolean, String, Enumeration, Binary, or "" when not given
    unit: str = ""


@dataclass(frozen=True)
class Component:
    name: str
    source: str  # archive-relative path of the FMU
    type: str
    connectors: tuple  # of Connector
    parameters: dict = field(default_factory=dict)  # bound values: variable name -> number (Real or Integer)
    fmu_path: Optional[Path] = None  # extracted FMU
    implementation: str = "any"  # the SSD's choice of FMI interface: any, CoSimulation, ModelExchange
    parameter_units: dict = field(default_factory=dict)  # variable name -> the unit its bound Real value is in


@dataclass(frozen=True)
class Connection:
    start: tuple  # (component, connector)
    end: tuple  # (component, connector)
    factor: float = 1.0
    offset: float = 0.0
    transformed: bool = False  # a LinearTransformation was given
    suppress_unit_conversion: bool = False  # the connection's suppressUnitConversion


@dataclass
class Ssd:
    path: Path  # the .ssp (or the folder holding SystemStructure.ssd)
    name: str
    system: str
    components: dict  # name -> Component, in file order
    connections: list
    units: dict  # unit name -> {"kg": int, ..., "rad": int, "factor": float, "offset": float} (checked numbers)
    start_time: Optional[float] = None
    stop_time: Optional[float] = None
    annotations: dict = field(default_factory=dict)  # type -> the annotation's child element (lxml)
    folder: Optional[Path] = None  # where the archive was extracted


def _schema_dir() -> Path:
    import fmpy

    d = Path(fmpy.__file__).resolve().parent / "ssp" / "schema"
    if not (d / "SystemStructureDescription.xsd").is_file():
        raise InputFileError(f"the SSP 1.0 schemas are not where fmpy keeps them ({d}): reinstall fmpy")
    return d


_SCHEMAS = {}


def schema(name: str):
    """The lxml XMLSchema of ``name`` (e.g. "SystemStructureDescription.xsd"), loaded once, offline."""
    from lxml import etree

    if name not in _SCHEMAS:
        parser = etree.XMLParser(resolve_entities=False, no_network=True)
        _SCHEMAS[name] = etree.XMLSchema(etree.parse(str(_schema_dir() / name), parser))
    return _SCHEMAS[name]


def parse_xml(data: bytes, where: str):
    """The root element of ``data``, parsed without entity expansion, DTDs or network access."""
    from lxml import etree

    if len(data) > MAX_XML_BYTES:
        raise InputFileError(f"{where}: {len(data)} bytes, more than the {MAX_XML_BYTES} an SSP XML file may have")
    if b"<!DOCTYPE" in data or b"<!ENTITY" in data:
        raise InputFileError(f"{where}: has a DOCTYPE or entity declaration; SSP files have none (refused: "
                             f"entity expansion)")
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, huge_tree=False,
                             remove_comments=True)
    try:
        return etree.fromstring(data, parser)
    except etree.XMLSyntaxError as exc:  # libxml2's message may hold a newline ("out of allowed range\n, line")
        raise InputFileError(f"{where}: not well-formed XML: {' '.join(str(exc).split())[:400]}") from None


def validate(root, schema_name: str, where: str) -> None:
    s = schema(schema_name)
    if not s.validate(root):
        e = s.error_log.last_error
        message = " ".join(e.message.split())  # one line, whatever the file put into the value
        for prefix, uri in NS.items():  # libxml2 names elements {namespace}Name: as the files write them
            message = message.replace(f"{{{uri}}}", f"{prefix}:")
        raise InputFileError(f"{where}: does not validate against the SSP 1.0 schema ({schema_name}): line "
                             f"{e.line}: {message[:400]}")


# ---------------------------------------------------------------------------- archive
def _safe_member(name: str, where: str) -> PurePosixPath:
    p = PurePosixPath(name)
    if not name or "\\" in name or name.startswith("/") or (len(name) > 1 and name[1] == ":") \
            or any(part in ("..", "") for part in p.parts if part != "/") or "\x00" in name:
        raise InputFileError(f"{where}: archive member {name!r} has an unsafe path (absolute, '..', drive or "
                             f"backslash): refused")
    return p


def extract(ssp: Path, dest: Path) -> None:
    """Extract the archive ``ssp`` into the empty folder ``dest`` under the rules of the module doc."""
    where = str(ssp)
    try:
        zf = zipfile.ZipFile(ssp)
    except (zipfile.BadZipFile, OSError, EOFError, ValueError, NotImplementedError) as exc:
        raise InputFileError(f"{where}: not an SSP archive (zip): {' '.join(str(exc).split())[:300]}") from None
    with zf:
        infos = zf.infolist()
        if len(infos) > MAX_MEMBERS:
            raise InputFileError(f"{where}: {len(infos)} members, more than {MAX_MEMBERS}")
        if sum(i.file_size for i in infos) > MAX_TOTAL_BYTES:
            raise InputFileError(f"{where}: declares more than {MAX_TOTAL_BYTES} bytes uncompressed")
        root = dest.resolve()
        total = 0
        seen = set()
        for info in infos:
            rel = _safe_member(info.filename, where)
            key = PurePosixPath(*rel.parts).as_posix().rstrip("/")
            if key in seen:  # else open(.., "xb") fails with an OSError naming the temporary folder
                raise InputFileError(f"{where}: archive member {info.filename!r} appears twice: refused")
            seen.add(key)
            mode = info.external_attr >> 16
            if stat.S_ISLNK(mode):
                raise InputFileError(f"{where}: archive member {info.filename!r} is a symbolic link: refused")
            target = (root / Path(*rel.parts)).resolve()
            if root != target and root not in target.parents:
                raise InputFileError(f"{where}: archive member {info.filename!r} leads outside the extraction "
                                     f"folder: refused")
            try:
                total = _extract_member(zf, info, target, total, where)
            except OSError as exc:  # a member over a file of the same name ("a", then "a/b"), a full disk
                raise InputFileError(f"{where}: archive member {info.filename!r} cannot be extracted: "
                                     f"{exc.strerror or exc}") from None
            except (zipfile.BadZipFile, zlib.error, EOFError, NotImplementedError, RuntimeError) as exc:
                # a CRC error, corrupt deflate data, a compression method or an encryption zipfile lacks
                raise InputFileError(f"{where}: archive member {info.filename!r} cannot be read: "
                                     f"{' '.join(str(exc).split()) or type(exc).__name__}") from None


def _extract_member(zf, info, target: Path, total: int, where: str) -> int:
    """Write one member to ``target`` (no more bytes than it declares); the running total of bytes."""
    if info.is_dir():
        target.mkdir(parents=True, exist_ok=True)
        return total
    target.parent.mkdir(parents=True, exist_ok=True)
    written = 0
    with zf.open(info) as src, open(target, "xb") as out:
        while True:
            chunk = src.read(1 << 20)
            if not chunk:
                break
            written += len(chunk)
            total += len(chunk)
            if written > info.file_size or total > MAX_TOTAL_BYTES:
                raise InputFileError(f"{where}: archive member {info.filename!r} inflates beyond its "
                                     f"declared size: refused")
            out.write(chunk)
    return total


# ---------------------------------------------------------------------------- SSD and SSV
# Every attribute read below goes through one of these: numbers by the XML Schema grammar of their
# type (fmugen.values: xs:double, xs:int, xs:boolean), names checked for what would break a message,
# a column name or a line of a CSV header.  A refusal names the archive, the file inside it, the
# element and the attribute.
MAX_NAME_LENGTH = 1024


def _float(el, attr: str, where: str, default=None) -> Optional[float]:
    """The finite xs:double attribute ``attr`` of ``el`` (``default`` when absent)."""
    v = el.get(attr)
    if v is None:
        return default
    return parse_xs_double(v, f"{where} {attr}")


def _bool(el, attr: str, where: str, default: bool = False) -> bool:
    v = el.get(attr)
    return default if v is None else parse_xs_boolean(v, f"{where} {attr}")


def _name(el, attr: str, where: str, required: bool = True, dot: bool = True) -> Optional[str]:
    """The name attribute ``attr`` of ``el``: present (when ``required``), not empty, without control
    characters (a newline in a name would split a one-line message and a CSV header), bounded; with
    ``dot=False`` also without '.' (component names: fmugen's signals are 'component.connector')."""
    v = el.get(attr)
    if v is None:
        if required:
            raise InputFileError(f"{where}: no {attr} attribute")
        return None
    if not v.strip():
        raise InputFileError(f"{where} {attr}: empty")
    if len(v) > MAX_NAME_LENGTH:
        raise InputFileError(f"{where} {attr}: {len(v)} characters ({v[:20]!r}...), more than {MAX_NAME_LENGTH}")
    if any(unicodedata.category(ch) in ("Cc", "Cf", "Cs", "Co", "Cn", "Zl", "Zp") for ch in v):
        raise InputFileError(f"{where} {attr}: {v!r} contains control or unassigned characters")
    if not dot and "." in v:
        raise InputFileError(f"{where} {attr}: {v!r} contains '.'; fmugen names a component's signals "
                             f"'component.connector', so component names cannot (rename the component)")
    return v


def _q(prefix: str, tag: str) -> str:
    return f"{{{NS[prefix]}}}{tag}"


def _units(parent, where: str, units: dict) -> dict:
    """The ``ssc:Unit`` definitions under ``parent`` added to ``units`` (name -> exponents, factor, offset):
    exponents xs:int, factor a finite xs:double > 0 (a conversion divides by it), offset finite; a name
    defined twice (differently, when ``units`` came from another file) is refused."""
    from ..fmi.units import BASE

    own = set()
    for u in parent.iterfind("ssc:Unit", NS):
        name = _name(u, "name", f"{where}: Unit")
        uw = f"{where}: Unit {name!r}: BaseUnit"
        b = u.find("ssc:BaseUnit", NS)
        if b is None:
            raise InputFileError(f"{where}: Unit {name!r}: no BaseUnit")
        d = {k: parse_xs_int(b.get(k), f"{uw} {k}") if b.get(k) is not None else 0 for k in BASE}
        d["factor"] = parse_xs_double(b.get("factor", "1"), f"{uw} factor")
        d["offset"] = parse_xs_double(b.get("offset", "0"), f"{uw} offset")
        if not d["factor"] > 0:
            raise InputFileError(f"{uw} factor: {b.get('factor')!r} is not positive (a unit is a positive multiple "
                                 f"of its SI base units)")
        if name in own or (name in units and units[name] != d):
            raise InputFileError(f"{where}: Unit {name!r}: defined twice" + ("" if name in own else
                                                                            " (differently in another file)"))
        own.add(name)
        units[name] = d
    return units


def _parameter_set(root, where: str, units: dict) -> tuple:
    """({parameter name: value}, {parameter name: unit of its Real value}) of an ssv:ParameterSet; its own
    unit definitions go into ``units``."""
    out, out_units = {}, {}
    for ue in root.iterfind("ssv:Units", NS):
        _units(ue, where, units)
    for p in root.iterfind("ssv:Parameters/ssv:Parameter", NS):
        name = _name(p, "name", f"{where}: Parameter")
        pw = f"{where}: parameter {name}"
        if name in out:
            raise InputFileError(f"{pw}: given twice (which value is meant?)")
        real, integer = p.find("ssv:Real", NS), p.find("ssv:Integer", NS)
        if real is not None:
            if real.get("value") is None:
                raise InputFileError(f"{pw}: Real: no value attribute")
            out[name] = _float(real, "value", f"{pw}: Real")
            unit = _name(real, "unit", f"{pw}: Real", required=False)
            if unit:
                out_units[name] = unit
        elif integer is not None:
            out[name] = parse_xs_int(integer.get("value"), f"{pw}: Integer value")
        else:
            kind = etree_local(p[0]) if len(p) else "no value element"
            raise InputFileError(f"{pw}: {kind} values are not supported (Real and Integer are)")
    return out, out_units


def etree_local(el) -> str:
    return el.tag.rsplit("}", 1)[-1] if isinstance(el.tag, str) else str(el.tag)


def _read_member(folder: Path, rel: str, where: str) -> bytes:
    p = _safe_member(rel, where)
    path = (folder / Path(*p.parts)).resolve()
    if folder.resolve() not in path.parents or not path.is_file():
        raise InputFileError(f"{where}: {rel!r} is not a file of the archive")
    if path.stat().st_size > MAX_XML_BYTES:
        raise InputFileError(f"{where}: {rel} is larger than {MAX_XML_BYTES} bytes")
    return path.read_bytes()


def _annotations(parent, where: str, prefix: str, out: dict) -> None:
    for a in parent.iterfind("ssd:Annotations/ssc:Annotation", NS):
        t = _name(a, "type", f"{where}: Annotation")
        if prefix + t in out:
            raise InputFileError(f"{where}: Annotation type {t!r} appears twice (which one is meant?)")
        out[prefix + t] = a[0] if len(a) else None


def _component(c, folder: Path, origin: Path, where: str, units: dict) -> Component:
    name = _name(c, "name", f"{where}: Component", dot=False)
    cw = f"{where}: component {name}"
    ctype = c.get("type", "application/x-fmu-sharedlibrary")
    if ctype != "application/x-fmu-sharedlibrary":
        raise InputFileError(f"{cw}: type {ctype!r} is not supported (FMUs only)")
    implementation = c.get("implementation", "any")
    if implementation not in ("any", "CoSimulation", "ModelExchange"):
        raise InputFileError(f"{cw}: implementation {implementation!r} is not supported")
    source = _name(c, "source", cw)
    conns, seen = [], set()
    for k in c.iterfind("ssd:Connectors/ssd:Connector", NS):
        kname = _name(k, "name", f"{cw}: Connector")
        if kname in seen:
            raise InputFileError(f"{cw}: Connector {kname!r} is declared twice")
        seen.add(kname)
        t = next((etree_local(x) for x in k if etree_local(x) in
                  ("Real", "Integer", "Boolean", "String", "Enumeration", "Binary")), "")
        unit = ""
        if t == "Real":
            unit = _name(k.find("ssc:Real", NS), "unit", f"{cw}: Connector {kname!r}: Real", required=False) or ""
        conns.append(Connector(kname, k.get("kind"), t, unit))
    params, param_units = {}, {}
    for b in c.iterfind("ssd:ParameterBindings/ssd:ParameterBinding", NS):
        bw = f"{cw}: parameter binding"
        if b.find("ssd:ParameterMapping", NS) is not None:
            raise InputFileError(f"{bw}: parameter mappings (.ssm) are not supported")
        if b.get("type", "application/x-ssp-parameter-set") != "application/x-ssp-parameter-set":
            raise InputFileError(f"{bw}: type {b.get('type')!r} is not supported")
        if b.get("sourceBase", "SSD") != "SSD":
            raise InputFileError(f"{bw}: sourceBase {b.get('sourceBase')!r} is not supported (SSD)")
        prefix = b.get("prefix", "")
        if prefix:
            _name(b, "prefix", bw)
        src = _name(b, "source", bw, required=False)
        inline = b.find("ssd:ParameterValues/ssv:ParameterSet", NS)
        if src is not None and inline is not None:
            raise InputFileError(f"{bw}: both a source {src!r} and inline ParameterValues (which is meant?)")
        if src is not None:
            ssv = parse_xml(_read_member(folder, src, bw), f"{origin}: {src}")
            if ssv.tag != _q("ssv", "ParameterSet"):
                raise InputFileError(f"{origin}: {src}: the root element is {etree_local(ssv)}, not an SSP 1.0 "
                                     f"ParameterSet")
            validate(ssv, "SystemStructureParameterValues.xsd", f"{origin}: {src}")
            values, vunits = _parameter_set(ssv, f"{origin}: {src}", units)
        else:
            values, vunits = _parameter_set(inline, bw, units) if inline is not None else ({}, {})
        for k, v in values.items():
            # SSP 1.0 (SystemStructureDescription.xsd, ParameterBinding/@prefix): "the specified prefix is
            # prepended to all names in the parameter source" -- not stripped from them
            if prefix + k in params:
                raise InputFileError(f"{bw}: {prefix + k!r} is bound by two parameter bindings (which value is "
                                     f"meant?)")
            params[prefix + k] = v
            if k in vunits:
                param_units[prefix + k] = vunits[k]
    return Component(name, source, ctype, tuple(conns), params, None, implementation, param_units)


def _connection(e, components: dict, where: str) -> Connection:
    cw0 = f"{where}: Connection"
    se, ee = (_name(e, a, cw0, required=False) for a in ("startElement", "endElement"))
    sc, ec = (_name(e, a, cw0) for a in ("startConnector", "endConnector"))
    cw = f"{where}: connection {se}.{sc} -> {ee}.{ec}"
    if se is None or ee is None:
        raise InputFileError(f"{cw}: connections to the system's own connectors are not supported")
    for comp, conn in ((se, sc), (ee, ec)):
        if comp not in components:
            raise InputFileError(f"{cw}: no component {comp!r} (components: {', '.join(components) or 'none'})")
        if conn not in {k.name for k in components[comp].connectors}:
            raise InputFileError(f"{cw}: component {comp} declares no Connector {conn!r}")
    lin = e.find("ssc:LinearTransformation", NS)
    if lin is None:  # FMPy writes and reads it in the ssd namespace
        lin = e.find("ssd:LinearTransformation", NS)
    if any(e.find(f"ssc:{t}", NS) is not None for t in ("BooleanMappingTransformation",
                                                        "IntegerMappingTransformation",
                                                        "EnumerationMappingTransformation")):
        raise InputFileError(f"{cw}: mapping transformations are not supported (LinearTransformation is)")
    f = _float(lin, "factor", f"{cw}: LinearTransformation", 1.0) if lin is not None else 1.0
    o = _float(lin, "offset", f"{cw}: LinearTransformation", 0.0) if lin is not None else 0.0
    return Connection((se, sc), (ee, ec), f, o, lin is not None, _bool(e, "suppressUnitConversion", cw))


def read_ssd(folder: Path, origin: Path) -> Ssd:
    """The system of ``folder/SystemStructure.ssd`` (an extracted archive; ``origin``: for messages)."""
    where = f"{origin}: {SSD_NAME}"
    if not (folder / SSD_NAME).is_file():
        raise InputFileError(f"{origin}: no {SSD_NAME} at the top of the archive")
    root = parse_xml(_read_member(folder, SSD_NAME, str(origin)), where)
    if root.tag != _q("ssd", "SystemStructureDescription"):
        raise InputFileError(f"{where}: the root element is {etree_local(root)}, not an SSP 1.0 "
                             f"SystemStructureDescription ({root.tag})")
    validate(root, "SystemStructureDescription.xsd", where)
    system = root.find("ssd:System", NS)
    sname = _name(system, "name", f"{where}: System")
    if system.find("ssd:SignalDictionaries", NS) is not None or \
            system.find("ssd:Elements/ssd:SignalDictionaryReference", NS) is not None:
        raise InputFileError(f"{where}: signal dictionaries are not supported")
    if system.find("ssd:Elements/ssd:System", NS) is not None:
        raise InputFileError(f"{where}: nested systems are not supported (one level of components)")
    if system.find("ssd:ParameterBindings", NS) is not None:
        raise InputFileError(f"{where}: parameter bindings of the system itself are not supported (bind them "
                             f"on the components)")
    units = {}
    for ue in root.iterfind("ssd:Units", NS):
        _units(ue, where, units)
    components = {}
    for c in system.iterfind("ssd:Elements/ssd:Component", NS):
        comp = _component(c, folder, origin, where, units)
        if comp.name in components:
            raise InputFileError(f"{where}: component {comp.name}: the name is used twice")
        components[comp.name] = comp
    if not components:
        raise InputFileError(f"{where}: System {sname!r} has no components (nothing to run)")
    connections, driven = [], {}
    for e in system.iterfind("ssd:Connections/ssd:Connection", NS):
        c = _connection(e, components, where)
        if c.end in driven:  # two sources for one input: neither value would be the input's
            raise InputFileError(f"{where}: connection {c.start[0]}.{c.start[1]} -> {c.end[0]}.{c.end[1]}: "
                                 f"{c.end[0]}.{c.end[1]} is already driven by {'.'.join(driven[c.end])}")
        driven[c.end] = c.start
        connections.append(c)
    de = root.find("ssd:DefaultExperiment", NS)
    start = stop = None
    annotations = {}
    if de is not None:
        start = _float(de, "startTime", f"{where}: DefaultExperiment")
        stop = _float(de, "stopTime", f"{where}: DefaultExperiment")
        if stop is not None and not stop > (start if start is not None else 0.0):
            raise InputFileError(f"{where}: DefaultExperiment stopTime {de.get('stopTime')!r} is not after its "
                                 f"startTime {de.get('startTime', '0')!r}")
        _annotations(de, f"{where}: DefaultExperiment", "DefaultExperiment/", annotations)
    _annotations(root, where, "", annotations)
    return Ssd(origin, _name(root, "name", f"{where}: SystemStructureDescription"), sname, components, connections,
               units, start, stop, annotations, folder)


def open_ssp(path, dest: Path) -> Ssd:
    """Extract ``path`` (an .ssp archive) into the new or empty folder ``dest`` and read its system."""
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"{path}: no such SSP file" if not path.exists() else f"{path}: not a file")
    dest = Path(dest)
    try:
        if dest.exists() and not dest.is_dir():
            raise InputFileError(f"{dest}: the extraction folder (workdir) is a file, not a folder")
        dest.mkdir(parents=True, exist_ok=True)
        if any(dest.iterdir()):
            raise InputFileError(f"{dest}: the extraction folder (workdir) must be empty")
    except OSError as exc:
        raise InputFileError(f"{dest}: cannot make the extraction folder (workdir): {exc.strerror or exc}") from None
    extract(path, dest)
    ssd = read_ssd(dest, path)
    out = {}
    for name, c in ssd.components.items():
        where = f"{path}: {SSD_NAME}: component {name}"
        rel = _safe_member(c.source, where)
        fmu = (dest / Path(*rel.parts)).resolve()
        if dest.resolve() not in fmu.parents or not fmu.is_file():
            raise InputFileError(f"{where}: source {c.source!r} is not a file of the archive")
        out[name] = replace(c, fmu_path=fmu)
    ssd.components = out
    return ssd


def is_ssp(path) -> bool:
    return str(path).lower().endswith(".ssp")


__all__ = ["Ssd", "Component", "Connector", "Connection", "open_ssp", "read_ssd", "extract", "parse_xml",
           "validate", "schema", "NS", "FMUGEN_NS", "FMUGEN_ANNOTATION", "OSP_NS", "OSP_ANNOTATION", "is_ssp",
           "read_fmi_description", "SSP_TYPE_OF_FMI3"]


#: SSP 1.0's connector and parameter types (ssc:Real, ssc:Integer, ...) are FMI 2.0's; an FMI 3.0 FMU's
#: Float64 is an ssc:Real, its Int32 an ssc:Integer.  Its other types keep their FMI 3.0 names, which no
#: SSP 1.0 type holds, so what refuses an unsupported type refuses them by name.
SSP_TYPE_OF_FMI3 = {"Float64": "Real", "Int32": "Integer"}


def read_fmi_description(path, validate: bool = False):
    """fmpy's model description of the FMU at ``path`` (FMI 2.0 or 3.0), its variables' types under SSP
    1.0's names (:data:`SSP_TYPE_OF_FMI3`), so that one check of a connector's or binding's type serves
    both FMI versions.  A fresh description per call: changing its types touches nobody else's."""
    from fmpy import read_model_description

    md = read_model_description(str(path), validate=validate)
    if str(md.fmiVersion).startswith("3"):
        for v in md.modelVariables:
            v.type = SSP_TYPE_OF_FMI3.get(v.type, v.type)
    return md


def without_aliases(model_description) -> list:
    """The FMU's variables with FMI 2.0 aliases left out: the first variable of each (type, valueReference)
    stands for its set (a URDF arm's ``shoulder_pan_joint.q`` is ``q[1]``), so a system gets one
    connector, one start value and one recorded column per value, not one per name."""
    seen, out = set(), []
    for v in model_description.modelVariables:
        key = (v.type, v.valueReference)
        if key not in seen:
            seen.add(key)
            out.append(v)
    return out
