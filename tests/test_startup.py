"""Start-up (issue 18): lazy imports, and the scene analysis cached with the FMUs.

No timing here (that is ``examples/bench_startup.py``): what is checked is what makes a start fast --
nothing heavy imported for ``fmugen --help`` -- and that the cached analysis gives exactly the system,
and the results, of a full analysis, under a key that changes with the content.
"""
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fmugen.cosim import run
from fmugen.scene import analysis_cache as ac

ROOT = Path(__file__).resolve().parents[1]
SPLIT = ROOT / "examples" / "scenes" / "single_joint_split.toml"

pytestmark = pytest.mark.usefixtures("private_reference_cache")


def test_help_imports_nothing_heavy():
    code = ("import sys\nfrom fmugen.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in ('sympy', 'numpy', 'scipy', 'fmpy', 'dask', 'matplotlib', 'control') "
            "if m in sys.modules))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-1] == "[]"
    assert "cosim" in r.stdout and "linearize" in r.stdout  # every command listed


def test_cached_analysis_gives_the_same_system_and_results(tmp_path):
    first = ac.build_scene_cached(SPLIT, tmp_path / "a", sets=["joint.J=2"])
    assert not isinstance(first.scene, ac.DeferredScene)  # analysed now, and stored
    again = ac.build_scene_cached(SPLIT, tmp_path / "b", sets=["joint.J=2"])
    assert isinstance(again.scene, ac.DeferredScene) and again.scene._full is None  # nothing derived
    assert again.system == type(first.system)(**{**first.system.__dict__, "units": tuple(
        type(u)(**{**u.__dict__, "path": tmp_path / "b" / u.path.name}) for u in first.system.units)})
    # the initial state's report and what pruning removed included; the FMUs now come from the cache
    assert again.summary() == re.sub(r"built in [0-9.]+ s", "cached", first.summary())
    r1 = run(first.system, "gauss-seidel", "linear", stop=0.05)
    r2 = run(again.system, "gauss-seidel", "linear", stop=0.05)
    assert r1.ok and np.array_equal(r1.values, r2.values)
    # the full scene is there when asked for
    assert again.scene.monolithic_model().nx == first.scene.monolithic_model().nx


def test_analysis_key_follows_the_content(tmp_path):
    scene = tmp_path / "scenes" / "s.toml"
    scene.parent.mkdir()
    shutil.copy(SPLIT, scene)
    k = ac.analysis_key(scene)
    assert k == ac.analysis_key(scene) and k is not None
    assert ac.analysis_key(scene, ["joint.J=2"]) != k
    scene.write_text(scene.read_text().replace("stop = 1.0", "stop = 0.9"))
    assert ac.analysis_key(scene) != k
    # a file the scene names (a parameter set) is part of the key
    pset = tmp_path / "scenes" / "mine.toml"
    pset.write_text("# parameters\n")
    text = scene.read_text().replace('parameter_set = "default"', 'parameter_set = "mine.toml"', 1)
    scene.write_text(text)
    k2 = ac.analysis_key(scene)
    pset.write_text("# other parameters\n")
    assert ac.analysis_key(scene) != k2
    # a factory runs code that is not in the key: never cached
    scene.write_text(text + '\n[instances.extra]\nfactory = "mymodule:make"\n')
    assert ac.analysis_key(scene) is None
