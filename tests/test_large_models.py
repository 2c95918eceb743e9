"""Large arms (issue 10): looped chain dynamics, build budgets, progress, clean-up on a kill.

The looped forward dynamics (articulated-body algorithm) and its Jacobian
(analytical Newton-Euler derivatives, one Cholesky solve) of
``c_runtime/chain_dynamics.c`` are checked against two independent sources:
Pinocchio's ``aba`` and ``computeABADerivatives`` at N = 24, and fmugen's own
straight-line code (symbolic Newton-Euler, forward-mode derivatives) on small
arms with what Pinocchio does not model (joint damping) and with parameters
changed at run time.  Build times are figures of examples/bench_large_models.py,
not assertions here.
"""
import os
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

from fmugen.codegen.c_code import generate_c
from fmugen.codegen.c_harness import CompiledModel
from fmugen.codegen.chain import LOOP_MIN_LINKS, ChainDynamics
from fmugen.codegen.evaluate import ModelEvaluator
from fmugen.dynamics.manipulator import Manipulator
from fmugen.fmi.build import BuildBudgetExceeded, build_fmu
from fmugen.robot.chain import chain_to_toml, n_link_chain
from fmugen.robot.description import Payload

ROOT = Path(__file__).resolve().parents[1]
RTOL = 1e-10


def rel(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return np.max(np.abs(a - b)) / np.max(np.abs(b))


def full_featured_chain(n, convention="modified", seed=11):
    """Prismatic joints, angle offsets, full inertia tensors, rotor inertia, a payload."""
    robot = n_link_chain(n, "RRP", seed=seed)
    links = tuple(replace(L, theta=sp.Float(0.07 * (i + 1)), rotor_inertia=sp.Float(0.02 * (i % 4)))
                  for i, L in enumerate(robot.links))
    payload = Payload(mass=sp.Float(0.8), com=(sp.Float(0.03), sp.Float(-0.02), sp.Float(0.05)))
    return replace(robot, links=links, convention=convention, payload=payload)


def states(n, count=3, seed=0):
    rng = np.random.default_rng(seed)
    return [(rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n), rng.uniform(-30, 30, n))
            for _ in range(count)]


def p_start(model):
    return np.array([v.start for v in model.parameters], dtype=float)


def test_24_links_equal_pinocchio_aba_and_its_derivatives():
    pin = pytest.importorskip("pinocchio")
    from fmugen.codegen.benchmarks import pinocchio_model

    n = 24
    robot = full_featured_chain(n)
    model = Manipulator(robot).state_space_model(outputs=("p_ee", "qdd"))
    assert any(isinstance(st, ChainDynamics) for st in model.program.steps)  # auto chose the loops
    pm = pinocchio_model(robot)
    pd = pm.createData()
    with CompiledModel.build(generate_c(model).source) as cm:
        for q, qd, tau in states(n):
            x = np.r_[q, qd]
            dx, y = cm.evaluate(p_start(model), 0.0, x, tau)
            qdd = pin.aba(pm, pd, q, qd, tau)
            assert rel(dx[n:], qdd) < RTOL
            assert np.array_equal(dx[:n], qd)
            assert rel(y[3:], qdd) < RTOL
            pin.forwardKinematics(pm, pd, q)
            # the end effector: origin of the last DH frame (modified DH: the last joint frame)
            assert rel(y[:3], pd.oMi[n].translation) < RTOL
            dfdx, dfdu, dgdx, dgdu = cm.jacobian(p_start(model), 0.0, x, tau)
            pin.computeABADerivatives(pm, pd, q, qd, tau)
            minv = np.triu(pd.Minv) + np.triu(pd.Minv, 1).T
            assert rel(dfdx[n:, :n], pd.ddq_dq) < RTOL
            assert rel(dfdx[n:, n:], pd.ddq_dv) < RTOL
            assert rel(dfdu[n:], minv) < RTOL
            assert np.array_equal(dfdx[:n], np.c_[np.zeros((n, n)), np.eye(n)])
            assert np.array_equal(dgdx[3:], dfdx[n:]) and np.array_equal(dgdu[3:], dfdu[n:])
            # d p_ee / dq: the linear rows of Pinocchio's joint Jacobian at the end effector's origin
            J = pin.computeJointJacobians(pm, pd, q)
            pin.updateFramePlacements(pm, pd)
            Jw = pin.getJointJacobian(pm, pd, n, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
            assert rel(dgdx[:3, :n], Jw[:3]) < RTOL and J is not None


@pytest.mark.parametrize("convention", ["standard", "modified"])
def test_loops_equal_straight_line_code_with_damping_and_changed_parameters(convention):
    """Two derivations that share no code: symbolic Newton-Euler + forward-mode derivatives
    (straight) and the runtime loops; damping (which Pinocchio lacks), symbolic parameters
    evaluated at run time, and the same again with the parameters folded."""
    robot = full_featured_chain(5, convention, seed=3)
    links = tuple(replace(L, damping=sp.Float(0.1 * (i + 1))) for i, L in enumerate(robot.links))
    robot = replace(robot, links=links)
    from fmugen.robot.loader import robot_from_toml

    robot = robot_from_toml(chain_to_toml(robot), source="<test>")  # every quantity a parameter
    arm = Manipulator(robot)
    straight = arm.state_space_model(outputs=("p_ee", "qdd"), strategy="straight")
    looped = arm.state_space_model(outputs=("p_ee", "qdd"), strategy="loops")
    assert [v.name for v in looped.parameters] == [v.name for v in straight.parameters]
    assert len(looped.parameters) > 50
    rng = np.random.default_rng(5)
    p0 = p_start(looped)
    p1 = p0 * rng.uniform(0.8, 1.2, p0.size)  # other masses, lengths, inertias, damping
    with CompiledModel.build(generate_c(straight).source) as cs, \
            CompiledModel.build(generate_c(looped).source) as cl, \
            CompiledModel.build(generate_c(looped.with_parameters_folded()).source) as cf:
        for (q, qd, tau), p in zip(states(5), (p0, p1, p1)):
            x = np.r_[q, qd]
            ref_dx, ref_y = cs.evaluate(p, 0.0, x, tau)
            dx, y = cl.evaluate(p, 0.0, x, tau)
            assert rel(dx, ref_dx) < RTOL and rel(y, ref_y) < RTOL
            for a, b in zip(cl.jacobian(p, 0.0, x, tau), cs.jacobian(p, 0.0, x, tau)):
                assert rel(a, b) < RTOL
        q, qd, tau = states(5)[0]
        # folding bakes in the file values: equal to the straight code at p0, not at p1
        assert rel(cf.evaluate([], 0.0, np.r_[q, qd], tau)[0], cs.evaluate(p0, 0.0, np.r_[q, qd], tau)[0]) < RTOL
        assert rel(cl.evaluate(p1, 0.0, np.r_[q, qd], tau)[0], cs.evaluate(p0, 0.0, np.r_[q, qd], tau)[0]) > 1e-4


def test_strategy_choice_and_its_limits():
    small, large = n_link_chain(LOOP_MIN_LINKS - 1), n_link_chain(LOOP_MIN_LINKS)

    def looped(m):
        return any(isinstance(st, ChainDynamics) for st in m.program.steps)

    assert not looped(Manipulator(small).state_space_model(outputs=()))
    assert looped(Manipulator(large).state_space_model(outputs=()))
    # locked joints (scenes) keep straight-line code, and are refused when loops are asked for
    assert not looped(Manipulator(large).state_space_model(outputs=(), locked={2: 0.3}))
    with pytest.raises(ValueError, match="locked joints.*strategy='straight'"):
        Manipulator(small).state_space_model(strategy="loops", locked={1: 0.0})
    with pytest.raises(ValueError, match="strategy must be"):
        Manipulator(small).state_space_model(strategy="fast")
    # composing a looped arm symbolically (a monolithic scene) is refused with the way out
    from fmugen.codegen.differentiate import differentiate
    from fmugen.codegen.program import Program

    m = Manipulator(large).state_space_model(outputs=())
    with pytest.raises(ValueError, match="group of its own.*strategy='straight'"):
        differentiate([m.program], m.derivatives, [v.symbol for v in m.states], Program("_z"), through_solves=True)


def test_python_evaluators_call_the_same_loops():
    """ModelEvaluator / linearize of a looped model (ctypes into chain_dynamics.c) equal the
    straight-line model's Python evaluation (numpy, symbolic derivatives)."""
    import fmugen

    arm = Manipulator(n_link_chain(LOOP_MIN_LINKS, "RRP", seed=4))
    looped = arm.state_space_model(outputs=("p_ee", "qdd"))
    straight = arm.state_space_model(outputs=("p_ee", "qdd"), strategy="straight")
    el, es = ModelEvaluator(looped), ModelEvaluator(straight)
    rng = np.random.default_rng(2)
    for _ in range(3):
        x, u = rng.uniform(-1.5, 1.5, 2 * arm.n), rng.uniform(-10, 10, arm.n)
        assert rel(el.f(0.0, x, u), es.f(0.0, x, u)) < RTOL and rel(el.g(0.0, x, u), es.g(0.0, x, u)) < RTOL
        for a, b in zip(el.jacobians(0.0, x, u), es.jacobians(0.0, x, u)):
            assert rel(a, b) < RTOL
    sys_l, sys_s = fmugen.linearize(looped, x=x, u=u), fmugen.linearize(straight, x=x, u=u)
    assert rel(sys_l.A, sys_s.A) < RTOL and rel(sys_l.B, sys_s.B) < RTOL


def test_external_wrenches_in_the_loops_equal_straight_line_code():
    """Forces at the centres of mass and torques (base frame) on links 1, 3 and the last: the
    looped FD and every Jacobian block, the wrench columns included, in C and through Python."""
    n, ks = LOOP_MIN_LINKS, (0, 2, LOOP_MIN_LINKS - 1)
    robot = full_featured_chain(n, "standard", seed=8)
    robot = replace(robot, links=tuple(replace(L, external_wrench=(i in ks)) for i, L in enumerate(robot.links)))
    arm = Manipulator(robot)
    looped = arm.state_space_model(outputs=("p_ee", "qdd"))
    straight = arm.state_space_model(outputs=("p_ee", "qdd"), strategy="straight")
    assert any(isinstance(st, ChainDynamics) for st in looped.program.steps)
    assert [v.name for v in looped.inputs] == [v.name for v in straight.inputs] and looped.nu == n + 18
    el, es = ModelEvaluator(looped), ModelEvaluator(straight)
    rng = np.random.default_rng(9)
    with CompiledModel.build(generate_c(looped).source) as cl:
        for _ in range(3):
            x, u = rng.uniform(-1.5, 1.5, 2 * n), rng.uniform(-20, 20, looped.nu)
            ref = es.jacobians(0.0, x, u)
            assert rel(cl.evaluate([], 0.0, x, u)[0], es.f(0.0, x, u)) < RTOL
            assert rel(el.f(0.0, x, u), es.f(0.0, x, u)) < RTOL
            for a, b, c in zip(cl.jacobian([], 0.0, x, u), el.jacobians(0.0, x, u), ref):
                assert rel(a, c) < RTOL and rel(b, c) < RTOL
            assert np.max(np.abs(ref[1][n:, n:])) > 1e-3  # the wrench columns are not trivially zero


def test_modelstructure_of_a_looped_model_is_dense():
    """The FD couples every qdd to every q, qd, tau: the XML must say so (exact for a spatial chain)."""
    from fmugen.fmi.model_description import model_description_xml

    m = Manipulator(n_link_chain(LOOP_MIN_LINKS)).state_space_model(outputs=("qdd",))
    deps = m.dependencies()
    n = LOOP_MIN_LINKS
    want = {v.symbol for v in m.states + m.inputs}
    assert all(d == want for d in deps["derivatives"][n:]) and all(d == want for d in deps["outputs"])
    assert "<ModelStructure>" in model_description_xml(m, "{x}", "m", ("me",), ())


def test_24_link_fmu_through_fmpy():
    """ME + CS in one build; fmpy's derivatives equal the harness's; CS integrates."""
    fmpy = pytest.importorskip("fmpy")
    from fmpy.validation import validate_fmu

    n = 24
    robot = n_link_chain(n, seed=1)
    model = Manipulator(robot).state_space_model()
    with tempfile.TemporaryDirectory() as tmp:
        res = build_fmu(model, Path(tmp) / "chain24.fmu", fmi_type="both", progress=False)
        assert validate_fmu(str(res.path)) == []
        assert res.op_counts["jacobian"].loops.mul > 0 and res.op_counts["evaluate"].expressions.mul == 0
        q0 = np.linspace(-0.5, 0.5, n)
        start = {f"q[{i + 1}]": q0[i] for i in range(n)}
        out = fmpy.simulate_fmu(str(res.path), fmi_type="CoSimulation", stop_time=0.05, output_interval=0.01,
                                start_values=start, output=[f"q[{n}]", "p_ee[3]"])
        assert np.all(np.isfinite(out[f"q[{n}]"]))
        # the arm falls: with qd(0) = 0, q(t) - q(0) ~ qdd(0) t^2 / 2 from the harness's qdd
        with CompiledModel.build(generate_c(model).source) as cm:
            dx, _ = cm.evaluate([], 0.0, np.r_[q0, np.zeros(n)], np.zeros(n))
        t = out["time"][1]
        assert out[f"q[{n}]"][1] - q0[-1] == pytest.approx(0.5 * dx[2 * n - 1] * t * t, rel=0.05)


def _tiny_model():
    return Manipulator(n_link_chain(LOOP_MIN_LINKS, seed=2)).state_space_model()


def test_budgets_stop_the_build_with_a_message_and_leave_nothing(tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    out = tmp_path / "out" / "m.fmu"
    with pytest.raises(BuildBudgetExceeded, match=r"exceeds the time budget of 0.01 s \(in stage"):
        build_fmu(_tiny_model(), out, budget_seconds=0.01, budget_start=time.perf_counter() - 1.0)
    with pytest.raises(BuildBudgetExceeded, match=r"MiB in use exceeds the memory budget of 1 MiB"):
        build_fmu(_tiny_model(), out, budget_memory=2**20)
    with pytest.raises(ValueError, match="budget_seconds must be a positive number"):
        build_fmu(_tiny_model(), out, budget_seconds=-1)
    assert list(tmp_path.iterdir()) == []
    # a compiler that never ends is stopped in its stage, and killed
    cc = tmp_path / "slowcc"
    cc.write_text(SLOW_CC.format(pids=tmp_path / "pids"))
    cc.chmod(0o755)
    with pytest.raises(BuildBudgetExceeded, match=r"time budget of 2 s \(in stage 'compile'\)"):
        build_fmu(_tiny_model(), out, budget_seconds=2, cc=str(cc))
    for pid in map(int, (tmp_path / "pids").read_text().split()):
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)
    # nothing else: no temporary folder, and not even the output's folder (made only after a compile works)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pids", "slowcc"]
    # within budget: built, and the budget did not change the result
    res = build_fmu(_tiny_model(), out, budget_seconds=600, budget_memory=4 * 2**30)
    assert res.path.is_file()


def test_cli_budget_is_one_line_and_exit_2(tmp_path):
    robot = tmp_path / "chain.toml"
    robot.write_text(chain_to_toml(n_link_chain(LOOP_MIN_LINKS, seed=1)))
    r = subprocess.run([sys.executable, "-m", "fmugen.cli", "build", str(robot), "-o", str(tmp_path / "c.fmu"),
                        "--budget-memory", "1M"], capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert r.stderr.strip().startswith("fmugen: build stopped:") and "memory budget of 1 MiB" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "c.fmu").exists()


def test_progress_only_when_asked_or_on_a_terminal(tmp_path, capsys):
    build_fmu(_tiny_model(), tmp_path / "a.fmu", progress=True)
    err = capsys.readouterr().err
    assert "generate (" in err and "compile (model.c" in err and err.count(" s\n") == 2
    build_fmu(_tiny_model(), tmp_path / "b.fmu")  # stderr is not a terminal under pytest
    assert capsys.readouterr().err == ""


SLOW_CC = """#!/bin/sh
echo $$ >> "{pids}"
exec sleep 60
"""

# SIGINT back to Python's default first: a pytest started in the background by a non-interactive shell
# hands its children SIGINT ignored, and build_fmu leaves an ignored SIGINT ignored
CHILD = """
import signal, sys, tempfile
signal.signal(signal.SIGINT, signal.default_int_handler)
tempfile.tempdir = {tmp!r}
from fmugen.dynamics.manipulator import Manipulator
from fmugen.fmi.build import build_fmu
from fmugen.robot.chain import n_link_chain
m = Manipulator(n_link_chain(2)).state_space_model()
build_fmu(m, {out!r}, cc={cc!r})
"""


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_killed_build_removes_its_files_and_its_compilers(tmp_path, sig):
    """The issue's 60-link build, killed by the user, left 19 MB behind: not any more."""
    work, pids = tmp_path / "tmp", tmp_path / "pids"
    work.mkdir()
    cc = tmp_path / "slowcc"
    cc.write_text(SLOW_CC.format(pids=pids))
    cc.chmod(0o755)
    out = tmp_path / "m.fmu"
    proc = subprocess.Popen([sys.executable, "-c", textwrap.dedent(CHILD.format(tmp=str(work), out=str(out),
                                                                             cc=str(cc)))],
                            stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    while not (pids.exists() and pids.read_text().strip()) and time.time() < deadline:
        time.sleep(0.1)
    assert any(work.iterdir()), "the build should be compiling in its temporary folder"
    proc.send_signal(sig)
    try:
        _, err = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        raise
    assert proc.returncode != 0, err
    assert "BuildInterrupted" in err or "KeyboardInterrupt" in err, err
    assert list(work.iterdir()) == [] and not out.exists() and not out.with_name("m.fmu.part").exists() \
        and not list(out.parent.glob(".m.fmu.*.part"))
    # the compilers it started are gone, also one started just as the signal came (it used to raise inside
    # subprocess.Popen, between fork and return, and the compiler ran on unknown to the build)
    for pid in map(int, pids.read_text().split()):
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)


def test_puma_keeps_straight_line_code():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from fmugen.robot.loader import load_robot_description

        robot = load_robot_description(ROOT / "robots" / "puma_thesis_com.toml")
    m = Manipulator(robot).state_space_model()
    assert not any(isinstance(st, ChainDynamics) for st in list(m.program.steps) + list(m.jacobian.steps))


def test_builds_in_worker_threads_stop_when_cancelled(tmp_path):
    """Signals reach only the main thread: a scene's groups build in worker threads (fmugen/scene/build.py)
    and learn of a Ctrl-C there, or of another group's failure, through fmugen.fmi.build.cancellable.  Two
    builds held in a 60 s compiler stop within seconds of the event, their compilers killed, no file left."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    from fmugen.fmi.build import BuildInterrupted, build_fmu, cancellable
    from fmugen.robot.chain import n_link_chain

    pids = tmp_path / "pids"
    cc = tmp_path / "slowcc"
    cc.write_text(SLOW_CC.format(pids=pids))
    cc.chmod(0o755)
    model = Manipulator(n_link_chain(2)).state_space_model()
    cancel = threading.Event()

    def one(k):
        with cancellable(cancel):
            build_fmu(model, tmp_path / f"m{k}.fmu", cc=str(cc))

    with ThreadPoolExecutor(max_workers=2) as ex:
        futures = [ex.submit(one, k) for k in range(2)]
        deadline = time.time() + 120
        while not (pids.exists() and len(pids.read_text().split()) >= 2) and time.time() < deadline:
            time.sleep(0.05)
        assert len(pids.read_text().split()) >= 2, "both builds should be compiling"
        t0 = time.time()
        cancel.set()
        for f in futures:
            with pytest.raises(BuildInterrupted, match="cancelled"):
                f.result(timeout=50)  # well inside the compilers' 60 s
    assert time.time() - t0 < 50
    for pid in map(int, pids.read_text().split()):
        with pytest.raises(ProcessLookupError):  # the compilers they started are gone
            os.kill(pid, 0)
    assert not list(tmp_path.glob("m*.fmu*")) and not list(tmp_path.glob(".m*"))
