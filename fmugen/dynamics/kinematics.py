"""Forward kinematics and the geometric Jacobian (DYNAMAN's third capability), over a tree.

``body_frames`` composes every body frame in base coordinates from the joint
transforms of :mod:`fmugen.dynamics.joint_frames`, ``^0T_i = ^0T_{parent(i)}
[R_i, p_i]``; ``frame_pose`` adds a named frame's fixed placement on its body
(a DH link frame -- the thesis's TRANSP for the last one --, a URDF tool
flange).

The geometric Jacobian J (6 x N) maps qd to the twist of a frame's origin
p, linear rows first, in base coordinates; only the joints on the path from
the frame's body to the base have non-zero columns:

    revolute joint j:  J_v = k_j x (p - o_j),  J_w = k_j
    prismatic joint j: J_v = k_j,              J_w = 0

where k_j is joint j's axis in base coordinates (``^0R_j axis_j``: the
motion leaves its own axis unchanged) and o_j the origin of body j, which
lies on the axis.

``dh_transform`` is the thesis's eq. (1) (standard convention)
``A_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``, or Craig's
``A_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i)`` for the modified
convention: the recursive Lagrange formulation of DH files works with it.
"""
from __future__ import annotations

import sympy as sp

from ..codegen.program import Program
from ..robot.description import REVOLUTE, Robot
from . import vectors as V
from .joint_frames import joint_transform
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


def homogeneous(R, p):
    """[R p; 0 1] as a list of rows."""
    return [[sp.sympify(R[r][c]) for c in range(3)] + [sp.sympify(p[r])] for r in range(3)] + [[Z, Z, Z, ONE]]


def compose(P: Program, T, A, hint="T"):
    """T A for homogeneous transforms (last rows [0 0 0 1])."""
    out = [[P.let(sum(T[i][k] * A[k][j] for k in range(3)) + (T[i][3] if j == 3 else 0), hint)
            for j in range(4)] for i in range(3)]
    return out + [[Z, Z, Z, ONE]]


def body_frames(P: Program, robot: Robot, q, trig: TrigCache = None, transform=None, frames=None) -> list:
    """[^0T_1, ..., ^0T_N]: body frames in base coordinates (0-based list).

    ``transform(i, q_i) -> (R, p)`` defaults to :func:`joint_transform`; the
    dynamics pass their engine's, so the bound rotations are shared.
    ``frames`` (names): compute only the bodies on their paths to the base
    (the others are None) -- a tool frame on one branch of a tree costs only
    that branch.
    """
    trig = trig or TrigCache(P)
    if transform is None:
        def transform(i, q_i):
            return joint_transform(P, trig, robot.bodies[i], q_i)
    needed = None
    if frames is not None:
        needed = set()
        for name in frames:
            needed |= set(robot.ancestors(robot.locate(name)[0]))
    Ts = []
    for i, b in enumerate(robot.bodies):
        if needed is not None and i not in needed:
            Ts.append(None)
            continue
        A = homogeneous(*transform(i, q[i]))
        Ts.append(A if b.parent < 0 else compose(P, Ts[b.parent], A))
    return Ts


def frame_pose(P: Program, robot: Robot, Ts, name: str):
    """``(body index, ^0T)`` of the body or frame ``name`` (KeyError names the known ones)."""
    parent, R, p = robot.locate(name)
    base = identity4() if parent < 0 else Ts[parent]
    if all(sp.sympify(x) == 0 for x in p) and all(sp.sympify(R[r][c]) == int(r == c) for r in range(3) for c in range(3)):
        return parent, base
    return parent, compose(P, base, homogeneous(R, p))


def geometric_jacobian(P: Program, robot: Robot, Ts, point=None, body: int = None) -> sp.Matrix:
    """6 x N geometric Jacobian of ``point`` (base coordinates) fixed to ``body``.

    Defaults: the origin of ``robot.end_frame``.  Linear rows first.
    """
    if point is None:
        body, T = frame_pose(P, robot, Ts, robot.end_frame)
        point = [T[r][3] for r in range(3)]
    n = robot.n
    J = sp.zeros(6, n)
    j = body
    while j is not None and j >= 0:
        b = robot.bodies[j]
        R = [[Ts[j][r][c] for c in range(3)] for r in range(3)]
        k = V.matvec(P, R, [sp.sympify(x) for x in b.axis], "k")
        if b.joint == REVOLUTE:
            o = [Ts[j][r][3] for r in range(3)]
            lin = V.cross(P, k, V.sub(P, point, o), "Jv")
            for r in range(3):
                J[r, j] = lin[r]
                J[3 + r, j] = k[r]
        else:
            for r in range(3):
                J[r, j] = k[r]
        j = b.parent
    return J


def link_frames(P: Program, robot: Robot, q, trig: TrigCache = None, transform=None) -> list:
    """[T_0 = I, T_1, ..., T_N]: the DH link frames ``frame1..frameN`` of a DH robot in base coordinates."""
    Ts = body_frames(P, robot, q, trig, transform)
    return [identity4()] + [frame_pose(P, robot, Ts, f"frame{i + 1}")[1] for i in range(robot.n)]
