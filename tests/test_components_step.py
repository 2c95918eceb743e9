"""Each component's step response against the same equations written
independently in plain numpy (no sympy), both solved by scipy (Radau, rtol 1e-10).

Inputs step at t = 0 from the rest point; outside the regularisation bands
the regularised functions equal the plain ones, so the numpy right-hand
sides use the textbook forms (sqrt, sign, min/max).
"""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from fmugen.components import (NumericModel, amplifier, controller, current_driver, dc_motor, hydraulic_actuator,
                               joint_inertia, load_parameter_set, ptp_trajectory, quintic_trajectory, servo_valve,
                               table_trajectory)

P = {fam: dict(v) for fam, v in load_parameter_set("default").sections.items()}
T_GRID = None


def simulate(model, u, T, x0=None):
    ev = NumericModel(model)
    u = np.asarray(u, dtype=float)
    x0 = ev.x0 if x0 is None else np.asarray(x0, float)
    ts = np.linspace(0, T, 201)
    sol = solve_ivp(lambda t, x: ev.f(t, x, u), (0, T), x0, method="Radau", rtol=1e-10,
                    atol=1e-12 * np.maximum(1, np.abs(x0)), t_eval=ts, jac=lambda t, x: ev.dfdx(t, x, u))
    assert sol.success
    y = np.array([ev.g(t, x, u) for t, x in zip(ts, sol.y.T)]).T if model.ny else np.zeros((0, len(ts)))
    return ts, sol.y, y


def reference(rhs, x0, T, out=None, scale=None):
    ts = np.linspace(0, T, 201)
    x0 = np.asarray(x0, float)
    atol = 1e-12 * (np.ones_like(x0) if scale is None else np.asarray(scale))
    sol = solve_ivp(lambda t, x: rhs(x), (0, T), x0, method="Radau", rtol=1e-10, atol=atol, t_eval=ts)
    assert sol.success
    y = np.array([out(x) for x in sol.y.T]).T if out else None
    return sol.y, y


def close(a, b, rtol=1e-6):
    a, b = np.atleast_2d(a), np.atleast_2d(b)
    for ra, rb in zip(a, b):
        assert np.max(np.abs(ra - rb)) <= rtol * max(np.max(np.abs(rb)), 1e-300)


def test_amplifier_real_pi():
    a = P["amplifier"]
    m = amplifier(kind="real", control="PI")
    u = [0.05, 0.01]  # theta_ref, theta
    e = u[0] - u[1]
    wp = 2 * math.pi * a["GBW"] / a["A0"]

    def rhs(x):
        z, v = x
        return [e, wp * (a["A0"] * (e + z / a["T_I"] - v / a["K_a"]) - v)]
    ts, x, y = simulate(m, u, 0.2)
    xr, _ = reference(rhs, [0, 0], 0.2)
    close(x, xr)
    close(y[0], xr[1])  # u = v


def test_amplifier_rails_and_ideal():
    m = amplifier(control="P", rails=True)
    ev = NumericModel(m)
    a = P["amplifier"]
    for err in (0.1, 0.5, -2.0):  # 1.6 V (linear), 8 V (linear), far beyond the rail
        expect = float(np.clip(a["K_a"] * err, -a["U_max"], a["U_max"]))
        assert ev.g(0, [], [err, 0.0])[0] == pytest.approx(expect, rel=1e-12)


@pytest.mark.parametrize("kind", ["lag", "coil"])
def test_current_driver(kind):
    d = P["current_driver"]
    u = 2.0
    if kind == "lag":
        rhs = lambda x: [d["omega_i"] * (d["G_i"] * u - x[0])]  # noqa: E731
    else:
        rhs = lambda x: [(d["A_pa"] * (u - d["R_s"] * x[0]) - (d["R_c"] + d["R_s"]) * x[0]) / d["L"]]  # noqa: E731
    ts, x, _ = simulate(current_driver(kind=kind), [u], 5e-3)
    xr, _ = reference(rhs, [0.0], 5e-3)
    close(x, xr)
    assert x[0, -1] == pytest.approx(d["G_i"] * u, rel=1e-4)  # static gain reached


def q_load(xh, PL, s):
    """Textbook orifice law Q_L = K_q0 x sqrt(1 - sgn(x) P_L/P_s) - K_c0 P_L."""
    K_q0 = s["Q_N"] * math.sqrt(s["P_s"] / s["dp_N"])
    return K_q0 * xh * math.sqrt(1 - np.sign(xh) * PL / s["P_s"]) - s["K_c0"] * PL


@pytest.mark.parametrize("order", [0, 1, 2])
@pytest.mark.parametrize("PL", [4.0e6, -6.0e6])
def test_servo_valve(order, PL):
    s = P["servo_valve"]
    i = 4e-3 if PL > 0 else -3e-3
    xs = i / s["i_rated"]
    wv, zv = s["omega_v"], s["zeta_v"]
    m = servo_valve(order=order)
    if order == 0:
        ev = NumericModel(m)
        names = [v.name for v in m.outputs]
        y = ev.g(0, [], [i, PL])
        assert y[names.index("Q_L")] == pytest.approx(q_load(xs, PL, s), rel=1e-12)
        return
    rhs = (lambda x: [wv * (xs - x[0])]) if order == 1 else \
        (lambda x: [x[1], wv**2 * (xs - x[0]) - 2 * zv * wv * x[1]])
    ts, x, y = simulate(m, [i, PL], 0.03)
    xr, yr = reference(rhs, np.zeros(order), 0.03, out=lambda x: q_load(x[0], PL, s), scale=[1e-3, 1][:order])
    close(x[0], xr[0])
    close(y[0], yr, rtol=1e-6)


def test_servo_valve_chambers_matches_load_form():
    # with P_A + P_B = P_s and P_T = 0 the mean of Q_A, Q_B is the load flow
    s = P["servo_valve"]
    ch, lp = NumericModel(servo_valve(order=0, flow="chambers")), NumericModel(servo_valve(order=0))
    for i, PL in ((3e-3, 5e6), (-7e-3, 2e6), (5e-3, -9e6)):
        PA, PB = (s["P_s"] + PL) / 2, (s["P_s"] - PL) / 2
        _, QA, QB = ch.g(0, [], [i, PA, PB])
        assert (QA + QB) / 2 == pytest.approx(lp.g(0, [], [i, PL])[1], rel=1e-12)


def test_actuator_load_pressure_and_joint():
    h, j = P["hydraulic_actuator"], P["joint_inertia"]
    Q, w = 2e-5, 0.5
    ts, x, y = simulate(hydraulic_actuator(), [Q, w], 0.05)
    c = 4 * h["beta_e"] / h["V_t"]
    xr, _ = reference(lambda x: [c * (Q - h["D_m"] * w - h["C_tm"] * x[0])], [0.0], 0.05, scale=[1e6])
    close(x, xr)
    close(y[0], h["D_m"] * xr[0])
    tau, tl = 30.0, 5.0
    ts, x, _ = simulate(joint_inertia(), [tau, tl], 2.0)
    xr, _ = reference(lambda x: [x[1], (tau - j["B_m"] * x[1] - tl) / j["J"]], [0, 0], 2.0)
    close(x, xr)


def test_actuator_two_chamber():
    h, s = P["hydraulic_actuator"], P["servo_valve"]
    QA, QB, th, w = 1e-5, 0.8e-5, 0.3, 0.2
    m = hydraulic_actuator(form="two_chamber")
    ts, x, y = simulate(m, [QA, QB, th, w], 0.02)
    VA, VB = h["V_t"] / 2 + h["D_m"] * th, h["V_t"] / 2 - h["D_m"] * th

    def rhs(x):
        PA, PB = x
        leak = h["C_im"] * (PA - PB)
        return [h["beta_e"] / VA * (QA - h["D_m"] * w - leak - h["C_em"] * PA),
                h["beta_e"] / VB * (-QB + h["D_m"] * w + leak - h["C_em"] * PB)]
    xr, _ = reference(rhs, [s["P_s"] / 2] * 2, 0.02, scale=[1e7, 1e7])
    close(x, xr)
    close(y[0], h["D_m"] * (xr[0] - xr[1]))  # far above the cavitation floor: exact


def test_dc_motor_elastic_and_controller():
    d, c = P["dc_motor"], P["controller"]
    i_ref, th, w = 2.0, 0.0, 0.0
    m = dc_motor(elasticity=True)
    ts, x, y = simulate(m, [i_ref, th, w], 0.01)

    def rhs(x):
        phi, wm, i, di = x
        ts_ = d["c"] * (phi - d["ratio"] * th) + d["d"] * (wm - d["ratio"] * w)
        fr = d["R_v0"] * wm / math.sqrt(wm**2 + d["w_fric"] ** 2) + d["R_v1"] * wm
        return [wm, (d["k_t"] * i - fr - ts_) / d["J_m"], di,
                d["omega_c"] ** 2 * (i_ref - i) - 2 * d["zeta_c"] * d["omega_c"] * di]
    xr, _ = reference(rhs, [0, 0, 0, 0], 0.01, scale=[1, 100, 1, 1e3])
    close(x, xr)
    close(y[0], d["ratio"] * (d["c"] * xr[0] + d["d"] * xr[1]))
    u = [0.3, 0.1, -20.0, -5.0]  # q_ref, qd_ref, phi_m, w_m
    ts, x, y = simulate(controller(), u, 0.05)
    e_w = c["ratio"] * u[1] + c["k_p"] * (c["ratio"] * u[0] - u[2]) - u[3]
    close(x[0], e_w / c["T_s"] * ts)
    close(y[0], c["k_s"] * (e_w / c["T_s"] * ts + e_w))


def test_trajectories():
    tr = P["trajectory"]
    ev = NumericModel(ptp_trajectory())
    ts = np.linspace(-0.5, 2.0, 2501)
    Y = np.array([ev.g(t, [], []) for t in ts]).T
    # the acceleration integrates to the speed and the speed to the position
    from scipy.integrate import cumulative_trapezoid
    assert np.max(np.abs(cumulative_trapezoid(Y[2], ts, initial=0) - Y[1])) < 0.02
    assert np.max(np.abs(tr["q_begin"] + cumulative_trapezoid(Y[1], ts, initial=0) - Y[0])) < 1e-5
    assert np.max(np.abs(Y[1])) == pytest.approx(tr["qd_max"], rel=1e-12)
    assert np.max(np.abs(Y[2])) == pytest.approx(tr["qdd_max"], rel=1e-12)
    # end time from the closed form: T_e = dq/qd_max + qd_max/qdd_max
    T_e = (tr["q_end"] - tr["q_begin"]) / tr["qd_max"] + tr["qd_max"] / tr["qdd_max"]
    assert ev.g(T_e + 1e-9, [], [])[0] == pytest.approx(tr["q_end"], rel=1e-12)
    assert ev.g(T_e - 0.01, [], [])[0] == pytest.approx(tr["q_end"] - tr["qdd_max"] * 0.01**2 / 2, rel=1e-12)
    # short move: triangular speed profile with peak sqrt(dq qdd_max)
    short = NumericModel(ptp_trajectory(overrides={"q_end": 0.4}))
    peak = max(short.g(t, [], [])[1] for t in np.linspace(0, 1, 2001))
    assert peak == pytest.approx(math.sqrt(0.4 * tr["qdd_max"]), rel=1e-3)
    # quintic against numpy's polynomial
    q5 = NumericModel(quintic_trajectory())
    poly = np.polynomial.Polynomial([0, 0, 0, 10, -15, 6])
    for t in (0.3, 1.0, 1.7):
        s = t / tr["T_move"]
        dq = tr["q_end"] - tr["q_begin"]
        y = q5.g(t, [], [])
        assert y[0] == pytest.approx(tr["q_begin"] + dq * poly(s), rel=1e-12)
        assert y[1] == pytest.approx(dq * poly.deriv()(s) / tr["T_move"], rel=1e-12)
        assert y[2] == pytest.approx(dq * poly.deriv(2)(s) / tr["T_move"] ** 2, rel=1e-12)
    # tables: linear equals numpy.interp; the cubic passes the knots, is C2, natural at the ends
    tk, yk = [0.0, 0.5, 1.2, 2.0], [0.0, 10.0, -5.0, 3.0]
    lin = NumericModel(table_trajectory(tk, yk, output="tau_ref", unit="N.m"))
    for t in np.linspace(-0.3, 2.4, 37):
        assert lin.g(t, [], [])[0] == pytest.approx(np.interp(t, tk, yk), abs=1e-12)
    cub = NumericModel(table_trajectory(tk, yk, kind="cubic"))
    for t, y in zip(tk, yk):
        assert cub.g(t, [], [])[0] == pytest.approx(y, abs=1e-12)
    for t in tk[1:-1]:
        lo, hi = cub.g(t - 1e-9, [], []), cub.g(t + 1e-9, [], [])
        assert lo[1] == pytest.approx(hi[1], abs=1e-6) and lo[2] == pytest.approx(hi[2], abs=1e-5)
    assert cub.g(tk[0] + 1e-12, [], [])[2] == pytest.approx(0, abs=1e-9)
    assert cub.g(tk[-1] - 1e-12, [], [])[2] == pytest.approx(0, abs=1e-9)
    with pytest.raises(ValueError, match="increase strictly"):
        table_trajectory([0, 1, 1], [0, 1, 2])
