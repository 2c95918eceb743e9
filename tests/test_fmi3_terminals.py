"""FMI 3.0 terminals (``terminalsAndIcons/terminalsAndIcons.xml``, fmugen/fmi/terminals.py): fmugen's connectors
as terminals of the FMI 3.0 FMUs it builds.

A scene group's FMU has one terminal per connector of its members whose variables are inputs or outputs of
the FMU (named as the FMU names variables, potentials ``signal``, the flow ``outflow`` where the FMU computes
it and ``inflow`` where it takes it); a robot built alone has one per joint.  The file validates against the
standard's schema (fmpy ships it; fmpy's validate_fmu does not read the file), every member names a variable
of the modelDescription, and FMI 2.0 FMUs carry no such file.
"""
from __future__ import annotations

import zipfile
from pathlib import Path

import fmpy
import pytest
from lxml import etree

import fmugen
from fmugen.components.connectors import TYPES
from fmugen.components.equations import load_component
from fmugen.errors import FmugenError, InputFileError
from fmugen.fmi.build import build_fmu
from fmugen.fmi.platforms import host_platform
from fmugen.fmi.terminals import (FLOWS, TERMINAL_KINDS, TERMINALS_PATH, Member, Terminal, check_terminals,
                                  terminals_xml)
from fmugen.scene import load_scene
from fmugen.scene.errors import SceneError

ROOT = Path(__file__).resolve().parent.parent
SPLIT = ROOT / "examples" / "scenes" / "single_joint_split.toml"
PUMA = ROOT / "robots" / "puma_thesis_com.toml"
SPRING = ROOT / "fmugen" / "components" / "library" / "spring_damper.toml"  # a translational flange

pytestmark = pytest.mark.skipif(host_platform() != "linux64", reason="FMI 3.0 export: x86_64 Linux only so far")

SCHEMA = etree.XMLSchema(file=str(Path(fmpy.__file__).parent / "schema" / "fmi3" / "fmi3TerminalsAndIcons.xsd"))

URDF = """<robot name="two">
  <link name="base"/>
  <link name="upper"><inertial><origin xyz="0 0 0.2"/><mass value="2.0"/>
    <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.01"/></inertial></link>
  <link name="lower"><inertial><origin xyz="0 0 0.15"/><mass value="1.0"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.005"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="100" velocity="2"/></joint>
  <joint name="{elbow}" type="revolute"><parent link="upper"/><child link="lower"/>
    <origin xyz="0 0 0.4"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="50" velocity="2"/></joint>
</robot>
"""

#: the arm in an FMU of its own, an actuator and its valve in another, bonded with ``connect``; nothing drives
#: the arm's tau[1] (pruned: fixed at its start), the actuator's chamber pressure is read by nobody outside
BONDED = """
[scene]
name = "bonded"
fmi_version = {version}
stop = 0.1
record = ["arm.q[1]"]
connect = [["act.flange", "arm.elbow"], ["valve.port", "act.port"]]
[instances]
{arm} = {{ robot = "two.urdf" }}
act = {{ type = "hydraulic_actuator" }}
valve = {{ type = "servo_valve" }}
[fmus.arm]
members = ["arm"]
[fmus.drive]
members = ["act", "valve"]
"""


def _scene_file(tmp_path: Path, version=3, arm="arm", elbow="elbow") -> Path:
    (tmp_path / "two.urdf").write_text(URDF.format(elbow=elbow))
    p = tmp_path / "bonded.toml"
    p.write_text(BONDED.format(version=version, arm=arm))
    return p


def _terminals(fmu: Path):
    """(terminals {name: (element, [(variableName, memberName, variableKind)])}, modelDescription); the file
    validated against fmi3TerminalsAndIcons.xsd."""
    with zipfile.ZipFile(fmu) as z:
        root = etree.fromstring(z.read(TERMINALS_PATH))
    SCHEMA.assertValid(root)
    assert root.get("fmiVersion") == "3.0"
    out = {}
    for t in root.iter("Terminal"):
        assert t.get("name") not in out
        out[t.get("name")] = (t, [(m.get("variableName"), m.get("memberName"), m.get("variableKind"))
                                  for m in t.iter("TerminalMemberVariable")])
    return out, fmpy.read_model_description(str(fmu))


def _check_members(terminals, md) -> None:
    """Every member an input or output of the FMU (the standard's restriction), its kind what its causality
    and role say: potentials signal, the flow outflow where the FMU computes it, inflow where it takes it."""
    causality = {v.name: v.causality for v in md.modelVariables}
    for name, (el, members) in terminals.items():
        kind = next(k for k, v in TERMINAL_KINDS.items() if v == el.get("terminalKind"))
        assert el.get("matchingRule") == "bus" and members, name
        for var, member, vkind in members:
            assert causality.get(var) in ("input", "output"), (name, var)
            assert member in TYPES[kind]["vars"]
            want = "signal" if member != FLOWS[kind] else {"output": "outflow", "input": "inflow"}[causality[var]]
            assert vkind == want, (name, var)


@pytest.fixture(scope="module")
def split_fmus(tmp_path_factory):
    d = tmp_path_factory.mktemp("fmi3_terminals_split")
    built = load_scene(SPLIT, set={"scene.fmi_version": 3}).build(d, use_cache=False)
    return {g: Path(f.path) for g, f in built.fmus.items()}


@pytest.fixture(scope="module")
def bonded(tmp_path_factory):
    d = tmp_path_factory.mktemp("fmi3_terminals_bonded")
    built = load_scene(_scene_file(d)).build(d / "out", use_cache=False)
    return built, {g: Path(f.path) for g, f in built.fmus.items()}


def test_split_scene_groups_have_their_connectors_as_terminals(split_fmus):
    chain, md = _terminals(split_fmus["chain"])
    _check_members(chain, md)
    # five instances: names qualified; the valve's and the actuator's ports are bonded inside the FMU
    # (P_L and Q_L connected between its members), so the actuator's flange is its one terminal
    assert {n: m for n, (_, m) in chain.items()} == {
        "actuator.flange": [("actuator.w", "w", "signal"), ("actuator.tau", "tau", "outflow")]}
    assert chain["actuator.flange"][0].get("terminalKind") == "org.fmugen.RotationalFlange"
    joint, md = _terminals(split_fmus["joint"])
    _check_members(joint, md)
    # one instance: its own names, the flange whole (the angle too: the amplifier reads it)
    assert {n: m for n, (_, m) in joint.items()} == {
        "flange": [("theta", "phi", "signal"), ("w", "w", "signal"), ("tau", "tau", "inflow")]}


def test_bonded_scene_terminals_follow_the_fmus_interface(bonded):
    built, fmus = bonded
    arm, md = _terminals(fmus["arm"])
    _check_members(arm, md)
    names = {v.name for v in md.modelVariables}
    # tau[1] is pruned (nothing drives it): not in the FMU, not in joint[1]; joint[2] keeps its torque
    assert "tau[1]" not in names and "tau[2]" in names
    assert arm["joint[1]"][1] == [("q[1]", "phi", "signal"), ("qd[1]", "w", "signal")]
    assert arm["joint[2]"][1] == [("q[2]", "phi", "signal"), ("qd[2]", "w", "signal"), ("tau[2]", "tau", "inflow")]
    assert set(arm) == {"joint[1]", "joint[2]"}  # the URDF names are the same connectors, not two more
    assert "elbow" in arm["joint[2]"][0].get("description")
    drive, md = _terminals(fmus["drive"])
    _check_members(drive, md)
    assert {n: m for n, (_, m) in drive.items()} == {
        "act.flange": [("act.w", "w", "signal"), ("act.tau", "tau", "outflow")]}
    # the bond act.flange <-> arm.elbow is the master's couplings between the two terminals, member by member
    by_member = {m: v for v, m, _ in arm["joint[2]"][1]}
    pairs = {(c.source[1], c.target[1]) for c in built.system.couplings}
    for var, member, kind in drive["act.flange"][1]:
        assert ((var, by_member[member]) if kind == "outflow" else (by_member[member], var)) in pairs


def test_robot_fmu_has_one_terminal_per_joint_and_fmi2_has_none(tmp_path):
    m = fmugen.load_robot(str(PUMA)).state_space_model()
    p3 = build_fmu(m, tmp_path / "puma3.fmu", fmi_version=3).path
    terms, md = _terminals(p3)
    _check_members(terms, md)
    assert list(terms) == [f"joint[{k}]" for k in range(1, 7)]
    for k in range(1, 7):
        el, members = terms[f"joint[{k}]"]
        assert el.get("terminalKind") == "org.fmugen.RotationalFlange"
        assert members == [(f"q[{k}]", "phi", "signal"), (f"qd[{k}]", "w", "signal"), (f"tau[{k}]", "tau", "inflow")]
    # FMI 2.0 has no terminals: the FMU of the same model is as before, without the folder
    p2 = build_fmu(m, tmp_path / "puma2.fmu").path
    assert not any(n.startswith("terminalsAndIcons") for n in zipfile.ZipFile(p2).namelist())
    # terminals=() asks for none: no file, even for a robot
    p0 = build_fmu(m, tmp_path / "puma3_none.fmu", fmi_version=3, terminals=()).path
    assert not any(n.startswith("terminalsAndIcons") for n in zipfile.ZipFile(p0).namelist())


def test_fmi2_scene_fmus_have_no_terminals(tmp_path):
    built = load_scene(_scene_file(tmp_path, version=2)).build(tmp_path / "out", use_cache=False)
    for f in built.fmus.values():
        assert not any(n.startswith("terminalsAndIcons") for n in zipfile.ZipFile(f.path).namelist())


def test_build_fmu_refuses_terminals_it_cannot_write(tmp_path):
    m = load_component(SPRING)
    good = Terminal("flange", TERMINAL_KINDS["translational"], (Member("F", "f", "inflow"),))
    with pytest.raises(FmugenError, match="FMI 2.0 has no terminals"):
        build_fmu(m, tmp_path / "x.fmu", terminals=[good])
    bad = [Terminal("flange", good.kind, (Member("no_such_variable", "f", "inflow"),))]
    with pytest.raises(FmugenError, match="not an input or output"):
        build_fmu(m, tmp_path / "x.fmu", fmi_version=3, terminals=bad)
    par = [v.name for v in m.parameters][0]
    with pytest.raises(FmugenError, match="not an input or output"):
        check_terminals([Terminal("flange", good.kind, (Member(par, "f", "inflow"),))], m)
    with pytest.raises(FmugenError, match="listed twice"):
        check_terminals([good, good], m)
    with pytest.raises(FmugenError, match="variableKind"):
        check_terminals([Terminal("flange", good.kind, (Member("F", "f", "flow"),))], m)
    with pytest.raises(FmugenError, match="control characters"):
        check_terminals([Terminal("fla\nnge", good.kind, good.members)], m)
    assert not list(tmp_path.iterdir())  # refused before anything was written


def test_hostile_names_are_refused_by_the_readers_and_escaped_by_the_writer(tmp_path):
    # the names a terminal is made of never reach the writer with XML metacharacters: instance names and
    # connector names are identifiers, URDF joint names letters, digits and _ . - /
    with pytest.raises(SceneError, match="ASCII identifier"):
        load_scene(_scene_file(tmp_path, arm='"a<b&c"'))
    with pytest.raises(SceneError, match="name must be"):
        load_scene(_scene_file(tmp_path, elbow="el&lt;b&amp;o&quot;w&gt;"))
    comp = SPRING.read_text()
    assert "[connectors.flange]" in comp
    (tmp_path / "c.toml").write_text(comp.replace("[connectors.flange]", '[connectors."fl<a&n\\"ge"]'))
    with pytest.raises(InputFileError, match="must be an identifier"):
        load_component(tmp_path / "c.toml")
    # the writer escapes whatever it is given: the text parses back as it was, the file validates
    name, var = 'j<1>&"x\'', 'a.b[1]&<c>'
    text = terminals_xml([Terminal(name, "org.fmugen.RotationalFlange", (Member(var, "tau", "inflow"),),
                                   description='</Terminal><!-- & ]]> \x01')])
    root = etree.fromstring(text.encode())
    SCHEMA.assertValid(root)
    t = root.find("Terminals/Terminal")
    assert t.get("name") == name and t.find("TerminalMemberVariable").get("variableName") == var
    assert t.get("description") == "</Terminal><!-- & ]]> ?"  # XML 1.0 cannot carry \x01: '?', as elsewhere


def test_terminal_kinds_cover_every_connector_type():
    assert set(TERMINAL_KINDS) == set(FLOWS) == set(TYPES)
    assert all(FLOWS[t] in TYPES[t]["vars"] for t in TYPES)
    assert all(k.startswith("org.fmugen.") for k in TERMINAL_KINDS.values())


def test_a_component_file_built_alone_has_its_connectors_as_terminals(tmp_path):
    """fmugen build of a component file with --fmi-version 3: its declared connector (the spring-damper's
    translational flange: s, v given, the force F taken as an input) is the FMU's terminal."""
    from fmugen.cli import main

    out = tmp_path / "spring3.fmu"
    assert main(["build", str(SPRING), "--fmi-version", "3", "-o", str(out)]) == 0
    terminals, md = _terminals(out)
    assert set(terminals) == {"flange"}
    _check_members(terminals, md)
    assert [(m[1], m[2]) for m in terminals["flange"][1]] == [("s", "signal"), ("v", "signal"), ("f", "inflow")]
