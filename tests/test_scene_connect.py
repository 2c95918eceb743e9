"""Connectors and ``connect``: bonds expanded into signal connections with causality checked, and the
PUMA hydraulic scene written with ``connect`` and ``[repeat]`` equal to the one written out signal by signal."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import fmugen
from fmugen.components import NumericModel
from fmugen.scene.build import _group_key
from fmugen.scene.errors import SceneError

ROOT = Path(__file__).resolve().parent.parent
NEW = ROOT / "examples/scenes/puma_hydraulic.toml"
OLD = ROOT / "tests/data/puma_hydraulic_signals.toml"


@pytest.mark.parametrize("name", ["puma_hydraulic", "puma_electric", "puma_wrist_locked"])
def test_shipped_scenes_with_connect_are_the_scenes_written_out(name):
    new_path, old_path = ROOT / f"examples/scenes/{name}.toml", ROOT / f"tests/data/{name}_signals.toml"
    old, new = fmugen.load_scene(old_path), fmugen.load_scene(new_path)
    assert len(new_path.read_text().splitlines()) < 0.6 * len(old_path.read_text().splitlines())
    assert new.connections == old.connections  # the same signals, in the same order
    assert new.spec.instances == old.spec.instances and new.spec.groups == old.spec.groups
    assert new.spec.record == old.spec.record and new.spec.cosim == old.spec.cosim
    assert new.spec.monolithic == old.spec.monolithic and new.groups == old.groups
    # the build cache key hashes everything that shapes an FMU: equal keys, identical FMUs
    x0 = {"arm.q[2]": -0.4}
    for g in old.groups:
        assert _group_key(new, g, True, x0, {}) == _group_key(old, g, True, x0, {})


def test_puma_hydraulic_with_connect_is_the_scene_written_out():
    old, new = fmugen.load_scene(OLD), fmugen.load_scene(NEW)
    assert len(NEW.read_text().splitlines()) < len(OLD.read_text().splitlines()) / 2
    a, b = old.group_model("joint2")[0], new.group_model("joint2")[0]
    assert a.derivatives == b.derivatives and a.states == b.states and a.inputs == b.inputs
    new = fmugen.load_scene(NEW)
    # twelve bonds: six hydraulic (P_L | Q_L), six rotational (w | tau), with their power variables
    bonds = {str(b_): b_ for b_ in new.spec.bonds}
    assert len(bonds) == 12
    f2 = bonds["act2.flange <-> arm.joint[2] (rotational)"]
    assert f2.signals == (("w", "arm.qd[2]", "act2.w"), ("tau", "act2.tau", "arm.tau[2]"))
    assert f2.power == ("act2.tau", "arm.qd[2]")
    assert bonds["valve5.port <-> act5.port (hydraulic)"].power == ("act5.P_L", "valve5.Q_L")


RIG = """
[scene]
name = "rig"
stop = 0.5
connect = [{pairs}]
[instances]
gear = {{ type = "lib:gear_backlash" }}
load = {{ type = "lib:stribeck" }}
act = {{ type = "lib:hydraulic_actuator" }}
valve = {{ type = "servo_valve" }}
valve_b = {{ type = "servo_valve" }}
inert = {{ type = "joint_inertia" }}
"""


def rig(tmp_path, pairs):
    p = tmp_path / "rig.toml"
    p.write_text(RIG.format(pairs=pairs))
    return fmugen.load_scene(p)


def test_connect_two_component_files_equals_the_hand_wiring(tmp_path):
    sc = rig(tmp_path, '["load.flange", "gear.load"], ["act.port", "valve.port"], ["act.flange", "inert.flange"]')
    assert ("load", "phi", "gear", "phi_L", None) in sc.connections
    assert ("load", "w", "gear", "w_L", None) in sc.connections
    assert ("gear", "tau", "load", "tau", None) in sc.connections
    m = sc.monolithic_model()
    ev = NumericModel(m)
    names = [v.name for v in m.states]
    rng = np.random.default_rng(4)
    x = rng.normal(0, 1, len(names))
    x[names.index("gear.phi_m")] = 50 * x[names.index("load.phi")] + 0.15  # in contact
    d = dict(zip(names, ev.f(0.0, x, np.zeros(m.nu))))
    g = NumericModel(fmugen.components.equations.load_component("lib:gear_backlash"))
    s = NumericModel(fmugen.components.equations.load_component("lib:stribeck"))
    xs = {n: x[names.index(n)] for n in names}
    tau = g.g(0, [xs["gear.phi_m"], xs["gear.w_m"]], [0.0, xs["load.phi"], xs["load.w"]])[0]
    assert d["load.w"] == pytest.approx(s.f(0, [xs["load.phi"], xs["load.w"]], [tau])[1], rel=1e-12)


@pytest.mark.parametrize("pairs, message", [
    ('["inert.flange", "load.flange"]', r"connect\[0\] \(inert.flange <-> load.flange\): both ends compute phi"),
    ('["valve.port", "valve_b.port"]', r"neither end computes p \(valve.P_L and valve_b.P_L are both inputs\)"),
    ('["valve.port", "load.flange"]', r"valve.port is a hydraulic connector but load.flange is a rotational"),
    ('["gear.load", "act.flange"]', r"gear.load needs phi \(gear.phi_L is an input\) but act.flange has no phi"),
    ('["gear.shaft", "load.flange"]', r"gear.shaft is not a connector of gear \(connectors: load\)"),
    ('["valve.Q_L", "valve_b.Q_L"]', r"both valve.Q_L and valve_b.Q_L compute the signal"),
    # named at the connect entry the file has, not at a generated connections[k] the file does not have
    ('["act.port", "valve.port"], ["valve.P_L", "act.P_L"]',
     r"connect\[1\] \(valve.P_L <-> act.P_L\): input valve.P_L is already driven by \[scene\] connect\[0\] "
     r"\(act.port <-> valve.port\)"),
    ('["act.port", "valve.port"], ["act.port", "valve.port"]', r"connect\[1\] .*already driven by \[scene\] connect\[0\]"),
])
def test_connect_refusals_name_both_ends(tmp_path, pairs, message):
    with pytest.raises(SceneError, match=message):
        rig(tmp_path, pairs)


def test_signal_pairs_are_directed_by_causality(tmp_path):
    sc = rig(tmp_path, '["act.Q_L", "valve.Q_L"], ["valve.P_L", "act.P_L"]')
    assert ("valve", "Q_L", "act", "Q_L", None) in sc.connections
    assert ("act", "P_L", "valve", "P_L", None) in sc.connections


def test_repeat_errors(tmp_path):
    text = NEW.read_text()
    for old, new, msg in [("q0 = [0.0, -0.4,", "q0 = [-0.4,", "one equal length"),
                          ('"amp{k}.u"', '"amp{kk}.u"', r"\{kk\} in 'amp\{kk\}.u' is not one of the values")]:
        p = tmp_path / "examples/scenes/s.toml"
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text.replace(old, new).replace("../../robots/", str(ROOT / "robots") + "/"))
        with pytest.raises(SceneError, match=msg):
            fmugen.load_scene(p)
    # --set reaches an expanded instance
    sc = fmugen.load_scene(NEW, set={"path2.q_end": 0.3})
    assert {v.name: v.start for v in sc.base_models["path2"].parameters}["q_end"] == 0.3


def test_record_bonds_and_energy_per_bond(tmp_path):
    from fmugen.scene.bonds import bond_power

    sc = rig(tmp_path, '["act.port", "valve.port"], ["act.flange", "inert.flange"]')
    assert sc.spec.record == ()
    p = tmp_path / "rig.toml"
    p.write_text(p.read_text().replace("stop = 0.5", "stop = 0.5\nrecord_bonds = true"))
    sc = fmugen.load_scene(p)
    assert sc.spec.record == ("act.P_L", "valve.Q_L", "act.tau", "inert.w")
    t = np.linspace(0, 2, 201)
    cols = {"act.P_L": np.full_like(t, 3e6), "valve.Q_L": 1e-5 * t, "act.tau": np.full_like(t, 4.0),
            "inert.w": np.cos(t)}
    (b1, p1, e1), (b2, p2, e2) = bond_power(sc.spec.bonds, t, cols.__getitem__)
    assert str(b1) == "act.port <-> valve.port (hydraulic)" and p1[-1] == pytest.approx(60.0)
    assert e1[-1] == pytest.approx(3e6 * 1e-5 * 2.0**2 / 2, rel=1e-12)  # integral of a ramp: trapezoid exact
    assert e2[-1] == pytest.approx(4.0 * np.sin(2.0), rel=1e-4)


URDF = """<robot name="two">
  <link name="base"/>
  <link name="upper"><inertial><origin xyz="0 0 0.2"/><mass value="2.0"/>
    <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.01"/></inertial></link>
  <link name="lower"><inertial><origin xyz="0 0 0.15"/><mass value="1.0"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.005"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="100" velocity="2"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="lower"/>
    <origin xyz="0 0 0.4"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="50" velocity="2"/></joint>
</robot>
"""


def test_connect_to_a_urdf_joint_by_name(tmp_path):
    (tmp_path / "two.urdf").write_text(URDF)
    (tmp_path / "s.toml").write_text("""
[scene]
name = "s"
connect = [["act.flange", "arm.elbow"], ["valve.port", "act.port"]]
[instances]
arm = { robot = "two.urdf" }
act = { type = "hydraulic_actuator" }
valve = { type = "servo_valve" }
""")
    sc = fmugen.load_scene(tmp_path / "s.toml")
    assert ("arm", "qd[2]", "act", "w", None) in sc.connections
    assert ("act", "tau", "arm", "tau[2]", None) in sc.connections
    assert str(sc.spec.bonds[0]) == "act.flange <-> arm.elbow (rotational)"
