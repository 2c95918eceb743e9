"""fmugen.control.linearize at non-zero operating points, against three independent sources.

The classic failure of symbolic linearisers is a Jacobian that is right at
zero and wrong elsewhere, so every check here is at a trimmed, non-zero
point: (1) central differences of the compiled C model (the generated
``evaluate``, called through the ctypes harness -- no Jacobian program
involved), (2) the built ME FMU's ``fmi2GetDirectionalDerivative`` read
through fmpy (what other FMI tools see), and (3) for the arm alone,
Pinocchio's analytical derivatives of the articulated-body algorithm
(``computeABADerivatives``), which share no code with fmugen.
"""
import warnings

import control
import numpy as np
import pytest

import fmugen
from fmugen.codegen.c_code import generate_c
from fmugen.codegen.c_harness import CompiledModel
from fmugen.codegen.evaluate import ModelEvaluator
from fmugen.components import (amplifier, assemble, current_driver, hydraulic_actuator, servo_valve,
                               single_joint)
from fmugen.control import linearize, linearize_fmu, signal_name, trim

Q0 = np.array([0.3, -0.5, 0.8, 0.2, -0.4, 0.6])


@pytest.fixture(scope="module")
def puma():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fmugen.load_robot("robots/puma_thesis_com.toml")


@pytest.fixture(scope="module")
def puma_model(puma):
    return puma.state_space_model(outputs=("p_ee",))


@pytest.fixture(scope="module")
def puma_hydraulic(puma):
    """Joint 2 of the PUMA driven by its hydraulic chain: the monolithic model of a scene."""
    s = "puma_joint2"
    comps = {"arm": puma.state_space_model(outputs=()), "amp": amplifier(parameter_set=s, control="PI"),
             "driver": current_driver(parameter_set=s), "valve": servo_valve(parameter_set=s),
             "actuator": hydraulic_actuator(parameter_set=s)}
    return assemble("puma_joint2_hydraulic", comps,
                    [("arm.q[2]", "amp.theta"), ("amp.u", "driver.u"), ("driver.i", "valve.i"),
                     ("actuator.P_L", "valve.P_L"), ("valve.Q_L", "actuator.Q_L"), ("arm.qd[2]", "actuator.w"),
                     ("actuator.tau", "arm.tau[2]")])


def central_differences(model, x, u, t=0.0):
    """[A B; C D] of the compiled C model by central differences, step 1e-6 relative."""
    ev = ModelEvaluator(model)
    with CompiledModel.build(generate_c(model).source) as cm:
        def fg(z):
            dx, y = cm.evaluate(ev.p, t, z[: model.nx], z[model.nx:])
            return np.r_[dx, y]

        z = np.r_[x, u]
        J = np.zeros((model.nx + model.ny, z.size))
        for k in range(z.size):
            h = 1e-6 * max(1.0, abs(z[k]))
            e = np.zeros(z.size)
            e[k] = h
            J[:, k] = (fg(z + e) - fg(z - e)) / (2 * h)
    nx = model.nx
    return J[:nx, :nx], J[:nx, nx:], J[nx:, :nx], J[nx:, nx:]


def assert_close(M, ref, rtol, what):
    scale = max(np.abs(ref).max(), 1e-300)
    err = np.abs(np.asarray(M) - ref).max() / scale
    assert err <= rtol, f"{what}: relative error {err:.2e} > {rtol:g}"


def test_puma_at_a_held_pose_equals_central_differences_of_the_compiled_model(puma, puma_model):
    op = trim(puma_model, at={"q": Q0, "qd": 0.0}, free=["tau"])
    sys = linearize(puma_model, op, outputs="computed")
    A, B, C, D = central_differences(puma_model, op.x, op.u)
    assert_close(sys.A, A, 1e-7, "A")
    assert_close(sys.B, B, 1e-7, "B")
    assert_close(sys.C, C, 1e-7, "C (p_ee)")
    assert np.abs(sys.D).max() == 0.0 and np.abs(D).max() < 1e-9


def test_puma_moving_equals_pinocchio_aba_derivatives(puma):
    """A and B of the arm = [[0, I], [d qdd/dq, d qdd/dqd]], [[0], [M^-1]] from Pinocchio."""
    pin = pytest.importorskip("pinocchio")
    from fmugen.codegen.benchmarks import pinocchio_model

    pm = pinocchio_model(puma.robot)
    data = pm.createData()
    model = puma.state_space_model(outputs=())
    rng = np.random.default_rng(12)
    for qd, tau in [(np.zeros(6), puma.bias(Q0, np.zeros(6))), (rng.uniform(-2, 2, 6), rng.uniform(-50, 50, 6))]:
        sys = linearize(model, np.r_[Q0, qd], tau)
        ddq_dq, ddq_dv, Minv = (np.array(M) for M in pin.computeABADerivatives(pm, data, Q0, qd, tau))
        Minv = np.triu(Minv) + np.triu(Minv, 1).T  # Pinocchio fills the upper triangle
        A = np.block([[np.zeros((6, 6)), np.eye(6)], [ddq_dq, ddq_dv]])
        B = np.vstack([np.zeros((6, 6)), Minv])
        assert_close(sys.A, A, 1e-10, "A vs Pinocchio")
        assert_close(sys.B, B, 1e-10, "B vs Pinocchio")


def test_puma_fmu_directional_derivatives_equal_the_symbolic_matrices(puma_model, tmp_path):
    fmu = tmp_path / "puma.fmu"
    fmugen.build_fmu(puma_model, fmu, fmi_type="me")
    rng = np.random.default_rng(5)
    x, u = np.r_[Q0, rng.uniform(-1, 1, 6)], rng.uniform(-40, 40, 6)
    sym, num = linearize(puma_model, x, u), linearize_fmu(fmu, x, u)
    assert num.state_labels == sym.state_labels and num.output_labels == sym.output_labels
    for a, b, what in zip((num.A, num.B, num.C, num.D), (sym.A, sym.B, sym.C, sym.D), "ABCD"):
        assert_close(a, b, 1e-12, what)
    # a parameter set away from the file value reaches both paths alike
    sym = linearize(puma_model, x, u, parameter_values={"m_3": 7.5})
    num = linearize_fmu(fmu, x, u, parameter_values={"m_3": 7.5})
    assert_close(num.A, sym.A, 1e-12, "A, m_3 = 7.5")
    assert np.abs(sym.A - linearize(puma_model, x, u).A).max() > 1e-3  # the parameter matters


def test_scene_monolithic_model_at_its_trim_point_three_ways(puma_hydraulic, tmp_path):
    """Arm + hydraulic chain held at a pose: symbolic = FMU = central differences."""
    m = puma_hydraulic
    op = trim(m, at={"arm.q": Q0, "arm.qd": 0.0, "amp.theta_ref": Q0[1]}, free=["arm.tau"])
    assert op["actuator.P_L"] != 0.0 and op["valve.x_v"] != 0.0  # a non-zero point of the chain too
    sym = linearize(m, op, outputs="all")
    A, B, C, D = central_differences(m, op.x, op.u)
    assert_close(sym.A, A, 1e-6, "A vs central differences")
    assert_close(sym.B, B, 1e-6, "B vs central differences")
    fmu = tmp_path / "scene.fmu"
    fmugen.build_fmu(m, fmu, fmi_type="me")
    num = linearize_fmu(fmu, op)
    assert num.state_labels == sym.state_labels and num.input_labels == sym.input_labels
    order = [num.output_labels.index(n) for n in sym.output_labels]
    assert_close(num.A, sym.A, 1e-12, "A vs FMU")
    assert_close(num.B, sym.B, 1e-12, "B vs FMU")
    assert_close(num.C[order], sym.C, 1e-12, "C vs FMU")


def test_one_naming_rule_and_one_function():
    """FMI names, '.' written '_'; components.linearise is fmugen.linearize."""
    import fmugen.components as comps

    assert comps.linearise is fmugen.linearize is linearize
    m = single_joint("default")
    sys = linearize(m)
    assert sys.state_labels == [signal_name(v.name) for v in m.states]
    assert "valve_x_v" in sys.state_labels and "amp_theta_ref" in sys.input_labels
    # selections by FMI name, python-control name or base name; B, C, D columns/rows follow
    part = linearize(m, outputs=["joint.theta", "actuator_tau"], inputs=["joint.tau_load"])
    assert part.output_labels == ["joint_theta", "actuator_tau"] and part.input_labels == ["joint_tau_load"]
    full = linearize(m)
    i_tau = full.output_labels.index("actuator_tau")
    assert np.array_equal(part.C[1], full.C[i_tau]) and np.array_equal(part.B[:, 0], full.B[:, 1])
    # python-control's vector conventions work on the names
    arm_like = linearize(fmugen.load_robot("robots/horn_2link.toml").state_space_model(outputs=()),
                         parameter_values={"m": 1.0, "l": 1.0, "g": 9.81})
    assert arm_like.find_states("q") == [0, 1]
    with pytest.raises(ValueError, match="no state/output named 'joint.omega'"):
        linearize(m, outputs=["joint.omega"])


def test_open_loop_scene_feeds_python_control_interconnect():
    """The linearised rig closes a loop in python-control with its own signal names."""
    m = single_joint("default", control="P")
    plant = linearize(m, outputs=["joint.theta"], inputs=["amp.theta_ref"])
    k = control.ss([], [], [], [[0.5]], inputs=["e"], outputs=["amp_theta_ref"], name="k")
    cl = control.interconnect([plant, k], inputs=["e"], outputs=["joint_theta"])
    G = plant.dcgain()
    assert np.isclose(cl.dcgain(), 0.5 * G, rtol=1e-12)
    # at rest with no load, P_L = 0, so no flow is needed and no error remains: unit static gain
    assert np.isclose(G, 1.0, rtol=1e-9)


def test_scene_file_monolithic_fmu_agrees(tmp_path):
    """A scene file's monolithic model, trimmed against a load: FMU = symbolic = central differences."""
    from fmugen.scene import load_scene

    m = load_scene("examples/scenes/single_joint_split.toml").monolithic_model()
    op = trim(m, at={"joint.tau_load": 60.0})
    assert op["actuator.P_L"] == pytest.approx(60.0 / 1.5e-5, rel=1e-12)
    sym = linearize(m, op)
    A, B, C, D = central_differences(m, op.x, op.u)
    assert_close(sym.A, A, 1e-6, "A vs central differences")
    assert_close(sym.B, B, 1e-6, "B vs central differences")
    fmu = tmp_path / "scene.fmu"
    fmugen.build_fmu(m, fmu, fmi_type="me")
    num = linearize_fmu(fmu, op)
    order = [num.output_labels.index(n) for n in sym.output_labels]
    for a, b, what in zip((num.A, num.B, num.C[order], num.D[order]), (sym.A, sym.B, sym.C, sym.D), "ABCD"):
        assert_close(a, b, 1e-12, what)
