"""Bad robot files: every error names the file, the link and the field.

Each case writes a small robot file into tmp_path that differs from a valid
two-link arm in one field, and checks the message of the RobotFileError.
"""
import re
import warnings

import numpy as np
import pytest

from fmugen.robot import RobotFileError, UnrealisableInertiaWarning, load_robot_description
from fmugen.robot.checks import inertia_problems

ROBOTS = __import__("pathlib").Path(__file__).resolve().parents[1] / "robots"

BASE_LINK = {
    "joint": '"revolute"',
    "a": "0.4",
    "alpha": '"pi/2"',
    "d": "0.1",
    "theta": "0",
    "mass": "2.0",
    "com": "[-0.2, 0, 0]",
    "inertia": "[[0.001, 0, 0], [0, 0.03, 0], [0, 0, 0.03]]",
}


def write_robot(tmp_path, link2=None, robot=None, drop2=(), extra="", parameters=""):
    """A valid 2-link file with link 2 ('elbow') changed by ``link2`` (field -> TOML text)."""
    head = {"name": '"twolink"', "gravity": "[0, 0, -9.81]"}
    head.update(robot or {})
    lines = ["[robot]"] + [f"{k} = {v}" for k, v in head.items() if v is not None]
    if parameters:
        lines += ["", "[parameters]", parameters]
    for i, changes in ((1, {}), (2, link2 or {})):
        fields = dict(BASE_LINK, name='"shoulder"' if i == 1 else '"elbow"')
        fields.update(changes)
        lines += ["", "[[links]]"] + [
            f"{k} = {v}" for k, v in fields.items() if v is not None and not (i == 2 and k in drop2)
        ]
    path = tmp_path / "bad_arm.toml"
    path.write_text("\n".join(lines) + "\n" + extra)
    return path


def expect_error(path, *fragments):
    with pytest.raises(RobotFileError) as info:
        load_robot_description(path)
    msg = str(info.value)
    assert str(path) in msg, msg
    for f in fragments:
        assert f in msg, f"{f!r} not in {msg!r}"
    return msg


LINK2 = "link 2 (elbow)"


def test_the_base_file_is_valid(tmp_path):
    robot = load_robot_description(write_robot(tmp_path))
    assert robot.n == 2 and robot.links[1].name == "elbow"


def test_unknown_joint_type(tmp_path):
    p = write_robot(tmp_path, {"joint": '"revolut"'})
    expect_error(p, LINK2, "joint", "'revolut'", "did you mean 'revolute'")


def test_missing_field(tmp_path):
    p = write_robot(tmp_path, drop2=("mass",))
    expect_error(p, LINK2, "missing required field", "mass")


def test_extra_field_with_suggestion(tmp_path):
    p = write_robot(tmp_path, {"dampng": "0.1"})
    expect_error(p, LINK2, "unknown field 'dampng'", "did you mean 'damping'")


def test_unknown_top_level_and_robot_fields(tmp_path):
    expect_error(write_robot(tmp_path, robot={"gravty": "[0, 0, -9.81]"}), "[robot]", "'gravty'", "'gravity'")
    expect_error(write_robot(tmp_path, extra="\n[paylod]\nmass = 1\n"), "unknown field 'paylod'", "'payload'")


@pytest.mark.parametrize("text", ["inf", "nan", '"1/0"', '"log(0)"'])
def test_non_finite_numbers(tmp_path, text):
    p = write_robot(tmp_path, {"mass": text})
    expect_error(p, LINK2, "mass", "non-finite")


def test_non_finite_inertia_entry(tmp_path):
    p = write_robot(tmp_path, {"inertia": "[[0.001, 0, 0], [0, inf, 0], [0, 0, 0.03]]"})
    expect_error(p, LINK2, "inertia[1][1]", "non-finite")


def test_negative_mass(tmp_path):
    p = write_robot(tmp_path, {"mass": "-2.0"})
    expect_error(p, LINK2, "mass", "negative mass -2 kg")


def test_negative_mass_through_a_parameter(tmp_path):
    p = write_robot(tmp_path, {"mass": '"2*m"'}, parameters="m = -1.5")
    expect_error(p, LINK2, "mass", "negative mass -3 kg")


def test_zero_mass_needs_zero_inertia(tmp_path):
    # a zero mass must be declared (issue 9), and a declared massless link has no inertia
    expect_error(write_robot(tmp_path, {"mass": "0"}), LINK2, "mass", "massless = true")
    expect_error(write_robot(tmp_path, {"mass": "0", "massless": "true"}), LINK2, "inertia",
                 "zero mass but non-zero inertia")
    # ... and the joint it hangs on must still move something: here its rotor
    robot = load_robot_description(write_robot(tmp_path, {"mass": "0", "massless": "true", "inertia": "[0, 0, 0]",
                                                          "rotor_inertia": "0.01"}))
    assert robot.links[1].mass == 0


def test_negative_rotor_inertia_and_damping(tmp_path):
    expect_error(write_robot(tmp_path, {"rotor_inertia": "-0.1"}), LINK2, "rotor_inertia", "negative")
    expect_error(write_robot(tmp_path, {"damping": "-0.1"}), LINK2, "damping", "negative")


def test_inertia_not_symmetric(tmp_path):
    p = write_robot(tmp_path, {"inertia": "[[0.01, 0.001, 0], [0.002, 0.03, 0], [0, 0, 0.03]]"})
    expect_error(p, LINK2, "inertia", "not symmetric", "0.001", "0.002")


def test_symbolic_inertia_not_symmetric(tmp_path):
    p = write_robot(tmp_path, {"inertia": '[["J", "c", 0], ["-c", "J", 0], [0, 0, "J"]]'})
    expect_error(p, LINK2, "inertia", "not symmetric")


def test_inertia_not_positive_semidefinite(tmp_path):
    # eigenvalues of [[0.01, 0.02], [0.02, 0.01]] are -0.01 and 0.03
    p = write_robot(tmp_path, {"inertia": "[[0.01, 0.02, 0], [0.02, 0.01, 0], [0, 0, 0.03]]"})
    msg = expect_error(p, LINK2, "inertia", "not positive semidefinite", "allow_unrealisable_inertia")
    moments = [float(x) for x in re.search(r"principal moments ([^)]*) kg", msg).group(1).split(",")]
    assert np.allclose(moments, [-0.01, 0.03, 0.03])


def test_inertia_violates_triangle_inequality(tmp_path):
    p = write_robot(tmp_path, {"inertia": "[0.01, 0.01, 0.03]"})
    expect_error(p, LINK2, "inertia", "triangle inequality", "0.01 + 0.01 < 0.03")


def test_triangle_equality_within_tolerance_is_accepted(tmp_path):
    # a thin disc: Ix + Iy = Iz exactly (to rounding)
    robot = load_robot_description(write_robot(tmp_path, {"inertia": "[0.0125, 0.0125, 0.025]"}))
    assert robot.links[1].inertia_com[2][2] != 0


def test_opt_in_per_link_accepts_with_warning(tmp_path):
    p = write_robot(tmp_path, {"inertia": "[0.01, 0.01, 0.03]", "allow_unrealisable_inertia": "true"})
    with pytest.warns(UnrealisableInertiaWarning, match=r"link 2 \(elbow\).*triangle inequality"):
        load_robot_description(p)


def test_opt_in_for_the_robot_accepts_with_warning(tmp_path):
    p = write_robot(tmp_path, {"inertia": "[0.01, 0.01, 0.03]"}, robot={"allow_unrealisable_inertia": "true"})
    with pytest.warns(UnrealisableInertiaWarning, match=r"link 2 \(elbow\)"):
        load_robot_description(p)


@pytest.mark.parametrize(
    "expr, fragment",
    [
        ('"2*eval"', "'eval' is a Python builtin"),
        ('"__import__(\'os\').system(\'true\')"', "not allowed"),
        ('"m.real"', "attribute access is not allowed"),
        ('"open(1)"', "call of 'open' is not allowed"),
        ('"2 x"', "syntax error"),
        ('"double*2"', "C keyword"),
    ],
)
def test_invalid_expressions_and_symbol_names(tmp_path, expr, fragment):
    expect_error(write_robot(tmp_path, {"mass": expr}), LINK2, "mass", fragment)


@pytest.mark.parametrize("name, fragment", [('"2x"', "not a valid identifier"), ("sin", "reserved"),
                                            ("lambda", "keyword"), ("__x", "reserved"),
                                            ("_t0", "reserved for generated code"),
                                            ("q_1", "variable of the model"),
                                            ("f_ext_2_x", "variable of the model")])
def test_invalid_parameter_names(tmp_path, name, fragment):
    p = write_robot(tmp_path, parameters=f"{name} = 1.0")
    expect_error(p, "[parameters]", "invalid parameter name", fragment)


def test_convention_must_be_standard_or_modified(tmp_path):
    p = write_robot(tmp_path, robot={"convention": '"craig"'})
    expect_error(p, "[robot]: convention", "'craig'", "standard, modified")


@pytest.mark.parametrize("text", ["[0, -9.81]", "-9.81", '[0, 0, "g", 1]', "[0, 0, [1]]"])
def test_gravity_must_be_three_quantities(tmp_path, text):
    expect_error(write_robot(tmp_path, robot={"gravity": text}), "[robot]: gravity", "list of 3")


def test_gravity_component_must_parse(tmp_path):
    expect_error(write_robot(tmp_path, robot={"gravity": '[0, 0, "-g*"]'}), "[robot]: gravity[2]", "syntax error")


def test_vectors_and_matrices_have_the_right_shape(tmp_path):
    expect_error(write_robot(tmp_path, {"com": "[0, 0]"}), LINK2, "com", "list of 3")
    expect_error(write_robot(tmp_path, {"inertia": "[[1, 0], [0, 1]]"}), LINK2, "inertia", "3x3")
    expect_error(write_robot(tmp_path, {"gyration_sq": "[1, 2]", "inertia": None}), LINK2, "gyration_sq", "list of 3")


def test_exactly_one_inertia_form(tmp_path):
    p = write_robot(tmp_path, {"gyration_sq": "[0.01, 0.01, 0.01]"})
    expect_error(p, LINK2, "exactly one of 'inertia' and 'gyration_sq'")
    expect_error(write_robot(tmp_path, drop2=("inertia",)), LINK2, "exactly one")


def test_inertia_about_must_be_com_or_origin(tmp_path):
    expect_error(write_robot(tmp_path, {"inertia_about": '"centre"'}), LINK2, "inertia_about", "com, origin")


def test_types_are_checked(tmp_path):
    expect_error(write_robot(tmp_path, {"mass": "true"}), LINK2, "mass", "boolean")
    expect_error(write_robot(tmp_path, {"external_wrench": '"yes"'}), LINK2, "external_wrench", "true or false")
    expect_error(write_robot(tmp_path, {"a": "[1]"}), LINK2, "a:", "expected a number")


def test_duplicate_link_names(tmp_path):
    expect_error(write_robot(tmp_path, {"name": '"shoulder"'}), "link 2 (shoulder)", "duplicate link name")


def test_robot_name_must_be_an_identifier(tmp_path):
    expect_error(write_robot(tmp_path, robot={"name": '"two link"'}), "[robot]: name", "identifier")


def test_toml_syntax_error_names_the_file(tmp_path):
    p = tmp_path / "broken.toml"
    p.write_text("[robot]\nname = \n")
    expect_error(p, "TOML syntax error")


def test_payload_errors(tmp_path):
    expect_error(write_robot(tmp_path, extra="\n[payload]\nmass = -1\ncom = [0, 0, 0]\n"), "[payload]: mass", "negative")
    expect_error(write_robot(tmp_path, extra="\n[payload]\nmass = 1\n"), "[payload]", "missing", "com")


def test_auto_parameter_name_clash_with_user_symbol(tmp_path):
    # link 1's mass 2.0 becomes parameter m_1; link 2 may not use a symbol m_1
    p = write_robot(tmp_path, {"mass": '"m_1"'}, parameters="m_1 = 3.0")
    expect_error(p, "link 1 (shoulder): mass", "'m_1'", "clashes")


# ------------------------------------------------------------------ PUMA data
def test_puma_thesis_link2_refused_without_opt_in(tmp_path):
    text = (ROBOTS / "puma_thesis.toml").read_text()
    assert text.count("allow_unrealisable_inertia = true") == 1
    p = tmp_path / "puma_no_opt_in.toml"
    p.write_text(text.replace("allow_unrealisable_inertia = true", ""))
    msg = expect_error(p, "link 2 (upper_arm)", "gyration_sq", "not positive semidefinite")
    # independent hand computation of the principal moments about the COM
    m, k2 = 77.3, np.array([565.7, 1847.0, 1408.0]) * 1e-4
    r = np.array([-21.6, 0.0, 21.75]) * 1e-2
    Ic = m * np.diag(k2) - m * (r @ r * np.eye(3) - np.outer(r, r))
    moments = [float(x) for x in re.search(r"principal moments ([^)]*) kg", msg).group(1).split(",")]
    assert np.allclose(moments, np.linalg.eigvalsh(Ic), rtol=1e-5)
    assert moments[0] < -0.89  # clearly negative, not a rounding artefact


def test_puma_thesis_accepted_with_warning_naming_link_2():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_robot_description(ROBOTS / "puma_thesis.toml")
    unreal = [w for w in caught if issubclass(w.category, UnrealisableInertiaWarning)]
    assert len(unreal) == 1
    assert "link 2 (upper_arm)" in str(unreal[0].message)
    assert "puma_thesis.toml" in str(unreal[0].message)


def test_puma_thesis_com_loads_silently():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        robot = load_robot_description(ROBOTS / "puma_thesis_com.toml")
    values = robot.parameter_values()
    for link in robot.links:
        m = float(link.mass.subs(values))
        I = np.array([[float(e.subs(values)) for e in row] for row in link.inertia_com])
        assert inertia_problems(m, I) == []


# ------------------------------------------------------- inertia_problems unit
def test_inertia_problems_on_known_bodies():
    # a solid box 0.1 x 0.2 x 0.3 m of 2 kg: realisable
    m, (A, B, C) = 2.0, (0.1, 0.2, 0.3)
    box = m / 12 * np.diag([B**2 + C**2, A**2 + C**2, A**2 + B**2])
    assert inertia_problems(m, box) == []
    # the same tensor rotated: still realisable (checks use principal moments)
    c, s = np.cos(0.7), np.sin(0.7)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    assert inertia_problems(m, R @ box @ R.T) == []
    # diag(1, 1, 3) about principal axes violates 1 + 1 >= 3; rotated it still must
    assert "triangle" in inertia_problems(1.0, R @ np.diag([1.0, 1.0, 3.0]) @ R.T)[0]
    assert "not positive semidefinite" in inertia_problems(1.0, np.diag([-1.0, 1.0, 1.0]))[0]
