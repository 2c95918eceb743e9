"""Joint transforms of the general joint model, and the DH chain in joint frames.

Every body i of a :class:`~fmugen.robot.description.Robot` is placed in its
parent's frame by ``[R, p] * M(axis, q_i + offset)`` (see
:mod:`fmugen.robot.description`).  :func:`joint_transform` binds, in a
Program, the rotation ``^{parent}R_i`` and translation ``^{parent}p_i`` of the
body frame for joint value q_i: both formulations' tree recursions, the
composite-rigid-body mass matrix and the forward kinematics read it.

The motion about a unit axis k by the angle theta is Rodrigues' rotation
``c E + s [k]x + (1 - c) k k^T``; for an exact axis (z of a DH chain, an
aligned URDF axis) sympy folds the structural zeros and ones, so a DH chain
gives exactly the statements of ``Rx(alpha) Rz(theta)`` and a URDF joint
placed without rotation gives the bare Rodrigues matrix.

:func:`joint_frame_chain` keeps the Denavit-Hartenberg view (a, alpha, theta,
d per joint frame) that the looped runtime of large chains
(:mod:`fmugen.codegen.chain`) and the Pinocchio model of the benchmarks read.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from ..robot.description import MODIFIED, PRISMATIC, REVOLUTE, STANDARD, Robot, combined_last_link


def rot_x(alpha):
    c, s = sp.cos(alpha), sp.sin(alpha)
    return sp.Matrix([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_z(theta):
    c, s = sp.cos(theta), sp.sin(theta)
    return sp.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def axis_rotation(k, c, s) -> list:
    """Rodrigues' rotation about the unit axis k with cos c and sin s (rows, unbound)."""
    k = [sp.sympify(x) for x in k]
    K = [[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]]
    # formal cos/sin first, so that c + (1 - c) folds to an exact 1 even for numeric angles
    C, S = sp.Dummy("c"), sp.Dummy("s")
    rows = [[(C if r == m else 0) + S * K[r][m] + (1 - C) * k[r] * k[m] for m in range(3)] for r in range(3)]
    return [[sp.expand(e).xreplace({C: c, S: s}) for e in row] for row in rows]


def joint_transform(P, trig, body, q_i) -> tuple:
    """``(R, p)``: body frame in its parent's frame for joint value ``q_i``, entries bound in P."""
    R0 = [[sp.sympify(x) for x in row] for row in body.rotation]
    p0 = [sp.sympify(x) for x in body.translation]
    k = [sp.sympify(x) for x in body.axis]
    theta = q_i + body.offset
    if body.joint == REVOLUTE:
        c, s = trig.cos_sin(theta)
        Rm = axis_rotation(k, c, s)
        R = [[P.let(sum(R0[r][m] * Rm[m][col] for m in range(3))) for col in range(3)] for r in range(3)]
        p = [P.let(x) for x in p0]
    elif body.joint == PRISMATIC:
        R = [[P.let(x) for x in row] for row in R0]
        p = [P.let(p0[r] + sum(R0[r][m] * k[m] for m in range(3)) * theta) for r in range(3)]
    else:
        raise ValueError(f"unknown joint type {body.joint!r}")
    return R, p


@dataclass(frozen=True)
class JointFrameLink:
    """Link i of a DH chain seen from its joint frame F_i (all entries sympy expressions)."""

    joint: str
    alpha: sp.Expr  # constant rotation Rx(alpha) in front of the joint
    a: sp.Expr  # constant translation Tx(a) in front of the joint
    theta0: sp.Expr  # angle offset (revolute) or fixed angle (prismatic)
    d0: sp.Expr  # length offset (prismatic) or fixed length (revolute)
    mass: sp.Expr
    com: tuple  # centre of mass in F_i
    inertia_com: sp.Matrix  # about the COM, F_i axes
    rotor_inertia: sp.Expr
    damping: sp.Expr
    external_wrench: bool
    # the DH frame L_i = F_i * (Tx(end_a) Rx(end_alpha)); identity for modified DH
    end_a: sp.Expr
    end_alpha: sp.Expr


def joint_frame_chain(robot: Robot) -> tuple:
    """The links of a DH robot (payload merged) expressed in joint frames."""
    if not robot.links:
        raise ValueError(f"{robot.name}: written as joints, not as a Denavit-Hartenberg chain")
    links = combined_last_link(robot)
    out = []
    for i, L in enumerate(links):
        if robot.convention == STANDARD:
            prev = links[i - 1] if i > 0 else None
            alpha_in = prev.alpha if prev else sp.Integer(0)
            a_in = prev.a if prev else sp.Integer(0)
            end_a, end_alpha = L.a, L.alpha
        elif robot.convention == MODIFIED:
            alpha_in, a_in = L.alpha, L.a
            end_a, end_alpha = sp.Integer(0), sp.Integer(0)
        else:  # the loader rejects this; keep a clear message for direct callers
            raise ValueError(f"unknown DH convention {robot.convention!r}")
        body = robot.bodies[i]
        out.append(
            JointFrameLink(
                joint=L.joint,
                alpha=alpha_in,
                a=a_in,
                theta0=L.theta,
                d0=L.d,
                mass=body.mass,
                com=tuple(body.com),
                inertia_com=sp.Matrix(body.inertia_com),
                rotor_inertia=L.rotor_inertia,
                damping=L.damping,
                external_wrench=L.external_wrench,
                end_a=end_a,
                end_alpha=end_alpha,
            )
        )
    return tuple(out)
