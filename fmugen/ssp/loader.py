"""An SSP system as the master's :class:`~fmugen.cosim.system.CosimSystem`.

:func:`load_system` reads an archive with :mod:`fmugen.ssp.ssd` and turns it
into the same in-memory system a scene build gives, so every scheme of the
master runs it:

* each component is a :class:`Unit`: its FMU (FMI 2.0 or 3.0, CS or ME -- ME when
  it has no Co-Simulation interface), start values = its parameter
  bindings (parameters, and inputs: SSP binds inputs' start values too);
* each connection between components is a :class:`Coupling` with the
  LinearTransformation's factor (an offset is refused: the master's
  couplings are ``target = factor * source``), or without one the
  conversion between the connectors' units (:func:`_unit_conversion`);
* recorded: every output connector as ``component.connector``.

An archive that fmugen wrote carries fmugen's run annotation
(``org.fmugen.run``): then the units' types, start values, the
Gauss-Seidel order, the recorded columns and the scene's [cosim] settings
are read back from it exactly as written, so the archive runs as the scene.
"""
from __future__ import annotations

import atexit
import math
import os
import re
import shutil
import tempfile
import unicodedata
from pathlib import Path
from typing import Optional

from ..errors import FmugenError, InputFileError
from ..values import parse_xs_boolean, parse_xs_double, parse_xs_int
from .ssd import FMUGEN_ANNOTATION, FMUGEN_NS, SSD_NAME, Ssd, _name, etree_local, open_ssp, without_aliases

_F = f"{{{FMUGEN_NS}}}"
_INTEGER = re.compile(r"[ \t\n\r]*[+-]?[0-9]+[ \t\n\r]*")


def _number(text, where: str):
    """A start value of fmugen's annotation: an int when written as an integer (an Integer variable's),
    else a finite xs:double."""
    x = parse_xs_double(text, where)
    return int(x) if _INTEGER.fullmatch(text) and abs(x) < 2 ** 53 else x


def _setting(text, where: str):
    """A run setting as the exporter writes it: true/false, an integer, an xs:double, else text (a scheme)."""
    if text is None:
        raise InputFileError(f"{where}: no value attribute")
    t = text.strip(" \t\n\r")
    if t in ("true", "false"):
        return t == "true"
    if _INTEGER.fullmatch(t):
        return parse_xs_int(t, where, "long")
    if re.fullmatch(r"[+-]?([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]+)?|-?INF|NaN", t):
        return parse_xs_double(t, where)  # refuses INF, NaN and 1e999: no setting takes them
    try:  # text Python reads as a number ("1_5", Arabic-Indic digits, "infinity") would reach float() later
        float(t)
    except ValueError:
        return text
    return parse_xs_double(t, where)  # refused by the grammar


def _names(text, where: str) -> tuple:
    """A white-space separated list of names (the Gauss-Seidel order, a unit's members)."""
    if text is None:
        return ()
    if any(unicodedata.category(ch) in ("Cc", "Cf") and ch not in " \t\n\r" for ch in text):
        raise InputFileError(f"{where}: {text[:40]!r} contains control characters")
    return tuple(text.split())


def _controls(text: str) -> bool:
    return any(unicodedata.category(ch) in ("Cc", "Cf", "Zl", "Zp") for ch in text)


def _one_line(message: str) -> str:
    """``message`` with every control or line-separator character written as its escape: a message
    quotes the FMU's own strings (units, causalities, names), which nobody checked for newlines."""
    if not _controls(message):
        return message
    return "".join(ch.encode("unicode_escape").decode("ascii") if unicodedata.category(ch) in
                   ("Cc", "Cf", "Zl", "Zp") else ch for ch in message)


def fmugen_run(ssd: Ssd) -> Optional[dict]:
    """fmugen's run annotation of ``ssd`` as plain data, or None when there is none.

    The annotation is not covered by the SSP schemas (it is fmugen's), so it is checked here element by
    element: every number by the xs:double grammar, every name against the system's components, every
    run setting by the rules of a scene's [cosim] table."""
    where = f"{ssd.path}: {SSD_NAME}: annotation {FMUGEN_ANNOTATION}"
    if FMUGEN_ANNOTATION not in ssd.annotations:
        return None
    run = ssd.annotations[FMUGEN_ANNOTATION]
    if run is None or run.tag != f"{_F}Run":
        got = "nothing" if run is None else etree_local(run) + (f" in {run.tag.split('}')[0][1:]!r}" if "}" in
                                                                 str(run.tag) else "")
        raise InputFileError(f"{where}: holds {got}, not fmugen's Run element ({FMUGEN_NS})")
    if run.get("version", "1") != "1":
        raise InputFileError(f"{where}: version {run.get('version')!r}; this fmugen reads version 1")
    comps = ssd.components
    out = {}
    for k in ("scene", "scheme", "extrapolation"):
        out[k] = _name(run, k, f"{where}: Run", required=False)
    for k in ("step", "startTime", "stopTime", "jacobiHoldLimit", "jacobiHoldStep"):
        if run.get(k) is not None:
            out[k] = parse_xs_double(run.get(k), f"{where}: Run {k}")
    for k in ("step", "jacobiHoldLimit", "jacobiHoldStep"):
        if k in out and not out[k] > 0:
            raise InputFileError(f"{where}: Run {k}: {run.get(k)!r} is not positive")
    if "startTime" in out and "stopTime" in out and not out["stopTime"] > out["startTime"]:
        raise InputFileError(f"{where}: Run stopTime {run.get('stopTime')!r} is not after startTime "
                             f"{run.get('startTime')!r}")
    orders = run.findall(f"{_F}Order")
    if len(orders) > 1:
        raise InputFileError(f"{where}: Order given {len(orders)} times")
    out["order"] = None
    if orders and (orders[0].text or "").strip():
        order = _names(orders[0].text, f"{where}: Order")
        for n in order:
            if n not in comps:
                raise InputFileError(f"{where}: Order names {n!r}, which is no component ({', '.join(comps)})")
        if sorted(order) != sorted(comps):
            raise InputFileError(f"{where}: Order {' '.join(order)!r} must name every component once "
                                 f"({', '.join(comps)})")
        out["order"] = order
    out["units"] = {}
    for u in run.iterfind(f"{_F}Unit"):
        name = _name(u, "name", f"{where}: Unit")
        uw = f"{where}: Unit {name}"
        if name not in comps:
            raise InputFileError(f"{uw}: no component of that name ({', '.join(comps)})")
        if name in out["units"]:
            raise InputFileError(f"{uw}: given twice (which one is meant?)")
        fmi_type = u.get("fmiType")
        if fmi_type not in ("cs", "me"):
            raise InputFileError(f"{uw}: fmiType {fmi_type!r} is neither 'cs' (Co-Simulation) nor 'me' "
                                 f"(Model Exchange)")
        starts = {}
        for st in u.iterfind(f"{_F}Start"):
            sname = _name(st, "name", f"{uw}: Start")
            if sname in starts:
                raise InputFileError(f"{uw}: Start {sname}: given twice (which value is meant?)")
            if st.get("value") is None:
                raise InputFileError(f"{uw}: Start {sname}: no value attribute")
            starts[sname] = _number(st.get("value"), f"{uw}: Start {sname} value")
        out["units"][name] = {"fmi_type": fmi_type, "solver": _name(u, "solver", uw, required=False),
                              "directional": parse_xs_boolean(u.get("directionalDerivatives", "false"),
                                                              f"{uw} directionalDerivatives"),
                              "members": _names(u.get("members"), f"{uw} members"), "starts": starts}
    out["record"], columns = [], set()
    for r in run.iterfind(f"{_F}Record"):
        column = _name(r, "column", f"{where}: Record")
        rw = f"{where}: Record {column}"
        if column in columns:
            raise InputFileError(f"{rw}: given twice (which one is meant?)")
        columns.add(column)
        unit, variable = _name(r, "unit", rw), _name(r, "variable", rw)
        if unit not in comps:
            raise InputFileError(f"{rw}: unit {unit!r} is no component ({', '.join(comps)})")
        out["record"].append((column, unit, variable, _name(r, "physicalUnit", rw, required=False) or ""))
    out["settings"] = {}
    for st in run.iterfind(f"{_F}Setting"):
        sname = _name(st, "name", f"{where}: Setting")
        sw = f"{where}: Setting {sname}"
        if sname in out["settings"]:
            raise InputFileError(f"{sw}: given twice (which value is meant?)")
        out["settings"][sname] = _setting(st.get("value"), f"{sw} value")
    from ..cosim.settings import check_table

    table = dict(out["settings"])
    for k in ("scheme", "extrapolation"):
        if out[k] is not None:
            table.setdefault(k, out[k])
    try:
        check_table(table, f"{where}: Setting")
    except FmugenError as exc:
        raise InputFileError(str(exc)) from None
    return out


def _unreadable(fmu: Path, version: str, exc: Exception) -> str:
    """Why fmpy could not read the FMU's description, naming the element: the first complaint of the FMI
    schema of its version (fmpy's parser alone says e.g. only 'ScalarVariable', the element it missed, for
    an FMI 2.0 description labelled 3.0); the parser's exception where the schema finds nothing."""
    try:
        from fmpy.validation import validate_fmu

        problems = validate_fmu(str(fmu))
    except Exception:  # the schema check itself failed: the parser's complaint is all there is
        problems = []
    if problems:
        return f"modelDescription.xml does not follow the FMI {version} schema: {' '.join(str(problems[0]).split())[:240]}"
    return f"{type(exc).__name__}: {' '.join(str(exc).split())[:200]}"


def _fmi(fmu: Path, name: str, where: str):
    import zipfile
    import zlib

    from .ssd import MAX_XML_BYTES, parse_xml, read_fmi_description

    cw = f"{where}: component {name} ({fmu.name})"
    try:  # the version first, with the same safe parser as the SSD: FMI 1.0 and others are refused by name
        with zipfile.ZipFile(fmu) as zf:
            info = zf.getinfo("modelDescription.xml")
            if info.file_size > MAX_XML_BYTES:
                raise InputFileError(f"{cw}: modelDescription.xml is larger than {MAX_XML_BYTES} bytes")
            version = parse_xml(zf.read(info), f"{cw}: modelDescription.xml").get("fmiVersion")
    except (zipfile.BadZipFile, KeyError, OSError, EOFError, zlib.error, NotImplementedError, RuntimeError) as exc:
        raise InputFileError(f"{cw}: not an FMU (zip with modelDescription.xml): "
                             f"{' '.join(str(exc).split())[:200] or type(exc).__name__}") from None
    if version not in ("2.0", "3.0"):
        raise InputFileError(f"{cw}: FMI {version} is not supported (FMI 2.0 and 3.0)")
    try:
        md = read_fmi_description(fmu)  # FMI 3.0's Float64/Int32 under SSP 1.0's names Real/Integer
    except Exception as exc:  # fmpy raises many kinds on a broken FMU
        raise InputFileError(f"{cw}: cannot read its FMU: {_unreadable(fmu, version, exc)}") from None
    if md.fmiVersion not in ("2.0", "3.0"):
        raise InputFileError(f"{cw}: FMI {md.fmiVersion} is not supported (FMI 2.0 and 3.0)")
    if md.coSimulation is None and md.modelExchange is None:
        raise InputFileError(f"{cw}: its modelDescription.xml has neither a CoSimulation nor a ModelExchange "
                             f"interface")
    return md


def can_set(v) -> bool:
    """Whether a run may set the start value of fmpy variable ``v``: a parameter (fixed or tunable), an
    input, or a state (an output or local with an exact start) -- FMI 2.0's rules for fmi2SetXXX before
    initialisation.  One rule for the SSP's bindings, ``--set`` and ``fmugen sweep x.ssp``."""
    return ((v.causality == "parameter" and v.variability in ("fixed", "tunable")) or v.causality == "input"
            or (v.initial == "exact" and v.causality in ("output", "local")))


def _bound(v, value, where: str):
    """The start value ``value`` checked for FMU variable ``v``: settable, of its type, in its range."""
    if not can_set(v):
        raise InputFileError(f"{where}: {v.name} is {v.causality}/{v.variability}"
                             f"{'/' + v.initial if v.initial else ''}; FMI 2.0 allows no start value for it")
    if v.type == "Integer":
        if isinstance(value, float) and not value.is_integer():
            raise InputFileError(f"{where}: {v.name} is an Integer variable; {value!r} is not a whole number")
        value = int(value)
        if not -2 ** 31 <= value < 2 ** 31:
            raise InputFileError(f"{where}: {value} is outside an FMI Integer (32 bits)")
    elif v.type != "Real":
        raise InputFileError(f"{where}: {v.name} is a {v.type} variable; bindings of Real and Integer values only")
    for bound, ok in (("min", lambda b: value >= b), ("max", lambda b: value <= b)):
        text = getattr(v, bound, None)
        if text is None:
            continue
        try:
            b = parse_xs_double(str(text), "the FMU's " + bound)
        except InputFileError:
            continue  # the FMU's own attribute is not a number: the FMU would not enforce it either
        if not ok(b):
            side = "below its minimum" if bound == "min" else "above its maximum"
            raise InputFileError(f"{where}: {v.name} = {value!r} is {side} {b!r} (the FMU's modelDescription.xml)")
    return value


def _fmi_type(c, md, run_unit, where: str) -> str:
    """"cs" or "me": the SSD's implementation, fmugen's annotation, else Co-Simulation when the FMU has it."""
    choice = {"CoSimulation": "cs", "ModelExchange": "me"}.get(c.implementation)
    said = f"implementation {c.implementation}"
    if run_unit is not None:
        if choice is not None and run_unit["fmi_type"] != choice:
            raise InputFileError(f"{where}: implementation {c.implementation} but annotation {FMUGEN_ANNOTATION} "
                                 f"says fmiType {run_unit['fmi_type']!r} (which is meant?)")
        choice, said = run_unit["fmi_type"], f"fmiType {run_unit['fmi_type']!r} of annotation {FMUGEN_ANNOTATION}"
    if choice is None:
        choice = "cs" if md.coSimulation is not None else "me"
    if choice == "cs" and md.coSimulation is None:
        raise InputFileError(f"{where}: {said} asks for Co-Simulation; the FMU has no such interface")
    if choice == "me" and md.modelExchange is None:
        raise InputFileError(f"{where}: {said} asks for Model Exchange; the FMU has no such interface")
    return choice


def to_system(ssd: Ssd, record: Optional[list] = None):
    """The :class:`CosimSystem` of a read archive (``record``: columns "component.connector" to keep)."""
    from ..cosim.system import CosimSystem, Coupling, Recorded, Unit

    if record is not None and (isinstance(record, (str, bytes)) or not all(isinstance(c, str) for c in record)):
        raise FmugenError(f"record: a list of columns 'component.connector' is needed, got {record!r:.60}")
    where = f"{ssd.path}: {SSD_NAME}"
    run = fmugen_run(ssd)
    units, mds, variables_of = [], {}, {}
    for name, c in ssd.components.items():
        cw = f"{where}: component {name}"
        md = _fmi(c.fmu_path, name, where)
        mds[name] = md
        variables = {v.name: v for v in md.modelVariables}
        variables_of[name] = variables
        for k in c.connectors:
            v = variables.get(k.name)
            if v is None:
                raise InputFileError(f"{cw}: Connector {k.name!r}: its FMU ({c.fmu_path.name}) has no such variable")
            if k.type and k.type != v.type:
                raise InputFileError(f"{cw}: Connector {k.name!r} is declared {k.type}; the FMU's variable is {v.type}")
            if k.kind in ("input", "output") and v.causality != k.kind:
                raise InputFileError(f"{cw}: Connector {k.name!r} is declared {k.kind}; the FMU's variable is "
                                     f"{v.causality}")
            if k.unit and v.unit and k.unit != v.unit:
                raise InputFileError(f"{cw}: Connector {k.name!r} is declared in [{k.unit}]; the FMU's variable "
                                     f"is in [{v.unit}] (state the conversion on the connection)")
        ru = run["units"].get(name) if run else None
        fmi_type = _fmi_type(c, md, ru, cw)
        directional = bool((md.coSimulation if fmi_type == "cs" else md.modelExchange).providesDirectionalDerivative)
        members = (name,)
        starts = {}
        if ru is not None:
            members, directional = ru["members"] or members, ru["directional"]
            # what fmugen's master set for the scene (states at rest, solver), then the bindings: the same
            # values unless someone edited the .ssv, and then the edit wins
            for k, value in ru["starts"].items():
                if k not in variables:
                    raise InputFileError(f"{where}: annotation {FMUGEN_ANNOTATION}: Unit {name}: Start {k!r}: its "
                                         f"FMU has no such variable")
                starts[k] = _bound(variables[k], value, f"{where}: annotation {FMUGEN_ANNOTATION}: Unit {name}: "
                                                        f"Start {k}")
        for k, value in c.parameters.items():
            bw = f"{cw}: parameter binding {k}"
            if k not in variables:
                raise InputFileError(f"{cw}: a parameter binding names {k!r}, which the FMU does not have")
            unit = c.parameter_units.get(k, "")
            fmu_unit = variables[k].unit or ""
            if unit and fmu_unit and unit != fmu_unit:  # a value stated in another unit: converted, or refused
                value = value * _unit_conversion(unit, fmu_unit, ssd.units, bw)
                if not math.isfinite(value):
                    raise InputFileError(f"{bw}: the value in [{fmu_unit}] is beyond the double range")
            starts[k] = _bound(variables[k], value, bw)
        units.append(Unit(name, Path(c.fmu_path), fmi_type, starts, directional, members))
    couplings = []
    for e in ssd.connections:
        (su, sv), (tu, tv) = e.start, e.end
        cw = f"{where}: connection {su}.{sv} -> {tu}.{tv}"
        ends = []
        for comp, conn, kind in ((su, sv, "output"), (tu, tv, "input")):
            v = variables_of[comp].get(conn)
            if v is None:
                raise InputFileError(f"{cw}: the FMU of {comp} has no variable {conn!r}")
            if v.type != "Real":
                raise InputFileError(f"{cw}: {comp}.{conn} is {v.type}; only Real connections are supported")
            if v.causality != kind:
                raise InputFileError(f"{cw}: {comp}.{conn} is {v.causality}, not {kind}")
            ends.append(v)
        if e.offset != 0.0:
            raise InputFileError(f"{cw}: a LinearTransformation with an offset is not supported (factor only)")
        unit = ends[1].unit or ""
        factor = e.factor
        if not e.transformed and not e.suppress_unit_conversion:
            factor = _unit_conversion(ends[0].unit or "", unit, ssd.units, cw)
        couplings.append(Coupling((su, sv), (tu, tv), factor, unit))
    if run and run["record"] and record is None:
        for column, comp, variable, _ in run["record"]:
            v = variables_of[comp].get(variable)
            rw = f"{where}: annotation {FMUGEN_ANNOTATION}: Record {column}"
            if v is None or v.type != "Real":
                raise InputFileError(f"{rw}: {comp} has no Real variable {variable!r}")
        recorded = tuple(Recorded(*r) for r in run["record"])
    else:
        recorded = []
        for name, md in mds.items():
            for v in without_aliases(md):
                if v.causality == "output" and v.type == "Real":
                    if _controls(v.name) or _controls(v.unit or ""):  # they become CSV header cells
                        raise InputFileError(f"{where}: component {name} ({ssd.components[name].fmu_path.name}): "
                                             f"output {v.name!r} [{v.unit!r}] contains control characters")
                    recorded.append(Recorded(f"{name}.{v.name}", name, v.name, v.unit or ""))
        if record is not None:
            by = {r.column: r for r in recorded}
            missing = [c for c in record if c not in by]
            if missing:
                raise InputFileError(f"{where}: record: no output {missing[0]!r:.80}; outputs: "
                                     f"{', '.join(by)}")
            if len(set(record)) != len(record):
                raise FmugenError(f"record: {next(c for c in record if record.count(c) > 1)!r} is named twice")
            recorded = [by[c] for c in record]
        recorded = tuple(recorded)
    start = ssd.start_time if ssd.start_time is not None else 0.0
    stop = ssd.stop_time if ssd.stop_time is not None else start + 1.0
    osp = _osp_step(ssd)
    if run:
        step = run.get("step") or run.get("jacobiHoldStep") or osp
        order, settings = run["order"], dict(run["settings"])
        for k in ("scheme", "extrapolation"):
            if run[k] is not None:
                settings.setdefault(k, run[k])
    else:
        step, order, settings = osp, None, {}
    if step is None:
        step = (stop - start) / 1000.0
    return CosimSystem(ssd.system or ssd.name, tuple(units), tuple(couplings), recorded, start, stop, float(step),
                       order, settings)


def _unit(name: str, defined: dict, where: str):
    """(base-unit exponents, factor, offset) of unit ``name``: the archive's own definition (SSD ``Units``,
    read and checked by :mod:`fmugen.ssp.ssd`), else fmugen's reading of the Modelica unit syntax; None
    when neither knows it."""
    from ..fmi.units import BASE, base_units

    d = defined.get(name)
    if d:
        return tuple(d[b] for b in BASE), d["factor"], d["offset"]
    try:
        u = base_units(name)
    except (ValueError, ZeroDivisionError, OverflowError, RecursionError):
        return None
    if not (math.isfinite(u.factor) and u.factor > 0 and math.isfinite(u.offset)):
        return None
    return tuple(getattr(u, b) for b in BASE), u.factor, u.offset


def _unit_conversion(source: str, target: str, defined: dict, where: str) -> float:
    """The factor a connection without a LinearTransformation converts by (SSP 1.0: an importer converts
    between the connectors' units unless suppressUnitConversion): 1 for equal units; refused when the
    units are different quantities, unknown, or need an offset (degC) -- a stated factor is then needed."""
    if not source or not target or source == target:
        return 1.0
    a, b = _unit(source, defined, where), _unit(target, defined, where)
    if a is None or b is None:
        raise InputFileError(f"{where}: cannot convert [{source}] to [{target}] (unit {source if a is None else target!r} "
                             f"unknown): state a LinearTransformation or suppressUnitConversion=\"true\"")
    if a[0] != b[0]:
        raise InputFileError(f"{where}: [{source}] and [{target}] are different quantities: state a "
                             f"LinearTransformation or suppressUnitConversion=\"true\"")
    if a[2] != 0.0 or b[2] != 0.0:
        raise InputFileError(f"{where}: converting [{source}] to [{target}] needs an offset, which the master's "
                             f"couplings (target = factor x source) do not have")
    factor = a[1] / b[1]
    if not (math.isfinite(factor) and factor > 0):
        raise InputFileError(f"{where}: the factor from [{source}] to [{target}] ({a[1]!r} / {b[1]!r}) is beyond "
                             f"the double range")
    return factor


def _osp_step(ssd: Ssd) -> Optional[float]:
    from .ssd import OSP_ANNOTATION, OSP_NS

    a = ssd.annotations.get("DefaultExperiment/" + OSP_ANNOTATION)
    if a is None:
        return None
    fs = a.find(f"{{{OSP_NS}}}FixedStepAlgorithm")
    if fs is None or fs.get("baseStepSize") is None:
        return None
    where = f"{ssd.path}: {SSD_NAME}: DefaultExperiment annotation {OSP_ANNOTATION}: FixedStepAlgorithm baseStepSize"
    step = parse_xs_double(fs.get("baseStepSize"), where)
    if not step > 0:
        raise InputFileError(f"{where}: {fs.get('baseStepSize')!r} is not positive")
    return step


def load_system(path, record: Optional[list] = None, workdir=None):
    """Read the SSP archive ``path`` and return its :class:`CosimSystem`.

    The archive is extracted (safely, see :mod:`fmugen.ssp.ssd`) into
    ``workdir`` (an empty or new folder), by default into a temporary folder
    removed when the Python process ends (not before: copies of the system,
    ``dataclasses.replace(system, ...)``, keep using its FMUs).  Bad input --
    the archive, ``record``, ``workdir`` -- is an :class:`~fmugen.errors.FmugenError`
    (an :class:`~fmugen.errors.InputFileError` naming the file inside the archive,
    the element and the attribute)."""
    for arg, value in (("path", path), ("workdir", workdir)):
        if value is not None and not isinstance(value, (str, os.PathLike)):
            raise FmugenError(f"load_system: {arg} must be a file path, got {type(value).__name__} {value!r:.60}")
    if isinstance(path, str) and not path.strip():
        raise FmugenError("load_system: path is empty")
    if workdir is None:
        # named after the archive: the master's messages name an FMU by its extracted path
        stem = re.sub(r"[^A-Za-z0-9_-]", "_", Path(path).stem)[:40]
        tmp = Path(tempfile.mkdtemp(prefix=f"fmugen_ssp_{stem}_"))
        atexit.register(shutil.rmtree, str(tmp), True)
        workdir = tmp
    try:
        return to_system(open_ssp(path, Path(workdir)), record)
    except InputFileError as exc:
        msg = _one_line(str(exc))
        if msg == str(exc):
            raise
        raise InputFileError(msg) from None
