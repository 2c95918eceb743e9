"""A warm cache never returns an FMU different from a cold build (every shipped scene, every input-file kind).

    python examples/cache_warm_cold.py                      # all shipped scenes (the PUMA ones take minutes)
    python examples/cache_warm_cold.py single_joint_split   # one scene

Each scene is copied, with the robot files it names, into a temporary
folder; its parameter sets (the scene-level ``parameter_set`` and every
instance's) are turned into files next to it.  Then, for each kind of input
file -- the scene file itself (its description), the robot file (a link
mass), a component file (a parameter value), the scene-level parameter-set
file and an instance's parameter-set file -- one value is edited and the scene is built twice: with
the cache of the previous builds (warm) and without any cache (cold).  FMU
builds are deterministic (fixed zip dates), so the two must be byte-for-byte
equal: the script compares sha256 hashes and exits 1 on any difference.
Finally a cache entry is truncated and another swapped, and the warm build
must again equal the cold one.
"""
from __future__ import annotations

import hashlib
import os
import re
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "examples" / "scenes"
DATA = ROOT / "fmugen" / "components" / "data"


def sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def build(scene: Path, out: Path, cache: bool) -> dict:
    from fmugen.scene import load_scene

    built = load_scene(scene).build(out, use_cache=cache, progress=lambda t: None)
    return {g: (sha(r.path), r.cached) for g, r in built.fmus.items()}


def scale_first(text: str, pattern: str, factor: float = 1.01) -> str:
    """``text`` with the first number after ``pattern`` (a regex ending before the number) scaled."""
    m = re.search(pattern + r"\s*=\s*([-+0-9.eE]+)", text, flags=re.M)
    if not m:
        return text
    new = repr(float(m.group(1)) * factor)
    return text[:m.start(1)] + new + text[m.end(1):]


def prepare(name: str, tmp: Path) -> Path:
    """The scene ``name`` in ``tmp``, its parameter sets as files next to it."""
    shutil.copytree(ROOT / "robots", tmp / "robots")  # TOML and URDF robots (and what a URDF names)
    sdir = tmp / "examples" / "scenes"
    sdir.mkdir(parents=True)
    if (ROOT / "examples" / "components").is_dir():  # component files the scenes name
        shutil.copytree(ROOT / "examples" / "components", tmp / "examples" / "components")
    text = (SCENES / f"{name}.toml").read_text()
    # every named (shipped) parameter set becomes a file beside the scene
    for set_name in sorted(set(re.findall(r'parameter_set\s*=\s*"([A-Za-z0-9_]+)"', text))):
        shutil.copy(DATA / f"{set_name}.toml", sdir / f"{set_name}_set.toml")
        text = text.replace(f'parameter_set = "{set_name}"', f'parameter_set = "{set_name}_set.toml"')
    # a scene-level file, used by components without one (a component file then needs its table: left out)
    if not re.search(r"^parameter_set", text, flags=re.M) and "file:" not in text:
        shutil.copy(DATA / "default.toml", sdir / "default_set.toml")
        text = text.replace("[scene]\n", '[scene]\nparameter_set = "default_set.toml"\n', 1)
    (sdir / f"{name}.toml").write_text(text)
    return sdir / f"{name}.toml"


def edits(scene: Path):
    """(what, function editing the files in place) for every input-file kind the scene has."""
    sdir = scene.parent
    text = scene.read_text()

    def scene_file():
        t = scene.read_text()
        if re.search(r"^description\s*=", t, flags=re.M):
            t = re.sub(r'^description\s*=\s*"', 'description = "edited: ', t, count=1, flags=re.M)
        else:
            t = t.replace("[scene]\n", '[scene]\ndescription = "edited"\n', 1)
        scene.write_text(t)

    out = [("scene file (description)", scene_file)]
    robots = re.findall(r'robot\s*=\s*"([^"]+)"', text)
    if robots:
        rfile = (sdir / robots[0]).resolve()
        if rfile.suffix == ".urdf":  # <mass value="3.7"/>
            def edit_robot():
                t = rfile.read_text()
                m = re.search(r'<mass\s+value="([^"]+)"', t)
                rfile.write_text(t[:m.start(1)] + repr(float(m.group(1)) * 1.01) + t[m.end(1):])
        else:
            def edit_robot():
                rfile.write_text(scale_first(rfile.read_text(), r"^mass"))
        out.append((f"robot file {rfile.name} (a link mass)", edit_robot))
    comps = re.findall(r'type\s*=\s*"file:([^"]+)"', text)
    if comps:
        cfile = (sdir / comps[0]).resolve()
        out.append((f"component file {cfile.name} (a parameter value)",
                    lambda: cfile.write_text(scale_first(cfile.read_text(), r"value"))))
    top = re.search(r'^parameter_set\s*=\s*"([^"]+)"', text, flags=re.M)
    if top:
        p = sdir / top.group(1)
        out.append((f"scene-level parameter set {p.name}",
                    lambda: p.write_text(_scale_every_first(p.read_text()))))
    inst = [s for s in re.findall(r'parameter_set\s*=\s*"([^"]+)"', text)[1 if top else 0:]
            if s.endswith(".toml") and (sdir / s).is_file()]
    if inst:
        p2 = sdir / inst[0]
        out.append((f"instance parameter set {p2.name}",
                    lambda: p2.write_text(_scale_every_first(p2.read_text()))))
    return out


def _scale_every_first(text: str) -> str:
    """The first value of every table scaled by 1.01 (whatever the components read, something changes)."""
    out, fresh = [], False
    for line in text.splitlines():
        if line.startswith("["):
            fresh = True
        elif fresh and re.match(r"^[A-Za-z_]\w*\s*=\s*[-+0-9.]", line):
            line = scale_first(line, r"^[A-Za-z_]\w*")
            fresh = False
        out.append(line)
    return "\n".join(out) + "\n"


def check(name: str) -> int:
    bad = 0
    with tempfile.TemporaryDirectory(prefix=f"warmcold-{name}-") as d:
        tmp = Path(d)
        os.environ["FMUGEN_CACHE"] = str(tmp / "cache")
        scene = prepare(name, tmp)
        t0 = time.perf_counter()
        build(scene, tmp / "first", cache=True)
        steps = edits(scene) + [("a truncated cache entry", None), ("a swapped cache entry", None)]
        for k, (what, edit) in enumerate(steps):
            cdir = tmp / "cache" / "fmus"
            entries = sorted(cdir.glob("*.fmu"), key=lambda p: p.stat().st_mtime)
            if edit is not None:
                edit()
            elif what.startswith("a truncated"):
                for e in entries:
                    e.write_bytes(e.read_bytes()[: max(1, e.stat().st_size // 3)])
            else:
                for a, b in zip(entries[::2], entries[1::2]):
                    os.replace(a, tmp / "x")
                    os.replace(b, a)
                    os.replace(tmp / "x", b)
            warm = build(scene, tmp / f"warm{k}", cache=True)
            cold = build(scene, tmp / f"cold{k}", cache=False)
            diff = [g for g in cold if warm[g][0] != cold[g][0]]
            served = sum(c for _, c in warm.values())
            bad += bool(diff)
            print(f"{name}: {what}: {len(cold)} FMUs, {served} served from the cache, "
                  f"{'DIFFERENT from cold: ' + ', '.join(diff) if diff else 'all equal to the cold build'}",
                  flush=True)
        print(f"{name}: {len(steps)} edits checked in {time.perf_counter() - t0:.0f} s")
    return bad


def main(argv) -> int:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="*", help="shipped scene names (default: all in examples/scenes)")
    names = ap.parse_args(argv).scenes or sorted(p.stem for p in SCENES.glob("*.toml"))
    bad = sum(check(n) for n in names)
    print(f"{len(names)} scene(s): {'no warm build differed from its cold build' if not bad else f'{bad} differed'}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
