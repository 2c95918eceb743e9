"""Hardening, third round: arguments are checked first, named in their refusal, and the command
line never writes over its own input.

Each refusal is exit 2 with one line naming the argument, and nothing is written (no output
folder, no FMU); unbounded work asked by one argument is refused with the number.
"""
from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from fmugen.cli import main

ROOT = Path(__file__).resolve().parents[1]
SPLIT = ROOT / "examples" / "scenes" / "single_joint_split.toml"
HORN = ROOT / "robots" / "horn_2link.toml"
RIG = """
[scene]
name = "rig"
stop = 0.05
step = 1e-3
[instances.joint]
type = "joint_inertia"
[fmus.joint]
members = ["joint"]
solver = "dopri5"
"""


def _refused(capsys, *argv) -> str:
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("fmugen") and err.count("\n") == 1 and "Traceback" not in err, err
    return err


def test_an_output_path_is_never_an_input_a_folder_for_a_file_or_a_file_for_a_folder(tmp_path, capsys):
    robot = tmp_path / "r.toml"
    robot.write_bytes(HORN.read_bytes())
    sets = ["--set", "m=1", "--set", "l=0.5", "--set", "g=9.81"]
    assert "input file" in _refused(capsys, "build", robot, "-o", robot, *sets)
    assert robot.read_bytes() == HORN.read_bytes()
    os.chdir(tmp_path)
    try:  # the same file under another spelling
        assert "input file" in _refused(capsys, "build", robot, "-o", "./r.toml", *sets)
    finally:
        os.chdir(ROOT)
    (tmp_path / "adir").mkdir()
    assert "a folder" in _refused(capsys, "build", robot, "-o", tmp_path / "adir", *sets)
    assert "a folder" in _refused(capsys, "build", robot, "-o", f"{tmp_path / 'newdir'}/", *sets)
    assert not (tmp_path / "newdir").exists()
    # a scene builds into a folder: an existing file (its own input or another) is refused
    assert "names a folder" in _refused(capsys, "build", SPLIT, "-o", robot)
    assert "input file" in _refused(capsys, "linearize", robot, "--out", robot, *sets)
    assert "names a folder" in _refused(capsys, "cosim", SPLIT, "--out", robot)
    assert robot.read_bytes() == HORN.read_bytes()


def test_building_x_fmu_keeps_a_users_x_fmu_part(tmp_path, capsys):
    out = tmp_path / "x.fmu"
    part = tmp_path / "x.fmu.part"
    part.write_text("the user's own file")
    assert main(["build", str(HORN), "-o", str(out), "--set", "m=1", "--set", "l=0.5", "--set", "g=9.81",
                 "--fmi-type", "cs"]) == 0
    assert part.read_text() == "the user's own file"
    assert zipfile.ZipFile(out).testzip() is None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.fmu", "x.fmu.part"]


@pytest.mark.parametrize("argv, named", [
    (["linearize", HORN, "--tol=-1"], "--tol"),
    (["linearize", HORN, "--tol", "nan"], "--tol"),
    (["linearize", HORN, "--tol", "inf"], "--tol"),
    (["linearize", HORN, "--time", "nan"], "--time"),
    (["linearize", HORN, "--time=-inf"], "--time"),
    (["report", SPLIT, "--target", "nan"], "--target"),
    (["report", SPLIT, "--target=-0.5"], "--target"),
    (["report", SPLIT, "--steps=-1e-3"], "--steps"),
    (["report", SPLIT, "--steps", "a,b"], "--steps 'a,b': 'a' is not a number"),
    (["report", SPLIT, "--steps", "2e-3,,1e-3"], "--steps"),
    (["report", SPLIT, "--internal", "rodas3:nan"], "--internal"),
    (["report", SPLIT, "--repeats", "0"], "--repeats"),
    (["cosim", SPLIT, "--step", "0"], "--step"),
    (["cosim", SPLIT, "--step", "1e-300"], "macro steps"),
    (["cosim", SPLIT, "--stop", "1e308"], "macro steps"),
    (["cosim", SPLIT, "--stop", "-1"], "--stop"),
    (["cosim", SPLIT, "--tol", "0"], "--tol"),
    (["reference", SPLIT, "--points", "1e11"], "1e+11"),
    (["reference", SPLIT, "--points", "-5"], "--points"),
    (["reference", SPLIT, "--stop", "nan"], "--stop"),
])
def test_a_bad_argument_is_named_and_nothing_is_written(tmp_path, capsys, argv, named):
    out = tmp_path / "out"
    err = _refused(capsys, *argv, "--out", out)
    assert named in err, err
    assert not out.exists()


def test_a_compiler_failure_is_one_line_and_leaves_no_output_folder(tmp_path):
    fake = tmp_path / "bin"
    fake.mkdir()
    (fake / "cc").write_text("#!/bin/sh\necho 'model.c:1:1: error: the compiler refuses' >&2\nexit 1\n")
    (fake / "cc").chmod(0o755)
    scene = tmp_path / "rig.toml"
    scene.write_text(RIG)
    env = dict(os.environ, PATH=f"{fake}{os.pathsep}{os.environ['PATH']}", FMUGEN_CACHE=str(tmp_path / "cache"),
               PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, "-m", "fmugen.cli", "build", str(scene), "-o", str(tmp_path / "o")],
                          capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr
    assert "C compiler failed" in proc.stderr and "the compiler refuses" in proc.stderr
    assert not (tmp_path / "o").exists()
