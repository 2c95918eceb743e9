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
    assert "input file" in _refused(capsys, "export-urdf", robot, "-o", robot)
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
    (["report", SPLIT, "--steps", "-2.5e-3"], "must be a positive macro step"),
    (["linearize", HORN, "--time", "-inf"], "--time -inf: must be a finite number"),
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


def test_the_files_own_cosim_step_is_bounded_before_anything_is_built(tmp_path, capsys):
    p = tmp_path / "s.toml"
    p.write_text("[cosim]\nstep = 1e-290\n\n" + SPLIT.read_text())
    assert "1e+290 macro steps" in _refused(capsys, "cosim", p, "--out", tmp_path / "o")
    assert "macro steps" in _refused(capsys, "cosim", SPLIT, "--set", "cosim.step=3e-280", "--out", tmp_path / "o")
    assert not (tmp_path / "o").exists()


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
    # a single FMU into a folder that does not exist yet: the folder is not left behind either
    proc = subprocess.run([sys.executable, "-m", "fmugen.cli", "build", str(HORN), "--set", "m=1", "--set", "l=1",
                           "--set", "g=9.81", "-o", str(tmp_path / "new" / "h.fmu")],
                          capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 1 and proc.stderr.count("\n") == 1 and "C compiler failed" in proc.stderr
    assert not (tmp_path / "new").exists()


# ----------------------------------------------------------------- bounded work, network waits
def test_a_device_fifo_or_huge_file_is_refused_before_it_is_read(tmp_path, capsys):
    assert "not a regular file" in _refused(capsys, "info", "/dev/zero")
    fifo = tmp_path / "pipe.toml"
    os.mkfifo(fifo)
    assert "not a regular file" in _refused(capsys, "info", fifo)  # would block forever if opened
    big = tmp_path / "big.toml"
    with open(big, "wb") as fh:
        fh.truncate(40 * 2**20)
    assert "40 MiB" in _refused(capsys, "build", big, "-o", tmp_path / "x.fmu")


@pytest.mark.parametrize("extra, named", [
    (["--scheme", "bogus"], "unknown scheme 'bogus'"),
    (["--scheme", "jacobi", "--extrapolation", "cubic"], "--scheme/--extrapolation"),
    (["--workers", "0"], "--workers 0"),
    (["--step", "0"], "--step"),
    (["--step", "1e-250"], "macro steps"),
    (["--scheduler", "tcp://127.0.0.1:1"], "cannot reach"),
    (["--scheduler", "not an address"], "--scheduler"),
    (["--grid", "amp.K_a=linspace(1,2,200000)", "--grid", "joint.B_m=linspace(0,1,300000)"], "1.2e+11 points"),
    (["--sample", "joint.B_m=uniform(0,1)", "-n", "7" * 330, "--seed", "1"], "a 330-digit number of samples"),
])
def test_a_sweep_refuses_before_writing_anything(tmp_path, capsys, extra, named):
    out = tmp_path / "sweep"
    err = _refused(capsys, "sweep", SPLIT, "--grid", "joint.J=0.5,1", *extra, "--out", out)
    assert named in err, err
    assert not out.exists()


def test_every_scheduler_wait_times_out(tmp_path):
    import socket
    import threading
    import time

    from fmugen.sweep.errors import SweepError
    from fmugen.sweep.execute import probe_scheduler

    def serve(sock, reply):
        conn, _ = sock.accept()
        if reply:
            conn.sendall(reply)
        time.sleep(3)
        conn.close()

    for reply, expected in ((b"HTTP/1.0 400 Bad Request\r\n\r\n", "not as a Dask scheduler"),
                            (b"", "no answer within")):
        srv = socket.socket()
        srv.bind(("127.0.0.1", 0))
        srv.listen(1)
        port = srv.getsockname()[1]
        th = threading.Thread(target=serve, args=(srv, reply), daemon=True)
        th.start()
        t0 = time.perf_counter()
        with pytest.raises(SweepError, match=expected):
            probe_scheduler(f"tcp://127.0.0.1:{port}", timeout=0.5)
        assert time.perf_counter() - t0 < 2.5
        srv.close()


def test_record_duplicates_are_refused_before_the_run(tmp_path, capsys):
    p = tmp_path / "dup.toml"
    p.write_text(SPLIT.read_text().replace('record = ["joint.theta",', 'record = ["joint.theta", "joint.theta",'))
    assert "more than once" in _refused(capsys, "cosim", p, "--out", tmp_path / "o")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("unit, fragment", [('"m"', "is in [m]"), ('"s"', "is in [s]"),
                                            ('"g"', "robot files hold SI values")])
def test_a_declared_unit_must_fit_the_field_it_is_used_in(tmp_path, capsys, unit, fragment):
    p = tmp_path / "r.toml"
    p.write_text(HORN.read_text().replace('m = { unit = "kg"', f"m = {{ unit = {unit}"))
    err = _refused(capsys, "info", p)
    assert "link 1 (link1): mass" in err and fragment in err and "[kg]" in err
    # a length declared in kg: refused where it is first used (the DH length a)
    q = tmp_path / "q.toml"
    q.write_text(HORN.read_text().replace('l = { unit = "m"', 'l = { unit = "kg"'))
    assert "link 1 (link1): a: l is in [kg]" in _refused(capsys, "info", q)


def test_units_inside_expressions_are_checked():
    import sympy as sp

    from fmugen.robot.checks import unit_problem

    m, l, t = sp.symbols("m l t", real=True)
    assert unit_problem(m * l**2, "kg.m2", {m: "kg", l: "m"}) is None
    assert unit_problem(m * l**2, "kg.m2", {m: "kg", l: "mm"}) is not None
    assert unit_problem(2 * l**2, "kg.m2", {l: "m"}) is None  # the 2 may be a mass: nothing to refuse
    assert "adds" in unit_problem(m + l, "kg", {m: "kg", l: "m"})
    assert "adds" in unit_problem(m - l * t, "kg", {m: "kg", l: "m", t: "s"})
    assert "argument of cos" in unit_problem(l * sp.cos(l), "m", {l: "m"})
    assert unit_problem(l * sp.cos(t), "m", {l: "m", t: "rad"}) is None
    assert unit_problem(m * l, "kg.m2", {m: "kg"}) is None  # l has no declared unit: nothing to check


@pytest.mark.parametrize("command, bad", [("cosim", ["--step", "0"]), ("reference", ["--points", "5e7"]),
                                          ("report", ["--target", "0"])])
def test_cosim_reference_and_report_honour_allow_factories(tmp_path, capsys, monkeypatch, command, bad):
    (tmp_path / "my_parts_i19.py").write_text(
        "from fmugen.components import joint_inertia\n"
        "def heavy_joint(name, parameter_set='default', overrides=None):\n"
        "    return joint_inertia(parameter_set=parameter_set, overrides=overrides, name=name)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    p = tmp_path / "f.toml"
    p.write_text(SPLIT.read_text().replace('joint = { type = "joint_inertia" }',
                                           'joint = { factory = "my_parts_i19:heavy_joint" }'))
    assert "--allow-factories" in _refused(capsys, command, p, *bad, "--out", tmp_path / "o")
    # allowed: the scene loads, and the command goes on to refuse its own bad argument
    err = _refused(capsys, command, p, "--allow-factories", *bad, "--out", tmp_path / "o")
    assert bad[0] in err and "factor" not in err
    assert not (tmp_path / "o").exists()
