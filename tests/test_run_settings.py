"""Run settings and start-up (issue 18).

One source of run settings: a scene's ``[cosim]`` key is honoured alike by ``fmugen cosim``, ``fmugen
report``, ``fmugen sweep`` and :func:`fmugen.cosim.run`, in the order file < ``--set`` < flag; unknown
keys are refused with the valid ones.

Start-up (no timing here: that is ``examples/bench_startup.py``): nothing heavy is imported for
``fmugen --help``, and the cached scene analysis gives exactly the system, and the results, of a full
analysis, under a key that changes with the content.
"""
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fmugen.cli import main
from fmugen.cosim import CosimError, run
from fmugen.cosim.settings import KEYS, resolve, resolve_file
from fmugen.scene import SceneError, analysis_cache as ac, load_scene

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
    # a fresh ``fmugen cosim`` reaches its first macro step from the cache without importing sympy, scipy or
    # matplotlib (what start-up costs)
    code = ("import sys\nimport fmugen.cosim.master as M\n"
            "def first_step(self, *a, **k):\n"
            "    print(len(self.units), sorted(m for m in ('sympy', 'scipy', 'matplotlib') if m in sys.modules))\n"
            "    raise SystemExit(0)\n"
            "M.Master.run = first_step\nfrom fmugen.cli import main\n"
            f"main(['cosim', {str(SPLIT)!r}, '--set', 'joint.J=2', '--out', {str(tmp_path / 'c')!r}])\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().split(maxsplit=1) == [str(len(first.system.units)), "[]"]
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


# ---------------------------------------------------------------------------------------------- settings
def test_file_then_set_then_flag():
    table = {"scheme": "newton", "step": 2e-3, "iteration_tol": 1e-6, "iterations": 5}
    s = resolve(table)
    assert (s.scheme, s.extrapolation, s.step, s.coupling_tol, s.max_iterations) == ("newton", "linear", 2e-3, 1e-6, 5)
    s = resolve(table, {"cosim.step": 4e-3, "joint.J": 2.0})
    assert s.step == 4e-3 and s.scheme == "newton"
    s = resolve(table, {"cosim.step": 4e-3}, step=1e-3, coupling_tol=1e-7, scheme=None)
    assert (s.step, s.coupling_tol, s.scheme) == (1e-3, 1e-7, "newton")
    assert resolve().keywords() == {"scheme": "gauss-seidel", "extrapolation": "linear", "order": None, "workers": 1,
                                    "step": None, "stop": None, "adaptive": False}


@pytest.mark.parametrize("table, sets, message", [
    ({"coupling_toll": 1e-6}, {}, r"unknown key 'coupling_toll' \(did you mean 'coupling_tol'\?\); valid \[cosim\] "
                                  r"keys: scheme, extrapolation, step"),
    ({}, {"cosim.input_derivatives": True}, r"--set cosim.input_derivatives: unknown key"),
    ({"iterations": 0}, {}, r"iterations must be >= 1"),
    ({"coupling_tol": -1.0}, {}, r"coupling_tol must be finite and positive"),
    ({"adaptive": "yes"}, {}, r"adaptive must be true or false"),
    ({"scheme": "jacobi", "extrapolation": "cubic"}, {}, r"need an iterated scheme"),
])
def test_bad_settings_are_refused(table, sets, message):
    with pytest.raises(CosimError, match=message):
        resolve(table, sets)


def test_scene_file_with_an_unknown_cosim_key_names_file_and_valid_keys(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text(SPLIT.read_text() + '\n[cosim]\ncoupling_toll = 1e-6\n')
    with pytest.raises(SceneError, match=r"s.toml: \[cosim\]: unknown key 'coupling_toll'.*valid \[cosim\] keys"):
        load_scene(scene)
    with pytest.raises(SceneError, match=r"--set cosim.stepp: no key 'stepp' in \[cosim\].*valid keys: " + ", ".join(KEYS)):
        load_scene(SPLIT, set=["cosim.stepp=1"])


@pytest.fixture(scope="module")
def iterated_scene(tmp_path_factory):
    """The split rig whose [cosim] asks for an iteration it cannot finish: 2 iterations to 1e-13 (its FMUs are
    the split rig's: [cosim] does not change them)."""
    d = tmp_path_factory.mktemp("iterated")
    scene = d / "split_iterated.toml"
    scene.write_text(SPLIT.read_text() + """
[cosim]
scheme = "iterative"
extrapolation = "linear"
step = 2e-3
iterations = 2
coupling_tol = 1e-13
""")
    return scene


def _summary(out):
    return (out / "summary.txt").read_text()


def test_every_cosim_key_is_honoured_by_command_api_sweep_and_report(iterated_scene, tmp_path):
    from fmugen.cosim.report import make_report
    from fmugen.sweep.prepare import run_options

    # the command: the file's settings, then --set, then the flags
    out = tmp_path / "cli"
    assert main(["cosim", str(iterated_scene), "--out", str(out), "--stop", "0.15"]) == 1
    text = _summary(out)
    assert "iterative/linear: failed" in text and "did not converge in 2 iterations" in text
    assert "(H 0.002..0.002 s)" in text
    assert main(["cosim", str(iterated_scene), "--out", str(out), "--stop", "0.15", "--set", "cosim.step=0.004",
                 "--iterations", "40", "--coupling-tol", "1e-6"]) == 0
    assert "iterative/linear: ok" in _summary(out) and "..0.004 s)" in _summary(out)  # the last step ends at 0.15
    cli = np.loadtxt(out / "results.csv", delimiter=",", skiprows=1)

    # the API, with the built scene: the same settings, the same numbers
    built = ac.build_scene_cached(iterated_scene, tmp_path / "api")
    r = run(built, stop=0.15)
    assert not r.ok and "did not converge in 2 iterations" in str(r.summary.failure)
    r = run(load_scene(iterated_scene, set=["cosim.step=0.004"]).build(tmp_path / "api2"), max_iterations=40,
            coupling_tol=1e-6, stop=0.15)
    assert r.ok and np.array_equal(np.column_stack([r.time, r.values]), cli)

    # the sweep's keywords and the report's runs: the same resolution
    settings = resolve_file(iterated_scene)
    assert run_options(built.system.settings) == settings.keywords()
    assert run_options(built.system.settings)["max_iterations"] == 2
    rep = make_report(built.system, built.scene.reference_problem(), [2e-3], [("iterative", "linear")], repeats=1,
                      stop=0.15, settings=settings)  # the reference of the dense-output test below: cached
    (row,) = rep.rows
    assert row.status == "failed" and "did not converge in 2 iterations" in row.failure
    assert "did not converge in 2 iterations" in rep.table()  # the reason in the text table too


# ---------------------------------------------------------------------------------------------- dense output
def test_dense_output_from_the_fmus_slopes(tmp_path):
    """Hermite between communication points from fmi2GetRealOutputDerivatives: the slope of the joint angle
    is the recorded joint speed, and between the points the interpolant's error is the coupling's (as at
    the points), where the straight line's is the interpolation's."""
    from fmugen.cosim.dense import hermite
    from fmugen.cosim.reference import solve_reference

    built = ac.build_scene_cached(SPLIT, tmp_path / "fmus")
    H, stop = 15e-3, 0.15  # Newton/cubic: a coupling error far below what a straight line between points makes
    r = run(built, "newton", "cubic", step=H, stop=stop, dense=True)
    assert r.ok and r.slopes.shape == r.values.shape
    th, w = r.columns.index("joint.theta"), r.columns.index("joint.w")
    np.testing.assert_allclose(r.slopes[:, th], r.values[:, w], rtol=1e-12, atol=1e-15)  # der(theta) = w
    assert np.all(np.isfinite(r.slopes))
    mid = 0.5 * (r.time[1:] + r.time[:-1])
    p = built.scene.reference_problem()
    from fmugen.cosim.system import ReferenceProblem

    p = ReferenceProblem(p.model, p.x0, p.u, p.columns, p.start_time, stop, p.nominals)
    ref = solve_reference(p, times=np.concatenate([r.time, mid]))
    n = len(r.time)
    e_cp = np.max(np.abs(r.values[:, th] - ref["joint.theta"][:n]))
    e_line = np.max(np.abs(hermite(r.time, r.values, None, mid)[:, th] - ref["joint.theta"][n:]))
    e_herm = np.max(np.abs(hermite(r.time, r.values, r.slopes, mid)[:, th] - ref["joint.theta"][n:]))
    # measured: e_cp 3.1e-6, the line 2.0e-4 (it would be reported as the run's error), Hermite 3.9e-6
    assert e_line > 10 * e_cp and e_herm < 2 * e_cp, (e_cp, e_line, e_herm)
