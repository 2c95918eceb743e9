"""Component and one-joint-rig FMUs: fmpy validation, ME and CS against scipy,
and the stiff set's explicit-versus-implicit solver behaviour.

FMUs are built once per module (each build compiles C, ~2 s).
"""
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu
from scipy.integrate import solve_ivp

from fmugen.components import (NumericModel, amplifier, controller, current_driver, dc_motor, hydraulic_actuator,
                               joint_inertia, linearise, load_assembly, ptp_trajectory, servo_valve, single_joint,
                               stable_step)
from fmugen.fmi.build import build_fmu

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.slow

# component, input start values, stop time
COMPONENTS = {
    "amplifier": (lambda: amplifier(kind="real", control="PI", rails=True), {"theta_ref": 0.05, "theta": 0.01}, 0.5),
    "current_driver": (lambda: current_driver(kind="lag"), {"u": 2.0}, 5e-3),
    "servo_valve": (lambda: servo_valve(order=2, stroke_limit=True), {"i": 4e-3, "P_L": 4e6}, 0.03),
    "hydraulic_actuator": (lambda: hydraulic_actuator(), {"Q_L": 2e-5, "w": 0.5}, 0.05),
    "two_chamber": (lambda: hydraulic_actuator(form="two_chamber", name="two_chamber"),
                    {"Q_A": 1e-5, "Q_B": 0.8e-5, "theta": 0.3, "w": 0.2}, 0.02),
    "joint": (lambda: joint_inertia(), {"tau": 30.0, "tau_load": 5.0}, 2.0),
    "motor": (lambda: dc_motor(elasticity=True), {"i_ref": 2.0}, 0.01),
    "controller": (lambda: controller(), {"q_ref": 0.3, "qd_ref": 0.1, "phi_m": -20.0, "w_m": -5.0}, 0.05),
    "trajectory": (lambda: ptp_trajectory(), {}, 1.5),
}


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    d = tmp_path_factory.mktemp("component_fmus")
    models = {key: make() for key, (make, _, _) in COMPONENTS.items()}
    # the compiler runs in subprocesses: two builds at a time on two cores
    with ThreadPoolExecutor(2) as pool:
        paths = dict(zip(models, pool.map(lambda k: build_fmu(models[k], d / f"{k}.fmu", fmi_type="both").path,
                                          models)))
    return {key: (models[key], paths[key], inputs, T) for key, (_, inputs, T) in COMPONENTS.items()}


def scipy_reference(model, inputs, T, ts):
    ev = NumericModel(model)
    u = np.array([inputs.get(v.name, v.start or 0.0) for v in model.inputs])
    if model.nx:
        sol = solve_ivp(lambda t, x: ev.f(t, x, u), (0, T), ev.x0, method="Radau", rtol=1e-11,
                        atol=1e-13 * np.maximum(1, np.abs(ev.x0)), t_eval=ts, jac=lambda t, x: ev.dfdx(t, x, u))
        X = sol.y
    else:
        X = np.zeros((0, len(ts)))
    Y = np.array([ev.g(t, x, u) for t, x in zip(ts, X.T)]).T if model.ny else np.zeros((0, len(ts)))
    return X, Y


@pytest.mark.parametrize("key", list(COMPONENTS))
def test_component_fmu_validates(fmus, key):
    assert validate_fmu(str(fmus[key][1])) == []


@pytest.mark.parametrize("fmi_type", ["ModelExchange", "CoSimulation"])
@pytest.mark.parametrize("key", list(COMPONENTS))
def test_component_fmu_matches_scipy(fmus, key, fmi_type):
    model, path, inputs, T = fmus[key]
    start = dict(inputs)
    kw = {"relative_tolerance": 1e-10} if fmi_type == "ModelExchange" else {}
    if fmi_type == "CoSimulation":
        start.update({"solver.method": 2, "solver.rtol": 1e-10, "solver.atol": 1e-10})
    names = [v.name for v in model.states] + [v.name for v in model.outputs]
    r = simulate_fmu(str(path), fmi_type=fmi_type, start_values=start, stop_time=T, output_interval=T / 50,
                     output=names, **kw)
    X, Y = scipy_reference(model, inputs, T, r["time"])
    for name, ref in zip(names, list(X) + list(Y)):
        scale = max(np.max(np.abs(ref)), 1e-300)
        assert np.max(np.abs(r[name] - ref)) <= 1e-5 * scale, name


@pytest.fixture(scope="module")
def stiff_rig(tmp_path_factory):
    model = load_assembly(ROOT / "examples" / "single_joint_stiff.toml")
    path = build_fmu(model, tmp_path_factory.mktemp("rig") / "single_joint_stiff.fmu", fmi_type="both").path
    return model, path


STEP = np.array([(0.0, 0.1, 0.0), (1.0, 0.1, 0.0)],
                dtype=[("time", float), ("amp.theta_ref", float), ("joint.tau_load", float)])


def rig_reference(model, ts):
    ev = NumericModel(model)
    u = np.array([0.1, 0.0])
    scale = np.array([v.nominal or 1.0 for v in model.states])
    sol = solve_ivp(lambda t, x: ev.f(t, x, u), (0, ts[-1]), ev.x0, method="Radau", rtol=1e-12,
                    atol=1e-14 * scale, t_eval=ts, jac=lambda t, x: ev.dfdx(t, x, u))
    return sol.y[[v.name for v in model.states].index("joint.theta")]


def test_rig_fmu_validates_and_me_matches(stiff_rig):
    model, path = stiff_rig
    assert validate_fmu(str(path)) == []
    r = simulate_fmu(str(path), fmi_type="ModelExchange", stop_time=0.3, output_interval=0.003, input=STEP,
                     relative_tolerance=1e-10, output=["joint.theta"])
    assert np.max(np.abs(r["joint.theta"] - rig_reference(model, r["time"]))) < 1e-6


def test_stiff_rk4_diverges_above_predicted_step_implicit_does_not(stiff_rig):
    model, path = stiff_rig
    h = stable_step(np.linalg.eigvals(linearise(model).A), "rk4")
    assert h == pytest.approx(56e-6, rel=0.03)  # actuator-chain.md
    T = 0.05
    common = dict(fmi_type="CoSimulation", stop_time=T, input=STEP, output=["joint.theta", "solver.n_rhs"])
    ok = simulate_fmu(str(path), start_values={"solver.method": 3, "solver.fixed_step": 0.9 * h},
                      output_interval=1e-3, **common)
    ref = rig_reference(model, ok["time"])
    assert np.max(np.abs(ok["joint.theta"] - ref)) < 1e-6  # stable, and accurate
    with pytest.raises(FMICallException):  # DoStep reports the blow-up (discard), the master stops
        r = simulate_fmu(str(path), start_values={"solver.method": 3, "solver.fixed_step": 1.1 * h},
                         output_interval=1e-3, **common)
        assert np.all(np.isfinite(r["joint.theta"])) and np.max(np.abs(r["joint.theta"])) < 1  # pragma: no cover
    # implicit solver: communication step 100x the explicit limit, stays within tolerance
    H = 100 * h
    T2 = 200 * H
    imp = simulate_fmu(str(path), fmi_type="CoSimulation", stop_time=T2, input=STEP, output_interval=H,
                       start_values={"solver.method": 2, "solver.rtol": 1e-8, "solver.atol": 1e-8},
                       output=["joint.theta", "solver.n_steps"])
    ref = rig_reference(model, imp["time"])
    assert np.max(np.abs(imp["joint.theta"] - ref)) < 1e-6
    assert abs(imp["joint.theta"][-1] - 0.1) < 0.01  # it got to the set point


def test_default_example_builds_me_and_cs(tmp_path):
    model = load_assembly(ROOT / "examples" / "single_joint_default.toml")
    for t in ("me", "cs"):
        path = build_fmu(model, tmp_path / f"sj_{t}.fmu", fmi_type=t).path
        assert validate_fmu(str(path)) == []


def test_custom_component_example_runs(tmp_path):
    """examples/custom_component.py: a user-written component, its FMU and the rig with it."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("custom_component", ROOT / "examples" / "custom_component.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    r = mod.main(tmp_path)
    # at rest under 50 N.m the load pressure is 50/D_m; the sensor reads K_p times it
    assert r["sensor.v_s"][-1] == pytest.approx(50 / 1.5e-5 * 1e-6, rel=2e-3)
