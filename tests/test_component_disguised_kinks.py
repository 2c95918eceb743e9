"""Kinks in disguise, widths that are no widths, literals outside the grammar and non-finite constants in
component files: each refused with one line naming the file, the equation and the rule; what is smooth (or
on constants only) is still accepted, and so is every shipped component file."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from fmugen.components.equations import load_component, read_component_file
from fmugen.errors import InputFileError

ROOT = Path(__file__).resolve().parent.parent

TEMPLATE = """[component]
name = "disguise"
equations = ["der(x) = (y - x)/T", "der(v) = (u - v)/T", "der(z) = (1 - z)/T", "y = {expr}", "a2 = x**2",
             "ax = x - v"]
[parameters]
T = {{ value = 0.1, unit = "s", min = 0.0 }}
p = {{ value = 2.0, unit = "1", min = 0.0 }}
q = {{ value = -1.5, unit = "1" }}
e = {{ value = 0.01, unit = "1", min = 0.0 }}
e0 = {{ value = 0.0, unit = "1", min = 0.0 }}
[inputs]
u = {{ unit = "1" }}
[states]
x = {{ unit = "1", start = 0.2 }}
v = {{ unit = "1" }}
z = {{ unit = "1", start = 1.0, min = 0.5, description = "a state kept positive (validity range)" }}
[intermediates]
a2 = {{ unit = "1" }}
ax = {{ unit = "1" }}
[outputs]
y = {{ unit = "1" }}
"""


def write(tmp_path, expr: str) -> Path:
    path = tmp_path / "disguise.toml"
    path.write_text(TEMPLATE.format(expr=expr.replace('"', '\\"')))
    return path


#: corners and jumps in disguise (on states, inputs, time), and widths that are not widths
DISGUISES = [
    "sqrt(x**2)",                          # abs(x)
    "(x**2)**0.5",                         # abs(x)
    "(x**2)**(1/2)",                       # abs(x)
    "(x + sqrt(x**2))/2",                  # max(x, 0)
    "(x - sqrt(x**2))/2",                  # min(x, 0)
    "sqrt(x*x)",                           # abs(x)
    "x/sqrt(x**2)",                        # sign(x)
    "sqrt(x**2)/x",                        # sign(x)
    "x*(x**2)**-0.5",                      # sign(x)
    "(x**4)**0.25",                        # abs(x)
    "sqrt(sqrt(x**4))",                    # abs(x)
    "exp(log(x**2)/2)",                    # abs(x)
    "exp(0.5*log(x**2))",                  # abs(x)
    "sqrt(v**2 - 2*v*x + x**2)",           # abs(x - v)
    "sqrt((x - u)**2)",                    # abs(x - u), an input
    "sqrt(u**2)",                          # abs(u)
    "sqrt(a2)",                            # through an intermediate a2 = x**2
    "sqrt(ax**2) + 1",                     # through an intermediate ax = x - v
    "sqrt(abs(x, 0.1) - 0.05)",            # the smooth abs is eps/2 at 0: its root has a corner there
    "sqrt(x**2 + p - p)",                  # p - p is 0
    "sqrt(x**2 + 0*p)",
    "sqrt(time/T)",                        # infinite slope at t = 0
    "x**p",                                # a parameter exponent (p = 0.5 would be sqrt(x))
    "1 + 0*(x**2)**0.5",                  # structurally a root of x**2 (sympy folds it to 1)
    # widths that are not widths
    "if smooth(x > 0, 0) then 1 else -1",  # literal 0
    "abs(x, x)",                           # the state itself
    "abs(x, 0)",
    "max(x, 0, 0.0)",
    "sign(x, -0.1)",                       # negative
    "abs(x, 1e-400)",                      # 0 as a double
    "abs(x, p - p)",                       # 0
    "sat(x, -1, 1, abs(x, 1))",            # depends on the state
    "min(x, 0, a2)",                       # an intermediate of a state
    "step(x, time/T)",                     # depends on time
    "deadzone(x, -1, 1, u)",               # an input
    "abs(x, -p)",                          # never positive (p >= 0)
    "if smooth(x > v, v) then 1 else 0",   # the other state
]

#: smooth, or kinked on parameters only, or with a proper width: accepted
ACCEPTED = [
    "sqrt(x**2 + 1)",
    "sqrt(x**2 + e**2)",
    "x/sqrt(x**2 + e**2)",
    "sqrt(abs(x, 0.1))",
    "sqrt(2*abs(x, e)/p)",
    "abs(x, e) + max(x, 0, e) + sign(x, e)",
    "if smooth(x > 0, e) then 1 else -1",
    "sqrt(p**2)*x",
    "abs(q)*x + sqrt(q**2)",
    "exp(0.5*log(p**2))*x",
    "(x**2)**1.5",                         # |x|**3: C^2 (an exponent >= 1 has no corner)
    "sqrt(z)",                             # z >= 0.5 (declared min)
    "z**-0.5",
    "sqrt(exp(x))",
    "(x**2 + 1)**0.5 - 1",
    "abs(x, e/2)",
    "x**2",
    "sqrt(p + 1)*x",
]


def one_line_refusal(tmp_path, expr, *, load=False):
    path = write(tmp_path, expr)
    with pytest.raises(InputFileError) as info:
        (load_component if load else read_component_file)(path)
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(str(path) + ": ")
    assert "equation 'y = " in msg, msg
    return msg


def test_the_disguise_list_is_long():
    assert len(DISGUISES) >= 20
    assert len(set(DISGUISES)) == len(DISGUISES)


@pytest.mark.parametrize("expr", DISGUISES)
def test_disguised_kinks_and_false_widths_are_refused_in_one_line(tmp_path, expr):
    msg = one_line_refusal(tmp_path, expr)
    assert "kink rule" in msg, msg
    assert re.search(r"can be 0 on a state, input or time|smoothing width|exact abs|corner", msg), msg


@pytest.mark.parametrize("expr", ACCEPTED)
def test_smooth_and_constant_forms_are_accepted(tmp_path, expr):
    load_component(write(tmp_path, expr))


def test_a_width_parameter_of_value_zero_is_refused_when_the_values_are_chosen(tmp_path):
    path = write(tmp_path, "abs(x, e)")
    load_component(path)  # e = 0.01
    with pytest.raises(InputFileError, match=r"equation 'y = abs\(x, e\)'.*width e .* is 0 .*kink rule"):
        load_component(path, overrides={"e": 0.0})
    msg = one_line_refusal(tmp_path, "abs(x, e0)", load=True)
    assert "kink rule" in msg


def test_exact_kinks_are_still_refused_and_a_disguise_is_refused_only_in_equations(tmp_path):
    assert "kink rule" not in one_line_refusal(tmp_path, "abs(x)")  # the existing rule, its own message
    # an indicator may have a corner (continuous between events): sqrt(x**2) there is fine
    path = tmp_path / "ind.toml"
    path.write_text("""[component]
equations = ["der(x) = -x/T + mode/T"]
[parameters]
T = { value = 0.1, unit = "s", min = 0.0 }
[states]
x = { unit = "1", start = 0.5 }
[discrete]
mode = { start = 0, unit = "1" }
[indicators]
far = "sqrt(x**2) - 0.25"
[[when]]
condition = "sqrt(x**2) < 0.25"
set = { mode = "sqrt(mode**2) + 1" }
""")
    load_component(path)


# ---------------------------------------------------------------------------------------- literals
@pytest.mark.parametrize("lit", ["0x10", "1_0", "0o17", "0b101", "1j", "007", "1_000.5", "1e1_0", "0X1F"])
def test_literals_outside_the_grammar_are_refused(tmp_path, lit):
    path = write(tmp_path, f"{lit}*x")
    with pytest.raises(InputFileError, match=rf"equation.*the number .* is not a literal of the language"):
        read_component_file(path)


@pytest.mark.parametrize("lit", ["12", "0", "0.5", ".5", "3.", "1e-3", "2.5E+6", "0.0", "10e2"])
def test_literals_of_the_grammar_are_accepted(tmp_path, lit):
    read_component_file(write(tmp_path, f"{lit}*x"))


# ---------------------------------------------------------------------------------------- non-finite
@pytest.mark.parametrize("expr", ["exp(1000)", "1e308*10", "log(0)", "1/0", "exp(1000)*x", "x + 10**300*1e10",
                                  "x*(if p > 1 then exp(800) else 1)", "0*x + exp(710)"])
def test_non_finite_constants_are_refused(tmp_path, expr):
    path = write(tmp_path, expr)
    with pytest.raises(InputFileError) as info:
        read_component_file(path)
    msg = str(info.value)
    assert "\n" not in msg and len(msg) < 400, msg
    assert re.search(r"non-finite|not a finite double|power too large", msg), msg


def test_non_finite_constants_in_events_are_refused(tmp_path):
    path = tmp_path / "ev.toml"
    path.write_text("""[component]
equations = ["der(x) = -x/T"]
[parameters]
T = { value = 0.1, unit = "s", min = 0.0 }
[states]
x = { unit = "1", start = 0.5 }
[indicators]
low = "x - 0.25"
[[when]]
condition = "x < 0.25"
set = { x = "exp(1000)" }
""")
    with pytest.raises(InputFileError, match=r"\[\[when\]\] 1 set x.*not a finite double"):
        read_component_file(path)


# ---------------------------------------------------------------------------------------- shipped files
SHIPPED = sorted((ROOT / "fmugen/components/library").glob("*.toml")) + sorted(
    (ROOT / "examples/components").glob("*.toml"))


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_every_shipped_component_file_is_accepted(path):
    m = load_component(path)
    assert m.dfdx is not None
