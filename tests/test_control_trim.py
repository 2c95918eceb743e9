"""fmugen.trim: operating points against closed forms, and clear refusals.

* the PUMA held at a pose: tau = h(q, 0), the gravity torque of the arm's
  own inverse dynamics (``arm.bias``), computed without the trim machinery;
* the one-joint hydraulic rig holding a load tau_L (actuator-chain equations):
  P_L = tau_L/D_m, leakage flow C_tm P_L metered by the spool,
  x_v = (C_tm + K_c0) P_L / (K_q0 sqrt(1 - P_L/P_s)), K_q0 = Q_N sqrt(P_s/dp_N),
  i = i_rated x_v, u = i/G_i, and then the amplifier: P control leaves the
  offset theta = theta_ref - u/K_a, PI holds theta = theta_ref with the
  integrator at z = T_I u/K_a;
* no equilibrium beyond the stall torque P_s D_m, none with the arm moving,
  and an under-determined request: refused with TrimError.
"""
import warnings

import numpy as np
import pytest

import fmugen
from fmugen.components import load_parameter_set, single_joint
from fmugen.control import TrimError, trim

Q0 = np.array([0.3, -0.5, 0.8, 0.2, -0.4, 0.6])


@pytest.fixture(scope="module")
def puma():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fmugen.load_robot("robots/puma_thesis_com.toml")


def test_puma_held_at_a_pose_needs_the_gravity_torque(puma):
    model = puma.state_space_model(outputs=())
    op = trim(model, at={"q": Q0, "qd": 0.0}, free=["tau"])
    g = puma.bias(Q0, np.zeros(6))
    assert np.abs(g).max() > 10.0  # a pose where gravity matters
    assert np.allclose(op["tau"], g, rtol=1e-12, atol=1e-9 * np.abs(g).max())
    assert op["tau"].shape == (6,) and op["tau[2]"] == op["tau"][1]
    assert op.max_residual < 1e-12
    assert op.free == [f"tau[{i}]" for i in range(1, 7)] and op.rank == 6
    # the other formulation gives the same torques (parameters by keyword reach the trim)
    op2 = trim(puma.state_space_model(outputs=(), formulation="lagrange"), at={"q": Q0, "qd": 0.0},
               free=["tau"], parameter_values={"m_3": 3.0})
    assert np.allclose(op2["tau"], puma.bias(Q0, np.zeros(6), m_3=3.0), rtol=1e-10, atol=1e-9)


def test_puma_pose_from_an_output_and_given_torques(puma):
    """Outputs can be given too: hold the end effector where the pose puts it, torques given."""
    model = puma.state_space_model(outputs=("p_ee",))
    p = puma.fk(Q0)[:3, 3]
    tau = puma.bias(Q0, np.zeros(6))
    # q[1], q[4], q[6] given; q[2], q[3], q[5] (and qd) solved from p_ee and rest
    op = trim(model, at={"p_ee": p, "tau": tau, "q[1]": Q0[0], "q[4]": Q0[3], "q[6]": Q0[5]},
              guess={"q": Q0 + 0.05})
    assert np.allclose(op["q"], Q0, atol=1e-9) and np.allclose(op["qd"], 0.0, atol=1e-12)


def chain_closed_form(set_name, load, theta_ref, control):
    P = load_parameter_set(set_name).sections
    D_m, C_tm = P["hydraulic_actuator"]["D_m"], P["hydraulic_actuator"]["C_tm"]
    v = P["servo_valve"]
    K_q0 = v["Q_N"] * np.sqrt(v["P_s"] / v["dp_N"])
    P_L = load / D_m
    x_v = (C_tm + v["K_c0"]) * P_L / (K_q0 * np.sqrt(1 - P_L / v["P_s"]))
    i = v["i_rated"] * x_v
    u = i / P["current_driver"]["G_i"]
    K_a = P["amplifier"]["K_a"]
    if control == "P":
        return dict(P_L=P_L, x_v=x_v, i=i, theta=theta_ref - u / K_a)
    return dict(P_L=P_L, x_v=x_v, i=i, theta=theta_ref, z=P["amplifier"]["T_I"] * u / K_a)


@pytest.mark.parametrize("control", ["P", "PI"])
def test_hydraulic_joint_holding_a_load_equals_the_closed_form(control):
    set_name, load, ref = "default", 120.0, 0.3  # stall torque of the default set: 210 N.m
    op = trim(single_joint(set_name, control=control), at={"amp.theta_ref": ref, "joint.tau_load": load})
    cf = chain_closed_form(set_name, load, ref, control)
    assert np.isclose(op["actuator.P_L"], cf["P_L"], rtol=1e-12)
    assert np.isclose(op["valve.x_v"], cf["x_v"], rtol=1e-10)
    assert np.isclose(op["driver.i"], cf["i"], rtol=1e-10)
    assert np.isclose(op["joint.theta"], cf["theta"], rtol=1e-10)
    assert abs(op["joint.w"]) < 1e-12 and abs(op["valve.v_v"]) < 1e-9
    if control == "PI":
        assert np.isclose(op["amp.z"], cf["z"], rtol=1e-10)
    assert op["actuator.tau"] == pytest.approx(load, rel=1e-12)
    assert "find_operating_point" in op.method  # a square problem goes to python-control


def test_hydraulic_joint_load_from_a_given_output():
    """Give the actuator torque, free the load input: the load that torque holds."""
    op = trim(single_joint("default"), at={"amp.theta_ref": 0.0, "actuator.tau": 80.0},
              free=["joint.tau_load"])
    assert op["joint.tau_load"] == pytest.approx(80.0, rel=1e-12)
    assert op["actuator.P_L"] == pytest.approx(80.0 / load_parameter_set("default").sections["hydraulic_actuator"]["D_m"],
                                               rel=1e-12)


def test_load_beyond_the_stall_torque_is_refused():
    P = load_parameter_set("default").sections
    stall = P["servo_valve"]["P_s"] * P["hydraulic_actuator"]["D_m"]
    trim(single_joint("default"), at={"amp.theta_ref": 0.0, "joint.tau_load": 0.95 * stall})  # holds
    with pytest.raises(TrimError, match="no operating point found") as err:
        trim(single_joint("default"), at={"amp.theta_ref": 0.0, "joint.tau_load": 1.1 * stall})
    assert err.value.operating_point.max_residual > 1e-3
    assert "der(" in str(err.value)


def test_refusals_name_the_problem(puma):
    model = puma.state_space_model(outputs=())
    with pytest.raises(TrimError, match="no operating point found"):  # moving arm is no equilibrium
        trim(model, at={"q": Q0, "qd": 0.1}, free=["tau"])
    with pytest.raises(TrimError, match="under-determined: 18 free"):
        trim(model, free=["tau"])
    with pytest.raises(ValueError, match="'q' has 6 element"):
        trim(model, at={"q": [0.1, 0.2]}, free=["tau"])
    with pytest.raises(ValueError, match="no state/input/output named 'qq'"):
        trim(model, at={"qq": 0.0})
    with pytest.raises(TrimError, match="outputs cannot be free"):
        trim(single_joint("default"), free=["actuator.tau"])


def test_a_scene_object_is_a_source():
    """Anything with monolithic_model() is accepted (how scenes come in)."""
    class Scene:
        def monolithic_model(self):
            return single_joint("default")

    op = trim(Scene(), at={"amp.theta_ref": 0.2, "joint.tau_load": 50.0})
    assert op["actuator.P_L"] == pytest.approx(50.0 / 1.5e-5, rel=1e-12)
    assert op["actuator_P_L"] == op["actuator.P_L"]  # python-control spelling reads the same value
    sys = fmugen.linearize(Scene(), op)
    assert sys.nstates == 6
