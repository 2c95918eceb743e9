"""Issue 27, classes 1 and 2: every reader takes numbers in its own format's grammar, and a sweep point
passes the checks a file value gets.

Python's ``float()`` reads ``1_5`` as 15, Arabic-Indic digits as digits, ``infinity`` and ``nan``; TOML
reads ``1_5`` and ``0x10``; Python's parser normalises full-width letters to ASCII (NFKC).  None of
those is a number of the format that holds it:

* URDF attributes are XML Schema values: one xs:double, or a white-space separated list of exactly
  three (``xyz="0 0 1"``) -- :func:`fmugen.values.parse_xs_double`;
* a number written as text (a robot file's expression string, ``--set``, ``--grid``/``--sample``,
  a command-line option) is a plain ASCII decimal -- :func:`fmugen.values.parse_decimal`.

Each refusal is one line naming the file (or option), the field and the problem.
"""
import math
import tempfile
from pathlib import Path

import pytest

from fmugen.arguments import count, number, number_list
from fmugen.errors import FmugenError, InputFileError
from fmugen.robot import RobotFileError, load_robot_description
from fmugen.robot.urdf import load_urdf
from fmugen.scene import SceneError, parse_sets
from fmugen.sweep.errors import SweepError
from fmugen.sweep.points import parse_grid, parse_samples
from fmugen.values import parse_decimal, parse_xs_double

ROOT = Path(__file__).resolve().parents[1]

URDF = """<?xml version="1.0"?>
<robot name="one">
  <link name="base"/>
  <link name="arm">
    <inertial><origin xyz="0.1 0 0"/><mass value="{mass}"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial>
  </link>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="arm"/><origin xyz="{xyz}" rpy="0 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="40" velocity="3"/>
  </joint>
</robot>
"""

# text -> why it is no number of the grammar (the non-ASCII ones: Arabic-Indic, full-width, superscript)
NOT_NUMBERS = ["1_5", "\u0663", "\uff11", "\u00b2", "infinity", "nan", "inf", "0x1p3", "0x10", "1,5", "", "1e",
               "--1", "1.2.3", "+-1", "1e1_0"]
NUMBERS = ["15", "1.5", ".5", "5.", "-2.5e-3", "+3E+2", "0", "-0.0", "007"]


def _urdf(tmp_path, mass="2.0", xyz="0 0 0.3"):
    p = tmp_path / "one.urdf"
    p.write_text(URDF.format(mass=mass, xyz=xyz), encoding="utf-8")
    return p


# ------------------------------------------------------------------------------------------ the grammars
@pytest.mark.parametrize("text", NUMBERS)
def test_plain_decimals_are_read_as_float_reads_them(text):
    # float() is the independent reference for the texts both grammars accept
    assert parse_decimal(text, "w") == float(text)
    assert parse_xs_double(text, "w") == float(text)


@pytest.mark.parametrize("text", NOT_NUMBERS)
def test_what_float_takes_but_the_grammars_do_not(text):
    for parse in (parse_decimal, parse_xs_double):
        with pytest.raises(FmugenError) as exc:
            parse(text, "f.toml: x")
        assert str(exc.value).startswith("f.toml: x: ") and "\n" not in str(exc.value)


def test_xs_double_specials_are_spelled_as_xml_schema_spells_them():
    assert math.isinf(parse_xs_double("-INF", "w", finite=False))
    assert math.isnan(parse_xs_double("NaN", "w", finite=False))
    with pytest.raises(InputFileError, match="INF is not a finite number"):
        parse_xs_double("INF", "w")


# ------------------------------------------------------------------------------------------ URDF
@pytest.mark.parametrize("mass", ["1_5", "\u0663", "infinity", "nan", "0x1p3", "1,5", "\uff12"])
def test_urdf_mass_in_pythons_grammar_is_refused(tmp_path, mass):
    p = _urdf(tmp_path, mass=mass)
    with pytest.raises(RobotFileError) as exc:
        load_urdf(p)
    msg = str(exc.value)
    assert msg.startswith(f"{p}: link 'arm': <inertial>: <mass>: value: ") and "is not an xs:double" in msg
    assert "\n" not in msg


def test_urdf_mass_in_schema_grammar_is_read(tmp_path):
    robot = load_urdf(_urdf(tmp_path, mass="1.5E0"))
    assert [p.value for p in robot.parameters if p.name == "m_arm"] == [1.5]


@pytest.mark.parametrize("xyz, problem", [
    ("0 0", "expected 3 numbers separated by spaces, found 2"),
    ("0 0 0.3 1", "expected 3 numbers separated by spaces, found 4"),
    ("0\u00a00 0.3", "expected 3 numbers separated by spaces, found 2"),  # a no-break space is not XML space
    ("0,0,0.3", "found 1"),
    ("0 0 1_5", "xyz[2]: '1_5' is not an xs:double"),
    ("0 NaN 0", "xyz[1]: NaN is not a finite number"),
])
def test_urdf_vectors_are_exactly_three_xs_doubles(tmp_path, xyz, problem):
    p = _urdf(tmp_path, xyz=xyz)
    with pytest.raises(RobotFileError) as exc:
        load_urdf(p)
    msg = str(exc.value)
    assert msg.startswith(f"{p}: joint 'j1': <origin>: ") and problem in msg and "\n" not in msg


def test_urdf_vector_with_xml_white_space_is_read(tmp_path):
    robot = load_urdf(_urdf(tmp_path, xyz="\t0  0\n0.3 "))
    vals = {p.name: p.value for p in robot.parameters}
    assert vals.get("p_j1_z") == 0.3


# ------------------------------------------------------------------------------------------ robot TOML
ROBOT = """[robot]
name = "one"
gravity = [0, 0, -9.81]
[parameters]
m = 2.0
[[links]]
name = "l1"
joint = "revolute"
a = 0.4
alpha = 0
d = 0
theta = 0
mass = {mass}
com = [-0.2, 0, 0]
inertia = [0.001, 0.03, 0.03]
"""


@pytest.mark.parametrize("mass, problem", [
    ('"1_5"', "the number '1_5' in '1_5' is not a decimal literal"),
    ('"0x10"', "the number '0x10'"),
    ('"0o17*m"', "the number '0o17'"),
    ('"\uff4d"', "non-ASCII character"),            # full-width m: NFKC would make it the parameter m
    ('"\U0001d426*2"', "non-ASCII character"),      # mathematical bold m
    ('"\u0663"', "non-ASCII character"),
])
def test_robot_file_number_strings_follow_the_decimal_grammar(tmp_path, mass, problem):
    p = tmp_path / "one.toml"
    p.write_text(ROBOT.format(mass=mass), encoding="utf-8")
    with pytest.raises(RobotFileError) as exc:
        load_robot_description(p)
    msg = str(exc.value)
    assert msg.startswith(str(p)) and "link 1 (l1): mass" in msg and problem in msg and "\n" not in msg


@pytest.mark.filterwarnings("ignore:.*declared but not used")
def test_robot_file_decimal_strings_and_toml_numbers_still_load(tmp_path):
    p = tmp_path / "one.toml"
    for mass, want in (('"1.5"', 1.5), ("1_5", 15.0), ('"0.5*m"', 1.0), ('"1e-1*m"', 0.2)):  # TOML's 1_5 is TOML
        p.write_text(ROBOT.format(mass=mass))
        robot = load_robot_description(p)
        vals = {q.symbol: q.value for q in robot.parameters}
        assert float(robot.links[0].mass.subs(vals)) == pytest.approx(want)


def test_component_file_expressions_are_ascii(tmp_path):
    from fmugen.components.equations import load_component

    text = (ROOT / "fmugen" / "components" / "library" / "pd.toml").read_text()
    bad = text.replace('"der(x_d) = (e - x_d)/T_f"', '"der(x_d) = (e - \uff58_d)/T_f"')
    assert bad != text
    p = tmp_path / "pd.toml"
    p.write_text(bad, encoding="utf-8")
    with pytest.raises(FmugenError) as exc:
        load_component(p)
    msg = str(exc.value)
    assert str(p) in msg and "non-ASCII character" in msg and "\n" not in msg


# ------------------------------------------------------------------------------------------ --set, sweeps, options
@pytest.mark.parametrize("value", ["1_5", "0x10", "0o17", "\u0663", "inf", "-nan", "1e999", "2024-01-01", "[1]"])
def test_set_values_follow_the_decimal_grammar(value):
    with pytest.raises(SceneError) as exc:
        parse_sets([f"joint.J={value}"])
    assert str(exc.value).startswith("--set joint.J=") and "\n" not in str(exc.value)


def test_set_values_that_are_numbers_words_or_strings():
    assert parse_sets(["a.b=5", "a.c=-2.5e-3", "a.d=PI", 'a.e="x y"', "a.f=true", "a.g=.5"]) == \
        {"a.b": 5, "a.c": -2.5e-3, "a.d": "PI", "a.e": "x y", "a.f": True, "a.g": 0.5}


@pytest.mark.parametrize("items, what", [
    (["joint.J=1_5"], "--grid joint.J: '1_5' is not a number"),
    (["joint.J=\u0661,2"], "--grid joint.J: '\u0661' is not a number"),  # \d took Arabic-Indic digits
    (["joint.J=linspace(\u0661,2,3)"], "linspace first: '\u0661' is not a number"),
    ({"joint.J": ["1_5"]}, "--grid joint.J: '1_5' is not a number"),
])
def test_grid_values_follow_the_decimal_grammar(items, what):
    with pytest.raises(SweepError) as exc:
        parse_grid(items)
    assert what in str(exc.value)


def test_sample_arguments_follow_the_decimal_grammar():
    with pytest.raises(SweepError, match="--sample joint.J: normal mean: '1_0' is not a number"):
        parse_samples(["joint.J=normal(1_0,0.1)"])


@pytest.mark.parametrize("call, text", [(number, "1_5"), (number, "\u0661"), (number, "infinity"),
                                        (count, "1_0"), (number_list, "1e-3,2_0")])
def test_command_line_numbers_follow_the_decimal_grammar(call, text):
    with pytest.raises(FmugenError) as exc:
        call(text, "--opt")
    assert str(exc.value).startswith(f"--opt {text!r}: ")
    assert number(" 2.5e-3 ", "--opt") == 2.5e-3 and count("1e3", "--n", high=10 ** 4) == 1000


# ------------------------------------------------------------------------------------------ sweep points
def test_sweep_points_get_the_checks_a_file_value_gets():
    """Negative and non-realisable inertias, negative damping: refused per point, the message naming the
    point and the swept parameter only (it listed every parameter of the robot)."""
    from fmugen.sweep.errors import PointRefused
    from fmugen.sweep.prepare import SweepPlan

    with tempfile.TemporaryDirectory() as d:
        plan = SweepPlan(ROOT / "examples" / "scenes" / "single_joint_split.toml",
                         ["joint.J", "joint.B_m", "joint.theta"], d)
        ok = {"joint.J": 1.0, "joint.B_m": 0.0, "joint.theta": 0.0}
        plan.check_point(0, ok)
        for change, said in ((("joint.J", -0.2), "refused: point 3: joint.J = -0.2 is not > 0"),
                             (("joint.B_m", -1e-3), "refused: point 3: joint.B_m = -0.001 is negative")):
            with pytest.raises(PointRefused) as exc:
                plan.check_point(3, {**ok, change[0]: change[1]})
            assert str(exc.value).startswith(said)


def test_a_robot_sweep_point_names_only_the_swept_inertia():
    from fmugen.sweep.errors import PointRefused
    from fmugen.sweep.prepare import SweepPlan

    with tempfile.TemporaryDirectory() as d:
        plan = SweepPlan(ROOT / "examples" / "scenes" / "ur5_electric.toml", ["arm.I_upper_arm_link_zz"], d)
        plan.check_point(0, {"arm.I_upper_arm_link_zz": 0.01})
        # I_zz = 1 > I_xx + I_yy = 2 x 0.2269: no rigid body has these principal moments
        with pytest.raises(PointRefused) as exc:
            plan.check_point(5, {"arm.I_upper_arm_link_zz": 1.0})
        msg = str(exc.value)
        assert msg.startswith("refused: point 5: arm: body 2 (upper_arm_link): not a realisable rigid body with "
                              "I_upper_arm_link_zz = 1.0: ") and "triangle inequality" in msg
        assert "m_shoulder_link" not in msg


def test_urdf_values_whose_mass_matrix_overflows_are_refused(tmp_path):
    """Each number a double, their product not: a centre of mass 1e200 m off gives m c^2 = inf (the
    reader's composite-body check computed with it, under numpy overflow warnings, and accepted)."""
    p = tmp_path / "one.urdf"
    p.write_text(URDF.format(mass="2.0", xyz="0 0 0.3").replace('<origin xyz="0.1 0 0"/>', '<origin xyz="1e200 0 0"/>'))
    with pytest.raises(RobotFileError) as exc:
        load_urdf(p)
    assert str(exc.value) == f"{p}: the mass matrix overflows double precision (at q = 0): masses, lengths or " \
                             f"inertias are too large"


def test_a_urdf_robot_value_that_leaves_a_joint_moving_nothing_is_refused():
    """The UR5's last link has its centre of mass on the wrist_3 axis: with its inertia set to zero (a point
    mass, realisable) the joint moves nothing, M_66 = 0 -- refused as the file's reader refuses it."""
    import fmugen
    from fmugen.robot.value_checks import robot_value_problem

    robot = fmugen.load_robot(ROOT / "robots" / "ur5.urdf").robot
    zero = {f"I_wrist_3_link_{a}": 0.0 for a in ("xx", "yy", "zz")}
    msg = robot_value_problem(robot, zero)
    assert msg.startswith("joint 'wrist_3_joint': moves no mass and no inertia about its axis") and \
        "the mass matrix is singular" in msg and msg.endswith("with I_wrist_3_link_xx = 0.0, "
                                                              "I_wrist_3_link_yy = 0.0, I_wrist_3_link_zz = 0.0")
    assert robot_value_problem(robot, {"I_wrist_3_link_yy": 0.02}) is None


def test_run_settings_and_memory_budgets_given_as_text_take_the_decimal_grammar():
    """Two readers of numbers as text float() still took: a run setting (fmugen.cosim.settings, reached by
    SSP annotations and the API) and `--budget-memory` (its number before the unit suffix)."""
    from fmugen.cli import _bytes
    from fmugen.cosim.errors import CosimError
    from fmugen.cosim.settings import _number

    assert _number("step", " 2.5e-3 ") == 2.5e-3 and _number("step", 3) == 3.0
    for bad in ("1_5", "\u0661", "0x10", "inf", "nan", ""):
        with pytest.raises(CosimError, match="step must be a number"):
            _number("step", bad)
    assert _bytes("1.5G") == 1.5 * 2**30 and _bytes("800M") == 800 * 2**20 and _bytes("4096") == 4096
    for bad in ("1_5G", "\u0663M", "0x10", "infM", "1,5G"):
        with pytest.raises(ValueError, match="a size such as 800M"):
            _bytes(bad)
