"""Issue 9, classes 2, 3, 7, 8 (names, J), 9 and 10: bad values are refused
where they are read, with the file, the entry, the field and the reason.

Every case is a reproduction from the issue or a variant of it, and asserts
the specific error (class and message fragments), never just "some error".
"""
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import fmugen
from fmugen.errors import FmugenError, InputFileError
from fmugen.robot import RobotFileError, load_robot_description
from fmugen.robot.checks import mass_matrix_numeric
from fmugen.robot.expressions import MAX_DEPTH, MAX_NODES, ExpressionError, quantity

ROOT = Path(__file__).resolve().parents[1]
STIFF = ROOT / "examples" / "single_joint_stiff.toml"

LINK = {
    "joint": '"revolute"', "a": "0.4", "alpha": "0", "d": "0", "theta": "0",
    "mass": "2.0", "com": "[-0.2, 0, 0]", "inertia": "[0.001, 0.03, 0.03]",
}


def robot_file(tmp_path, link2=None, parameters="", name='"twolink"', n_links=2):
    lines = ["[robot]", f"name = {name}", "gravity = [0, 0, -9.81]"]
    if parameters:
        lines += ["[parameters]", parameters]
    for i in range(1, n_links + 1):
        fields = dict(LINK, name=f'"l{i}"')
        if i == n_links:
            fields.update(link2 or {})
        lines += ["[[links]]"] + [f"{k} = {v}" for k, v in fields.items()]
    p = tmp_path / "arm.toml"
    p.write_text("\n".join(lines) + "\n")
    return p


def refused(path, *fragments, cls=RobotFileError):
    with pytest.raises(cls) as info:
        load_robot_description(path)
    msg = str(info.value)
    assert str(path) in msg, msg
    for f in fragments:
        assert f in msg, f"{f!r} not in {msg!r}"
    assert "\n" not in msg
    return msg


# --------------------------------------------------------------------------
# non-finite values (issue item 2)
# --------------------------------------------------------------------------
@pytest.mark.parametrize("text", ['"1e308*10"', '"exp(1000)"', '"1e200*1e200"', '"1e160*1e160"',
                                  '"2**60*1e300"'])
def test_overflowing_quantities_are_refused_at_load(tmp_path, text):
    refused(robot_file(tmp_path, {"mass": text}), "link 2 (l2): mass", "not a finite double-precision number")


@pytest.mark.parametrize("text", ["nan", "inf", "-inf"])
def test_toml_nan_and_inf_are_refused(tmp_path, text):
    refused(robot_file(tmp_path, {"a": text}), "link 2 (l2): a", "non-finite")


def test_overflow_through_a_parameter_value_names_the_expression(tmp_path):
    p = robot_file(tmp_path, {"mass": '"m*1e10"'}, parameters="m = 1e300")
    refused(p, "link 2 (l2): mass", "'m*1e10' with the [parameters] values", "not a finite double")
    p = robot_file(tmp_path, {"mass": '"m"'}, parameters='m = "1e308*10"')
    refused(p, "[parameters]: m: value", "not a finite double")


def test_large_but_finite_values_still_load(tmp_path):
    # the check is about doubles, not taste: 1e300 is a double
    robot = load_robot_description(robot_file(tmp_path, {"d": '"1e150*1e150"'}))
    assert float(robot.links[1].d.subs({p.symbol: p.value for p in robot.parameters})) == 1e300


# --------------------------------------------------------------------------
# expression size (issue item 3): a clear message, never RecursionError
# --------------------------------------------------------------------------
def balanced(depth):
    return "1" if depth == 0 else f"({balanced(depth - 1)}+{balanced(depth - 1)})"


@pytest.mark.parametrize("text, fragment", [
    ("+".join(["1"] * 999), "nested too deeply"),
    ("-" * 1500 + "1", "nested too deeply"),
    ("(" * 400 + "1" + ")" * 400, "nested too deeply"),
    ("sqrt(" * 300 + "1" + ")" * 300, "nested too deeply"),
    (balanced(8), "too long"),  # 511 nodes, but only 9 levels deep
])
def test_expression_size_is_bounded(text, fragment):
    assert len(text) <= 2000
    with pytest.raises(ExpressionError, match=fragment) as info:
        quantity(text)
    assert isinstance(info.value, FmugenError) and isinstance(info.value, ValueError)
    assert str(MAX_DEPTH) in str(info.value) or str(MAX_NODES) in str(info.value)


def test_expressions_within_the_bounds_still_parse():
    assert quantity("+".join(["1"] * 40)) == 40
    assert quantity("-" * 40 + "2") == 2
    assert quantity(balanced(5)) == 32


def test_deep_expression_in_a_robot_file_names_file_and_field(tmp_path):
    p = robot_file(tmp_path, {"mass": '"' + "+".join(["1"] * 999) + '"'})
    refused(p, "link 2 (l2): mass", "nested too deeply")


# --------------------------------------------------------------------------
# massless and zero-inertia chains (issue item 7)
# --------------------------------------------------------------------------
def test_zero_mass_must_be_declared(tmp_path):
    refused(robot_file(tmp_path, {"mass": "0", "inertia": "[0, 0, 0]"}), "link 2 (l2): mass", "massless = true")


def test_declared_massless_link_that_leaves_a_joint_without_inertia_is_refused(tmp_path):
    p = robot_file(tmp_path, {"mass": "0", "inertia": "[0, 0, 0]", "massless": "true"})
    refused(p, "link 2 (l2)", "mass matrix is singular", "joint 2")


def test_declared_massless_link_with_a_rotor_loads_and_evaluates(tmp_path):
    p = robot_file(tmp_path, {"mass": "0", "inertia": "[0, 0, 0]", "massless": "true", "rotor_inertia": "0.05"})
    arm = fmugen.load_robot(p)
    M = arm.mass_matrix(np.array([0.3, -0.7]))
    assert M[1, 1] == pytest.approx(0.05, rel=1e-12)  # only the rotor moves with joint 2
    assert np.all(np.linalg.eigvalsh(M) > 0)


def test_point_mass_on_the_joint_axis_is_refused(tmp_path):
    # a single link: mass on the axis of joint 1 and no inertia -> M = 0
    p = robot_file(tmp_path, {"com": "[0, 0, 0]", "inertia": "[0, 0, 0]", "a": "0"}, n_links=1)
    refused(p, "link 1 (l1)", "mass matrix is singular", "joint 1")


def test_massless_flag_contradicting_the_mass_is_refused(tmp_path):
    refused(robot_file(tmp_path, {"massless": "true"}), "link 2 (l2): massless", "a massless link has mass = 0")


def test_numeric_mass_matrix_of_the_check_matches_the_derivation():
    """The independent M(q) of the well-posedness check equals the symbolic one (PUMA, q random)."""
    from fmugen.robot.checks import numeric, numeric_matrix

    arm = fmugen.load_robot(ROOT / "robots" / "puma_thesis.toml")
    robot = arm.robot if hasattr(arm, "robot") else arm.description
    values = {p.symbol: p.value for p in robot.parameters}
    links = [dict(prismatic=L.joint == "prismatic", a=numeric(L.a, values), alpha=numeric(L.alpha, values),
                  d=numeric(L.d, values), theta=numeric(L.theta, values), mass=numeric(L.mass, values),
                  com=[numeric(c, values) for c in L.com],
                  inertia=numeric_matrix([list(r) for r in L.inertia_com], values),
                  rotor=numeric(L.rotor_inertia, values)) for L in robot.links]
    q = np.random.default_rng(1).uniform(-2, 2, len(links))
    payload = None
    if robot.payload is not None:
        payload = (numeric(robot.payload.mass, values), [numeric(c, values) for c in robot.payload.com])
    M = mass_matrix_numeric(links, q, robot.convention == "modified", payload)
    assert np.allclose(M, arm.mass_matrix(q), rtol=1e-10, atol=1e-12)


# --------------------------------------------------------------------------
# messages that can be acted on (issue item 9)
# --------------------------------------------------------------------------
def test_rotated_inertia_symmetric_to_the_last_bit_loads(tmp_path):
    c, s = math.cos(0.3), math.sin(0.3)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    I = R @ np.diag([0.001, 0.002, 0.0025]) @ R.T
    I[1, 0] = np.nextafter(I[0, 1], 1)  # differ in the last bit, as a rotated tensor does
    assert I[0, 1] != I[1, 0]
    rows = "[" + ", ".join("[" + ", ".join(repr(float(v)) for v in row) + "]" for row in I) + "]"
    robot = load_robot_description(robot_file(tmp_path, {"inertia": rows}))
    assert robot.links[1].inertia_com[0][1] == robot.links[1].inertia_com[1][0]


def test_really_asymmetric_inertia_prints_every_digit(tmp_path):
    rows = "[[0.001, 0.000769340545513206, 0], [0.000769340545513207, 0.002, 0], [0, 0, 0.0025]]"
    # a relative difference of 1e-15 of the largest entry is symmetric ...
    load_robot_description(robot_file(tmp_path, {"inertia": rows}))
    rows = "[[0.001, 0.0007693405, 0], [0.0007693406, 0.002, 0], [0, 0, 0.0025]]"
    # ... 1e-10 absolute (4e-8 of the largest entry) is not, and the message shows the numbers apart
    refused(robot_file(tmp_path, {"inertia": rows}), "link 2 (l2): inertia", "not symmetric",
            "= 0.0007693405 but", "= 0.0007693406")


def test_binary_file_is_named(tmp_path):
    p = tmp_path / "arm.toml"
    p.write_bytes(b"[robot]\nname = \"x\"\n\xff\xfe\x00\x01 binary")
    msg = refused(p, "not a UTF-8 text file", cls=InputFileError)
    assert "offset" in msg
    with pytest.raises(ValueError):  # still a ValueError for old callers
        fmugen.load_robot(p)


def test_missing_file_is_the_projects_error(tmp_path):
    p = tmp_path / "nope.toml"
    with pytest.raises(InputFileError, match="no such robot file"):
        fmugen.load_robot(p)


def test_unknown_unit_names_the_file_and_parameter(tmp_path):
    p = robot_file(tmp_path, {"mass": '"m"'}, parameters='m = { value = 2.0, unit = "furlong" }')
    refused(p, "[parameters]: m: unit", "furlong")


def test_long_robot_name_is_refused(tmp_path):
    refused(robot_file(tmp_path, name='"' + "a" * 300 + '"'), "[robot]: name", "at most 64 characters")


# --------------------------------------------------------------------------
# components, parameter sets and assemblies
# --------------------------------------------------------------------------
def assembly(tmp_path, old="", new="", extra=""):
    text = STIFF.read_text().replace(old, new) + extra
    p = tmp_path / "rig.toml"
    p.write_text(text, encoding="utf-8")
    return p


def load_refused(path, *fragments):
    from fmugen.components.assembly import load_assembly

    with pytest.raises(InputFileError) as info:
        load_assembly(path)
    msg = str(info.value)
    assert str(path) in msg, msg
    for f in fragments:
        assert f in msg, f"{f!r} not in {msg!r}"
    return msg


@pytest.mark.parametrize("override, fragment", [
    ("J = -2.0", "J = -2.0 is not > 0"),
    ("J = 0.0", "J = 0.0 is not > 0"),
    ("B_m = -1.0", "B_m = -1.0 is negative"),
    ("J = nan", "non-finite"),
    ("J = inf", "non-finite"),
])
def test_assembly_overrides_are_checked(tmp_path, override, fragment):
    p = assembly(tmp_path, extra=f"\n[components.joint.parameters]\n{override}\n")
    load_refused(p, "[components.joint]", fragment)


@pytest.mark.parametrize("section, line, fragment", [
    ("hydraulic_actuator", "V_t = -1e-5", "[hydraulic_actuator] V_t = -1e-05 is not > 0"),
    ("hydraulic_actuator", "beta_e = 0.0", "[hydraulic_actuator] beta_e = 0.0 is not > 0"),
    ("servo_valve", "P_s = -14e6", "[servo_valve] P_s = -14000000.0 is not > 0"),
    ("joint_inertia", "J = -2.0", "[joint_inertia] J = -2.0 is not > 0"),
])
def test_parameter_set_files_are_checked(tmp_path, section, line, fragment):
    from fmugen.components.parameters import load_parameter_set

    src = (ROOT / "fmugen" / "components" / "data" / "stiff.toml").read_text()
    key = line.split()[0]
    text = "\n".join(line if ln.startswith(key + " ") else ln for ln in src.splitlines())
    p = tmp_path / "bad_set.toml"
    p.write_text(text)
    with pytest.raises(InputFileError) as info:
        load_parameter_set(p)
    assert str(p) in str(info.value) and fragment in str(info.value), str(info.value)


def test_api_override_is_checked():
    from fmugen.components.joint import joint_inertia

    with pytest.raises(FmugenError, match=r"joint_inertia: parameter override J = -2 is not > 0"):
        joint_inertia(overrides={"J": -2})
    with pytest.raises(FmugenError, match="is not finite"):
        joint_inertia(overrides={"J": float("nan")})


@pytest.mark.parametrize("name, fragment", [
    ('"r\u00e9sum\u00e9"', "'\u00e9' are not allowed"),
    ('"' + "a" * 300 + '"', "got 300 characters"),
    ('"rig name"', "' ' are not allowed"),
])
def test_assembly_names_are_ascii_identifiers_of_bounded_length(tmp_path, name, fragment):
    p = assembly(tmp_path, 'name = "single_joint_stiff"', f"name = {name}")
    load_refused(p, "[assembly] name must be a C identifier", fragment)


def test_unicode_instance_name_is_refused(tmp_path):
    p = assembly(tmp_path, "[components.joint]", '[components."j\u00f6int"]')
    load_refused(p, "[components.j\u00f6int]: the instance name must be a C identifier")


def test_assembly_binary_and_missing_files(tmp_path):
    from fmugen.components.assembly import load_assembly

    p = tmp_path / "b.toml"
    p.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00")
    load_refused(p, "not a UTF-8 text file")
    with pytest.raises(InputFileError, match="no such assembly file"):
        load_assembly(tmp_path / "missing.toml")


# --------------------------------------------------------------------------
# the two-chamber actuator's stroke (issue item 10)
# --------------------------------------------------------------------------
def test_two_chamber_stroke_beyond_the_volumes_is_refused():
    from fmugen.components.hydraulic_actuator import hydraulic_actuator

    # stiff set: V_t = 1e-5 m3, D_m = 1.5e-5 m3/rad -> volumes allow |theta| < 1/3 rad
    with pytest.raises(FmugenError, match=r"stroke = 0\.4 rad .*V_t/2 - D_m\*stroke = -1e-06 m3 <= 0.*"
                                          r"\|position\| < 0\.333333 rad"):
        hydraulic_actuator(form="two_chamber", parameter_set="stiff", overrides={"stroke": 0.4})


def test_two_chamber_declares_the_range_its_volumes_allow():
    from fmugen.components.hydraulic_actuator import hydraulic_actuator

    m = hydraulic_actuator(form="two_chamber", parameter_set="stiff")
    theta = {v.name: v for v in m.inputs}["theta"]
    assert theta.max == pytest.approx(1e-5 / (2 * 1.5e-5), rel=1e-15) and theta.min == -theta.max
    m = hydraulic_actuator(form="two_chamber", parameter_set="stiff", overrides={"stroke": 0.3})
    assert {v.name: v for v in m.inputs}["theta"].max == 0.3
    P = {v.name: v for v in m.states}
    assert P["P_A"].min == -0.9e5 and P["P_A"].max == 14e6
    lp = hydraulic_actuator(parameter_set="stiff")
    assert lp.states[0].min == -14e6 and lp.states[0].max == 14e6


# --------------------------------------------------------------------------
# the command line: one line, exit status 2, for every user error
# --------------------------------------------------------------------------
def cli(*args):
    return subprocess.run([sys.executable, "-m", "fmugen.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=ROOT)


@pytest.mark.parametrize("cmd", [["equations"], ["build", "--fmi-type", "cs"], ["info"]])
def test_cli_missing_and_binary_files_exit_2_with_one_line(tmp_path, cmd):
    r = cli(*cmd, tmp_path / "missing.toml")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "missing.toml" in r.stderr, r.stderr
    b = tmp_path / "bin.toml"
    b.write_bytes(b"\x00\xff\xfe binary")
    r = cli(*cmd, b)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "not a UTF-8 text file" in r.stderr, r.stderr


def test_cli_deep_expression_and_bad_assembly_exit_2(tmp_path):
    p = robot_file(tmp_path, {"mass": '"' + "-" * 1500 + '2"'})
    for cmd in (["equations"], ["build", "--fmi-type", "cs", "-o", tmp_path / "x.fmu"]):
        r = cli(*cmd, p)
        assert r.returncode == 2 and "nested too deeply" in r.stderr and "Traceback" not in r.stderr, r.stderr
        assert r.stderr.count("\n") == 1
    a = assembly(tmp_path, 'name = "single_joint_stiff"', 'name = "r\u00e9sum\u00e9"')
    r = cli("build", a, "--fmi-type", "cs", "-o", tmp_path / "y.fmu")
    assert r.returncode == 2 and "must be a C identifier" in r.stderr and "Traceback" not in r.stderr


def test_bad_unit_of_a_table_trajectory_names_file_and_component(tmp_path):
    p = assembly(tmp_path, extra='\n[components.path]\ntype = "table_trajectory"\ntimes = [0.0, 1.0]\n'
                                 'values = [0.0, 1.0]\nunit = "furlong"\n')
    load_refused(p, "[components.path]", "furlong")


@pytest.mark.parametrize("name, fragment", [("\u00e4\u00e4\u00f6", "no ASCII letters or digits"),
                                            ("a" * 300, "at most 64 characters")])
def test_build_refuses_names_that_make_no_model_identifier(tmp_path, name, fragment):
    import dataclasses

    from fmugen.components.joint import joint_inertia
    from fmugen.fmi import build_fmu

    model = dataclasses.replace(joint_inertia(), name=name)
    with pytest.raises(FmugenError, match=fragment):
        build_fmu(model, tmp_path / "x.fmu")


def test_generator_names_the_variable_and_origin_of_a_bad_start(tmp_path):
    """Reached only through the API (files are refused earlier): the message still says where."""
    import dataclasses

    from fmugen.codegen.c_code import generate_c

    arm = fmugen.load_robot(robot_file(tmp_path))
    model = arm.state_space_model()
    bad = dataclasses.replace(model, parameters=(dataclasses.replace(model.parameters[0], start=float("inf")),)
                              + model.parameters[1:])
    with pytest.raises(ValueError, match=rf"from {tmp_path}.*parameter '{model.parameters[0].name}': "
                                         r"non-finite start value inf"):
        generate_c(bad)
    nostart = dataclasses.replace(model, states=(dataclasses.replace(model.states[0], start=None),)
                                  + model.states[1:])
    with pytest.raises(ValueError, match=rf"from {tmp_path}.*state 'q\[1\]' has no start value"):
        generate_c(nostart)


def test_cli_symbolic_parameter_without_value_names_the_file(tmp_path):
    r = cli("build", "robots/horn_2link.toml", "--fmi-type", "cs", "-o", tmp_path / "h.fmu")
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "robots/horn_2link.toml" in r.stderr and "parameter 'm' has no start value" in r.stderr, r.stderr


# --------------------------------------------------------------------------
# seeded random mutations of real files: only the project's errors come out
# --------------------------------------------------------------------------
MUTATION_VALUES = [
    "0", "-1", "1e308", '"1e308*10"', "nan", "inf", '"x"', '"m*"', "[]", "[1,2]", "{}", "true", '"\\u0000"',
    '"exp(exp(10))"', '"sqrt(-1)"', '"log(0)"', '"1/0"', '"0**-1"', '"(-8)**(1/3)"', '"abs(-1e309)"',
    '"tan(pi/2)"', '"10**64"', '"1e-400"', '"pi**64"', '"q_1"', '"_x"', "[[1,2,3],[4,5,6],[7,8]]", "-0.0",
    "12345678901234567890123", '""', '"' + "(" * 60 + "1" + ")" * 60 + '"', '"1' + "*1" * 150 + '"',
    '"' + "x" * 300 + '"', '["a", 1]', '"origin"',
]
EXTRA_KEYS = ["massless", "rotor_inertia", "damping", "inertia_about", "external_wrench", "zz", "type", "kind"]


def mutated(text, rng):
    lines = text.splitlines()
    for _ in range(rng.randint(1, 3)):
        i = rng.choice([k for k, ln in enumerate(lines) if "=" in ln and not ln.lstrip().startswith("#")])
        key = lines[i].split("=", 1)[0]
        r = rng.random()
        if r < 0.7:
            lines[i] = f"{key}= {rng.choice(MUTATION_VALUES)}"
        elif r < 0.8:
            del lines[i]
        elif r < 0.9:
            lines.insert(i, f"{rng.choice(EXTRA_KEYS)} = {rng.choice(MUTATION_VALUES)}")
        else:
            lines[i] = lines[i].replace("=", "==", 1)
    return "\n".join(lines) + "\n"


def test_mutated_robot_and_assembly_files_raise_only_fmugen_errors(tmp_path):
    """300 seeded mutations of robots/stanford_arm.toml and examples/single_joint_stiff.toml (values,
    types, deleted and added fields, broken syntax): each loads or raises an InputFileError/FmugenError
    -- found this way and fixed: a list as component type (TypeError), a 300-character set name
    (OSError), an overflowing mass matrix (LinAlgError)."""
    import random
    import warnings

    from fmugen.components.assembly import load_assembly

    rng = random.Random(9)
    bases = {"robot": (ROOT / "robots" / "stanford_arm.toml").read_text(), "assembly": STIFF.read_text()}
    outcomes = {"loaded": 0, "refused": 0}
    for k in range(300):
        kind = "robot" if rng.random() < 0.6 else "assembly"
        p = tmp_path / f"m{k}.toml"
        p.write_text(mutated(bases[kind], rng))
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                (load_robot_description if kind == "robot" else load_assembly)(p)
            outcomes["loaded"] += 1
        except FmugenError as exc:
            assert str(p) in str(exc) or "parameter set" in str(exc), str(exc)
            outcomes["refused"] += 1
    assert outcomes["refused"] > 150 and outcomes["loaded"] > 10, outcomes
