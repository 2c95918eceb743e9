"""Robot files load into the canonical description; the parser is safe; the chain is sound.

Numbers are checked against independent sources: textbook inertia of a solid
box about a corner and about its centre, the thesis's numbers converted by
hand, the uniform-rod formulas, and exact trigonometric values.
"""
import warnings
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

from fmugen.robot import (
    ExpressionError,
    chain_to_toml,
    load_robot_description,
    n_link_chain,
    robot_from_toml,
)
from fmugen.robot.checks import inertia_problems
from fmugen.robot.expressions import parse_expression, quantity, snap_angle

ROBOTS = Path(__file__).resolve().parents[1] / "robots"
SHIPPED = ["horn_2link", "freund_rp", "puma_thesis", "puma_thesis_com", "stanford_arm"]


def load(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # puma_thesis warns by design (tested elsewhere)
        return load_robot_description(ROBOTS / f"{name}.toml")


def free_symbols(robot):
    exprs = list(robot.gravity)
    for l in robot.links:
        exprs += [l.a, l.alpha, l.d, l.theta, l.mass, l.rotor_inertia, l.damping, *l.com]
        exprs += [e for row in l.inertia_com for e in row]
    if robot.payload:
        exprs += [robot.payload.mass, *robot.payload.com]
    return set().union(*(sp.sympify(e).free_symbols for e in exprs))


def num(expr, robot):
    return float(sp.sympify(expr).xreplace(robot.parameter_values()))


# ------------------------------------------------------------ shipped robots
@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_robot_loads_and_lists_every_symbol_once(name):
    robot = load(name)
    names = [p.name for p in robot.parameters]
    assert len(names) == len(set(names))
    assert {p.symbol for p in robot.parameters} == free_symbols(robot)
    for p in robot.parameters:
        assert p.symbol == sp.Symbol(p.name, real=True)
        if name in ("puma_thesis", "puma_thesis_com", "stanford_arm"):
            assert p.value is not None and p.unit and p.description


def test_horn_is_symbolic_as_in_the_report():
    robot = load("horn_2link")
    m, l, g = sp.symbols("m l g", real=True)
    assert [p.name for p in robot.parameters] == ["m", "l", "g"]
    assert all(p.value is None for p in robot.parameters)
    assert robot.gravity == (0, -g, 0)
    for link in robot.links:
        assert (link.a, link.alpha, link.d, link.theta) == (l, 0, 0, 0)
        assert link.com == (-l / 2, 0, 0)
        assert sp.Matrix(link.inertia_com) == sp.diag(0, m * l**2 / 12, m * l**2 / 12)


def test_freund_rod_and_disc():
    robot = load("freund_rp")
    disc, rod = robot.links
    lr, Ir, Idscz = sp.symbols("lr I_r Idscz", real=True)
    assert (disc.joint, rod.joint) == ("revolute", "prismatic")
    assert disc.alpha == -sp.pi / 2 and sp.cos(disc.alpha) == 0  # exact: y1 is vertical
    assert rod.com == (0, 0, -lr / 2)
    assert sp.Matrix(rod.inertia_com) == sp.diag(Ir, Ir, 0)
    assert disc.inertia_com[1][1] == Idscz  # about the vertical axis y1
    assert robot.gravity == (0, 0, -sp.Symbol("g", real=True))


def test_puma_numbers_are_the_thesis_numbers_in_si():
    robot = load("puma_thesis_com")
    # thesis CONST data (kg, cm, cm^2), converted here by hand
    m = [33.5, 77.3, 36.3, 8.95, 2.39, 1.00]
    k2 = np.array([[451.0, 451.0, 57.9], [565.7, 1847.0, 1408.0], [672.8, 679.1, 36.0],
                   [31.6, 21.1, 31.6], [6.9, 11.2, 6.9], [33.8, 33.8, 0.911]]) / 1e4
    rbar = np.array([[0, 0, 8.0], [-21.6, 0, 21.75], [0, 0, 21.6], [0, 2.0, 0], [0, 0, 0], [0, 0, 1.0]]) / 100
    d = np.array([0, 0, 12.5, 43.2, 0, 0]) / 100
    a = np.array([0, 43.2, 1.9, 0, 0, 0]) / 100
    alpha = [-sp.pi / 2, 0, sp.pi / 2, -sp.pi / 2, sp.pi / 2, 0]
    for i, link in enumerate(robot.links):
        assert link.alpha == alpha[i] and link.theta == 0
        assert num(link.a, robot) == pytest.approx(a[i], abs=1e-15)
        assert num(link.d, robot) == pytest.approx(d[i], abs=1e-15)
        assert num(link.mass, robot) == pytest.approx(m[i])
        assert [num(c, robot) for c in link.com] == pytest.approx(list(rbar[i]), abs=1e-15)
        I = np.array([[num(e, robot) for e in row] for row in link.inertia_com])
        assert np.allclose(I, m[i] * np.diag(k2[i]), rtol=1e-12, atol=0)
    assert robot.gravity == (0, 0, sp.Symbol("g_z", real=True))
    assert robot.parameter("g_z").value == -9.81


def test_puma_literal_reading_is_the_parallel_axis_shift_of_the_com_reading():
    lit, com = load("puma_thesis"), load("puma_thesis_com")
    for a, b in zip(lit.links, com.links):
        m = num(a.mass, lit)
        r = np.array([num(c, lit) for c in a.com])
        I_lit = np.array([[num(e, lit) for e in row] for row in a.inertia_com])
        I_o = np.array([[num(e, com) for e in row] for row in b.inertia_com])  # m diag(k2)
        # hand parallel axis, entry by entry: I_c,xx = I_o,xx - m (ry^2 + rz^2), I_c,xz = I_o,xz + m rx rz
        x, y, z = r
        expected = I_o - m * np.array([[y * y + z * z, -x * y, -x * z],
                                       [-x * y, x * x + z * z, -y * z],
                                       [-x * z, -y * z, x * x + y * y]])
        assert np.allclose(I_lit, expected, rtol=1e-12, atol=1e-15)
    # link 2 of the literal reading has an x-z product of inertia m * rx * rz
    assert num(lit.links[1].inertia_com[0][2], lit) == pytest.approx(77.3 * -0.216 * 0.2175)


def test_stanford_arm():
    robot = load("stanford_arm")
    assert [l.joint[0] for l in robot.links] == list("rrprrr")
    boom = robot.links[2]
    assert boom.theta == -sp.pi / 2 and boom.d == 0
    assert robot.parameter("Ia_3").unit == "kg" and robot.parameter("Ia_1").unit == "kg.m2"
    assert num(robot.links[0].rotor_inertia, robot) == 0.953
    values = robot.parameter_values()
    for link in robot.links:
        I = np.array([[float(sp.sympify(e).xreplace(values)) for e in row] for row in link.inertia_com])
        assert inertia_problems(float(link.mass.xreplace(values)), I) == []


@pytest.mark.parametrize("name", SHIPPED)
def test_chain_to_toml_round_trips_shipped_robots(name):
    robot = load(name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        back = robot_from_toml(chain_to_toml(robot), source=f"<{name}>")
    assert back.links == robot.links and back.gravity == robot.gravity
    assert {(p.name, p.value) for p in back.parameters} == {(p.name, p.value) for p in robot.parameters}


# ----------------------------------------------- conversion to the description
def write(tmp_path, text):
    p = tmp_path / "arm.toml"
    p.write_text(text)
    return p


BOX_ABOUT_CORNER = """
[robot]
name = "box"
gravity = [0, 0, "-g"]
[parameters]
M = {{ unit = "kg" }}
A = {{ unit = "m" }}
B = {{ unit = "m" }}
C = {{ unit = "m" }}
[[links]]
joint = "revolute"
a = 0
alpha = 0
d = 0
theta = 0
mass = {mass}
com = [{cx}, {cy}, {cz}]
inertia = {inertia}
inertia_about = "origin"
"""


def test_parallel_axis_symbolic_solid_box_about_its_corner(tmp_path):
    # a solid box [0,A]x[0,B]x[0,C] about the corner (tensor form, products negated):
    # Ixx = M(B^2+C^2)/3, Ixy = -M A B/4 ...; about its centre: diag(M(B^2+C^2)/12, ...)
    inertia = ('[["M*(B**2+C**2)/3", "-M*A*B/4", "-M*A*C/4"], ["-M*A*B/4", "M*(A**2+C**2)/3", "-M*B*C/4"],'
               ' ["-M*A*C/4", "-M*B*C/4", "M*(A**2+B**2)/3"]]')
    text = BOX_ABOUT_CORNER.format(mass='"M"', cx='"A/2"', cy='"B/2"', cz='"C/2"', inertia=inertia)
    robot = load_robot_description(write(tmp_path, text))
    M, A, B, C = sp.symbols("M A B C", real=True)
    expected = sp.diag(M * (B**2 + C**2), M * (A**2 + C**2), M * (A**2 + B**2)) / 12
    assert sp.simplify(sp.Matrix(robot.links[0].inertia_com) - expected) == sp.zeros(3, 3)


def test_parallel_axis_numeric_box_becomes_parameters(tmp_path):
    Mv, (A, B, C) = 3.0, (0.1, 0.2, 0.4)
    Io = np.array([[Mv * (B**2 + C**2) / 3, -Mv * A * B / 4, -Mv * A * C / 4],
                   [-Mv * A * B / 4, Mv * (A**2 + C**2) / 3, -Mv * B * C / 4],
                   [-Mv * A * C / 4, -Mv * B * C / 4, Mv * (A**2 + B**2) / 3]])
    inertia = "[" + ", ".join("[" + ", ".join(repr(float(v)) for v in row) + "]" for row in Io) + "]"
    text = BOX_ABOUT_CORNER.format(mass=Mv, cx=A / 2, cy=B / 2, cz=C / 2, inertia=inertia)
    text = text.replace('[parameters]\nM = { unit = "kg" }\nA = { unit = "m" }\nB = { unit = "m" }\nC = { unit = "m" }\n', "")
    text = text.replace('"-g"', "-9.81")
    robot = load_robot_description(write(tmp_path, text))
    # the file's numbers are parameters I_1_xy etc. holding the values *as given* (about the corner)
    assert robot.parameter("I_1_xy").value == pytest.approx(-Mv * A * B / 4)
    assert robot.parameter("I_1_xy").unit == "kg.m2"
    assert "origin" in robot.parameter("I_1_xy").description
    Ic = np.array([[num(e, robot) for e in row] for row in robot.links[0].inertia_com])
    expected = Mv / 12 * np.diag([B**2 + C**2, A**2 + C**2, A**2 + B**2])
    assert np.allclose(Ic, expected, rtol=0, atol=1e-15)


def test_numbers_become_named_parameters_and_zeros_stay_structural(tmp_path):
    text = """
[robot]
name = "two"
convention = "modified"
gravity = [0, 0, -9.81]
[parameters]
l2 = { value = 0.5, unit = "m", description = "forearm length" }
[[links]]
name = "base"
joint = "prismatic"
a = 0
alpha = 0
d = 0.25
theta = "-1.5707963267948966"
mass = 4
com = [0, 0.01, "-0.1"]
gyration_sq = [0.02, 0.02, 0.01]
rotor_inertia = 0.5
damping = 1.5
[[links]]
name = "fore"
joint = "revolute"
a = 0.3
alpha = -1.5707963267948966
d = 0
theta = 0
mass = 2.0
com = ["-l2/2", 0, 0]
inertia = [0, "2.0*l2**2/12", "2*l2**2/12"]
external_wrench = true
[payload]
mass = 0.5
com = [0, 0, 0.05]
"""
    robot = load_robot_description(write(tmp_path, text))
    assert robot.convention == "modified"
    assert "modified DH: a_{i-1}" in robot.parameter("a_2").description
    base, fore = robot.links
    s = lambda n: sp.Symbol(n, real=True)
    assert (base.a, base.alpha, base.d, base.theta) == (0, 0, s("d_1"), -sp.pi / 2)
    assert base.mass == s("m_1") and base.com == (0, s("rc_1_y"), s("rc_1_z"))
    assert sp.Matrix(base.inertia_com) == s("m_1") * sp.diag(s("k2_1_xx"), s("k2_1_yy"), s("k2_1_zz"))
    assert (base.rotor_inertia, base.damping) == (s("Ia_1"), s("b_1"))
    assert robot.parameter("Ia_1").unit == "kg" and robot.parameter("b_1").unit == "N.s/m"
    assert robot.parameter("rc_1_z").value == -0.1
    assert fore.alpha == -sp.pi / 2 and sp.sin(fore.alpha) == -1
    assert fore.com == (-s("l2") / 2, 0, 0)
    # "2.0" in a string is exact: the inertia is m l^2/12 with rational coefficients
    assert fore.inertia_com[1][1] == fore.inertia_com[2][2] == s("l2") ** 2 / 6
    assert fore.external_wrench and not base.external_wrench
    assert robot.payload.mass == s("m_L") and robot.payload.com == (0, 0, s("rc_L_z"))
    assert robot.gravity == (0, 0, s("g_z"))
    p = robot.parameter("m_2")
    assert (p.value, p.unit, p.description) == (2.0, "kg", "mass of link 2 (fore)")
    assert robot.parameter("l2").description == "forearm length"
    assert [p.name for p in robot.parameters][0] == "l2"  # declared parameters first
    assert {p.symbol for p in robot.parameters} == free_symbols(robot)


def test_undeclared_symbols_are_parameters_without_value_and_unused_ones_warn(tmp_path):
    text = """
[robot]
name = "one"
gravity = [0, 0, "-g"]
[parameters]
unused = 1.0
[[links]]
joint = "revolute"
a = "L"
alpha = 0
d = 0
theta = "phi0"
mass = "m"
com = ["-L/2", 0, 0]
inertia = [0, "m*L**2/12", "m*L**2/12"]
"""
    with pytest.warns(UserWarning, match="declared but not used: unused"):
        robot = load_robot_description(write(tmp_path, text))
    assert {p.name: p.value for p in robot.parameters} == {"L": None, "g": None, "m": None, "phi0": None}
    assert robot.links[0].name == "link1"


# ------------------------------------------------------------- the parser
@pytest.mark.parametrize(
    "text",
    [
        "__import__('os')",
        "__import__('os').system('echo hi')",
        "os.system",
        "x.__class__",
        "lambda: 1",
        "(lambda x: x)(1)",
        "eval('1')",
        "exec('1')",
        "getattr(x, 'y')",
        "f(x)",
        "eval",
        "[1, 2]",
        "x[0]",
        "x if y else z",
        "x < 1",
        "'text'",
        "1j",
        "sqrt(x, y)",
        "sin(x=1)",
        "x; y",
        "10**10**10",
        "",
    ],
)
def test_parser_rejects_code(text):
    with pytest.raises(ExpressionError):
        quantity(text)


def test_parser_builds_the_expected_sympy_objects():
    x, m, l = sp.symbols("x m l", real=True)
    assert parse_expression("m*l**2/12") == m * l**2 / 12
    assert parse_expression("-(x - 1)") == 1 - x
    assert parse_expression("sqrt(x)*sin(x)+cos(x)-tan(x)+exp(x)+log(x)+abs(x)") == (
        sp.sqrt(x) * sp.sin(x) + sp.cos(x) - sp.tan(x) + sp.exp(x) + sp.log(x) + sp.Abs(x))
    assert parse_expression("0.1") == sp.Rational(1, 10)
    assert parse_expression("2.5e-3") == sp.Rational(1, 400)
    assert parse_expression("pi/2") == sp.pi / 2
    assert quantity(3) == sp.Integer(3) and isinstance(quantity(0.3), sp.Float)
    assert parse_expression("x").is_real


def test_angle_snapping():
    exact = snap_angle(quantity(-1.5707963267948966))
    assert exact == -sp.pi / 2
    assert sp.cos(exact) == 0 and sp.sin(exact) == -1
    assert snap_angle(quantity(np.pi)) == sp.pi
    assert snap_angle(quantity(3 * np.pi / 2)) == 3 * sp.pi / 2
    assert snap_angle(quantity(0.0)) == 0
    off = snap_angle(quantity(np.pi / 2 + 1e-9))  # a real angle, not a rounding of pi/2
    assert isinstance(off, sp.Float)
    assert snap_angle(quantity("pi/2 + x")) == sp.pi / 2 + sp.Symbol("x", real=True)


# ------------------------------------------------------------- the chain
def test_chain_nominal_values_are_uniform_rods():
    robot = n_link_chain(5, "RRP")
    assert [l.joint[0].upper() for l in robot.links] == list("RRPRR")
    assert [l.alpha for l in robot.links] == [sp.pi / 2, 0, -sp.pi / 2, sp.pi / 2, 0]
    assert robot.parameters == () and not free_symbols(robot)
    m, length, r = 1.0, 0.3, 0.02
    for link in robot.links:
        I = np.array(link.inertia_com, dtype=float)
        assert np.allclose(I, np.diag([m * r**2 / 2, m * (3 * r**2 + length**2) / 12, m * (3 * r**2 + length**2) / 12]))
        assert np.allclose(np.array(link.com, dtype=float), [-length / 2, 0, 0])


def test_chain_random_values_are_realisable_and_reproducible():
    a = n_link_chain(12, "RP", seed=7)
    b = n_link_chain(12, "RP", seed=7)
    c = n_link_chain(12, "RP", seed=8)
    assert a.links == b.links and a.links != c.links
    for link in a.links:
        I = np.array(link.inertia_com, dtype=float)
        assert inertia_problems(float(link.mass), I) == []
        assert abs(I[0, 1]) > 0 and abs(I[0, 2]) > 0  # rotated principal axes: products present
        # principal moments are those of the rod: two equal, the third from the radius
        lam = np.linalg.eigvalsh(I)
        assert lam[1] == pytest.approx(lam[2], rel=1e-9)
        length = float(link.a)
        radius = np.sqrt(2 * lam[0] / float(link.mass))
        assert lam[2] == pytest.approx(float(link.mass) * (3 * radius**2 + length**2) / 12, rel=1e-9)


def test_chain_is_not_planar():
    # joint axes z_0 .. z_{n-1}: with alpha cycling through pi/2, 0, -pi/2 they span 3-D space
    robot = n_link_chain(4)
    R = sp.eye(3)
    axes = [R[:, 2]]
    for link in robot.links[:-1]:
        ca, sa = sp.cos(link.alpha), sp.sin(link.alpha)
        R = R * sp.Matrix([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])  # theta = 0 pose
        axes.append(R[:, 2])
    assert sp.Matrix.hstack(*axes).rank() >= 2
    assert any(ax != axes[0] and ax != -axes[0] for ax in axes)


def test_symbolic_chain_has_parameters_with_the_same_values():
    numeric = n_link_chain(3, "RPR", seed=3)
    symbolic = n_link_chain(3, "RPR", symbolic=True, seed=3)
    values = symbolic.parameter_values()
    assert symbolic.parameter("m_2").unit == "kg" and symbolic.parameter("I_3_xy").value is not None
    for ln, ls in zip(numeric.links, symbolic.links):
        assert ls.mass == sp.Symbol(ls.mass.name, real=True)
        for en, es in zip([ln.a, ln.d, ln.mass, *ln.com], [ls.a, ls.d, ls.mass, *ls.com]):
            assert float(es.xreplace(values)) == float(en)
        assert np.allclose(np.array(ln.inertia_com, dtype=float),
                           np.array(sp.Matrix(ls.inertia_com).xreplace(values), dtype=float), rtol=1e-15)


def test_chain_cli_writes_a_loadable_file(tmp_path, capsys):
    from fmugen.robot.chain import main

    assert main(["3", "--joints", "PRR", "--seed", "2"]) == 0
    path = write(tmp_path, capsys.readouterr().out)
    robot = load_robot_description(path)
    assert [l.joint[0] for l in robot.links] == ["p", "r", "r"]
    expected = n_link_chain(3, "PRR", seed=2)
    assert num(robot.links[1].mass, robot) == float(expected.links[1].mass)


def test_chain_rejects_bad_patterns():
    with pytest.raises(ValueError):
        n_link_chain(3, "RX")
    with pytest.raises(ValueError):
        n_link_chain(0)
