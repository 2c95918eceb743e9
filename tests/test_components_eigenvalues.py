"""Linearised one-joint chain: eigenvalues of actuator-chain.md, stiffness, stable steps.

The reference numbers are the note's table ("Test values: eigenvalues of the
linearised joint at rest"); the Jacobian is the assembled SymbolicModel's
exact dfdx at rest.  A second, independent reference is the state matrix
written out by hand from the note's equations (numpy, no sympy).
"""
import math

import numpy as np
import pytest

from fmugen.components import linearise, load_parameter_set, single_joint, stable_step

NOTE = {  # (set, control, opamp) -> eigenvalues from actuator-chain.md
    ("default", "P", "ideal"): [-10.541594, -6.1155814 + 54.32192j, -6.1155814 - 54.32192j,
                                -439.76686 + 448.7483j, -439.76686 - 448.7483j, -2399.9995],
    ("default", "PI", "ideal"): [-2.7494184, -7.7222064, -6.1505299 + 54.125395j, -6.1505299 - 54.125395j,
                                 -439.7669 + 448.74809j, -439.7669 - 448.74809j, -2399.9995],
    ("default", "PI", "real"): [-2.7495365, -7.7214494, -6.1509533 + 54.124685j, -6.1509533 - 54.124685j,
                                -439.7668 + 448.74806j, -439.7668 - 448.74806j, -2399.9995, -394954.34],
    ("stiff", "P", "ideal"): [-10.205078, -98.010603 + 362.626j, -98.010603 - 362.626j,
                              -1319.2558 + 1346.3601j, -1319.2558 - 1346.3601j, -50000],
    ("stiff", "PI", "ideal"): [-2.7562014, -7.4057837, -98.032168 + 362.60426j, -98.032168 - 362.60426j,
                               -1319.2558 + 1346.3597j, -1319.2558 - 1346.3597j, -50000],
    ("stiff", "PI", "real"): [-2.7563226, -7.4050509, -98.033965 + 362.5992j, -98.033965 - 362.5992j,
                              -1319.2543 + 1346.3598j, -1319.2543 - 1346.3598j, -50000, -394954.34],
}
RATIO = {("default", "P", "ideal"): 392, ("default", "PI", "ideal"): 873, ("default", "PI", "real"): 1.44e5,
         ("stiff", "P", "ideal"): 4.9e3, ("stiff", "PI", "ideal"): 1.81e4, ("stiff", "PI", "real"): 1.43e5}


def match(computed, reference):
    """Pair each reference eigenvalue with the nearest computed one; max relative error."""
    computed = list(np.asarray(computed, dtype=complex))
    assert len(computed) == len(reference)
    worst = 0.0
    for r in reference:
        k = int(np.argmin([abs(c - r) for c in computed]))
        worst = max(worst, abs(computed.pop(k) - r) / abs(r))
    return worst


def hand_matrix(set_name, control, opamp):
    """State matrix of the linearised chain written from the note's equations.

    States: theta, w, P_L, x, x_dot, i, [z], [v].
    """
    p = {fam: dict(v) for fam, v in load_parameter_set(set_name).sections.items()}
    a, d, sv, ha, j = p["amplifier"], p["current_driver"], p["servo_valve"], p["hydraulic_actuator"], p["joint_inertia"]
    K_q0 = sv["Q_N"] * math.sqrt(sv["P_s"] / sv["dp_N"])
    n = 6 + (control == "PI") + (opamp == "real")
    A = np.zeros((n, n))
    A[0, 1] = 1
    A[1, 1], A[1, 2] = -j["B_m"] / j["J"], ha["D_m"] / j["J"]
    c = 4 * ha["beta_e"] / ha["V_t"]
    A[2, 1], A[2, 2], A[2, 3] = -c * ha["D_m"], -c * (sv["K_c0"] + ha["C_tm"]), c * K_q0
    A[3, 4] = 1
    A[4, 3], A[4, 4], A[4, 5] = -sv["omega_v"] ** 2, -2 * sv["zeta_v"] * sv["omega_v"], sv["omega_v"] ** 2 / sv["i_rated"]
    e_in = np.zeros(n)
    e_in[0] = -1
    if control == "PI":
        A[6, 0] = -1
        e_in[6] = 1 / a["T_I"]
    if opamp == "real":
        wp = 2 * math.pi * a["GBW"] / a["A0"]
        A[n - 1] += wp * a["A0"] * e_in
        A[n - 1, n - 1] -= wp * (a["A0"] / a["K_a"] + 1)
        u = np.zeros(n)
        u[n - 1] = 1
    else:
        u = a["K_a"] * e_in
    A[5] += d["omega_i"] * d["G_i"] * u
    A[5, 5] -= d["omega_i"]
    return A


@pytest.mark.parametrize("case", list(NOTE))
def test_eigenvalues_match_note(case):
    set_name, control, opamp = case
    m = single_joint(set_name, control=control, opamp=opamp)
    assert m.nx == len(NOTE[case])
    ev = np.linalg.eigvals(linearise(m).A)
    assert match(ev, NOTE[case]) < 1e-6
    # the independent hand-written matrix agrees much more tightly
    assert match(ev, list(np.linalg.eigvals(hand_matrix(*case)))) < 1e-9
    re = np.abs(ev.real)
    assert re.max() / re.min() == pytest.approx(RATIO[case], rel=0.01)


def test_stiff_set_is_stiff():
    for control, opamp in (("PI", "ideal"), ("PI", "real")):
        re = np.abs(np.linalg.eigvals(linearise(single_joint("stiff", control=control, opamp=opamp)).A).real)
        assert re.max() / re.min() >= 1e4


@pytest.mark.parametrize("set_name, control, opamp, euler, rk4", [
    ("default", "P", "ideal", 0.83e-3, 1.16e-3),
    ("stiff", "P", "ideal", 40e-6, 56e-6),
    ("default", "PI", "real", 5e-6, 7e-6),
    ("stiff", "PI", "real", 5e-6, 7e-6),
])
def test_stable_explicit_steps_match_note(set_name, control, opamp, euler, rk4):
    ev = np.linalg.eigvals(linearise(single_joint(set_name, control=control, opamp=opamp)).A)
    assert stable_step(ev, "euler") == pytest.approx(euler, rel=0.03)
    assert stable_step(ev, "rk4") == pytest.approx(rk4, rel=0.03)
    # closed form for explicit Euler: h < min 2|Re l|/|l|^2
    assert stable_step(ev, "euler") == pytest.approx(min(-2 * l.real / abs(l) ** 2 for l in ev), rel=1e-9)


def test_rk4_boundary_on_real_axis():
    # RK4's real-axis stability interval is [-2.785293563..., 0]
    assert stable_step([-1.0], "rk4") == pytest.approx(2.785293563405282, rel=1e-9)


@pytest.mark.parametrize("set_name", ["default", "stiff"])
def test_coil_driver_reproduces_lag(set_name):
    # the shipped coil values are chosen for the lag's gain and bandwidth
    lag = np.linalg.eigvals(linearise(single_joint(set_name, driver="lag")).A)
    coil = np.linalg.eigvals(linearise(single_joint(set_name, driver="coil")).A)
    assert match(coil, list(lag)) < 1e-9


@pytest.mark.parametrize("j", range(1, 7))
def test_puma_joint_sets_are_stable(j):
    ev = np.linalg.eigvals(linearise(single_joint(f"puma_joint{j}", control="PI")).A)
    assert np.all(ev.real < 0)
