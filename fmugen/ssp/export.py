"""A scene as a standard SSP 1.0 archive: ``fmugen ssp SCENE -o scene.ssp``.

The archive holds

* ``SystemStructure.ssd``: one component per FMU of the scene
  (``resources/<group>.fmu``) with its input and output connectors (type
  Real, unit), the SSD unit definitions (SI base-unit exponents, as in the
  FMUs' modelDescription), the scene's connections between FMUs (a stated
  conversion factor as a ``LinearTransformation``), a ``DefaultExperiment``
  (start, stop; libcosim's fixed step in the Open Simulation Platform's
  annotation: a step at which held-input Jacobi is stable), and fmugen's own
  run settings as an annotation of type ``org.fmugen.run`` in the namespace
  ``urn:fmugen:ssp:1`` (scheme, extrapolation, macro step, Gauss-Seidel order,
  each FMU's type, internal solver and tolerances, the recorded columns, the
  scene's [cosim] table): what fmugen reads back to run exactly as the scene;
* ``resources/<group>.ssv``: a parameter set per component binding every
  parameter of the FMU (the scene's values, ``--set`` included), the internal
  solver (``solver.method``, ``solver.rtol``, ``solver.atol``) and the start
  values of its inputs (the state of rest).  The FMUs carry the same values
  as their own start values; the binding makes them visible and editable.

Every XML file is validated against the SSP 1.0 schemas (FMPy's copies)
before the archive is written; the archive appears only when complete.
"""
from __future__ import annotations

import math
import os
import re
import tempfile
import zipfile
from pathlib import Path
from typing import Optional

from .. import __version__
from ..errors import FmugenError
from .ssd import (FMUGEN_ANNOTATION, FMUGEN_NS, NS, OSP_ANNOTATION, OSP_NS, SSD_NAME, parse_xml,
                  read_fmi_description, validate, without_aliases)

#: what an SSP cannot say and other importers therefore do not do (written into the annotation)
NOT_EXPRESSIBLE = (
    "coupling schemes other than held-input Jacobi (Gauss-Seidel order, iterated and Newton coupling) "
    "are fmugen's: other tools run their own loop",
    "extrapolated or Hermite inputs (fmi2SetRealInputDerivatives) are fmugen's choice, not the archive's",
    "Model-Exchange groups are integrated together by fmugen's master; other tools run their "
    "Co-Simulation interface",
    "adaptive macro steps with rollback are fmugen's",
)


def _fmt(x) -> str:
    if isinstance(x, bool):
        return "true" if x else "false"
    if isinstance(x, int):
        return str(x)
    x = float(x)
    if not math.isfinite(x):
        raise FmugenError(f"a value to write into the SSP is not finite: {x}")
    return repr(x)


def _unit_element(parent, unit: str):
    from lxml import etree

    from ..fmi.units import base_units

    u = etree.SubElement(parent, f"{{{NS['ssc']}}}Unit", name=unit)
    b = base_units(unit)
    bu = etree.SubElement(u, f"{{{NS['ssc']}}}BaseUnit")
    for k, e in b.exponents().items():
        if int(e):
            bu.set(k, str(int(e)))
    if b.factor != 1.0:
        bu.set("factor", _fmt(b.factor))


def _ssv(name: str, md, bound: dict) -> bytes:
    """The parameter set of one FMU: every parameter and the inputs' start values (``bound``: values
    the system sets over the FMU's own, e.g. an external component's bindings)."""
    from lxml import etree

    root = etree.Element(f"{{{NS['ssv']}}}ParameterSet", nsmap={"ssv": NS["ssv"], "ssc": NS["ssc"]},
                         version="1.0", name=name)
    params = etree.SubElement(root, f"{{{NS['ssv']}}}Parameters")
    for v in without_aliases(md):
        if v.causality not in ("parameter", "input") or v.start is None:
            continue
        if v.variability == "constant":
            continue
        p = etree.SubElement(params, f"{{{NS['ssv']}}}Parameter", name=v.name)
        value = bound.get(v.name, v.start)
        if v.type == "Real":
            el = etree.SubElement(p, f"{{{NS['ssv']}}}Real", value=_fmt(float(value)))
            if v.unit:
                el.set("unit", v.unit)
        elif v.type == "Integer":
            etree.SubElement(p, f"{{{NS['ssv']}}}Integer", value=str(int(float(value))))
        else:
            params.remove(p)
    validate(root, "SystemStructureParameterValues.xsd", f"{name}.ssv")
    return etree.tostring(root, xml_declaration=True, encoding="UTF-8", pretty_print=True)


def ssd_xml(built, settings: dict, libcosim_step: float) -> tuple:
    """(SystemStructure.ssd bytes, {group: .ssv bytes}) of a built scene (:class:`BuiltScene`)."""
    from lxml import etree

    scene, system = built.scene, built.system
    D, C = NS["ssd"], NS["ssc"]
    root = etree.Element(f"{{{D}}}SystemStructureDescription",
                         # every namespace on the root: libcosim's parser (boost ptree) takes an element's
                         # attributes, xmlns included, for a child of <osp:Algorithm>
                         nsmap={"ssd": D, "ssc": C, "ssv": NS["ssv"], "osp": OSP_NS, "fmugen": FMUGEN_NS},
                         version="1.0", name=scene.name,
                         generationTool=f"fmugen {__version__}")
    if scene.spec.description:
        root.set("description", scene.spec.description)
    sysel = etree.SubElement(root, f"{{{D}}}System", name=scene.name)
    if scene.spec.description:
        sysel.set("description", scene.spec.description)
    elements = etree.SubElement(sysel, f"{{{D}}}Elements")
    stems = resource_stems([u.name for u in system.units])
    units, ssvs, mds = [], {}, {}
    for u in system.units:
        md = read_fmi_description(u.path, validate=True)  # FMI 2.0 or 3.0, types under SSP 1.0's names
        mds[u.name] = md
        comp = etree.SubElement(elements, f"{{{D}}}Component", name=u.name,
                                source=f"resources/{stems[u.name]}.fmu",
                                type="application/x-fmu-sharedlibrary")
        conns = etree.SubElement(comp, f"{{{D}}}Connectors")
        for v in without_aliases(md):
            if v.causality in ("input", "output") and v.type == "Real":
                k = etree.SubElement(conns, f"{{{D}}}Connector", name=v.name, kind=v.causality)
                r = etree.SubElement(k, f"{{{C}}}Real")
                if v.unit:
                    r.set("unit", v.unit)
                    if v.unit not in units:
                        units.append(v.unit)
        if len(conns) == 0:
            comp.remove(conns)
        b = etree.SubElement(etree.SubElement(comp, f"{{{D}}}ParameterBindings"), f"{{{D}}}ParameterBinding",
                             source=f"resources/{stems[u.name]}.ssv")
        b.set("type", "application/x-ssp-parameter-set")
        ssvs[u.name] = _ssv(u.name, md, dict(u.start_values))
    if system.couplings:
        ce = etree.SubElement(sysel, f"{{{D}}}Connections")
        for c in system.couplings:
            (su, sv), (tu, tv) = c.source, c.target
            e = etree.SubElement(ce, f"{{{D}}}Connection", startElement=su, startConnector=sv, endElement=tu,
                                 endConnector=tv)
            # a stated factor, or a factor of 1 between different unit strings (a scene's stated factor 1,
            # "rad" to "1"): written out, else an importer converts the units itself (SSP 1.0) or refuses them
            units_differ = _var_unit(mds, su, sv) != _var_unit(mds, tu, tv)
            if c.factor != 1.0 or units_differ:
                etree.SubElement(e, f"{{{C}}}LinearTransformation", factor=_fmt(c.factor), offset="0.0")
    if units:
        ue = etree.SubElement(root, f"{{{D}}}Units")
        for un in units:
            _unit_element(ue, un)
    de = etree.SubElement(root, f"{{{D}}}DefaultExperiment", startTime=_fmt(system.start_time),
                          stopTime=_fmt(system.stop_time))
    osp = etree.SubElement(etree.SubElement(de, f"{{{D}}}Annotations"), f"{{{C}}}Annotation",
                           type=OSP_ANNOTATION)
    alg = etree.SubElement(osp, f"{{{OSP_NS}}}Algorithm")
    etree.SubElement(alg, f"{{{OSP_NS}}}FixedStepAlgorithm", baseStepSize=_fmt(libcosim_step))

    ann = etree.SubElement(etree.SubElement(root, f"{{{D}}}Annotations"), f"{{{C}}}Annotation",
                           type=FMUGEN_ANNOTATION)
    F = FMUGEN_NS
    run = etree.SubElement(ann, f"{{{F}}}Run", version="1", scene=scene.name,
                           scheme=str(settings["scheme"]), extrapolation=str(settings["extrapolation"]),
                           step=_fmt(system.step), startTime=_fmt(system.start_time),
                           stopTime=_fmt(system.stop_time))
    if math.isfinite(built.jacobi_limit):
        run.set("jacobiHoldLimit", _fmt(built.jacobi_limit))
    run.set("jacobiHoldStep", _fmt(libcosim_step))
    if system.order:
        etree.SubElement(run, f"{{{F}}}Order").text = " ".join(system.order)
    for u in system.units:
        g = scene.groups.get(u.name)  # None: a component of an [external] SSP
        el = etree.SubElement(run, f"{{{F}}}Unit", name=u.name, fmiType=u.fmi_type,
                              directionalDerivatives=_fmt(bool(u.provides_directional_derivative)),
                              members=" ".join(u.members))
        if u.fmi_type == "cs" and g is not None:
            el.set("solver", g.solver)
        for k, v in u.start_values.items():  # what the master sets before initialisation
            etree.SubElement(el, f"{{{F}}}Start", name=k, value=_fmt(v))
    for r in system.recorded:
        etree.SubElement(run, f"{{{F}}}Record", column=r.column, unit=r.unit, variable=r.variable,
                         physicalUnit=r.physical_unit or "")
    for k, v in sorted(dict(system.settings).items()):
        etree.SubElement(run, f"{{{F}}}Setting", name=str(k), value=_fmt(v) if not isinstance(v, str) else v)
    for text in NOT_EXPRESSIBLE:
        etree.SubElement(run, f"{{{F}}}NotExpressible").text = text
    validate(root, "SystemStructureDescription.xsd", SSD_NAME)
    data = etree.tostring(root, xml_declaration=True, encoding="UTF-8", pretty_print=True)
    parse_xml(data, SSD_NAME)  # what we write, we can read under our own rules
    return data, ssvs


def export_ssp(scene, output, fmus_dir=None, scheme: Optional[str] = None,
               extrapolation: Optional[str] = None, progress=None) -> dict:
    """Build ``scene`` and write the SSP archive ``output``; returns what was written.

    ``fmus_dir``: where the FMUs are built (default: a temporary folder);
    ``scheme``/``extrapolation``: fmugen's run settings recorded in the
    annotation (default: the scene's [cosim], else gauss-seidel/linear, as
    ``fmugen cosim``).
    """
    from ..cosim.master import check_choices

    if not (hasattr(scene, "spec") and hasattr(scene, "build")):
        raise FmugenError(f"export_ssp: scene must be a loaded scene (fmugen.load_scene), got "
                          f"{type(scene).__name__}")
    for arg, value in (("output", output), ("fmus_dir", fmus_dir)):
        if (value is not None or arg == "output") and not isinstance(value, (str, os.PathLike)):
            raise FmugenError(f"export_ssp: {arg} must be a file path, got {type(value).__name__} {value!r:.60}")
    for arg, value in (("scheme", scheme), ("extrapolation", extrapolation)):
        if value is not None and not isinstance(value, str):
            raise FmugenError(f"export_ssp: {arg} must be a name, got {value!r:.60}")
    out = Path(output)
    if out.suffix.lower() != ".ssp":
        raise FmugenError(f"{out}: an SSP archive is named *.ssp")
    if out.is_dir():
        raise FmugenError(f"{out}: is a folder; the archive to write is a file")
    st = dict(scene.spec.cosim or {})
    scheme, extrapolation = check_choices(scheme or st.get("scheme", "gauss-seidel"),
                                          extrapolation or st.get("extrapolation", "linear"))
    with tempfile.TemporaryDirectory(prefix="fmugen_ssp_") as tmp:
        built = scene.build(Path(fmus_dir) if fmus_dir else Path(tmp) / "fmus", progress=progress)
        step = built.default_step or built.system.step
        ssd, ssvs = ssd_xml(built, {"scheme": scheme, "extrapolation": extrapolation}, step)
        stems = resource_stems([u.name for u in built.system.units])
        part = out.with_name(f".{out.name}.{os.getpid()}.part")
        try:
            out.parent.mkdir(parents=True, exist_ok=True)
            with zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as zf:
                zf.writestr(_info(SSD_NAME), ssd)
                for u in built.system.units:
                    zf.writestr(_info(f"resources/{stems[u.name]}.ssv"), ssvs[u.name])
                    zf.writestr(_info(f"resources/{stems[u.name]}.fmu"), Path(u.path).read_bytes())
            os.replace(part, out)
        except OSError as exc:  # a read-only folder, a full disk: one line naming the archive
            raise FmugenError(f"{out}: cannot write the archive: {exc.strerror or exc}") from None
        finally:
            if part.exists():
                part.unlink()
    return {"path": out, "fmus": [u.name for u in built.system.units], "libcosim_step": step,
            "jacobi_limit": built.jacobi_limit, "scheme": scheme, "extrapolation": extrapolation,
            "run_step": run_step(built.system), "built": built}


def run_step(system) -> float:
    """The macro step fmugen's run of ``system`` takes: its ``[cosim] step`` when the scene sets one (what
    the archive's run settings carry and the run read back uses), else the system's step."""
    return float(dict(system.settings).get("step", system.step))


def _var_unit(mds: dict, unit: str, name: str) -> str:
    return next((v.unit or "" for v in mds[unit].modelVariables if v.name == name), "")


def resource_stems(names) -> dict:
    """The file stem under ``resources/`` of each component: its name when that is a plain file name, else
    the name with every other character replaced by ``_`` (and a number when two collide).  A component of an
    [external] SSP carries a name from someone else's file: ``../x`` or ``a/b`` must not become a member path
    (zip slip in the archive we hand on) nor overwrite another component's FMU."""
    out, used = {}, set()
    for name in names:
        stem = name if _PLAIN.fullmatch(name) else re.sub(r"[^A-Za-z0-9_-]", "_", name)[:64] or "component"
        k, base = 2, stem
        while stem.lower() in used:  # case-insensitive: the archive may be extracted on such a file system
            stem, k = f"{base}_{k}", k + 1
        used.add(stem.lower())
        out[name] = stem
    return out


_PLAIN = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}")


def _info(name: str) -> zipfile.ZipInfo:
    i = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))  # reproducible archives
    i.compress_type = zipfile.ZIP_DEFLATED
    i.external_attr = 0o644 << 16
    return i
