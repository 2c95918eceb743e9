"""Component files (fmugen.components.equations): the shipped examples against independent
solutions, the dimension checker, the parser's hardening, and scene use like a built-in type."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import fmugen
from fmugen.components import NumericModel, hydraulic_actuator
from fmugen.components.equations import library_names, load_component, read_component_file
from fmugen.errors import FmugenError, InputFileError

ROOT = Path(__file__).resolve().parent.parent
RTOL = 1e-10


# -- independent, piecewise numpy forms of the smooth kinks (the library builds them branch-free) --
def huber(d, eps):
    return abs(d) if abs(d) >= eps else d * d / (2 * eps) + eps / 2


def relu(d, eps):
    return (d + huber(d, eps)) / 2


def sat(x, lo, hi, eps):
    return lo + relu(x - lo, eps) - relu(x - hi, eps)


def smoothstep(d, eps):
    c = min(1.0, max(-1.0, d / eps))
    return 0.5 + 0.75 * c - 0.25 * c**3


def simulate(model, inputs, t_end, x0=None, method="Radau"):
    """The component's own equations (compiled program) under scipy (Radau: with its exact Jacobian), inputs u(t)."""
    ev = NumericModel(model)
    x0 = [v.start for v in model.states] if x0 is None else x0
    jac = {"jac": lambda t, x: ev.dfdx(t, x, inputs(t))} if method == "Radau" else {}
    sol = solve_ivp(lambda t, x: ev.f(t, x, inputs(t)), (0, t_end), x0, method=method, rtol=RTOL,
                    atol=1e-12, dense_output=True, **jac)
    assert sol.success
    return sol, ev


def reference(f, x0, t_end, method="Radau"):
    sol = solve_ivp(f, (0, t_end), x0, method=method, rtol=RTOL, atol=1e-12, dense_output=True)
    assert sol.success
    return sol


def params(model):
    return {p.name: p.start for p in model.parameters}


# ----------------------------------------------------------------------------- shipped examples
def test_spring_damper_step_equals_closed_form():
    m = load_component("lib:spring_damper")
    p = params(m)
    F = 3.0
    sol, ev = simulate(m, lambda t: [F], 2.0)
    wn = math.sqrt(p["c"] / p["m"])
    z = p["d"] / (2 * math.sqrt(p["c"] * p["m"]))
    wd = wn * math.sqrt(1 - z * z)
    t = np.linspace(0, 2, 41)
    s = F / p["c"] * (1 - np.exp(-z * wn * t) * (np.cos(wd * t) + z / math.sqrt(1 - z * z) * np.sin(wd * t)))
    assert np.max(np.abs(sol.sol(t)[0] - s)) < 1e-8 * F / p["c"] * 10
    # the output f_s = c s + d v
    x = sol.sol(1.0)
    assert ev.g(1.0, x, [F])[0] == pytest.approx(p["c"] * x[0] + p["d"] * x[1], rel=1e-13)


def test_first_order_sensor_equals_closed_form():
    m = load_component("lib:first_order_sensor")
    p = params(m)
    P = 8e6
    sol, ev = simulate(m, lambda t: [P], 0.01)
    t = np.linspace(0, 0.01, 21)
    assert np.max(np.abs(sol.sol(t)[0] - P * (1 - np.exp(-t / p["T_s"])))) < 1e-7 * P
    assert ev.g(0.01, sol.sol(0.01), [P])[0] == pytest.approx(
        p["K_s"] * P * (1 - math.exp(-0.01 / p["T_s"])) + p["v_0"], rel=1e-8)


def test_stribeck_against_hand_written_equations():
    m = load_component("lib:stribeck")
    p = params(m)
    tau = lambda t: 4.0 * math.sin(3.0 * t)  # noqa: E731  -- sticks near the reversals, slips between

    def f(t, x):
        w = x[1]
        tf = (p["T_c"] + (p["T_s"] - p["T_c"]) * math.exp(-(w / p["w_s"]) ** 2)) * w / math.sqrt(
            w * w + p["w_eps"] ** 2) + p["b"] * w
        return [w, (tau(t) - tf) / p["J"]]

    sol, _ = simulate(m, lambda t: [tau(t)], 1.5)
    ref = reference(f, [0.0, 0.0], 1.5)
    t = np.linspace(0, 1.5, 31)
    assert np.max(np.abs(sol.sol(t) - ref.sol(t))) < 1e-7
    assert np.max(np.abs(ref.sol(t)[1])) > 10  # it does slip


def test_gear_backlash_against_hand_written_equations():
    m = load_component("lib:gear_backlash")
    p = params(m)
    phiL = lambda t: 0.01 * math.sin(5 * t)  # noqa: E731
    wL = lambda t: 0.05 * math.cos(5 * t)  # noqa: E731
    taum = lambda t: 0.4 * math.sin(3 * t)  # noqa: E731

    def torque(x, t):
        delta = x[0] / p["n"] - phiL(t)
        dz = delta - sat(delta, -p["beta"], p["beta"], p["eps_b"])
        contact = smoothstep(huber(delta, p["eps_b"]) - p["beta"], p["eps_b"])
        return p["c"] * dz + p["d"] * (x[1] / p["n"] - wL(t)) * contact

    def f(t, x):
        return [x[1], (taum(t) - torque(x, t) / p["n"] - p["b_m"] * x[1]) / p["J_m"]]

    sol, ev = simulate(m, lambda t: [taum(t), phiL(t), wL(t)], 1.0, method="DOP853")  # not stiff
    ref = reference(f, [0.0, 0.0], 1.0, method="DOP853")
    t = np.linspace(0, 1, 41)
    assert np.max(np.abs(sol.sol(t)[0] - ref.sol(t)[0])) < 1e-6
    taus = [torque(ref.sol(tk), tk) for tk in t]
    assert max(taus) > 1 and min(taus) < -0.3  # both flanks of the backlash are hit
    assert np.allclose([ev.g(tk, sol.sol(tk), [taum(tk), phiL(tk), wL(tk)])[0] for tk in t], taus, atol=1e-4)


def test_pid_anti_windup_against_hand_written_equations():
    m = load_component("lib:pid")
    p = params(m)
    r = lambda t: 0.5 if t > 0.01 else 0.0  # noqa: E731  -- a step that saturates the output
    y = lambda t: 0.3 * (1 - math.exp(-t / 0.05))  # noqa: E731

    def out(x, t):
        e = r(t) - y(t)
        v = p["K_p"] * e + p["K_i"] * x[0] + p["K_d"] * (e - x[1]) / p["T_f"]
        return v, sat(v, -p["U_max"], p["U_max"], p["eps_U"]), e

    def f(t, x):
        v, u, e = out(x, t)
        return [e + (u - v) / (p["K_i"] * p["T_t"]), (e - x[1]) / p["T_f"]]

    sol, ev = simulate(m, lambda t: [r(t), y(t)], 0.4)
    ref = solve_ivp(f, (0, 0.4), [0.0, 0.0], method="Radau", rtol=RTOL, atol=1e-12, dense_output=True,
                    max_step=0.005)
    t = np.linspace(0.0, 0.4, 81)
    assert np.max(np.abs(sol.sol(t) - ref.sol(t))) < 1e-7
    u = np.array([out(ref.sol(tk), tk)[1] for tk in t])
    assert np.max(u) == pytest.approx(p["U_max"], abs=p["eps_U"])  # saturated ...
    # ... and the integrator did not wind up: without back-calculation z would be the error's integral
    integral = np.trapezoid([r(tk) - y(tk) for tk in t], t)
    assert sol.sol(0.4)[0] < 0.5 * integral


def test_relief_valve_against_hand_written_equations():
    m = load_component("lib:relief_valve")
    p = params(m)
    P = lambda t: 300e5 * t / 0.05 if t < 0.05 else 300e5  # noqa: E731  -- ramp to 300 bar

    def f(t, x):
        xss = sat((P(t) - p["P_cr"]) / p["k_x"], 0.0, p["x_max"], p["eps_x"])
        return [(xss - x[0]) / p["T_v"]]

    sol, ev = simulate(m, lambda t: [P(t)], 0.1)
    ref = solve_ivp(f, (0, 0.1), [0.0], method="Radau", rtol=RTOL, atol=1e-14, dense_output=True, max_step=1e-3)
    t = np.linspace(0, 0.1, 51)
    assert np.max(np.abs(sol.sol(t)[0] - ref.sol(t)[0])) < 1e-9
    Q = p["C_d"] * p["w_a"] * ref.sol(0.1)[0] * math.sqrt(2 * huber(300e5, p["dp_eps"]) / p["rho"])
    assert ev.g(0.1, sol.sol(0.1), [300e5])[0] == pytest.approx(Q, rel=1e-7)
    assert ref.sol(0.1)[0] == pytest.approx(p["x_max"], rel=1e-6)  # fully open above 150 + 100 bar
    assert sol.sol(0.02)[0] == 0.0 or abs(sol.sol(0.02)[0]) < 1e-12  # shut below the cracking pressure


def test_rate_limiter_ramps_at_its_rate():
    m = load_component("lib:rate_limiter")
    p = params(m)
    sol, _ = simulate(m, lambda t: [20.0], 0.2)  # above the amplitude limit too
    # exact: the rate limit R_max until the tracking error falls inside (R_max T + eps_R T), then U_max
    assert sol.sol(0.05)[0] == pytest.approx(p["R_max"] * 0.05, rel=1e-9)
    assert sol.sol(0.2)[0] == pytest.approx(p["U_max"], rel=1e-6)


def test_pd_against_hand_written_equations():
    m = load_component("lib:pd")
    p = params(m)
    y = lambda t: 0.1 * math.sin(20 * t)  # noqa: E731

    def f(t, x):
        return [(0.2 - y(t) - x[0]) / p["T_f"]]

    sol, ev = simulate(m, lambda t: [0.2, y(t)], 0.3)
    ref = reference(f, [0.0], 0.3)
    e = 0.2 - y(0.3)
    assert ev.g(0.3, sol.sol(0.3), [0.2, y(0.3)])[0] == pytest.approx(
        p["K_p"] * e + p["K_d"] * (e - ref.sol(0.3)[0]) / p["T_f"], rel=1e-8)


def test_hydraulic_actuator_file_equals_the_builtin_to_round_off():
    """The built-in type re-expressed as a component file: same variables, equations and Jacobians."""
    a = hydraulic_actuator(parameter_set="puma_joint2")
    b = load_component("lib:hydraulic_actuator", overrides=params(a))
    assert [(v.name, v.unit, v.start) for v in a.states] == [(v.name, v.unit, v.start) for v in b.states]
    assert [v.name for v in a.inputs] == [v.name for v in b.inputs]
    assert [v.name for v in a.outputs] == [v.name for v in b.outputs]
    assert params(a) == params(b)
    ea, eb = NumericModel(a), NumericModel(b)
    rng = np.random.default_rng(21)
    for _ in range(20):
        x, u = rng.normal(0, 5e6, 1), np.array([rng.normal(0, 1e-4), rng.normal(0, 2)])
        assert eb.f(0, x, u) == pytest.approx(ea.f(0, x, u), rel=1e-14, abs=1e-20)
        assert eb.g(0, x, u) == pytest.approx(ea.g(0, x, u), rel=1e-14)
        for ja, jb in zip(ea.jacobians(0, x, u), eb.jacobians(0, x, u)):
            assert np.allclose(ja, jb, rtol=1e-14, atol=0)


# ----------------------------------------------------------------------------- dimensions
def write(tmp_path, equations, extra="", name="c.toml"):
    text = f"""
[component]
name = "c"
equations = {equations!r}
[parameters]
J = {{ value = 0.1, unit = "kg.m2" }}
k = {{ value = 10.0, unit = "N.m/rad" }}
w_e = {{ value = 1e-3, unit = "rad/s" }}
[inputs]
tau = {{ unit = "N.m", start = 0.0 }}
[states]
phi = {{ unit = "rad" }}
w = {{ unit = "rad/s" }}
{extra}
""".replace("'", '"')
    p = tmp_path / name
    p.write_text(text)
    return p


def test_dimension_checker_refuses_a_wrong_equation(tmp_path):
    p = write(tmp_path, ["der(phi) = w", "der(w) = (tau - k*phi)/J*w"])
    with pytest.raises(InputFileError) as e:
        read_component_file(p)
    msg = str(e.value)
    assert str(p) in msg and "der(w) = (tau - k*phi)/J*w" in msg
    assert "[s-2]" in msg and "[s-3]" in msg  # both sides' dimensions (rad is the SI's pure number)
    p = write(tmp_path, ["der(phi) = w", "der(w) = (tau - J)/J"])
    with pytest.raises(InputFileError, match=r"'tau' is \[kg.m2.s-2\] but 'J' is \[kg.m2\] \(in 'tau - J'\)"):
        read_component_file(p)
    p = write(tmp_path, ["der(phi) = w", "der(w) = (tau - k*phi)/J + tanh(w)"])
    with pytest.raises(InputFileError, match=r"argument of tanh must be a pure number"):
        read_component_file(p)
    p = write(tmp_path, ["der(phi) = w", "der(w) = (tau - k*phi)/J*exp(-(w/w_e)**2) + 0"])
    assert read_component_file(p)  # a pure-number exponent; 0 fits every dimension
    p = write(tmp_path, ["der(phi) = w", "der(w) = (tau - k*phi)/J**w"])
    with pytest.raises(InputFileError, match="exponent"):
        read_component_file(p)
    p = write(tmp_path, ["der(phi) = w", "der(w) = tau/J"], extra='[outputs]\ny = { unit = "bar" }')
    with pytest.raises(InputFileError, match="coherent SI"):
        read_component_file(p)


def test_every_shipped_component_file_is_dimensionally_consistent():
    files = [f"lib:{n}" for n in library_names()] + [str(ROOT / "examples/components/geared_drive.toml")]
    assert len(files) >= 9
    for f in files:
        load_component(f)


# ----------------------------------------------------------------------------- parser hardening
@pytest.mark.parametrize("rhs, why", [
    ("__import__('os').system('true')", "not allowed|identifier|unknown name"),
    ("w.__class__", "attribute"),
    ("(lambda: 0)()", "lambda|not allowed"),
    ("open('/etc/passwd')", "unknown name|not allowed"),
    ("'text'", "not a real number|not allowed"),
    ("w if phi > 0 else tau", "must start an expression"),
    ("w; import os", "syntax|cannot read|not allowed"),
    ("w\n+ 1", "control character"),
    ("[w, w][0]", "not allowed|subscript"),
    ("1e400*w", "non-finite|finite"),
    ("exp(1000)*w", "finite"),
    ("w/0", "non-finite"),
    ("log(0)*w", "non-finite"),
    ("2**10**10*w", "power too large"),
    ("(" * 60 + "w" + ")" * 60, "nested too deeply"),
    ("+".join(["w"] * 300), "too long|more than"),
    ("min(w, phi)", "corner on a state"),
    ("w_e*sign(w)", "jump on a state"),
    ("abs(w)", "corner on a state"),
    ("if w > 0 then w else -w", "if-condition on a state"),
    ("if w > 0 and phi > 0 then w else -w", "one comparison"),
    ("if w == 0 then w else -w", "one comparison"),
    ("if w > 0 then w", "without 'else'"),
    ("tanh(w, phi)", "exactly 1 argument"),
    ("smooth(w > 0, w_e)", "only an if-condition"),
    ("der(w)", "only a left-hand side"),
    ("w > 0", "only an if-condition"),
    ("w + phi", "dimensionally inconsistent: 'w' is \\[s-1\\] but 'phi' is \\[1\\]"),
    ("time_", "unknown name"),
])
def test_parser_refuses(tmp_path, rhs, why):
    p = write(tmp_path, ["der(phi) = w", "der(w) = tau/J"], extra=f'[outputs]\ny = {{ unit = "rad/s" }}')
    text = p.read_text().replace('"der(w) = tau/J"]', '"der(w) = tau/J", ' + _toml_string("y = " + rhs) + "]")
    p.write_text(text)
    with pytest.raises(FmugenError, match=why):
        load_component(p)


def _toml_string(s):
    return "'''" + s + "'''" if "\n" not in s else '"' + s.replace("\\", "\\\\").replace("\n", "\\n").replace('"', '\\"') + '"'


def test_smooth_forms_and_exact_forms(tmp_path):
    eqs = ["der(phi) = w", "der(w) = tau/J",
           "y1 = if smooth(w > w_e, w_e) then 2 else -1",
           "y2 = if k > 5e7*J*w_e*w_e then 1 else 0",
           "y3 = sat(w, -w_e, w_e, w_e/10)/w_e + abs(k/(J*w_e*w_e) - 2e7)*1e-7",
           "y4 = atan2(w, w_e) + min(w, 2*w_e, w_e/4)/w_e + sign(w, w_e) + deadzone(w, -w_e, w_e, w_e/4)/w_e"]
    p = write(tmp_path, eqs, extra="[outputs]\n" + "\n".join(f'y{i} = {{ unit = "1" }}' for i in range(1, 5)))
    m = load_component(p)
    ev = NumericModel(m)
    we = 1e-3
    for w in (-5e-3, -1e-3, 0.0, 0.4e-3, 1.5e-3, 2e-3, 7e-3):
        y = ev.g(0, [0.0, w], [0.0])
        assert y[0] == pytest.approx(-1 + 3 * smoothstep(w - we, we), abs=1e-14)
        assert y[1] == 1.0  # exact on parameters
        assert y[2] == pytest.approx(sat(w, -we, we, we / 10) / we + 8.0, abs=1e-12)
        mn = w - relu(w - 2 * we, we / 4)
        assert y[3] == pytest.approx(math.atan2(w, we) + mn / we + w / math.hypot(w, we)
                                     + (w - sat(w, -we, we, we / 4)) / we, abs=1e-12)
    # a parameter set or override changes the exact if (k = 3 < 5)
    assert NumericModel(load_component(p, overrides={"k": 3.0})).g(0, [0.0, 0.0], [0.0])[1] == 0.0
    # exact Jacobians: finite and equal to central differences, at and beside the kinks
    for w in (0.0, we, we + 1e-7, 2 * we):
        dg = ev.jacobians(0, [0.0, w], [0.0])[2]
        h = 1e-9
        fd = (ev.g(0, [0.0, w + h], [0.0]) - ev.g(0, [0.0, w - h], [0.0])) / (2 * h)
        assert np.all(np.isfinite(dg))
        assert np.allclose(dg[:, 1], fd, rtol=1e-5, atol=1e-2)


def test_file_errors_name_file_and_field(tmp_path):
    p = write(tmp_path, ["der(phi) = w"])
    with pytest.raises(InputFileError, match=r"c.toml: no equation for der\(w\)"):
        read_component_file(p)
    p = write(tmp_path, ["der(phi) = w", "der(w) = tau/J", "der(w) = 0"])
    with pytest.raises(InputFileError, match="a second equation"):
        read_component_file(p)
    p = write(tmp_path, ["der(phi) = w", "der(w) = tau/J", "tau = 0"])
    with pytest.raises(InputFileError, match="is an input"):
        read_component_file(p)
    p = write(tmp_path, ["der(phi) = w", "der(w) = a/J", "a = b", "b = a"],
              extra='[intermediates]\na = { unit = "N.m" }\nb = { unit = "N.m" }')
    with pytest.raises(InputFileError, match="cycle"):
        read_component_file(p)
    p.write_text(p.read_text().replace("value = 0.1", "value = nan"))
    with pytest.raises(InputFileError, match="finite"):
        read_component_file(p)
    p = write(tmp_path, ["der(phi) = w", "der(w) = tau/J"]).read_text()
    (tmp_path / "d.toml").write_text(p.replace('J = {', 'if = {'))
    with pytest.raises(InputFileError, match="keyword|identifier|reserved"):
        read_component_file(tmp_path / "d.toml")
    with pytest.raises(InputFileError, match="outside its range"):
        load_component("lib:stribeck", overrides={"J": -1.0})
    with pytest.raises(InputFileError, match="no parameter set 'nope'"):
        load_component("lib:stribeck", parameter_set="nope")


# ----------------------------------------------------------------------------- in a scene
SCENE = """
[scene]
name = "rig"
stop = 0.5
step = 1e-3
record = ["load.phi", "load.tau_f"]
connections = [["src.q_ref", "ctl.r"], ["load.phi", "ctl.y"], ["ctl.u", "load.tau", {factor}]]
[instances]
src = {{ type = "ptp_trajectory", parameters = {{ q_begin = 0.0, q_end = 0.5, qd_max = 2.0, qdd_max = 20.0, t_start = 0.0 }} }}
ctl = {{ type = "lib:pd", parameters = {{ K_p = 50.0 }} }}
load = {{ type = "file:comp/stribeck.toml", parameter_set = "heavy" }}
"""


def test_component_file_in_a_scene_like_a_builtin(tmp_path):
    (tmp_path / "comp").mkdir()
    (tmp_path / "comp/stribeck.toml").write_text((ROOT / "fmugen/components/library/stribeck.toml").read_text())
    sc = tmp_path / "rig.toml"
    sc.write_text(SCENE.format(factor='1.0'))
    # units on connections: V never meets N.m unless a factor is stated
    sc.write_text(SCENE.format(factor="").replace(', ]]', ']]').replace('"load.tau", ]', '"load.tau"]'))
    with pytest.raises(FmugenError, match=r"unit mismatch: ctl.u is in \[V\] but load.tau expects \[N.m\]"):
        fmugen.load_scene(sc)
    sc.write_text(SCENE.format(factor="1.0"))
    scene = fmugen.load_scene(sc, set={"load.T_c": 15.0})
    m = scene.monolithic_model()
    pv = {p.name: p.start for p in m.parameters}
    assert pv["load.J"] == 0.5 and pv["load.T_c"] == 15.0 and pv["ctl.K_p"] == 50.0  # set, file, parameters
    # the monolithic model against the same system written by hand
    ev = NumericModel(m)
    names = [v.name for v in m.states]
    x = np.array([{"load.phi": 0.1, "load.w": 0.3, "ctl.x_d": 0.02}[n] for n in names])
    d = dict(zip(names, ev.f(0.2, x, np.zeros(m.nu))))
    from fmugen.components import ptp_trajectory
    r = NumericModel(ptp_trajectory(overrides={"q_begin": 0.0, "q_end": 0.5, "qd_max": 2.0, "qdd_max": 20.0,
                                               "t_start": 0.0})).g(0.2, [], [])[0]
    e = r - 0.1
    u = 50.0 * e + 5.0 * (e - 0.02) / 2e-3
    tf = (15.0 + 15.0 * math.exp(-(0.3 / 0.1) ** 2)) * 0.3 / math.hypot(0.3, 1e-3) + 0.02 * 0.3
    assert d["load.w"] == pytest.approx((u - tf) / 0.5, rel=1e-12)
    assert d["ctl.x_d"] == pytest.approx((e - 0.02) / 2e-3, rel=1e-12)
    # a parameter the scene does not name, refused with the file named
    with pytest.raises(FmugenError, match="not a parameter, state, input or discrete state of load"):
        fmugen.load_scene(sc, set={"load.T_x": 1.0}).monolithic_model()
    sc.write_text(SCENE.format(factor="1.0").replace("file:comp/stribeck.toml", "file:comp/none.toml"))
    with pytest.raises(FmugenError, match=r"\[instances.load\] type = 'file:comp/none.toml'.*no such component file"):
        fmugen.load_scene(sc)


# ----------------------------------------------------------------------------- state feedback
def test_lqr_gain_closed_around_the_nonlinear_scene_as_a_component_file(tmp_path):
    """K from python-control's lqr, written as a component file, closed around the plant in a scene:
    the closed loop's A is A - B K of the design (to round-off)."""
    import control

    plant = load_component("lib:spring_damper", name="plant")
    lm = fmugen.linearize(plant, x=[0.0, 0.0], u=[0.0])
    K, _, _ = control.lqr(lm, np.diag([100.0, 1.0]), np.eye(1))
    x_ref, u_ff = [0.02, 0.0], [2.0]  # hold s = 0.02 m: the spring needs c s = 2 N
    (tmp_path / "c").mkdir()
    fmugen.control.state_feedback_file(tmp_path / "c/lqr.toml", K, plant, ["s", "v"], ["F"], x_ref, u_ff)
    fb = load_component(tmp_path / "c/lqr.toml")
    assert [p.unit for p in fb.parameters][:2] == ["kg.s-2", "kg.s-1"]  # N/m and N/(m/s)
    (tmp_path / "loop.toml").write_text("""
[scene]
name = "loop"
stop = 1.0
connect = [["plant.s", "fb.s"], ["plant.v", "fb.v"], ["fb.F", "plant.F"]]
[instances]
plant = { type = "lib:spring_damper" }
fb = { type = "file:c/lqr.toml" }
""")
    sc = fmugen.load_scene(tmp_path / "loop.toml")
    m = sc.monolithic_model()
    closed = fmugen.linearize(m, x=[0.0, 0.0], u=[])
    order = [[v.name for v in m.states].index(n) for n in ("plant.s", "plant.v")]
    A = np.asarray(closed.A)[np.ix_(order, order)]
    assert np.allclose(A, np.asarray(lm.A) - np.asarray(lm.B) @ K, rtol=1e-12, atol=1e-12)
    ev = NumericModel(m)
    x = np.array([0.02, 0.0])[np.argsort(order)]
    assert np.max(np.abs(ev.f(0, x, []))) < 1e-12  # the reference is an equilibrium


def test_state_feedback_file_splits_long_rows(tmp_path, monkeypatch):
    import fmugen.control.feedback as fbm

    plant = load_component("lib:spring_damper")
    K = np.array([[3.0, 0.5]])
    a = NumericModel(load_component(fbm.state_feedback_file(tmp_path / "a.toml", K, plant, ["s", "v"], ["F"],
                                                            [0.1, 0.2], [1.0])))
    monkeypatch.setattr(fbm, "TERMS_PER_LINE", 1)
    b = NumericModel(load_component(fbm.state_feedback_file(tmp_path / "b.toml", K, plant, ["s", "v"], ["F"],
                                                            [0.1, 0.2], [1.0])))
    assert "s_1_2 = K_1_2*(v - ref_v)" in (tmp_path / "b.toml").read_text()
    np.savetxt(tmp_path / "K.csv", K, delimiter=",")  # the gain from a file
    c = NumericModel(load_component(fbm.state_feedback_file(tmp_path / "c.toml", tmp_path / "K.csv", plant,
                                                            ["s", "v"], ["F"], [0.1, 0.2], [1.0])))
    u = [0.7, -0.4]
    assert a.g(0, [], u)[0] == pytest.approx(1.0 - 3.0 * 0.6 - 0.5 * (-0.6), rel=1e-14)
    assert b.g(0, [], u)[0] == a.g(0, [], u)[0] == c.g(0, [], u)[0]
    with pytest.raises(FmugenError, match="K is 1x3, expected 1x2"):
        fbm.state_feedback_file(tmp_path / "d.toml", np.ones((1, 3)), plant, ["s", "v"], ["F"])


def test_linearising_at_rest_inside_a_smoothed_coulomb_term_is_flagged(tmp_path):
    """At rest the smoothed sign acts as a viscous damper T_s/w_eps: the linearisation shows it
    (closed form), fmugen says so, and the friction-free choice it offers removes it."""
    from fmugen.control.kinks import kink_warnings

    (tmp_path / "s.toml").write_text('[scene]\nname = "s"\n[instances]\nload = { type = "lib:stribeck" }\n')
    sc = fmugen.load_scene(tmp_path / "s.toml")
    m = fmugen.control.scene_model(sc)
    op = fmugen.trim(m, at={"load.phi": 0.0, "load.w": 0.0}, free=["load.tau"])
    A = np.asarray(fmugen.linearize(m, op).A)
    assert A[1, 1] == pytest.approx(-(3.0 / 1e-3 + 0.02) / 0.05, rel=1e-12)
    (line,) = kink_warnings(sc, m, op)
    assert "load: sign(w, w_eps)" in line and "--set load.w_eps=1e12" in line
    sc0 = fmugen.load_scene(tmp_path / "s.toml", set={"load.w_eps": 1e12})
    m0 = fmugen.control.scene_model(sc0)
    op0 = fmugen.trim(m0, at={"load.phi": 0.0, "load.w": 0.0}, free=["load.tau"])
    assert kink_warnings(sc0, m0, op0) == []
    assert np.asarray(fmugen.linearize(m0, op0).A)[1, 1] == pytest.approx(-0.02 / 0.05, rel=1e-6)
    # outside the band (slipping at 1 rad/s): nothing to say
    from types import SimpleNamespace

    x1 = np.array([{"load.phi": 0.0, "load.w": 1.0}[v.name] for v in m.states])
    assert kink_warnings(sc, m, SimpleNamespace(x=x1, u=np.array([2.0]), t=0.0)) == []


def test_hostile_text_of_a_component_file_stays_inside_comments_and_xml(tmp_path):
    """Descriptions and provenance are data: escaped in model.c and modelDescription.xml."""
    import xml.dom.minidom

    from fmugen.codegen.c_code import generate_c
    from fmugen.fmi.model_description import model_description_xml

    evil = '*/ int pwned = 1; /* ??/ <!-- ]]> &amp; "q" </fmiModelDescription>'
    p = write(tmp_path, ["der(phi) = w", "der(w) = tau/J"])
    text = p.read_text().replace('name = "c"', f'name = "c"\ndescription = {_toml_string(evil)}\n'
                                                f'provenance = {_toml_string(evil)}')
    text = text.replace('[inputs]\ntau = { unit = "N.m", start = 0.0 }',
                        f'[inputs]\ntau = {{ unit = "N.m", start = 0.0, description = {_toml_string(evil)} }}')
    p.write_text(text)
    m = load_component(p)
    assert "pwned" in m.description and "pwned" in m.provenance
    c = generate_c(m).source
    for line in c.splitlines():
        if "pwned" in line:
            assert "*/ int" not in line and "??/" not in line
    doc = xml.dom.minidom.parseString(model_description_xml(m, "{00000000-0000-0000-0000-000000000000}", "c"))
    assert "pwned" in doc.documentElement.getAttribute("description")


@pytest.mark.parametrize("old, new, message", [
    ("w = { unit = \"rad/s\" }", "\"w;x\" = { unit = \"rad/s\" }", "must be an identifier"),
    ("w = { unit = \"rad/s\" }", "w__x = { unit = \"rad/s\" }", "must be an identifier"),
    ("w = { unit = \"rad/s\" }", "w = { unit = \"rad/s</x>\" }", "unit"),
    ("w = { unit = \"rad/s\" }", "w = { unit = \"rad/s\", start = inf }", "finite"),
    ("w = { unit = \"rad/s\" }", "w = { unit = \"rad/s\", nominal = -1.0 }", "nominal must be positive"),
    ("w = { unit = \"rad/s\" }", "w = { unit = \"rad/s\", min = 2.0, max = 1.0 }", "min .* is above max"),
    ("w = { unit = \"rad/s\" }", "w = { unit = \"rad/s\", evil = 1 }", "unknown key"),
])
def test_declarations_are_checked(tmp_path, old, new, message):
    p = write(tmp_path, ["der(phi) = w", "der(w) = tau/J"])
    p.write_text(p.read_text().replace(old, new).replace("der(w)", "der(w)"))
    with pytest.raises(InputFileError, match=message):
        read_component_file(p)


def test_exact_kinks_on_parameters_in_an_fmu(tmp_path):
    """if/abs/sign/min/max/sat/deadzone/step on parameters stay exact in C and follow a parameter set at run
    time: x' = -k x/T + 8 x0/T (k = 2) or -x/T (k = 1/2), y = 2x or x -- closed forms."""
    import fmpy

    from fmugen.fmi.build import build_fmu

    m = load_component(ROOT / "tests/data/exact_parameter_kinks.toml")
    fmu = tmp_path / "pw.fmu"
    build_fmu(m, fmu, fmi_type="cs")
    for k, n_el, x, y in ((2.0, 1.0, 0.004 + 0.996 * math.exp(-2), 2), (0.5, -1.0, math.exp(-1), 1)):
        r = fmpy.simulate_fmu(str(fmu), stop_time=0.1, start_values={"k": k, "n_el": n_el, "solver.method": 2,
                                                                    "solver.rtol": 1e-10, "solver.atol": 1e-12},
                              output=["x", "y"])
        assert r["x"][-1] == pytest.approx(x, rel=1e-7) and r["y"][-1] == pytest.approx(y * x, rel=1e-7)


def test_component_files_in_an_assembly_file(tmp_path):
    (tmp_path / "asm.toml").write_text("""
[assembly]
name = "rig"
inputs = ["ctl.r"]
connections = [["load.phi", "ctl.y"], ["ctl.u", "load.tau", 1.0]]
[components.ctl]
type = "lib:pd"
parameters = { K_p = 50.0 }
[components.load]
type = "lib:stribeck"
parameter_set = "heavy"
""")
    m = fmugen.components.load_assembly(tmp_path / "asm.toml")
    p = params(m)
    assert p["ctl.K_p"] == 50.0 and p["load.J"] == 0.5 and [v.name for v in m.inputs] == ["ctl.r"]
    ev = NumericModel(m)
    x = {"ctl.x_d": 0.01, "load.phi": 0.1, "load.w": 0.0}
    d = dict(zip([v.name for v in m.states], ev.f(0, [x[v.name] for v in m.states], [0.3])))
    u = 50.0 * 0.2 + 5.0 * (0.2 - 0.01) / 2e-3
    assert d["load.w"] == pytest.approx(u / 0.5, rel=1e-12)  # at rest: the smoothed sign is 0


def test_fmugen_linearize_a_component_file_flags_the_smoothed_coulomb_term(tmp_path, capsys):
    from fmugen.cli import main

    lib = str(ROOT / "fmugen/components/library/stribeck.toml")
    args = ["linearize", lib, "--at", "w=0", "--at", "phi=0", "--trim", "tau", "--out"]
    assert main(args + [str(tmp_path / "a.npz")]) == 0
    out = capsys.readouterr().out
    assert "warning: sign(w, w_eps)" in out and "--set w_eps=1e12" in out
    assert np.load(tmp_path / "a.npz")["A"][1, 1] == pytest.approx(-(3.0 / 1e-3 + 0.02) / 0.05, rel=1e-12)
    assert main(args + [str(tmp_path / "b.npz"), "--set", "w_eps=1e12"]) == 0
    assert "warning" not in capsys.readouterr().out
    assert np.load(tmp_path / "b.npz")["A"][1, 1] == pytest.approx(-0.02 / 0.05, rel=1e-6)  # friction-free


def test_commands_take_lib_names_like_scenes_and_the_api(tmp_path, capsys):
    """``lib:NAME`` names a shipped component file on the command line as in a scene and in
    load_component (fmugen info lib:stribeck said "no such TOML file")."""
    from fmugen.cli import main

    assert main(["info", "lib:stribeck", "--set", "J=0.25"]) == 0
    assert "J [kg.m2] = 0.25" in capsys.readouterr().out
    assert main(["linearize", "lib:stribeck", "--at", "w=0", "--at", "phi=0", "--trim", "tau", "--set", "w_eps=1e12",
                 "--out", str(tmp_path / "a.npz")]) == 0
    assert np.load(tmp_path / "a.npz")["A"][1, 1] == pytest.approx(-0.02 / 0.05, rel=1e-6)  # -b/J, friction-free
    assert main(["info", "lib:nope"]) == 2
    assert "no shipped component 'nope'" in capsys.readouterr().err
