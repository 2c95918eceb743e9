"""An SSP's components inside a scene: a supplier's FMUs beside the scene's own instances.

    [external]
    ssp = "supplier.ssp"                    # path relative to the scene file
    connections = [
      ["joint.w", "B.v_in", 1000.0],        # scene -> component (a stated factor, as in [scene] connections)
      ["B.F", "joint.tau_load", 1.0],       # component -> scene
    ]
    record = ["B.F"]                         # component outputs to record (columns "component.connector")

The archive is read and its system loaded as :mod:`fmugen.ssp` reads any
archive (safely, its parameter bindings and internal connections honoured);
its components become units of the scene's co-simulation system next to
the scene's own FMUs, under their SSP names (which must not be FMU groups
of the scene).  Connections are checked like the scene's: both ends exist,
direction (a state or output drives an input), units equal in SI base units
unless a factor is stated, no input driven twice.  A scene input that a
component drives stays an input of its FMU (as if listed in ``[scene]
inputs``) and a scene variable a component reads stays an output.

What a scene with external parts cannot do: it has no symbolic model of the
whole, so there is no reference solution (``fmugen reference`` and a
scene's ``fmugen report`` refuse it; export it with ``fmugen ssp`` and run
``fmugen report x.ssp`` for a self-convergence reference); its state of rest
and held-input Jacobi limit are those of the scene's own instances, with
the externally driven inputs at their start values.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from .errors import SceneError, did_you_mean

EXTERNAL_KEYS = {"ssp", "connections", "record"}


@dataclass
class External:
    path: Path
    system: object  # CosimSystem of the archive
    to_scene: list = field(default_factory=list)  # (component, connector, inst, var, factor)
    from_scene: list = field(default_factory=list)  # (inst, var, component, connector, factor)
    record: list = field(default_factory=list)  # (component, connector, unit)


def _connections(raw, where):
    if not isinstance(raw, list):
        raise SceneError(f"{where} connections must be a list of [source, target] or [source, target, factor]")
    out = []
    for k, c in enumerate(raw):
        w = f"{where} connections[{k}]"
        if isinstance(c, dict):
            if set(c) - {"from", "to", "factor"} or "from" not in c or "to" not in c:
                raise SceneError(f"{w}: a table connection has keys from, to and (optional) factor")
            s, t, f = c["from"], c["to"], c.get("factor")
        elif isinstance(c, list) and len(c) in (2, 3):
            s, t, f = c[0], c[1], (c[2] if len(c) == 3 else None)
        else:
            raise SceneError(f"{w}: expected [\"source\", \"target\"] or [\"source\", \"target\", factor], got {c!r}")
        if not isinstance(s, str) or not isinstance(t, str) or "." not in s or "." not in t:
            raise SceneError(f"{w}: endpoints are strings 'instance.variable' or 'component.connector'")
        if f is not None and (isinstance(f, bool) or not isinstance(f, (int, float)) or not math.isfinite(f) or f == 0):
            raise SceneError(f"{w}: factor must be a finite, non-zero number, got {f!r}")
        out.append((s, t, None if f is None else float(f), w))
    return out


def read_external(scene, raw) -> External:
    """The scene's ``[external]`` table checked against the scene and the archive."""
    from ..components.connect import same_unit
    from ..ssp.loader import load_system

    src = scene.src
    where = f"{src}: [external]"
    if not isinstance(raw, dict):
        raise SceneError(f"{where} must be a table")
    for k in raw:
        if k not in EXTERNAL_KEYS:
            raise SceneError(f"{where} has unknown key {k!r}{did_you_mean(k, EXTERNAL_KEYS)}")
    if not isinstance(raw.get("ssp"), str):
        raise SceneError(f"{where} ssp must name an SSP archive (a path relative to the scene file)")
    p = Path(raw["ssp"])
    p = p if p.is_absolute() else Path(src).parent / p
    system = load_system(p)
    comps = {u.name: u for u in system.units}
    clash = sorted(set(comps) & (set(scene.groups) | set(scene.spec.instances)))
    if clash:
        raise SceneError(f"{where}: the archive's component(s) {', '.join(clash)} have the name of an instance or "
                         f"FMU of the scene")
    from fmpy import read_model_description

    fmi = {name: {v.name: v for v in read_model_description(str(u.path), validate=False).modelVariables}
           for name, u in comps.items()}
    ext = External(p, system)
    driven = {(ti, tv) for _, _, ti, tv, _ in scene.connections}
    driven |= {c.target for c in system.couplings}
    for s, t, f, w in _connections(raw.get("connections", []), where):
        si, sv = s.split(".", 1)
        ti, tv = t.split(".", 1)
        if si in comps and ti in comps:
            raise SceneError(f"{w}: {s} -> {t} joins two components of the archive: connect them in the archive")
        if si not in comps and ti not in comps:
            raise SceneError(f"{w}: {s} -> {t} joins no component of the archive ({', '.join(comps)}): put it "
                             f"in [scene] connections")
        if si in comps:
            v = fmi[si].get(sv)
            if v is None or v.causality != "output":
                raise SceneError(f"{w}: {s} is not an output of component {si}"
                                 f"{did_you_mean(sv, [n for n, x in fmi[si].items() if x.causality == 'output'])}")
            ti_, tv_ = scene._endpoint(t, w)
            kind, var = scene._var(ti_, tv_, w)
            if kind != "input":
                raise SceneError(f"{w}: wrong direction: {t} is a {kind}, not an input")
            su, tu = v.unit or "", var.unit or ""
            target = (ti_, tv_)
        else:
            si_, sv_ = scene._endpoint(s, w)
            kind, var = scene._var(si_, sv_, w)
            if kind == "input":
                raise SceneError(f"{w}: wrong direction: {s} is an input")
            v = fmi[ti].get(tv)
            if v is None or v.causality != "input":
                raise SceneError(f"{w}: {t} is not an input of component {ti}"
                                 f"{did_you_mean(tv, [n for n, x in fmi[ti].items() if x.causality == 'input'])}")
            su, tu = var.unit or "", v.unit or ""
            target = (ti, tv)
        if f is None and not same_unit(su, tu):
            raise SceneError(f"{w}: unit mismatch: {s} is in [{su or '1'}] but {t} expects [{tu or '1'}]; state a "
                             f"conversion factor")
        if target in driven:
            raise SceneError(f"{w}: input {t} is already driven")
        driven.add(target)
        if si in comps:
            ext.to_scene.append((si, sv, target[0], target[1], f))
        else:
            ext.from_scene.append((si_, sv_, ti, tv, f))
    rec = raw.get("record", [])
    if not isinstance(rec, list) or not all(isinstance(r, str) for r in rec):
        raise SceneError(f"{where} record must be a list of 'component.connector'")
    for r in rec:
        c, _, n = r.partition(".")
        v = fmi.get(c, {}).get(n)
        if v is None or v.causality != "output":
            raise SceneError(f"{where} record: {r} is not an output of a component of the archive")
        ext.record.append((c, n, v.unit or ""))
    return ext


def extend_system(scene, system):
    """``system`` (the scene's own FMUs) with the archive's components, couplings and records added."""
    from dataclasses import replace

    from ..cosim.system import Coupling, Recorded

    ext = scene.external
    couplings = list(system.couplings) + list(ext.system.couplings)
    for c, n, inst, var, f in ext.to_scene:
        unit = scene._var(inst, var, scene.src)[1].unit or ""
        couplings.append(Coupling((c, n), (scene.group_of(inst), scene.fmu_name(inst, var)),
                                  1.0 if f is None else f, unit))
    for inst, var, c, n, f in ext.from_scene:
        couplings.append(Coupling((scene.group_of(inst), scene.fmu_name(inst, var)), (c, n),
                                  1.0 if f is None else f, ""))
    recorded = list(system.recorded) + [Recorded(f"{c}.{n}", c, n, u) for c, n, u in ext.record]
    order = tuple(system.order or (u.name for u in system.units)) + tuple(u.name for u in ext.system.units)
    return replace(system, units=tuple(system.units) + tuple(ext.system.units), couplings=tuple(couplings),
                   recorded=tuple(recorded), order=order)
