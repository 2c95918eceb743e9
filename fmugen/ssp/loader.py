"""An SSP system as the master's :class:`~fmugen.cosim.system.CosimSystem`.

:func:`load_system` reads an archive with :mod:`fmugen.ssp.ssd` and turns it
into the same in-memory system a scene build gives, so every scheme of the
master runs it:

* each component is a :class:`Unit`: its FMU (FMI 2.0 CS or ME -- ME when
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
import shutil
import tempfile
from pathlib import Path
from typing import Optional

from ..errors import InputFileError
from .ssd import FMUGEN_ANNOTATION, FMUGEN_NS, Ssd, open_ssp, without_aliases

_F = f"{{{FMUGEN_NS}}}"


def _number(text: str, where: str):
    try:
        x = float(text)
    except (TypeError, ValueError):
        raise InputFileError(f"{where}: {text!r} is not a number") from None
    if x != x or x in (float("inf"), float("-inf")):
        raise InputFileError(f"{where}: {text!r} is not finite")
    return int(x) if x == int(x) and "." not in text and "e" not in text.lower() else x


def _setting(text: str):
    try:
        x = float(text)
    except ValueError:
        return {"true": True, "false": False}.get(text, text)
    return int(x) if x == int(x) and "." not in text and "e" not in text.lower() else x


def fmugen_run(ssd: Ssd) -> Optional[dict]:
    """fmugen's run annotation of ``ssd`` as plain data, or None."""
    run = ssd.annotations.get(FMUGEN_ANNOTATION)
    if run is None or run.tag != f"{_F}Run":
        return None
    where = f"{ssd.path}: annotation {FMUGEN_ANNOTATION}"
    out = {k: run.get(k) for k in ("scene", "scheme", "extrapolation")}
    for k in ("step", "startTime", "stopTime", "jacobiHoldLimit", "jacobiHoldStep"):
        if run.get(k) is not None:
            out[k] = float(_number(run.get(k), f"{where}: {k}"))
    order = run.find(f"{_F}Order")
    out["order"] = tuple(order.text.split()) if order is not None and order.text else None
    out["units"] = {}
    for u in run.iterfind(f"{_F}Unit"):
        starts = {s.get("name"): _number(s.get("value"), f"{where}: unit {u.get('name')}: {s.get('name')}")
                  for s in u.iterfind(f"{_F}Start")}
        out["units"][u.get("name")] = {"fmi_type": u.get("fmiType"), "solver": u.get("solver"),
                                       "directional": u.get("directionalDerivatives") == "true",
                                       "members": tuple((u.get("members") or "").split()), "starts": starts}
    out["record"] = [(r.get("column"), r.get("unit"), r.get("variable"), r.get("physicalUnit") or "")
                     for r in run.iterfind(f"{_F}Record")]
    out["settings"] = {s.get("name"): _setting(s.get("value")) for s in run.iterfind(f"{_F}Setting")}
    return out


def _fmi(fmu: Path, name: str, where: str):
    import zipfile

    from fmpy import read_model_description

    from .ssd import MAX_XML_BYTES, parse_xml

    try:  # the version first, with the same safe parser as the SSD: FMI 1.0/3.0 are refused by name
        with zipfile.ZipFile(fmu) as zf:
            info = zf.getinfo("modelDescription.xml")
            if info.file_size > MAX_XML_BYTES:
                raise InputFileError(f"{where}: component {name}: modelDescription.xml is larger than "
                                     f"{MAX_XML_BYTES} bytes")
            version = parse_xml(zf.read(info), f"{where}: component {name}: modelDescription.xml").get("fmiVersion")
    except (zipfile.BadZipFile, KeyError, OSError) as exc:
        raise InputFileError(f"{where}: component {name}: not an FMU (zip with modelDescription.xml): {exc}") from None
    if version != "2.0":
        raise InputFileError(f"{where}: component {name}: FMI {version} is not supported (FMI 2.0 only)")
    try:
        md = read_model_description(str(fmu), validate=False)
    except Exception as exc:  # fmpy raises many kinds on a broken FMU
        raise InputFileError(f"{where}: component {name}: cannot read its FMU: {exc}") from None
    if md.fmiVersion != "2.0":
        raise InputFileError(f"{where}: component {name}: FMI {md.fmiVersion} is not supported (FMI 2.0 only)")
    return md


def to_system(ssd: Ssd, record: Optional[list] = None):
    """The :class:`CosimSystem` of a read archive (``record``: columns "component.connector" to keep)."""
    from ..cosim.system import CosimSystem, Coupling, Recorded, Unit

    where = str(ssd.path)
    run = fmugen_run(ssd)
    units, mds = [], {}
    for name, c in ssd.components.items():
        md = _fmi(c.fmu_path, name, where)
        mds[name] = md
        fmi_type = "cs" if md.coSimulation is not None else "me"
        starts = dict(c.parameters)
        members = (name,)
        directional = bool((md.coSimulation or md.modelExchange).providesDirectionalDerivative)
        if run and name in run["units"]:
            ru = run["units"][name]
            fmi_type, members, directional = ru["fmi_type"], ru["members"] or members, ru["directional"]
            if fmi_type == "me" and md.modelExchange is None:
                raise InputFileError(f"{where}: component {name}: the annotation says Model Exchange, the FMU "
                                     f"has no such interface")
            # what fmugen's master set for the scene (states at rest, solver), then the bindings: the same
            # values unless someone edited the .ssv, and then the edit wins
            starts = dict(ru["starts"])
            starts.update(c.parameters)
        variables = {v.name: v for v in md.modelVariables}
        for k in starts:
            if k not in variables:
                raise InputFileError(f"{where}: component {name}: a parameter binding names {k!r}, which the FMU "
                                     f"does not have")
        units.append(Unit(name, Path(c.fmu_path), fmi_type, starts, directional, members))
    couplings = []
    for e in ssd.connections:
        (su, sv), (tu, tv) = e.start, e.end
        cw = f"{where}: connection {su}.{sv} -> {tu}.{tv}"
        ends = []
        for comp, conn, kind in ((su, sv, "output"), (tu, tv, "input")):
            if comp not in ssd.components:
                raise InputFileError(f"{cw}: no component {comp!r}")
            v = {x.name: x for x in mds[comp].modelVariables}.get(conn)
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
        recorded = tuple(Recorded(*r) for r in run["record"])
    else:
        recorded = []
        for name, md in mds.items():
            for v in without_aliases(md):
                if v.causality == "output" and v.type == "Real":
                    recorded.append(Recorded(f"{name}.{v.name}", name, v.name, v.unit or ""))
        if record is not None:
            by = {r.column: r for r in recorded}
            missing = [c for c in record if c not in by]
            if missing:
                raise InputFileError(f"{where}: record: no output {missing[0]!r}; outputs: "
                                     f"{', '.join(by)}")
            recorded = [by[c] for c in record]
        recorded = tuple(recorded)
    start = ssd.start_time if ssd.start_time is not None else 0.0
    stop = ssd.stop_time if ssd.stop_time is not None else start + 1.0
    if run:
        step = run.get("step") or run.get("jacobiHoldStep")
        order, settings = run["order"], dict(run["settings"])
        settings.setdefault("scheme", run["scheme"])
        settings.setdefault("extrapolation", run["extrapolation"])
    else:
        step, order, settings = _osp_step(ssd), None, {}
        if step is None:
            step = (stop - start) / 1000.0
    return CosimSystem(ssd.system or ssd.name, tuple(units), tuple(couplings), recorded, start, stop, float(step),
                       order, settings)


def _unit(name: str, defined: dict, where: str):
    """(base-unit exponents, factor, offset) of unit ``name``: the archive's own definition (SSD ``Units``),
    else fmugen's reading of the Modelica unit syntax; None when neither knows it."""
    from ..fmi.units import BASE, base_units

    d = defined.get(name)
    if d:
        try:
            return (tuple(int(d.get(b, 0)) for b in BASE), float(d.get("factor", 1.0)),
                    float(d.get("offset", 0.0)))
        except ValueError:
            raise InputFileError(f"{where}: unit {name!r}: its BaseUnit is not numbers: {d}") from None
    try:
        u = base_units(name)
    except ValueError:
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
    return a[1] / b[1]


def _osp_step(ssd: Ssd) -> Optional[float]:
    from .ssd import OSP_ANNOTATION, OSP_NS

    a = ssd.annotations.get("DefaultExperiment/" + OSP_ANNOTATION)
    if a is None:
        return None
    fs = a.find(f"{{{OSP_NS}}}FixedStepAlgorithm")
    if fs is None or not fs.get("baseStepSize"):
        return None
    step = float(_number(fs.get("baseStepSize"), f"{ssd.path}: {OSP_ANNOTATION} FixedStepAlgorithm baseStepSize"))
    if step <= 0:
        raise InputFileError(f"{ssd.path}: {OSP_ANNOTATION} FixedStepAlgorithm baseStepSize {step} is not positive")
    return step


def load_system(path, record: Optional[list] = None, workdir=None):
    """Read the SSP archive ``path`` and return its :class:`CosimSystem`.

    The archive is extracted (safely, see :mod:`fmugen.ssp.ssd`) into
    ``workdir`` (an empty or new folder), by default into a temporary folder
    removed when the Python process ends (not before: copies of the system,
    ``dataclasses.replace(system, ...)``, keep using its FMUs)."""
    if workdir is None:
        tmp = Path(tempfile.mkdtemp(prefix="fmugen_ssp_"))
        atexit.register(shutil.rmtree, str(tmp), True)
        workdir = tmp
    return to_system(open_ssp(path, Path(workdir)), record)
