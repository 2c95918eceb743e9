"""Build a scene: one FMU per group, reused from a cache when nothing changed.

The cache key of an FMU is a hash of everything that shapes it: the group's
instances (their files' contents, options, parameter values, what is
fixed), the connections and records touching it, the initial values baked
into it, the FMI type and internal-solver choice, whether pruning is on,
and the generator itself (every source file of fmugen and of the C
runtime).  Cached FMUs live in ``$FMUGEN_CACHE`` (default
``~/.cache/fmugen``) and are copied into the output folder.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Optional

from .. import __version__
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

    def summary(self) -> str:
        lines = [self.scene.initial.report()]
        for r in self.fmus.values():
            lines.append(r.line())
            lines += [f"    pruned: {x}" for x in r.removed]
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
    return Path(os.environ.get("FMUGEN_CACHE") or Path.home() / ".cache" / "fmugen")


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


def _group_key(scene, group: str, prune: bool, x0: dict) -> str:
    g = scene.groups[group]
    members = set(g.members)
    parts = {
        "generator": generator_fingerprint(),
        "group": dataclasses.asdict(g),
        "prune": prune,
        "jacobian": scene.needs_jacobian(g),
        "instances": {},
        "connections": [c for c in scene.connections if c[0] in members or c[2] in members],
        "record": [r for r in scene.spec.record if r.split(".", 1)[0] in members],
        "x0": {k: v for k, v in sorted(x0.items()) if k.split(".", 1)[0] in members},
        "run": [scene.spec.start, scene.spec.stop, scene.spec.step, scene.spec.tolerance],
        "default_set": scene.spec.parameter_set,
    }
    for inst in sorted(members):
        ins = scene.spec.instances[inst]
        d = dataclasses.asdict(ins)
        d["locked"] = {str(k): v for k, v in ins.locked.items()}
        if ins.kind in ("robot", "file"):
            d["file"] = hashlib.sha256(Path(ins.source).read_bytes()).hexdigest()
        if ins.parameter_set and ins.parameter_set.endswith(".toml"):
            d["set_file"] = hashlib.sha256(Path(ins.parameter_set).read_bytes()).hexdigest()
        d["sets"] = scene._sets.get(inst, {})
        parts["instances"][inst] = d
    text = json.dumps(parts, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:32]


def _total_ops(op_counts: dict) -> int:
    n = 0
    for ops in op_counts.values():
        t = ops.total
        n += t.mul + t.add + t.div + t.n_calls
    return n


def build_scene(scene, out_dir, prune: bool = True, progress=None, use_cache: bool = True,
                jobs: Optional[int] = None) -> BuiltScene:
    """Build every group of ``scene`` into ``out_dir/<group>.fmu`` and return what was built.

    Every group model is derived first, so an error in any of them stops the
    build before a file is written; the FMUs are then generated and compiled
    ``jobs`` at a time (default: the number of cores, at most 4) into a
    staging folder and moved into ``out_dir`` together when all succeeded.
    """
    from ..fmi.build import build_fmu

    progress = progress or Progress()
    out = Path(out_dir)
    progress(f"scene {scene.name}: initial state ({scene.spec.initial})")
    x0 = scene.initial.values
    cdir = cache_dir() / "fmus"
    plan = {}  # group -> (key, model or None when cached, removed)
    for gname, g in scene.groups.items():
        key = _group_key(scene, gname, prune, x0)
        if use_cache and (cdir / f"{key}.fmu").is_file() and (cdir / f"{key}.json").is_file():
            plan[gname] = (key, None, [])
        else:
            progress(f"{gname}: derive ({', '.join(g.members)})")
            model, removed = scene.group_model(gname, prune=prune, x0=x0)
            plan[gname] = (key, model, removed)

    out.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=".building-", dir=out))
    try:
        def one(gname):
            key, model, removed = plan[gname]
            g = scene.groups[gname]
            target = stage / f"{gname}.fmu"
            cached, meta = cdir / f"{key}.fmu", cdir / f"{key}.json"
            if model is None:
                shutil.copyfile(cached, target)
                r = FmuReport(**{**json.loads(meta.read_text()), "path": out / target.name, "cached": True,
                                 "build_seconds": 0.0})
                r.members = tuple(r.members)
                progress(r.line())
                return r
            t0 = time.perf_counter()
            progress(f"{gname}: generate and compile ({model.nx} states)")
            tol = g.tolerance or scene.spec.tolerance
            try:
                res = build_fmu(model, target, fmi_type="both" if g.fmi_type == "me" else g.fmi_type,
                                model_identifier=gname,
                                default_experiment={"startTime": scene.spec.start, "stopTime": scene.spec.stop,
                                                    "stepSize": scene.spec.step, "tolerance": tol})
            except ValueError as exc:
                raise SceneError(f"{scene.src}: [fmus.{gname}]: {exc}") from None
            r = FmuReport(group=gname, path=out / target.name, members=tuple(g.members), states=model.nx,
                          inputs=model.nu, outputs=model.ny, parameters=model.np,
                          ops={k: str(v) for k, v in res.op_counts.items()}, total_ops=_total_ops(res.op_counts),
                          library_bytes=_library_size(target), build_seconds=time.perf_counter() - t0,
                          cached=False, has_jacobian=model.jacobian is not None, removed=removed)
            if use_cache:
                cdir.mkdir(parents=True, exist_ok=True)
                tmp = cdir / f"{key}.{os.getpid()}.part"
                shutil.copyfile(target, tmp)
                os.replace(tmp, cached)
                d = dataclasses.asdict(r)
                d.pop("path")
                meta.write_text(json.dumps(d, default=str))
            progress(r.line())
            return r

        jobs = jobs or min(4, os.cpu_count() or 1)
        with ThreadPoolExecutor(max_workers=jobs) as ex:
            futures = {g: ex.submit(one, g) for g in plan}
            reports = {g: f.result() for g, f in futures.items()}
        for g in plan:
            os.replace(stage / f"{g}.fmu", out / f"{g}.fmu")
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    paths = {g: out / f"{g}.fmu" for g in plan}
    return BuiltScene(scene, out, reports, scene.cosim_system(paths))


def _library_size(fmu: Path) -> int:
    import zipfile

    with zipfile.ZipFile(fmu) as zf:
        return sum(i.file_size for i in zf.infolist() if i.filename.startswith("binaries/"))
