"""Scenes: models, initial state at rest, FMUs per group, pruning, locked joints, cache."""
import textwrap
import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy.validation import validate_fmu

import fmugen
from fmugen.codegen.evaluate import ModelEvaluator
from fmugen.components import amplifier, current_driver, hydraulic_actuator, joint_inertia, ptp_trajectory, servo_valve
from fmugen.scene import load_scene

SPLIT = Path("examples/scenes/single_joint_split.toml")
PUMA = Path("examples/scenes/puma_hydraulic.toml")


@pytest.fixture(scope="module")
def split_built(tmp_path_factory):
    out = tmp_path_factory.mktemp("split")
    return load_scene(SPLIT).build(out, use_cache=False)


def test_split_fmus_validate_and_keep_their_names(split_built):
    for r in split_built.fmus.values():
        assert validate_fmu(str(r.path)) == []
    md = {g: fmpy.read_model_description(str(r.path)) for g, r in split_built.fmus.items()}
    joint = {v.name: v.causality for v in md["joint"].modelVariables}
    chain = {v.name: v.causality for v in md["chain"].modelVariables}
    # one instance keeps its own names; several use instance.variable
    assert joint["theta"] == "output" and joint["tau"] == "input" and "tau_load" not in joint
    assert chain["amp.theta"] == "input" and chain["actuator.w"] == "input" and chain["actuator.tau"] == "output"
    de = md["joint"].defaultExperiment
    assert (de.startTime, de.stopTime, de.stepSize, de.tolerance) == ("0.0", "1.0", "0.001", "1e-10")


def test_split_system_couples_the_groups(split_built):
    s = split_built.system
    pairs = {(c.source, c.target) for c in s.couplings}
    assert pairs == {(("joint", "theta"), ("chain", "amp.theta")), (("joint", "w"), ("chain", "actuator.w")),
                     (("chain", "actuator.tau"), ("joint", "tau"))}
    assert s.order[0] == "joint"  # the mechanics first in Gauss-Seidel
    assert [r.column for r in s.recorded] == ["joint.theta", "joint.w", "actuator.tau", "actuator.P_L"]


def test_monolithic_model_equals_components_wired_by_hand():
    sc = load_scene(SPLIT)
    m = sc.monolithic_model()
    ev = ModelEvaluator(m)
    c = {"path": ptp_trajectory(overrides=dict(q_begin=0.0, q_end=0.1, qd_max=1.0, qdd_max=10.0, t_start=0.05)),
         "amp": amplifier(), "driver": current_driver(), "valve": servo_valve(), "actuator": hydraulic_actuator(),
         "joint": joint_inertia()}
    e = {k: ModelEvaluator(v) for k, v in c.items()}
    rng = np.random.default_rng(7)
    x = rng.normal(size=m.nx) * np.array([v.nominal or 1.0 for v in m.states])
    xs = dict(zip([v.name for v in m.states], x))
    t = 0.08
    q_ref = e["path"].g(t)[0]
    u = e["amp"].g(t, None, [q_ref, xs["joint.theta"]])[0]
    Q = e["valve"].g(t, [xs["valve.x_v"], xs["valve.v_v"]], [xs["driver.i"], xs["actuator.P_L"]])[0]
    tau = e["actuator"].g(t, [xs["actuator.P_L"]], [Q, xs["joint.w"]])[0]
    expected = np.r_[e["driver"].f(t, [xs["driver.i"]], [u]),
                     e["valve"].f(t, [xs["valve.x_v"], xs["valve.v_v"]], [xs["driver.i"], xs["actuator.P_L"]]),
                     e["actuator"].f(t, [xs["actuator.P_L"]], [Q, xs["joint.w"]]),
                     e["joint"].f(t, [xs["joint.theta"], xs["joint.w"]], [tau, 0.0])]
    assert np.allclose(ev.f(t, x, np.zeros(m.nu)), expected, rtol=1e-12, atol=0)


def test_second_build_comes_from_the_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("FMUGEN_CACHE", str(tmp_path / "cache"))
    a = load_scene(SPLIT).build(tmp_path / "a")
    b = load_scene(SPLIT).build(tmp_path / "b")
    assert not any(r.cached for r in a.fmus.values()) and all(r.cached for r in b.fmus.values())
    assert (tmp_path / "a" / "joint.fmu").read_bytes() == (tmp_path / "b" / "joint.fmu").read_bytes()
    c = load_scene(SPLIT, set={"joint.J": 5.0}).build(tmp_path / "c")  # a changed value rebuilds that FMU only
    assert not c.fmus["joint"].cached and c.fmus["chain"].cached


def test_puma_starts_at_rest_held_by_its_chains():
    sc = load_scene(PUMA)
    init = sc.initial
    m = init.model
    x = np.array([init.values[v.name] for v in m.states])
    f = ModelEvaluator(m).f(0.0, x, np.zeros(m.nu))
    nom = np.array([v.nominal or 1.0 for v in m.states])
    assert np.max(np.abs(f) / nom) < 1e-6
    # each actuator's torque D_m P_L equals the gravity torque of the arm at the pose (Manipulator's own evaluator)
    arm = fmugen.load_robot("robots/puma_thesis_com.toml")
    q = np.array([init.values[f"arm.q[{k}]"] for k in range(1, 7)])
    g = arm.bias(q, np.zeros(6))
    params = {v.name: v.start for v in m.parameters}
    tau = np.array([params[f"act{k}.D_m"] * init.values[f"act{k}.P_L"] for k in range(1, 7)])
    assert np.allclose(tau, g, rtol=1e-8, atol=1e-6 * np.max(np.abs(g)))
    assert abs(g[1]) > 100  # the shoulder really carries the arm


def test_puma_equilibrium_with_PI_amplifiers_holds_the_exact_pose(tmp_path):
    text = PUMA.read_text().replace('control = "P"', 'control = "PI"')
    p = tmp_path / "examples" / "scenes" / "pi.toml"
    p.parent.mkdir(parents=True)
    p.write_text(text.replace("../../robots/", str(Path("robots").resolve()) + "/"))
    init = load_scene(p).initial
    q = [init.values[f"arm.q[{k}]"] for k in range(1, 7)]
    assert np.allclose(q, [0.0, -0.4, 0.6, 0.0, 0.5, 0.0], atol=1e-9)  # integrators remove the P loop's offset


def test_locked_joints_are_the_free_rows_of_the_full_arm():
    arm = fmugen.load_robot("robots/puma_thesis_com.toml")
    locked = {4: 0.3, 5: -0.2, 6: 0.1}
    m = arm.state_space_model(outputs=(), locked=locked)
    assert [v.name for v in m.states] == ["q[1]", "q[2]", "q[3]", "qd[1]", "qd[2]", "qd[3]"]
    ev = ModelEvaluator(m)
    rng = np.random.default_rng(2)
    for _ in range(3):
        q3, qd3, tau3 = rng.normal(size=3), rng.normal(size=3), 50 * rng.normal(size=3)
        q, qd = np.r_[q3, 0.3, -0.2, 0.1], np.r_[qd3, 0, 0, 0]
        M, h = arm.mass_matrix(q), arm.bias(q, qd)
        qdd = np.linalg.solve(M[:3, :3], tau3 - h[:3])
        assert np.allclose(ev.f(0.0, np.r_[q3, qd3], tau3)[3:], qdd, rtol=1e-11, atol=1e-11)
    full = arm.state_space_model(outputs=())
    assert m.operation_count() < 0.6 * full.operation_count()


def test_pruning_leaves_out_what_the_scene_does_not_need(tmp_path):
    # explicit internal solver: no Jacobian, providesDirectionalDerivative false
    sc = load_scene(SPLIT, set={"fmus.joint.solver": "dopri5"})
    m, removed = sc.group_model("joint")
    assert m.jacobian is None and any("Jacobian" in r for r in removed)
    built = sc.build(tmp_path, use_cache=False)
    md = fmpy.read_model_description(str(built.fmus["joint"].path))
    assert md.coSimulation.providesDirectionalDerivative is False
    # a fixed parameter is folded to the scene's value, not the file's
    sc2 = load_scene(SPLIT, set={"joint.J": 5.0})
    sc2.spec.instances["joint"] = type(sc2.spec.instances["joint"])(
        **{**sc2.spec.instances["joint"].__dict__, "fixed": ("J",)})
    mj, _ = sc2.group_model("joint")
    assert "J" not in [v.name for v in mj.parameters]
    ev = ModelEvaluator(mj)
    assert np.isclose(ev.f(0.0, [0.0, 0.0], [10.0])[1], 10.0 / 5.0)
    # the arm: unread outputs and undriven external inputs gone; unpruned keeps them
    arm_p, rem = load_scene(PUMA).group_model("arm")
    arm_u, _ = load_scene(PUMA).group_model("arm", prune=False)
    assert arm_p.ny == 0 and arm_u.ny == 3 + 6
    assert arm_p.operation_count() < arm_u.operation_count()


def test_scene_with_a_locked_wrist_builds_an_arm_of_three_joints():
    sc = load_scene("examples/scenes/puma_wrist_locked.toml")
    m, removed = sc.group_model("arm")
    assert [v.name for v in m.states] == ["q[1]", "q[2]", "q[3]", "qd[1]", "qd[2]", "qd[3]"]
    assert any("locked" in r for r in removed)
    full, _ = load_scene(PUMA).group_model("arm")
    assert m.operation_count() < 0.5 * full.operation_count()
    # at rest the chains hold the arm's gravity torque of the full arm with the wrist at its locked pose
    init = sc.initial
    arm = fmugen.load_robot("robots/puma_thesis_com.toml")
    q = np.r_[[init.values[f"arm.q[{k}]"] for k in (1, 2, 3)], 0.0, 0.5, 0.0]
    g = arm.bias(q, np.zeros(6))[:3]
    params = {v.name: v.start for v in init.model.parameters}
    tau = [params[f"act{k}.D_m"] * init.values[f"act{k}.P_L"] for k in (1, 2, 3)]
    assert np.allclose(tau, g, rtol=1e-8, atol=1e-6 * np.max(np.abs(g)))


def test_the_joint_fmu_carries_the_stroke_its_two_chamber_actuator_allows(tmp_path):
    text = SPLIT.read_text()
    for a, b in [('valve = { type = "servo_valve", order = 2 }', 'valve = { type = "servo_valve", order = 2, flow = "chambers" }'),
                 ('form = "load_pressure"', 'form = "two_chamber"'),
                 ('parameter_set = "default"', 'parameter_set = "stiff"'),
                 ('["actuator.P_L", "valve.P_L"],', '["actuator.P_A", "valve.P_A"], ["actuator.P_B", "valve.P_B"], ["joint.theta", "actuator.theta"],'),
                 ('["valve.Q_L", "actuator.Q_L"],', '["valve.Q_A", "actuator.Q_A"], ["valve.Q_B", "actuator.Q_B"],'),
                 ('"actuator.tau", "actuator.P_L"]', '"actuator.tau", "actuator.P_L"]')]:
        assert a in text
        text = text.replace(a, b)
    p = tmp_path / "two_chamber.toml"
    p.write_text(text)
    m, _ = load_scene(p).group_model("joint")
    theta = next(v for v in m.states if v.name == "theta")
    # V_A,B = V_t/2 -+ D_m theta > 0:  |theta| < V_t / (2 D_m) = 1e-5 / 3e-5 rad (stiff set)
    assert np.isclose(theta.max, 1e-5 / (2 * 1.5e-5)) and np.isclose(theta.min, -1e-5 / (2 * 1.5e-5))


def test_a_long_arm_alone_in_its_fmu_uses_the_looped_dynamics_and_the_reference_straight_code(tmp_path):
    from fmugen.robot.chain import chain_to_toml, n_link_chain

    (tmp_path / "chain8.toml").write_text(chain_to_toml(n_link_chain(8, seed=3)))
    (tmp_path / "s.toml").write_text(textwrap.dedent('''
        [scene]
        name = "long_arm"
        stop = 0.1
        record = ["arm.q[8]"]
        connections = [["k.theta", "arm.tau[8]", 1.0]]
        [instances.arm]
        robot = "chain8.toml"
        start = { "q[2]" = 0.3 }
        [instances.k]
        type = "joint_inertia"
        [fmus.arm]
        members = ["arm"]
        [fmus.k]
        members = ["k"]
        '''))
    sc = load_scene(tmp_path / "s.toml")
    m, _ = sc.group_model("arm")
    assert any(type(st).__name__ == "ChainDynamics" for st in m.program.steps)
    mono = sc.monolithic_model()
    assert not any(type(st).__name__ == "ChainDynamics" for st in mono.program.steps)
    x = np.array([v.start or 0.0 for v in mono.states])
    arm_x = x[[k for k, v in enumerate(mono.states) if v.name.startswith("arm.")]]
    f_loop = ModelEvaluator(m).f(0.0, arm_x, np.zeros(m.nu))
    f_mono = ModelEvaluator(mono).f(0.0, x, np.zeros(mono.nu))[:len(arm_x)]
    assert np.allclose(f_loop, f_mono, rtol=1e-10, atol=1e-10)
