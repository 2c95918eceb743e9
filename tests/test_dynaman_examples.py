"""DYNAMAN's two validation examples, symbolically, against independent closed forms."""
import pytest
import sympy as sp

import fmugen
from symbolic_zero import is_identically_zero


def hand_lagrangian(q, qd, kinetic, potential):
    """M and h from L = T - V by sympy differentiation (tau = M qdd + h)."""
    t = sp.Symbol("t")
    qt = [sp.Function(f"Q{i}")(t) for i in range(len(q))]
    to_t = {**{q[i]: qt[i] for i in range(len(q))}, **{qd[i]: qt[i].diff(t) for i in range(len(q))}}
    L = (kinetic - potential).xreplace(to_t)
    qdd = [sp.Symbol(f"A{i}") for i in range(len(q))]
    back = {}
    for i in range(len(q)):
        back[qt[i].diff(t, 2)] = qdd[i]
    for i in range(len(q)):
        back[qt[i].diff(t)] = qd[i]
    for i in range(len(q)):
        back[qt[i]] = q[i]
    eqs = []
    for i in range(len(q)):
        e = sp.diff(L.diff(qt[i].diff(t)), t) - L.diff(qt[i])
        eqs.append(sp.expand(e.subs(back)))
    M = sp.Matrix(len(q), len(q), lambda i, j: eqs[i].coeff(qdd[j]))
    h = sp.Matrix([eqs[i].subs({a: 0 for a in qdd}) for i in range(len(q))])
    return M, h


@pytest.mark.parametrize("formulation", fmugen.FORMULATIONS)
def test_horn_two_link_equals_hand_lagrangian(formulation):
    """Example I: two equal uniform rods, planar, gravity along -y (OCR of the report is garbled)."""
    arm = fmugen.load_robot("robots/horn_2link.toml", formulation)
    m, l, g = (arm.robot.parameter(n).symbol for n in ("m", "l", "g"))
    q1, q2 = arm.q
    w1, w2 = arm.qd
    # centres of mass of two uniform rods of length l from the base joint
    c1 = sp.Matrix([l / 2 * sp.cos(q1), l / 2 * sp.sin(q1)])
    c2 = sp.Matrix([l * sp.cos(q1) + l / 2 * sp.cos(q1 + q2), l * sp.sin(q1) + l / 2 * sp.sin(q1 + q2)])
    v1 = c1.diff(q1) * w1
    v2 = c2.diff(q1) * w1 + c2.diff(q2) * w2
    Irod = m * l**2 / 12
    T = m / 2 * (v1.dot(v1) + v2.dot(v2)) + Irod / 2 * (w1**2 + (w1 + w2) ** 2)
    V = m * g * (c1[1] + c2[1])
    M_ref, h_ref = hand_lagrangian(arm.q, arm.qd, T, V)
    M, h = arm.closed_form()
    for e in list(M - M_ref) + list(h - h_ref):
        assert is_identically_zero(e, arm.q)
    # the report's printed first mass-matrix entry: (3 cos q2 + 5)/6 * 2 m l^2 / ... -> m l^2 (5/3 + cos q2)
    assert sp.simplify(M[0, 0] - m * l**2 * (sp.Rational(5, 3) + sp.cos(q2))) == 0


@pytest.mark.parametrize("formulation", fmugen.FORMULATIONS)
@pytest.mark.parametrize("rod", ["line_mass", "uniform_rod"])
def test_freund_rp_equals_printed_equations(formulation, rod):
    """Example II as printed (report section 4), rod without (or with) its own inertia."""
    arm = fmugen.load_robot("robots/freund_rp.toml", formulation)
    P = {n: arm.robot.parameter(n).symbol for n in ("md", "Idscz", "mr", "lr", "I_r", "g")}
    mr, lr, Id = P["mr"], P["lr"], P["Idscz"]
    I_r = 0 if rod == "line_mass" else mr * lr**2 / 12
    r2 = arm.q[1]
    th1d, r2d = arm.qd
    M, h = arm.closed_form()
    M, h = M.subs(P["I_r"], I_r), h.subs(P["I_r"], I_r)
    # report: thdd1 ((lr^2 - 4 r2 lr + 4 r2^2) mr / 4 + Idscz) = T1 + (thd1 r2d lr - 2 r2 thd1 r2d) mr
    #         r2dd mr = F2 - (thd1^2 lr - 2 r2 thd1^2) mr / 2
    M_ref = sp.Matrix([[(lr**2 - 4 * r2 * lr + 4 * r2**2) * mr / 4 + Id + I_r, 0], [0, mr]])
    h_ref = sp.Matrix([-(th1d * r2d * lr - 2 * r2 * th1d * r2d) * mr, (th1d**2 * lr - 2 * r2 * th1d**2) * mr / 2])
    assert sp.simplify(M - M_ref) == sp.zeros(2, 2)
    assert sp.simplify(h - h_ref) == sp.zeros(2, 1)
