"""Build a scene: one FMU per group, reused from a cache when nothing changed.

The cache key of an FMU is a hash of everything that shapes it: the group's
instances (the contents of their robot files, parameter-set files -- the
scene-level ``parameter_set`` included -- and factory modules, options,
parameter values, what is fixed), the scene's name and description, the
connections and records touching it, the validity ranges it takes from the
inputs it drives, the initial values baked into it, the FMI type and
internal-solver choice, whether pruning is on, and the generator itself
(every source file of fmugen and of the C runtime).  Cached FMUs live in
``$FMUGEN_CACHE`` (default ``~/.cache/fmugen``); an entry's metadata records
its key and the sha256 of its FMU, and an entry is served only when both
match (checked again on the copy written out), so a truncated, swapped or
damaged entry is rebuilt, never copied out.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Optional

import numpy as np

from .. import __version__
from ..cache import cache_home
from .errors import SceneError


@dataclass
class FmuReport:
    group: str
    path: Path
    members: tuple
    states: int
    inputs: int
    outputs: int
    parameters: int
    ops: dict  # function -> operation count text
    total_ops: int  # multiplications + additions + divisions of evaluate and jacobian
    library_bytes: int
    build_seconds: float
    cached: bool
    has_jacobian: bool
    removed: list = field(default_factory=list)

    def line(self) -> str:
        how = "cached" if self.cached else f"built in {self.build_seconds:.1f} s"
        return (f"{self.path.name}: {self.states} states, {self.inputs} inputs, {self.outputs} outputs, "
                f"{self.total_ops} ops{'' if self.has_jacobian else ' (no Jacobian)'}, "
                f"library {self.library_bytes / 1024:.0f} KiB, {how}")


@dataclass
class BuiltScene:
    scene: object
    out_dir: Path
    fmus: dict  # group -> FmuReport
    system: object  # CosimSystem
    inputs: list = field(default_factory=list)  # inputs of the system ("inst.var"): undriven, not fixed
    stale: list = field(default_factory=list)  # FMUs of an earlier build of this folder, removed
    jacobi_limit: float = float("inf")  # first unstable held-input Jacobi step [s] (linearised at rest)
    default_step: float = 0.0  # the FMUs' DefaultExperiment stepSize: stable for held-input Jacobi

    def summary(self) -> str:
        lines = [self.scene.initial.report()]
        for r in self.fmus.values():
            lines.append(r.line())
            lines += [f"    pruned: {x}" for x in r.removed]
        lines.append("inputs of the system: " + (", ".join(self.inputs) if self.inputs else
                                                 "none (undriven inputs are fixed; [scene] inputs keeps them)"))
        if len(self.fmus) > 1:
            lim = "no limit found" if self.jacobi_limit == float("inf") else \
                "limit not computed" if self.jacobi_limit != self.jacobi_limit else \
                f"stable below H = {self.jacobi_limit:.3g} s"
            lines.append(f"held-input Jacobi (most importers' loop): {lim} (linearised at the initial state); "
                         f"DefaultExperiment stepSize {self.default_step:g} s")
        if self.stale:
            lines.append(f"removed from an earlier build in {self.out_dir}: {', '.join(self.stale)}")
        return "\n".join(lines)


class Progress:
    """Stage messages on a terminal (stderr), silent when piped."""

    def __init__(self, enabled: Optional[bool] = None):
        self.enabled = sys.stderr.isatty() if enabled is None else enabled
        self.t0 = time.perf_counter()

    def __call__(self, text: str) -> None:
        if self.enabled:
            print(f"[{time.perf_counter() - self.t0:6.1f} s] {text}", file=sys.stderr, flush=True)


def cache_dir() -> Path:
    return cache_home()


@lru_cache(maxsize=1)
def generator_fingerprint() -> str:
    """Hash of every source file of fmugen and of its C runtime: any change invalidates the cache."""
    h = hashlib.sha256(__version__.encode())
    # c_runtime/ next to the package (fmugen.fmi.build.runtime_dir, which is not imported: it loads sympy,
    # and a run from cached FMUs must start in well under a second)
    roots = [Path(__file__).resolve().parents[1], Path(__file__).resolve().parents[2] / "c_runtime"]
    for root in roots:
        for p in sorted(root.rglob("*")):
            if p.suffix in (".py", ".c", ".h", ".toml") and "__pycache__" not in p.parts:
                h.update(p.relative_to(root).as_posix().encode())
                h.update(p.read_bytes())
    return h.hexdigest()


def _file_digest(path) -> str:
    """sha256 of a file's content ("missing: <path>" when it cannot be read: the model step reports that)."""
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return f"missing: {path}"


def _set_digest(pset) -> str:
    """A parameter set as it enters a key: a file by its content; a shipped set by name (the
    generator fingerprint holds the shipped files' contents)."""
    if isinstance(pset, str) and pset.endswith(".toml"):
        return _file_digest(pset)
    return str(pset)


def _factory_digest(ref: str) -> str:
    """A factory's module by the content of its source file, where Python can find it."""
    import importlib.util

    try:
        spec = importlib.util.find_spec(ref.split(":", 1)[0])
    except (ImportError, ValueError):
        spec = None
    origin = getattr(spec, "origin", None)
    return _file_digest(origin) if origin and Path(origin).is_file() else ref


def _group_key(scene, group: str, prune: bool, x0: dict, u0: Optional[dict] = None) -> str:
    """Everything that shapes the group's FMU, files by their content (never by their names)."""
    u0 = u0 or {}
    g = scene.groups[group]
    members = set(g.members)
    parts = {
        "generator": generator_fingerprint(),
        "group": dataclasses.asdict(g),
        "scene": [scene.spec.name, scene.spec.description],
        "prune": prune,
        "jacobian": scene.needs_jacobian(g),
        "instances": {},
        "connections": [c for c in scene.connections if c[0] in members or c[2] in members],
        "record": [r for r in scene.spec.record if r.split(".", 1)[0] in members],
        "x0": {k: v for k, v in sorted(x0.items()) if k.split(".", 1)[0] in members},
        "u0": {k: v for k, v in sorted(u0.items()) if k.split(".", 1)[0] in members},
        "inputs": [i for i in scene.spec.inputs if i.split(".", 1)[0] in members],
        "external": scene.external_links(members),
        "run": [scene.spec.start, scene.spec.stop, scene.spec.step, scene.spec.tolerance],
        "platforms": scene.spec.platforms,
        "fmi_version": scene.spec.fmi_version,
        "default_set": _set_digest(scene.spec.parameter_set),
        # validity ranges the group's sources take from the inputs they drive (other instances' models)
        "ranges": sorted((si, sv, scene._var(ti, tv, scene.src)[1].min, scene._var(ti, tv, scene.src)[1].max)
                         for si, sv, ti, tv, f in scene.connections if si in members and f is None),
    }
    for inst in sorted(members):
        ins = scene.spec.instances[inst]
        d = dataclasses.asdict(ins)
        d["locked"] = {str(k): v for k, v in ins.locked.items()}
        if ins.kind in ("robot", "file"):
            d["file"] = _file_digest(ins.source)
        elif ins.kind == "factory":
            d["module"] = _factory_digest(ins.source)
        if ins.kind != "robot":
            d["set_file"] = _set_digest(ins.parameter_set or (scene.spec.parameter_set if ins.kind != "factory"
                                                               else None))
        d["sets"] = scene._sets.get(inst, {})
        parts["instances"][inst] = d
    text = json.dumps(parts, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:32]


def _cached_entry(cdir: Path, key: str):
    """The metadata of cache entry ``key`` when the entry is whole (its FMU has the recorded hash,
    its metadata names this key); None otherwise (a truncated, swapped or damaged entry is rebuilt)."""
    fmu, meta = cdir / f"{key}.fmu", cdir / f"{key}.json"
    try:
        d = json.loads(meta.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(d, dict) or d.get("key") != key or not isinstance(d.get("sha256"), str):
        return None
    if _file_digest(fmu) != d["sha256"]:
        return None
    return d


def _total_ops(op_counts: dict) -> int:
    n = 0
    for ops in op_counts.values():
        t = ops.total
        n += t.mul + t.add + t.div + t.n_calls
    return n


#: the list of files a scene build wrote into its output folder (to remove them when a later build does not)
MANIFEST = ".fmugen-build.json"


def _runtime_start(scene, g) -> dict:
    """The group's internal solver and tolerances as start values of the FMU (XML and binary alike)."""
    from .file import SOLVERS

    tol = g.tolerance or scene.spec.tolerance
    return {"solver.method": SOLVERS[g.solver], "solver.rtol": tol, "solver.atol": tol}


def _remove_stale(out: Path, written: list) -> list:
    """Remove the FMUs an earlier build listed in ``out/MANIFEST`` that this build did not write.

    Only names the manifest lists, only plain ``.fmu`` files directly in ``out``: a folder that
    also holds the user's own files loses none of them.
    """
    removed = []
    try:
        old = json.loads((out / MANIFEST).read_text()).get("fmus", [])
    except (OSError, ValueError, AttributeError):
        old = []
    for name in old:
        if not isinstance(name, str) or name in written or "/" in name or "\\" in name \
                or not name.endswith(".fmu"):
            continue
        p = out / name
        if p.is_file() and not p.is_symlink():
            p.unlink()
            removed.append(name)
    (out / MANIFEST).write_text(json.dumps({"generator": f"fmugen {__version__}", "fmus": written}) + "\n")
    return removed


def build_scene(scene, out_dir, prune: Optional[bool] = None, progress=None, use_cache: bool = True,
                jobs: Optional[int] = None) -> BuiltScene:
    """Build every group of ``scene`` into ``out_dir/<group>.fmu`` and return what was built.

    ``prune`` None: the scene's ``[scene] prune``.  Each FMU carries the
    scene's state of rest as start values (states and inputs) and its
    group's internal solver and tolerances (``solver.method``,
    ``solver.rtol``, ``solver.atol``).  FMUs that an earlier build wrote
    into ``out_dir`` and this one does not are removed (``.fmugen-build.json``
    lists what a build wrote; nothing else is touched).

    Every group model is derived first, so an error in any of them stops the
    build before a file is written; the FMUs are then generated and compiled
    ``jobs`` at a time (default: the number of cores, at most 4) into a
    staging folder and moved into ``out_dir`` together when all succeeded.
    """
    from ..fmi.build import build_fmu, cancellable

    progress = progress or Progress()
    prune = scene.spec.prune if prune is None else bool(prune)
    out = Path(out_dir)
    progress(f"scene {scene.name}: initial state ({scene.spec.initial})")
    x0 = scene.initial.values
    u0 = scene.rest_inputs
    cdir = cache_dir() / "fmus"
    keys = {gname: _group_key(scene, gname, prune, x0, u0) for gname in scene.groups}
    limit = _jacobi_limit(scene, keys, use_cache)
    from .stability import stable_step  # here: it imports scipy (start-up of a run from cached FMUs)

    default_step = stable_step(limit, scene.spec.step, STABLE_SAFETY)
    plan = {}  # group -> (key, model or None when cached, removed)
    for gname, g in scene.groups.items():
        key = hashlib.sha256(f"{keys[gname]} {default_step!r}".encode()).hexdigest()[:32]
        if use_cache and _cached_entry(cdir, key) is not None:
            plan[gname] = (key, None, [])
        else:
            progress(f"{gname}: derive ({', '.join(g.members)})")
            model, removed = scene.group_model(gname, prune=prune, x0=x0, u0=u0)
            plan[gname] = (key, model, removed)

    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=".building-", dir=out))
    derive_lock = threading.Lock()
    ok = False
    try:
        def one(gname):
            key, model, removed = plan[gname]
            g = scene.groups[gname]
            target = stage / f"{gname}.fmu"
            cached, meta = cdir / f"{key}.fmu", cdir / f"{key}.json"
            if model is None:
                d = _cached_entry(cdir, key)
                if d is not None:
                    shutil.copyfile(cached, target)
                if d is not None and _file_digest(target) == d["sha256"]:  # the copy is the entry hashed
                    d = {k: v for k, v in d.items() if k not in ("key", "sha256")}
                    r = FmuReport(**{**d, "path": out / target.name, "cached": True, "build_seconds": 0.0})
                    r.members = tuple(r.members)
                    progress(r.line())
                    return r
                progress(f"{gname}: cache entry {key} damaged or replaced: rebuilt")
                with derive_lock:
                    model, removed = scene.group_model(gname, prune=prune, x0=x0, u0=u0)
            t0 = time.perf_counter()
            progress(f"{gname}: generate and compile ({model.nx} states)")
            tol = g.tolerance or scene.spec.tolerance
            if len(scene.groups) > 1:
                lim = "none found" if limit == float("inf") else "not computed" if limit != limit else \
                    f"{limit:.3g} s"
                model = dataclasses.replace(model, description=(
                    f"{model.description} [scene {scene.name}: held-input Jacobi stability limit {lim} "
                    f"(linearised at rest); couple with the scene's connections]").strip())
            terminals = None  # FMI 2.0 has none
            if scene.spec.fmi_version == 3:
                with derive_lock:  # ports() loads robot files: one thread at a time, as deriving
                    terminals = group_terminals(scene, gname, model)
            try:
                res = build_fmu(model, target, fmi_type="both" if g.fmi_type == "me" else g.fmi_type,
                                model_identifier=gname,
                                default_experiment={"startTime": scene.spec.start, "stopTime": scene.spec.stop,
                                                    "stepSize": default_step, "tolerance": tol},
                                runtime_start=_runtime_start(scene, g), platforms=scene.spec.platforms,
                                fmi_version=scene.spec.fmi_version, terminals=terminals)
            except ValueError as exc:
                raise SceneError(f"{scene.src}: [fmus.{gname}]: {exc}") from None
            r = FmuReport(group=gname, path=out / target.name, members=tuple(g.members), states=model.nx,
                          inputs=model.nu, outputs=model.ny, parameters=model.np,
                          ops={k: str(v) for k, v in res.op_counts.items()}, total_ops=_total_ops(res.op_counts),
                          library_bytes=_library_size(target), build_seconds=time.perf_counter() - t0,
                          cached=False, has_jacobian=model.jacobian is not None, removed=removed)
            if use_cache:
                cdir.mkdir(parents=True, exist_ok=True)
                tmp = cdir / f"{key}.{os.getpid()}.{threading.get_ident()}.part"
                shutil.copyfile(target, tmp)
                os.replace(tmp, cached)
                d = dataclasses.asdict(r)
                d.pop("path")
                d.update(key=key, sha256=_file_digest(target))
                tmp.write_text(json.dumps(d, default=str))
                os.replace(tmp, meta)
            progress(r.line())
            return r

        jobs = jobs or min(4, os.cpu_count() or 1)
        # the groups build in worker threads, where no signal arrives: a Ctrl-C (or SIGTERM) in the main
        # thread, or one group's failure, sets `cancel`, and every other group's build stops within a
        # poll of its compilers, killing them, instead of running them to the end
        cancel = threading.Event()

        def cancellable_one(g):
            with cancellable(cancel):
                return one(g)

        with ThreadPoolExecutor(max_workers=jobs) as ex:
            futures = {g: ex.submit(cancellable_one, g) for g in plan}
            try:
                reports = {g: f.result() for g, f in futures.items()}
            except BaseException:
                cancel.set()
                for f in futures.values():
                    f.cancel()
                raise
        for g in plan:
            os.replace(stage / f"{g}.fmu", out / f"{g}.fmu")
        ok = True
    finally:
        shutil.rmtree(stage, ignore_errors=True)
        if not ok and created:  # a failed build leaves no (empty) output folder behind
            try:
                out.rmdir()
            except OSError:
                pass
    stale = _remove_stale(out, [f"{g}.fmu" for g in plan])
    paths = {g: out / f"{g}.fmu" for g in plan}
    return BuiltScene(scene, out, reports, scene.cosim_system(paths), scene.system_inputs(prune), stale,
                      limit, default_step)


def group_terminals(scene, group: str, model) -> list:
    """The FMI 3.0 terminals of ``group``'s FMU ``model`` (fmugen/fmi/terminals.py): one per connector of its
    members (fmugen/scene/connect.py ``ports``) with variables among the FMU's inputs and outputs, named as
    the FMU names variables (:meth:`Scene.fmu_name`: ``flange`` alone, ``act.flange`` in a group of several).

    A connector whose flow is connected to another member of the group is bonded inside the FMU and is no
    terminal of it (a member that only reads a potential -- a sensor -- bonds nothing).  A robot joint's own
    name (URDF joint, DH link) is the same connector as its ``joint[k]``: one terminal ``joint[k]``, the name
    in its description."""
    from ..fmi.terminals import FLOWS, connector_terminal, interface
    from .connect import ports

    members = scene.groups[group].members
    io = interface(model)
    inside = set()  # (instance, variable) connected to or from another member of the group
    for si, sv, ti, tv, _ in scene.connections:
        if si in members and ti in members:
            inside |= {(si, sv), (ti, tv)}
    out = []
    for inst in members:
        names = {}  # (type, mapping) -> the connector's names, joint[k] first (ports' order)
        for cname, (ctype, mapping) in ports(scene, inst).items():
            names.setdefault((ctype, tuple(mapping.items())), []).append(cname)
        for (ctype, items), (cname, *aliases) in names.items():
            mapping = dict(items)
            bonded = [mapping[FLOWS[ctype]]] if FLOWS[ctype] in mapping else list(mapping.values())
            if all((inst, v) in inside for v in bonded):
                continue
            also = f" (also named {', '.join(aliases)} in the scene)" if aliases else ""
            t = connector_terminal(scene.fmu_name(inst, cname), ctype,
                                   {k: scene.fmu_name(inst, v) for k, v in mapping.items()}, io,
                                   description=f"{ctype} connector {cname} of {inst}{also}")
            if t is not None:
                out.append(t)
    return out


#: the DefaultExperiment step is at most this fraction of the held-input Jacobi limit (the
#: linearisation holds at rest only), rounded down to 1-2-5 x 10^k
STABLE_SAFETY = 0.8


def _jacobi_limit(scene, keys: dict, use_cache: bool) -> float:
    """:func:`fmugen.scene.stability.jacobi_hold_limit`, cached under the hash of every group's key and of the
    analysis' version."""
    if len(keys) < 2:
        return float("inf")
    # version 2 (issue 29): the FMUs linearised on their own, feedthrough delayed a step; version 1 took the
    # monolithic model's blocks, feedthrough as exact -- its entries (limits up to 1e4 x too large) never served
    version = "jacobi-hold-limit v2"
    key = hashlib.sha256(f"{version} {' '.join(sorted(keys.values()))}".encode()).hexdigest()[:32]
    path = cache_dir() / "stability" / f"{key}.json"
    if use_cache and path.is_file():
        try:  # served only as written for this key (a swapped or edited entry is computed again)
            d = json.loads(path.read_text())
            value = d["jacobi_hold_limit"]
            if d.get("key") == key and d.get("sha256") == hashlib.sha256(f"{key} {value}".encode()).hexdigest():
                return float(value)
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            pass
    from .stability import jacobi_hold_limit  # here: it imports scipy (start-up from cached FMUs)

    try:
        limit = jacobi_hold_limit(scene)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:  # a model the linearisation cannot take
        progress = Progress()
        progress(f"held-input Jacobi limit not computed ({exc}): DefaultExperiment stepSize = the scene's step")
        return float("nan")
    if use_cache:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.part")
        value = limit if limit != float("inf") else "inf"
        tmp.write_text(json.dumps({"jacobi_hold_limit": value, "key": key,
                                   "sha256": hashlib.sha256(f"{key} {value}".encode()).hexdigest()}))
        os.replace(tmp, path)
    return limit


def _library_size(fmu: Path) -> int:
    import zipfile

    with zipfile.ZipFile(fmu) as zf:
        return sum(i.file_size for i in zf.infolist() if i.filename.startswith("binaries/"))
