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

FORMAT = 2  # of the stored record (2: the FMUs copied into the artefact)


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
                  "jacobi_limit": built.jacobi_limit if built.jacobi_limit != float("inf") else None,
                  "default_step": built.default_step}
        fd, tmp = tempfile.mkstemp(dir=target.parent, suffix=".part")
        with os.fdopen(fd, "w") as f:
            json.dump(record, f, default=str)
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
        stale = _remove_stale(out, [f"{g}.fmu" for g in reports])
        system = _system_from_json(self.record["system"], {g: out / f"{g}.fmu" for g in reports})
        lim = self.record.get("jacobi_limit")
        return BuiltScene(self.scene, out, reports, system, list(self.record.get("inputs", [])), stale,
                          float("inf") if lim is None else float(lim), float(self.record.get("default_step", 0.0)))


def cached_analysis(path, sets=None, allow_factories: bool = False) -> Optional[CachedAnalysis]:
    """The stored analysis of the scene file ``path`` with ``sets``, when there is one with its FMUs."""
    key = analysis_key(path, sets)
    if key is None:
        return None
    try:
        record = json.loads(_record_path(key).read_text())
        if record.get("format") != FORMAT:
            return None
    except (OSError, ValueError):
        return None
    folder = _record_path(key).with_suffix("")
    if not all((folder / f"{g}.fmu").is_file() for g in record.get("fmus", {})):
        return None
    return CachedAnalysis(key, record, path, sets, allow_factories)


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
