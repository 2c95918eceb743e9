"""URDF files: read safely, refused clearly, and the same dynamics as Pinocchio's own URDF parser.

Pinocchio (PyPI ``pin``) reads the URDF with its own parser (urdfdom) and
builds its model independently of fmugen's reader; both are compared on a
representative subset of ``example-robot-data`` (PyPI ``example-robot-data``):
a chain with fixed tool frames (UR5), a tree with prismatic fingers, a mimic
joint and a merged hand (Panda), continuous joints (Kinova), a 16-DoF tree (Allegro hand:
a palm with four fingers); unaligned axes and exact fixed-joint merging on a
handmade arm.  The whole collection is in
``examples/urdf_table.py``.
"""
import importlib.metadata
import warnings
from pathlib import Path

import numpy as np
import pytest

import fmugen
from fmugen.dynamics.manipulator import Manipulator
from fmugen.robot.checks import RobotFileError
from fmugen.robot.urdf import MimicJointWarning, load_urdf, robot_from_urdf

pin = pytest.importorskip("pinocchio")
# published URDFs (and the massless tcp below) have inertias that are not rigid bodies: kept, with a warning
pytestmark = pytest.mark.filterwarnings("ignore::fmugen.robot.checks.UnrealisableInertiaWarning")

from fmugen.codegen.benchmarks import pinocchio_urdf_map, to_pinocchio  # noqa: E402


def erd_robots() -> Path:
    """The robots folder of the installed example-robot-data wheel."""
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed (pip install -e '.[test]')")
    return Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots"))


FD_RTOL = 1e-9
FK_ATOL = 1e-12


def compare_with_pinocchio(path, states=3, seed=0):
    """Largest relative errors of M, h, forward dynamics and absolute FK/Jacobian errors (m) over every frame."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = load_urdf(path)
    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    arm = Manipulator(robot)
    # Pinocchio's rnea/crba/aba model neither damping nor friction
    zero = {p.name: 0.0 for p in robot.parameters if p.name.startswith(("b_", "fc_"))}
    mp = pinocchio_urdf_map(model, robot)
    iv = [m[1] for m in mp]
    assert model.nv == robot.n
    rng = np.random.default_rng(seed)
    err = dict(M=0.0, h=0.0, fd=0.0, fk=0.0, J=0.0)
    for _ in range(states):
        q, qd, tau = rng.uniform(-1, 1, robot.n), rng.uniform(-1, 1, robot.n), rng.uniform(-5, 5, robot.n)
        qp, vp = to_pinocchio(model, mp, q, qd)
        taup = np.zeros(model.nv)
        taup[iv] = tau
        Mp = pin.crba(model, data, qp)
        Mp = (np.triu(Mp) + np.triu(Mp, 1).T)[np.ix_(iv, iv)]
        hp = pin.rnea(model, data, qp, vp, np.zeros(model.nv))[iv]
        ap = pin.aba(model, data, qp, vp, taup)[iv]
        err["M"] = max(err["M"], np.abs(arm.mass_matrix(q, **zero) - Mp).max() / np.abs(Mp).max())
        err["h"] = max(err["h"], np.abs(arm.bias(q, qd, **zero) - hp).max() / np.abs(hp).max())
        err["fd"] = max(err["fd"], np.abs(arm.forward_dynamics(q, qd, tau, **zero) - ap).max() / np.abs(ap).max())
    pin.computeJointJacobians(model, data, qp)
    pin.updateFramePlacements(model, data)
    for name in robot.frame_names():
        fid = model.getFrameId(name, pin.BODY)
        assert fid < len(model.frames), name
        T = arm.fk(q, name)
        err["fk"] = max(err["fk"], np.abs(T[:3, 3] - data.oMf[fid].translation).max(),
                        np.abs(T[:3, :3] - data.oMf[fid].rotation).max())
        Jp = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)[:, iv]
        err["J"] = max(err["J"], np.abs(arm.jacobian(q, name) - Jp).max())
    return robot, err


@pytest.mark.parametrize("rel, kind", [
    ("ur_description/urdf/ur5_robot.urdf", "chain"),
    ("panda_description/urdf/panda.urdf", "tree"),
    ("kinova_description/robots/kinova.urdf", "chain"),
    ("allegro_hand_description/urdf/allegro_left_hand.urdf", "tree"),
])
def test_example_robot_data_subset_equals_pinocchio(rel, kind):
    robot, err = compare_with_pinocchio(erd_robots() / rel)
    assert robot.is_chain == (kind == "chain")
    assert err["M"] < FD_RTOL and err["h"] < FD_RTOL and err["fd"] < FD_RTOL, err
    assert err["fk"] < FK_ATOL and err["J"] < FK_ATOL, err


def test_subset_covers_what_it_claims():
    """The subset has continuous, prismatic, fixed and mimic joints, chains and trees."""
    root = erd_robots()
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        panda = load_urdf(root / "panda_description/urdf/panda.urdf")
    assert any(issubclass(x.category, MimicJointWarning) and "panda_finger_joint2" in str(x.message) for x in w)
    assert [b.joint for b in panda.bodies].count("prismatic") == 2
    assert 'type="continuous"' in (root / "kinova_description/robots/kinova.urdf").read_text()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        allegro = load_urdf(root / "allegro_hand_description/urdf/allegro_left_hand.urdf")
    assert len(allegro.children(-1)) == 4 and not allegro.is_chain  # four fingers on the fixed palm
    ur5 = load_urdf(root / "ur_description/urdf/ur5_robot.urdf")
    assert {"ee_link", "tool0", "base_link", "world"} <= {f.name for f in ur5.frames}
    assert ur5.bodies[1].limits.lower == pytest.approx(-2 * np.pi) and ur5.bodies[1].limits.effort == 150.0


# ------------------------------------------------------------- handmade files
TCP_INERTIA = ('<inertial><origin xyz="0.01 0 0" rpy="0 0.3 0"/><mass value="0"/>'
               '<inertia ixx="1e-4" ixy="0" ixz="0" iyy="2e-4" iyz="0" izz="2.5e-4"/></inertial>')


def arm_urdf(joint2="revolute", extra="", tool_mass="0.7", fixed_rpy="0.3 -0.2 0.5", axis2="0 1 0",
             tcp=TCP_INERTIA):
    return f"""<?xml version="1.0"?>
<robot name="two-link arm">
  <link name="base"/>
  <link name="upper">
    <inertial><origin xyz="0.01 0.02 0.2" rpy="0.1 0.2 0.3"/><mass value="2.0"/>
      <inertia ixx="0.03" ixy="0.001" ixz="-0.002" iyy="0.04" iyz="0.003" izz="0.02"/></inertial>
    <visual><geometry><mesh filename="package://nowhere/upper.stl"/></geometry></visual>
  </link>
  <link name="fore">
    <inertial><origin xyz="0.15 0 0.01"/><mass value="1.2"/>
      <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
  </link>
  <link name="tool">
    <inertial><origin xyz="0.02 0.01 0.03" rpy="0.4 0 0"/><mass value="{tool_mass}"/>
      <inertia ixx="0.001" ixy="0.0001" ixz="0" iyy="0.002" iyz="0" izz="0.0015"/></inertial>
  </link>
  <link name="tcp">{tcp}</link>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/><origin xyz="0 0 0.3" rpy="0 0 0.2"/>
    <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="40" velocity="3"/>
    <dynamics damping="0.5" friction="0"/>
  </joint>
  <joint name="elbow" type="{joint2}">
    <parent link="upper"/><child link="fore"/><origin xyz="0.05 0 0.4" rpy="0.3 0 0"/>
    <axis xyz="{axis2}"/><limit lower="-1" upper="1" effort="20" velocity="3"/>
  </joint>
  <joint name="flange" type="fixed">
    <parent link="fore"/><child link="tool"/><origin xyz="0.3 0.01 -0.02" rpy="{fixed_rpy}"/>
  </joint>
  <joint name="tcp_joint" type="fixed">
    <parent link="tool"/><child link="tcp"/><origin xyz="0 0 0.1"/>
  </joint>
  {extra}
</robot>
"""


@pytest.mark.parametrize("joint2, axis2", [("revolute", "0 1 0"), ("prismatic", "0.6 0 0.8"),
                                           ("continuous", "0.3 0.4 -0.5")])
def test_fixed_joint_merging_and_axes_equal_pinocchio(tmp_path, joint2, axis2):
    """A fixed joint with rotation, an inertial origin with rpy, a massless link with inertia (the tcp),
    unaligned axes: exact against Pinocchio."""
    path = tmp_path / "arm.urdf"
    path.write_text(arm_urdf(joint2, axis2=axis2))
    robot, err = compare_with_pinocchio(path, states=4)
    assert robot.n == 2 and [f.name for f in robot.frames] == ["base", "tool", "tcp"]
    assert err["M"] < 1e-13 and err["fd"] < 1e-12 and err["fk"] < 1e-15 and err["J"] < 1e-15, err
    # the merged tool moved the mass: without it the comparison fails
    light = tmp_path / "light.urdf"
    light.write_text(arm_urdf(joint2, axis2=axis2, tool_mass="0.6"))
    model = pin.buildModelFromUrdf(str(path))
    arm = Manipulator(load_urdf(light))
    q = np.array([0.3, 0.2])
    qp = to_pinocchio(model, pinocchio_urdf_map(model, arm.robot), q)
    assert np.abs(arm.mass_matrix(q) - pin.crba(model, model.createData(), qp)).max() > 1e-4


def test_parameters_are_named_by_links_and_joints_and_set_like_any_other(tmp_path):
    path = tmp_path / "arm.urdf"
    path.write_text(arm_urdf())
    arm = fmugen.load_robot(path)
    names = {p.name for p in arm.robot.parameters}
    assert {"m_upper", "m_fore", "m_tool", "rc_tool_x", "I_tool_xy", "p_elbow_z", "b_shoulder", "g_z"} <= names
    assert arm.robot.name == "two_link_arm" and arm.robot.end_frame == "fore"
    q = np.array([0.4, -0.3])
    # a heavier tool = a heavier merged body: M grows by the tool's own contribution only
    M0, M1 = arm.mass_matrix(q), arm.mass_matrix(q, m_tool=1.7)
    heavier = tmp_path / "heavier.urdf"
    heavier.write_text(arm_urdf(tool_mass="1.7"))
    assert np.allclose(M1, fmugen.load_robot(heavier).mass_matrix(q), rtol=1e-13, atol=0)
    assert not np.allclose(M0, M1)
    m = arm.state_space_model(outputs=())
    q1 = next(v for v in m.states if v.name == "q[1]")
    tau2 = next(v for v in m.inputs if v.name == "tau[2]")
    assert (q1.min, q1.max, tau2.min, tau2.max) == (-2.0, 2.0, -20.0, 20.0)
    assert "shoulder" in q1.description and q1.unit == "rad"
    # damping b qd is in h
    h0 = arm.bias(q, [1.0, 0.0], b_shoulder=0.0)
    assert arm.bias(q, [1.0, 0.0])[0] - h0[0] == pytest.approx(0.5, rel=1e-12)


def test_smooth_coulomb_friction(tmp_path):
    path = tmp_path / "arm.urdf"
    path.write_text(arm_urdf().replace('friction="0"', 'friction="2.0"'))
    arm = fmugen.load_robot(path)
    q = np.array([0.1, 0.2])
    h = arm.bias(q, [0.005, 0.0])
    h0 = arm.bias(q, [0.005, 0.0], fc_shoulder=0.0)
    assert h[0] - h0[0] == pytest.approx(2.0 * np.tanh(0.005 / 0.01), rel=1e-12)


# ------------------------------------------------------------- refusals
def refused(text, match, tmp_path, name="bad.urdf"):
    p = tmp_path / name
    p.write_text(text)
    with pytest.raises(RobotFileError, match=match) as exc:
        load_urdf(p)
    assert str(exc.value).startswith(str(p)) and "\n" not in str(exc.value)
    return str(exc.value)


def test_entities_dtds_and_external_references_are_refused(tmp_path):
    laughs = ('<?xml version="1.0"?>\n<!DOCTYPE lolz [<!ENTITY lol "lol"><!ENTITY lol2 "&lol;&lol;&lol;">]>\n'
              '<robot name="&lol2;"><link name="a"/></robot>')
    refused(laughs, "DOCTYPE", tmp_path)
    external = ('<?xml version="1.0"?>\n<!DOCTYPE r [<!ENTITY x SYSTEM "file:///etc/passwd">]>\n'
                '<robot name="r"><link name="&x;"/></robot>')
    refused(external, "DOCTYPE", tmp_path)
    refused('<robot name="r"><link name="a"/>', r"line 1, column \d+: XML syntax error", tmp_path)


def test_xacro_is_refused_with_a_hint(tmp_path):
    refused(arm_urdf(), "xacro", tmp_path, name="arm.urdf.xacro")
    macro = arm_urdf(extra='<xacro:include filename="other.xacro"/>').replace(
        '<robot name="two-link arm">', '<robot name="a" xmlns:xacro="http://www.ros.org/wiki/xacro">')
    refused(macro, "xacro macros.*expand", tmp_path)
    refused(arm_urdf().replace('value="2.0"', 'value="${m}"'), "xacro", tmp_path)
    # a mere namespace declaration (files generated by xacro keep it) is fine
    ok = tmp_path / "ok.urdf"
    ok.write_text(arm_urdf().replace('<robot name="two-link arm">',
                                     '<robot name="a" xmlns:xacro="http://www.ros.org/wiki/xacro">'))
    assert load_urdf(ok).n == 2


def test_size_and_depth_limits(tmp_path, monkeypatch):
    import fmugen.robot.urdf as U

    deep = "<robot name='r'>" + "<a>" * 40 + "</a>" * 40 + "<link name='x'/></robot>"
    refused(deep, "deeper than 32", tmp_path)
    monkeypatch.setattr(U, "MAX_BYTES", 1000)
    refused(arm_urdf(), "bytes", tmp_path)


@pytest.mark.parametrize("edit, match", [
    (lambda t: t.replace('name="elbow" type="revolute"', 'name="elbow" type="floating"'),
     "joint 'elbow': type 'floating': a floating joint"),
    (lambda t: t.replace('name="elbow" type="revolute"', 'name="elbow" type="planar"'), "joint 'elbow'.*planar"),
    (lambda t: t.replace('name="elbow" type="revolute"', 'name="elbow" type="ball"'), "joint 'elbow': unknown type"),
    (lambda t: t.replace('<parent link="tool"/>', '<parent link="tcp"/>'), "joint 'tcp_joint'.*cycle"),
    (lambda t: t.replace('<parent link="fore"/><child link="tool"/>', '<parent link="fore"/><child link="upper"/>'),
     "joint 'flange': link 'upper' already has a parent"),
    (lambda t: t.replace('<link name="base"/>', '<link name="base"/><link name="loose"/>'), "2 root links"),
    (lambda t: t.replace('<mass value="2.0"/>', '<mass value="nan"/>'), "link 'upper'.*'nan' is not an xs:double"),
    (lambda t: t.replace('<mass value="2.0"/>', '<mass value="INF"/>'), "link 'upper'.*INF is not a finite number"),
    (lambda t: t.replace('<mass value="2.0"/>', '<mass value="-2"/>'), "negative mass"),
    (lambda t: t.replace('xyz="0 0 0.3"', 'xyz="0 0.3"'), "joint 'shoulder'.*expected 3"),
    (lambda t: t.replace('<axis xyz="0 0 1"/>', '<axis xyz="0 0 0"/>'), "joint 'shoulder'.*zero vector"),
    (lambda t: t.replace('<child link="fore"/>', '<child link="forearm"/>'), "joint 'elbow'.*no such link"),
    (lambda t: t.replace('<link name="base"/>', '<link name="base"/><link name="base"/>'), "link 'base'.*twice"),
    (lambda t: t.replace('name="fore"', 'name="fore*/"'), "name must be"),
])
def test_bad_files_are_refused_naming_the_joint(tmp_path, edit, match):
    refused(edit(arm_urdf()), match, tmp_path)


def test_names_never_reach_generated_code_unsanitised(tmp_path):
    """Parameter names are C identifiers made from the file's names; the robot name too."""
    text = arm_urdf().replace('name="upper"', 'name="up-per.v2"').replace('link="upper"', 'link="up-per.v2"')
    robot = robot_from_urdf(text, "x.urdf")
    assert robot.name == "two_link_arm"
    assert "m_up_per_v2" in {p.name for p in robot.parameters}
    assert all(p.name.isidentifier() for p in robot.parameters)


# ------------------------------------------------------------- frames as FMU outputs
def test_frame_outputs_their_jacobians_and_locked_branches():
    """p:/R:/J: outputs equal fk/jacobian; d p / d q in the model Jacobian is J's linear rows; locking a
    branch (the Panda's fingers) keeps exactly the free rows and computes only the named frame's path."""
    from fmugen.codegen.evaluate import ModelEvaluator

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        arm = fmugen.load_robot(erd_robots() / "panda_description/urdf/panda.urdf")
    m = arm.state_space_model(outputs=("p:panda_hand_tcp", "R:panda_hand", "J:panda_leftfinger"))
    names = [v.name for v in m.outputs]
    assert names[:3] == ["p_panda_hand_tcp[1]", "p_panda_hand_tcp[2]", "p_panda_hand_tcp[3]"]
    assert "R_panda_hand[2,3]" in names and "J_panda_leftfinger[6,9]" in names and len(names) == 3 + 9 + 54
    q4 = m.states[3]  # the elbow's range [-3.0718, -0.0698] excludes 0: it starts mid-range
    assert (q4.name, q4.min, q4.max, q4.start) == ("q[4]", -3.0718, -0.0698, pytest.approx(-1.5708))
    ev = ModelEvaluator(m)
    rng = np.random.default_rng(3)
    q = rng.uniform(-1, 1, 9)
    x, u = np.r_[q, rng.uniform(-1, 1, 9)], np.zeros(9)
    y = ev.g(0.0, x, u)
    assert np.abs(y[:3] - arm.fk(q, "panda_hand_tcp")[:3, 3]).max() < 1e-14
    assert np.abs(y[3:12].reshape(3, 3) - arm.fk(q, "panda_hand")[:3, :3]).max() < 1e-14
    assert np.abs(y[12:].reshape(6, 9) - arm.jacobian(q, "panda_leftfinger")).max() < 1e-14
    _, _, C, _ = ev.jacobians(0.0, x, u)
    assert np.abs(C[:3, :9] - arm.jacobian(q, "panda_hand_tcp")[:3]).max() < 1e-13
    # the TCP's Jacobian has no finger columns; the left finger's has its own joint and not the right one's
    J = arm.jacobian(q, "panda_leftfinger")
    assert not J[:, 8].any() and J[:, 7].any()

    locked = arm.state_space_model(outputs=("p:panda_hand_tcp",), locked={8: 0.01, 9: 0.02})
    assert [v.name for v in locked.states][:7] == [f"q[{i}]" for i in range(1, 8)] and locked.nx == 14
    lev = ModelEvaluator(locked)
    q7, qd7, tau7 = rng.uniform(-1, 1, 7), rng.uniform(-1, 1, 7), rng.uniform(-5, 5, 7)
    qf, qdf = np.r_[q7, 0.01, 0.02], np.r_[qd7, 0.0, 0.0]
    M, h = arm.mass_matrix(qf), arm.bias(qf, qdf)
    qdd = np.linalg.solve(M[:7, :7], tau7 - h[:7])
    assert np.abs(lev.f(0.0, np.r_[q7, qd7], tau7)[7:] - qdd).max() < 1e-10 * np.abs(qdd).max()
    assert locked.operation_count() < arm.state_space_model(outputs=("p:panda_hand_tcp",)).operation_count()
    with pytest.raises(ValueError, match="no body or frame 'tool0'.*known: panda_link1"):
        arm.state_space_model(outputs=("p:tool0",))
    with pytest.raises(ValueError, match="unknown output 'X:panda_hand'"):
        arm.state_space_model(outputs=("X:panda_hand",))


def test_a_scene_takes_a_urdf_robot_with_frame_outputs(tmp_path):
    from fmugen.scene import load_scene

    (tmp_path / "arm.urdf").write_text(arm_urdf())
    (tmp_path / "s.toml").write_text("""
[scene]
name = "urdf_arm"
[instances.arm]
robot = "arm.urdf"
outputs = ["p:tcp", "J:tool"]
locked = { "q[2]" = 0.1 }
[fmus.arm]
members = ["arm"]
""")
    scene = load_scene(tmp_path / "s.toml")
    m, removed = scene.instance_model("arm")
    assert [v.name for v in m.states] == ["q[1]", "qd[1]"]
    assert [v.name for v in m.outputs][:3] == ["p_tcp[1]", "p_tcp[2]", "p_tcp[3]"]
    assert "J_tool[6,1]" in [v.name for v in m.outputs] and "J_tool[1,2]" not in [v.name for v in m.outputs]


# ------------------------------------------------------------- the two derivations over a tree
def random_tree(n=7, seed=5):
    """A random tree in the general joint model: unaligned axes, rotated placements, prismatic joints,
    offsets, rotor inertia, full inertia tensors (Robot written as joints, no file)."""
    import sympy as sp

    from fmugen.robot.description import Body, Frame, Robot

    rng = np.random.default_rng(seed)

    def rot():
        qm, r = np.linalg.qr(rng.normal(size=(3, 3)))
        qm = qm @ np.diag(np.sign(np.diag(r)))
        return qm if np.linalg.det(qm) > 0 else -qm

    def f(x):
        return sp.Float(float(x))

    bodies, path = [], [-1]
    for i in range(n):
        # depth-first numbering (each subtree contiguous, as URDF files are read): the parent is
        # the base or a body on the path to the previous one
        parent = int(rng.choice(path))
        path = path[:path.index(parent) + 1] + [i]
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        R, Rb = rot(), rot()
        I = Rb @ np.diag(rng.uniform(0.01, 0.05, 3) + [0.0, 0.0, 0.02]) @ Rb.T
        bodies.append(Body(
            name=f"b{i}", joint="prismatic" if i % 3 == 2 else "revolute", parent=parent,
            rotation=tuple(tuple(f(x) for x in row) for row in R), translation=tuple(f(x) for x in rng.uniform(-0.3, 0.3, 3)),
            axis=tuple(f(x) for x in axis), mass=f(rng.uniform(0.5, 2)), com=tuple(f(x) for x in rng.uniform(-0.1, 0.1, 3)),
            inertia_com=tuple(tuple(f(x) for x in row) for row in 0.5 * (I + I.T)),
            rotor_inertia=f(0.01 * i), offset=f(0.1 * i), joint_name=f"j{i}"))
    frames = (Frame("tip", n - 1, ((1, 0, 0), (0, 1, 0), (0, 0, 1)), (f(0.1), f(0), f(0.05))),)
    return Robot(name="tree", convention="joints", links=(), gravity=(f(0.3), f(-0.2), f(-9.81)),
                 bodies=tuple(bodies), frames=frames, end_frame="tip")


def test_newton_euler_and_composite_bodies_agree_on_a_random_tree_and_equal_pinocchio():
    """Three derivations over a tree: M by CRBA equals M by n Newton-Euler passes (unit accelerations)
    and the recursive Lagrange form; they and the forward dynamics equal Pinocchio's crba/rnea/aba."""
    import sympy as sp

    from fmugen.codegen.benchmarks import pinocchio_model
    from fmugen.codegen.python_code import compile_program

    robot = random_tree()
    assert not robot.is_chain and len(robot.children(-1)) >= 1
    arm = Manipulator(robot)
    d = arm.derivation()
    n, zeros = robot.n, [sp.Integer(0)] * robot.n
    cols = [d.engine.torques(arm.q, zeros, [sp.Integer(int(k == j)) for k in range(n)]) for j in range(n)]
    M_ne = compile_program(d.program, [arm.q], [sp.Matrix(n, n, lambda i, j: cols[j][i])], "m")
    model = pinocchio_model(robot)
    data = model.createData()
    rng = np.random.default_rng(0)
    for _ in range(3):
        q, qd, qdd, tau = (rng.uniform(-1, 1, n) for _ in range(4))
        M = arm.mass_matrix(q)
        assert np.abs(M - M_ne(q)[0]).max() < 1e-13 * np.abs(M).max()
        Mp = pin.crba(model, data, q)
        assert np.abs(M - (np.triu(Mp) + np.triu(Mp, 1).T)).max() < 1e-12 * np.abs(M).max()
        tp = pin.rnea(model, data, q, qd, qdd)
        assert np.abs(arm.inverse_dynamics(q, qd, qdd) - tp).max() < 1e-12 * np.abs(tp).max()
        ap = pin.aba(model, data, q, qd, tau)
        assert np.abs(arm.forward_dynamics(q, qd, tau) - ap).max() < 1e-10 * np.abs(ap).max()
        # the thesis's recursive Lagrange form, extended to the tree (4x4 matrices, nothing shared with NE)
        assert np.abs(arm.inverse_dynamics(q, qd, qdd, formulation="lagrange") - tp).max() < 1e-12 * np.abs(tp).max()
        assert np.abs(arm.mass_matrix(q, formulation="lagrange") - M).max() < 1e-12 * np.abs(M).max()


# ------------------------------------------------------------- export
@pytest.mark.parametrize("robot_file", ["puma_thesis_com.toml", "stanford_arm.toml"])
def test_export_urdf_gives_pinocchio_the_same_dynamics(tmp_path, robot_file):
    """fmugen export-urdf: Pinocchio's URDF parser reads the file into the dynamics of the TOML robot,
    and fmugen reads it back into the same bodies (frames frame1..frameN included)."""
    from fmugen.cli import main

    out = tmp_path / "robot.urdf"
    src = Path(__file__).resolve().parents[1] / "robots" / robot_file
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["export-urdf", str(src), "-o", str(out)]) == 0
        arm = fmugen.load_robot(src)
    robot = arm.robot
    model = pin.buildModelFromUrdf(str(out))
    model.armature = np.array([float(b.rotor_inertia.xreplace(robot.parameter_values())) for b in robot.bodies])
    data = model.createData()
    mp = pinocchio_urdf_map(model, load_urdf(out))
    iv = [m[1] for m in mp]
    back = Manipulator(load_urdf(out))
    rng = np.random.default_rng(7)
    for _ in range(3):
        q, qd, tau = rng.uniform(-2, 2, 6), rng.uniform(-1, 1, 6), rng.uniform(-20, 20, 6)
        qp, vp = to_pinocchio(model, mp, q, qd)
        taup = np.zeros(6)
        taup[iv] = tau
        ap = pin.aba(model, data, qp, vp, taup)[iv]
        assert np.abs(arm.forward_dynamics(q, qd, tau) - ap).max() < 1e-10 * np.abs(ap).max()
        Mp = pin.crba(model, data, qp)
        Mp = (np.triu(Mp) + np.triu(Mp, 1).T)[np.ix_(iv, iv)]
        assert np.abs(back.mass_matrix(q) + np.diag(model.armature[iv]) - Mp).max() < 1e-12 * np.abs(Mp).max()
        pin.framesForwardKinematics(model, data, qp)
        T = data.oMf[model.getFrameId("frame6")]
        assert np.abs(arm.fk(q)[:3, 3] - T.translation).max() < 1e-12
        assert np.abs(back.fk(q, "frame6") - arm.fk(q)).max() < 1e-12


def test_rpy_of_rotations_round_trips_including_gimbal_lock():
    from fmugen.robot.urdf import rpy_matrix
    from fmugen.robot.urdf_export import rotation_rpy

    rng = np.random.default_rng(1)
    cases = [rng.uniform(-np.pi, np.pi, 3) for _ in range(50)] + [[0.3, np.pi / 2, -0.2], [1.0, -np.pi / 2, 0.4]]
    for rpy in cases:
        R = rpy_matrix(rpy)
        assert np.abs(rpy_matrix(rotation_rpy(R)) - R).max() < 1e-14


def test_shipped_ur5_scene_starts_at_rest_held_by_its_drives():
    """examples/scenes/ur5_electric.toml: the URDF arm in a scene; at the solved state of rest each drive's
    joint torque equals the arm's gravity torque (Manipulator's own evaluator) and nothing moves."""
    from fmugen.codegen.evaluate import ModelEvaluator

    root = Path(__file__).resolve().parents[1]
    init = fmugen.load_scene(root / "examples/scenes/ur5_electric.toml").initial
    m = init.model
    x = np.array([init.values[v.name] for v in m.states])
    ev = ModelEvaluator(m)
    f = ev.f(0.0, x, np.zeros(m.nu))
    nom = np.array([v.nominal or 1.0 for v in m.states])
    assert np.max(np.abs(f) / nom) < 1e-6
    y = ev.g(0.0, x, np.zeros(m.nu))
    out = [v.name for v in m.outputs]
    tau = np.array([y[out.index(f"mot{k}.tau")] for k in range(1, 7)])
    arm = fmugen.load_robot(root / "robots/ur5.urdf")
    q = np.array([init.values[f"arm.q[{k}]"] for k in range(1, 7)])
    g = arm.bias(q, np.zeros(6))
    assert np.allclose(tau, g, rtol=1e-8, atol=1e-8 * np.max(np.abs(g)))
    assert abs(g[1]) > 30  # the shoulder carries the arm
    p = np.array([y[out.index(f"arm.p_tool0[{r}]")] for r in (1, 2, 3)])
    assert np.abs(p - arm.fk(q, "tool0")[:3, 3]).max() < 1e-12


def test_a_joint_that_moves_nothing_is_refused(tmp_path):
    text = arm_urdf(tool_mass="0.0", tcp="").replace('<mass value="1.2"/>', '<mass value="0"/>').replace(
        '<inertia ixx="0.002" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>', '').replace(
        '<inertia ixx="0.001" ixy="0.0001" ixz="0" iyy="0.002" iyz="0" izz="0.0015"/>', '')
    refused(text, "joint 'elbow': moves no mass", tmp_path)


def test_armature_makes_a_joint_that_moves_nothing_buildable(tmp_path):
    """The refusal names the fix, a rotor (armature) inertia; with it (API and scene) the dynamics equal
    Pinocchio's with the same model.armature (as examples/urdf_table.py builds Romeo's hands)."""
    from fmugen.scene import load_scene

    text = arm_urdf(tool_mass="0.0", tcp="").replace('<mass value="1.2"/>', '<mass value="0"/>').replace(
        '<inertia ixx="0.002" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>', '').replace(
        '<inertia ixx="0.001" ixy="0.0001" ixz="0" iyy="0.002" iyz="0" izz="0.0015"/>', '')
    refused(text, r"armature = \{ elbow = 1e-3 \}", tmp_path)
    with pytest.raises(RobotFileError, match="armature.*'elbw'.*no moving joint of that name; joints: shoulder, elbow"):
        robot_from_urdf(text, "x.urdf", armature={"elbw": 1e-3})
    with pytest.raises(RobotFileError, match="must be a finite number >= 0"):
        robot_from_urdf(text, "x.urdf", armature={"elbow": -1.0})
    robot = robot_from_urdf(text, "x.urdf", armature={"elbow": 2e-3})
    ia = {p.name: p for p in robot.parameters}["Ia_elbow"]
    assert (ia.value, ia.unit) == (2e-3, "kg.m2")
    arm = Manipulator(robot)
    model = pin.buildModelFromXML(text)
    model.armature[model.joints[model.getJointId("elbow")].idx_v] = 2e-3
    data = model.createData()
    zero = {p.name: 0.0 for p in robot.parameters if p.name.startswith(("b_", "fc_"))}
    q, qd, tau = np.array([0.3, -0.4]), np.array([0.5, 0.2]), np.array([1.0, 0.01])
    ref = pin.aba(model, data, q, qd, tau)
    assert np.abs(arm.forward_dynamics(q, qd, tau, **zero) - ref).max() <= 1e-12 * np.abs(ref).max()

    (tmp_path / "arm.urdf").write_text(text)
    (tmp_path / "s.toml").write_text("""
[scene]
name = "armature"
[instances.arm]
robot = "arm.urdf"
armature = { elbow = 2e-3 }
[fmus.arm]
members = ["arm"]
""")
    m, _ = load_scene(tmp_path / "s.toml").instance_model("arm")
    assert {v.name: v.start for v in m.parameters}["Ia_elbow"] == 2e-3


def test_mimic_joints_tied_to_their_leader(tmp_path):
    """mimic="tied": the elbow follows the shoulder (q2 = -0.5 q1 + 0.1); the model keeps one joint and its
    acceleration is the projection G^T M G qdd = G^T (tau - h) of the full arm's M and h (numpy)."""
    from fmugen.codegen.evaluate import ModelEvaluator

    path = tmp_path / "arm.urdf"
    path.write_text(arm_urdf().replace('<axis xyz="0 1 0"/>', '<axis xyz="0 1 0"/>'
                                       '<mimic joint="shoulder" multiplier="-0.5" offset="0.1"/>'))
    with pytest.warns(MimicJointWarning, match="elbow"):
        assert fmugen.load_robot(path).robot.bodies[1].mimic is None
    arm = fmugen.load_robot(path, mimic="tied")
    assert arm.robot.bodies[1].mimic[0] == 0
    m = arm.state_space_model(outputs=("qdd", "p:tcp", "J:tcp"))
    assert [v.name for v in m.states] == ["q[1]", "qd[1]"] and [v.name for v in m.inputs] == ["tau[1]"]
    ev = ModelEvaluator(m)
    G = np.array([[1.0], [-0.5]])
    for q1, qd1, tau1 in ((0.3, 0.7, 2.0), (-1.1, -0.4, -5.0)):
        q, qd = np.array([q1, -0.5 * q1 + 0.1]), np.array([qd1, -0.5 * qd1])
        M, h = arm.mass_matrix(q), arm.bias(q, qd)
        qdd = np.linalg.solve(G.T @ M @ G, G.T @ (np.array([tau1, 0.0]) - h))
        assert ev.f(0.0, [q1, qd1], [tau1])[1] == pytest.approx(qdd[0], rel=1e-12)
        y = ev.g(0.0, [q1, qd1], [tau1])
        assert y[9] == pytest.approx(qdd[0], rel=1e-12)  # outputs: p_tcp, J_tcp, then qdd
        assert np.abs(y[0:3] - arm.fk(q, "tcp")[:3, 3]).max() < 1e-14
        assert np.abs(y[3:9] - (arm.jacobian(q, "tcp") @ G)[:, 0]).max() < 1e-14  # d p_tcp / d q1 includes q2
    # the exact model Jacobian against central differences of f
    x, u, e = np.array([0.3, 0.7]), np.array([2.0]), 1e-6
    A, B, _, _ = ev.jacobians(0.0, x, u)
    A_fd = np.column_stack([(ev.f(0.0, x + e * d, u) - ev.f(0.0, x - e * d, u)) / (2 * e) for d in np.eye(2)])
    assert np.abs(A - A_fd).max() < 1e-6 * np.abs(A).max()
    assert B[1, 0] == pytest.approx((ev.f(0.0, x, u + e)[1] - ev.f(0.0, x, u - e)[1]) / (2 * e), rel=1e-6)
    with pytest.raises(ValueError, match="follow another joint"):
        arm.state_space_model(locked={2: 0.0})


def test_a_scene_ties_mimic_joints(tmp_path):
    from fmugen.scene import load_scene
    from fmugen.scene.errors import SceneError

    (tmp_path / "arm.urdf").write_text(arm_urdf().replace(
        '<axis xyz="0 1 0"/>', '<axis xyz="0 1 0"/><mimic joint="shoulder" multiplier="2"/>'))
    text = '[scene]\nname = "m"\n[instances.arm]\nrobot = "arm.urdf"\nmimic = "{}"\n[fmus.arm]\nmembers = ["arm"]\n'
    (tmp_path / "s.toml").write_text(text.format("tied"))
    m, _ = load_scene(tmp_path / "s.toml").instance_model("arm")
    assert [v.name for v in m.states] == ["q[1]", "qd[1]"]
    (tmp_path / "s.toml").write_text(text.format("glued"))
    with pytest.raises(SceneError, match="mimic must be 'independent' or 'tied'"):
        load_scene(tmp_path / "s.toml")


def test_urdf_table_example_runs(capsys):
    """examples/urdf_table.py, cut down to one robot (the whole table: examples/urdf_table_results.md)."""
    import importlib.util
    import sys

    path = Path(__file__).resolve().parents[1] / "examples" / "urdf_table.py"
    spec = importlib.util.spec_from_file_location("urdf_table", path)
    table = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("urdf_table", table)
    spec.loader.exec_module(table)
    assert table.main(["--only", "double_pendulum_continuous", "--states", "1", "--repeat", "1"]) == 0
    out = capsys.readouterr().out
    assert "| double_pendulum_continuous.urdf | 2 | chain |" in out and "1 built and within tolerance" in out


def test_linearize_takes_a_urdf_robot(tmp_path):
    """fmugen linearize robots/ur5.urdf --trim tau: the holding torque is the UR5's gravity torque."""
    from fmugen.cli import main

    root = Path(__file__).resolve().parents[1]
    q = [0.1, -1.2, 1.0, -1.4, -1.57, 0.0]
    out = tmp_path / "ur5.npz"
    assert main(["linearize", str(root / "robots/ur5.urdf"), "--at", "q=" + ",".join(map(str, q)), "--at", "qd=0",
                 "--trim", "tau", "--out", str(out)]) == 0
    lin = np.load(out)
    g = fmugen.load_robot(root / "robots/ur5.urdf").bias(q, np.zeros(6))
    assert np.abs(lin["u0"] - g).max() < 1e-8 * np.abs(g).max() and lin["A"].shape == (12, 12)


def test_fmu_variables_have_urdf_joint_name_aliases(tmp_path):
    """FMI 2.0 aliases <joint>.q/.qd/.tau (same value reference and unit) next to q[i], qd[i], tau[i]: fmpy's
    validation passes, one variable per alias set carries a start (FMI 2.0 sec. 2.2.7; FMI Library removes a
    set with two), so a state's alias has the state's causality and no start and an input's alias is a local
    without start (an input must have one); a run read through the alias names equals the run read through
    the indexed names; a joint name that is no identifier is cleaned (2el-bow/x -> _2el_bow_x)."""
    from fmpy import read_model_description, simulate_fmu
    from fmpy.validation import validate_fmu

    from fmugen.cli import main

    text = arm_urdf().replace('joint name="elbow"', 'joint name="2el-bow/x"')
    (tmp_path / "arm.urdf").write_text(text)
    fmu = tmp_path / "arm.fmu"
    assert main(["build", str(tmp_path / "arm.urdf"), "-o", str(fmu), "--fmi-type", "both"]) == 0
    assert validate_fmu(str(fmu)) == []
    by = {v.name: v for v in read_model_description(str(fmu)).modelVariables}
    for old, new in [("q[1]", "shoulder.q"), ("qd[2]", "_2el_bow_x.qd"), ("tau[2]", "_2el_bow_x.tau")]:
        a, b = by[old], by[new]
        assert (b.valueReference, b.variability, b.unit) == (a.valueReference, a.variability, a.unit)
        assert b.start is None and a.start is not None and b.initial == "calculated"
        assert b.causality == ("local" if old.startswith("tau") else a.causality)
    sets = {}
    for v in by.values():
        sets.setdefault((v.type, v.valueReference), []).append(v)
    assert all(sum(v.start is not None for v in s) <= 1 for s in sets.values())
    runs = []
    for names in (("q[1]", "qd[2]", "tau[2]"), ("shoulder.q", "_2el_bow_x.qd", "_2el_bow_x.tau")):
        r = simulate_fmu(str(fmu), fmi_type="ModelExchange", stop_time=0.3, output_interval=0.05,
                         start_values={"tau[1]": 4.0, "tau[2]": -2.0}, output=list(names))
        runs.append(np.column_stack([r[n] for n in names]))
    assert np.abs(runs[0]).max() > 1e-3 and np.array_equal(runs[0], runs[1])
    assert np.all(runs[1][:, 2] == -2.0)  # the input read back through its joint name
    # a system made of it (SSP connectors, start values, recorded columns) sees each value once, by its
    # indexed name: the aliases are left out
    from fmugen.ssp.ssd import without_aliases

    kept = [v.name for v in without_aliases(read_model_description(str(fmu)))]
    assert "q[1]" in kept and "tau[2]" in kept and not any(n.endswith((".q", ".qd", ".tau")) for n in kept)
    assert len(kept) == len({(v.type, v.valueReference) for v in by.values()})
