"""Hardening, third round: a warm cache never serves a stale or corrupt result.

Every input that shapes an FMU enters its cache key by content (a scene-level
``parameter_set = "p.toml"`` file, resolved next to the scene; the scene's
description; robot files), and an entry is verified by its hash before it is
served.  The oracle is a cold build: FMUs are built deterministically (fixed
zip dates), so a warm build must give the very bytes a cold build gives.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np
import pytest

from fmugen.scene import load_scene
from fmugen.scene.build import _cached_entry, _group_key

DATA = Path(__file__).resolve().parents[1] / "fmugen" / "components" / "data"

RIG = """
[scene]
name = "rig"
description = "{desc}"
parameter_set = "p.toml"
stop = 0.05
step = 1e-3
record = ["joint.theta"]

[instances.joint]
type = "joint_inertia"
start = {{ theta = 0.1, w = 1.0 }}

[fmus.joint]
members = ["joint"]
solver = "dopri5"
"""


def _sha(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _rig(folder: Path, desc="one joint", J=None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    text = (DATA / "default.toml").read_text()
    if J is not None:
        text = text.replace("[joint_inertia]", f"[joint_inertia]\nJ = {J!r}", 1)
        lines, seen = [], False  # keep only the first J of the table
        for line in text.splitlines():
            if line.split("=")[0].strip() == "J":
                if seen:
                    continue
                seen = True
            lines.append(line)
        text = "\n".join(lines) + "\n"
    (folder / "p.toml").write_text(text)
    (folder / "rig.toml").write_text(RIG.format(desc=desc))
    return folder / "rig.toml"


def _key(path) -> str:
    sc = load_scene(path)
    return _group_key(sc, "joint", True, sc.initial.values, sc.rest_inputs)


def _entry_of(cdir: Path, sha: str) -> str:
    """The cache key whose entry records the FMU hash ``sha``."""
    import json

    (key,) = [p.stem for p in cdir.glob("*.json") if json.loads(p.read_text()).get("sha256") == sha]
    return key


def test_every_input_file_enters_the_key_by_content_resolved_next_to_the_scene(tmp_path, monkeypatch):
    scene = _rig(tmp_path / "a")
    k0 = _key(scene)
    monkeypatch.chdir(tmp_path)  # the parameter set is the scene's neighbour whatever the working folder
    assert _key(scene) == k0 and load_scene(scene).base_models["joint"].parameters
    _rig(tmp_path / "a", J=0.37)  # the parameter set file's content changed, its name did not
    k1 = _key(scene)
    assert k1 != k0
    _rig(tmp_path / "a", desc="another description", J=0.37)
    assert _key(scene) != k1
    # the same files in another folder give the same key (content, not path)
    assert _key(_rig(tmp_path / "b", desc="another description", J=0.37)) == _key(scene)


def test_a_warm_build_equals_a_cold_build_and_bad_entries_are_rebuilt(tmp_path, monkeypatch):
    monkeypatch.setenv("FMUGEN_CACHE", str(tmp_path / "cache"))
    scene = _rig(tmp_path / "s")
    a = load_scene(scene).build(tmp_path / "o1")
    hA = _sha(a.fmus["joint"].path)
    assert not a.fmus["joint"].cached

    _rig(tmp_path / "s", J=0.29)  # edit the parameter set file: the cached FMU is stale
    b = load_scene(scene).build(tmp_path / "o2")
    hB = _sha(b.fmus["joint"].path)
    assert not b.fmus["joint"].cached and hB != hA
    cold = load_scene(scene).build(tmp_path / "o3", use_cache=False)
    assert _sha(cold.fmus["joint"].path) == hB  # warm (rebuilt) == cold

    cdir = tmp_path / "cache" / "fmus"
    keyB = _entry_of(cdir, hB)
    entry = cdir / f"{keyB}.fmu"
    entry.write_bytes(entry.read_bytes()[:1000])  # truncated entry
    c = load_scene(scene).build(tmp_path / "o4")
    assert not c.fmus["joint"].cached and _sha(c.fmus["joint"].path) == hB

    _rig(tmp_path / "s")  # back to the first parameter set: its entry is whole and served
    keyA = _entry_of(cdir, hA)
    d = load_scene(scene).build(tmp_path / "o5")
    assert d.fmus["joint"].cached and _sha(d.fmus["joint"].path) == hA

    os.replace(cdir / f"{keyB}.fmu", cdir / f"{keyA}.fmu")  # swapped: A's name holds B's FMU
    e = load_scene(scene).build(tmp_path / "o6")
    assert not e.fmus["joint"].cached and _sha(e.fmus["joint"].path) == hA
    assert _cached_entry(cdir, keyA) is not None
    os.replace(cdir / f"{keyA}.json", cdir / f"{keyB}.json")  # metadata moved: it names another key
    os.replace(cdir / f"{keyA}.fmu", cdir / f"{keyB}.fmu")
    assert _cached_entry(cdir, keyB) is None and _cached_entry(cdir, keyA) is None


def test_the_reference_cache_serves_only_whole_entries_of_its_own_key(tmp_path, monkeypatch):
    from fmugen.cosim import reference

    monkeypatch.setenv("FMUGEN_CACHE", str(tmp_path / "cache"))
    prob = load_scene(_rig(tmp_path / "s")).reference_problem()
    times = np.linspace(prob.start_time, prob.stop_time, 11)
    r0 = reference.solve_reference(prob, times)
    assert not r0.cached and reference.solve_reference(prob, times).cached
    (entry,) = (tmp_path / "cache" / "reference").glob("*.npz")
    with np.load(entry) as z:
        data = {k: z[k] for k in z.files}
    np.savez(entry, **{**data, "Q": data["Q"] + 1.0})  # edited dense output, digest kept
    r1 = reference.solve_reference(prob, times)
    assert not r1.cached and np.array_equal(r1.values, r0.values)
    entry.write_bytes(entry.read_bytes()[:200])  # truncated
    assert not reference.solve_reference(prob, times).cached
    # another problem's entry under this key (swapped files): its key inside differs
    other = load_scene(_rig(tmp_path / "t", J=0.5)).reference_problem()
    reference.solve_reference(other, times)
    (e2,) = [p for p in (tmp_path / "cache" / "reference").glob("*.npz") if p != entry]
    os.replace(e2, entry)
    r3 = reference.solve_reference(prob, times)
    assert not r3.cached and np.array_equal(r3.values, r0.values)


def test_the_analysis_cache_key_holds_component_files_and_refuses_devices(tmp_path):
    import shutil

    from fmugen.scene.analysis_cache import analysis_key

    root = Path(__file__).resolve().parents[1]
    (tmp_path / "examples" / "scenes").mkdir(parents=True)
    shutil.copytree(root / "examples" / "components", tmp_path / "examples" / "components")
    shutil.copytree(root / "robots", tmp_path / "robots")
    scene = tmp_path / "examples" / "scenes" / "puma_geared_drive.toml"
    shutil.copy(root / "examples" / "scenes" / "puma_geared_drive.toml", scene)
    k0 = analysis_key(scene)
    part = tmp_path / "examples" / "components" / "geared_drive.toml"
    part.write_text(part.read_text().replace("value = 0.5,", "value = 0.55,", 1))  # type = "file:..." edited
    assert analysis_key(scene) != k0
    assert analysis_key("/dev/zero") is None  # refused before it is read (the full load says why)


def test_the_stability_limit_cache_serves_only_its_own_entry(tmp_path, monkeypatch):
    import json

    from fmugen.scene.build import _jacobi_limit

    monkeypatch.setenv("FMUGEN_CACHE", str(tmp_path / "cache"))
    scene = load_scene(Path(__file__).resolve().parents[1] / "examples" / "scenes" / "single_joint_split.toml")
    keys = {"chain": "k1", "joint": "k2"}
    limit = _jacobi_limit(scene, keys, True)
    (entry,) = (tmp_path / "cache" / "stability").glob("*.json")
    d = json.loads(entry.read_text())
    entry.write_text(json.dumps({**d, "jacobi_hold_limit": 1e9}))  # edited: the FMUs' step would follow it
    assert _jacobi_limit(scene, keys, True) == limit
    other = _jacobi_limit(scene, {"chain": "k3", "joint": "k4"}, True)
    for f in (tmp_path / "cache" / "stability").glob("*.json"):  # another key's entry under this name
        if f != entry:
            os.replace(f, entry)
    assert _jacobi_limit(scene, keys, True) == limit == other
