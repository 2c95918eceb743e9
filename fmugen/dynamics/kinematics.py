"""Forward kinematics and the geometric Jacobian (DYNAMAN's third capability).

``dh_transform`` is the thesis's eq. (1) (standard convention)
``A_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``, or Craig's
``A_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i)`` for the modified
convention.  ``T_i = T_{i-1} A_i`` (eq. 2, 33) gives every link frame in base
coordinates, the thesis's TRANSP for the last one.

The geometric Jacobian J (6 x N) maps qd to the twist of the last frame's
origin, linear rows first, in base coordinates:

    revolute joint i:  J_v = z_i x (p_N - o_i),  J_w = z_i
    prismatic joint i: J_v = z_i,                J_w = 0

where z_i, o_i are the joint's axis and a point on it (frame i-1 in the
standard convention, frame i in the modified one).
"""
from __future__ import annotations

import sympy as sp

from ..codegen.program import Program
from ..robot.description import MODIFIED, REVOLUTE, Robot
from . import vectors as V
from .trig import TrigCache

Z, ONE = sp.Integer(0), sp.Integer(1)


def dh_transform(P: Program, trig: TrigCache, link, q_i, modified: bool):
    """The 4x4 link transform A_i (list of rows) with its entries bound in P."""
    if link.joint == REVOLUTE:
        theta, d = link.theta + q_i, link.d
    else:
        theta, d = link.theta, link.d + q_i
    ct, st = trig.cos_sin(theta)
    ca, sa = trig.cos_sin(link.alpha)
    a, d = sp.sympify(link.a), sp.sympify(d)
    if not modified:
        return [
            [ct, P.let(-st * ca), P.let(st * sa), P.let(a * ct)],
            [st, P.let(ct * ca), P.let(-ct * sa), P.let(a * st)],
            [Z, sa, ca, d],
            [Z, Z, Z, ONE],
        ]
    return [
        [ct, -st, Z, a],
        [P.let(ca * st), P.let(ca * ct), -sa, P.let(-sa * d)],
        [P.let(sa * st), P.let(sa * ct), ca, P.let(ca * d)],
        [Z, Z, Z, ONE],
    ]


def identity4():
    return [[ONE if i == j else Z for j in range(4)] for i in range(4)]


def compose(P: Program, T, A, hint="T"):
    """T A for homogeneous transforms (last rows [0 0 0 1])."""
    out = [[P.let(sum(T[i][k] * A[k][j] for k in range(3)) + (T[i][3] if j == 3 else 0), hint)
            for j in range(4)] for i in range(3)]
    return out + [[Z, Z, Z, ONE]]


def link_frames(P: Program, robot: Robot, q, trig: TrigCache = None) -> list:
    """[T_0 = I, T_1, ..., T_N]: every link frame in base coordinates."""
    trig = trig or TrigCache(P)
    modified = robot.convention == MODIFIED
    Ts = [identity4()]
    for i, L in enumerate(robot.links):
        Ts.append(compose(P, Ts[-1], dh_transform(P, trig, L, q[i], modified)))
    return Ts


def geometric_jacobian(P: Program, robot: Robot, Ts) -> sp.Matrix:
    """6 x N geometric Jacobian of the last frame's origin (linear rows first)."""
    n = robot.n
    modified = robot.convention == MODIFIED
    pN = [Ts[n][r][3] for r in range(3)]
    J = sp.zeros(6, n)
    for i, L in enumerate(robot.links):
        T = Ts[i + 1] if modified else Ts[i]
        z = [T[r][2] for r in range(3)]
        if L.joint == REVOLUTE:
            o = [T[r][3] for r in range(3)]
            lin = V.cross(P, z, V.sub(P, pN, o), "Jv")
            for r in range(3):
                J[r, i] = lin[r]
                J[3 + r, i] = z[r]
        else:
            for r in range(3):
                J[r, i] = z[r]
    return J
