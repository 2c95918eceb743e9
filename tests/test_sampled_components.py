"""Clocked component files ([clocks.<name>], [[when]] clock = ...): the parser, the shipped discrete
controllers against hand-written difference equations, and the python-control side (a dlqr state
feedback, a c2d compensator written as files; the ZOH plant of fmugen linearize --dt).

The library blocks are run by the model's own evaluator at every sample instant (the event iteration
with the clock's tick flag set, ``ModelEvaluator.tick_iteration``) on a random input sequence, and
compared with the difference equations written out here, independently of the file."""
import math

import numpy as np
import pytest

from fmugen.codegen.evaluate import ModelEvaluator
from fmugen.components.equations import load_component, read_component_file
from fmugen.errors import InputFileError

RNG = np.random.default_rng(7)


def run_blocks(model, inputs, T, params=None, output="u"):
    """The held output after each sample instant k T for inputs[k] (a row per instant)."""
    ev = ModelEvaluator(model, params or {})
    j = [v.name for v in model.outputs].index(output)
    out = []
    for k, u in enumerate(inputs):
        t = k * T
        _, clocks = ev.next_tick(t)
        assert list(clocks) == [0], (k, clocks)
        ev.tick_iteration(t, np.zeros(0), np.asarray(u, float), clocks)
        out.append(ev.g(t + 0.3 * T, np.zeros(0), np.asarray(u, float))[j])  # held between instants
        # a repeated tick at the same instant (a step ending a rounding error later) changes nothing
        before = ev.discrete
        ev.tick_iteration(t + 1e-15, np.zeros(0), np.asarray(u, float), clocks)
        assert np.array_equal(before, ev.discrete)
    return np.array(out)


def pi_reference(e, T, Kp, Ki, method, lo=-np.inf, hi=np.inf, delay=0):
    I, ep, out, nxt = 0.0, 0.0, [], 0.0
    for ek in e:
        In = I + T * (ep if method == 0 else ek if method == 1 else (ek + ep) / 2)
        v = Kp * ek + Ki * In
        if (v > hi and ek > 0) or (v < lo and ek < 0):
            uk = min(max(Kp * ek + Ki * I, lo), hi)
        else:
            I, uk = In, min(max(v, lo), hi)
        ep = ek
        out.append(nxt if delay else uk)
        nxt = uk
    return np.array(out)


@pytest.mark.parametrize("method", [0, 1, 2], ids=["forward", "backward", "tustin"])
def test_discrete_pi_is_its_difference_equation(method):
    T, Kp, Ki = 2e-3, 3.0, 40.0
    r, y = RNG.normal(size=60), RNG.normal(size=60)
    m = load_component("lib:discrete_pi", overrides={"K_p": Kp, "K_i": Ki, "T_s": T, "method": method,
                                                     "u_min": -1e3, "u_max": 1e3})
    got = run_blocks(m, np.c_[r, y], T)
    assert np.abs(got - pi_reference(r - y, T, Kp, Ki, method)).max() < 1e-12
    # the transfer function the file names: C(z) = K_p + K_i T F(z)
    import control

    z = control.tf([1, 0], [1], T)
    F = {0: 1 / (z - 1), 1: z / (z - 1), 2: (z + 1) / (2 * (z - 1))}[method]
    ref = control.forced_response(Kp + Ki * T * F, np.arange(60) * T, r - y).outputs
    assert np.abs(got - ref).max() < 1e-9


def test_discrete_pi_clamps_and_delays():
    T, Kp, Ki = 1e-2, 2.0, 50.0
    e = np.r_[np.full(40, 1.0), np.full(40, -0.2)]  # long enough to saturate, then back
    m = load_component("lib:discrete_pi", overrides={"K_p": Kp, "K_i": Ki, "T_s": T, "u_min": -1.0, "u_max": 1.0})
    got = run_blocks(m, np.c_[e, np.zeros_like(e)], T)
    ref = pi_reference(e, T, Kp, Ki, 0, -1.0, 1.0)
    assert np.abs(got - ref).max() < 1e-12
    assert got.max() == 1.0 and np.all(got[3:40] == 1.0)
    # clamped: the output leaves the limit at the first sample after the error reverses (no wind-up)
    assert got[40] < 1.0
    unclamped = pi_reference(e, T, Kp, Ki, 0)
    assert unclamped[45] > 1.0  # without anti-windup it would still be far above the limit
    delayed = run_blocks(load_component("lib:discrete_pi", overrides={
        "K_p": Kp, "K_i": Ki, "T_s": T, "u_min": -1.0, "u_max": 1.0, "delay": 1}), np.c_[e, np.zeros_like(e)], T)
    assert delayed[0] == 0.0 and np.array_equal(delayed[1:], got[:-1])


@pytest.mark.parametrize("method", [0, 1, 2], ids=["forward", "backward", "tustin"])
def test_discrete_pid_is_its_difference_equation(method):
    T, Kp, Ki, Kd, Tf = 1e-3, 20.0, 300.0, 0.4, 4e-3
    r, y = RNG.normal(size=80), RNG.normal(size=80)
    m = load_component("lib:discrete_pid", overrides={"K_p": Kp, "K_i": Ki, "K_d": Kd, "T_f": Tf, "T_s": T,
                                                      "method": method, "u_min": -1e4, "u_max": 1e4})
    got = run_blocks(m, np.c_[r, y], T)
    a, b = {0: (1 - T / Tf, Kd / Tf), 1: (Tf / (Tf + T), Kd / (Tf + T)),
            2: ((2 * Tf - T) / (2 * Tf + T), 2 * Kd / (2 * Tf + T))}[method]
    I = D = ep = 0.0
    ref = []
    for ek in r - y:
        I += T * (ep if method == 0 else ek if method == 1 else (ek + ep) / 2)
        D = a * D + b * (ek - ep)
        ep = ek
        ref.append(Kp * ek + Ki * I + D)
    assert np.abs(got - np.array(ref)).max() < 1e-10
    # and the discretised C(s) = K_p + K_i/s + K_d s/(1 + T_f s) of the named rule
    import control

    z = control.tf([1, 0], [1], T)
    s = {0: (z - 1) / T, 1: (z - 1) / (z * T), 2: 2 * (z - 1) / (T * (z + 1))}[method]
    C = Kp + Ki * T * {0: 1 / (z - 1), 1: z / (z - 1), 2: (z + 1) / (2 * (z - 1))}[method] + Kd * s / (1 + Tf * s)
    out = control.forced_response(C, np.arange(80) * T, r - y).outputs
    assert np.abs(got - out).max() < 1e-8 * max(1.0, np.abs(out).max())


def test_discrete_pid_clamps():
    T = 1e-3
    e = np.r_[np.full(100, 0.5), np.full(50, -0.05)]
    m = load_component("lib:discrete_pid", overrides={"T_s": T, "u_min": -10.0, "u_max": 10.0})
    got = run_blocks(m, np.c_[e, np.zeros_like(e)], T)
    assert got.max() <= 10.0 and got.min() >= -10.0 and np.all(got[1:100] == 10.0)
    assert got[101] < 10.0  # left the limit at once when the error reversed


def test_sampler_quantises_and_delays():
    T, q = 1e-3, 2 * math.pi / 4096  # an encoder of 4096 counts
    x = np.cumsum(RNG.normal(scale=3e-3, size=50))
    plain = run_blocks(load_component("lib:sampler"), x[:, None], T, output="y")
    assert np.array_equal(plain, x)
    enc = run_blocks(load_component("lib:sampler", overrides={"q_step": q}), x[:, None], T, output="y")
    assert np.abs(enc - q * np.floor(x / q + 0.5)).max() < 1e-15
    assert np.abs(enc - x).max() <= q / 2 + 1e-15 and len(np.unique(np.round(enc / q))) > 3
    late = run_blocks(load_component("lib:sampler", overrides={"q_step": q, "delay": 1}), x[:, None], T, output="y")
    assert late[0] == 0.0 and np.array_equal(late[1:], enc[:-1])


def test_the_tick_flag_and_clock_of_a_file():
    m = load_component("lib:discrete_pi", overrides={"T_s": 2e-3})
    names = [v.name for v in m.events.discrete]
    assert "sample.tick" in names and "sample.last" in names
    (clock,) = m.events.clocks
    assert clock.tick.name == "sample.tick" and clock.tick.start == 0.0
    ev = ModelEvaluator(m)
    P, O = ev.clocks()
    assert P.tolist() == [2e-3] and O.tolist() == [0.0]
    assert "sample.tick" not in [v.name for v in m.outputs] and not m.events.indicators


# ---------------------------------------------------------------------------------------------------
# refusals: one line naming the file, the table or clause, and the problem
# ---------------------------------------------------------------------------------------------------
BASE = """
[component]
name = "c"
equations = ["u = u_k"]
[parameters]
T_s = { value = 1e-3, unit = "s" }
K = { value = 2.0, unit = "V/rad" }
G = { value = 1.0, unit = "V" }
[inputs]
e = { unit = "rad" }
[discrete]
u_k = { start = 0.0, unit = "V" }
[outputs]
u = { unit = "V" }
"""
CLOCK = '[clocks.sample]\nperiod = "T_s"\n'
WHEN = '[[when]]\nclock = "sample"\nset = { u_k = "K*e" }\n'

BAD = {
    "no period": (BASE + '[clocks.sample]\noffset = "0"\n' + WHEN, r"\[clocks.sample\] needs period"),
    "period unit": (BASE + '[clocks.sample]\nperiod = "G"\n' + WHEN, r"\[clocks.sample\] period = 'G' is \[.*\]: .*times \[s\]"),
    "period reads input": (BASE + '[clocks.sample]\nperiod = "T_s + 0*e"\n' + WHEN,
                           r"\[clocks.sample\] period .*parameters and numbers only, not e"),
    "period type": (BASE + '[clocks.sample]\nperiod = true\n' + WHEN, r"\[clocks.sample\] period must be"),
    "period zero": (BASE + '[clocks.sample]\nperiod = 0\n' + WHEN, r"\[clocks.sample\] period = 0.0 is 0.*positive"),
    "offset negative": (BASE + CLOCK + 'offset = -1e-3\n' + WHEN, r"\[clocks.sample\] offset .*>= 0"),
    "unknown key": (BASE + CLOCK + "delay = true\n" + WHEN, r"\[clocks.sample\] has unknown key\(s\) delay.*delay"),
    "clock name": (BASE + '[clocks.K]\nperiod = "T_s"\n' + WHEN.replace("sample", "K"), r"\[clocks.K\]: 'K' is also"),
    "hidden name": (BASE.replace("G = {", "tick_sample = {") + CLOCK + WHEN, r"tick_sample.*clock's own"),
    "not a table": (BASE + '[clocks]\nsample = "T_s"\n' + WHEN, r"\[clocks.sample\] must be a table"),
    "unknown clock": (BASE + CLOCK + WHEN.replace('clock = "sample"', 'clock = "fast"'),
                      r"\[\[when\]\] 1 clock = 'fast': not a declared clock; declared: sample"),
    "no clock table": (BASE + WHEN, r"\[\[when\]\] 1 clock = 'sample': no \[clocks.<name>\] table declares it"),
    "unused clock": (BASE + CLOCK + '[clocks.other]\nperiod = "T_s"\n' + WHEN, r"\[clocks.other\]: no \[\[when\]\] clause"),
    "neither": (BASE + CLOCK + WHEN + '[[when]]\nset = { u_k = "0" }\n', r"\[\[when\]\] 2 needs condition"),
    "value unit": (BASE + CLOCK + WHEN.replace("K*e", "e"), r"\[\[when\]\] 1 set u_k = 'e': the value is \[1\] but u_k"),
    "round on input": (BASE.replace('"u = u_k"', '"u = u_k + G*round(e/K/G)"') + CLOCK + WHEN,
                       r"equation 'u = u_k \+ G\*round\(e/K/G\)'.*staircase"),
    "round of a dimension": (BASE + CLOCK + WHEN.replace("K*e", "G*round(u_k)"), r"argument of round must be a pure number"),
    "bad condition": (BASE + CLOCK + WHEN.replace('clock = "sample"', 'clock = "sample"\ncondition = "e"'),
                      r"\[\[when\]\] 1 condition 'e': a condition must be a comparison"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_malformed_clocked_files_are_refused_in_one_line(tmp_path, case):
    text, pattern = BAD[case]
    p = tmp_path / f"{case.replace(' ', '_')}.toml"
    p.write_text(text)
    with pytest.raises(InputFileError) as err:
        load_component(p)
    msg = str(err.value)
    assert "\n" not in msg and str(p) in msg, msg
    import re

    assert re.search(pattern, msg), msg


def test_clock_with_condition_and_number_period(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text(BASE + '[clocks.sample]\nperiod = 0.004\noffset = "2*T_s"\n'
                 + WHEN.replace('clock = "sample"', 'clock = "sample"\ncondition = "e > 0"'))
    m = load_component(p)
    ev = ModelEvaluator(m)
    assert ev.clocks()[0].tolist() == [0.004] and ev.clocks()[1].tolist() == [2e-3]
    ev.tick_iteration(2e-3, np.zeros(0), np.array([-1.0]), [0])
    assert ev.g(2e-3, np.zeros(0), np.array([-1.0]))[0] == 0.0  # condition false: no update
    ev.tick_iteration(6e-3, np.zeros(0), np.array([0.5]), [0])
    assert ev.g(6e-3, np.zeros(0), np.array([0.5]))[0] == 1.0
    assert read_component_file(p).clocks[0].tick == "sample.tick"


# ---------------------------------------------------------------------------------------------------
# python-control into files
# ---------------------------------------------------------------------------------------------------
def _plant():
    import sympy as sp
    from fmugen.codegen.model import SymbolicModel, Variable

    q, w, u = sp.symbols("q w u", real=True)
    return SymbolicModel.from_equations(
        "cart", [Variable("q", q, "rad", start=0.0, output=True), Variable("w", w, "rad/s", start=0.0, output=True)],
        [Variable("u", u, "N.m", start=0.0)], [], [w, (u - 0.5 * w) / 2.0])


def test_dlqr_state_feedback_file_closes_the_discrete_loop(tmp_path):
    import control

    from fmugen.control import c2d, linearize, state_feedback_file
    from fmugen.control.linearize import linear_model

    T = 0.05
    plant = _plant()
    lm = c2d(linear_model(plant), T)
    assert lm.dt == T
    sysd = control.c2d(linearize(plant), T, "zoh")
    assert np.abs(lm.A - sysd.A).max() < 1e-12 and np.abs(lm.B - sysd.B).max() < 1e-12
    K, _, _ = control.dlqr(lm.A, lm.B, np.diag([10.0, 1.0]), [[0.1]])
    x_ref = [0.2, 0.0]
    path = state_feedback_file(tmp_path / "fb.toml", K, plant, ["q", "w"], ["u"], x_ref=x_ref, u_ff=[0.3],
                               sample_period=T)
    m = load_component(path)
    assert m.events.clocks and [v.name for v in m.outputs] == ["u"]
    # the file's law at a sample, held: u[k] = u_ff - K (x[k] - x_ref)
    ev = ModelEvaluator(m)
    x = np.array([0.05, -0.4])
    ev.tick_iteration(0.0, np.zeros(0), x, [0])
    assert abs(ev.g(0.01, np.zeros(0), np.array([9.0, 9.0]))[0] - (0.3 - K @ (x - x_ref))[0]) < 1e-12
    # the discrete closed loop with the file's law is the design's A - B K
    Acl = lm.A - lm.B @ K
    assert np.all(np.abs(np.linalg.eigvals(Acl)) < 1)
    ev = ModelEvaluator(m)
    xk, traj = np.array([0.0, 0.0]), []
    for k in range(40):
        ev.tick_iteration(k * T, np.zeros(0), xk, [0])
        uk = ev.g(k * T, np.zeros(0), xk)[0]
        traj.append(xk)
        xk = lm.A @ xk + lm.B[:, 0] * uk
    xs = [np.zeros(2)]
    for k in range(39):
        xs.append(lm.A @ xs[-1] + lm.B[:, 0] * (0.3 - K @ (xs[-1] - x_ref))[0])
    assert np.abs(np.array(traj) - np.array(xs)).max() < 1e-12


def test_c2d_compensator_as_a_discrete_controller_file(tmp_path):
    import control

    from fmugen.control import discrete_controller_file

    T = 1e-3
    lead = control.tf([0.05, 1.0], [0.005, 1.0]) * 12.0  # a lead compensator [V/rad]
    Cd = control.c2d(lead, T, "tustin")
    path = discrete_controller_file(tmp_path / "lead.toml", Cd, inputs=[("e", "rad")], outputs=[("u", "V")],
                                    name="lead")
    m = load_component(path)
    e = RNG.normal(size=200)
    got = run_blocks(m, e[:, None], T)
    ref = control.forced_response(control.ss(Cd), np.arange(200) * T, e).outputs
    assert np.abs(got - ref).max() < 1e-10 * np.abs(ref).max()
    # a state-space system with two inputs and a plain (A, B, C, D) tuple
    A, B, C, D = [[0.9, 0.1], [0.0, 0.5]], [[1.0, 0.0], [0.0, 2.0]], [[1.0, -1.0]], [[0.0, 0.25]]
    p2 = discrete_controller_file(tmp_path / "ss.toml", (A, B, C, D), sample_period=0.01)
    u = RNG.normal(size=(30, 2))
    got = run_blocks(load_component(p2), u, 0.01, output="y_1")
    ref = control.forced_response(control.ss(A, B, C, D, 0.01), np.arange(30) * 0.01, u.T).outputs
    assert np.abs(got - ref).max() < 1e-12
    from fmugen.errors import FmugenError

    with pytest.raises(FmugenError, match="no sample period"):
        discrete_controller_file(tmp_path / "c.toml", lead)


def test_linearize_dt_writes_the_zoh_plant(tmp_path):
    import control
    import subprocess
    import sys

    plant = tmp_path / "plant.toml"
    plant.write_text('[component]\nname = "lag"\nequations = ["der(x) = (K*u - x)/tau"]\n'
                     '[parameters]\nK = { value = 2.0, unit = "rad/V" }\ntau = { value = 0.1, unit = "s" }\n'
                     '[inputs]\nu = { unit = "V" }\n[states]\nx = { unit = "rad" }\n')
    out = tmp_path / "p.npz"
    r = subprocess.run([sys.executable, "-m", "fmugen.cli", "linearize", str(plant), "--no-trim", "--dt", "0.02",
                        "--out", str(out)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "discretised (zero-order hold) at dt = 0.02 s" in r.stdout
    z = np.load(out)
    phi = math.exp(-0.2)
    assert float(z["dt"]) == 0.02 and abs(z["A"][0, 0] - phi) < 1e-14 and abs(z["B"][0, 0] - 2 * (1 - phi)) < 1e-14
    assert abs(z["A_continuous"][0, 0] + 10.0) < 1e-14
    ref = control.c2d(control.ss(z["A_continuous"], z["B_continuous"], z["C"], z["D"]), 0.02, "zoh")
    assert np.abs(ref.A - z["A"]).max() < 1e-14
    bad = subprocess.run([sys.executable, "-m", "fmugen.cli", "linearize", str(plant), "--no-trim", "--dt", "0",
                          "--out", str(out)], capture_output=True, text=True)
    assert bad.returncode != 0 and "--dt" in bad.stderr


def test_a_clocked_file_as_an_fmu_me_and_cs(tmp_path):
    """The generated C of a clocked file: under fmpy the ME run stops at every instant (nextEventTime)
    and CS steps to each; both give the difference equation of a constant error, held between."""
    from fmpy import simulate_fmu

    import fmugen

    T, Kp, Ki, e = 0.01, 2.0, 30.0, 0.1
    m = load_component("lib:discrete_pi", overrides={"T_s": T, "K_p": Kp, "K_i": Ki})
    fmu = tmp_path / "pi.fmu"
    fmugen.build_fmu(m, fmu, fmi_type="both")
    exact = lambda k: Kp * e + Ki * T * e * k  # noqa: E731  forward Euler: I_k = k T e
    for kind, dt in (("CoSimulation", 0.025), ("ModelExchange", 0.0025)):
        r = simulate_fmu(str(fmu), fmi_type=kind, stop_time=0.2, output_interval=dt, start_values={"r": e},
                         output=["u"])
        k = np.floor(r["time"] / T + 1e-9)
        last = np.r_[r["time"][1:] != r["time"][:-1], True]  # ME: the row after each event
        assert np.abs(r["u"][last] - exact(k[last])).max() < 1e-12, kind
        if kind == "ModelExchange":  # output points between instants: the value held
            jumps = r["time"][1:][np.abs(np.diff(r["u"])) > 0]
            assert len(jumps) >= 19 and np.all(np.abs(jumps / T - np.round(jumps / T)) < 1e-9), jumps


def test_discrete_state_feedback_is_its_law():
    T, K = 2e-3, np.array([12.0, 0.8])
    m = load_component("lib:discrete_state_feedback", overrides={
        "K_theta": K[0], "K_w": K[1], "theta_ref": 0.1, "w_ref": -0.2, "u_ff": 0.5, "T_s": T})
    x = RNG.normal(size=(40, 2))
    got = run_blocks(m, x, T)
    assert np.abs(got - (0.5 - (x - [0.1, -0.2]) @ K)).max() < 1e-13
