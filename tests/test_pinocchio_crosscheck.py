"""fmugen's dynamics against Pinocchio (rnea, crba, aba) on the same robot.

The benchmark examples/bench_generated_code.py compares the speed of the
generated C with Pinocchio's; that comparison means something only if both
compute the same quantities.  Pinocchio's recursive algorithms share no code
with fmugen's formulations; the Pinocchio model is built from the robot
description by fmugen.codegen.benchmarks.pinocchio_model (joint placements
from the DH parameters, inertias moved into the joint frames).  The recursive
Lagrange formulation works in the DH frames directly, so agreement with it
also checks that conversion.  Skipped when Pinocchio (PyPI ``pin``) is absent.
"""
import importlib.util
import sys
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

pin = pytest.importorskip("pinocchio")

from fmugen.codegen.benchmarks import (forward_dynamics_model, inverse_dynamics_model,  # noqa: E402
                                       mass_matrix_model, pinocchio_model)
from fmugen.codegen.c_code import generate_c  # noqa: E402
from fmugen.codegen.c_harness import CompiledModel  # noqa: E402
from fmugen.dynamics.manipulator import FORMULATIONS, Manipulator  # noqa: E402
from fmugen.robot.chain import n_link_chain  # noqa: E402
from fmugen.robot.description import Payload  # noqa: E402
from fmugen.robot.loader import load_robot_description  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RTOL = 1e-10


def load(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # puma_thesis opts in to its unrealisable link 2
        return load_robot_description(ROOT / "robots" / f"{name}.toml")


def states(n, count=4, seed=0):
    rng = np.random.default_rng(seed)
    return [(rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n), rng.uniform(-5, 5, n),
             rng.uniform(-30, 30, n)) for _ in range(count)]


def rel(a, b):
    """inf-norm error of a relative to the reference b."""
    return np.max(np.abs(np.asarray(a) - b)) / np.max(np.abs(b))


def symmetric(upper):
    """crba fills the upper triangle only."""
    return np.triu(upper) + np.triu(upper, 1).T


def assert_same_dynamics(arm, model, formulation, values=None):
    values = values or {}
    data = model.createData()
    for q, qd, qdd, tau in states(arm.n):
        tau_pin = pin.rnea(model, data, q, qd, qdd)
        assert rel(arm.inverse_dynamics(q, qd, qdd, formulation=formulation, **values), tau_pin) < RTOL
        M_pin = symmetric(pin.crba(model, data, q))
        assert rel(arm.mass_matrix(q, formulation=formulation, **values), M_pin) < RTOL
        qdd_pin = pin.aba(model, data, q, qd, tau)
        assert rel(arm.forward_dynamics(q, qd, tau, formulation=formulation, **values), qdd_pin) < RTOL


@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize("name", ["puma_thesis_com", "puma_thesis"])
def test_puma_equals_pinocchio(name, formulation):
    robot = load(name)
    assert_same_dynamics(Manipulator(robot), pinocchio_model(robot), formulation)


def test_puma_with_other_parameter_values():
    """Parameters set away from the file values reach both models alike."""
    robot = load("puma_thesis_com")
    values = {"m_2": 60.0, "a_2": 0.5, "rc_3_z": 0.1, "g_z": -3.7}
    assert_same_dynamics(Manipulator(robot), pinocchio_model(robot, values), "newton_euler", values)


def spatial_chain(convention):
    """A random 5-link RRP.. chain with everything Pinocchio models switched on:
    prismatic joints, angle offsets, full inertia tensors, rotor inertia
    (Pinocchio's armature), a payload; read in the given DH convention."""
    robot = n_link_chain(5, "RRP", seed=7)
    links = tuple(replace(L, theta=sp.Float(0.1 * (i + 1)), rotor_inertia=sp.Float(0.05 * (i + 1)))
                  for i, L in enumerate(robot.links))
    payload = Payload(mass=sp.Float(0.8), com=(sp.Float(0.03), sp.Float(-0.02), sp.Float(0.05)))
    return replace(robot, links=links, convention=convention, payload=payload)


@pytest.mark.parametrize("convention", ["standard", "modified"])
def test_spatial_chain_equals_pinocchio(convention):
    robot = spatial_chain(convention)
    arm = Manipulator(robot)
    model = pinocchio_model(robot)
    assert list(model.armature) == pytest.approx([0.05 * (i + 1) for i in range(5)])
    for formulation in FORMULATIONS:
        assert_same_dynamics(arm, model, formulation)


def test_the_comparison_can_fail():
    """A model that differs in one link's mass is caught."""
    robot = load("puma_thesis_com")
    arm = Manipulator(robot)
    model = pinocchio_model(robot, {"m_3": 36.3 * 1.001})
    q, qd, qdd, _ = states(arm.n)[0]
    assert rel(arm.inverse_dynamics(q, qd, qdd), pin.rnea(model, model.createData(), q, qd, qdd)) > 1e-6


def test_damping_and_missing_values_are_refused():
    robot = n_link_chain(2, seed=1)
    damped = replace(robot, links=(replace(robot.links[0], damping=sp.Float(0.3)),) + robot.links[1:])
    with pytest.raises(ValueError, match="link 1: joint damping"):
        pinocchio_model(damped)
    with pytest.raises(KeyError, match="unknown parameter"):
        pinocchio_model(load("puma_thesis_com"), {"no_such": 1.0})
    sym = n_link_chain(2, symbolic=True)
    p = sym.parameters[1]
    with pytest.raises(ValueError, match=f"no value for parameter.*{p.name}"):
        pinocchio_model(replace(sym, parameters=tuple(replace(q, value=None) if q is p else q
                                                      for q in sym.parameters)))


def test_generated_c_equals_pinocchio_with_parameters_set():
    """The C the benchmark times (ID, lower triangle of M, forward dynamics)
    with run-time parameters set away from the file values.  (The folded
    variants are checked by the benchmark itself, see the last test.)"""
    robot = load("puma_thesis_com")
    arm = Manipulator(robot)
    values = {"m_2": 70.0, "d_4": 0.4, "k2_3_xx": 0.05}
    model = pinocchio_model(robot, values)
    data = model.createData()
    n = arm.n
    lower = [(i, j) for i in range(n) for j in range(i + 1)]
    for make in (inverse_dynamics_model, mass_matrix_model, forward_dynamics_model):
        sm = make(arm, "newton_euler")
        p = [values.get(v.name, v.start) for v in sm.parameters]
        with CompiledModel.build(generate_c(sm).source) as cm:
            for q, qd, qdd, tau in states(n, 3, seed=5):
                if make is inverse_dynamics_model:
                    _, y = cm.evaluate(p, 0.0, [], np.concatenate([q, qd, qdd]))
                    assert rel(y, pin.rnea(model, data, q, qd, qdd)) < RTOL
                elif make is mass_matrix_model:
                    _, y = cm.evaluate(p, 0.0, [], q)
                    M = symmetric(pin.crba(model, data, q))
                    assert rel(y, [M[i, j] for i, j in lower]) < RTOL
                else:
                    dx, _ = cm.evaluate(p, 0.0, np.concatenate([q, qd]), tau, want_y=False)
                    assert rel(dx[:n], qd) == 0.0
                    assert rel(dx[n:], pin.aba(model, data, q, qd, tau)) < RTOL


def test_benchmark_example_runs(capsys, monkeypatch):
    """examples/bench_generated_code.py, cut down: one robot, NE only, one round."""
    spec = importlib.util.spec_from_file_location("bench_generated_code",
                                                  ROOT / "examples" / "bench_generated_code.py")
    bench = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, spec.name, bench)  # its dataclasses look their module up
    spec.loader.exec_module(bench)
    rc = bench.main(["--robots", "robots/puma_thesis_com.toml", "--formulations", "newton_euler",
                     "--repeat", "1", "--calls", "10", "--states", "2", "--build-repeat", "0"])
    out = capsys.readouterr().out
    assert rc == 0
    assert "difference" in out and "(ok, tolerance 1e-10)" in out
    for fn in ("pin.rnea", "pin.crba", "pin.aba"):
        assert fn in out
