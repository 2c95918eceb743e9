"""The arm assembled with an actuator chain: one model, program-level composition.

Joint 2 of the thesis PUMA is driven by the hydraulic chain of the shared
note (amplifier -> driver -> servo valve -> actuator, PUMA joint-2 parameter
set); the other joints keep their torque inputs.  This is the monolithic form
that co-simulation results are measured against.
"""
import fmpy
import numpy as np
import pytest
from fmpy.validation import validate_fmu

import fmugen
from fmugen.codegen.evaluate import ModelEvaluator
from fmugen.components import amplifier, assemble, current_driver, hydraulic_actuator, servo_valve
from fmugen.fmi.build import build_fmu

SET = "puma_joint2"


@pytest.fixture(scope="module")
def parts():
    arm = fmugen.load_robot("robots/puma_thesis_com.toml").state_space_model(outputs=())
    comps = {"arm": arm, "amp": amplifier(parameter_set=SET), "driver": current_driver(parameter_set=SET),
             "valve": servo_valve(parameter_set=SET), "actuator": hydraulic_actuator(parameter_set=SET)}
    connections = [("arm.q[2]", "amp.theta"), ("amp.u", "driver.u"), ("driver.i", "valve.i"),
                   ("actuator.P_L", "valve.P_L"), ("valve.Q_L", "actuator.Q_L"), ("arm.qd[2]", "actuator.w"),
                   ("actuator.tau", "arm.tau[2]")]
    return comps, assemble("puma_joint2_hydraulic", comps, connections)


def test_assembly_has_the_expected_interface(parts):
    _, m = parts
    assert [v.name for v in m.inputs] == ["arm.tau[1]", "arm.tau[3]", "arm.tau[4]", "arm.tau[5]", "arm.tau[6]",
                                          "amp.theta_ref"]
    assert m.nx == 12 + 2 + 1 + 1  # arm (q, qd), valve spool (x_v, v_v), driver lag (i), load pressure


def test_assembled_derivatives_equal_the_components_wired_by_hand(parts):
    comps, m = parts
    ev = {k: ModelEvaluator(c) for k, c in comps.items()}
    asm = ModelEvaluator(m)
    rng = np.random.default_rng(3)
    names = [v.name for v in m.states]
    x = rng.normal(size=m.nx) * np.array([v.nominal or 1.0 for v in m.states])
    u = rng.normal(size=m.nu)
    xs = {n: x[k] for k, n in enumerate(names)}
    us = {v.name: u[k] for k, v in enumerate(m.inputs)}

    def part(inst):
        return np.array([xs[f"{inst}.{v.name}"] for v in comps[inst].states])

    q2, qd2 = xs["arm.q[2]"], xs["arm.qd[2]"]
    amp_u = ev["amp"].g(0.0, part("amp") if comps["amp"].nx else None, [us["amp.theta_ref"], q2])
    drv_i = xs["driver.i"]  # the lag driver's current is a state
    P_L = xs["actuator.P_L"]
    Q_L = ev["valve"].g(0.0, part("valve"), [drv_i, P_L])
    tau2 = ev["actuator"].g(0.0, part("actuator"), [Q_L[0], qd2])
    tau = [us["arm.tau[1]"], tau2[0], us["arm.tau[3]"], us["arm.tau[4]"], us["arm.tau[5]"], us["arm.tau[6]"]]
    expected = np.r_[ev["arm"].f(0.0, part("arm"), tau),
                     ev["amp"].f(0.0, part("amp"), [us["amp.theta_ref"], q2]) if comps["amp"].nx else [],
                     ev["driver"].f(0.0, part("driver"), amp_u),
                     ev["valve"].f(0.0, part("valve"), [drv_i, P_L]),
                     ev["actuator"].f(0.0, part("actuator"), [Q_L[0], qd2])]
    assert np.allclose(asm.f(0.0, x, u), expected, rtol=1e-12, atol=0)


def test_assembled_jacobian_matches_finite_differences(parts):
    _, m = parts
    asm = ModelEvaluator(m)
    rng = np.random.default_rng(5)
    nominal = np.array([v.nominal or 1.0 for v in m.states])
    x = rng.normal(size=m.nx) * nominal
    u = rng.normal(size=m.nu)
    A, B, _, _ = asm.jacobians(0.0, x, u)
    f0 = asm.f(0.0, x, u)
    for k in range(m.nx):
        h = 1e-6 * nominal[k]
        e = np.zeros(m.nx)
        e[k] = h
        fd = (asm.f(0.0, x + e, u) - asm.f(0.0, x - e, u)) / (2 * h)
        assert np.allclose(A[:, k], fd, rtol=1e-5, atol=1e-7 * (np.abs(f0) + 1)), m.states[k].name
    for k in range(m.nu):
        e = np.zeros(m.nu)
        e[k] = 1e-6
        fd = (asm.f(0.0, x, u + e) - asm.f(0.0, x, u - e)) / 2e-6
        assert np.allclose(B[:, k], fd, rtol=1e-5, atol=1e-7 * (np.abs(f0) + 1)), m.inputs[k].name


def test_assembled_fmu_validates_and_the_implicit_solver_tracks_a_step(parts, tmp_path):
    _, m = parts
    path = build_fmu(m, tmp_path / "pj2.fmu", fmi_type="cs").path
    assert validate_fmu(str(path)) == []
    # hold the other joints with their gravity torques at the start pose; step joint 2's reference
    arm = fmugen.load_robot("robots/puma_thesis_com.toml")
    q0 = np.zeros(6)
    g = arm.bias(q0, np.zeros(6))
    start = {f"arm.tau[{i}]": g[i - 1] for i in (1, 3, 4, 5, 6)}
    start.update({"amp.theta_ref": 0.1, "solver.method": 2, "solver.rtol": 1e-6, "solver.atol": 1e-6})
    r = fmpy.simulate_fmu(str(path), fmi_type="CoSimulation", stop_time=1.0, output_interval=0.01,
                          start_values=start, output=["arm.q[2]"])
    assert np.all(np.isfinite(r["arm.q[2]"]))
    # the hydraulic position loop pulls joint 2 towards the reference against gravity
    assert abs(r["arm.q[2]"][-1] - 0.1) < 0.05
