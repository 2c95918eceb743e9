"""The scene analysis, cached with the FMUs: a run from cached FMUs starts in well under a second.

Building a scene twice costs little when its FMUs are cached
(:mod:`fmugen.scene.build`), but *knowing* that they are cached needs their
keys, and the keys need the scene analysed: every instance's symbolic model
derived (the PUMA's: seconds of sympy), the connections checked, the state of
rest solved.  This module caches the outcome of that analysis -- the
:class:`~fmugen.cosim.system.CosimSystem` (couplings, recorded columns, the
consistent start values of every FMU), the report of the initial state and
the FMUs themselves (copies, each with its sha256) -- as a separate artefact,
``analysis/<key>.json`` and ``analysis/<key>/`` in the cache folder, under its own **content key**: the generator (every
source file of fmugen and of its C runtime), the scene file's bytes and
location, the ``--set`` overrides, and the bytes of every ``.toml`` file the
scene names (robot files, URDF, parameter sets, component files).  Change any of them and the scene
is analysed again.  Scenes with Python factories are never cached this way
(their code is not part of the key).

:func:A record is trusted only as written: it carries the sha256 of its own content
and key (:func:`_seal`), its FMU copies their sha256 each, and its structure is
checked before use (:func:`_check_record`: group names are identifiers -- they
become file names --, start values finite numbers, every field of the type
it is read as).  A truncated, damaged, edited or hostile record -- not JSON,
nested thousands deep, a directory or a device where the file should be,
larger than :data:`MAX_RECORD_BYTES` -- is ignored: the scene is analysed
and built again, and the record written anew.

:func:`build_scene_cached` is what the commands call: the cached analysis and
FMUs when both are there (nothing of sympy, scipy or the scene models is
imported), else :func:`fmugen.scene.load_scene` and ``Scene.build`` as
before, then the analysis is stored.  The :class:`BuiltScene` it returns
loads the full :class:`~fmugen.scene.Scene` only when something asks for it.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Optional

from .build import BuiltScene, FmuReport, Progress, cache_dir, generator_fingerprint
from .settings import parse_sets

FORMAT = 3  # of the stored record (2: the FMUs copied into the artefact; 3: the record sealed by its digest)
#: largest record read (the PUMA's is ~100 kB); a larger file in the cache is not a record of ours
MAX_RECORD_BYTES = 16 * 2**20


def _toml_names(data, out: set) -> None:
    """Every string in the file data that names a .toml or .urdf file (robots, parameter sets, components)."""
    if isinstance(data, dict):
        for v in data.values():
            _toml_names(v, out)
    elif isinstance(data, list):
        for v in data:
            _toml_names(v, out)
    elif isinstance(data, str) and data.lower().endswith((".toml", ".urdf")):
        out.add(data[len("file:"):] if data.startswith("file:") else data)  # type = "file:part.toml" too


def analysis_key(path, sets=None) -> Optional[str]:
    """The content key of a scene's analysis, or None when it is not cacheable (factories, unreadable)."""
    import tomllib

    from ..errors import FmugenError, read_text_file

    path = Path(path).resolve()
    try:  # bounded: a device, a FIFO or a huge file is refused, never read (the full load says so)
        raw = read_text_file(path, "scene file").encode("utf-8")
        data = tomllib.loads(raw.decode("utf-8"))
    except (OSError, FmugenError, UnicodeDecodeError, tomllib.TOMLDecodeError, RecursionError):
        return None  # the full load reports it
    sets = parse_sets(sets)
    instances = data.get("instances")
    if not isinstance(instances, dict) or any(isinstance(i, dict) and "factory" in i for i in instances.values()):
        return None
    names: set = set()
    _toml_names(data, names)
    _toml_names(list(sets.values()), names)
    files = {}
    for name in sorted(names):
        for base in (path.parent, Path.cwd()):
            p = (base / name).resolve()
            if p.is_file():
                files[f"{base == path.parent}:{name}"] = hashlib.sha256(p.read_bytes()).hexdigest()
    parts = {"format": FORMAT, "generator": generator_fingerprint(), "scene": str(path),
             "bytes": hashlib.sha256(raw).hexdigest(), "sets": sets, "files": files}
    return hashlib.sha256(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()[:32]


def _record_path(key: str) -> Path:
    return cache_dir() / "analysis" / f"{key}.json"


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _seal(key: str, record: dict) -> str:
    """The digest of ``record`` (without its own "digest") under ``key``: what a served record must match."""
    body = {k: v for k, v in record.items() if k != "digest"}
    text = json.dumps(body, sort_keys=True, default=str, allow_nan=False)
    return hashlib.sha256(f"{key} {text}".encode()).hexdigest()


def _is_number(v) -> bool:
    import math

    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _check_record(record, key: str) -> None:
    """Raise ValueError unless ``record`` is a sealed record of :data:`FORMAT` whose fields have the types
    they are read as (the FMU reports' fields, the system's units, couplings and start values)."""
    from ..errors import IDENTIFIER_PATTERN

    def need(ok, what):
        if not ok:
            raise ValueError(what)

    need(isinstance(record, dict), "not a table")
    need(record.get("format") == FORMAT, "another format")
    need(record.get("digest") == _seal(key, record), "digest does not match")
    need(isinstance(record.get("name"), str) and isinstance(record.get("initial_report"), str), "name/report")
    x0 = record.get("x0")
    need(isinstance(x0, dict) and all(isinstance(k, str) and _is_number(v) for k, v in x0.items()), "x0")
    spec = record.get("spec")
    need(isinstance(spec, dict) and isinstance(spec.get("name"), str)
         and all(_is_number(spec.get(k)) for k in ("start", "stop", "step"))
         and isinstance(spec.get("cosim"), dict) and isinstance(spec.get("bonds"), list), "spec")
    fields = {f.name for f in dataclasses.fields(FmuReport)} - {"path", "cached", "build_seconds"}
    fmus = record.get("fmus")
    need(isinstance(fmus, dict) and fmus, "fmus")
    for g, entry in fmus.items():
        need(isinstance(g, str) and IDENTIFIER_PATTERN.match(g) is not None, "a group name is no identifier")
        need(isinstance(entry, dict) and isinstance(entry.get("sha256"), str) and len(entry["sha256"]) == 64
             and isinstance(entry.get("report"), dict) and fields <= set(entry["report"])
             and set(entry["report"]) <= fields | {"cached", "build_seconds"}, f"fmus.{g}")
        r = entry["report"]
        need(r.get("group") == g and isinstance(r.get("members"), list)
             and all(isinstance(r.get(k), int) and not isinstance(r.get(k), bool) and r[k] >= 0
                     for k in ("states", "inputs", "outputs", "parameters", "total_ops", "library_bytes")),
             f"fmus.{g}.report")
    system = record.get("system")
    need(isinstance(system, dict) and isinstance(system.get("units"), list)
         and isinstance(system.get("couplings"), list) and isinstance(system.get("recorded"), list)
         and all(_is_number(system.get(k)) for k in ("start", "stop", "step")), "system")
    for u in system["units"]:
        need(isinstance(u, dict) and u.get("name") in fmus and u.get("fmi_type") in ("cs", "me")
             and isinstance(u.get("start_values"), dict)
             and all(isinstance(k, str) and (_is_number(v) or isinstance(v, (bool, str)))
                     for k, v in u["start_values"].items())
             and isinstance(u.get("directional"), bool) and isinstance(u.get("members"), list), "system.units")
    for c in system["couplings"]:
        need(isinstance(c, dict) and all(isinstance(c.get(k), list) and len(c[k]) == 2 and c[k][0] in fmus
                                         and isinstance(c[k][1], str) for k in ("source", "target"))
             and _is_number(c.get("factor")), "system.couplings")
    for r in system["recorded"]:
        need(isinstance(r, list) and len(r) == 4 and r[1] in fmus and isinstance(r[0], str), "system.recorded")
    need(isinstance(system.get("settings", {}), dict) and isinstance(system.get("rest_unstable", []), list)
         and isinstance(record.get("inputs", []), list), "system.settings")
    lim, step = record.get("jacobi_limit"), record.get("default_step", 0.0)
    need((lim is None or lim == "nan" or _is_number(lim)) and _is_number(step), "jacobi_limit/default_step")


def _system_to_json(system) -> dict:
    return {"name": system.name, "start": system.start_time, "stop": system.stop_time, "step": system.step,
            "order": list(system.order) if system.order else None, "settings": dict(system.settings),
            "units": [{"name": u.name, "fmi_type": u.fmi_type, "start_values": dict(u.start_values),
                       "directional": bool(u.provides_directional_derivative), "members": list(u.members)}
                      for u in system.units],
            "couplings": [{"source": list(c.source), "target": list(c.target), "factor": c.factor, "unit": c.unit}
                          for c in system.couplings],
            "recorded": [[r.column, r.unit, r.variable, r.physical_unit] for r in system.recorded],
            "rest_unstable": list(getattr(system, "rest_unstable", ()))}


def _system_from_json(d: dict, paths: dict):
    from ..cosim.system import CosimSystem, Coupling, Recorded, Unit

    units = tuple(Unit(u["name"], Path(paths[u["name"]]), u["fmi_type"], dict(u["start_values"]), u["directional"],
                       tuple(u["members"])) for u in d["units"])
    couplings = tuple(Coupling(tuple(c["source"]), tuple(c["target"]), c["factor"], c["unit"]) for c in d["couplings"])
    recorded = tuple(Recorded(*r) for r in d["recorded"])
    return CosimSystem(d["name"], units, couplings, recorded, d["start"], d["stop"], d["step"],
                       tuple(d["order"]) if d["order"] else None, dict(d["settings"]),
                       tuple(d.get("rest_unstable", ())))


class _CachedInitial:
    """The initial state as cached: its report and values; anything else from the full scene."""

    def __init__(self, report: str, values: dict, scene):
        self._report, self.values, self._scene = report, values, scene

    def report(self) -> str:
        return self._report

    def __getattr__(self, name):
        return getattr(self._scene.full.initial, name)


class _CachedSpec:
    """What the commands read of a scene's spec before running (times, [cosim], bonds); the rest loads it."""

    def __init__(self, d: dict, scene):
        self.name, self.start, self.stop, self.step = d["name"], d["start"], d["stop"], d["step"]
        self.cosim, self._scene = dict(d["cosim"]), scene
        self.bonds = _bonds_from_json(d["bonds"])

    def __getattr__(self, name):
        return getattr(self._scene.full.spec, name)


def _bonds_to_json(bonds) -> list:
    return [{"ends": list(b.ends), "type": b.type, "signals": [list(x) for x in b.signals], "power": list(b.power)}
            for b in bonds]


@dataclasses.dataclass(frozen=True)
class CachedBond:
    """A bond as :class:`fmugen.scene.connect.Bond` has it (that module imports the component library,
    sympy included: seconds of start-up; :mod:`fmugen.scene.bonds` reads only these fields)."""

    ends: tuple
    type: str
    signals: tuple
    power: tuple

    def __str__(self) -> str:
        return f"{self.ends[0]} <-> {self.ends[1]} ({self.type})"


def _bonds_from_json(items) -> tuple:
    return tuple(CachedBond(tuple(b["ends"]), b["type"], tuple(tuple(x) for x in b["signals"]), tuple(b["power"]))
                 for b in items or ())


class DeferredScene:
    """Stands in for the :class:`~fmugen.scene.Scene` of a cached analysis; loads it on first use of
    anything the cache does not hold (name, spec times, [cosim], bonds and the initial state's report)."""

    def __init__(self, path, sets, allow_factories, record):
        self._args = (path, sets, allow_factories)
        self._full = None
        self.name = record["name"]
        self.spec = _CachedSpec(record["spec"], self)
        self.initial = _CachedInitial(record["initial_report"], record["x0"], self)

    @property
    def full(self):
        if self._full is None:
            from .scene import load_scene

            path, sets, allow = self._args
            self._full = load_scene(path, set=sets, allow_factories=allow)
        return self._full

    def __getattr__(self, name):
        return getattr(self.full, name)


def store(key: str, scene, built: BuiltScene) -> None:
    """Write the analysis of ``scene`` (built as ``built``) and copies of its FMUs under ``key``; a failure
    to write is ignored (the next run analyses again)."""
    target = _record_path(key)
    folder = target.with_suffix("")
    spec = scene.spec
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fmus = {}
        for g, r in built.fmus.items():
            tmp = folder / f".{g}.{os.getpid()}.part"
            shutil.copyfile(r.path, tmp)
            os.replace(tmp, folder / f"{g}.fmu")
            d = dataclasses.asdict(r)
            d.pop("path")
            fmus[g] = {"report": d, "sha256": _digest(folder / f"{g}.fmu")}
        record = {"format": FORMAT, "name": scene.name, "initial_report": scene.initial.report(),
                  "x0": {k: float(v) for k, v in scene.initial.values.items()},
                  "spec": {"name": spec.name, "start": spec.start, "stop": spec.stop, "step": spec.step,
                           "cosim": dict(spec.cosim or {}), "bonds": _bonds_to_json(getattr(spec, "bonds", ()))},
                  "fmus": fmus, "system": _system_to_json(built.system), "inputs": list(built.inputs),
                  # inf: no limit (None); NaN: not computed ("nan": JSON has no NaN)
                  "jacobi_limit": None if built.jacobi_limit == float("inf") else
                  "nan" if built.jacobi_limit != built.jacobi_limit else built.jacobi_limit,
                  "default_step": built.default_step}
        record = json.loads(json.dumps(record, default=str, allow_nan=False))  # as it will be read back
        record["digest"] = _seal(key, record)
        _check_record(record, key)  # never store what would not be served
        fd, tmp = tempfile.mkstemp(dir=target.parent, suffix=".part")
        with os.fdopen(fd, "w") as f:
            json.dump(record, f)
        os.replace(tmp, target)
    except (OSError, TypeError, ValueError):
        pass


class CachedAnalysis:
    """A scene's stored analysis: :attr:`scene` (a :class:`DeferredScene`) now, the FMUs on
    :meth:`materialise`."""

    def __init__(self, key: str, record: dict, path, sets, allow_factories):
        self.key, self.record = key, record
        self.scene = DeferredScene(path, sets, allow_factories, record)

    def materialise(self, out_dir, progress=None) -> Optional[BuiltScene]:
        """The FMUs copied into ``out_dir`` (checked against their digests) and the built scene; None when
        a copy in the cache is damaged (then the caller builds as usual)."""
        from .build import _remove_stale

        progress = progress or Progress()
        folder = _record_path(self.key).with_suffix("")
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        reports = {}
        for g, entry in self.record["fmus"].items():
            target = out / f"{g}.fmu"
            tmp = out / f".{g}.fmu.{os.getpid()}.part"
            try:
                shutil.copyfile(folder / f"{g}.fmu", tmp)
                if _digest(tmp) != entry["sha256"]:
                    tmp.unlink()
                    return None
            except OSError:
                return None
            os.replace(tmp, target)
            r = FmuReport(**{**entry["report"], "path": target, "cached": True, "build_seconds": 0.0})
            r.members = tuple(r.members)
            reports[g] = r
            progress(r.line())
        try:  # checked when read (_check_record); a record that still does not fit is not served
            system = _system_from_json(self.record["system"], {g: out / f"{g}.fmu" for g in reports})
        except (KeyError, TypeError, ValueError, AttributeError):
            return None
        stale = _remove_stale(out, [f"{g}.fmu" for g in reports])
        lim = self.record.get("jacobi_limit")
        return BuiltScene(self.scene, out, reports, system, list(self.record.get("inputs", [])), stale,
                          float("inf") if lim is None else float(lim), float(self.record.get("default_step", 0.0)))


def cached_analysis(path, sets=None, allow_factories: bool = False) -> Optional[CachedAnalysis]:
    """The stored analysis of the scene file ``path`` with ``sets``, when there is one with its FMUs."""
    from ..errors import FmugenError, read_text_file

    key = analysis_key(path, sets)
    if key is None:
        return None
    rec = _record_path(key)
    try:  # bounded, a regular file, UTF-8 (read_text_file); then sealed and well-typed, or not served
        if rec.is_file() and rec.stat().st_size > MAX_RECORD_BYTES:
            return None
        record = json.loads(read_text_file(rec, "analysis record"))
        _check_record(record, key)
    except (OSError, ValueError, FmugenError, RecursionError):  # FmugenError: missing, a device, not UTF-8
        return None
    folder = rec.with_suffix("")
    if not all((folder / f"{g}.fmu").is_file() for g in record["fmus"]):
        return None
    try:
        return CachedAnalysis(key, record, path, sets, allow_factories)
    except (KeyError, TypeError, ValueError, AttributeError):
        return None


def build_scene_cached(path, out_dir, sets=None, allow_factories: bool = False, progress=None,
                       scene=None) -> BuiltScene:
    """The scene file ``path`` built into ``out_dir``: from the cached analysis and FMUs when both are there,
    else analysed (or ``scene``, loaded already from the same path and sets) and built, and the analysis
    stored for next time."""
    if scene is None or isinstance(scene, DeferredScene):
        cached = cached_analysis(path, sets, allow_factories)
        if cached is not None:
            built = cached.materialise(out_dir, progress)
            if built is not None:
                return built
    if scene is None or isinstance(scene, DeferredScene):
        from .scene import load_scene

        scene = scene.full if isinstance(scene, DeferredScene) else load_scene(path, set=sets,
                                                                               allow_factories=allow_factories)
    built = scene.build(out_dir, progress=progress)
    key = analysis_key(path, sets)
    if key is not None:
        store(key, scene, built)
    return built
