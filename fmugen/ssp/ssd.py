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
* every SSD and SSV is validated against those schemas before it is read,
  and what fmugen does not support is refused with one line each: signal
  dictionaries, parameter mappings (.ssm), nested systems, connections to
  the system's own connectors, non-Real connectors, FMI 1.0/3.0 components,
  non-FMU components.
"""
from __future__ import annotations

import stat
import zipfile
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Optional

from ..errors import InputFileError

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
    units: dict  # unit name -> {base unit exponents, factor, offset}
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
    except etree.XMLSyntaxError as exc:
        raise InputFileError(f"{where}: not well-formed XML: {exc}") from None


def validate(root, schema_name: str, where: str) -> None:
    s = schema(schema_name)
    if not s.validate(root):
        e = s.error_log.last_error
        raise InputFileError(f"{where}: does not validate against the SSP 1.0 schema ({schema_name}): line "
                             f"{e.line}: {e.message}")


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
    except (zipfile.BadZipFile, OSError) as exc:
        raise InputFileError(f"{where}: not an SSP archive (zip): {exc}") from None
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
            if info.is_dir():
                target.mkdir(parents=True, exist_ok=True)
                continue
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


# ---------------------------------------------------------------------------- SSD and SSV
def _float(el, attr: str, where: str, default=None) -> Optional[float]:
    v = el.get(attr)
    if v is None:
        return default
    try:
        x = float(v)
    except ValueError:
        raise InputFileError(f"{where}: {attr}={v!r} is not a number") from None
    if x != x or x in (float("inf"), float("-inf")):
        raise InputFileError(f"{where}: {attr}={v!r} is not finite")
    return x


def _q(prefix: str, tag: str) -> str:
    return f"{{{NS[prefix]}}}{tag}"


def _parameter_set(root, where: str) -> dict:
    out = {}
    for p in root.iterfind("ssv:Parameters/ssv:Parameter", NS):
        name = p.get("name")
        real, integer = p.find("ssv:Real", NS), p.find("ssv:Integer", NS)
        if real is not None:
            out[name] = _float(real, "value", f"{where}: parameter {name}")
        elif integer is not None:
            out[name] = int(integer.get("value"))
        else:
            kind = etree_local(p[0]) if len(p) else "?"
            raise InputFileError(f"{where}: parameter {name}: {kind} values are not supported (Real and "
                                 f"Integer are)")
    return out


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
    sname = system.get("name")
    if system.find("ssd:SignalDictionaries", NS) is not None or \
            system.find("ssd:Elements/ssd:SignalDictionaryReference", NS) is not None:
        raise InputFileError(f"{where}: signal dictionaries are not supported")
    if system.find("ssd:Elements/ssd:System", NS) is not None:
        raise InputFileError(f"{where}: nested systems are not supported (one level of components)")
    if system.find("ssd:ParameterBindings", NS) is not None:
        raise InputFileError(f"{where}: parameter bindings of the system itself are not supported (bind them "
                             f"on the components)")
    components = {}
    for c in system.iterfind("ssd:Elements/ssd:Component", NS):
        name = c.get("name")
        cw = f"{where}: component {name}"
        ctype = c.get("type", "application/x-fmu-sharedlibrary")
        if ctype != "application/x-fmu-sharedlibrary":
            raise InputFileError(f"{cw}: type {ctype!r} is not supported (FMUs only)")
        if c.get("implementation", "any") not in ("any", "CoSimulation", "ModelExchange"):
            raise InputFileError(f"{cw}: implementation {c.get('implementation')!r} is not supported")
        if name in components:
            raise InputFileError(f"{cw}: the name is used twice")
        conns = []
        for k in c.iterfind("ssd:Connectors/ssd:Connector", NS):
            t = next((etree_local(x) for x in k if etree_local(x) in
                      ("Real", "Integer", "Boolean", "String", "Enumeration", "Binary")), "")
            unit = ""
            if t == "Real":
                unit = k.find("ssc:Real", NS).get("unit", "")
            conns.append(Connector(k.get("name"), k.get("kind"), t, unit))
        params = {}
        for b in c.iterfind("ssd:ParameterBindings/ssd:ParameterBinding", NS):
            bw = f"{cw}: parameter binding"
            if b.find("ssd:ParameterMapping", NS) is not None:
                raise InputFileError(f"{bw}: parameter mappings (.ssm) are not supported")
            if b.get("type", "application/x-ssp-parameter-set") != "application/x-ssp-parameter-set":
                raise InputFileError(f"{bw}: type {b.get('type')!r} is not supported")
            if b.get("sourceBase", "SSD") != "SSD":
                raise InputFileError(f"{bw}: sourceBase {b.get('sourceBase')!r} is not supported (SSD)")
            prefix = b.get("prefix", "")
            src = b.get("source")
            if src is not None:
                ssv = parse_xml(_read_member(folder, src, bw), f"{origin}: {src}")
                validate(ssv, "SystemStructureParameterValues.xsd", f"{origin}: {src}")
                values = _parameter_set(ssv, f"{origin}: {src}")
            else:
                inline = b.find("ssd:ParameterValues/ssv:ParameterSet", NS)
                values = _parameter_set(inline, bw) if inline is not None else {}
            for k, v in values.items():
                # SSP 1.0 (SystemStructureDescription.xsd, ParameterBinding/@prefix): "the specified prefix is
                # prepended to all names in the parameter source" -- not stripped from them
                params[prefix + k] = v
        components[name] = Component(name, c.get("source"), ctype, tuple(conns), params)
    connections = []
    for e in system.iterfind("ssd:Connections/ssd:Connection", NS):
        se, sc, ee, ec = (e.get(a) for a in ("startElement", "startConnector", "endElement", "endConnector"))
        cw = f"{where}: connection {se}.{sc} -> {ee}.{ec}"
        if se is None or ee is None:
            raise InputFileError(f"{cw}: connections to the system's own connectors are not supported")
        lin = e.find("ssc:LinearTransformation", NS)
        if lin is None:  # FMPy writes and reads it in the ssd namespace
            lin = e.find("ssd:LinearTransformation", NS)
        if any(e.find(f"ssc:{t}", NS) is not None for t in ("BooleanMappingTransformation",
                                                            "IntegerMappingTransformation",
                                                            "EnumerationMappingTransformation")):
            raise InputFileError(f"{cw}: mapping transformations are not supported (LinearTransformation is)")
        f = _float(lin, "factor", cw, 1.0) if lin is not None else 1.0
        o = _float(lin, "offset", cw, 0.0) if lin is not None else 0.0
        connections.append(Connection((se, sc), (ee, ec), f, o, lin is not None,
                                      e.get("suppressUnitConversion", "false") in ("true", "1")))
    units = {}
    for u in root.iterfind("ssd:Units/ssc:Unit", NS):
        b = u.find("ssc:BaseUnit", NS)
        units[u.get("name")] = dict(b.attrib) if b is not None else {}
    de = root.find("ssd:DefaultExperiment", NS)
    start = stop = None
    annotations = {}
    if de is not None:
        start = _float(de, "startTime", f"{where}: DefaultExperiment")
        stop = _float(de, "stopTime", f"{where}: DefaultExperiment")
        for a in de.iterfind("ssd:Annotations/ssc:Annotation", NS):
            annotations["DefaultExperiment/" + a.get("type")] = a[0] if len(a) else None
    for a in root.iterfind("ssd:Annotations/ssc:Annotation", NS):
        annotations[a.get("type")] = a[0] if len(a) else None
    return Ssd(origin, root.get("name"), sname, components, connections, units, start, stop, annotations, folder)


def open_ssp(path, dest: Path) -> Ssd:
    """Extract ``path`` (an .ssp archive) into the new folder ``dest`` and read its system."""
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"{path}: no such SSP file")
    dest.mkdir(parents=True, exist_ok=True)
    if any(dest.iterdir()):
        raise InputFileError(f"{dest}: the extraction folder must be empty")
    extract(path, dest)
    ssd = read_ssd(dest, path)
    out = {}
    for name, c in ssd.components.items():
        where = f"{path}: component {name}"
        rel = _safe_member(c.source, where)
        fmu = (dest / Path(*rel.parts)).resolve()
        if dest.resolve() not in fmu.parents or not fmu.is_file():
            raise InputFileError(f"{where}: source {c.source!r} is not a file of the archive")
        out[name] = Component(c.name, c.source, c.type, c.connectors, c.parameters, fmu)
    ssd.components = out
    return ssd


def is_ssp(path) -> bool:
    return str(path).lower().endswith(".ssp")


__all__ = ["Ssd", "Component", "Connector", "Connection", "open_ssp", "read_ssd", "extract", "parse_xml",
           "validate", "schema", "NS", "FMUGEN_NS", "FMUGEN_ANNOTATION", "OSP_NS", "OSP_ANNOTATION", "is_ssp"]


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
