"""Hybrid components in scenes: the events go through assembly, the hybrid reference and the master.

A torque ramp tau = r t (its own FMU) drives lib:stick_slip (J = 0.05, T_c = 2, T_s = 3, b = 0.02): the
shaft is stuck until tau reaches T_s at t_b = T_s / r = 3 s, then J w' = r t - T_c - b w from w(t_b) = 0,

    w(t) = (r t - T_c)/b - r J/b^2 + C exp(-b (t - t_b)/J),   C = r J/b^2 - (r t_b - T_c)/b,

and phi its integral.  The reference (Radau with located events and restarts, fmugen/cosim/hybrid_reference)
meets the closed form; the co-simulation's master sees the event (solver.n_events), restarts its input
history there, and converges to the reference.
"""
from pathlib import Path

import numpy as np
import pytest

import fmugen
from fmugen.cosim import run, solve_reference

J, T_C, T_S, B, RATE = 0.05, 2.0, 3.0, 0.02, 1.0
T_B = T_S / RATE

RAMP = """
[component]
name = "ramp"
description = "a torque ramp"
equations = ["der(tau) = rate"]
[parameters]
rate = { value = 1.0, unit = "N.m/s", description = "slope" }
[states]
tau = { unit = "N.m", start = 0.0, output = true, description = "torque" }
"""

SCENE = """
[scene]
name = "ramp_stick"
stop = 5.0
step = 1e-2
record = ["shaft.phi", "shaft.w", "shaft.tau_f", "src.tau"]
connections = [["src.tau", "shaft.tau"]]
[instances]
src = { type = "file:ramp.toml" }
shaft = { type = "lib:stick_slip" }
[fmus.src]
members = ["src"]
[fmus.shaft]
members = ["shaft"]
"""


def closed_form(t):
    t = np.asarray(t, dtype=float)
    a = B / J
    C = RATE * J / B ** 2 - (RATE * T_B - T_C) / B
    s = np.maximum(t - T_B, 0.0)
    w = np.where(t > T_B, (RATE * t - T_C) / B - RATE * J / B ** 2 + C * np.exp(-a * s), 0.0)
    # phi = int_{t_b}^t w
    F = lambda tt: RATE * tt ** 2 / (2 * B) - T_C * tt / B - RATE * J * tt / B ** 2  # noqa: E731
    phi = np.where(t > T_B, F(t) - F(T_B) + C * (1 - np.exp(-a * s)) / a, 0.0)
    return phi, w


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    d = tmp_path_factory.mktemp("ramp_stick")
    (d / "ramp.toml").write_text(RAMP)
    (d / "scene.toml").write_text(SCENE)
    return d


def test_the_hybrid_reference_meets_the_closed_form(scene):
    sc = fmugen.load_scene(scene / "scene.toml")
    t = np.linspace(0.0, 5.0, 501)
    ref = solve_reference(sc.reference_problem(), times=t, cache=False)
    assert ref.settings["events"] == 1 and abs(ref.settings["event_times"][0] - T_B) < 1e-9
    phi, w = closed_form(t)
    assert np.abs(ref["shaft.w"] - w).max() < 1e-7 * np.abs(w).max()
    assert np.abs(ref["shaft.phi"] - phi).max() < 1e-7 * np.abs(phi).max()
    assert np.all(ref["shaft.phi"][t < T_B] == 0.0)  # stuck: not one ulp of creep
    # stuck, the friction is the constraint torque (= the drive); sliding, T_c + b w
    assert np.allclose(ref["shaft.tau_f"][t < T_B], RATE * t[t < T_B], rtol=0, atol=1e-12)
    assert ref.error_of("shaft.phi") < 1e-8


@pytest.mark.parametrize("scheme,ext", [("gauss-seidel", "linear"), ("newton", "linear")])
def test_cosimulation_across_the_breakaway_converges_to_the_reference(scene, scheme, ext, tmp_path):
    sc = fmugen.load_scene(scene / "scene.toml")
    built = sc.build(tmp_path / "fmus")
    t = np.linspace(0.0, 5.0, 501)
    ref = solve_reference(sc.reference_problem(), times=t, cache=False)
    errs = []
    for H in (0.04, 0.01):
        r = run(built.system, scheme, ext, step=H)
        assert r.ok and r.summary.events == 1 and r.summary.discontinuities == 1, r.summary
        idx = np.rint(r.time / 0.01).astype(int)
        errs.append(np.abs(r["shaft.phi"] - ref["shaft.phi"][idx]).max())
    assert errs[1] < 1e-5 and errs[1] <= errs[0] * 1.01, errs


def test_the_monolithic_fmu_locates_the_breakaway_at_any_step(scene, tmp_path):
    """One FMU for the whole scene: the ramp is inside it, so the breakaway is located inside the step
    (0.5 s communication steps give the trajectory of 0.01 s steps)."""
    from fmpy import simulate_fmu

    sc = fmugen.load_scene(scene / "scene.toml", set={"scene.monolithic": True})
    built = sc.build(tmp_path / "mono")
    path = str(built.system.units[0].path)
    out = []
    for H in (0.5, 0.01):
        r = simulate_fmu(path, fmi_type="CoSimulation", stop_time=5.0, output_interval=H,
                         start_values={"solver.rtol": 1e-10}, output=["shaft.phi", "shaft.w"])
        out.append(r[-1]["shaft.phi"])
    phi_end = closed_form([5.0])[0][0]
    assert abs(out[0] - phi_end) < 1e-6 * phi_end and abs(out[1] - phi_end) < 1e-6 * phi_end, (out, phi_end)


def test_the_stick_slip_drive_holds_the_puma_shoulder_where_the_smoothed_twin_creeps(tmp_path):
    """examples/scenes/puma_geared_drive_hybrid.toml, power off to 0.3 s: the arm hangs in the gear's
    contact, the stuck motor holds it -- q[2] constant to round-off -- while the smoothed drive of the
    same numbers (puma_geared_drive_smooth.toml) creeps under the gravity load; co-simulated with
    Newton/cubic at 10 ms, the hybrid scene meets its hybrid reference to 1e-4 rad."""
    scenes = Path(__file__).resolve().parents[1] / "examples" / "scenes"
    creep = {}
    for k in ("hybrid", "smooth"):
        sc = fmugen.load_scene(scenes / f"puma_geared_drive_{k}.toml", set={"scene.stop": 0.6})
        r = run(sc.build(tmp_path / k).system, "newton", "cubic", step=0.01)
        assert r.ok, r.summary
        hold = r.time <= 0.3 + 1e-9
        creep[k] = float(np.abs(r["arm.q[2]"][hold] - r["arm.q[2]"][0]).max())
        if k == "hybrid":
            assert r["arm.q[2]"][-1] > -0.39  # the path moved it after the hold
            ref = solve_reference(sc.reference_problem(), times=r.time, cache=False)
            assert ref.settings["events"] >= 1
            assert np.abs(r["arm.q[2]"] - ref["arm.q[2]"]).max() < 1e-4
    assert creep["hybrid"] < 1e-12 and creep["smooth"] > 1e-5, creep


PENDULUM = """<?xml version="1.0"?>
<robot name="pend">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0.5 0 0"/><mass value="1.0"/>
    <inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 1 0"/>
    <limit lower="-1.0" upper="1.0" effort="100" velocity="10"/><dynamics friction="6.0"/></joint>
</robot>
"""


@pytest.mark.parametrize("friction", ["stick-slip", "smooth"])
def test_a_scene_robot_takes_friction_and_limits_as_events(tmp_path, friction):
    """A URDF pendulum whose breakaway (6 N.m) exceeds its gravity torque: with friction = "stick-slip" the
    scene holds it where it starts, to the bit; the smooth tanh friction lets it creep."""
    (tmp_path / "arm.urdf").write_text(PENDULUM)
    (tmp_path / "scene.toml").write_text(f"""
[scene]
name = "held"
stop = 2.0
step = 1e-3
record = ["arm.q[1]"]
[instances.arm]
robot = "arm.urdf"
friction = "{friction}"
limits = "stops"
start = {{ "q[1]" = 0.3 }}
[fmus.arm]
members = ["arm"]
""")
    sc = fmugen.load_scene(tmp_path / "scene.toml")
    r = run(sc.build(tmp_path / "fmus").system, "jacobi", "hold")
    drift = float(np.abs(r["arm.q[1]"] - 0.3).max())
    assert (drift == 0.0) if friction == "stick-slip" else (drift > 1e-3), drift


def test_a_scene_robot_refuses_an_unknown_friction(tmp_path):
    from fmugen.scene.errors import SceneError

    (tmp_path / "arm.urdf").write_text(PENDULUM)
    (tmp_path / "scene.toml").write_text('[scene]\nname = "x"\nstop = 1.0\n[instances.arm]\nrobot = "arm.urdf"\n'
                                         'friction = "sticky"\n[fmus.arm]\nmembers = ["arm"]\n')
    with pytest.raises(SceneError, match="friction must be 'smooth' or 'stick-slip', got 'sticky'"):
        fmugen.load_scene(tmp_path / "scene.toml")


def test_an_adaptive_run_lands_a_communication_point_on_the_event(scene, tmp_path):
    """An FMU reports an event inside an adaptive macro step (solver.n_events, solver.last_event_time): the
    master rolls back and takes a step that ends just past it, so the breakaway (t_b = 3 s) falls on a
    communication point, where a fixed 70 ms grid has none within 5 ms."""
    sc = fmugen.load_scene(scene / "scene.toml")
    built = sc.build(tmp_path / "fmus")
    fixed = run(built.system, "gauss-seidel", "linear", step=0.07)
    adaptive = run(built.system, "gauss-seidel", "linear", step=0.07, adaptive=True, tol=1e-4)
    assert np.min(np.abs(fixed.time - T_B)) > 5e-3
    assert adaptive.ok and adaptive.summary.rollbacks >= 1 and np.min(np.abs(adaptive.time - T_B)) < 1e-8
